"""Newton's quadratic rate, the limit load of an SVK column (load cutting and the stop message), the
linear elastic limit against an independent small-strain FE code, rigid-footing kinematics."""

import numpy as np
import pytest
from fem_helpers import SMALL_SLOPE, linear_small_strain, make_continuum

from gransim.fem import DofMap, Problem, RigidBody, rectangle_mesh, run_load_steps
from gransim.fem.constraints import rotation
from gransim.fem.output import observed_orders
from gransim.fem.slope import setup_for, slope_problem


def test_newton_quadratic_on_reduced_slope():
    """Reduced slope, paper load on the neo-Hookean stand-in (large strains near the footing): every
    step converges to round-off and the observed order of the energy norm is near 2."""
    prob = slope_problem(make_continuum("neo-hookean"), setup_for("paper", SMALL_SLOPE, load_steps=5))
    res = run_load_steps(prob, setup_for("paper", SMALL_SLOPE, load_steps=5).schedule())
    assert res.completed
    for s in res.steps:
        e = s.energy_norms
        # converged: e <= 1e-20, or the residual reached round-off (the last e is then ~1e-12 or less)
        assert e[0] == 1.0 and e[-1] <= 1e-11
        assert len(e) <= 6
        p = observed_orders(e)
        # the last order is often limited by round-off; the ones before must be quadratic
        assert np.all(p[:-1] > 1.7) if len(p) > 1 else p[0] > 1.7


def _column(material, force, nx=2, ny=4, width=1.0, height=2.0):
    mesh = rectangle_mesh(nx, ny, width, height)
    X = mesh.nodes
    base = np.flatnonzero(X[:, 1] == 0)
    sides = np.flatnonzero(((X[:, 0] == 0) | (X[:, 0] == width)) & (X[:, 1] < height))
    top = np.flatnonzero(X[:, 1] == height)
    fixed = np.unique(np.concatenate([2 * base, 2 * base + 1, 2 * sides]))
    body = RigidBody(top, np.array([width / 2, height]), np.array([width / 2, height]))
    return Problem(mesh, material, DofMap.build(X, fixed, body), footing_force=(0.0, force))


def test_limit_load_of_svk_column_is_found_and_reported():
    """Uniaxial strain of St Venant-Kirchhoff: P_22 = (lam + 2 mu)/2 lam2 (lam2^2 - 1) has its
    compressive maximum -(lam + 2 mu)/(3 sqrt 3) at lam2 = 1/sqrt 3. Loading to 1.2 times that force,
    the stepper must cut the increment and stop between 1/1.2 - 1/64 and 1/1.2 of the load."""
    mat = make_continuum("svk")
    p_lim = (mat.lam + 2 * mat.mu) / (3 * np.sqrt(3))
    prob = _column(mat, -1.2 * p_lim * 1.0)
    res = run_load_steps(prob, [(0.0, 1.0)], min_fraction=1 / 64)
    assert not res.completed
    lam_f = res.limit["last_converged_load"][1]
    assert 1 / 1.2 - 1 / 64 - 1e-12 <= lam_f <= 1 / 1.2
    # the converged states below the limit are the analytic uniaxial-strain solution
    sol = res.limit["partial"]
    lam2 = sol.F[:, 1, 1]
    assert np.allclose(sol.F[:, 0, 0], 1.0) and np.allclose(sol.F[:, 0, 1], 0.0, atol=1e-12)
    P22 = 0.5 * (mat.lam + 2 * mat.mu) * lam2 * (lam2**2 - 1)
    assert np.allclose(P22, -1.2 * p_lim * lam_f, rtol=1e-10)
    assert res.limit["reason"]


def test_small_load_matches_independent_linear_elasticity(continuum):
    """At 1e-4 of the dead load, u equals the small-strain solution with C = A(F = 1), computed by an
    independent element loop (B matrices, dense solve); the difference shrinks linearly with the load."""
    setup = setup_for("service", SMALL_SLOPE)
    prob = slope_problem(continuum, setup)
    C = continuum.evaluate(np.eye(2)[None]).tangent[0]
    diffs = []
    for scale in (1e-4, 2e-4):
        q_lin = linear_small_strain(prob, C, scale)
        res = run_load_steps(prob, [(scale, 0.0)])
        q = res.steps[0].solution.q
        diffs.append(np.linalg.norm(q - q_lin) / np.linalg.norm(q_lin))
    assert diffs[0] < 1e-3
    assert diffs[1] / diffs[0] == pytest.approx(2.0, rel=0.05)  # O(load) geometric/material non-linearity


def test_rigid_footing_moves_rigidly_for_large_rotation():
    setup = setup_for("service", SMALL_SLOPE)
    prob = slope_problem(make_continuum("neo-hookean"), setup)
    dm = prob.dofs
    q = np.zeros(dm.n_reduced)
    q[-3:] = [0.3, -0.2, 0.4]
    u = dm.displacement(q)
    nodes = dm.body.nodes
    x = dm.X[nodes] + u[nodes]
    d0 = np.linalg.norm(dm.X[nodes][:, None] - dm.X[nodes][None], axis=-1)
    d1 = np.linalg.norm(x[:, None] - x[None], axis=-1)
    assert np.allclose(d0, d1, atol=1e-12)
    assert np.allclose(x - (dm.body.reference + q[-3:-1]), (dm.X[nodes] - dm.body.reference) @ rotation(0.4).T)
    # T = du/dq by central differences
    T = dm.jacobian(q).toarray()
    h = 1e-7
    for j in (0, dm.n_reduced - 3, dm.n_reduced - 1):
        e = np.zeros_like(q)
        e[j] = h
        fd = (dm.displacement(q + e) - dm.displacement(q - e)).ravel() / (2 * h)
        assert np.allclose(fd, T[:, j], atol=1e-8)


def test_dead_load_in_steps_reaches_the_single_step_state():
    """``dead_load_steps`` = K splits the dead load into K equal steps before the footing: the
    schedule holds k/K, and for a path-independent (hyperelastic) material the state at the full
    dead load is the single-step one (the same equilibrium, to Newton's tolerance); bad K refused."""
    from gransim.errors import InputError

    one = setup_for("service", SMALL_SLOPE, load_steps=2)
    three = setup_for("service", SMALL_SLOPE, load_steps=2, dead_load_steps=3)
    assert one.schedule() == [(1.0, 0.0), (1.0, 0.5), (1.0, 1.0)]
    assert three.schedule() == [(1 / 3, 0.0), (2 / 3, 0.0), (1.0, 0.0), (1.0, 0.5), (1.0, 1.0)]
    mat = make_continuum("neo-hookean")
    ra = run_load_steps(slope_problem(mat, one), one.schedule()[:1])
    rb = run_load_steps(slope_problem(mat, three), three.schedule()[:3])
    assert ra.completed and rb.completed and [s.load for s in rb.steps] == three.schedule()[:3]
    qa, qb = ra.steps[-1].solution.q, rb.steps[-1].solution.q
    assert np.linalg.norm(qb - qa) <= 1e-9 * np.linalg.norm(qa)
    # a third of the dead load is not the full one (the steps are really applied in turn)
    assert np.linalg.norm(rb.steps[0].solution.q - qa) > 0.5 * np.linalg.norm(qa)
    for bad in (0, -1, 1.5, True):
        with pytest.raises(InputError, match="dead_load_steps"):
            setup_for("service", SMALL_SLOPE, dead_load_steps=bad)
