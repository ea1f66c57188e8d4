"""The outputs of one run of Guo & Zhao's FEM x DEM biaxial test: strict readers and the HDF5 file.

The job writes text files (``job/femxdem_record.py``, every float by ``repr``, each file ended by an
``END`` line). The readers here refuse, as :class:`IncompleteOutputError` naming the file, a file
that is missing, lacks its ``END`` line, has a malformed or short row, or holds other steps or Gauss
points than the run asked for: nothing is stored from a run whose evidence is incomplete.

HDF5 layout (``kind = "femxdem-reference"``, written atomically by :func:`gransim.io.atomic_h5`)::

    /steps/<column>        (n_steps + 1,) per load step, step 0 = before loading; the columns of
                           job/femxdem_record.py STEP_COLUMNS, plus the derived
                           eps_a, q, q_top, eps_v (:func:`derived`)
    /newton/step, iteration, relative_error      every error msFEM2D printed
    /maps/step, n_items, seconds, worker_cpu_seconds, function (strings)   every Pool.map
    /fields/step_<t>/x (ng, 2), stress (ng, 2, 2), strain (ng, 2, 2), fabric (ng, 2, 2),
                     void_ratio (ng,), rotation (ng,)
    /rve/radii, masses (n,), contacts (n_contacts, 4: r1 r2 kn ks);
         attrs stress (3, 3), hsize (3, 3), dt, iterations, n_contacts, friction, engines, damping
    root attrs: provenance (gransim.io), yade_version, escript_version, packages, patch_sha256,
                originals, timing and load figures (see docs/femxdem_reference.md)

Signs: tension positive, as YADE and escript compute them (the stresses are negative in
compression). q and eps_a are positive in compression loading, as Guo & Zhao plot them.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.io import atomic_h5, open_result

from ..errors import ReferenceRunError
from .job.femxdem_record import DEM_MAPS, STEP_COLUMNS

KIND = "femxdem-reference"
#: biaxialSmooth.py:36: the confining stress on the sides (tension positive), Pa
CONFINING = -1.0e5

FIELD_COLUMNS = (
    "x y stress_xx stress_xy stress_yx stress_yy strain_xx strain_xy strain_yx strain_yy"
    " fabric_xx fabric_xy fabric_yx fabric_yy void_ratio rotation"
).split()


class IncompleteOutputError(ReferenceRunError):
    """An output of the run is missing, cut short or inconsistent with what was asked."""


def _lines(path: Path) -> list:
    try:
        return path.read_text().splitlines()
    except FileNotFoundError:
        raise IncompleteOutputError(f"incomplete: {path} is missing") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise IncompleteOutputError(f"incomplete: {path} cannot be read ({exc})") from None


def _ended(path: Path, lines: list, prefix: str = "END") -> list:
    """The lines before the final ``END`` line; refuses a file without it."""
    if not lines or not lines[-1].startswith(prefix):
        raise IncompleteOutputError(f"incomplete: {path} has no final {prefix!r} line (cut short)")
    return lines[:-1]


def _floats(path: Path, lineno: int, text: str, n: int) -> list:
    parts = text.split()
    if len(parts) != n:
        raise IncompleteOutputError(f"incomplete: {path}:{lineno} has {len(parts)} values, expected {n}")
    try:
        return [float(p) for p in parts]
    except ValueError:
        raise IncompleteOutputError(f"incomplete: {path}:{lineno} holds a value that is not a number") from None


def read_keyvalues(path) -> dict:
    """``key = value`` lines ended by ``END`` (versions.txt, rve.txt)."""
    path = Path(path)
    out = {}
    for k, line in enumerate(_ended(path, _lines(path)), 1):
        key, sep, value = line.partition(" = ")
        if not sep:
            raise IncompleteOutputError(f"incomplete: {path}:{k} is not a 'key = value' line")
        out[key] = value
    return out


@dataclass(frozen=True)
class RveRecord:
    """The consolidated RVE of prepareRVE.py (``rve.txt``): 3D stress (Pa, with the cell's z size
    0.1 m: prepareRVE.py:11), cell ``hsize`` (3, 3), radii and masses (n,), ``contacts``
    (n_contacts, 4): r1, r2, kn, ks of each contact, friction after ``setContactFriction``."""

    n_bodies: int
    dt: float
    iterations: int
    stress: np.ndarray
    hsize: np.ndarray
    unbalanced: float
    n_contacts: int
    tan_friction: tuple
    material_friction_angle: tuple
    engines: tuple
    damping: tuple
    contacts: np.ndarray
    radii: np.ndarray
    masses: np.ndarray


def read_rve(path) -> RveRecord:
    path = Path(path)
    kv = read_keyvalues(path)
    need = ("n_bodies", "dt", "iterations", "stress", "hsize", "unbalanced", "n_contacts", "tan_friction")
    need += ("material_friction_angle", "engines", "damping", "contacts", "radii", "masses")
    missing = [k for k in need if k not in kv]
    if missing:
        raise IncompleteOutputError(f"incomplete: {path} lacks {', '.join(missing)}")
    try:
        rec = RveRecord(
            n_bodies=int(kv["n_bodies"]),
            dt=float(kv["dt"]),
            iterations=int(kv["iterations"]),
            stress=np.array([float(v) for v in kv["stress"].split()]).reshape(3, 3),
            hsize=np.array([float(v) for v in kv["hsize"].split()]).reshape(3, 3),
            unbalanced=float(kv["unbalanced"]),
            n_contacts=int(kv["n_contacts"]),
            tan_friction=tuple(float(v) for v in kv["tan_friction"].split()),
            material_friction_angle=tuple(float(v) for v in kv["material_friction_angle"].split()),
            engines=tuple(kv["engines"].split()),
            damping=tuple(float(v) for v in kv["damping"].split()),
            contacts=np.array([float(v) for v in kv["contacts"].split()]).reshape(-1, 4),
            radii=np.array([float(v) for v in kv["radii"].split()]),
            masses=np.array([float(v) for v in kv["masses"].split()]),
        )
    except ValueError as exc:
        raise IncompleteOutputError(f"incomplete: {path}: a malformed value ({exc})") from None
    if rec.radii.shape != (rec.n_bodies,) or rec.masses.shape != (rec.n_bodies,):
        raise IncompleteOutputError(f"incomplete: {path}: {rec.radii.size} radii for {rec.n_bodies} bodies")
    if rec.contacts.shape != (rec.n_contacts, 4):
        raise IncompleteOutputError(f"incomplete: {path}: {rec.contacts.shape[0]} contact rows for {rec.n_contacts}")
    return rec


def read_steps(path, n_steps: int) -> dict:
    """``steps.txt`` of a run of ``n_steps`` load steps: a dict column -> (n_steps + 1,) array and
    ``wall_total`` (s) from its ``END`` line."""
    path = Path(path)
    lines = _lines(path)
    if not lines or lines[0] != "# " + " ".join(STEP_COLUMNS):
        raise IncompleteOutputError(f"incomplete: {path} lacks its header line")
    body = lines[1:]
    end = body[-1] if body else ""
    m = re.fullmatch(r"END steps=(\d+) wall_total=(\S+)", end)
    rows = [_floats(path, k + 2, ln, len(STEP_COLUMNS)) for k, ln in enumerate(body[:-1] if m else body)]
    got = [int(r[0]) for r in rows]
    if got != list(range(len(rows))):
        raise IncompleteOutputError(f"incomplete: {path}: steps {got} are not 0, 1, 2, ...")
    if not m:
        last = got[-1] if got else None
        raise IncompleteOutputError(
            f"incomplete: {path} has no END line: the run stopped after step {last} of {n_steps} (cut short)"
        )
    if len(rows) != n_steps + 1 or int(m.group(1)) != n_steps:
        raise IncompleteOutputError(f"incomplete: {path} holds steps 0..{len(rows) - 1}, expected 0..{n_steps}")
    data = np.array(rows)
    out = {c: data[:, k] for k, c in enumerate(STEP_COLUMNS)}
    out["step"] = out["step"].astype(np.int64)
    out["iterations"] = out["iterations"].astype(np.int64)
    out["n_dem_maps"] = out["n_dem_maps"].astype(np.int64)
    out["wall_total"] = float(m.group(2))
    return out


def read_table(path, columns: int, names) -> list:
    """Rows of a ``# header`` + rows + ``END`` file, split into ``columns`` fields."""
    path = Path(path)
    lines = _ended(path, _lines(path))
    if not lines or not lines[0].startswith("# "):
        raise IncompleteOutputError(f"incomplete: {path} lacks its header line")
    if lines[0][2:].split() != list(names):
        raise IncompleteOutputError(f"incomplete: {path}: header {lines[0]!r} is not {' '.join(names)!r}")
    rows = []
    for k, ln in enumerate(lines[1:], 2):
        parts = ln.split()
        if len(parts) != columns:
            raise IncompleteOutputError(f"incomplete: {path}:{k} has {len(parts)} fields, expected {columns}")
        rows.append(parts)
    return rows


