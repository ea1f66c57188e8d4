"""The biaxial specimen: follower pressure (resultant, load stiffness), the homogeneous solution of a
uniform elastic specimen against its closed form, the residual's derivative, Newton's rate."""

import numpy as np
import pytest
from scipy.optimize import brentq

from gransim.errors import InputError
from gransim.fem import NeoHookean, lame
from gransim.fem.biaxial import BiaxialSpec, biaxial_setup, run_biaxial
from gransim.fem.incremental import PressureLoad, newton_step
from gransim.fem.isoparametric import rectangle
from gransim.fem.material_points import GaussPoints
from gransim.fem.point_laws import HyperelasticPoint, J2Plasticity

P = 1.0e5


def test_default_specimen_is_guo_and_zhaos():
    s = biaxial_setup()
    assert s.problem.mesh.element == "Q8" and s.problem.mesh.n_elements == 8 * 16
    assert s.spec.n_gauss == 512 and s.problem.n_gauss == 512
    X = s.problem.mesh.nodes
    assert X[:, 0].max() == 0.05 and X[:, 1].max() == 0.1
    assert np.array_equal(X[s.centre], [0.025, 0.0])
    # smooth platens: vertical dofs of the top and bottom rows, plus the bottom centre's horizontal
    assert s.problem.fixed.size == 2 * 17 + 1
    assert np.all(s.du_fixed[np.isin(s.problem.fixed, 2 * s.top + 1)] == -1e-4)
    assert np.count_nonzero(s.du_fixed) == 17


@pytest.mark.parametrize("element", ["Q8", "Q9"])
def test_pressure_resultant_is_pressure_times_side_length(element):
    spec = BiaxialSpec(element=element, gauss=3 if element == "Q9" else 2)
    s = biaxial_setup(spec)
    X = s.problem.mesh.nodes
    fl, fr = s.left.forces(X).sum(axis=0), s.right.forces(X).sum(axis=0)
    assert np.allclose(fl, [P * 0.1, 0.0], rtol=0, atol=1e-12 * P * 0.1)
    assert np.allclose(fr, [-P * 0.1, 0.0], rtol=0, atol=1e-12 * P * 0.1)
    # on a bulged, tilted side the resultant is p times the chord turned by a quarter (n ds integrated)
    rng = np.random.default_rng(3)
    x = X + 2e-3 * rng.standard_normal(X.shape)
    ends = s.left.edges[:, [0, -1]]
    start = x[np.setdiff1d(ends[:, 0], ends[:, 1])[0]]
    end = x[np.setdiff1d(ends[:, 1], ends[:, 0])[0]]
    chord = end - start
    assert np.allclose(s.left.forces(x).sum(axis=0), -P * np.array([chord[1], -chord[0]]), rtol=1e-12)
    # the edges' shape functions: a uniform pressure on a straight Q8 side gives the consistent nodal
    # forces 1/6, 2/3, 1/6 of p times the edge length
    f = s.left.forces(X)
    h = 0.1 / spec.ny
    e0 = s.left.edges[0]
    assert np.allclose(f[e0[1], 0], P * h * 2 / 3, rtol=1e-13)


def test_pressure_load_stiffness_is_exact():
    mesh = rectangle(2, 3, 1.0, 2.0, "Q8", distort=0.1, curve=0.05, seed=1)
    load = PressureLoad(mesh.edges_on(np.abs(mesh.nodes[:, 0] - 1.0) < 1e-12), 3.0)
    x = mesh.nodes + 0.05 * np.random.default_rng(0).standard_normal(mesh.nodes.shape)
    dx = 0.01 * np.random.default_rng(1).standard_normal(x.shape)
    K = load.stiffness(mesh.n_nodes)
    # the forces are linear in x: the difference equals K dx up to round-off
    assert np.allclose((load.forces(x + dx) - load.forces(x)).ravel(), K @ dx.ravel(), rtol=0, atol=1e-14)


def _plane_strain_neo_hookean_lateral_stretch(lam, mu, l2, p):
    """lambda_1 with sigma_xx(lambda_1, lambda_2) = -p for sigma = (mu (B - 1) + lam ln J 1) / J."""

    def sxx(l1):
        J = l1 * l2
        return (mu * (l1**2 - 1) + lam * np.log(J)) / J + p

    return brentq(sxx, 0.5, 2.0, xtol=1e-16, rtol=1e-15)


