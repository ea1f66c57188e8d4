"""Frictionless damped DEM relaxation of a periodic RVE to rest at a prescribed F, LIGGGHTS and LAMMPS.

The relaxed RVE of :mod:`gransim.rve.relaxed` minimises the contact energy over periodic
fluctuations at fixed F (Miehe & Dettmar, "A framework for micro-macro transitions in periodic
particle aggregates of granular materials", 2004, sections 3-4). A DEM run at the same F with a box
that does not move, frictionless contacts (kt = 0, mu = 0) whose elastic part is the same linear
normal spring (Meier, Steinmann & Kuhl 2007, eqs 3-5: f = -E_n eps n, so kn = E_n) and viscous
normal damping only (``gamman``; gammat = 0) dissipates energy until the particles rest in a local
minimum of that energy: the state whose stress the relaxed RVE computes.

A *state* is a name and F. The deformed assembly is the reference RVE mapped affinely, x = F X
(X wrapped into the reference cell), in the box F C, with zero velocities:

* diagonal F (compression paths): the orthogonal periodic box of
  :func:`reference_runs.decks.taylor.periodic_state_packing`, run by the mirror deck of
  :func:`reference_runs.decks.biaxial.write_biaxial_deck` with both axes fixed (``Loading()``: no
  ``fix deform``), in LIGGGHTS (``hooke/stiffness tangential history``, ``fix nve/sphere``) or LAMMPS
  (``gran/hooke/history``, ``fix nve/sphere disc``). The native engine
  (:class:`gransim.dem.DEMEngine` in that code's flavour) mirrors each deck step for step.
* simple shear F = [[1, g], [0, 1]] (LAMMPS only: LIGGGHTS 3.8.0's triclinic boxes have no periodic
  ghosts, shared notes): a true periodic triclinic box F C (data file with its ``xy`` tilt, centres
  x = F X, :func:`reference_runs.decks.taylor.triclinic_state`), the deck of
  :func:`reference_runs.decks.shear.deck_text` with ``ShearLoading()`` (no ``fix deform``: the box
  stays); native :class:`gransim.dem.sheared.ShearEngine` (flavour lammps).

Outputs of every job: thermo every :data:`THERMO_EVERY` steps (box, virial stress ``c_pt[1,2,4]``,
compression positive) and a ``dump custom`` (id x y vx vy omegaz fx fy tqz mass radius) at steps 0
and ``nsteps``; the final frame gives the kinetic energy and the positions from which the residual
forces are recomputed.

The RVE (:func:`relaxation_packing`): the perturbed triangular lattice of the stored Taylor case,
8 x 8 disks (seed 7), first relaxed at F = 1 by the relaxed RVE's Newton minimiser, so that the
reference is at rest (as the generator's FIRE packings are) and every disk has at least three
contacts (no rattlers: see docs/validation.md, ``relaxation``, on why rattlers matter here).
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

from gransim.dem.settings import DEMSettings, Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import GransimError, InputError
from gransim.geometry import Packing
from gransim.io import load_packing, save_packing
from gransim.paper import KN_2D
from gransim.rve.relaxed import RelaxedMaterial

from ..demo_packings import perturbed_lattice
from ..engines import get_engine
from ..runner import run_job
from ..store import STORED
from .biaxial import write_biaxial_deck
from .shear import deck_text as shear_deck_text
from .taylor import _write_lammps_data, periodic_state_packing, triclinic_state

#: the prescribed states: name -> F (compression paths and a simple shear)
STATES = {
    "iso": ((0.998, 0.0), (0.0, 0.998)),
    "compression-22": ((1.0, 0.0), (0.0, 0.997)),
    "shear-12": ((1.0, 0.002), (0.0, 1.0)),
}
#: the states each code runs (LIGGGHTS: orthogonal boxes only)
ENGINE_STATES = {"liggghts": ("iso", "compression-22"), "lammps": ("iso", "compression-22", "shear-12")}
#: damping ratio of the normal contact of two median disks (overdamped: every mode of the network
#: is damped and a disk pushed off a contact leaves it without rebounding)
DAMPING_RATIO = 2.0
STEPS_PER_CONTACT = 50.0
SKIN_D50 = 0.05
#: steps of each relaxation (measured on the lattice RVE: at rest to round-off, KE/U ~ 4e-27, after
#: about 2000 steps in every state; 5000 leave a factor 2.5)
NSTEPS = 5000
THERMO_EVERY = 100
DUMP = "dump.atoms"
#: the stored jobs: reference_runs/stored/<STORED_CASE>/<engine>-<state>/
STORED_CASE = "relaxation-lattice-8x8"
LATTICE = {"nx": 8, "ny": 8, "seed": 7}


def state_F(name: str) -> np.ndarray:
    """F (2, 2) of a state of :data:`STATES`."""
    if name not in STATES:
        raise InputError(f"unknown relaxation state {name!r}; choose one of: {', '.join(STATES)}")
    return np.array(STATES[name], float)


def relaxation_packing() -> Packing:
    """The RVE of the case, regenerated: ``perturbed_lattice(8, 8, seed=7)`` moved to its relaxed
    minimum at F = 1 (x = X + w*(1), :class:`gransim.rve.relaxed.RelaxedMaterial`, E_n = KN_2D).
    The stored ``packing.h5`` is the case's definition; this is how it was made."""
    p = perturbed_lattice(LATTICE["nx"], LATTICE["ny"], seed=LATTICE["seed"])
    r = RelaxedMaterial(p, KN_2D)(np.eye(2))
    if r.rattlers.any():
        raise InputError(f"relaxation packing: {int(r.rattlers.sum())} rattlers at F = 1 (expected none)")
    meta = dict(p.metadata)
    meta.update({"source": "perturbed_lattice relaxed at F = 1", **LATTICE, "kn": KN_2D})
    return Packing(p.positions + r.fluctuation, p.radii, p.cell, density=p.density, metadata=meta)