def read_fields(path, step: int, n_gauss: int) -> dict:
    """``fields_<step>.txt``: per Gauss point x (ng, 2), stress, strain, fabric (ng, 2, 2),
    void_ratio, rotation (ng,)."""
    path = Path(path)
    lines = _ended(path, _lines(path))
    want = f"# step {step} n_gauss {n_gauss}"
    if not lines or lines[0] != want:
        raise IncompleteOutputError(f"incomplete: {path}: first line is not {want!r}")
    if len(lines) < 2 or lines[1] != "# " + " ".join(FIELD_COLUMNS):
        raise IncompleteOutputError(f"incomplete: {path} lacks its column line")
    rows = [_floats(path, k + 3, ln, len(FIELD_COLUMNS)) for k, ln in enumerate(lines[2:])]
    if len(rows) != n_gauss:
        raise IncompleteOutputError(f"incomplete: {path} holds {len(rows)} Gauss points, expected {n_gauss}")
    a = np.array(rows).reshape(n_gauss, len(FIELD_COLUMNS))
    return {
        "x": a[:, 0:2],
        "stress": a[:, 2:6].reshape(-1, 2, 2),
        "strain": a[:, 6:10].reshape(-1, 2, 2),
        "fabric": a[:, 10:14].reshape(-1, 2, 2),
        "void_ratio": a[:, 14],
        "rotation": a[:, 15],
    }


