"""Two-disk decks for the rolling-resistance laws, one per code and model.

The same oblique impact of two spinning disks (:func:`rolling_case`: counter-spinning disks that
meet along a normal 20 degrees off x, stick, roll against each other and part; a large periodic
2D box, no periodic image in reach, a skin large enough that no neighbour list is rebuilt), with
the linear Hooke normal law, tangential history and one rolling-resistance model:

* ``law="epsd2"``, ``"epsd"``, ``"cdt"``: LIGGGHTS 3.8.0 ``pair_style gran model hooke/stiffness
  tangential history rolling_friction MODEL`` with ``fix property/global kn kt gamman gammat
  coefficientFriction coefficientRollingFriction (peratomtypepair)`` (and
  ``coefficientRollingViscousDamping`` for ``epsd``);
* ``law="sds"``: LAMMPS 29Sep2021 ``pair_style granular`` + ``pair_coeff * * hooke KN DAMP
  damping mass_velocity tangential linear_history KT XGAMMAT MU rolling sds KROLL GAMMAROLL
  MUROLL``, with DAMP = gamma_n (1/s) and XGAMMAT = gamma_t/gamma_n: with ``mass_velocity`` the
  normal force is kn delta - m* gamma_n v_n, the normal law of ``gran/hooke/history`` and of
  LIGGGHTS' ``hooke/stiffness`` (``velocity`` would take DAMP as a coefficient in kg/s, the
  build's default ``viscoelastic`` scales it with a = sqrt(R* delta)).

Each deck dumps ``id x y vx vy omegaz fx fy tqz mass radius`` every step at %.17g and writes thermo
every step. :func:`run_rolling` runs one (``reference_runs.runner.run_job(..., engine=...)``);
:func:`make_stored` writes ``reference_runs/stored/rolling-<code>/<law>/`` (README by hand).
"""

from __future__ import annotations

import math
import shutil
import tempfile
from pathlib import Path

from gransim.contacts.laws import deck_lines, make_law
from gransim.errors import InputError

from . import twodisk

#: law name -> (engine, deck file name)
LAWS = {
    "epsd2": ("liggghts", "in.liggghts"),
    "cdt": ("liggghts", "in.liggghts"),
    "epsd": ("liggghts", "in.liggghts"),
    "sds": ("lammps", "in.lammps"),
}

DATA_NAME = "data.rolling"
DUMP_NAME = twodisk.DUMP_NAME


_g = twodisk.g


def rolling_case() -> dict:
    """The two-disk case: parameters as plain floats (SI).

    Disks r = 1.0 mm and 0.8 mm, 2D density 25 kg/m^2 (m = pi r^2 rho); centres 2 um apart from
    touching along a normal 20 degrees off x, closing at about 0.12 m/s; spins 40 and -10 rad/s
    (relative spin 50 rad/s). Hooke: kn = 1000 N/m, kt = 800 N/m, gamma_n = 2000 1/s,
    gamma_t = 1000 1/s (mass-scaled), mu = 0.4; contact time pi/sqrt(kn/m* - (gamma_n/2)^2) about
    5.6e-4 s; dt = 2.5e-6 s (about 225 steps in contact), 300 steps.
    Rolling: mu_r = 0.2 (every model), ``epsd`` viscous coefficient eta_r = 0.3;
    ``sds``: KROLL = kt (N/m), GAMMAROLL = 0.002 kg/s, MUROLL = mu_r: torque R* |F_r| <= R* mu_r |F_n|,
    the cap of LIGGGHTS' models.
    """
    r1, r2 = 1.0e-3, 0.8e-3
    ang = math.radians(20.0)
    dist = r1 + r2 + 2.0e-6
    x1 = (0.05, 0.05)
    x2 = (0.05 + dist * math.cos(ang), 0.05 + dist * math.sin(ang))
    return {
        "radii": (r1, r2),
        "density": 25.0,
        "positions": (x1, x2),
        "velocities": ((0.07, 0.03), (-0.05, -0.02)),
        "spins": (40.0, -10.0),
        "kn": 1000.0,
        "kt": 800.0,
        "gamman": 2000.0,
        "gammat": 1000.0,
        "friction": 0.4,
        "rolling_friction": 0.2,
        "rolling_viscous": 0.3,
        "kroll": 800.0,
        "gammaroll": 0.002,
        "dt": 2.5e-6,
        "nsteps": 300,
        "skin": 2.0e-3,
        "box": (0.1, 0.1),
    }


