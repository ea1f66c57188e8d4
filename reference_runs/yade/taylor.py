"""Taylor (affine) RVE states computed by YADE: the job, the reader of its output and the driver.

:func:`yade_taylor_job` writes the job of one packing (all its states: one YADE process, ~1 s to
start): the constant script :data:`reference_runs.yade.script.TAYLOR_SCRIPT` and ``input.json``
(format there). For every state of the study paths (:func:`reference_runs.decks.taylor.path_F`)
the packing is deformed affinely, centres x = F X (X wrapped into the reference cell, computed by
numpy as for the LIGGGHTS and LAMMPS decks) and cell F C, which YADE gets as ``O.cell.hSize =
[[F C, 0], [0, z]]``: a true periodic cell for all four paths (YADE's cell may be sheared).

The z size ``z`` is the smallest power of two >= 4 r_max (YADE needs it larger than every
diameter; docs/yade.md). YADE's stresses are divided by the 3D volume ``O.cell.volume`` =
det(hSize), so the 2D stress (N/m) is the 3D one times z; z being a power of two, that product
is exact and the only difference from gransim's sum / (det F V_ref) is the rounding of the two
determinants and of the sums (:func:`reference_runs.taylor_numpy.taylor_stress_numpy`).

:func:`read_yade_taylor` reads ``taylor.out`` and refuses it, with
:class:`~reference_runs.errors.ReferenceRunError` (``incomplete: ...``), when it is cut short (no
``END`` line), a state is missing or out of order, or a state's contact rows do not number its
``n_contacts``. :func:`run_yade_taylor` runs (or reuses) the job through
:func:`reference_runs.yade.job.run_yade_job` with that reader as its evidence check, so an
incomplete output is a failed job, never an ``ok`` one.
"""

from __future__ import annotations

import json
import math
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.dem.yade_arithmetic import yade_cell_z
from gransim.errors import InputError
from gransim.geometry import Packing

from ..decks.taylor import PATHS, _wrapped_reference, path_F
from ..errors import ReferenceRunError
from ..taylor import TaylorRun, TaylorSeries
from .job import run_yade_job
from .script import OUTPUT_MAGIC, OUTPUT_VERSION, TAYLOR_SCRIPT

OUTPUT_NAME = "taylor.out"
INPUT_NAME = "input.json"
_N_C = 14  # fields of a contact row
_N_S = 4 + 9 + 9 + 36  # fields of a state row


def cell_z(packing: Packing) -> float:
    """z size of the YADE cell (m): :func:`gransim.dem.yade_arithmetic.yade_cell_z` of the radii."""
    return yade_cell_z(packing.radii)


def yade_taylor_job(
    packing: Packing,
    kn: float,
    paths=PATHS,
    n_steps: int = 50,
    max_strain: float = 0.1,
    stride: int = 1,
    name: str = "packing",
):
    """Script text, input files and the state list of the YADE Taylor job of one packing.

    Returns ``(script, files, states)``: ``files`` is ``{"input.json": bytes}``, ``states`` a list
    of dicts ``{index, path, k, F}`` in job order.
    """
    if not kn > 0 or not math.isfinite(kn):
        raise InputError(f"kn: must be a finite number > 0, got {kn!r}")
    C = np.asarray(packing.cell, float)
    _, X = _wrapped_reference(packing)
    states, entries = [], []
    for path in paths:
        Fs = path_F(path, n_steps, max_strain, stride)
        ks = list(range(0, n_steps + 1, stride))
        if ks[-1] != n_steps:
            ks.append(n_steps)
        for k, F in zip(ks, Fs):
            index = len(states)
            states.append({"index": index, "path": path, "k": int(k), "F": F.tolist()})
            entries.append({"index": index, "F": F.tolist(), "cell": (F @ C).tolist(), "positions": (X @ F.T).tolist()})
    meta = {
        "name": name,
        "kn": float(kn),
        "z": cell_z(packing),
        "radii": [float(r) for r in packing.radii],
        "density": float(packing.density),
        "reference_cell": C.tolist(),
        "reference_area": float(abs(np.linalg.det(C))),
        "n_steps": n_steps,
        "max_strain": max_strain,
        "stride": stride,
        "paths": list(paths),
        "state_list": states,
        "states": entries,
    }
    return TAYLOR_SCRIPT, {INPUT_NAME: json.dumps(meta).encode()}, states


