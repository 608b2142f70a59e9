"""Exact shock states of a porous material (the epsilon-alpha model of
:mod:`impactpipe.hydro.eos.porosity`) for verifying the hydro stage.

Both solutions take a resolved EOS spec with a ``porosity`` block and the material initially at
rest at its bulk density rho_00 = rho_s0 / alpha_0 (V_00 = alpha_0 / rho_s0), e = 0, P = 0.
Along the monotone compression of a steady wave the distension is the compaction curve's value
at the final strain eps_v = ln(V / V_00), so the porous material's Hugoniot is that of the
state function P(V, e) = P_s(alpha(eps_v) / V, e) / alpha(eps_v); above the crush strain
(alpha = 1) it is the Hugoniot of the solid EOS centred on V_00.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.optimize import brentq

from impactpipe.hydro.eos import pack_eos, pressure_sound_speed
from impactpipe.hydro.eos.porosity import distension_of_strain, pack_porosity


def _porous_pressure(spec: dict):
    """(P(V, e) of the compacted porous material (Pa; V m^3/kg, e J/kg), V_00, the parameter row)."""
    eos = pack_eos([spec])
    row = pack_porosity([spec], eos)[0]
    v00 = float(spec["porosity"]["alpha0"]) / float(spec["rho0"])

    def pressure(v, e):
        alpha = distension_of_strain(row, math.log(v / v00))
        return pressure_sound_speed(eos.kind[0], eos.params[0], eos.table, alpha / v, e)[0] / alpha

    return pressure, v00, row


def _largest_root(f, v_start, v_stop, samples):
    """The largest V in (v_stop, v_start) where ``f`` turns from negative to positive (brentq)."""
    volumes = np.linspace(v_start, v_stop, samples)
    signs = np.sign([f(v) for v in volumes])
    first = int(np.flatnonzero(signs > 0)[0])
    return brentq(f, volumes[first], volumes[first - 1], rtol=1e-14)


def porous_hugoniot(spec: dict, particle_velocity: float) -> tuple[float, float, float]:
    """(P (Pa), rho (kg/m^3), alpha (-)) behind a steady shock of particle velocity u_p (m/s).

    Rankine-Hugoniot from rest: e = u_p^2 / 2 and P (V_00 - V) = u_p^2, with P = P(V, e) of the
    module docstring, solved for V (the first crossing of the Rayleigh line below V_00).
    """
    pressure, v00, row = _porous_pressure(spec)
    e = 0.5 * particle_velocity ** 2
    v = _largest_root(lambda v: pressure(v, e) * (v00 - v) - particle_velocity ** 2, v00 * (1.0 - 1e-9),
                      0.2 * v00, 4000)
    alpha = distension_of_strain(row, math.log(v / v00))
    return pressure(v, e), 1.0 / v, alpha


def two_wave_speeds(spec: dict, particle_velocity: float) -> tuple[float, float, float, float]:
    """(U_1, U_2 (m/s), P_1, P_2 (Pa)): the elastic precursor and the compaction wave driven by a
    piston at ``particle_velocity`` (m/s), speeds in the material's initial frame.

    The precursor compresses the material at frozen distension alpha_0 to the elastic strain eps_e
    (V_1 = V_00 exp(eps_e)); e_1 = P_1 (V_00 - V_1) / 2 with P_1 = P_s(alpha_0 / V_1, e_1) / alpha_0
    gives its mass flux j_1 = sqrt(P_1 / (V_00 - V_1)), speed U_1 = j_1 V_00 and particle velocity
    u_1 = j_1 (V_00 - V_1).  The compaction wave takes state 1 to the piston's u_2:
    (u_2 - u_1)^2 = (P_2 - P_1) (V_1 - V_2), e_2 = e_1 + (P_1 + P_2) (V_1 - V_2) / 2 and P_2 = P(V_2, e_2),
    solved for V_2 (the first crossing of the Rayleigh line below V_1); U_2 = u_1 + j_2 V_1 with
    j_2 = (u_2 - u_1) / (V_1 - V_2).  Two waves run apart when U_2 < U_1.
    """
    pressure, v00, _ = _porous_pressure(spec)
    v1 = v00 * math.exp(float(spec["porosity"]["eps_e"]))
    e1 = brentq(lambda e: e - 0.5 * pressure(v1, e) * (v00 - v1), 0.0, 1.0e6, rtol=1e-14)
    p1 = pressure(v1, e1)
    j1 = math.sqrt(p1 / (v00 - v1))
    u1 = j1 * (v00 - v1)
    du = particle_velocity - u1

    def rayleigh(v2):
        p2 = p1 + du ** 2 / (v1 - v2)
        return p2, e1 + 0.5 * (p1 + p2) * (v1 - v2)

    v2 = _largest_root(lambda v: pressure(v, rayleigh(v)[1]) - rayleigh(v)[0], v1 * (1.0 - 1e-6), 0.3 * v1, 3000)
    return j1 * v00, u1 + du / (v1 - v2) * v1, p1, rayleigh(v2)[0]
