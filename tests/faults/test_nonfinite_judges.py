"""No judge passes on NaN or inf, and none passes on empty evidence.

``max(0.0, nan)`` is 0.0, ``nan <= tol`` and ``nan > tol`` are both False and ``np.nanmax`` drops
NaN: each of these once turned a NaN out of a code into a PASS. Every judge is fed NaN and inf
on either side (native or reference), in one entry or all, in the tolerance or the scale, and
nothing at all; each must fail and name the quantity. The array-level judges are checked on
generated arrays (hypothesis); the end-to-end case is ``gransim reference taylor`` on a packing
with two coincident disks (every stress LIGGGHTS writes is NaN).
"""

from __future__ import annotations

import dataclasses
import math
import re
import types

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from reference_runs import judge

BAD = st.sampled_from([math.nan, math.inf, -math.inf])
FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


def _word(x: float) -> str:
    return "NaN" if math.isnan(x) else ("+inf" if x > 0 else "-inf")


@st.composite
def finite_pair_with_bad_entry(draw):
    """(a, b, side 0/1, flat index, bad value, all entries bad?): two equal finite arrays of any
    shape (1 to 3 dimensions), then NaN or inf put into one side, at one place or everywhere."""
    shape = draw(hnp.array_shapes(min_dims=1, max_dims=3, min_side=1, max_side=5))
    a = draw(hnp.arrays(np.float64, shape, elements=st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)))
    b = a + draw(hnp.arrays(np.float64, shape, elements=st.floats(-1e-3, 1e-3)))
    side = draw(st.integers(0, 1))
    idx = draw(st.integers(0, a.size - 1))
    bad = draw(BAD)
    everywhere = draw(st.booleans())
    target = (a, b)[side]
    if everywhere:
        target[...] = bad
    else:
        target.flat[idx] = bad
    return a, b, side, idx, bad, everywhere


# ----------------------------------------------------------------------------- the shared judge
@FAST
@given(finite_pair_with_bad_entry())
def test_max_rel_diff_refuses_nan_or_inf_on_either_side(case):
    a, b, side, idx, bad, everywhere = case
    names = ("native", "LIGGGHTS")
    with pytest.raises(judge.NonFiniteError) as exc:
        judge.max_rel_diff(a, b, "stress of state 3", sides=names)
    msg = str(exc.value)
    assert msg.startswith(f"stress of state 3 ({names[side]}) is {_word(bad)}"), msg
    if everywhere and a.size > 1:
        assert f"{a.size} of {a.size} entries non-finite" in msg


@FAST
@given(
    hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=2), elements=st.floats(-1e6, 1e6)),
    BAD,
)
def test_max_rel_diff_refuses_a_nan_or_inf_scale(a, bad):
    with pytest.raises(judge.NonFiniteError, match=r"scale of pressure is (NaN|\+inf|-inf)"):
        judge.max_rel_diff(a, a.copy(), "pressure", scale=bad)


@FAST
@given(hnp.arrays(np.float64, hnp.array_shapes(min_dims=1, max_dims=2), elements=st.floats(-1e6, 1e6)))
def test_max_rel_diff_of_finite_arrays_is_the_finite_relative_difference(a):
    b = a * (1 + 1e-12)
    got = judge.max_rel_diff(a, b, "q")
    scale = np.abs(b).max()
    want = np.abs(a - b).max() / scale if scale > 0 else np.abs(a - b).max()
    assert math.isfinite(got) and got == pytest.approx(want, rel=1e-12, abs=0)


@pytest.mark.parametrize("shape", [(0,), (0, 2, 2), (3, 0)])
def test_max_rel_diff_of_nothing_fails(shape):
    with pytest.raises(judge.NoEvidenceError, match="stress: nothing to compare"):
        judge.max_rel_diff(np.zeros(shape), np.zeros(shape), "stress")


