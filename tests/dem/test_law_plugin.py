"""Contact laws as plug-ins: a law registered here, in a test module only, runs
through the unchanged integrator and neighbour list of gransim.dem and gives the analytic two-disk
impact; the Hooke laws still are plug-ins of the same loop; checkpoints round-trip bit for bit
through the run file in both flavours; the compiled loop of a law is loaded from numba's disk cache
by a second process."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from collections import namedtuple
from pathlib import Path

import numpy as np
import pytest

from gransim._numba import njit
from gransim.contacts.hooke import HookeLammps, HookeLiggghts, hooke_law
from gransim.contacts.laws import law_spec, register_law
from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import OutputSettings, read_record, read_run
from gransim.dem.run import Phase, run_phases
from gransim.errors import InputError
from gransim.geometry import Packing

# ----------------------------------------------------------------------------- the toy law
#: linear spring-dashpot without tangential force: kn (N/m), gamma (1/s, mass-scaled damping)
LinearDashpot = namedtuple("LinearDashpot", ["kn", "gamma"])


@njit(inline="always")
def linear_dashpot_pair(law, hist, e, delx, dely, rsq, radi, radj, vix, viy, vjx, vjy, wi, wj, mi, mj, dt, update):
    """F_n = kn delta - m_eff gamma v_n along n = d/|d| (may pull at the end of the contact: the
    textbook linear spring-dashpot); history column 0 = time in contact (s), flip +1 (a scalar)."""
    r = math.sqrt(rsq)
    nx = delx / r
    ny = dely / r
    meff = mi * mj / (mi + mj)
    vn = (vix - vjx) * nx + (viy - vjy) * ny
    fn = law.kn * (radi + radj - r) - meff * law.gamma * vn
    if update:
        hist[e, 0] += dt
    return fn * nx, fn * ny, 0.0, 0.0, False, fn


def linear_dashpot_energy(law, overlap, hist):
    return float(0.5 * law.kn * np.sum(overlap**2))


# cache=False: a class of a test module must stay out of the shared disk cache of the kernels
# (every process loading them would have to import this module; laws.LawSpec.cache)
register_law(LinearDashpot, linear_dashpot_pair, 1, flip=(1.0,), energy=linear_dashpot_energy, cache=False)

R = 1.0e-3  # m
RHO = 1000.0  # kg/m^2
KN = 1.0e5  # N/m
V0 = 0.1  # m/s, each disk towards the other
GAP = 1.0e-6  # m, initial surface gap


def _pair(v0=V0):
    pk = Packing(
        positions=np.array([[4.0e-3, 5.0e-3], [4.0e-3 + 2 * R + GAP, 5.0e-3]]),
        radii=np.array([R, R]),
        cell=np.diag([1.0e-2, 1.0e-2]),
        density=RHO,
    )
    return pk, np.array([[v0, 0.0], [-v0, 0.0]])


def _impact(zeta, steps_per_contact, law_of=None, flavour="liggghts"):
    """Head-on impact of two equal disks; returns (analytic tc, measured tc, analytic e, measured e,
    history max, engine, steps in contact)."""
    pk, vel = _pair()
    m = np.pi * R * R * RHO
    meff = m / 2
    omega = math.sqrt(KN / meff)
    gamma = 2 * zeta * omega
    omega_d = omega * math.sqrt(1 - zeta**2)
    tc = math.pi / omega_d
    dt = tc / steps_per_contact
    s = DEMSettings(kn=KN, kt=0.0, gamma_n=gamma, gamma_t=0.0, mu=0.0, dt=dt, skin=2.0e-6, flavour=flavour)
    law = LinearDashpot(KN, gamma) if law_of is None else law_of(s)
    eng = DEMEngine(pk, s, velocities=vel, law=law)
    nsteps = int(1.3 * steps_per_contact) + int(GAP / (2 * V0) / dt) + 20
    res = eng.advance(Loading(), nsteps)
    touching = res["n_contacts"] > 0
    vout = eng.v[1, 0] - eng.v[0, 0]  # separation speed after the impact
    e_exact = math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))
    return tc, touching.sum() * dt, e_exact, vout / (2 * V0), eng, int(touching.sum()), dt


@pytest.mark.parametrize("zeta", [0.0, 0.2])
def test_toy_law_two_disk_impact_matches_the_analytic_solution(zeta):
    """m_eff d'' + m_eff gamma d' + kn d = 0 (d overlap): contact time pi / omega_d with
    omega_d = omega sqrt(1 - zeta^2), omega = sqrt(kn/m_eff), restitution
    e = exp(-pi zeta / sqrt(1 - zeta^2)) (e.g. Schwager & Poeschel, "Coefficient of restitution
    and linear-dashpot model revisited", Granular Matter 9, 2007, eq. 3 with the force allowed to
    pull). Tolerances: contact time within 2 dt (the first and the last step of the contact are
    detected to within one step each; measured: exactly N steps); restitution within
    2 pi^2/N^2 + 0.75 zeta pi/N for N steps per contact: velocity Verlet's error is
    O((omega dt)^2), and the dashpot sees the half-step velocity, a first-order error in the
    damping (measured at zeta = 0.2: -1.62e-3, -8.0e-4, -4.0e-4 at N = 200, 400, 800, i.e.
    0.51 zeta pi/N; undamped: below 3e-8). A restitution formula off by 1% (5e-3 here) fails."""
    n = 400
    tc, tc_num, e, e_num, eng, _, dt = _impact(zeta, n)
    assert abs(tc_num - tc) <= 2 * dt
    assert abs(e_num - e) <= 2 * math.pi**2 / n**2 + 0.75 * zeta * math.pi / n
    # the law's history (time in contact) went through the engine's rebuilds and hand-overs
    assert eng.n_rebuilds > 10
    # momentum: the pair force is applied as +f / -f, so total momentum stays zero
    assert abs(eng.m @ eng.v[:, 0]) < 1e-15 * eng.m[0] * V0
    assert abs(eng.v[:, 1]).max() == 0.0


def test_toy_law_error_converges_as_its_order():
    """Halving dt halves the restitution error of the damped impact (first order: the dashpot
    sees the half-step velocity; measured ratio 2.02), and without damping the exit speed equals
    the entry speed to 1e-7 (measured <= 2.7e-8 at N = 200, 400: velocity Verlet is symplectic,
    what is left comes from the contact starting and ending inside a step): the toy law is
    integrated by the engine's own integrator, not by anything law-specific."""
    errs = {}
    for zeta in (0.0, 0.2):
        for n in (200, 400):
            _, _, e, e_num, *_ = _impact(zeta, n)
            errs[zeta, n] = abs(e_num - e)
    assert 1.6 < errs[0.2, 200] / errs[0.2, 400] < 2.4
    assert max(errs[0.0, 200], errs[0.0, 400]) < 1e-7


