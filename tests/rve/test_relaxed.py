"""Physics checks of the relaxed periodic RVE (gransim.rve.relaxed).

Derivative consistency (P = dW_rel/dF, A = dP/dF by central differences on states whose active
set does not change within the step), major symmetry, the Taylor bound W_rel <= W_Taylor on the
standard 70- and 350-disk RVEs, the exact Taylor limit of a Bravais lattice, strict relaxation and
periodicity of the fluctuation on a disordered RVE, rattlers, the warm start and input checks.
"""

from __future__ import annotations

import numpy as np
import pytest
from rve_fixtures import lattice_packing

from gransim import InputError, Packing
from gransim.contacts import find_neighbours
from gransim.io import load_packing
from gransim.rve import RelaxedMaterial, TaylorMaterial

KN = 2.8e7  # N/m, the slope problem's E_n


def _rel(a, b):
    return float(np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b)))


@pytest.fixture(scope="module")
def standard(tmp_path_factory):
    """The ten 70- and 350-disk standard RVEs (rve-70-1..5, rve-350-1..5), generated into a tmp
    dir (about 6 s); the 700-disk ones are left to bench/rve_relaxed.py (generation is slow)."""
    from gransim.generation import standard_packings

    d = tmp_path_factory.mktemp("packings")
    paths = standard_packings(d, names=[f"rve-{n}-{k}" for n in (70, 350) for k in range(1, 6)])
    return {k: load_packing(v) for k, v in paths.items()}


def triangular_lattice(nx=8, ny=8, a=1e-3, radius=0.52e-3) -> Packing:
    """Perfect triangular lattice (a Bravais lattice: every disk a centre of symmetry), overlaps
    of 2 * radius - a with the 6 neighbours."""
    j, i = np.divmod(np.arange(nx * ny), nx)
    x = np.column_stack([i + 0.5 * (j % 2), j * np.sqrt(3) / 2]) * a
    cell = np.diag([nx * a, ny * a * np.sqrt(3) / 2])
    return Packing(positions=x, radii=np.full(nx * ny, radius), cell=cell)


def _compression(k=0):
    """A few compressive / shearing F (det < 1), deterministic."""
    rng = np.random.default_rng(100 + k)
    F = np.diag([0.998, 0.9985]) + 1e-3 * rng.uniform(-1, 1, (2, 2))
    return F


@pytest.mark.parametrize("name", ["rve-70-1", "sheared-lattice"])
def test_stress_and_tangent_are_derivatives_of_relaxed_energy(standard, name):
    """P = dW_rel/dF and A = dP/dF by central differences, to 1e-6 (norm-relative).

    The FD states are relaxed from the converged w* (same local minimum); the active set (contact
    count, rattler set, fixed disk) is asserted equal at F +- h, so W_rel is smooth across the step.
    h = 1e-7: truncation O(h^2), round-off ~ 1e-16 / h ~ 1e-9 relative, Newton residual 1e-12 of
    the mean contact force (force_tol) adds below 1e-8.
    """
    p = standard[name] if name in standard else lattice_packing(7, 6, seed=3, shear=0.4)
    mat = RelaxedMaterial(p, KN, force_tol=1e-12)
    for k in range(2):
        F = _compression(k)
        res = mat(F)
        assert res.stable and res.n_contacts > 50
        h = 1e-7
        Pfd = np.zeros((2, 2))
        Afd = np.zeros((2, 2, 2, 2))
        for a in range(2):
            for b in range(2):
                dF = np.zeros((2, 2))
                dF[a, b] = h
                plus, minus = mat(F + dF, start=res), mat(F - dF, start=res)
                for r in (plus, minus):
                    assert r.n_contacts == res.n_contacts
                    assert np.array_equal(r.rattlers, res.rattlers) and r.fixed == res.fixed
                Pfd[a, b] = (plus.energy - minus.energy) / (2 * h)
                Afd[:, :, a, b] = (plus.piola - minus.piola) / (2 * h)
        assert _rel(Pfd, res.piola) < 1e-6
        assert _rel(Afd, res.tangent) < 1e-6
        A = res.tangent
        assert np.max(np.abs(A - A.transpose(2, 3, 0, 1))) <= 1e-12 * np.max(np.abs(A))


