"""LIGGGHTS biaxial output -> the native DEM run file (``kind = "dem-run"``, docs/schema_dem.md).

So that every analysis reading native runs (``gransim.dem.read_run``/``read_snapshot``,
``gransim voidcells``, ``gransim dem-export``) reads a LIGGGHTS run the same way. What LIGGGHTS
does not output cleanly is marked, not invented:

* stress: thermo ``compute pressure`` (compression positive) -> tension positive, as in native files;
  LIGGGHTS gives xx, yy and xy = (1/A) sum d_x f_y only, so [1, 0] repeats [0, 1] (native files keep
  the full non-symmetric Love sum);
* snapshot contacts: the touching pairs recomputed from the dumped positions (i, j, image
  shift, overlap); ``force``, ``tangential_spring`` are NaN and ``sliding`` False, because
  ``compute pair/gran/local`` re-evaluates contacts at output time instead of reporting the
  applied forces (docs/liggghts.md, "Stress and other output");
* series ``n_contacts`` (-1), ``mean_overlap`` and ``kinetic_energy`` (NaN) between dumps.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem.output import RunRecord, write_run
from gransim.geometry import Packing

from . import store
from .conventions import cauchy_from_pressure
from .decks.biaxial import read_dump, read_thermo, short_case


def _contacts(x, r, cell) -> dict:
    nl = find_neighbours(x, r, cell, skin=0.0)
    m = len(nl)
    return {
        "i": nl.i,
        "j": nl.j,
        "shift": nl.shift,
        "force": np.full((m, 2), np.nan),
        "overlap": nl.overlaps(r),
        "tangential_spring": np.full((m, 2), np.nan),
        "sliding": np.zeros(m, bool),
    }


def biaxial_job_to_run_file(
    path, packing: Packing, thermo: dict, dumps: dict, dt: float, settings: dict | None = None, source: str = ""
) -> Path:
    """Write a LIGGGHTS biaxial job as a native run file.

    Parameters
    ----------
    path : output .h5 (written atomically).
    packing : the assembly the job started from (the data file's packing).
    thermo : :func:`reference_runs.decks.biaxial.read_thermo` of the job's log (step, lx, ly,
        sxx, syy, sxy; pressure columns compression positive).
    dumps : :func:`reference_runs.decks.biaxial.read_dump` of its ``dump custom`` (rows by id).
    dt : time step (s).
    settings : the run's settings (stored as the ``settings`` attribute and parameters).
    source : a note on where the job came from (its directory, manifest), kept in the settings.
    """
    steps = np.asarray(thermo["step"], np.int64)
    T = len(steps)
    cells = np.zeros((T, 2, 2))
    cells[:, 0, 0] = thermo["lx"]
    cells[:, 1, 1] = thermo["ly"]
    sig = np.array([cauchy_from_pressure(a, b, c) for a, b, c in zip(thermo["sxx"], thermo["syy"], thermo["sxy"])])
    settings = {**(settings or {}), "source": "LIGGGHTS", "source_note": source}
    text = json.dumps(settings, sort_keys=True, default=str)
    rec = RunRecord(packing=packing, settings_text=text, fingerprint="liggghts:" + str(hash(text) & 0xFFFFFFFF))
    # write_run stores -stress (engine convention is compression positive): hand it that form
    rec.series = {
        "step": list(steps),
        "time": list(steps * dt),
        "cell": list(cells),
        "stress": list(-sig),
        "n_contacts": [-1] * T,
        "mean_overlap": [np.nan] * T,
        "kinetic_energy": [np.nan] * T,
        "phase": [1] * T,
    }
    r = packing.radii
    for step, fr in sorted(dumps.items()):
        k = int(np.searchsorted(steps, step))
        if k >= T or steps[k] != step:
            continue
        x = np.column_stack([fr["x"], fr["y"]])
        rec.snapshots[int(step)] = {
            "time": float(step * dt),
            "cell": cells[k],
            "positions": x,
            "velocities": np.column_stack([fr["vx"], fr["vy"]]),
            "spins": np.asarray(fr["omegaz"], float),
            "contacts": _contacts(x, r, cells[k]),
        }
        rec.series["n_contacts"][k] = len(rec.snapshots[int(step)]["contacts"]["i"])
    rec.complete = True
    return write_run(path, rec, parameters=settings)


def trajectory_to_run_file(
    path,
    packing: Packing,
    steps,
    stress,
    lengths,
    frames: dict,
    dt: float,
    settings: dict | None = None,
    source: str = "",
) -> Path:
    """Same as :func:`biaxial_job_to_run_file` from plain arrays: ``steps`` (T,), ``stress`` (T, 3)
    pressure-convention xx, yy, xy (compression positive), ``lengths`` (T, 2), ``frames``
    {step: {"x": (N, 2), "v": (N, 2), "w": (N,)}} (the validation layer's trajectories)."""
    stress = np.asarray(stress, float)
    lengths = np.asarray(lengths, float)
    thermo = {
        "step": np.asarray(steps, np.int64),
        "lx": lengths[:, 0],
        "ly": lengths[:, 1],
        "sxx": stress[:, 0],
        "syy": stress[:, 1],
        "sxy": stress[:, 2],
    }
    dumps = {
        int(k): {"x": f["x"][:, 0], "y": f["x"][:, 1], "vx": f["v"][:, 0], "vy": f["v"][:, 1], "omegaz": f["w"]}
        for k, f in frames.items()
    }
    return biaxial_job_to_run_file(path, packing, thermo, dumps, dt, settings, source)


def stored_short_run_file(path) -> Path:
    """The stored biaxial-short LIGGGHTS run (reference_runs/stored/biaxial-short) as a run file."""
    d = store.STORED / "biaxial-short"
    p, s, _, _ = short_case()
    return biaxial_job_to_run_file(
        path, p, read_thermo(d / "log.liggghts"), read_dump(d / "dump.atoms"), s.dt, settings=s.to_dict(), source=str(d)
    )
