"""Rolling resistance added to the Hooke history law, as each code computes it: jitted scalar laws.

* :func:`hooke_epsd2_liggghts`: LIGGGHTS-PUBLIC 3.8.0 ``pair_style gran model hooke/stiffness
  tangential history rolling_friction epsd2`` (``fix property/global coefficientRollingFriction
  peratomtypepair``): an elastic-perfectly-plastic rolling spring, no dashpot;
* :func:`hooke_epsd_liggghts`: ``rolling_friction epsd`` (+ ``coefficientRollingViscousDamping``):
  spring, dashpot below the cap, slider;
* :func:`hooke_cdt_liggghts`: ``rolling_friction cdt``: a constant torque against the relative spin;
* :func:`hooke_sds_granular_lammps`: LAMMPS 29Sep2021 ``pair_style granular`` + ``pair_coeff * *
  hooke KN DAMP damping MODEL tangential linear_history KT XGAMMAT MU rolling sds KROLL GAMMAROLL
  MUROLL``: spring-dashpot-slider on a rolling displacement.

All four exist in the Debian builds (the decks of ``reference_runs/decks/rolling.py`` run with
``/usr/bin/liggghts`` and ``/usr/bin/lmp``); LIGGGHTS 3.8.0 also has ``epsd3`` and ``luding``
(not written here).

Calling convention: the 13 pair arguments of :func:`gransim.contacts.hooke.hooke_history`
(``delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj``: d = x_i - x_j, rsq < (r_i +
r_j)^2, SI), the law's parameters, ``dt``, the law's history floats, ``update`` (True in a step,
False in the set-up call of a ``run``). Every law returns ``(fx, fy, ti, tj, *history, sliding,
rolling, fn, tr)``: force on i (N; j gets minus it), the total torques on i and j (N m: tangential
+ rolling), the updated history, whether the Coulomb cap of the tangential force was active,
whether the rolling cap was active, the normal force (N) and the rolling torque on i alone (N m;
j receives -tr). Per-contact history (:data:`HISTORY_WIDTH`): the tangential spring xi (2 floats,
m), then

* epsd2, epsd: 1 float, the z component of LIGGGHTS' ``r_torque_old`` (N m; the codes store three,
  x and y stay exact zeros in 2D);
* cdt: none;
* sds: 2 floats, LAMMPS' rolling displacement psi (m) in the plane (stored as a vector because
  LAMMPS rotates it into the new tangent plane with a rescaling, pair_granular.cpp:571-591, which
  a scalar would reproduce only up to round-off; z stays zero).

Sources, ``LIG`` = LIGGGHTS-PUBLIC-3.8.0/src, ``LMP`` = lammps-0~20220106.git7586adbb6a/src
(the Debian source trees). 2D: omega = (0, 0, w), n = (nx, ny, 0); every product with a zero
component is an exact zero, so the 3D source reduces exactly to the z line written here.

**The models side by side** (w = w_i - w_j the relative spin, R* = r_i r_j/(r_i + r_j), M the
rolling torque with i receiving -M and j +M, theta the relative rotation, docs/laws.md):

* epsd2 (LIG rolling_model_epsd2.h:161-228): k_r = k_t R*^2 (the tangential stiffness kt of
  ``hooke/stiffness``, N/m, so k_r in N m/rad), M <- M_old + k_r w dt, |M| <= mu_r R* |F_n| (F_n the
  damped normal force), M scaled onto the cap and stored. No dashpot (the comment at :226 says so).
* epsd (LIG rolling_model_epsd.h:247-331): k_r = 2.25 k_n mu_r^2 R*^2 (Iwashita & Oda 1998's
  stiffness in the form of Wensrich & Katterfeld, *Powder Technol.* 217, 2012, eq (8)), the same
  spring and cap; below the cap a dashpot C w with C = eta_r 2 sqrt(I_r k_r), I_r = 1.5 I'_i I'_j /
  (I'_i + I'_j), I' = m r^2 in 2D (:205-215; 1.4 in 3D); the dashpot is not part of the stored torque.
* cdt (LIG rolling_model_cdt.h:133-166): M = mu_r k_n delta R* w/|w| (elastic normal force only),
  no history, no torque when w = 0.
* sds (LMP GRANULAR/pair_granular.cpp:553-617, 678-707): rolling velocity v_r = R* (w_rel x n)
  (Wang et al., *Particuology* 23, 2015, eq (31)), in 2D v_r = R* w t with t = (-ny, nx);
  psi <- frame update (projection on the tangent plane *rescaled to the old length* when
  |psi.n| k_roll > 1e-10 F_rcrit), then psi += v_r dt; F_r = -k_roll psi - gamma_roll v_r;
  |F_r| > mu_roll |F_n| (spring + dashpot together): psi = -(F_rcrit F_r/|F_r| + gamma_roll v_r)/k_roll,
  F_r scaled; torque R* (n x F_r) on i and minus it on j. As a rotational law: M = K theta + C w with
  K = k_roll R*^2, C = gamma_roll R*^2, cap mu_roll R* |F_n|.

**As plug-ins of the DEM loop** (:mod:`gransim.contacts.laws`; widths and flips
:data:`HISTORY_WIDTH`, :data:`HISTORY_FLIP`): :class:`HookeEpsd2Liggghts` (kn, kt, gamma_n,
gamma_t, mu, mu_r), :class:`HookeEpsdLiggghts` (... mu_r, eta_r), :class:`HookeCdtLiggghts`
(... mu_r), :class:`HookeSdsLammps` (kn, damp, damping index as a float, kt, xgammat, mu, kroll,
gammaroll, muroll; the whole history of a separated pair is zeroed, LMP pair_granular.cpp:283-288;
LIGGGHTS keeps it: ``surfacesClose`` is unreachable with contactDistanceFactor 1,
LIG pair_gran_base.h:414). By name: :func:`gransim.contacts.laws.make_law` ("hooke-epsd2-liggghts",
"hooke-epsd-liggghts", "hooke-cdt-liggghts", "hooke-sds-lammps"). Energies (registered for all
four): the Hooke springs kn delta^2/2 + kt |xi|^2/2 plus the rolling spring, M^2/(2 k_r) for
epsd2/epsd (:func:`epsd_energy`, k_r from R* of each contact), kroll |psi|^2/2 for sds, none for
cdt (a constant torque, no spring). The epsd dashpot and the cdt torque only dissipate.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._numba import njit
from ..errors import InputError

# damping models of pair_style granular (pair_granular.cpp:56 enum order), re-exported: the laws'
# damping argument
from .granular import (  # noqa: F401
    DAMPING_MASS_VELOCITY,
    DAMPING_TSUJI,
    DAMPING_VELOCITY,
    DAMPING_VISCOELASTIC,
    damp_normal,
    granular_forces,
    granular_geometry,
    spring_dashpot_slider,
)
from .hooke import hooke_history, hooke_timescale, liggghts_hooke_lines
from .laws import as_law_float, deck_float, lightest_pair_mass, register_law

#: history floats per law (tangential spring first)
HISTORY_WIDTH = {"epsd2": 3, "epsd": 3, "cdt": 2, "sds": 4}

#: signs of the history columns seen from the other particle (a list entry (i, j) stored as (j, i)):
#: the tangential spring and the epsd torque flip; sds' psi is unchanged (w_rel and n both flip)
HISTORY_FLIP = {
    "epsd2": (-1.0, -1.0, -1.0),
    "epsd": (-1.0, -1.0, -1.0),
    "cdt": (-1.0, -1.0),
    "sds": (-1.0, -1.0, 1.0, 1.0),
}


@njit(inline="always")
def epsd2_torque(w, reff, kt, fn, mu_r, dt, m, update):
    """LIGGGHTS ``rolling_friction epsd2``, 2D (LIG rolling_model_epsd2.h:161-224).

    Parameters
    ----------
    w : relative spin w_i - w_j (rad/s), epsd2.h:130. reff : R* (m), :107. kt : tangential
    stiffness of ``hooke/stiffness`` (N/m, ``sidata.kt``, normal_model_hooke_stiffness.h:246).
    fn : normal force with its damping (N, ``sidata.Fn``). mu_r : coefficientRollingFriction (-,
    a length ratio: the cap is mu_r R* |F_n|). dt : s. m : stored torque (N m). update : bool.

    Returns ``(M, m, capped)``: M = min(|m + k_r w dt|, mu_r R* |F_n|) sgn(...) with
    k_r = kt R*^2 (:193), the torque with i receiving -M, j +M (:136-141); m = M in a step (:217-224;
    the set-up call computes the increment but does not store it).
    """
    kr = kt * reff * reff
    rt = m + w * (dt * kr)
    mag = math.sqrt(rt * rt)
    rmax = abs(fn) * reff * mu_r
    capped = False
    if mag > rmax:
        capped = True
        rt *= rmax / mag
    if update:
        m = rt
    return rt, m, capped


@njit(inline="always")
def epsd_torque(w, reff, kn, fn, mu_r, eta_r, mi, mj, radi, radj, dt, m, update):
    """LIGGGHTS ``rolling_friction epsd``, 2D (LIG rolling_model_epsd.h:205-331).

    Parameters: as :func:`epsd2_torque`, with kn the normal stiffness (N/m, ``sidata.kn``),
    eta_r coefficientRollingViscousDamping (-), masses (kg) and radii (m) of i and j.

    k_r = 2.25 kn mu_r^2 R*^2 (:282); spring and cap as epsd2 (the stored torque is the capped
    spring torque, :293-320); below the cap the dashpot C w, C = eta_r 2 sqrt(I_r k_r) with
    I_r = 1.5 (m_i r_i^2)(m_j r_j^2)/(m_i r_i^2 + m_j r_j^2) (2D, :212-214) is added to M but not
    stored (:322-329); above the cap no dashpot. Returns ``(M, m, capped)``.
    """
    ri = mi * radi * radi
    rj = mj * radj * radj
    r_inertia = 1.5 * ri * rj / (ri + rj)
    kr = 2.25 * kn * mu_r * mu_r * reff * reff
    rt = m + w * (dt * kr)
    mag = math.sqrt(rt * rt)
    rmax = abs(fn) * reff * mu_r
    capped = False
    if mag > rmax:
        capped = True
        rt *= rmax / mag
        if update:
            m = rt
    else:
        if update:
            m = rt
        r_coef = eta_r * 2 * math.sqrt(r_inertia * kr)
        rt += r_coef * w
    return rt, m, capped


@njit(inline="always")
def cdt_torque(w, reff, kn, deltan, mu_r):
    """LIGGGHTS ``rolling_friction cdt``, 2D (LIG rolling_model_cdt.h:135-156): M = w (mu_r kn delta
    R*/|w|) (the elastic normal force kn delta, not F_n), 0 for w = 0. Returns ``(M, capped)``,
    capped True whenever M != 0 (the torque is always at its limit)."""
    wmag = math.sqrt(w * w)
    if wmag > 0.0:
        return w * (mu_r * kn * deltan * reff / wmag), True
    return 0.0, False


@njit(inline="always")
def hooke_epsd2_liggghts(
    delx,
    dely,
    rsq,
    radi,
    radj,
    vix,
    viy,
    vjx,
    vjy,
    wi,
    wj,
    mi,
    mj,
    kn,
    kt,
    gamman,
    gammat,
    mu,
    mu_r,
    dt,
    s0,
    s1,
    m,
    update,
):
    """``hooke/stiffness tangential history rolling_friction epsd2`` for one touching pair.

    Parameters: those of :func:`gransim.contacts.hooke.hooke_history` (kn, kt N/m; gamman, gammat
    1/s mass-scaled; mu), mu_r (coefficientRollingFriction), then dt, s0, s1 (spring, m), m
    (rolling torque, N m), update. The contact models run normal, tangential, rolling in this order
    (LIG contact_models.h:228-238); the rolling torque is subtracted from i's and added to j's
    torque after the tangential one (epsd2.h:136-141). Returns ``(fx, fy, ti, tj, s0, s1, m,
    sliding, rolling, fn, tr)`` (module docstring).
    """
    fx, fy, ti, tj, s0, s1, sliding, fn = hooke_history(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    reff = radi * radj / (radi + radj)
    rt, m, capped = epsd2_torque(wi - wj, reff, kt, fn, mu_r, dt, m, update)
    return fx, fy, ti - rt, tj + rt, s0, s1, m, sliding, capped, fn, -rt


@njit(inline="always")
def hooke_epsd_liggghts(
    delx,
    dely,
    rsq,
    radi,
    radj,
    vix,
    viy,
    vjx,
    vjy,
    wi,
    wj,
    mi,
    mj,
    kn,
    kt,
    gamman,
    gammat,
    mu,
    mu_r,
    eta_r,
    dt,
    s0,
    s1,
    m,
    update,
):
    """``hooke/stiffness tangential history rolling_friction epsd`` (eta_r:
    coefficientRollingViscousDamping); otherwise as :func:`hooke_epsd2_liggghts`."""
    fx, fy, ti, tj, s0, s1, sliding, fn = hooke_history(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    reff = radi * radj / (radi + radj)
    rt, m, capped = epsd_torque(wi - wj, reff, kn, fn, mu_r, eta_r, mi, mj, radi, radj, dt, m, update)
    return fx, fy, ti - rt, tj + rt, s0, s1, m, sliding, capped, fn, -rt


@njit(inline="always")
def hooke_cdt_liggghts(
    delx,
    dely,
    rsq,
    radi,
    radj,
    vix,
    viy,
    vjx,
    vjy,
    wi,
    wj,
    mi,
    mj,
    kn,
    kt,
    gamman,
    gammat,
    mu,
    mu_r,
    dt,
    s0,
    s1,
    update,
):
    """``hooke/stiffness tangential history rolling_friction cdt``; returns ``(fx, fy, ti, tj, s0,
    s1, sliding, rolling, fn, tr)`` (no rolling history)."""
    fx, fy, ti, tj, s0, s1, sliding, fn = hooke_history(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    reff = radi * radj / (radi + radj)
    deltan = (radi + radj) - math.sqrt(rsq)
    rt, capped = cdt_torque(wi - wj, reff, kn, deltan, mu_r)
    return fx, fy, ti - rt, tj + rt, s0, s1, sliding, capped, fn, -rt


@njit(inline="always")
def hooke_sds_granular_lammps(
    delx,
    dely,
    rsq,
    radi,
    radj,
    vix,
    viy,
    vjx,
    vjy,
    wi,
    wj,
    mi,
    mj,
    kn,
    damp,
    damping,
    kt,
    xgammat,
    mu,
    kroll,
    gammaroll,
    muroll,
    dt,
    s0,
    s1,
    p0,
    p1,
    update,
):
    """:func:`hooke_sds_parts` with the torques whole: returns ``(fx, fy, ti, tj, s0, s1, p0, p1,
    sliding, rolling, fn, tr)``, ti = -(r_i - delta/2)(n x F_t)_z + tr, tj = -(r_j - delta/2)(n x
    F_t)_z - tr, tr = R* (n x F_r)_z (arguments there)."""
    fx, fy, ti, tj, s0, s1, p0, p1, sliding, rolling, fn, tr = hooke_sds_parts(
        delx,
        dely,
        rsq,
        radi,
        radj,
        vix,
        viy,
        vjx,
        vjy,
        wi,
        wj,
        mi,
        mj,
        kn,
        damp,
        damping,
        kt,
        xgammat,
        mu,
        kroll,
        gammaroll,
        muroll,
        dt,
        s0,
        s1,
        p0,
        p1,
        update,
    )
    return fx, fy, ti + tr, tj - tr, s0, s1, p0, p1, sliding, rolling, fn, tr


@njit(inline="always")
def hooke_sds_parts(
    delx,
    dely,
    rsq,
    radi,
    radj,
    vix,
    viy,
    vjx,
    vjy,
    wi,
    wj,
    mi,
    mj,
    kn,
    damp,
    damping,
    kt,
    xgammat,
    mu,
    kroll,
    gammaroll,
    muroll,
    dt,
    s0,
    s1,
    p0,
    p1,
    update,
):
    """LAMMPS ``pair_style granular``, ``hooke KN DAMP damping MODEL tangential linear_history KT
    XGAMMAT MU rolling sds KROLL GAMMAROLL MUROLL`` (no twisting, no ``limit_damping``).

    Parameters (after the 13 pair arguments)
    ----------
    kn : KN (N/m). damp : DAMP; its unit depends on ``damping`` (one of ``DAMPING_*``):
        velocity kg/s, mass_velocity 1/s (so m* DAMP v_n: the damping of ``gran/hooke/history``
        with gamman = DAMP), viscoelastic 1/(m s) (times a = sqrt(R* delta)), tsuji (DAMP is then
        the alpha of the caller; the polynomial map of pair_granular.cpp:987-991 is not applied here).
    kt : KT (N/m). xgammat : tangential damping as a multiple of the normal prefactor. mu : MU.
    kroll : KROLL (N/m). gammaroll : GAMMAROLL (kg/s). muroll : MUROLL (-).
    dt, s0, s1 (spring xi, m), p0, p1 (rolling displacement psi, m), update.

    Law (``pgr`` = LMP GRANULAR/pair_granular.cpp): normal as in
    :func:`gransim.contacts.hertz.hertz_mindlin_granular_lammps` without the factor a
    (``HOOKE``, pgr:349-350): F_n = kn delta - eta v_n, eta = DAMP x (1, m*, a m*, sqrt(m* kn))
    (pgr:363-376); tangential ``linear_history`` (pgr:426-533): k_t = KT, frame update with
    rescaling, xi += v_t,rel dt (full radii in v_t,rel), F_t = -KT xi - XGAMMAT eta v_t,rel, cap on
    spring + damping; rolling (pgr:553-617) as in the module docstring with F_rcrit = MUROLL |F_n|;
    torques -(r_i - delta/2)(n x F_t)_z + R*(n x F_r)_z on i and -(r_j - delta/2)(n x F_t)_z -
    R*(n x F_r)_z on j, accumulated in that order (pgr:659-707).

    Returns ``(fx, fy, ti_t, tj_t, s0, s1, p0, p1, sliding, rolling, fn, tr)`` with the
    tangential torques ti_t = -(r_i - delta/2)(n x F_t)_z, tj_t = -(r_j - delta/2)(n x F_t)_z and
    the rolling torque on i, tr = R*(n x F_r)_z (j receives -tr): LAMMPS adds them to the
    particle's torque one after the other (the DEM loop does too: ``split_torque``).
    """
    nx, ny, vnnr, meff, Reff, delta, a, vtr1, vtr2 = granular_geometry(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj
    )
    Fne = kn * delta
    damp_normal_prefactor = damp * damp_normal(damping, meff, a, kn)
    Fdamp = -damp_normal_prefactor * vnnr
    Fntot = Fne + Fdamp
    Fncrit = abs(Fntot)
    Fscrit = mu * Fncrit
    damp_tangential = xgammat * damp_normal_prefactor
    s0, s1, fs1, fs2, sliding = spring_dashpot_slider(
        s0, s1, nx, ny, vtr1, vtr2, kt, damp_tangential, Fscrit, dt, update
    )
    # rolling resistance, pgr:545-617 (relrot = (0, 0, w_i - w_j))
    relrot3 = wi - wj
    vrl1 = Reff * -(relrot3 * ny)  # Reff*(relrot2*nz - relrot3*ny)
    vrl2 = Reff * (relrot3 * nx)  # Reff*(relrot3*nx - relrot1*nz)
    Frcrit = muroll * Fncrit
    p0, p1, fr1, fr2, rolling = spring_dashpot_slider(p0, p1, nx, ny, vrl1, vrl2, kroll, gammaroll, Frcrit, dt, update)
    fx, fy, ti, tj = granular_forces(nx, ny, Fntot, fs1, fs2, radi, radj, delta)
    torroll3 = Reff * (nx * fr2 - ny * fr1)
    return fx, fy, ti, tj, s0, s1, p0, p1, sliding, rolling, Fntot, torroll3


def rolling_stiffness(
    law: str, reff: float, kn: float = 0.0, kt: float = 0.0, mu_r: float = 0.0, kroll: float = 0.0
) -> float:
    """The rotational stiffness K (N m/rad) of ``law``: epsd2 kt R*^2, epsd 2.25 kn mu_r^2 R*^2,
    sds kroll R*^2 (M = K theta below the cap); cdt has none (returns 0)."""
    if law == "epsd2":
        return kt * reff * reff
    if law == "epsd":
        return 2.25 * kn * mu_r * mu_r * reff * reff
    if law == "sds":
        return kroll * reff * reff
    if law == "cdt":
        return 0.0

    raise InputError(f"law: expected one of epsd2, epsd, cdt, sds, got {law!r}")


# ----------------------------------------------------------------------------- plug-ins
#: LIGGGHTS ``hooke/stiffness tangential history rolling_friction epsd2``: kn, kt (N/m),
#: gamma_n, gamma_t (1/s), mu, mu_r (-) (:func:`hooke_epsd2_liggghts`)
HookeEpsd2Liggghts = namedtuple("HookeEpsd2Liggghts", ["kn", "kt", "gamma_n", "gamma_t", "mu", "mu_r"])
#: ... ``rolling_friction epsd``, eta_r = coefficientRollingViscousDamping (:func:`hooke_epsd_liggghts`)
HookeEpsdLiggghts = namedtuple("HookeEpsdLiggghts", ["kn", "kt", "gamma_n", "gamma_t", "mu", "mu_r", "eta_r"])
#: ... ``rolling_friction cdt`` (:func:`hooke_cdt_liggghts`)
HookeCdtLiggghts = namedtuple("HookeCdtLiggghts", ["kn", "kt", "gamma_n", "gamma_t", "mu", "mu_r"])
#: LAMMPS ``granular hooke KN DAMP damping MODEL tangential linear_history KT XGAMMAT MU rolling sds
#: KROLL GAMMAROLL MUROLL`` (:func:`hooke_sds_granular_lammps`; damping = ``DAMPING_*`` as a float)
HookeSdsLammps = namedtuple(
    "HookeSdsLammps", ["kn", "damp", "damping", "kt", "xgammat", "mu", "kroll", "gammaroll", "muroll"]
)


def rolling_pair(core, n_params: int, width: int, split: bool = False):
    """The pair function of a rolling law from its one-pair arithmetic ``core(delx, dely, rsq,
    radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, p_1 .. p_n, dt, h_1 .. h_w, update) -> (fx, fy,
    ti, tj, h_1 .. h_w, sliding, rolling, fn, tr)`` with p the law's ``n_params`` fields in the
    order of ``core``'s parameters and h the entry's history of ``width`` columns (read from
    ``hist[e]`` and written back). ``split``: the pair returns the rolling torque apart, (..., fn,
    tr, -tr) (``LawSpec.split_torque``). One adapter for the four laws: (n_params, width) = (6, 3)
    epsd2, (7, 3) epsd, (6, 2) cdt, (9, 4) sds; numba keeps only the branch of the law (constants
    of the closure), as it inlines no call with ``*args``."""
    if (n_params, width) not in ((6, 3), (7, 3), (6, 2), (9, 4)):
        raise InputError(f"rolling_pair: (n_params, width) {(n_params, width)} is none of the rolling laws'")

    @njit(inline="always")
    def pair(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
        if width == 2:
            fx, fy, ti, tj, h0, h1, sl, _, fn, tr = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], law[5], dt, hist[e, 0], hist[e, 1], update,
            )  # fmt: skip
        elif width == 3 and n_params == 6:
            fx, fy, ti, tj, h0, h1, h2, sl, _, fn, tr = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], law[5], dt, hist[e, 0], hist[e, 1], hist[e, 2], update,
            )  # fmt: skip
            hist[e, 2] = h2
        elif width == 3:
            fx, fy, ti, tj, h0, h1, h2, sl, _, fn, tr = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], law[5], law[6], dt, hist[e, 0], hist[e, 1], hist[e, 2], update,
            )  # fmt: skip
            hist[e, 2] = h2
        else:
            fx, fy, ti, tj, h0, h1, h2, h3, sl, _, fn, tr = core(
                delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj,
                law[0], law[1], law[2], law[3], law[4], law[5], law[6], law[7], law[8], dt,
                hist[e, 0], hist[e, 1], hist[e, 2], hist[e, 3], update,
            )  # fmt: skip
            hist[e, 2] = h2
            hist[e, 3] = h3
        hist[e, 0] = h0
        hist[e, 1] = h1
        if split:
            return fx, fy, ti, tj, sl, fn, tr, -tr
        return fx, fy, ti, tj, sl, fn

    return pair


#: pair functions of the rolling laws (:func:`rolling_pair`): hist[e] = (xi_x, xi_y, M_old) for
#: epsd2 and epsd, (xi_x, xi_y) for cdt, (xi_x, xi_y, psi_x, psi_y) for sds, whose tangential and
#: rolling torques are returned apart (``split_torque``: LAMMPS' order of accumulation)
epsd2_pair = rolling_pair(hooke_epsd2_liggghts, 6, 3)
epsd_pair = rolling_pair(hooke_epsd_liggghts, 7, 3)
cdt_pair = rolling_pair(hooke_cdt_liggghts, 6, 2)
sds_pair = rolling_pair(hooke_sds_parts, 9, 4, split=True)


@njit(inline="always")
def history_reset(law, hist, e):
    """LAMMPS ``pair_style granular``: a separated pair's history is zeroed (LMP pair_granular.cpp:283-288)."""
    for k in range(hist.shape[1]):
        hist[e, k] = 0.0


