"""Importing the command line compiles no kernel: every impactpipe command, sweep pool worker and
MPI rank imports it, and a kernel called at import time (without a cache) would be compiled again
in each of those processes."""

import subprocess
import sys

PROBE = """
from numba.core import event
compiled = []
class Listener(event.Listener):
    def on_start(self, ev):
        compiled.append(ev.data["dispatcher"].py_func.__qualname__)
    def on_end(self, ev):
        pass
event.register("numba:compile", Listener())
import impactpipe.pipeline.cli  # noqa: F401
import impactpipe.hydro.strength.model  # noqa: F401
print(",".join(compiled))
"""


def test_importing_the_command_line_compiles_no_kernel():
    result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "", f"compiled at import: {result.stdout.strip()}"
