"""ROCK-model shear damage: the strain to failure and its pressure dependence.

Shear damage grows with the equivalent plastic strain increment d eps_p (-):

    dD_s = d eps_p / eps_f(P)

with the failure strain eps_f(P) (Pa for P):

    eps_f = FAILURE_STRAIN_BRITTLE                                 P <= P_bd (brittle)
    eps_f = FAILURE_STRAIN_BRITTLE + (FAILURE_STRAIN_DUCTILE - FAILURE_STRAIN_BRITTLE)
            (P - P_bd) / (P_bp - P_bd)                             P_bd < P < P_bp (semi-brittle)
    no shear damage (eps_f infinite)                               P >= P_bp (plastic)

the brittle-ductile (P_bd) and brittle-plastic (P_bp) transition pressures of the ROCK
presets.  Tensile damage is complete (D = 1) at tensile failure
(:mod:`impactpipe.hydro.strength.update`).  Total damage D = D_s + D_t is capped at 1.
"""

from __future__ import annotations

from numba import njit

#: Failure strain in the brittle regime (P <= P_bd).
FAILURE_STRAIN_BRITTLE = 1.0e-4
#: Failure strain reached at the brittle-plastic transition P_bp.
FAILURE_STRAIN_DUCTILE = 0.1


@njit(cache=True, inline="always")
def failure_strain(pressure, p_bd, p_bp):
    """Equivalent plastic strain to shear failure eps_f(P) (-); 0 means no shear damage (P >= P_bp)."""
    if pressure <= p_bd:
        return FAILURE_STRAIN_BRITTLE
    if pressure >= p_bp:
        return 0.0
    frac = (pressure - p_bd) / (p_bp - p_bd)
    return FAILURE_STRAIN_BRITTLE + (FAILURE_STRAIN_DUCTILE - FAILURE_STRAIN_BRITTLE) * frac


@njit(cache=True, inline="always")
def shear_damage_increment(plastic_strain_increment, pressure, p_bd, p_bp):
    """Shear damage increment d eps_p / eps_f(P) (-), 0 above the brittle-plastic transition."""
    eps_f = failure_strain(pressure, p_bd, p_bp)
    if eps_f <= 0.0:
        return 0.0
    return plastic_strain_increment / eps_f
