"""Snapshots for the void-cell analysis from DEM run files (schema: docs/schema_dem.md).

The reader uses h5py directly on the documented layout (``kind = "dem-run"``), so the void-cell
package does not import :mod:`gransim.dem`. Parsed LIGGGHTS runs written in the same schema
are read the same way.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, ResultFileError
from ..io.hdf5 import open_result
from .snapshot import Snapshot

#: compression phase code of /series/phase (biaxial protocol)
PHASE_COMPRESSION = 1


@dataclass(frozen=True)
class RunSnapshot:
    """A snapshot picked at a requested strain.

    Attributes
    ----------
    requested : float
        Requested axial strain eps22 (compression positive, e.g. 1e-4 = 0.01%).
    strain : float
        Strain of the snapshot actually used, eps22 = -ln(Ly / Ly0) with Ly0 the cell height at
        the start of the compression phase (the first /series row with phase == 1; row 0 if the
        run has no phase column or no compression phase).
    step : int
        DEM step of the snapshot.
    snapshot : Snapshot
    """

    requested: float
    strain: float
    step: int
    snapshot: Snapshot


def _strain_origin(series) -> tuple[int, float]:
    cells = series["cell"][()]
    steps = series["step"][()]
    k = 0
    if "phase" in series:
        ph = series["phase"][()]
        comp = np.flatnonzero(ph == PHASE_COMPRESSION)
        if comp.size:
            k = int(comp[0])
    return int(steps[k]), float(np.linalg.norm(cells[k][:, 1]))


def _cell_rate(series, step: int) -> np.ndarray:
    """dC/dt at ``step`` by central differences of /series/cell (one-sided at the ends)."""
    steps = series["step"][()]
    t = series["time"][()]
    cells = series["cell"][()]
    if len(steps) < 2:
        return np.zeros((2, 2))
    k = int(np.clip(np.searchsorted(steps, step), 0, len(steps) - 1))
    a, b = max(k - 1, 0), min(k + 1, len(steps) - 1)
    if t[b] == t[a]:
        return np.zeros((2, 2))
    return (cells[b] - cells[a]) / (t[b] - t[a])


def _read_snapshot(g, radii, cell_rate, add_streaming: bool) -> Snapshot:
    c = g["contacts"]
    x = g["positions"][()]
    C = g["cell"][()]
    v = g["velocities"][()]
    if add_streaming:
        v = v + x @ (cell_rate @ np.linalg.inv(C)).T
    return Snapshot(
        positions=x,
        cell=C,
        contacts_i=c["i"][()],
        contacts_j=c["j"][()],
        contacts_shift=c["shift"][()],
        velocities=v,
        cell_velocity=cell_rate,
        radii=radii,
    )


#: shapes of the datasets the reader uses (N particles, M contacts of each snapshot, T series rows)
_SNAPSHOT_SHAPES = {"cell": (2, 2), "positions": ("N", 2), "velocities": ("N", 2)}
_CONTACT_SHAPES = {"i": ("M",), "j": ("M",), "shift": ("M", 2)}
_SERIES_SHAPES = {"step": (), "time": (), "cell": (2, 2)}


def _check(group, shapes, sizes, path, what):
    for k, shp in shapes.items():
        if k not in group or not hasattr(group[k], "shape"):
            raise ResultFileError(f"{path}: {what}: dataset {group.name}/{k} is missing")
        got = tuple(group[k].shape)
        want = []
        for e in shp:
            if isinstance(e, str):
                sizes.setdefault(e, got[0] if got else -1)
                e = sizes[e]
            want.append(e)
        if got != tuple(want):
            raise ResultFileError(
                f"{path}: {what}: dataset {group.name}/{k} has shape {got}, expected "
                f"{tuple(want)}: truncated or corrupt run file"
            )


def _check_layout(f, path, n):
    """Series of equal lengths, snapshots of the packing's N with consistent contacts."""
    ser = f["series"]
    t = None
    for k, trail in _SERIES_SHAPES.items():
        if k not in ser:
            raise ResultFileError(f"{path}: dataset /series/{k} is missing")
        shp = tuple(ser[k].shape)
        if len(shp) != 1 + len(trail) or shp[1:] != trail:
            raise ResultFileError(f"{path}: dataset /series/{k} has shape {shp}, expected (T,) + {trail}")
        t = shp[0] if t is None else t
        if shp[0] != t or t == 0:
            raise ResultFileError(
                f"{path}: dataset /series/{k} has {shp[0]} rows, /series/step has {t}: truncated or corrupt run file"
            )
    for k, d in ser.items():  # every other series (stress, phase, ...) has the same rows
        if hasattr(d, "shape") and (len(d.shape) == 0 or d.shape[0] != t):
            raise ResultFileError(
                f"{path}: dataset /series/{k} has shape {tuple(d.shape)}, /series/step "
                f"has {t} rows: truncated or corrupt run file"
            )
    for h in f["snapshots"].values():
        sizes = {} if n is None else {"N": n}
        _check(h, _SNAPSHOT_SHAPES, sizes, path, f"snapshot {h.name}")
        if "contacts" not in h:
            raise ResultFileError(f"{path}: snapshot {h.name} has no contacts group")
        _check(h["contacts"], _CONTACT_SHAPES, {}, path, f"contacts of snapshot {h.name}")


