"""Constraints: fixed displacement components and a rigid, massless footing.

The unknowns of the solver are the reduced coordinates q = [free nodal dofs, rigid-body dofs]. A
rigid body moves the nodes s attached to it by a translation c = (c_x, c_y) and a finite rotation
theta about the reference point X_c::

    u_s(q) = c + (R(theta) - 1) (X_s - X_c),     R(theta) = [[cos, -sin], [sin, cos]].

The map is exact for large rotations, so the reduced residual r = T^T (f_int - f_ext) - Q and the
reduced tangent K_q = T^T K T + sum_s (f_int - f_ext)_s . d^2 u_s / d theta^2 - dQ/dq (T = du/dq)
stay consistent and Newton keeps its quadratic rate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InputError


def rotation(theta: float) -> np.ndarray:
    """R(theta) (2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[c, -s], [s, c]])


def rotation_d1(theta: float) -> np.ndarray:
    """dR/dtheta (2, 2)."""
    c, s = np.cos(theta), np.sin(theta)
    return np.array([[-s, -c], [c, -s]])


@dataclass(frozen=True)
class RigidBody:
    """Nodes that move rigidly with a reference point X_c (m); a point load acts at ``load_point``."""

    nodes: np.ndarray
    reference: np.ndarray
    load_point: np.ndarray


@dataclass(frozen=True, eq=False)
class DofMap:
    """Reduced coordinates for fixed dofs (value 0) and at most one rigid body.

    Attributes
    ----------
    n_full : int
        2 Nn nodal dofs.
    free : (nf,) int
        Full dof index of each free reduced coordinate q[:nf].
    body : RigidBody or None
        q[nf:nf+3] = (c_x, c_y, theta) when present.
    """

    n_full: int
    free: np.ndarray
    body: RigidBody | None
    X: np.ndarray
    prescribed: np.ndarray

    @classmethod
    def build(cls, nodes: np.ndarray, fixed_dofs, body: RigidBody | None = None, values=None) -> DofMap:
        """Free dofs = all dofs not fixed and not on the rigid body.

        ``values`` (same length as ``fixed_dofs``, m) are the prescribed displacements of the fixed
        dofs (default 0); they are applied in full from the first iteration on.
        """
        n_full = 2 * len(nodes)
        fixed_dofs = np.asarray(fixed_dofs, dtype=np.int64)
        if fixed_dofs.size and (fixed_dofs.min() < 0 or fixed_dofs.max() >= n_full):
            raise InputError(f"fixed_dofs: indices must lie in [0, {n_full})")
        prescribed = np.zeros(n_full)
        if values is not None:
            values = np.asarray(values, dtype=float)
            if values.shape != fixed_dofs.shape:
                raise InputError(f"values: expected shape {fixed_dofs.shape} (one per fixed dof), got {values.shape}")
            prescribed[fixed_dofs] = values
        fixed = np.zeros(n_full, dtype=bool)
        fixed[fixed_dofs] = True
        if body is not None:
            slave = np.zeros(n_full, dtype=bool)
            slave[2 * body.nodes] = slave[2 * body.nodes + 1] = True
            if np.any(slave & fixed):
                raise InputError("constraints: a rigid-body node also has a fixed dof")
            fixed |= slave
        return cls(n_full, np.flatnonzero(~fixed), body, np.asarray(nodes, dtype=float), prescribed)

    @property
    def n_reduced(self) -> int:
        """Number of unknowns q."""
        return self.free.size + (3 if self.body is not None else 0)

    def displacement(self, q: np.ndarray) -> np.ndarray:
        """Nodal displacements u (Nn, 2) from q."""
        u = self.prescribed.copy()
        nf = self.free.size
        u[self.free] = q[:nf]
        u = u.reshape(-1, 2)
        if self.body is not None:
            c, th = q[nf : nf + 2], q[nf + 2]
            d = self.X[self.body.nodes] - self.body.reference
            u[self.body.nodes] = c + d @ (rotation(th) - np.eye(2)).T
        return u

    def body_point_displacement(self, q: np.ndarray, point) -> np.ndarray:
        """Displacement (2,) of a point rigidly attached to the body."""
        nf = self.free.size
        d = np.asarray(point, dtype=float) - self.body.reference
        return q[nf : nf + 2] + (rotation(q[nf + 2]) - np.eye(2)) @ d

    def jacobian(self, q: np.ndarray) -> sp.csr_matrix:
        """T = du/dq (n_full, n_reduced), sparse."""
        nf = self.free.size
        rows = [self.free]
        cols = [np.arange(nf)]
        vals = [np.ones(nf)]
        if self.body is not None:
            nodes = self.body.nodes
            d = self.X[nodes] - self.body.reference
            dth = d @ rotation_d1(q[nf + 2]).T  # (ns, 2)
            for i in range(2):
                rows += [2 * nodes + i, 2 * nodes + i]
                cols += [np.full(nodes.size, nf + i), np.full(nodes.size, nf + 2)]
                vals += [np.ones(nodes.size), dth[:, i]]
        return sp.csr_matrix(
            (np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(self.n_full, self.n_reduced)
        )

    def rotation_curvature(self, q: np.ndarray, r_full: np.ndarray) -> float:
        """sum_s r_s . d^2 u_s / dtheta^2 with d^2 u_s/dtheta^2 = -R(theta) (X_s - X_c)."""
        nf = self.free.size
        nodes = self.body.nodes
        d = self.X[nodes] - self.body.reference
        d2 = -d @ rotation(q[nf + 2]).T
        return float(np.sum(r_full.reshape(-1, 2)[nodes] * d2))

    def point_load(self, q: np.ndarray, force) -> tuple[np.ndarray, np.ndarray]:
        """Generalised force Q (n_reduced,) of a fixed-direction force (2,) at the body's load point,
        and its derivative dQ/dtheta (n_reduced,) (the load stiffness of a rotating lever arm)."""
        nf = self.free.size
        force = np.asarray(force, dtype=float)
        d = self.body.load_point - self.body.reference
        th = q[nf + 2]
        Q = np.zeros(self.n_reduced)
        dQ = np.zeros(self.n_reduced)
        Q[nf : nf + 2] = force
        Q[nf + 2] = force @ (rotation_d1(th) @ d)
        dQ[nf + 2] = force @ (-rotation(th) @ d)
        return Q, dQ