def _spring_energy(law, overlap, hist):
    """kn delta^2/2 + kt |xi|^2/2 summed (J), xi = hist[:, 0:2]."""
    h = np.asarray(hist, np.float64)
    return 0.5 * law.kn * float(np.sum(np.asarray(overlap, np.float64) ** 2)) + 0.5 * law.kt * float(
        np.sum(h[:, :2] ** 2)
    )


def cdt_energy(law, overlap, hist, radi=None, radj=None) -> float:
    """kn delta^2/2 + kt |xi|^2/2 summed (J); cdt's rolling torque stores no energy."""
    return _spring_energy(law, overlap, hist)


def sds_energy(law, overlap, hist, radi=None, radj=None) -> float:
    """kn delta^2/2 + kt |xi|^2/2 + kroll |psi|^2/2 summed (J): F_n = kn delta, F_t = -kt xi,
    F_r = -kroll psi below the caps (hist (K, 4); LMP pair_granular.cpp:349-350, 499-501, 597-599).
    The rolling spring: psi grows by v_r dt = R* w dt t (t = (-n_y, n_x), pgr:553-561), so a
    relative rotation d theta changes U by kroll psi.t R* d theta = -tr d theta, tr = R* (n x F_r)_z
    the rolling torque on i: U is its potential in the relative rotation (radii not needed)."""
    h = np.asarray(hist, np.float64)
    return _spring_energy(law, overlap, hist) + 0.5 * law.kroll * float(np.sum(h[:, 2:4] ** 2))


