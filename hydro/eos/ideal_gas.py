"""Ideal (polytropic) gas equation of state.

    P = (gamma - 1) rho e                       (Pa)
    c_K^2 = gamma (gamma - 1) e = gamma P / rho (m^2/s^2)
    T = e / c_v                                 (K)

Parameter row layout (``params[k]``, float64):

====  ========  ===========================================
slot  name      meaning
====  ========  ===========================================
0     gamma     ratio of specific heats (-), > 1
1     cv        specific heat at constant volume (J/kg/K)
====  ========  ===========================================
"""

from numba import njit

GAMMA = 0
CV = 1

#: Floor on the squared sound speed (m^2/s^2); reached only for e <= 0, which is not a
#: valid ideal-gas state, and keeps c_K^2 positive for the solver.
C2_FLOOR = 1.0e-12


@njit(cache=True)
def ideal_gas_pressure_sound_speed(params, rho, e):
    """Pressure P = (gamma - 1) rho e (Pa) and c_K^2 = gamma (gamma - 1) e (m^2/s^2).

    rho in kg/m^3, e in J/kg.  c_K^2 is floored at ``C2_FLOOR``.
    """
    gamma = params[GAMMA]
    p = (gamma - 1.0) * rho * e
    c2 = gamma * (gamma - 1.0) * e
    if c2 < C2_FLOOR:
        c2 = C2_FLOOR
    return p, c2


@njit(cache=True)
def ideal_gas_temperature(params, rho, e):
    """Temperature T = e / c_v (K) for e in J/kg."""
    return e / params[CV]


@njit(cache=True)
def ideal_gas_energy_from_pressure(params, rho, p):
    """Specific internal energy e = P / ((gamma - 1) rho) (J/kg) for P in Pa, rho in kg/m^3."""
    return p / ((params[GAMMA] - 1.0) * rho)
