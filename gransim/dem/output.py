"""Results files of DEM runs (layout: docs/schema_dem.md), reading, VTK export and the
stress-strain plot (Fig. 7b of Kuhn (1997))."""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np

from ..contacts.neighbours import find_neighbours
from ..errors import InputError, ResultFileError
from ..geometry import Packing
from ..io import atomic_h5, atomic_path, open_result, particles_to_vtu, read_packing_group, write_packing_group
from ..io.hdf5 import remove_stale_temporaries

KIND = "dem-run"
#: kind of the simple-shear run file (``gransim.dem.sheared.run_shear_file``, layout: docs/shear.md),
#: read by :func:`read_run` and :func:`read_snapshot` as well
SHEAR_KIND = "shear-run"
RUN_KINDS = (KIND, SHEAR_KIND)
SERIES_KEYS = ("step", "time", "cell", "stress", "n_contacts", "mean_overlap", "kinetic_energy", "phase")
_GZ = {"compression": "gzip", "compression_opts": 4}


@dataclass(frozen=True)
class OutputSettings:
    """How often to write: series rows, snapshots, checkpoints (in steps; 0 = never)."""

    series_every: int = 1
    snapshot_every: int = 1000
    checkpoint_every: int = 20000

    def __post_init__(self):
        for k in ("series_every", "snapshot_every", "checkpoint_every"):
            v = getattr(self, k)
            if int(v) != v or v < 0:
                raise InputError(f"{k}: expected an integer >= 0, got {v!r}")
        if self.series_every == 0:
            raise InputError("series_every: must be >= 1")

    def to_dict(self) -> dict:
        return {k: int(getattr(self, k)) for k in ("series_every", "snapshot_every", "checkpoint_every")}


@dataclass
class RunRecord:
    """In-memory content of a run file (what :func:`write_run` writes)."""

    packing: Packing
    settings_text: str
    fingerprint: str
    series: dict = field(default_factory=lambda: {k: [] for k in SERIES_KEYS})
    snapshots: dict = field(default_factory=dict)  # step -> dict of arrays
    checkpoint: dict | None = None  # arrays + "step" + "protocol_state"
    complete: bool = False
    stop_reason: str = ""
    unsettled: list = field(default_factory=list)  # phases that ended unsettled (allow_unsettled)
    output: dict | None = None  # OutputSettings.to_dict() of the run (None: not stored)
    allow_unsettled: bool = False
    #: what is on disk of this record (written by :func:`write_run` / :func:`write_checkpoint` or
    #: read by :func:`read_record`): the run file's path, os.stat key and write token, the series
    #: rows and snapshot steps in it (``file_rows``, ``file_snapshots``) and with its checkpoint
    #: parts (``rows``, ``snapshots``), the parts' number and bytes; lets the next write copy or
    #: skip them instead of encoding them again (None: write everything)
    stored: dict | None = field(default=None, repr=False, compare=False)

    def truncate(self, step: int) -> None:
        """Keep the series rows and snapshots up to ``step`` (a resume from the checkpoint there)."""
        keep = int(np.searchsorted(np.asarray(self.series["step"], np.int64), step, side="right"))  # rows ascend
        for k in self.series:
            del self.series[k][keep:]
        self.snapshots = {s: v for s, v in self.snapshots.items() if s <= step}
        if self.stored is not None:
            st = dict(self.stored)
            for rows, snaps in (("rows", "snapshots"), ("file_rows", "file_snapshots")):
                st[rows] = min(int(st[rows]), keep)
                st[snaps] = frozenset(s for s in st[snaps] if s <= step)
            st["compact"] = True  # the next write is a whole run file (its parts end here)
            self.stored = st

    def series_arrays(self, start: int = 0) -> dict:
        """The series rows from ``start`` on as arrays (the engine's compression-positive stress)."""
        out = {}
        for k in SERIES_KEYS:
            v = self.series[k][start:]
            if k in ("cell", "stress"):
                out[k] = np.array(v, np.float64).reshape(-1, 2, 2)
            elif k in ("step", "n_contacts"):
                out[k] = np.array(v, np.int64)
            elif k == "phase":
                out[k] = np.array(v, np.int8)
            else:
                out[k] = np.array(v, np.float64)
        return out


#: rows of a chunk of the /series datasets (fixed, so that a checkpoint appends rows to the chunks
#: a previous write stored instead of re-encoding the series)
SERIES_CHUNK = 1024


def _stat_key(path) -> tuple | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns)


def _reusable(path: Path, rec: RunRecord) -> dict | None:
    """What the file at ``path`` already holds of ``rec`` (its first ``rows`` series rows and the
    snapshots of ``snapshots``), when it is the file this process last wrote or read for ``rec``
    (same device, inode, size and modification time) and its fingerprint is ``rec``'s."""
    st = rec.stored
    if not st or st.get("path") != str(path.resolve()) or st.get("stat") != _stat_key(path):
        return None
    return st


def _write_series(g, arrays: dict) -> None:
    for k, v in arrays.items():
        g.create_dataset(k, data=v, chunks=(SERIES_CHUNK,) + v.shape[1:], maxshape=(None,) + v.shape[1:], **_GZ)


