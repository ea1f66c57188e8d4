"""The consistent tangent by perturbation (gransim.fem.perturbation): the central difference of a
Gauss point's calls from its committed state.

* on a smooth law (neo-Hookean) it converges to the exact tangent at order 2 as h shrinks, down to
  the round-off floor, below which its error grows as 1/h;
* on Guo & Zhao's DEM RVE it equals, bit for bit, a central difference written here from the DEM
  calls themselves (``rve_run`` with D = +-h, no point law), and it predicts the stress change of a
  mixed strain increment tens of times better than the contact-stiffness tangent; in calls of a
  fixed step count (h < 2e-5: 2 steps) it converges until the round-off floor;
* a tangent evaluation leaves the committed state unchanged, bit for bit; a kept tangent is the one
  a writable copy recomputes; stress and states are the wrapped law's, bit for bit;
* a run commits the states the single RVE replays, and its predictor uses the committed state's
  own tangent; on a 2-worker LocalCluster it gives the in-process bits; gransim femxdem --tangent
  perturbation resumes bit for bit, and a resume with another tangent (or another h) is refused
  naming both.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

from gransim.dem.yade_arithmetic import RVE_STATE_FIELDS, guo_zhao_stress_tangent, rve_run, rve_run_rotation
from gransim.fem.biaxial import BiaxialSpec
from gransim.fem.dem_rve import DemRVE, load_rve_state
from gransim.fem.femxdem import run_femxdem
from gransim.fem.material_points import freeze
from gransim.fem.materials import NeoHookean, lame
from gransim.fem.perturbation import DEFAULT_STEP, PerturbationTangent
from gransim.fem.point_laws import HyperelasticPoint, HyperState

ROOT = Path(__file__).resolve().parents[2]
#: a Gauss point's load steps (axial compression, lateral expansion, some shear), twice over
CHAIN = [np.array([[3e-4, 1e-4], [0.0, -1e-3]]), np.array([[4e-4, -2e-4], [1e-4, -1e-3]])] * 3


def _rel(a, b) -> float:
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.fixture(scope="module")
def loaded():
    """The DEM law and a committed state six load steps from the prepared RVE (contacts sliding)."""
    law = DemRVE.prepared()
    st = law.initial_state(0)
    for D in CHAIN:
        _, _, st = law.update(np.eye(2) + D, st)
    return law, freeze(st)


def test_the_central_difference_converges_at_order_two_to_a_smooth_laws_tangent():
    law = HyperelasticPoint(NeoHookean(*lame(1e8, 0.3)))
    st = freeze(HyperState(np.array([[0.97, 0.05], [-0.02, 1.03]]), 1))
    exact = law.response(st)[1]  # the exact chain rule (point_laws.cauchy_and_tangent)
    hs = [1e-2 / 4**i for i in range(12)]
    err = [_rel(PerturbationTangent(law, h).tangent(st), exact) for h in hs]
    orders = np.log(np.array(err[:-1]) / err[1:]) / np.log(4)
    # truncation: error ~ h^2 (measured 2.00 down to h = 1e-5, 1e-10 of the tangent)
    assert np.all(orders[:5] > 1.95), orders
    assert min(err) < 2e-10
    # round-off: the stress difference is ~eps of the stress, over 2h: the error grows as 1/h (measured
    # order -1.1 to -1.3 below h = 1e-7)
    assert err[-1] > 30 * min(err) and np.all(orders[-3:] < -0.5), orders


def test_the_dem_tangent_is_the_central_difference_of_the_dem_calls(loaded):
    law, st = loaded
    pert = PerturbationTangent(law, DEFAULT_STEP)
    h = pert.applied_step
    assert abs(h / DEFAULT_STEP - 1) < 1e-11 and (1.0 + h) - 1.0 == h and 1.0 - (1.0 - h) == h
    ref = np.empty((2, 2, 2, 2))
    for k in range(2):
        for m in range(2):
            E = np.zeros((2, 2))
            E[k, m] = h
            plus = guo_zhao_stress_tangent(rve_run(st.rve, E))[0]
            minus = guo_zhao_stress_tangent(rve_run(st.rve, -E))[0]
            ref[:, :, k, m] = (plus - minus) / (2 * h)
    t = pert.tangent(st)
    assert np.array_equal(t, ref)
    contact = law.response(st)[1]
    assert _rel(contact, t) > 0.3  # not the contact-stiffness tangent: sliding and rearrangement lower it


def test_the_dem_tangent_predicts_a_mixed_increment(loaded):
    """The stress change along a mixed direction A, as the central difference of two calls of
    +-h A: the perturbation tangent's T : A within 3 % (measured 1.0-1.3 % at h = 3e-4 and 1e-3),
    the contact-stiffness tangent's over 30 % off (measured 53 %)."""
    law, st = loaded
    A = np.array([[0.35, -0.6], [0.2, -1.0]])
    contact = law.response(st)[1]
    for h in (DEFAULT_STEP, 1e-3):
        t = PerturbationTangent(law, h).tangent(st)
        dd = (law.update(np.eye(2) + h * A, st)[0] - law.update(np.eye(2) - h * A, st)[0]) / (2 * h)
        assert _rel(np.einsum("ijkl,kl->ij", t, A), dd) < 0.03, h
        assert _rel(np.einsum("ijkl,kl->ij", contact, A), dd) > 0.3, h


