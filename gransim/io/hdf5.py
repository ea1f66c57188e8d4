"""HDF5 results files (schema in docs/schema.md), written atomically.

Every file gransim writes has root attributes ``format = "gransim"``, ``schema_version``,
``kind`` (what the file holds, e.g. "packing", "rve-study", "dem-run") and the provenance
record of :func:`gransim.io.provenance.provenance`.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import json
import os
import re
import tempfile
import time
from pathlib import Path

import h5py
import numpy as np

from ..errors import GransimError, InputError, ResultFileError
from ..geometry import Packing
from ..progress import check_interrupt
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


#: errno values of a full disk, an exceeded quota, a file over the size limit
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)
_HDF5_ERRNO = re.compile(r"errno = (\d+)")


class OutputWriteError(OSError):
    """A result could not be written (disk full, quota exceeded, file too large, I/O error...).

    One line naming the file and the cause; nothing partial is left at the target (the temporary
    file was removed, a previous file of that name is unchanged). ``errno`` is the system's."""

    def __init__(self, path, err: int | None, cause: str):
        super().__init__(err, cause, str(path))
        self.path = Path(path)
        self.cause = cause

    def __str__(self) -> str:
        return (
            f"cannot write {self.path}: {self.cause}; nothing was written (the temporary file was removed; "
            "a previous file of that name is unchanged)"
        )


def _write_errno(exc: BaseException) -> int | None:
    """The errno of a failed write: an OSError's, or the one HDF5 quotes in its message
    ("file write failed: ... errno = 28, ...", also inside h5py's RuntimeErrors)."""
    err = getattr(exc, "errno", None)
    if isinstance(exc, OSError) and err and err in DISK_FULL_ERRNOS:
        return err
    m = _HDF5_ERRNO.search(str(exc))
    if m and int(m.group(1)) in DISK_FULL_ERRNOS:
        return int(m.group(1))
    return err if isinstance(exc, OSError) and not isinstance(exc, GransimError) else None


def _as_write_error(path, exc: BaseException) -> OutputWriteError | None:
    """The one-line error of a failed write of ``path`` (None: not a write failure of the system)."""
    if isinstance(exc, (GransimError, OutputWriteError)) or not isinstance(exc, (OSError, RuntimeError)):
        return None
    err = _write_errno(exc)
    if err is None:
        return None
    cause = os.strerror(err).lower() if err else "write failed"
    if err in DISK_FULL_ERRNOS:
        cause += f" ({errno.errorcode.get(err, err)}): free space or write elsewhere"
    return OutputWriteError(path, err, cause)


#: temporaries of :func:`atomic_path` are ``.<name>.<pid>-<8 random characters><suffix>``; before
#: the pid was part of the name they were ``.<name>.<8 random characters><suffix>``
_TMP_RANDOM = "[a-z0-9_]{8}"
#: a temporary without a pid in its name is stale when no HDF5 writer holds its lock and it has
#: not changed for this long (s)
LEGACY_TMP_AGE_S = 60.0


def _pid_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, another user's
        return True
    return True


def _locked_by_writer(path: Path) -> bool:
    """True when another open file holds an exclusive flock on ``path`` (HDF5 holds one while it
    writes a file)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except OSError as exc:
        return exc.errno in (errno.EAGAIN, errno.EWOULDBLOCK, errno.EACCES)
    finally:
        os.close(fd)  # also releases our probe lock
    return False


def stale_temporaries(path) -> list[Path]:
    """Temporaries of :func:`atomic_path` for ``path`` left by a process that died (SIGKILL, power
    cut) before it could remove them: those whose pid (in the name) is no longer running; a
    temporary of the older naming (no pid) when no writer holds its lock and it has not changed for
    :data:`LEGACY_TMP_AGE_S`. A live process's temporary is never listed."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    pat = re.compile(rf"^\.{re.escape(path.name)}\.(?:(\d+)-)?{_TMP_RANDOM}(\..*)?$")
    out = []
    try:
        names = os.listdir(parent)
    except OSError:
        return out
    now = time.time()
    for name in names:
        m = pat.match(name)
        if not m or not (name.endswith(".tmp") or m.group(2)):
            continue
        p = parent / name
        if m.group(1) is not None:
            if _pid_alive(int(m.group(1))):
                continue
        else:
            try:
                if now - p.stat().st_mtime < LEGACY_TMP_AGE_S:
                    continue
            except OSError:
                continue
            if _locked_by_writer(p):
                continue
        out.append(p)
    return out


