"""The per-cell results of ``gransim voidcells`` as an HDF5 file (kind ``"voidcells"``,
layout in docs/voidcell.md), written atomically with the provenance.

A measure the loading leaves undefined is stored as NaN with an attribute ``undefined`` on the
dataset saying why (e.g. the relative motion of eq (21) in simple shear at constant volume:
"undefined (mean L_22 = 2.5e-18 against |L| = 0.0614)"), never as the number the division gives.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.hdf5 import atomic_h5
from .core import VoidCells

KIND = "voidcells"


def write_results(path, results, run=None, kind: str = "", motion: str = "velocity") -> Path:
    """Write one group ``/snapshots/<k>`` per analysed snapshot.

    Parameters
    ----------
    path : output file (.h5)
    results : sequence of (RunSnapshot, VoidCells) (:func:`gransim.voidcell.io.load_run_snapshots`)
    run : the run file analysed (recorded); kind : its kind ("dem-run", "shear-run");
    motion : "velocity" (gradients in 1/s) or "displacement" (increments, dimensionless)
    """
    params = {"run": str(run) if run is not None else None, "run_kind": kind, "motion": motion}
    with atomic_h5(path, kind=KIND, parameters=params) as f:
        f.attrs["motion"] = motion
        g = f.create_group("snapshots")
        for k, (rs, vc) in enumerate(results):
            _write_one(g.create_group(f"{k:03d}"), rs, vc)
    return Path(path)


def _write_one(h, rs, vc: VoidCells) -> None:
    h.attrs["step"] = int(rs.step)
    h.attrs["requested"] = float(rs.requested)
    h.attrs["strain"] = float(rs.strain)
    h.attrs["measure"] = str(rs.measure)
    h["cell"] = vc.snapshot.cell
    d = vc.dcel
    h["face_area"] = d.face_area
    h["valence"] = d.valence
    h["face_centroid"] = d.face_centroid
    h["L"] = vc.L
    h["L_cells"] = vc.L_cells
    h["L_mean"] = vc.L_mean
    h["vertices"] = vc.graph.vertices
    h["removed"] = vc.graph.removed
    lbar = bool(np.any(vc.L_mean != 0))
    for name in ("alpha", "w"):
        ds = h.create_dataset(name, data=getattr(vc, name))
        if not lbar:
            ds.attrs["undefined"] = "undefined (|L| = 0: the mean gradient vanishes)"
    why = vc.v_rel_undefined
    n = vc.snapshot.n_particles
    ds = h.create_dataset("v_rel", data=np.full((n, 2), np.nan) if why is not None else vc.v_rel)
    if why is not None:
        ds.attrs["undefined"] = why
    for key, value in vc.summary().items():
        if isinstance(value, str):
            h.attrs[key] = np.nan
            h.attrs[f"{key}_undefined"] = value
        else:
            h.attrs[key] = value