@dataclass(frozen=True)
class RunOutputs:
    """Everything a complete run wrote (see the module docstring)."""

    steps: dict
    newton: dict
    maps: dict
    fields: dict  # step -> dict of read_fields
    versions: dict
    rve: RveRecord


def read_outputs(job_dir, n_steps: int, n_gauss: int, field_steps) -> RunOutputs:
    """Read and check every output of a run in ``job_dir`` (its ``result/`` and ``rve.txt``)."""
    job_dir = Path(job_dir)
    res = job_dir / "result"
    versions = read_keyvalues(res / "versions.txt")
    steps = read_steps(res / "steps.txt", n_steps)
    nrows = read_table(res / "newton.txt", 3, ("step", "iteration", "relative_error"))
    try:
        newton = {
            "step": np.array([int(r[0]) for r in nrows], dtype=np.int64),
            "iteration": np.array([int(r[1]) for r in nrows], dtype=np.int64),
            "relative_error": np.array([float(r[2]) for r in nrows]),
        }
    except ValueError:
        raise IncompleteOutputError(f"incomplete: {res / 'newton.txt'} holds a malformed row") from None
    for t in range(1, n_steps + 1):
        its = newton["iteration"][newton["step"] == t]
        if its.size == 0 or int(its.max()) != int(steps["iterations"][t]):
            raise IncompleteOutputError(
                f"incomplete: {res / 'newton.txt'}: step {t}'s iterations do not end at the "
                f"{int(steps['iterations'][t])} of steps.txt"
            )
    mrows = read_table(res / "maps.txt", 5, ("step", "function", "n_items", "seconds", "worker_cpu_seconds"))
    try:
        maps = {
            "step": np.array([int(r[0]) for r in mrows], dtype=np.int64),
            "function": [r[1] for r in mrows],
            "n_items": np.array([int(r[2]) for r in mrows], dtype=np.int64),
            "seconds": np.array([float(r[3]) for r in mrows]),
            "worker_cpu_seconds": np.array([float(r[4]) for r in mrows]),
        }
    except ValueError:
        raise IncompleteOutputError(f"incomplete: {res / 'maps.txt'} holds a malformed row") from None
    bad = [n for f, n in zip(maps["function"], maps["n_items"]) if f in DEM_MAPS and n != n_gauss]
    if bad:
        raise IncompleteOutputError(f"incomplete: {res / 'maps.txt'}: a DEM map over {bad[0]} RVEs, expected {n_gauss}")
    fields = {int(t): read_fields(res / f"fields_{int(t)}.txt", int(t), n_gauss) for t in field_steps}
    rve = read_rve(job_dir / "rve.txt")
    return RunOutputs(steps, newton, maps, fields, versions, rve)