def test_history_of_the_toy_law_survives_rebuilds():
    """Column 0 of the toy law's history accumulates dt per step in contact; the list is rebuilt
    every ~10 steps during the contact (skin 2 um, 0.1 um per step), each rebuild handing the
    history over (kernels.hand_over_history), so at the end of the contact it holds the contact
    duration: steps in contact times dt."""
    pk, vel = _pair()
    m = np.pi * R * R * RHO
    tc = math.pi / math.sqrt(KN / (m / 2))
    dt = tc / 400
    s = DEMSettings(kn=KN, kt=0.0, gamma_n=0.0, gamma_t=0.0, mu=0.0, dt=dt, skin=2.0e-6)
    eng = DEMEngine(pk, s, velocities=vel, law=LinearDashpot(KN, 0.0))
    assert eng.xi.shape == (eng.ea.size, 1)
    hmax = 0.0
    touch = 0
    r0 = eng.n_rebuilds
    for _ in range(480):
        res = eng.advance(Loading(), 1)
        touch += int(res["n_contacts"][0] > 0)
        if eng.xi.size:
            hmax = max(hmax, float(eng.xi[:, 0].max()))
    assert eng.n_rebuilds - r0 > 20
    assert touch > 350
    assert hmax == pytest.approx(touch * dt, rel=1e-12)


