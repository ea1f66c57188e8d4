"""Hertz-Mindlin contact with tangential history, as each code computes it: three jitted scalar laws.

* :func:`hertz_history_liggghts`: LIGGGHTS-PUBLIC 3.8.0 ``pair_style gran model hertz tangential
  history`` (material constants through ``fix property/global``; :class:`gransim.contacts.material.
  HertzLiggghts` turns them into the law's parameters);
* :func:`hertz_history_lammps`: LAMMPS 29Sep2021 ``pair_style gran/hertz/history KN KT GAMMAN
  GAMMAT MU 1`` (the Hooke coefficients scaled by sqrt(delta R*));
* :func:`hertz_mindlin_granular_lammps`: LAMMPS 29Sep2021 ``pair_style granular`` with
  ``pair_coeff * * hertz/material E DAMP NU damping MODEL tangential mindlin NULL GAMMAT MU``
  (:class:`gransim.contacts.material.HertzMaterialLammps`).

Calling convention (that of :func:`gransim.contacts.hooke.hooke_history`): the 13 pair arguments
``delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj`` (d = x_i - x_j with j possibly
a periodic image, rsq = |d|^2 < (r_i + r_j)^2: the caller tests contact; radii m, velocities m/s,
spins rad/s, masses kg), then the law's own parameters, then ``dt, s0, s1, update`` (time step s,
the stored tangential history, True in a time step and False in the set-up evaluation of a
``run``). Every law returns the same tuple ``(fx, fy, ti, tj, s0, s1, sliding, fn)``: force on i
(N; j receives minus it), torques on i and on j (N m, the same sign on both, as the codes apply
them), the updated history, whether the Coulomb cap was active, and the normal force (N).

Per-contact history: two floats (``HISTORY_WIDTH``), the tangential spring xi = (s0, s1) in m
(the codes store three; the z component stays an exact zero in 2D). Pure functions, inputs as
floats, jitted with ``gransim._numba.njit(inline="always")``: a DEM loop or a plug-in registry
calls them as it calls the Hooke law.

**2D.** Neither code has a 2D (cylinder) Hertz law. Both apply the 3D sphere-sphere law to the
disks, with R* = r_i r_j/(r_i + r_j) from the disk radii and the disks' masses m = pi r^2 rho
(LIGGGHTS' 2D density column is mass per area; LAMMPS ``set density/disc``). The forces are
therefore the 3D forces (N) between spheres of the disks' radii acting on bodies of the disks'
masses, not forces per unit thickness; no "2D" flag enters the laws (normal_model_hertz.h and
pair_granular.cpp never read ``domain->dimension``). The classical 3D impact answers apply to
the disks as they are, with m* the effective disk mass (docs/laws.md).

**Elastic normal law** (Hertz 1882; Johnson, *Contact Mechanics*, 1985, eq (4.23)):
F_n = (4/3) Y* sqrt(R*) delta^(3/2), potential U = (8/15) Y* sqrt(R*) delta^(5/2), normal
stiffness dF_n/d delta = 2 Y* sqrt(R* delta) = 2 Y* a with a = sqrt(R* delta) the contact radius.
Mindlin's tangential stiffness at the start of tangential loading (Mindlin, *J. Appl. Mech.* 16,
1949; Di Renzo & Di Maio 2004, eq (13)): k_t = 8 G* a. Both codes use exactly these (LAMMPS
through the user's KN, KT in ``gran/hertz/history``).

**As plug-ins of the DEM loop** (:mod:`gransim.contacts.laws`; history width 2, the spring xi,
flip -1): :class:`HertzHistoryLiggghts` (yeff, geff, betaeff, tdamp, mu: the arguments of
:func:`hertz_history_liggghts`; LIGGGHTS keeps a separated pair's spring),
:class:`HertzHistoryLammps` (kn, kt, gamma_n, gamma_t, mu; the spring of a separated pair is
zeroed, pair_gran_hertz_history.cpp:126-132) and :class:`HertzGranularLammps` (E, damp, kt0,
gammat_ratio, mu, damping as a float index; zeroed apart, pair_granular.cpp:283-288). Build them
by name with :func:`gransim.contacts.laws.make_law` ("hertz-liggghts", "hertz-lammps",
"hertz-granular-lammps"). Energy (the engine's balance): :func:`hertz_energy`, registered for
all three (the normal potential of each code's parametrisation; the spring energy k_t |xi|^2/2,
a potential of xi at fixed overlap only).
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
from .laws import as_law_float, deck_float, lightest_pair_mass, register_law, spring_pair
from .material import LIGGGHTS_YOUNGS_SI, HertzLiggghts, HertzMaterialLammps

#: floats of per-contact history of every law in this module (the tangential spring xi, m)
HISTORY_WIDTH = 2

#: normal_model_hertz.h:236, the literal as LIGGGHTS writes it (parsed to the nearest double)
SQRT_FIVE_OVER_SIX = 0.91287092917527685576161630466800355658790782499663875


@njit(inline="always")
def hertz_history_liggghts(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, yeff, geff, betaeff, tdamp, mu, dt, s0, s1, update
):
    """LIGGGHTS 3.8.0 ``gran model hertz tangential history`` for one touching pair.

    Parameters (after the 13 pair arguments, see the module docstring)
    ----------
    yeff : Y* (Pa), ``Yeff`` (global_properties.cpp:432).
    geff : G* (Pa), ``Geff`` (global_properties.cpp:463).
    betaeff : beta = ln e/sqrt(ln^2 e + pi^2) (< 0, 0 for e = 1; global_properties.cpp:539).
    tdamp : 1.0 with tangential damping (the default ``tangential_damping on``,
        normal_model_hertz.h:90), 0.0 without.
    mu : coefficientFriction. dt : time step (s). s0, s1 : spring xi (m). update : bool.

    Law, in the source's order (``LIG`` = LIGGGHTS-PUBLIC-3.8.0/src):
    * kinematics as ``hooke/stiffness`` (surface_model_default.h:146-203): n = d/r, v_n = v_rel.n,
      delta = r_i + r_j - r, lever arms c = r - delta/2, v_t,rel = v_t - d x (c_i w_i + c_j w_j)/r;
      m* = m_i m_j/(m_i + m_j) (pair_gran_base.h:384);
    * normal (normal_model_hertz.h:211-255): R* = r_i r_j/(r_i + r_j), a = sqrt(R* delta),
      S_n = 2 Y* a, S_t = 8 G* a, k_n = 4/3 Y* a, k_t = S_t,
      gamma_n = -2 sqrt(5/6) beta sqrt(S_n m*), gamma_t = -2 sqrt(5/6) beta sqrt(S_t m*) (both
      in kg/s: damping coefficients, not mass-scaled rates as in ``hooke/stiffness``),
      F_n = k_n delta - gamma_n v_n (no force limit: may be attractive);
    * tangential (tangential_model_history.h:147-227): in a step xi += v_t,rel dt, then
      xi -= (xi.n) n (projection without rescaling); F_t = -k_t xi; when k_t|xi| > mu|F_n|
      (strictly) F_t is scaled to mu|F_n| (no damping) and, in a step, xi = -F_t/k_t; otherwise
      F_t -= gamma_t v_t,rel. k_t follows the current overlap: xi is *not* rescaled when delta
      changes, so F_t = -k_t(delta) xi (not Mindlin's incremental dF_t = -k_t(delta) d xi);
    * torques -c_i (n x F_t)_z on i and -c_j (n x F_t)_z on j (tangential_model_history.h:230-261).

    Returns ``(fx, fy, ti, tj, s0, s1, sliding, fn)`` (module docstring).
    """
    r = math.sqrt(rsq)
    rinv = 1.0 / r
    enx = delx * rinv
    eny = dely * rinv
    meff = mi * mj / (mi + mj)
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
    # normal_model_hertz.h:211-255
    reff = radi * radj / (radi + radj)
    sqrtval = math.sqrt(reff * deltan)
    Sn = 2.0 * yeff * sqrtval
    St = 8.0 * geff * sqrtval
    kn = 4.0 / 3.0 * yeff * sqrtval
    kt = St
    gamman = -2.0 * SQRT_FIVE_OVER_SIX * betaeff * math.sqrt(Sn * meff)
    gammat = 0.0
    if tdamp != 0.0:
        gammat = -2.0 * SQRT_FIVE_OVER_SIX * betaeff * math.sqrt(St * meff)
    fn = -gamman * vn + kn * deltan
    # tangential_model_history.h:147-227
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
            if update:
                s0 = -ft1 / kt
                s1 = -ft2 / kt
        else:
            ft1 = 0.0
            ft2 = 0.0
    else:
        ft1 -= gammat * vtr1
        ft2 -= gammat * vtr2
    tor3 = enx * ft2 - eny * ft1
    fx = fn * enx + ft1
    fy = fn * eny + ft2
    return fx, fy, -cri * tor3, -crj * tor3, s0, s1, sliding, fn


@njit(inline="always")
def hertz_history_lammps(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """LAMMPS 29Sep2021 ``pair_style gran/hertz/history KN KT GAMMAN GAMMAT MU 1`` for one pair.

    Parameters: as :func:`gransim.contacts.hooke.hooke_history_lammps` (kn in N/m^2 = Pa: the
    Hertz coefficient, F_n = kn delta sqrt(R* delta); kt in Pa; gamman, gammat mass-scaled
    damping per unit sqrt(R* delta): 1/(s m); mu). ``KT NULL`` means 2/7 KN and ``GAMMAT NULL``
    GAMMAN/2 in the deck (pair_gran_hertz_history.cpp:285-290); pass the numbers here.

    Law (``pghh`` = src/GRANULAR/pair_gran_hertz_history.cpp), the Hooke history law of
    ``gran/hooke/history`` with both its normal and its tangential force multiplied by
    p = sqrt(delta r_i r_j/(r_i + r_j)) (``polyhertz``, pghh:183):
    * ccel = p (kn delta/r - m* gamman (v.d)/r^2) (pghh:181-184), force d ccel, F_n = ccel r:
      F_n = kn sqrt(R*) delta^(3/2) - m* gamman sqrt(R* delta) v_n, so KN = 4/3 Y* gives
      LIGGGHTS' elastic force and the damping is proportional to m* a, not to sqrt(m* S_n);
    * v_t,rel with the full radii as lever arms: wr = (r_i w_i + r_j w_j)/r (pghh:160-162, 189-191);
    * in a step xi += v_t,rel dt; |xi| taken before the projection xi -= ((xi.d)/r^2) d
      (pghh:199-215);
    * F_t = -p (kt xi + m* gammat v_t,rel) (pghh:219-221): KT = 8 G* gives Mindlin's 8 G* a, and
      the spring, as in LIGGGHTS, is not rescaled when delta changes;
    * cap with spring + damping: |F_t| > mu|F_n| and |xi| != 0: xi = (mu|F_n|/|F_t|)(xi +
      m* gammat v/kt) - m* gammat v/kt, F_t scaled (pghh:225-240; the cap applies in the set-up
      call too);
    * torques -r_i (d x F_t)_z/r on i, -r_j (d x F_t)_z/r on j (pghh:251-264).

    Returns ``(fx, fy, ti, tj, s0, s1, sliding, fn)``, fn = ccel r (N).
    """
    r = math.sqrt(rsq)
    rinv = 1.0 / r
    rsqinv = 1.0 / rsq
    vr1 = vix - vjx
    vr2 = viy - vjy
    vnnr = vr1 * delx + vr2 * dely
    vn1 = delx * vnnr * rsqinv
    vn2 = dely * vnnr * rsqinv
    vt1 = vr1 - vn1
    vt2 = vr2 - vn2
    wr3 = (radi * wi + radj * wj) * rinv
    meff = mi * mj / (mi + mj)
    radsum = radi + radj
    damp = meff * gamman * vnnr * rsqinv
    ccel = kn * (radsum - r) * rinv - damp
    polyhertz = math.sqrt((radsum - r) * radi * radj / radsum)
    ccel *= polyhertz
    vtr1 = vt1 + dely * wr3  # vt1 - (delz wr2 - dely wr3), delz = wr2 = 0
    vtr2 = vt2 - delx * wr3  # vt2 - (delx wr3 - delz wr1)
    if update:
        s0 += vtr1 * dt
        s1 += vtr2 * dt
    shrmag = math.sqrt(s0 * s0 + s1 * s1)
    rsht = (s0 * delx + s1 * dely) * rsqinv
    if update:
        s0 -= rsht * delx
        s1 -= rsht * dely
    fs1 = -polyhertz * (kt * s0 + meff * gammat * vtr1)
    fs2 = -polyhertz * (kt * s1 + meff * gammat * vtr2)
    fs = math.sqrt(fs1 * fs1 + fs2 * fs2)
    fn = mu * abs(ccel * r)
    sliding = False
    if fs > fn:
        sliding = True
        if shrmag != 0.0:
            s0 = (fn / fs) * (s0 + meff * gammat * vtr1 / kt) - meff * gammat * vtr1 / kt
            s1 = (fn / fs) * (s1 + meff * gammat * vtr2 / kt) - meff * gammat * vtr2 / kt
            fs1 *= fn / fs
            fs2 *= fn / fs
        else:
            fs1 = 0.0
            fs2 = 0.0
    fx = delx * ccel + fs1
    fy = dely * ccel + fs2
    tor3 = rinv * (delx * fs2 - dely * fs1)
    return fx, fy, -(radi * tor3), -(radj * tor3), s0, s1, sliding, ccel * r


@njit(inline="always")
def hertz_mindlin_granular_lammps(
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
    E,
    damp,
    kt0,
    gammat_ratio,
    mu,
    damping,
    dt,
    s0,
    s1,
    update,
):
    """LAMMPS 29Sep2021 ``pair_style granular``, ``hertz/material E DAMP NU damping MODEL
    tangential mindlin NULL GAMMAT MU`` (no rolling, no twisting, no ``limit_damping``).

    Parameters (after the 13 pair arguments)
    ----------
    E : 4/3 Y* (Pa): pair_granular.cpp:1009-1011 stores ``FOURTHIRDS*mix_stiffnessE``.
    damp : the damping coefficient; for ``damping tsuji`` alpha(e) of
        :func:`gransim.contacts.material.tsuji_alpha_lammps` (pair_granular.cpp:987-992).
    kt0 : 8 G* (Pa) (``tangential mindlin NULL``, pair_granular.cpp:1021-1023).
    gammat_ratio : the tangential GAMMAT, a multiple of the normal damping prefactor.
    mu : friction coefficient. damping : one of ``DAMPING_*`` (0 velocity, 1 mass_velocity,
        2 viscoelastic, 3 tsuji). dt, s0, s1, update : as the other laws (``update`` False:
        ``historyupdate`` false in the set-up, pair_granular.cpp:191).

    Law (``pgr`` = src/GRANULAR/pair_granular.cpp):
    * n = d/r, v_n = v_rel.n (pgr:290-308), R* = r_i r_j/(r_i + r_j) (pgr:263), delta = R - r,
      a = sqrt(delta R*) (pgr:325-326, 351), F_ne = E delta a = 4/3 Y* sqrt(R*) delta^(3/2),
      k_nfac = E a (pgr:349-355);
    * damping prefactor eta (pgr:363-373): velocity 1, mass_velocity m*, viscoelastic a m*,
      tsuji sqrt(m* E a) = sqrt(m* 4/3 Y* a), times ``damp``; F_n = F_ne - eta v_n (pgr:374-376);
      Fscrit = mu |F_n| (pgr:419-421);
    * tangential (pgr:390-533): v_t,rel = v_t - n x (r_i w_i + r_j w_j) (full radii, no 1/r);
      k_t = 8 G* a, damping GAMMAT eta; in a step, *first* the frame update: when
      |xi.n| k_t > 1e-10 Fscrit, xi is projected on the tangent plane and rescaled to its old
      length (pgr:449-473), *then* xi += v_t,rel dt (pgr:479-481); F_t = -k_t xi - GAMMAT eta
      v_t,rel (pgr:499-501); when |F_t| > Fscrit (strictly) and |xi| != 0:
      xi = -(Fscrit F_t/|F_t| + GAMMAT eta v_t,rel)/k_t and F_t scaled to Fscrit (pgr:509-532);
      no rescaling of xi when delta changes (that is ``mindlin_rescale``, pgr:434-446);
    * torques -(r_i - delta/2)(n x F_t)_z on i and -(r_j - delta/2)(n x F_t)_z on j
      (pgr:659-666, 693-696).

    ``damping tsuji`` has LIGGGHTS' form (damping coefficient proportional to sqrt(m* S_n), so
    delta^(1/4)); LIGGGHTS' gamma_n = -2 sqrt(5/6) beta sqrt(2 Y* a m*) equals eta of tsuji
    with damp = -sqrt(5) beta exactly in the real numbers (not bit for bit: other operations).
    Returns ``(fx, fy, ti, tj, s0, s1, sliding, fn)``, fn = F_ne + F_damp (N).
    """
    nx, ny, vnnr, meff, _, delta, a, vtr1, vtr2 = granular_geometry(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj
    )
    knfac = E
    Fne = knfac * delta
    Fne *= a
    knfac *= a
    damp_normal_prefactor = damp * damp_normal(damping, meff, a, knfac)
    Fdamp = -damp_normal_prefactor * vnnr
    Fntot = Fne + Fdamp
    Fncrit = abs(Fntot)
    Fscrit = mu * Fncrit
    k_tangential = kt0
    damp_tangential = gammat_ratio * damp_normal_prefactor
    k_tangential *= a
    s0, s1, fs1, fs2, sliding = spring_dashpot_slider(
        s0, s1, nx, ny, vtr1, vtr2, k_tangential, damp_tangential, Fscrit, dt, update
    )
    fx, fy, ti, tj = granular_forces(nx, ny, Fntot, fs1, fs2, radi, radj, delta)
    return fx, fy, ti, tj, s0, s1, sliding, Fntot


def elastic_normal_force(delta, reff, yeff):
    """F_n = 4/3 Y* sqrt(R*) delta^(3/2) (N) for delta > 0, else 0 (Johnson 1985, eq (4.23))."""
    if delta <= 0.0:
        return 0.0
    return 4.0 / 3.0 * yeff * math.sqrt(reff) * delta**1.5


def elastic_normal_potential(delta, reff, yeff):
    """U = 8/15 Y* sqrt(R*) delta^(5/2) (J), dU/d delta = :func:`elastic_normal_force`."""
    if delta <= 0.0:
        return 0.0
    return 8.0 / 15.0 * yeff * math.sqrt(reff) * delta**2.5


# ----------------------------------------------------------------------------- plug-ins
#: LIGGGHTS ``gran model hertz tangential history``: Y*, G* (Pa), beta (-), tangential damping
#: flag (1.0/0.0), mu (-) (:func:`hertz_history_liggghts`)
#: and the material constants its deck lines give the code (E (Pa), nu, e; NaN: built from the
#: coefficients alone, no deck)
HertzHistoryLiggghts = namedtuple(
    "HertzHistoryLiggghts",
    ["yeff", "geff", "betaeff", "tdamp", "mu", "youngs_modulus", "poisson_ratio", "restitution"],
    defaults=(math.nan,) * 3,
)
#: LAMMPS ``gran/hertz/history KN KT GAMMAN GAMMAT MU 1``: kn, kt (Pa), gamma_n, gamma_t
#: (1/(s m)), mu (:func:`hertz_history_lammps`)
HertzHistoryLammps = namedtuple("HertzHistoryLammps", ["kn", "kt", "gamma_n", "gamma_t", "mu"])
#: LAMMPS ``granular hertz/material ... tangential mindlin NULL``: E = 4/3 Y* (Pa), damp, kt0 =
#: 8 G* (Pa), gammat_ratio, mu, damping (model index as a float, ``DAMPING_*``)
#: (:func:`hertz_mindlin_granular_lammps`)
#: and the deck's E (Pa), NU and DAMP as given (tsuji: the restitution; NaN: no deck)
HertzGranularLammps = namedtuple(
    "HertzGranularLammps",
    ["E", "damp", "kt0", "gammat_ratio", "mu", "damping", "youngs_modulus", "poisson_ratio", "damp_given"],
    defaults=(math.nan,) * 3,
)


#: pair functions of the Hertz laws (:func:`gransim.contacts.laws.spring_pair`: the spring in
#: ``hist[e, 0:2]``): LIGGGHTS' with yeff, geff, betaeff, tdamp, mu; LAMMPS' gran/hertz/history with
#: kn, kt, gamma_n, gamma_t, mu; LAMMPS' granular hertz/material with E, damp, kt0, gammat_ratio,
#: mu, damping (the namedtuples' first fields, in the order of the functions' parameters)
hertz_pair_liggghts = spring_pair(hertz_history_liggghts, 5)
hertz_pair_lammps = spring_pair(hertz_history_lammps, 5)
hertz_pair_granular_lammps = spring_pair(hertz_mindlin_granular_lammps, 6)


@njit(inline="always")
def history_reset(law, hist, e):
    """LAMMPS: a pair that does not touch has its whole history zeroed
    (pair_gran_hertz_history.cpp:126-132, pair_granular.cpp:283-288)."""
    for k in range(hist.shape[1]):
        hist[e, k] = 0.0


def hertz_coefficients(law):
    """(c_n, c_t) of a Hertz law object: its elastic normal force is F_n = c_n sqrt(R*) delta^(3/2)
    and its tangential spring stiffness k_t = c_t sqrt(R* delta), each in the code's own
    parametrisation (Pa):

    * :class:`HertzHistoryLiggghts`: k_n = 4/3 Y* sqrt(R* delta), F_n = k_n delta, k_t = S_t =
      8 G* sqrt(R* delta) (LIG normal_model_hertz.h:221, 232-235, 255), so c_n = 4/3 Y*, c_t = 8 G*;
    * :class:`HertzHistoryLammps`: F_n = ccel r = KN delta sqrt(R* delta) (polyhertz, LMP
      GRANULAR/pair_gran_hertz_history.cpp:182-184), F_t = -polyhertz KT xi (:219-221):
      c_n = KN, c_t = KT;
    * :class:`HertzGranularLammps`: F_ne = E delta a, k_t = kt0 a, a = sqrt(R* delta) (LMP
      GRANULAR/pair_granular.cpp:326, 349-354, 426-433): c_n = E (= 4/3 Y*), c_t = kt0 (= 8 G*).
    """
    if isinstance(law, HertzHistoryLiggghts):
        return 4.0 / 3.0 * law.yeff, 8.0 * law.geff
    if isinstance(law, HertzHistoryLammps):
        return law.kn, law.kt
    if isinstance(law, HertzGranularLammps):
        return law.E, law.kt0

    raise InputError(
        "law: expected a Hertz law (HertzHistoryLiggghts, HertzHistoryLammps, "
        f"HertzGranularLammps), got {type(law).__name__}"
    )


def hertz_energy(law, overlap, hist, radi, radj) -> float:
    """Elastic energy (J) of K touching Hertz contacts (the law's registered ``energy``).

    ``overlap`` (K,) m, ``hist`` (K, 2) the tangential springs xi (m), ``radi``, ``radj`` (K,) m.
    With the coefficients of :func:`hertz_coefficients` (c_n, c_t) and R* = r_i r_j/(r_i + r_j):

    * normal: U_n = integral_0^delta F_n d delta' = 2/5 c_n sqrt(R*) delta^(5/2) (= 8/15 Y*
      sqrt(R*) delta^(5/2) for c_n = 4/3 Y*; Johnson 1985, eq (4.23)): dU_n/d delta is the
      elastic normal force of each code exactly (its k_n(delta) delta);
    * tangential: U_t = k_t(delta) |xi|^2 / 2, k_t = c_t sqrt(R* delta) (Mindlin 1949): -dU_t/dxi
      is the code's spring force -k_t(delta) xi below the Coulomb cap. It is a potential of xi at
      fixed delta only: neither code rescales xi when delta changes (LIGGGHTS
      tangential_model_history.h:147-171, LAMMPS pair_gran_hertz_history.cpp:199-221 and
      pair_granular.cpp without ``mindlin_rescale``), so along a path with a changing overlap the
      work of F_t is not the change of U_t (the difference d U_t = |xi|^2/2 dk_t is neither
      stored nor dissipated by the law). Frictionless contacts keep xi = 0 and are exact.
    """
    d = np.asarray(overlap, np.float64)
    R = radi * radj / (radi + radj)
    cn, ct = hertz_coefficients(law)
    un = 0.4 * cn * np.sqrt(R) * d**2.5
    ut = 0.5 * ct * np.sqrt(R * d) * np.sum(np.asarray(hist, np.float64)[:, :2] ** 2, axis=1)
    return float(np.sum(un) + np.sum(ut))


# ------------------------------------------------------------------ time scale, deck lines, names
def _lightest_pair(packing):
    """(m*, R*) of the two lightest disks (kg, m): the highest frequency sqrt(k/m*) of a Hertz
    contact, whose stiffness grows as sqrt(R*) while m* grows as R*^2 (2D masses pi r^2 rho)."""
    r = np.sort(np.asarray(packing.radii, np.float64))
    return lightest_pair_mass(packing), float(r[0] * r[1] / (r[0] + r[1]))


def hertz_timescale(law, packing, overlap=0.0):
    """(contact time, damping ratio) of the two lightest disks at the overlap ``overlap`` (m), the
    largest present: the tangent stiffnesses k_n = dF_n/d delta = 3/2 c_n a and k_t = c_t a
    (a = sqrt(R* delta), c_n, c_t of :func:`hertz_coefficients`; Johnson 1985, eq (4.23)
    differentiated), k = max(k_n, k_t), contact time pi sqrt(m*/k) of the linearised contact;
    damping ratio c/(2 sqrt(k m*)) of the larger damping coefficient c of the law at that overlap
    (LIGGGHTS: sqrt(5/6) |beta| for both, normal_model_hertz.h:231-238; gran/hertz/history: m* GN a,
    m* GT a; granular: DAMP times the prefactor of its damping model, GAMMAT times that). No
    overlap (inf, 0): a Hertz contact has no stiffness at zero overlap, the check then has nothing
    to bound (the divergence check of the engine still watches the run)."""
    if not overlap > 0.0:
        return math.inf, 0.0
    meff, reff = _lightest_pair(packing)
    a = math.sqrt(reff * overlap)
    cn, ct = hertz_coefficients(law)
    k = max(1.5 * cn * a, ct * a)
    if isinstance(law, HertzHistoryLiggghts):
        zeta = SQRT_FIVE_OVER_SIX * abs(law.betaeff)
    else:
        if isinstance(law, HertzHistoryLammps):
            c = meff * max(law.gamma_n, law.gamma_t) * a
        else:
            eta = law.damp * damp_normal.py_func(law.damping, meff, a, law.E * a)
            c = eta * max(1.0, law.gammat_ratio)
        zeta = c / (2.0 * math.sqrt(k * meff))
    return math.pi * math.sqrt(meff / k), float(zeta)


def hertz_liggghts_lines(law) -> list[str]:
    """LIGGGHTS 3.8.0 ``gran model hertz tangential history`` with the material constants of the
    law (youngsModulus, poissonsRatio per type; coefficientRestitution, coefficientFriction per
    type pair); ``soft_particles``/``hard_particles`` for a modulus outside 5e6..1e9 Pa (LIGGGHTS
    refuses it otherwise, docs/liggghts.md), ``tangential_damping off`` when the flag is 0."""
    E, nu, e = law.youngs_modulus, law.poisson_ratio, law.restitution
    if not (math.isfinite(E) and math.isfinite(nu) and math.isfinite(e)):
        raise InputError(
            "law: a LIGGGHTS Hertz law for a deck needs its material constants (build it by name: "
            "make_law('hertz-liggghts', youngs_modulus=..., poisson_ratio=..., restitution=..., friction=...))"
        )
    prop = "fix m{} all property/global {} peratomtypepair 1 {}"
    lines = [
        f"fix m1 all property/global youngsModulus peratomtype {deck_float(E)}",
        f"fix m2 all property/global poissonsRatio peratomtype {deck_float(nu)}",
        prop.format(3, "coefficientRestitution", deck_float(e)),
        prop.format(4, "coefficientFriction", deck_float(law.mu)),
    ]
    lo, hi = LIGGGHTS_YOUNGS_SI
    if not lo <= E <= hi:
        lines.insert(0, "soft_particles yes" if E < lo else "hard_particles yes")
    tang = "" if law.tdamp else " tangential_damping off"
    return lines + [f"pair_style gran model hertz tangential history{tang}", "pair_coeff * *"]


def hertz_lammps_lines(law) -> list[str]:
    """LAMMPS 29 Sep 2021 ``pair_style gran/hertz/history KN KT GAMMAN GAMMAT MU 1``."""
    v = " ".join(deck_float(getattr(law, k)) for k in ("kn", "kt", "gamma_n", "gamma_t", "mu"))
    return [f"pair_style gran/hertz/history {v} 1", "pair_coeff * *"]


def hertz_granular_lines(law) -> list[str]:
    """LAMMPS 29 Sep 2021 ``pair_style granular`` + ``pair_coeff * * hertz/material E DAMP NU
    damping MODEL tangential mindlin NULL GAMMAT MU`` with the constants the law was built from."""
    E, nu, damp = law.youngs_modulus, law.poisson_ratio, law.damp_given
    if not (math.isfinite(E) and math.isfinite(nu) and math.isfinite(damp)):
        raise InputError(
            "law: a LAMMPS granular Hertz law for a deck needs its material constants (build it by name: "
            "make_law('hertz-granular-lammps', youngs_modulus=..., poisson_ratio=..., damp=..., friction=...))"
        )
    model = HertzMaterialLammps.DAMPING_MODELS[int(law.damping)]
    return [
        "pair_style granular",
        (
            f"pair_coeff * * hertz/material {deck_float(E)} {deck_float(damp)} {deck_float(nu)} damping "
            f"{model} tangential mindlin NULL {deck_float(law.gammat_ratio)} {deck_float(law.mu)}"
        ),
    ]


def build_hertz_liggghts(youngs_modulus, poisson_ratio, restitution, friction, tangential_damping=True):
    """:class:`HertzHistoryLiggghts` of the material constants (checked by
    :class:`gransim.contacts.material.HertzLiggghts`)."""
    m = HertzLiggghts(youngs_modulus, poisson_ratio, restitution, friction, tangential_damping=tangential_damping)
    return HertzHistoryLiggghts(*m.coefficients(), m.youngs_modulus, m.poisson_ratio, m.restitution)


def build_hertz_lammps(**p):
    """:class:`HertzHistoryLammps` of KN, KT (Pa, > 0 resp. >= 0), GAMMAN, GAMMAT (1/(s m)), MU."""
    name = "hertz-lammps"
    return HertzHistoryLammps(
        *(as_law_float(name, k, p[k], allow_zero=k != "kn") for k in ("kn", "kt", "gamma_n", "gamma_t", "mu"))
    )


def build_hertz_granular(youngs_modulus, poisson_ratio, damp, friction, gammat_ratio=1.0, damping="tsuji"):
    """:class:`HertzGranularLammps` of the material constants (checked by
    :class:`gransim.contacts.material.HertzMaterialLammps`)."""
    m = HertzMaterialLammps(youngs_modulus, poisson_ratio, damp, friction, gammat_ratio=gammat_ratio, damping=damping)
    E, d, kt0, g, mu, idx = m.coefficients()
    return HertzGranularLammps(E, d, kt0, g, mu, float(idx), m.youngs_modulus, m.poisson_ratio, m.damp)


register_law(
    HertzHistoryLiggghts,
    hertz_pair_liggghts,
    HISTORY_WIDTH,
    energy=hertz_energy,
    name="hertz-liggghts",
    code="liggghts",
    required=("youngs_modulus", "poisson_ratio", "restitution", "friction"),
    optional={"tangential_damping": True},
    build=build_hertz_liggghts,
    description="gran model hertz tangential history",
    timescale=hertz_timescale,
    deck=hertz_liggghts_lines,
)
register_law(
    HertzHistoryLammps,
    hertz_pair_lammps,
    HISTORY_WIDTH,
    apart=history_reset,
    energy=hertz_energy,
    name="hertz-lammps",
    code="lammps",
    required=("kn", "kt", "gamma_n", "gamma_t", "mu"),
    build=build_hertz_lammps,
    description="gran/hertz/history KN KT GAMMAN GAMMAT MU 1",
    timescale=hertz_timescale,
    deck=hertz_lammps_lines,
)
register_law(
    HertzGranularLammps,
    hertz_pair_granular_lammps,
    HISTORY_WIDTH,
    apart=history_reset,
    energy=hertz_energy,
    name="hertz-granular-lammps",
    code="lammps",
    required=("youngs_modulus", "poisson_ratio", "damp", "friction"),
    optional={"gammat_ratio": 1.0, "damping": "tsuji"},
    build=build_hertz_granular,
    description="granular hertz/material E DAMP NU damping MODEL tangential mindlin NULL",
    timescale=hertz_timescale,
    deck=hertz_granular_lines,
)
