"""A porous slab moving onto a reflecting wall (1d-planar): the verification scene of the porous
Hugoniot and of the porous elastic wave speed.

The slab of ``length`` (m) fills [0, length) at its bulk density rho_00 = rho_s0 / alpha0 with
e = 0 and moves at -``speed`` (m/s) onto the reflecting wall at x = 0; void fills
[length, 1.25 length) up to an outflow end.  The wall stops the material: a wave runs back into
the slab and leaves it at rest, a steady shock for a strong impact (its state on the porous
Hugoniot, :func:`impactpipe.hydro.exact.porous_hugoniot`) and, below the elastic limit eps_e of
a material with chi < 1, a weak pulse at the porous wave speed chi c_s0 (Collins, Melosh &
Wuennemann 2011) with the acoustic plateau pressure rho_00 chi c_s0 u.

Not a config scene (it is not in :data:`impactpipe.hydro.problems.PROBLEMS`): tests and
benchmarks build it from a material spec.
"""

from __future__ import annotations

import numpy as np

from impactpipe.hydro.eos import pack_eos
from impactpipe.hydro.mesh.blocks import BlockMesh
from impactpipe.hydro.mesh.state import HydroState
from impactpipe.hydro.solver import Simulation


def setup(spec: dict, speed: float, cells: int, length: float = 1.0, cfl: float = 0.4,
          name: str = "porous_basalt") -> Simulation:
    """The slab of material ``name`` (``spec``: an EOS spec with a ``porosity`` block) at -``speed``
    (m/s), ``cells`` cells across its ``length`` (m)."""
    alpha0 = spec["porosity"]["alpha0"]
    mesh = BlockMesh.uniform("1d-planar", [0.0], [1.25 * length], [cells * 5 // 4], [("reflecting", "outflow")])
    state = HydroState.empty(mesh, 1)
    x = mesh.cell_centers()[:, 0]
    state.set_material(mesh, (x < length).astype(float), 0, pack_eos([spec]), spec["rho0"] / alpha0,
                       np.array([-speed, 0.0, 0.0]), specific_energy=0.0)
    return Simulation(mesh, [name], [spec], state, cfl=cfl)


def wave_front(snapshot, speed: float, window: tuple[float, float] = (0.1, 0.5)) -> tuple[float, float]:
    """The wave's plateau pressure (Pa), the median over x in ``window`` (m), and its front's
    speed in the material's frame (m/s): x_front / t + u, x_front the farthest cell whose pressure
    exceeds half the plateau, t the snapshot's time."""
    xs = snapshot.centers[:, 0]
    pressure = snapshot.pressure.reshape(-1)
    plateau = float(np.median(pressure[(xs > window[0]) & (xs < window[1])]))
    front = xs[np.flatnonzero(pressure > 0.5 * plateau).max()]
    return plateau, float(front / snapshot.time + speed)
