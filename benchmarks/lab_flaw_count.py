"""The laboratory impact's head-on r-z proxy against resolution, with the flaw count of the
Grady-Kipp fracture model tied to the mesh (N ln N, the default) or fixed.

Writes configs from configs/lab/basalt_sphere_nylon_headon_rz.yaml (flaws of Weibull k 5e34
m^-3, m 8.5; snapshots at 2, 4, 6, 8, 10, 15 us; to 20 us) at each ``--cells`` per projectile
radius and for each variant, runs their hydro stage and prints, per run, the mass fraction of
the target in fragments and the largest fragment (cells with D < 0.5) at 10 and 20 us, and
the strain of the body's strongest flaw as a stress, E eps_n = E (n_tot / (k V))^(1/m)
(docs/validation.md, "The laboratory impact against resolution").  Variants:

- ``default``: n_tot = N ln N flaws over the N cells the target fills, active-flaw limit on;
- ``fixed``: ``flaw_count: 100000`` at every resolution;
- ``nolimit``: N ln N flaws, ``active_flaw_limit: false``.

    python benchmarks/lab_flaw_count.py --cells 2 4 8 --variants default fixed --out runs/lab_flaw_count

Each run takes seconds (2 cells) to about ten minutes (16 cells) on one core.
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
from pathlib import Path

import yaml

from impactpipe.hydro.output.io import read_snapshot
from impactpipe.hydro.strength.flaws import default_flaw_count

ROOT = Path(__file__).resolve().parent.parent
PROXY = ROOT / "configs" / "lab" / "basalt_sphere_nylon_headon_rz.yaml"
OUTPUT_TIMES = [2e-6, 4e-6, 6e-6, 8e-6, 1e-5, 1.5e-5]
VARIANTS = {"default": {}, "fixed": {"flaw_count": 100000}, "nolimit": {"active_flaw_limit": False}}
READ_TIMES = (1e-5, 2e-5)
MAX_DAMAGE = 0.5


def proxy_config(name: str, cells: int, extra: dict, out: Path) -> dict:
    """The head-on proxy at ``cells`` per projectile radius with the flaws of k 5e34 m^-3 and
    the damage keys ``extra``."""
    config = yaml.safe_load(PROXY.read_text())
    config["name"] = name
    config["output"] = str(out / name)
    config["hydro"]["cells_per_projectile_radius"] = cells
    config["hydro"]["output_times"] = list(OUTPUT_TIMES)
    damage = {"model": "grady_kipp", "preset": "basalt", "weibull_k": 5.0e34}
    damage.update(extra)
    config["materials"]["basalt"]["strength"]["damage"] = damage
    return config


def fragments(run_dir: Path, time: float) -> tuple[float, float]:
    """(mass fraction in fragments, largest fragment) of the target at ``time`` (s), cells with
    D < MAX_DAMAGE (`impactpipe fragments`)."""
    out = subprocess.run([sys.executable, "-m", "impactpipe.pipeline.cli", "fragments", str(run_dir), "--time",
                          str(time), "--max-damage", str(MAX_DAMAGE), "--top", "1"],
                         capture_output=True, text=True, check=True).stdout.splitlines()
    head = out[0]
    share = float(head.split("kg, ")[1].split()[0])
    largest = float(out[2].split()[1]) if len(out) > 2 and out[2].split()[0] == "1" else 0.0
    return share, largest


def strongest_flaw_stress(run_dir: Path) -> float:
    """E eps_n (Pa) of the body's strongest flaw, eps_n = (n_tot / (k V))^(1/m): V the basalt's
    volume and N the cells it fills in the t = 0 snapshot, n_tot the config's ``flaw_count`` or
    N ln N (:func:`~impactpipe.hydro.strength.flaws.default_flaw_count`), k, m and E the run's."""
    damage = yaml.safe_load((run_dir / "config.resolved.yaml").read_text())["materials"]["basalt"]["strength"]["damage"]
    start = read_snapshot(run_dir / "hydro.h5", 0)
    k = start.material_names.index("basalt")
    fill = start.volume_fraction[:, k]
    held = (fill > 0.0) & (start.partial_density[:, k] > 0.0)
    volume = float((fill * start.block_cell_volumes())[held].sum())
    count = damage.get("flaw_count") or default_flaw_count(int(held.sum()))
    return damage["young_modulus"] * (count / (damage["weibull_k"] * volume)) ** (1.0 / damage["weibull_m"])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[2, 4, 8])
    parser.add_argument("--variants", nargs="+", choices=sorted(VARIANTS), default=["default", "fixed"])
    parser.add_argument("--out", type=Path, default=Path("runs/lab_flaw_count"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    print("variant   cells  E eps_n (MPa)  10 us: in fragments / largest  20 us: in fragments / largest")
    for variant in args.variants:
        for cells in args.cells:
            name = f"{variant}_c{cells}"
            path = args.out / f"{name}.yaml"
            path.write_text(yaml.safe_dump(proxy_config(name, cells, VARIANTS[variant], args.out), sort_keys=False))
            subprocess.run([sys.executable, "-m", "impactpipe.pipeline.cli", "run", str(path), "--stage", "hydro",
                            "--force", "-q"], check=True)
            run_dir = args.out / name
            cols = [f"{share:.3f} / {largest:.3f}" for share, largest in (fragments(run_dir, t) for t in READ_TIMES)]
            print(f"{variant:9s} {cells:5d}  {strongest_flaw_stress(run_dir) / 1e6:13.1f}  {cols[0]:>29s}  {cols[1]:>29s}",
                  flush=True)


if __name__ == "__main__":
    main()
