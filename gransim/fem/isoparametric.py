"""Isoparametric quadrilaterals Q4, Q8 (serendipity) and Q9 (Lagrange) with any n x n Gauss rule.

Beside the slope's Q1 (:mod:`gransim.fem.element`, kept as it is), for the quadratic elements of the
FEM x DEM biaxial test (Guo & Zhao, Int. J. Numer. Meth. Engng 99 (2014) 789-818: 8-node
quadrilaterals with 2 x 2 Gauss points, escript/finley ``Rectangle(order=2, integrationOrder=2)``).

Parent nodes (node order of finley and of Zienkiewicz & Taylor, The Finite Element Method vol. 1,
2000, section 8.6): corners counter-clockwise from (-1, -1) (0-3), then the midsides bottom, right,
top, left (4-7), then the centre (8, Q9 only). Shape functions (Zienkiewicz & Taylor eqs 8.21-8.23)::

    Q4: N_a = (1 + xi xi_a)(1 + eta eta_a) / 4
    Q8: corners N_a = (1 + xi xi_a)(1 + eta eta_a)(xi xi_a + eta eta_a - 1) / 4,
        midsides N_a = (1 - xi^2)(1 + eta eta_a) / 2 (xi_a = 0), (1 + xi xi_a)(1 - eta^2) / 2 (eta_a = 0)
    Q9: N_a = l_i(xi) l_j(eta), l_-1 = s(s - 1)/2, l_0 = 1 - s^2, l_1 = s(s + 1)/2

Here every element's N is built the same way, as the nodal (Kronecker) basis of its monomial space
(Q4 {1, xi, eta, xi eta}; Q8 adds xi^2, eta^2, xi^2 eta, xi eta^2; Q9 adds xi^2 eta^2), by inverting the
Vandermonde matrix of the parent nodes; tests/fem/test_isoparametric.py checks it against the closed
forms above.

Kinematics and weak form are those of :mod:`gransim.fem.element` for any node count n and Gauss
rule with G points per element (F = 1 + sum_a u_a (x) dN_a/dX, f_int = sum_g w_g P dN/dX,
K = sum_g w_g dN/dX . A . dN/dX; A[i,J,k,L] = dP_iJ/dF_kL). Arrays: E elements, G points per
element, n nodes per element; the flat Gauss point index is ``e * G + g``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, as_positive_float
from ..errors import InputError
from .quadrature import SquareRule, square_rule

_CORNERS = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
_MIDS = [(0, -1), (1, 0), (0, 1), (-1, 0)]
_PARENT = {
    "Q4": np.array(_CORNERS, float),
    "Q8": np.array(_CORNERS + _MIDS, float),
    "Q9": np.array([*_CORNERS, *_MIDS, (0, 0)], float),
}
#: exponents (a, b) of the monomials xi^a eta^b spanning each element's shape functions
_MONOMIALS = {
    "Q4": [(0, 0), (1, 0), (0, 1), (1, 1)],
    "Q8": [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (2, 1), (1, 2)],
    "Q9": [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2), (2, 1), (1, 2), (2, 2)],
}
ELEMENTS = tuple(_PARENT)
#: local node triples (start corner, midside, end corner) of the four edges, counter-clockwise
EDGES = ((0, 4, 1), (1, 5, 2), (2, 6, 3), (3, 7, 0))


def parent_nodes(element: str) -> np.ndarray:
    """Parent coordinates (n, 2) of the element's nodes."""
    if element not in _PARENT:
        raise InputError(f"element: unknown element {element!r}; choose one of {', '.join(ELEMENTS)}")
    return _PARENT[element]


def _monomials(xi: np.ndarray, exps) -> tuple[np.ndarray, np.ndarray]:
    """Monomials (p, m) and their derivatives (p, m, 2) at xi (p, 2)."""
    x, y = xi[:, 0:1], xi[:, 1:2]
    a = np.array([e[0] for e in exps], float)[None]
    b = np.array([e[1] for e in exps], float)[None]
    M = x**a * y**b
    dx = np.where(a > 0, a * x ** np.maximum(a - 1, 0), 0.0) * y**b
    dy = x**a * np.where(b > 0, b * y ** np.maximum(b - 1, 0), 0.0)
    return M, np.stack([dx, dy], axis=-1)


