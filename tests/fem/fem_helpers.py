"""Shared helpers of the fem tests (imported as a plain module: tests/fem has no __init__)."""

import numpy as np

from gransim import Packing
from gransim.fem import NeoHookean, StVenantKirchhoff, lame
from gransim.fem.mesh import SlopeGeometry

#: A reduced slope (10 x 5 elements) with the same footing, slope and supports as the full one.
SMALL_SLOPE = SlopeGeometry(columns=10, rows=5)


def make_continuum(kind):
    """Neo-Hookean or St Venant-Kirchhoff with E = 3e7 Pa, nu = 0.3."""
    lam, mu = lame(3.0e7, 0.3)
    return NeoHookean(lam, mu) if kind == "neo-hookean" else StVenantKirchhoff(lam, mu)


def random_F(rng, n, scale=0.1):
    """Random deformation gradients near identity with det F > 0."""
    F = np.eye(2) + scale * rng.uniform(-1, 1, size=(n, 2, 2))
    assert np.all(np.linalg.det(F) > 0)
    return F


def triangular_packing(nx: int = 6, ny: int = 6, swell: float = 1.0005, jitter: float = 0.0, seed: int = 0) -> Packing:
    """Monodisperse triangular lattice (spacing 1 mm), radius 0.5 mm * swell: with swell > 1 every
    lattice neighbour overlaps by (swell - 1) * 1 mm. Isotropic small-strain response (6-fold)."""
    a = 1e-3
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    if jitter:
        x += np.random.default_rng(seed).uniform(-jitter, jitter, x.shape) * a
    return Packing(positions=x, radii=np.full(len(x), 0.5 * a * swell), cell=np.diag([nx * a, ny * h]))


def linear_small_strain(problem, A, gravity_scale):
    """Independent linearised Q1 solution (element loops, dense solve) of the problem's reduced system
    under ``gravity_scale`` times its body force, with a constant tangent A[i,J,k,L] (4th order, no
    symmetry assumed): sum_e int grad(v) : A : grad(u) dV = int v . b dV. Returns q (n_reduced,)."""
    mesh, dm = problem.mesh, problem.dofs
    D = np.asarray(A).reshape(4, 4)  # rows (i, J), columns (k, L)
    n = 2 * mesh.n_nodes
    K = np.zeros((n, n))
    f = np.zeros(n)
    g = 1 / np.sqrt(3)
    for el in mesh.elements:
        xe = mesh.nodes[el]
        for xi, eta in [(-g, -g), (g, -g), (g, g), (-g, g)]:
            dN = 0.25 * np.array(
                [[-(1 - eta), -(1 - xi)], [1 - eta, -(1 + xi)], [1 + eta, 1 + xi], [-(1 + eta), 1 - xi]]
            )
            N = 0.25 * np.array(
                [(1 - xi) * (1 - eta), (1 + xi) * (1 - eta), (1 + xi) * (1 + eta), (1 - xi) * (1 + eta)]
            )
            J = xe.T @ dN
            dNx = dN @ np.linalg.inv(J)
            Gm = np.zeros((4, 8))  # grad u components (1,1), (1,2), (2,1), (2,2) from nodal dofs
            Gm[0, 0::2] = dNx[:, 0]
            Gm[1, 0::2] = dNx[:, 1]
            Gm[2, 1::2] = dNx[:, 0]
            Gm[3, 1::2] = dNx[:, 1]
            dofs = np.ravel([[2 * a, 2 * a + 1] for a in el])
            K[np.ix_(dofs, dofs)] += Gm.T @ D @ Gm * np.linalg.det(J)
            f[dofs[0::2]] += N * problem.body_force[0] * np.linalg.det(J)
            f[dofs[1::2]] += N * problem.body_force[1] * np.linalg.det(J)
    T = dm.jacobian(np.zeros(dm.n_reduced)).toarray()  # rigid footing at theta = 0: the linear map
    return np.linalg.solve(T.T @ K @ T, T.T @ f * gravity_scale)
