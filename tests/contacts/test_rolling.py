"""Rolling-resistance laws of gransim.contacts.rolling: bit-for-bit two-disk runs against
LIGGGHTS 3.8.0 (epsd2, epsd, cdt) and LAMMPS 29Sep2021 (granular rolling sds) (stored runs,
reference_runs/stored/rolling-*/README.md; live runs when the binaries exist), each model's
torque cap, dissipation, and the decay of a spinning pair against each model's 2D decay law
(the rolling-resistance benchmark in the spirit of Mohajeri et al., Powder Technol. 447, 2024)."""

from __future__ import annotations

import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from gransim.contacts import hooke, rolling
from reference_runs.decks import rolling as decks

sys.path.insert(0, str(Path(__file__).parent))
import rolling_replay

ROOT = Path(__file__).resolve().parents[2]
STORED = ROOT / "reference_runs/stored"
LAWS = list(decks.LAWS)


def _py(f):
    return getattr(f, "py_func", f)


def _compare(law, dump_path):
    d = decks.read_rolling_dump(dump_path)
    case = decks.rolling_case()
    masses = d[0]["mass"]
    assert masses == pytest.approx(math.pi * np.array(case["radii"]) ** 2 * case["density"], rel=1e-15)
    rep = rolling_replay.replay(law, case, list(masses))
    assert sorted(d) == list(range(case["nsteps"] + 1))
    touching = capped = 0
    for step, fr in d.items():
        for k in ("x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz"):
            assert np.array_equal(fr[k], np.array(rep[step][k])), (law, step, k)
        touching += fr["fx"][0] != 0.0
        capped += rep[step]["rolling"]
    # the run is a rolling contact for 223 steps; the spring models pass through both regimes
    assert touching > 200
    if law in ("epsd2", "epsd", "sds"):
        assert 0 < capped < touching
    return rep


@pytest.mark.parametrize("law", LAWS)
def test_bit_for_bit_with_stored_run(law):
    """The test-local nve/sphere loop with the native law reproduces every dumped number of every
    step of the stored run (positions, velocities, spins, forces, torques): difference 0."""
    _compare(law, decks.stored_dir(STORED, law) / decks.DUMP_NAME)


def _live(law, tmp_path):
    engine = decks.LAWS[law][0]
    if shutil.which("liggghts" if engine == "liggghts" else "lmp") is None:
        pytest.skip(f"{engine} binary not installed")
    res = decks.run_rolling(tmp_path / law, law)
    stored = decks.stored_dir(STORED, law) / decks.LAWS[law][1]
    assert stored.read_text() == decks.deck_text(decks.rolling_case(), law)
    _compare(law, res.path(decks.DUMP_NAME))


@pytest.mark.liggghts
@pytest.mark.parametrize("law", ["epsd2", "epsd", "cdt"])
def test_bit_for_bit_with_live_liggghts(law, tmp_path):
    """The same against a fresh run of /usr/bin/liggghts (skipped without it)."""
    _live(law, tmp_path)


@pytest.mark.lammps
def test_bit_for_bit_with_live_lammps(tmp_path):
    """The same against a fresh run of /usr/bin/lmp (skipped without it)."""
    _live("sds", tmp_path)


def _cap(law, case, fr):
    """Each model's own bound on the rolling torque of one frame (N m)."""
    r1, r2 = case["radii"]
    reff = r1 * r2 / (r1 + r2)
    mu_r = case["rolling_friction"]
    if law == "cdt":  # cdt uses the elastic normal force kn delta, not F_n
        d = math.hypot(fr["x"][0] - fr["x"][1], fr["y"][0] - fr["y"][1])
        return mu_r * reff * case["kn"] * (r1 + r2 - d)
    return mu_r * reff * abs(fr["fn"])


