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
  ghosts, docs/liggghts.md): a true periodic triclinic box F C (data file with its ``xy`` tilt, centres
  x = F X, :func:`reference_runs.decks.taylor.triclinic_state`), the deck of
  :func:`reference_runs.decks.shear.deck_text` with ``ShearLoading()`` (no ``fix deform``: the box
  stays); native :class:`gransim.dem.sheared.ShearEngine` (flavour lammps).

Outputs of every job: thermo every :data:`THERMO_EVERY` steps (rve-70-1: :data:`RVE_THERMO_EVERY`;
box, virial stress ``c_pt[1,2,4]``, compression positive) and a ``dump custom`` (id x y vx vy omegaz
fx fy tqz mass radius) at steps 0 and ``nsteps``; the final frame gives the kinetic energy and the
positions from which the residual forces are recomputed.

Two RVEs (*variants*, :class:`Variant`), each with its states, damping and step count:

* ``lattice`` (:func:`relaxation_packing`): the perturbed triangular lattice of the stored Taylor
  case, 8 x 8 disks (seed 7), first relaxed at F = 1 by the relaxed RVE's Newton minimiser, so that
  the reference is at rest and every disk has at least three contacts (no rattlers). Damping ratio
  2, 5000 steps (at rest to round-off after about 2000).
