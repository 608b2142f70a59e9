"""Several MPI ranks for one run: launching them, and what rank 0 tells the others.

``impactpipe run CONFIG --ranks N`` starts ``mpiexec -n N python -m impactpipe.pipeline.cli
run CONFIG ...`` (:func:`launch`).  Under ``mpiexec`` (:func:`join_world`) rank 0 runs the
pipeline as a single process would: the run store, its lock, the logs, every stage other
than hydro and all files.  The other ranks only take part in the hydro stage: they wait for
rank 0's order (:func:`wait_for_order`, sleeping rather than polling), receive their blocks of
rank 0's simulation, advance them, and exit after the hydro stage; an order of None (the
hydro stage does not run, or rank 0 stopped before it) lets them exit at once.

A sweep runs each of its points this way too (``execution.ranks_per_run``,
:func:`impactpipe.pipeline.sweep.run_point`), with ``mpiexec`` or Slurm's ``srun`` as the
launcher (:func:`launch_command`); rank 0 stops the run when the process that launched the
ranks is gone (:func:`watch_launching_process`).
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import signal
import socket
import subprocess
import sys
import sysconfig
import threading
import time
from pathlib import Path
from typing import Any


from .lock import process_alive

#: Environment variables that MPI launchers set in the processes they start (MPICH / Hydra and
#: Slurm's PMI, Open MPI, PMIx); without any of them mpi4py is not imported at all.
LAUNCHER_VARIABLES = ("PMI_SIZE", "PMI_RANK", "OMPI_COMM_WORLD_SIZE", "PMIX_RANK")
INSTALL_HINT = 'pip install "impactpipe[mpi]"'
#: Exit statuses of the pipeline itself (done, failed, bad input, stopped by a signal); any other
#: status of ``mpiexec`` means a rank died under it.
PIPELINE_STATUSES = (0, 1, 2, 130)
#: Seconds between the checks of a rank waiting for rank 0's order.
ORDER_POLL = 0.05
#: Set by :func:`rank_environment` to ``HOST PID`` of the process that starts the ranks: rank 0
#: stops the run once that process is gone (:func:`watch_launching_process`).
LAUNCHED_BY_VARIABLE = "IMPACTPIPE_LAUNCHED_BY"
#: Seconds between rank 0's checks that the process that launched the ranks is alive.
LAUNCHER_POLL = 0.5

_world: dict[str, Any] = {"comm": None, "ordered": False}


class RanksUnavailable(RuntimeError):
    """Several ranks were asked for but mpi4py or ``mpiexec`` is missing."""


def mpi_installed() -> bool:
    """Whether mpi4py can be imported (the ``mpi`` extra is installed)."""
    return importlib.util.find_spec("mpi4py") is not None


def mpiexec_path() -> str:
    """The ``mpiexec`` beside this Python (the mpich wheel installs it there), else the one on PATH."""
    beside = Path(sysconfig.get_path("scripts")) / "mpiexec"
    if beside.is_file():
        return str(beside)
    found = shutil.which("mpiexec")
    if found is None:
        raise RanksUnavailable(f"no mpiexec found beside {sys.executable} or on PATH ({INSTALL_HINT} brings one)")
    return found


def launcher_path(launcher: str) -> str:
    """The program of ``launcher``, ``mpiexec`` (:func:`mpiexec_path`) or ``srun`` (on PATH)."""
    if launcher == "mpiexec":
        return mpiexec_path()
    found = shutil.which(launcher)
    if found is None:
        raise RanksUnavailable(f"no {launcher} on PATH (srun comes with Slurm)")
    return found


def launch_command(nranks: int, arguments: list[str], launcher: str = "mpiexec", threads: int | None = None,
                   options: list[str] | tuple[str, ...] = ()) -> list[str]:
    """``mpiexec -n N <this python> -m impactpipe.pipeline.cli <arguments>``, or with ``launcher``
    ``srun``: ``srun -n N --cpus-per-task=<threads> ...`` (each rank's numba threads; left out
    when ``threads`` is None).  ``options`` go after ``-n N`` (``--mpi=pmix``, a host file)."""
    if not mpi_installed():
        raise RanksUnavailable(f"{nranks} ranks need mpi4py and an MPI library: {INSTALL_HINT}")
    command = [launcher_path(launcher), "-n", str(nranks)]
    if launcher == "srun" and threads is not None:
        command.append(f"--cpus-per-task={threads}")
    return [*command, *options, sys.executable, "-m", "impactpipe.pipeline.cli", *arguments]


def rank_environment(nranks: int, threads: int | None = None) -> dict[str, str]:
    """This process's environment for the ranks it starts: ``NUMBA_NUM_THREADS`` = ``threads``, or
    when None cores / ranks (at least 1) unless it is set, and :data:`LAUNCHED_BY_VARIABLE`."""
    env = dict(os.environ)
    if threads is None:
        env.setdefault("NUMBA_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // nranks)))
    else:
        env["NUMBA_NUM_THREADS"] = str(threads)
    env[LAUNCHED_BY_VARIABLE] = f"{socket.gethostname()} {os.getpid()}"
    return env


def launch(nranks: int, arguments: list[str]) -> int:
    """Run ``arguments`` of the command line on ``nranks`` MPI ranks; returns the exit status.

    Each rank gets ``NUMBA_NUM_THREADS`` = cores / ranks (at least 1) unless it is set.  While
    ``mpiexec`` runs, Ctrl-C reaches it from the terminal (this process ignores it) and a
    SIGTERM sent to this process is passed on, so rank 0 stops the run at the end of a step;
    so it does when this process is killed (:func:`watch_launching_process`).
    """
    process = subprocess.Popen(launch_command(nranks, arguments), env=rank_environment(nranks))
    previous = {signal.SIGINT: signal.signal(signal.SIGINT, signal.SIG_IGN),
                signal.SIGTERM: signal.signal(signal.SIGTERM, lambda signum, frame: process.send_signal(signum))}
    try:
        return process.wait()
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)


def watch_launching_process() -> None:
    """Rank 0 of ranks started by impactpipe (:func:`rank_environment`): stop the run once the
    process that launched them is gone (a sweep's worker that was killed), as a SIGTERM would:
    the hydro stage ends its step and keeps its checkpoint.  Does nothing without
    :data:`LAUNCHED_BY_VARIABLE`; a launching process on another host cannot be watched."""
    recorded = os.environ.get(LAUNCHED_BY_VARIABLE)
    if not recorded:
        return
    host, pid = recorded.rsplit(" ", 1)
    threading.Thread(target=_stop_when_gone, args=(host, int(pid)), name="watch-launcher", daemon=True).start()


def _stop_when_gone(host: str, pid: int) -> None:
    """Sleep while process ``pid`` on ``host`` runs, then SIGTERM this process (once)."""
    while process_alive(host, pid):
        time.sleep(LAUNCHER_POLL)
    sys.stderr.write(f"the process {pid} that launched the ranks is gone; stopping the run\n")
    sys.stderr.flush()
    os.kill(os.getpid(), signal.SIGTERM)


def join_world():
    """The world communicator when this process is one of several MPI ranks, else None."""
    if not any(name in os.environ for name in LAUNCHER_VARIABLES) or not mpi_installed():
        return None
    from mpi4py import MPI

    comm = MPI.COMM_WORLD
    _world["comm"] = comm if comm.size > 1 else None
    return _world["comm"]


def world():
    """The communicator :func:`join_world` found (None for a single process)."""
    return _world["comm"]


def send_order(order: dict | None) -> None:
    """Rank 0: tell the other ranks what to do (the hydro stage's order, or None: exit)."""
    comm = _world["comm"]
    if comm is None or _world["ordered"]:
        return
    _world["ordered"] = True
    comm.Ibarrier().Wait()  # matches the others' Ibarrier (a blocking Barrier would not)
    comm.bcast(order, root=0)


def abort(comm, reason: str) -> None:
    """End every rank of ``comm`` at once, exit status 1: one rank failed where the others wait
    for it (mpiexec does not end them when one rank exits with an error)."""
    sys.stderr.write(f"rank {comm.rank}: {reason}; ending every MPI rank\n")
    sys.stderr.flush()
    comm.Abort(1)


def release() -> None:
    """Rank 0 at the end of the run: let ranks still waiting for an order exit."""
    send_order(None)


def wait_for_order(comm) -> dict | None:
    """Ranks other than 0: sleep until rank 0 sends its order, then return it."""
    request = comm.Ibarrier()
    while not request.Test():
        time.sleep(ORDER_POLL)
    return comm.bcast(None, root=0)
