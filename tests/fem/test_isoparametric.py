"""Q4, Q8 and Q9 isoparametric elements: Gauss rule exactness, shape functions against their closed
forms, the patch test on curved elements, residual vs stiffness by finite differences, and the
convergence rates against Timoshenko's closed-form cantilever."""

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from gransim.errors import InputError
from gransim.fem import Q1Geometry, rectangle_mesh
from gransim.fem.assembly import Assembler
from gransim.fem.isoparametric import (
    QuadGeometry,
    QuadMesh,
    edge_shape_functions,
    parent_nodes,
    rectangle,
    shape_functions,
)
from gransim.fem.quadrature import gauss_legendre, square_rule

# ---------------------------------------------------------------------- quadrature


@pytest.mark.parametrize("n", [1, 2, 3, 4, 5])
def test_gauss_legendre_exact_to_degree_2n_minus_1_and_not_beyond(n):
    x, w = gauss_legendre(n)
    for k in range(2 * n):
        exact = 2.0 / (k + 1) if k % 2 == 0 else 0.0
        assert abs(w @ x**k - exact) < 1e-14
    k = 2 * n  # the first degree the rule misses: its error is far above round-off
    assert abs(w @ x**k - 2.0 / (k + 1)) > 1e-3


@pytest.mark.parametrize("n", [2, 3])
def test_square_rule_exact_for_tensor_monomials(n):
    r = square_rule(n)
    assert r.size == n * n and abs(r.weights.sum() - 4.0) < 1e-14
    xi, eta = r.points.T
    for a in range(2 * n):
        for b in range(2 * n):
            exact = (2.0 / (a + 1) if a % 2 == 0 else 0.0) * (2.0 / (b + 1) if b % 2 == 0 else 0.0)
            assert abs(r.weights @ (xi**a * eta**b) - exact) < 1e-14
    # degree 2n in one variable is not integrated exactly
    assert abs(r.weights @ xi ** (2 * n) - 2 * 2.0 / (2 * n + 1)) > 1e-3


def test_rule_size_checked():
    with pytest.raises(InputError, match="Gauss points per direction"):
        square_rule(0)


# ---------------------------------------------------------------------- shape functions


def _closed_form(element, xi):
    """Zienkiewicz & Taylor's closed forms (eqs 8.21-8.23), written out independently."""
    x, y = xi[:, 0:1], xi[:, 1:2]
    nodes = parent_nodes(element)
    xa, ya = nodes[None, :, 0], nodes[None, :, 1]
    if element == "Q4":
        return 0.25 * (1 + x * xa) * (1 + y * ya)
    if element == "Q8":
        corner = 0.25 * (1 + x * xa) * (1 + y * ya) * (x * xa + y * ya - 1)
        mid_x = 0.5 * (1 - x**2) * (1 + y * ya)  # xi_a = 0
        mid_y = 0.5 * (1 + x * xa) * (1 - y**2)  # eta_a = 0
        return np.where((xa != 0) & (ya != 0), corner, np.where(xa == 0, mid_x, mid_y))

    def lag(s, sa):
        return np.where(sa < 0, s * (s - 1) / 2, np.where(sa > 0, s * (s + 1) / 2, 1 - s**2))

    return lag(x, xa) * lag(y, ya)


@pytest.mark.parametrize("element", ["Q4", "Q8", "Q9"])
def test_shape_functions_closed_form_kronecker_and_derivatives(element):
    rng = np.random.default_rng(1)
    xi = rng.uniform(-1, 1, (30, 2))
    N, dN = shape_functions(element, xi)
    assert np.abs(N - _closed_form(element, xi)).max() < 1e-14
    nodes = parent_nodes(element)
    assert np.abs(shape_functions(element, nodes)[0] - np.eye(len(nodes))).max() < 1e-14
    assert np.abs(N.sum(axis=1) - 1).max() < 1e-14
    h = 1e-6
    for j in range(2):
        e = np.zeros(2)
        e[j] = h
        fd = (shape_functions(element, xi + e)[0] - shape_functions(element, xi - e)[0]) / (2 * h)
        assert np.abs(fd - dN[:, :, j]).max() < 1e-9


