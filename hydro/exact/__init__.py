"""Exact and reference solutions for verifying the hydro stage.

- ``riemann``: exact Riemann solver for the ideal gas (shocks, rarefactions, vacuum);
- ``sedov``: Sedov-Taylor point blast (planar, cylindrical, spherical);
- ``noh``: Noh implosion (planar, cylindrical, spherical);
- ``impedance``: Hugoniots of any dispatcher EOS and planar impedance matching;
- ``porous``: the Hugoniot and the two-wave (precursor, compaction) solution of a porous material;
- ``spherical_elastic``: a spherically symmetric elastic wave in a linear-elastic solid.
"""

from impactpipe.hydro.exact.impedance import (
    HugoniotState,
    ImpactState,
    hugoniot_from_particle_velocity,
    hugoniot_state,
    planar_impact_state,
)
from impactpipe.hydro.exact.noh import noh_shock_speed, noh_solution
from impactpipe.hydro.exact.porous import porous_hugoniot, two_wave_speeds
from impactpipe.hydro.exact.riemann import exact_riemann, riemann_star_state
from impactpipe.hydro.exact.sedov import SedovSolution, sedov_solution
from impactpipe.hydro.exact.spherical_elastic import SphericalWave, spherical_elastic_wave

__all__ = [
    "HugoniotState", "ImpactState", "hugoniot_from_particle_velocity", "hugoniot_state",
    "planar_impact_state", "noh_shock_speed", "noh_solution", "exact_riemann",
    "riemann_star_state", "SedovSolution", "sedov_solution", "porous_hugoniot", "two_wave_speeds",
    "SphericalWave", "spherical_elastic_wave",
]