def shape_functions(element: str, xi) -> tuple[np.ndarray, np.ndarray]:
    """N (p, n) and dN/dxi (p, n, 2) of ``element`` at parent points xi (p, 2)."""
    nodes = parent_nodes(element)
    exps = _MONOMIALS[element]
    xi = np.atleast_2d(np.asarray(xi, dtype=float))
    V, _ = _monomials(nodes, exps)  # V[a, m]: monomial m at node a
    C = np.linalg.inv(V)  # N_a = sum_m M_m C[m, a]
    M, dM = _monomials(xi, exps)
    return M @ C, np.einsum("pmj,ma->paj", dM, C)


@dataclass(frozen=True, eq=False)
class QuadMesh:
    """A mesh of one isoparametric quadrilateral type in the reference configuration.

    Attributes
    ----------
    nodes : (Nn, 2) float64
        Reference coordinates X (m).
    elements : (E, n) int64
        Node indices per element in the parent order of the module docstring.
    element : str
        ``Q4``, ``Q8`` or ``Q9``.
    """

    nodes: np.ndarray
    elements: np.ndarray
    element: str

    def __post_init__(self):
        n = parent_nodes(self.element).shape[0]
        nodes = as_array(self.nodes, "nodes", (None, 2))
        elements = as_array(self.elements, "elements", (None, n), dtype=np.int64)
        if elements.size and (elements.min() < 0 or elements.max() >= nodes.shape[0]):
            raise InputError(f"elements: node indices must lie in [0, {nodes.shape[0]})")
        for name, a in (("nodes", nodes), ("elements", elements)):
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @property
    def n_nodes(self) -> int:
        """Number of nodes Nn."""
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        """Number of elements E."""
        return self.elements.shape[0]

    def with_nodes(self, nodes) -> QuadMesh:
        """The same connectivity on other node positions (e.g. the configuration of a load step)."""
        return QuadMesh(np.asarray(nodes, dtype=float), self.elements, self.element)

    def edges_on(self, mask) -> np.ndarray:
        """Element edges (k, 2 or 3) whose nodes all satisfy ``mask`` (Nn,) bool: (start, [mid,] end)
        counter-clockwise around their element, so the outward normal is to the right of start -> end."""
        mask = np.asarray(mask, dtype=bool)
        local = [e if self.element != "Q4" else (e[0], e[2]) for e in EDGES]
        out = [self.elements[:, list(t)] for t in local]
        cand = np.concatenate(out)
        return cand[np.all(mask[cand], axis=1)]