def _write_snapshot(sg, step: int, snap: dict) -> None:
    h = sg.create_group(f"s{step:010d}")
    h.attrs["step"] = step
    h.attrs["time"] = snap["time"]
    for k in ("cell", "positions", "velocities", "spins"):
        h.create_dataset(k, data=snap[k], **(_GZ if np.ndim(snap[k]) and len(snap[k]) > 1 else {}))
    c = h.create_group("contacts")
    for k, v in snap["contacts"].items():
        v = np.asarray(v)
        c.create_dataset(
            k,
            data=v,
            chunks=(min(max(len(v), 1), 65536),) + v.shape[1:] if len(v) else None,
            **(_GZ if len(v) else {}),
        )


def write_run(path, rec: RunRecord, parameters: dict | None = None, seed=None) -> Path:
    """Write the whole record atomically (a crash never leaves a half-written file).

    A new file is always written beside the old one and renamed over it, but what the previous
    write of ``rec`` by this process (or :func:`read_record`) already stored is not encoded again:
    its series rows and snapshots are copied from that file as stored (compressed chunks, nothing
    decoded) and only the new rows and snapshots are compressed. So a checkpoint costs a copy of
    the stored bytes plus the encoding of what is new, not a re-encoding of the whole run."""
    path = Path(path)
    base = _reusable(path, rec)
    arrays_from = 0
    token = os.urandom(8).hex()
    with atomic_h5(path, kind=KIND, parameters=parameters or json.loads(rec.settings_text), seed=seed) as f:
        f.attrs["write_token"] = token
        f.attrs["fingerprint"] = rec.fingerprint
        f.attrs["settings"] = rec.settings_text
        f.attrs["n_particles"] = rec.packing.n
        f.attrs["complete"] = bool(rec.complete)
        f.attrs["stop_reason"] = rec.stop_reason
        f.attrs["allow_unsettled"] = bool(rec.allow_unsettled)
        f.attrs["unsettled_phases"] = json.dumps(rec.unsettled)
        if rec.output is not None:
            f.attrs["output_settings"] = json.dumps(rec.output, sort_keys=True)
        n_rows = len(rec.series["step"])
        src = None
        if base is not None:
            try:
                src = h5py.File(path, "r")
                if src.attrs.get("fingerprint") != rec.fingerprint or not _extendable(src, base["file_rows"]):
                    src.close()
                    src = None
            except OSError:
                src = None
        try:
            kept = set()
            if src is not None:
                src.copy(src["packing"], f, name="packing")
                src.copy(src["series"], f, name="series")
                arrays_from = min(int(base["file_rows"]), n_rows)
                g = f["series"]
                new = rec.series_arrays(arrays_from)
                for k in SERIES_KEYS:
                    v = -new[k] if k == "stress" else new[k]
                    d = g[k]
                    d.resize(arrays_from + len(v), axis=0)
                    if len(v):
                        d[arrays_from:] = v
                have = set(src["snapshots"].keys())
                kept = {s for s in base["file_snapshots"] if s in rec.snapshots and f"s{s:010d}" in have}
            else:
                write_packing_group(f.create_group("packing"), rec.packing)
                g = f.create_group("series")
                g.attrs["stress_sign"] = "tension positive (gransim convention; = -LIGGGHTS compute pressure)"
                arrays = rec.series_arrays()
                arrays["stress"] = -arrays["stress"]  # the engine works in LIGGGHTS' compression-positive
                _write_series(g, arrays)  # virial; files are tension positive
            sg = f.create_group("snapshots")
            for step in sorted(rec.snapshots):
                if step in kept:
                    name = f"s{step:010d}"
                    src.copy(src["snapshots"][name], sg, name=name)
                else:
                    _write_snapshot(sg, step, rec.snapshots[step])
        finally:
            if src is not None:
                src.close()
        if rec.checkpoint is not None:
            _write_checkpoint_group(f, rec.checkpoint)
    remove_parts(path)  # the run file now holds everything they held
    rec.stored = _stored(path, token, n_rows, frozenset(rec.snapshots))
    return Path(path)


def _stored(path: Path, token, rows: int, snapshots: frozenset) -> dict:
    return {
        "path": str(Path(path).resolve()),
        "stat": _stat_key(path),
        "token": token,
        "file_rows": rows,
        "file_snapshots": snapshots,
        "rows": rows,
        "snapshots": snapshots,
        "parts": 0,
        "parts_bytes": 0,
        "compact": False,
    }


# ------------------------------------------------------------------------------ checkpoint parts
#: kind of a checkpoint part file (``.<run file>.part-<seq>.h5``, beside the run file)
PART_KIND = "dem-run-part"
#: a checkpoint is written as a part file while the parts since the last whole write of the run
#: file total at most this fraction of its size; the next one rewrites the run file (and removes
#: the parts). The run file is rewritten each time the run's data grew by this fraction: its
#: rewrites cost a bounded multiple of the final file's writing, whatever the checkpoint interval
COMPACT_FRACTION = 0.5
_PART = re.compile(r"^\.(?P<name>.+)\.part-(?P<seq>\d{6})\.h5$")