def test_edge_shape_functions_interpolate_quadratics():
    s = np.linspace(-1, 1, 7)
    for m, nodes in ((2, np.array([-1.0, 1.0])), (3, np.array([-1.0, 0.0, 1.0]))):
        N, dN = edge_shape_functions(m, s)
        f = 0.3 + 1.7 * nodes + (0.9 * nodes**2 if m == 3 else 0)
        assert np.allclose(N @ f, 0.3 + 1.7 * s + (0.9 * s**2 if m == 3 else 0), atol=1e-14)
        assert np.allclose(dN @ f, 1.7 + (1.8 * s if m == 3 else 0), atol=1e-14)


# ---------------------------------------------------------------------- meshes and geometry


@pytest.mark.parametrize("element", ["Q4", "Q8", "Q9"])
def test_rectangle_mesh_counts_and_area(element):
    m = rectangle(3, 2, 1.5, 1.0, element, distort=0.15, curve=0.1, seed=2)
    nodes = {"Q4": 4 * 3, "Q8": 7 * 5 - 6, "Q9": 7 * 5}[element]
    assert m.n_nodes == nodes and m.n_elements == 6
    geom = QuadGeometry.from_mesh(m, 3)
    # interior edges move but the boundary stays straight: the area is exact (3x3 integrates the
    # isoparametric Jacobian exactly: degree <= 3 per direction for Q8, Q9)
    assert geom.weight.sum() == pytest.approx(1.5, rel=1e-13)


def test_inverted_element_is_refused():
    m = rectangle(1, 1, element="Q8")
    nodes = m.nodes.copy()
    nodes[[0, 1]] = nodes[[1, 0]]
    with pytest.raises(InputError, match="element 0"):
        QuadGeometry.from_mesh(m.with_nodes(nodes))


def test_q4_geometry_equals_the_slope_q1_element():
    """Independent implementations: the generic element with Q4 and 2x2 Gauss against Q1Geometry."""
    mesh = rectangle_mesh(3, 2, 2.0, 1.0, distort=0.2, seed=4)
    q1 = Q1Geometry.from_mesh(mesh)
    q4 = QuadGeometry.from_mesh(QuadMesh(mesh.nodes, mesh.elements, "Q4"), 2)
    rng = np.random.default_rng(0)
    u = 0.05 * rng.standard_normal(mesh.nodes.shape)
    F = q1.deformation_gradient(u)
    # Q1 orders its Gauss points like its nodes (counter-clockwise), the square rule row by row
    perm = [0, 1, 3, 2]
    F4 = q4.deformation_gradient(u).reshape(-1, 4, 2, 2)[:, perm].reshape(-1, 2, 2)
    assert np.abs(F - F4).max() < 1e-14
    P = rng.standard_normal(F.shape)
    A = rng.standard_normal((len(F), 2, 2, 2, 2))
    inv = np.argsort(perm)  # per-point arrays in Q1 order -> square-rule order

    def to_q4(a):
        return a.reshape(-1, 4, *a.shape[1:])[:, inv].reshape(a.shape)

    assert np.abs(q1.internal_forces(P) - q4.internal_forces(to_q4(P))).max() < 1e-13
    assert np.abs(q1.stiffness(A) - q4.stiffness(to_q4(A))).max() < 1e-12
    assert np.abs(q1.weight - q4.weight[:, perm]).max() < 1e-15


# ---------------------------------------------------------------------- linear elasticity helpers


def elastic_tangent(lam, mu):
    """A_iJkL = lam d_iJ d_kL + mu (d_ik d_JL + d_iL d_Jk): the small-strain isotropic tangent."""
    d = np.eye(2)
    return lam * np.einsum("ij,kl->ijkl", d, d) + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))


def solve_linear(mesh, rule, C, fixed_dofs, values):
    """Linear elastic K u = 0 with prescribed dofs: u (Nn, 2)."""
    geom = QuadGeometry.from_mesh(mesh, rule)
    asm = Assembler.from_elements(mesh.elements, mesh.n_nodes)
    K = asm.matrix(geom.stiffness(np.broadcast_to(C, (geom.n_gauss, 2, 2, 2, 2)))).tocsc()
    u = np.zeros(asm.n_dofs)
    u[fixed_dofs] = values
    free = np.setdiff1d(np.arange(asm.n_dofs), fixed_dofs)
    rhs = -(K[free][:, fixed_dofs] @ u[fixed_dofs])
    u[free] = spla.spsolve(K[free][:, free].tocsc(), rhs)
    return u.reshape(-1, 2), geom


def boundary_dofs(mesh, x0, x1, y0, y1):
    X = mesh.nodes
    on = np.isclose(X[:, 0], x0) | np.isclose(X[:, 0], x1) | np.isclose(X[:, 1], y0) | np.isclose(X[:, 1], y1)
    b = np.flatnonzero(on)
    return np.sort(np.concatenate([2 * b, 2 * b + 1]))


