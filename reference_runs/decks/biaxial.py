"""LIGGGHTS 3.8.0 deck of a DEM run that mirrors gransim.dem.DEMEngine step for step.

Same contact law (``hooke/stiffness`` + ``tangential history``, mass-scaled damping), time step,
skin and neighbour rule (``neigh_modify delay 0 every 1 check yes``), no atom sorting
(``atom_modify map array sort 0 0.0``), ``newton off``, and the loading as ``fix deform``
``variable`` style with ``remap x`` (shared notes liggghts-3.8.md):

* rate axis: ``del = c*step`` with c = rate L0 dt written as one literal (%.17g), so that the
  box lo = lo0 - del/2, hi = hi0 + del/2 is the same double as the engine's;
* servo axis: ``del = (lx - L0) + k*(f_sxx - target)*lx`` with k = dt gain one literal and
  ``f_sxx`` a ``fix ave/time`` (defined before ``fix deform``: evaluated first in end_of_step) of
  a ``compute pressure`` of its own, so it divides by the area of the box used for the forces.

Thermo prints, every ``thermo_every`` steps at %.17g, the step, box (lx ly xlo xhi ylo yhi)
and a separate ``compute pressure`` (virial only) evaluated after ``fix deform``: the stress the
engine reports. A ``dump custom`` writes id x y vx vy omegaz fx fy tqz mass radius every
``dump_every`` steps at %.17g.
"""

from __future__ import annotations

from pathlib import Path

from gransim.dem.settings import DEMSettings, Loading
from gransim.geometry import Packing
from gransim.io import atomic_path
from reference_runs.datafile import write_data_file


def _g(v: float) -> str:
    return f"{float(v):.17g}"


def _deform_axis(name: str, ctl, L0: float, dt: float) -> tuple[list[str], str]:
    """Variable lines and the fix deform keyword of one axis (or "" for a fixed axis)."""
    if ctl.mode == "fixed":
        return [], ""
    if ctl.mode == "rate":
        c = ctl.rate * L0 * dt
        lines = [f"variable d{name} equal {_g(c)}*step"]
    else:
        k = dt * ctl.gain
        comp = "1" if name == "x" else "2"
        lines = [f"compute ps{name} all pressure thermo_temp virial",
                 f"fix avs{name} all ave/time 1 1 1 c_ps{name}[{comp}]",
                 f"variable d{name} equal (l{name}-{_g(L0)})+{_g(k)}*(f_avs{name}-{_g(ctl.target)})*l{name}"]
    return lines, f"{name} variable v_d{name} v_zero"


def write_biaxial_deck(job_dir, packing: Packing, settings: DEMSettings, loading: Loading, nsteps: int,
                       thermo_every: int = 1, dump_every: int = 100, velocities=None, spins=None) -> Path:
    """Write ``in.biaxial`` and ``data.biaxial`` into ``job_dir``; return the deck path.

    Outputs of the run (in job_dir): the log (thermo), ``dump.atoms`` (dump custom).
    Run: :func:`run_liggghts` (``run_job``: log ``log.lammps``), or by hand
    ``liggghts -in in.biaxial -log log.liggghts -screen none -nocite``.
    """
    import numpy as np

    from gransim.dem import kernels

    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    # wrap as the engine does at set-up (Domain::pbc: x += L once), not through fractional
    # coordinates (Packing.wrapped rounds every coordinate): both codes then start from the
    # same doubles
    x = np.array(packing.positions)
    lost = kernels.pbc_wrap(x, np.zeros(2), np.array([packing.cell[0, 0], packing.cell[1, 1]]))
    if lost >= 0:
        raise ValueError(f"particle {lost} lies more than one cell length outside the cell")
    write_data_file(job / "data.biaxial", packing.replace(positions=x), velocities=velocities, omegas=spins,
                    wrap=False)
    s = settings
    Lx, Ly = float(packing.cell[0, 0]), float(packing.cell[1, 1])
    xl, xa = _deform_axis("x", loading.x, Lx, s.dt)
    yl, ya = _deform_axis("y", loading.y, Ly, s.dt)
    # servo computes must precede their use, ave/time fixes must precede fix deform
    pre = [ln for ln in xl + yl if not ln.startswith("variable")]
    var = [ln for ln in xl + yl if ln.startswith("variable")]
    deform = ""
    if xa or ya:
        deform = f"fix deform all deform 1 {xa} {ya} remap x".replace("  ", " ")
    lines = [
        "# gransim.dem mirror deck (reference_runs/decks/biaxial.py)",
        "units si", "dimension 2", "atom_style sphere", "atom_modify map array sort 0 0.0",
        "boundary p p p", "newton off", "communicate single vel yes",
        "read_data data.biaxial",
        f"neighbor {_g(s.skin)} bin", "neigh_modify delay 0 every 1 check yes",
        f"timestep {_g(s.dt)}",
        "fix m1 all property/global kn peratomtypepair 1 " + _g(s.kn),
        "fix m2 all property/global kt peratomtypepair 1 " + _g(s.kt),
        "fix m3 all property/global gamman peratomtypepair 1 " + _g(s.gamma_n),
        "fix m4 all property/global gammat peratomtypepair 1 " + _g(s.gamma_t),
        "fix m5 all property/global coefficientFriction peratomtypepair 1 " + _g(s.mu),
        "pair_style gran model hooke/stiffness tangential history",
        "pair_coeff * *",
        "fix integr all nve/sphere", "fix e2d all enforce2d",
        "variable zero equal 0",
        *pre, *var,
    ]
    if deform:
        lines.append(deform)
    lines += [
        "compute pt all pressure thermo_temp virial",
        "thermo_style custom step lx ly xlo xhi ylo yhi c_pt[1] c_pt[2] c_pt[4]",
        "thermo_modify format float %.17g norm no",
        f"thermo {int(thermo_every)}",
        f"dump d1 all custom {int(dump_every)} dump.atoms id x y vx vy omegaz fx fy tqz mass radius",
        "dump_modify d1 sort id format \"%d" + " %.17g" * 10 + "\"",
        f"run {int(nsteps)}",
    ]
    deck = job / "in.biaxial"
    with atomic_path(deck) as tmp:
        Path(tmp).write_text("\n".join(lines) + "\n")
    return deck