def part_path(path, seq: int) -> Path:
    """The checkpoint part ``seq`` (1, 2, ...) of the run file ``path``."""
    path = Path(path)
    return path.parent / f".{path.name}.part-{int(seq):06d}.h5"


def part_paths(path) -> list[Path]:
    """The checkpoint part files of the run file ``path`` on disk, in order."""
    path = Path(path)
    try:
        names = os.listdir(path.parent if str(path.parent) else ".")
    except OSError:
        return []
    out = []
    for name in names:
        m = _PART.match(name)
        if m and m.group("name") == path.name:
            out.append((int(m.group("seq")), path.parent / name))
    return [p for _, p in sorted(out)]


def remove_stale_run_temporaries(path) -> None:
    """Remove the temporaries a killed run left beside its run file ``path`` (of the run file and
    of its checkpoint parts; :func:`gransim.io.hdf5.stale_temporaries`: never a live process's)."""
    path = Path(path)
    remove_stale_temporaries(path)
    try:
        names = os.listdir(path.parent if str(path.parent) else ".")
    except OSError:
        return
    pre = f"..{path.name}.part-"
    for name in {n[1 : len(pre) + 6 + 3] for n in names if n.startswith(pre)}:
        remove_stale_temporaries(path.parent / name)


def remove_parts(path) -> None:
    """Remove the checkpoint parts of ``path`` (and the temporaries of parts a killed run left)."""
    for p in part_paths(path):
        p.unlink(missing_ok=True)
    remove_stale_run_temporaries(path)


def write_checkpoint(path, rec: RunRecord, parameters: dict | None = None, seed=None) -> Path:
    """A checkpoint of a run in progress: what is new since the last write (series rows,
    snapshots) and the checkpoint, in a small part file beside the run file, written atomically
    (:func:`part_path`); or, when the parts have grown past :data:`COMPACT_FRACTION` of the run
    file (or there is no run file of this record yet), the whole run file (:func:`write_run`,
    which removes the parts). Its cost is that of the new data, not of the whole run.

    The run file alone stays a complete, consistent dem-run file (every reader reads it); after a
    kill it holds the run up to its last whole write, and :func:`read_record` (a resume) adds the
    parts written after it."""
    path = Path(path)
    st = _reusable(path, rec)
    if (
        st is None
        or st.get("compact")
        or st.get("token") is None
        or st["parts_bytes"] > COMPACT_FRACTION * st["stat"][2]
        or st["rows"] > len(rec.series["step"])
    ):
        return write_run(path, rec, parameters, seed)
    seq = int(st["parts"]) + 1
    row0 = int(st["rows"])
    new_snaps = sorted(s for s in rec.snapshots if s not in st["snapshots"])
    out = part_path(path, seq)
    with atomic_h5(out, kind=PART_KIND, parameters={"run_file": path.name, "seq": seq}) as f:
        f.attrs["fingerprint"] = rec.fingerprint
        f.attrs["base_token"] = st["token"]
        f.attrs["seq"] = seq
        f.attrs["row0"] = row0
        f.attrs["stop_reason"] = rec.stop_reason
        f.attrs["unsettled_phases"] = json.dumps(rec.unsettled)
        g = f.create_group("series")
        for k, v in rec.series_arrays(row0).items():
            g.create_dataset(k, data=-v if k == "stress" else v)
        sg = f.create_group("snapshots")
        for step in new_snaps:
            _write_snapshot(sg, step, rec.snapshots[step])
        if rec.checkpoint is not None:
            _write_checkpoint_group(f, rec.checkpoint)
    ck_bytes = sum(np.asarray(v).nbytes for v in rec.checkpoint["arrays"].values()) if rec.checkpoint else 0
    rec.stored = {
        **st,
        "rows": len(rec.series["step"]),
        "snapshots": frozenset(rec.snapshots),
        "parts": seq,
        # the data the parts add (their checkpoints are superseded by the next one)
        "parts_bytes": int(st["parts_bytes"]) + max(out.stat().st_size - ck_bytes, 0),
    }
    return out


def _write_checkpoint_group(f, checkpoint: dict) -> None:
    ck = f.create_group("checkpoint")
    ck.attrs["step"] = int(checkpoint["step"])
    ck.attrs["ordering"] = str(checkpoint.get("ordering", "code"))
    ck.attrs["protocol_state"] = json.dumps(checkpoint["protocol_state"])
    for k, v in checkpoint["arrays"].items():
        ck.create_dataset(k, data=np.asarray(v))


def _read_checkpoint_group(f, path, n: int) -> dict:
    ck = f["checkpoint"]
    if "step" not in ck.attrs:
        raise ResultFileError(f"{path}: /checkpoint has no attribute 'step'")
    ordering = str(ck.attrs.get("ordering", "code"))
    shapes = {"code": CHECKPOINT_SHAPES, "fast": FAST_CHECKPOINT_SHAPES}.get(ordering)
    if shapes is None:
        raise ResultFileError(f"{path}: /checkpoint has an unknown ordering {ordering!r}")
    _check_shapes(ck, shapes, {"N": n}, path, "checkpoint")
    state = _json_attr(f, path, "protocol_state", where=ck, want=dict)
    arrays = {}
    ck.visititems(lambda name, obj: arrays.__setitem__(name, obj[()]) if hasattr(obj, "shape") else None)
    return {"step": int(ck.attrs["step"]), "protocol_state": state, "arrays": arrays, "ordering": ordering}


