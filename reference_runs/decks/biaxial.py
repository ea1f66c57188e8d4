"""LIGGGHTS 3.8.0 (or LAMMPS 29Sep2021) deck of a DEM run that mirrors gransim.dem.DEMEngine step for step.

Same contact law (``hooke/stiffness`` + ``tangential history``, mass-scaled damping), time step,
skin and neighbour rule (``neigh_modify delay 0 every 1 check yes``), no atom sorting
(``atom_modify map array sort 0 0.0``), ``newton off``, and the loading as ``fix deform``
``variable`` style with ``remap x`` (docs/liggghts.md, "The biaxial test's stress servo"):

* rate axis: ``del = c*step`` with c = rate L0 dt written as one literal (%.17g), so that the
  box lo = lo0 - del/2, hi = hi0 + del/2 is the same double as the engine's;
* servo axis: ``del = (lx - L0) + k*(f_sxx - target)*lx`` with k = dt gain one literal and
  ``f_sxx`` a ``fix ave/time`` (defined before ``fix deform``: evaluated first in end_of_step) of
  a ``compute pressure`` of its own, so it divides by the area of the box used for the forces.

Thermo prints, every ``thermo_every`` steps at %.17g, the step, box (lx ly xlo xhi ylo yhi)
and a separate ``compute pressure`` (virial only) evaluated after ``fix deform``: the stress the
engine reports. A ``dump custom`` writes id x y vx vy omegaz fx fy tqz mass radius every
``dump_every`` steps at %.17g.

``engine="lammps"`` writes the LAMMPS (29 Sep 2021, Debian ``lmp``) form of the same run
(``in.lammps``, docs/lammps.md): ``pair_style gran/hooke/history KN KT GAMMAN GAMMAT MU 1``,
``set group all density/disc RHO`` after ``read_data`` (this build reads the density column
as 3D: m = 4/3 pi r^3 rho), ``fix nve/sphere disc`` (I = m r^2/2), ``comm_modify mode single
vel yes``, ``compute pressure NULL virial``, ``dump_modify ... format line``. The native engine
mirrors it with ``DEMSettings(flavour="lammps")``.
"""

from __future__ import annotations

import datetime
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from gransim.contacts.laws import deck_lines, law_code, make_law
from gransim.contacts.material import effective_shear, effective_youngs
from gransim.dem import kernels
from gransim.dem.lattice import lattice_packing
from gransim.dem.settings import AxisControl, DEMSettings, Loading
from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_path, liggghts_version
from reference_runs.datafile import write_data_file
from reference_runs.parsers import parse_dump_custom, parse_log
from reference_runs.runner import run_job


def _g(v: float) -> str:
    return f"{float(v):.17g}"


ENGINES = ("liggghts", "lammps")
#: deck file name per engine (the run's log: log.liggghts / log.lammps)
DECK_NAMES = {"liggghts": "in.biaxial", "lammps": "in.lammps"}


def _deform_axis(name: str, ctl, L0: float, dt: float, temp: str = "thermo_temp") -> tuple[list[str], str]:
    """Variable lines and the fix deform keyword of one axis (or "" for a fixed axis)."""
    if ctl.mode == "fixed":
        return [], ""
    if ctl.mode == "rate":
        c = ctl.rate * L0 * dt
        lines = [f"variable d{name} equal {_g(c)}*step"]
    else:
        k = dt * ctl.gain
        comp = "1" if name == "x" else "2"
        lines = [
            f"compute ps{name} all pressure {temp} virial",
            f"fix avs{name} all ave/time 1 1 1 c_ps{name}[{comp}]",
            f"variable d{name} equal (l{name}-{_g(L0)})+{_g(k)}*(f_avs{name}-{_g(ctl.target)})*l{name}",
        ]
    return lines, f"{name} variable v_d{name} v_zero"


