"""The run directory's log: the records of one run appended to ``RUN_DIR/run.log``.

The file primitives (atomic writes, datasets with units, provenance) are in
:mod:`impactpipe.storage`.
"""

from __future__ import annotations

import contextlib
import logging
import os
import threading
from collections.abc import Iterator

RUN_LOG = "run.log"


@contextlib.contextmanager
def run_log(run_dir: str | os.PathLike) -> Iterator[None]:
    """Append the ``impactpipe`` log records of the calling thread, INFO and above, to
    ``RUN_DIR/run.log`` while the block runs (the file opens at the first record).

    Only the calling thread's records go to the file, so runs in threads of one process (a
    Dask worker with several threads) keep separate logs.  The package logger is lowered to
    INFO if it is set higher, and left there (runs in other threads may still be logging), so
    a quiet console still leaves a full log: console handlers filter by their own level
    (``impactpipe.pipeline.cli`` sets it).  A nested call for the same file adds nothing.
    """
    package = logging.getLogger("impactpipe")
    path = os.path.abspath(os.path.join(run_dir, RUN_LOG))
    if any(isinstance(h, logging.FileHandler) and h.baseFilename == path for h in package.handlers):
        yield
        return
    os.makedirs(run_dir, exist_ok=True)
    handler = logging.FileHandler(path, delay=True)
    handler.setLevel(logging.INFO)
    handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(name)s: %(message)s"))
    thread = threading.get_ident()
    handler.addFilter(lambda record: record.thread == thread)
    if package.level == logging.NOTSET or package.level > logging.INFO:
        package.setLevel(logging.INFO)
    package.addHandler(handler)
    try:
        yield
    finally:
        package.removeHandler(handler)
        handler.close()
