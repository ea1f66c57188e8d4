"""Physics checks of the Taylor homogenization (eqs 6-12 of Meier, Steinmann & Kuhl)."""

from __future__ import annotations

import numpy as np
import pytest
from rve_fixtures import lattice_packing, random_packing

from gransim import InputError, Packing
from gransim.rve import TaylorMaterial, contact_state, homogenize
from gransim.rve.reference import crosscheck, homogenize_bruteforce

KN = 1.0e7  # N/m


def _random_F(rng, amplitude):
    """F = R(theta) U with U = I + sym noise: positive det, 'near' (small amplitude) or 'far'."""
    while True:
        F = np.eye(2) + amplitude * rng.uniform(-1, 1, (2, 2))
        if np.linalg.det(F) > 0.3:
            return F


def _rel(a, b):
    return np.max(np.abs(np.asarray(a) - np.asarray(b))) / np.max(np.abs(b))


@pytest.mark.parametrize("name", ["lattice", "sheared", "random"])
@pytest.mark.parametrize("amplitude", [0.02, 0.25])
def test_stress_and_tangent_are_derivatives(packings, name, amplitude):
    """P = dW/dF and A = dP/dF by central differences, to 1e-6 (norm-relative).

    Step h = 1e-7 |F|: truncation O(h^2) ~ 1e-14 relative for the smooth piecewise-quadratic
    W, round-off ~ 1e-16/h ~ 1e-9; a contact opening inside +-h would break smoothness, which
    the fixed seeds avoid (checked by equal contact counts at F +- h).
    """
    p = packings[name]
    mat = TaylorMaterial(p, KN)
    rng = np.random.default_rng(11)
    for _ in range(3):
        F = _random_F(rng, amplitude)
        res = mat(F)
        h = 1e-7
        Pfd = np.zeros((2, 2))
        Afd = np.zeros((2, 2, 2, 2))
        for k in range(2):
            for L in range(2):
                dF = np.zeros((2, 2))
                dF[k, L] = h
                plus, minus = mat(F + dF), mat(F - dF)
                assert plus.n_contacts == minus.n_contacts == res.n_contacts
                Pfd[k, L] = (plus.energy - minus.energy) / (2 * h)
                Afd[:, :, k, L] = (plus.piola - minus.piola) / (2 * h)
        assert res.n_contacts > 20
        assert _rel(Pfd, res.piola) < 1e-6
        assert _rel(Afd, res.tangent) < 1e-6


def test_major_symmetry_and_cauchy_symmetry(packings):
    rng = np.random.default_rng(5)
    for p in packings.values():
        res = homogenize(p, _random_F(rng, 0.2), KN)
        A = res.tangent
        assert np.max(np.abs(A - A.transpose(2, 3, 0, 1))) <= 1e-14 * np.max(np.abs(A))
        assert abs(res.cauchy[0, 1] - res.cauchy[1, 0]) <= 1e-14 * np.max(np.abs(res.cauchy))


def test_objectivity(packings):
    """W(QF) = W(F), P(QF) = Q P(F), A(QF)_iJkL = Q_ia Q_kb A(F)_aJbL for rotations Q."""
    rng = np.random.default_rng(7)
    for p in packings.values():
        F = _random_F(rng, 0.15)
        for theta in (0.3, 2.0, -1.1):
            Q = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
            a, b = homogenize(p, F, KN), homogenize(p, Q @ F, KN)
            assert a.n_contacts == b.n_contacts
            assert abs(b.energy - a.energy) <= 1e-13 * a.energy
            assert _rel(b.piola, Q @ a.piola) < 1e-13
            assert _rel(b.tangent, np.einsum("ia,kb,aJbL->iJkL", Q, Q, a.tangent)) < 1e-13
            assert _rel(b.cauchy, Q @ a.cauchy @ Q.T) < 1e-13


