"""Snapshots for the void-cell analysis from DEM run files of either layout.

Two kinds of run file are read, with h5py on their documented layouts (the void-cell package does
not import :mod:`gransim.dem`):

* ``kind = "dem-run"`` (docs/schema_dem.md): the biaxial test (``gransim biaxial``) in an
  orthogonal cell; ``/series/cell`` (T, 2, 2); snapshots ``/snapshots/s<step>`` with their contacts.
  Velocities exclude the affine remap of the positions (``fix deform ... remap x``). Parsed
  LIGGGHTS runs written in the same schema are read the same way.
* ``kind = "shear-run"`` (docs/shear.md): simple shear (``gransim shear``) in a sheared cell;
  ``/series/box`` (T, 5) = lx, ly, xy, ylo, yhi, the cell [[lx, xy], [0, ly]]; snapshots
  ``/snapshots/<step>`` without contacts: the contacts are the overlapping pairs of the snapshot's
  disks, |x_j + C n - x_i| < r_i + r_j (the engine's contact test). Velocities are lab-frame
  velocities, the streaming part included (LAMMPS ``fix deform ... remap v``, docs/shear.md).

The strain that picks a snapshot follows the loading: the axial strain eps22 = -ln(Ly/Ly0) of a
biaxial run (Ly0 at the start of the compression phase), the shear strain gamma = (xy - xy0)/Ly0 of
a run whose cell tilts (xy0, Ly0 of the first /series row).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InputError, ResultFileError
from ..geometry.bins import pairs_within, wrap_fractional
from ..io.hdf5 import open_result
from .snapshot import Snapshot

#: compression phase code of /series/phase (biaxial protocol)
PHASE_COMPRESSION = 1
#: the run-file kinds read here and how each stores velocities ("remap": without the streaming
#: velocity of the affine remap, "absolute": lab-frame velocities)
RUN_KINDS = {"dem-run": "remap", "shear-run": "absolute"}
#: the strain measures: "axial" eps22 = -ln(Ly/Ly0) (compression positive), "shear" gamma
MEASURES = {"axial": "axial strain eps22 = -ln(Ly/Ly0)", "shear": "shear strain gamma = (xy - xy0)/Ly0"}


@dataclass(frozen=True)
class RunSnapshot:
    """A snapshot picked at a requested strain.

    Attributes
    ----------
    requested : float
        Requested strain (e.g. 1e-4 = 0.01%), of the run's ``measure``.
    strain : float
        Strain of the snapshot actually used: for ``measure == "axial"`` eps22 = -ln(Ly / Ly0) with
        Ly0 the cell height at the start of the compression phase (the first /series row with
        phase == 1; row 0 if the run has no phase column or no compression phase); for
        ``measure == "shear"`` gamma = (xy - xy0) / Ly0 with xy0, Ly0 of the first /series row.
    step : int
        DEM step of the snapshot.
    snapshot : Snapshot
    measure : {"axial", "shear"}
    """

    requested: float
    strain: float
    step: int
    snapshot: Snapshot
    measure: str = "axial"


@dataclass(frozen=True)
class RunInfo:
    """What a run file holds, for choosing strains (:func:`describe_run`).

    kind : "dem-run" or "shear-run"; measure : "axial" or "shear" (:class:`RunSnapshot`);
    steps : (S,) int64 and strains : (S,) float64 of its snapshots in step order; step0 : first step
    of the loading (start of the compression phase; 0 for shear); velocities : how the file stores
    velocities ("remap" or "absolute", :data:`RUN_KINDS`).
    """

    kind: str
    measure: str
    steps: np.ndarray
    strains: np.ndarray
    step0: int
    velocities: str


def _kind(f, path) -> str:
    kind = f.attrs.get("kind")
    kind = kind.decode() if isinstance(kind, bytes) else kind
    if kind not in RUN_KINDS:
        raise ResultFileError(f"{path}: holds {kind!r}, expected " + " or ".join(repr(k) for k in RUN_KINDS))
    return kind


def _series_cells(f) -> np.ndarray:
    """The cell of every /series row, (T, 2, 2) (m): /series/cell, or [[lx, xy], [0, ly]] of /series/box."""
    ser = f["series"]
    if "cell" in ser:
        return ser["cell"][()]
    box = ser["box"][()]
    cells = np.zeros((box.shape[0], 2, 2))
    cells[:, 0, 0], cells[:, 0, 1], cells[:, 1, 1] = box[:, 0], box[:, 2], box[:, 1]
    return cells


def _measure(kind: str, cells: np.ndarray) -> str:
    """ "shear" for a shear run or any run whose cell tilts, else "axial"."""
    return "shear" if kind == "shear-run" or np.any(cells[:, 0, 1] != cells[0, 0, 1]) else "axial"


def _strain_origin(f, cells, measure) -> tuple[int, np.ndarray]:
    """First step of the loading and the cell there."""
    ser = f["series"]
    steps = ser["step"][()]
    k = 0
    if measure == "axial" and "phase" in ser:
        comp = np.flatnonzero(ser["phase"][()] == PHASE_COMPRESSION)
        if comp.size:
            k = int(comp[0])
    return int(steps[k]), cells[k]


def _strain(C, C0, measure) -> float:
    """Strain of cell ``C`` from the origin cell ``C0`` (:class:`RunSnapshot`)."""
    if measure == "shear":
        return float((C[0, 1] - C0[0, 1]) / C0[1, 1])
    return float(-np.log(np.linalg.norm(C[:, 1]) / np.linalg.norm(C0[:, 1])))


def _cell_rate(steps, t, cells, step: int) -> np.ndarray:
    """dC/dt at ``step`` by central differences of the series cells (one-sided at the ends)."""
    if len(steps) < 2:
        return np.zeros((2, 2))
    k = int(np.clip(np.searchsorted(steps, step), 0, len(steps) - 1))
    a, b = max(k - 1, 0), min(k + 1, len(steps) - 1)
    if t[b] == t[a]:
        return np.zeros((2, 2))
    return (cells[b] - cells[a]) / (t[b] - t[a])


def touching_pairs(positions, radii, cell):
    """The contacts of a snapshot without a contact list: every pair of overlapping disks.

    Pairs (i, j, n) with |x_j + C n - x_i| < r_i + r_j, each once, n the image shift relative to
    ``positions`` as given (:func:`gransim.geometry.bins.pairs_within` finds them among the wrapped
    points xw = x - C m; the shift then is t + m_i - m_j). O(N).

    Returns i, j (M,) int64 and shift (M, 2) int64.
    """
    x = np.ascontiguousarray(positions, np.float64)
    C = np.ascontiguousarray(cell, np.float64)
    _, _, m = wrap_fractional(x, C)
    i, j, t, _ = pairs_within(x, np.ascontiguousarray(radii, np.float64), C)
    return i, j, t + m[i] - m[j]


def _read_snapshot(g, radii, cell_rate, add_streaming: bool) -> Snapshot:
    x = g["positions"][()]
    C = g["cell"][()]
    v = g["velocities"][()]
    if "contacts" in g:
        c = g["contacts"]
        ci, cj, cs = c["i"][()], c["j"][()], c["shift"][()]
    else:  # a shear-run snapshot: the overlapping pairs
        ci, cj, cs = touching_pairs(x, radii, C)
    if add_streaming:
        v = v + x @ (cell_rate @ np.linalg.inv(C)).T
    return Snapshot(
        positions=x,
        cell=C,
        contacts_i=ci,
        contacts_j=cj,
        contacts_shift=cs,
        velocities=v,
        cell_velocity=cell_rate,
        radii=radii,
    )


#: shapes of the datasets the reader uses (N particles, M contacts of each snapshot, T series rows)
_SNAPSHOT_SHAPES = {"cell": (2, 2), "positions": ("N", 2), "velocities": ("N", 2)}
_CONTACT_SHAPES = {"i": ("M",), "j": ("M",), "shift": ("M", 2)}
#: the series datasets of each kind: trailing shape after (T,)
_SERIES_SHAPES = {
    "dem-run": {"step": (), "time": (), "cell": (2, 2)},
    "shear-run": {"step": (), "time": (), "box": (5,)},
}


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


def _check_layout(f, path, kind, n):
    """Series of equal lengths, snapshots of the packing's N with consistent contacts (a
    shear-run snapshot has none: then the radii are needed to find them)."""
    ser = f["series"]
    t = None
    for k, trail in _SERIES_SHAPES[kind].items():
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
        if "contacts" in h:
            _check(h["contacts"], _CONTACT_SHAPES, {}, path, f"contacts of snapshot {h.name}")
        elif kind == "dem-run":
            raise ResultFileError(f"{path}: snapshot {h.name} has no contacts group")
        elif n is None:
            raise ResultFileError(
                f"{path}: snapshot {h.name} has no contacts and the file no /packing/radii to find them"
            )


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


@dataclass(frozen=True)
class _Run:
    """A checked run file, open: its series cells, snapshots in step order, strain measure."""

    info: RunInfo
    names: list
    steps: np.ndarray
    times: np.ndarray
    cells: np.ndarray
    radii: np.ndarray | None


def _open_run(f, path, allow_incomplete: bool) -> _Run:
    kind = _kind(f, path)
    check_complete(f, path, allow_incomplete)
    if "snapshots" not in f or not len(f["snapshots"]):
        raise ResultFileError(f"{path}: no /snapshots in this run")
    if "series" not in f:
        raise ResultFileError(f"{path}: no /series in this run")
    radii = f["packing/radii"][()] if "packing/radii" in f else None
    if radii is not None and radii.ndim != 1:
        raise ResultFileError(f"{path}: /packing/radii has shape {radii.shape}, expected (N,)")
    _check_layout(f, path, kind, None if radii is None else radii.shape[0])
    cells = _series_cells(f)
    measure = _measure(kind, cells)
    step0, C0 = _strain_origin(f, cells, measure)
    sn = f["snapshots"]
    keyed = sorted((int(sn[n].attrs["step"]) if "step" in sn[n].attrs else int(n.lstrip("s")), n) for n in sn)
    snap_steps = np.array([k for k, _ in keyed], np.int64)
    names = [n for _, n in keyed]
    strains = np.array([_strain(sn[n]["cell"][()], C0, measure) for n in names])
    info = RunInfo(kind, measure, snap_steps, strains, step0, RUN_KINDS[kind])
    return _Run(info, names, f["series/step"][()], f["series/time"][()], cells, radii)


def describe_run(path, allow_incomplete: bool = False) -> RunInfo:
    """Kind, strain measure and the snapshots' steps and strains of a run file (checked as by
    :func:`load_run_snapshots`)."""
    with open_result(path) as f:
        return _open_run(f, path, allow_incomplete).info


def load_run_snapshots(
    path, strains, motion: str = "velocity", velocities: str = "auto", allow_incomplete: bool = False
) -> list[RunSnapshot]:
    """The snapshots of a DEM run nearest to the requested strains.

    Parameters
    ----------
    path : str or Path
        A gransim results file of kind "dem-run" (docs/schema_dem.md) or "shear-run"
        (docs/shear.md).
    strains : sequence of float, or None
        Strains of the run's measure (:class:`RunSnapshot`; 1e-4 = 0.01%): the axial compressive
        strain eps22 = -ln(Ly/Ly0) measured from the start of the compression phase of a
        biaxial run, the shear strain gamma = (xy - xy0)/Ly0 of a shear run. None: every
        snapshot of the run, in order (``requested`` is then the snapshot's own strain).
    motion : {"velocity", "displacement"}
        "velocity": the snapshot's particle velocities with dC/dt from the series cells (the
        instantaneous velocity gradient, as in the paper). "displacement": displacement
        increments from the chosen snapshot to the next one (a displacement-gradient increment).
    velocities : {"auto", "remap", "absolute"}
        What the stored velocities are. "remap" (the native biaxial engine and LIGGGHTS with
        ``fix deform ... remap x``): the box change moves every position affinely each step and
        the stored v excludes that motion, so the particle velocity is v + (dC/dt) C^{-1} x.
        "absolute" (the sheared cell, LAMMPS ``remap v``): the stored v is the full particle
        velocity. "auto" (default): as the file's kind stores them (:data:`RUN_KINDS`).
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
    if velocities not in ("auto", "remap", "absolute"):
        raise InputError(f"velocities: choose 'auto', 'remap' or 'absolute', got {velocities!r}")
    if strains is not None:
        try:
            req = np.atleast_1d(np.asarray(strains, dtype=float))
        except (TypeError, ValueError):
            raise InputError(f"strain: expected numbers, got {strains!r}") from None
        bad = req[~np.isfinite(req)]
        if bad.size:
            raise InputError(f"strain: {bad[0]!r} is not a finite number")
    with open_result(path) as f:
        run = _open_run(f, path, allow_incomplete)
        info, names = run.info, run.names
        steps, eps = info.steps, info.strains
        add_streaming = (info.velocities if velocities == "auto" else velocities) == "remap"
        phase = "compression-phase " if info.measure == "axial" else ""
        eligible = np.flatnonzero(steps >= info.step0)
        if strains is None:  # every frame, in order (the consolidation phase included)
            picks = [(float(eps[k]), k) for k in range(len(names) - (motion == "displacement"))]
        if motion == "displacement":
            eligible = eligible[eligible < len(names) - 1]
        if eligible.size == 0 and strains is not None:
            raise ResultFileError(
                f"{path}: no {phase}snapshot from step {info.step0}"
                + (" with a next one (--motion displacement)" if motion == "displacement" else "")
            )
        if strains is not None:
            ee = np.sort(eps[eligible])
            gap = float(np.max(np.diff(ee))) if ee.size > 1 else 0.0  # snapshot spacing in strain
            gap = max(gap, 1e-12)
            picks = []
            for s in (float(v) for v in np.atleast_1d(strains)):
                k = int(eligible[np.argmin(np.abs(eps[eligible] - s))])
                if abs(eps[k] - s) > gap:
                    raise InputError(
                        f"strain {s:g} is outside the range of the run: its {phase}snapshots "
                        f"cover {info.measure} strain {eps[eligible].min():.4g} .. {eps[eligible].max():.4g} "
                        f"(spacing up to {gap:.3g}); nearest snapshot is at strain {eps[k]:.4g} (step {steps[k]})"
                    )
                picks.append((s, k))
        out = []
        sn = f["snapshots"]
        for s, k in picks:
            g = sn[names[k]]
            rate = _cell_rate(run.steps, run.times, run.cells, int(steps[k]))
            snap = _read_snapshot(g, run.radii, rate, add_streaming)
            if motion == "displacement":
                g1 = sn[names[k + 1]]
                snap = snap.with_displacements_to(g1["positions"][()], g1["cell"][()])
            out.append(
                RunSnapshot(requested=s, strain=float(eps[k]), step=int(steps[k]), snapshot=snap, measure=info.measure)
            )
    return out