def epsd_energy(law, overlap, hist, radi, radj) -> float:
    """epsd2/epsd: kn delta^2/2 + kt |xi|^2/2 + M^2/(2 k_r) summed (J); ``radi``, ``radj`` (K,) m.

    The rolling spring of both models: M <- M_old + k_r w dt (LIG rolling_model_epsd2.h:193-199,
    rolling_model_epsd.h:282-288), i.e. M = k_r theta with theta the relative rotation since the
    contact began (or since the cap last acted), U_r = k_r theta^2/2 = M^2/(2 k_r), dU_r/d theta = M;
    k_r = kt R*^2 (epsd2.h:193) or 2.25 kn mu_r^2 R*^2 (epsd.h:282), R* = r_i r_j/(r_i + r_j),
    both constant in time. M is the stored torque (hist[:, 2], capped at mu_r R* |F_n|: the
    slider's excess is dissipated, not stored). The epsd dashpot (C w, not stored) stores
    nothing. k_r = 0 (epsd with mu_r = 0) stores nothing (M stays 0)."""
    R = radi * radj / (radi + radj)
    if isinstance(law, HookeEpsd2Liggghts):
        kr = law.kt * R * R
    else:
        kr = 2.25 * law.kn * law.mu_r * law.mu_r * R * R
    m = np.asarray(hist, np.float64)[:, 2]
    ur = np.divide(0.5 * m * m, kr, out=np.zeros_like(m), where=kr > 0)
    return _spring_energy(law, overlap, hist) + float(np.sum(ur))