def test_in_calls_of_two_steps_the_dem_tangent_converges_down_to_round_off(loaded):
    """Below h = 2e-5 every call runs 2 steps: the map D -> sigma is then smooth between the
    contacts' thresholds (Coulomb limits, contacts made, the collider's decisions), which small
    enough perturbations no longer cross, and the difference converges until the stress's round-off
    over 2h takes over (measured: 1e-4 between h = 6.2e-8 and 2.1e-8, 1e-8 between 2.1e-8 and
    6.9e-9, then growing as 1/h: 1e-6 at h = 8.5e-11)."""
    law, st = loaded
    hs = [1.5e-5 / 3**i for i in range(12)]
    t = [PerturbationTangent(law, h).tangent(st) for h in hs]
    diff = [_rel(a, b) for a, b in zip(t[1:], t)]  # diff[i]: h = hs[i + 1] against hs[i]
    assert diff[6] < 1e-7 < diff[5], diff  # h = 6.9e-9 against 2.1e-8: no threshold crossed any more
    assert diff[-1] > 10 * diff[6], diff  # h = 8.5e-11: round-off


def test_a_tangent_leaves_the_committed_state_unchanged(loaded):
    law, st = loaded
    before = {f: np.array(getattr(st.rve, f), copy=True) for f in RVE_STATE_FIELDS}
    inc, rot = np.array(st.increments), np.array(st.rotation)
    pert = PerturbationTangent(law, DEFAULT_STEP)
    f = np.eye(2) + np.array([[2e-4, 1e-4], [-1e-4, -1e-3]])
    sigma, t1, new = pert.update(f, st)
    t2 = pert.tangent(st)  # kept: the same bits
    for name, v in before.items():
        assert np.array_equal(v, np.asarray(getattr(st.rve, name)), equal_nan=True), name
    assert np.array_equal(inc, st.increments) and np.array_equal(rot, st.rotation) and st.updates == len(CHAIN)
    assert np.array_equal(t1, t2)
    # the stress and the new state are the wrapped law's, to the bit
    s0, _, n0 = law.update(f, st)
    assert np.array_equal(sigma, s0) and np.array_equal(new.rve.positions, n0.rve.positions)
    assert np.array_equal(new.increments, n0.increments) and np.array_equal(new.rotation, n0.rotation)
    # a writable copy (never kept) recomputes the kept tangent's bits
    copy = dataclasses.replace(st, rve=dataclasses.replace(st.rve, positions=np.array(st.rve.positions)))
    assert np.array_equal(pert.tangent(copy), t1)
    assert copy not in pert._kept and st in pert._kept


@pytest.fixture(scope="module")
def perturbed_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("fxp") / "run"
    summary = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", out=out, tangent="perturbation")
    with h5py.File(out / "checkpoint" / "states_002.h5", "r") as f:
        arrays = {k: np.array(v) for k, v in f["states"].items()}
        tangent = f["tangent"][()]
    return out, summary, DemRVE.unpack_states(arrays), tangent