def test_toy_law_equals_frictionless_hooke_to_round_off():
    """An independent implementation: LIGGGHTS' Hooke law with kt = mu = 0 is the same linear
    spring-dashpot (F_n = kn delta - m_eff gamma_n v_n), written in another floating-point
    order: the two trajectories agree to round-off (1e-12 relative in velocity)."""
    _, _, _, e_toy, eng_toy, _, _ = _impact(0.2, 400)
    _, _, _, e_hooke, eng_h, _, _ = _impact(
        0.2, 400, law_of=lambda s: hooke_law(s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.flavour)
    )
    assert isinstance(eng_h.law, HookeLiggghts)
    np.testing.assert_allclose(eng_toy.v, eng_h.v, rtol=0, atol=1e-12 * V0)
    np.testing.assert_allclose(eng_toy.x, eng_h.x, rtol=0, atol=1e-12 * R)
    assert e_toy == pytest.approx(e_hooke, abs=1e-11)


def test_default_law_follows_the_flavour_and_bad_laws_are_refused():
    pk, _ = _pair()
    s = DEMSettings(kn=KN, dt=1e-7, skin=2e-6)
    assert isinstance(DEMEngine(pk, s).law, HookeLiggghts)
    assert isinstance(DEMEngine(pk, DEMSettings(**{**s.to_dict(), "flavour": "lammps"})).law, HookeLammps)
    assert law_spec(HookeLammps(1.0, 1.0, 0.0, 0.0, 0.5)).apart is not None  # LAMMPS resets the spring
    assert law_spec(HookeLiggghts(1.0, 1.0, 0.0, 0.0, 0.5)).apart is None
    Unknown = namedtuple("Unknown", ["k"])
    with pytest.raises(InputError, match="law: expected an instance of a registered contact law"):
        DEMEngine(pk, s, law=Unknown(1.0))
    with pytest.raises(InputError, match="width must be an integer >= 0"):
        register_law(Unknown, linear_dashpot_pair, -1)
    with pytest.raises(InputError, match="params must be a namedtuple class"):
        register_law(dict, linear_dashpot_pair, 0)
    with pytest.raises(InputError, match="flip must hold 2 signs"):
        register_law(Unknown, linear_dashpot_pair, 2, flip=(1.0,))
    with pytest.raises(InputError, match="flavour: expected 'liggghts' or 'lammps'"):
        hooke_law(1.0, 1.0, 0.0, 0.0, 0.5, "yade")
    with pytest.raises(InputError, match="kn: must be finite and > 0"):
        hooke_law(-1.0, 1.0, 0.0, 0.0, 0.5)


# ----------------------------------------------------------------------------- checkpoints
SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
LOADING = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))


@pytest.mark.parametrize("flavour", ["liggghts", "lammps"])
def test_checkpoint_round_trip_through_the_run_file_is_bit_for_bit(tmp_path, flavour):
    """A run stopped at step 250 (checkpoint in the run file, read back by read_record and
    DEMEngine.restore) and resumed ends exactly where the uninterrupted run ends: every state
    array, the springs (the law's history) and the stress series equal to the last bit."""
    pk = lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)
    s = DEMSettings(**{**SETTINGS.to_dict(), "flavour": flavour})
    out_full, out_piece = tmp_path / "full.h5", tmp_path / "piece.h5"
    o = OutputSettings(series_every=1, snapshot_every=0, checkpoint_every=100)
    ph = [Phase("load", LOADING, 600)]
    run_phases(pk, s, ph, out_full, o, show_progress=False)
    run_phases(pk, s, ph, out_piece, o, show_progress=False, stop_at_step=250)
    rec = read_record(out_piece)
    assert rec.checkpoint["step"] == 250 and not rec.complete
    # the checkpoint restores an engine identical to one advanced to 250 directly
    eng = DEMEngine(pk, s)
    eng.advance(LOADING, 250)
    again = DEMEngine(pk, s)
    again.restore(rec.checkpoint["arrays"], rec.checkpoint["step"])
    for name, arr in eng.state_arrays().items():
        np.testing.assert_array_equal(again.state_arrays()[name], arr, err_msg=name)
    assert np.any(eng.xi != 0.0)  # springs carried, not trivially zero
    a = eng.advance(LOADING, 350)
    b = again.advance(LOADING, 350)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    run_phases(pk, s, ph, out_piece, o, show_progress=False, resume=True)
    full, piece = read_run(out_full), read_run(out_piece)
    assert piece.complete
    for k in ("stress", "cell", "n_contacts", "kinetic_energy"):
        np.testing.assert_array_equal(piece.series[k], full.series[k], err_msg=k)
    np.testing.assert_array_equal(
        read_record(out_piece).checkpoint["arrays"]["neighbours/xi"],
        read_record(out_full).checkpoint["arrays"]["neighbours/xi"],
    )