@dataclass(frozen=True, eq=False)
class YadeState:
    """One state as YADE wrote it.

    Attributes
    ----------
    index : state index. n_contacts : real interactions. volume : ``O.cell.volume`` (3D, m^3).
    stress : (3, 3) ``utils.getStress()`` (N/m^2, 3D volume, compression negative).
    stress_t, tangent : (3, 3) stress and (6, 6) tangent of ``utils.getStressAndTangent()``.
    ids : (M, 2) body ids; cell_dist : (M, 3) ``cellDist``; normal_force, shear_force : (M, 3)
    (on body 2); penetration : (M,) ``penetrationDepth``.
    """

    index: int
    n_contacts: int
    volume: float
    stress: np.ndarray
    stress_t: np.ndarray
    tangent: np.ndarray
    ids: np.ndarray
    cell_dist: np.ndarray
    normal_force: np.ndarray
    shear_force: np.ndarray
    penetration: np.ndarray


def _incomplete(path, msg):
    return ReferenceRunError(f"incomplete: {path}: {msg}", job_dir=Path(path).parent, problems=[f"incomplete: {msg}"])


def read_yade_taylor(path, n_states: int | None = None) -> list:
    """The states of a YADE Taylor output file, in order (list of :class:`YadeState`).

    ``n_states``: how many states the job asked for (default: the header's count). Raises
    :class:`~reference_runs.errors.ReferenceRunError` (``incomplete: ...``) for a file that is
    missing, unreadable, of another format, cut short (no ``END`` line, a partial line), with a
    state missing or out of order, or with a state whose contact rows do not number its
    ``n_contacts``.
    """
    path = Path(path)
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise _incomplete(path, f"cannot read it ({exc})") from None
    lines = text.split("\n")
    if lines and lines[-1] == "":
        lines.pop()
    else:
        raise _incomplete(path, "the last line is cut short (no newline at the end)")
    head = lines[0].split() if lines else []
    magic = OUTPUT_MAGIC.split()
    if head[:2] != magic or len(head) != 5 or head[3] != "n_states":
        raise _incomplete(
            path, f"not a gransim YADE Taylor output (first line {lines[0][:80]!r})" if lines else "empty"
        )
    if head[2] != str(OUTPUT_VERSION):
        raise _incomplete(path, f"format version {head[2]}, this reader reads {OUTPUT_VERSION}")
    declared = int(head[4])
    want = declared if n_states is None else int(n_states)
    if declared != want:
        raise _incomplete(path, f"the header announces {declared} states, the job has {want}")
    states, rows, ended = [], [], False
    for lineno, line in enumerate(lines[1:], 2):
        f = line.split()
        where = f"line {lineno}"
        if ended:
            raise _incomplete(path, f"{where}: text after the END line")
        try:
            if f and f[0] == "C" and len(f) == _N_C:
                if int(f[1]) != len(states):
                    raise _incomplete(path, f"{where}: a contact of state {f[1]} where state {len(states)} is due")
                rows.append([float(v) for v in f[2:]])
            elif f and f[0] == "S" and len(f) == _N_S:
                index, n = int(f[1]), int(f[2])
                if index != len(states):
                    raise _incomplete(path, f"{where}: state {index} where state {len(states)} is due (one missing)")
                if n != len(rows):
                    raise _incomplete(path, f"state {index}: {len(rows)} contact rows for n_contacts = {n}")
                v = np.array([float(x) for x in f[3:]])
                r = np.array(rows, float).reshape(-1, _N_C - 2)
                states.append(
                    YadeState(
                        index,
                        n,
                        float(v[0]),
                        v[1:10].reshape(3, 3),
                        v[10:19].reshape(3, 3),
                        v[19:55].reshape(6, 6),
                        r[:, 0:2].astype(np.int64),
                        r[:, 2:5].astype(np.int64),
                        r[:, 5:8],
                        r[:, 8:11],
                        r[:, 11],
                    )
                )
                rows = []
            elif f and f[0] == "END" and len(f) == 2:
                if int(f[1]) != len(states) or rows:
                    raise _incomplete(path, f"{where}: END {f[1]} after {len(states)} complete states")
                ended = True
            else:
                raise _incomplete(path, f"{where}: malformed line {line[:80]!r}")
        except ValueError:
            raise _incomplete(path, f"{where}: a field is not a number: {line[:80]!r}") from None
    if not ended:
        raise _incomplete(path, f"cut short after {len(states)} of {want} states (no END line)")
    if len(states) != want:
        raise _incomplete(path, f"{len(states)} of {want} states")
    for s in states:
        if not (np.all(np.isfinite(s.stress)) and np.all(np.isfinite(s.tangent))):
            raise ReferenceRunError(f"{path}: state {s.index}: a stress or tangent entry is NaN or inf")
    return states


