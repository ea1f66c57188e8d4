"""Pieces of LAMMPS' ``pair_style granular`` (29Sep2021, GRANULAR/pair_granular.cpp) shared by the
laws written in its arithmetic: the normal damping prefactor of each ``damping`` model and the
spring-dashpot-slider update of a history 2-vector (the tangential ``linear_history``/``mindlin``
spring and the ``rolling sds`` displacement use the same steps, pair_granular.cpp:455-532, 553-617).

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
