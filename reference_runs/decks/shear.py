"""LAMMPS (29 Sep 2021) deck of true periodic simple shear that mirrors gransim.dem.sheared step
for step: a triclinic box (``change_box all triclinic``) sheared by ``fix deform 1 xy erate RATE
remap v`` (Lees-Edwards; or any other ``xy`` style and ``fix deform N`` of the
:class:`~gransim.dem.sheared.ShearLoading`, except trate, which needs a tilted start), y fixed or
under a normal-stress servo ``y variable v_dy v_ry``; a general velocity gradient adds ``x erate``
and ``y erate`` and may take ``remap x`` (``ShearLoading.x_erate``, ``y_erate``, ``remap``).

Same contact law (``pair_style gran/hooke/history KN KT GAMMAN GAMMAT MU 1``, mass-scaled damping),
time step, skin and neighbour rule (``neigh_modify delay 0 every 1 check yes``), no atom sorting,
``newton off``, ``comm_modify mode single vel yes`` (ghost velocities: ``remap v`` needs them),
2D masses and inertia (``set group all density/disc RHO`` after ``read_data``, which takes the
density column as 3D in this build; ``fix nve/sphere disc``). The servo of y is

    variable dy equal (ly-LY0)+K*(f_avsy-TARGET)*ly        K = dt gain as one %.17g literal
    variable ry equal GAIN*(f_avsy-TARGET)*ly              h_rate[1]: the y image velocity jump

with ``f_avsy`` a ``fix ave/time 1 1 1`` of a ``compute pressure NULL virial`` of its own, defined
before ``fix deform`` so that it is evaluated first in end_of_step (the stress of the step over
the area of the box the forces used; the native engine does the same arithmetic).

Thermo, every ``thermo_every`` steps at %.17g: step, lx, ly, xy, xlo, xhi, ylo, yhi and the
virial stress (compression positive) xx, yy, xy of a separate ``compute pressure NULL virial``.
``dump custom`` every ``dump_every`` steps: id x y vx vy omegaz fx fy tqz mass radius at %.17g.
Run it with ``lmp -in in.shear -log log.lammps -screen none -nocite`` in the job directory, or
:func:`run_lammps`.
"""

from __future__ import annotations

import datetime
import shutil
import tempfile
from pathlib import Path

import numpy as np

from gransim.contacts.laws import deck_lines
from gransim.dem import kernels
from gransim.dem.lattice import lattice_packing
from gransim.dem.settings import DEMSettings
from gransim.dem.sheared import ShearLoading
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_path
from reference_runs.datafile import write_data_file
from reference_runs.engines import LAMMPS
from reference_runs.parsers import parse_dump_custom, parse_log
from reference_runs.runner import run_job

DECK = "in.shear"
DATA = "data.shear"
DUMP = "dump.atoms"


def _g(v: float) -> str:
    return f"{float(v):.17g}"


def wrapped_packing(packing: Packing) -> Packing:
    """The packing with its centres wrapped into [0, Lx) x [0, Ly) as ``Domain::pbc`` would do
    (x += L once): the positions written to the data file, and those to give the native engine so
    that both codes start from the same doubles. Needs an orthogonal cell (the deck starts untilted)."""
    C = np.asarray(packing.cell, float)
    if C[0, 1] != 0.0 or C[1, 0] != 0.0:
        raise InputError(
            "packing.cell: the LAMMPS shear deck starts from an orthogonal cell (the data file "
            f"has no tilt; change_box makes it triclinic), got off-diagonal {C[0, 1]!r}, {C[1, 0]!r}"
        )
    x = np.array(packing.positions, np.float64)
    lost = kernels.pbc_wrap(x, np.zeros(2), np.array([C[0, 0], C[1, 1]]))
    if lost >= 0:
        raise InputError(f"packing.positions: particle {lost} lies more than one cell length outside the cell")
    return packing.replace(positions=x)


