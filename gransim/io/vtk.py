"""VTK export (meshio) for ParaView: particles as points with radius and any per-particle fields."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..geometry import Packing
from ..geometry.cell import wrap as wrap_points
from .hdf5 import atomic_path


def particles_to_vtu(path, positions, radii, point_data: dict | None = None, cell=None, wrap: bool = True) -> Path:
    """Write disks as VTK points (vertex cells) with ``radius`` and extra point data.

    ``positions`` (N, 2) are embedded in 3D with z = 0. With ``cell`` and ``wrap``
    the centres are wrapped into the primary cell first. Use ParaView's "Point
    Gaussian" or a Glyph filter scaled by ``radius`` to draw disks.
    """
    import meshio  # noqa: PLC0415 - start-up: meshio (~0.1 s)

    x = np.asarray(positions, float)
    if cell is not None and wrap:
        x, _ = wrap_points(x, np.asarray(cell, float))
    pts = np.column_stack([x, np.zeros(len(x))])
    data = {"radius": np.asarray(radii, float)}
    for k, v in (point_data or {}).items():
        v = np.asarray(v, float)
        if v.ndim == 2 and v.shape[1] == 2:
            v = np.column_stack([v, np.zeros(len(v))])
        data[k] = v
    mesh = meshio.Mesh(pts, [("vertex", np.arange(len(x)).reshape(-1, 1))], point_data=data)
    with atomic_path(path, suffix=".vtu") as tmp:
        meshio.write(tmp, mesh, file_format="vtu")
    return Path(path)


def packing_to_vtu(path, packing: Packing, point_data: dict | None = None) -> Path:
    """Export a packing to a .vtu file (see :func:`particles_to_vtu`)."""
    return particles_to_vtu(path, packing.positions, packing.radii, point_data, cell=packing.cell)
