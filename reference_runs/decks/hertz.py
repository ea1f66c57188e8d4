"""Two-disk oblique impact decks for the Hertz-Mindlin laws, one per code and law.

Three decks of the same impact (:func:`impact_case`: two spinning disks meeting obliquely in a
large periodic 2D box, far from its edges so no periodic image comes near, skin large enough
that no neighbour list is rebuilt during the run):

* ``law="liggghts"``: LIGGGHTS 3.8.0 ``pair_style gran model hertz tangential history`` with
  ``fix property/global youngsModulus peratomtype``, ``poissonsRatio peratomtype``,
  ``coefficientRestitution peratomtypepair``, ``coefficientFriction peratomtypepair``;
* ``law="gran-hertz-history"``: LAMMPS 29Sep2021 ``pair_style gran/hertz/history KN KT GAMMAN
  GAMMAT MU 1`` with KN = 4/3 Y*, KT = 8 G* (Hertz' elastic force and Mindlin's stiffness);
* ``law="granular"``: LAMMPS ``pair_style granular`` + ``pair_coeff * * hertz/material E e NU
  damping tsuji tangential mindlin NULL GAMMAT MU`` with GAMMAT = sqrt(8 G*/(2 Y*)) (the ratio
  LIGGGHTS' gamma_t/gamma_n = sqrt(S_t/S_n) has).

Each deck dumps ``id x y vx vy omegaz fx fy tqz mass radius`` every step at %.17g and writes
thermo every step. The law lines come from the law itself (:func:`native_law`,
:func:`gransim.contacts.laws.deck_lines`). Run them with :func:`run_impact` (``reference_runs.runner.run_job(...,
engine=...)``); :func:`make_stored` writes ``reference_runs/stored/hertz-<code>/`` with a README.
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

from gransim.contacts.laws import deck_lines, make_law
from gransim.contacts.material import (
    HertzLiggghts,
    HertzMaterialLammps,
    effective_shear,
    effective_youngs,
)
from gransim.errors import InputError

from . import twodisk

#: law name -> (engine, deck file name, job sub-directory)
LAWS = {
    "liggghts": ("liggghts", "in.liggghts", "liggghts"),
    "gran-hertz-history": ("lammps", "in.lammps", "gran-hertz-history"),
    "granular": ("lammps", "in.lammps", "granular"),
}

DATA_NAME = "data.impact"
DUMP_NAME = twodisk.DUMP_NAME


_g = twodisk.g


def impact_case() -> dict:
    """The impact: parameters as plain floats (SI).

    Disks r = 1.0 mm and 0.8 mm, 2D density 25 kg/m^2 (m = pi r^2 rho), E = 7e8 Pa, nu = 0.3,
    e = 0.6, mu = 0.3; centres 2 um apart from touching along a normal 20 degrees off x, closing
    speed about 1.2 m/s with a tangential component and spins of 300 and -500 rad/s (the contact
    sticks, then slides); dt = 5e-7 s (Hertz contact time about 7.4e-5 s: about 150 steps),
    220 steps (the disks separate at about step 150).
    LAMMPS ``gran/hertz/history``: GAMMAN = 2e4 1/(s m) (damping m* gamman a), GAMMAT = GAMMAN/2.
    """
    r1, r2 = 1.0e-3, 0.8e-3
    ang = math.radians(20.0)
    gap = 2.0e-6
    dist = r1 + r2 + gap
    x1 = (0.05, 0.05)
    x2 = (0.05 + dist * math.cos(ang), 0.05 + dist * math.sin(ang))
    E, nu, e, mu = 7.0e8, 0.3, 0.6, 0.3
    Y = effective_youngs(E, nu, E, nu)
    G = effective_shear(E, nu, E, nu)
    return {
        "radii": (r1, r2),
        "density": 25.0,
        "positions": (x1, x2),
        "velocities": ((0.7, 0.35), (-0.4, -0.25)),
        "spins": (300.0, -500.0),
        "youngs_modulus": E,
        "poisson_ratio": nu,
        "restitution": e,
        "friction": mu,
        "dt": 5.0e-7,
        "nsteps": 220,
        "skin": 2.0e-3,
        "box": (0.1, 0.1),
        "kn": 4.0 / 3.0 * Y,
        "kt": 8.0 * G,
        "gamman": 2.0e4,
        "gammat": 1.0e4,
        "gammat_ratio": math.sqrt(8.0 * G / (2.0 * Y)),
    }


def liggghts_law(case: dict) -> HertzLiggghts:
    return HertzLiggghts(case["youngs_modulus"], case["poisson_ratio"], case["restitution"], case["friction"])


def granular_law(case: dict) -> HertzMaterialLammps:
    return HertzMaterialLammps(
        case["youngs_modulus"],
        case["poisson_ratio"],
        case["restitution"],
        case["friction"],
        gammat_ratio=case["gammat_ratio"],
        damping="tsuji",
    )


def native_law(case: dict, law: str):
    """The law object of ``law`` (one of :data:`LAWS`) with the case's parameters, built by name
    (:func:`gransim.contacts.laws.make_law`): its deck lines are the deck's."""
    c = case
    if law == "liggghts":
        return make_law(
            "hertz-liggghts",
            youngs_modulus=c["youngs_modulus"],
            poisson_ratio=c["poisson_ratio"],
            restitution=c["restitution"],
            friction=c["friction"],
        )
    if law == "gran-hertz-history":
        return make_law(
            "hertz-lammps", kn=c["kn"], kt=c["kt"], gamma_n=c["gamman"], gamma_t=c["gammat"], mu=c["friction"]
        )
    return make_law(
        "hertz-granular-lammps",
        youngs_modulus=c["youngs_modulus"],
        poisson_ratio=c["poisson_ratio"],
        damp=c["restitution"],
        friction=c["friction"],
        gammat_ratio=c["gammat_ratio"],
        damping="tsuji",
    )