# ------------------------------------------------------------------ time scale, deck lines, names
#: ``damping`` models of ``pair_style granular`` (pair_granular.cpp:849-866), by their index
DAMPING_MODELS = ("velocity", "mass_velocity", "viscoelastic", "tsuji")


def sds_timescale(law, packing, overlap=0.0):
    """(contact time, damping ratio) of :class:`HookeSdsLammps` for the two lightest disks: contact
    time pi sqrt(m*/k), k = max(KN, KT) (N/m); damping ratio c/(2 sqrt(k m*)) with c the larger of
    the normal damping DAMP eta(MODEL) (:func:`gransim.contacts.granular.damp_normal` at the
    overlap ``overlap``, m) and the tangential XGAMMAT times it."""
    meff = lightest_pair_mass(packing)
    k = max(law.kn, law.kt)
    r = np.sort(np.asarray(packing.radii, np.float64))
    reff = float(r[0] * r[1] / (r[0] + r[1]))
    a = math.sqrt(reff * max(float(overlap), 0.0))
    c = law.damp * damp_normal.py_func(law.damping, meff, a, law.kn)
    c = c * max(1.0, law.xgammat)
    return float(np.pi * np.sqrt(meff / k)), float(c / (2.0 * math.sqrt(k * meff)))


def sds_lines(law) -> list[str]:
    """LAMMPS 29 Sep 2021 ``pair_style granular`` + ``pair_coeff * * hooke KN DAMP damping MODEL
    tangential linear_history KT XGAMMAT MU rolling sds KROLL GAMMAROLL MUROLL``."""
    g = deck_float
    return [
        "pair_style granular",
        (
            f"pair_coeff * * hooke {g(law.kn)} {g(law.damp)} damping {DAMPING_MODELS[int(law.damping)]} "
            f"tangential linear_history {g(law.kt)} {g(law.xgammat)} {g(law.mu)} "
            f"rolling sds {g(law.kroll)} {g(law.gammaroll)} {g(law.muroll)}"
        ),
    ]


