"""Tabulated (SESAME-style) equation of state on a (rho, T) grid.

File format (text, whitespace separated, ``#`` starts a comment that runs to the end of
the line; line breaks between values are free except for the header):

1. header line: ``n_rho n_T rho_ref`` -- grid sizes (integers >= 2) and the reference
   (ambient) density in kg/m^3 returned by ``reference_density``;
2. density grid, n_rho values (kg/m^3), > 0 and strictly increasing;
3. temperature grid, n_T values (K), strictly increasing;
4. pressure block P(rho_i, T_j) (Pa), n_rho * n_T values, density-major (all n_T values of
   rho_0 first, then rho_1, ...);
5. energy block E(rho_i, T_j) (J/kg), same order, strictly increasing in T at each rho.

Evaluation at (rho, e): bilinear interpolation in (x = ln rho, T).  At fixed rho, E is
piecewise linear and increasing in T, so e -> T is inverted exactly by a bisection over
the temperature intervals followed by a linear solve.  With w, tau the fractional
positions in the (x, T) cell,

    P    = bilinear(P_ij; w, tau),   T = T_j + tau (T_{j+1} - T_j)
    dP/de|_rho   = P_tau / E_tau
    dP/drho|_e   = (P_w - P_tau E_w / E_tau) / (rho dx)
    c_K^2        = dP/drho|_e + (P / rho^2) dP/de|_rho,   floored at ``C2_FLOOR``

where P_w, P_tau, E_w, E_tau are the derivatives of the bilinear surfaces with respect to
w and tau (differences of the table values across the cell) and dx = x_{i+1} - x_i.
A density outside the grid, or an energy outside [E(rho, T_0), E(rho, T_last)], is clamped
to the table edge and reported with flag = 1.

Parameter row layout for a TABLE material (``params[k]``, float64):

====  ========  ===========================================================
slot  name      meaning
====  ========  ===========================================================
0     offset    index in the flat ``table`` array where this table starts
1     n_rho     number of densities
2     n_T       number of temperatures
3     rho_ref   reference density (kg/m^3)
====  ========  ===========================================================

Flat data from ``offset``: ln rho grid (n_rho), T grid (n_T), P (n_rho n_T), E (n_rho n_T).
"""

import dataclasses
import math
import os

import numpy as np
from numba import njit

OFFSET = 0
N_RHO = 1
N_T = 2
RHO_REF = 3

#: Floor on c_K^2 (m^2/s^2): c_K >= 1 m/s.
C2_FLOOR = 1.0


class EOSTableError(ValueError):
    """A malformed EOS table; ``str`` reads ``path:line: what is wrong``."""

    def __init__(self, path, line, what):
        self.path = str(path)
        self.line = line
        self.what = what
        super().__init__(f"{self.path}:{line}: {what}")


@dataclasses.dataclass(frozen=True)
class TabulatedEOS:
    """An EOS table read from a file: P and E on a (rho, T) grid (SI units)."""

    path: str
    rho_ref: float
    density: np.ndarray
    temperature: np.ndarray
    pressure: np.ndarray
    energy: np.ndarray

    def flat(self):
        """Flat float64 data as stored in ``EOSArrays.table``: ln rho, T, P, E."""
        return np.concatenate([np.log(self.density), self.temperature,
                               self.pressure.ravel(), self.energy.ravel()]).astype(np.float64)


def _tokens(path):
    """(value text, line number) for every whitespace-separated token, comments removed."""
    out = []
    with open(path, encoding="utf-8") as fh:
        for number, line in enumerate(fh, start=1):
            body = line.split("#", 1)[0]
            out.extend((tok, number) for tok in body.split())
    return out


def _float(path, tok, line, what):
    try:
        value = float(tok)
    except ValueError:
        raise EOSTableError(path, line, f"{what}: cannot read {tok!r} as a number") from None
    if not math.isfinite(value):
        raise EOSTableError(path, line, f"{what}: value {tok!r} is not finite")
    return value