def check_complete(f, path, allow_incomplete: bool = False) -> tuple[bool, str]:
    """``complete`` and ``stop_reason`` of an open run file; refuses an unfinished run.

    :class:`ResultFileError` naming the file and its stop reason when ``complete`` is False (or
    missing) and not ``allow_incomplete``."""
    if "complete" not in f.attrs:
        complete, why = False, "the file has no 'complete' attribute (docs/schema_dem.md)"
    else:
        complete = bool(f.attrs["complete"])
        why = f.attrs.get("stop_reason", "")
        why = (why.decode() if isinstance(why, bytes) else str(why)) or "no stop_reason recorded"
    if not complete and not allow_incomplete:
        raise ResultFileError(
            f"{path}: incomplete run (complete = False): {why}; --allow-incomplete "
            "(allow_incomplete=True) reads it anyway"
        )
    return complete, ("" if complete else why)


def load_run_snapshots(
    path, strains, motion: str = "velocity", velocities: str = "remap", allow_incomplete: bool = False
) -> list[RunSnapshot]:
    """The snapshots of a DEM run nearest to the requested axial strains.

    Parameters
    ----------
    path : str or Path
        A gransim results file of kind "dem-run" (docs/schema_dem.md).
    strains : sequence of float, or None
        Axial compressive strains eps22 = -ln(Ly/Ly0) (1e-4 = 0.01%), measured from the start
        of the compression phase. None: every snapshot of the run, in order (``requested`` is
        then the snapshot's own strain).
    motion : {"velocity", "displacement"}
        "velocity": the snapshot's particle velocities with dC/dt from /series/cell (the
        instantaneous velocity gradient, as in the paper). "displacement": displacement
        increments from the chosen snapshot to the next one (a displacement-gradient increment).
    velocities : {"remap", "absolute"}
        What the stored velocities are. "remap" (default, the native engine and LIGGGHTS with
        ``fix deform ... remap x``): the box change moves every position affinely each step and
        the stored v excludes that motion, so the particle velocity is v + (dC/dt) C^{-1} x.
        "absolute": the stored v is the full particle velocity.
    allow_incomplete : bool
        Read a run that did not finish (root attribute ``complete`` False); refused by default.

    Raises
    ------
    ResultFileError for a missing/foreign file, one without snapshots, an unfinished run (unless
    ``allow_incomplete``), series of different lengths or snapshots of the wrong shape (naming
    the dataset); InputError for a non-finite strain or one farther from its nearest snapshot
    than the largest strain gap between snapshots (outside the range the run covers; the message
    gives the range). The strain actually used is returned with each snapshot.
    """
    if motion not in ("velocity", "displacement"):
        raise InputError(f"motion: choose 'velocity' or 'displacement', got {motion!r}")
    if velocities not in ("remap", "absolute"):
        raise InputError(f"velocities: choose 'remap' or 'absolute', got {velocities!r}")
    if strains is not None:
        try:
            req = np.atleast_1d(np.asarray(strains, dtype=float))
        except (TypeError, ValueError):
            raise InputError(f"strain: expected numbers, got {strains!r}") from None
        bad = req[~np.isfinite(req)]
        if bad.size:
            raise InputError(f"strain: {bad[0]!r} is not a finite number")
    with open_result(path, kind="dem-run") as f:
        check_complete(f, path, allow_incomplete)
        if "snapshots" not in f or not len(f["snapshots"]):
            raise ResultFileError(f"{path}: no /snapshots in this run")
        if "series" not in f:
            raise ResultFileError(f"{path}: no /series in this run")
        radii = f["packing/radii"][()] if "packing/radii" in f else None
        if radii is not None and radii.ndim != 1:
            raise ResultFileError(f"{path}: /packing/radii has shape {radii.shape}, expected (N,)")
        _check_layout(f, path, None if radii is None else radii.shape[0])
        series = f["series"]
        step0, Ly0 = _strain_origin(series)
        names = sorted(f["snapshots"].keys())
        steps = np.array([int(f["snapshots"][n].attrs.get("step", int(n[1:]))) for n in names])
        eps = np.array([-np.log(np.linalg.norm(f["snapshots"][n]["cell"][()][:, 1]) / Ly0) for n in names])
        eligible = np.flatnonzero(steps >= step0)
        if strains is None:  # every frame, in order (the consolidation phase included)
            picks = [(float(eps[k]), k) for k in range(len(names) - (motion == "displacement"))]
        if motion == "displacement":
            eligible = eligible[eligible < len(names) - 1]
        if eligible.size == 0 and strains is not None:
            raise ResultFileError(f"{path}: no snapshot in the compression phase (from step {step0})")
        if strains is not None:
            ee = np.sort(eps[eligible])
            gap = float(np.max(np.diff(ee))) if ee.size > 1 else 0.0  # snapshot spacing in strain
            gap = max(gap, 1e-12)
            picks = []
            for s in (float(v) for v in np.atleast_1d(strains)):
                k = int(eligible[np.argmin(np.abs(eps[eligible] - s))])
                if abs(eps[k] - s) > gap:
                    raise InputError(
                        f"strain {s:g} is outside the range of the run: its compression-phase snapshots "
                        f"cover {eps[eligible].min():.4g} .. {eps[eligible].max():.4g} (spacing up to "
                        f"{gap:.3g}); nearest snapshot is at strain {eps[k]:.4g} (step {steps[k]})"
                    )
                picks.append((s, k))
        out = []
        for s, k in picks:
            g = f["snapshots"][names[k]]
            rate = _cell_rate(series, int(steps[k]))
            snap = _read_snapshot(g, radii, rate, velocities == "remap")
            if motion == "displacement":
                g1 = f["snapshots"][names[k + 1]]
                snap = snap.with_displacements_to(g1["positions"][()], g1["cell"][()])
            out.append(RunSnapshot(requested=s, strain=float(eps[k]), step=int(steps[k]), snapshot=snap))
    return out