def relaxation_settings(packing: Packing, kn: float = KN_2D, flavour: str = "liggghts") -> DEMSettings:
    """Frictionless damped settings: kt = 0, mu = 0, gamma_t = 0, gamma_n for a damping ratio
    :data:`DAMPING_RATIO` of two median disks, dt = contact time / :data:`STEPS_PER_CONTACT`, skin
    :data:`SKIN_D50` D50 (:meth:`gransim.dem.DEMSettings.for_packing`)."""
    s = DEMSettings.for_packing(
        packing,
        kn,
        kt=0.0,
        mu=0.0,
        damping_ratio=DAMPING_RATIO,
        steps_per_contact=STEPS_PER_CONTACT,
        skin_d50=SKIN_D50,
        flavour=flavour,
    )
    return dataclasses.replace(s, gamma_t=0.0)


def deformed_state(packing: Packing, F):
    """The assembly at F: ``(packing_at_F, kind)``, kind ``"orthogonal"`` (diagonal F: centres x =
    F X in [0, F11 Lx) x [0, F22 Ly)) or ``"triclinic"`` (packing with cell [[lx, xy], [0, ly]] and
    centres x = F X as in the LAMMPS periodic Taylor route)."""
    F = np.asarray(F, float)
    if F[0, 1] == 0.0 and F[1, 0] == 0.0:
        return periodic_state_packing(packing, F), "orthogonal"
    if F[1, 0] != 0.0:
        raise InputError(f"F: the relaxation decks take diagonal F or simple shear F12 (F21 = 0), got {F.tolist()}")
    x, (lx, ly, xy), _ = triclinic_state(packing, F)
    return packing.replace(positions=x, cell=np.array([[lx, xy], [0.0, ly]])), "triclinic"


def write_job(job_dir, packing: Packing, F, settings: DEMSettings, nsteps: int = NSTEPS, engine: str = "liggghts"):
    """Write the deck and data file of one relaxation into ``job_dir``; returns (deck text, files)."""
    q, kind = deformed_state(packing, F)
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    if kind == "orthogonal":
        deck = write_biaxial_deck(
            job, q, settings, Loading(), nsteps, thermo_every=THERMO_EVERY, dump_every=nsteps, engine=engine
        )
        data = "data.biaxial"
    else:
        if engine != "lammps":
            raise InputError(
                "engine: a sheared (triclinic) periodic box runs in LAMMPS only (LIGGGHTS 3.8.0 loses the "
                "periodic ghosts of tilted boxes, shared notes liggghts-3.8.md)"
            )
        data = "data.shear"
        c = q.cell
        _write_lammps_data(job / data, q.positions, q.radii, q.density, (c[0, 0], c[1, 1], c[0, 1]))
        deck = job / "in.shear"
        deck.write_text(
            shear_deck_text(q, settings, ShearLoading(), nsteps, thermo_every=THERMO_EVERY, dump_every=nsteps)
        )
    return deck.read_text(), {data: (job / data).read_bytes()}


