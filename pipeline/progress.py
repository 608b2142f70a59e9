"""Progress reporting for long stages: a tqdm bar with ETA on a terminal, log lines otherwise.

Numba kernels cannot call tqdm, so stages advance in chunks from a Python loop and call
the reporter between chunks with the simulated time reached.
"""

from __future__ import annotations

import logging
import sys
import time

from tqdm import tqdm

log = logging.getLogger(__name__)


class StageProgress:
    """Callable progress reporter for one stage: ``progress(t)`` with t the simulated time (s).

    ``total`` is the simulated time the stage will reach (or None when unknown).  On a
    terminal a tqdm bar shows the fraction done and the ETA; off a terminal (or with
    ``bar=False``) a log line is written at most every ``log_interval`` wall seconds.
    """

    def __init__(self, stage: str, total: float | None, bar: bool = True, log_interval: float = 30.0):
        self.stage = stage
        self.total = total
        self.log_interval = log_interval
        self._last_log = time.monotonic()
        self._start = self._last_log
        use_bar = bar and sys.stderr.isatty() and total is not None and total > 0
        self._bar = (
            tqdm(total=float(total), desc=stage, unit="s(sim)", leave=False, dynamic_ncols=True,
                 bar_format="{desc}: {percentage:3.0f}%|{bar}| t={n:.4g}/{total:.4g} s [{elapsed}<{remaining}]")
            if use_bar else None
        )

    def __call__(self, t: float) -> None:
        if self._bar is not None:
            self._bar.n = min(float(t), self._bar.total)
            self._bar.refresh()
            return
        now = time.monotonic()
        if now - self._last_log >= self.log_interval:
            self._last_log = now
            if self.total:
                frac = min(t / self.total, 1.0)
                eta = (now - self._start) * (1.0 - frac) / frac if frac > 0 else float("nan")
                log.info("%s: t = %.4g / %.4g s (%.0f%%), ETA %.0f s", self.stage, t, self.total, 100 * frac, eta)
            else:
                log.info("%s: t = %.4g s", self.stage, t)

    def close(self) -> None:
        """Remove the bar from the terminal."""
        if self._bar is not None:
            self._bar.close()
            self._bar = None
