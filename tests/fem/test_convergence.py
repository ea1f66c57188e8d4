"""Q1 mesh convergence against an exact linear-elastic solution (a convergence rate, not a single number).

Exact solution of the Navier equations (lam + mu) grad div u + mu lap u = 0 without body force:
u = a grad phi with the harmonic phi = exp(x) cos(y), i.e. u = a (exp(x) cos y, -exp(x) sin y)
(div u = lap phi = 0 and lap u = grad lap phi = 0, for any lam, mu). Its trace is prescribed on the
whole boundary of the unit square; the gransim FE machinery (Q1 element, assembly, Dirichlet dofs,
Newton) solves it on n x n meshes with a linear small-strain material. Errors are integrated here
with 4 x 4 Gauss points and shape functions written out in this file: the L2 displacement error
falls as h^2 and the energy-norm error as h^1 (the Q1 interpolation orders); the observed rates are
fitted over four meshes and must lie within 0.1 of those values.
"""

import numpy as np
import pytest

from gransim.fem import DofMap, MaterialResult, Problem, newton, rectangle_mesh

LAM, MU = 1.2e7, 0.8e7  # Pa
AMP = 1e-4  # m: small displacements, the linear theory is exact for the linear material below
_I = np.eye(2)
C4 = LAM * np.einsum("ij,kl->ijkl", _I, _I) + MU * (np.einsum("ik,jl->ijkl", _I, _I) + np.einsum("il,jk->ijkl", _I, _I))


class LinearElastic:
    """Small-strain isotropic elasticity as a batched material: P = C : sym(F - 1), A = C."""

    def evaluate(self, F):
        H = np.asarray(F) - _I
        eps = 0.5 * (H + np.swapaxes(H, 1, 2))
        P = np.einsum("ijkl,gkl->gij", C4, eps)
        A = np.broadcast_to(C4, (len(F), 2, 2, 2, 2)).copy()
        W = 0.5 * np.einsum("gij,gij->g", P, eps)
        return MaterialResult(P, A, P.copy(), W, np.full(len(F), -1))


def exact(x):
    """u (.., 2) and grad u (.., 2, 2) of the exact solution."""
    ex, c, s = np.exp(x[..., 0]), np.cos(x[..., 1]), np.sin(x[..., 1])
    u = AMP * np.stack([ex * c, -ex * s], axis=-1)
    grad = AMP * np.stack([np.stack([ex * c, -ex * s], -1), np.stack([-ex * s, -ex * c], -1)], -2)
    return u, grad


def errors(mesh, u_h):
    """(L2 error of u, energy-norm error sqrt(int (e_h - e) : C : (e_h - e))) with 4 x 4 Gauss points."""
    gp, gw = np.polynomial.legendre.leggauss(4)
    l2 = en = 0.0
    for el in mesh.elements:
        xe, ue = mesh.nodes[el], u_h[el]
        for xi, wx in zip(gp, gw):
            for eta, wy in zip(gp, gw):
                N = 0.25 * np.array(
                    [(1 - xi) * (1 - eta), (1 + xi) * (1 - eta), (1 + xi) * (1 + eta), (1 - xi) * (1 + eta)]
                )
                dN = 0.25 * np.array(
                    [[-(1 - eta), -(1 - xi)], [1 - eta, -(1 + xi)], [1 + eta, 1 + xi], [-(1 + eta), 1 - xi]]
                )
                J = xe.T @ dN
                w = wx * wy * np.linalg.det(J)
                dNx = dN @ np.linalg.inv(J)
                u_ex, g_ex = exact(N @ xe)
                d = N @ ue - u_ex
                gd = ue.T @ dNx - g_ex
                e = 0.5 * (gd + gd.T)
                l2 += w * d @ d
                en += w * np.einsum("ij,ijkl,kl->", e, C4, e)
    return np.sqrt(l2), np.sqrt(en)


def solve(n):
    mesh = rectangle_mesh(n, n, 1.0, 1.0)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 1) | (X[:, 1] == 0) | (X[:, 1] == 1))
    dofs = np.concatenate([2 * bnd, 2 * bnd + 1])
    u_b = exact(X)[0].ravel()
    prob = Problem(mesh, LinearElastic(), DofMap.build(X, dofs, values=u_b[dofs]))
    sol = newton(prob, np.zeros(prob.dofs.n_reduced), (0.0, 0.0))
    return mesh, sol.u


def test_q1_convergence_rates_on_an_exact_elastic_solution():
    ns = np.array([4, 8, 16, 32])
    errs = np.array([errors(*solve(n)) for n in ns])
    h = 1.0 / ns
    rate_l2 = np.polyfit(np.log(h), np.log(errs[:, 0]), 1)[0]
    rate_en = np.polyfit(np.log(h), np.log(errs[:, 1]), 1)[0]
    assert rate_l2 == pytest.approx(2.0, abs=0.1), errs
    assert rate_en == pytest.approx(1.0, abs=0.1), errs
    # and the error is a discretisation error, not noise: it falls monotonically
    assert np.all(np.diff(errs, axis=0) < 0)
