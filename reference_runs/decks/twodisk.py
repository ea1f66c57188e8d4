"""Pieces shared by the two-disk decks of the contact laws (``hertz.py``, ``rolling.py``): the
data file, the head of each code's deck, the output lines, writing and running one job.

A two-disk case is a dict with ``box`` (Lx, Ly), ``positions`` (2, 2), ``radii`` (2,),
``velocities`` (2, 2), ``spins`` (2,), ``density`` (mass per area, kg/m^2), ``skin``, ``dt`` and
``nsteps``. Numbers are written with %.17g so that both codes start from gransim's doubles.
"""

from __future__ import annotations

from pathlib import Path

from gransim.io import atomic_path
from reference_runs.parsers import parse_dump_custom
from reference_runs.runner import run_job

DUMP_NAME = "dump.atoms"
#: the lines every two-disk deck starts with, after its comment
HEAD = [
    "units si",
    "dimension 2",
    "atom_style sphere",
    "atom_modify map array sort 0 0.0",
    "boundary p p p",
    "newton off",
]


def g(v: float) -> str:
    return f"{float(v):.17g}"


def data_text(case: dict, title: str) -> str:
    """The data file (atom_style sphere: id type diameter density x y z; Velocities
    id vx vy vz wx wy wz), %.17g; ``title`` is its first line."""
    Lx, Ly = case["box"]
    lines = [
        title,
        "",
        "2 atoms",
        "1 atom types",
        "",
        f"0 {g(Lx)} xlo xhi",
        f"0 {g(Ly)} ylo yhi",
        "-0.005 0.005 zlo zhi",
        "",
        "Atoms",
        "",
    ]
    for k in range(2):
        x, y = case["positions"][k]
        lines.append(f"{k + 1} 1 {g(2.0 * case['radii'][k])} {g(case['density'])} {g(x)} {g(y)} 0")
    lines += ["", "Velocities", ""]
    for k in range(2):
        vx, vy = case["velocities"][k]
        lines.append(f"{k + 1} {g(vx)} {g(vy)} 0 0 0 {g(case['spins'][k])}")
    return "\n".join(lines) + "\n"


def preamble(engine: str, comment: str, case: dict, data_name: str) -> list[str]:
    """Comment, :data:`HEAD`, communication, read_data (LAMMPS: 2D masses by ``set ...
    density/disc``), neighbour rule and time step of one code's deck."""
    c = case
    if engine == "liggghts":
        comm = ["communicate single vel yes", f"read_data {data_name}"]
    else:
        comm = [
            "comm_modify mode single vel yes",
            f"read_data {data_name}",
            f"set group all density/disc {g(c['density'])}",
        ]
    return [
        comment,
        *HEAD,
        *comm,
        f"neighbor {g(c['skin'])} bin",
        "neigh_modify delay 0 every 1 check yes",
        f"timestep {g(c['dt'])}",
    ]


def output_lines(engine: str, nsteps: int) -> list[str]:
    """Thermo every step and ``dump custom`` of id x y vx vy omegaz fx fy tqz mass radius every step
    at %.17g (LAMMPS' dump_modify needs ``format line``), then ``run nsteps``."""
    fmt = "" if engine == "liggghts" else "line "
    return [
        "thermo_style custom step atoms ke",
        "thermo_modify format float %.17g norm no",
        "thermo 1",
        f"dump d1 all custom 1 {DUMP_NAME} id x y vx vy omegaz fx fy tqz mass radius",
        f'dump_modify d1 sort id format {fmt}"%d' + " %.17g" * 10 + '"',
        f"run {int(nsteps)}",
    ]


def write_job(job_dir, deck_name: str, text: str, data_name: str, data: str) -> Path:
    """Write the deck and its data file into ``job_dir`` (atomically); return the deck path."""
    job = Path(job_dir)
    job.mkdir(parents=True, exist_ok=True)
    with atomic_path(job / data_name) as tmp:
        Path(tmp).write_text(data)
    deck = job / deck_name
    with atomic_path(deck) as tmp:
        Path(tmp).write_text(text)
    return deck


def run_two_disk(job_dir, engine: str, text: str, data_name: str, data: str, timeout: float | None = 120.0):
    """Run a two-disk deck through :func:`reference_runs.runner.run_job` (always rerun; the dump is
    a required output); returns the :class:`~reference_runs.runner.JobResult`."""
    return run_job(
        job_dir,
        text,
        files={data_name: data},
        timeout=timeout,
        outputs=(DUMP_NAME,),
        expected_runs=1,
        progress=False,
        force=True,
        engine=engine,
    )


def read_dump(path) -> dict:
    """``dump.atoms`` as {step: {column: (2,) array}} (rows sorted by id)."""
    return {int(fr.step): dict(fr.columns) for fr in parse_dump_custom(Path(path))}
