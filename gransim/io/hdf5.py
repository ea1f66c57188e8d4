"""HDF5 results files (schema in docs/schema.md), written atomically.

Every file gransim writes has root attributes ``format = "gransim"``, ``schema_version``,
``kind`` (what the file holds, e.g. "packing", "rve-study", "dem-run") and the provenance
record of :func:`gransim.io.provenance.provenance`.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from pathlib import Path

import h5py
import numpy as np

from ..errors import InputError, ResultFileError
from ..geometry import Packing
from .provenance import provenance

FORMAT = "gransim"
SCHEMA_VERSION = 1


def _fsync(path, directory: bool = False) -> None:
    """fsync a file (or a directory entry); silently skipped where the OS does not allow it."""
    try:
        fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path next to ``path``; rename it onto ``path`` only on success.

    A crash inside the block leaves no file at ``path`` (and removes the temporary),
    so a half-written file never looks complete. The temporary is flushed to disk (fsync) before
    the rename, and the directory after it, so a power cut cannot leave a renamed but empty file.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or ".tmp", dir=path.parent)
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; results are ordinary files
    tmp = Path(tmp)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, path)
        _fsync(path.parent, directory=True)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def atomic_h5(path, kind: str, parameters: dict | None = None, seed=None, liggghts: bool = False, lammps: bool = False):
    """Open a new HDF5 file for writing, atomically; root attributes carry the provenance
    (:func:`gransim.io.provenance.provenance`; ``liggghts``/``lammps``: also the version that
    code's binary reports about itself).

    Usage::

        with atomic_h5("out.h5", kind="packing", parameters={...}, seed=3) as f:
            f.create_dataset(...)
    """
    with atomic_path(path, suffix=".h5.tmp") as tmp:
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["kind"] = kind
            for k, v in provenance(parameters, seed, liggghts, lammps).items():
                f.attrs[k] = v
            yield f


def open_result(path, kind: str | None = None) -> h5py.File:
    """Open a gransim results file for reading; checks that it is ours (and of ``kind``).

    Raises :class:`ResultFileError` for a missing, unreadable or foreign file.
    """
    path = Path(path)
    if not path.exists():
        raise ResultFileError(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise ResultFileError(f"{path}: not a readable HDF5 file ({exc})") from None
    try:
        fmt = f.attrs.get("format")
        fmt = fmt.decode() if isinstance(fmt, bytes) else fmt
    except (OSError, TypeError, ValueError):  # an attribute h5py cannot read
        fmt = None
    if fmt != FORMAT:
        f.close()
        raise ResultFileError(f"{path}: not a gransim results file (no format='gransim' attribute)")
    if kind is not None and f.attrs.get("kind") != kind:
        got = f.attrs.get("kind")
        f.close()
        raise ResultFileError(f"{path}: holds {got!r}, expected {kind!r}")
    return f


def write_packing_group(group: h5py.Group, packing: Packing) -> None:
    """Store a packing in ``group``: datasets positions (N,2), radii (N,), cell (2,2); attrs."""
    group.create_dataset("positions", data=packing.positions)
    group.create_dataset("radii", data=packing.radii)
    group.create_dataset("cell", data=packing.cell)
    group.attrs["density"] = packing.density
    group.attrs["metadata"] = json.dumps(dict(packing.metadata), sort_keys=True, default=str)
    group.attrs["units"] = "m, kg/m^2 (density = mass per area)"


def _read_dataset(group: h5py.Group, name: str, where: str, ndim: int) -> np.ndarray:
    obj = group.get(name)
    if not isinstance(obj, h5py.Dataset):
        raise ResultFileError(f"{where}/{name}: expected a dataset, found a {type(obj).__name__}")
    if obj.dtype.kind not in "biuf":
        raise ResultFileError(f"{where}/{name}: expected numbers, found dtype {obj.dtype}")
    if obj.ndim != ndim:
        raise ResultFileError(f"{where}/{name}: expected {ndim} dimension(s), found shape {obj.shape}")
    return obj[()]


def read_packing_group(group: h5py.Group) -> Packing:
    """Inverse of :func:`write_packing_group`.

    Raises :class:`ResultFileError` naming the file, the dataset or attribute and what is wrong
    (missing or malformed datasets, a ``metadata`` attribute that is not a JSON object, values
    a :class:`Packing` refuses, such as radii <= 0 or a degenerate cell).
    """
    where = f"{group.file.filename}:{group.name}"
    missing = [k for k in ("positions", "radii", "cell") if k not in group]
    if missing:
        raise ResultFileError(f"{where}: no packing here (missing {missing})")
    positions = _read_dataset(group, "positions", where, 2)
    radii = _read_dataset(group, "radii", where, 1)
    cell = _read_dataset(group, "cell", where, 2)
    raw = group.attrs.get("metadata", "{}")
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8", "replace")
    try:
        metadata = json.loads(raw) if isinstance(raw, str) else None
    except json.JSONDecodeError as exc:
        raise ResultFileError(f"{where}: attribute 'metadata' is not valid JSON ({exc})") from None
    if not isinstance(metadata, dict):
        raise ResultFileError(
            f"{where}: attribute 'metadata' must hold a JSON object, got "
            f"{type(metadata).__name__ if isinstance(raw, str) else type(raw).__name__}"
        )
    density = group.attrs.get("density", 2650.0)
    try:
        density = float(density)
    except (TypeError, ValueError):
        raise ResultFileError(f"{where}: attribute 'density' is not a number ({density!r})") from None
    try:
        return Packing(positions=positions, radii=radii, cell=cell, density=density, metadata=metadata)
    except InputError as exc:
        raise ResultFileError(f"{where}: not a valid packing: {exc}") from None


def save_packing(path, packing: Packing, parameters: dict | None = None, seed=None) -> Path:
    """Write one packing to ``path`` (group ``/packing``), atomically, with provenance."""
    if parameters is None:
        parameters = dict(packing.metadata)
    if seed is None:
        seed = packing.metadata.get("seed")
    with atomic_h5(path, kind="packing", parameters=parameters, seed=seed) as f:
        write_packing_group(f.create_group("packing"), packing)
    return Path(path)


def load_packing(path, group: str = "packing") -> Packing:
    """Read a packing written by :func:`save_packing` (or any group holding one)."""
    with open_result(path) as f:
        if group not in f or not isinstance(f[group], h5py.Group):
            raise ResultFileError(f"{path}: no group {group!r} (has {sorted(f.keys())})")
        return read_packing_group(f[group])


def read_provenance(path) -> dict:
    """Root attributes of a results file as a dict (JSON fields decoded)."""
    with open_result(path) as f:
        out = {}
        for k, v in f.attrs.items():
            if isinstance(v, bytes):
                v = v.decode()
            if k in ("parameters", "seed") and isinstance(v, str):
                try:
                    v = json.loads(v)
                except json.JSONDecodeError:
                    pass
            out[k] = v.item() if isinstance(v, np.generic) else v
        return out
