"""Pieces of LAMMPS' ``pair_style granular`` (29Sep2021, GRANULAR/pair_granular.cpp) shared by the
laws written in its arithmetic: the contact's geometry and relative velocities, the normal damping
prefactor of each ``damping`` model, the spring-dashpot-slider update of a history 2-vector (the
tangential ``linear_history``/``mindlin`` spring and the ``rolling sds`` displacement use the same
steps, pair_granular.cpp:455-532, 553-617) and the force and torques of the pair.

Inline jitted functions: the calling laws (:mod:`gransim.contacts.hertz`,
:mod:`gransim.contacts.rolling`) keep LAMMPS' floating-point order through them.
"""

from __future__ import annotations

import math

from .._numba import njit

#: ``damping`` models of ``pair_style granular`` as float-coded indices
DAMPING_VELOCITY, DAMPING_MASS_VELOCITY, DAMPING_VISCOELASTIC, DAMPING_TSUJI = 0, 1, 2, 3
#: pair_granular.cpp's EPSILON (a history vector is re-projected only above this share of the cap)
EPSILON = 1e-10


@njit(inline="always")
def granular_geometry(delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj):
    """The contact of one touching pair as ``PairGranular::compute`` forms it (pair_granular.cpp:
    206-262, 2D): (nx, ny, vnnr, meff, Reff, delta, a, vtr1, vtr2) with n = d / r, vnnr = v_r.n,
    m* = m_i m_j / (m_i + m_j), R* = r_i r_j / (r_i + r_j), delta = r_i + r_j - r,
    a = sqrt(delta R*), v_tr = v_r - (v_r.n) n + n x (r_i w_i + r_j w_j) the relative tangential
    velocity at the contact (pgr:455-466). Every value with LAMMPS' operations in its order (no
    value depends on another's rounding through a shared sum)."""
    r = math.sqrt(rsq)
    rinv = 1.0 / r
    nx = delx * rinv
    ny = dely * rinv
    vr1 = vix - vjx
    vr2 = viy - vjy
    vnnr = vr1 * nx + vr2 * ny
    vn1 = nx * vnnr
    vn2 = ny * vnnr
    meff = mi * mj / (mi + mj)
    radsum = radi + radj
    Reff = radi * radj / radsum
    delta = radsum - r
    dR = delta * Reff
    a = math.sqrt(dR)
    vt1 = vr1 - vn1
    vt2 = vr2 - vn2
    wr3 = radi * wi + radj * wj
    vtr1 = vt1 + ny * wr3  # vt1 - (nz wr2 - ny wr3)
    vtr2 = vt2 - nx * wr3  # vt2 - (nx wr3 - nz wr1)
    return nx, ny, vnnr, meff, Reff, delta, a, vtr1, vtr2


@njit(inline="always")
def granular_forces(nx, ny, Fntot, fs1, fs2, radi, radj, delta):
    """(fx, fy, ti, tj): the force on i (normal plus tangential) and the tangential torques on i and
    j, each with its lever arm r - delta/2 (pgr:640-664, 2D)."""
    fx = nx * Fntot + fs1
    fy = ny * Fntot + fs2
    tor3 = nx * fs2 - ny * fs1
    return fx, fy, -((radi - 0.5 * delta) * tor3), -((radj - 0.5 * delta) * tor3)


@njit(inline="always")
def damp_normal(damping, meff, a, knfac):
    """The factor of DAMP in the normal damping coefficient (pair_granular.cpp:422-432): 1
    (velocity), m* (mass_velocity), a m* (viscoelastic, a = sqrt(R* delta)), sqrt(m* knfac)
    (tsuji, knfac the normal stiffness of the step), 0 for an unknown model."""
    if damping == DAMPING_VELOCITY:
        return 1.0
    if damping == DAMPING_MASS_VELOCITY:
        return meff
    if damping == DAMPING_VISCOELASTIC:
        return a * meff
    if damping == DAMPING_TSUJI:
        return math.sqrt(meff * knfac)
    return 0.0


@njit(inline="always")
def spring_dashpot_slider(s0, s1, nx, ny, v1, v2, k, damp, crit, dt, update):
    """One step of a history 2-vector s with stiffness ``k``, dashpot ``damp`` and cap ``crit``.

    With ``update``: rotate s into the plane normal to n keeping its length (when its normal part
    is above EPSILON of the cap), then s += v dt. Force f = -k s - damp v; if |f| > crit, f is
    scaled to the cap and s set to the spring that gives it. Returns (s0, s1, f1, f2, capped).
    """
    if update:
        rsht = s0 * nx + s1 * ny
        if abs(rsht) * k > EPSILON * crit:
            shrmag = math.sqrt(s0 * s0 + s1 * s1)
            s0 -= rsht * nx
            s1 -= rsht * ny
            prjmag = math.sqrt(s0 * s0 + s1 * s1)
            scalefac = shrmag / prjmag if prjmag > 0 else 0.0
            s0 *= scalefac
            s1 *= scalefac
        s0 += v1 * dt
        s1 += v2 * dt
    f1 = -k * s0 - damp * v1
    f2 = -k * s1 - damp * v2
    f = math.sqrt(f1 * f1 + f2 * f2)
    capped = False
    if f > crit:
        capped = True
        if math.sqrt(s0 * s0 + s1 * s1) != 0.0:
            s0 = -1.0 / k * (crit * f1 / f + damp * v1)
            s1 = -1.0 / k * (crit * f2 / f + damp * v2)
            f1 *= crit / f
            f2 *= crit / f
        else:
            f1 = 0.0
            f2 = 0.0
    return s0, s1, f1, f2, capped
