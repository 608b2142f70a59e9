"""Progress reporting for long stages: a tqdm bar with ETA on a terminal, log lines otherwise.

Numba kernels cannot call tqdm, so stages advance in chunks from a Python loop and call
the reporter between chunks with the simulated time reached.  Before the first chunk of a
fresh install numba compiles the kernels for minutes; :func:`compile_notice` says so.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import threading
import time
from collections.abc import Iterator

from tqdm import tqdm

log = logging.getLogger(__name__)


class StageProgress:
    """Callable progress reporter for one stage: ``progress(t)`` with t the simulated time (s).

    ``total`` is the simulated time the stage will reach (or None when unknown).  On a
    terminal a tqdm bar shows the fraction done and the ETA; off a terminal (or with
    ``bar=False``) a log line is written at most every ``log_interval`` wall seconds.

    The rate behind the ETA is measured from the first call on, (t - t_1) / (wall - wall_1):
    a stage resumed from a checkpoint starts at t_1 > 0, and numba's compilation of the
    first chunk lies before that call, so neither makes the ETA too short.
    """

    def __init__(self, stage: str, total: float | None, bar: bool = True, log_interval: float = 30.0):
        self.stage = stage
        self.total = total
        self.log_interval = log_interval
        self._use_bar = bar and sys.stderr.isatty() and total is not None and total > 0
        self._bar = None
        self._first: tuple[float, float] | None = None  # (wall, t) at the first call
        self._last_log = time.monotonic()

    def __call__(self, t: float) -> None:
        now = time.monotonic()
        if self._first is None:
            self._first = (now, float(t))
            if self._use_bar:
                self._bar = tqdm(total=float(self.total), initial=min(float(t), float(self.total)), desc=self.stage,
                                 unit="s(sim)", leave=False, dynamic_ncols=True,
                                 bar_format="{desc}: {percentage:3.0f}%|{bar}| t={n:.4g}/{total:.4g} s "
                                            "[{elapsed}<{remaining}]")
        if self._bar is not None:
            self._bar.n = min(float(t), self._bar.total)
            self._bar.refresh()
            return
        if now - self._last_log >= self.log_interval:
            self._last_log = now
            if self.total:
                log.info("%s: t = %.4g / %.4g s (%.0f%%), ETA %.0f s", self.stage, t, self.total,
                         100 * min(t / self.total, 1.0), self.eta(t, now))
            else:
                log.info("%s: t = %.4g s", self.stage, t)

    def eta(self, t: float, now: float) -> float:
        """Wall seconds left (s) at simulated time ``t`` and monotonic wall time ``now``, at the rate
        since the first call; NaN before any progress."""
        wall0, t0 = self._first
        if self.total is None or t <= t0:
            return float("nan")
        return (now - wall0) * max(self.total - t, 0.0) / (t - t0)

    def close(self) -> None:
        """Remove the bar from the terminal."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None


#: What the console shows when numba starts compiling a kernel that is not in its cache.
COMPILE_MESSAGE = "compiling numerical kernels (first run only, about 2 minutes)"


@contextlib.contextmanager
def compile_notice() -> Iterator[None]:
    """While the block runs, the first compilation numba starts in this thread logs
    :data:`COMPILE_MESSAGE`, and the block's end logs the wall time the compilations took.

    Numba signals a compilation (event ``numba:compile``) only for a kernel that its cache
    cannot supply (a fresh install, changed source, new argument types), never for one
    loaded from the cache, so a warm install shows nothing.
    """
    from numba.core import event

    class Notice(event.Listener):
        thread = threading.get_ident()
        depth = 0
        started = 0.0
        seconds = 0.0
        count = 0

        def on_start(self, ev: event.Event) -> None:
            if threading.get_ident() != self.thread:
                return
            if self.depth == 0:
                if self.count == 0:
                    log.info(COMPILE_MESSAGE)
                self.started = time.perf_counter()
            self.depth += 1
            self.count += 1

        def on_end(self, ev: event.Event) -> None:
            if threading.get_ident() != self.thread:
                return
            self.depth -= 1
            if self.depth == 0:
                self.seconds += time.perf_counter() - self.started

    notice = Notice()
    with event.install_listener("numba:compile", notice):
        yield
    if notice.count:
        log.info("numerical kernels compiled in %.0f s", notice.seconds)