def _apply_parts(path: Path, rec: RunRecord, token) -> tuple[int, int]:
    """Add the checkpoint parts of ``path`` written after its last whole write (same token, seq
    1, 2, ... without a gap, each starting at the row the previous one ended) to ``rec``. Returns
    (parts applied, their bytes). Parts of another write of the file (a run killed between its
    rewrite and the removal of the parts) are ignored."""
    if token is None:
        return 0, 0
    applied, nbytes = 0, 0
    for p in part_paths(path):
        try:
            with h5py.File(p, "r") as f:
                if (
                    f.attrs.get("kind") != PART_KIND
                    or f.attrs.get("base_token") != token
                    or f.attrs.get("fingerprint") != rec.fingerprint
                    or int(f.attrs.get("seq", -1)) != applied + 1
                    or int(f.attrs.get("row0", -1)) != len(rec.series["step"])
                ):
                    continue
                g = f["series"]
                cols = {k: g[k][()] for k in SERIES_KEYS}
                snaps = {}
                for h in f["snapshots"].values():
                    _check_snapshot(h, rec.packing.n, p)
                    snaps[int(h.attrs["step"])] = {
                        "time": float(h.attrs["time"]),
                        **{k: h[k][()] for k in ("cell", "positions", "velocities", "spins")},
                        "contacts": {k: v[()] for k, v in h["contacts"].items()},
                    }
                ck = _read_checkpoint_group(f, p, rec.packing.n) if "checkpoint" in f else rec.checkpoint
                reason = f.attrs.get("stop_reason", "")
                unsettled = _json_attr(f, p, "unsettled_phases", default=[], want=list)
        except (OSError, KeyError, ValueError, ResultFileError):
            break  # an unreadable part ends the chain: resume from the one before
        for k in SERIES_KEYS:
            rec.series[k].extend(-cols[k] if k == "stress" else cols[k])
        rec.snapshots.update(snaps)
        rec.checkpoint = ck
        rec.stop_reason = reason.decode() if isinstance(reason, bytes) else str(reason)
        rec.unsettled = unsettled
        applied += 1
        nbytes += p.stat().st_size
    return applied, nbytes


def _extendable(src, rows: int) -> bool:
    """The stored /series can take appended rows (chunked, unlimited, at least ``rows`` rows; files
    of older versions have chunks as small as their first write) and /packing and /snapshots exist."""
    if "packing" not in src or "snapshots" not in src or "series" not in src:
        return False
    for k in SERIES_KEYS:
        d = src["series"].get(k)
        if not isinstance(d, h5py.Dataset) or d.chunks is None or d.maxshape[0] is not None:
            return False
        if d.chunks[0] < SERIES_CHUNK // 4 or d.shape[0] < rows:
            return False
    return True


#: trailing shape of each /series dataset (all have the same number of rows T)
SERIES_SHAPES = {
    "step": (),
    "time": (),
    "cell": (2, 2),
    "stress": (2, 2),
    "n_contacts": (),
    "mean_overlap": (),
    "kinetic_energy": (),
    "phase": (),
}
#: shape of each snapshot dataset (N particles) and contact dataset (M contacts); "W" is the width
#: of the contact law's per-contact history (gransim.contacts.laws: 2 for the Hooke and Hertz laws,
#: 3 for epsd2/epsd, 4 for sds), read from the file and the same in every dataset that has it
SNAPSHOT_SHAPES = {"cell": (2, 2), "positions": ("N", 2), "velocities": ("N", 2), "spins": ("N",)}
CONTACT_SHAPES = {
    "i": ("M",),
    "j": ("M",),
    "shift": ("M", 2),
    "force": ("M", 2),
    "overlap": ("M",),
    "tangential_spring": ("M", "W"),
    "sliding": ("M",),
}
#: checkpoint arrays: shape in N particles and K neighbour-list entries
CHECKPOINT_SHAPES = {
    "positions": ("N", 2),
    "velocities": ("N", 2),
    "spins": ("N",),
    "forces": ("N", 2),
    "torques": ("N",),
    "box_lo": (2,),
    "box_hi": (2,),
    "x_hold": ("N", 2),
    "box_lo_hold": (2,),
    "box_hi_hold": (2,),
    "neighbours/a": ("K",),
    "neighbours/b": ("K",),
    "neighbours/shift": ("K", 2),
    "neighbours/owned_both": ("K",),
    "neighbours/xi": ("K", "W"),
    "virial": (4,),
}
#: the checkpoint arrays of the fast ordering (:meth:`gransim.dem.fast.FastCell.state_arrays`: the
#: particles in the sorted order and their permutation; the list's arrays are checked by its restore)
FAST_CHECKPOINT_SHAPES = {
    **{f"sorted/{k}": ("N",) for k in ("x", "y", "vx", "vy", "w", "fx", "fy", "t", "xh", "yh", "perm")},
    "virial": (4,),
}


