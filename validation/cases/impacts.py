"""Analytic 2D impact benchmarks on native, LIGGGHTS and LAMMPS (case ``impacts``; docs/impacts.md).

Binary impacts of disks (I = m r^2/2) in the style of Chung & Ooi, "Benchmark tests for verifying
discrete element modelling codes at particle impact level", Granular Matter 13 (2011) 643-656
(tests 1-8), with the rigid-body oblique analysis of Thornton, Cummins & Cleary, "An investigation
of the comparative behaviour of alternative contact force models during inelastic collisions",
Powder Technology 233 (2013) 30-46 (Psi1 = 2 v_t/(mu (1 + e) v_n)), adapted to disks. A wall is
a disk of 25 times the radius (625 times the mass): every formula below is written for two bodies
of arbitrary masses, so the finite "wall" mass is exact, not an approximation.

Each *scene* (one job per code) is a set of independent impacts sharing one contact law (the law is
a parameter of the scene: :class:`reference_runs.decks.impact.HookeLaw` for both codes, the Hertz
laws ``HertzLiggghtsLaw``, ``HertzHistoryLammpsLaw``, ``HertzGranularLammpsLaw`` for one code
each). Each impact is run by the native engine in the arithmetic of each code that has the law
(the Hooke scenes: both flavours), by LIGGGHTS and/or by
LAMMPS (live, or their stored outputs ``reference_runs/stored/impacts-<code>/<scene>/``), and, to
measure the time-step error, by the native engine at dt/2.

Normal impact, linear law (derivation). With delta the overlap and m_eff = m1 m2/(m1 + m2),
m_eff delta'' = -kn delta - m_eff gamma_n delta', i.e. delta'' + 2 zeta w0 delta' + w0^2 delta = 0
with w0 = sqrt(kn/m_eff), zeta = gamma_n/(2 w0) (gamma_n is mass-scaled, 1/s, in both codes), and
delta(0) = 0, delta'(0) = v_n:

    delta(t) = (v_n/w_d) exp(-zeta w0 t) sin(w_d t),   w_d = w0 sqrt(1 - zeta^2)          (1)

Neither code limits the damped force to repulsion (LIGGGHTS ``limitForce`` off, LAMMPS without
``limit_damping``) and both end the contact when the disks stop overlapping (rsq < radsum^2), so
the contact ends at delta = 0: contact time t_c = pi/w_d (2), restitution
e = -delta'(t_c)/v_n = exp(-pi zeta/sqrt(1 - zeta^2)) (3), peak overlap at tan(w_d t_m) =
sqrt(1 - zeta^2)/zeta: delta_max = (v_n/w0) exp(-zeta atan(sqrt(1 - zeta^2)/zeta)/sqrt(1 - zeta^2)) (4).

Tangential impulse (rigid-body limit, disks). With n from disk 1 to disk 2 and t = z x n, the
slip velocity of the contact point of 1 relative to 2 is s = (v1 - v2).t + r1 w1 + r2 w2. A
tangential impulse J (on 1 along -sign(s) t, on 2 opposite) changes it by
-sign(s) J (1/m1 + 1/m2 + r1^2/I1 + r2^2/I2) = -sign(s) 3 J/m_eff (disks: r^2/I = 2/m; spheres
have 5/2, hence the 7/2 of the 3D results) (5). Coulomb friction through the whole contact gives
J = mu P with P = int |F_n| dt; it holds (gross sliding) iff 3 mu P/m_eff <= |s0|. For an
undamped normal law P = (1 + e) m_eff v_n, so gross sliding iff Psi1 = 2|s0|/(mu (1 + e) v_n) >= 6
(spheres: 7), and then

    s' = s0 - sign(s0) 3 mu P/m_eff  (Psi2 = Psi1 - 6),  w_i' = w_i - sign(s0) 2 mu P/(m_i r_i),
    v_i,t' = v_i,t -+ sign(s0) mu P/m_i                                                  (6)

(for Psi1 < 6 the rigid body rolls out: s' = 0). Both codes cap |F_t| by mu |F_n| with the
absolute value, so for a damped law the friction impulse is mu int |F_n| dt: from (1), F_n =
-m_eff delta'', which changes sign once (at w_d t* = pi - atan(2 a w_d/(w_d^2 - a^2)), a = zeta w0),
so int |F_n| dt = m_eff v_n (1 - e + 2 u*) with u* = |delta'(t*)|/v_n (7) (= 1 + e for zeta = 0).

Sticking (mu -> infinity; the "small-angle" regime without slip). The spring xi (xi' = s) and the
tangential damping obey (m_eff/3) xi'' = -kt xi - m_eff gamma_t xi': a damped oscillator of
w_t = sqrt(3 kt/m_eff), zeta_t = 3 gamma_t/(2 w_t), started at xi = 0, xi' = s0 and released at
t_c of (2):  s'/s0 = exp(-zeta_t w_t t_c) (cos(w_td t_c) - zeta_t/sqrt(1 - zeta_t^2) sin(w_td t_c)) (8),
w_td = w_t sqrt(1 - zeta_t^2); J = m_eff (s0 - s')/3 then gives spins and velocities by (6). With a
finite mu and Psi1 < 6 (microslip) there is no closed form for the discrete cap: those impacts are
reported beside the rigid-body limit (info) and checked against the Coulomb bound |F_t| <= mu |F_n|
at every step.

Hertz-Mindlin scenes (one code each: LIGGGHTS ``gran model hertz tangential history``, LAMMPS
``gran/hertz/history`` with KN = 4/3 Y*, KT = 8 G*, LAMMPS ``granular hertz/material ...
tangential mindlin NULL``; both codes apply the sphere law to the disks, docs/laws.md "2D"). With
K = 4/3 Y* sqrt(R*) and m* delta'' = -K delta^(3/2) (Hertz 1882; Johnson, *Contact Mechanics*
1985, eq (4.23)), energy conservation gives, for an undamped impact at v_n,

    delta_max = (5 m* v_n^2/(4 K))^(2/5),  F_max = K delta_max^(3/2)                          (H1, H2)
    t_c = 2 (delta_max/v_n) int_0^1 dx/sqrt(1 - x^(5/2)) = 2 (delta_max/v_n) (2/5) B(2/5, 1/2)
        = 2.9432 delta_max/v_n,  e = 1,  int F_n dt = 2 m* v_n                               (H3)

(the classical sphere results: nothing changes for disks except m* = the disk masses). Damping
of LIGGGHTS' hertz, -2 sqrt(5/6) beta sqrt(2 Y* a m*) v_n = -sqrt(5) beta sqrt(m* K) delta^(1/4)
v_n, and of LAMMPS' tsuji, alpha(DAMP) sqrt(m* K) delta^(1/4) v_n (pair_granular.cpp:363-373,
987-991), is the same form; with delta = D x, t = (D/v_n) tau, D = (m* v_n^2/K)^(2/5):

    x'' + alpha x^(1/4) x' + x^(3/2) = 0,  x(0) = 0, x'(0) = 1                               (H4)

(Tsuji, Tanaka & Ishida, Powder Technol. 71, 1992): the restitution depends on alpha alone (no
speed). It has no closed form: e, t_c, delta_max, F_max of a damped scene are the DOP853
integral of (H4) (rtol 1e-12), an independent computation. LIGGGHTS (alpha = -sqrt(5) beta(e))
is judged against the requested e (H4 returns it to 1e-11); LAMMPS tsuji against H4 at
alpha(DAMP): 0.43960 for DAMP = 0.3 (the polynomial is not the inverse of H4: docs/laws.md).
Oblique impacts (undamped): the rigid-body limit (5)-(6) with P = 2 m* v_n holds in gross
sliding (Psi1 >= 6: the cap mu F_n acts from the first step because 6 (G*/Y*) s0/v_n > mu,
Mindlin's initial ratio of the spring force to F_n, and the slip never reverses). Sticking
(mu = 1e3, undamped): xi'' = -(3/m*) 8 G* sqrt(R* delta(t)) xi (both codes keep xi when delta
changes, F_t = -k_t(delta) xi; Mindlin 1949; Di Renzo & Di Maio 2004, eq (13)), released at
delta = 0 (H5): integrated with (H1) by DOP853 (no closed form: k_t varies through the impact);
1% in k_t moves s'/s0 by 2.1e-2.

What is not exact: the lever arm (LIGGGHTS r - delta/2, LAMMPS r: relative O(delta/r) = 4e-5 here),
the rotation of the normal during contact (O(v_t t_c/(r1 + r2)) <= 6e-5 rad) and the time step
(measured by halving dt; the tolerances and the measured order are in the records).
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..core import (
    CaseResult,
    Context,
    case,
    compare,
    evidence,
    in_pair,
    info,
    stored_dir,
    stored_job_record,
)

CODES = ("liggghts", "lammps")
CODE = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}

# -- the common material and geometry ------------------------------------------------------
R = 0.01              # disk radius (m)
RHO = 1000.0          # mass per area (kg/m^2): m = pi r^2 rho = 0.314 kg
R_WALL = 25.0 * R     # the disk standing in for a wall (625 m)
KN = 1.0e6            # N/m
V = 1.0e-3            # impact speed (m/s): delta_max/r ~ 4e-5
DT = 5.0e-6           # s: contact time of two equal disks / 249 (the damping's O(dt) error, docs/impacts.md)
EVERY = 5             # frames (dumps) every 5 steps: sampling interval 2.5e-5 s = t_c / 50
GAP_SAMPLES = 2.3     # the disks touch 2.3 sampling intervals after the start (a generic phase)
SKIN = 0.1 * R
#: analytic tolerances (relative unless stated): the time-step error at DT measured by halving dt
#: (docs/impacts.md, "Measured") with a margin of about 3
TOL = {
    "contact time": (3.0e-3, ("time-step error, first order from the damping's half-step lag: measured 6e-6 (zeta 0), "
                             "4.5e-4 (zeta 0.1) to 1.9e-3 (zeta 0.35 between equal disks) at dt = 5e-6 s, halved at "
                             "dt/2 (order 1.0); 1% stiffness changes it by 5e-3")),
    "restitution": (1.0e-2, ("time-step error (relative): measured <= 7.9e-3 at dt = 5e-6 s (zeta 0.5), 5e-7 undamped; "
                            "order 0.2-3 (the sub-step phase of the contact end moves with dt); 1% damping changes "
                            "it by 1.3e-2 (zeta 0.35) to 2.4e-2 (zeta 0.5)")),
    "peak overlap": (5.0e-3, ("time-step error: measured <= 3.3e-3 (zeta 0.5), 1e-7 undamped")),
    "friction impulse": (2.0e-4, ("gross sliding: measured <= 4.1e-5 (85 deg) at dt = 5e-6 s, about order 0.1-1 "
                                 "(dominated by the lever arm r - delta/2 in LIGGGHTS, O(delta/r))")),
    "exit slip": (1.0e-4, ("|s' - s'_analytic|/|s0|: measured <= 1.2e-5 (LIGGGHTS lever arm), LAMMPS <= 7e-6")),
    "exit spin": (1.0e-4, ("r1 |w1' - w1'_analytic|/|s0|: measured <= 1.1e-5")),
    "friction impulse (stick)": (2.0e-2, ("sticking oscillator: first-order time-step error of the tangential damping "
                                         "(w_t = sqrt(3) w0, zeta_t = 0.17): measured <= 1.4e-2 at dt = 5e-6 s")),
    "exit slip (stick)": (1.5e-2, ("|s'/s0 - eq (8)|: measured <= 8.4e-3 at dt = 5e-6 s")),
    "exit spin (stick)": (1.0e-2, ("r1 |w1' - w1'_analytic|/|s0|: measured <= 3.0e-3 at dt = 5e-6 s")),
    "coulomb bound": (1.0e-9, ("max over contact frames of |F_t|/(mu |F_n|) - 1 (instantaneous normal): the cap is exact "
                              "in both codes")),
}
#: Hertz scenes (V_H = 0.01 m/s, t_c = 840-970 steps): the time-step error at DT, measured by halving dt
#: (docs/impacts.md, "Measured"), with a margin of about 3
TOL_HERTZ = {
    "contact time": (1.5e-3, (
        "normal: time-step error <= 3.4e-4 (damped, order 0.9), 7e-7 undamped (order 2); oblique: "
        "the rotation of the normal during a 4.8e-3 s contact (v_t t_c/(r1 + r2) = 1.8e-4 rad), "
        "dt-independent, <= 4.0e-4 (85 deg); 1% stiffness changes it by 4e-3")),
    "restitution": (1.5e-3, (
        "time-step error <= 4.1e-4 (damped, DAMP 0.3), 6e-9 undamped; oblique <= 5.8e-5 "
        "(geometric); a restitution formula off by 1% changes it by 1e-2")),
    "peak overlap": (3.0e-3, (
        "time-step error <= 4.9e-4 (damped), 6e-7 undamped; oblique <= 9.5e-4 (geometric, 85 deg)")),
    "peak force": (4.0e-3, (
        "time-step error <= 4.0e-4 (damped), 9e-7 undamped; oblique <= 1.4e-3 (geometric, 85 deg)")),
    "friction impulse": (5.0e-3, (
        "gross sliding: mu int |F_n| dt with P = 2 m* v_n; measured <= 1.7e-3 (85 deg), "
        "dt-independent: the normal impulse of the curved path")),
    "exit slip": (1.0e-3, (
        "|s' - s'_rigid|/|s0|: measured <= 3.4e-4, dt-independent: the lever arm r - delta/2 "
        "(delta/r = 1.6e-3) and the rotation of the normal")),
    "exit spin": (1.0e-3, "r1 |w1' - w1'_rigid|/|s0|: measured <= 3.4e-4 (as the exit slip)"),
    "friction impulse (stick)": (2.0e-2, (
        "sticking Mindlin oscillator (reference integrated): measured <= 7.2e-3 at dt = 5e-6 s "
        "(erratic order: k_t ~ sqrt(delta) ends the contact with a square-root singularity); "
        "1% Mindlin stiffness changes it by 6.7e-2")),
    "exit slip (stick)": (6.0e-3, (
        "|s'/s0 - s'/s0 integrated|: measured <= 2.2e-3 at dt = 5e-6 s, 1.9e-3 at dt/2; "
        "1% Mindlin stiffness changes it by 2.1e-2")),
    "exit spin (stick)": (4.0e-3, "r1 |w1' - w1'_reference|/|s0|: measured <= 1.4e-3 at dt = 5e-6 s"),
    "coulomb bound": TOL["coulomb bound"],
}
BIT_POS, BIT_REL = 1e-10, 1e-8


def tolerances(scene) -> dict:
    """The tolerance table of ``scene``: :data:`TOL_HERTZ` for a Hertz law, :data:`TOL` otherwise."""
    return TOL_HERTZ if hasattr(scene.law, "hertz") else TOL


# ====================================================================== analytic solutions
def normal_linear(meff: float, kn: float, gamma_n: float, vn: float) -> dict:
    """Damped linear normal impact, eqs (1)-(4) and (7) of the module docstring.

    Parameters: meff (kg), kn (N/m), gamma_n (1/s, mass-scaled), vn (approach speed, m/s > 0).
    Returns dict: w0 (1/s), zeta (-), wd (1/s), contact time (s), restitution (-), peak overlap (m),
    normal impulse factor P/(m_eff v_n) = int |F_n| dt/(m_eff v_n) (-). Needs zeta < 1/sqrt(2)
    (F_n changes sign once).
    """
    w0 = math.sqrt(kn / meff)
    z = gamma_n / (2.0 * w0)
    if not 0.0 <= z < 1.0 / math.sqrt(2.0):
        raise ValueError(f"zeta = {z:.4g}: the closed forms here need 0 <= zeta < 1/sqrt(2)")
    wd = w0 * math.sqrt(1.0 - z * z)
    e = math.exp(-math.pi * z / math.sqrt(1.0 - z * z))
    if z == 0.0:
        dmax, ustar = vn / w0, 1.0
    else:
        dmax = vn / w0 * math.exp(-z * math.atan(math.sqrt(1.0 - z * z) / z) / math.sqrt(1.0 - z * z))
        a = z * w0
        ts = (math.pi - math.atan(2.0 * a * wd / (wd * wd - a * a))) / wd
        ustar = -math.exp(-a * ts) * (math.cos(wd * ts) - a / wd * math.sin(wd * ts))
    return {"w0": w0, "zeta": z, "wd": wd, "contact time": math.pi / wd, "restitution": e,
            "peak overlap": dmax, "impulse factor": 1.0 - e + 2.0 * ustar}


def tangential_exit(m1, m2, r1, r2, s0: float, J: float) -> dict:
    """Exit slip, spins and tangential velocity changes after a tangential impulse J >= 0 opposing
    s0 (eq 5-6): {"exit slip", "dw1", "dw2", "dv1t", "dv2t"} (m/s, rad/s)."""
    meff = m1 * m2 / (m1 + m2)
    sg = math.copysign(1.0, s0) if s0 != 0 else 0.0
    return {"exit slip": s0 - sg * 3.0 * J / meff, "dw1": -sg * 2.0 * J / (m1 * r1), "dw2": -sg * 2.0 * J / (m2 * r2),
            "dv1t": -sg * J / m1, "dv2t": sg * J / m2, "friction impulse": J}


def oblique_rigid(m1, m2, r1, r2, vn, s0, mu, P) -> dict:
    """Rigid-body limit of an oblique impact with Coulomb friction (eq 6): P = int |F_n| dt (N s).
    Returns :func:`tangential_exit` plus "sliding" (gross sliding through the contact) and "psi1"."""
    meff = m1 * m2 / (m1 + m2)
    sliding = abs(s0) >= 3.0 * mu * P / meff
    J = mu * P if sliding else meff * abs(s0) / 3.0
    out = tangential_exit(m1, m2, r1, r2, s0, J)
    if not sliding:
        out["exit slip"] = 0.0
    out.update(sliding=sliding, psi1=2.0 * abs(s0) * meff / (mu * P) if mu > 0 else math.inf)
    return out


def stick_ratio(meff: float, kt: float, gamma_t: float, tc: float) -> float:
    """s'/s0 of a sticking contact, eq (8): the damped tangential oscillator released at tc."""
    wt = math.sqrt(3.0 * kt / meff)
    zt = 3.0 * gamma_t / (2.0 * wt)
    if not 0.0 <= zt < 1.0:
        raise ValueError(f"zeta_t = {zt:.4g}: eq (8) needs an underdamped tangential oscillator")
    wtd = wt * math.sqrt(1.0 - zt * zt)
    return math.exp(-zt * wt * tc) * (math.cos(wtd * tc) - zt / math.sqrt(1.0 - zt * zt) * math.sin(wtd * tc))


