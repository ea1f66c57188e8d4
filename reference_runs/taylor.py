"""Run Taylor RVE states through LIGGGHTS or LAMMPS and read back their stresses (and contacts).

:func:`run_taylor` writes the job of :func:`reference_runs.decks.taylor.taylor_job`, runs it
with :func:`reference_runs.runner.run_job` (skipped when already complete) and returns a
:class:`TaylorRun`: per path and route the deformation gradients and the Cauchy stress
(tension positive, N/m) as the code computed it (``engine="liggghts"`` or ``"lammps"``; LAMMPS
runs the periodic route on all four paths, the shear paths in a triclinic box, and its results
are mapped back from the engine frame ``x_engine = Q x`` of each state). :func:`write_taylor_h5` stores it
(layout in docs/schema_reference_runs.md).
"""

from __future__ import annotations

import json
import types
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.errors import ResultFileError
from gransim.geometry import Packing
from gransim.io import atomic_h5, open_result, write_packing_group

from .conventions import cauchy_from_pressure, cauchy_from_stress_atom_sum
from .decks.taylor import LAMMPS_CONTACT_COLUMNS, PATHS, ROUTES, image_state_packing, taylor_job
from .engines import YADE
from .errors import ReferenceRunError
from .parsers import pair_gran_local_names, parse_dump_local, parse_log
from .runner import run_job


@dataclass(frozen=True, eq=False)
class TaylorSeries:
    """Taylor stresses of one code along one path by one route.

    Attributes
    ----------
    path, route : names (see :data:`~reference_runs.decks.taylor.PATHS`, ``ROUTES``).
    k : (T,) state index along the path.
    F : (T, 2, 2) deformation gradients.
    cauchy : (T, 2, 2) Cauchy stress (N/m, tension positive) = central stress/atom sum / (det F V_ref).
    cauchy_pressure : (T, 2, 2) -p from ``compute pressure`` (periodic route only; NaN otherwise).
    stress_atom_sum : (T, 3) raw sums xx, yy, xy of stress/atom over the central particles (N m).
    contact_files : per state, the job-relative contact dump (or None).
    """

    path: str
    route: str
    k: np.ndarray
    F: np.ndarray
    cauchy: np.ndarray
    cauchy_pressure: np.ndarray
    stress_atom_sum: np.ndarray
    contact_files: tuple
    frames: tuple = ()  # per state Q (x_engine = Q x); identity except LAMMPS periodic shear-21


@dataclass(frozen=True, eq=False)
class TaylorRun:
    """All Taylor states of one packing run through LIGGGHTS or LAMMPS (``engine``)."""

    name: str
    packing: Packing
    kn: float
    job_dir: Path
    series: types.MappingProxyType  # (path, route) -> TaylorSeries
    manifest: dict
    engine: str = "liggghts"

    def get(self, path: str, route: str = "images") -> TaylorSeries:
        try:
            return self.series[(path, route)]
        except KeyError:
            raise KeyError(f"no series ({path!r}, {route!r}); have {sorted(self.series)}") from None

    def contacts(self, path: str, route: str, k: int):
        """The contact rows (a :class:`~reference_runs.parsers.DumpFrame`) of one state.

        LIGGGHTS: the columns of ``compute pair/gran/local id pos force delta``. LAMMPS: ``id1 id2
        dist fx fy fz`` and ``delta`` = r_1 + r_2 - dist, with the force on id1 mapped back to
        gransim's frame (f = Q^T f_engine). Each periodic contact appears once in the periodic
        route; in the images route a contact between a central particle and an image appears
        from both ends (its periodic twin).
        """
        s = self.get(path, route)
        idx = int(np.nonzero(s.k == k)[0][0])
        f = s.contact_files[idx]
        if f is None:
            raise ResultFileError("this job did not dump contacts (contacts=False)")
        if self.engine != "lammps":
            (frame,) = parse_dump_local(self.job_dir / f, names=pair_gran_local_names(("id", "pos", "force", "delta")))
            return frame
        (frame,) = parse_dump_local(self.job_dir / f, names=LAMMPS_CONTACT_COLUMNS)
        Q = np.asarray(s.frames[idx], float)
        fxy = np.column_stack([frame["fx"], frame["fy"]]) @ Q  # rows: (Q^T f)^T = f^T Q
        r = self.packing.radii
        cols = dict(frame.columns)
        cols["fx"], cols["fy"] = fxy[:, 0].copy(), fxy[:, 1].copy()
        # atom ids are 1..N (central particles) and, in the images route, N+1.. (copies of src)
        src = self._image_sources(path, route, int(k)) if route == "images" else np.arange(len(r))
        rr = r[src[np.asarray(frame["id1"]) - 1]] + r[src[np.asarray(frame["id2"]) - 1]]
        cols["delta"] = rr - np.asarray(frame["dist"])
        for v in cols.values():
            v.flags.writeable = False
        return type(frame)(frame.step, frame.box, frame.tilt, frame.boundary, types.MappingProxyType(cols))

    def _image_sources(self, path: str, route: str, k: int) -> np.ndarray:
        """Original particle index of every atom of an images-route state (regenerated)."""
        s = self.get(path, route)
        F = s.F[int(np.nonzero(s.k == k)[0][0])]
        _, _, src, _ = image_state_packing(self.packing, F)
        return src