@pytest.mark.parametrize("law", LAWS)
def test_rolling_torque_never_exceeds_its_cap(law):
    """Every step of the two-disk run: epsd2 and sds |M| <= mu_r R* |F_n| (sds: spring and dashpot
    together, pair_granular.cpp:604), cdt |M| = mu_r R* kn delta exactly while spinning. epsd caps
    only its spring: the stored torque obeys the cap, the total with the dashpot may exceed it
    (rolling_model_epsd.h:294-330; measured here: it does, in the steps where F_n is small)."""
    case = decks.rolling_case()
    d = decks.read_rolling_dump(decks.stored_dir(STORED, law) / decks.DUMP_NAME)
    rep = rolling_replay.replay(law, case, list(d[0]["mass"]))
    over = 0
    for fr in rep.values():
        if fr["fx"][0] == 0.0:
            continue
        cap = _cap(law, case, fr)
        if law == "epsd":
            assert abs(fr["h"][2]) <= cap * (1 + 1e-15)
            over += abs(fr["tr"]) > cap
        elif law == "cdt":
            assert abs(fr["tr"]) == pytest.approx(cap, rel=1e-14)
        else:
            assert abs(fr["tr"]) <= cap * (1 + 1e-15)
            if fr["rolling"]:
                assert abs(fr["tr"]) == pytest.approx(cap, rel=1e-14)
    if law == "epsd":
        assert over > 0


def _pair(law, delta, w, m, dt=2.5e-6, vn=0.0, update=True, gammaroll=0.002):
    """One call of ``law`` on a fixed pair with overlap delta (normal 20 deg), relative spin w
    (w_i = w, w_j = 0), normal velocity vn, rolling history m (the law's columns after the spring)."""
    case = decks.rolling_case()
    r1, r2 = case["radii"]
    ang = math.radians(20.0)
    dist = r1 + r2 - delta
    delx, dely = -dist * math.cos(ang), -dist * math.sin(ang)
    m1, m2 = math.pi * r1 * r1 * 25.0, math.pi * r2 * r2 * 25.0
    params = rolling_replay.law_params(law, dict(case, gammaroll=gammaroll))
    vix, viy = -vn * math.cos(ang), -vn * math.sin(ang)
    return _py(rolling_replay.FUNCS[law])(
        delx,
        dely,
        delx * delx + dely * dely,
        r1,
        r2,
        vix,
        viy,
        0.0,
        0.0,
        w,
        0.0,
        m1,
        m2,
        *params,
        dt,
        0.0,
        0.0,
        *m,
        update,
    )


def _energy(law, h):
    """Energy stored in the rolling element (J): M^2/(2K) for epsd2/epsd, kroll |psi|^2/2 for sds."""
    case = decks.rolling_case()
    r1, r2 = case["radii"]
    reff = r1 * r2 / (r1 + r2)
    if law == "cdt":
        return 0.0
    if law == "sds":
        return 0.5 * case["kroll"] * (h[2] ** 2 + h[3] ** 2)
    K = rolling.rolling_stiffness(law, reff, kn=case["kn"], kt=case["kt"], mu_r=case["rolling_friction"])
    return h[2] ** 2 / (2 * K)


@pytest.mark.parametrize("law", LAWS)
def test_rolling_resistance_only_dissipates(law):
    """Per step, the work done on the contact by the relative rotation, -M w dt (M: the rolling
    torque on i), is at least the change of the energy stored in the rolling element: D >= 0.
    epsd2 (and sds without its dashpot) is an elastic-perfectly-plastic element whose update
    M_new = M_old + K w dt gives D = K (w dt)^2/2 below the cap and D = ((M_old - M_new)^2 +
    2 c (|T| - c))/(2K) > 0 on it (T the trial torque, c the cap); epsd and sds add their dashpots'
    C w^2 dt; cdt has no stored energy and M w >= 0. Random sequences of spins (reversing) and
    overlaps (the cap moving, loading and unloading), 400 steps each, with normal velocity (F_n
    damped)."""
    rng = np.random.default_rng(7)
    width = rolling.HISTORY_WIDTH[law]
    for _ in range(5):
        hist = [0.0] * (width - 2)
        for _ in range(400):
            w = rng.normal(0.0, 60.0)
            delta = rng.uniform(2e-6, 2e-5)
            out = _pair(law, delta, w, hist, vn=rng.normal(0.0, 0.01))
            new = list(out[4 : 4 + width])
            tr = out[7 + width]
            e_old = _energy(law, [0.0, 0.0, *hist])
            e_new = _energy(law, new)
            D = -tr * w * 2.5e-6 - (e_new - e_old)
            assert D >= -1e-12 * (abs(tr * w * 2.5e-6) + e_old + e_new + 1e-30)
            if law == "epsd" and not out[5 + width]:
                # the dashpot part M - M_spring opposes the relative spin
                assert (-tr - new[2]) * w >= 0.0
            hist = new[2:]


