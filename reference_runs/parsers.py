"""Parsers of LIGGGHTS 3.8.0 and LAMMPS output: the log's thermo tables, ``dump custom`` and ``dump local``.

Both codes write the same log and dump formats (checked on LAMMPS 29 Sep 2021 - Update 2: the
banner ``LAMMPS (29 Sep 2021 - Update 2)``, ``Step ...`` headers, ``Loop time of ...``, ``ERROR:``
and ``WARNING:`` lines with the source location appended); :attr:`LogFile.engine` says which
code wrote a log.

Everything is read into plain numpy arrays held by small frozen dataclasses. Numbers are
read as float64; decks should print them with ``%.17g`` (``thermo_modify format float
%.17g``, ``dump_modify ... format`` with one ``%.17g`` per column) so that they round-trip
exactly. The box bounds of dumps are printed with 6 digits whatever the format (shared
notes): take the box from thermo columns (``lx ly xlo ...``) when precision matters.

No sign or unit conversion happens here; see :mod:`reference_runs.conventions`.
"""

from __future__ import annotations

import re
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.errors import ResultFileError

from .engines import engine_of_log

_LOOP = re.compile(r"^Loop time of ")
_LOST = re.compile(r"Lost atoms", re.IGNORECASE)


@dataclass(frozen=True)
class LogLine:
    """One line of a log: 1-based line number and text (no newline)."""

    lineno: int
    text: str

    def __str__(self) -> str:
        return f"{self.lineno}: {self.text}"


@dataclass(frozen=True, eq=False)
class ThermoRun:
    """The thermo table of one ``run`` command.

    Attributes
    ----------
    columns : column names as printed in the header (``Step``, ``Atoms``, ``p[1]``, ...).
        ``thermo_style custom`` prints ``c_p[1]`` as ``p[1]``; :meth:`column` accepts both.
    data : (T, K) float64, one row per thermo output.
    complete : True when the run's ``Loop time of`` line was reached.
    header_line : 1-based line number of the header in the log.
    """

    columns: tuple
    data: np.ndarray
    complete: bool
    header_line: int

    def column(self, name: str) -> np.ndarray:
        """Column ``name`` (T,); ``c_X``, ``v_X``, ``f_X`` prefixes and case are ignored."""
        key = _column_key(name)
        for k, c in enumerate(self.columns):
            if _column_key(c) == key:
                return self.data[:, k]
        raise KeyError(f"thermo column {name!r} not in {list(self.columns)}")

    __getitem__ = column

    @property
    def steps(self) -> np.ndarray:
        """Time step numbers (T,) int64."""
        return self.column("Step").astype(np.int64)

    def __len__(self) -> int:
        return self.data.shape[0]


def _column_key(name: str) -> str:
    name = name.strip().lower()
    if len(name) > 2 and name[1] == "_" and name[0] in "cvf":
        name = name[2:]
    return name


@dataclass(frozen=True, eq=False)
class LogFile:
    """A parsed ``log.lammps``.

    Attributes
    ----------
    path : the file read (None when parsed from text).
    version : version from the banner (``LIGGGHTS-PUBLIC 3.8.0``, ``LAMMPS 29 Sep 2021 - Update 2``)
        or None.
    runs : thermo tables, one per ``run`` (``run 0`` included), in order.
    errors : lines starting with ``ERROR`` (``ERROR:`` or ``ERROR on proc N:``).
    warnings : lines starting with ``WARNING``.
    lost_atoms : a ``Lost atoms`` line was printed, or the ``Atoms`` column dropped within a run.
    """

    path: Path | None
    version: str | None
    runs: tuple
    errors: tuple
    warnings: tuple
    lost_atoms: bool
    n_lines: int
    engine: str | None = None  # "liggghts", "lammps" (from the banner) or None


def _floats(line: str, k: int):
    parts = line.split()
    if len(parts) != k:
        return None
    try:
        return [float(p) for p in parts]
    except ValueError:
        return None


