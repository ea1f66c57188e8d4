"""The periodic packing: disks in a periodic 2D cell."""

from __future__ import annotations

import dataclasses
import types
from dataclasses import dataclass, field

import numpy as np

from .._validate import as_array, as_positive_float
from ..errors import InputError
from .cell import cell_area, check_cell, wrap


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Packing:
    """Disks in a periodic 2D cell (immutable; arrays are read-only copies).

    Attributes
    ----------
    positions : (N, 2) float64
        Disk centres (m). May lie outside the primary cell.
    radii : (N,) float64
        Disk radii (m), all > 0.
    cell : (2, 2) float64
        Lattice vectors as columns (m); det > 0.
    density : float
        Mass per unit area of the disk material (kg/m^2), so m_i = density pi r_i^2
        (the 2D convention LIGGGHTS uses for ``dimension 2``).
    metadata : mapping
        Free-form description (distribution, seed, generator parameters...).

    Transforms (:meth:`deformed`, :meth:`wrapped`, :meth:`replace`) return new objects.
    """

    positions: np.ndarray
    radii: np.ndarray
    cell: np.ndarray
    density: float = 2650.0
    metadata: types.MappingProxyType = field(default_factory=dict)

    def __post_init__(self):
        pos = as_array(self.positions, "positions", (None, 2))
        n = pos.shape[0]
        rad = as_array(self.radii, "radii", (n,))
        if n < 2:
            raise InputError(f"positions: a packing needs at least 2 particles, got N = {n}")
        if np.any(rad <= 0):
            i = int(np.argmax(rad <= 0))
            raise InputError(f"radii: must be > 0, radius {i} is {rad[i]!r}")
        cell = check_cell(self.cell)
        dens = as_positive_float(self.density, "density")
        object.__setattr__(self, "positions", _frozen(pos))
        object.__setattr__(self, "radii", _frozen(rad))
        object.__setattr__(self, "cell", _frozen(cell))
        object.__setattr__(self, "density", dens)
        object.__setattr__(self, "metadata", types.MappingProxyType(dict(self.metadata)))

    # -- derived quantities -------------------------------------------------
    @property
    def n(self) -> int:
        """Number of disks N."""
        return self.positions.shape[0]

    @property
    def area(self) -> float:
        """Cell area det C (m^2)."""
        return cell_area(self.cell)

    @property
    def solid_area(self) -> float:
        """Sum of disk areas pi r^2 (m^2), overlaps not subtracted."""
        return float(np.pi * np.sum(self.radii**2))

    @property
    def solid_fraction(self) -> float:
        """Packing fraction phi = solid area / cell area (overlaps not subtracted)."""
        return self.solid_area / self.area

    @property
    def void_ratio(self) -> float:
        """Void ratio e = (1 - phi) / phi."""
        phi = self.solid_fraction
        return (1.0 - phi) / phi

    @property
    def masses(self) -> np.ndarray:
        """Disk masses m = density pi r^2 (kg), (N,)."""
        return self.density * np.pi * self.radii**2

    @property
    def d50(self) -> float:
        """Area-weighted median diameter (m): the 2D analogue of the weight-median D50."""
        d = np.sort(2 * self.radii)
        w = np.cumsum(d**2)
        return float(d[np.searchsorted(w, 0.5 * w[-1])])

    # -- transforms ---------------------------------------------------------
    def replace(self, **changes) -> Packing:
        """A copy with some fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def wrapped(self) -> Packing:
        """The same packing with every centre moved into the primary cell."""
        xw, _ = wrap(self.positions, self.cell)
        return self.replace(positions=xw)

    def deformed(self, F) -> Packing:
        """Affine (Taylor) map x = F X of every centre and of the cell, eq (1) of Meier et al."""
        F = as_array(F, "F", (2, 2))
        if np.linalg.det(F) <= 0:
            raise InputError(f"F: det F must be > 0, got {np.linalg.det(F):.6g}")
        return self.replace(positions=self.positions @ F.T, cell=F @ self.cell)

    def __repr__(self) -> str:
        return f"Packing(n={self.n}, cell={self.cell.tolist()}, phi={self.solid_fraction:.4f}, density={self.density})"