def test_granular_mass_velocity_normal_is_gran_hooke_history():
    """``damping mass_velocity`` makes granular hooke's normal force kn delta - m* DAMP v_n, the
    normal force of ``gran/hooke/history`` with gamman = DAMP (to round-off: other operations);
    ``velocity`` is DAMP v_n (kg/s), ``viscoelastic`` a m* DAMP v_n: neither equals it."""
    case = decks.rolling_case()
    r1, r2 = case["radii"]
    m1, m2 = math.pi * r1 * r1 * 25.0, math.pi * r2 * r2 * 25.0
    ang = 0.3
    for delta, vn in ((1e-6, 0.05), (1e-5, -0.1), (3e-5, 0.2)):
        dist = r1 + r2 - delta
        args = (
            dist * math.cos(ang),
            dist * math.sin(ang),
            dist * dist,
            r1,
            r2,
            vn * math.cos(ang),
            vn * math.sin(ang),
            0.0,
            0.0,
            0.0,
            0.0,
            m1,
            m2,
        )
        ref = _py(hooke.hooke_history_lammps)(*args, 1000.0, 800.0, 2000.0, 1000.0, 0.4, 1e-6, 0.0, 0.0, False)[7]
        got = {}
        for model in (rolling.DAMPING_VELOCITY, rolling.DAMPING_MASS_VELOCITY, rolling.DAMPING_VISCOELASTIC):
            got[model] = _py(rolling.hooke_sds_granular_lammps)(
                *args, 1000.0, 2000.0, model, 800.0, 0.5, 0.4, 800.0, 0.0, 0.2, 1e-6, 0.0, 0.0, 0.0, 0.0, False
            )[10]
        assert got[rolling.DAMPING_MASS_VELOCITY] == pytest.approx(ref, rel=1e-13)
        assert got[rolling.DAMPING_VELOCITY] != pytest.approx(ref, rel=1e-3)
        assert got[rolling.DAMPING_VISCOELASTIC] != pytest.approx(ref, rel=1e-3)


# ----------------------------------------------------------------------------- decay benchmark
#
# Two disks (r 1.0 and 0.8 mm, 25 kg/m^2) held at a fixed overlap delta (centres fixed, F_n =
# kn delta: no normal motion), mu = 0 and gamma_t = 0 (no tangential force: the rolling torque
# alone acts), spins w_i = w0, w_j = 0. With I = m r^2/2 and the torque -M on i, +M on j, the
# relative spin w = w_i - w_j obeys I_r dw/dt = -M, I_r = I_i I_j/(I_i + I_j), and I_i w_i + I_j w_j
# is conserved. The 2D decay laws (theta the relative rotation, K the model's rotational stiffness,
# c = mu_r R* F_n its cap):
# * cdt: M = c sgn(w): w = w0 - c t/I_r, stops at t* = w0 I_r/c;
# * epsd2, sds without dashpot (K = kt R*^2, resp. kroll R*^2): elastic w = w0 cos(Omega t),
#   Omega = sqrt(K/I_r), until K theta = c at t1 = asin(c/(K theta0))/Omega (theta0 = w0/Omega),
#   w1 = sqrt(w0^2 - (c/sqrt(K I_r))^2); then w = w1 - c (t - t1)/I_r, zero at
#   t2 = t1 + w1 I_r/c; then an undamped oscillation of amplitude c/sqrt(K I_r) (the energy
#   c^2/(2K) left in the spring is never dissipated);
# * epsd, sds below the cap: I_r theta'' + C theta' + K theta = 0 with epsd C = eta_r 2 sqrt(3 I_r K)
#   (LIGGGHTS' 1.5 m r^2 pair inertia is 3 I_r for disks), zeta = eta_r sqrt(3); sds
#   C = gammaroll R*^2: w = w0 e^(-zeta Omega t)(cos(Omega_d t) - zeta/sqrt(1-zeta^2) sin(Omega_d t)).

