"""Input errors end as one ``file:line: key: message`` line and exit 2 before anything is written;
``run()`` applies the checks of ``validate``; read-only runs are analysed and plotted elsewhere."""

import contextlib
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml
from click.testing import CliRunner

from impactpipe.pipeline import stages
from impactpipe.pipeline.cli import main
from impactpipe.pipeline.config import ConfigError, load_config
from impactpipe.pipeline.sweep import SweepError, load_sweep

HERE = Path(__file__).parent
SOD = (Path(__file__).parent / "configs" / "sod.yaml").read_text()
SEDOV = """name: sedov
scene:
  problem: sedov
  energy: 1.0
  ambient: {material: gas, density: 1.0, pressure: 1.0e-5}
  cells: 96
materials:
  gas: {eos: {model: ideal_gas, gamma: 1.4}}
hydro:
  max_levels: 3
"""


def rejected(tmp_path, text: bytes | str, expected: str):
    """``validate`` and ``run`` of the config ``text`` both exit 2 with the one line ``expected``
    (after the file name) and write nothing."""
    path = tmp_path / "c.yaml"
    (path.write_bytes if isinstance(text, bytes) else path.write_text)(text)
    for command in (["validate", str(path)], ["run", str(path), "--out", str(tmp_path / "run")]):
        result = CliRunner().invoke(main, command)
        assert result.exit_code == 2, result.output
        assert result.output.strip().splitlines() == [f"{path}:{expected}"], result.output
    assert not (tmp_path / "run").exists()


def validates_on_one_rank_only(tmp_path, text: str, ranks_message: str):
    """``validate`` accepts the config ``text`` (exit 0), and ``--ranks 2`` is refused with
    ``ranks_message`` before any work."""
    from impactpipe.pipeline.adapters.hydro import too_many_ranks
    from impactpipe.pipeline.checks import check

    path = tmp_path / "one_rank.yaml"
    path.write_text(text)
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 0, result.output
    config = load_config(path)
    assert too_many_ranks(config, check(config), 2) == ranks_message


def test_non_utf8_bytes_name_the_line_and_key(tmp_path):
    text = SOD.replace("name: sod", "name: sod # caf\xe9").encode("latin-1")
    rejected(tmp_path, text, "2: name: not UTF-8 text: byte 0xe9 at column 16 (save the file as UTF-8)")


def test_duplicate_keys_are_errors(tmp_path):
    text = SOD.replace("  end_time: 0.2\n", "  end_time: 0.2\n  cells: 128\n")
    rejected(tmp_path, text, "9: scene.cells: duplicate key (first given at line 5); give it once")


def test_hydro_end_time_of_a_verification_scene_is_an_error(tmp_path):
    rejected(tmp_path, SOD + "hydro: {end_time: 1.0}\n",
             "11: hydro.end_time: applies to impact scenes only; the shock_tube scene runs to scene.end_time, "
             "so this value would be ignored: remove it and set scene.end_time")


def test_time_stepping_is_global_or_per_level_and_per_level_refuses_what_it_does_not_carry(tmp_path):
    """``hydro.time_stepping``: an unknown mode, and per_level with self-gravity or on several MPI ranks, are
    refused before any work; per_level alone validates."""
    sedov = SEDOV.replace("cells: 96", "cells: 128")
    rejected(tmp_path, sedov + "  time_stepping: sometimes\n",
             "11: hydro.time_stepping: must be one of 'global' or 'per_level' (got 'sometimes')")
    case8c = (HERE.parent / "configs" / "reference" / "case8c.yaml").read_text()
    rejected(tmp_path, case8c.replace("  self_gravity: false\n", "  self_gravity: true\n  time_stepping: per_level\n"),
             "19: hydro.time_stepping: per_level does not support self-gravity (hydro.self_gravity) yet; "
             "use global")
    validates_on_one_rank_only(tmp_path, sedov + "  time_stepping: per_level\n", (
        "--ranks 2: hydro.time_stepping per_level runs the hydro stage on one process in this version; use "
        "--ranks 1 or hydro.time_stepping global"))


def test_python_run_applies_the_checks_of_validate(tmp_path):
    """A Sedov config with three levels whose root level would not hold whole blocks, and mesh cells
    the block size does not divide, raise the located ConfigError from ``run()`` (as validate does),
    before anything is written; with a cell count it divides, validate accepts the three levels."""
    path = tmp_path / "sedov.yaml"
    path.write_text(SEDOV)
    with pytest.raises(ConfigError) as info:
        stages.run(load_config(path), tmp_path / "run", show_progress=False)
    assert info.value.messages == [f"{path}:6: scene.cells: 96 is not a multiple of 64, the block size 16 "
                                   "(hydro.block_cells) times 2^(3 - 1): scene.cells counts cells of the finest of 3 "
                                   "levels (hydro.max_levels) and the root level holds whole blocks; use a multiple "
                                   "of 64 or fewer levels"]
    path.write_text(SEDOV.replace("cells: 96", "cells: 128"))
    result = CliRunner().invoke(main, ["validate", str(path)])
    assert result.exit_code == 0 and "adaptive, 3 levels" in result.output, result.output
    path.write_text(SOD.replace("cells: 64", "cells: 100"))
    with pytest.raises(ConfigError) as info:
        stages.run(load_config(path), tmp_path / "run", show_progress=False)
    assert info.value.messages == [f"{path}:5: scene.cells: 100 is not a multiple of the block size 8 "
                                   "(hydro.block_cells); use a multiple of 8"]
    assert not (tmp_path / "run").exists()