def rectangle(
    nx: int,
    ny: int,
    lx: float = 1.0,
    ly: float = 1.0,
    element: str = "Q8",
    origin=(0.0, 0.0),
    distort: float = 0.0,
    curve: float = 0.0,
    seed: int = 0,
) -> QuadMesh:
    """A structured nx x ny mesh of [x0, x0 + lx] x [y0, y0 + ly].

    Nodes lie on the (2 nx + 1) x (2 ny + 1) grid (Q4: (nx + 1) x (ny + 1)), numbered row by row from
    the bottom; Q8 omits the element centres. ``distort`` moves the interior corner nodes randomly
    by up to that fraction of the smaller element size; midside nodes then sit at their edge's
    midpoint, moved off it by up to ``curve`` of the element size (curved edges, interior edges
    only); the Q9 centre sits at the mean of its element's corners. Both keep the mesh valid for
    fractions below ~0.2 and exercise non-affine isoparametric maps (patch tests).
    """
    parent_nodes(element)
    nx, ny = int(nx), int(ny)
    if nx < 1 or ny < 1:
        raise InputError(f"nx, ny: need at least one element each way, got {nx}, {ny}")
    lx = as_positive_float(lx, "lx")
    ly = as_positive_float(ly, "ly")
    rng = np.random.default_rng(seed)
    h = min(lx / nx, ly / ny)
    if element == "Q4":
        X, Y = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1))
        P = np.stack([X, Y], axis=-1)
        if distort:
            P[1:-1, 1:-1] += distort * h * rng.uniform(-1, 1, P[1:-1, 1:-1].shape)
        idx = np.arange((nx + 1) * (ny + 1)).reshape(ny + 1, nx + 1)
        j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
        el = np.stack([idx[j, i], idx[j, i + 1], idx[j + 1, i + 1], idx[j + 1, i]], axis=-1).reshape(-1, 4)
        return QuadMesh(P.reshape(-1, 2) + np.asarray(origin, float), el, element)
    mx, my = 2 * nx + 1, 2 * ny + 1
    X, Y = np.meshgrid(np.linspace(0, lx, mx), np.linspace(0, ly, my))
    P = np.stack([X, Y], axis=-1)  # P[row, col]
    if distort:
        inner = P[2:-2:2, 2:-2:2]
        P[2:-2:2, 2:-2:2] = inner + distort * h * rng.uniform(-1, 1, inner.shape)
    # midsides at their edge's midpoint (then curved), centres at the mean of the corners
    P[::2, 1::2] = 0.5 * (P[::2, 0:-1:2] + P[::2, 2::2])
    P[1::2, ::2] = 0.5 * (P[0:-1:2, ::2] + P[2::2, ::2])
    P[1::2, 1::2] = 0.25 * (P[0:-1:2, 0:-1:2] + P[0:-1:2, 2::2] + P[2::2, 0:-1:2] + P[2::2, 2::2])
    if curve:
        for sl in ((slice(2, -2, 2), slice(1, None, 2)), (slice(1, None, 2), slice(2, -2, 2))):
            sub = P[sl]
            P[sl] = sub + curve * h * rng.uniform(-1, 1, sub.shape)
    keep = np.ones((my, mx), dtype=bool)
    if element == "Q8":
        keep[1::2, 1::2] = False
    number = np.full((my, mx), -1, dtype=np.int64)
    number[keep] = np.arange(int(keep.sum()))
    j, i = np.meshgrid(np.arange(ny), np.arange(nx), indexing="ij")
    r, c = 2 * j.ravel(), 2 * i.ravel()
    local = [(0, 0), (0, 2), (2, 2), (2, 0), (0, 1), (1, 2), (2, 1), (1, 0), (1, 1)]  # (d_row, d_col)
    n = parent_nodes(element).shape[0]
    el = np.stack([number[r + dr, c + dc] for dr, dc in local[:n]], axis=1)
    return QuadMesh(P[keep] + np.asarray(origin, float), el, element)