* ``rve-70-1`` (:func:`rve_packing`): the standard 70-disk RVE of Meier, Steinmann & Kuhl (2007,
  section 4; :mod:`gransim.generation.standard`, seed 1), the RVE of the Taylor and FE2 studies,
  with its 3-4 rattlers. Its softest mode is 2.6e-2 of the median contact frequency, so the decay
  of the contact-damped DEM is limited by it: damping ratio :data:`RVE_DAMPING_RATIO` (near the
  fastest decay of the linearised network, below the engines' stability limit at dt = t_c / 50)
  and :data:`RVE_NSTEPS` steps (see docs/validation.md, ``relaxation``).
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
from gransim.generation.standard import shipped_packing
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
from .taylor import _lammps_data_text, periodic_state_packing, triclinic_state

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

#: the random standard RVE of the second variant (gransim.generation.standard, shipped copy)
RVE_NAME = "rve-70-1"
#: its states: 0.1% compressions, and a simple shear of 1e-3 after 0.1% isotropic compression (a
#: simple shear alone does not start from w = 0: see docs/validation.md, ``relaxation``, limits)
RVE_STATES = {
    "iso": ((0.999, 0.0), (0.0, 0.999)),
    "compression-22": ((1.0, 0.0), (0.0, 0.999)),
    "iso-shear-12": ((0.999, 0.001), (0.0, 0.999)),
}
RVE_ENGINE_STATES = {
    "liggghts": ("iso", "compression-22"),
    "lammps": ("iso", "compression-22", "iso-shear-12"),
}
#: damping ratio of two median disks on rve-70-1. Contact damping damps a network mode of
#: frequency w at a rate that grows with the ratio until the mode is overdamped; the linearised
#: network at iso 0.1% (softest mode 2.6e-2 of the median contact frequency) decays fastest near a
#: ratio of 10 (8.9e-3, 1.7e-2, 8.0e-3 of that frequency at 5, 10, 20; 3.5e-3 at 2). The engines'
#: explicit step is stable for the lightest pair's ratio (0.54 times this one) up to about 9 at
#: dt = t_c / 50; 8 keeps a 15% margin
RVE_DAMPING_RATIO = 8.0
#: steps of each rve-70-1 relaxation: every state at rest (kinetic energy of the disks in contact
#: <= 1e-16 of the elastic energy, rho <= 1e-8) by 40000-60000 steps (measured, docs/validation.md;
#: a free rattler hitting a neighbour later can stir the network again, e.g. iso at ~70000)
RVE_NSTEPS = 60000
#: thermo interval of the rve-70-1 jobs (61 rows a log, as the lattice's 51)
RVE_THERMO_EVERY = 1000
RVE_STORED_CASE = "relaxation-rve-70-1"


@dataclasses.dataclass(frozen=True)
class Variant:
    """One RVE of the case: its stored jobs (``reference_runs/stored/<stored_case>``), states (name ->
    F), the states each code runs, the damping ratio of two median disks and the steps of a run."""

    key: str
    stored_case: str
    states: dict
    engine_states: dict
    damping_ratio: float
    nsteps: int
    thermo_every: int = THERMO_EVERY


def variant(key: str) -> Variant:
    """The variant ``"lattice"`` or ``"rve-70-1"`` from this module's constants."""
    if key == "lattice":
        return Variant(key, STORED_CASE, STATES, ENGINE_STATES, DAMPING_RATIO, NSTEPS)
    if key == RVE_NAME:
        return Variant(
            key, RVE_STORED_CASE, RVE_STATES, RVE_ENGINE_STATES, RVE_DAMPING_RATIO, RVE_NSTEPS, RVE_THERMO_EVERY
        )
    raise InputError(f"unknown relaxation variant {key!r}; choose 'lattice' or {RVE_NAME!r}")


def state_F(name: str, states: dict | None = None) -> np.ndarray:
    """F (2, 2) of a state of ``states`` (default :data:`STATES`, the lattice's)."""
    states = STATES if states is None else states
    if name not in states:
        raise InputError(f"unknown relaxation state {name!r}; choose one of: {', '.join(states)}")
    return np.array(states[name], float)


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


def rve_packing() -> Packing:
    """The standard RVE :data:`RVE_NAME` as shipped (:func:`gransim.generation.standard.shipped_packing`);
    InputError when the shipped copy is missing or was made by another generator version."""
    path = shipped_packing(RVE_NAME)
    if path is None:
        raise InputError(f"the shipped standard packing {RVE_NAME!r} is missing or outdated (gransim packings --force)")
    return load_packing(path)


def relaxation_settings(
    packing: Packing, kn: float = KN_2D, flavour: str = "liggghts", damping_ratio: float = DAMPING_RATIO
) -> DEMSettings:
    """Frictionless damped settings: kt = 0, mu = 0, gamma_t = 0, gamma_n for ``damping_ratio``
    (default :data:`DAMPING_RATIO`) of two median disks, dt = contact time / :data:`STEPS_PER_CONTACT`,
    skin :data:`SKIN_D50` D50 (:meth:`gransim.dem.DEMSettings.for_packing`)."""
    s = DEMSettings.for_packing(
        packing,
        kn,
        kt=0.0,
        mu=0.0,
        damping_ratio=damping_ratio,
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


def write_job(
    job_dir,
    packing: Packing,
    F,
    settings: DEMSettings,
    nsteps: int = NSTEPS,
    engine: str = "liggghts",
    thermo_every: int = THERMO_EVERY,
):
    """Write the deck and data file of one relaxation into ``job_dir``; returns (deck text, files)."""
    q, kind = deformed_state(packing, F)
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    if kind == "orthogonal":
        deck = write_biaxial_deck(
            job, q, settings, Loading(), nsteps, thermo_every=thermo_every, dump_every=nsteps, engine=engine
        )
        data = "data.biaxial"
    else:
        if engine != "lammps":
            raise InputError(
                "engine: a sheared (triclinic) periodic box runs in LAMMPS only (LIGGGHTS 3.8.0 loses the "
                "periodic ghosts of tilted boxes, docs/liggghts.md)"
            )
        data = "data.shear"
        c = q.cell
        (job / data).write_text(_lammps_data_text(q.positions, q.radii, q.density, (c[0, 0], c[1, 1], c[0, 1])))
        deck = job / "in.shear"
        deck.write_text(
            shear_deck_text(q, settings, ShearLoading(), nsteps, thermo_every=thermo_every, dump_every=nsteps)
        )
    return deck.read_text(), {data: (job / data).read_bytes()}


def run_relaxation_job(
    job_dir,
    packing,
    F,
    settings,
    nsteps: int = NSTEPS,
    engine: str = "liggghts",
    timeout=None,
    thermo_every: int = THERMO_EVERY,
):
    """Write and run (or reuse, when complete) one relaxation job; returns the
    :class:`~reference_runs.runner.JobResult`."""
    with tempfile.TemporaryDirectory() as tmp:
        deck, files = write_job(tmp, packing, F, settings, nsteps, engine, thermo_every)
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
`python -m reference_runs.store --case {store_case}` on {date}.

- RVE: `packing.h5` ({n} disks, cell {lx:.6g} m x {ly:.6g} m): {rve}
- Contact: kn = E_n = {kn:g} N/m, kt = 0, mu = 0, gamman = {gn:.6g} 1/s (damping ratio {zeta:g} of two median disks),
  gammat = 0; dt = {dt:.6g} s; skin {skin:.6g} m; {nsteps} steps, box fixed at F C, velocities zero at the start.
- States (F): {states}.
- LIGGGHTS: {lig_version}; LAMMPS: {lmp_version}.
- One job directory per `<engine>-<state>`: deck (`in.liggghts` / `in.lammps`), data file, `log.lammps`
  (thermo every {thermo} steps: box and virial stress `c_pt[1,2,4]`, compression positive, `%.17g`),
  `dump.atoms` (steps 0 and {nsteps}: id x y vx vy omegaz fx fy tqz mass radius), `manifest.json`
  (command, version, SHA-256 of inputs and outputs).
- Orthogonal states: the mirror deck of `reference_runs.decks.biaxial.write_biaxial_deck` with both axes
  fixed; {shear_name} (LAMMPS): the deck of `reference_runs.decks.shear.deck_text` with `ShearLoading()` on a
  data file with the tilt xy = F12 Ly (a true periodic triclinic box).
"""

_RVE_TEXT = {
    "lattice": "`reference_runs.demo_packings.perturbed_lattice(8, 8,\n  seed=7)` moved to its relaxed "
    "minimum at F = 1 (`reference_runs.decks.relaxation.relaxation_packing`).",
    RVE_NAME: f"the standard RVE `{RVE_NAME}` of Meier, Steinmann & Kuhl (2007,\n  section 4), a byte copy of "
    f"the shipped `gransim/generation/data/standard/{RVE_NAME}.h5` (its provenance inside;\n  "
    "`reference_runs.decks.relaxation.rve_packing`).",
}
#: the store CLI's --case of each variant
STORE_CASE = {"lattice": "relaxation", RVE_NAME: "relaxation-rve"}


def regenerate(dest: Path | None = None, timeout: float | None = 600.0, key: str = "lattice") -> Path:
    """Run every state of the variant ``key`` (``"lattice"`` or :data:`RVE_NAME`) in both codes and
    store the jobs (without stdout/stderr) with ``packing.h5`` and a README under ``dest`` (default
    ``reference_runs/stored/<variant's stored case>``). Needs ``liggghts`` and ``lmp``."""
    v = variant(key)
    dest = Path(dest) if dest else STORED / v.stored_case
    for engine in v.engine_states:
        get_engine(engine).find()  # both binaries, before anything is written
    tmp = dest.parent / (dest.name + ".job")
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    try:
        _regenerate_into(tmp, timeout, v)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(dest, ignore_errors=True)
    tmp.rename(dest)
    return dest


def _regenerate_into(tmp: Path, timeout, v: Variant) -> None:
    dest_name = tmp.name[: -len(".job")]
    if v.key == "lattice":
        p = relaxation_packing()
        save_packing(tmp / "packing.h5", p, parameters={**LATTICE, "kn": KN_2D, "relaxed_at_identity": True}, seed=7)
    else:
        rve_packing()  # the shipped copy exists and is current
        shutil.copyfile(shipped_packing(RVE_NAME), tmp / "packing.h5")
    p = load_packing(tmp / "packing.h5")
    versions = {}
    for engine, names in v.engine_states.items():
        eng = get_engine(engine)
        eng.find()
        versions[engine] = eng.version()
        s = relaxation_settings(p, flavour=engine, damping_ratio=v.damping_ratio)
        for name in names:
            job = tmp / f"{engine}-{name}"
            run_relaxation_job(job, p, state_F(name, v.states), s, v.nsteps, engine, timeout, v.thermo_every)
            for junk in ("stdout.txt", "stderr.txt", ".lock"):
                (job / junk).unlink(missing_ok=True)
    s = relaxation_settings(p, damping_ratio=v.damping_ratio)
    (tmp / "README.md").write_text(
        _README.format(
            case=dest_name,
            store_case=STORE_CASE[v.key],
            date=_dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            n=p.n,
            lx=p.cell[0, 0],
            ly=p.cell[1, 1],
            rve=_RVE_TEXT[v.key],
            kn=KN_2D,
            gn=s.gamma_n,
            zeta=v.damping_ratio,
            dt=s.dt,
            skin=s.skin,
            nsteps=v.nsteps,
            thermo=v.thermo_every,
            states="; ".join(f"{k}: F = {np.array(f).tolist()}" for k, f in v.states.items()),
            shear_name=", ".join(k for k, f in v.states.items() if f[0][1] != 0.0),
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
