"""Run Guo & Zhao's FEM x DEM biaxial test (Debian's YADE 2023.02a + escript 5.6) on this machine.

Two stages, each a job directory of its own:

1. :func:`prepare_rve`: prepareRVE.py's recipe (``n_disks`` disks, r_mean 5 mm +- 40 %, periodic cell
   0.24 m for 400 disks, scaled as sqrt(n / 400) for fewer, consolidated frictionless to 100 kPa,
   then friction angle 0.5 rad) writes ``0.yade.gz`` and ``rve.txt``.
2. :func:`run_biaxial`: biaxialSmooth.py (mesh ``nx`` x ``ny``, ``steps`` load steps,
   ``workers`` processes of msFEM2D's multiprocessing pool) writes the records of
   ``job/femxdem_record.py``; they are read strictly (:mod:`.output`) and stored in one HDF5 file,
   written atomically, with provenance.

Both run Debian's ``/usr/bin/python3`` (YADE's launcher is a Python 3.11 script for that interpreter;
the ``python3`` first on ``PATH`` may be another one, whose numpy escript's bindings reject) on the
files of :func:`reference_runs.femxdem.port.install_port`, in a clean environment (escript's Python
and library folders, ``OMP_NUM_THREADS=1``, ``HOME`` inside the job), through
:func:`reference_runs.runner.start_watched`: own session, every process marked, private ``TMPDIR``,
a watchdog, everything killed on timeout, exception or exit, so nothing is left running.

Nothing listening: the scripts import YADE's launcher as a module (``yadeimport.py -> /usr/bin/yade``,
as simDEM.py does), and the launcher starts its TCP servers only when it runs as ``__main__``
(/usr/bin/yade:388-393). The stage checks this while it runs: every 0.5 s it looks up the sockets of
every process of the job among the LISTEN rows of ``/proc/net/tcp*``; a listening socket, or YADE's
server lines on stderr, fail the stage (and its processes are killed).
"""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from gransim.errors import InputError

from ..errors import ReferenceRunError
from ..runner import _job_pids, finish_watched, start_watched
from ..yade.job import SERVER_LINES
from .output import read_outputs, read_rve, write_h5
from .port import INSTALL_HINT, PortError, check_originals, install_port, recorder_sha256

DEBIAN_PYTHON = "/usr/bin/python3"
ESCRIPT_ROOT = "/usr/lib/python3-escript"
PARAMS_NAME = "femxdem_params.json"
RESULT_NAME = "femxdem.h5"
#: prepareRVE.py:8-9: 400 disks in a 0.24 m periodic cell
CELL_400 = 0.24
PACKAGES = ("yade", "libyade", "python3-escript")