def _attr(f, path, name):
    if name not in f.attrs:
        raise ResultFileError(f"{path}: no root attribute {name!r}: not a complete dem-run file (docs/schema_dem.md)")
    v = f.attrs[name]
    return v.decode() if isinstance(v, bytes) else v


def _json_attr(f, path, name, default=None, where=None, want=None):
    obj = f if where is None else where
    if name not in obj.attrs:
        if default is not None:
            return default
        raise ResultFileError(f"{path}: no attribute {name!r} on {obj.name}")
    text = obj.attrs[name]
    text = text.decode() if isinstance(text, bytes) else str(text)
    try:
        v = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ResultFileError(
            f"{path}: attribute {name!r} of {obj.name} is not valid JSON ({exc}): corrupt run file"
        ) from None
    if want is not None and not isinstance(v, want):
        raise ResultFileError(
            f"{path}: attribute {name!r} of {obj.name} holds a JSON {type(v).__name__}, expected a {want.__name__}"
        )
    return v


def _check_shapes(group, shapes: dict, sizes: dict, path, what: str):
    """Every dataset of ``shapes`` present (optional ones in ``sizes`` context) with the right shape."""
    for k, shp in shapes.items():
        if k not in group or not hasattr(group[k], "shape"):
            raise ResultFileError(f"{path}: {what}: dataset {group.name}/{k} is missing")
        got = group[k].shape
        want = []
        for d, e in enumerate(shp):
            if isinstance(e, str):
                if e not in sizes:
                    sizes[e] = got[d] if len(got) > d else -1
                e = sizes[e]
            want.append(e)
        if tuple(got) != tuple(want):
            raise ResultFileError(
                f"{path}: {what}: dataset {group.name}/{k} has shape {tuple(got)}, expected "
                f"{tuple(want)} ({', '.join(f'{a} = {b}' for a, b in sizes.items())}): truncated or "
                "corrupt run file"
            )


def _check_snapshot(h, n: int, path):
    for a in ("step", "time"):
        if a not in h.attrs:
            raise ResultFileError(f"{path}: snapshot {h.name} has no attribute {a!r}")
    _check_shapes(h, SNAPSHOT_SHAPES, {"N": n}, path, f"snapshot of step {int(h.attrs['step'])}")
    if "contacts" not in h:
        raise ResultFileError(f"{path}: snapshot {h.name} has no contacts group")
    _check_shapes(h["contacts"], CONTACT_SHAPES, {}, path, f"contacts of the snapshot of step {int(h.attrs['step'])}")


def _check_run_file(f, path) -> dict:
    """Structure of a dem-run file: root attributes, settings JSON, series lengths and shapes,
    snapshot shapes. Returns the decoded settings. Raises ResultFileError naming the dataset."""
    for name in ("fingerprint", "complete", "stop_reason"):
        _attr(f, path, name)
    settings = _json_attr(f, path, "settings", want=dict)
    for g in ("packing", "series", "snapshots"):
        if g not in f:
            raise ResultFileError(f"{path}: no /{g} group: not a complete dem-run file")
    if "radii" not in f["packing"]:
        raise ResultFileError(f"{path}: no /packing/radii")
    n = int(f["packing/radii"].shape[0]) if f["packing/radii"].ndim == 1 else -1
    if n < 1:
        raise ResultFileError(f"{path}: /packing/radii has shape {f['packing/radii'].shape}, expected (N,)")
    ser = f["series"]
    for k in SERIES_KEYS:
        if k not in ser:
            raise ResultFileError(f"{path}: dataset /series/{k} is missing")
    t = ser["step"].shape[0] if ser["step"].ndim == 1 else -1
    if t < 1:
        raise ResultFileError(f"{path}: dataset /series/step has shape {ser['step'].shape}, expected (T,) with T >= 1")
    for k, trail in SERIES_SHAPES.items():
        shp = ser[k].shape
        if len(shp) != 1 + len(trail) or tuple(shp[1:]) != trail:
            raise ResultFileError(f"{path}: dataset /series/{k} has shape {shp}, expected (T,) + {trail}")
        if shp[0] != t:
            raise ResultFileError(
                f"{path}: dataset /series/{k} has {shp[0]} rows, /series/step has {t}: truncated or corrupt run file"
            )
    for h in f["snapshots"].values():
        _check_snapshot(h, n, path)
    return settings


def _run_flags(f, path) -> dict:
    return {
        "complete": bool(_attr(f, path, "complete")),
        "stop_reason": str(_attr(f, path, "stop_reason")),
        "unsettled": _json_attr(f, path, "unsettled_phases", default=[], want=list),
        "output": _json_attr(f, path, "output_settings", default={}, want=dict) or None,
        "allow_unsettled": bool(f.attrs.get("allow_unsettled", False)),
    }