def parse_log(source) -> LogFile:
    """Parse a LIGGGHTS or LAMMPS log (path or the text itself) into thermo runs, errors and warnings.

    A thermo header is a line whose first word is ``Step`` (``thermo_style custom step ...``
    must start with ``step``); the rows that follow are the lines with the header's number
    of numeric fields (interleaved ``WARNING`` lines are kept apart) until ``Loop time of``.
    A run cut short by an error has ``complete = False``.
    """
    if isinstance(source, Path) or (
        isinstance(source, str) and source and "\n" not in source and Path(source).is_file()
    ):
        path = Path(source)
        try:
            text = path.read_text(errors="replace")
        except OSError as exc:
            raise ResultFileError(f"{path}: cannot read log ({exc})") from None
    else:
        path, text = None, str(source)
    lines = text.splitlines()
    version, engine = None, None
    runs, errors, warnings = [], [], []
    lost = False
    cur_cols, cur_rows, cur_line = None, [], 0

    def close(complete):
        nonlocal cur_cols, cur_rows
        if cur_cols is not None:
            data = np.array(cur_rows, dtype=np.float64).reshape(len(cur_rows), len(cur_cols))
            data.flags.writeable = False
            runs.append(ThermoRun(tuple(cur_cols), data, complete, cur_line))
        cur_cols, cur_rows = None, []

    for n, line in enumerate(lines, start=1):
        s = line.strip()
        if version is None and s.startswith(("LIGGGHTS", "LAMMPS")):
            eng, v = engine_of_log(s)
            if eng is not None:
                version, engine = v, eng.name
        if s.startswith("ERROR"):
            errors.append(LogLine(n, s))
            if _LOST.search(s):
                lost = True
            continue
        if s.startswith("WARNING"):
            warnings.append(LogLine(n, s))
            if _LOST.search(s):
                lost = True
            continue
        if cur_cols is not None:
            if _LOOP.match(s):
                close(True)
                continue
            row = _floats(s, len(cur_cols))
            if row is not None:
                cur_rows.append(row)
                continue
        words = s.split()
        if words and words[0] == "Step" and len(words) > 1 and _floats(s, len(words)) is None:
            close(False)
            cur_cols, cur_rows, cur_line = words, [], n
    close(False)
    for run in runs:
        try:
            atoms = run.column("Atoms")
        except KeyError:
            continue
        if atoms.size and np.any(atoms < atoms[0]):
            lost = True
    return LogFile(path, version, tuple(runs), tuple(errors), tuple(warnings), lost, len(lines), engine)


# --------------------------------------------------------------------------- dumps
@dataclass(frozen=True, eq=False)
class DumpFrame:
    """One frame of a ``dump custom`` or ``dump local`` file.

    Attributes
    ----------
    step : time step.
    box : (3, 2) float64 box bounds (lo, hi) per axis, as printed (6 digits in 3.8.0).
    tilt : (3,) xy xz yz tilt factors of a triclinic box, or None.
    boundary : the boundary flags of the BOX BOUNDS line (e.g. ``pp pp pp``).
    columns : read-only mapping name -> (n,) array. ``id``, ``type``, ``id1``, ``id2`` are int64,
        everything else float64. ``dump custom`` frames are sorted by ``id``.
    """

    step: int
    box: np.ndarray
    tilt: np.ndarray | None
    boundary: str
    columns: types.MappingProxyType

    def __getitem__(self, name: str) -> np.ndarray:
        try:
            return self.columns[name]
        except KeyError:
            raise KeyError(f"dump column {name!r} not in {list(self.columns)}") from None

    @property
    def names(self) -> tuple:
        return tuple(self.columns)

    def __len__(self) -> int:
        return len(next(iter(self.columns.values()))) if self.columns else 0

    def array(self, *names) -> np.ndarray:
        """Columns stacked as (n, len(names)) float64."""
        return np.column_stack([np.asarray(self[nm], float) for nm in names])


_INT_COLUMNS = {"id", "type", "id1", "id2", "mol"}


