"""The wheel users install holds every module of the source tree (no package listed by hand)."""

from __future__ import annotations

import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE_FOLDERS = ("storage", "hydro", "handoff", "nbody", "analysis", "pipeline")


def test_the_wheel_holds_every_source_module_and_the_package_data(tmp_path):
    source = tmp_path / "source"  # a copy, so that the build leaves nothing in the checkout
    for name in ("pyproject.toml", "setup.py", "README.md"):
        shutil.copy2(ROOT / name, source / name if source.exists() else (source.mkdir() or source / name))
    for folder in PACKAGE_FOLDERS:
        shutil.copytree(ROOT / folder, source / folder, ignore=shutil.ignore_patterns("__pycache__"))
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(source)],
                   check=True, cwd=tmp_path)
    (wheel,) = tmp_path.glob("impactpipe-*.whl")
    with zipfile.ZipFile(wheel) as archive:
        names = set(archive.namelist())
    expected = {f"impactpipe/{path.relative_to(ROOT).as_posix()}"
                for folder in PACKAGE_FOLDERS for path in (ROOT / folder).rglob("*.py")}
    expected.add("impactpipe/pipeline/data/materials.yaml")
    missing = sorted(expected - names)
    assert not missing, f"missing from the wheel: {missing}"
    assert any(name.endswith("entry_points.txt") for name in names)
