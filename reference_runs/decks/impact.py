"""LIGGGHTS 3.8.0 / LAMMPS 29Sep2021 deck of a scene of binary disk impacts (validation case ``impacts``).

A *scene* is a set of independent two-disk impacts laid side by side in one orthogonal periodic
box, far enough apart that no disk of one impact ever comes within the neighbour cut-off of a
disk of another, and each pair only a few steps from touching, so that every pair meets exactly
once during the run (the box is many contact-durations of travel wide). All impacts of a scene
share one contact law with one set of parameters (the law is a parameter of the deck: a
:class:`HookeLaw` today; a Hertz-Mindlin law adds its own class with the same two methods).

The deck mirrors :class:`gransim.dem.DEMEngine` step for step (as
:mod:`reference_runs.decks.biaxial`: ``newton off``, no atom sorting, ``neigh_modify delay 0
every 1 check yes``, ``fix nve/sphere`` with 2D inertia m r^2/2, ``fix enforce2d``, no box
deformation). Output: ``dump.atoms`` (``dump custom`` every ``dump_every`` steps, %.17g: id x y
vx vy omegaz fx fy tqz) and a thermo line (step, atoms) every ``thermo_every`` steps.

LAMMPS form (``engine="lammps"``, docs/lammps.md): ``set group all density/disc RHO`` after
``read_data`` (m = pi r^2 rho), ``fix nve/sphere disc``, ``comm_modify mode single vel yes``,
``dump_modify ... format line``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gransim.dem.settings import DEMSettings
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_path
from reference_runs.datafile import write_data_file

ENGINES = ("liggghts", "lammps")
#: deck file name written by :func:`write_impact_deck` (run_job copies it to its own deck name)
DECK_NAMES = {"liggghts": "in.liggghts", "lammps": "in.lammps"}
DATA_NAME = "data.impact"
DUMP_NAME = "dump.atoms"
DUMP_COLUMNS = ("id", "x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz")


def _g(v: float) -> str:
    return f"{float(v):.17g}"


@dataclass(frozen=True)
class HookeLaw:
    """Linear spring-dashpot law with tangential history (today's native law, docs/dem.md).

    F_n = kn delta - m_eff gamma_n v_n; spring xi += v_t,rel dt, F_t = -kt xi - m_eff gamma_t
    v_t,rel, Coulomb cap mu |F_n| (each code's own cap: docs/lammps.md, items A-B).

    Attributes
    ----------
    kn, kt : normal, tangential stiffness (N/m; 2D: per unit thickness reads the same).
    gamma_n, gamma_t : mass-scaled damping rates (1/s): damping coefficient m_eff gamma.
    mu : Coulomb friction coefficient (-).

    LIGGGHTS: ``pair_style gran model hooke/stiffness tangential history`` with ``fix
    property/global`` kn, kt, gamman, gammat, coefficientFriction. LAMMPS: ``pair_style
    gran/hooke/history KN KT GAMMAN GAMMAT MU 1`` (the trailing 1: tangential damping on; no
    ``limit_damping``, so a damped normal force may turn attractive before the pair opens, as in
    LIGGGHTS, whose ``limitForce`` is off).
    """

    kn: float
    kt: float
    gamma_n: float = 0.0
    gamma_t: float = 0.0
    mu: float = 0.5
    name: str = "hooke"

    def __post_init__(self):
        for k in ("kn", "kt", "gamma_n", "gamma_t", "mu"):
            v = getattr(self, k)
            if not (isinstance(v, int | float | np.floating) and np.isfinite(v) and v >= 0):
                raise InputError(f"HookeLaw.{k}: expected a finite number >= 0, got {v!r}")
        if self.kn <= 0:
            raise InputError(f"HookeLaw.kn: expected > 0 N/m, got {self.kn!r}")

    def dem_settings(self, dt: float, skin: float, flavour: str = "liggghts") -> DEMSettings:
        """The native engine's settings of this law (serial mode, the mode compared step for step)."""
        return DEMSettings(kn=self.kn, kt=self.kt, gamma_n=self.gamma_n, gamma_t=self.gamma_t, mu=self.mu,
                           dt=dt, skin=skin, mode="serial", flavour=flavour)

    def deck_lines(self, engine: str) -> list[str]:
        """The pair-style lines of the deck for ``engine`` ("liggghts" or "lammps")."""
        if engine == "lammps":
            return [(f"pair_style gran/hooke/history {_g(self.kn)} {_g(self.kt)} {_g(self.gamma_n)} "
                 f"{_g(self.gamma_t)} {_g(self.mu)} 1"), "pair_coeff * *"]
        return ["fix m1 all property/global kn peratomtypepair 1 " + _g(self.kn),
                "fix m2 all property/global kt peratomtypepair 1 " + _g(self.kt),
                "fix m3 all property/global gamman peratomtypepair 1 " + _g(self.gamma_n),
                "fix m4 all property/global gammat peratomtypepair 1 " + _g(self.gamma_t),
                "fix m5 all property/global coefficientFriction peratomtypepair 1 " + _g(self.mu),
                "pair_style gran model hooke/stiffness tangential history", "pair_coeff * *"]

    def describe(self) -> str:
        return (f"Hooke + tangential history: kn {self.kn:g} N/m, kt {self.kt:g} N/m, gamma_n {self.gamma_n:.6g} 1/s, "
                f"gamma_t {self.gamma_t:.6g} 1/s, mu {self.mu:g}")


def write_impact_deck(job_dir, packing: Packing, law, dt: float, skin: float, nsteps: int, velocities,
                      spins, engine: str = "liggghts", dump_every: int = 1, thermo_every: int = 10) -> Path:
    """Write the deck (``in.liggghts`` or ``in.lammps``) and ``data.impact`` into ``job_dir``.

    Parameters
    ----------
    packing : the scene (orthogonal cell, box [0, Lx] x [0, Ly]; every centre inside the box).
    law : the contact law (an object with ``deck_lines(engine)``, e.g. :class:`HookeLaw`).
    dt, skin : time step (s) and neighbour skin (m). nsteps : steps of the single ``run``.
    velocities : (N, 2) m/s; spins : (N,) rad/s.
    engine : "liggghts" or "lammps" (ValueError otherwise).

    Returns the deck path. Run it with ``reference_runs.runner.run_job(job_dir, deck_text,
    files={"data.impact": ...}, outputs=("dump.atoms",), engine=engine)``.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    x = np.asarray(packing.positions)
    L = np.array([packing.cell[0, 0], packing.cell[1, 1]])
    if np.any(x < 0) or np.any(x >= L):
        raise ValueError("packing: every centre must lie inside the box [0, Lx) x [0, Ly) (the scene is not wrapped)")
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    write_data_file(job / DATA_NAME, packing, velocities=velocities, omegas=spins, wrap=False)
    head = ["units si", "dimension 2", "atom_style sphere", "atom_modify map array sort 0 0.0",
            "boundary p p p", "newton off"]
    if engine == "lammps":
        lines = ["# gransim impact scene, LAMMPS form (reference_runs/decks/impact.py)", *head,
                 "comm_modify mode single vel yes", f"read_data {DATA_NAME}",
                 f"set group all density/disc {_g(packing.density)}"]
        integ = "fix integr all nve/sphere disc"
        fmt = "line "
    else:
        lines = ["# gransim impact scene (reference_runs/decks/impact.py)", *head,
                 "communicate single vel yes", f"read_data {DATA_NAME}"]
        integ = "fix integr all nve/sphere"
        fmt = ""
    lines += [f"neighbor {_g(skin)} bin", "neigh_modify delay 0 every 1 check yes", f"timestep {_g(dt)}",
              *law.deck_lines(engine), integ, "fix e2d all enforce2d",
              "thermo_style custom step atoms", f"thermo {int(thermo_every)}",
              f"dump d1 all custom {int(dump_every)} {DUMP_NAME} " + " ".join(DUMP_COLUMNS),
              f"dump_modify d1 sort id format {fmt}\"%d" + " %.17g" * (len(DUMP_COLUMNS) - 1) + "\"",
              f"run {int(nsteps)}"]
    deck = job / DECK_NAMES[engine]
    with atomic_path(deck) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    return deck


def read_frames(dump_path) -> dict:
    """``dump.atoms`` as {step: {"x": (N, 2), "v": (N, 2), "w": (N,), "f": (N, 2), "t": (N,)}}
    (rows sorted by id; :func:`reference_runs.parsers.parse_dump_custom`)."""
    from reference_runs.parsers import parse_dump_custom

    out = {}
    for fr in parse_dump_custom(Path(dump_path)):
        out[int(fr.step)] = {"x": fr.array("x", "y"), "v": fr.array("vx", "vy"), "w": np.array(fr["omegaz"], float),
                             "f": fr.array("fx", "fy"), "t": np.array(fr["tqz"], float)}
    return out
