"""Stateful Gauss points: the point laws' tangents, commit-on-convergence, in process vs Dask bit
for bit, and no process left after exit."""

import pickle
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from gransim.fem import NeoHookean, lame
from gransim.fem.biaxial import BiaxialSpec, biaxial_setup, run_biaxial
from gransim.fem.incremental import StepFailure, newton_step
from gransim.fem.material_points import DaskGaussPoints, GaussPoints, MaterialPointError, gauss_points
from gransim.fem.point_laws import HyperelasticPoint, J2Plasticity

ROOT = Path(__file__).resolve().parents[2]
SPEC = BiaxialSpec(nx=2, ny=4, steps=3, top_step=1e-3)


def j2(weak=(5, 6)):
    return J2Plasticity(1e8, 0.3, 1.5e5, 1e6, -1e5, weak_points=weak, weak_factor=0.8)


def _fd_tangent(law, state, f, h=1e-7):
    fd = np.zeros((2, 2, 2, 2))
    for k in range(2):
        for m in range(2):
            e = np.zeros((2, 2))
            e[k, m] = h
            fd[:, :, k, m] = (law.update(f + e, state)[0] - law.update(f - e, state)[0]) / (2 * h)
    return fd


@pytest.mark.parametrize("plastic", [False, True])
def test_j2_tangent_is_the_derivative_of_its_stress(plastic):
    law = j2()
    state = law.initial_state(0)
    f = np.eye(2) + (np.array([[-2e-3, 5e-4], [1e-4, 1e-3]]) if plastic else 1e-6 * np.ones((2, 2)))
    s, T, new = law.update(f, state)
    assert (new.alpha > 0) == plastic
    assert np.abs(_fd_tangent(law, state, f) - T).max() < 1e-7 * np.abs(T).max()


def test_j2_return_lands_on_the_yield_surface():
    law = j2(weak=())
    state = law.initial_state(0)
    _, _, new = law.update(np.diag([1.003, 0.996]), state)
    s = new.stress - np.trace(new.stress) / 3 * np.eye(3)
    assert np.sqrt(np.sum(s * s)) == pytest.approx(np.sqrt(2 / 3) * (1.5e5 + 1e6 * new.alpha), rel=1e-12)


def test_hyperelastic_point_tangent():
    law = HyperelasticPoint(NeoHookean(*lame(3e7, 0.3)), np.array([[1.05, 0.02], [0.01, 0.97]]))
    state = law.initial_state(0)
    f = np.eye(2) + np.array([[0.02, 0.01], [-0.03, 0.01]])
    _, T, new = law.update(f, state)
    assert np.abs(_fd_tangent(law, state, f) - T).max() < 1e-7 * np.abs(T).max()
    assert np.allclose(new.F, f @ state.F, rtol=0, atol=1e-15)


# ---------------------------------------------------------------------- commit on convergence


def _state_bytes(points):
    return [pickle.dumps((s.stress.tobytes(), s.alpha, s.updates)) for s in points.states()]


def _check_commit_semantics(points):
    setup = biaxial_setup(SPEC)
    recs = run_biaxial(setup, points)  # 3 steps, several iterates each
    assert sum(len(r.errors) for r in recs) > len(recs)  # more iterates than steps
    assert all(s.updates == 3 for s in points.states())  # each commit one update of the committed state
    before = _state_bytes(points)
    resp = [a.copy() for a in points.committed_response()]
    # a step whose Newton solve is rejected (one iteration allowed, tolerance unreachable)
    with pytest.raises(StepFailure, match="no convergence in 1 Newton"):
        newton_step(setup.problem, points, recs[-1].x, setup.du_fixed, tol=1e-30, max_iter=1)
    assert _state_bytes(points) == before
    for a, b in zip(resp, points.committed_response()):
        assert np.array_equal(a, b)
    # an evaluation then a revert: nothing changes; a commit after a revert is refused
    points.evaluate(np.broadcast_to(np.diag([1.01, 0.98]), (SPEC.n_gauss, 2, 2)))
    points.revert()
    assert _state_bytes(points) == before
    with pytest.raises(Exception, match="no trial state"):
        points.commit()
    return recs


def test_rejected_iterates_leave_committed_states_unchanged_in_process():
    _check_commit_semantics(GaussPoints(j2(), SPEC.n_gauss))


class Mutating(J2Plasticity):
    """A faulty law that writes into the state it was given."""

    def update(self, f, state):
        state.stress[0, 0] += 1.0
        return super().update(f, state)


def test_a_law_writing_into_its_state_is_stopped_and_named():
    law = Mutating(1e8, 0.3, 1.5e5)
    points = GaussPoints(law, 4)
    before = _state_bytes(points)
    with pytest.raises(MaterialPointError, match="Gauss point 0: ValueError.*read-only"):
        points.evaluate(np.broadcast_to(np.eye(2), (4, 2, 2)))
    assert _state_bytes(points) == before


MARK = 1.5e5 + 1e-3  # the yield stress that marks the failing point (the law sees states, not indices)