BR1, BR2, BRHO, BDELTA, BKN, BKT, BMUR = 1.0e-3, 0.8e-3, 25.0, 1.0e-5, 1000.0, 800.0, 0.2
BREFF = BR1 * BR2 / (BR1 + BR2)
BM = (math.pi * BR1**2 * BRHO, math.pi * BR2**2 * BRHO)
BI = (0.5 * BM[0] * BR1**2, 0.5 * BM[1] * BR2**2)
BIR = BI[0] * BI[1] / (BI[0] + BI[1])
BCAP = BMUR * BREFF * BKN * BDELTA


def _decay(law, w0, dt, nsteps, eta_r=0.3, gammaroll=0.0):
    ang = math.radians(20.0)
    dist = BR1 + BR2 - BDELTA
    case = {
        "radii": (BR1, BR2),
        "positions": ((0.0, 0.0), (dist * math.cos(ang), dist * math.sin(ang))),
        "velocities": ((0.0, 0.0), (0.0, 0.0)),
        "spins": (w0, 0.0),
        "dt": dt,
        "nsteps": nsteps,
    }
    hk = (BKN, BKT, 2000.0, 0.0, 0.0, BMUR)
    params = {
        "epsd2": hk,
        "cdt": hk,
        "epsd": hk + (eta_r,),
        "sds": (BKN, 2000.0, rolling.DAMPING_MASS_VELOCITY, BKT, 0.0, 0.0, BKT, gammaroll, BMUR),
    }[law]
    rep = rolling_replay.replay(law, case, BM, fixed_centres=True, params=params)
    t = np.arange(nsteps + 1) * dt
    wi = np.array([rep[n]["omegaz"][0] for n in range(nsteps + 1)])
    wj = np.array([rep[n]["omegaz"][1] for n in range(nsteps + 1)])
    # no tangential force, equal and opposite rolling torques: angular momentum is conserved
    assert np.allclose(BI[0] * wi + BI[1] * wj, BI[0] * w0, rtol=1e-12, atol=0)
    return t, wi - wj, rep


def _first_zero(t, w):
    k = int(np.argmax(w <= 0.0))
    return t[k - 1] + w[k - 1] / (w[k - 1] - w[k]) * (t[k] - t[k - 1])


def test_decay_cdt_is_linear():
    """cdt: the relative spin falls linearly at c/I_r to round-off (the torque is constant while
    w > 0) and reaches t* = w0 I_r/c within one step; then it stays within one kick c dt/I_r of
    zero (the half-step spin alternates in sign and so does the torque: the full-step spin
    freezes at a value below one kick, a property of the constant-torque model in the nve step)."""
    w0, dt = 100.0, 2.5e-6
    tstar = w0 * BIR / BCAP
    t, w, _ = _decay("cdt", w0, dt, int(1.2 * tstar / dt))
    run = t < tstar - 2 * dt
    assert np.max(np.abs(w[run] - (w0 - BCAP * t[run] / BIR))) < 1e-10 * w0
    kick = BCAP * dt / BIR
    assert abs(t[int(np.argmax(w < kick))] - tstar) < dt
    assert np.max(np.abs(w[t > tstar + dt])) <= kick * (1 + 1e-9)