def test_a_run_commits_the_single_rves_states_and_their_own_tangents(perturbed_run):
    out, summary, states, tangent = perturbed_run
    first, _ = load_rve_state()
    for g, s in enumerate(states):  # the perturbation calls left no trace in the committed states
        rve, rot = first, np.zeros(first.n)
        for D in s.increments:
            rve, rot = rve_run_rotation(rve, D, rot)
        assert np.array_equal(rve.positions, s.rve.positions) and np.array_equal(rot, s.rotation), g
    # the committed tangent (the next predictor's) is the committed state's own
    pert = PerturbationTangent(DemRVE.prepared(), DEFAULT_STEP)
    for g in (0, 3):
        assert np.array_equal(tangent[g], pert.tangent(freeze(states[g])))
    assert summary["parameters"]["tangent"] == {"kind": "perturbation", "step": DEFAULT_STEP}
    assert "tangent: perturbation" in summary["report"]


def _gransim(*args, timeout=600):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(ROOT / ".venv" / "numba-cache")}
    return subprocess.run(
        [sys.executable, "-m", "gransim", "femxdem", *map(str, args)], capture_output=True, text=True,
        timeout=timeout, env=env, cwd=ROOT,
    )  # fmt: skip


def test_cli_tangent_option_resumes_and_refuses_another_tangent(perturbed_run, tmp_path):
    _, summary, _, _ = perturbed_run
    base = ["--rve", "dem", "--mesh", "1x1", "--steps", "2", "--out", tmp_path]
    p = _gransim(*base, "--tangent", "perturbation", "--stop-after", "1")
    assert p.returncode == 0, p.stderr[-2000:]
    p = _gransim(*base, "--resume")  # the default tangent is the contact stiffness
    assert p.returncode == 2 and "--resume" in p.stderr, p.stderr[-2000:]
    assert "written with --tangent perturbation --tangent-step 0.0003, this run has --tangent contact" in p.stderr
    p = _gransim(*base, "--resume", "--tangent", "perturbation", "--tangent-step", "1e-3")
    assert p.returncode == 2 and "this run has --tangent perturbation --tangent-step 0.001" in p.stderr, p.stderr
    p = _gransim(*base, "--resume", "--tangent", "perturbation")
    assert p.returncode == 0, p.stderr[-2000:]
    with h5py.File(tmp_path / "femxdem.h5", "r") as f:
        assert '"tangent": {"kind": "perturbation", "step": 0.0003}' in f.attrs["parameters"]
        q = f["curves/deviatoric_stress"][()]
        stress = f["final/stress"][()]
    assert np.array_equal(q, [r.deviatoric_stress for r in summary["steps"]])  # resumed = uninterrupted
    assert np.array_equal(stress, summary["steps"][-1].stress)
    for args, msg in [
        (["--rve", "j2", "--tangent", "perturbation"], "--tangent: applies to the DEM RVEs"),
        (["--rve", "dem", "--tangent-step", "1e-3"], "--tangent-step: applies to --tangent perturbation only"),
        (["--rve", "dem", "--tangent", "perturbation", "--tangent-step", "1e-6"], "--tangent-step"),
    ]:
        p = _gransim(*args, "--out", tmp_path / "bad")
        assert p.returncode == 2 and msg in p.stderr, (args, p.stderr[-2000:])


def test_on_dask_the_perturbation_run_gives_the_same_bits(perturbed_run):
    """The tangents are computed where the states live (each chunk's worker, at its commit), and the
    run on a 2-worker LocalCluster in 2 chunks is the in-process run's bits."""
    pytest.importorskip("distributed")
    from gransim.parallel import make_executor

    _, summary, _, _ = perturbed_run
    with make_executor(workers=2) as ex:
        dask = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", executor=ex, tangent="perturbation")
    assert "Dask" in dask["report"]
    for a, b in zip(summary["steps"], dask["steps"], strict=True):
        for key in ("x", "stress", "F", "errors", "residuals"):
            assert np.array_equal(getattr(a, key), getattr(b, key)), key
    assert [len(r.errors) for r in dask["steps"]] == [1, 2]  # the contact tangent needs 2 and 3