def _header(packing: Packing, settings: DEMSettings, law) -> list:
    """The deck's lines before its loading: units, cell, data, law, integration (the module)."""
    s = settings
    if s.mode != "serial":
        raise InputError(f"settings.mode: the deck mirrors the serial engine, got {s.mode!r}")
    return [
        "# gransim.dem.sheared mirror deck (reference_runs/decks/shear.py)",
        "units si",
        "dimension 2",
        "boundary p p p",
        "atom_style sphere",
        "atom_modify map array sort 0 0.0",
        "newton off",
        "comm_modify mode single vel yes",
        f"read_data {DATA}",
        "change_box all triclinic",
        f"set group all density/disc {_g(packing.density)}",
        f"neighbor {_g(s.skin)} bin",
        "neigh_modify delay 0 every 1 check yes",
        f"timestep {_g(s.dt)}",
        *deck_lines(s.hooke_law("lammps") if law is None else law, "lammps"),
        "fix integr all nve/sphere disc",
        "fix e2d all enforce2d",
    ]


def _deform(packing: Packing, settings: DEMSettings, loading: ShearLoading) -> tuple[list, list]:
    """(lines defining the servo's variables, the ``fix deform`` line or none) of ``loading``."""
    if not isinstance(loading, ShearLoading):
        raise InputError(f"loading: expected a ShearLoading, got {type(loading).__name__}")
    lines, deform = [], []
    if loading.xy == "trate":
        raise InputError(
            "loading: xy trate needs a tilted start, and this deck starts from an orthogonal cell "
            "(change_box all triclinic, xy = 0; LAMMPS refuses trate at zero tilt)"
        )
    if loading.x_erate != 0.0:
        deform.append(f"x erate {_g(loading.x_erate)}")
    if loading.y == "erate":
        deform.append(f"y erate {_g(loading.y_erate)}")
    if loading.moves_tilt:
        deform.append(f"xy {loading.xy} {_g(loading.value)}")
    if loading.y == "servo":
        k = settings.dt * loading.gain
        t = _g(loading.target)
        Ly = float(packing.cell[1, 1])
        lines += [
            "compute psy all pressure NULL virial",
            "fix avsy all ave/time 1 1 1 c_psy[2]",
            f"variable dy equal (ly-{_g(Ly)})+{_g(k)}*(f_avsy-({t}))*ly",
            f"variable ry equal {_g(loading.gain)}*(f_avsy-({t}))*ly",
        ]
        deform.append("y variable v_dy v_ry")
    fix = [f"fix def all deform {loading.every} {' '.join(deform)} remap {loading.remap}"] if deform else []
    return lines, fix


_THERMO = [
    "compute pt all pressure NULL virial",
    "thermo_style custom step lx ly xy xlo xhi ylo yhi c_pt[1] c_pt[2] c_pt[4]",
    "thermo_modify format float %.17g norm no",
]
_DUMP_COLUMNS = "id x y vx vy omegaz fx fy tqz mass radius"


def _count(name: str, v) -> int:
    v = int(v)
    if v < 1:
        raise InputError(f"{name}: expected an integer >= 1, got {v}")
    return v


def deck_text(
    packing: Packing,
    settings: DEMSettings,
    loading: ShearLoading,
    nsteps: int,
    thermo_every: int = 1,
    dump_every: int = 100,
    law=None,
) -> str:
    """The LAMMPS input deck (text) of a simple-shear run of ``nsteps`` steps (see the module).
    ``law``: a LAMMPS contact law (:func:`gransim.contacts.laws.make_law`) whose deck lines replace
    those of the Hooke law of ``settings`` (``gran/hooke/history``)."""
    nsteps, thermo_every = _count("nsteps", nsteps), _count("thermo_every", thermo_every)
    dump_every = _count("dump_every", dump_every)
    lines = _header(packing, settings, law)
    servo, fix = _deform(packing, settings, loading)
    lines += servo + fix + _THERMO
    lines += [
        f"thermo {thermo_every}",
        f"dump d1 all custom {dump_every} {DUMP} {_DUMP_COLUMNS}",
        "dump_modify d1 sort id format float %.17g",
        f"run {nsteps}",
    ]
    return "\n".join(lines) + "\n"


def call_dump(k: int) -> str:
    """The file of the state after call ``k`` (1, 2, ...) of :func:`sequence_deck_text`."""
    return f"dump.call{int(k)}"


