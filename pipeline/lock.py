"""One writer per run directory: an OS file lock on ``RUN_DIR/.lock``.

The lock is ``flock`` on the lock file, held for as long as a run (or a sweep point) writes
the directory.  The kernel frees it when its process dies, ``kill -9`` included, so a
lock is never stale; the file itself records the holder (host, pid, since when) so a
second writer can name it, and is emptied on a clean release.  A holder's record found
in a lock that is free belongs to a process that died holding it: it is taken over with
a notice.

The lock is re-entrant within one thread (a sweep point holds it around the adoption of
shared stages and the run that follows), and exclusive between threads and processes.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import logging
import os
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

from impactpipe import storage

log = logging.getLogger(__name__)

LOCK_FILE = ".lock"
#: Seconds between attempts of a waiting :func:`run_lock` and between its reminders.
WAIT_POLL = 0.2
WAIT_REMINDER = 60.0

_held = threading.local()


class RunDirError(RuntimeError):
    """A run directory cannot be written: another process holds it, or it is not writable."""


class RunLocked(RunDirError):
    """Another process (or thread) holds the run directory's lock; ``holder`` is its record."""

    def __init__(self, run_dir: Path, holder: dict):
        self.run_dir = run_dir
        self.holder = holder
        super().__init__(f"{run_dir} is in use by {describe(holder)}; wait for it to finish or stop it "
                         f"(one writer per run directory)")


def describe(holder: dict) -> str:
    """``process PID on HOST since TIME`` for a lock record (what is known of it)."""
    if not holder:
        return "another process (no record in its lock file yet)"
    return f"process {holder.get('pid', '?')} on {holder.get('host', '?')} since {holder.get('since', '?')}"


def _record() -> dict:
    return {"host": socket.gethostname(), "pid": os.getpid(), "since": storage.utc_now()}


def _read(fh) -> dict:
    fh.seek(0)
    text = fh.read()
    try:
        data = json.loads(text) if text.strip() else {}
    except json.JSONDecodeError:
        return {"unreadable": text[:200]}
    return data if isinstance(data, dict) else {}


def _open(run_dir: Path):
    """The lock file opened for reading and writing (the directory made if missing); an
    unwritable place raises RunDirError naming the directory."""
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(run_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as exc:
        if exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
            raise RunDirError(f"{run_dir}: cannot write there ({exc.strerror}); nothing was written") from None
        raise
    return os.fdopen(fd, "r+")


@contextlib.contextmanager
def run_lock(run_dir: str | os.PathLike, wait: bool = False, what: str = "") -> Iterator[None]:
    """Hold ``RUN_DIR/.lock`` while the block runs.

    Held elsewhere: raises :class:`RunLocked` at once, or with ``wait`` logs who holds it
    (``what`` names the waiter, e.g. a sweep point) and waits until it is free.  Not
    writable: raises :class:`RunDirError`.  Re-entered in the same thread, it does nothing.
    """
    run_dir = Path(run_dir)
    key = os.path.realpath(run_dir)
    held = _held.__dict__.setdefault("paths", set())
    if key in held:
        yield
        return
    fh = _open(run_dir)
    try:
        _acquire(fh, run_dir, wait, what)
        previous = _read(fh)
        if previous:
            log.warning("%s: taking over the lock of %s, which stopped without releasing it", run_dir,
                        describe(previous))
        fh.seek(0)
        fh.truncate()
        fh.write(json.dumps(_record()) + "\n")
        fh.flush()
        held.add(key)
        try:
            yield
        finally:
            held.discard(key)
            fh.seek(0)
            fh.truncate()
            fh.flush()
    finally:
        fh.close()  # closing the file releases the flock


def _acquire(fh, run_dir: Path, wait: bool, what: str) -> None:
    reminded = None
    while True:
        try:
            fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            return
        except BlockingIOError:
            holder = _read(fh)
        if not wait:
            raise RunLocked(run_dir, holder)
        now = time.monotonic()
        if reminded is None or now - reminded >= WAIT_REMINDER:
            log.warning("%s%s is in use by %s; waiting for it", f"{what}: " if what else "", run_dir,
                        describe(holder))
            reminded = now
        time.sleep(WAIT_POLL)


def recorded_holder(run_dir: str | os.PathLike) -> dict:
    """The holder recorded in ``RUN_DIR/.lock``: the process that holds the lock, or the last one
    that died holding it ({} when the lock was released cleanly or never taken)."""
    try:
        with open(Path(run_dir) / LOCK_FILE) as fh:
            return _read(fh)
    except FileNotFoundError:
        return {}


def process_alive(host: str | None, pid: int | None) -> bool:
    """Whether process ``pid`` on ``host`` may still run: False only when it is known to be gone
    (this host, no such process); another host's process cannot be checked and counts as alive."""
    if pid is None:
        return False
    if host not in (None, socket.gethostname()):
        return True
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