def test_square_lattice_exact():
    """Disks on a square lattice (spacing a, radius R, a < 2R < a sqrt 2), F = diag(l1, l2).

    Only the axial neighbours touch: eps_k = 2R - l_k a, W = kn (eps_1^2 + eps_2^2) / (2 a^2),
    P = diag(-kn eps_1 / a, -kn eps_2 / a); the tangent entries are derived in the comments.
    """
    a, R = 1e-3, 0.52e-3
    p = Packing(positions=[[0.0, 0.0], [a, 0.0]], radii=[R, R], cell=[[2 * a, 0], [0, a]])
    l1, l2 = 0.99, 1.01
    res = homogenize(p, np.diag([l1, l2]), KN)
    e1, e2 = 2 * R - l1 * a, 2 * R - l2 * a
    assert res.n_contacts == 4
    assert res.energy == pytest.approx(KN * (e1**2 + e2**2) / (2 * a**2), rel=1e-14)
    np.testing.assert_allclose(res.piola, np.diag([-KN * e1 / a, -KN * e2 / a]), rtol=1e-14)
    # pair along 1: n = e1, L = a e1, d = l1 a: A_1111 += kn 2R/d a^2 - kn e1/d a^2 = kn a,
    # A_2121 += -kn eps_1 / d * a^2 (geometric); per area a^2
    A = res.tangent
    assert A[0, 0, 0, 0] == pytest.approx(KN, rel=1e-14)
    assert A[1, 1, 1, 1] == pytest.approx(KN, rel=1e-14)
    assert A[1, 0, 1, 0] == pytest.approx(-KN * e1 / (l1 * a), rel=1e-13)
    assert A[0, 1, 0, 1] == pytest.approx(-KN * e2 / (l2 * a), rel=1e-13)
    assert A[0, 0, 1, 1] == 0.0 and A[0, 1, 1, 0] == 0.0
    np.testing.assert_allclose(res.cauchy, res.piola @ np.diag([l1, l2]) / (l1 * l2), rtol=1e-15)


def test_zero_without_overlaps():
    """Disks that do not overlap (even after moderate deformation): W = 0, P = 0, A = 0."""
    p = lattice_packing(6, 6, seed=2, swell=0.8, spread=0.05)
    for F in (np.eye(2), np.array([[1.05, 0.1], [0.0, 1.1]])):
        res = homogenize(p, F, KN)
        assert res.n_contacts == 0
        assert res.energy == 0.0
        assert not np.any(res.piola) and not np.any(res.tangent) and not np.any(res.cauchy)


def test_stress_continuous_as_contacts_open_and_close(packings):
    """Along a compression path the contact set changes, yet P has no jump: the largest change
    between neighbouring states shrinks in proportion to the step (Lipschitz), while contacts
    open/close inside the path."""
    p = packings["random"]
    mat = TaylorMaterial(p, KN)
    jumps = []
    for steps in (400, 800):
        t = np.linspace(0.0, 1.0, steps + 1)
        F = np.zeros((t.size, 2, 2))
        F[:, 0, 0] = 1.0 + 0.08 * t
        F[:, 1, 1] = 1.0 - 0.03 * t
        F[:, 0, 1] = 0.05 * t
        b = mat.evaluate(F)
        assert np.unique(b.n_contacts).size > 5  # the contact set really changes
        jumps.append(np.max(np.abs(np.diff(b.piola, axis=0))) / np.max(np.abs(b.piola)))
    assert jumps[1] < 0.6 * jumps[0]


def test_two_disks_contact_closing_is_continuous():
    """Exact case: P (and W) go to zero continuously as one contact opens; A jumps (Heaviside)."""
    a, R = 1e-3, 0.251e-3  # four disks per cell, only the pair along 1 at distance a/2 can touch
    p = Packing(positions=[[0, 0], [0.5 * a, 0]], radii=[R, R], cell=[[a, 0], [0, 10 * a]])
    lam_c = 2 * R / (0.5 * a)  # stretch at which the contact opens
    below, above = (
        homogenize(p, np.diag([lam_c * (1 - 1e-9), 1.0]), KN),
        homogenize(p, np.diag([lam_c * (1 + 1e-9), 1.0]), KN),
    )
    assert below.n_contacts == 2 and above.n_contacts == 0
    assert np.max(np.abs(below.piola)) < 1e-9 * KN * R / a * 10
    assert below.tangent[0, 0, 0, 0] > 0 and above.tangent[0, 0, 0, 0] == 0


@pytest.mark.parametrize("name", ["lattice", "sheared", "random"])
def test_agrees_with_bruteforce(packings, name):
    """The numba path against the plain-numpy all-images sum: 1e-12 relative (round-off of
    summation order only), identical contact counts."""
    for rec in crosscheck({name: packings[name]}, KN):
        assert rec["contacts_equal"], rec
        assert rec["rel_energy"] < 1e-12 and rec["rel_piola"] < 1e-12 and rec["rel_tangent"] < 1e-12, rec