def _read_frames(path, count_item: str, columns_item: str, names=None, sort_by=()):
    path = Path(path)
    try:
        lines = path.read_text().splitlines()
    except OSError as exc:
        raise ResultFileError(f"{path}: cannot read dump ({exc})") from None
    frames = []
    k = 0
    nl = len(lines)

    def bad(msg):
        return ResultFileError(f"{path}:{k + 1}: {msg}")

    while k < nl:
        if not lines[k].strip():
            k += 1
            continue
        if lines[k].strip() != "ITEM: TIMESTEP":
            raise bad(f"expected 'ITEM: TIMESTEP', got {lines[k][:60]!r}")
        try:
            step = int(lines[k + 1])
            if lines[k + 2].strip() != f"ITEM: {count_item}":
                raise bad(f"expected 'ITEM: {count_item}' (is this the right kind of dump?)")
            n = int(lines[k + 3])
            bb = lines[k + 4].split()
            if bb[:3] != ["ITEM:", "BOX", "BOUNDS"]:
                raise bad("expected 'ITEM: BOX BOUNDS'")
            words = bb[3:]
            triclinic = words[:3] == ["xy", "xz", "yz"]
            boundary = " ".join(words[3:] if triclinic else words)
            rows = [[float(v) for v in lines[k + 5 + a].split()] for a in range(3)]
            box = np.array([r[:2] for r in rows])
            tilt = np.array([r[2] for r in rows]) if triclinic else None
            head = lines[k + 8].split()
            if head[:2] != ["ITEM:", columns_item]:
                raise bad(f"expected 'ITEM: {columns_item} ...'")
        except (IndexError, ValueError):
            raise bad("truncated or malformed frame header") from None
        cols = head[2:]
        if names is not None:
            if len(names) != len(cols):
                raise bad(f"{len(cols)} columns in the file, {len(names)} names given: {list(names)}")
            cols = list(names)
        start = k + 9
        if start + n > nl:
            raise bad(f"frame at step {step} truncated: {n} rows announced, {nl - start} present")
        if n:
            try:
                vals = np.array(" ".join(lines[start : start + n]).split(), dtype=np.float64)
            except ValueError:
                raise bad(f"non-numeric entry in frame at step {step}") from None
            if vals.size != n * len(cols):
                raise bad(f"frame at step {step}: ragged rows ({vals.size} values for {n} x {len(cols)})")
            table = vals.reshape(n, len(cols))
        else:
            table = np.zeros((0, len(cols)))
        present = [c for c in sort_by if c in cols]
        if present and n:
            order = np.lexsort([table[:, cols.index(c)] for c in reversed(present)])
            table = table[order]
        out = {}
        for a, c in enumerate(cols):
            col = table[:, a].astype(np.int64) if c in _INT_COLUMNS else table[:, a].copy()
            col.flags.writeable = False
            out[c] = col
        box.flags.writeable = False
        frames.append(DumpFrame(step, box, tilt, boundary, types.MappingProxyType(out)))
        k = start + n
    return tuple(frames)


def parse_dump_custom(path) -> tuple:
    """Read a ``dump custom`` file: a tuple of :class:`DumpFrame`, each sorted by ``id``.

    Column names are those of the ``ITEM: ATOMS`` line (``id type x y fx ...``).
    """
    return _read_frames(path, "NUMBER OF ATOMS", "ATOMS", sort_by=("id",))


def parse_dump_local(path, names=None, sort: bool = True) -> tuple:
    """Read a ``dump local`` file: a tuple of :class:`DumpFrame`.

    Parameters
    ----------
    names : optional column names replacing those of the ``ITEM: ENTRIES`` line (e.g.
        ``c_pl[1] ...``); see :func:`pair_gran_local_names`.
    sort : sort rows by (``id1``, ``id2``) when those columns exist (LIGGGHTS lists contacts
        in neighbour-list order, which depends on binning and MPI ranks).
    """
    return _read_frames(path, "NUMBER OF ENTRIES", "ENTRIES", names=names, sort_by=("id1", "id2") if sort else ())


#: column names of ``compute pair/gran/local`` per keyword, in the order LIGGGHTS writes them
#: (compute_pair_gran_local.cpp, ``add_pair``: pos, vel, id, force, force_normal,
#: force_tangential, torque, history, contactArea, delta, heatFlux)
_PGL = (
    ("pos", ("x1", "y1", "z1", "x2", "y2", "z2")),
    ("vel", ("vx1", "vy1", "vz1", "vx2", "vy2", "vz2")),
    ("id", ("id1", "id2", "periodic")),
    ("force", ("fx", "fy", "fz")),
    ("force_normal", ("fnx", "fny", "fnz")),
    ("force_tangential", ("ftx", "fty", "ftz")),
    ("torque", ("tqx", "tqy", "tqz")),
    ("history", None),
    ("contactArea", ("area",)),
    ("delta", ("delta",)),
    ("heatFlux", ("heatflux",)),
)


def pair_gran_local_names(keywords, n_history: int = 0) -> tuple:
    """Column names of ``compute ID all pair/gran/local <keywords>``, in output order.

    ``pos`` gives x1..z2 (positions remapped into the box, so the branch vector of a contact
    across a periodic boundary needs the minimum image), ``id`` gives id1, id2 and a periodic
    flag, ``force`` the force on id1, ``history`` ``n_history`` columns h1.. (e.g. 3 for a
    tangential spring). Without keywords LIGGGHTS writes pos, vel, id, force, torque, history
    and contactArea.
    """
    kw = set(keywords) if keywords else {"pos", "vel", "id", "force", "torque", "history", "contactArea"}
    unknown = kw - {k for k, _ in _PGL}
    if unknown:
        raise ValueError(f"unknown pair/gran/local keywords {sorted(unknown)}")
    out = []
    for key, cols in _PGL:
        if key in kw:
            out += [f"h{a + 1}" for a in range(n_history)] if cols is None else list(cols)
    return tuple(out)


__all__ = [
    "DumpFrame",
    "LogFile",
    "LogLine",
    "ThermoRun",
    "pair_gran_local_names",
    "parse_dump_custom",
    "parse_dump_local",
    "parse_log",
]
