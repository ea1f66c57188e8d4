"""Checkpoint of the relaxed RVE's Gauss-point history (gransim.fem.checkpoint): replaying the committed
F restores every fluctuation bit for bit, so a path resumed after step 1 ends where the
uninterrupted path ends (every array of every step, and the committed fluctuations)."""

import numpy as np
import pytest
from fem_helpers import triangular_packing

from gransim.errors import InputError
from gransim.fem import DofMap, Problem, rectangle_mesh, run_load_steps
from gransim.fem.checkpoint import read_checkpoint, replay_history, write_checkpoint

rve = pytest.importorskip("gransim.rve")

PATH = [(1e-4, 0.0), (2e-4, 0.0), (3e-4, 0.0)]
PARAMS = {"case": "relaxed box", "tol": 1e-9}


def _box(material):
    mesh = rectangle_mesh(2, 2, 3.0, 3.0, distort=0.15, seed=2)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 3) | (X[:, 1] == 0) | (X[:, 1] == 3))
    return Problem(
        mesh, material, DofMap.build(X, np.concatenate([2 * bnd, 2 * bnd + 1])), body_force=(0.0, -2.5e3 * 9.81)
    )


def _relaxed():
    return rve.RelaxedMaterial(triangular_packing(6, 6, swell=1.0005, jitter=0.02, seed=1), 2.8e7)


class _Stop(Exception):
    pass


def test_relaxed_path_resumed_from_a_checkpoint_is_bitwise(tmp_path):
    ref_mat = _relaxed()
    ref = run_load_steps(_box(ref_mat), PATH, tol=1e-9, max_iter=2)
    assert ref.completed

    ck = tmp_path / "checkpoint"
    commits = []

    def on_step(rec):
        write_checkpoint(ck, PARAMS, rec, [], commits)
        raise _Stop  # the process dies right after step 1's checkpoint

    with pytest.raises(_Stop):
        run_load_steps(
            _box(_relaxed()),
            PATH,
            tol=1e-9,
            max_iter=2,
            on_step=on_step,
            on_commit=lambda sol: commits.append(np.array(sol.F)),
        )
    mat = _relaxed()  # a new process: empty history
    prob = _box(mat)
    state, stored = read_checkpoint(ck, PARAMS)
    assert len(state.steps) == 1 and len(stored) == 1
    replay_history(mat, stored)
    res = run_load_steps(prob, PATH, tol=1e-9, max_iter=2, start=state)
    assert res.completed and len(res.steps) == len(ref.steps)
    for a, b in zip(ref.steps, res.steps):
        for k in ("q", "u", "F", "energy_norms", "residual_norms"):
            assert np.array_equal(getattr(a.solution, k), getattr(b.solution, k)), (a.step, k)
        for k in ("piola", "cauchy", "n_contacts"):
            x, y = getattr(a.solution.material, k), getattr(b.solution.material, k)
            assert np.array_equal(x, y), (a.step, k)
    for g in range(16):
        assert np.array_equal(ref_mat.committed_fluctuation(g), mat.committed_fluctuation(g))
    with pytest.raises(InputError, match="tol = 1e-09.*tol = 1e-12"):
        read_checkpoint(ck, {**PARAMS, "tol": 1e-12})