@FAST
@given(hnp.array_shapes(min_dims=1, max_dims=3, min_side=0, max_side=3).filter(lambda s: 0 in s))
def test_max_rel_diff_of_any_empty_shape_fails(shape):
    with pytest.raises(judge.NoEvidenceError, match="stress: nothing to compare"):
        judge.max_rel_diff(np.zeros(shape), np.zeros(shape), "stress")


def test_max_rel_diff_of_different_shapes_fails():
    with pytest.raises(judge.JudgeError, match="stress: native has shape"):
        judge.max_rel_diff(np.zeros(3), np.zeros(4), "stress")


@FAST
@given(
    st.lists(st.floats(0, 1e6), max_size=8),
    st.integers(0, 8),
    BAD,
)
def test_worst_and_peak_never_drop_a_nan_or_inf(values, pos, bad):
    vals = list(values)
    vals.insert(min(pos, len(vals)), bad)
    assert not math.isfinite(judge.peak(vals))
    assert not math.isfinite(judge.peak([np.array(vals)]))
    with pytest.raises(judge.NonFiniteError, match="contact force is"):
        judge.worst(vals, "contact force")
    if math.isnan(bad):
        assert math.isnan(judge.peak(vals))
    # the pattern this replaces: max() keeps a number seen before the NaN
    if values and math.isnan(bad) and pos >= len(values):
        assert math.isfinite(max(vals))


def test_worst_and_peak_of_nothing_fail():
    assert math.isnan(judge.peak([]))
    assert math.isnan(judge.peak([np.zeros(0)]))
    with pytest.raises(judge.NoEvidenceError, match="stress: nothing to compare"):
        judge.worst([], "stress")


@FAST
@given(st.floats(allow_nan=True, allow_infinity=True), st.floats(allow_nan=True, allow_infinity=True))
def test_within_is_false_unless_both_are_finite(value, tol):
    ok = judge.within(value, tol)
    if not (math.isfinite(value) and math.isfinite(tol) and tol >= 0):
        assert ok is False
    else:
        assert ok is (value <= tol)


@FAST
@given(finite_pair_with_bad_entry())
def test_defined_diff_fails_when_only_one_side_is_undefined(case):
    a, b, side, idx, bad, everywhere = case
    d = judge.defined_diff(a, b)
    assert not math.isfinite(d)
    if math.isnan(bad):  # undefined (NaN) on one side only: a failure, never dropped
        assert math.isnan(d)


def test_defined_diff_ignores_entries_undefined_on_both_sides():
    a = np.array([0.5, np.nan, 0.25])
    assert judge.defined_diff(a, a + np.array([1e-3, 0.0, 0.0])) == pytest.approx(1e-3)
    assert math.isnan(judge.defined_diff(np.full(3, np.nan), np.full(3, np.nan)))  # nothing defined
    assert math.isnan(judge.defined_diff(np.zeros(0), np.zeros(0)))


# ----------------------------------------------------------------------------- validation records
@FAST
@given(finite_pair_with_bad_entry())
def test_validation_compare_fails_naming_the_side_that_holds_the_nan(case):
    from validation.core import compare, peak

    a, b, side, idx, bad, everywhere = case
    value = peak([np.abs(a - b)])
    rec = compare("case/x", "stress", "max_rel_diff", value, 1e-8, "why", inputs={"native": a, "LIGGGHTS": b})
    assert not rec.passed and rec.verdict == "FAIL"
    assert f"stress ({('native', 'LIGGGHTS')[side]}) is {_word(bad)}" in rec.metric


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_validation_compare_fails_on_a_nan_or_inf_value_or_tolerance(bad):
    from validation.core import compare

    rec = compare("c", "stress", "max_rel_diff", bad, 1e-8, "why")
    assert not rec.passed and f"stress is {_word(bad)}" in rec.metric
    rec = compare("c", "stress", "max_rel_diff", 0.0, bad, "why")
    assert not rec.passed and f"tolerance of stress is {_word(bad)}" in rec.metric
    assert compare("c", "stress", "max_rel_diff", 0.0, 1e-8, "why").passed  # the same, finite: passes


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_a_check_record_never_passes_on_a_nan_or_inf_whatever_its_rule(bad):
    from validation.core import Record

    # a case that computed ``passed`` by ``not value > tol`` (True for NaN) or with a lenient rule
    rec = Record("c", "contact_force", "max_abs_diff/max_force", bad, 1e-10, not bad > 1e-10, "why")
    assert not rec.passed and rec.verdict == "FAIL" and f"contact_force is {_word(bad)}" in rec.metric
    rec = Record("c", "stress", "m", 0.0, bad, True, "why")
    assert not rec.passed
    info = Record("c", "figure", "m", bad, math.nan, True, "shown", kind="info")  # info: no verdict
    assert info.verdict == "info"


