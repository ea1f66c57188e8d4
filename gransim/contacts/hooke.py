"""LIGGGHTS ``hooke/stiffness`` normal law with ``tangential history`` and the same pair in LAMMPS'
``gran/hooke/history`` arithmetic, each in two forms: with the code's branches, for one touching
pair (:func:`hooke_history`, :func:`hooke_history_lammps`: the entry-by-entry loops, the rolling
laws) and branch-free, for any list entry (:func:`hooke_liggghts`, :func:`hooke_lammps`: the block
path of the SIMD loops, :func:`hooke_select_liggghts`, :func:`hooke_select_lammps`, and the fast
path). The two forms are the same operations on the path the code takes (held equal entry by
entry by tests/dem/test_simd_bitwise.py); the branch-free one computes both arms of every branch.

The elastic part of the normal force is :func:`gransim.contacts.law.force_magnitude`
(eq (5) of Meier et al.: F = E_n eps with E_n = kn); this module adds what the DEM needs:
mass-scaled viscous damping, the incremental tangential spring and the Coulomb cap, in the
exact floating-point order of LIGGGHTS-PUBLIC 3.8.0 (surface_model_default.h,
normal_model_hooke_stiffness.h, tangential_model_history.h; docs/liggghts.md).

Conventions (2D, all SI): the pair is (i, j) with d = x_i - x_j (j possibly a periodic image),
n = d/|d| pointing from j to i, overlap delta = r_i + r_j - |d| > 0. Forces returned act on i;
j receives minus the force (and its own torque, of the same sign, see below).

As plug-ins of the DEM loop (:mod:`gransim.contacts.laws`), this module declares the laws
"hooke-liggghts" (:class:`HookeLiggghts`) and "hooke-lammps" (:class:`HookeLammps`) whole:
parameters kn, kt, gamma_n, gamma_t, mu; history width 2 (the spring xi); the scalar pair
function and its branch-free twin (the block path of the force loops); the contact time and
damping ratio of the time-step check; the elastic energy; the deck lines of each code.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._numba import njit
from .._validate import as_positive_float
from ..errors import InputError
from .law import force_magnitude
from .laws import deck_float, lightest_pair_mass, register_law, spring_pair, spring_select


@njit(inline="always")
def hooke_liggghts(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """LIGGGHTS 3.8.0 ``hooke/stiffness`` + ``tangential history`` for one list entry, touching
    or not, branch-free, the one copy of the law in LIGGGHTS' arithmetic (:func:`hooke_select_liggghts`
    the block path of the SIMD force loops and the fast path's law; :func:`hooke_history` the
    entry-by-entry loops' convention;
    surface_model_default.h, normal_model_hooke_stiffness.h, tangential_model_history.h).

    Written without a data-dependent jump: the branches of the code (contact, the sign test of
    ``force_magnitude``, the Coulomb cap, a zero spring) are selects between values that are all
    computed, so a loop over list entries calling it runs as SIMD code and every lane gives the
    bits of the code's scalar arithmetic on the path the code takes (IEEE square root and division,
    no fused multiply-add: ``fastmath`` is off, gransim/_numba.py). What a select throws away may
    be inf or nan (a zero spring's ratio); it never reaches a result.

    Parameters
    ----------
    delx, dely : float, m. d = x_i - x_j (image of j). rsq : |d|^2 (m^2).
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
    (touch, fx, fy, ti, tj, s0, s1, sliding, overlap, fn): touch 1.0 when rsq < (r_i + r_j)^2
    (the loops' contact test) else 0.0, sliding 1.0 or 0.0 (floats, not bools: a bool taken out
    of a returned tuple counts as an alias to numba's parfor analysis and keeps the caller's loop
    from vectorising). When touching: force on i F = F_n n + F_t (N) with F_n = kn delta - m_eff
    gamman v_n (may be attractive: no force limit) and F_t = -kt xi - m_eff gammat v_t,rel, or,
    when kt |xi| > mu |F_n| (strictly), F_t = -kt xi mu|F_n|/(kt|xi|) and, in a step, xi = -F_t/kt;
    torques on i and j -c_i (n x F_t)_z and -c_j (n x F_t)_z, c = r - delta/2 (the same sign on
    both, as LIGGGHTS applies them); the updated spring; F_n (N). Not touching: the stored spring
    (LIGGGHTS keeps a spring while its pair is in the list), the other values meaningless.
    overlap r_i + r_j - |d| (m) in either case.
    """
    radsum = radi + radj
    touch = rsq < radsum * radsum
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
    deltan = radsum - r
    cri = radi - 0.5 * deltan
    crj = radj - 0.5 * deltan
    wr3 = (cri * wi + crj * wj) * rinv
    vtr1 = vt1 + dely * wr3
    vtr2 = vt2 - delx * wr3
    # the elastic normal force, eq (5) of Meier et al. (gransim.contacts.law: the RVE's law too)
    fe = force_magnitude(radsum - r, kn)
    fn = -(meff * gamman) * vn + fe
    if update:  # uniform over a loop (False only in the set-up evaluation)
        u0 = s0 + vtr1 * dt
        u1 = s1 + vtr2 * dt
        rsht = u0 * enx + u1 * eny
        u0 -= rsht * enx
        u1 -= rsht * eny
    else:
        u0 = s0
        u1 = s1
    shrmag = math.sqrt(u0 * u0 + u1 * u1)
    ft1 = -(kt * u0)
    ft2 = -(kt * u1)
    ft_shear = kt * shrmag
    ft_friction = mu * abs(fn)
    sl = ft_shear > ft_friction
    nz = shrmag != 0.0
    ratio = ft_friction / ft_shear
    ft1c = ft1 * ratio
    ft2c = ft2 * ratio
    gt = meff * gammat
    ft1d = ft1 - gt * vtr1
    ft2d = ft2 - gt * vtr2
    z1 = ft1c if nz else 0.0
    z2 = ft2c if nz else 0.0
    ft1 = z1 if sl else ft1d
    ft2 = z2 if sl else ft2d
    # every value computed before the selects (an expensive operation inside a conditional arm
    # stays a branch, which stops the vectoriser); & not `and` (no short circuit)
    # the capped spring is written back only in a step: LIGGGHTS 3.8.0 guards the write with
    # `if (update_history)` (tangential_model_history.h:195-200); a set-up evaluation (a further
    # `run`) leaves every spring as it was
    capped = sl & nz & update
    # the quotient of a select (the capped force where the spring is capped, 1.0 elsewhere, where
    # the select below throws the quotient away): the same bits as -ft1c / kt. Written so, LLVM
    # orders the SIMD block loop of gransim.dem.fast_kernels.forces_v differently (the same
    # instructions) and it runs 1.24x faster (docs/performance.md, "Scheduling of the block loop")
    k0 = -(ft1c if capped else 1.0) / kt
    k1 = -(ft2c if capped else 1.0) / kt
    u0 = k0 if capped else u0
    u1 = k1 if capped else u1
    tor3 = enx * ft2 - eny * ft1
    fx = fn * enx + ft1
    fy = fn * eny + ft2
    return (
        1.0 if touch else 0.0,
        fx,
        fy,
        -cri * tor3,
        -crj * tor3,
        u0 if touch else s0,
        u1 if touch else s1,
        1.0 if sl else 0.0,
        deltan,
        fn,
    )


@njit(inline="always")
def hooke_lammps(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """LAMMPS 29 Sep 2021 ``pair_style gran/hooke/history`` for one list entry, touching or not,
    branch-free as :func:`hooke_liggghts` (the same arguments; :func:`hooke_select_lammps` the
    block path, :func:`hooke_history_lammps` the entry-by-entry loops' convention).

    The law and the floating-point order are those of LAMMPS' ``PairGranHookeHistory::compute``
    (src/GRANULAR/pair_gran_hooke_history.cpp, docs/lammps.md) restricted to 2D (z components are
    zero there and drop out exactly). What differs from LIGGGHTS' ``hooke/stiffness`` +
    ``tangential history``:

    * normal force per unit branch length: ccel = kn (r_i + r_j - r)/r - m_eff gamman (v.d)/r^2,
      force d ccel, so F_n = ccel r (the same value up to round-off);
    * relative tangential velocity with the full radii as lever arms:
      v_t,rel = v_t + d x (r_i w_i + r_j w_j)/r (LIGGGHTS: r - delta/2);
    * spring update xi += v_t,rel dt, |xi| taken *before* the projection
      xi -= ((xi.d)/r^2) d;
    * the Coulomb cap compares the whole tangential force, spring *and* damping,
      F_t = -(kt xi + m_eff gammat v_t,rel), with mu |F_n|: when |F_t| > mu |F_n| (strictly) and
      |xi| != 0, F_t is scaled by mu|F_n|/|F_t| and the spring set to
      xi = (mu|F_n|/|F_t|)(xi + m_eff gammat v_t,rel/kt) - m_eff gammat v_t,rel/kt
      (so that -(kt xi + m_eff gammat v_t,rel) is the capped force); |xi| = 0: F_t = 0;
    * torques -r_i (d x F_t)_z/r on i and -r_j (d x F_t)_z/r on j (full radii, same sign);
    * a pair that does not touch has its spring reset to zero (so returned when not touching; the
      entry-by-entry loops call :func:`spring_reset`); ``update`` False is LAMMPS' set-up
      evaluation (``shearupdate = 0``: no increment and no projection; the cap still applies).

    Returns (touch, fx, fy, ti, tj, s0, s1, sliding, overlap, fn) as :func:`hooke_liggghts`, fn =
    ccel r (N).
    """
    radsum = radi + radj
    touch = rsq < radsum * radsum
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
    damp = meff * gamman * vnnr * rsqinv
    ccel = kn * ((radi + radj) - r) * rinv - damp
    vtr1 = vt1 + dely * wr3
    vtr2 = vt2 - delx * wr3
    if update:
        u0 = s0 + vtr1 * dt
        u1 = s1 + vtr2 * dt
    else:
        u0 = s0
        u1 = s1
    shrmag = math.sqrt(u0 * u0 + u1 * u1)
    rsht = (u0 * delx + u1 * dely) * rsqinv
    if update:
        u0 -= rsht * delx
        u1 -= rsht * dely
    gt = meff * gammat
    fs1 = -(kt * u0 + gt * vtr1)
    fs2 = -(kt * u1 + gt * vtr2)
    fs = math.sqrt(fs1 * fs1 + fs2 * fs2)
    fn = mu * abs(ccel * r)
    sl = fs > fn
    nz = shrmag != 0.0
    q = fn / fs
    capped = sl & nz
    c0 = q * (u0 + gt * vtr1 / kt) - gt * vtr1 / kt
    c1 = q * (u1 + gt * vtr2 / kt) - gt * vtr2 / kt
    u0 = c0 if capped else u0
    u1 = c1 if capped else u1
    fq1 = fs1 * q
    fq2 = fs2 * q
    z1 = fq1 if nz else 0.0
    z2 = fq2 if nz else 0.0
    fs1 = z1 if sl else fs1
    fs2 = z2 if sl else fs2
    fx = delx * ccel + fs1
    fy = dely * ccel + fs2
    tor3 = rinv * (delx * fs2 - dely * fs1)
    return (
        1.0 if touch else 0.0,
        fx,
        fy,
        -(radi * tor3),
        -(radj * tor3),
        u0 if touch else 0.0,
        u1 if touch else 0.0,
        1.0 if sl else 0.0,
        radsum - r,
        ccel * r,
    )


@njit(inline="always")
def hooke_select_liggghts(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """:func:`hooke_liggghts` as the block path: (touch, fx, fy, ti, tj, s0, s1, sliding, overlap)."""
    t, fx, fy, ti, tj, u0, u1, sl, dn, _ = hooke_liggghts(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    return t, fx, fy, ti, tj, u0, u1, sl, dn


@njit(inline="always")
def hooke_select_lammps(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """:func:`hooke_lammps` as the block path: (touch, fx, fy, ti, tj, s0, s1, sliding, overlap)."""
    t, fx, fy, ti, tj, u0, u1, sl, dn, _ = hooke_lammps(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    return t, fx, fy, ti, tj, u0, u1, sl, dn


@njit(inline="always")
def hooke_history(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """One touching pair in LIGGGHTS' arithmetic, the convention of the entry-by-entry loops and
    of the laws built on it (the rolling laws): :func:`hooke_liggghts`, the one copy of the law,
    with its results as ``(fx, fy, ti, tj, s0, s1, sliding, fn)``: force on i (N), torques on i
    and j (N m), the updated tangential spring (m, frame of i), sliding (the Coulomb cap active),
    the normal force (N). The arguments are those of :func:`hooke_liggghts`; ``rsq`` must be below
    (r_i + r_j)^2 (the caller tests contact). A copy with the code's branches was measured 10 %
    faster in the sheared cell's entry-by-entry loop; against it, interleaved (``python -m
    bench.ab_dem --base f3ce714 --head e612176 --n 20000 --mode sheared --windows 10``, load 5-7),
    this form gave 1.08 (0.69-1.49): no loss measurable on that machine."""
    _, fx, fy, ti, tj, u0, u1, sl, _, fn = hooke_liggghts(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    return fx, fy, ti, tj, u0, u1, sl != 0.0, fn


@njit(inline="always")
def hooke_history_lammps(
    delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
):
    """One touching pair in LAMMPS' arithmetic (``pair_style gran/hooke/history``): :func:`hooke_lammps`,
    the one copy of the law, with the results of :func:`hooke_history`."""
    _, fx, fy, ti, tj, u0, u1, sl, _, fn = hooke_lammps(
        delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gamman, gammat, mu, dt, s0, s1, update
    )
    return fx, fy, ti, tj, u0, u1, sl != 0.0, fn


#: LIGGGHTS 3.8.0 ``hooke/stiffness`` + ``tangential history`` (:func:`hooke_history`): kn, kt (N/m),
#: gamma_n, gamma_t (1/s, mass-scaled), mu (-)
HookeLiggghts = namedtuple("HookeLiggghts", ["kn", "kt", "gamma_n", "gamma_t", "mu"])
#: LAMMPS 29 Sep 2021 ``gran/hooke/history`` (:func:`hooke_history_lammps`), the same parameters
HookeLammps = namedtuple("HookeLammps", ["kn", "kt", "gamma_n", "gamma_t", "mu"])


def hooke_law(kn, kt, gamma_n, gamma_t, mu, flavour: str = "liggghts"):
    """The Hooke law object of ``flavour`` ("liggghts" or "lammps") with checked parameters."""
    cls = {"liggghts": HookeLiggghts, "lammps": HookeLammps}.get(flavour)
    if cls is None:
        raise InputError(f"flavour: expected 'liggghts' or 'lammps', got {flavour!r}")
    return cls(
        as_positive_float(kn, "kn"),
        as_positive_float(kt, "kt", allow_zero=True),
        as_positive_float(gamma_n, "gamma_n", allow_zero=True),
        as_positive_float(gamma_t, "gamma_t", allow_zero=True),
        as_positive_float(mu, "mu", allow_zero=True),
    )


#: pair functions of the two Hooke laws (:func:`gransim.contacts.laws.spring_pair`: the spring in
#: ``hist[e, 0:2]``), :func:`hooke_history` and :func:`hooke_history_lammps` with kn, kt, gamma_n,
#: gamma_t, mu
hooke_pair_liggghts = spring_pair(hooke_history, 5)
hooke_pair_lammps = spring_pair(hooke_history_lammps, 5)


@njit(inline="always")
def spring_reset(law, hist, e):
    """LAMMPS ``PairGranHookeHistory::compute``: a pair that does not touch has its spring zeroed."""
    hist[e, 0] = 0.0
    hist[e, 1] = 0.0


def hooke_energy(law, overlap, hist, radi=None, radj=None) -> float:
    """sum kn overlap^2/2 + kt |xi|^2/2 (J) over touching contacts (overlap (K,), hist (K, 2); the
    radii are not needed). F_n = kn delta is its delta-derivative (hooke_history: ``force_magnitude``;
    LAMMPS ccel r = kn (R - r), pair_gran_hooke_history.cpp:244), F_t = -kt xi below the cap its
    xi-derivative. The spring is a potential of xi at every overlap (kt constant); both codes
    project xi on the tangent plane each step (LIGGGHTS without rescaling: |xi| shrinks with the
    rotation of n, energy leaves the spring without work)."""
    return float(0.5 * law.kn * np.sum(overlap**2) + 0.5 * law.kt * np.sum(hist[:, :2] ** 2))


#: block paths of the two Hooke laws (:func:`gransim.contacts.laws.spring_select`): the branch-free
#: :func:`hooke_select_liggghts` and :func:`hooke_select_lammps` with the law's parameters
hooke_block_liggghts = spring_select(hooke_select_liggghts)
hooke_block_lammps = spring_select(hooke_select_lammps)


# ------------------------------------------------------------------ time scale, deck lines, names
#: parameters of both Hooke laws
HOOKE_PARAMETERS = ("kn", "kt", "gamma_n", "gamma_t", "mu")


def hooke_timescale(law, packing, overlap=0.0):
    """(contact time, damping ratio) of the two lightest disks (m_eff = m_1 m_2/(m_1 + m_2)) for a
    Hooke law (any law with fields kn, kt, gamma_n, gamma_t; ``overlap`` is not needed: the
    stiffness is constant). Contact time pi sqrt(m_eff/k) (s) of the undamped normal contact with
    k = max(kn, kt) (N/m); damping ratio zeta = max(gamma_n, gamma_t)/(2 omega), omega =
    sqrt(k/m_eff): the relative normal motion obeys m_eff d'' + m_eff gamma d' + k d = 0 with the
    mass-scaled rate gamma (1/s, LIGGGHTS ``gamman``), i.e. d'' + 2 zeta omega d' + omega^2 d = 0.
    The larger of the stiffnesses and of the dampings: the conservative choice for the limit of
    :func:`gransim.dem.engine.stability_limit`."""
    meff = lightest_pair_mass(packing)
    k = max(law.kn, law.kt)
    tc = float(np.pi * np.sqrt(meff / k))
    omega = np.sqrt(k / meff)
    return tc, float(max(law.gamma_n, law.gamma_t) / (2.0 * omega))


def liggghts_hooke_lines(law, rolling: str = "") -> list[str]:
    """LIGGGHTS 3.8.0 ``gran model hooke/stiffness tangential history`` (kn, kt, gamman, gammat,
    coefficientFriction as ``fix property/global ... peratomtypepair 1``; ``rolling`` the
    ``rolling_friction`` model of gransim.contacts.rolling, its coefficients after these)."""
    prop = "fix m{} all property/global {} peratomtypepair 1 {}"
    lines = [
        prop.format(1, "kn", deck_float(law.kn)),
        prop.format(2, "kt", deck_float(law.kt)),
        prop.format(3, "gamman", deck_float(law.gamma_n)),
        prop.format(4, "gammat", deck_float(law.gamma_t)),
        prop.format(5, "coefficientFriction", deck_float(law.mu)),
    ]
    if rolling:
        lines.append(prop.format(6, "coefficientRollingFriction", deck_float(law.mu_r)))
        if rolling == "epsd":
            lines.append(prop.format(7, "coefficientRollingViscousDamping", deck_float(law.eta_r)))
        rolling = f" rolling_friction {rolling}"
    return lines + [f"pair_style gran model hooke/stiffness tangential history{rolling}", "pair_coeff * *"]


def lammps_gran_history_lines(law, style: str = "hooke") -> list[str]:
    """LAMMPS 29 Sep 2021 ``pair_style gran/<style>/history KN KT GAMMAN GAMMAT MU 1``."""
    v = " ".join(deck_float(getattr(law, k)) for k in HOOKE_PARAMETERS)
    return [f"pair_style gran/{style}/history {v} 1", "pair_coeff * *"]


register_law(
    HookeLiggghts,
    hooke_pair_liggghts,
    2,
    energy=hooke_energy,
    select=hooke_block_liggghts,
    name="hooke-liggghts",
    code="liggghts",
    required=HOOKE_PARAMETERS,
    build=lambda **p: hooke_law(*(p[k] for k in HOOKE_PARAMETERS), flavour="liggghts"),
    description="hooke/stiffness tangential history",
    timescale=hooke_timescale,
    deck=liggghts_hooke_lines,
)
register_law(
    HookeLammps,
    hooke_pair_lammps,
    2,
    apart=spring_reset,
    energy=hooke_energy,
    select=hooke_block_lammps,
    name="hooke-lammps",
    code="lammps",
    required=HOOKE_PARAMETERS,
    build=lambda **p: hooke_law(*(p[k] for k in HOOKE_PARAMETERS), flavour="lammps"),
    description="gran/hooke/history",
    timescale=hooke_timescale,
    deck=lammps_gran_history_lines,
)