def _build_liggghts(cls, name):
    def build(**p):
        return cls(*(as_law_float(name, k, p[k], allow_zero=k != "kn") for k in cls._fields))

    return build


def build_sds(damping="mass_velocity", **p):
    """:class:`HookeSdsLammps` with checked values (KT and KROLL > 0: the caps divide by them)."""
    name = "hooke-sds-lammps"
    if damping not in DAMPING_MODELS:
        raise InputError(f"law {name}: damping: expected one of {', '.join(DAMPING_MODELS)}, got {damping!r}")
    keys = ("kn", "damp", "kt", "xgammat", "mu", "kroll", "gammaroll", "muroll")
    v = {k: as_law_float(name, k, p[k], allow_zero=k != "kn") for k in keys}
    for k in ("kt", "kroll"):
        if v[k] == 0.0:
            raise InputError(f"law {name}: {k}: expected a stiffness > 0 N/m (the cap divides by it), got 0")
    return HookeSdsLammps(
        v["kn"], v["damp"], float(DAMPING_MODELS.index(damping)), v["kt"], v["xgammat"], v["mu"],
        v["kroll"], v["gammaroll"], v["muroll"],
    )  # fmt: skip


for _model, _cls, _energy in (
    ("epsd2", HookeEpsd2Liggghts, epsd_energy),
    ("epsd", HookeEpsdLiggghts, epsd_energy),
    ("cdt", HookeCdtLiggghts, cdt_energy),
):
    _name = f"hooke-{_model}-liggghts"
    register_law(
        _cls,
        {"epsd2": epsd2_pair, "epsd": epsd_pair, "cdt": cdt_pair}[_model],
        HISTORY_WIDTH[_model],
        flip=HISTORY_FLIP[_model],
        energy=_energy,
        name=_name,
        code="liggghts",
        required=_cls._fields,
        build=_build_liggghts(_cls, _name),
        description=f"hooke/stiffness ... rolling_friction {_model}",
        # the normal and tangential springs of the Hooke law; the rolling spring of two equal disks
        # oscillates at sqrt(kt/(2 m*)) (epsd2) or slower (epsd, mu_r < 2/3): not the limit
        timescale=hooke_timescale,
        deck=lambda law, _m=_model: liggghts_hooke_lines(law, rolling=_m),
    )
register_law(
    HookeSdsLammps,
    sds_pair,
    HISTORY_WIDTH["sds"],
    apart=history_reset,
    flip=HISTORY_FLIP["sds"],
    energy=sds_energy,
    split_torque=True,
    name="hooke-sds-lammps",
    code="lammps",
    required=("kn", "damp", "kt", "xgammat", "mu", "kroll", "gammaroll", "muroll"),
    optional={"damping": "mass_velocity"},
    build=build_sds,
    description="granular hooke ... tangential linear_history ... rolling sds",
    timescale=sds_timescale,
    deck=sds_lines,
)