def test_sweep_points_get_the_same_checks_before_any_work(tmp_path):
    base = tmp_path / "sod.yaml"
    base.write_text(SOD)
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump({"name": "cells", "base": str(base), "output": str(tmp_path / "sweep"),
                                    "axes": {"scene.cells": [64, 100]}}))
    with pytest.raises(SweepError) as info:
        load_sweep(path)
    assert info.value.messages == [f"point scene.cells=100: {base}:5: scene.cells: 100 is not a multiple of the "
                                   "block size 8 (hydro.block_cells); use a multiple of 8"]
    path.write_text(f"name: dup\nbase: {base}\nname: again\n")
    with pytest.raises(SweepError, match=f"{path}:3: name: duplicate key"):
        load_sweep(path)


def _can_write(directory: Path) -> bool:
    try:
        (directory / ".probe").write_text("")
    except OSError:
        return False
    (directory / ".probe").unlink()
    return True


@contextlib.contextmanager
def read_only(directory: Path):
    """``directory`` and everything in it unwritable: modes without write bits, and where that does
    not stop this process (root) the immutable attribute; skips the test where neither works."""
    paths = [directory, *directory.rglob("*")]
    modes = {p: p.stat().st_mode for p in paths}
    for p in paths:
        p.chmod(modes[p] & ~0o222)
    immutable = _can_write(directory) and shutil.which("chattr") is not None and \
        subprocess.run(["chattr", "+i", *map(str, paths)], capture_output=True).returncode == 0
    try:
        if _can_write(directory):
            pytest.skip("cannot make a directory read-only for this process")
        yield
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", *map(str, paths)], check=True)
        for p in paths:
            p.chmod(modes[p])


def test_read_only_output_directory_is_a_clear_error(tmp_path):
    path = tmp_path / "sod.yaml"
    path.write_text(SOD)
    out = tmp_path / "readonly"
    out.mkdir()
    with read_only(out):
        result = CliRunner().invoke(main, ["run", str(path), "--out", str(out / "run")])
    assert result.exit_code == 2, result.output
    assert result.output.strip() == f"error: {out / 'run'}: cannot write there (Permission denied); nothing was written" \
        or result.output.strip() == f"error: {out / 'run'}: cannot write there (Operation not permitted); nothing " \
                                    "was written", result.output
    assert not (out / "run").exists()


def test_read_only_finished_run_is_analysed_and_plotted_elsewhere(tmp_path):
    """A tiny real impact, made read-only: rerunning or analysing it in place exits 2 with a hint;
    ``analyze --out`` and ``plot --out`` write into another directory."""
    config = tmp_path / "tiny.yaml"
    config.write_text((HERE.parent / "configs" / "quickstart.yaml").read_text()
                      .replace("cells_per_projectile_radius: 4", "cells_per_projectile_radius: 2")
                      .replace("velocity: 250.0", "velocity: 1.0e2"))
    run_dir = tmp_path / "run"
    assert CliRunner().invoke(main, ["run", str(config), "--out", str(run_dir), "-q"]).exit_code == 0
    before = stages.read_summary(run_dir)
    other = tmp_path / "other"
    with read_only(run_dir):
        again = CliRunner().invoke(main, ["analyze", str(run_dir)])
        assert again.exit_code == 2 and "Traceback" not in again.output, again.output
        assert f"`impactpipe analyze {run_dir} --out DIR` writes the analysis elsewhere" in again.output
        plot = CliRunner().invoke(main, ["plot", str(run_dir)])
        assert plot.exit_code == 2 and "give --out DIR or --out FILE.png" in plot.output, plot.output
        analysed = CliRunner().invoke(main, ["analyze", str(run_dir), "--out", str(other), "-q"])
        assert analysed.exit_code == 0, analysed.output
        plotted = CliRunner().invoke(main, ["plot", str(run_dir), "--out", str(other / "figures")])
        assert plotted.exit_code == 0, plotted.output
    summary = stages.read_summary(other)
    assert summary["M_lr_over_M_T"] == before["M_lr_over_M_T"] and summary["Q"] == before["Q"]
    assert (other / "analysis.h5").is_file()
    assert [p.suffix for p in (other / "figures").iterdir()] == [".png"]


def test_void_settling_on_several_levels_or_ranks_is_refused_before_any_work(tmp_path):
    """``scene.settling`` settles void column by column on a mesh of one level in one process:
    with two levels validate names the key (where the Simulation used to raise at its first step),
    and ``--ranks 2`` is refused; with one level it validates."""
    collapse = (HERE.parent / "configs" / "column_collapse.yaml").read_text()
    settled = collapse.replace("  cells_per_height: 16\n", "  cells_per_height: 16\n  settling: true\n")
    rejected(tmp_path, settled.replace("  block_cells: 8\n", "  block_cells: 8\n  max_levels: 2\n"),
             "15: scene.settling: void settling runs on a mesh of one level; hydro.max_levels resolves to 2: "
             "set hydro.max_levels: 1 or scene.settling: false")
    validates_on_one_rank_only(tmp_path, settled, (
        "--ranks 2: scene.settling (void settling) runs the hydro stage on one process in this version; use "
        "--ranks 1 or scene.settling: false"))