def test_tiny_cell_self_images():
    """Cells smaller than a disk diameter: a disk touches its own images (counted once each)."""
    p = Packing(
        positions=[[0.1e-3, 0.2e-3], [0.6e-3, 0.7e-3]],
        radii=[0.45e-3, 0.3e-3],
        cell=[[0.8e-3, 0.2e-3], [0.0, 0.9e-3]],
    )
    for F in (np.eye(2), np.array([[0.9, 0.1], [-0.05, 1.1]])):
        ref = homogenize_bruteforce(p, F, KN)
        res = homogenize(p, F, KN)
        assert res.n_contacts == ref["n_contacts"] > 4
        assert _rel(res.tangent, ref["tangent"]) < 1e-12 and _rel(res.piola, ref["piola"]) < 1e-12


def test_candidate_cache_catches_contacts_opening_and_closing():
    """A small skin forces rebuilds along a strong compression; the cached path must still
    equal the brute force at every state (no missed closing contact), and states inside the
    skin must not rebuild."""
    p = random_packing(40, seed=4, phi=0.8)
    mat = TaylorMaterial(p, KN, skin_fraction=0.02)
    mat(np.eye(2))
    assert mat.n_builds == 1
    mat(np.diag([0.995, 1.0]))  # sigma_min = 0.995 > 1/1.02: within the skin
    assert mat.n_builds == 1
    counts = []
    for lam in np.linspace(1.0, 0.8, 9):
        F = np.array([[lam, 0.1 * (1 - lam)], [0.0, 1.0 / np.sqrt(lam)]])
        res = mat(F)
        ref = homogenize_bruteforce(p, F, KN)
        assert res.n_contacts == ref["n_contacts"]
        assert _rel(res.piola, ref["piola"]) < 1e-12
        counts.append(res.n_contacts)
    assert mat.n_builds > 3
    assert counts[-1] > counts[0]  # contacts closed along the path
    # back to the reference state: an older set is valid again, no new build
    n = mat.n_builds
    mat(np.eye(2))
    assert mat.n_builds == n


def test_batched_equals_single_and_rve_index(packings):
    names = list(packings)
    mat = TaylorMaterial(packings, KN)
    rng = np.random.default_rng(3)
    F = np.array([_random_F(rng, 0.1) for _ in range(12)])
    idx = rng.integers(0, len(names), 12)
    b = mat.evaluate(F, idx)
    for g in range(12):
        one = homogenize(packings[names[idx[g]]], F[g], KN)
        assert b[g].n_contacts == one.n_contacts
        np.testing.assert_allclose(b.tangent[g], one.tangent, rtol=0, atol=1e-13 * np.abs(one.tangent).max())
        np.testing.assert_allclose(b.cauchy[g], one.cauchy, rtol=0, atol=1e-13 * np.abs(one.cauchy).max())
    assert np.all(b.n_candidates >= b.n_contacts)


def _rotation(t):
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_response_depends_on_F_alone_bitwise(seed):
    """The Taylor response is a function of F alone (x = F X, no history), bit for bit.

    F2 evaluated on a fresh material (candidate set anchored at F2), after F1 (a rotation: its
    set covers F2, sigma_min(F2 F1^-1) = sigma_min(F2), and is reused) and after F1 then F3 (beyond
    the skin of F1's set: a rebuild, whose set then evaluates F2) gives the same W, P, A, sigma
    and contact count to the last bit. The sets come from cell lists at other anchors, which list
    the pairs in other orders; the kernel adds the active contacts in the set's order, so only a
    canonical order of every set makes the sums identical. Without it (cell-list order) seeds 1
    and 2 differ after F1 and seeds 3 and 4 after F3 (in P and A, ~1e-16 relative).
    """
    p = random_packing(120, seed=seed, phi=0.9)
    F1 = _rotation(0.5)
    F2 = np.array([[0.965, 0.02], [0.01, 1.0]])  # sigma_min 0.96 > 1/1.1: inside the skin of F1's set
    F3 = _rotation(-0.9) @ np.array([[0.88, 0.04], [-0.02, 1.01]])  # sigma_min 0.88 < 1/1.1: a rebuild
    ref = TaylorMaterial(p, KN).evaluate(F2)
    after1 = TaylorMaterial(p, KN)
    after1(F1)
    got1 = after1.evaluate(F2)
    assert after1.n_builds == 1  # F2 used F1's set
    after3 = TaylorMaterial(p, KN)
    after3(F1)
    after3(F3)
    assert after3.n_builds == 2  # F3 forced a rebuild
    got3 = after3.evaluate(F2)
    assert after3.n_builds == 2  # F2 used a cached set (the latest valid one: F3's)
    assert got3.n_candidates[0] != ref.n_candidates[0]  # another set than the fresh one
    assert ref.n_contacts[0] > 100
    for got in (got1, got3):
        for name in ("energy", "piola", "tangent", "cauchy", "n_contacts"):
            assert np.array_equal(getattr(got, name), getattr(ref, name)), name
    # the single-state path (serial kernel) too
    one_fresh = TaylorMaterial(p, KN)(F2)
    for mat in (after1, after3):
        one = mat(F2)
        assert one.energy == one_fresh.energy
        assert np.array_equal(one.piola, one_fresh.piola) and np.array_equal(one.tangent, one_fresh.tangent)