def remove_stale_temporaries(path) -> list[Path]:
    """Remove :func:`stale_temporaries` of ``path``; returns the files removed."""
    done = []
    for p in stale_temporaries(path):
        try:
            p.unlink()
            done.append(p)
        except FileNotFoundError:
            pass
        except OSError:
            continue
    return done


@contextlib.contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path next to ``path``; rename it onto ``path`` only on success.

    A crash inside the block leaves no file at ``path`` (and removes the temporary),
    so a half-written file never looks complete. The temporary is flushed to disk (fsync) before
    the rename, and the directory after it, so a power cut cannot leave a renamed but empty file.

    The temporary is ``.<name>.<pid>-<random><suffix>``: temporaries of ``path`` left by a killed
    process (SIGKILL) are removed on the next write of ``path`` (:func:`remove_stale_temporaries`).
    A write that fails for lack of space (or any other refusal of the system) raises
    :class:`OutputWriteError`, one line naming the file. A SIGINT or SIGTERM received during the
    write (:mod:`gransim.progress`) abandons it before the rename (:class:`~gransim.progress.Interrupted`).
    """

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    remove_stale_temporaries(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.{os.getpid()}-", suffix=suffix or ".tmp", dir=path.parent)
    except OSError as exc:
        werr = _as_write_error(path, exc)
        if werr is None:
            raise
        raise werr from None
    os.close(fd)
    umask = os.umask(0)
    os.umask(umask)
    tmp = Path(tmp)
    try:
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; results are ordinary files
        yield tmp
        check_interrupt()
        _fsync(tmp)
        os.replace(tmp, path)
        _fsync(path.parent, directory=True)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        werr = _as_write_error(path, exc)
        if werr is None:
            raise
        raise werr from None


def atomic_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_path`): a reader sees the old
    file or the whole new one, never a part. Returns ``path``."""
    with atomic_path(path) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return Path(path)


@contextlib.contextmanager
def atomic_h5(path, kind: str, parameters: dict | None = None, seed=None, liggghts: bool = False, lammps: bool = False):
    """Open a new HDF5 file for writing, atomically; root attributes carry the provenance
    (:func:`gransim.io.provenance.provenance`; ``liggghts``/``lammps``: also the version that
    code's binary reports about itself).

    Usage::

        with atomic_h5("out.h5", kind="packing", parameters={...}, seed=3) as f:
            f.create_dataset(...)

    The file is assembled in memory and written in one piece: a full disk raises
    :class:`OutputWriteError` naming ``path``, the temporary is removed and nothing is left at
    ``path`` (a previous file there is unchanged).
    """
    with atomic_path(path, suffix=".h5.tmp") as tmp:
        # the file is built in memory (HDF5's core driver) and its bytes written by Python: a full
        # disk is then an ordinary failed write. HDF5 writing to a full disk itself leaves objects it
        # can neither flush nor close, and the interpreter crashes (segmentation fault) at the
        # latest when they are deallocated
        f = h5py.File(str(tmp), "w", driver="core", backing_store=False)
        try:
            f.attrs["format"] = FORMAT
            f.attrs["schema_version"] = SCHEMA_VERSION
            f.attrs["kind"] = kind
            for k, v in provenance(parameters, seed, liggghts, lammps).items():
                f.attrs[k] = v
            yield f
            f.flush()
            image = f.id.get_file_image()
        finally:
            f.close()
        with open(tmp, "wb") as fh:
            fh.write(image)
        del image


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