def test_relaxed_energy_never_exceeds_taylor(standard):
    """W_rel(F) <= W_Taylor(F) (the minimum includes w = 0) on the ten 70- and 350-disk standard
    RVEs for compression, shear and extension; W(F, 0) of the relaxed code equals TaylorMaterial's W (an
    independent kernel) to round-off."""
    rng = np.random.default_rng(3)
    Fs = [np.eye(2), np.diag([0.995, 0.999]), np.array([[1.0, 0.004], [0.0, 0.999]]), np.diag([1.002, 0.997])] + [
        np.eye(2) + 3e-3 * rng.uniform(-1, 1, (2, 2)) for _ in range(3)
    ]
    for name, p in standard.items():
        mat, tay = RelaxedMaterial(p, KN), TaylorMaterial(p, KN)
        for F in Fs:
            wt = tay(F).energy
            assert abs(mat.energy(F, np.zeros((p.n, 2))) - wt) <= 1e-12 * wt + 1e-300
            assert mat(F).energy <= wt * (1 + 1e-12), (name, F)


def test_bravais_lattice_reproduces_taylor_exactly():
    """Every disk of a perfect triangular lattice is a centre of symmetry: under a homogeneous F
    the forces on each disk cancel pairwise (W_w = 0 at w = 0) and so do the rows of W_wF, so the
    relaxed P and A equal Taylor's (eqs 10-12) up to round-off and w stays 0."""
    p = triangular_lattice()
    mat, tay = RelaxedMaterial(p, KN), TaylorMaterial(p, KN)
    for F in (np.eye(2), np.diag([0.99, 0.995]), np.array([[1.0, 0.01], [0.002, 0.998]])):
        r, t = mat(F), tay(F)
        assert r.n_contacts == t.n_contacts == 3 * p.n
        assert not r.rattlers.any() and r.stable
        assert np.max(np.abs(r.fluctuation)) <= 1e-14 * 1e-3
        assert _rel(r.piola, t.piola) < 1e-12
        assert _rel(r.tangent, t.tangent) < 1e-10
        assert abs(r.energy - t.energy) <= 1e-12 * t.energy


def test_disordered_rve_relaxes_and_fluctuation_is_periodic(standard):
    """Under compression the disordered rve-70-1 relaxes strictly below Taylor (by > 1 %), the
    residual is at the tolerance, and W(F, w) is unchanged when one disk's w gets a current lattice
    vector F C n (that disk becomes its own periodic image)."""
    p = standard["rve-70-1"]
    mat, tay = RelaxedMaterial(p, KN), TaylorMaterial(p, KN)
    F = np.diag([0.997, 0.998])
    r = mat(F)
    wt = tay(F).energy
    assert r.energy < 0.99 * wt
    assert np.max(np.abs(r.fluctuation)) > 0
    w = np.array(r.fluctuation)
    assert abs(mat.energy(F, w) - r.energy) <= 1e-12 * r.energy
    for k, n in ((5, (1, 0)), (17, (0, -1)), (40, (2, 1))):
        w2 = w.copy()
        w2[k] += F @ p.cell @ np.array(n, float)
        assert abs(mat.energy(F, w2) - r.energy) <= 1e-12 * r.energy
    # the whole fluctuation shifted rigidly: same energy (the gauge the fixed disk removes)
    assert abs(mat.energy(F, w + 3e-5) - r.energy) <= 1e-12 * r.energy


def test_rattlers_are_reported_and_keep_their_fluctuation():
    """A small disk put into a void of the lattice touches nothing: it is a rattler, excluded from
    the solve, and its start w is kept (it is force-free anywhere in its void); the rest is the
    lattice (Taylor)."""
    base = triangular_lattice()
    hole = (base.positions[0] + base.positions[1] + base.positions[8]) / 3
    p = Packing(positions=np.vstack([base.positions, hole]), radii=np.append(base.radii, 0.02e-3), cell=base.cell)
    mat = RelaxedMaterial(p, KN)
    start = np.zeros((p.n, 2))
    start[-1] = [1e-5, -2e-5]
    F = np.diag([0.99, 0.995])
    r, t = mat(F, start=start), TaylorMaterial(p, KN)(F)
    assert r.rattlers[-1] and np.count_nonzero(r.rattlers) == 1
    assert np.array_equal(r.fluctuation[-1], start[-1])
    assert _rel(r.piola, t.piola) < 1e-12 and _rel(r.tangent, t.tangent) < 1e-10