def sequence_deck_text(packing: Packing, settings: DEMSettings, runs, law=None) -> str:
    """The deck of a sequence of LAMMPS ``run`` commands, each under its own ``fix deform``
    (``runs``: (ShearLoading, nsteps) pairs; no servo), as a material point driven call after call
    (:mod:`gransim.fem.lammps_rve`): first ``run 0`` (the set-up state, :func:`call_dump` ``(0)``),
    then ``fix def`` ... ``run n`` ``unfix def`` per call, thermo at the first and last step of
    each run, and after each run ``write_dump`` of the state to :func:`call_dump` ``(k)`` (the
    columns of ``dump.atoms``, sorted by id, %.17g)."""
    runs = list(runs)
    if not runs:
        raise InputError("runs: expected at least one (loading, nsteps)")
    lines = _header(packing, settings, law) + _THERMO + ["thermo 1000000000", "run 0"]
    lines.append(f"write_dump all custom {call_dump(0)} {_DUMP_COLUMNS} modify sort id format float %.17g")
    for k, (ld, n) in enumerate(runs, 1):
        servo, fix = _deform(packing, settings, ld)
        if servo:
            raise InputError(f"runs[{k - 1}]: a sequence of calls takes no servo")
        lines += fix + [f"run {_count('nsteps', n)}"] + (["unfix def"] if fix else [])
        lines.append(f"write_dump all custom {call_dump(k)} {_DUMP_COLUMNS} modify sort id format float %.17g")
    return "\n".join(lines) + "\n"


def write_shear_deck(
    job_dir,
    packing: Packing,
    settings: DEMSettings,
    loading: ShearLoading,
    nsteps: int,
    thermo_every: int = 1,
    dump_every: int = 100,
    velocities=None,
    spins=None,
) -> Path:
    """Write ``in.shear`` and ``data.shear`` (:func:`reference_runs.datafile.write_data_file`, the
    centres wrapped by :func:`wrapped_packing`) into ``job_dir``; return the deck path."""
    text = deck_text(packing, settings, loading, nsteps, thermo_every, dump_every)
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    write_data_file(job / DATA, wrapped_packing(packing), velocities=velocities, omegas=spins, wrap=False)
    deck = job / DECK
    with atomic_path(deck) as tmp:
        Path(tmp).write_text(text)
    return deck


# -- readers --------------------------------------------------------------------------------

THERMO_COLUMNS = ("step", "lx", "ly", "xy", "xlo", "xhi", "ylo", "yhi", "sxx", "syy", "sxy")
_THERMO_NAMES = ("Step", "Lx", "Ly", "Xy", "Xlo", "Xhi", "Ylo", "Yhi", "c_pt[1]", "c_pt[2]", "c_pt[4]")


def read_thermo(log_path) -> dict:
    """Thermo rows of the deck's run as arrays keyed by THERMO_COLUMNS (stress compression positive)."""
    run = parse_log(Path(log_path)).runs[-1]
    out = {k: np.array(run.column(name)) for k, name in zip(THERMO_COLUMNS, _THERMO_NAMES)}
    out["step"] = out["step"].astype(np.int64)
    return out


def read_dump(dump_path) -> dict:
    """``dump.atoms`` as {step: {column: array}} (rows sorted by id)."""
    return {int(fr.step): dict(fr.columns) for fr in parse_dump_custom(Path(dump_path))}


# -- the stored cross-check cases -------------------------------------------------------------

SHORT_STEPS = 3000
SHORT_DUMP_EVERY = 500
SHORT_CASES = ("constant-volume", "servo")