def run_relaxation_job(job_dir, packing, F, settings, nsteps: int = NSTEPS, engine: str = "liggghts", timeout=None):
    """Write and run (or reuse, when complete) one relaxation job; returns the
    :class:`~reference_runs.runner.JobResult`."""
    with tempfile.TemporaryDirectory() as tmp:
        deck, files = write_job(tmp, packing, F, settings, nsteps, engine)
    return run_job(
        job_dir,
        deck,
        files=files,
        outputs=(DUMP,),
        expected_runs=1,
        progress=False,
        timeout=timeout,
        engine=engine,
    )


_README = """\
# Stored reference outputs: `{case}`

Frictionless damped DEM relaxations to rest of one periodic RVE at prescribed deformation
gradients F (validation case `relaxation`, docs/validation.md). Made by
`python -m reference_runs.store --case relaxation` on {date}.

- RVE: `packing.h5` ({n} disks, cell {lx:.6g} m x {ly:.6g} m): `reference_runs.demo_packings.perturbed_lattice(8, 8,
  seed=7)` moved to its relaxed minimum at F = 1 (`reference_runs.decks.relaxation.relaxation_packing`).
- Contact: kn = E_n = {kn:g} N/m, kt = 0, mu = 0, gamman = {gn:.6g} 1/s (damping ratio {zeta:g} of two median disks),
  gammat = 0; dt = {dt:.6g} s; skin {skin:.6g} m; {nsteps} steps, box fixed at F C, velocities zero at the start.
- States (F): {states}.
- LIGGGHTS: {lig_version}; LAMMPS: {lmp_version}.
- One job directory per `<engine>-<state>`: deck (`in.liggghts` / `in.lammps`), data file, `log.lammps`
  (thermo every {thermo} steps: box and virial stress `c_pt[1,2,4]`, compression positive, `%.17g`),
  `dump.atoms` (steps 0 and {nsteps}: id x y vx vy omegaz fx fy tqz mass radius), `manifest.json`
  (command, version, SHA-256 of inputs and outputs).
- Orthogonal states: the mirror deck of `reference_runs.decks.biaxial.write_biaxial_deck` with both axes
  fixed; shear-12 (LAMMPS): the deck of `reference_runs.decks.shear.deck_text` with `ShearLoading()` on a
  data file with the tilt xy = F12 Ly (a true periodic triclinic box).
"""


def regenerate(dest: Path | None = None, timeout: float | None = 600.0) -> Path:
    """Run every state of :data:`ENGINE_STATES` in both codes and store the jobs (without
    stdout/stderr) with ``packing.h5`` and a README under ``dest`` (default
    ``reference_runs/stored/relaxation-lattice-8x8``). Needs ``liggghts`` and ``lmp``."""
    dest = Path(dest) if dest else STORED / STORED_CASE
    for engine in ENGINE_STATES:
        get_engine(engine).find()  # both binaries, before anything is written
    tmp = dest.parent / (dest.name + ".job")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        _regenerate_into(tmp, timeout)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    return dest


def _regenerate_into(tmp: Path, timeout) -> None:
    dest_name = tmp.name[: -len(".job")]
    p = relaxation_packing()
    save_packing(tmp / "packing.h5", p, parameters={**LATTICE, "kn": KN_2D, "relaxed_at_identity": True}, seed=7)
    p = load_packing(tmp / "packing.h5")
    versions = {}
    for engine, names in ENGINE_STATES.items():
        eng = get_engine(engine)
        eng.find()
        versions[engine] = eng.version()
        s = relaxation_settings(p, flavour=engine)
        for name in names:
            job = tmp / f"{engine}-{name}"
            run_relaxation_job(job, p, state_F(name), s, NSTEPS, engine, timeout)
            for junk in ("stdout.txt", "stderr.txt", ".lock"):
                (job / junk).unlink(missing_ok=True)
    s = relaxation_settings(p)
    (tmp / "README.md").write_text(
        _README.format(
            case=dest_name,
            date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            n=p.n,
            lx=p.cell[0, 0],
            ly=p.cell[1, 1],
            kn=KN_2D,
            gn=s.gamma_n,
            zeta=DAMPING_RATIO,
            dt=s.dt,
            skin=s.skin,
            nsteps=NSTEPS,
            thermo=THERMO_EVERY,
            states="; ".join(f"{k}: F = {np.array(v).tolist()}" for k, v in STATES.items()),
            lig_version=versions.get("liggghts"),
            lmp_version=versions.get("lammps"),
        )
    )


def main(argv=None) -> int:  # pragma: no cover - thin CLI
    try:
        print(regenerate())
    except GransimError as exc:
        print(f"relaxation store: error: {exc}", file=sys.stderr)
        return 2
    return 0
