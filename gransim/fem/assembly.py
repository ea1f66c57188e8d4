"""Sparse assembly with a precomputed pattern.

The COO triplets of all element matrices are mapped once to the slots of a CSR matrix; assembling
a new tangent is then one ``np.bincount`` of the element entries into ``K.data``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True, eq=False)
class Assembler:
    """Assembly of element vectors (E, n, 2) and matrices (E, 2n, 2n) for 2 dofs per node, n nodes
    per element (4 for the slope's Q1; 8 or 9 for :mod:`gransim.fem.isoparametric`).

    Global dof of node n, direction i: ``2 n + i``.
    """

    n_dofs: int
    element_dofs: np.ndarray  # (E, 2n)
    indptr: np.ndarray
    indices: np.ndarray
    slot: np.ndarray  # (E*4n^2,) CSR data position of each element entry

    @classmethod
    def from_elements(cls, elements: np.ndarray, n_nodes: int) -> Assembler:
        """Build the CSR pattern of a mesh's stiffness matrix."""
        elements = np.asarray(elements, dtype=np.int64)
        m = 2 * elements.shape[1]
        edofs = (2 * elements[:, :, None] + np.arange(2)[None, None, :]).reshape(-1, m)
        rows = np.repeat(edofs, m, axis=1).ravel()
        cols = np.tile(edofs, (1, m)).ravel()
        n = 2 * n_nodes
        key = rows * n + cols
        uniq, slot = np.unique(key, return_inverse=True)
        r, c = np.divmod(uniq, n)
        indptr = np.zeros(n + 1, dtype=np.int64)
        np.add.at(indptr, r + 1, 1)
        indptr = np.cumsum(indptr)
        return cls(n, edofs, indptr, c.astype(np.int64), slot.ravel())

    def vector(self, fe: np.ndarray) -> np.ndarray:
        """Global vector (n_dofs,) from element vectors (E, n, 2)."""
        return np.bincount(self.element_dofs.ravel(), weights=fe.ravel(), minlength=self.n_dofs)

    def matrix(self, Ke: np.ndarray) -> sp.csr_matrix:
        """Global CSR matrix from element matrices (E, 2n, 2n)."""
        data = np.bincount(self.slot, weights=Ke.ravel(), minlength=self.indices.size)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n_dofs, self.n_dofs))