def read_taylor_job(job_dir, packing: Packing, manifest: dict | None = None) -> TaylorRun:
    """Parse a finished Taylor job directory into a :class:`TaylorRun`."""
    job_dir = Path(job_dir)
    meta = json.loads((job_dir / "states.json").read_text())
    engine = meta.get("engine", "liggghts")
    log = parse_log(job_dir / "log.lammps")
    states = meta["states"]
    if len(log.runs) != len(states):
        raise ReferenceRunError(
            f"{job_dir}: {len(states)} states in states.json but {len(log.runs)} runs in log.lammps", job_dir=job_dir
        )
    V = float(meta["reference_area"])
    groups: dict = {}
    for st, run in zip(states, log.runs):
        if len(run) != 1 or int(run.steps[0]) != st["index"]:
            raise ReferenceRunError(
                f"{job_dir}: run of state {st['index']} has steps {run.steps.tolist()}", job_dir=job_dir
            )
        F = np.array(st["F"], float)
        Q = np.array(st.get("frame", np.eye(2)), float)
        sums = np.array([run["c_sc[1]"][0], run["c_sc[2]"][0], run["c_sc[3]"][0]])
        # the engine's stress in its own frame, mapped back: sigma = Q^T sigma_engine Q
        sig = Q.T @ cauchy_from_stress_atom_sum(*sums, np.linalg.det(F) * V) @ Q
        if Q[0, 1] != 0:  # raw sums in gransim's frame too (xx and yy swapped)
            sums = np.array([sums[1], sums[0], sums[2]])
        if st["route"] == "periodic":
            sp = Q.T @ cauchy_from_pressure(run["c_p[1]"][0], run["c_p[2]"][0], run["c_p[4]"][0]) @ Q
        else:
            sp = np.full((2, 2), np.nan)
        groups.setdefault((st["path"], st["route"]), []).append(
            (st["k"], F, sig, sp, sums, st["contacts_file"], tuple(map(tuple, Q.tolist())))
        )
    series = {}
    for key, rows in groups.items():
        k, F, sig, sp, sums, cf, fr = zip(*rows)
        series[key] = TaylorSeries(
            key[0], key[1], np.array(k), np.array(F), np.array(sig), np.array(sp), np.array(sums), tuple(cf), tuple(fr)
        )
    return TaylorRun(
        meta["name"], packing, float(meta["kn"]), job_dir, types.MappingProxyType(series), manifest or {}, engine
    )


