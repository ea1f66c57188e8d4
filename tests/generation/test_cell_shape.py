"""make_packing(cell="shape"): enthalpy minimised over the cell shape (gransim.generation.fire_shape).

Independent checks: the virial stress, the net forces and the enthalpy are plain numpy sums over
the brute-force O(N^2) periodic search (find_neighbours_bruteforce), not the generator's kernels.
"""

import numpy as np
import pytest
import scipy.linalg

from gransim.contacts import find_neighbours_bruteforce
from gransim.errors import InputError
from gransim.generation import make_packing, shipped_packing
from gransim.generation.fire_shape import _expm_upper, enthalpy_and_cell_forces
from gransim.generation.pack import DEFAULT_MEAN_OVERLAP, JAMMING_OVERLAP, SHAPE_FORCE_TOL
from gransim.io import load_packing

N = 120
TOL = SHAPE_FORCE_TOL  # make_packing's default force_tol with cell="shape" (1e-5)


@pytest.fixture(scope="module")
def pair():
    """The same request (seed, target) with a square cell and with the cell shape free."""
    return make_packing("quartz-sand", N, seed=4), make_packing("quartz-sand", N, seed=4, cell="shape")


def virial(p):
    """(sigma (2, 2), net forces (N, 2), contact overlaps) with k_n = 1 (compression positive;
    sigma = 1/A sum_c eps_c l_c (x) l_c / |l_c| is dimensionless: force / length / k_n in 2D)."""
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    n = nl.branch / nl.distance[:, None]
    sig = np.einsum("c,ci,cj->ij", eps, n, nl.branch) / p.area
    F = np.zeros((p.n, 2))
    np.add.at(F, nl.i, -eps[:, None] * n)
    np.add.at(F, nl.j, eps[:, None] * n)
    return sig, F, eps


def test_shape_packing_is_shear_stress_free_at_the_imposed_pressure(pair):
    sq, sh = pair
    sig, F, eps = virial(sh)
    P = sh.metadata["pressure_reduced"]  # k_n = 1: the imposed pressure in the units of sig
    # the cell residual of the stop criterion, checked independently: sigma = P I to force_tol P
    assert abs(sig[0, 1]) <= 1.001 * TOL * P
    assert abs(sig[0, 0] - sig[1, 1]) <= 1.001 * TOL * P
    assert abs(sig[0, 0] - P) <= 1.001 * TOL * P and abs(sig[1, 1] - P) <= 1.001 * TOL * P
    # force balance of every disk (residual="max")
    assert np.max(np.linalg.norm(F, axis=1)) <= 1.001 * TOL * eps.mean()
    # the square cell of the same request carries a shear stress far above that tolerance (and
    # above the scale mode's own 1e-3): the shape mode is what removes it
    s0, _, _ = virial(sq)
    p0 = 0.5 * np.trace(s0)
    assert max(abs(s0[0, 1]), abs(s0[0, 0] - s0[1, 1])) > 1e-2 * p0
    assert np.array_equal(sq.cell, sq.cell[0, 0] * np.eye(2))


def test_shape_packing_meets_the_targets_in_an_upper_triangular_cell(pair):
    sq, sh = pair
    _, _, eps = virial(sh)
    assert eps.mean() / (2 * sh.radii.mean()) == pytest.approx(DEFAULT_MEAN_OVERLAP, rel=0.021)
    assert np.array_equal(np.sort(sh.radii), np.sort(sq.radii))  # same sizes for the seed
    C = sh.cell
    assert C[1, 0] == 0.0 and C[0, 0] > 0 and C[1, 1] > 0
    assert abs(C[0, 1]) <= 0.5 * C[0, 0] * (1 + 1e-12)  # lattice-reduced
    assert C[0, 1] != 0.0 and C[0, 0] != C[1, 1]  # the shape did relax (a square cell would be exact)
    frac = np.linalg.solve(C, sh.positions.T).T
    assert np.all((frac >= 0) & (frac < 1))
    assert 0.82 < sh.solid_fraction < 0.87
    assert sh.metadata["cell"] == "shape" and sq.metadata["cell"] == "scale"


