"""Richardson over hydro resolutions, pooling every hand-off of each resolution's hydro run.

Each argument CELLS=DIR names a directory written by ``impactpipe convergence`` whose runs
all hand off one hydro run at CELLS cells per projectile radius (a
``handoff.particle_resolution`` ladder with ``--seeds`` and ``--reuse-hydro`` of that run).
Every finished run's M_lr/M_T (``runs/*/summary.json``) is one sample of its resolution,
whatever its particle size (docs/accuracy.md: particles of 10-40 cells per R_P agree within
their standard errors), unless ``--particle-resolution`` keeps only some.  Prints per
resolution the number of hand-offs, their mean and its standard error, then the Richardson
estimate over the three finest resolutions and its uncertainty under those standard errors
(:func:`impactpipe.pipeline.convergence.richardson_uncertainty`):

    python benchmarks/pooled_richardson.py 20=DIR20 40=DIR40 80=DIR80 [--tolerance 0.05] \
        [--particle-resolution 10,20]
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np
import yaml

from impactpipe.pipeline.convergence import richardson, richardson_uncertainty, uncertainty_text


def handoff_samples(directory: Path, particle_resolutions: set[float] | None) -> list[float]:
    """M_lr/M_T of every finished run under ``directory/runs`` (optionally of some particle sizes only)."""
    samples = []
    for summary_path in sorted((directory / "runs").glob("*/summary.json")):
        value = json.loads(summary_path.read_text()).get("M_lr_over_M_T")
        if value is None or not math.isfinite(value):
            continue
        if particle_resolutions is not None:
            config = yaml.safe_load((summary_path.parent / "config.resolved.yaml").read_text())
            if float(config["handoff"].get("particle_resolution") or math.nan) not in particle_resolutions:
                continue
        samples.append(float(value))
    return samples


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("rungs", nargs="+", metavar="CELLS=DIR")
    parser.add_argument("--tolerance", type=float, default=0.05)
    parser.add_argument("--particle-resolution", default=None, help="comma-separated particle resolutions to keep")
    args = parser.parse_args()
    keep = None if args.particle_resolution is None else {float(v) for v in args.particle_resolution.split(",")}
    cells, means, sems = [], [], []
    for text in args.rungs:
        value, _, directory = text.partition("=")
        samples = handoff_samples(Path(directory), keep)
        cells.append(float(value))
        means.append(float(np.mean(samples)))
        sems.append(float(np.std(samples, ddof=1) / math.sqrt(len(samples))))
        print(f"{value:>6} cells/R_P: {len(samples):3d} hand-offs, M_lr/M_T = {means[-1]:.4f} +- {sems[-1]:.4f}")
    h = 1.0 / np.array(cells)
    ext = richardson(h, np.array(means))
    print("Richardson:", f"{ext.value:.4f} (order {ext.order:.3g})" if ext.ok else ext.status)
    unc = richardson_uncertainty(h, np.array(means), np.array(sems), args.tolerance)
    if unc is not None:
        print(uncertainty_text("hydro.cells_per_projectile_radius", [f"{c:g}" for c in cells], unc, args.tolerance))


if __name__ == "__main__":
    main()
