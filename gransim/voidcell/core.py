"""The void-cell analysis as a compute object: ``VoidCells(...).compute(snapshot)``."""

from __future__ import annotations

import numpy as np

from .._validate import as_positive_float, check_choice
from ..errors import GransimError, InputError
from .dcel import DCEL, build_dcel
from .graph import ParticleGraph, build_graph
from .measures import (
    alignment,
    assembly_average,
    d50_area_weighted,
    face_gradients,
    halfedge_velocities,
    normalised_vorticity,
    relative_motion,
    relative_motion_undefined,
)
from .snapshot import Snapshot

#: choices of the reference gradient Lbar in eqs (18)-(21)
REFERENCES = ("cells", "cell")


class NotComputedError(GransimError, AttributeError):
    """A result of a compute object was read before ``compute()``."""


class VoidCells:
    """Kuhn's void-cell deformation measures of one snapshot (002, secs 2-4).

    Parameters
    ----------
    reference : {"cells", "cell"}
        The average gradient Lbar of eqs (18)-(21): "cells" = the area-weighted mean of the cells,
        eq (3) (default); "cell" = the imposed gradient of the periodic cell, (dC/dt) C^{-1}. For
        a valid framework on the torus both are equal (a test checks it) except for round-off.
    check_crossings : bool
        Run the explicit O(E) crossing test of the contact lines (default True).
    d50 : float, optional
        D50 (m) for eq (21); default: area-weighted median of the snapshot's radii.

    Results (after :meth:`compute`; reading them earlier raises :class:`NotComputedError`):
    ``graph``, ``dcel``, ``face_area`` (F,), ``valence`` (F,), ``L`` (F, 2, 2), ``L_mean`` (2, 2),
    ``alpha`` (F,), ``w`` (F,), ``v_rel`` (N, 2), counts and :meth:`summary`.
    """

    def __init__(self, reference: str = "cells", check_crossings: bool = True, d50=None):
        self.reference = check_choice(reference, "reference", REFERENCES)
        self.check_crossings = bool(check_crossings)
        self.d50 = None if d50 is None else as_positive_float(d50, "d50")
        self._r = None

    def compute(self, snapshot: Snapshot) -> VoidCells:
        """Build the graph, the faces and the measures of ``snapshot``; returns self."""
        if not isinstance(snapshot, Snapshot):
            raise InputError(f"snapshot: expected a gransim.voidcell.Snapshot, got {type(snapshot).__name__}")
        s = snapshot
        graph = build_graph(s.n_particles, s.contacts_i, s.contacts_j, s.contacts_shift)
        dcel = build_dcel(
            s.positions,
            s.cell,
            graph.edge_i,
            graph.edge_j,
            graph.edge_shift,
            graph.n_vertices,
            check_crossings=self.check_crossings,
        )
        v = s.velocities
        Cd = s.cell_velocity
        dv = halfedge_velocities(dcel.origin, dcel.dest, dcel.shift, v, Cd)  # eq (5)
        L = face_gradients(dcel.face_ptr, dcel.face_halfedges, dcel.vec, dv, dcel.face_area)
        L_cells = assembly_average(L, dcel.face_area)
        Lbar = L_cells if self.reference == "cells" else s.imposed_gradient
        d50 = self.d50
        if d50 is None and s.radii is not None:
            d50 = d50_area_weighted(s.radii)
        v_rel = None
        v_rel_undefined = relative_motion_undefined(Lbar)
        if d50 is None:
            v_rel_undefined = "undefined (no D50: the snapshot has no radii and no d50 was given)"
        if v_rel_undefined is None:
            v_rel = relative_motion(s.positions, v, Lbar, d50)
        if np.all(Lbar == 0):
            alpha = np.full(dcel.n_faces, np.nan)
            w = np.full(dcel.n_faces, np.nan)
        else:
            alpha = alignment(L, Lbar)
            w = normalised_vorticity(L, Lbar)
        self._r = dict(
            snapshot=s,
            graph=graph,
            dcel=dcel,
            L=L,
            L_cells=L_cells,
            L_mean=Lbar,
            alpha=alpha,
            w=w,
            v_rel=v_rel,
            v_rel_undefined=v_rel_undefined,
            d50=d50,
        )
        return self

    # -- results --------------------------------------------------------------
    def _get(self, key):
        if self._r is None:
            raise NotComputedError(f"VoidCells.{key} is not available before compute(snapshot)")
        return self._r[key]

    @property
    def snapshot(self) -> Snapshot:
        return self._get("snapshot")

    @property
    def graph(self) -> ParticleGraph:
        """The pruned particle graph."""
        return self._get("graph")

    @property
    def dcel(self) -> DCEL:
        """Half-edges and faces."""
        return self._get("dcel")

    @property
    def n_faces(self) -> int:
        """L-script of eq (16): number of void cells."""
        return self.dcel.n_faces

    @property
    def n_edges(self) -> int:
        """M-bar: edges of the framework."""
        return self.dcel.n_edges

    @property
    def n_vertices(self) -> int:
        """N-bar: vertices of the framework."""
        return self.dcel.n_vertices

    @property
    def coordination(self) -> float:
        """Effective coordination number 2 M-bar / N-bar of the framework (3.75 in sec. 4)."""
        return 2.0 * self.n_edges / self.n_vertices

    @property
    def face_area(self) -> np.ndarray:
        """Areas A^i of the void cells (m^2), (F,)."""
        return self.dcel.face_area

    @property
    def valence(self) -> np.ndarray:
        """Valence m of each void cell, (F,)."""
        return self.dcel.valence

    @property
    def L(self) -> np.ndarray:
        """Average velocity gradient of each void cell, eq (7), (F, 2, 2) (1/s)."""
        return self._get("L")

    @property
    def L_cells(self) -> np.ndarray:
        """Area-weighted mean of the cells, eq (3), (2, 2)."""
        return self._get("L_cells")

    @property
    def L_mean(self) -> np.ndarray:
        """The reference gradient Lbar used in eqs (18)-(21), (2, 2)."""
        return self._get("L_mean")

    @property
    def alpha(self) -> np.ndarray:
        """Alignment of each cell with Lbar, eqs (18)-(19), (F,)."""
        return self._get("alpha")

    @property
    def w(self) -> np.ndarray:
        """Normalised vorticity of each cell, eq (20), (F,)."""
        return self._get("w")

    @property
    def v_rel(self) -> np.ndarray:
        """Relative particle motion, eq (21), (N, 2) (dimensionless). It needs D50 (radii or
        ``d50``) and a mean L_22 that is not round-off (:func:`~.measures.relative_motion_undefined`);
        otherwise :class:`InputError` with :attr:`v_rel_undefined` as the message."""
        v = self._get("v_rel")
        if v is None:
            raise InputError(f"v_rel: relative motion (eq 21) {self.v_rel_undefined}")
        return v

    @property
    def v_rel_undefined(self) -> str | None:
        """Why eq (21) has no value here ("undefined (mean L_22 = ... against |L| = ...)" or
        "undefined (no D50 ...)"), None when :attr:`v_rel` holds it."""
        return self._get("v_rel_undefined")

    @property
    def v_rel_rms(self) -> float | str:
        """Root mean square |v_rel| over the particles (eq 21), or :attr:`v_rel_undefined`."""
        if self.v_rel_undefined is not None:
            return self.v_rel_undefined
        return float(np.sqrt(np.mean(np.sum(self.v_rel**2, axis=1))))

    @property
    def mean_alpha(self) -> float:
        """Mean alignment over the cells (unweighted, as in sec. 4: 0.73 at 0.01% strain); NaN when
        Lbar = 0 or every cell is at rest."""
        a = self.alpha[np.isfinite(self.alpha)]
        return float(a.mean()) if a.size else float("nan")

    @property
    def fraction_nonpositive_alpha(self) -> float:
        """Fraction of cells with alpha <= 0 (about 22% at 0.16% strain in sec. 4)."""
        a = self.alpha[np.isfinite(self.alpha)]
        return float(np.count_nonzero(a <= 0) / a.shape[0]) if a.size else float("nan")

    def summary(self) -> dict:
        """Counts and statistics as a flat dict (one table row). A measure the loading leaves
        undefined is the text saying why instead of a number: alpha (eqs 18-19) when Lbar = 0,
        the relative motion (eq 21) as :attr:`v_rel_undefined`."""
        lbar = bool(np.any(self.L_mean != 0))
        undefined = "undefined (|L| = 0: the mean gradient vanishes)"
        return {
            "n_particles": self.snapshot.n_particles,
            "n_contacts": self.snapshot.n_contacts,
            "faces": self.n_faces,
            "edges": self.n_edges,
            "vertices": self.n_vertices,
            "euler": self.dcel.euler_characteristic,
            "coordination_2M_over_N": self.coordination,
            "mean_alpha": self.mean_alpha if lbar else undefined,
            "fraction_alpha_le_0": self.fraction_nonpositive_alpha if lbar else undefined,
            "rms_v_rel": self.v_rel_rms,
            **{f"removed_{k}": v for k, v in self.graph.removal_counts().items() if k != "kept"},
        }

    def __repr__(self) -> str:
        if self._r is None:
            return f"VoidCells(reference={self.reference!r}, not computed)"
        return (
            f"VoidCells(faces={self.n_faces}, edges={self.n_edges}, "
            f"vertices={self.n_vertices}, "
            f"mean_alpha={self.mean_alpha:.3f})"
        )
