"""Shock Hugoniots of any dispatcher EOS and the planar impedance-matching solution.

Hugoniot centred on the initial state (rho0, e0, P0 = P(rho0, e0)) of material at rest:
for a compressed density rho the shocked energy e solves the Rankine-Hugoniot energy
equation

    e - e0 = (P(rho, e) + P0) (1/rho0 - 1/rho) / 2

(a bracketed root find in e), and then

    u_p = sqrt((P - P0) (1/rho0 - 1/rho)),   U_s = u_p / (1 - rho0/rho)     (m/s).

Given u_p instead, the compression x = 1 - rho0/rho in (0, 1) with u_p(x) = u_p is found
by a second root find (u_p grows with x along the Hugoniot).

Planar impact of a flyer at ``velocity`` v on a target at rest: the shocked states on both
sides of the contact share pressure and particle velocity u (lab frame), so u solves

    P_target(u_p = u) = P_flyer(u_p = v - u),   0 < u < v.

EOS arguments are resolved spec dicts as taken by ``impactpipe.hydro.eos.pack_eos``.
"""

import math
from typing import NamedTuple

from scipy.optimize import brentq

from impactpipe.hydro.eos import pack_eos, pressure_sound_speed, reference_density

#: Relative tolerance of the root finds.
RTOL = 1.0e-13
#: Most bracket-expansion steps.
MAX_EXPANSIONS = 200


class HugoniotState(NamedTuple):
    """A shocked state, in the frame where the unshocked material is at rest (SI units)."""

    density: float
    energy: float
    pressure: float
    particle_velocity: float
    shock_velocity: float


class ImpactState(NamedTuple):
    """Planar impact solution.

    pressure (Pa) and particle_velocity (m/s, lab frame: the target's u_p and the contact
    speed) are common to both shocked states; ``target`` and ``flyer`` are the Hugoniot
    states of each material in its own initial rest frame (the flyer's u_p is v - u).
    """

    pressure: float
    particle_velocity: float
    target: HugoniotState
    flyer: HugoniotState


class _Material:
    """One packed material with its initial state (rho0, e0, P0)."""

    def __init__(self, spec, rho0, e0):
        eos = pack_eos([spec])
        self.kind = eos.kind[0]
        self.row = eos.params[0]
        self.table = eos.table
        if rho0 is None:
            rho0 = reference_density(self.kind, self.row, self.table)
            if rho0 <= 0.0:
                raise ValueError("this EOS has no reference density: give rho0")
        self.rho0 = float(rho0)
        self.e0 = float(e0)
        self.p0 = self.pressure(self.rho0, self.e0)

    def pressure(self, rho, e):
        return pressure_sound_speed(self.kind, self.row, self.table, rho, e)[0]

    def hugoniot_energy(self, rho):
        """Energy on the Hugoniot at rho (J/kg); NaN beyond the limiting compression."""
        dv = 1.0 / self.rho0 - 1.0 / rho

        def residual(e):
            return e - self.e0 - 0.5 * (self.pressure(rho, e) + self.p0) * dv

        e_lo = self.e0
        if residual(e_lo) >= 0.0:
            return e_lo
        step = abs(self.pressure(rho, self.e0) + self.p0) * dv + 1.0
        e_hi = e_lo + step
        for _ in range(MAX_EXPANSIONS):
            if residual(e_hi) > 0.0:
                return brentq(residual, e_lo, e_hi, xtol=1.0e-300, rtol=RTOL)
            e_lo = e_hi
            step *= 2.0
            e_hi = e_lo + step
        return math.nan

    def state_at_compression(self, x):
        """Hugoniot state at x = 1 - rho0/rho (NaN fields beyond the limiting compression)."""
        rho = self.rho0 / (1.0 - x)
        e = self.hugoniot_energy(rho)
        p = self.pressure(rho, e) if math.isfinite(e) else math.nan
        u_p = math.sqrt(max(p - self.p0, 0.0) * x / self.rho0) if math.isfinite(p) else math.nan
        return HugoniotState(rho, e, p, u_p, u_p / x if x > 0.0 else math.nan)

    def state_at_particle_velocity(self, u_p):
        if u_p == 0.0:
            return HugoniotState(self.rho0, self.e0, self.p0, 0.0, math.nan)

        def residual(x):
            u = self.state_at_compression(x).particle_velocity
            return (u if math.isfinite(u) else math.inf) - u_p

        x_hi = 0.5
        x_lo = 0.0
        for _ in range(MAX_EXPANSIONS):
            if residual(x_hi) > 0.0:
                break
            x_lo = x_hi
            x_hi = 1.0 - 0.5 * (1.0 - x_hi)
        else:
            raise ValueError(f"no Hugoniot state with u_p = {u_p} m/s")
        while not math.isfinite(self.state_at_compression(x_hi).particle_velocity):
            x_mid = 0.5 * (x_lo + x_hi)
            if residual(x_mid) > 0.0:
                x_hi = x_mid
            else:
                x_lo = x_mid
        x = brentq(residual, x_lo, x_hi, xtol=1.0e-300, rtol=RTOL)
        return self.state_at_compression(x)


def hugoniot_state(eos, density, rho0=None, e0=0.0):
    """Hugoniot state at ``density`` (kg/m^3) from the initial state (rho0, e0).

    rho0 defaults to the EOS reference density (required for an ideal gas), e0 to 0 J/kg;
    P0 = P(rho0, e0).  Raises ValueError beyond the limiting compression.
    """
    material = _Material(eos, rho0, e0)
    if density <= material.rho0:
        raise ValueError(f"density {density} must exceed rho0 = {material.rho0} for a shock")
    state = material.state_at_compression(1.0 - material.rho0 / density)
    if not math.isfinite(state.energy):
        raise ValueError(f"density {density} is beyond the limiting shock compression")
    return state


def hugoniot_from_particle_velocity(eos, particle_velocity, rho0=None, e0=0.0):
    """Hugoniot state with the given particle velocity u_p >= 0 (m/s); see ``hugoniot_state``."""
    if particle_velocity < 0.0:
        raise ValueError(f"particle velocity must be >= 0, got {particle_velocity}")
    return _Material(eos, rho0, e0).state_at_particle_velocity(float(particle_velocity))


def planar_impact_state(flyer_eos, target_eos, velocity):
    """Impedance-matching solution of a planar flyer at ``velocity`` (m/s) on a target at rest.

    Both materials start at their reference density with e = 0.
    """
    if velocity <= 0.0:
        raise ValueError(f"impact velocity must be > 0, got {velocity}")
    flyer = _Material(flyer_eos, None, 0.0)
    target = _Material(target_eos, None, 0.0)

    def mismatch(u):
        return (target.state_at_particle_velocity(u).pressure
                - flyer.state_at_particle_velocity(velocity - u).pressure)

    u = brentq(mismatch, 0.0, float(velocity), xtol=1.0e-300, rtol=RTOL)
    target_state = target.state_at_particle_velocity(u)
    flyer_state = flyer.state_at_particle_velocity(velocity - u)
    return ImpactState(pressure=target_state.pressure, particle_velocity=u,
                       target=target_state, flyer=flyer_state)