def read_record(path) -> RunRecord:
    """Read a run file back into a :class:`RunRecord` (used to resume).

    Checks the structure first (:class:`ResultFileError` naming the attribute or dataset for a
    missing attribute, invalid settings JSON, series of different lengths, snapshots or
    checkpoint arrays of the wrong shape). ``complete`` / ``stop_reason`` are returned as stored:
    see :func:`require_complete`.
    """
    with open_result(path, kind=KIND) as f:
        _check_run_file(f, path)
        fl = _run_flags(f, path)
        rec = RunRecord(
            packing=read_packing_group(f["packing"]),
            settings_text=str(_attr(f, path, "settings")),
            fingerprint=str(_attr(f, path, "fingerprint")),
            complete=fl["complete"],
            stop_reason=fl["stop_reason"],
            unsettled=fl["unsettled"],
            output=fl["output"],
            allow_unsettled=fl["allow_unsettled"],
        )
        for k in SERIES_KEYS:
            v = f["series"][k][()]
            rec.series[k] = list(-v if k == "stress" else v)  # back to the engine's compression-positive virial
        for h in f["snapshots"].values():
            step = int(h.attrs["step"])
            rec.snapshots[step] = {
                "time": float(h.attrs["time"]),
                **{k: h[k][()] for k in ("cell", "positions", "velocities", "spins")},
                "contacts": {k: v[()] for k, v in h["contacts"].items()},
            }
        if "checkpoint" in f:
            rec.checkpoint = _read_checkpoint_group(f, path, rec.packing.n)
        token = f.attrs.get("write_token")
        token = token.decode() if isinstance(token, bytes) else token
    file_rows, file_snaps = len(rec.series["step"]), frozenset(rec.snapshots)
    parts, nbytes = _apply_parts(Path(path), rec, token)
    rec.stored = {
        **_stored(path, token, file_rows, file_snaps),
        "rows": len(rec.series["step"]),
        "snapshots": frozenset(rec.snapshots),
        "parts": parts,
        "parts_bytes": nbytes,
    }
    return rec


def require_complete(
    record, path=None, hint: str = "pass allow_incomplete=True (CLI --allow-incomplete) to read it anyway"
):
    """Refuse an unfinished run: :class:`ResultFileError` naming the file, its ``stop_reason`` and ``hint``.

    ``record`` is anything with ``complete`` and ``stop_reason`` (:class:`RunRecord`,
    :class:`RunResult`); ``path`` defaults to ``record.path``.
    """
    if record.complete:
        return record
    path = path if path is not None else getattr(record, "path", "run file")
    why = record.stop_reason or "no stop_reason recorded"
    raise ResultFileError(f"{path}: incomplete run (complete = False): {why}; {hint}")


@dataclass(frozen=True)
class RunResult:
    """A finished (or stopped) DEM run as read from its file."""

    path: Path
    packing: Packing
    settings: dict
    series: dict
    snapshot_steps: tuple
    complete: bool
    stop_reason: str
    unsettled_phases: tuple = ()  # dicts (phase, name, step, reason) of phases that ended unsettled
    output_settings: dict | None = None  # series_every, snapshot_every, checkpoint_every (None: not stored)
    kind: str = KIND  # "dem-run" or "shear-run" (series of a shear run: box, shear_strain; no phase)

    def strain(self) -> np.ndarray:
        """Logarithmic strains ln(L/L0) of the two axes, (T, 2) (compression negative)."""
        L = np.stack([self.series["cell"][:, 0, 0], self.series["cell"][:, 1, 1]], axis=1)
        L0 = np.array([self.packing.cell[0, 0], self.packing.cell[1, 1]])
        return np.log(L / L0)


def read_run(path) -> RunResult:
    """Series, packing and settings of a run file (``series["stress"]`` tension positive, N/m).

    The structure is checked as by :func:`read_record`; ``complete`` and ``stop_reason`` are
    returned as stored (an unfinished run is read: callers that need a finished one call
    :func:`require_complete`). A shear run (kind "shear-run", docs/shear.md) is read the same way:
    its ``series`` has ``cell`` (T, 2, 2) = [[lx, xy], [0, ly]] from ``/series/box``, beside
    ``box``, ``shear_strain``, ``stress``, ``n_contacts``, ``kinetic_energy`` (no ``phase``)."""
    with _open_run(path) as f:
        if f.attrs.get("kind") == SHEAR_KIND:
            return _read_shear_run(f, path)
        settings = _check_run_file(f, path)
        fl = _run_flags(f, path)
        series = {k: f["series"][k][()] for k in SERIES_KEYS}
        return RunResult(
            path=Path(path),
            packing=read_packing_group(f["packing"]),
            settings=settings,
            series=series,
            snapshot_steps=tuple(int(h.attrs["step"]) for h in f["snapshots"].values()),
            complete=fl["complete"],
            stop_reason=fl["stop_reason"],
            unsettled_phases=tuple(fl["unsettled"]),
            output_settings=fl["output"],
        )


def _open_run(path):
    """The run file ``path`` open for reading, of a kind in :data:`RUN_KINDS` (ResultFileError otherwise)."""
    f = open_result(path)
    kind = f.attrs.get("kind")
    if kind not in RUN_KINDS:
        f.close()
        raise ResultFileError(f"{path}: holds {kind!r}, expected {KIND!r} or {SHEAR_KIND!r}")
    return f