CASES = [("Q8", 2), ("Q8", 3), ("Q9", 3)]


@pytest.mark.parametrize(("element", "n"), CASES)
def test_linear_patch_test_on_curved_elements(element, n):
    """A linear displacement field on the boundary of a patch of distorted, curved elements is
    reproduced exactly inside, with the exact constant stress at every Gauss point."""
    mesh = rectangle(3, 3, 1.0, 1.0, element, distort=0.15, curve=0.08, seed=7)
    C = elastic_tangent(1.3e7, 0.9e7)
    H = np.array([[0.011, -0.007], [0.004, 0.013]])
    exact = mesh.nodes @ H.T + np.array([0.002, -0.001])
    dofs = boundary_dofs(mesh, 0, 1, 0, 1)
    u, geom = solve_linear(mesh, n, C, dofs, exact.ravel()[dofs])
    assert np.abs(u - exact).max() < 1e-13 * np.abs(exact).max() * 100
    grad = geom.deformation_gradient(u) - np.eye(2)
    assert np.abs(grad - H).max() < 1e-12 * np.abs(H).max() * 100


@pytest.mark.parametrize(("element", "n"), CASES)
def test_nonlinear_patch_test(element, n, continuum):
    """Finite-strain patch test: boundary nodes on an affine field, Newton with the hyperelastic
    material recovers it inside (P(F0) everywhere, zero interior residual)."""
    mesh = rectangle(3, 3, 1.0, 1.0, element, distort=0.15, curve=0.08, seed=3)
    geom = QuadGeometry.from_mesh(mesh, n)
    asm = Assembler.from_elements(mesh.elements, mesh.n_nodes)
    F0 = np.array([[1.08, 0.12], [-0.05, 0.93]])
    exact = mesh.nodes @ (F0 - np.eye(2)).T
    dofs = boundary_dofs(mesh, 0, 1, 0, 1)
    free = np.setdiff1d(np.arange(asm.n_dofs), dofs)
    u = np.zeros(asm.n_dofs)
    for t in (0.25, 0.5, 0.75, 1.0):  # boundary values in four increments, Newton in each
        u[dofs] = t * exact.ravel()[dofs]
        for _ in range(12):
            m = continuum.evaluate(geom.deformation_gradient(u.reshape(-1, 2)))
            r = asm.vector(geom.internal_forces(m.piola))
            if np.abs(r[free]).max() < 1e-12 * np.abs(asm.vector(np.abs(geom.internal_forces(m.piola)))).max():
                break
            K = asm.matrix(geom.stiffness(m.tangent)).tocsc()
            u[free] -= spla.spsolve(K[free][:, free].tocsc(), r[free])
    assert np.abs(u.reshape(-1, 2) - exact).max() < 1e-11
    P0 = continuum.evaluate(F0[None]).piola[0]
    assert np.abs(m.piola - P0).max() < 1e-9 * np.abs(P0).max()


@pytest.mark.parametrize(("element", "n"), CASES)
def test_stiffness_is_derivative_of_residual(element, n, continuum):
    """The assembled tangent equals the central difference of the assembled internal forces."""
    mesh = rectangle(2, 1, 1.0, 0.6, element, distort=0.1, curve=0.05, seed=9)
    geom = QuadGeometry.from_mesh(mesh, n)
    asm = Assembler.from_elements(mesh.elements, mesh.n_nodes)
    rng = np.random.default_rng(5)
    u = 0.03 * rng.standard_normal(asm.n_dofs)

    def res(v):
        return asm.vector(geom.internal_forces(continuum.evaluate(geom.deformation_gradient(v.reshape(-1, 2))).piola))

    K = asm.matrix(geom.stiffness(continuum.evaluate(geom.deformation_gradient(u.reshape(-1, 2))).tangent)).toarray()
    h = 1e-6
    fd = np.empty_like(K)
    for j in range(asm.n_dofs):
        e = np.zeros_like(u)
        e[j] = h
        fd[:, j] = (res(u + e) - res(u - e)) / (2 * h)
    assert np.linalg.norm(fd - K) / np.linalg.norm(K) < 1e-7
    # a wrong tangent is seen: 1% off in one Gauss point's tangent
    A = continuum.evaluate(geom.deformation_gradient(u.reshape(-1, 2))).tangent.copy()
    A[0] *= 1.01
    K_bad = asm.matrix(geom.stiffness(A)).toarray()
    assert np.linalg.norm(fd - K_bad) / np.linalg.norm(K) > 1e-4


