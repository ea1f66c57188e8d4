"""LIGGGHTS ``hooke/stiffness`` normal law with ``tangential history``, as one jitted scalar function.

The elastic part of the normal force is :func:`gransim.contacts.law.force_magnitude`
(eq (5) of Meier et al.: F = E_n eps with E_n = kn); this module adds what the DEM needs:
mass-scaled viscous damping, the incremental tangential spring and the Coulomb cap, in the
exact floating-point order of LIGGGHTS-PUBLIC 3.8.0 (surface_model_default.h,
normal_model_hooke_stiffness.h, tangential_model_history.h; see shared notes liggghts-3.8.md).

Conventions (2D, all SI): the pair is (i, j) with d = x_i - x_j (j possibly a periodic image),
n = d/|d| pointing from j to i, overlap delta = r_i + r_j - |d| > 0. Forces returned act on i;
j receives minus the force (and its own torque, of the same sign, see below).
"""

from __future__ import annotations

import math

from .._numba import njit
from .law import force_magnitude


@njit(inline="always")
def hooke_history(delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                  kn, kt, gamman, gammat, mu, dt, s0, s1, update):
    """One touching pair: force on i, torques on i and j, updated tangential spring.

    Parameters
    ----------
    delx, dely : float, m. d = x_i - x_j (image of j).
    rsq : float, m^2. |d|^2, must be < (r_i + r_j)^2 (the caller tests contact).
    radi, radj : radii (m). vix, viy, vjx, vjy : velocities (m/s). wi, wj : spins (rad/s).
    mi, mj : masses (kg).
    kn, kt : normal / tangential stiffness (N/m).
    gamman, gammat : mass-scaled damping rates (1/s): damping coefficient = m_eff gamma.
    mu : Coulomb friction coefficient. dt : time step (s).
    s0, s1 : stored tangential spring xi (m), frame of i.
    update : bool. True in a time step (xi += v_t,rel dt, then projected on the tangent
        plane); False in the set-up evaluation (LIGGGHTS ``run`` set-up: no increment).

    Returns
    -------
    fx, fy : force on i (N). F = F_n n + F_t with F_n = kn delta - m_eff gamman v_n
        (may be attractive: no force limit) and F_t = -kt xi - m_eff gammat v_t,rel, or, when
        kt |xi| > mu |F_n| (strictly), F_t = -kt xi mu|F_n|/(kt|xi|) and xi = -F_t/kt.
    ti, tj : torques on i and j (N m): -c_i (n x F_t)_z and -c_j (n x F_t)_z, c = r - delta/2
        (the same sign on both, as LIGGGHTS applies them).
    s0, s1 : updated spring (m).
    sliding : bool, the Coulomb cap was active.
    fn : normal force F_n (N).
    """
    r = math.sqrt(rsq)
    rinv = 1.0 / r
    enx = delx * rinv
    eny = dely * rinv
    meff = mi * mj / (mi + mj)
    # relative velocity at the contact point (surface_model_default.h order)
    vr1 = vix - vjx
    vr2 = viy - vjy
    vn = vr1 * enx + vr2 * eny
    vt1 = vr1 - vn * enx
    vt2 = vr2 - vn * eny
    radsum = radi + radj
    deltan = radsum - r
    cri = radi - 0.5 * deltan
    crj = radj - 0.5 * deltan
    wr3 = (cri * wi + crj * wj) * rinv
    vtr1 = vt1 + dely * wr3
    vtr2 = vt2 - delx * wr3
    # normal: elastic part (eq 5 of Meier et al.) + mass-scaled damping
    fn = -(meff * gamman) * vn + force_magnitude(radsum - r, kn)
    # tangential spring with history
    if update:
        s0 += vtr1 * dt
        s1 += vtr2 * dt
        rsht = s0 * enx + s1 * eny
        s0 -= rsht * enx
        s1 -= rsht * eny
    shrmag = math.sqrt(s0 * s0 + s1 * s1)
    ft1 = -(kt * s0)
    ft2 = -(kt * s1)
    ft_shear = kt * shrmag
    ft_friction = mu * abs(fn)
    sliding = False
    if ft_shear > ft_friction:
        sliding = True
        if shrmag != 0.0:
            ratio = ft_friction / ft_shear
            ft1 *= ratio
            ft2 *= ratio
            s0 = -ft1 / kt
            s1 = -ft2 / kt
        else:
            ft1 = 0.0
            ft2 = 0.0
    else:
        gt = meff * gammat
        ft1 -= gt * vtr1
        ft2 -= gt * vtr2
    tor3 = enx * ft2 - eny * ft1
    fx = fn * enx + ft1
    fy = fn * eny + ft2
    return fx, fy, -cri * tor3, -crj * tor3, s0, s1, sliding, fn