# ---------------------------------------------------------------------- Hertz-Mindlin
def hertz_undamped(meff: float, reff: float, y43: float, vn: float) -> dict:
    """Undamped Hertz normal impact of two bodies (H1-H3 of the module docstring).

    Parameters: meff (kg), reff = R* (m), y43 = 4/3 Y* (Pa), vn (m/s > 0). With K = y43 sqrt(R*):
    peak overlap (5 m* vn^2/(4 K))^(2/5) (m), peak force K delta_max^(3/2) (N), contact time
    2 (delta_max/vn) (2/5) B(2/5, 1/2) = 2.9432 delta_max/vn (s), restitution 1, impulse factor
    int F_n dt/(m* vn) = 2."""
    K = y43 * math.sqrt(reff)
    dmax = (5.0 * meff * vn * vn / (4.0 * K)) ** 0.4
    beta = math.gamma(0.4) * math.gamma(0.5) / math.gamma(0.9)
    return {"peak overlap": dmax, "peak force": K * dmax ** 1.5, "contact time": 2.0 * dmax / vn * 0.4 * beta,
            "restitution": 1.0, "impulse factor": 2.0}


def hertz_scaled_ode(alpha: float, rtol: float = 1e-12) -> dict:
    """The dimensionless damped Hertz impact x'' + alpha x^(1/4) x' + x^(3/2) = 0, x(0) = 0,
    x'(0) = 1 (H4: delta = D x, t = (D/vn) tau, D = (m* vn^2/K)^(2/5), force K D^(3/2) f with
    f = x^(3/2) + alpha x^(1/4) x'), integrated by DOP853 (scipy) to the return to x = 0 (the
    codes end the contact there: the damped force may be attractive before it).

    Returns the contact time tau_c, the peak overlap x_max, the peak force f_max, the restitution
    -x'(tau_c) and the impulse factor int |f| dtau, all dimensionless (alpha >= 0)."""
    from scipy.integrate import solve_ivp

    if not (math.isfinite(alpha) and alpha >= 0.0):
        raise ValueError(f"alpha: expected a damping coefficient >= 0, got {alpha!r}")

    def rhs(t, y):
        x = max(y[0], 0.0)
        f = x ** 1.5 + alpha * x ** 0.25 * y[1]
        return [y[1], -f, abs(f)]

    def back(t, y):
        return y[0]

    back.terminal, back.direction = True, -1
    sol = solve_ivp(rhs, (0.0, 20.0), [0.0, 1.0, 0.0], method="DOP853", rtol=rtol, atol=1e-14,
                    events=back, dense_output=True, first_step=1e-6)
    tc = float(sol.t_events[0][0])
    yc = sol.y_events[0][0]
    ts = np.linspace(0.0, tc, 20001)
    y = sol.sol(ts)
    f = np.clip(y[0], 0, None) ** 1.5 + alpha * np.clip(y[0], 0, None) ** 0.25 * y[1]
    k = int(np.argmax(y[0]))
    from scipy.optimize import minimize_scalar

    xm = -minimize_scalar(lambda t: -sol.sol(t)[0], bounds=(ts[max(k - 1, 0)], ts[min(k + 1, len(ts) - 1)]),
                          method="bounded", options={"xatol": 1e-13}).fun
    kf = int(np.argmax(f))

    def force(t):
        yy = sol.sol(t)
        x = max(yy[0], 0.0)
        return x ** 1.5 + alpha * x ** 0.25 * yy[1]

    fm = -minimize_scalar(lambda t: -force(t), bounds=(ts[max(kf - 1, 0)], ts[min(kf + 1, len(ts) - 1)]),
                          method="bounded", options={"xatol": 1e-13}).fun
    return {"tau_c": tc, "x_max": float(xm), "f_max": float(fm), "restitution": float(-yc[1]),
            "impulse": float(yc[2])}


