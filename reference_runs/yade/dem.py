"""Periodic DEM runs in YADE: the biaxial test with its stress servo and periodic simple shear, for the
assemblies of the LIGGGHTS and LAMMPS decks; the reader of their output and the driver.

The law is linear and elastic-frictional (kn, kt, mu of :class:`gransim.dem.DEMSettings`; Cundall
and Strack's law in YADE), without contact damping: YADE 2023.02a's linear spring-dashpot law
(``Law2_ScGeom_ViscElPhys_Basic``) adds the velocity of a contact's periodic image with the wrong
sign (``ViscoelasticPM.cpp:118``, measured: docs/yade.md), which in a deforming periodic cell puts
a force of the cell's own speed on every contact across the boundary. The job builders refuse
settings with damping (:func:`undamped` removes it); the LIGGGHTS and LAMMPS decks run the same
undamped settings.

:func:`biaxial_job` maps a run of :mod:`reference_runs.decks.biaxial` (a packing, the Hooke law of
:class:`gransim.dem.DEMSettings`, a :class:`gransim.dem.Loading`: each axis fixed, at an engineering
rate or under the stress servo) and :func:`shear_job` one of :mod:`reference_runs.decks.shear`
(:class:`gransim.dem.sheared.ShearLoading`: ``xy erate`` with y fixed or under the servo) onto the
constant script :data:`reference_runs.yade.dem_script.DEM_SCRIPT` and its ``input.json`` (format
and what YADE does: that module and docs/yade.md). :func:`short_biaxial` and :func:`short_shear`
are the decks' short cases (120 disks). :func:`run_yade_dem` runs a job through
:func:`reference_runs.yade.job.run_yade_job` with :func:`check_output` as its evidence check, so a
job whose output is incomplete is failed, never ``ok``; :func:`read_yade_dem` reads the output.

Units and signs as in gransim: m, s, kg (2D masses rho pi r^2, rho in kg/m^2), N; stress N/m,
tension positive.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.dem.settings import DEMSettings, Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import InputError
from gransim.geometry import Packing

from ..decks import biaxial as biaxial_deck
from ..decks import shear as shear_deck
from ..errors import ReferenceRunError
from .dem_script import DEM_SCRIPT, INPUT_NAME, OUTPUT_MAGIC, OUTPUT_NAME, OUTPUT_VERSION
from .job import run_yade_job
from .taylor import cell_z

_N_T = 15  # fields of a thermo row
_N_P = 12  # of a particle row
_N_C = 10  # of a contact row


def _law(settings: DEMSettings, law) -> dict:
    """kn, kt, mu of the settings; the runs are undamped (module doc)."""
    if law is not None:
        raise InputError(f"law: the YADE script runs the linear law of DEMSettings (kn, kt, mu), got {law!r}")
    s = settings
    if s.gamma_n != 0 or s.gamma_t != 0:
        raise InputError(
            f"settings.gamma_n, gamma_t: the YADE runs are undamped (0, 0), got {s.gamma_n!r}, {s.gamma_t!r}: YADE "
            "2023.02a's linear spring-dashpot law (Law2_ScGeom_ViscElPhys_Basic) adds the velocity of a contact's "
            "periodic image with the wrong sign (ViscoelasticPM.cpp:118; docs/yade.md); use undamped(settings)"
        )
    return {"kn": float(s.kn), "kt": float(s.kt), "mu": float(s.mu)}


def undamped(settings: DEMSettings) -> DEMSettings:
    """``settings`` with gamma_n = gamma_t = 0: the law the YADE runs have (module doc)."""
    return dataclasses.replace(settings, gamma_n=0.0, gamma_t=0.0)


def _axis(ctl, L0: float, dt: float) -> dict:
    if ctl.mode == "fixed":
        return {"mode": "fixed"}
    if ctl.mode == "rate":
        return {"mode": "rate", "c": ctl.rate * L0 * dt}  # the decks' literal c = rate L0 dt
    return {"mode": "servo", "k": dt * ctl.gain, "target": float(ctl.target)}


def _job(
    packing: Packing, settings: DEMSettings, loading: dict, nsteps, thermo_every, dump_every, velocities, spins, law
):
    nsteps, thermo_every, dump_every = int(nsteps), int(thermo_every), int(dump_every)
    for name, v in (("nsteps", nsteps), ("thermo_every", thermo_every), ("dump_every", dump_every)):
        if v < 1:
            raise InputError(f"{name}: expected an integer >= 1, got {v}")
    p = shear_deck.wrapped_packing(packing)  # centres wrapped as the decks write them (x += L once)
    n = p.n
    v = np.zeros((n, 2)) if velocities is None else np.asarray(velocities, float).reshape(n, 2)
    w = np.zeros(n) if spins is None else np.asarray(spins, float).reshape(n)
    meta = {
        "law": _law(settings, law),
        "z": cell_z(p),
        "dt": float(settings.dt),
        "n_steps": nsteps,
        "thermo_every": thermo_every,
        "dump_every": dump_every,
        "loading": loading,
        "density": float(p.density),
        "cell": np.asarray(p.cell, float).tolist(),
        "radii": [float(r) for r in p.radii],
        "positions": p.positions.tolist(),
        "velocities": v.tolist(),
        "spins": w.tolist(),
    }
    return DEM_SCRIPT, {INPUT_NAME: json.dumps(meta).encode()}


def biaxial_job(
    packing: Packing,
    settings: DEMSettings,
    loading: Loading,
    nsteps: int,
    thermo_every: int = 1,
    dump_every: int = 100,
    velocities=None,
    spins=None,
    law=None,
):
    """``(script, files)`` of the YADE run of :func:`reference_runs.decks.biaxial.write_biaxial_deck`
    with the same arguments (Hooke law only: ``law`` must be None)."""
    if not isinstance(loading, Loading):
        raise InputError(f"loading: expected a gransim.dem.Loading, got {type(loading).__name__}")
    C = np.asarray(packing.cell, float)
    spec = {
        "xx": _axis(loading.x, float(C[0, 0]), float(settings.dt)),
        "yy": _axis(loading.y, float(C[1, 1]), float(settings.dt)),
        "xy_erate": 0.0,
    }
    return _job(packing, settings, spec, nsteps, thermo_every, dump_every, velocities, spins, law)


def shear_job(
    packing: Packing,
    settings: DEMSettings,
    loading: ShearLoading,
    nsteps: int,
    thermo_every: int = 1,
    dump_every: int = 100,
    velocities=None,
    spins=None,
    law=None,
):
    """``(script, files)`` of the YADE run of :func:`reference_runs.decks.shear.write_shear_deck`
    with the same arguments: ``xy erate`` only, changed every step (``every`` 1)."""
    if not isinstance(loading, ShearLoading):
        raise InputError(f"loading: expected a ShearLoading, got {type(loading).__name__}")
    if loading.xy != "erate":
        raise InputError(f"loading.xy: the YADE script shears at a constant erate, got xy {loading.xy!r}")
    if loading.every != 1:
        raise InputError(f"loading.every: the YADE script changes the cell every step, got every = {loading.every}")
    y = {"mode": "fixed"}
    if loading.y == "servo":
        y = {"mode": "servo", "k": float(settings.dt) * loading.gain, "target": float(loading.target)}
    spec = {"xx": {"mode": "fixed"}, "yy": y, "xy_erate": float(loading.erate)}
    return _job(packing, settings, spec, nsteps, thermo_every, dump_every, velocities, spins, law)


def short_biaxial():
    """The biaxial short case of the decks (:func:`reference_runs.decks.biaxial.short_case`),
    undamped: ``(packing, settings, loading, nsteps)``."""
    p, s, ld, n = biaxial_deck.short_case()
    return p, undamped(s), ld, n


def short_shear(name: str):
    """A shear short case of the LAMMPS deck (:func:`reference_runs.decks.shear.short_case`,
    ``constant-volume`` or ``servo``), undamped."""
    p, s, ld, n = shear_deck.short_case(name)
    return p, undamped(s), ld, n


@dataclass(frozen=True, eq=False)
class YadeFrame:
    """One dumped step.

    Attributes
    ----------
    step : k. positions, velocities, forces : (N, 2) by body id (velocity v_(k-1/2), the mean field
    included). spins, torques, mass, radius : (N,). ids : (M, 2) contact body ids; cell_dist :
    (M, 2); normal_force, shear_force : (M, 2) (on body 2); penetration : (M,).
    """

    step: int
    positions: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    forces: np.ndarray
    torques: np.ndarray
    mass: np.ndarray
    radius: np.ndarray
    ids: np.ndarray
    cell_dist: np.ndarray
    normal_force: np.ndarray
    shear_force: np.ndarray
    penetration: np.ndarray


@dataclass(frozen=True, eq=False)
class YadeDemOutput:
    """A complete ``dem.out``.

    Attributes
    ----------
    n_particles, n_steps, thermo_every, dump_every : from the header (checked against the job).
    step : (T,) thermo steps. cell : (T, 2, 2) lattice vectors as columns (m). stress : (T, 2, 2)
    z ``getStress()`` (N/m, tension positive). vel_grad : (T, 2, 2) the loading's velGrad of the
    step (1/s). n_contacts : (T,). frames : {step: :class:`YadeFrame`}.
    """

    n_particles: int
    n_steps: int
    thermo_every: int
    dump_every: int
    step: np.ndarray
    cell: np.ndarray
    stress: np.ndarray
    vel_grad: np.ndarray
    n_contacts: np.ndarray
    frames: dict


def expected_steps(n_steps: int, every: int) -> list:
    """Steps a period writes: 0, every, 2 every, ... and the last."""
    ks = list(range(0, n_steps + 1, every))
    return ks if ks[-1] == n_steps else [*ks, n_steps]


def _incomplete(path, msg):
    return ReferenceRunError(f"incomplete: {path}: {msg}", job_dir=Path(path).parent, problems=[f"incomplete: {msg}"])


def read_yade_dem(path, expect: dict | None = None) -> YadeDemOutput:
    """Read ``dem.out`` (:mod:`reference_runs.yade.dem_script`); ``expect``: the job's
    ``n_particles``, ``n_steps``, ``thermo_every``, ``dump_every`` (default: the header's).

    Raises :class:`~reference_runs.errors.ReferenceRunError` (``incomplete: ...``) for a file that
    is missing, unreadable, of another format or cut short (no ``END`` line, a partial line), a
    header that differs from the job, a thermo step or frame missing or out of order, a frame whose
    particle rows are not ids 0..N-1 in order or whose contact rows do not number its
    ``n_contacts``; and for a NaN or inf anywhere."""
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
    keys = ("n_particles", "n_steps", "thermo_every", "dump_every")
    if head[:2] != OUTPUT_MAGIC.split() or len(head) != 11 or tuple(head[3::2]) != keys:
        raise _incomplete(path, f"not a gransim YADE DEM output (first line {lines[0][:80]!r})" if lines else "empty")
    if head[2] != str(OUTPUT_VERSION):
        raise _incomplete(path, f"format version {head[2]}, this reader reads {OUTPUT_VERSION}")
    hdr = dict(zip(keys, (int(v) for v in head[4::2])))
    for k, v in (expect or {}).items():
        if hdr[k] != int(v):
            raise _incomplete(path, f"the header has {k} = {hdr[k]}, the job {int(v)}")
    N = hdr["n_particles"]
    t_due = expected_steps(hdr["n_steps"], hdr["thermo_every"])
    f_due = expected_steps(hdr["n_steps"], hdr["dump_every"])
    thermo, frames, ended = [], {}, False
    cur = None  # the frame being read: [step, n_contacts, particle rows, contact rows]

    def close_frame(where):
        step, nc, prow, crow = cur
        if len(prow) != N or len(crow) != nc:
            raise _incomplete(
                path, f"{where}: frame of step {step} has {len(prow)} of {N} particles and {len(crow)} of {nc} contacts"
            )
        P = np.array(prow, float).reshape(N, _N_P - 1)
        if not np.array_equal(P[:, 0], np.arange(N)):
            missing = sorted(set(range(N)) - {int(i) for i in P[:, 0]})
            raise _incomplete(
                path, f"frame of step {step}: particle ids are not 0..{N - 1} in order (missing {missing[:5]})"
            )
        Cm = np.array(crow, float).reshape(nc, _N_C - 1)
        frames[step] = YadeFrame(
            step, P[:, 1:3], P[:, 3:5], P[:, 5], P[:, 6:8], P[:, 8], P[:, 9], P[:, 10],
            Cm[:, 0:2].astype(np.int64), Cm[:, 2:4].astype(np.int64), Cm[:, 4:6], Cm[:, 6:8], Cm[:, 8],
        )  # fmt: skip

    for lineno, line in enumerate(lines[1:], 2):
        f = line.split()
        where = f"line {lineno}"
        if ended:
            raise _incomplete(path, f"{where}: text after the END line")
        try:
            kind = f[0] if f else ""
            if kind in ("P", "C"):
                if cur is None:
                    raise _incomplete(path, f"{where}: a {kind} row outside a frame")
                want = _N_P if kind == "P" else _N_C
                if len(f) != want:
                    raise _incomplete(path, f"{where}: malformed line {line[:80]!r}")
                if kind == "P" and cur[3]:
                    raise _incomplete(path, f"{where}: a particle row after the frame's contact rows")
                (cur[2] if kind == "P" else cur[3]).append([float(v) for v in f[1:]])
                continue
            if cur is not None:
                close_frame(where)
                cur = None
            if kind == "T" and len(f) == _N_T:
                k = int(f[1])
                due = t_due[len(thermo)] if len(thermo) < len(t_due) else None
                if k != due:
                    raise _incomplete(path, f"{where}: thermo step {k} where step {due} is due (one missing)")
                thermo.append([float(v) for v in f[1:]])
            elif kind == "F" and len(f) == 4:
                k, n_p, nc = int(f[1]), int(f[2]), int(f[3])
                due = f_due[len(frames)] if len(frames) < len(f_due) else None
                if k != due:
                    raise _incomplete(path, f"{where}: frame of step {k} where step {due} is due (one missing)")
                if n_p != N:
                    raise _incomplete(path, f"{where}: frame of step {k} announces {n_p} particles, the run has {N}")
                cur = [k, nc, [], []]
            elif kind == "END" and len(f) == 2:
                if int(f[1]) != hdr["n_steps"]:
                    raise _incomplete(path, f"{where}: END {f[1]} for a run of {hdr['n_steps']} steps")
                ended = True
            else:
                raise _incomplete(path, f"{where}: malformed line {line[:80]!r}")
        except ValueError:
            raise _incomplete(path, f"{where}: a field is not a number: {line[:80]!r}") from None
    if cur is not None:  # the file ends inside a frame (no END line): it must be whole to count
        close_frame("at the end of the file")
    if not ended:
        raise _incomplete(
            path,
            f"cut short after {len(thermo)} of {len(t_due)} thermo steps and {len(frames)} of {len(f_due)} frames "
            "(no END line)",
        )
    if len(thermo) != len(t_due) or len(frames) != len(f_due):
        raise _incomplete(path, f"{len(thermo)} of {len(t_due)} thermo steps and {len(frames)} of {len(f_due)} frames")
    T = np.array(thermo, float)
    out = YadeDemOutput(
        N, hdr["n_steps"], hdr["thermo_every"], hdr["dump_every"], T[:, 0].astype(np.int64),
        T[:, 1:5].reshape(-1, 2, 2), T[:, 5:9].reshape(-1, 2, 2), T[:, 9:13].reshape(-1, 2, 2),
        T[:, 13].astype(np.int64), frames,
    )  # fmt: skip
    bad = [("thermo", T)] + [
        (
            f"frame {k}",
            np.concatenate(
                [
                    fr.positions.ravel(),
                    fr.velocities.ravel(),
                    fr.forces.ravel(),
                    fr.normal_force.ravel(),
                    fr.shear_force.ravel(),
                ]
            ),
        )
        for k, fr in frames.items()
    ]
    for what, a in bad:
        if not np.all(np.isfinite(a)):
            raise ReferenceRunError(f"{path}: {what}: a value is NaN or inf")
    return out


def _expect(job_dir: Path) -> dict:
    meta = json.loads((job_dir / INPUT_NAME).read_text())
    return {
        "n_particles": len(meta["radii"]),
        "n_steps": meta["n_steps"],
        "thermo_every": meta["thermo_every"],
        "dump_every": meta["dump_every"],
    }


def check_output(job_dir) -> list:
    """Problems of a YADE DEM job's output (empty: complete): the evidence check of the job."""
    job_dir = Path(job_dir)
    try:
        read_yade_dem(job_dir / OUTPUT_NAME, _expect(job_dir))
    except ReferenceRunError as exc:
        return [str(exc)]
    except (OSError, ValueError, KeyError) as exc:
        return [f"incomplete: {job_dir / INPUT_NAME}: cannot read the job's counts ({exc})"]
    return []


def run_yade_dem(job_dir, script: str, files: dict, timeout: float | None = 600.0, force: bool = False):
    """Run (or reuse) a YADE DEM job (:func:`biaxial_job`, :func:`shear_job`) in ``job_dir`` and read
    it: ``(output, manifest)`` with ``output`` a :class:`YadeDemOutput`. Raises
    :class:`~reference_runs.errors.ReferenceRunError` when the job fails or its output is incomplete."""
    res = run_yade_job(job_dir, script, files, timeout=timeout, outputs=[OUTPUT_NAME], force=force, check=check_output)
    return read_yade_dem(Path(job_dir) / OUTPUT_NAME, _expect(Path(job_dir))), res.manifest


def contact_stress(frame: YadeFrame, cell: np.ndarray) -> np.ndarray:
    """(2, 2) Love-Weber stress of a frame's contact rows, sum (fn + fs) (x) (x_1 - x_2 - h cellDist)
    / det h (N/m), as YADE's ``Shop::getStress`` sums it (docs/yade.md), from the written numbers."""
    h = np.asarray(cell, float)
    x = frame.positions
    branch = x[frame.ids[:, 0]] - x[frame.ids[:, 1]] - frame.cell_dist @ h.T
    f = frame.normal_force + frame.shear_force
    return f.T @ branch / abs(float(np.linalg.det(h)))


__all__ = [
    "YadeDemOutput",
    "YadeFrame",
    "biaxial_job",
    "check_output",
    "contact_stress",
    "expected_steps",
    "read_yade_dem",
    "run_yade_dem",
    "shear_job",
    "short_biaxial",
    "short_shear",
    "undamped",
]