def check_output(job_dir) -> list:
    """Problems of a YADE Taylor job's output (empty: complete): the evidence check of the job."""
    job_dir = Path(job_dir)
    try:
        n = len(json.loads((job_dir / INPUT_NAME).read_text())["states"])
        read_yade_taylor(job_dir / OUTPUT_NAME, n)
    except ReferenceRunError as exc:
        return [str(exc)]
    except (OSError, ValueError, KeyError) as exc:
        return [f"incomplete: {job_dir / INPUT_NAME}: cannot read the state count ({exc})"]
    return []


@dataclass(frozen=True, eq=False)
class YadeTaylorRun:
    """All Taylor states of one packing computed by YADE.

    Attributes
    ----------
    packing, kn, z, job_dir, manifest : as run. states : the list ``{index, path, k, F}``.
    F : (T, 2, 2). cauchy : (T, 2, 2) 2D Cauchy stress (N/m, tension positive) = z times the
    (x, y) block of ``getStress()``. tangent : (T, 6, 6) ``getStressAndTangent()`` tangent
    times z (N/m). n_contacts : (T,). raw : the :class:`YadeState` list.
    """

    packing: Packing
    kn: float
    z: float
    job_dir: Path
    manifest: dict
    states: tuple
    F: np.ndarray
    cauchy: np.ndarray
    tangent: np.ndarray
    n_contacts: np.ndarray
    raw: tuple


def run_yade_taylor(
    packing: Packing,
    kn: float,
    job_dir,
    paths=PATHS,
    n_steps: int = 50,
    max_strain: float = 0.1,
    stride: int = 1,
    name: str = "packing",
    timeout: float | None = 600.0,
    force: bool = False,
) -> YadeTaylorRun:
    """Run (or reuse) the YADE Taylor job of one packing and read it (see the module doc)."""
    script, files, states = yade_taylor_job(packing, kn, paths, n_steps, max_strain, stride, name)
    res = run_yade_job(job_dir, script, files, timeout=timeout, outputs=[OUTPUT_NAME], force=force, check=check_output)
    raw = read_yade_taylor(Path(job_dir) / OUTPUT_NAME, len(states))
    z = cell_z(packing)
    return YadeTaylorRun(
        packing,
        float(kn),
        z,
        Path(job_dir),
        res.manifest,
        tuple(states),
        np.array([s["F"] for s in states], float),
        np.array([s.stress[:2, :2] * z for s in raw]),
        np.array([s.tangent * z for s in raw]),
        np.array([s.n_contacts for s in raw]),
        tuple(raw),
    )


def as_taylor_run(run: YadeTaylorRun, name: str):
    """The YADE run as a :class:`reference_runs.taylor.TaylorRun` (``engine="yade"``), the form
    the LIGGGHTS and LAMMPS Taylor runs take, so that :func:`reference_runs.cases.compare_taylor`
    and :func:`reference_runs.taylor.write_taylor_h5` serve all three codes.

    Every path is on the ``periodic`` route (YADE's periodic cell may be sheared): ``cauchy`` = z
    times the (x, y) block of ``getStress()``, ``cauchy_pressure`` = z times that of the stress of
    ``getStressAndTangent()`` (the code's second stress, in the place of LIGGGHTS' and LAMMPS'
    ``compute pressure``), ``stress_atom_sum`` = (xx, yy, xy) of ``getStress()`` times
    ``O.cell.volume``, the contact sum sum f (x) l (N m), tension positive like gransim's.
    """
    groups: dict = {}
    for t, st in enumerate(run.states):
        groups.setdefault(st["path"], []).append(t)
    series = {}
    for path, idx in groups.items():
        raw = [run.raw[t] for t in idx]
        series[(path, "periodic")] = TaylorSeries(
            path,
            "periodic",
            np.array([run.states[t]["k"] for t in idx]),
            run.F[idx],
            run.cauchy[idx],
            np.array([s.stress_t[:2, :2] * run.z for s in raw]),
            np.array([[s.stress[0, 0] * s.volume, s.stress[1, 1] * s.volume, s.stress[0, 1] * s.volume] for s in raw]),
            (None,) * len(idx),
            tuple(((1.0, 0.0), (0.0, 1.0)) for _ in idx),
        )
    return TaylorRun(name, run.packing, run.kn, run.job_dir, types.MappingProxyType(series), run.manifest, "yade")


__all__ = [
    "OUTPUT_NAME",
    "as_taylor_run",
    "YadeState",
    "YadeTaylorRun",
    "cell_z",
    "check_output",
    "read_yade_taylor",
    "run_yade_taylor",
    "yade_taylor_job",
]