def normal_hertz(meff: float, reff: float, y43: float, vn: float, alpha: float = 0.0) -> dict:
    """Hertz normal impact (undamped: closed forms :func:`hertz_undamped`; damped with the
    coefficient alpha sqrt(m* y43 a) of LIGGGHTS' hertz and LAMMPS' tsuji: :func:`hertz_scaled_ode`
    scaled back, H4). Keys as :func:`normal_linear` plus "peak force" (N) and "source"."""
    if alpha == 0.0:
        return dict(hertz_undamped(meff, reff, y43, vn), source="closed form")
    K = y43 * math.sqrt(reff)
    D = (meff * vn * vn / K) ** 0.4
    o = hertz_scaled_ode(alpha)
    return {"peak overlap": D * o["x_max"], "peak force": K * D ** 1.5 * o["f_max"],
            "contact time": D / vn * o["tau_c"], "restitution": o["restitution"],
            "impulse factor": o["impulse"], "source": "integrated (DOP853)"}


def hertz_stick(meff: float, reff: float, y43: float, kt0: float, vn: float, rtol: float = 1e-12) -> float:
    """s'/s0 of an undamped sticking Hertz-Mindlin impact (H5): delta'' = -K delta^(3/2)/m*,
    xi'' = -(3/m*) kt0 sqrt(R* delta) xi (F_t = -k_t(delta) xi: both codes keep xi when delta
    changes), xi(0) = 0, xi'(0) = s0, released at the return to delta = 0; linear in s0.
    Integrated by DOP853 (scipy): no closed form (k_t varies through the impact)."""
    from scipy.integrate import solve_ivp

    K = y43 * math.sqrt(reff)

    def rhs(t, y):
        d = max(y[0], 0.0)
        return [y[1], -K * d ** 1.5 / meff, y[3], -3.0 * kt0 * math.sqrt(reff * d) * y[2] / meff]

    def back(t, y):
        return y[0]

    back.terminal, back.direction = True, -1
    tc = hertz_undamped(meff, reff, y43, vn)["contact time"]
    sol = solve_ivp(rhs, (0.0, 2.0 * tc), [0.0, vn, 0.0, 1.0], method="DOP853", rtol=rtol, atol=1e-16,
                    events=back, first_step=tc * 1e-6)
    return float(sol.y_events[0][0][3])


