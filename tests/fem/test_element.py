"""Q1 element: shape functions, patch tests, consistent stiffness (finite differences)."""

import numpy as np
import pytest
from fem_helpers import SMALL_SLOPE

from gransim.errors import InputError
from gransim.fem import DofMap, Mesh, Problem, Q1Geometry, newton, rectangle_mesh
from gransim.fem.element import shape_functions
from gransim.fem.slope import setup_for, slope_problem


def test_shape_functions_partition_of_unity():
    xi = np.random.default_rng(0).uniform(-1, 1, size=(20, 2))
    N, dN = shape_functions(xi)
    assert np.allclose(N.sum(axis=1), 1.0)
    assert np.allclose(dN.sum(axis=1), 0.0)
    # nodal interpolation reproduces a linear field exactly
    nodes = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], float)
    f = nodes @ [0.3, -1.7] + 2.0
    assert np.allclose(N @ f, xi @ [0.3, -1.7] + 2.0)


def test_geometry_area_and_linear_gradients():
    mesh = rectangle_mesh(4, 3, 2.0, 1.5, distort=0.2, seed=3)
    geom = Q1Geometry.from_mesh(mesh)
    assert geom.weight.sum() == pytest.approx(3.0, rel=1e-13)
    # an affine displacement field gives the exact constant gradient at every Gauss point
    H = np.array([[0.1, -0.05], [0.2, 0.03]])
    F = geom.deformation_gradient(mesh.nodes @ H.T)
    assert np.allclose(F, np.eye(2) + H, atol=1e-14)


def _patch(material, F0):
    mesh = rectangle_mesh(3, 3, 1.0, 1.0, distort=0.2, seed=7)
    X = mesh.nodes
    boundary = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 1) | (X[:, 1] == 0) | (X[:, 1] == 1))
    dofs = np.concatenate([2 * boundary, 2 * boundary + 1])
    u_exact = X @ (F0 - np.eye(2)).T
    dm = DofMap.build(X, dofs, values=u_exact.ravel()[dofs])
    return Problem(mesh, material, dm), u_exact, boundary


def test_patch_test_homogeneous_deformation(continuum):
    """Boundary nodes on an affine field; Newton from zero recovers the field, P(F0) at every Gauss point
    and zero interior residual, on distorted elements."""
    F0 = np.array([[1.08, 0.12], [-0.05, 0.93]])
    prob, u_exact, _ = _patch(continuum, F0)
    sol = newton(prob, np.zeros(prob.dofs.n_reduced), (0.0, 0.0))
    assert np.allclose(sol.u, u_exact, atol=1e-12)
    P0 = continuum.evaluate(F0[None]).piola[0]
    assert np.allclose(sol.material.piola, P0, rtol=0, atol=1e-9 * np.abs(P0).max())
    r, *_ = prob.evaluate(sol.q, (0.0, 0.0), tangent=False)
    # interior residual vs the size of the nodal forces: round-off only
    f = prob.assembler.vector(prob.geometry.internal_forces(sol.material.piola))
    assert np.abs(r).max() < 1e-12 * np.abs(f).max()


@pytest.mark.parametrize("with_footing_rotation", [0.0, 0.2])
def test_stiffness_is_derivative_of_residual(continuum, with_footing_rotation):
    """Reduced tangent (element, assembly, rigid footing with finite rotation, lever-arm load) equals the
    central difference of the reduced residual to 1e-6 relative."""
    setup = setup_for("paper", SMALL_SLOPE)
    prob = slope_problem(continuum, setup)
    rng = np.random.default_rng(11)
    q = 0.05 * rng.standard_normal(prob.dofs.n_reduced)
    q[-1] = with_footing_rotation
    load = (1.0, 0.7)
    _, K, *_ = prob.evaluate(q, load)
    K = K.toarray()
    h = 1e-6
    fd = np.empty_like(K)
    for j in range(K.shape[1]):
        e = np.zeros_like(q)
        e[j] = h
        fd[:, j] = (prob.evaluate(q + e, load, tangent=False)[0] - prob.evaluate(q - e, load, tangent=False)[0]) / (
            2 * h
        )
    err = np.linalg.norm(fd - K, axis=0) / np.linalg.norm(K, axis=0)
    assert err.max() < 1e-6


def test_bad_mesh_inputs():
    with pytest.raises(InputError, match="counter-clockwise"):
        Mesh(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float), np.array([[0, 3, 2, 1]]))
    with pytest.raises(InputError, match="node indices"):
        Mesh(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float), np.array([[0, 1, 2, 4]]))
    with pytest.raises(InputError, match="values"):
        DofMap.build(np.zeros((4, 2)), [0, 1], values=[0.0])