def data_text(case: dict) -> str:
    """The data file (:func:`reference_runs.decks.twodisk.data_text`)."""
    return twodisk.data_text(
        case, "two-disk impact written by reference_runs/decks/hertz.py (2D: density = mass per area)"
    )


def deck_text(case: dict, law: str) -> str:
    """The deck of ``law`` (one of :data:`LAWS`)."""
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    c = case
    engine = LAWS[law][0]
    head = "LIGGGHTS form" if engine == "liggghts" else f"LAMMPS {law}"
    lines = [
        *twodisk.preamble(engine, f"# two-disk Hertz impact, {head} (reference_runs/decks/hertz.py)", c, DATA_NAME),
        *deck_lines(native_law(c, law), engine),
        "fix integr all nve/sphere" + ("" if engine == "liggghts" else " disc"),
        "fix e2d all enforce2d",
    ]
    fmt = "" if engine == "liggghts" else "line "
    lines += twodisk.output_lines("liggghts" if fmt == "" else "lammps", c["nsteps"])
    return "\n".join(lines) + "\n"


def write_impact_deck(job_dir, law: str, case: dict | None = None) -> Path:
    """Write the deck of ``law`` and ``data.impact`` into ``job_dir``; return the deck path."""
    case = impact_case() if case is None else case
    return twodisk.write_job(job_dir, LAWS[law][1], deck_text(case, law), DATA_NAME, data_text(case))


def run_impact(job_dir, law: str, case: dict | None = None, timeout: float | None = 120.0):
    """Run the deck of ``law`` in ``job_dir`` (:func:`reference_runs.decks.twodisk.run_two_disk`,
    always rerun); returns the :class:`~reference_runs.runner.JobResult`."""
    case = impact_case() if case is None else case
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    return twodisk.run_two_disk(job_dir, LAWS[law][0], deck_text(case, law), DATA_NAME, data_text(case), timeout)


#: ``dump.atoms`` as {step: {column: (2,) array}} (rows sorted by id)
read_impact_dump = twodisk.read_dump


def make_stored(out_root, timeout: float | None = 120.0) -> dict:
    """Run the three decks and store them as ``out_root/hertz-liggghts/`` and
    ``out_root/hertz-lammps/{gran-hertz-history,granular}/`` (deck, data, log, dump, manifest;
    the README beside them is written by hand). Returns {law: stored directory}."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="hertz-stored-") as tmp:
        for law, (engine, deck_name, sub) in LAWS.items():
            res = run_impact(Path(tmp) / sub, law, timeout=timeout)
            dest = Path(out_root) / f"hertz-{engine}"
            if engine == "lammps":
                dest = dest / sub
            dest.mkdir(parents=True, exist_ok=True)
            for name in (deck_name, DATA_NAME, "log.lammps", DUMP_NAME, "manifest.json"):
                shutil.copyfile(Path(res.job_dir) / name, dest / name)
            out[law] = dest
    return out