def _slider_law(w0, K):
    Om = math.sqrt(K / BIR)
    t1 = math.asin(BCAP / (K * w0 / Om)) / Om
    w1 = math.sqrt(w0**2 - (BCAP / math.sqrt(K * BIR)) ** 2)
    return t1, w1, t1 + w1 * BIR / BCAP, BCAP / math.sqrt(K * BIR)


@pytest.mark.parametrize("law", ["epsd2", "sds"])
def test_decay_spring_slider(law):
    """epsd2 (K = kt R*^2) and sds without dashpot (K = kroll R*^2, kroll = kt here: the same law):
    the slope of the sliding phase is c/I_r, the spin stops at t2 and keeps oscillating with
    amplitude c/sqrt(K I_r) (epsd2 has no dashpot: the spring energy c^2/(2K) stays). Tolerance
    from halving dt (dt = 2.5e-6 s, Omega dt = 0.009): stop-time error measured 3.2e-5 t2 -> 8.1e-6
    t2 (epsd2) and 9.0e-6 -> 2.3e-6 (sds): second order (ratio 4); amplitude within 1.3e-5."""
    K = BKT * BREFF**2
    w0 = 100.0
    t1, _, t2, amp = _slider_law(w0, K)
    errs = []
    for dt in (2.5e-6, 1.25e-6):
        t, w, _ = _decay(law, w0, dt, int((t2 + 2e-3) / dt))
        slide = (t > t1 + 20 * dt) & (t < t2 - 20 * dt)
        slope = np.polyfit(t[slide], w[slide], 1)[0]
        assert slope == pytest.approx(-BCAP / BIR, rel=1e-9)
        tz = _first_zero(t, w)
        errs.append(abs(tz - t2))
        assert errs[-1] < 1e-4 * t2
        late = w[t > t2 + 1e-3]
        assert np.max(np.abs(late)) == pytest.approx(amp, rel=1e-4)
    assert 3.0 < errs[0] / errs[1] < 5.0


@pytest.mark.parametrize("law", ["epsd", "sds"])
def test_decay_damped_below_cap(law):
    """epsd (zeta = eta_r sqrt 3 = 0.52) and sds with GAMMAROLL (zeta = C/(2 sqrt(K I_r)) = 0.3)
    below the cap: the relative spin follows the damped oscillator. Tolerance from halving dt
    (Omega dt = 0.004, 0.002): the largest error over two periods, relative to w0, measured
    9.2e-4 -> 4.6e-4 (epsd), 8.3e-4 -> 4.2e-4 (sds): first order (the dashpot sees the half-kicked
    spin), ratio 2."""
    if law == "epsd":
        K = 2.25 * BKN * BMUR**2 * BREFF**2
        zeta = 0.3 * math.sqrt(3.0)
        kw = {"eta_r": 0.3}
    else:
        K = BKT * BREFF**2
        zeta = 0.3
        kw = {"gammaroll": zeta * 2 * math.sqrt(K * BIR) / BREFF**2}
    Om = math.sqrt(K / BIR)
    w0 = 0.3 * BCAP / math.sqrt(K * BIR)  # well below the cap
    od = Om * math.sqrt(1 - zeta**2)
    errs = []
    for dt in (4e-3 / Om, 2e-3 / Om):
        n = int(4 * math.pi / Om / dt)
        t, w, rep = _decay(law, w0, dt, n, **kw)
        assert not any(rep[k]["rolling"] for k in rep)
        exact = w0 * np.exp(-zeta * Om * t) * (np.cos(od * t) - zeta / math.sqrt(1 - zeta**2) * np.sin(od * t))
        errs.append(np.max(np.abs(w - exact)) / w0)
    assert errs[0] < 2e-3
    assert 1.8 < errs[0] / errs[1] < 2.2