@pytest.mark.parametrize(("element", "gauss"), [("Q8", 2), ("Q9", 3)])
def test_uniform_elastic_specimen_is_homogeneous_and_matches_the_closed_form(element, gauss):
    lam, mu = lame(3e7, 0.3)
    spec = BiaxialSpec(nx=4, ny=8, element=element, gauss=gauss, steps=3, top_step=2e-3, tol=1e-12)
    s = biaxial_setup(spec)
    recs = run_biaxial(s, GaussPoints(HyperelasticPoint(NeoHookean(lam, mu)), spec.n_gauss))
    X = s.problem.mesh.nodes
    for r in recs:
        l2 = 1 - r.step * spec.top_step / spec.height
        l1 = _plane_strain_neo_hookean_lateral_stretch(lam, mu, l2, P)
        exact = np.column_stack([0.025 + l1 * (X[:, 0] - 0.025), l2 * X[:, 1]])
        assert np.abs(r.x - exact).max() < 1e-12 * 0.1
        assert np.abs(r.F - np.diag([l1, l2])).max() < 1e-11
        J = l1 * l2
        syy = (mu * (l2**2 - 1) + lam * np.log(J)) / J
        assert np.abs(r.stress[:, 0, 0] + P).max() < 1e-9 * P
        assert np.abs(r.stress[:, 1, 1] - syy).max() < 1e-9 * abs(syy)
        assert np.abs(r.stress[:, 0, 1]).max() < 1e-9 * P
        # the curves: platen force per width and the area
        assert r.deviatoric_stress == pytest.approx(-syy - P, rel=1e-9)
        assert r.axial_strain == pytest.approx(1 - l2, rel=1e-12)
        assert r.volumetric_strain == pytest.approx(J - 1, rel=1e-10)


def _j2(weak=(40, 41, 42, 43)):
    return J2Plasticity(1e8, 0.3, 1.5e5, 1e6, -1e5, weak_points=weak, weak_factor=0.8)


def test_tangent_is_the_derivative_of_the_residual():
    """K of an iterate (plastic states, follower pressure, geometric terms) against central
    differences of the residual; the trial states are reverted after each evaluation."""
    spec = BiaxialSpec(nx=2, ny=4, steps=2, top_step=1e-3)
    s = biaxial_setup(spec)
    pts = GaussPoints(_j2(weak=(5,)), spec.n_gauss)
    rec = run_biaxial(s, pts)[-1]
    prob = s.problem
    geom = prob.geometry(rec.x)
    rng = np.random.default_rng(2)
    du = 1e-3 * rng.standard_normal(prob.assembler.n_dofs)

    def evaluate(v, tangent):
        u = v.reshape(-1, 2)
        f = geom.deformation_gradient(u)
        sigma, T = pts.evaluate(f)
        pts.revert()
        return prob.residual(geom, rec.x, u, sigma, T, f, tangent)

    r, K, _ = evaluate(du, True)
    K = K.toarray()
    h = 1e-9
    fd = np.empty_like(K)
    for j in range(du.size):
        e = np.zeros_like(du)
        e[j] = h
        fd[:, j] = (evaluate(du + e, False)[0] - evaluate(du - e, False)[0]) / (2 * h)
    assert np.linalg.norm(fd - K) / np.linalg.norm(K) < 1e-6
    assert all(st.updates == 2 for st in pts.states())


def _orders(res):
    """Observed orders log(r_k+1 / r_k) / log(r_k / r_k-1) above 1e-13 of the force scale (round-off: 4e-14)."""
    r = np.asarray(res)
    r = r[r > 1e-13]
    return np.diff(np.log(r))[1:] / np.diff(np.log(r))[:-1]


class ScaledTangent(J2Plasticity):
    """The J2 law with its tangent 30 % too stiff: an inconsistent tangent."""

    def update(self, f, state):
        s, T, new = super().update(f, state)
        return s, 1.3 * T, new


def test_newton_converges_quadratically_with_the_consistent_tangent():
    spec = BiaxialSpec(nx=4, ny=8, steps=2, top_step=1e-3, tol=1e-13)
    s = biaxial_setup(spec)
    recs = run_biaxial(s, GaussPoints(_j2(), spec.n_gauss))
    for r in recs:
        o = _orders(r.residuals[1:])  # from the first evaluation on (the predictor uses the committed tangent)
        assert len(o) >= 1 and o[-2:].max() > 1.7, (r.residuals, o)  # the asymptotic rate: the last two
    # the same with a wrong tangent converges linearly (order ~1): the rate test can fail
    pts = GaussPoints(
        ScaledTangent(1e8, 0.3, 1.5e5, 1e6, -1e5, weak_points=(40, 41, 42, 43), weak_factor=0.8), spec.n_gauss
    )
    res = newton_step(s.problem, pts, s.problem.mesh.nodes, s.du_fixed, tol=1e-9, max_iter=60)
    o = _orders(res.residuals[1:])
    assert len(o) >= 2 and o[-2:].max() < 1.3, o


def test_spec_is_checked():
    with pytest.raises(InputError, match="hourglass"):
        BiaxialSpec(element="Q9", gauss=2)
    with pytest.raises(InputError, match="element"):
        BiaxialSpec(element="Q4")
    with pytest.raises(InputError, match="top_step"):
        BiaxialSpec(top_step=-1e-4)