# ====================================================================== scenes
@dataclass(frozen=True)
class Impact:
    """One binary impact: disk 1 (left) moves towards disk 2 along +x (the normal n).

    kind: "normal" (checks t_c, e, delta_max), "sliding" (also eq 6), "microslip" (eq 6 as info,
    Coulomb bound), "stick" (also eq 8; the scene's mu is huge). v1, v2 (2,) m/s, w1, w2 rad/s.
    """

    label: str
    kind: str
    r1: float
    r2: float
    v1: tuple
    v2: tuple
    w1: float = 0.0
    w2: float = 0.0
    note: str = ""


@dataclass(frozen=True)
class Scene:
    """A set of impacts sharing one contact law (one job per code)."""

    name: str
    law: object
    impacts: tuple
    suites: tuple = ("default", "full")
    description: str = ""
    meta: dict = field(default_factory=dict)


def _mass(r):
    return math.pi * r * r * RHO


def _meff(r1, r2):
    m1, m2 = _mass(r1), _mass(r2)
    return m1 * m2 / (m1 + m2)


def _head_on(label, kind, r1, r2, vn, vt=0.0, w1=0.0, w2=0.0, note=""):
    """Zero-momentum frame for equal disks; the larger body (r2 > r1) at rest."""
    if r1 == r2:
        return Impact(label, kind, r1, r2, (vn / 2, vt / 2), (-vn / 2, -vt / 2), w1, w2, note)
    return Impact(label, kind, r1, r2, (vn, vt), (0.0, 0.0), w1, w2, note)


ZETAS_WALL = (0.0, 0.1, 0.2, 0.35, 0.5)
ANGLES = (5.0, 15.0, 30.0, 45.0, 60.0, 65.0, 70.0, 80.0, 85.0)
MU_OBLIQUE = 0.3


def scenes(suite: str = "default") -> list[Scene]:
    """The scenes of ``suite`` (quick: normal zeta 0 and 0.35, oblique; default/full: all)."""
    from reference_runs.decks.impact import HookeLaw

    out = []
    w0_wall = math.sqrt(KN / _meff(R, R_WALL))
    for z in ZETAS_WALL:
        g = 2.0 * z * w0_wall
        law = HookeLaw(kn=KN, kt=KN, gamma_n=g, gamma_t=0.0, mu=MU_OBLIQUE)
        imps = (_head_on("disks", "normal", R, R, V, note="Chung & Ooi test 1 (two equal disks, head on)"),
                _head_on("wall", "normal", R, R_WALL, V, note="Chung & Ooi tests 2-3 (disk on a wall)"))
        out.append(Scene(f"normal-z{z:g}", law, imps, ("quick", "default", "full") if z in (0.0, 0.35)
                         else ("default", "full"),
                         f"normal impacts, zeta = {z:g} against the wall disk ({z / math.sqrt(2):.3g} between "
                         "equal disks: m_eff is half)"))
    law = HookeLaw(kn=KN, kt=KN, gamma_n=0.0, gamma_t=0.0, mu=MU_OBLIQUE)
    imps = []
    for a in ANGLES:
        vn, vt = V * math.cos(math.radians(a)), V * math.sin(math.radians(a))
        kind = "sliding" if vt / (MU_OBLIQUE * vn) >= 6.0 else "microslip"
        imps.append(_head_on(f"angle{a:g}", kind, R, R_WALL, vn, vt,
                             note=f"Chung & Ooi test 4: {a:g} deg from the normal, |v| = {V:g} m/s"))
    for psi in (3.0, 8.0, 16.0, -8.0):  # test 6: spinning disk on the wall
        w = psi * MU_OBLIQUE * V / R
        imps.append(_head_on(f"spin-wall{psi:g}", "sliding" if abs(psi) >= 6 else "microslip", R, R_WALL, V, w1=w,
                             note=f"Chung & Ooi test 6: w1 = {w:.4g} rad/s (Psi1 = {psi:g})"))
    for psi in (3.0, 10.0):  # test 7: two equal disks with equal spins
        w = psi * MU_OBLIQUE * V / (2 * R)
        imps.append(_head_on(f"spin-disks{psi:g}", "sliding" if psi >= 6 else "microslip", R, R, V, w1=w, w2=w,
                             note=f"Chung & Ooi test 7: w1 = w2 = {w:.4g} rad/s (Psi1 = {psi:g})"))
    for psi in (3.0, 10.0):  # test 8: different disks (radius 1:2), zero momentum, disk 1 spinning
        m1, m2 = _mass(R), _mass(2 * R)
        w = psi * MU_OBLIQUE * V / R
        imps.append(Impact(f"spin-unequal{psi:g}", "sliding" if psi >= 6 else "microslip", R, 2 * R,
                           (V * m2 / (m1 + m2), 0.0), (-V * m1 / (m1 + m2), 0.0), w, 0.0,
                           f"Chung & Ooi test 8: radii 1:2, w1 = {w:.4g} rad/s (Psi1 = {psi:g})"))
    out.append(Scene("oblique", law, tuple(imps), ("quick", "default", "full"),
                     f"oblique and spinning impacts, mu = {MU_OBLIQUE}, no damping (e = 1)"))
    zs = 0.1
    g = 2.0 * zs * w0_wall
    law = HookeLaw(kn=KN, kt=KN, gamma_n=g, gamma_t=g, mu=1.0e3)
    imps = []
    for a in (20.0, 45.0):
        vn, vt = V * math.cos(math.radians(a)), V * math.sin(math.radians(a))
        imps.append(_head_on(f"angle{a:g}", "stick", R, R_WALL, vn, vt, note=f"{a:g} deg, sticking (mu = 1e3)"))
    imps.append(_head_on("spin-wall", "stick", R, R_WALL, V, w1=0.3, note="spinning disk, sticking"))
    imps.append(_head_on("spin-disks", "stick", R, R, V, w1=0.15, w2=0.15, note="two spinning disks, sticking"))
    out.append(Scene("stick", law, tuple(imps), ("default", "full"),
                     f"sticking contacts (mu = 1e3), zeta = {zs} (wall), gamma_t = gamma_n"))
    out += hertz_scenes()
    return [s for s in out if suite in s.suites]