@dataclass(frozen=True, eq=False)
class QuadGeometry:
    """Reference-configuration quantities of every element at its Gauss points.

    Attributes
    ----------
    dNdX : (E, G, n, 2)
        dN_a/dX_J at Gauss point g of element e (1/m).
    weight : (E, G)
        Gauss weight times det(dX/dxi) (m^2); ``weight.sum()`` is the mesh area.
    N : (G, n)
        Shape function values at the Gauss points.
    points : (E, G, 2)
        Gauss point positions (m).
    elements : (E, n)
        Connectivity.
    rule : SquareRule
    """

    dNdX: np.ndarray
    weight: np.ndarray
    N: np.ndarray
    points: np.ndarray
    elements: np.ndarray
    rule: SquareRule

    @classmethod
    def from_mesh(cls, mesh: QuadMesh, rule: SquareRule | int = 2) -> QuadGeometry:
        """Reference gradients at an n x n Gauss rule (``rule``: a SquareRule or n); raises
        InputError naming the element when det(dX/dxi) <= 0 at one of its Gauss points."""
        rule = rule if isinstance(rule, SquareRule) else square_rule(rule)
        N, dNdxi = shape_functions(mesh.element, rule.points)  # (G, n), (G, n, 2)
        Xe = mesh.nodes[mesh.elements]  # (E, n, 2)
        J = np.einsum("eaI,gaj->egIj", Xe, dNdxi)
        detJ = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        if np.any(detJ <= 0):
            e = int(np.argwhere(detJ <= 0)[0, 0])
            raise InputError(f"mesh: element {e} is inverted or degenerate (det dX/dxi <= 0 at a Gauss point)")
        Jinv = np.linalg.inv(J)
        dNdX = np.einsum("gaj,egjI->egaI", dNdxi, Jinv)
        points = np.einsum("ga,eaI->egI", N, Xe)
        return cls(np.ascontiguousarray(dNdX), detJ * rule.weights[None, :], N, points, mesh.elements, rule)

    @property
    def n_gauss(self) -> int:
        """Total number of Gauss points E G."""
        return self.weight.size

    @property
    def nodes_per_element(self) -> int:
        """n."""
        return self.elements.shape[1]

    def deformation_gradient(self, u: np.ndarray) -> np.ndarray:
        """F = 1 + grad u at every Gauss point, (E G, 2, 2), from nodal displacements u (Nn, 2)."""
        F = np.einsum("eai,egaJ->egiJ", u[self.elements], self.dNdX)
        F[..., 0, 0] += 1.0
        F[..., 1, 1] += 1.0
        return F.reshape(-1, 2, 2)

    def interpolate(self, v: np.ndarray) -> np.ndarray:
        """Nodal values v (Nn, k) at the Gauss points: (E G, k)."""
        return np.einsum("ga,eak->egk", self.N, v[self.elements]).reshape(-1, v.shape[1])

    def internal_forces(self, P: np.ndarray) -> np.ndarray:
        """Element internal forces (E, n, 2) from the first Piola stress P (E G, 2, 2)."""
        E, G = self.weight.shape
        P = P.reshape(E, G, 2, 2) * self.weight[:, :, None, None]
        return np.matmul(self.dNdX, np.swapaxes(P, 2, 3)).sum(axis=1)

    def stiffness(self, A: np.ndarray) -> np.ndarray:
        """Element matrices (E, 2n, 2n), dof order (a, i) -> 2a + i, from A (E G, 2, 2, 2, 2)."""
        E, G = self.weight.shape
        n = self.nodes_per_element
        Gt = E * G
        dN = np.swapaxes(self.dNdX.reshape(Gt, n, 2), 1, 2)  # (Gt, J, a)
        B = np.zeros((Gt, 2, 2, n, 2))
        B[:, 0, :, :, 0] = dN
        B[:, 1, :, :, 1] = dN
        B = B.reshape(Gt, 4, 2 * n)
        D = np.asarray(A).reshape(Gt, 4, 4)
        K = np.matmul(np.swapaxes(B, 1, 2) * self.weight.reshape(Gt, 1, 1), np.matmul(D, B))
        return K.reshape(E, G, 2 * n, 2 * n).sum(axis=1)

    def body_forces(self, b0: np.ndarray) -> np.ndarray:
        """Consistent nodal forces (E, n, 2) of a body force per reference volume b0 (N/m^3): a
        constant (2,) or one value per Gauss point (E G, 2)."""
        b0 = np.asarray(b0, dtype=float)
        E, G = self.weight.shape
        b = np.broadcast_to(b0, (E * G, 2)).reshape(E, G, 2)
        return np.einsum("eg,ga,egi->eai", self.weight, self.N, b)


def edge_shape_functions(n_edge_nodes: int, s) -> tuple[np.ndarray, np.ndarray]:
    """1D Lagrange shape functions on [-1, 1] (p, m) and d/ds (p, m) for edges of 2 (start, end) or
    3 (start, mid, end) nodes."""
    s = np.asarray(s, dtype=float)[:, None]
    if n_edge_nodes == 2:
        return np.hstack([(1 - s) / 2, (1 + s) / 2]), np.hstack([-0.5 + 0 * s, 0.5 + 0 * s])
    if n_edge_nodes == 3:
        N = np.hstack([s * (s - 1) / 2, 1 - s**2, s * (s + 1) / 2])
        dN = np.hstack([s - 0.5, -2 * s, s + 0.5])
        return N, dN
    raise InputError(f"edge nodes: expected 2 or 3, got {n_edge_nodes}")
