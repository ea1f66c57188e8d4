"""Checkpoint of the relaxed RVE's Gauss-point history (gransim.fem.checkpoint): replaying every
committed attempt's FE iterates restores every fluctuation bit for bit, so a path resumed after
step 1 ends where the uninterrupted path ends (every array of every step, and the committed
fluctuations), for both starts of the relaxation. Started from the previous FE iterate's trial
(``warm_start="trial"``) the committed F alone is not enough: its replay lands on the same
minimisers only to the relaxation's tolerance."""

import h5py
import numpy as np
import pytest

from gransim.errors import InputError
from gransim.fem import DofMap, Problem, rectangle_mesh, run_load_steps
from gransim.fem.checkpoint import read_checkpoint, replay_history, step_path, write_checkpoint

rve = pytest.importorskip("gransim.rve")

PATH = [(0.03, 0.0), (0.06, 0.0), (0.09, 0.0)]
PARAMS = {"case": "relaxed box", "tol": 1e-20}


@pytest.fixture(scope="module")
def rve70(tmp_path_factory):
    pytest.importorskip("gransim.generation")
    from gransim.generation import standard_packings
    from gransim.io import load_packing

    paths = standard_packings(tmp_path_factory.mktemp("packings"), names=["rve-70-1"])
    return load_packing(paths["rve-70-1"])


def _box(material):
    mesh = rectangle_mesh(2, 2, 3.0, 3.0, distort=0.15, seed=2)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 3) | (X[:, 1] == 0) | (X[:, 1] == 3))
    return Problem(
        mesh, material, DofMap.build(X, np.concatenate([2 * bnd, 2 * bnd + 1])), body_force=(0.0, -2.5e3 * 9.81)
    )


class _Stop(Exception):
    pass


def _resumed(ck, packing, commits_of, ws):
    mat = rve.RelaxedMaterial(packing, 2.8e7, warm_start=ws)  # a new process: empty history
    prob = _box(mat)
    state, stored = read_checkpoint(ck, PARAMS)
    assert len(state.steps) == 1 and len(stored) == 1  # step 1, one commit (not cut)
    replay_history(mat, commits_of(stored))
    return mat, state, prob


@pytest.mark.parametrize("ws", ["trial", "committed"])
def test_relaxed_path_resumed_from_a_checkpoint_is_bitwise(tmp_path, rve70, ws):
    ref_mat = rve.RelaxedMaterial(rve70, 2.8e7, warm_start=ws)
    ref = run_load_steps(_box(ref_mat), PATH)
    assert ref.completed

    ck = tmp_path / "checkpoint"
    commits = []

    def on_step(rec):
        write_checkpoint(ck, PARAMS, rec, [], commits)
        raise _Stop  # the process dies right after step 1's checkpoint

    with pytest.raises(_Stop):
        run_load_steps(
            _box(rve.RelaxedMaterial(rve70, 2.8e7, warm_start=ws)),
            PATH,
            on_step=on_step,
            on_commit=lambda sol: commits.append(np.array(sol.iterates)),
        )
    assert len(commits) == 1 and len(commits[0]) == len(ref.steps[0].energy_norms) >= 3  # one F per FE iterate
    mat, state, prob = _resumed(ck, rve70, lambda stored: stored, ws)
    res = run_load_steps(prob, PATH, start=state)
    assert res.completed and len(res.steps) == len(ref.steps)
    for a, b in zip(ref.steps, res.steps):
        for k in ("q", "u", "F", "energy_norms", "residual_norms"):
            assert np.array_equal(getattr(a.solution, k), getattr(b.solution, k)), (a.step, k)
        for k in ("piola", "cauchy", "n_contacts"):
            x, y = getattr(a.solution.material, k), getattr(b.solution.material, k)
            assert np.array_equal(x, y), (a.step, k)
    for g in range(16):
        assert np.array_equal(ref_mat.committed_fluctuation(g), mat.committed_fluctuation(g))

    # the committed F alone: with the committed start the same bits; with the trial start the same
    # minimisers (P to the relaxation's tolerance; rattlers, which carry no force, may sit elsewhere
    # in their voids) but not the same bits
    only_f, _, _ = _resumed(ck, rve70, lambda stored: [seq[-1] for seq in stored], ws)
    ref1 = rve.RelaxedMaterial(rve70, 2.8e7, warm_start=ws)
    F1 = run_load_steps(_box(ref1), PATH[:1]).steps[0].solution.F
    same = [np.array_equal(only_f.committed_fluctuation(g), ref1.committed_fluctuation(g)) for g in range(16)]
    assert all(same) if ws == "committed" else not all(same)
    a, b = only_f.evaluate(F1), ref1.evaluate(F1)  # both start converged at the committed F
    assert np.abs(a.piola - b.piola).max() < 1e-10 * np.abs(b.piola).max()

    with pytest.raises(InputError, match="tol = 1e-20.*tol = 1e-12"):
        read_checkpoint(ck, {**PARAMS, "tol": 1e-12})
    with h5py.File(step_path(ck, 1), "r+") as f:  # a damaged file: its iterates do not end at its commit
        f["commit_iterates"][-1] = f["commit_iterates"][0]
    with pytest.raises(InputError, match="last iterate is not its committed F"):
        read_checkpoint(ck, PARAMS)