def read_sesame_table(path):
    """Read and check a table file (format in the module docstring) -> ``TabulatedEOS``.

    Raises ``EOSTableError`` naming the file, the line and the fault: a bad header, a wrong
    number of values, a value that is not a finite number, a non-positive or non-increasing
    density grid, a non-increasing temperature grid, or E not strictly increasing in T.
    """
    path = os.fspath(path)
    tokens = _tokens(path)
    if not tokens:
        raise EOSTableError(path, 1, "empty table: expected a header 'n_rho n_T rho_ref'")
    header_line = tokens[0][1]
    header = [tok for tok, line in tokens if line == header_line]
    if len(header) != 3:
        raise EOSTableError(path, header_line,
                            f"header must hold 3 values 'n_rho n_T rho_ref', found {len(header)}")
    sizes = []
    for name, tok in zip(("n_rho", "n_T"), header[:2]):
        try:
            size = int(tok)
        except ValueError:
            raise EOSTableError(path, header_line,
                                f"header {name}: {tok!r} is not an integer") from None
        if size < 2:
            raise EOSTableError(path, header_line, f"header {name}: must be >= 2, got {size}")
        sizes.append(size)
    n_rho, n_t = sizes
    rho_ref = _float(path, header[2], header_line, "header rho_ref")
    if rho_ref <= 0.0:
        raise EOSTableError(path, header_line, f"header rho_ref: must be > 0, got {rho_ref}")

    body = tokens[3:]
    blocks = (("density grid", n_rho), ("temperature grid", n_t),
              ("pressure block", n_rho * n_t), ("energy block", n_rho * n_t))
    expected = sum(size for _, size in blocks)
    if len(body) < expected:
        start = 0
        for name, size in blocks:
            if len(body) < start + size:
                last_line = body[-1][1] if body else header_line
                raise EOSTableError(
                    path, last_line,
                    f"file ends inside the {name}: it holds {len(body) - start} of {size} "
                    f"values (n_rho={n_rho}, n_T={n_t})")
            start += size
    if len(body) > expected:
        tok, line = body[expected]
        raise EOSTableError(path, line,
                            f"unexpected value {tok!r} after the energy block "
                            f"(expected {expected} values for n_rho={n_rho}, n_T={n_t})")

    arrays = []
    lines = []
    start = 0
    for name, size in blocks:
        chunk = body[start:start + size]
        arrays.append(np.array([_float(path, tok, line, name) for tok, line in chunk]))
        lines.append([line for _, line in chunk])
        start += size
    density, temperature, pressure, energy = arrays

    if density[0] <= 0.0:
        raise EOSTableError(path, lines[0][0], f"density grid: must be > 0, got {density[0]}")
    for name, grid, grid_lines in (("density grid", density, lines[0]),
                                   ("temperature grid", temperature, lines[1])):
        for k in range(1, grid.size):
            if grid[k] <= grid[k - 1]:
                raise EOSTableError(path, grid_lines[k],
                                    f"{name} not strictly increasing: {grid[k]} after {grid[k - 1]}")
    pressure = pressure.reshape(n_rho, n_t)
    energy = energy.reshape(n_rho, n_t)
    for i in range(n_rho):
        for j in range(1, n_t):
            if energy[i, j] <= energy[i, j - 1]:
                raise EOSTableError(
                    path, lines[3][i * n_t + j],
                    f"energy block: E not strictly increasing in T at rho={density[i]} "
                    f"(index {i}): E={energy[i, j]} at T={temperature[j]} after "
                    f"E={energy[i, j - 1]} at T={temperature[j - 1]}")
    return TabulatedEOS(path=path, rho_ref=rho_ref, density=density, temperature=temperature,
                        pressure=pressure, energy=energy)


def write_sesame_table(path, density, temperature, pressure, energy, rho_ref, comment=""):
    """Write a table in the format read by ``read_sesame_table``.

    density (n_rho,) kg/m^3, temperature (n_T,) K, pressure and energy (n_rho, n_T) in Pa
    and J/kg, rho_ref kg/m^3; ``comment`` lines are written as ``#`` comments on top.
    """
    density = np.asarray(density, dtype=np.float64)
    temperature = np.asarray(temperature, dtype=np.float64)
    pressure = np.asarray(pressure, dtype=np.float64)
    energy = np.asarray(energy, dtype=np.float64)
    with open(path, "w", encoding="utf-8") as fh:
        for line in comment.splitlines():
            fh.write(f"# {line}\n")
        fh.write(f"{density.size} {temperature.size} {rho_ref!r}\n")
        fh.write("# density grid (kg/m^3)\n")
        fh.write(" ".join(f"{v:.17g}" for v in density) + "\n")
        fh.write("# temperature grid (K)\n")
        fh.write(" ".join(f"{v:.17g}" for v in temperature) + "\n")
        for name, block in (("pressure (Pa)", pressure), ("energy (J/kg)", energy)):
            fh.write(f"# {name}, one line per density\n")
            for row in block:
                fh.write(" ".join(f"{v:.17g}" for v in row) + "\n")


@njit(cache=True)
def _locate(table, start, n, v):
    """Index k in [0, n-2] with g[k] <= v <= g[k+1] for the grid g = table[start:start+n]."""
    lo = 0
    hi = n - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if table[start + mid] <= v:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _density_cell(params, table, rho):
    """Clamp ln rho to the grid: (cell i, weight w, cell width dx, rho used, flag)."""
    off = int(params[OFFSET])
    n_rho = int(params[N_RHO])
    flag = 0
    x_lo = table[off]
    x_hi = table[off + n_rho - 1]
    x = math.log(rho) if rho > 0.0 else x_lo
    if rho <= 0.0 or x < x_lo:
        x = x_lo
        flag = 1
    elif x > x_hi:
        x = x_hi
        flag = 1
    i = _locate(table, off, n_rho, x)
    dx = table[off + i + 1] - table[off + i]
    return i, (x - table[off + i]) / dx, dx, math.exp(x), flag


