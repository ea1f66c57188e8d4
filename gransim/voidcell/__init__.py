"""Kuhn's void-cell deformation measures: M.R. Kuhn 1997, "Deformation measures for granular
materials" (Mechanics of Deformation and Flow of Particulate Materials, ASCE, pp. 91-104), secs 2-4.

Particle graph on the torus (:mod:`.graph`), half-edge structure and faces (:mod:`.dcel`), the
consistent Q^m (:mod:`.qmatrix`), per-cell velocity gradients and statistics (:mod:`.measures`),
the compute object :class:`VoidCells`, maps (:mod:`.plots`) and VTK export (:mod:`.vtk`).
Depends only on :mod:`gransim.geometry`.
"""

from .core import NotComputedError, VoidCells
from .dcel import DCEL, build_dcel
from .graph import ParticleGraph, build_graph, find_bridges
from .measures import (
    alignment,
    assembly_average,
    face_gradients,
    normalised_vorticity,
    polygon_gradient,
    relative_motion,
)
from .qmatrix import q_matrix, q_separations
from .snapshot import Snapshot

__all__ = [
    "DCEL",
    "NotComputedError",
    "ParticleGraph",
    "Snapshot",
    "VoidCells",
    "alignment",
    "assembly_average",
    "build_dcel",
    "build_graph",
    "face_gradients",
    "find_bridges",
    "normalised_vorticity",
    "polygon_gradient",
    "q_matrix",
    "q_separations",
    "relative_motion",
]
