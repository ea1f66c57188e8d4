"""Two-disk oblique impact decks for the Hertz-Mindlin laws, one per code and law (issue #16 item 2).

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
thermo every step. Run them with :func:`run_impact` (``reference_runs.runner.run_job(...,
engine=...)``); :func:`make_stored` writes ``reference_runs/stored/hertz-<code>/`` with a README.
"""

from __future__ import annotations

import math
from pathlib import Path

from gransim.contacts.material import (
    HertzLiggghts,
    HertzMaterialLammps,
    effective_shear,
    effective_youngs,
)
from gransim.errors import InputError
from gransim.io import atomic_path

#: law name -> (engine, deck file name, job sub-directory)
LAWS = {
    "liggghts": ("liggghts", "in.liggghts", "liggghts"),
    "gran-hertz-history": ("lammps", "in.lammps", "gran-hertz-history"),
    "granular": ("lammps", "in.lammps", "granular"),
}

DATA_NAME = "data.impact"
DUMP_NAME = "dump.atoms"


def _g(v: float) -> str:
    return f"{float(v):.17g}"


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
        "radii": (r1, r2), "density": 25.0, "positions": (x1, x2),
        "velocities": ((0.7, 0.35), (-0.4, -0.25)), "spins": (300.0, -500.0),
        "youngs_modulus": E, "poisson_ratio": nu, "restitution": e, "friction": mu,
        "dt": 5.0e-7, "nsteps": 220, "skin": 2.0e-3, "box": (0.1, 0.1),
        "kn": 4.0 / 3.0 * Y, "kt": 8.0 * G, "gamman": 2.0e4, "gammat": 1.0e4,
        "gammat_ratio": math.sqrt(8.0 * G / (2.0 * Y)),
    }


def liggghts_law(case: dict) -> HertzLiggghts:
    return HertzLiggghts(case["youngs_modulus"], case["poisson_ratio"], case["restitution"], case["friction"])


def granular_law(case: dict) -> HertzMaterialLammps:
    return HertzMaterialLammps(case["youngs_modulus"], case["poisson_ratio"], case["restitution"],
                               case["friction"], gammat_ratio=case["gammat_ratio"], damping="tsuji")


def data_text(case: dict) -> str:
    """The data file (atom_style sphere: id type diameter density x y z; Velocities
    id vx vy vz wx wy wz), %.17g."""
    Lx, Ly = case["box"]
    lines = ["two-disk impact written by reference_runs/decks/hertz.py (2D: density = mass per area)", "",
             "2 atoms", "1 atom types", "", f"0 {_g(Lx)} xlo xhi", f"0 {_g(Ly)} ylo yhi",
             "-0.005 0.005 zlo zhi", "", "Atoms", ""]
    for k in range(2):
        x, y = case["positions"][k]
        lines.append(f"{k + 1} 1 {_g(2.0 * case['radii'][k])} {_g(case['density'])} {_g(x)} {_g(y)} 0")
    lines += ["", "Velocities", ""]
    for k in range(2):
        vx, vy = case["velocities"][k]
        lines.append(f"{k + 1} {_g(vx)} {_g(vy)} 0 0 0 {_g(case['spins'][k])}")
    return "\n".join(lines) + "\n"