def test_validation_compare_over_nothing_fails():
    from validation.core import compare, peak

    rec = compare("c", "stress", "max_rel_diff", peak([]), 1e-8, "why")
    assert not rec.passed and "stress is NaN" in rec.metric


def test_stress_differences_with_a_nan_stress_fail_the_record():
    from validation.core import compare
    from validation.dem_compare import Trajectory, stress_differences
    from validation.judges import _max

    steps = np.arange(5)
    s = np.ones((5, 3))
    L = np.ones((5, 2))
    for side in (0, 1):
        bad = s.copy()
        bad[3, 1] = np.nan
        a, b = (Trajectory(steps, bad, L, {}), Trajectory(steps, s, L, {}))[:: 1 if side == 0 else -1]
        _, rel, _ = stress_differences(a, b)
        rec = compare("c", "stress", "max rel", _max(rel), 1e-8, "why")
        assert not rec.passed and "stress is NaN" in rec.metric


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_envelope_ratios_fail_on_a_nan_step(bad):
    from validation.judges import envelope_ratio

    d = np.array([0.0, 1e-12, 2e-12, 3e-12])
    env = np.array([1e-11, 1e-11, 1e-11, 1e-11])
    # the one envelope criterion, pointwise (biaxial-full) and with a floor (simple-shear)
    assert judge.within(envelope_ratio(d, env, 2.0), 2.0) and judge.within(envelope_ratio(d, env, 2.0, 1e-10), 2.0)
    for which in ("d", "env"):
        dd, ee = d.copy(), env.copy()
        (dd if which == "d" else ee)[2] = bad
        assert math.isnan(envelope_ratio(dd, ee, 2.0)), which
        assert math.isnan(envelope_ratio(dd, ee, 2.0, 1e-10)), which


def test_voidcell_records_fail_on_a_nan_frame_after_a_finite_one():
    from validation.judges import cell_records

    cmp = {"same": [True, True], "alpha": [1e-12, math.nan], "w": [1e-12, 1e-12], "steps": [0, 10]}
    recs = {r.quantity: r for r in cell_records("voidcells/x", cmp)}
    assert not recs["alpha"].passed and "alpha is NaN" in recs["alpha"].metric
    assert recs["w"].passed