def test_blocked_batch_is_bitwise_the_serial_kernel(packings):
    """The batch kernel evaluates up to LANES states per pass over a shared candidate set (SIMD
    lanes, out-of-contact candidates added as -0.0); the single-state path sums one state's
    contacts one after the other. Both must give the same W, P, A, sigma and contact count to the
    last bit, for any mix of RVEs and candidate sets in a batch: here three RVEs in random order,
    a batch of 45 states (not a multiple of LANES), states far enough apart to need several sets
    per RVE, and states with no contact at all (stretched apart)."""
    from gransim.rve import taylor

    names = list(packings)
    rng = np.random.default_rng(11)
    F = np.array([_random_F(rng, 0.12) for _ in range(40)] + [np.diag([1.3, 1.3])] * 5)
    idx = rng.integers(0, len(names), F.shape[0])
    mat = TaylorMaterial(packings, KN, skin_fraction=0.03)
    b = mat.evaluate(F, idx)
    assert mat.n_builds > len(names)  # several candidate sets per RVE in one batch
    assert np.any(b.n_contacts == 0) and b.n_contacts.max() > 20
    order, block_starts, block_set = taylor._blocks(mat._assign(F, idx))
    assert np.diff(block_starts).max() == taylor.LANES and np.diff(block_starts).min() < taylor.LANES
    for g in range(F.shape[0]):
        one = TaylorMaterial(packings, KN, skin_fraction=0.03)(F[g], int(idx[g]))
        assert one.n_contacts == b.n_contacts[g]
        assert one.energy == b.energy[g]
        for name in ("piola", "tangent", "cauchy"):
            assert np.array_equal(getattr(one, name), getattr(b, name)[g]), (g, name)


def test_the_same_states_again_reuse_the_last_batch():
    """evaluate() keeps its last batch: the same F (and RVE indices) again returns it without a
    kernel call (a Newton solve starts where the previous one converged); any other F, even one
    changed in place in the caller's array by one ulp, is evaluated, and equals a fresh material's."""
    p = random_packing(40, seed=4, phi=0.9)
    mat = TaylorMaterial(p, KN)
    F = np.stack([np.eye(2), np.diag([0.99, 1.0])])
    a = mat.evaluate(F)
    assert mat.evaluate(F.copy()) is a
    F[1, 0, 0] = np.nextafter(0.99, 1.0)  # the caller's array changed in place
    b = mat.evaluate(F)
    assert b is not a
    ref = TaylorMaterial(p, KN).evaluate(F)
    for name in ("energy", "piola", "tangent", "cauchy", "n_contacts"):
        assert np.array_equal(getattr(b, name), getattr(ref, name)), name
    assert not np.array_equal(b.piola[1], a.piola[1])
    assert mat.evaluate(F, cauchy=False) is not b  # another request: evaluated


def test_contact_state_forces_reproduce_piola(packings):
    """P = 1/V sum f (x) L (eq 10) from the per-contact forces."""
    p = packings["sheared"]
    F = np.array([[0.98, 0.03], [0.01, 1.0]])
    cs = contact_state(p, F, KN)
    res = homogenize(p, F, KN)
    assert len(cs) == res.n_contacts
    np.testing.assert_allclose(
        np.einsum("mi,mJ->iJ", cs.force, cs.reference_branch) / p.area,
        res.piola,
        rtol=0,
        atol=1e-12 * np.abs(res.piola).max(),
    )
    assert np.all(cs.overlap > 0)
    np.testing.assert_allclose(np.linalg.norm(cs.normals, axis=1), 1.0)


@pytest.mark.parametrize(
    "F, match",
    [
        (np.diag([1.0, -1.0]), "det F must be > 0"),
        (np.zeros((2, 2)), "det F must be > 0"),
        (np.eye(3), r"expected shape \(2, 2\)"),
        (np.array([[1.0, np.nan], [0.0, 1.0]]), "NaN"),
        (np.array([[1.0, np.inf], [0.0, 1.0]]), "NaN or inf"),
        ("abc", "numeric"),
    ],
)
def test_bad_deformation_gradient(packings, F, match):
    with pytest.raises(InputError, match=match):
        homogenize(packings["lattice"], F, KN)