def write_biaxial_deck(
    job_dir,
    packing: Packing,
    settings: DEMSettings,
    loading: Loading,
    nsteps: int,
    thermo_every: int = 1,
    dump_every: int = 100,
    velocities=None,
    spins=None,
    engine: str = "liggghts",
    law=None,
) -> Path:
    """Write the deck (``in.biaxial`` for LIGGGHTS, ``in.lammps`` for LAMMPS) and
    ``data.biaxial`` into ``job_dir``; return the deck path.

    Outputs of the run (in job_dir): the log (thermo), ``dump.atoms`` (dump custom).
    Run: :func:`run_deck` (``run_job``), or by hand
    ``liggghts -in in.biaxial -log log.liggghts -screen none -nocite`` /
    ``lmp -in in.lammps -log log.lammps -screen none -nocite``.
    ``engine``: "liggghts" or "lammps" (ValueError otherwise).
    ``law``: optional contact law object (``gransim.contacts.laws.make_law``) of ``engine``'s code;
    its pair_style / property lines replace the Hooke lines of ``settings`` (:func:`law_lines`;
    InputError for a law of the other code). ``settings`` still gives dt and the skin.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")

    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    # wrap as the engine does at set-up (Domain::pbc: x += L once), not through fractional
    # coordinates (Packing.wrapped rounds every coordinate): both codes then start from the
    # same doubles
    x = np.array(packing.positions)
    lost = kernels.pbc_wrap(x, np.zeros(2), np.array([packing.cell[0, 0], packing.cell[1, 1]]))
    if lost >= 0:
        raise ValueError(f"particle {lost} lies more than one cell length outside the cell")
    write_data_file(job / "data.biaxial", packing.replace(positions=x), velocities=velocities, omegas=spins, wrap=False)
    s = settings
    Lx, Ly = float(packing.cell[0, 0]), float(packing.cell[1, 1])
    temp = "NULL" if engine == "lammps" else "thermo_temp"
    xl, xa = _deform_axis("x", loading.x, Lx, s.dt, temp)
    yl, ya = _deform_axis("y", loading.y, Ly, s.dt, temp)
    # servo computes must precede their use, ave/time fixes must precede fix deform
    pre = [ln for ln in xl + yl if not ln.startswith("variable")]
    var = [ln for ln in xl + yl if ln.startswith("variable")]
    deform = ""
    if xa or ya:
        deform = f"fix deform all deform 1 {xa} {ya} remap x".replace("  ", " ")
    if engine == "lammps":
        lines = [
            "# gransim.dem mirror deck, LAMMPS form (reference_runs/decks/biaxial.py)",
            "units si",
            "dimension 2",
            "atom_style sphere",
            "atom_modify map array sort 0 0.0",
            "boundary p p p",
            "newton off",
            "comm_modify mode single vel yes",
            "read_data data.biaxial",
            # read_data takes the density column as 3D in this build: 2D masses pi r^2 rho
            f"set group all density/disc {_g(packing.density)}",
            f"neighbor {_g(s.skin)} bin",
            "neigh_modify delay 0 every 1 check yes",
            f"timestep {_g(s.dt)}",
            *law_pair_lines(law, s, engine),
            "fix integr all nve/sphere disc",
            "fix e2d all enforce2d",
            "variable zero equal 0",
            *pre,
            *var,
        ]
    else:
        lines = [
            "# gransim.dem mirror deck (reference_runs/decks/biaxial.py)",
            "units si",
            "dimension 2",
            "atom_style sphere",
            "atom_modify map array sort 0 0.0",
            "boundary p p p",
            "newton off",
            "communicate single vel yes",
            "read_data data.biaxial",
            f"neighbor {_g(s.skin)} bin",
            "neigh_modify delay 0 every 1 check yes",
            f"timestep {_g(s.dt)}",
            *law_pair_lines(law, s, engine),
            "fix integr all nve/sphere",
            "fix e2d all enforce2d",
            "variable zero equal 0",
            *pre,
            *var,
        ]
    if deform:
        lines.append(deform)
    fmt = "line " if engine == "lammps" else ""  # LAMMPS: dump_modify format line "..."
    lines += [
        f"compute pt all pressure {temp} virial",
        "thermo_style custom step lx ly xlo xhi ylo yhi c_pt[1] c_pt[2] c_pt[4]",
        "thermo_modify format float %.17g norm no",
        f"thermo {int(thermo_every)}",
        f"dump d1 all custom {int(dump_every)} dump.atoms id x y vx vy omegaz fx fy tqz mass radius",
        f'dump_modify d1 sort id format {fmt}"%d' + " %.17g" * 10 + '"',
        f"run {int(nsteps)}",
    ]
    deck = job / DECK_NAMES[engine]
    with atomic_path(deck) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    return deck


def law_pair_lines(law, settings: DEMSettings, engine: str) -> list[str]:
    """The deck lines of a contact law for ``engine`` (material properties, pair_style, pair_coeff),
    as the law's module declares them (:func:`gransim.contacts.laws.deck_lines`).

    ``law`` None: the Hooke law of ``settings`` in ``engine``'s arithmetic (``hooke/stiffness
    tangential history`` / ``gran/hooke/history``). InputError for a law of the other code or one
    without deck lines.
    """
    if law is None:
        law = settings.hooke_law(engine)
    return deck_lines(law, engine)


#: the laws of the short case (:func:`short_case_law`), Hooke's contact time and damping
SHORT_CASE_LAWS = (
    "hertz-liggghts",
    "hooke-epsd2-liggghts",
    "hooke-epsd-liggghts",
    "hooke-cdt-liggghts",
    "hertz-lammps",
    "hertz-granular-lammps",
    "hooke-sds-lammps",
)


def short_case_law(name: str):
    """The law ``name`` for :func:`short_case`, with a contact time and damping comparable to its
    Hooke law (kn = kt = 1e5 N/m, 50 1/s, mu 0.5).

    Hertz: r about 1 mm, m* about 4.2e-3 kg, overlaps about 4e-5 m, R* about 5e-4 m, a = sqrt(R*
    delta) about 1.4e-4 m; E = 6e8 Pa, nu = 0.3 (Y* = 3.3e8 Pa) gives the tangent stiffness
    2 Y* a about 9e4 N/m; e = 0.98 (Hooke's zeta = 50/(2 sqrt(kn/m*)) = 0.005, e = 0.984);
    ``gran/hertz/history`` KN = 4/3 Y*, KT = 8 G*, GAMMAN = GAMMAT = 50/1.4e-4 = 3.5e5 1/(s m)
    (damping m* GAMMAN a = m* 50 at that overlap); ``granular``: damping tsuji with e, GAMMAT =
    sqrt(8 G*/(2 Y*)). Rolling: Hooke's parameters, mu_r = 0.1, eta_r = 0.3; sds KROLL = 1e5 N/m,
    GAMMAROLL = 0.2 kg/s (m* 50), MUROLL = 0.1.
    """
    E, nu, e, mu = 6.0e8, 0.3, 0.98, 0.5
    hooke = {"kn": 1e5, "kt": 1e5, "gamma_n": 50.0, "gamma_t": 50.0, "mu": mu}
    if name == "hertz-liggghts":
        return make_law(name, youngs_modulus=E, poisson_ratio=nu, restitution=e, friction=mu)
    if name == "hertz-granular-lammps":
        Y, G = effective_youngs(E, nu, E, nu), effective_shear(E, nu, E, nu)
        return make_law(
            name, youngs_modulus=E, poisson_ratio=nu, damp=e, friction=mu, gammat_ratio=(8.0 * G / (2.0 * Y)) ** 0.5
        )
    if name == "hertz-lammps":
        Y, G = effective_youngs(E, nu, E, nu), effective_shear(E, nu, E, nu)
        return make_law(name, kn=4.0 / 3.0 * Y, kt=8.0 * G, gamma_n=3.5e5, gamma_t=3.5e5, mu=mu)
    if name in ("hooke-epsd2-liggghts", "hooke-cdt-liggghts"):
        return make_law(name, **hooke, mu_r=0.1)
    if name == "hooke-epsd-liggghts":
        return make_law(name, **hooke, mu_r=0.1, eta_r=0.3)
    if name == "hooke-sds-lammps":
        return make_law(
            name,
            kn=1e5,
            damp=50.0,
            damping="mass_velocity",
            kt=1e5,
            xgammat=1.0,
            mu=mu,
            kroll=1e5,
            gammaroll=0.2,
            muroll=0.1,
        )
    raise InputError(f"law: expected one of {', '.join(SHORT_CASE_LAWS)}, got {name!r}")


def make_stored_law(name: str, out_root, timeout: float | None = 900.0) -> Path:
    """Run the short case with the law ``name`` (:func:`short_case_law`) in its code and store
    deck, data, log, dump and a README under ``out_root/biaxial-short-<name>/``."""
    engine = law_code(name)
    out = Path(out_root) / f"biaxial-short-{name}"
    out.mkdir(parents=True, exist_ok=True)
    p, s, ld, n = short_case()
    law = short_case_law(name)
    with tempfile.TemporaryDirectory(prefix=f"biaxial-short-{name}-") as tmp:
        deck = write_biaxial_deck(
            tmp, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY, engine=engine, law=law
        )
        log = run_deck(deck, engine, timeout=timeout)
        for src in (deck, Path(tmp) / "data.biaxial", log, Path(tmp) / "dump.atoms"):
            shutil.copyfile(src, out / src.name)
    head = (out / log.name).read_text().splitlines()[0]
    (out / "README.md").write_text(f"""# biaxial-short-{name}: {engine} reference for the law {name} (step for step)

- Case: `reference_runs.decks.biaxial.short_case()` (120 disks, servo on x to 100 N/m, y at
  -1 1/s, dt 2e-6 s, skin 2e-5 m), {n} steps, with the law
  `reference_runs.decks.biaxial.short_case_law("{name}")` = `{law!r}`.
- Code: {head}, `/usr/bin/{"liggghts" if engine == "liggghts" else "lmp"}` (Debian package), serial.
- Files: `{deck.name}` (deck, `write_biaxial_deck(..., engine="{engine}", law=law)`), `data.biaxial`
  (%.17g), `{log.name}` (thermo every step: box and virial stress), `dump.atoms` (every
  {SHORT_CASE_DUMP_EVERY} steps: id x y vx vy omegaz fx fy tqz mass radius).
- Regenerate: `python -c "from reference_runs.decks.biaxial import make_stored_law;
  make_stored_law('{name}', 'reference_runs/stored')"`.
- Date: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
- Used by: tests/dem/test_law_runs.py (native `DEMEngine(..., law=law)` with
  `DEMSettings(flavour="{engine}")`; tolerances positions 1e-10 D50, stresses 1e-8 relative).
""")
    return out


# -- readers of this deck's outputs (thin wrappers over reference_runs.parsers) -------------

THERMO_COLUMNS = ("step", "lx", "ly", "xlo", "xhi", "ylo", "yhi", "sxx", "syy", "sxy")
_THERMO_NAMES = ("Step", "Lx", "Ly", "Xlo", "Xhi", "Ylo", "Yhi", "c_pt[1]", "c_pt[2]", "c_pt[4]")


def read_thermo(log_path) -> dict:
    """Thermo rows of the deck's (single) run as arrays keyed by THERMO_COLUMNS
    (:func:`reference_runs.parsers.parse_log`)."""
    run = parse_log(Path(log_path)).runs[-1]
    out = {k: np.array(run.column(name)) for k, name in zip(THERMO_COLUMNS, _THERMO_NAMES)}
    out["step"] = out["step"].astype(np.int64)
    return out


def read_dump(dump_path) -> dict:
    """``dump.atoms`` as {step: {"id", "x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz", "mass",
    "radius"}} (rows sorted by id; :func:`reference_runs.parsers.parse_dump_custom`)."""
    return {int(fr.step): dict(fr.columns) for fr in parse_dump_custom(Path(dump_path))}


# -- the stored cross-check case ------------------------------------------------------------

SHORT_CASE_STEPS = 3000
SHORT_CASE_DUMP_EVERY = 500


def short_case():
    """The step-for-step case of tests/dem/test_liggghts.py (reference_runs/stored/biaxial-short).

    120 polydisperse disks on a jittered triangular lattice, overlapping by about 4% of a radius
    (contacts across the periodic boundary from step 0), kn = kt = 1e5 N/m, gamma_n = gamma_t =
    50 1/s, mu = 0.5, dt = 2e-6 s (contact time / 45), skin 2e-5 m; x: servo to sigma_11 =
    100 N/m with gain 0.01 1/(Pa s); y: compression at 1 1/s. About 60 of 150 contacts slide.
    Returns (packing, settings, loading, nsteps).
    """
    p = lattice_packing(10, 12, seed=1, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
    ld = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))
    return p, s, ld, SHORT_CASE_STEPS


def run_deck(deck: Path, engine: str = "liggghts", np: int = 1, timeout: float | None = 600.0) -> Path:
    """Run a deck written by :func:`write_biaxial_deck` in its directory; returns the log path.

    ``engine``: "liggghts" or "lammps" (the code the deck was written for). Through
    :func:`reference_runs.runner.run_job` (job directory = the deck's directory, ``np`` MPI
    processes, always rerun; the deck is copied to the runner's deck name, the log is
    ``log.lammps`` and a ``manifest.json`` records command, version and hashes): no process of the
    job outlives the caller (:func:`reference_runs.runner.start_watched`). ``timeout`` (s, None: no
    limit) kills the job after that time (``ReferenceRunError`` with ``timed_out=True``). Raises
    :class:`~reference_runs.errors.ReferenceRunError` (binary missing, non-zero exit, ERROR or
    WARNING lines, no ``dump.atoms``, a log short of the run) quoting the log.
    """
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    deck = Path(deck)
    data = (deck.parent / "data.biaxial").read_bytes()
    return run_job(
        deck.parent,
        deck.read_text(),
        engine=engine,
        files={"data.biaxial": data},
        np=np,
        timeout=timeout,
        outputs=("dump.atoms",),
        expected_runs=1,
        progress=False,
        force=True,
    ).log_path


def run_liggghts(deck: Path, np: int = 1, timeout: float | None = 600.0) -> Path:
    """:func:`run_deck` with ``engine="liggghts"`` (kept for its callers)."""
    return run_deck(deck, "liggghts", np=np, timeout=timeout)


def make_stored(out_dir, timeout: float | None = 600.0, engine: str = "liggghts") -> Path:
    """Run the short case with LIGGGHTS or LAMMPS (serial, :func:`run_deck`) and store deck, data,
    log and dump with a README. The job runs in a scratch directory; the stored names are the
    deck's own (``in.biaxial`` + ``log.liggghts``, or ``in.lammps`` + ``log.lammps``), as read by
    tests/dem/test_liggghts.py and tests/dem/test_lammps.py."""
    if engine not in ENGINES:
        raise ValueError(f"engine: expected one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "lammps":
        return _make_stored_lammps(Path(out_dir), timeout)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p, s, ld, n = short_case()
    with tempfile.TemporaryDirectory(prefix="biaxial-short-") as tmp:
        deck = write_biaxial_deck(tmp, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY)
        log = run_liggghts(deck, timeout=timeout)
        for src, name in (
            (deck, "in.biaxial"),
            (Path(tmp) / "data.biaxial", "data.biaxial"),
            (log, "log.liggghts"),
            (Path(tmp) / "dump.atoms", "dump.atoms"),
        ):
            shutil.copyfile(src, out / name)
    version = liggghts_version() or "unknown"  # as the binary reports itself, with its path
    head = (out / "log.liggghts").read_text().splitlines()[0]
    (out / "README.md").write_text(f"""# biaxial-short: LIGGGHTS reference for the DEM engine (step for step)

- Case: `reference_runs.decks.biaxial.short_case()` (120 disks, servo on x to 100 N/m, y at
  -1 1/s, mu 0.5, kn = kt = 1e5 N/m, damping 50 1/s, dt 2e-6 s, skin 2e-5 m), {n} steps.
- Code: {head} ({version}), serial, 1 MPI process.
- Files: `in.biaxial` (deck, written by `reference_runs/decks/biaxial.py`), `data.biaxial`
  (data file, %.17g), `log.liggghts` (thermo every step: box and virial stress after
  `fix deform`, %.17g), `dump.atoms` (dump custom every {SHORT_CASE_DUMP_EVERY} steps).
- Command: `liggghts -in in.liggghts -log log.lammps -screen none -nocite` in a scratch job
  directory (`reference_runs.runner.run_job`; deck and data as here), log stored as `log.liggghts`.
- Regenerate: `python -c "from reference_runs.decks.biaxial import make_stored;
  make_stored('reference_runs/stored/biaxial-short')"`.
- Date: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
- Used by: tests/dem/test_liggghts.py (tolerances: positions 1e-10 D50, stresses 1e-8 relative).
""")
    return out


def _make_stored_lammps(out: Path, timeout: float | None) -> Path:
    """:func:`make_stored` for LAMMPS (reference_runs/stored/biaxial-short-lammps)."""
    out.mkdir(parents=True, exist_ok=True)
    p, s, ld, n = short_case()
    with tempfile.TemporaryDirectory(prefix="biaxial-short-lammps-") as tmp:
        deck = write_biaxial_deck(tmp, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY, engine="lammps")
        log = run_deck(deck, "lammps", timeout=timeout)
        for src, name in (
            (deck, "in.lammps"),
            (Path(tmp) / "data.biaxial", "data.biaxial"),
            (log, "log.lammps"),
            (Path(tmp) / "dump.atoms", "dump.atoms"),
        ):
            shutil.copyfile(src, out / name)
    lines = (out / "log.lammps").read_text().splitlines()
    head = lines[0]
    builds = next((ln.split("=")[1].strip() for ln in lines if ln.startswith("Neighbor list builds")), "?")
    lmp = shutil.which("lmp") or "lmp"
    try:
        pkg = (
            subprocess.run(
                ["dpkg-query", "-W", "-f", "${Version}", "lammps"],
                capture_output=True,
                text=True,
                timeout=30,
                check=False,
            ).stdout.strip()
            or "unknown"
        )
    except (OSError, subprocess.SubprocessError):
        pkg = "unknown"
    title = "biaxial-short-lammps: LAMMPS reference for the DEM engine (step for step)"
    (out / "README.md").write_text(f"""# {title}

- Case: `reference_runs.decks.biaxial.short_case()` (120 disks, servo on x to 100 N/m, y at
  -1 1/s, mu 0.5, kn = kt = 1e5 N/m, damping 50 1/s, dt 2e-6 s, skin 2e-5 m), {n} steps: the
  same case as `../biaxial-short` (LIGGGHTS), the same data file.
- Code: {head} (`{lmp}`, Debian package lammps {pkg}), serial, 1 MPI process;
  {builds} neighbour list builds in the run.
- Files: `in.lammps` (deck, written by `reference_runs/decks/biaxial.py` with `engine="lammps"`),
  `data.biaxial` (data file, %.17g; masses set by `set group all density/disc`), `log.lammps`
  (thermo every step: box and virial stress after `fix deform`, %.17g), `dump.atoms` (dump
  custom every {SHORT_CASE_DUMP_EVERY} steps).
- Command: `lmp -in in.lammps -log log.lammps -screen none -nocite` in a scratch job directory
  (`reference_runs.decks.biaxial.run_deck(deck, "lammps")`; deck and data as here).
- Regenerate: `python -c "from reference_runs.decks.biaxial import make_stored;
  make_stored('reference_runs/stored/biaxial-short-lammps', engine='lammps')"`.
- Date: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")}
- Used by: tests/dem/test_lammps.py (native `DEMSettings(flavour="lammps")`; measured: exactly
  equal; tolerances positions 1e-10 D50, stresses 1e-8 relative). Differences of the two codes:
  docs/lammps.md.
""")
    return out