def test_rattler_pressed_into_a_neighbour_is_expelled_to_zero_force():
    """A disk in a void of the lattice, started overlapping one lattice disk (a rattler with one
    contact), is pushed out to zero force: the result has no contact on it and the lattice's Taylor
    P and A, from every start (two overlaps, two directions); held where it started it would add
    its contact force to P."""
    base = triangular_lattice()
    hole = (base.positions[0] + base.positions[1] + base.positions[8]) / 3
    r_small = 0.03e-3  # the void's free radius under F is ~0.05e-3
    p = Packing(positions=np.vstack([base.positions, hole]), radii=np.append(base.radii, r_small), cell=base.cell)
    mat, F = RelaxedMaterial(p, KN), np.diag([0.99, 0.995])
    t = TaylorMaterial(base, KN)(F)
    for k, overlap in ((0, 3e-6), (1, 8e-6)):
        x = F @ p.positions[-1]
        d = F @ base.positions[k] - x
        gap = np.linalg.norm(d) - (r_small + base.radii[k])
        start = np.zeros((p.n, 2))
        start[-1] = d / np.linalg.norm(d) * (gap + overlap)  # into disk k only
        assert mat.energy(F, start) > TaylorMaterial(p, KN)(F).energy
        r = mat(F, start=start)
        assert r.rattlers[-1] and r.n_held == 0
        assert r.n_contacts == 3 * base.n
        assert _rel(r.piola, t.piola) < 1e-12 and _rel(r.tangent, t.tangent) < 1e-10


def test_stress_does_not_depend_on_the_start(standard):
    """P and A at a given F are those of the minimiser, not of the start: from w = 0, from a random
    periodic w (a tenth of the mean overlap per component) and warm from the minimiser at another F
    they agree to 1e-12 (P) and 1e-11 (A), on 70- and 350-disk standard RVEs. (With rattlers held
    where they started, two starts differed by 4e-5.)"""
    rng = np.random.default_rng(11)
    for name in ("rve-70-1", "rve-70-2", "rve-350-1"):
        p = standard[name]
        mat = RelaxedMaterial(p, KN)
        for F in (np.eye(2), np.array([[0.9995, 0.0002], [0.0001, 0.9997]])):
            ref = mat(F)
            eps = 1e-3 * float(p.radii.mean())  # ~ the mean overlap of the standard packings
            starts = (0.1 * eps * rng.uniform(-1, 1, (p.n, 2)), mat(F + 2e-4 * np.array([[1.0, 0.3], [-0.2, 0.5]])))
            for start in starts:
                r = mat(F, start=start)
                assert _rel(r.piola, ref.piola) < 1e-12, (name, F)
                assert _rel(r.tangent, ref.tangent) < 1e-11, (name, F)
                assert np.array_equal(r.rattlers, ref.rattlers) and r.n_contacts == ref.n_contacts


def test_warm_start_history_commit_and_revert(standard):
    """evaluate() starts each Gauss point from its committed w* (plus the first-order predictor
    dw*/dF : dF): a nearby F converges in fewer Newton iterations than from w = 0; revert() keeps
    the old history."""
    p = standard["rve-350-1"]
    mat = RelaxedMaterial(p, KN)
    F1 = np.stack([np.diag([0.998, 0.999]), np.array([[0.999, 0.001], [0.0, 0.998]])])
    b1 = mat.evaluate(F1)
    with pytest.raises(InputError, match="commit"):
        RelaxedMaterial(p, KN).commit()
    mat.commit()
    w_committed = mat.committed_fluctuation(0)
    F2 = F1 + 2e-5 * np.array([[-1.0, 0.5], [0.3, -0.7]])
    warm = mat.evaluate(F2)
    cold = RelaxedMaterial(p, KN).evaluate(F2)
    assert np.all(warm.n_newton < cold.n_newton), (warm.n_newton, cold.n_newton, b1.n_newton)
    assert np.all(warm.energy <= TaylorMaterial(p, KN).evaluate(F2).energy)
    mat.revert()
    assert np.array_equal(mat.committed_fluctuation(0), w_committed)


