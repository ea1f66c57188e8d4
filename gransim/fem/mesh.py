"""Structured quadrilateral meshes: a rectangle (tests) and the slope of Meier et al. section 5.

Nodes are numbered row by row (``node = row * (nx + 1) + col``); elements are bilinear quadrilaterals
(Q1) with counter-clockwise connectivity ``(bottom-left, bottom-right, top-right, top-left)``.
Coordinates in m.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, as_positive_float
from ..errors import InputError


@dataclass(frozen=True, eq=False)
class Mesh:
    """A 2D Q1 mesh in the reference configuration.

    Attributes
    ----------
    nodes : (Nn, 2) float64
        Reference coordinates X (m).
    elements : (Ne, 4) int64
        Node indices of each quadrilateral, counter-clockwise.
    """

    nodes: np.ndarray
    elements: np.ndarray

    def __post_init__(self):
        nodes = as_array(self.nodes, "nodes", (None, 2))
        elements = as_array(self.elements, "elements", (None, 4), dtype=np.int64)
        if elements.size and (elements.min() < 0 or elements.max() >= nodes.shape[0]):
            raise InputError(
                f"elements: node indices must lie in [0, {nodes.shape[0]}), got [{elements.min()}, {elements.max()}]"
            )
        x = nodes[elements]  # (Ne, 4, 2)
        area2 = np.sum(
            x[:, :, 0] * np.roll(x[:, :, 1], -1, axis=1) - np.roll(x[:, :, 0], -1, axis=1) * x[:, :, 1], axis=1
        )
        if np.any(area2 <= 0):
            raise InputError(
                f"elements: element {int(np.argmax(area2 <= 0))} is not counter-clockwise or has zero area"
            )
        for name, a in (("nodes", nodes), ("elements", elements)):
            a.flags.writeable = False
            object.__setattr__(self, name, a)

    @property
    def n_nodes(self) -> int:
        """Number of nodes Nn."""
        return self.nodes.shape[0]

    @property
    def n_elements(self) -> int:
        """Number of elements Ne."""
        return self.elements.shape[0]


def _grid_elements(nx: int, ny: int) -> np.ndarray:
    """Connectivity of an (nx, ny) structured grid numbered row by row."""
    col, row = np.meshgrid(np.arange(nx), np.arange(ny))
    n0 = (row * (nx + 1) + col).ravel()
    return np.stack([n0, n0 + 1, n0 + nx + 2, n0 + nx + 1], axis=1).astype(np.int64)


def rectangle_mesh(nx: int, ny: int, lx: float = 1.0, ly: float = 1.0, distort: float = 0.0, seed: int = 0) -> Mesh:
    """An nx x ny rectangle [0, lx] x [0, ly]; ``distort`` moves interior nodes randomly.

    ``distort`` is a fraction of the smaller element size (use < 0.25 to keep elements convex); the
    patch test uses it to exercise non-parallelogram elements.
    """
    if int(nx) < 1 or int(ny) < 1:
        raise InputError(f"nx, ny: need at least one element each way, got {nx}, {ny}")
    lx = as_positive_float(lx, "lx")
    ly = as_positive_float(ly, "ly")
    X, Y = np.meshgrid(np.linspace(0, lx, nx + 1), np.linspace(0, ly, ny + 1))
    nodes = np.stack([X.ravel(), Y.ravel()], axis=1)
    if distort:
        rng = np.random.default_rng(seed)
        h = min(lx / nx, ly / ny)
        interior = (nodes[:, 0] > 0) & (nodes[:, 0] < lx) & (nodes[:, 1] > 0) & (nodes[:, 1] < ly)
        nodes[interior] += distort * h * rng.uniform(-1, 1, size=(int(interior.sum()), 2))
    return Mesh(nodes, _grid_elements(int(nx), int(ny)))


@dataclass(frozen=True)
class SlopeGeometry:
    """The slope geometry of Meier, Steinmann & Kuhl, section 5, whose Fig. 6 did not survive the text
    extraction: the dimensions below are gransim's reading of it.

    20 columns of width 3.875 m; the ground surface is at ``toe_height`` for x <= ``toe_x``, rises
    linearly to ``crest_height`` at ``crest_x`` (45 degrees) and stays there up to ``length``; each
    column is split into ``rows`` equal elements from y = 0 to the surface.
    """

    columns: int = 20
    rows: int = 19
    length: float = 77.5
    toe_x: float = 23.25
    toe_height: float = 15.5
    crest_x: float = 38.75
    crest_height: float = 31.0

    def surface(self, x):
        """Ground surface height y_s(x) (m)."""
        x = np.asarray(x, dtype=float)
        t = np.clip((x - self.toe_x) / (self.crest_x - self.toe_x), 0.0, 1.0)
        return self.toe_height + t * (self.crest_height - self.toe_height)


def slope_mesh(geometry: SlopeGeometry | None = None) -> Mesh:
    """The structured slope mesh: ``columns x rows`` Q1 elements (380 for the default geometry)."""
    g = geometry or SlopeGeometry()
    x = np.linspace(0.0, g.length, g.columns + 1)
    s = np.linspace(0.0, 1.0, g.rows + 1)
    X = np.broadcast_to(x, (g.rows + 1, g.columns + 1))
    Y = s[:, None] * g.surface(x)[None, :]
    nodes = np.stack([X.ravel(), Y.ravel()], axis=1)
    return Mesh(nodes, _grid_elements(g.columns, g.rows))