#: trailing shapes of the /series datasets of a shear run, and of its snapshots' datasets
SHEAR_SERIES_SHAPES = {
    "step": (),
    "time": (),
    "box": (5,),
    "shear_strain": (),
    "stress": (2, 2),
    "n_contacts": (),
    "kinetic_energy": (),
}
SHEAR_SNAPSHOT_SHAPES = {"cell": (2, 2), "positions": ("N", 2), "velocities": ("N", 2), "spins": ("N",)}


def _check_shear_file(f, path) -> int:
    """Structure of a shear-run file (docs/shear.md); returns N. ResultFileError naming the dataset."""
    for name in ("complete", "stop_reason", "settings"):
        _attr(f, path, name)
    for g in ("packing", "series", "snapshots"):
        if g not in f:
            raise ResultFileError(f"{path}: no /{g} group: not a complete shear-run file (docs/shear.md)")
    if "radii" not in f["packing"] or f["packing/radii"].ndim != 1:
        raise ResultFileError(f"{path}: no /packing/radii of shape (N,)")
    n = int(f["packing/radii"].shape[0])
    ser = f["series"]
    t = None
    for k, trail in SHEAR_SERIES_SHAPES.items():
        if k not in ser:
            raise ResultFileError(f"{path}: dataset /series/{k} is missing")
        shp = ser[k].shape
        if len(shp) != 1 + len(trail) or tuple(shp[1:]) != trail or shp[0] < 1:
            raise ResultFileError(f"{path}: dataset /series/{k} has shape {shp}, expected (T,) + {trail}")
        t = shp[0] if t is None else t
        if shp[0] != t:
            raise ResultFileError(
                f"{path}: dataset /series/{k} has {shp[0]} rows, /series/step has {t}: truncated or corrupt run file"
            )
    for h in f["snapshots"].values():
        if "step" not in h.attrs:
            raise ResultFileError(f"{path}: snapshot {h.name} has no attribute 'step'")
        _check_shapes(h, SHEAR_SNAPSHOT_SHAPES, {"N": n}, path, f"snapshot of step {int(h.attrs['step'])}")
    return n


def _read_shear_run(f, path) -> RunResult:
    _check_shear_file(f, path)
    fl = _run_flags(f, path)
    series = {k: f["series"][k][()] for k in SHEAR_SERIES_SHAPES}
    box = series["box"]
    cell = np.zeros((box.shape[0], 2, 2))
    cell[:, 0, 0], cell[:, 0, 1], cell[:, 1, 1] = box[:, 0], box[:, 2], box[:, 1]
    series["cell"] = cell
    return RunResult(
        path=Path(path),
        packing=read_packing_group(f["packing"]),
        settings=_json_attr(f, path, "settings", want=dict),
        series=series,
        snapshot_steps=tuple(sorted(int(h.attrs["step"]) for h in f["snapshots"].values())),
        complete=fl["complete"],
        stop_reason=fl["stop_reason"],
        kind=SHEAR_KIND,
    )


@dataclass(frozen=True)
class Snapshot:
    """One snapshot: positions (N,2), velocities (N,2), spins (N,), cell (2,2), contacts dict
    (i, j, shift, force (on j), overlap, tangential_spring, sliding)."""

    step: int
    time: float
    cell: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    radii: np.ndarray
    contacts: dict


def read_snapshot(path, step: int | None = None) -> Snapshot:
    """The snapshot at ``step`` (None = the last one). A shear run's snapshot (no contact list, no
    time attribute) has the contacts i, j, shift of its overlapping disks
    (:func:`gransim.contacts.find_neighbours`, skin 0: the engine's contact test) and the time of
    its step from the settings' dt."""
    with _open_run(path) as f:
        if f.attrs.get("kind") == SHEAR_KIND:
            return _read_shear_snapshot(f, path, step)
        g = f["snapshots"]
        names = sorted(g.keys())
        if not names:
            raise ResultFileError(f"{path}: no snapshots")
        if step is None:
            name = names[-1]
        else:
            name = f"s{int(step):010d}"
            if name not in g:
                have = [int(n[1:]) for n in names]
                raise ResultFileError(f"{path}: no snapshot at step {step} (have {have[:5]}...{have[-3:]})")
        h = g[name]
        if "packing" not in f or "radii" not in f["packing"]:
            raise ResultFileError(f"{path}: no /packing/radii")
        _check_snapshot(h, int(f["packing/radii"].shape[0]), path)
        return Snapshot(
            step=int(h.attrs["step"]),
            time=float(h.attrs["time"]),
            cell=h["cell"][()],
            positions=h["positions"][()],
            velocities=h["velocities"][()],
            spins=h["spins"][()],
            radii=f["packing/radii"][()],
            contacts={k: v[()] for k, v in h["contacts"].items()},
        )