def derived(steps: dict, confining: float = CONFINING) -> dict:
    """Curves from the per-step records (all (n_steps + 1,)):

    - ``eps_a`` = -axial_strain: the axial strain, positive in compression (t |vel| / ly);
    - ``q`` = <sigma_xx> - <sigma_yy>: the deviatoric stress of the volume-averaged Gauss-point
      stresses (Pa, positive when the axial stress is the more compressive);
    - ``q_top`` = confining - force_top_y / length_top: the same from the top platen's resultant
      (biaxialSmooth.py:91-95) and the applied confinement;
    - ``eps_v`` = <eps_xx> + <eps_yy>: the volumetric strain of the volume-averaged accumulated
      Gauss-point strains (small-strain increments summed, msFEM2D.py:247), dilation positive.
    """
    return {
        "eps_a": -steps["axial_strain"],
        "q": steps["stress_xx"] - steps["stress_yy"],
        "q_top": confining - steps["force_top_y"] / steps["length_top"],
        "eps_v": steps["strain_xx"] + steps["strain_yy"],
    }


def timing(out: RunOutputs, workers: int) -> dict:
    """Timing figures of a run: wall times, Newton iterations, RVE calls (one shear2D plus one
    getStressAndTangent2D of one Gauss point), DEM wall per RVE call seen by the master, the
    worker-seconds per RVE call (workers x that: the pool keeps every worker busy) and the workers'
    CPU seconds per RVE call (from /proc, what a shared machine's load does not inflate)."""
    s = out.steps
    f = np.array(out.maps["function"])
    sec = out.maps["seconds"]
    n = out.maps["n_items"]
    shear = f == "shear2D"
    dem = np.isin(f, DEM_MAPS)
    loaded = out.maps["step"] > 0
    n_calls = int(n[shear & loaded].sum())
    dem_wall = float(sec[dem & loaded].sum())
    dem_cpu = float(out.maps["worker_cpu_seconds"][dem & loaded].sum())
    return {
        "wall_total": float(s["wall_total"]),
        "wall_step0": float(s["wall_step"][0]),
        "wall_loading": float(s["wall_step"][1:].sum()),
        "wall_solve": float(s["wall_solve"][1:].sum()),
        "wall_dem": dem_wall,
        "newton_iterations": [int(v) for v in s["iterations"][1:]],
        "rve_calls": n_calls,
        "dem_wall_per_rve_call": dem_wall / n_calls if n_calls else math.nan,
        "worker_seconds_per_rve_call": workers * dem_wall / n_calls if n_calls else math.nan,
        "dem_worker_cpu": dem_cpu,
        "worker_cpu_per_rve_call": dem_cpu / n_calls if n_calls else math.nan,
        "cpu_main": float(s["cpu_main"][-1]),
        "cpu_workers": float(s["cpu_workers"][-1]),
        "load1_mean": float(np.mean(s["load1"])),
    }


