"""The console says when numba compiles kernels (a fresh install) and stays silent when they come
from numba's cache."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

from impactpipe.pipeline.progress import COMPILE_MESSAGE

KERNELS = textwrap.dedent("""
    import numba
    from impactpipe.storage import atomic_path

    @numba.njit(cache=True)
    def twice(x):
        return 2.0 * x

    def hydro(ctx):
        assert twice(1.5) == 3.0
        with atomic_path(ctx.path("hydro")) as tmp:
            tmp.write_text("hydro")
        return {}
""")
RUN = textwrap.dedent("""
    import logging, sys
    from impactpipe.pipeline import stages
    from impactpipe.pipeline.config import parse_config
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    config = parse_config(open(sys.argv[1]).read(), source=sys.argv[1])
    stages.run(config, sys.argv[2], show_progress=False, force=True, stage_functions={"hydro": "kernels:hydro"})
""")
SOD = (Path(__file__).parent / "configs" / "sod.yaml").read_text()


def test_compiling_is_announced_on_a_cold_cache_only(tmp_path):
    (tmp_path / "kernels.py").write_text(KERNELS)
    (tmp_path / "sod.yaml").write_text(SOD)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba-cache"),
           "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}

    def run():
        result = subprocess.run([sys.executable, "-c", RUN, str(tmp_path / "sod.yaml"), str(tmp_path / "run")],
                                env=env, capture_output=True, text=True, timeout=600)
        assert result.returncode == 0, result.stderr
        return result.stderr.splitlines()

    cold = run()
    assert cold.count(COMPILE_MESSAGE) == 1, cold
    assert cold.index("hydro: --force") < cold.index(COMPILE_MESSAGE), "shown while the stage compiles"
    assert any(line.startswith("numerical kernels compiled in ") for line in cold), cold
    warm = run()
    assert COMPILE_MESSAGE not in warm and not any("compiled" in line for line in warm), warm
    assert "hydro: --force" in warm