def test_trial_start_follows_the_iterates_revert_returns_to_committed(standard):
    """warm_start="trial": within an attempt each evaluate starts from the previous evaluate's
    trial. An FE-like sequence (a load increment, then corrections of 1e-6 and 1e-10) needs at
    most 2 Newton iterations at the corrections (1 for the factorisation of A at a converged
    start), where a start from the committed state needs as many as at the first iterate; the
    final P and A equal the committed start's to 1e-10 relative (the relaxation's tolerance
    1e-12 x mean contact force, measured 2e-12: both are the same minimiser, whereas another
    basin differs by 1e-4 or more). After revert() the next evaluate starts from the committed
    state (bitwise the committed-start material's result); commit() copies the last trial (an
    evaluate at the same F then starts converged: 1 iteration, bitwise the same P)."""
    p = standard["rve-70-1"]
    F0 = np.eye(2)[None]
    F1 = np.array([[[0.9995, 2e-4], [1e-4, 0.9997]]])
    dF = np.array([[[1.0, 0.3], [-0.2, -0.6]]])
    seq = [F1, F1 + 1e-6 * dF, F1 + 1e-6 * dF + 1e-10 * dF]
    runs = {}
    for ws in ("trial", "committed"):
        mat = RelaxedMaterial(p, KN, warm_start=ws)
        mat.evaluate(F0)
        mat.commit()
        runs[ws] = (mat, [mat.evaluate(F) for F in seq])
    warm, cold = runs["trial"][1], runs["committed"][1]
    assert warm[0].n_newton[0] == cold[0].n_newton[0] >= 3  # the same start at the first iterate
    assert warm[1].n_newton[0] <= 2 and warm[2].n_newton[0] <= 2, [b.n_newton for b in warm]
    assert cold[2].n_newton[0] >= 3, [b.n_newton for b in cold]
    assert _rel(warm[2].piola, cold[2].piola) < 1e-10 and _rel(warm[2].tangent, cold[2].tangent) < 1e-10
    mat, cmat = runs["trial"][0], runs["committed"][0]
    mat.evaluate(np.array([[[0.99, 3e-3], [0.0, 0.995]]]))  # a failed attempt's far iterate
    mat.revert()
    cmat.revert()
    a, b = mat.evaluate(seq[1]), cmat.evaluate(seq[1])
    assert np.array_equal(a.piola, b.piola) and np.array_equal(a.tangent, b.tangent)
    mat.commit()
    again = mat.evaluate(seq[1])
    assert again.n_newton[0] == 1 and np.array_equal(again.piola, a.piola)
    with pytest.raises(InputError, match="warm_start"):
        RelaxedMaterial(p, KN, warm_start="previous")
    assert RelaxedMaterial(p, KN, warm_start="committed").fresh().warm_start == "committed"


def test_bad_inputs_name_the_option(standard):
    p = standard["rve-70-1"]
    with pytest.raises(InputError, match="normal_stiffness"):
        RelaxedMaterial(p, -1.0)
    with pytest.raises(InputError, match="min_contacts"):
        RelaxedMaterial(p, KN, min_contacts=7)
    with pytest.raises(InputError, match="force_tol"):
        RelaxedMaterial(p, KN, force_tol=0.0)
    mat = RelaxedMaterial(p, KN)
    with pytest.raises(InputError, match="det F"):
        mat(np.array([[1.0, 0.0], [0.0, -1.0]]))
    with pytest.raises(InputError, match="start"):
        mat(np.eye(2), start=np.zeros((3, 2)))
    with pytest.raises(InputError, match="rve"):
        mat.evaluate(np.eye(2), rve=2)


