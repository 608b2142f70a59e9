"""Tracer cost on the reference impact (case 8c): `python benchmarks/tracer_cost_reference.py`.

Runs 150 hydro steps from t = 0 (after 5 warm-up steps) without tracers and with 9990
tracers on the 2d-cylindrical ray layout, alternating twice, and prints each wall time and
the overhead min(with) / min(without) - 1.  Issue goal: 1e4 tracers add under 10 %.
"""

import time
from pathlib import Path

from impactpipe.pipeline.adapters.hydro import add_tracers, build_simulation
from impactpipe.pipeline import derived
from impactpipe.pipeline.config import load_config

CONFIG = Path(__file__).resolve().parent.parent / "configs" / "reference" / "case8c.yaml"
TRACERS = 9990  # a multiple of the layout's 30 rays
WARMUP_STEPS = 5
TIMED_STEPS = 150


def timed_run(config, values, tracers: int) -> float:
    """Wall time (s) of TIMED_STEPS steps of a fresh case 8c simulation with ``tracers`` tracers."""
    sim = build_simulation(config, values)
    if tracers:
        config.hydro.tracers.count = tracers
        add_tracers(sim, config, values["end_time"])
    for _ in range(WARMUP_STEPS):
        sim.step()
    start = time.perf_counter()
    for _ in range(TIMED_STEPS):
        sim.step()
    return time.perf_counter() - start


def main() -> None:
    config = load_config(CONFIG)
    values = derived.derive(config)
    bare, traced = [], []
    for _ in range(2):
        bare.append(timed_run(config, values, 0))
        traced.append(timed_run(config, values, TRACERS))
        print(f"bare {bare[-1]:.2f} s, {TRACERS} tracers {traced[-1]:.2f} s", flush=True)
    print(f"tracer overhead: {min(traced) / min(bare) - 1:.3f}")


if __name__ == "__main__":
    main()
