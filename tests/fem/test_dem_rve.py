"""Guo & Zhao's DEM RVE as a Gauss-point law, in YADE's arithmetic, against YADE 2023.02a.

* stored YADE output (tests/fem/data/yade_rve, with its manifest): the RVE prepareRVE.py prepared
  in YADE (gransim/fem/data/guo_zhao_rve.h5), driven by three strain increments through
  simDEM.shear2D; the native calls give YADE's saved scene field by field, and getStress /
  getStressAndTangent after every call, to the bit;
* (a) a one-element specimen: every Gauss point's RVE equals a single RVE driven from the prepared
  state by that point's own strain history, to the bit;
* (b) with YADE installed, a Gauss point's history replayed in YADE (prepareRVE.py run afresh, then
  simDEM.shear2D per increment) gives the native state after every call, to the bit;
* the disks' rotation: spin dt summed after every step; free disks in a turning cell turn by the
  cell's spin, exactly; with YADE, each disk's State::rot() equals the native sum after every call
  to the round-off of YADE's quaternions; a Gauss point's rotations are its single RVE's;
* an update never writes into the committed state; a resumed run equals an uninterrupted one;
* the first collider run kept from a read-only state gives the bits of a computed one, and a
  writable state is never served a kept one;
* the call is a run of the one engine (the sheared yade cell, gransim.dem.yade_cell): advanced in
  any blocks, and chained on one engine through its saved scenes, it gives rve_run's bits; calls
  from a read-only state reuse its set-up and leave it unchanged; a diverging call and a cell too
  small for its bounds are SimulationErrors naming the call and the step; a scene of another
  material and a call on the orthogonal cell are InputErrors.
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest

from gransim.dem.yade_arithmetic import (
    RVE_STATE_FIELDS,
    guo_zhao_stress_tangent,
    n_steps_of,
    rve_run,
    rve_run_rotation,
    rve_stress_tangent,
)
from gransim.errors import InputError
from gransim.fem.biaxial import BiaxialSpec
from gransim.fem.dem_rve import DemRVE, load_rve_state
from gransim.fem.femxdem import FemxdemInterrupted, run_femxdem
from gransim.fem.material_points import freeze
from validation.judges import differing

DATA = Path(__file__).parent / "data" / "yade_rve"
HAVE_YADE = shutil.which("yade") is not None
EPS = np.finfo(float).eps


def same_state(a, b) -> list:
    """Fields of two YadeRVEStates that differ (NaN equal to NaN)."""
    return differing(a, b, RVE_STATE_FIELDS)


def test_prepared_rve_is_guo_and_zhaos():
    st, prov = load_rve_state()
    assert prov["engine_version"] == "YADE 2023.02a" and st.n == 400
    # 2650 kg/m^3 x 0.1 m x pi r^2; E 6e8, ks/kn = poisson 0.8; friction angle 0.5 rad; damping 0.1
    assert np.allclose(st.mass, 2650 * 0.1 * np.pi * st.radii**2, rtol=1e-15)
    assert (st.young, st.poisson, st.friction_angle, st.damping) == (6e8, 0.8, 0.5, 0.1)
    assert np.all(st.tan_phi == np.tan(0.5))
    r1, r2 = st.radii[st.ids[:, 0]], st.radii[st.ids[:, 1]]
    assert np.allclose(st.kn, 2 * 6e8 * r1 * r2 / (r1 + r2), rtol=1e-14) and np.allclose(st.ks, 0.8 * st.kn, rtol=1e-14)
    s, _ = rve_stress_tangent(st)
    assert np.array_equal(s, np.array(prov["stress_getStress_Pa"])[:2, :2])
    assert abs(s[0, 0] + 1e5) < 1e2 and abs(s[1, 1] + 1e5) < 1e2  # relStressTol 1e-3 of 100 kPa


def test_stored_yade_calls_equal_the_native_calls_bit_for_bit():
    ref, prov = load_rve_state(DATA / "after_calls.h5")
    manifest = json.loads((DATA / "manifest.json").read_text())
    assert manifest["status"] == "ok" and manifest["engine_version"] == "YADE 2023.02a"
    assert prov["rve_out_sha256"] == manifest["outputs"]["rve.out"]
    st, _ = load_rve_state()
    first = st
    for D, call in zip(prov["increments"], prov["calls"][1:]):
        st = rve_run(st, np.reshape(D, (2, 2)))
        assert st.iteration == call["iter"]
        s, t = rve_stress_tangent(st)
        assert np.array_equal(s, np.array(call["stress"])[:2, :2]), call["call"]
        T = np.array(call["tangent"])[np.ix_([0, 1, 5], [0, 1, 5])]
        assert np.array_equal(np.triu(t), np.triu(T)), call["call"]
    assert same_state(st, ref) == []
    # the evidence is not trivial: contacts were made and lost, and shear forces carried
    before = {tuple(i) for i in first.ids}
    after = {tuple(i) for i in st.ids}
    assert before - after and after - before
    assert np.count_nonzero(st.shear_force) > len(st.kn)


def test_free_disks_in_a_turning_cell_turn_with_it_exactly():
    """Disks without contacts (the prepared RVE's radii halved, at rest): no torque, so each spin
    is NewtonIntegrator's dSpin = -(dVelGrad_01 - dVelGrad_10) / 2 (NewtonIntegrator.cpp:155-157,
    :329) from the first step on, and every disk turns by ns steps of spin dt, added one by one
    (a trapezoid on the spins before and after, 0 and w, would give half)."""
    st, _ = load_rve_state()
    free = dataclasses.replace(
        st, radii=0.5 * st.radii, velocities=np.zeros_like(st.velocities), spins=np.zeros(st.n),
        ids=np.zeros((0, 2), np.int64), cell_dist=np.zeros((0, 2), np.int64), normal=np.zeros((0, 2)),
        kn=np.zeros(0), ks=np.zeros(0), tan_phi=np.zeros(0), normal_force=np.zeros((0, 2)),
        shear_force=np.zeros((0, 2)),
    )  # fmt: skip
    start = np.linspace(-1e-3, 1e-3, st.n)  # carried on, never modified
    start.flags.writeable = False
    expected, rve, rot, spin = start.copy(), free, start, 0.0
    for D in (np.array([[2e-4, -1e-3], [6e-4, -5e-4]]), np.array([[-1e-4, 3e-4], [-2e-3, 1e-4]])):
        ns = n_steps_of(D)
        rate = D / (ns * st.dt)
        L0 = rve.newton_prev_vel_grad
        spin += -(0.5 * ((rate[0, 1] - L0[0, 1]) - (rate[1, 0] - L0[1, 0])))
        for _ in range(ns):
            expected = expected + spin * st.dt
        rve, rot = rve_run_rotation(rve, D, rot)
        assert len(rve.kn) == 0 and np.all(rve.spins == spin)
        assert np.array_equal(rot, expected)
    # the cell's own rotation (D_yx - D_xy) / 2 per call: 0.8 mrad, then -1.15 mrad
    assert np.allclose(rot - start, 0.5 * (6e-4 + 1e-3) + 0.5 * (-2e-3 - 3e-4), rtol=1e-12, atol=0)
    assert np.array_equal(start, np.linspace(-1e-3, 1e-3, st.n))


@pytest.fixture(scope="module")
def one_element(tmp_path_factory):
    """A 1 x 1 Q8 specimen (4 Gauss points), 2 steps, checkpointed."""
    out = tmp_path_factory.mktemp("fx") / "run"
    summary = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", out=out)
    with h5py.File(out / "checkpoint" / "states_002.h5", "r") as f:
        arrays = {k: np.array(v) for k, v in f["states"].items()}
    return out, summary, DemRVE.unpack_states(arrays)


def test_a_gauss_point_equals_a_single_rve_driven_by_its_strain_path(one_element):
    _, summary, states = one_element
    assert len(states) == 4 and all(s.updates == 2 for s in states)
    first, _ = load_rve_state()
    for g, s in enumerate(states):
        rve, rot = first, np.zeros(first.n)
        for D in s.increments:
            rve, rot = rve_run_rotation(rve, D, rot)
        assert same_state(rve, s.rve) == [], g
        assert np.array_equal(rot, s.rotation), g  # carried through the checkpoint to the bit
    q = [r.deviatoric_stress for r in summary["steps"]]
    assert 0 < q[0] < q[1]  # the specimen hardens under compression


def test_an_update_never_writes_into_the_committed_state():
    law = DemRVE.prepared()
    st = freeze(law.initial_state(0))
    copy = {f: np.array(getattr(st.rve, f), copy=True) for f in RVE_STATE_FIELDS}
    f = np.array([[1.0002, 1e-5], [-2e-5, 0.999]])
    s1, t1, new1 = law.update(f, st)
    s2, t2, new2 = law.update(f, st)  # an iterate again from the same committed state: the same bits
    assert all(np.array_equal(copy[k], np.asarray(getattr(st.rve, k)), equal_nan=True) for k in copy)
    assert np.array_equal(s1, s2) and np.array_equal(t1, t2) and same_state(new1.rve, new2.rve) == []
    sig, t = guo_zhao_stress_tangent(new1.rve)
    assert np.array_equal(sig, sig.T) and np.array_equal(t, np.transpose(t, (1, 0, 2, 3)))


def test_a_kept_first_collider_run_gives_the_bits_of_a_computed_one():
    """The first collider run of a call does not read the strain increment: kept from the first
    call from a read-only state, it serves the next calls from it (other increments, as Newton's
    iterates) with the bits of calls that compute it (from a writable copy, which is never kept)."""
    from gransim.dem import yade_arithmetic as ya

    base = DemRVE.prepared().initial
    # a state some steps away from the prepared one (contacts made and lost since), then read-only
    state = rve_run(base, np.array([[4e-4, -2e-4], [1e-4, -1e-3]]))
    frozen = freeze(dataclasses.replace(state))
    increments = [np.array([[3e-4, 1e-4], [0.0, -1e-3]]), np.array([[-5e-4, 2e-4], [-1e-4, 1.5e-3]])]
    kept = [rve_run_rotation(frozen, D) for D in increments]
    assert frozen in ya._FIRST_RUNS  # kept after the first call, used by the second
    for D, (new, rot) in zip(increments, kept):
        writable = dataclasses.replace(state, **{f: np.array(getattr(state, f)) for f in ("positions", "ids")})
        ref, rot_ref = rve_run_rotation(writable, D)
        assert writable not in ya._FIRST_RUNS
        assert same_state(new, ref) == [] and np.array_equal(rot, rot_ref)
    assert same_state(kept[0][0], kept[1][0]) != []  # two increments, two states: the comparison can fail


def test_a_writable_state_is_never_served_a_kept_first_run():
    """A state whose arrays can change is recomputed every call: moving one disk between two calls
    changes the result."""
    base = DemRVE.prepared().initial
    state = dataclasses.replace(base, positions=np.array(base.positions))
    D = np.array([[3e-4, 1e-4], [0.0, -1e-3]])
    first, _ = rve_run_rotation(state, D)
    state.positions[0] += 1e-4  # 0.02 of a radius
    second, _ = rve_run_rotation(state, D)
    assert "positions" in same_state(first, second)
    state.positions[0] -= 1e-4
    again, _ = rve_run_rotation(state, D)
    assert same_state(first, again) == []


def test_resume_equals_an_uninterrupted_run(one_element, tmp_path):
    out, summary, states = one_element
    cut = tmp_path / "cut"
    with pytest.raises(FemxdemInterrupted):
        run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", out=cut, stop_after=1)
    resumed = run_femxdem(BiaxialSpec(nx=1, ny=1, steps=2), rve="dem", out=cut, resume=True)
    for a, b in zip(summary["steps"], resumed["steps"]):
        assert a.deviatoric_stress == b.deviatoric_stress and a.volumetric_strain == b.volumetric_strain
    with h5py.File(out / "femxdem.h5", "r") as f, h5py.File(cut / "femxdem.h5", "r") as g:
        assert np.array_equal(f["final/x"][()], g["final/x"][()])
        assert np.array_equal(f["final/stress"][()], g["final/stress"][()])


@pytest.mark.skipif(not HAVE_YADE, reason="yade binary not installed (apt-get install yade; make engines)")
def test_b_a_gauss_points_history_replayed_in_yade_is_the_native_rve(one_element, tmp_path):
    from reference_runs.yade.rve import disk_rotations, prepare_job, run_rve_job, state_of

    _, _, states = one_element
    inc = states[0].increments
    recs, manifest = run_rve_job(tmp_path / "job", *prepare_job(increments=inc.reshape(-1, 4)))
    assert manifest["engine_version"] == "YADE 2023.02a" and len(recs) == len(inc) + 1
    first, _ = load_rve_state()
    assert same_state(state_of(recs[0]), first) == []  # prepareRVE.py gives the stored RVE again
    assert not np.any(disk_rotations(recs[0]))  # refOri = ori in the prepared RVE
    rve, rot, steps = first, np.zeros(first.n), 0
    for D, rec in zip(inc, recs[1:]):
        rve, rot = rve_run_rotation(rve, D, rot)
        assert same_state(rve, state_of(rec)) == [], rec["call"]
        assert np.array_equal(rve_stress_tangent(rve)[0], np.array(rec["stress"])[:2, :2])
        # YADE composes unit quaternions, q <- normalize(q(|w| dt, z) q) per step (NewtonIntegrator.cpp:
        # 330-336), and State::rot() reads 2 atan2(|q_z|, |q_w|) of refOri^-1 ori (core/State.hpp:40-45):
        # each step rounds the angle relatively by ~eps, as the double sum does; bound eps x steps x
        # max|theta| (measured 30 times below it: 4.3e-16 rad after 769 steps, docs/femxdem.md)
        steps += n_steps_of(D)
        yade = disk_rotations(rec)
        tol = EPS * steps * np.max(np.abs(rot))
        assert np.max(np.abs(yade - rot)) <= tol, (rec["call"], np.max(np.abs(yade - rot)), tol)
        assert np.max(np.abs(rot)) > 1e9 * tol  # the disks turned: the comparison has a scale
    assert same_state(rve, states[0].rve) == [] and np.array_equal(rot, states[0].rotation)


# ----------------------------------------------------------------------------- the one engine
D_A = np.array([[3e-4, 1e-4], [0.0, -1e-3]])
D_B = np.array([[-5e-4, 2e-4], [-1e-4, 1.5e-3]])


def test_the_engine_runs_a_call_in_any_blocks_and_chains_calls_through_saved_scenes():
    """The sheared yade cell runs simDEM.shear2D: a call advanced in two blocks equals rve_run, and
    a second run on the same engine loads the scene the first saved (a fresh collider sort), as the
    script's next call does: rve_run of rve_run, to the bit."""
    from gransim.dem.yade_cell import VelGradRun, scene_engine

    st, _ = load_rve_state()
    ref1 = rve_run(st, D_A)
    ref2 = rve_run(ref1, D_B)
    eng = scene_engine(st)
    assert eng.step == st.iteration and eng.cell_kind == "sheared" and eng.law.young == st.young
    with pytest.raises(InputError, match="no saved scene"):
        eng.cell_ops.scene(eng)
    ns = n_steps_of(D_A)
    eng.start_run(VelGradRun(D_A / (ns * st.dt)), ns)
    out = eng.advance(37)
    assert out["cell"].shape == (37, 2, 2) and "stress" not in out  # no per-step stress in a call
    eng.advance(ns - 37)
    assert same_state(eng.cell_ops.scene(eng), ref1) == []
    ns2 = n_steps_of(D_B)
    eng.start_run(VelGradRun(D_B / (ns2 * st.dt)), ns2)
    eng.advance(ns2)
    assert same_state(eng.cell_ops.scene(eng), ref2) == []
    assert same_state(ref1, ref2) != []  # the comparison can fail


