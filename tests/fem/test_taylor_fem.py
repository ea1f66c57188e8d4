"""The FE solver with the real Taylor RVE material (gransim.rve) on small lattice RVEs."""

import numpy as np
import pytest
from fem_helpers import SMALL_SLOPE, linear_small_strain, triangular_packing

from gransim.fem import DofMap, NewtonFailure, Problem, newton, rectangle_mesh, run_load_steps
from gransim.fem.materials import AssignedRVEs
from gransim.fem.output import observed_orders
from gransim.fem.slope import limit_message, setup_for, slope_problem

rve = pytest.importorskip("gransim.rve")

E_N = 2.8e7


@pytest.fixture(scope="module")
def taylor():
    return rve.TaylorMaterial(triangular_packing(6, 6, swell=1.0005, jitter=0.02, seed=1), E_N)


def _patch(material, F0):
    mesh = rectangle_mesh(3, 3, 2.0, 1.0, distort=0.2, seed=5)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 2) | (X[:, 1] == 0) | (X[:, 1] == 1))
    dofs = np.concatenate([2 * bnd, 2 * bnd + 1])
    u = X @ (F0 - np.eye(2)).T
    return Problem(mesh, material, DofMap.build(X, dofs, values=u.ravel()[dofs])), u


def test_patch_test_reproduces_rve_stress(taylor):
    F0 = np.array([[0.995, 0.004], [-0.002, 0.990]])
    prob, u_exact = _patch(taylor, F0)
    sol = newton(prob, np.zeros(prob.dofs.n_reduced), (0.0, 0.0))
    assert np.allclose(sol.u, u_exact, atol=1e-13)
    P0 = taylor.evaluate(F0[None]).piola[0]
    assert np.allclose(sol.material.piola, P0, rtol=0, atol=1e-10 * np.abs(P0).max())
    r, *_ = prob.evaluate(sol.q, (0.0, 0.0), tangent=False)
    f = prob.assembler.vector(prob.geometry.internal_forces(sol.material.piola))
    assert np.abs(r).max() < 1e-12 * np.abs(f).max()


def test_all_contacts_open_gives_clear_singular_tangent_error(taylor):
    """Stretching the patch opens every contact: zero stress and tangent, Newton reports it."""
    prob, u = _patch(taylor, np.diag([1.1, 1.1]))
    prob = Problem(prob.mesh, taylor, prob.dofs, body_force=(0.0, -2.5e4))  # weight: r != 0
    assert np.all(taylor.evaluate(prob.geometry.deformation_gradient(u)).n_contacts == 0)
    with pytest.raises(NewtonFailure, match="singular tangent"):
        newton(prob, u.ravel()[prob.dofs.free], (1.0, 0.0))


def test_stiffness_is_derivative_of_residual(taylor):
    setup = setup_for("service", SMALL_SLOPE)
    prob = slope_problem(taylor, setup)
    rng = np.random.default_rng(4)
    q = 1e-3 * rng.standard_normal(prob.dofs.n_reduced)
    q[-1] = 1e-3
    load = (1.0, 0.5)
    _, K, *_ = prob.evaluate(q, load)
    K = K.toarray()
    h = 1e-8  # far below the distance to the next contact change at these states
    cols = np.arange(0, K.shape[1], 3).tolist() + [K.shape[1] - 1]
    for j in cols:
        e = np.zeros_like(q)
        e[j] = h
        fd = (prob.evaluate(q + e, load, tangent=False)[0] - prob.evaluate(q - e, load, tangent=False)[0]) / (2 * h)
        assert np.linalg.norm(fd - K[:, j]) < 1e-6 * np.linalg.norm(K[:, j])


def test_small_load_matches_linear_elasticity_with_rve_tangent(taylor):
    """A clamped box of the prestressed, anisotropic (jittered lattice) RVE material under 1e-3 of its
    weight: the uniform prestress P(1) is balanced by the walls (u = 0 at zero load), and u equals the
    linear solution with the full tangent A(F = 1) (geometric part included) from an independent
    element loop; the difference is second order in the load."""
    mesh = rectangle_mesh(4, 4, 4.0, 4.0, distort=0.15, seed=2)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 4) | (X[:, 1] == 0) | (X[:, 1] == 4))
    prob = Problem(
        mesh, taylor, DofMap.build(X, np.concatenate([2 * bnd, 2 * bnd + 1])), body_force=(0.0, -2.5e3 * 9.81)
    )
    res0 = run_load_steps(prob, [(0.0, 0.0)])
    assert np.abs(res0.steps[0].solution.q).max() < 1e-14
    A0 = taylor.evaluate(np.eye(2)[None]).tangent[0]
    diffs = []
    for scale in (1e-3, 2e-3):
        q_lin = linear_small_strain(prob, A0, scale)
        q = run_load_steps(prob, [(scale, 0.0)]).steps[0].solution.q
        diffs.append(np.linalg.norm(q - q_lin) / np.linalg.norm(q_lin))
    assert diffs[0] < 1e-5
    assert 1.5 < diffs[1] / diffs[0] < 2.5


def test_paper_load_on_reduced_slope_stops_at_crest_mechanism():
    """Two nearly perfect lattice RVEs assigned in turn; the paper load on the reduced slope: the
    crest loses its contacts, the footing load cannot be carried to the end, and the stop message
    names the last converged load and the contact-free Gauss points (which lie at the crest)."""
    mat = rve.TaylorMaterial([triangular_packing(5, 6, 1.0005, 0.0002, seed=s) for s in (1, 2)], E_N)
    setup = setup_for("paper", SMALL_SLOPE, load_steps=5)
    prob = slope_problem(AssignedRVEs(mat, np.arange(200) % 2), setup)
    res = run_load_steps(prob, setup.schedule(), min_fraction=1 / 16)
    assert len(res.steps) >= 3 and not res.completed
    for st in res.steps:  # every converged step converges quadratically (Taylor tangent is consistent)
        e = st.energy_norms
        assert e[-1] <= 1e-11 and len(e) <= 9
        if len(e) >= 4:
            assert max(observed_orders(e)[-2:]) > 1.6
    lam = res.limit["last_converged_load"][1]
    assert 0.5 < lam < 1.0
    msg = limit_message(prob, setup, res)
    assert f"footing {lam:.4f} of the target" in msg and "Gauss points without contacts" in msg
    last = res.limit["partial"] or res.steps[-1].solution
    free = np.flatnonzero(last.material.n_contacts == 0)
    assert free.size > 0
    xy = prob.geometry.points.reshape(-1, 2)[free]
    g = SMALL_SLOPE
    assert np.all((xy[:, 0] > g.toe_x) & (xy[:, 0] < setup.footing_right) & (xy[:, 1] > 0.5 * g.crest_height))


def test_prestress_release_does_not_change_the_answer():
    """Releasing the RVE prestress imbalance with the dead load is a continuation only: at full dead
    load the state equals the one reached by applying everything at once (when that converges)."""
    mat = rve.TaylorMaterial(triangular_packing(5, 6, 1.0005, 0.0002, seed=1), E_N)
    setup = setup_for("service", SMALL_SLOPE, load_steps=2)
    sols = []
    for release in (True, False):
        p = slope_problem(mat, setup)
        p = Problem(p.mesh, mat, p.dofs, p.body_force, p.footing_force, release_prestress=release)
        res = run_load_steps(p, setup.schedule())
        assert res.completed
        sols.append(res.steps[-1].solution.q)
    assert np.allclose(sols[0], sols[1], rtol=0, atol=1e-9 * np.abs(sols[0]).max())
