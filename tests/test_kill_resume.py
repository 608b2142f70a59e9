"""A run killed with SIGKILL between any two of its writes (a power loss) and rerun with the
same call gives the uninterrupted run's files bit for bit.

A child process runs the pipeline with every file write counted: each ``os.replace`` (the
rename that completes an atomic write, and the hydro stage's final rename) and each HDF5
file opened for writing.  At the n-th write the child kills itself with SIGKILL, before or
after the write.  The n are drawn at random but reproducibly over all the run's writes; the
hydro stage writes its checkpoint after every step here, so most kills resume from a
checkpoint.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from test_stop_resume import OVERRIDES, QUICKSTART, assert_same_files, assert_same_summary

KILLS = 6
RNG_SEED = 424242
#: Checkpoint after every step, so the kills land between checkpoint writes too.
KILL_OVERRIDES = {**OVERRIDES, "hydro.checkpoint_wall_seconds": 1.0e-9}
STAGE_FILES = ("hydro.h5", "handoff.h5", "nbody.h5", "analysis.h5")

CHILD = textwrap.dedent("""
    import json, os, signal, sys
    import h5py

    kill_at = int(sys.argv[1])
    count = [0]

    def write_happens():
        count[0] += 1
        if count[0] == kill_at:
            os.kill(os.getpid(), signal.SIGKILL)

    real_replace = os.replace

    def replace(src, dst, *args, **kwargs):
        write_happens()
        real_replace(src, dst, *args, **kwargs)
        write_happens()

    os.replace = replace
    real_init = h5py.File.__init__

    def init(self, name, mode="r", *args, **kwargs):
        if mode != "r":
            write_happens()
        real_init(self, name, mode, *args, **kwargs)

    h5py.File.__init__ = init
    from impactpipe.pipeline import load_config, run

    run(load_config(sys.argv[2], overrides=json.loads(sys.argv[3])), sys.argv[4], show_progress=False)
    print("writes", count[0])
""")


def run_child(kill_at: int, run_dir: Path, script: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(script), str(kill_at), str(QUICKSTART), json.dumps(KILL_OVERRIDES),
                           str(run_dir)], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def child_reference(tmp_path_factory):
    """The uninterrupted run (kill at write 0: never) and its number of writes."""
    base = tmp_path_factory.mktemp("kill")
    script = base / "child.py"
    script.write_text(CHILD)
    reference = base / "reference"
    done = run_child(0, reference, script)
    assert done.returncode == 0, done.stderr
    writes = int(done.stdout.split()[-1])
    return script, reference, writes


@pytest.mark.parametrize("where", np.random.default_rng(RNG_SEED).random(KILLS), ids=lambda w: f"at{w:.3f}")
def test_a_kill_between_two_writes_resumes_to_the_same_answer(where, child_reference, tmp_path):
    script, reference, writes = child_reference
    kill_at = 1 + int(where * (writes - 1))
    killed = run_child(kill_at, tmp_path, script)
    assert killed.returncode == -signal.SIGKILL, (kill_at, writes, killed.stderr[-2000:])
    resumed = run_child(0, tmp_path, script)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    assert_same_files(tmp_path, reference, STAGE_FILES)
    assert_same_summary(tmp_path, reference)
