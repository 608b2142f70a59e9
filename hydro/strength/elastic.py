"""Objective elastic update of the deviatoric stress (Jaumann rate) and the radial return.

Deviatoric stress S (Pa), symmetric and traceless, as six scalars in the order
(xx, yy, zz, xy, xz, yz); in 2d-cylindrical (r, z, theta) the slots are (rr, zz, thth, rz, -, -).
L_ij = d v_i / d x_j (1/s) is the velocity gradient, D = (L + L^T) / 2 the strain rate,
W = (L - L^T) / 2 the spin.  The Jaumann rate

    dS/dt = 2 G (D - tr(D) I / 3) + W S - S W

is integrated over dt as S_new = Q S Q^T + 2 G dt (D - tr(D) I / 3), with the rotation
Q = (I - dt W / 2)^-1 (I + dt W / 2) (Cayley / Hughes-Winget): Q is exactly orthogonal, so a
rigid rotation keeps every invariant of S to round-off (objectivity), and Q -> exp(W dt)
to second order.  With h the axial vector of dt W / 2 (H v = h x v),

    Q = I + 2 / (1 + h.h) (H + h h^T - (h.h) I).

Radial return (:func:`radial_return`): the von Mises equivalent stress sigma_eq =
sqrt(3 J2) = sqrt(3/2 S:S) is scaled back to Y when it exceeds Y; the equivalent plastic
strain increment is (sigma_eq - Y) / (3 G) (for G > 0).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, inline="always")
def jaumann_update(sxx, syy, szz, sxy, sxz, syz,
                   lxx, lxy, lxz, lyx, lyy, lyz, lzx, lzy, lzz, dt, shear_modulus):
    """S_new = Q S Q^T + 2 G dt dev(D) (Pa); see the module docstring.  Returns the six components."""
    # axial vector of H = dt W / 2, W_ij = (L_ij - L_ji) / 2
    h1 = 0.25 * dt * (lzy - lyz)
    h2 = 0.25 * dt * (lxz - lzx)
    h3 = 0.25 * dt * (lyx - lxy)
    hh = h1 * h1 + h2 * h2 + h3 * h3
    c = 2.0 / (1.0 + hh)
    q00 = 1.0 + c * (h1 * h1 - hh)
    q11 = 1.0 + c * (h2 * h2 - hh)
    q22 = 1.0 + c * (h3 * h3 - hh)
    q01 = c * (-h3 + h1 * h2)
    q10 = c * (h3 + h1 * h2)
    q02 = c * (h2 + h1 * h3)
    q20 = c * (-h2 + h1 * h3)
    q12 = c * (-h1 + h2 * h3)
    q21 = c * (h1 + h2 * h3)
    # A = Q S
    a00 = q00 * sxx + q01 * sxy + q02 * sxz
    a01 = q00 * sxy + q01 * syy + q02 * syz
    a02 = q00 * sxz + q01 * syz + q02 * szz
    a10 = q10 * sxx + q11 * sxy + q12 * sxz
    a11 = q10 * sxy + q11 * syy + q12 * syz
    a12 = q10 * sxz + q11 * syz + q12 * szz
    a20 = q20 * sxx + q21 * sxy + q22 * sxz
    a21 = q20 * sxy + q21 * syy + q22 * syz
    a22 = q20 * sxz + q21 * syz + q22 * szz
    # R = A Q^T (symmetric)
    rxx = a00 * q00 + a01 * q01 + a02 * q02
    ryy = a10 * q10 + a11 * q11 + a12 * q12
    rzz = a20 * q20 + a21 * q21 + a22 * q22
    rxy = a00 * q10 + a01 * q11 + a02 * q12
    rxz = a00 * q20 + a01 * q21 + a02 * q22
    ryz = a10 * q20 + a11 * q21 + a12 * q22
    # deviatoric strain increment
    third = (lxx + lyy + lzz) / 3.0
    g2 = 2.0 * shear_modulus * dt
    rxx += g2 * (lxx - third)
    ryy += g2 * (lyy - third)
    rzz += g2 * (lzz - third)
    rxy += shear_modulus * dt * (lxy + lyx)
    rxz += shear_modulus * dt * (lxz + lzx)
    ryz += shear_modulus * dt * (lyz + lzy)
    # remove the round-off trace
    tr = (rxx + ryy + rzz) / 3.0
    return rxx - tr, ryy - tr, rzz - tr, rxy, rxz, ryz


@njit(cache=True, inline="always")
def equivalent_stress(sxx, syy, szz, sxy, sxz, syz):
    """Von Mises equivalent stress sqrt(3 J2), J2 = S:S / 2 (Pa)."""
    ss = sxx * sxx + syy * syy + szz * szz + 2.0 * (sxy * sxy + sxz * sxz + syz * syz)
    return np.sqrt(1.5 * ss)


@njit(cache=True, inline="always")
def radial_return(sxx, syy, szz, sxy, sxz, syz, yield_stress, shear_modulus):
    """Return S to the yield surface sqrt(3 J2) <= Y along the radial direction.

    Returns (sxx, syy, szz, sxy, sxz, syz, plastic_strain_increment, returned): the scaled
    components (Pa), the equivalent plastic strain increment (sigma_eq - Y) / (3 G) (-)
    and whether a return happened.
    """
    seq = equivalent_stress(sxx, syy, szz, sxy, sxz, syz)
    y = max(yield_stress, 0.0)
    if seq <= y:
        return sxx, syy, szz, sxy, sxz, syz, 0.0, False
    f = y / seq
    dep = (seq - y) / (3.0 * shear_modulus) if shear_modulus > 0.0 else 0.0
    return sxx * f, syy * f, szz * f, sxy * f, sxz * f, syz * f, dep, True