E_H, NU_H = 5.0e8, 0.3    # Young's modulus (Pa; inside LIGGGHTS' SI limits) and Poisson's ratio
V_H = 0.01                # impact speed of the Hertz scenes (m/s): t_c ~ 4.2e-3 to 4.8e-3 s = 840-970 steps
ANGLES_H = (30.0, 60.0, 70.0, 80.0, 85.0)
MU_STICK = 1.0e3


def hertz_scenes() -> list[Scene]:
    """The Hertz-Mindlin scenes, one code each (docs/impacts.md): per law an undamped scene
    (normal, oblique, spinning), a sticking one (mu 1e3) and a damped normal one (LIGGGHTS e = 0.5,
    LAMMPS tsuji DAMP = 0.3)."""
    from reference_runs.decks.impact import (
        HertzGranularLammpsLaw,
        HertzHistoryLammpsLaw,
        HertzLiggghtsLaw,
    )

    laws = {
        "hertz-liggghts": lambda mu, damped: HertzLiggghtsLaw(E_H, NU_H, 0.5 if damped else 1.0, mu),
        "hertz-lammps": lambda mu, damped: HertzHistoryLammpsLaw(E_H, NU_H, mu),
        "hertz-granular": lambda mu, damped: (
            HertzGranularLammpsLaw(E_H, NU_H, 0.3, mu, 0.0, "tsuji") if damped
            else HertzGranularLammpsLaw(E_H, NU_H, 0.0, mu)),
    }
    normal = (_head_on("disks", "normal", R, R, V_H, note="Chung & Ooi test 1 (Hertz: equal disks)"),
              _head_on("wall", "normal", R, R_WALL, V_H, note="Chung & Ooi tests 2-3 (Hertz: wall)"))
    out = []
    for name, make in laws.items():
        imps = list(normal)
        for a in ANGLES_H:
            vn, vt = V_H * math.cos(math.radians(a)), V_H * math.sin(math.radians(a))
            kind = "sliding" if vt / (MU_OBLIQUE * vn) >= 6.0 else "microslip"
            imps.append(_head_on(f"angle{a:g}", kind, R, R_WALL, vn, vt,
                                 note=f"Chung & Ooi test 4 (Hertz): {a:g} deg"))
        for psi in (8.0, 16.0):
            imps.append(_head_on(f"spin-wall{psi:g}", "sliding", R, R_WALL, V_H,
                                 w1=psi * MU_OBLIQUE * V_H / R,
                                 note=f"Chung & Ooi test 6 (Hertz): Psi1 = {psi:g}"))
        out.append(Scene(name, make(MU_OBLIQUE, False), tuple(imps),
                         ("quick", "default", "full") if name == "hertz-liggghts" else ("default", "full"),
                         f"{name}: undamped, mu = {MU_OBLIQUE}: normal, oblique and spinning impacts"))
        imps = []
        for a in (20.0, 45.0):
            vn, vt = V_H * math.cos(math.radians(a)), V_H * math.sin(math.radians(a))
            imps.append(_head_on(f"angle{a:g}", "stick", R, R_WALL, vn, vt,
                                 note=f"{a:g} deg, sticking (mu 1e3)"))
        imps.append(_head_on("spin-wall", "stick", R, R_WALL, V_H, w1=3.0, note="spinning disk, sticking"))
        out.append(Scene(f"{name}-stick", make(MU_STICK, False), tuple(imps), ("default", "full"),
                         f"{name}: undamped, sticking (mu 1e3): the Mindlin stiffness 8 G* a"))
        tag = "e0.5" if name == "hertz-liggghts" else ("tsuji0.3" if name == "hertz-granular" else None)
        if tag:
            out.append(Scene(f"{name}-{tag}", make(MU_OBLIQUE, True), normal, ("default", "full"),
                             f"{name}: damped ({tag}), normal impacts"))
    return out


def layout(scene: Scene, dt: float = DT):
    """(packing, velocities, spins, nsteps, pairs) of the scene: pair k in slot k along x, each
    pair GAP_STEPS base steps from touching; the run lasts until every pair has separated."""
    from gransim.geometry import Packing

    rmax = max(max(i.r1, i.r2) for i in scene.impacts)
    S = 4 * rmax + 2 * max(i.r1 + i.r2 for i in scene.impacts) + 4 * SKIN
    Ly = 4 * rmax + 4 * SKIN
    pos, rad, vel, spin, pairs = [], [], [], [], []
    tmax = 0.0
    for k, im in enumerate(scene.impacts):
        vn = im.v1[0] - im.v2[0]
        gap = vn * GAP_SAMPLES * EVERY * DT
        cx = (k + 0.5) * S
        pos += [(cx - im.r1 - gap, Ly / 2), (cx + im.r2, Ly / 2)]
        rad += [im.r1, im.r2]
        vel += [im.v1, im.v2]
        spin += [im.w1, im.w2]
        pairs.append((2 * k, 2 * k + 1))
        an = normal_answers(scene.law, im)
        tmax = max(tmax, GAP_SAMPLES * EVERY * DT + an["contact time"])
    every = round(EVERY * DT / dt)
    nsteps = (math.ceil(tmax / (every * dt)) + 3) * every
    cell = np.diag([S * len(scene.impacts), Ly])
    p = Packing(np.array(pos), np.array(rad), cell, density=RHO, metadata={"scene": scene.name})
    return p, np.array(vel, float), np.array(spin, float), nsteps, pairs


def normal_answers(law, im: Impact) -> dict:
    """The normal closed forms of impact ``im`` under ``law`` (linear: :func:`normal_linear`;
    Hertz: :func:`normal_hertz` with the law's ``hertz()`` constants)."""
    m1, m2 = _mass(im.r1), _mass(im.r2)
    meff = m1 * m2 / (m1 + m2)
    vn = im.v1[0] - im.v2[0]
    if not hasattr(law, "hertz"):
        return dict(normal_linear(meff, law.kn, law.gamma_n, vn), source="closed form")
    h = law.hertz()
    if h["damping"] not in ("none", "tsuji"):
        raise ValueError(f"{law.name}: no closed form for damping {h['damping']!r}")
    return normal_hertz(meff, im.r1 * im.r2 / (im.r1 + im.r2), h["y43"], vn, h["alpha"])


# ====================================================================== runs
def native_settings(law, dt: float, flavour: str):
    """The native engine's settings for ``law`` (the tests perturb this hook)."""
    return law.dem_settings(dt, SKIN, flavour)


def native_law(law, flavour: str):
    """The native engine's plug-in law for ``law`` (None: the Hooke law of the settings; the tests
    perturb this hook)."""
    return law.native_law(flavour)


def run_native(scene: Scene, flavour: str, dt: float = DT) -> dict:
    """The native engine's frames at the dump steps (every EVERY * DT / dt steps):
    {step: {"x", "v", "w", "f", "t"}}."""
    from gransim.dem import DEMEngine, Loading

    p, v, w, n, _ = layout(scene, dt)
    every = round(EVERY * DT / dt)
    eng = DEMEngine(p, native_settings(scene.law, dt, flavour), velocities=v, spins=w,
                    law=native_law(scene.law, flavour))
    ld = Loading()
    frames = {0: _frame(eng)}
    for k in range(every, n + 1, every):
        eng.advance(ld, every)
        frames[k] = _frame(eng)
    return frames