def run_taylor(
    packing: Packing,
    kn: float,
    job_dir,
    name: str = "packing",
    paths=PATHS,
    routes=ROUTES,
    n_steps: int = 50,
    max_strain: float = 0.1,
    stride: int = 1,
    contacts: bool = False,
    np_procs: int = 1,
    timeout: float | None = 3600.0,
    progress: bool = True,
    cleanup_inputs: bool = True,
    force: bool = False,
    engine: str = "liggghts",
) -> TaylorRun:
    """Run (or reuse) the Taylor job of one packing and parse it.

    ``engine``: ``"liggghts"`` or ``"lammps"`` (the deck of
    :func:`reference_runs.decks.taylor.taylor_job` for that code).

    ``timeout`` (s, None: no limit) bounds the job (and the wait for another process
    writing the same job): :class:`~reference_runs.errors.ReferenceRunError` with
    ``timed_out=True`` after it. ``force`` reruns even a complete job. ``cleanup_inputs`` deletes
    the per-state data files after a successful run (the manifest keeps their hashes; they are
    rewritten if the job has to run again). A reused job is verified first
    (:func:`reference_runs.runner.run_job`).
    """
    deck, files, states = taylor_job(
        packing,
        kn,
        paths=paths,
        routes=routes,
        n_steps=n_steps,
        max_strain=max_strain,
        stride=stride,
        contacts=contacts,
        name=name,
        engine=engine,
    )
    outputs = ["states.json"] + [s.contacts_file for s in states if s.contacts_file]
    if contacts:
        for s in states:
            (Path(job_dir) / s.contacts_file).parent.mkdir(parents=True, exist_ok=True)
    res = run_job(
        job_dir,
        deck,
        files,
        np=np_procs,
        timeout=timeout,
        progress=progress,
        outputs=outputs,
        expected_runs=len(states),
        desc=f"taylor {name}",
        force=force,
        engine=engine,
    )
    if cleanup_inputs and not res.skipped:
        for fname in files:
            if fname.endswith(".data"):
                (Path(job_dir) / fname).unlink(missing_ok=True)
    return read_taylor_job(job_dir, packing, res.manifest)


def write_taylor_h5(path, runs, parameters: dict | None = None):
    """Store Taylor runs: ``/<name>/packing``, ``/<name>/<path>/F``, ``/<name>/<path>/<route>/cauchy``..."""
    runs = list(runs)
    params = dict(parameters or {})
    engines = {run.engine for run in runs}
    with atomic_h5(
        path, kind="liggghts-taylor", parameters=params, liggghts="liggghts" in engines, lammps="lammps" in engines
    ) as f:
        if "yade" in engines:  # as gransim.io's provenance records LIGGGHTS' and LAMMPS' versions
            f.attrs["yade_version"] = YADE.version() or "absent"
        f.attrs["sign_convention"] = "tension positive (sigma = -p_liggghts)"
        f.attrs["units"] = "F dimensionless; stress N/m (2D); kn N/m"
        for run in runs:
            g = f.create_group(run.name)
            g.attrs["kn"] = run.kn
            g.attrs["engine"] = run.engine
            g.attrs["job_dir"] = str(run.job_dir)
            g.attrs["manifest"] = json.dumps(run.manifest, sort_keys=True)
            write_packing_group(g.create_group("packing"), run.packing)
            for (p, r), s in sorted(run.series.items()):
                gp = g.require_group(p)
                if "F" not in gp:
                    gp.create_dataset("F", data=s.F)
                    gp.create_dataset("k", data=s.k)
                gr = gp.create_group(r)
                gr.create_dataset("F", data=s.F)
                gr.create_dataset("cauchy", data=s.cauchy)
                gr.create_dataset("stress_atom_sum", data=s.stress_atom_sum)
                if r == "periodic":
                    gr.create_dataset("cauchy_pressure", data=s.cauchy_pressure)
    return Path(path)


def read_taylor_h5(path) -> dict:
    """``{name: {(path, route): {"F": ..., "cauchy": ...}}}`` from :func:`write_taylor_h5`."""
    out = {}
    with open_result(path, kind="liggghts-taylor") as f:
        for name in f:
            d = {}
            for p in f[name]:
                if p == "packing":
                    continue
                for r in f[name][p]:
                    if r in ROUTES:
                        d[(p, r)] = {k: f[name][p][r][k][()] for k in f[name][p][r]}
            out[name] = d
    return out


__all__ = [
    "PATHS",
    "ROUTES",
    "TaylorRun",
    "TaylorSeries",
    "read_taylor_h5",
    "read_taylor_job",
    "run_taylor",
    "write_taylor_h5",
]