class FailsAt(J2Plasticity):
    """Raises at one Gauss point once its state has been updated once (its second step)."""

    def update(self, f, state):
        if state.updates >= 1 and state.yield_stress == MARK:
            raise RuntimeError("the RVE lost a particle")
        return super().update(f, state)

    def initial_state(self, g):
        s = super().initial_state(g)
        return type(s)(s.stress, s.alpha, MARK if g == 7 else s.yield_stress, s.updates)


def test_a_failing_point_is_named_with_its_step_and_states_are_kept():
    law = FailsAt(1e8, 0.3, 1.5e5, 1e6, -1e5)
    setup = biaxial_setup(SPEC)
    points = GaussPoints(law, SPEC.n_gauss)
    with pytest.raises(StepFailure, match=r"load step 2: Gauss point 7: RuntimeError: the RVE lost a particle") as exc:
        run_biaxial(setup, points)
    assert exc.value.point == 7
    assert all(s.updates == 1 for s in points.states())


# ---------------------------------------------------------------------- Dask


@pytest.fixture(scope="module")
def dask2():
    pytest.importorskip("distributed")
    from gransim.parallel import make_executor

    ex = make_executor(workers=2)
    try:
        yield ex
    finally:
        ex.close()


def _fields(recs, points):
    out = []
    for r in recs:
        out += [r.x, r.stress, r.F, r.strain, r.errors, r.residuals]
        out += [np.array([r.axial_strain, r.deviatoric_stress, r.volumetric_strain])]
    out += [np.array([s.stress for s in points.states()]), np.array([s.alpha for s in points.states()])]
    return out


@pytest.mark.parametrize("chunks", [2, 3])
def test_dask_gives_the_same_bits_as_in_process(dask2, chunks):
    setup = biaxial_setup(SPEC)
    serial = GaussPoints(j2(), SPEC.n_gauss)
    a = _fields(run_biaxial(setup, serial), serial)
    dist = gauss_points(j2(), SPEC.n_gauss, dask2, n_chunks=chunks)
    assert isinstance(dist, DaskGaussPoints)
    assert len(set(dist.pids())) == 2  # the chunks live on both workers, not here
    b = _fields(run_biaxial(setup, dist), dist)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert x.dtype == y.dtype and np.array_equal(x, y)
    assert any(np.any(s.alpha > 0) for s in dist.states())  # plastic flow happened: the states matter


def test_rejected_iterates_leave_committed_states_unchanged_on_dask(dask2):
    points = gauss_points(j2(), SPEC.n_gauss, dask2, n_chunks=3)
    _check_commit_semantics(points)


def test_dask_failure_names_the_gauss_point(dask2):
    law = FailsAt(1e8, 0.3, 1.5e5, 1e6, -1e5)
    points = gauss_points(law, SPEC.n_gauss, dask2, n_chunks=2)
    with pytest.raises(StepFailure, match="load step 2: Gauss point 7"):
        run_biaxial(biaxial_setup(SPEC), points)
    assert all(s.updates == 1 for s in points.states())


SCRIPT = textwrap.dedent(
    """
    import sys, psutil
    from gransim.fem.biaxial import BiaxialSpec, biaxial_setup, run_biaxial
    from gransim.fem.material_points import gauss_points
    from gransim.fem.point_laws import J2Plasticity
    from gransim.parallel import make_executor

    if __name__ == "__main__":  # the workers are spawned processes: they import this file
        fail = sys.argv[1] == "fail"
        spec = BiaxialSpec(nx=2, ny=4, steps=2, top_step=1e-3)
        law = J2Plasticity(1e8, 0.3, 1.5e5, 1e6, -1e5)
        with make_executor(workers=2) as ex:
            pts = gauss_points(law, spec.n_gauss, ex)
            kids = psutil.Process().children(recursive=True)
            print("PIDS", *[f"{p.pid}:{p.create_time()!r}" for p in kids], flush=True)
            run_biaxial(biaxial_setup(spec), pts)
            if fail:
                raise RuntimeError("failing on purpose")
    """
)


@pytest.mark.parametrize("how", ["ok", "fail"])
def test_no_process_left_after_exit(tmp_path, how):
    pytest.importorskip("distributed")
    psutil = pytest.importorskip("psutil")
    script = tmp_path / "run.py"
    script.write_text(SCRIPT)
    p = subprocess.run([sys.executable, str(script), how], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert (p.returncode == 0) == (how == "ok"), p.stderr[-2000:]
    line = next(ln for ln in p.stdout.splitlines() if ln.startswith("PIDS"))
    pids = [(int(a), float(b)) for a, b in (x.split(":") for x in line.split()[1:])]
    assert len(pids) >= 2  # the workers (and their nannies) existed
    procs = []
    for pid, created in pids:
        try:
            proc = psutil.Process(pid)
            if proc.create_time() == created:  # the same process, not a new one reusing its pid
                procs.append(proc)
        except psutil.NoSuchProcess:
            pass
    # multiprocessing's resource tracker ends when it reads EOF from the exited parent: a few ms
    _, alive = psutil.wait_procs(procs, timeout=10)
    assert not [(p.pid, p.name()) for p in alive]