def _frame(eng) -> dict:
    return {"x": eng.x.copy(), "v": eng.v.copy(), "w": eng.w.copy(), "f": eng.f.copy(), "t": eng.t.copy()}


def write_job_deck(job_dir, scene: Scene, engine: str) -> tuple[str, dict]:
    """(deck text, input files) of the scene's job for ``engine``."""
    from reference_runs.decks.impact import DATA_NAME, write_impact_deck

    p, v, w, n, _ = layout(scene)
    deck = write_impact_deck(job_dir, p, scene.law, DT, SKIN, n, v, w, engine=engine, dump_every=EVERY,
                             thermo_every=EVERY * 10)
    return deck.read_text(), {DATA_NAME: (Path(job_dir) / DATA_NAME).read_bytes()}


def run_code(ctx: Context, scene: Scene, engine: str) -> tuple[dict, Path, bool]:
    """Frames of the scene in ``engine`` (live when installed, else stored); (frames, job dir, live)."""
    from reference_runs.decks.impact import DUMP_NAME, read_frames
    from reference_runs.runner import run_job

    live = ctx.liggghts if engine == "liggghts" else ctx.lammps
    if live:
        job = ctx.work("reference", "impacts", engine, scene.name)
        p, _, _, n, _ = layout(scene)
        with tempfile.TemporaryDirectory() as tmp:
            text, files = write_job_deck(tmp, scene, engine)
        res = run_job(job, text, files=files, outputs=(DUMP_NAME,), expected_runs=1, progress=False,
                      timeout=ctx.job_timeout(p.n * n), engine=engine)
        job = res.job_dir
    else:
        job = stored_dir(f"impacts-{engine}") / scene.name
    from gransim.errors import ResultFileError

    try:  # a cut or damaged dump is missing evidence (the evidence record names it), not a crash
        frames = read_frames(job / DUMP_NAME) if (job / DUMP_NAME).exists() else {}
    except ResultFileError:
        frames = {}
    return frames, job, live


# ====================================================================== measurements
def _hermite_root(da, db, pa, pb, h) -> float:
    """Root in [0, 1] of the cubic Hermite interpolant of delta on one sampling interval (values
    da, db, rates pa, pb, length h): the crossing of delta = 0 to O(h^4)."""
    c = [2 * da + h * pa - 2 * db + h * pb, -3 * da - 2 * h * pa + 3 * db - h * pb, h * pa, da]
    r = [x.real for x in np.roots(c) if abs(x.imag) < 1e-9 and -1e-9 <= x.real <= 1 + 1e-9]
    return min(r, key=lambda x: abs(x - da / (da - db))) if r else da / (da - db)


def measure(frames: dict, scene: Scene, pairs, dt: float) -> list[dict]:
    """Per impact, from the frames: contact time (crossings of delta = 0 by the cubic Hermite
    interpolant of delta and delta' between frames), restitution, peak overlap (parabola through
    the largest sampled overlap), exit slip and spin, friction impulse m1 |dv1.t|, and the largest
    |F_t|/(mu |F_n|) - 1 over the contact frames. NaN where the contact did not start or end
    between frames."""
    keys = ("contact time", "restitution", "peak overlap", "peak force", "exit slip", "w1'",
            "friction impulse", "coulomb bound", "s0")
    if len(frames) < 4:
        return [{k: math.nan for k in keys} for _ in scene.impacts]
    steps = np.array(sorted(frames))
    times = steps * dt
    X = np.stack([frames[s]["x"] for s in steps])
    Vv = np.stack([frames[s]["v"] for s in steps])
    W = np.stack([frames[s]["w"] for s in steps])
    F = np.stack([frames[s]["f"] for s in steps])
    out = []
    for im, (i, j) in zip(scene.impacts, pairs):
        q = {k: math.nan for k in keys}
        d = X[:, j] - X[:, i]
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        delta = im.r1 + im.r2 - dist
        rate = np.einsum("ij,ij->i", Vv[:, i] - Vv[:, j], d) / dist
        on = np.flatnonzero(delta > 0)
        if len(steps) < 4 or on.size == 0 or on[0] == 0 or on[-1] >= len(steps) - 1:
            out.append(q)
            continue
        a, b = on[0], on[-1]
        h0, h1 = times[a] - times[a - 1], times[b + 1] - times[b]
        t0 = times[a - 1] + h0 * _hermite_root(delta[a - 1], delta[a], rate[a - 1], rate[a], h0)
        t1 = times[b] + h1 * _hermite_root(delta[b], delta[b + 1], rate[b], rate[b + 1], h1)
        q["contact time"] = t1 - t0
        k = int(np.argmax(delta))
        den = delta[k + 1] - 2 * delta[k] + delta[k - 1]
        q["peak overlap"] = float(delta[k] - (delta[k + 1] - delta[k - 1]) ** 2 / (8 * den))
        n = d[k] / dist[k]
        t = np.array([-n[1], n[0]])
        vin, vout = Vv[0, i] - Vv[0, j], Vv[-1, i] - Vv[-1, j]
        q["restitution"] = -float(vout @ n) / float(vin @ n)
        s0 = float(vin @ t) + im.r1 * W[0, i] + im.r2 * W[0, j]
        s1 = float(vout @ t) + im.r1 * W[-1, i] + im.r2 * W[-1, j]
        q["s0"], q["exit slip"], q["w1'"] = s0, s1, float(W[-1, i])
        q["friction impulse"] = abs(_mass(im.r1) * float((Vv[-1, i] - Vv[0, i]) @ t))
        nn = d[a:b + 1] / dist[a:b + 1, None]
        fn = np.einsum("ij,ij->i", F[a:b + 1, i], nn)
        ft = F[a:b + 1, i, 1] * nn[:, 0] - F[a:b + 1, i, 0] * nn[:, 1]
        kf = int(np.argmax(-fn))
        if 0 < kf < len(fn) - 1:
            f0, f1, f2 = -fn[kf - 1], -fn[kf], -fn[kf + 1]
            q["peak force"] = float(f1 - (f2 - f0) ** 2 / (8 * (f2 - 2 * f1 + f0)))
        mu = scene.law.mu
        q["coulomb bound"] = float(np.max(np.abs(ft) / (mu * np.abs(fn)))) - 1.0 if mu > 0 else math.nan
        out.append(q)
    return out


def analytic(scene: Scene, im: Impact) -> dict:
    """The analytic answers of one impact (module docstring, eqs 2-8)."""
    law = scene.law
    m1, m2 = _mass(im.r1), _mass(im.r2)
    meff = m1 * m2 / (m1 + m2)
    vn = im.v1[0] - im.v2[0]
    nl = normal_answers(law, im)
    if isinstance(getattr(law, "restitution", None), float):  # LIGGGHTS hertz: e as requested
        nl["restitution (ODE)"] = nl["restitution"]
        nl["restitution"] = law.restitution
    s0 = (im.v1[1] - im.v2[1]) + im.r1 * im.w1 + im.r2 * im.w2
    P = nl["impulse factor"] * meff * vn
    out = dict(nl, s0=s0, P=P)
    if im.kind in ("sliding", "microslip"):
        rb = oblique_rigid(m1, m2, im.r1, im.r2, vn, s0, law.mu, P)
        out.update(rb)
        out["w1'"] = im.w1 + rb["dw1"]
    elif im.kind == "stick":
        if hasattr(law, "hertz"):
            h = law.hertz()
            if h["damping"] != "none":
                raise ValueError(f"{scene.name}: the sticking Hertz reference is undamped")
            ratio = hertz_stick(meff, im.r1 * im.r2 / (im.r1 + im.r2), h["y43"], h["kt0"], vn)
        else:
            ratio = stick_ratio(meff, law.kt, law.gamma_t, nl["contact time"])
        J = meff * abs(s0) * (1.0 - ratio) / 3.0
        te = tangential_exit(m1, m2, im.r1, im.r2, s0, J)
        out.update(te)
        out["stick ratio"] = ratio
        out["w1'"] = im.w1 + te["dw1"]
    return out