def write_h5(path, out: RunOutputs, parameters: dict, attrs: dict) -> Path:
    """Write a complete run to ``path`` atomically (layout in the module docstring)."""
    seed = parameters.get("seed")
    with atomic_h5(path, kind=KIND, parameters=parameters, seed=seed) as f:
        g = f.create_group("steps")
        for k, v in out.steps.items():
            if k != "wall_total":
                g.create_dataset(k, data=v)
        for k, v in derived(out.steps).items():
            g.create_dataset(k, data=v)
        g = f.create_group("newton")
        for k, v in out.newton.items():
            g.create_dataset(k, data=v)
        g = f.create_group("maps")
        for k in ("step", "n_items", "seconds", "worker_cpu_seconds"):
            g.create_dataset(k, data=out.maps[k])
        g.create_dataset("function", data=np.array(out.maps["function"], dtype="S"))
        g = f.create_group("fields")
        for t, fl in sorted(out.fields.items()):
            h = g.create_group(f"step_{t:04d}")
            h.attrs["step"] = t
            for k, v in fl.items():
                h.create_dataset(k, data=v)
        g = f.create_group("rve")
        g.create_dataset("radii", data=out.rve.radii)
        g.create_dataset("masses", data=out.rve.masses)
        g.create_dataset("contacts", data=out.rve.contacts)
        for k in ("n_bodies", "dt", "iterations", "unbalanced", "n_contacts"):
            g.attrs[k] = getattr(out.rve, k)
        g.attrs["stress"] = out.rve.stress
        g.attrs["hsize"] = out.rve.hsize
        g.attrs["tan_friction"] = np.array(out.rve.tan_friction)
        g.attrs["material_friction_angle"] = np.array(out.rve.material_friction_angle)
        g.attrs["engines"] = " ".join(out.rve.engines)
        g.attrs["damping"] = np.array(out.rve.damping)
        f.attrs["versions"] = json.dumps(out.versions, sort_keys=True)
        f.attrs["timing"] = json.dumps(timing(out, int(parameters["workers"])), sort_keys=True)
        for k, v in attrs.items():
            f.attrs[k] = v if isinstance(v, (str, int, float)) else json.dumps(v, sort_keys=True)
    return Path(path)


def read_h5(path) -> dict:
    """The curves and figures of a results file: ``steps`` (dict of arrays), ``fields`` (step ->
    dict), ``newton``, ``attrs`` (root attributes, JSON decoded where they are JSON)."""
    with open_result(path, kind=KIND) as f:
        steps = {k: f["steps"][k][()] for k in f["steps"]}
        fields = {int(h.attrs["step"]): {k: h[k][()] for k in h} for h in f["fields"].values()}
        newton = {k: f["newton"][k][()] for k in f["newton"]}
        attrs = {}
        for k, v in f.attrs.items():
            if isinstance(v, bytes):
                v = v.decode()
            if isinstance(v, str) and v[:1] in "{[":
                try:
                    v = json.loads(v)
                except ValueError:
                    pass
            attrs[k] = v
    return {"steps": steps, "fields": fields, "newton": newton, "attrs": attrs}


__all__ = [
    "CONFINING",
    "KIND",
    "IncompleteOutputError",
    "RunOutputs",
    "RveRecord",
    "derived",
    "read_fields",
    "read_h5",
    "read_keyvalues",
    "read_outputs",
    "read_rve",
    "read_steps",
    "timing",
    "write_h5",
]
