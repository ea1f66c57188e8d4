"""The input of the void-cell analysis: a frozen snapshot of particle centres, contacts, motion.

Built from native DEM HDF5 output (:func:`gransim.voidcell.io.load_run_snapshots` reads the DEM
schema of docs/schema_dem.md), from parsed LIGGGHTS dumps, or from LAMMPS dumps (the simple-shear
validation builds the native and the LAMMPS snapshots the same way).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_choice
from ..errors import InputError
from ..geometry.cell import check_cell

#: what the ``velocities`` field holds
MOTIONS = ("velocity", "displacement")


def _frozen(a):
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class Snapshot:
    """Particle centres, contacts and particle motion at one instant (immutable).

    Attributes
    ----------
    positions : (N, 2) float64
        Particle centres x_k (m); need not lie in the primary cell.
    cell : (2, 2) float64
        Periodic cell C, columns = lattice vectors (m), det C > 0.
    contacts_i, contacts_j : (M,) int64
        Contacting particles, 0 <= i, j < N.
    contacts_shift : (M, 2) int64
        Image shift n of the contact: particle i touches the image x_j + C n, so the branch
        vector (graph edge) is l_ij = x_j + C n - x_i (the convention of
        :func:`gransim.contacts.find_neighbours` and of the DEM schema).
    velocities : (N, 2) float64
        Particle velocities v_k (m/s) when ``motion == "velocity"``; displacement increments
        u_k (m) when ``motion == "displacement"`` (then every gradient computed from the
        snapshot is a displacement-gradient increment, dimensionless, instead of a velocity
        gradient in 1/s).
    cell_velocity : (2, 2) float64
        Rate of the cell, dC/dt (m/s) (or its increment C1 - C0 for displacements). The image
        x_j + C n moves with v_j + (dC/dt) n. Default zero (a fixed cell).
    radii : (N,) float64 or None
        Particle radii (m); only needed for D50 in the relative motion of eq (21).
    motion : {"velocity", "displacement"}
    """

    positions: np.ndarray
    cell: np.ndarray
    contacts_i: np.ndarray
    contacts_j: np.ndarray
    contacts_shift: np.ndarray
    velocities: np.ndarray
    cell_velocity: np.ndarray | None = None
    radii: np.ndarray | None = None
    motion: str = "velocity"

    def __post_init__(self):
        x = as_array(self.positions, "positions", (None, 2))
        n = x.shape[0]
        C = check_cell(self.cell)
        ci = as_array(self.contacts_i, "contacts_i", (None,), dtype=np.int64)
        m = ci.shape[0]
        cj = as_array(self.contacts_j, "contacts_j", (m,), dtype=np.int64)
        cs = as_array(
            np.reshape(self.contacts_shift, (-1, 2)) if np.size(self.contacts_shift) == 0 else self.contacts_shift,
            "contacts_shift",
            (m, 2),
            dtype=np.int64,
        )
        for name, idx in (("contacts_i", ci), ("contacts_j", cj)):
            bad = np.flatnonzero((idx < 0) | (idx >= n))
            if bad.size:
                k = int(bad[0])
                raise InputError(
                    f"{name}: contact {k} refers to missing particle {int(idx[k])} "
                    f"(valid indices 0..{n - 1}; {bad.size} such contacts)"
                )
        selfc = np.flatnonzero((ci == cj) & np.all(cs == 0, axis=1))
        if selfc.size:
            k = int(selfc[0])
            raise InputError(f"contacts: contact {k} joins particle {int(ci[k])} to itself with zero image shift")
        v = as_array(self.velocities, "velocities", (n, 2))
        Cd = np.zeros((2, 2)) if self.cell_velocity is None else as_array(self.cell_velocity, "cell_velocity", (2, 2))
        r = None
        if self.radii is not None:
            r = as_array(self.radii, "radii", (n,))
            if np.any(r <= 0):
                raise InputError(f"radii: must be > 0, radius {int(np.argmax(r <= 0))} is {r[np.argmax(r <= 0)]!r}")
        check_choice(self.motion, "motion", MOTIONS)
        for name, val in (
            ("positions", x),
            ("cell", C),
            ("contacts_i", ci),
            ("contacts_j", cj),
            ("contacts_shift", cs),
            ("velocities", v),
            ("cell_velocity", Cd),
            ("radii", r),
        ):
            object.__setattr__(self, name, None if val is None else _frozen(val))

    @property
    def n_particles(self) -> int:
        """N."""
        return self.positions.shape[0]

    @property
    def n_contacts(self) -> int:
        """M (contacts as given, before pruning)."""
        return self.contacts_i.shape[0]

    @property
    def imposed_gradient(self) -> np.ndarray:
        """The cell's velocity gradient (dC/dt) C^{-1} (1/s), (2, 2) (an increment for
        displacements)."""
        return self.cell_velocity @ np.linalg.inv(self.cell)

    def replace(self, **changes) -> Snapshot:
        """A copy with fields replaced (validated again)."""
        return dataclasses.replace(self, **changes)

    def with_displacements_to(self, positions, cell) -> Snapshot:
        """The same graph with motion = displacement increments to a later state.

        ``positions`` (N, 2) and ``cell`` (2, 2) describe the later state; particles may have been
        wrapped differently between the two. The displacement is taken through fractional
        coordinates s = C^{-1} x with the nearest-image convention, Delta s = s1 - s0 -
        round(s1 - s0), u = C1 (s0 + Delta s) - C0 s0, valid while every particle moves less
        than half a cell between the states. The cell increment C1 - C0 becomes
        ``cell_velocity``.
        """
        x1 = as_array(positions, "positions", (self.n_particles, 2))
        C1 = check_cell(cell)
        C0 = self.cell
        s0 = np.linalg.solve(C0, self.positions.T).T
        s1 = np.linalg.solve(C1, x1.T).T
        ds = s1 - s0
        ds -= np.round(ds)
        u = (s0 + ds) @ C1.T - self.positions
        return self.replace(velocities=u, cell_velocity=C1 - C0, motion="displacement")

    def __repr__(self) -> str:
        return f"Snapshot(N={self.n_particles}, M={self.n_contacts}, motion={self.motion!r})"