def errors(q: dict, an: dict, im: Impact) -> dict:
    """Errors of measured ``q`` against ``an`` per checked quantity (see TOL)."""
    e = {"contact time": abs(q["contact time"] / an["contact time"] - 1.0),
         "restitution": abs(q["restitution"] / an["restitution"] - 1.0),
         "peak overlap": abs(q["peak overlap"] / an["peak overlap"] - 1.0)}
    if "peak force" in an:
        e["peak force"] = abs(q["peak force"] / an["peak force"] - 1.0)
    if im.kind in ("sliding", "stick"):
        s0 = abs(an["s0"])
        sfx = "" if im.kind == "sliding" else " (stick)"
        e["friction impulse" + sfx] = abs(q["friction impulse"] / an["friction impulse"] - 1.0)
        e["exit slip" + sfx] = abs(q["exit slip"] - an["exit slip"]) / s0
        e["exit spin" + sfx] = im.r1 * abs(q["w1'"] - an["w1'"]) / s0
    if im.kind in ("sliding", "microslip"):
        e["coulomb bound"] = max(q["coulomb bound"], 0.0) if math.isfinite(q["coulomb bound"]) else math.nan
    return {k: (v if math.isfinite(v) else math.nan) for k, v in e.items()}


# ====================================================================== comparisons
def bitwise_records(label: str, a: dict, b: dict, who: str) -> list:
    """Step-for-step records of two trajectories over the steps both hold (evidence separately)."""
    common = sorted(set(a) & set(b))
    if not common:
        return [compare(label, "positions", f"max |dx|/D (native vs {who}, no common frames)", math.nan,
                        BIT_POS, "nothing to compare")]
    out = []
    D = 2 * R
    dx = max(float(np.max(np.abs(a[s]["x"] - b[s]["x"]))) for s in common) / D
    out.append(compare(label, "positions", f"max |dx|/D over {len(common)} frames (native vs {who})", dx, BIT_POS,
                       "the native engine in this code's arithmetic reproduces it bit for bit (docs/lammps.md); "
                       "1e-10 D as biaxial-short"))
    for key, name in (("v", "velocities"), ("w", "spins"), ("f", "forces"), ("t", "torques")):
        top = max(float(np.max(np.abs(b[s][key]))) for s in common) or 1.0
        diff = max(float(np.max(np.abs(a[s][key] - b[s][key]))) for s in common) / top
        out.append(compare(label, name, f"max |d{key}|/max|{key}| (native vs {who})", diff, BIT_REL,
                           "bit for bit expected; 1e-8 relative as biaxial-short"))
    return out


def _fmt(v):
    return "nan" if not math.isfinite(v) else f"{v:.6g}"


@case("impacts", "Analytic 2D impact benchmarks: normal, oblique and spinning disks (native, LIGGGHTS, LAMMPS)",
      suites=("quick", "default", "full"), order=15)
