"""Total-Lagrangian bilinear quadrilateral (Q1) with 2 x 2 Gauss quadrature, vectorised over elements.

Kinematics (reference configuration X, displacement u, plane strain, unit thickness)::

    F = 1 + sum_a u_a (x) dN_a/dX                                   (per Gauss point)

Weak form and its linearisation (P first Piola stress, A = dP/dF with A[i,J,k,L] = dP_iJ/dF_kL)::

    f_int[a, i]      = sum_g w_g P_iJ dN_a/dX_J                      (N per m of thickness)
    K[a, i, b, k]    = sum_g w_g dN_a/dX_J A_iJkL dN_b/dX_L          (N/m per m of thickness)
    f_body[a, i]     = sum_g w_g N_a b0_i                            (b0: body force per reference volume)

``w_g`` is the Gauss weight times det(dX/dxi) (reference area, m^2). Arrays: E elements, G = 4 Gauss
points per element, 4 nodes per element; the flat Gauss point index is ``e * 4 + g``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from .mesh import Mesh

_XI_NODES = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
_GP = 1.0 / np.sqrt(3.0)
#: Gauss points in the parent square, ordered like the nodes (counter-clockwise from bottom-left).
XI_GAUSS = _GP * _XI_NODES
W_GAUSS = np.ones(4)


def shape_functions(xi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear shape functions N (n, 4) and their parent derivatives dN/dxi (n, 4, 2) at xi (n, 2)."""
    xi = np.atleast_2d(xi)
    a = 1.0 + xi[:, None, 0] * _XI_NODES[None, :, 0]
    b = 1.0 + xi[:, None, 1] * _XI_NODES[None, :, 1]
    N = 0.25 * a * b
    dN = np.stack([0.25 * _XI_NODES[None, :, 0] * b, 0.25 * a * _XI_NODES[None, :, 1]], axis=-1)
    return N, dN


@dataclass(frozen=True, eq=False)
class Q1Geometry:
    """Reference-configuration quantities of every element at its 4 Gauss points.

    Attributes
    ----------
    dNdX : (E, 4, 4, 2)
        dN_a/dX_J at Gauss point g of element e: ``dNdX[e, g, a, J]`` (1/m).
    weight : (E, 4)
        Quadrature weight times det J (m^2); ``weight.sum()`` is the mesh area.
    N : (4, 4)
        Shape function values ``N[g, a]``.
    points : (E, 4, 2)
        Gauss point positions in the reference configuration (m).
    elements : (E, 4)
        Connectivity (copied from the mesh).
    """

    dNdX: np.ndarray
    weight: np.ndarray
    N: np.ndarray
    points: np.ndarray
    elements: np.ndarray

    @classmethod
    def from_mesh(cls, mesh: Mesh) -> Q1Geometry:
        """Precompute the reference gradients; raises InputError for an inverted element."""
        N, dNdxi = shape_functions(XI_GAUSS)  # (4 g, 4 a), (4 g, 4 a, 2)
        Xe = mesh.nodes[mesh.elements]  # (E, 4 a, 2)
        J = np.einsum("eaI,gaj->egIj", Xe, dNdxi)  # dX_I/dxi_j
        detJ = np.linalg.det(J)
        if np.any(detJ <= 0):
            e = int(np.argwhere(detJ <= 0)[0, 0])
            raise InputError(f"mesh: element {e} has a non-positive Jacobian at a Gauss point")
        Jinv = np.linalg.inv(J)  # dxi_j/dX_I
        dNdX = np.einsum("gaj,egjI->egaI", dNdxi, Jinv)
        points = np.einsum("ga,eaI->egI", N, Xe)
        return cls(np.ascontiguousarray(dNdX), detJ * W_GAUSS[None, :], N, points, np.asarray(mesh.elements))

    @property
    def n_gauss(self) -> int:
        """Total number of Gauss points 4 E."""
        return self.weight.size

    def deformation_gradient(self, u: np.ndarray) -> np.ndarray:
        """F at every Gauss point, (4E, 2, 2), from nodal displacements u (Nn, 2)."""
        ue = u[self.elements]  # (E, 4, 2)
        F = np.einsum("eai,egaJ->egiJ", ue, self.dNdX)
        F[..., 0, 0] += 1.0
        F[..., 1, 1] += 1.0
        return F.reshape(-1, 2, 2)

    def internal_forces(self, P: np.ndarray) -> np.ndarray:
        """Element internal force vectors (E, 4, 2) from the Piola stress P (4E, 2, 2)."""
        P = P.reshape(-1, 4, 2, 2) * self.weight[:, :, None, None]
        # f_ai = sum_g w_g P_iJ dN_a/dX_J: one batched matmul (G, a, J) @ (G, J, i), summed over g
        return np.matmul(self.dNdX, np.swapaxes(P, 2, 3)).sum(axis=1)

    def stiffness(self, A: np.ndarray) -> np.ndarray:
        """Element stiffness matrices (E, 8, 8), dof order (a, i) -> 2a + i, from A (4E, 2, 2, 2, 2)."""
        E = self.elements.shape[0]
        G = 4 * E
        # K_e = sum_g w_g B_g^T D_g B_g with D = A as a 4 x 4 matrix (rows iJ, columns kL) and
        # B[(i, J), (a, k)] = delta_ik dN_a/dX_J (grad u from the element dofs): batched matmuls
        dN = np.swapaxes(self.dNdX.reshape(G, 4, 2), 1, 2)  # (G, J, a)
        B = np.zeros((G, 2, 2, 4, 2))
        B[:, 0, :, :, 0] = dN
        B[:, 1, :, :, 1] = dN
        B = B.reshape(G, 4, 8)
        D = np.asarray(A).reshape(G, 4, 4)
        K = np.matmul(np.swapaxes(B, 1, 2) * self.weight.reshape(G, 1, 1), np.matmul(D, B))
        return K.reshape(E, 4, 8, 8).sum(axis=1)

    def body_forces(self, b0) -> np.ndarray:
        """Consistent nodal body forces (E, 4, 2) for a constant b0 (2,) per reference volume (N/m^3)."""
        b0 = np.asarray(b0, dtype=float)
        return np.einsum("eg,ga,i->eai", self.weight, self.N, b0)
