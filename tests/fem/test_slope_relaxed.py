"""The FE2 machinery with the relaxed RVE (gransim.rve.RelaxedMaterial) at every Gauss point.

A 70-disk standard RVE (generated, seed fixed by gransim.generation) on small meshes: the patch
test, the small-load linear solution with the relaxed tangent at F = 1, Newton's rate (only the
condensed consistent tangent A = W_FF - W_Fw W_ww^-1 W_wF gives order 2), Gauss-point history
commit/revert across a rejected load step, and the CLI's --rve check.
"""

import numpy as np
import pytest
from fem_helpers import linear_small_strain

from gransim.fem import DofMap, Problem, rectangle_mesh, run_load_steps
from gransim.fem.output import observed_orders
from gransim.fem.run import patch_check

rve = pytest.importorskip("gransim.rve")

E_N = 2.8e7


@pytest.fixture(scope="module")
def rve70(tmp_path_factory):
    pytest.importorskip("gransim.generation")
    from gransim.generation import standard_packings
    from gransim.io import load_packing

    paths = standard_packings(tmp_path_factory.mktemp("packings"), names=["rve-70-1"])
    return load_packing(paths["rve-70-1"])


def _box(material, weight=2.5e3 * 9.81):
    """Clamped 3 x 3 box (distorted): the uniform prestress P(1) is carried by the walls."""
    mesh = rectangle_mesh(3, 3, 3.0, 3.0, distort=0.15, seed=2)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 3) | (X[:, 1] == 0) | (X[:, 1] == 3))
    return Problem(mesh, material, DofMap.build(X, np.concatenate([2 * bnd, 2 * bnd + 1])), body_force=(0.0, -weight))


def test_patch_test_with_relaxed_rve(rve70):
    """An affine boundary field is solved by that field, with P(F0) of the relaxed RVE everywhere."""
    pc = patch_check(rve.RelaxedMaterial(rve70, E_N))
    assert pc["displacement"] < 1e-9 and pc["stress"] < 1e-9, pc


def test_trial_start_makes_the_patch_path_dependent(rve70):
    """Why the committed start is the default: the patch's F0 (strains ~5e-3, 20 overlap strains
    of rve-70-1) rearranges the RVE. Started from the committed state (F = 1) every Gauss point
    reaches the same minimiser at F0 (the test above); started from its previous FE iterate's trial
    each point follows its own, non-affine FE iterates into its own energy basin, and the patch no
    longer reproduces the affine field (measured 3e-4 in u, 2e-3 in P, against 1e-9 allowed)."""
    pc = patch_check(rve.RelaxedMaterial(rve70, E_N, warm_start="trial"))
    assert pc["displacement"] > 1e-6 and pc["stress"] > 1e-6, pc


def test_small_load_matches_linear_solution_with_relaxed_tangent(rve70):
    """Under 1e-3 and 2e-3 of the weight the Newton solution equals the linear solution with the
    relaxed tangent A(F = 1) (independent element loop, dense solve); the difference is second
    order in the load (ratio ~2 between the two loads)."""
    mat = rve.RelaxedMaterial(rve70, E_N)
    prob = _box(mat)
    A0 = mat.evaluate(np.broadcast_to(np.eye(2), (1, 2, 2))).tangent[0]  # slot 0: from w*(F = 1)
    mat.revert()
    diffs = []
    for scale in (1e-3, 2e-3):
        q_lin = linear_small_strain(prob, A0, scale)
        res = run_load_steps(_box(rve.RelaxedMaterial(rve70, E_N)), [(scale, 0.0)])
        assert res.completed
        diffs.append(np.linalg.norm(res.steps[0].solution.q - q_lin) / np.linalg.norm(q_lin))
    print("small-load differences", diffs)
    assert diffs[0] < 1e-3
    assert 1.5 < diffs[1] / diffs[0] < 2.5


