"""YADE's periodic DEM runs as runs of the validation matrix: live, stored, and native in YADE's arithmetic.

YADE 2023.02a runs the decks' short cases undamped (:mod:`reference_runs.yade.dem`: its damped law
takes a periodic image's velocity with the wrong sign, docs/yade.md). Three kinds of run, each a
:class:`validation.dem_compare.Trajectory` for the shared judges:

* :func:`live` : the YADE job run now (``reference_runs.yade.dem.run_yade_dem``, process group,
  timeout, no port), reused when complete;
* :func:`stored` : the same job's output stored under ``reference_runs/stored/<case>-yade/<name>``
  (``dem.out.gz``, gzip -9 -n, and the job's ``manifest.json``: YADE's version, the script's
  sha256, the input's sha256, the command), the stand-in of the live run when YADE is absent
  (``Run.fallback``); :func:`stored_verify` checks it against its manifest and against the inputs
  the case would give YADE now, and a file cut short, a frame or a step missing is an
  ``incomplete`` record (the run is then empty, so every comparison on it fails too);
* :func:`taylor_live`, :func:`taylor_stored` : YADE's Taylor states of the study RVEs
  (:mod:`reference_runs.yade.taylor`), run now or read from ``reference_runs/stored/taylor-rve-yade``;
* :func:`impact_live`, :func:`impact_stored` : YADE's runs of the impact scenes
  (:mod:`reference_runs.yade.impacts`), run now or read from ``reference_runs/stored/impacts-yade``;
* :func:`native` : ``gransim.dem.yade_arithmetic.yade_run`` on the same case (bit for bit with YADE
  at every step, docs/yade.md "The native yade arithmetic").

The trajectory's conventions are those of the decks' readers: stress compression positive (-z
``getStress()``; xx, yy, xy, YADE's stress is not symmetrised and xy is its (0, 1) entry), box
lengths (lx, ly) of an orthogonal cell or (lx, ly, xy) of a sheared one (``hSize`` [[lx, xy],
[0, ly]]); frames x, v (YADE's v_(k-1/2), the mean field included, on both sides alike), w, f, t.
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import json
import tempfile
from pathlib import Path

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem.yade_arithmetic import yade_run
from gransim.voidcell import Snapshot
from reference_runs.decks.shear import wrapped_packing
from reference_runs.errors import ReferenceRunError
from reference_runs.yade.dem import read_yade_dem, run_yade_dem
from reference_runs.yade.dem_script import INPUT_NAME, OUTPUT_NAME
from reference_runs.yade.impacts import INPUT_NAME as IMPACT_INPUT
from reference_runs.yade.impacts import OUTPUT_NAME as IMPACT_OUTPUT
from reference_runs.yade.impacts import impact_job, on_step_frames, read_yade_impact, yade_impacts
from reference_runs.yade.taylor import INPUT_NAME as TAYLOR_INPUT
from reference_runs.yade.taylor import OUTPUT_NAME as TAYLOR_OUTPUT
from reference_runs.yade.taylor import YadeTaylorRun, cell_z, read_yade_taylor, run_yade_taylor, yade_taylor_job

from .core import Record, compare
from .dem_compare import Trajectory, cell_rate

#: the stored output of a job: the output gzipped (gzip -9 -n) and the job's manifest
STORED_OUTPUT = OUTPUT_NAME + ".gz"
STORED_MANIFEST = "manifest.json"


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _trajectory(step, cell, stress, frames, sheared: bool) -> Trajectory:
    st = -np.stack([stress[:, 0, 0], stress[:, 1, 1], stress[:, 0, 1]], axis=1)
    cols = [cell[:, 0, 0], cell[:, 1, 1]] + ([cell[:, 0, 1]] if sheared else [])
    return Trajectory(np.asarray(step, np.int64), st, np.stack(cols, axis=1), frames)


def from_output(out, sheared: bool) -> Trajectory:
    """The trajectory of a YADE ``dem.out`` (:class:`reference_runs.yade.dem.YadeDemOutput`)."""
    frames = {
        int(k): {"x": f.positions, "v": f.velocities, "w": f.spins, "f": f.forces, "t": f.torques}
        for k, f in out.frames.items()
    }
    return _trajectory(out.step, out.cell, out.stress, frames, sheared)


def empty(sheared: bool) -> Trajectory:
    """A run without any step or frame (what an incomplete stored output leaves to compare)."""
    return Trajectory(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3 if sheared else 2)), {})


def native(packing, settings, loading, nsteps: int, thermo_every: int, dump_every: int, sheared: bool) -> Trajectory:
    """``yade_run`` of the case (the packing wrapped into the cell as the YADE job wraps it), sampled
    as the YADE job writes: every ``thermo_every``-th step, a frame every ``dump_every``-th."""
    r = yade_run(wrapped_packing(packing), settings, loading, nsteps)
    keep = np.arange(0, nsteps + 1, thermo_every)
    frames = {
        int(k): {"x": r.positions[k], "v": r.velocities[k], "w": r.spins[k], "f": r.forces[k], "t": r.torques[k]}
        for k in range(0, nsteps + 1, dump_every)
    }
    return _trajectory(r.step[keep], r.cell[keep], r.stress[keep], frames, sheared)


def live(job_dir, job, timeout: float, sheared: bool, manifests: dict | None = None, key: str = "") -> Trajectory:
    """Run (or reuse) the YADE job ``job = (script, files)`` in ``job_dir`` and read it. A failed or
    incomplete job raises (:class:`reference_runs.errors.ReferenceRunError`): the case did not run."""
    out, manifest = run_yade_dem(job_dir, *job, timeout=timeout)
    if manifests is not None:
        manifests[key] = manifest
    return from_output(out, sheared)


@functools.lru_cache(maxsize=16)
def _read_stored(d: str, sheared: bool) -> tuple:
    """(trajectory, output bytes or None, problem or ""): the stored output read with the evidence
    accounting of the live job (``read_yade_dem`` against its own input counts)."""
    d = Path(d)
    try:
        text = gzip.decompress((d / STORED_OUTPUT).read_bytes())
    except (OSError, EOFError, gzip.BadGzipFile) as exc:
        return empty(sheared), None, f"incomplete: {d / STORED_OUTPUT}: cannot be read ({exc})"
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / OUTPUT_NAME).write_bytes(text)
        try:
            meta = json.loads((d / INPUT_NAME).read_text())
            expect = {k: meta[k] for k in ("n_steps", "thermo_every", "dump_every")}
            expect["n_particles"] = len(meta["radii"])
            out = read_yade_dem(Path(tmp) / OUTPUT_NAME, expect)
        except ReferenceRunError as exc:
            return empty(sheared), text, str(exc).splitlines()[0].replace(tmp, str(d))
        except (OSError, ValueError, KeyError) as exc:
            return empty(sheared), text, f"incomplete: {d / INPUT_NAME}: cannot read the job's counts ({exc})"
    return from_output(out, sheared), text, ""


def stored(d, sheared: bool):
    """The ``make`` of a stored YADE run in directory ``d``: its trajectory, or an empty one when the
    output is incomplete (:func:`stored_verify` records why)."""
    return lambda: _read_stored(str(d), sheared)[0]


STORED_REASON = (
    "a stored YADE output stands in for the live run only if it is the output of this very case: its sha256 is "
    "the manifest's, the manifest's script is today's DEM_SCRIPT and its input.json the one this case gives YADE "
    "now, and YADE's version is recorded; otherwise the comparisons would judge another run"
)


def stored_verify(d, job, sheared: bool):
    """The ``verify`` of a stored YADE run: the output complete (an ``incomplete`` record naming the
    problem otherwise) and equal to its manifest's hashes, the script and the input those of the
    case now (``job = (script, files)`` as :func:`reference_runs.yade.dem.biaxial_job` builds it)."""

    def verify(label: str, _run) -> list:
        _, text, problem = _read_stored(str(d), sheared)
        if problem:
            return [Record(label, "evidence", f"incomplete: stored YADE output: {problem}", 1.0, 0.0, False)]
        man = json.loads((Path(d) / STORED_MANIFEST).read_text())
        script, files = job
        bad = [
            what
            for what, ok in (
                ("output sha256", _sha(text) == man.get("outputs", {}).get(OUTPUT_NAME)),
                ("status", man.get("status") == "ok"),
                ("YADE version", str(man.get("engine_version", "")).startswith("YADE ")),
                ("script sha256", man.get("deck_sha256") == _sha(script.encode())),
                ("input sha256", man.get("inputs", {}).get(INPUT_NAME) == _sha(files[INPUT_NAME])),
                ("stored input", (Path(d) / INPUT_NAME).read_bytes() == files[INPUT_NAME]),
                ("command", bool(man.get("command"))),
            )
            if not ok
        ]
        return [
            compare(
                label,
                "evidence",
                f"stored YADE output against its manifest ({man.get('engine_version')}): items that differ"
                + (f" ({', '.join(bad)})" if bad else ""),
                float(len(bad)),
                0.0,
                STORED_REASON,
            )
        ]

    return verify


def store(job_dir, dest) -> None:
    """Store a complete YADE job (its ``dem.out`` gzipped, its input and manifest) in ``dest``:
    ``python -c "from validation.yade_runs import store; store(JOB, DEST)"`` after a live run."""
    job_dir, dest = Path(job_dir), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    (dest / STORED_OUTPUT).write_bytes(gzip.compress((job_dir / OUTPUT_NAME).read_bytes(), 9, mtime=0))
    (dest / INPUT_NAME).write_bytes((job_dir / INPUT_NAME).read_bytes())
    (dest / STORED_MANIFEST).write_bytes((job_dir / STORED_MANIFEST).read_bytes())


def yade_snapshot(tr: Trajectory, step: int, radii: np.ndarray, dt: float) -> Snapshot:
    """A :class:`gransim.voidcell.Snapshot` of a frame of a YADE run in an orthogonal cell, built as
    :func:`validation.dem_compare.snapshot` builds the decks' (contacts = overlapping pairs of the
    positions, dC/dt by central differences of the box lengths) except the velocities: YADE's hold
    the mean field already (homoDeform 2, docs/yade.md), so they are taken as they are, at
    v_(k-1/2) as YADE holds them (the same on the native side)."""
    fr = tr.frames[step]
    C = np.diag(tr.lengths[tr.at([step])[0]])
    nl = find_neighbours(fr["x"], radii, C, skin=0.0)
    return Snapshot(
        positions=fr["x"],
        cell=C,
        contacts_i=nl.i,
        contacts_j=nl.j,
        contacts_shift=nl.shift,
        velocities=fr["v"],
        cell_velocity=cell_rate(tr, step, dt),
        radii=radii,
    )


# ---------------------------------------------------------------- Taylor states
def taylor_live(packings: dict, kn: float, job_root, n_steps: int, stride: int, timeout) -> dict:
    """YADE's Taylor jobs of ``packings`` ({RVE: packing}), one per RVE in ``job_root/<RVE>``
    (reused when complete): {RVE: :class:`reference_runs.yade.taylor.YadeTaylorRun`, or the first
    line of the error of a job that failed or left an incomplete output}. ``timeout(packing)``."""
    out = {}
    for name, packing in packings.items():
        try:
            out[name] = run_yade_taylor(
                packing, kn, Path(job_root) / name, n_steps=n_steps, stride=stride, name=name, timeout=timeout(packing)
            )
        except ReferenceRunError as exc:
            out[name] = str(exc).splitlines()[0]
    return out


def taylor_stored(packings: dict, kn: float, root, n_steps: int, stride: int) -> dict:
    """The stored outputs of YADE's Taylor jobs (``root/<RVE>``: ``taylor.out.gz``, ``input.json``,
    ``manifest.json``), read as :func:`taylor_live` reads a job: {RVE: run, or why it cannot stand in
    (incomplete, or not this job's output: its hashes against the manifest and the input this case
    gives YADE now)}."""
    out = {}
    for name, packing in packings.items():
        d = Path(root) / name
        script, files, states = yade_taylor_job(packing, kn, n_steps=n_steps, stride=stride, name=name)
        try:
            text = gzip.decompress((d / (TAYLOR_OUTPUT + ".gz")).read_bytes())
            man = json.loads((d / STORED_MANIFEST).read_text())
        except (OSError, EOFError, ValueError, gzip.BadGzipFile) as exc:
            out[name] = f"incomplete: stored YADE output {d}: cannot be read ({exc})"
            continue
        bad = [
            what
            for what, ok in (
                ("output sha256", _sha(text) == man.get("outputs", {}).get(TAYLOR_OUTPUT)),
                ("script sha256", man.get("deck_sha256") == _sha(script.encode())),
                ("input sha256", man.get("inputs", {}).get(TAYLOR_INPUT) == _sha(files[TAYLOR_INPUT])),
                ("YADE version", str(man.get("engine_version", "")).startswith("YADE ")),
            )
            if not ok
        ]
        if bad:
            out[name] = f"stored YADE output {d} is not this job's: {', '.join(bad)} differ from its manifest"
            continue
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / TAYLOR_OUTPUT).write_bytes(text)
            try:
                raw = read_yade_taylor(Path(tmp) / TAYLOR_OUTPUT, len(states))
            except ReferenceRunError as exc:
                out[name] = f"stored YADE output: {str(exc).splitlines()[0].replace(tmp, str(d))}"
                continue
        z = cell_z(packing)
        out[name] = YadeTaylorRun(
            packing,
            float(kn),
            z,
            d,
            man,
            tuple(states),
            np.array([s["F"] for s in states], float),
            np.array([s.stress[:2, :2] * z for s in raw]),
            np.array([s.tangent * z for s in raw]),
            np.array([s.n_contacts for s in raw]),
            tuple(raw),
        )
    return out


def store_taylor(job_dir, dest) -> None:
    """Store a complete YADE Taylor job (``taylor.out`` gzipped, its input and manifest) in ``dest``."""
    job_dir, dest = Path(job_dir), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    (dest / (TAYLOR_OUTPUT + ".gz")).write_bytes(gzip.compress((job_dir / TAYLOR_OUTPUT).read_bytes(), 9, mtime=0))
    (dest / TAYLOR_INPUT).write_bytes((job_dir / TAYLOR_INPUT).read_bytes())
    (dest / STORED_MANIFEST).write_bytes((job_dir / STORED_MANIFEST).read_bytes())


# ---------------------------------------------------------------- impact scenes
def impact_live(job_dir, packing, velocities, spins, law, dt: float, n_steps: int, every: int, timeout) -> dict:
    """YADE's run of an impact scene now (reused when complete): its frames on the step
    (:func:`reference_runs.yade.impacts.yade_impacts`). A failed or incomplete job raises."""
    frames, _ = yade_impacts(job_dir, packing, velocities, spins, law, dt, n_steps, every, timeout=timeout)
    return frames


def impact_stored(d, packing, velocities, spins, law, dt: float, n_steps: int, every: int):
    """The stored output of YADE's run of an impact scene (``d``: ``impact.out.gz``, ``input.json``,
    ``manifest.json``): its frames on the step, or why it cannot stand in (incomplete, or not this
    scene's job: its hashes against the manifest and the input the case gives YADE now)."""
    d = Path(d)
    script, files = impact_job(packing, velocities, spins, law, dt, n_steps, every)
    try:
        text = gzip.decompress((d / (IMPACT_OUTPUT + ".gz")).read_bytes())
        man = json.loads((d / STORED_MANIFEST).read_text())
    except (OSError, EOFError, ValueError, gzip.BadGzipFile) as exc:
        return f"incomplete: stored YADE output {d}: cannot be read ({exc})"
    bad = [
        what
        for what, ok in (
            ("output sha256", _sha(text) == man.get("outputs", {}).get(IMPACT_OUTPUT)),
            ("script sha256", man.get("deck_sha256") == _sha(script.encode())),
            ("input sha256", man.get("inputs", {}).get(IMPACT_INPUT) == _sha(files[IMPACT_INPUT])),
            ("YADE version", str(man.get("engine_version", "")).startswith("YADE ")),
        )
        if not ok
    ]
    if bad:
        return f"stored YADE output {d} is not this job's: {', '.join(bad)} differ from its manifest"
    meta = json.loads(files[IMPACT_INPUT])
    expect = {"n_particles": len(meta["mass"]), "n_steps": n_steps, "every": every}
    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / IMPACT_OUTPUT).write_bytes(text)
        try:
            out = read_yade_impact(Path(tmp) / IMPACT_OUTPUT, expect)
        except ReferenceRunError as exc:
            return f"stored YADE output: {str(exc).splitlines()[0].replace(tmp, str(d))}"
    return on_step_frames(out, files)


def store_impact(job_dir, dest) -> None:
    """Store a complete YADE impact job (``impact.out`` gzipped, its input and manifest) in ``dest``."""
    job_dir, dest = Path(job_dir), Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    (dest / (IMPACT_OUTPUT + ".gz")).write_bytes(gzip.compress((job_dir / IMPACT_OUTPUT).read_bytes(), 9, mtime=0))
    (dest / IMPACT_INPUT).write_bytes((job_dir / IMPACT_INPUT).read_bytes())
    (dest / STORED_MANIFEST).write_bytes((job_dir / STORED_MANIFEST).read_bytes())