# -- readers of this deck's outputs (thin wrappers over reference_runs.parsers) -------------

THERMO_COLUMNS = ("step", "lx", "ly", "xlo", "xhi", "ylo", "yhi", "sxx", "syy", "sxy")
_THERMO_NAMES = ("Step", "Lx", "Ly", "Xlo", "Xhi", "Ylo", "Yhi", "c_pt[1]", "c_pt[2]", "c_pt[4]")


def read_thermo(log_path) -> dict:
    """Thermo rows of the deck's (single) run as arrays keyed by THERMO_COLUMNS
    (:func:`reference_runs.parsers.parse_log`)."""
    import numpy as np

    from reference_runs.parsers import parse_log

    run = parse_log(Path(log_path)).runs[-1]
    out = {k: np.array(run.column(name)) for k, name in zip(THERMO_COLUMNS, _THERMO_NAMES)}
    out["step"] = out["step"].astype(np.int64)
    return out


def read_dump(dump_path) -> dict:
    """``dump.atoms`` as {step: {"id", "x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz", "mass",
    "radius"}} (rows sorted by id; :func:`reference_runs.parsers.parse_dump_custom`)."""
    from reference_runs.parsers import parse_dump_custom

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
    from gransim.dem.lattice import lattice_packing
    from gransim.dem.settings import AxisControl

    p = lattice_packing(10, 12, seed=1, spread=0.1, compression=0.04)
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
    ld = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))
    return p, s, ld, SHORT_CASE_STEPS


def run_liggghts(deck: Path, np: int = 1, timeout: float | None = 600.0) -> Path:
    """Run a deck written by :func:`write_biaxial_deck` in its directory; returns the log path.

    A thin wrapper over :func:`reference_runs.runner.run_job` (job directory = the deck's
    directory, ``np`` MPI processes, always rerun): the deck is copied to ``in.liggghts``, the
    log is ``log.lammps`` and a ``manifest.json`` records command, version and hashes.
    ``timeout`` (s, None: no limit) kills the job after that time (``ReferenceRunError`` with
    ``timed_out=True``). Raises :class:`~reference_runs.errors.ReferenceRunError` (binary missing,
    non-zero exit, ERROR or unexpected WARNING lines, no ``dump.atoms``, a log or dump short of the
    runs and frames the deck asks for) quoting the log.
    """
    from reference_runs.runner import run_job

    deck = Path(deck)
    data = (deck.parent / "data.biaxial").read_bytes()
    res = run_job(deck.parent, deck.read_text(), files={"data.biaxial": data}, np=np, timeout=timeout,
                  outputs=("dump.atoms",), expected_runs=1, progress=False, force=True)
    return res.log_path


def make_stored(out_dir, timeout: float | None = 600.0) -> Path:
    """Run the short case with LIGGGHTS (serial, :func:`run_liggghts`) and store deck, data, log
    and dump with a README. The job runs in a scratch directory; the stored names are the
    deck's own (``in.biaxial``, ``log.liggghts``), as read by tests/dem/test_liggghts.py."""
    import datetime
    import shutil
    import tempfile

    from gransim.io import liggghts_version

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    p, s, ld, n = short_case()
    with tempfile.TemporaryDirectory(prefix="biaxial-short-") as tmp:
        deck = write_biaxial_deck(tmp, p, s, ld, n, thermo_every=1, dump_every=SHORT_CASE_DUMP_EVERY)
        log = run_liggghts(deck, timeout=timeout)
        for src, name in ((deck, "in.biaxial"), (Path(tmp) / "data.biaxial", "data.biaxial"),
                          (log, "log.liggghts"), (Path(tmp) / "dump.atoms", "dump.atoms")):
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
- Date: {datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}
- Used by: tests/dem/test_liggghts.py (tolerances: positions 1e-10 D50, stresses 1e-8 relative).
""")
    return out