def test_cell_forces_are_the_derivatives_of_the_enthalpy(pair):
    """Q = -dH/de of the kernel against central differences of an independent enthalpy sum, for the
    three cell strains (dh = e h, centres affine: x -> G x), and dH/dh = -(A sigma - P A I) h^-T
    against differences in the cell entries at fixed fractional coordinates."""
    _, p = pair
    ell = 2 * p.radii.mean()
    x, r, h = p.positions / ell, p.radii / ell, p.cell / ell
    P = p.metadata["pressure_reduced"]
    # away from equilibrium (at the minimum Q ~ 1e-3 P A and a difference quotient would test its
    # own truncation error): centres moved by ~1e-3 and the cell sheared and stretched by ~1e-3
    rng = np.random.default_rng(0)
    x = x + 1e-3 * rng.standard_normal(x.shape)
    h = np.array([[1.001, 0.002], [0.0, 0.999]]) @ h

    def H(x, h):
        nl = find_neighbours_bruteforce(x, r, h, 0.0)
        return 0.5 * np.sum(nl.overlaps(r) ** 2) + P * np.linalg.det(h)

    H0, Q, f, diag = enthalpy_and_cell_forces(x, r, h, P)
    assert H0 == pytest.approx(H(x, h), rel=1e-13)
    assert np.max(np.abs(Q)) > 1e-2 * P * np.linalg.det(h)  # a real force to check
    t = 1e-6
    for k, (a, b) in enumerate(((0, 0), (0, 1), (1, 1))):
        E = np.zeros((2, 2))
        E[a, b] = t
        Gp, Gm = scipy.linalg.expm(E), scipy.linalg.expm(-E)
        dH = (H(x @ Gp.T, Gp @ h) - H(x @ Gm.T, Gm @ h)) / (2 * t)
        assert -dH == pytest.approx(Q[k], rel=1e-6, abs=1e-9 * P * np.linalg.det(h))
    # in the cell entries, fractional coordinates held
    s = np.linalg.solve(h, x.T).T
    A = np.linalg.det(h)
    S = np.array([[diag[5], diag[7]], [diag[7], diag[6]]])
    dHdh = -(S - P * A * np.eye(2)) @ np.linalg.inv(h).T
    for a, b in ((0, 0), (0, 1), (1, 1)):
        dh = np.zeros((2, 2))
        dh[a, b] = t * h[0, 0]
        fd = (H(s @ (h + dh).T, h + dh) - H(s @ (h - dh).T, h - dh)) / (2 * t * h[0, 0])
        assert dHdh[a, b] == pytest.approx(fd, rel=1e-6)
    # the net forces of the same kernel pass
    nl = find_neighbours_bruteforce(x, r, h, 0.0)
    eps = nl.overlaps(r)
    n = nl.branch / nl.distance[:, None]
    F = np.zeros_like(x)
    np.add.at(F, nl.i, -eps[:, None] * n)
    np.add.at(F, nl.j, eps[:, None] * n)
    assert np.allclose(f, F, rtol=0, atol=1e-12 * eps.max())


@pytest.mark.parametrize("a, b, c", [(1e-3, 2e-3, -5e-4), (0.3, -0.7, 0.3), (0.2, 0.5, 0.2 + 1e-9), (-0.4, 0.1, 0.6)])
def test_cell_drift_is_the_matrix_exponential(a, b, c):
    G = np.zeros((2, 2))
    _expm_upper(a, b, c, G)
    assert np.allclose(G, scipy.linalg.expm(np.array([[a, b], [0.0, c]])), rtol=1e-14, atol=1e-15)