@pytest.mark.parametrize("where", ["native", "LIGGGHTS"])
def test_taylor_contact_forces_fail_on_a_nan_force(where):
    from gransim import rve
    from reference_runs.demo_packings import perturbed_lattice
    from validation.cases.taylor import compare_contact_forces, contact_records

    p = perturbed_lattice(4, 4, seed=1)
    F = np.eye(2)
    cs = rve.contact_state(p, F, 1e7)
    # a LIGGGHTS-like dump of the same contacts: id1 id2 x1 y1 x2 y2 fx fy (force on id1)
    x = p.positions
    xa = x[cs.i]
    xb = xa + cs.branch
    frame = {
        "id1": cs.i + 1,
        "id2": cs.j + 1,
        "x1": xa[:, 0],
        "y1": xa[:, 1],
        "x2": xb[:, 0],
        "y2": xb[:, 1],
        "fx": cs.force[:, 0].copy(),
        "fy": cs.force[:, 1].copy(),
    }
    ok = compare_contact_forces(p, F, frame, contact_state_fn=lambda *a: cs)
    assert all(r.passed for r in contact_records("t", ok)), "the comparison passes before a NaN is put in"
    if where == "LIGGGHTS":
        frame["fx"][len(cs.i) // 2] = np.nan  # not the first: max() kept the value before it
        bad = cs
    else:
        f = cs.force.copy()
        f[len(cs.i) // 2, 1] = np.nan
        bad = dataclasses.replace(cs, force=f)

    def fn(*args):
        return bad

    cmp = compare_contact_forces(p, F, frame, contact_state_fn=fn)
    recs = {r.quantity: r for r in contact_records("t", cmp)}
    assert not recs["contact_force"].passed and "contact_force is NaN" in recs["contact_force"].metric


# ----------------------------------------------------------------------------- reference: Taylor
def _fake_taylor_run(name="lattice-4x4-seed1", engine="liggghts", n_states=3):
    """A TaylorRun whose code stresses are the numpy Taylor stresses themselves (difference 0), on
    compression-11 (images and periodic route) and shear-12 (images)."""
    from reference_runs.demo_packings import perturbed_lattice
    from reference_runs.taylor import TaylorRun, TaylorSeries
    from reference_runs.taylor_numpy import taylor_stress_numpy

    p = perturbed_lattice(4, 4, seed=1)
    kn = 1e7
    series = {}
    for path, route in (("compression-11", "images"), ("compression-11", "periodic"), ("shear-12", "images")):
        k = np.arange(n_states)
        if path.startswith("compression"):
            F = np.array([np.diag([1 - 0.01 * i, 1.0]) for i in k])
        else:
            F = np.array([[[1.0, 0.01 * i], [0.0, 1.0]] for i in k])
        sig = np.array([taylor_stress_numpy(p, f, kn).cauchy for f in F])
        sp = sig.copy() if route == "periodic" else np.full_like(sig, np.nan)
        series[(path, route)] = TaylorSeries(path, route, k, F, sig, sp, np.zeros((len(k), 3)), (None,) * len(k))
    return TaylorRun(name, p, kn, "job", types.MappingProxyType(series), {"elapsed_s": 0.1}, engine)


def _with(run, key, **arrays):
    """``run`` with the series ``key`` replaced by one whose arrays ``arrays`` are given."""
    s = dataclasses.replace(run.series[key], **arrays)
    return dataclasses.replace(run, series=types.MappingProxyType({**run.series, key: s}))


def test_compare_taylor_passes_the_untouched_run():
    from reference_runs.cases import TAYLOR_RTOL, compare_taylor

    out = compare_taylor(_fake_taylor_run())
    assert set(out) == {("compression-11", "images"), ("compression-11", "periodic"), ("shear-12", "images")}
    assert max(out.values()) <= TAYLOR_RTOL


@pytest.mark.parametrize("bad", [math.nan, math.inf])
@pytest.mark.parametrize("what", ["cauchy", "cauchy_pressure"])
@pytest.mark.parametrize("state", [0, 2])
@pytest.mark.parametrize("everywhere", [False, True])
def test_compare_taylor_fails_naming_the_state_and_the_code(bad, what, state, everywhere):
    from reference_runs.cases import compare_taylor

    run = _fake_taylor_run(engine="lammps")
    key = ("compression-11", "periodic")
    arr = getattr(run.series[key], what).copy()
    if everywhere:
        arr[...] = bad
    else:
        arr[state, 1, 0] = bad
    with pytest.raises(judge.NonFiniteError) as exc:
        compare_taylor(_with(run, key, **{what: arr}))
    k = 0 if everywhere else state
    quantity = "stress" if what == "cauchy" else "pressure stress"
    assert str(exc.value).startswith(
        f"{quantity} of state {k} of compression-11, periodic route of lattice-4x4-seed1 (lammps) is {_word(bad)}"
    ), str(exc.value)


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_compare_taylor_fails_naming_numpy_when_the_reference_stress_is_nan(monkeypatch, bad):
    from reference_runs import taylor_numpy
    from reference_runs.cases import compare_taylor

    run = _fake_taylor_run()  # its code side from the real numpy stress
    real = taylor_numpy.taylor_stress_numpy
    calls = []

    def poisoned(packing, F, kn, cand=None):
        out = real(packing, F, kn, cand)
        calls.append(1)
        if len(calls) == 4:  # the 4th state judged, after finite ones
            return dataclasses.replace(out, cauchy=np.full((2, 2), bad))
        return out

    monkeypatch.setattr(taylor_numpy, "taylor_stress_numpy", poisoned)
    with pytest.raises(judge.NonFiniteError, match=rf"of lattice-4x4-seed1 \(numpy\) is {re.escape(_word(bad))}"):
        compare_taylor(run)


def test_compare_taylor_fails_on_a_nan_deformation_gradient():
    from reference_runs.cases import compare_taylor

    run = _fake_taylor_run()
    key = ("shear-12", "images")
    F = run.series[key].F.copy()
    F[1, 0, 1] = np.nan
    with pytest.raises(judge.NonFiniteError, match="deformation gradient of state 1 of shear-12, images route"):
        compare_taylor(_with(run, key, F=F))


def test_compare_taylor_of_no_state_fails():
    from reference_runs.cases import compare_taylor

    run = _fake_taylor_run()
    with pytest.raises(judge.NoEvidenceError, match="Taylor states of lattice-4x4-seed1: none in the job"):
        compare_taylor(dataclasses.replace(run, series=types.MappingProxyType({})))
    key = ("shear-12", "images")
    s = run.series[key]
    cut = _with(run, key, k=s.k[:0], F=s.F[:0], cauchy=s.cauchy[:0], cauchy_pressure=s.cauchy_pressure[:0])
    with pytest.raises(judge.NoEvidenceError, match="shear-12, images route of lattice-4x4-seed1: none in the job"):
        compare_taylor(cut)


def test_run_taylor_set_returns_nan_and_names_the_nan(monkeypatch, tmp_path):
    """The set's verdict (worst <= tolerance, as ``gransim reference taylor`` and the named cases
    judge it) is a failure when one packing of several holds a NaN: max(0.0, nan) was 0.0."""
    import reference_runs.taylor as taylor_mod
    from reference_runs.cases import TAYLOR_RTOL, run_taylor_set

    good = _fake_taylor_run("good")
    key = ("compression-11", "images")
    sig = good.series[key].cauchy.copy()
    sig[1] = np.nan
    bad = dataclasses.replace(_with(good, key, cauchy=sig), name="bad")
    runs = {"good": good, "bad": bad, "good2": dataclasses.replace(good, name="good2")}
    monkeypatch.setattr(taylor_mod, "run_taylor", lambda packing, kn, job, name, **kw: runs[name])
    lines = []
    _, worst = run_taylor_set({n: good.packing for n in runs}, tmp_path, echo=lines.append, progress=False)
    assert math.isnan(worst) and not judge.within(worst, TAYLOR_RTOL)
    text = "\n".join(lines)
    assert "bad: N = 16" in text
    assert "FAIL: stress of state 1 of compression-11, images route of bad (liggghts) is NaN" in text
    _, worst = run_taylor_set({}, tmp_path / "none", echo=lines.append, progress=False)
    assert math.isnan(worst) and "no packings: nothing was compared (FAIL)" in lines[-1]


def test_taylor_named_case_verdict_fails_on_nan(capsys):
    from reference_runs.cases import _verdict

    assert _verdict("taylor-demo", math.nan) == 1
    assert "FAIL" in capsys.readouterr().out
    assert _verdict("taylor-demo", 0.0) == 0


def test_reference_taylor_on_two_coincident_disks_fails_naming_the_nan(real_liggghts, tmp_path, capsys):
    """End to end: every stress LIGGGHTS writes for a packing with two coincident disks is NaN
    (0/0 normal); the command exits 1 naming the state and the code, never PASS."""
    from gransim.cli import main
    from gransim.geometry import Packing
    from gransim.io import save_packing
    from reference_runs.demo_packings import perturbed_lattice

    p = perturbed_lattice(4, 4, seed=1)
    x = p.positions.copy()
    x[1] = x[0]
    save_packing(tmp_path / "coincident.h5", Packing(x, p.radii, p.cell, density=p.density))
    rc = main(["reference", "taylor", str(tmp_path / "coincident.h5"), "--stride", "25", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert rc == 1, out
    assert "PASS" not in out
    assert "FAIL: stress of state 0 of compression-11, images route of coincident (liggghts) is NaN" in out
    assert "= nan (FAIL" in out


# ----------------------------------------------------------------------------- replay
def _replay_fakes(monkeypatch, tmp_path, code_frames, nat_frames, thermo):
    """A deck of 3 disks, one ``run 2``, thermo every step (lx, c_p[1]) and one dump every step
    (x y vx fx); the code's log and dump are ``thermo`` {column: values} and ``code_frames``; the
    native run holds ``nat_frames`` as its states (its box in ``nat.parts[0].hi``, its virial in
    ``nat.parts[0].virial``: c_p[1] = virial xx / area)."""
    from reference_runs.replay import compare as rc
    from reference_runs.replay.deck import ComputeSpec, DumpSpec, RunSpec
    from reference_runs.replay.drive import NativePart, NativeRun, State

    ids = np.array([1, 2, 3])
    dump = DumpSpec("d1", 1, "dump.atoms", ("id", "x", "y", "vx", "fx"))
    run = RunSpec(2, 1, 0, 1, ("lx", "c_p[1]"))
    deck = types.SimpleNamespace(
        nsteps=2,
        runs=(run,),
        computes={"p": ComputeSpec("p", "pressure", ("thermo_temp", "virial"), 1)},
        d50=1e-3,
        packing=types.SimpleNamespace(n=3),
        engine="liggghts",
        dumps=[dump],
        ids=ids,
        settings=types.SimpleNamespace(dt=1e-6),
    )
    lo, hi = np.zeros((3, 2)), np.ones((3, 2)) * 0.01
    z = np.zeros(3)

    def state(s, cols):
        x = np.column_stack([cols["x"], cols["y"]])
        v = np.column_stack([cols["vx"], z])
        f = np.column_stack([cols["fx"], z])
        return State(s, s == 0, x, v, z, f, z, lo[s], hi[s], 0.0, np.array([1e-4, 0.0, 0.0, 0.0]))

    states = {s: state(s, c) for s, c in nat_frames.items()}
    virial = np.tile([1e-4, 0.0, 0.0, 0.0], (3, 1))
    part = NativePart(0, 2, lo, hi, np.zeros(3), np.ones((3, 6)), np.ones(3), np.zeros(3, int), states, virial)
    nat = NativeRun((part,), 0, np.ones(3), np.ones(3), ids)

    cols = list(thermo)

    class Run:
        complete = True
        columns = tuple(cols)

        def __init__(self):
            n = len(next(iter(thermo.values()))) if thermo else 0
            self.steps = np.arange(n)
            self.data = np.column_stack([np.asarray(thermo[k], float) for k in cols]) if cols else np.zeros((0, 0))

    log = types.SimpleNamespace(errors=[], runs=[Run()] if thermo else [], version="x")

    class Frame(dict):
        def __init__(self, step, cols):
            super().__init__(cols)
            self.step = step

    monkeypatch.setattr(rc, "parse_log", lambda path: log)
    monkeypatch.setattr(rc, "parse_dump_custom", lambda path: [Frame(s, c) for s, c in code_frames.items()])
    (tmp_path / "dump.atoms").write_text("")
    return rc, deck, nat, {"dump.atoms": tmp_path / "dump.atoms"}


def _frames(n_steps=3):
    rng = np.random.default_rng(0)
    return {
        s: {"id": np.array([1, 2, 3]), "x": rng.uniform(0, 1e-2, 3), "y": rng.uniform(0, 1e-2, 3),
            "vx": rng.normal(size=3), "fx": rng.normal(size=3)}
        for s in range(n_steps)
    }  # fmt: skip


def _copy(frames):
    return {s: {k: v.copy() for k, v in f.items()} for s, f in frames.items()}


@pytest.mark.parametrize("side", ["liggghts", "native"])
@pytest.mark.parametrize("col", ["x", "vx", "fx"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_replay_dump_check_fails_on_a_nan_in_a_later_frame(monkeypatch, tmp_path, side, col, bad):
    code = _frames()
    nat = _copy(code)
    (code if side == "liggghts" else nat)[2][col][1] = bad  # frame 2 after two equal frames
    thermo = {"lx": np.full(3, 0.01), "c_p[1]": np.ones(3)}
    rc, deck, natrun, paths = _replay_fakes(monkeypatch, tmp_path, code, nat, thermo)
    checks = {c.quantity: c for c in rc.compare_dumps(deck, natrun, paths)}
    c = checks[f"dump d1 {col}"]
    assert not c.passed
    assert f"dump d1 {col} at step 2 ({side}) is {_word(bad)}" in c.detail, c.detail
    others = [k for k in ("x", "vx", "fx") if k != col]
    assert all(checks[f"dump d1 {k}"].passed for k in others)


@pytest.mark.parametrize("side", ["liggghts", "native"])
@pytest.mark.parametrize("column", ["lx", "c_p[1]"])
@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_replay_thermo_check_fails_naming_the_column(monkeypatch, tmp_path, side, column, bad):
    code = _frames()
    thermo = {"lx": np.full(3, 0.01), "c_p[1]": np.ones(3)}
    if side == "liggghts":
        thermo[column] = thermo[column].copy()
        thermo[column][2] = bad
    rc, deck, natrun, paths = _replay_fakes(monkeypatch, tmp_path, code, _copy(code), thermo)
    if side == "native":
        if column == "lx":
            natrun.parts[0].hi[2, 0] = bad
        else:
            natrun.parts[0].states[2].virial[0] = bad
    checks = {c.quantity.split(" (")[0]: c for c in rc.compare_thermo(deck, natrun, tmp_path / "log")}
    c = checks[f"thermo {column}"]
    assert not c.passed and f"thermo {column} ({side}) is" in c.detail, c.detail
    other = "c_p[1]" if column == "lx" else "lx"
    if not (side == "native" and column == "lx"):  # the native pressure divides by that box's area
        assert checks[f"thermo {other}"].passed


def test_replay_without_frames_or_checks_fails(monkeypatch, tmp_path):
    rc, deck, natrun, paths = _replay_fakes(monkeypatch, tmp_path, {}, _frames(), {})
    checks = rc.compare_dumps(deck, natrun, paths)
    assert checks and not any(c.passed for c in checks)  # frames missing, and nothing compared
    assert not rc.ReplayResult(deck, [], tmp_path, "x").passed  # no check at all: not a pass
    c = rc.Check("stress", "max rel", math.nan, 1e-8, True)  # whatever rule set passed
    assert not c.passed and "stress is NaN" in c.detail


# ----------------------------------------------------------------------------- benchmarks
def _bench_job(n, rate, peak_mib=100.0, steps=10, code=False):
    j = {"n": n, "steps": steps, "loop_s": n * steps / rate, "rate": rate, "rebuilds": 1, "peak_kib": peak_mib * 1024}
    if code:  # a LIGGGHTS/LAMMPS job (as tests/foundation/test_bench_dem_records.py builds them)
        j.update(rank_peaks_kib=[peak_mib * 1024], memory_mb_estimate=1.0, breakdown={"Pair": 0.5, "Other": 0.1})
    else:
        j["contacts"] = 3
    return j


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_bench_ratio_over_a_nan_rate_is_a_failure_not_a_number(bad):
    """A NaN rate in the middle of three repeats: statistics.median sorted it anywhere and the
    ratio of medians came out a plausible number."""
    import bench
    from bench import dem

    n = 100
    res = {
        (n, dem.NATIVE_1): [_bench_job(n, r) for r in (3e6, bad, 2e6)],
        (n, dem.LIG_1): [_bench_job(n, r, code=True) for r in (1e6, 2e6, 1.5e6)],
    }
    recs = dem._records(res, [n], [dem.NATIVE_1, dem.LIG_1])
    ratio = next(r for r in recs if r["name"] == f"{dem.NATIVE_1} / {dem.LIG_1}, 100 disks")
    problem = bench.judge_record(ratio)
    assert problem == f"{dem.NATIVE_1} / {dem.LIG_1}, 100 disks is NaN"
    assert ratio["meets"] is False and ratio["note"].startswith("FAIL: ") and ratio["value"] == "NaN"
    assert bench.show(ratio["value"]) == "NaN (FAIL)"
    series = next(r for r in recs if r.get("series"))
    assert bench.judge_record(series) and "is NaN" in series["failed"] and series["meets"] is False
    pts = {"name": "scaling", "value": 1.2, "series": [(100, 500.0), (1000, bad)]}
    assert bench.judge_record(pts) == f"scaling: a point of its series is {_word(bad)} ((1000, {bad!r}))"


@FAST
@given(st.lists(st.floats(0.1, 1e9), min_size=0, max_size=6), st.integers(0, 6), BAD)
def test_bench_median_never_hides_a_nan_or_inf(values, pos, bad):
    import bench

    vals = list(values)
    vals.insert(min(pos, len(vals)), bad)
    assert math.isnan(bench.median(vals))
    assert math.isnan(bench.median([]))
    if values:
        assert bench.median(values) == pytest.approx(float(np.median(values)))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, np.float64("nan")])
def test_bench_record_and_its_printout_fail_on_nan(bad, capsys):
    import bench

    rec = {"name": "fast / LAMMPS, 1e6 disks", "value": bad, "unit": "x", "target": ">= 1", "note": "n"}
    assert bench.print_records([rec, {"name": "ok", "value": 1.0, "unit": "s", "target": None, "note": ""}]) == 1
    out = capsys.readouterr().out
    assert "(FAIL)" in out and "FAIL: fast / LAMMPS, 1e6 disks is" in out
    assert bench.judge_record({"name": "ok", "value": 2.0}) is None
    assert bench.judge_record({"name": "unmeasured", "value": None}) is None  # not measured: not a NaN
    other = {"name": "gen", "value": 1.0, "ratio": bad}  # another figure of the record
    assert bench.judge_record(other) == f"gen: its ratio is {_word(float(bad))}"


def test_bench_suite_exits_1_naming_a_nan_record(monkeypatch, tmp_path, capsys):
    import json
    import sys

    from bench import __main__ as bm

    area = types.ModuleType("bench.zz_nan")
    area.run = lambda quick: [
        {"name": "zz ratio", "value": math.nan, "unit": "x", "target": ">= 1", "note": ""},
        {"name": "zz time", "value": 1.5, "unit": "s", "target": None, "note": ""},
    ]
    monkeypatch.setitem(sys.modules, "bench.zz_nan", area)
    monkeypatch.setattr(bm.pkgutil, "iter_modules", lambda path: [types.SimpleNamespace(name="zz_nan")])
    monkeypatch.setattr(bm, "machine", lambda: {"host": "test"})
    assert bm.main(["--results", str(tmp_path)]) == 1
    captured = capsys.readouterr()
    assert "zz ratio: NaN (FAIL)" in captured.out and "FAIL: zz_nan: zz ratio is NaN" in captured.err
    doc = json.loads((tmp_path / "bench.json").read_text())  # still valid JSON (no bare NaN)
    assert doc["failed_records"] == ["zz_nan: zz ratio is NaN"]
    rec = doc["records"][0]
    assert rec["meets"] is False and rec["value"] == "NaN"