# ----------------------------------------------------------------------------- disk cache
_CHILD = r"""
import json, sys
sys.path.insert(0, {here!r})
import numpy as np
import test_law_plugin as T
from gransim.contacts.laws import register_law
from gransim.dem import DEMEngine, Loading, kernels as K
# the private NUMBA_CACHE_DIR of this test may hold the test law: cached like a package law
register_law(T.LinearDashpot, T.linear_dashpot_pair, 1, flip=(1.0,), energy=T.linear_dashpot_energy)
pk, vel = T._pair()
from gransim.dem import DEMSettings
s = DEMSettings(kn=T.KN, kt=0.0, gamma_n=10.0, mu=0.0, dt=1e-7, skin=2e-6)
eng = DEMEngine(pk, s, velocities=vel, law=T.LinearDashpot(T.KN, 10.0))
eng.advance(Loading(), 20)
st = K.run_block.stats
print(json.dumps({{"hits": sum(st.cache_hits.values()), "misses": sum(st.cache_misses.values()),
                  "v": eng.v.tolist()}}))
"""


def test_the_loop_of_a_law_is_loaded_from_the_disk_cache_by_a_second_process(tmp_path):
    """numba specialises run_block on the law's namedtuple type; the first process compiles it
    into a fresh NUMBA_CACHE_DIR, the second loads it (a cache hit, no miss) and computes the
    same result. (A closure made at run time would not be disk-cached.)"""
    code = _CHILD.format(here=str(Path(__file__).parent))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_DISABLE_JIT", None)
    outs = []
    for _ in range(2):
        r = subprocess.run(
            [sys.executable, "-c", code], check=False, env=env, capture_output=True, text=True, timeout=900
        )
        assert r.returncode == 0, r.stderr[-2000:]
        outs.append(json.loads(r.stdout.strip().splitlines()[-1]))
    assert outs[0]["misses"] >= 1
    assert outs[1]["misses"] == 0 and outs[1]["hits"] >= 1
    assert outs[0]["v"] == outs[1]["v"]


_PLAIN = r"""
import sys
from reference_runs.decks.biaxial import short_case
from gransim.dem import DEMEngine
p, s, ld, _ = short_case()
DEMEngine(p, s).advance(ld, 5)
print("ok")
"""


def test_a_law_registered_without_cache_leaves_the_shared_cache_usable(tmp_path):
    """A law of a test module (cache=False) runs in this process; a process that cannot import
    this module then still loads the same NUMBA_CACHE_DIR (numba unpickles a kernel's whole index:
    one signature naming this module's class would raise ModuleNotFoundError there, measured)."""
    code = _CHILD.replace("register_law(T.LinearDashpot", "(lambda *a, **k: None)(T.LinearDashpot")
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache")}
    env.pop("NUMBA_DISABLE_JIT", None)
    r = subprocess.run(
        [sys.executable, "-c", code.format(here=str(Path(__file__).parent))],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    r = subprocess.run(
        [sys.executable, "-c", _PLAIN],
        check=False,
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
        cwd=str(Path(__file__).parents[2]),
    )
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stderr[-2000:]