def test_shape_packing_through_the_rve_materials(pair):
    """The sheared cell is a valid RVE: the Taylor RVE at F = 1 evaluates the packing's own
    contacts (across the tilted boundary), so its stress is -k_n sigma_virial = -k_n P I to
    force_tol; the relaxed RVE converges at F = 1 with a positive definite W_ww, and its stress
    (positions relaxed to round-off) stays isotropic to 10 force_tol (the residual forces of 1e-5
    <f> move the soft modes a little; at force_tol 1e-3 this shear stress was 1e-2 P)."""
    from gransim.rve import RelaxedMaterial, TaylorMaterial

    _, p = pair
    kn = 1e7
    P = kn * p.metadata["pressure_reduced"]  # N/m
    T = TaylorMaterial(p, kn).evaluate(np.eye(2)[None]).piola[0]
    assert np.allclose(T, -P * np.eye(2), rtol=0, atol=1.001 * TOL * P)
    R = RelaxedMaterial(p, kn)(np.eye(2))
    assert R.stable and R.n_held == 0
    assert np.allclose(R.piola, -P * np.eye(2), rtol=0, atol=10 * TOL * P)


def deviatoric_block(A):
    """D_a:A:D_b (2, 2) on the deviatoric plane, D_1 = sym(e1 x e2), D_2 = (e1 x e1 - e2 x e2)/2."""
    B = [np.array([[0.0, 0.5], [0.5, 0.0]]), np.array([[0.5, 0.0], [0.0, -0.5]])]
    M = np.array([[np.einsum("ij,ijkl,kl", a, A, b) for b in B] for a in B])
    return 0.5 * (M + M.T)


def test_shape_packing_is_an_enthalpy_minimum_hence_shear_stable(pair):
    """At a minimum of H = U + p A over the centres *and* the cell, the relaxed enthalpy
    H_rel(g) = V (W_rel(1 + g D) + p det(1 + g D)) has a minimum at g = 0 for every deviatoric D.
    With |D|^2 = 1/2, det(1 + g D) = 1 - g^2 / 4, so d^2 H_rel / dg^2 = V (D:A:D - p / 2) >= 0: the
    relaxed tangent on the deviatoric plane has no eigenvalue below p/2 (Dagois-Bohy et al., PRL
    109, 095703, 2012: shear-stabilised packings have G > 0). The square cell of the same seed is a
    minimum over the centres and the cell scale only and violates the bound (their instability)."""
    from gransim.rve import RelaxedMaterial

    kn = 1e7
    sq, sh = pair
    out = []
    for p in (sq, sh):
        R = RelaxedMaterial(p, kn)(np.eye(2))
        pressure = -0.5 * np.trace(R.piola)
        out.append(np.linalg.eigvalsh(deviatoric_block(np.asarray(R.tangent)))[0] / pressure)
    assert out[1] >= 0.5
    assert out[0] < 0.5


def test_shape_with_a_solid_fraction_target():
    # the solid-fraction path jams at JAMMING_OVERLAP first: the same stages as this request
    p = make_packing("quartz-sand", 60, seed=2, cell="shape", mean_overlap=JAMMING_OVERLAP)
    target = round(p.metadata["phi_jamming"] + 0.01, 4)
    q = make_packing("quartz-sand", 60, seed=2, cell="shape", solid_fraction=target)
    assert q.solid_fraction == pytest.approx(target, rel=1e-12)
    # compressed affinely from the jammed cell (the same shape) and relaxed at fixed cell
    assert q.cell / np.sqrt(q.area) == pytest.approx(p.cell / np.sqrt(p.area), rel=1e-12)
    _, F, eps = virial(q)
    assert np.max(np.linalg.norm(F, axis=1)) <= 1.001 * TOL * eps.mean()


def test_scale_default_is_the_shipped_standard_rve_bit_for_bit():
    shipped = load_packing(shipped_packing("rve-70-2"))
    fresh = make_packing("quartz-sand", 70, seed=2, cell="scale")
    for field in ("positions", "radii", "cell"):
        assert np.array_equal(getattr(shipped, field), getattr(fresh, field)), field


def test_unknown_cell_mode_is_refused():
    with pytest.raises(InputError, match=r"unknown cell 'foo'.*scale, shape"):
        make_packing("quartz-sand", 50, seed=1, cell="foo")