def test_minimiser_is_in_equilibrium_by_an_independent_force_sum(standard):
    """At w* the net contact force on every disk vanishes, the fixed disk (translation gauge) and
    the rattlers included (they are expelled to zero force, none held): recomputed with the
    cell-list neighbour search at x = F X + w* and numpy (not the relaxation's kernels), relative
    to the mean contact force; no contact touches a rattler."""
    p = standard["rve-350-2"]
    F = np.array([[0.997, 0.001], [0.0, 0.998]])
    r = RelaxedMaterial(p, KN)(F)
    x = p.positions @ F.T + r.fluctuation
    nl = find_neighbours(x, p.radii, F @ p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    n = nl.branch[c] / nl.distance[c, None]
    f = -KN * eps[c, None] * n  # force on i (eq 5)
    net = np.zeros((p.n, 2))
    np.add.at(net, nl.i[c], f)
    np.add.at(net, nl.j[c], -f)
    fmean = KN * eps[c].mean()
    assert int(c.sum()) == r.n_contacts
    assert np.max(np.abs(net)) <= 1e-9 * fmean
    assert 0 < np.count_nonzero(r.rattlers) < 0.2 * p.n and r.n_held == 0
    assert not np.any(r.rattlers[nl.i[c]] | r.rattlers[nl.j[c]])


def test_simple_shear_from_zero_finds_the_backbone_minimum(standard):
    """Simple shear F = [[1, 1e-3], [0, 1]] on rve-70-1 opens the stretched contacts at w = 0 (the
    principal stretch 5e-4 is twice the mean overlap) and the rattler cascade leaves no backbone
    there; relaxed from w = 0 (continuation in F, see "Continuation") the result is the proper
    minimum: no held disk, every disk in balance by an independent force sum (net force <= 1e-8 of
    the mean contact force), and energy and P equal (1e-10, 1e-12) to those reached by warm starts
    in steps of 1e-4 of g, a path on which every state has a backbone. The energy is far below
    the Taylor energy (the held fallback was 25-95 % above the minimum)."""
    p = standard["rve-70-1"]
    mat = RelaxedMaterial(p, KN)
    F = np.array([[1.0, 1e-3], [0.0, 1.0]])
    warm = None
    for g in np.arange(1, 11) * 1e-4:
        warm = mat(np.array([[1.0, g], [0.0, 1.0]]), start=warm)
        assert warm.n_held == 0 and not np.all(warm.rattlers), g  # the path keeps its backbone
    r = mat(F)
    assert r.n_held == 0 and r.held_force == 0.0
    assert np.count_nonzero(r.rattlers) < 0.2 * p.n
    x = p.positions @ F.T + r.fluctuation
    nl = find_neighbours(x, p.radii, F @ p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    f = -KN * eps[c, None] * nl.branch[c] / nl.distance[c, None]  # force on i (eq 5)
    net = np.zeros((p.n, 2))
    np.add.at(net, nl.i[c], f)
    np.add.at(net, nl.j[c], -f)
    assert np.max(np.abs(net)) <= 1e-8 * KN * eps[c].mean()
    assert abs(r.energy - warm.energy) <= 1e-10 * warm.energy
    assert _rel(r.piola, warm.piola) < 1e-12
    assert r.energy < 0.9 * TaylorMaterial(p, KN)(F).energy


def test_condensation_solves_an_indefinite_w_ww_exactly():
    """(W_ww)^-1 W_wF of the condensed tangent (R5): a positive definite W_ww through the block
    LDL^T, an indefinite one (its LDL^T needs a shift) through the sparse LU of the unshifted matrix,
    both equal to a dense solve; the block matrix equals the dense assembly of the blocks."""
    from gransim.rve.relaxed import _LDL, _block_matrix, _condensation_solve

    rng = np.random.default_rng(4)
    nb = 12
    pairs = [(i, j) for i in range(nb) for j in range(i + 1, nb) if rng.random() < 0.3]
    pairs += [(0, 1), (0, 1)]  # a duplicate block adds
    Ap = np.zeros(nb + 1, np.int64)
    for _, j in pairs:
        Ap[j + 1] += 1
    Ap = np.cumsum(Ap)
    Ai = np.empty(Ap[-1], np.int64)
    Ax = np.empty((Ap[-1], 2, 2))
    fill = Ap[:-1].copy()
    dense = np.zeros((2 * nb, 2 * nb))
    for i, j in pairs:
        K = rng.normal(size=(2, 2))
        K = K + K.T
        Ai[fill[j]], Ax[fill[j]] = i, K
        fill[j] += 1
        dense[2 * i : 2 * i + 2, 2 * j : 2 * j + 2] += K
        dense[2 * j : 2 * j + 2, 2 * i : 2 * i + 2] += K
    B = rng.normal(size=(2 * nb, 4))
    for shift, definite in ((20.0, True), (0.5, False)):
        Hd = np.array([shift * np.eye(2) for _ in range(nb)])
        W = dense + np.kron(np.eye(nb), shift * np.eye(2))
        assert (np.linalg.eigvalsh(W).min() > 0) == definite
        np.testing.assert_array_equal(_block_matrix(Hd, Ap, Ai, Ax).toarray(), W)
        lu = _LDL(Hd, Ap, Ai, Ax)
        assert lu.shifted == (not definite)
        X = _condensation_solve(lu, Hd, Ap, Ai, Ax, B)
        assert np.abs(X - np.linalg.solve(W, B)).max() <= 1e-10 * np.abs(X).max()
        if not definite:  # the shifted factorisation's solve is another matrix's
            assert np.abs(lu.solve(B) - X).max() > 1e-3 * np.abs(X).max()
    # a singular W_ww (a zero mode: no unique equilibrium branch) keeps the shifted solve
    Hd = np.ones((1, 2, 2))
    no = (np.zeros(2, np.int64), np.zeros(0, np.int64), np.zeros((0, 2, 2)))
    lu = _LDL(Hd, *no)
    assert lu.shifted
    np.testing.assert_array_equal(_condensation_solve(lu, Hd, *no, B[:2]), lu.solve(B[:2]))