def test_calls_from_a_read_only_state_reuse_its_set_up_and_leave_it_unchanged():
    from gransim.dem import yade_arithmetic as ya

    state = freeze(dataclasses.replace(rve_run(load_rve_state()[0], D_B)))
    copy = {f: np.array(getattr(state, f), copy=True) for f in RVE_STATE_FIELDS}
    rot = np.linspace(0.0, 1e-3, state.n)
    rot.flags.writeable = False
    first, r1 = rve_run_rotation(state, D_A, rot)
    assert state in ya._FIRST_RUNS  # kept by the first call, restored by the second
    second, r2 = rve_run_rotation(state, D_A, rot)
    assert same_state(first, second) == [] and np.array_equal(r1, r2)
    assert all(np.array_equal(copy[k], np.asarray(getattr(state, k)), equal_nan=True) for k in copy)
    assert np.array_equal(rot, np.linspace(0.0, 1e-3, state.n)) and not np.array_equal(r1, rot)


def test_a_failing_call_is_a_simulation_error_naming_the_call_and_the_step():
    from gransim.errors import SimulationError

    st, _ = load_rve_state()
    unstable = dataclasses.replace(st, dt=30 * st.dt)  # 30 times YADE's step: the integration blows up
    diverged = r"RVE call from iteration 13810 \(100 steps\): step 13\d{3}: (kinetic energy blow-up|particle)"
    with pytest.raises(SimulationError, match=diverged):
        rve_run(unstable, D_A)
    small = dataclasses.replace(st, hsize=0.1 * np.asarray(st.hsize))  # a 2 cm cell: bounds over its half
    with pytest.raises(SimulationError, match=r"step 13810: a bound spans over half of the cell"):
        rve_run(small, D_A)
    assert same_state(rve_run(st, D_A), rve_run(st, D_A)) == []  # the thread's engine serves again


def test_a_scene_of_another_material_or_a_call_on_the_orthogonal_cell_is_refused():
    from gransim.dem.yade_cell import VelGradRun, scene_checkpoint, scene_engine

    st, _ = load_rve_state()
    eng = scene_engine(st)
    with pytest.raises(InputError, match="material"):
        eng.restore(scene_checkpoint(dataclasses.replace(st, young=2 * st.young)), st.iteration)
    with pytest.raises(InputError, match="vel_grad"):
        VelGradRun(np.array([[np.nan, 0.0], [0.0, 0.0]]))
    from gransim.dem.engine import Engine
    from reference_runs.decks.shear import wrapped_packing
    from reference_runs.yade.dem import short_biaxial

    p, s, _, _ = short_biaxial()
    with pytest.raises(InputError, match="sheared yade cell"):
        Engine(wrapped_packing(p), s, flavour="yade").start_run(VelGradRun(np.zeros((2, 2))), 10)
