"""Test-session settings.

Under pytest-xdist (the README's test command) every worker process runs numba's parallel
kernels on its share of the cores, NUMBA_NUM_THREADS // workers threads (at least one): with
each worker on every core, two workers on two cores ran the column-collapse tests ten times
slower than alone, their threads waiting on each other.  Subprocesses a test starts keep
NUMBA_NUM_THREADS, and a test may still set more threads for itself (numba.set_num_threads).
"""

import os

import numba


def pytest_configure(config):
    workers = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1"))
    if workers > 1:
        numba.set_num_threads(max(1, numba.config.NUMBA_NUM_THREADS // workers))