def impacts(ctx: Context) -> CaseResult:
    res = CaseResult(
        "impacts", "Analytic 2D impact benchmarks: normal, oblique and spinning disks (native, LIGGGHTS, LAMMPS)",
        "Binary disk impacts (Chung &amp; Ooi 2011 tests 1-8 adapted to disks, I = m r<sup>2</sup>/2; a disk of 25 "
        "radii standing in for the wall) with the linear Hooke law with tangential history, run by the native engine "
        "in both flavours, LIGGGHTS 3.8.0 and LAMMPS 29Sep2021, against the closed forms of docs/impacts.md: contact "
        "time pi/w_d, restitution exp(-pi zeta/sqrt(1 - zeta<sup>2</sup>)), peak overlap, the rigid-body limit of "
        "gross sliding (Psi1 &ge; 6 for disks) and the sticking tangential oscillator. Each analytic record's value is "
        "the largest error over the implementations; its metric lists the analytic value and each one's value.")
    res.declare("native-liggghts", "bit for bit: every step of every impact of the Hooke scenes and "
                                   "of LIGGGHTS' hertz scenes (native flavour liggghts)")
    res.declare("native-lammps", "bit for bit: every step of every impact of the Hooke scenes and of "
                                 "LAMMPS' gran/hertz/history and granular hertz/material scenes "
                                 "(native flavour lammps)")
    all_scenes = scenes(ctx.suite)
    if any(len(s.law.engines) == 2 for s in all_scenes):
        res.declare("liggghts-lammps", "Hooke scenes: the codes' answers differ by at most the sum of "
                                       "their analytic tolerances (both lie within them); their "
                                       "difference equals the native flavours' difference")
    else:
        res.skip_pair("liggghts-lammps", "only single-code (Hertz) scenes selected: each is judged "
                                         "against its own closed forms")
    table_rows, dt_rows = [], []
    cross = {}
    nat_key = {"liggghts": "native", "lammps": "native-lammps"}
    for sc in all_scenes:
        _, _, _, nsteps, pairs = layout(sc)
        lab = f"impacts/{sc.name}"
        codes = tuple(c for c in CODES if c in sc.law.engines)
        ref = nat_key[codes[0]]
        tols = tolerances(sc)
        got = {nat_key[c]: run_native(sc, c) for c in codes}
        half = run_native(sc, codes[0], DT / 2)
        for code in codes:
            frames, job, live = run_code(ctx, sc, code)
            pair = f"native-{code}"
            recs = [] if live else [stored_job_record(f"{lab}/{code}", job)]
            recs.append(evidence(f"{lab}/{code}", f"{CODE[code]} frames", list(range(0, nsteps + 1, EVERY)),
                                  list(frames)))
            recs += bitwise_records(f"{lab}/{code}", got[nat_key[code]], frames, CODE[code])
            res.records += in_pair(recs, pair)
            got[code] = frames
            if not live:
                res.notes.append(f"{sc.name}: {CODE[code]} absent, its stored outputs <code>{job}</code> are used.")
        meas = {who: measure(fr, sc, pairs, DT) for who, fr in got.items()}
        m_half = measure(half, sc, pairs, DT / 2)
        worst = {}
        for k, im in enumerate(sc.impacts):
            an = analytic(sc, im)
            errs = {who: errors(meas[who][k], an, im) for who in got}
            eh = errors(m_half[k], an, im)
            for qn in errs[ref]:
                tol, why = tols[qn]
                vals = {who: errs[who][qn] for who in got}
                val = max(vals.values(), key=lambda x: math.inf if not math.isfinite(x) else x)
                src = qn.replace(" (stick)", "")
                if src == "exit spin":
                    src = "w1'"
                aval = an.get(src, math.nan)
                shown = ", ".join(f"{w} {_fmt(meas[w][k][src])}" for w in got)
                kind = an.get("source", "analytic") if src in ("contact time", "peak overlap", "peak force",
                                                               "restitution") else "analytic"
                if src == "restitution" and "restitution (ODE)" in an:
                    kind = f"requested e; DOP853 gives {an['restitution (ODE)']:.10g}"
                if im.kind == "stick" and hasattr(sc.law, "hertz") and src != qn:
                    kind = "Mindlin oscillator integrated (DOP853)"
                metric = (f"error ({kind if qn != 'coulomb bound' else 'bound'} "
                          f"{_fmt(aval) if qn != 'coulomb bound' else 'mu |F_n|'}; {shown})")
                res.records.append(compare(f"{lab}/{im.label}", qn, metric, val, tol, why))
                e1, e2 = errs[ref][qn], eh[qn]
                w_ = worst.setdefault(qn, [0.0, 0.0])
                if math.isfinite(e1) and math.isfinite(e2):
                    w_[0], w_[1] = max(w_[0], e1), max(w_[1], e2)
                if len(codes) == 2:
                    cross.setdefault((sc.name, qn), []).append(
                        (meas["liggghts"][k][src], meas["lammps"][k][src], meas["native"][k][src],
                         meas["native-lammps"][k][src], tol))
            if im.kind == "microslip":
                res.records.append(info(f"{lab}/{im.label}", "exit slip vs rigid-body limit",
                                        f"s'/s0: rigid limit 0 (rolling; Psi1 = {an['psi1']:.3g} < 6); "
                                        + ", ".join(f"{w} {_fmt(meas[w][k]['exit slip'] / an['s0'])}" for w in got),
                                        meas[codes[0]][k]["exit slip"] / an["s0"],
                                        "microslip: the compliant tangential spring leaves a residual slip the rigid "
                                        "limit has not; no closed form for the discrete cap"))

            def cell(code, key, k=k, meas=meas):
                return _fmt(meas[code][k][key]) if code in meas else "-"

            table_rows.append([sc.name, im.label, im.kind, f"{an['contact time']:.6g}",
                               cell("liggghts", "contact time"), cell("lammps", "contact time"),
                               f"{an['restitution']:.6g}", cell("liggghts", "restitution"),
                               cell("lammps", "restitution"),
                               _fmt(an.get("exit slip", math.nan)), cell("liggghts", "exit slip"),
                               cell("lammps", "exit slip")])
        for qn, (e1, e2) in worst.items():
            order = math.log2(e1 / e2) if e1 > 1e-12 and e2 > 0 else math.nan
            res.records.append(info(lab, f"{qn}: time-step order", f"max error {e1:.3g} at dt = {DT:g} s, {e2:.3g} "
                                    f"at dt/2: observed order log2(ratio)", order,
                                    f"native engine ({codes[0]} arithmetic) at dt and dt/2: the "
                                    "discretisation error the tolerance covers"))
            dt_rows.append([sc.name, qn, f"{e1:.3g}", f"{e2:.3g}", _fmt(order)])
    # -- LIGGGHTS vs LAMMPS
    for (name, qn), rows in cross.items():
        a = np.array([r[:4] for r in rows], float)
        tol = rows[0][4]
        scale = np.maximum(np.abs(a[:, 0]), 1e-300)
        if qn.startswith(("exit", "coulomb")):
            scale = np.ones_like(scale)
        dif = np.abs(a[:, 0] - a[:, 1]) / scale
        raw = float(np.max(dif)) if np.all(np.isfinite(dif)) else math.nan
        unexpl = np.abs((a[:, 0] - a[:, 1]) - (a[:, 2] - a[:, 3])) / np.maximum(np.abs(a[:, 0]), 1e-300)
        un = float(np.max(unexpl)) if np.all(np.isfinite(unexpl)) else math.nan
        lab = f"impacts/{name}/cross"
        res.records += in_pair([
            info(lab, f"{qn}: LIGGGHTS - LAMMPS", "raw max difference (relative; absolute for slips and spins)", raw,
                 "LAMMPS' lever arm is r (LIGGGHTS r - delta/2) and its Coulomb cap includes the damping "
                 "(docs/lammps.md A-B): the spinning and oblique answers differ by O(delta/r)"),
            compare(lab, f"{qn}: difference explained by the native flavours",
                    "max |(LIGGGHTS - LAMMPS) - (native liggghts - native lammps)| / |value|", un, 1e-9,
                    "the codes' difference is the difference of the two laws, nothing else")], "liggghts-lammps")
        if qn != "coulomb bound":
            res.records += in_pair([compare(lab, f"{qn}: LIGGGHTS vs LAMMPS", "max |LIGGGHTS - LAMMPS| over impacts",
                                            raw, 2 * tol, "both lie within the analytic tolerance, so they differ by "
                                            "at most twice it")], "liggghts-lammps")
    res.tables.append(("Impacts: analytic value and each code's value (contact time s, restitution, exit slip m/s)",
                       ["scene", "impact", "kind", "t_c analytic", "t_c LIGGGHTS", "t_c LAMMPS", "e analytic",
                        "e LIGGGHTS", "e LAMMPS", "s' analytic", "s' LIGGGHTS", "s' LAMMPS"], table_rows))
    res.tables.append((("Time-step error (native, in the arithmetic of the scene's first code): "
                        "largest error over the scene's impacts"),
                       ["scene", "quantity", f"dt = {DT:g} s", "dt/2", "order"], dt_rows))
    return res


# ====================================================================== stored outputs
def make_stored(root=None, suite: str = "full", timeout: float = 600.0, names=None) -> list[Path]:
    """Run the scenes of ``suite`` (only ``names`` if given) in each code that has the scene's law
    and store the job directories under ``reference_runs/stored/impacts-<code>/<scene>/`` (deck,
    data, log, dump, manifest), other scene directories kept, with a README listing them all.
    Needs ``liggghts`` and ``lmp``."""
    import datetime
    import json
    import shutil

    from reference_runs import store
    from reference_runs.decks.impact import DUMP_NAME
    from reference_runs.runner import run_job

    root = Path(root or store.STORED)
    out = []
    for code in CODES:
        base = root / f"impacts-{code}"
        base.mkdir(parents=True, exist_ok=True)
        for sc in scenes(suite):
            if code not in sc.law.engines or (names is not None and sc.name not in names):
                continue
            job = base / sc.name
            if job.exists():
                shutil.rmtree(job)
            with tempfile.TemporaryDirectory() as tmp:
                text, files = write_job_deck(tmp, sc, code)
                res = run_job(Path(tmp) / "job", text, files=files, outputs=(DUMP_NAME,), expected_runs=1,
                              progress=False, timeout=timeout, engine=code, force=True)
                shutil.copytree(res.job_dir, job)
            out.append(job)
        laws = {s.name: s.law.describe() for s in scenes("full") if code in s.law.engines}
        rows, versions = [], set()
        for d in sorted(x for x in base.iterdir() if x.is_dir()):
            man = json.loads((d / "manifest.json").read_text()) if (d / "manifest.json").exists() else {}
            versions.add(f"{man.get('engine_version')} ({man.get('engine_binary')}, "
                         f"Debian {man.get('engine_package')})")
            rows.append(f"| `{d.name}` | {laws.get(d.name, '?')} | {man.get('end', '?')} |")
        (base / "README.md").write_text(f"""# impacts-{code}: {CODE[code]} outputs of the impact benchmarks

- Case: `validation/cases/impacts.py` (docs/impacts.md): one job directory per scene (as
  `reference_runs.runner.run_job` leaves it: deck, `data.impact`, `log.lammps`, `dump.atoms` every
  5 steps at %.17g, `manifest.json` with SHA-256 of every file).
- Deck: `reference_runs/decks/impact.py` (`write_impact_deck(..., engine="{code}")`), the scene's law:

  | scene | law | finished |
  |---|---|---|
{chr(10).join("  " + r for r in rows)}

- Code: {'; '.join(sorted(versions))}, serial.
- Command: `{'liggghts -in in.liggghts' if code == 'liggghts' else 'lmp -in in.lammps'} -log log.lammps -screen none
  -nocite` in the job directory.
- Regenerate: `python -c "from validation.cases.impacts import make_stored; make_stored()"` (one scene:
  `make_stored(names=["<scene>"])`).
- Written: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}
- Used by: the `impacts` validation case when {CODE[code]} is not installed, and
  tests/validation/test_impacts.py.
""")
    return out