def _read_shear_snapshot(f, path, step) -> Snapshot:
    _check_shear_file(f, path)
    g = f["snapshots"]
    by_step = {int(h.attrs["step"]): name for name, h in g.items()}
    if not by_step:
        raise ResultFileError(f"{path}: no snapshots")
    have = sorted(by_step)
    if step is None:
        step = have[-1]
    if int(step) not in by_step:
        raise ResultFileError(f"{path}: no snapshot at step {step} (have {have[:5]}...{have[-3:]})")
    h = g[by_step[int(step)]]
    x, C, r = h["positions"][()], h["cell"][()], f["packing/radii"][()]
    nl = find_neighbours(x, r, C, skin=0.0)
    dt = _json_attr(f, path, "settings", want=dict).get("dem", {}).get("dt", float("nan"))
    return Snapshot(
        step=int(step),
        time=float(step) * float(dt),
        cell=C,
        positions=x,
        velocities=h["velocities"][()],
        spins=h["spins"][()],
        radii=r,
        contacts={"i": nl.i, "j": nl.j, "shift": nl.shift},
    )


def snapshot_to_vtu(path, step: int | None, out, allow_incomplete: bool = False) -> Path:
    """Write one snapshot as a ParaView .vtu (points with radius, velocity, spin, contact count).

    An unfinished run (``complete`` False) is refused unless ``allow_incomplete``."""
    run = read_run(path)
    if not allow_incomplete:
        require_complete(run, path)
    s = read_snapshot(path, step)
    z = np.bincount(s.contacts["i"], minlength=len(s.radii)) + np.bincount(s.contacts["j"], minlength=len(s.radii))
    return particles_to_vtu(
        out,
        s.positions,
        s.radii,
        point_data={"velocity": s.velocities, "spin": s.spins, "contacts": z.astype(float)},
        cell=s.cell,
    )


def plot_stress_strain(path, out, allow_incomplete: bool = False) -> Path:
    """Fig. 7b of Kuhn (1997): stress ratio sigma_22/sigma_11 and deviator (sigma_22 - sigma_11)/2
    against the axial strain -eps_22 (compression phase; compression-positive stresses).

    An unfinished run (``complete`` False) is refused unless ``allow_incomplete``; its plot then
    says so in the title, with the stop reason."""
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    run = read_run(path)
    if not allow_incomplete:
        require_complete(run, path)
    if run.kind == SHEAR_KIND:
        return _plot_shear(run, path, out, plt)
    sel = run.series["phase"] == 1
    if not np.any(sel):
        sel = np.ones_like(run.series["phase"], bool)
    eps = run.strain()[sel]
    e22 = -(eps[:, 1] - eps[0, 1])
    st = -run.series["stress"][sel]  # plotted compression positive, as in the paper
    s11, s22 = st[:, 0, 0], st[:, 1, 1]
    fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
    ax[0].plot(e22 * 100, s22 / s11)
    ax[0].set_xlabel(r"axial strain $-\varepsilon_{22}$ (%)")
    ax[0].set_ylabel(r"$\bar\sigma_{22}/\bar\sigma_{11}$")
    ax[1].plot(e22 * 100, 0.5 * (s22 - s11), label="deviator")
    ax[1].plot(e22 * 100, s11, label=r"$\bar\sigma_{11}$")
    ax[1].set_xlabel(r"axial strain $-\varepsilon_{22}$ (%)")
    ax[1].set_ylabel("stress (N/m)")
    ax[1].legend()
    title = f"biaxial compression, {run.packing.n} disks ({Path(path).name})"
    if not run.complete:
        why = run.stop_reason if len(run.stop_reason) < 90 else run.stop_reason[:87] + "..."
        title = f"INCOMPLETE RUN: {why}\n" + title
    elif run.unsettled_phases:
        title = f"UNSETTLED: {', '.join(u['name'] for u in run.unsettled_phases)} (allow_unsettled)\n" + title
    fig.suptitle(title, color="red" if not run.complete or run.unsettled_phases else "black")
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out, suffix=out.suffix) as tmp:
        fig.savefig(tmp, dpi=120, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
    return out


def _plot_shear(run: RunResult, path, out, plt) -> Path:
    """Shear stress sigma_xy and normal stress -sigma_yy (tension positive) against gamma."""
    gam, st = run.series["shear_strain"], run.series["stress"]
    fig, ax = plt.subplots(figsize=(5, 3.5))
    ax.plot(gam, st[:, 0, 1], label=r"$\sigma_{xy}$")
    ax.plot(gam, -st[:, 1, 1], label=r"$-\sigma_{yy}$")
    ax.set_xlabel(r"shear strain $\gamma$")
    ax.set_ylabel("stress (N/m, tension positive)")
    ax.legend()
    title = f"simple shear, {run.packing.n} disks ({Path(path).name})"
    if not run.complete:
        why = run.stop_reason if len(run.stop_reason) < 90 else run.stop_reason[:87] + "..."
        title = f"INCOMPLETE RUN: {why}\n" + title
    fig.suptitle(title, color="red" if not run.complete else "black", fontsize=9)
    fig.tight_layout()
    out = Path(out)
    with atomic_path(out, suffix=out.suffix) as tmp:
        fig.savefig(tmp, dpi=120, format=out.suffix.lstrip(".") or "png")
    plt.close(fig)
    return out