def _echo(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


@dataclass(frozen=True)
class FemxdemParams:
    """One run. Defaults are Guo & Zhao's benchmark (biaxialSmooth.py:40-48, 78; prepareRVE.py:9).

    nx, ny : elements across and along the 50 x 100 mm specimen (4 Gauss points, one RVE each).
    steps : load steps of 1e-4 m at the top.
    workers : processes of msFEM2D's pool (>= 2: msFEM2D.py:36-40 refuses one).
    field_steps : steps whose Gauss-point fields are written (0 = before loading).
    n_disks, seed : the RVE (prepareRVE.py's makeCloud); the cell is 0.24 sqrt(n_disks / 400) m.
    """

    nx: int = 8
    ny: int = 16
    steps: int = 100
    workers: int = 16
    field_steps: tuple = field(default=(0, 100))
    n_disks: int = 400
    seed: int = 1

    @property
    def cell(self) -> float:
        return CELL_400 if self.n_disks == 400 else CELL_400 * math.sqrt(self.n_disks / 400.0)

    @property
    def n_gauss(self) -> int:
        return 4 * self.nx * self.ny

    def checked(self) -> FemxdemParams:
        """Self, once every value is valid; else :class:`InputError` naming the option."""
        for name, low in (("nx", 1), ("ny", 1), ("steps", 1), ("workers", 2), ("n_disks", 2), ("seed", 0)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < low:
                why = " (msFEM2D's pool needs more than one process)" if name == "workers" else ""
                raise InputError(f"--{name.replace('_', '-')}: expected an integer >= {low}{why}, got {v!r}")
        fs = tuple(self.field_steps)
        if any(isinstance(t, bool) or not isinstance(t, int) or not 0 <= t <= self.steps for t in fs):
            raise InputError(f"--field-steps: expected steps in 0..{self.steps}, got {list(fs)}")
        return FemxdemParams(**{**asdict(self), "field_steps": tuple(sorted(set(fs)))})

    def job_parameters(self) -> dict:
        """What the job's scripts read (femxdem_params.json)."""
        d = asdict(self)
        d["field_steps"] = list(self.field_steps)
        d["cell"] = self.cell
        return d


def check_installed() -> None:
    """Debian's python3, escript and the YADE files the port needs; :class:`PortError` otherwise."""
    if not os.access(DEBIAN_PYTHON, os.X_OK):
        raise PortError(f"{DEBIAN_PYTHON} is missing: {INSTALL_HINT}")
    if not (Path(ESCRIPT_ROOT) / "esys" / "escript").is_dir():
        raise PortError(f"escript is not installed ({ESCRIPT_ROOT}/esys/escript missing): {INSTALL_HINT}")
    check_originals()


def job_env(job_dir: Path) -> dict:
    """The jobs' whole environment (nothing inherited but the language): escript's Python and
    library folders (what run-escript3 sets), the ported modules, one OpenMP thread per process,
    unbuffered output (msFEM2D's pool forks: a buffer copied into a worker would be written twice)."""
    return {
        "PATH": "/usr/bin:/bin",
        "HOME": str(job_dir / "home"),
        "LANG": "C.UTF-8",
        "PYTHONPATH": os.pathsep.join([ESCRIPT_ROOT, str(job_dir / "FEMxDEM"), str(job_dir)]),
        "LD_LIBRARY_PATH": f"{ESCRIPT_ROOT}/lib",
        "OMP_NUM_THREADS": "1",
        "PYTHONUNBUFFERED": "1",
        "PYTHONNOUSERSITE": "1",
        "PYTHONDONTWRITEBYTECODE": "1",
        # YADE's launcher, imported as yadeimport, has invalid escapes (/usr/bin/yade:220-231)
        "PYTHONWARNINGS": "ignore::DeprecationWarning",
    }


def listening_ports(pids) -> list:
    """TCP ports on which any of ``pids`` listens: their socket inodes (``/proc/PID/fd``) among the
    LISTEN rows (state 0A) of ``/proc/PID/net/tcp`` and ``tcp6``."""
    inodes, tables = set(), set()
    for pid in pids:
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            if target.startswith("socket:["):
                inodes.add(target[8:-1])
        tables.add(pid)
    ports = set()
    for pid in tables:
        for name in ("tcp", "tcp6"):
            try:
                rows = Path(f"/proc/{pid}/net/{name}").read_text().splitlines()[1:]
            except OSError:
                continue
            for row in rows:
                f = row.split()
                if len(f) > 9 and f[3] == "0A" and f[9] in inodes:
                    ports.add(int(f[1].rsplit(":", 1)[1], 16))
        break  # one network namespace: one table is enough
    return sorted(ports)


def _tail(path: Path, n: int = 12) -> list:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return []
    return [ln for ln in lines if ln.strip()][-n:]


def _fresh_dir(path: Path, what: str) -> None:
    """Make ``path`` an empty job directory; an existing one is removed only when it is one of ours
    (it holds femxdem_params.json)."""
    if path.exists():
        if not (path / PARAMS_NAME).is_file():
            raise InputError(f"{path}: exists and is not a {what} directory of this command; choose another --out")
        shutil.rmtree(path)
    path.mkdir(parents=True)


@dataclass(frozen=True)
class StageResult:
    rc: int
    wall: float
    load_before: tuple
    load_after: tuple


def run_stage(cmd, job_dir: Path, timeout: float | None, what: str, on_poll=None) -> StageResult:
    """Run ``cmd`` in ``job_dir`` (stdout.txt, stderr.txt there) through :func:`start_watched`;
    a non-zero exit, a timeout or a listening socket is a :class:`ReferenceRunError` naming
    ``what`` and ``job_dir``, with the end of stderr. ``on_poll()`` is called every 0.5 s."""
    job_dir = Path(job_dir).resolve()
    env = job_env(job_dir)
    Path(env["HOME"]).mkdir(exist_ok=True)
    load_before = os.getloadavg()
    t0 = time.monotonic()
    with open(job_dir / "stdout.txt", "wb") as out, open(job_dir / "stderr.txt", "wb") as err:
        job = start_watched(
            cmd, env=env, private_tmp=True, cwd=str(job_dir), stdin=subprocess.DEVNULL, stdout=out, stderr=err
        )
        try:
            while True:
                try:
                    rc = job.proc.wait(timeout=0.5)
                    break
                except subprocess.TimeoutExpired:
                    pass
                ports = listening_ports(_job_pids(job.pgid, job.marker))
                if ports:
                    raise ReferenceRunError(
                        f"{what}: a process of the job listens on TCP port(s) {ports}; killed ({job_dir})",
                        job_dir=job_dir,
                    )
                if on_poll is not None:
                    on_poll()
                if timeout is not None and time.monotonic() - t0 > timeout:
                    raise ReferenceRunError(
                        f"{what}: timed out after {timeout:g} s; every process of the job killed ({job_dir})",
                        job_dir=job_dir,
                        log_lines=_tail(job_dir / "stderr.txt"),
                        timed_out=True,
                    )
        finally:
            finish_watched(job, 0.5)
    wall = time.monotonic() - t0
    servers = [ln for ln in _tail(job_dir / "stderr.txt", 10**6) if SERVER_LINES.match(ln)]
    if servers:
        raise ReferenceRunError(f"{what}: YADE started its TCP servers ({job_dir})", job_dir=job_dir, log_lines=servers)
    if rc != 0:
        raise ReferenceRunError(
            f"{what} failed: exit status {rc} ({job_dir}, stderr.txt)",
            job_dir=job_dir,
            log_lines=_tail(job_dir / "stderr.txt"),
        )
    return StageResult(rc, wall, load_before, os.getloadavg())


def _recipe(params: FemxdemParams) -> dict:
    return {"n_disks": params.n_disks, "seed": params.seed, "cell": params.cell}


def prepare_rve(rve_dir, params: FemxdemParams, timeout: float | None = 600.0, reuse: bool = True):
    """prepareRVE.py in ``rve_dir``; returns (the :class:`~.output.RveRecord`, wall s or None when
    a complete RVE of the same recipe and port was reused)."""
    params = params.checked()
    rve_dir = Path(rve_dir).resolve()
    port = check_originals()
    want = {**_recipe(params), "patch_sha256": port.sha256, "recorder_sha256": recorder_sha256()}
    if reuse and (rve_dir / "0.yade.gz").is_file() and (rve_dir / "rve.txt").is_file():
        try:
            have = json.loads((rve_dir / PARAMS_NAME).read_text())
        except (OSError, ValueError):
            have = {}
        if {k: have.get(k) for k in want} == want:
            rec = read_rve(rve_dir / "rve.txt")
            if rec.n_bodies == params.n_disks:
                return rec, None
    _fresh_dir(rve_dir, "RVE")
    install_port(rve_dir, port)
    (rve_dir / PARAMS_NAME).write_text(json.dumps({**params.job_parameters(), **want}, indent=1) + "\n")
    _echo(f"femxdem: preparing the RVE ({params.n_disks} disks, seed {params.seed}) in {rve_dir}")
    res = run_stage([DEBIAN_PYTHON, "prepareRVE.py"], rve_dir, timeout, "prepareRVE.py")
    if not (rve_dir / "0.yade.gz").is_file():
        raise ReferenceRunError(f"prepareRVE.py wrote no 0.yade.gz ({rve_dir})", job_dir=rve_dir)
    rec = read_rve(rve_dir / "rve.txt")
    if rec.n_bodies != params.n_disks:
        raise ReferenceRunError(
            f"prepareRVE.py: makeCloud placed {rec.n_bodies} disks, not {params.n_disks} ({rve_dir})", job_dir=rve_dir
        )
    return rec, res.wall


def _packages() -> dict:
    try:
        out = subprocess.run(
            ["dpkg-query", "-W", "-f", "${Package} ${Version}\n", *PACKAGES],
            capture_output=True,
            text=True,
            timeout=30,
        ).stdout
    except (OSError, subprocess.TimeoutExpired):
        return {}
    return dict(line.split(" ", 1) for line in out.splitlines() if " " in line)


class _Progress:
    """One line on stderr per step the job records."""

    def __init__(self, path: Path, n_steps: int):
        self.path, self.n_steps, self.seen = path, n_steps, 0

    def __call__(self):
        try:
            lines = self.path.read_text().splitlines()
        except OSError:
            return
        rows = [ln.split() for ln in lines[1:] if ln and not ln.startswith(("#", "END"))]
        for r in rows[self.seen :]:
            if len(r) >= 17:
                _echo(f"femxdem: step {r[0]}/{self.n_steps}: {r[14]} Newton iterations, {float(r[16]):.1f} s")
        self.seen = max(self.seen, len(rows))


def run_biaxial(out_dir, params: FemxdemParams, rve_dir=None, timeout: float | None = None) -> Path:
    """The whole run into ``out_dir``: ``rve/`` (unless ``rve_dir`` names a prepared RVE),
    ``job/`` and ``femxdem.h5`` (written only when every output is complete). Returns the HDF5 path."""
    params = params.checked()
    check_installed()
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    h5 = out_dir / RESULT_NAME
    h5.unlink(missing_ok=True)  # a failed rerun must not leave the previous run's file looking current
    t0 = time.monotonic()
    rve_path = Path(rve_dir).resolve() if rve_dir is not None else out_dir / "rve"
    rve, rve_wall = prepare_rve(rve_path, params, timeout, reuse=True)
    job = out_dir / "job"
    _fresh_dir(job, "job")
    port = install_port(job)
    for name in ("0.yade.gz", "rve.txt"):
        shutil.copyfile(rve_path / name, job / name)
    (job / PARAMS_NAME).write_text(json.dumps(params.job_parameters(), indent=1) + "\n")
    _echo(
        f"femxdem: biaxialSmooth.py, {params.nx} x {params.ny} elements ({params.n_gauss} RVEs), "
        f"{params.steps} steps, {params.workers} workers, in {job}"
    )
    left = None if timeout is None else max(1.0, timeout - (time.monotonic() - t0))
    stage = run_stage(
        [DEBIAN_PYTHON, "biaxialSmooth.py"],
        job,
        left,
        "biaxialSmooth.py",
        on_poll=_Progress(job / "result" / "steps.txt", params.steps),
    )
    outputs = read_outputs(job, params.steps, params.n_gauss, params.field_steps)
    v = outputs.versions
    attrs = {
        "yade_version": f"YADE {v.get('yade_version', '?')}",
        "escript_version": f"escript getVersion() = {v.get('escript_getVersion', '?')}",
        "packages": _packages(),
        "patch_sha256": port.sha256,
        "recorder_sha256": recorder_sha256(),
        "originals": {o.path: {"sha256": o.sha256, "package": o.package} for o in port.originals},
        "command": [DEBIAN_PYTHON, "biaxialSmooth.py"],
        "wall_run": stage.wall,
        "wall_rve_prepare": -1.0 if rve_wall is None else rve_wall,
        "load_before": list(stage.load_before),
        "load_after": list(stage.load_after),
        "cpu_count": os.cpu_count() or 0,
        "rve_reused": rve_wall is None,
    }
    write_h5(h5, outputs, {**params.job_parameters(), "rve_dir": str(rve_path)}, attrs)
    return h5


__all__ = [
    "DEBIAN_PYTHON",
    "ESCRIPT_ROOT",
    "FemxdemParams",
    "check_installed",
    "job_env",
    "listening_ports",
    "prepare_rve",
    "run_biaxial",
    "run_stage",
]