def test_spurious_zero_energy_modes():
    """Free-free 2 x 2 meshes: Q8 with 2 x 2 Gauss points (Guo & Zhao's element) and Q9 with 3 x 3 have
    only the 3 rigid-body modes; Q9 with 2 x 2 has communicable spurious (hourglass) modes, so it is not
    offered for the biaxial specimen."""
    C = elastic_tangent(1.0, 1.0)

    def zero_modes(element, n):
        mesh = rectangle(2, 2, element=element)
        geom = QuadGeometry.from_mesh(mesh, n)
        asm = Assembler.from_elements(mesh.elements, mesh.n_nodes)
        K = asm.matrix(geom.stiffness(np.broadcast_to(C, (geom.n_gauss, 2, 2, 2, 2)))).toarray()
        ev = np.linalg.eigvalsh(0.5 * (K + K.T))
        return int(np.sum(np.abs(ev) < 1e-10 * ev.max()))

    assert zero_modes("Q8", 2) == 3
    assert zero_modes("Q8", 3) == 3
    assert zero_modes("Q9", 3) == 3
    assert zero_modes("Q9", 2) > 3


# ---------------------------------------------------------------------- convergence


def timoshenko_cantilever(X, P=1e3, L=4.0, D=1.0, E=1e8, nu=0.3):
    """Plane-stress cantilever under an end shear P (N/m) with a parabolic traction at x = 0, clamped
    in Timoshenko's sense at x = L (Timoshenko & Goodier, Theory of Elasticity, 1951, section 21;
    written as in Augarde & Deeks, Finite Elem. Anal. Des. 44 (2008) 595-601, eqs 2-3). A cubic
    displacement field, outside the Q8 and Q9 spaces. Checked symbolically: it satisfies
    equilibrium with sigma_xx = -P (L - x) y / I, sigma_yy = 0, tau_xy = P (D^2/4 - y^2) / (2 I)."""
    x, y = X[:, 0], X[:, 1]
    I = D**3 / 12
    ux = -P * y / (6 * E * I) * ((6 * L - 3 * x) * x + (2 + nu) * (y**2 - D**2 / 4))
    uy = P / (6 * E * I) * (3 * nu * y**2 * (L - x) + (4 + 5 * nu) * D**2 * x / 4 + (3 * L - x) * x**2)
    return np.stack([ux, uy], axis=1)


def _l2_error(mesh, u, exact_fn):
    """Relative L2 error of the FE displacement against the closed form (7 x 7 Gauss points per element)."""
    g = QuadGeometry.from_mesh(mesh, 7)
    uh = g.interpolate(u)
    ue = exact_fn(g.points.reshape(-1, 2))
    w = g.weight.ravel()
    return float(np.sqrt(w @ np.sum((uh - ue) ** 2, axis=1) / (w @ np.sum(ue**2, axis=1))))


@pytest.mark.parametrize(("element", "n", "rate"), [("Q8", 2, 3), ("Q8", 3, 3), ("Q9", 3, 3), ("Q4", 2, 2)])
def test_displacement_error_converges_at_order_h3(element, n, rate):
    """Timoshenko's cantilever with its exact displacement on the whole boundary: the relative L2
    displacement error falls as h^3 for Q8 and Q9 (h^2 for Q4, showing the test tells them apart)."""
    E, nu, L, D = 1e8, 0.3, 4.0, 1.0
    C = elastic_tangent(E * nu / (1 - nu**2), E / (2 * (1 + nu)))  # plane stress

    def exact(X):
        return timoshenko_cantilever(X, L=L, D=D, E=E, nu=nu)

    errors, hs = [], []
    for k in (1, 2, 4, 8):
        mesh = rectangle(4 * k, k, L, D, element, origin=(0.0, -D / 2))
        dofs = boundary_dofs(mesh, 0, L, -D / 2, D / 2)
        u, _ = solve_linear(mesh, n, C, dofs, exact(mesh.nodes).ravel()[dofs])
        errors.append(_l2_error(mesh, u, exact))
        hs.append(D / k)
    orders = np.diff(np.log(errors)) / np.diff(np.log(hs))
    assert orders[-1] == pytest.approx(rate, abs=0.25), (errors, orders)
    assert np.all(orders > rate - 0.35)