def test_bad_batch_and_stiffness(packings):
    mat = TaylorMaterial(packings, KN)
    F = np.stack([np.eye(2), np.diag([1.0, 0.0])])
    with pytest.raises(InputError, match="at index 1"):
        mat.evaluate(F, [0, 0])
    with pytest.raises(InputError, match="one index per F"):
        mat.evaluate(np.stack([np.eye(2)] * 2), [0])
    with pytest.raises(InputError, match=r"\[0, 3\)"):
        mat.evaluate(np.eye(2), [5])
    with pytest.raises(InputError, match="no deformation gradients"):
        mat.evaluate(np.zeros((0, 2, 2)), [])
    with pytest.raises(InputError, match="pass an RVE index"):
        mat.evaluate(np.eye(2))
    for kn in (0.0, -1.0, np.nan, "x"):
        with pytest.raises(InputError, match="normal_stiffness"):
            homogenize(packings["lattice"], np.eye(2), kn)
    with pytest.raises(InputError, match="Packing"):
        homogenize(np.zeros((3, 2)), np.eye(2), KN)


def test_many_rebuilds_prune_old_sets_and_stay_exact():
    """More anchors than MAX_SETS_PER_RVE: old sets dropped between calls, still exact."""
    from gransim.rve import taylor

    p = random_packing(30, seed=6, phi=0.8)
    mat = TaylorMaterial(p, KN, skin_fraction=0.001)
    lams = np.linspace(1.0, 0.85, taylor.MAX_SETS_PER_RVE + 8)
    for lam in lams:
        mat(np.diag([lam, 1.0]))
    assert mat.n_builds > taylor.MAX_SETS_PER_RVE
    assert len(mat._rves[0].sets) <= taylor.MAX_SETS_PER_RVE + 1
    F = np.stack([np.diag([lam, 1.0]) for lam in lams[::7]])
    b = mat.evaluate(F)
    for g in range(F.shape[0]):
        ref = homogenize_bruteforce(p, F[g], KN)
        assert b.n_contacts[g] == ref["n_contacts"]
        assert _rel(b.piola[g], ref["piola"]) < 1e-12


@pytest.fixture(scope="module")
def standard_rves(tmp_path_factory):
    """The 15 standard RVEs: reused from results/packings when generated there, else generated
    (about 15 s) into a temporary folder, so this acceptance test always runs."""
    from pathlib import Path

    from gransim.cli.cmd_rve import standard_rve_names
    from gransim.generation import standard_packings
    from gransim.rve.study import load_packings

    names = standard_rve_names()
    d = Path("results/packings")
    if not all((d / f"{k}.h5").exists() for k in names):
        d = tmp_path_factory.mktemp("packings")
    return load_packings(standard_packings(d, names=names))


@pytest.mark.slow
def test_all_standard_rves_agree_with_bruteforce(standard_rves):
    """Acceptance: numba path = brute force to 1e-12 on all 15 RVEs (contacts identical)."""
    # three states per RVE keep this under ~15 s; ``gransim rve-check`` runs eight
    Fs = np.array([[[0.95, 0.0], [0.0, 1.0]], [[1.0, 0.05], [0.0, 1.0]], [[1.08, -0.06], [0.09, 0.93]]])
    assert len(standard_rves) == 15
    for rec in crosscheck(standard_rves, 2.8e7, Fs):
        assert rec["contacts_equal"], rec
        assert max(rec["rel_energy"], rec["rel_piola"], rec["rel_tangent"]) < 1e-12, rec


def test_pruning_keeps_the_sets_in_use():
    """Sets used recently survive pruning: the identity-anchored set, used at every call, is kept
    while many far states force builds; afterwards states near I need no new build."""
    from gransim.rve import taylor

    p = random_packing(30, seed=6, phi=0.8)
    mat = TaylorMaterial(p, KN, skin_fraction=0.01)
    for lam in 0.98 * 0.985 ** np.arange(taylor.MAX_SETS_PER_RVE + 8):  # each beyond the last skin
        mat.evaluate(np.stack([np.eye(2), np.diag([lam, 1.0])]))
    n = mat.n_builds
    assert n > taylor.MAX_SETS_PER_RVE
    mat(np.diag([1.0, 1.005]))
    assert mat.n_builds == n