@njit(cache=True)
def _column(params, table, block, i, w, j):
    """Block value (0 = P, 1 = E) interpolated in ln rho at temperature index j."""
    off = int(params[OFFSET])
    n_rho = int(params[N_RHO])
    n_t = int(params[N_T])
    start = off + n_rho + n_t + block * n_rho * n_t
    return (1.0 - w) * table[start + i * n_t + j] + w * table[start + (i + 1) * n_t + j]


@njit(cache=True)
def _energy_cell(params, table, i, w, e):
    """Clamp e to [E(rho, T_0), E(rho, T_last)]: (temperature cell j, weight tau, flag)."""
    n_t = int(params[N_T])
    flag = 0
    e_lo = _column(params, table, 1, i, w, 0)
    e_hi = _column(params, table, 1, i, w, n_t - 1)
    if e < e_lo:
        e = e_lo
        flag = 1
    elif e > e_hi:
        e = e_hi
        flag = 1
    lo = 0
    hi = n_t - 1
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if _column(params, table, 1, i, w, mid) <= e:
            lo = mid
        else:
            hi = mid
    e_j = _column(params, table, 1, i, w, lo)
    e_k = _column(params, table, 1, i, w, lo + 1)
    return lo, (e - e_j) / (e_k - e_j), flag


@njit(cache=True)
def _cell_values(params, table, block, i, j):
    """Corner values (f00, f10, f01, f11) of block (0 = P, 1 = E); first index rho, second T."""
    off = int(params[OFFSET])
    n_rho = int(params[N_RHO])
    n_t = int(params[N_T])
    start = off + n_rho + n_t + block * n_rho * n_t
    k = start + i * n_t + j
    return table[k], table[k + n_t], table[k + 1], table[k + n_t + 1]


@njit(cache=True)
def table_pressure_sound_speed(params, table, rho, e):
    """Pressure P (Pa), c_K^2 (m^2/s^2) and bounds flag (1 = clamped) at (rho, e).

    See the module docstring for the interpolation and the derivative formulas.
    """
    i, w, dx, rho_used, flag_rho = _density_cell(params, table, rho)
    j, tau, flag_e = _energy_cell(params, table, i, w, e)
    p00, p10, p01, p11 = _cell_values(params, table, 0, i, j)
    e00, e10, e01, e11 = _cell_values(params, table, 1, i, j)
    p = (p00 * (1.0 - w) * (1.0 - tau) + p10 * w * (1.0 - tau)
         + p01 * (1.0 - w) * tau + p11 * w * tau)
    p_w = (1.0 - tau) * (p10 - p00) + tau * (p11 - p01)
    p_tau = (1.0 - w) * (p01 - p00) + w * (p11 - p10)
    e_w = (1.0 - tau) * (e10 - e00) + tau * (e11 - e01)
    e_tau = (1.0 - w) * (e01 - e00) + w * (e11 - e10)
    dp_de = p_tau / e_tau
    dp_drho = (p_w - p_tau * e_w / e_tau) / (rho_used * dx)
    c2 = dp_drho + p / (rho_used * rho_used) * dp_de
    if c2 < C2_FLOOR:
        c2 = C2_FLOOR
    flag = 1 if (flag_rho or flag_e) else 0
    return p, c2, flag


@njit(cache=True)
def table_temperature(params, table, rho, e):
    """Temperature T (K) at (rho, e) from the inversion of E(rho, T); clamped at the edges."""
    n_rho = int(params[N_RHO])
    t_start = int(params[OFFSET]) + n_rho
    i, w, dx, rho_used, flag_rho = _density_cell(params, table, rho)
    j, tau, flag_e = _energy_cell(params, table, i, w, e)
    return table[t_start + j] + tau * (table[t_start + j + 1] - table[t_start + j])


@njit(cache=True)
def table_energy_from_pressure(params, table, rho, p):
    """Specific internal energy e (J/kg) with P(rho, e) = p on the interpolated table.

    At the (clamped) density, scans the temperature intervals for the first one whose
    interpolated pressures bracket p and solves linearly; exact inverse of the
    interpolation.  Returns NaN when p lies outside the table's pressures at this density.
    """
    n_t = int(params[N_T])
    i, w, dx, rho_used, flag_rho = _density_cell(params, table, rho)
    p_j = _column(params, table, 0, i, w, 0)
    for j in range(n_t - 1):
        p_k = _column(params, table, 0, i, w, j + 1)
        if (p_j - p) * (p_k - p) <= 0.0:
            tau = (p - p_j) / (p_k - p_j)
            e_j = _column(params, table, 1, i, w, j)
            e_k = _column(params, table, 1, i, w, j + 1)
            return e_j + tau * (e_k - e_j)
        p_j = p_k
    return math.nan


@njit(cache=True)
def table_reference_density(params):
    """Reference density rho_ref (kg/m^3) from the table header."""
    return params[RHO_REF]
