"""VTK export of the void cells (meshio): polygons with per-cell data, for ParaView."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.hdf5 import atomic_path
from .core import VoidCells


def cells_to_vtu(path, vc: VoidCells, wrap: bool = True) -> Path:
    """Write every void cell as a VTK polygon with cell data.

    Each face gets its own vertices (lifted polygon, z = 0), moved by a lattice vector so that its
    centroid lies in the primary cell when ``wrap``. Cell data: ``area`` (m^2), ``valence``,
    ``alpha`` (eq 18), ``w`` (eq 20), ``L`` (the 2x2 gradient of eq 7 as 4 components
    L11, L12, L21, L22) and ``face`` (index). Faces are grouped in one polygon block per valence.
    """
    import meshio  # noqa: PLC0415 - start-up: meshio (~0.1 s)

    d = vc.dcel
    C = vc.snapshot.cell
    x = vc.snapshot.positions
    fh, ptr = d.face_halfedges, d.face_ptr
    fv = d.vec[fh]
    csum = np.cumsum(fv, axis=0) - fv
    counts = np.diff(ptr)
    fid = np.repeat(np.arange(d.n_faces), counts)
    pts = x[d.origin[fh[ptr[:-1]]]][fid] + csum - csum[ptr[:-1]][fid]
    if wrap:
        k = np.floor(np.linalg.solve(C, d.face_centroid.T).T)
        pts = pts - k[fid] @ C.T
    points = np.column_stack([pts, np.zeros(len(pts))])
    blocks, order = [], []
    for m in np.unique(counts):
        faces = np.flatnonzero(counts == m)
        blocks.append(
            ("polygon" if m > 4 else {3: "triangle", 4: "quad"}[int(m)], ptr[faces][:, None] + np.arange(m)[None, :])
        )
        order.append(faces)
    data = {
        "area": d.face_area,
        "valence": counts.astype(float),
        "alpha": vc.alpha,
        "w": vc.w,
        "L": vc.L.reshape(-1, 4),
        "face": np.arange(d.n_faces, dtype=float),
    }
    cell_data = {k: [np.asarray(v)[f] for f in order] for k, v in data.items()}
    mesh = meshio.Mesh(points, blocks, cell_data=cell_data)
    with atomic_path(path, suffix=".vtu") as tmp:
        meshio.write(tmp, mesh, file_format="vtu")
    return Path(path)