def short_case(name: str):
    """A step-for-step case (reference_runs/stored/shear-short-lammps/NAME).

    The 120 disks of the biaxial short case (``lattice_packing(10, 12, seed=1, spread=0.1,
    compression=0.04)``, in contact across the boundary from step 0), kn = kt = 1e5 N/m, gamma_n =
    gamma_t = 50 1/s, mu = 0.5, dt = 2e-6 s, skin 2e-5 m, 3000 steps sheared at xy erate 2.5 1/s
    (1.5% shear strain). "constant-volume": y fixed; "servo": y servo to sigma_yy = 1000 N/m
    (compression positive) with gain 1e-2 1/(Pa s). Returns (packing, settings, loading, nsteps);
    the packing is already wrapped (:func:`wrapped_packing`).
    """
    if name not in SHORT_CASES:
        raise InputError(f"unknown shear case {name!r}; choose one of: {', '.join(SHORT_CASES)}")
    p = wrapped_packing(lattice_packing(10, 12, seed=1, spread=0.1, compression=0.04))
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
    if name == "constant-volume":
        ld = ShearLoading(erate=2.5)
    else:
        ld = ShearLoading(erate=2.5, y="servo", target=1000.0, gain=1e-2)
    return p, s, ld, SHORT_STEPS


def run_lammps(deck: Path, timeout: float | None = 600.0) -> Path:
    """Run a deck written by :func:`write_shear_deck` in its directory with LAMMPS (serial,
    :func:`reference_runs.runner.run_job`, ``engine="lammps"``, always rerun); returns the log."""
    deck = Path(deck)
    data = (deck.parent / DATA).read_bytes()
    res = run_job(
        deck.parent,
        deck.read_text(),
        files={DATA: data},
        np=1,
        timeout=timeout,
        outputs=(DUMP,),
        expected_runs=1,
        progress=False,
        force=True,
        engine="lammps",
    )
    return res.log_path


def make_stored(out_dir, timeout: float | None = 600.0) -> Path:
    """Run both short cases with LAMMPS in scratch job directories and store deck, data, log and
    dump of each under ``out_dir/CASE/`` with a README (provenance: the binary's banner, command,
    date)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    heads = {}
    for name in SHORT_CASES:
        p, s, ld, n = short_case(name)
        dest = out / name
        dest.mkdir(exist_ok=True)
        with tempfile.TemporaryDirectory(prefix=f"shear-{name}-") as tmp:
            deck = write_shear_deck(tmp, p, s, ld, n, thermo_every=1, dump_every=SHORT_DUMP_EVERY)
            log = run_lammps(deck, timeout=timeout)
            for src, fname in (
                (deck, DECK),
                (Path(tmp) / DATA, DATA),
                (log, "log.lammps"),
                (Path(tmp) / DUMP, DUMP),
            ):
                shutil.copyfile(src, dest / fname)
        heads[name] = (dest / "log.lammps").read_text().splitlines()[0]
    version = LAMMPS.version() or "unknown"
    package = LAMMPS.package_version() or "unknown"
    date = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    (out / "README.md").write_text(f"""# shear-short-lammps: LAMMPS reference of true periodic simple shear

- Cases (`reference_runs.decks.shear.short_case(NAME)`): 120 disks (`lattice_packing(10, 12, seed=1,
  spread=0.1, compression=0.04)`), kn = kt = 1e5 N/m, gamma_n = gamma_t = 50 1/s, mu 0.5, dt 2e-6 s,
  skin 2e-5 m, {SHORT_STEPS} steps of `fix deform 1 xy erate 2.5 remap v` (1.5% shear strain);
  `constant-volume/`: y fixed; `servo/`: y servo `y variable v_dy v_ry` to sigma_yy = 1000 N/m.
- Code: {version} (log banner `{heads[SHORT_CASES[0]]}`; Debian package {package}), serial,
  1 MPI process.
- Files per case: `{DECK}` (deck, written by `reference_runs/decks/shear.py`), `{DATA}` (data file,
  %.17g), `log.lammps` (thermo every step: step lx ly xy xlo xhi ylo yhi and the virial stress
  xx yy xy, compression positive, %.17g), `{DUMP}` (dump custom every {SHORT_DUMP_EVERY} steps).
- Command: `lmp -in in.lammps -log log.lammps -screen none -nocite` in a scratch job directory
  (`reference_runs.runner.run_job(..., engine="lammps")`; the deck is stored as `{DECK}`).
- Regenerate: `python -c "from reference_runs.decks.shear import make_stored;
  make_stored('reference_runs/stored/shear-short-lammps')"`.
- Date: {date}
- Used by: tests/dem/test_sheared.py (tolerances: positions 1e-10 D50, stress 1e-8 relative).
""")
    return out
