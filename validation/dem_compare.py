"""Native DEM runs and LIGGGHTS runs of the same deck, as comparable trajectories.

Used by the cases ``biaxial-short``, ``biaxial-full`` and ``voidcell``. Both sides produce a
:class:`Trajectory`: the stress (LIGGGHTS' compression-positive virial, the in-memory form of
:class:`gransim.dem.DEMEngine`; the comparisons are sign-independent) and the box lengths at every
step, and per-particle frames (positions, velocities, spins, forces, torques) every
``dump_every`` steps. The LIGGGHTS side runs through :func:`reference_runs.runner.run_job` (job
directory with a manifest; a complete job with the same inputs is reused) and is read with
:mod:`reference_runs.parsers`.

``native_setup`` is the one place where the native side's settings are taken from the deck's:
it is the identity, and the tests of the validation layer replace it (1% stiffer contacts, no
servo) to show that the cases can fail.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem import DEMEngine
from gransim.voidcell import Snapshot
from reference_runs.decks.biaxial import write_biaxial_deck
from reference_runs.parsers import parse_dump_custom, parse_log
from reference_runs.runner import run_job

from .core import default_job_timeout, evidence

#: per-particle columns of a frame
FRAME_KEYS = ("x", "v", "w", "f", "t")


def native_setup(settings, loading):
    """Settings of the native side (identity; the validation tests perturb it)."""
    return settings, loading


@dataclass(frozen=True)
class Trajectory:
    """One run seen at every step (stress, box) and every ``dump_every`` steps (particles).

    steps : (T,) int64 step numbers of the series (0 = the run's set-up).
    stress : (T, 3) xx, yy, xy of the virial stress, compression positive (N/m).
    lengths : (T, 2) box side lengths after the step (m).
    frames : {step: {"x": (N, 2), "v": (N, 2), "w": (N,), "f": (N, 2), "t": (N,)}}.
    elapsed : wall time of the run (s), 0 when a stored or reused run was read.
    """

    steps: np.ndarray
    stress: np.ndarray
    lengths: np.ndarray
    frames: dict
    elapsed: float = 0.0

    def at(self, steps) -> np.ndarray:
        """Row indices of ``steps`` in the series."""
        idx = np.searchsorted(self.steps, steps)
        if np.any(idx >= len(self.steps)) or np.any(self.steps[np.minimum(idx, len(self.steps) - 1)] != steps):
            raise KeyError(f"steps {steps} not all in the series")
        return idx


def _frame(eng) -> dict:
    return {"x": eng.x.copy(), "v": eng.v.copy(), "w": eng.w.copy(), "f": eng.f.copy(), "t": eng.t.copy()}


def run_native(
    packing,
    settings,
    loading,
    nsteps: int,
    dump_every: int,
    velocities=None,
    spins=None,
    thermo_every: int = 1,
    law=None,
    check_dt: bool = True,
) -> Trajectory:
    """Run the native engine (serial mode, the mode compared step for step) from ``packing``; the
    series keeps every ``thermo_every``-th step (as the LIGGGHTS deck's thermo). ``law``: a
    contact law object of :mod:`gransim.contacts.laws` (None: the Hooke law of ``settings``)."""
    settings, loading = native_setup(settings, loading)
    t0 = time.perf_counter()
    kw = {} if law is None else {"law": law}
    eng = DEMEngine(packing, settings, velocities=velocities, spins=spins, check_dt=check_dt, **kw)
    box0 = (eng.lo.copy(), eng.hi.copy())
    st = [np.array([eng.stress[0, 0], eng.stress[1, 1], eng.stress[0, 1]])[None]]
    L = [eng.box_lengths.copy()[None]]
    frames = {0: _frame(eng)}
    done = 0
    while done < nsteps:
        stop = min(nsteps, (done // dump_every + 1) * dump_every)
        out = eng.advance(loading, stop - done, phase_step0=0, phase_box0=box0)
        done = stop
        s = out["stress"]
        st.append(np.stack([s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]], axis=1))
        L.append(out["lengths"])
        if done % dump_every == 0:
            frames[done] = _frame(eng)
    keep = slice(None, None, int(thermo_every))
    return Trajectory(
        np.arange(nsteps + 1)[keep], np.concatenate(st)[keep], np.concatenate(L)[keep], frames, time.perf_counter() - t0
    )


def read_reference(log_path, dump_path) -> Trajectory:
    """A trajectory from the log (thermo: step lx ly xlo xhi ylo yhi c_pt[1] c_pt[2] c_pt[4]) and the
    ``dump custom`` (id x y vx vy omegaz fx fy tqz mass radius) of a deck of
    :func:`reference_runs.decks.biaxial.write_biaxial_deck`."""
    run = parse_log(Path(log_path)).runs[-1]
    steps = run.steps
    stress = np.stack([run["c_pt[1]"], run["c_pt[2]"], run["c_pt[4]"]], axis=1)
    lengths = np.stack([run["lx"], run["ly"]], axis=1)
    frames = {}
    for fr in parse_dump_custom(Path(dump_path)):
        frames[int(fr.step)] = {
            "x": fr.array("x", "y"),
            "v": fr.array("vx", "vy"),
            "w": np.array(fr["omegaz"]),
            "f": fr.array("fx", "fy"),
            "t": np.array(fr["tqz"]),
        }
    return Trajectory(steps, stress, lengths, frames)


#: the LIGGGHTS and LAMMPS mirror decks print the same columns
read_liggghts = read_reference


#: display names of the reference codes
CODE_NAMES = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}


def run_reference_job(
    job_dir,
    packing,
    settings,
    loading,
    nsteps: int,
    dump_every: int,
    velocities=None,
    spins=None,
    np_procs: int = 1,
    thermo_every: int = 1,
    timeout: float | None = None,
    engine: str = "liggghts",
    law=None,
) -> tuple[Trajectory, dict]:
    """Write the mirror deck of the run for ``engine`` ("liggghts" or "lammps") and run it in
    ``job_dir`` (reused when complete).

    ``timeout`` (s) kills the job (and its process group) when exceeded; None scales it with the
    work (:data:`validation.core.JOB_TIMEOUT_PER_PSTEP`). Returns the trajectory and the job
    manifest (command, version, elapsed time, hashes). Both codes' decks print the same thermo
    and dump columns, so one reader serves both. ``law``: a contact law object (None: the Hooke
    law of ``settings``), written into the deck in ``engine``'s syntax.
    """
    if timeout is None:
        timeout = default_job_timeout(packing.n * nsteps)

    kw = {} if engine == "liggghts" else {"engine": engine}
    lkw = {} if law is None else {"law": law}
    with tempfile.TemporaryDirectory() as tmp:
        deck = write_biaxial_deck(
            tmp,
            packing,
            settings,
            loading,
            nsteps,
            thermo_every=thermo_every,
            dump_every=dump_every,
            velocities=velocities,
            spins=spins,
            **kw,
            **lkw,
        )
        files = {q.name: q.read_bytes() for q in Path(tmp).iterdir() if q.is_file() and q != deck}
        res = run_job(
            job_dir,
            deck.read_text(),
            files=files,
            np=np_procs,
            outputs=("dump.atoms",),
            expected_runs=1,
            progress=False,
            timeout=timeout,
            **kw,
        )
    traj = read_liggghts(res.log_path, res.path("dump.atoms"))
    el = 0.0 if res.skipped else float(res.manifest.get("elapsed_s", 0.0))
    return Trajectory(traj.steps, traj.stress, traj.lengths, traj.frames, el), res.manifest


def run_liggghts_job(
    job_dir,
    packing,
    settings,
    loading,
    nsteps: int,
    dump_every: int,
    velocities=None,
    spins=None,
    np_procs: int = 1,
    thermo_every: int = 1,
    timeout: float | None = None,
) -> tuple[Trajectory, dict]:
    """:func:`run_reference_job` with LIGGGHTS."""
    return run_reference_job(
        job_dir,
        packing,
        settings,
        loading,
        nsteps,
        dump_every,
        velocities,
        spins,
        np_procs=np_procs,
        thermo_every=thermo_every,
        timeout=timeout,
    )


# ------------------------------------------------------------------ evidence
def expected_steps(nsteps: int, every: int = 1) -> np.ndarray:
    """Steps a run of ``nsteps`` samples when it keeps every ``every``-th step from 0: the thermo
    rows of the LIGGGHTS deck and the native series, and (with ``every`` = the dump interval) the
    dump frames."""
    return np.arange(0, int(nsteps) + 1, int(every), dtype=np.int64)


#: the frames of a run dumped every ``dump_every`` steps are sampled like its series
expected_frames = expected_steps


def trajectory_evidence(label: str, who: str, tr: Trajectory, steps, frames) -> list:
    """Evidence records of one side: every expected series step and every expected frame present.

    ``steps``/``frames`` are the expected step numbers (:func:`expected_steps`,
    :func:`expected_frames`; None: not checked); ``who`` names the side (``native``, ``LIGGGHTS``). A frame counts
    only if it holds every per-particle column for the same number of particles as frame 0 and
    finite values.
    """
    recs = []
    if steps is not None:
        have = set(int(s) for s in tr.steps[np.all(np.isfinite(tr.stress), axis=1)]) if len(tr.steps) else set()
        recs.append(evidence(label, f"{who} series steps", [int(s) for s in steps], have))
    if frames is not None:
        n0 = None  # particle count of the first whole frame: every frame must have it
        good = set()
        for s, fr in tr.frames.items():
            try:
                n = len(fr["x"])
                ok = all(k in fr and len(fr[k]) == n and np.all(np.isfinite(fr[k])) for k in FRAME_KEYS)
            except (KeyError, TypeError):
                ok = False
            if ok:
                n0 = n if n0 is None else n0
                if n == n0:
                    good.add(int(s))
        recs.append(evidence(label, f"{who} frames", [int(s) for s in frames], good))
    return recs


# ------------------------------------------------------------------ differences
def position_difference(a: np.ndarray, b: np.ndarray, lengths: np.ndarray) -> float:
    """Largest |x_a - x_b| (m) over particles and axes, modulo the box (a code may wrap a particle
    at another step)."""
    d = a - b
    d -= np.round(d / lengths) * lengths
    return float(np.abs(d).max())


def frame_differences(a: Trajectory, b: Trajectory, d50: float, steps=None) -> dict:
    """Per frame step: position difference / D50 and the relative differences of velocities,
    spins, forces, torques (max |a - b| / max |b| over the frame). Returns {key: (steps, values)}.

    ``steps``: the frames to compare (default: those present in both). A step missing on either
    side is a KeyError: completeness is checked first (:func:`trajectory_evidence`)."""
    if steps is None:
        steps = sorted(set(a.frames) & set(b.frames))
    steps = np.array(sorted(int(s) for s in steps), np.int64)
    out = {k: np.zeros(len(steps)) for k in FRAME_KEYS}
    for n, s in enumerate(steps):
        fa, fb = a.frames[s], b.frames[s]
        L = b.lengths[b.at([s])[0]]
        out["x"][n] = position_difference(fa["x"], fb["x"], L) / d50
        for k in ("v", "w", "f", "t"):
            scale = float(np.abs(fb[k]).max()) or 1.0
            out[k][n] = float(np.abs(fa[k] - fb[k]).max()) / scale
    return {"steps": steps, **out}


def reduce_sheared(d: np.ndarray, cell: np.ndarray) -> np.ndarray:
    """``d`` (N, 2) minus the nearest lattice vector of ``cell`` (columns a1, a2): a disk wrapped at
    another step on one side differs by a lattice vector of the current box (remap v moves a
    wrapped disk as its image)."""
    lam = np.linalg.solve(cell, d.T).T
    return d - np.round(lam) @ cell.T


def sheared_cell(box_row) -> np.ndarray:
    """The cell [[lx, xy], [0, ly]] of a box row (lx, ly, xy) of a sheared run."""
    lx, ly, xy = (float(v) for v in box_row[:3])
    return np.array([[lx, xy], [0.0, ly]])


def sheared_frame_differences(a: Trajectory, b: Trajectory, d50: float, steps) -> dict:
    """:func:`frame_differences` of runs in a sheared cell (``lengths`` (T, 3) = lx, ly, xy):
    positions modulo the sheared cell of ``b`` (:func:`reduce_sheared`)."""
    steps = np.array(sorted(int(s) for s in steps), np.int64)
    out = {k: np.zeros(len(steps)) for k in FRAME_KEYS}
    for n, s in enumerate(steps):
        fa, fb = a.frames[s], b.frames[s]
        cell = sheared_cell(b.lengths[b.at([s])[0]])
        out["x"][n] = float(np.abs(reduce_sheared(fa["x"] - fb["x"], cell)).max()) / d50
        for k in ("v", "w", "f", "t"):
            scale = float(np.abs(fb[k]).max()) or 1.0
            out[k][n] = float(np.abs(fa[k] - fb[k]).max()) / scale
    return {"steps": steps, **out}


def stress_differences(a: Trajectory, b: Trajectory, steps=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per step: max_component |sigma_a - sigma_b| / max_component |sigma_b| (sigma_xy passes
    through zero, so the scale is the largest component), and |L_a - L_b| max (m). Returns
    (steps, rel stress diff, box diff). ``steps`` default: those present in both."""
    steps = np.intersect1d(a.steps, b.steps) if steps is None else np.asarray(steps, np.int64)
    ia, ib = a.at(steps), b.at(steps)
    sa, sb = a.stress[ia], b.stress[ib]
    scale = np.abs(sb).max(axis=1)
    rel = np.abs(sa - sb).max(axis=1) / np.where(scale > 0, scale, 1.0)
    dl = np.abs(a.lengths[ia] - b.lengths[ib]).max(axis=1)
    return steps, rel, dl


# ------------------------------------------------------------------ void-cell snapshots
def cell_rate(tr: Trajectory, step: int, dt: float) -> np.ndarray:
    """dC/dt (2, 2) at ``step`` by central differences of the box lengths (one-sided at the ends)."""
    k = int(tr.at([step])[0])
    a, b = max(k - 1, 0), min(k + 1, len(tr.steps) - 1)
    rate = (tr.lengths[b] - tr.lengths[a]) / ((tr.steps[b] - tr.steps[a]) * dt)
    return np.diag(rate)


def snapshot(tr: Trajectory, step: int, radii: np.ndarray, dt: float):
    """A :class:`gransim.voidcell.Snapshot` of a frame, the same way for both codes.

    Contacts from the positions (``find_neighbours(skin=0)``: overlapping pairs), so both sides
    use one contact definition. Velocities: both codes deform the box with ``remap x``, so the
    stored v lacks the affine streaming; it is added, v + (dC/dt) C^{-1} x (voidcell notes).
    """
    fr = tr.frames[step]
    C = np.diag(tr.lengths[tr.at([step])[0]])
    Cd = cell_rate(tr, step, dt)
    nl = find_neighbours(fr["x"], radii, C, skin=0.0)
    v = fr["v"] + fr["x"] @ (Cd @ np.linalg.inv(C)).T
    return Snapshot(
        positions=fr["x"],
        cell=C,
        contacts_i=nl.i,
        contacts_j=nl.j,
        contacts_shift=nl.shift,
        velocities=v,
        cell_velocity=Cd,
        radii=radii,
    )