def deck_text(case: dict, law: str) -> str:
    """The deck of ``law`` (one of :data:`LAWS`)."""
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    c = case
    head = ["units si", "dimension 2", "atom_style sphere", "atom_modify map array sort 0 0.0",
            "boundary p p p", "newton off"]
    if law == "liggghts":
        lines = [
            "# two-disk Hertz impact, LIGGGHTS form (reference_runs/decks/hertz.py)", *head,
            "communicate single vel yes", f"read_data {DATA_NAME}",
            f"neighbor {_g(c['skin'])} bin", "neigh_modify delay 0 every 1 check yes",
            f"timestep {_g(c['dt'])}",
            f"fix m1 all property/global youngsModulus peratomtype {_g(c['youngs_modulus'])}",
            f"fix m2 all property/global poissonsRatio peratomtype {_g(c['poisson_ratio'])}",
            f"fix m3 all property/global coefficientRestitution peratomtypepair 1 {_g(c['restitution'])}",
            f"fix m4 all property/global coefficientFriction peratomtypepair 1 {_g(c['friction'])}",
            "pair_style gran model hertz tangential history", "pair_coeff * *",
            "fix integr all nve/sphere", "fix e2d all enforce2d",
        ]
        fmt = ""
    else:
        lines = [
            f"# two-disk Hertz impact, LAMMPS {law} (reference_runs/decks/hertz.py)", *head,
            "comm_modify mode single vel yes", f"read_data {DATA_NAME}",
            f"set group all density/disc {_g(c['density'])}",
            f"neighbor {_g(c['skin'])} bin", "neigh_modify delay 0 every 1 check yes",
            f"timestep {_g(c['dt'])}",
        ]
        if law == "gran-hertz-history":
            lines += [(f"pair_style gran/hertz/history {_g(c['kn'])} {_g(c['kt'])} {_g(c['gamman'])} "
                       f"{_g(c['gammat'])} {_g(c['friction'])} 1"), "pair_coeff * *"]
        else:
            lines += ["pair_style granular",
                      (f"pair_coeff * * hertz/material {_g(c['youngs_modulus'])} {_g(c['restitution'])} "
                       f"{_g(c['poisson_ratio'])} damping tsuji tangential mindlin NULL "
                       f"{_g(c['gammat_ratio'])} {_g(c['friction'])}")]
        lines += ["fix integr all nve/sphere disc", "fix e2d all enforce2d"]
        fmt = "line "
    lines += [
        "thermo_style custom step atoms ke",
        "thermo_modify format float %.17g norm no",
        "thermo 1",
        f"dump d1 all custom 1 {DUMP_NAME} id x y vx vy omegaz fx fy tqz mass radius",
        f"dump_modify d1 sort id format {fmt}\"%d" + " %.17g" * 10 + "\"",
        f"run {int(c['nsteps'])}",
    ]
    return "\n".join(lines) + "\n"


def write_impact_deck(job_dir, law: str, case: dict | None = None) -> Path:
    """Write the deck of ``law`` and ``data.impact`` into ``job_dir``; return the deck path."""
    case = impact_case() if case is None else case
    text = deck_text(case, law)
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    with atomic_path(job / DATA_NAME) as tmp:
        Path(tmp).write_text(data_text(case))
    deck = job / LAWS[law][1]
    with atomic_path(deck) as tmp:
        Path(tmp).write_text(text)
    return deck


def run_impact(job_dir, law: str, case: dict | None = None, timeout: float | None = 120.0):
    """Run the deck of ``law`` in ``job_dir`` through :func:`reference_runs.runner.run_job`
    (always rerun); returns the :class:`~reference_runs.runner.JobResult`."""
    from reference_runs.runner import run_job

    case = impact_case() if case is None else case
    if law not in LAWS:
        raise InputError(f"law: expected one of {', '.join(LAWS)}, got {law!r}")
    engine = LAWS[law][0]
    return run_job(job_dir, deck_text(case, law), files={DATA_NAME: data_text(case)}, timeout=timeout,
                   outputs=(DUMP_NAME,), expected_runs=1, progress=False, force=True, engine=engine)


def read_impact_dump(path) -> dict:
    """``dump.atoms`` as {step: {column: (2,) array}} (rows sorted by id)."""
    from reference_runs.parsers import parse_dump_custom

    return {int(fr.step): dict(fr.columns) for fr in parse_dump_custom(Path(path))}


def make_stored(out_root, timeout: float | None = 120.0) -> dict:
    """Run the three decks and store them as ``out_root/hertz-liggghts/`` and
    ``out_root/hertz-lammps/{gran-hertz-history,granular}/`` (deck, data, log, dump, manifest;
    the README beside them is written by hand). Returns {law: stored directory}."""
    import shutil
    import tempfile

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