def test_newton_converges_quadratically_with_relaxed_rve(rve70):
    """The box under a tenth, then a fifth of its weight: every converged Newton solve reaches
    round-off and its observed order p_k = log(e_k+1/e_k) / log(e_k/e_k-1), over the last triple
    of energy norms above round-off (1e-20), is >= 1.8 (the condensed consistent tangent
    A = W_FF - W_Fw W_ww^-1 W_wF of a P that no longer depends on where the rattlers started).

    Precondition asserted at the converged states: every Gauss point's RVE keeps a backbone with
    no held rattler (at larger loads parts of the box stretch the 70-disk RVE beyond its overlaps,
    the network falls apart and the held-rattler fallback makes P only piecewise smooth).

    W_rel is only piecewise smooth where a contact of an RVE opens or closes (Phi'' jumps at
    eps = 0), so the order is asserted on the steps whose last Newton step of the last triple runs
    on unchanged active sets (contact and rattler counts of every RVE, recorded at every material
    evaluation); a step with a contact change there (step 2: the RVEs' contact count 4792 -> 4793
    between its iterates 2 and 3, one rattler more at iterate 2) must still reach round-off. At
    least one step is checked for the order."""
    mat = rve.RelaxedMaterial(rve70, E_N)
    sets, calls = [], []
    evaluate, commit = mat.evaluate, mat.commit

    def recording_evaluate(F, *a, **k):
        b = evaluate(F, *a, **k)
        calls.append((tuple(b.n_contacts), tuple(b.n_rattlers)))
        return b

    def recording_commit():
        sets.append(list(calls))
        calls.clear()
        commit()

    mat.evaluate, mat.commit = recording_evaluate, recording_commit
    prob = _box(mat)
    res = run_load_steps(prob, [(0.1, 0.0), (0.2, 0.0)])
    assert res.completed, res.limit
    mat.evaluate, mat.commit = evaluate, commit
    settled_steps = 0
    for st, seen in zip(res.steps, sets[-len(res.steps) :], strict=True):
        e = np.asarray(st.energy_norms)
        above = e[e > 1e-20]
        orders = observed_orders(above) if above.size >= 3 else np.array([])
        idx = np.flatnonzero(e > 1e-20)
        calls_k = seen[len(seen) - e.size :]  # the evaluations of the converging attempt, one per norm
        # the last Newton step of the last triple ran on an unchanged active set at every RVE
        settled = len(seen) >= e.size and idx.size >= 3 and calls_k[idx[-2]] == calls_k[idx[-1]]
        print(st.step, st.cuts, e, orders, settled, [(int(sum(c)), int(sum(r))) for c, r in calls_k])
        assert e[-1] <= 1e-14
        if settled:
            settled_steps += 1
            assert orders.size and orders[-1] >= 1.8, (e, orders)
        b = mat.evaluate(st.solution.F)
        mat.revert()
        assert np.all(b.n_held == 0) and np.all(b.n_rattlers < rve70.n // 2)
    assert settled_steps >= 1


def _recorded(packing, warm_start):
    """A relaxed material that records, per evaluate, (mean, max) RVE Newton iterations over the
    Gauss points and the batch."""
    mat = rve.RelaxedMaterial(packing, E_N, warm_start=warm_start)
    log = []
    evaluate = mat.evaluate

    def recording_evaluate(F, *a, **k):
        b = evaluate(F, *a, **k)
        log.append((float(np.mean(b.n_newton)), int(np.max(b.n_newton)), b))
        return b

    mat.evaluate = recording_evaluate
    return mat, log


def test_fe_iterates_warm_start_the_rve_and_converge_to_the_committed_start(rve70):
    """One load step (a tenth of the weight) of the 3 x 3 box, the relaxed RVE at every Gauss
    point, started from the previous FE iterate's trial (warm_start="trial") or from the committed
    state at every FE iteration ("committed"). With the trial start the RVE Newton iterations per
    Gauss point fall along the FE iteration to 1 at the last FE iterate (the factorisation for A
    at an already converged start: the iterate moved F by ~1e-10); with the committed start they
    stay at the first iterate's count. Both converge to the same FE solution: at the final F the
    trial start's P and A equal a start from the committed state to 1e-10 relative (the RVE
    tolerance, measured 2e-12; another energy minimum would differ by >= 1e-4), and the FE
    displacements agree to 1e-9 relative (measured 1e-12)."""
    out = {}
    for ws in ("trial", "committed"):
        mat, log = _recorded(rve70, ws)
        prob = _box(mat)
        log.clear()  # the reference state at F = 1
        res = run_load_steps(prob, [(0.1, 0.0)])
        assert res.completed and res.steps[0].cuts == 0
        out[ws] = (res.steps[0].solution, list(log))
    (sol_w, log_w), (sol_c, log_c) = out["trial"], out["committed"]
    means_w = [m for m, _, _ in log_w]
    means_c = [m for m, _, _ in log_c]
    print("RVE Newton iterations per point by FE iterate: trial", means_w, "committed", means_c)
    assert len(log_w) >= 4 and len(log_c) >= 4
    assert means_w[1] == means_c[1] >= 3  # the same start (the committed state) at the 2nd iterate
    assert all(b <= a for a, b in zip(means_w[1:], means_w[2:])), means_w  # falls along the iteration
    assert log_w[-1][1] == 1 and means_w[-1] == 1.0
    assert min(means_c[2:]) >= 0.9 * means_c[1], means_c  # restarts the whole increment every time
    cold = rve.RelaxedMaterial(rve70, E_N, warm_start="committed")
    _box(cold)  # commits the reference state at F = 1, the state committed before the step
    b = cold.evaluate(sol_w.F)
    last = log_w[-1][2]
    rel = lambda x, y: float(np.abs(x - y).max() / np.abs(y).max())  # noqa: E731
    assert rel(last.piola, b.piola) < 1e-10 and rel(last.tangent, b.tangent) < 1e-10
    assert rel(sol_w.q, sol_c.q) < 1e-9


def test_rejected_step_leaves_gauss_point_history_unchanged(rve70):
    """Step 1 (1e-4 of the weight) converges, step 2 (60 x the weight) cannot in 2 iterations
    (max_iter = 2): its attempts are reverted and the
    committed fluctuations equal those of a run that stopped after step 1 (bitwise)."""
    a = rve.RelaxedMaterial(rve70, E_N)
    res = run_load_steps(_box(a), [(1e-4, 0.0), (60.0, 0.0)], tol=1e-9, max_iter=2, min_fraction=0.5)
    assert len(res.steps) == 1 and not res.completed and res.failures
    b = rve.RelaxedMaterial(rve70, E_N)
    assert run_load_steps(_box(b), [(1e-4, 0.0)], tol=1e-9, max_iter=2).completed
    G = 36
    moved = 0
    for g in range(G):
        wa, wb = a.committed_fluctuation(g), b.committed_fluctuation(g)
        assert np.array_equal(wa, wb)
        moved += np.abs(wa).max() > 0
    assert moved == G  # the history is not trivially empty


def test_cli_rejects_bad_rve(capsys):
    from gransim.cli import main

    try:
        rc = main(["slope", "--rve", "voronoi", "--figures", "none"])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "--rve" in err and "taylor or relaxed" in err


def test_bad_relaxed_start_is_refused(capsys):
    from gransim.cli import main
    from gransim.errors import InputError
    from gransim.fem.run import make_material

    try:
        rc = main(["slope", "--rve", "relaxed", "--relaxed-start", "previous", "--figures", "none"])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and "--relaxed-start" in err and "committed" in err
    with pytest.raises(InputError, match="--relaxed-start"):
        make_material("taylor", rve="relaxed", relaxed_start="previous")


def test_tangent_is_the_derivative_where_the_rve_equilibrium_is_not_a_minimum(tmp_path, monkeypatch):
    """The reduced slope of the ``slope-relaxed`` validation case (10 x 5 mesh, the 30-disk
    jittered lattice RVE, service protocol): in its last two load steps some Gauss points' RVEs end at
    an equilibrium whose W_ww is not positive definite (``stable`` False: compressive contacts'
    negative tangential stiffness). Their tangent must still be dP/dF of the states the material
    returns from its committed start: central differences of P along a random dF at every FE
    iterate of those steps, each from the same committed history, agree with A:dF to 1e-6 at every
    Gauss point whose contacts do not change within +-h. (With A from the shifted factorisation
    the unstable points were off by up to 8e-3, and the FE Newton converged linearly.)"""
    from gransim.fem.mesh import SlopeGeometry
    from gransim.fem.run import run_slope_case
    from gransim.io import save_packing
    from gransim.rve import relaxed as RX
    from validation.cases.slope_relaxed import lattice_packing

    calls, commits, checked, unstable = [0], [0], [0], [0]
    evaluate, commit = RX.RelaxedMaterial.evaluate, RX.RelaxedMaterial.commit

    def counted(self):
        commits[0] += 1
        commit(self)

    def check(self, F, rve=None, cauchy=True):
        b = evaluate(self, F, rve, cauchy)
        calls[0] += 1
        # the first commit is the reference state at F = 1, then one per load step: after the
        # fourth and the fifth come the FE iterates of steps 4 and 5
        if 4 <= commits[0] <= 5 and np.any(~b.stable):
            dF = np.random.default_rng(calls[0]).normal(size=np.shape(F))
            h = 1e-7
            plus, minus = evaluate(self, F + h * dF, rve, cauchy), evaluate(self, F - h * dF, rve, cauchy)
            num = (plus.piola - minus.piola) / (2 * h)
            ana = np.einsum("giJkL,gkL->giJ", b.tangent, dF)
            same = (plus.n_contacts == b.n_contacts) & (minus.n_contacts == b.n_contacts)
            G = len(F)
            err = np.linalg.norm((num - ana).reshape(G, -1), axis=1) / np.linalg.norm(ana.reshape(G, -1), axis=1)
            bad = np.flatnonzero(same & (err > 1e-6))
            assert bad.size == 0, (calls[0], bad, err[bad], b.stable[bad])
            checked[0] += 1
            unstable[0] += int(np.count_nonzero(~b.stable & same))
            evaluate(self, F, rve, cauchy)  # the iterate's own trials again
        return b

    monkeypatch.setattr(RX.RelaxedMaterial, "evaluate", check)
    monkeypatch.setattr(RX.RelaxedMaterial, "commit", counted)
    save_packing(tmp_path / "lattice.h5", lattice_packing())
    s = run_slope_case("service", packing=str(tmp_path / "lattice.h5"), out=tmp_path / "out", figures="none",
                       geometry=SlopeGeometry(columns=10, rows=5), rve="relaxed", load_steps=4)  # fmt: skip
    assert len(s["result"].steps) == 5 and checked[0] >= 3, (checked, calls, commits)
    assert unstable[0] > 0  # the check saw equilibria that are not minima