def native_law(case: dict, law: str):
    """The law object of ``law`` (one of :data:`LAWS`) with the case's parameters, built by name
    (:func:`gransim.contacts.laws.make_law`): its deck lines are the deck's."""
    c = case
    if law == "sds":
        return make_law(
            "hooke-sds-lammps",
            kn=c["kn"],
            damp=c["gamman"],
            damping="mass_velocity",
            kt=c["kt"],
            xgammat=c["gammat"] / c["gamman"],
            mu=c["friction"],
            kroll=c["kroll"],
            gammaroll=c["gammaroll"],
            muroll=c["rolling_friction"],
        )
    p = {"kn": c["kn"], "kt": c["kt"], "gamma_n": c["gamman"], "gamma_t": c["gammat"], "mu": c["friction"]}
    p["mu_r"] = c["rolling_friction"]
    if law == "epsd":
        p["eta_r"] = c["rolling_viscous"]
    return make_law(f"hooke-{law}-liggghts", **p)


def data_text(case: dict) -> str:
    """The data file (:func:`reference_runs.decks.twodisk.data_text`)."""
    return twodisk.data_text(case, "two disks written by reference_runs/decks/rolling.py (2D: density = mass per area)")


def deck_text(case: dict, law: str) -> str:
    """The deck of ``law`` (one of :data:`LAWS`)."""
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    c = case
    engine = LAWS[law][0]
    head = f"LIGGGHTS rolling_friction {law}" if engine == "liggghts" else "LAMMPS granular rolling sds"
    lines = [
        *twodisk.preamble(
            engine, f"# two-disk rolling resistance, {head} (reference_runs/decks/rolling.py)", c, DATA_NAME
        ),
        *deck_lines(native_law(c, law), engine),
        "fix integr all nve/sphere" + ("" if engine == "liggghts" else " disc"),
        "fix e2d all enforce2d",
    ]
    fmt = "" if engine == "liggghts" else "line "
    lines += twodisk.output_lines("liggghts" if fmt == "" else "lammps", c["nsteps"])
    return "\n".join(lines) + "\n"


def write_rolling_deck(job_dir, law: str, case: dict | None = None) -> Path:
    """Write the deck of ``law`` and ``data.rolling`` into ``job_dir``; return the deck path."""
    case = rolling_case() if case is None else case
    return twodisk.write_job(job_dir, LAWS[law][1], deck_text(case, law), DATA_NAME, data_text(case))


def run_rolling(job_dir, law: str, case: dict | None = None, timeout: float | None = 120.0):
    """Run the deck of ``law`` in ``job_dir`` (:func:`reference_runs.decks.twodisk.run_two_disk`,
    always rerun); returns the :class:`~reference_runs.runner.JobResult`."""
    case = rolling_case() if case is None else case
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    return twodisk.run_two_disk(job_dir, LAWS[law][0], deck_text(case, law), DATA_NAME, data_text(case), timeout)


#: ``dump.atoms`` as {step: {column: (2,) array}} (rows sorted by id)
read_rolling_dump = twodisk.read_dump


def stored_dir(root, law: str) -> Path:
    """``root/rolling-<code>/<law>`` (the layout of :func:`make_stored`)."""
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    return Path(root) / f"rolling-{LAWS[law][0]}" / law


def make_stored(out_root, laws=None, timeout: float | None = 120.0) -> dict:
    """Run the decks of ``laws`` (default all) and store each as ``out_root/rolling-<code>/<law>/``
    (deck, data, log, dump, manifest; the README beside them is written by hand).
    Returns {law: stored directory}."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="rolling-stored-") as tmp:
        for law in LAWS if laws is None else laws:
            res = run_rolling(Path(tmp) / law, law, timeout=timeout)
            dest = stored_dir(out_root, law)
            dest.mkdir(parents=True, exist_ok=True)
            for name in (LAWS[law][1], DATA_NAME, "log.lammps", DUMP_NAME, "manifest.json"):
                shutil.copyfile(Path(res.job_dir) / name, dest / name)
            out[law] = dest
    return out
