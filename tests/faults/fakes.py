"""Fake ``liggghts`` (and ``lmp``) executables for fault tests, and a small real deck to run through them.

``write_fake(..., engine="lammps")`` writes a fake ``lmp`` instead: the same kinds, with the LAMMPS
banner ``LAMMPS (29 Sep 2021 - Update 2 fake-<kind>)`` (the kinds that run the real binary run the
real ``lmp`` and mark its log's banner the same way); :func:`small_lammps_deck` is the LAMMPS
twin of :func:`small_deck`.

Each fake is a Python script named ``liggghts`` in its own directory (see ``conftest.py`` for the
fixture that puts it on PATH). It appends ``<role> <pid>`` lines to ``pids.txt`` next to itself
(roles: ``fake``, ``grandchild``, ``real``) so that tests can check that no process is left.
Asked for its version (``-in /dev/null``, as :func:`gransim.io.liggghts_version` does) every fake
prints ``LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0 fake-<kind>, ...)``; the kinds that run the real
binary rewrite the banner of the log the same way, so a manifest of a fake run never reads like a
real one.

Kinds
-----
error        writes a log (banner, the deck, ``ERROR: fake failure ...``) and exits 1.
silent       exits 0 writing nothing.
hang         writes the banner and a thermo header, starts a grandchild in its process group that
             ignores SIGTERM (``sh -c "trap '' TERM; exec sleep 1000"``), then sleeps forever.
truncate-log runs the real binary with the same arguments, then cuts the log after the first
             ``FAKE_KEEP_ROWS`` (default 3) thermo rows of the first run; exits 0.
cut-dumps    real run, then keeps only the first frame of every dump file below the job directory.
warning      real run, then inserts ``WARNING: fake warning ...`` after the first thermo header.
slow         sleeps ``FAKE_LIGGGHTS_DELAY`` s (default 2), then runs the real binary (lock tests).
"""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

KINDS = ("error", "silent", "hang", "truncate-log", "cut-dumps", "warning", "slow")
#: kinds that run the real binary underneath
REAL_KINDS = ("truncate-log", "cut-dumps", "warning", "slow")

#: the lines every fake script runs first: ``rec(role, pid)`` appends ``<role> <pid>`` to its pid
#: file, the fake records itself, ``args`` its arguments (a template piece: braces doubled)
_RECORD = r"""def rec(role, pid):
    with open(PIDS, "a") as fh:
        fh.write(f"{{role}} {{pid}}\n")
rec("fake", os.getpid())
args = sys.argv[1:]
"""

_SCRIPT = (
    r"""#!{python}
# fake liggghts, kind {kind!r} (tests/faults/fakes.py)
import os, subprocess, sys, time
from pathlib import Path
KIND, REAL, PIDS, ENGINE = {kind!r}, {real!r}, {pids!r}, {engine!r}
"""
    + _RECORD
    + r"""def opt(name, default=None):
    for k, a in enumerate(args[:-1]):
        if a == name:
            return args[k + 1]
    return default
deck, log = opt("-in"), opt("-log", "log.lammps")
if ENGINE == "lammps":
    BANNER = f"LAMMPS (29 Sep 2021 - Update 2 fake-{{KIND}})"
else:
    BANNER = f"LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0 fake-{{KIND}}, stand-in written by tests/faults/fakes.py)"
if deck == os.devnull:
    print(BANNER)
    sys.exit(0)
def write_log(lines):
    if log != "none":
        Path(log).write_text("\n".join(lines) + "\n")
def deck_lines():
    try:
        return Path(deck).read_text().splitlines()
    except (OSError, TypeError):
        return []
def real_run():
    p = subprocess.Popen([REAL, *args])
    rec("real", p.pid)
    rc = p.wait()
    if log != "none" and Path(log).exists():
        lines = Path(log).read_text().splitlines()
        if lines and lines[0].startswith("LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0,"):
            lines[0] = lines[0].replace("3.8.0,", f"3.8.0 fake-{{KIND}},", 1)
        elif lines and lines[0].startswith("LAMMPS (") and lines[0].endswith(")"):
            lines[0] = lines[0][:-1] + f" fake-{{KIND}})"
        Path(log).write_text("\n".join(lines) + "\n")
    return rc
if KIND == "error":
    write_log([BANNER, *deck_lines(), f"ERROR: fake failure (the fake {{ENGINE}} of kind 'error')"])
    print("ERROR: fake failure", file=sys.stderr)
    sys.exit(1)
if KIND == "silent":
    sys.exit(0)
if KIND == "hang":
    write_log([BANNER, "Setting up run ...", "Step Atoms", "       0       36"])
    g = subprocess.Popen(["sh", "-c", "trap '' TERM; exec sleep 1000"])
    rec("grandchild", g.pid)
    time.sleep(1000)
    sys.exit(0)
if KIND == "slow":
    time.sleep(float(os.environ.get("FAKE_LIGGGHTS_DELAY", "2")))
    sys.exit(real_run())
rc = real_run()
if KIND == "truncate-log":
    keep = int(os.environ.get("FAKE_KEEP_ROWS", "3"))
    lines = Path(log).read_text().splitlines()
    head = next(k for k, ln in enumerate(lines) if ln.split()[:1] == ["Step"])
    Path(log).write_text("\n".join(lines[:head + 1 + keep]) + "\n")
elif KIND == "cut-dumps":
    for p in Path(".").rglob("*"):
        if not p.is_file():
            continue
        try:
            text = p.read_text()
        except (OSError, UnicodeDecodeError):
            continue
        if text.startswith("ITEM: TIMESTEP"):
            second = text.find("ITEM: TIMESTEP", 1)
            if second > 0:
                p.write_text(text[:second])
elif KIND == "warning":
    lines = Path(log).read_text().splitlines()
    head = next(k for k, ln in enumerate(lines) if ln.split()[:1] == ["Step"])
    lines.insert(head + 1, "WARNING: fake warning inserted by the fake liggghts (tests/faults)")
    Path(log).write_text("\n".join(lines) + "\n")
sys.exit(rc)
"""
)


def fakes_on_path(tmp_path_factory, monkeypatch, write, real, real_kinds, name: str, install: str):
    """The generator behind the ``fake_<code>`` fixtures: yields ``make(kind)``, which writes the
    fake ``name`` of that kind (``write(bindir, kind, real)``) into a fresh temporary directory,
    puts it first on PATH and returns it; a kind of ``real_kinds`` skips the test when the real
    binary ``real`` is absent (``install``: how to get it). The runner's SIGTERM-to-SIGKILL grace
    is 0.5 s meanwhile; at teardown whatever a fake recorded and left running is killed."""
    import pytest  # noqa: PLC0415 - only the fixtures need it

    import reference_runs.runner as runner  # noqa: PLC0415 - only the fixtures need it

    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)
    made = []

    def make(kind: str):
        if kind in real_kinds and real is None:
            pytest.skip(f"fake {name} kind {kind!r} needs the real {name} binary ({install})")
        fake = write(tmp_path_factory.mktemp(f"fake-{name}-{kind}"), kind, real)
        monkeypatch.setenv("PATH", f"{fake.bindir}{os.pathsep}{os.environ.get('PATH', '')}")
        made.append(fake)
        return fake

    yield make
    for fake in made:
        fake.kill_leftovers()


def pid_alive(pid: int) -> bool:
    """True when process ``pid`` exists and is not a zombie."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
        return stat[stat.rfind(")") + 2 :].split()[0] not in ("Z", "X")
    except OSError:
        return False


@dataclass(frozen=True)
class FakeLiggghts:
    """A fake binary: ``kind``, its ``path`` and directory, and the pid file it appends to."""

    kind: str
    path: Path
    pid_file: Path

    @property
    def bindir(self) -> Path:
        return self.path.parent

    def pids(self, role: str | None = None) -> list:
        """Pids recorded so far (all roles, or one of ``fake``, ``grandchild``, ``real``)."""
        try:
            rows = [ln.split() for ln in self.pid_file.read_text().splitlines() if ln.strip()]
        except OSError:
            return []
        return [int(p) for r, p in rows if role is None or r == role]

    def alive(self) -> list:
        """Recorded pids still running (zombies excluded)."""
        return [p for p in self.pids() if pid_alive(p)]

    def wait_gone(self, timeout: float = 5.0) -> list:
        """Wait up to ``timeout`` s for every recorded process to end; returns those still alive."""
        deadline = time.monotonic() + timeout
        while True:
            left = self.alive()
            if not left or time.monotonic() > deadline:
                return left
            time.sleep(0.05)

    def kill_leftovers(self) -> None:
        """SIGKILL whatever recorded process is still alive (fixture teardown)."""
        for p in self.alive():
            try:
                os.kill(p, signal.SIGKILL)
            except OSError:
                pass


def write_fake(bindir, kind: str, real: str | None = None, engine: str = "liggghts") -> FakeLiggghts:
    """Write the fake ``liggghts`` (``engine="lammps"``: ``lmp``) of ``kind`` into ``bindir``
    (created); ``real`` is the real binary, needed by :data:`REAL_KINDS`."""
    if kind not in KINDS:
        raise ValueError(f"unknown fake kind {kind!r}; choose one of {KINDS}")
    if engine not in ("liggghts", "lammps"):
        raise ValueError(f"unknown engine {engine!r}")
    if kind in REAL_KINDS and not real:
        raise ValueError(f"fake kind {kind!r} needs the real {engine} binary")
    bindir = Path(bindir)
    bindir.mkdir(parents=True, exist_ok=True)
    pids = bindir / "pids.txt"
    path = bindir / ("lmp" if engine == "lammps" else "liggghts")
    path.write_text(_SCRIPT.format(python=sys.executable, kind=kind, real=real, pids=str(pids), engine=engine))
    path.chmod(0o755)
    return FakeLiggghts(kind, path, pids)


# ----------------------------------------------------------------------------- a small real deck
_SETUP = """\
units si
atom_style sphere
dimension 2
boundary p p p
newton off
communicate single vel yes
atom_modify map array sort 0 0.0
read_data p.data
neighbor 1e-5 bin
neigh_modify delay 0
fix m1 all property/global kn peratomtypepair 1 1e6
fix m2 all property/global kt peratomtypepair 1 0
fix m3 all property/global gamman peratomtypepair 1 0
fix m4 all property/global gammat peratomtypepair 1 0
fix m5 all property/global coefficientFriction peratomtypepair 1 0
pair_style gran model hooke/stiffness tangential no_history
pair_coeff * *
fix 2d all enforce2d
fix i all nve/sphere
timestep 1e-7
thermo_style custom step atoms
thermo 4
"""


def small_deck(tail: str = "run 10\n", dump_every: int | None = 5, local_every: int | None = None):
    """A 36-disk deck (perturbed 6 x 6 lattice at rest, elastic contacts) that LIGGGHTS runs in
    about 0.5 s: ``(deck_text, files, outputs)`` for :func:`reference_runs.runner.run_job`.

    ``tail`` holds the run commands; ``dump_every`` adds ``dump d1 all custom N dump.atoms id x y``
    and ``local_every`` ``dump d2 all local N dump.contacts`` of ``compute pair/gran/local`` (both in
    ``outputs``).
    """
    import numpy as np

    from reference_runs.datafile import write_data_file
    from reference_runs.demo_packings import perturbed_lattice

    p = perturbed_lattice(6, 6, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        write_data_file(Path(tmp) / "p.data", p, velocities=np.zeros((p.n, 2)))
        data = (Path(tmp) / "p.data").read_bytes()
    deck, outputs = _SETUP, []
    if dump_every:
        deck += f"dump d1 all custom {int(dump_every)} dump.atoms id x y\n"
        outputs.append("dump.atoms")
    if local_every:
        deck += (
            "compute pl all pair/gran/local id pos force delta\n"
            f"dump d2 all local {int(local_every)} dump.contacts c_pl[1] c_pl[2]\n"
        )
        outputs.append("dump.contacts")
    return deck + tail, {"p.data": data}, outputs


_LAMMPS_SETUP = """\
units si
atom_style sphere
dimension 2
boundary p p p
newton off
comm_modify mode single vel yes
atom_modify map array sort 0 0.0
read_data p.data
set group all density/disc 2650
neighbor 1e-5 bin
neigh_modify delay 0
pair_style gran/hooke 1e6 0 0 0 0 0
pair_coeff * *
fix 2d all enforce2d
fix i all nve/sphere disc
timestep 1e-7
thermo_style custom step atoms
thermo 4
"""


def small_lammps_deck(tail: str = "run 10\n", dump_every: int | None = 5):
    """The LAMMPS twin of :func:`small_deck` (same 36 disks, ``pair_style gran/hooke``):
    ``(deck_text, files, outputs)`` for ``run_job(..., engine="lammps")``."""
    import numpy as np

    from reference_runs.datafile import write_data_file
    from reference_runs.demo_packings import perturbed_lattice

    p = perturbed_lattice(6, 6, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        write_data_file(Path(tmp) / "p.data", p, velocities=np.zeros((p.n, 2)))
        data = (Path(tmp) / "p.data").read_bytes()
    deck, outputs = _LAMMPS_SETUP, []
    if dump_every:
        deck += f"dump d1 all custom {int(dump_every)} dump.atoms id x y\n"
        outputs.append("dump.atoms")
    return deck + tail, {"p.data": data}, outputs


#: first lines of a YADE job script in a fault test: the YADE process writes its pid to yade.pid
YADE_PID_PREFIX = "import os\nopen('yade.pid', 'w').write(str(os.getpid()))\n"


def assert_yade_gone(job_dir) -> None:
    """The YADE process whose pid ``YADE_PID_PREFIX`` wrote in ``job_dir`` is gone (no zombie),
    and no TCP port of it is listening (``ss -ltnp``, where installed)."""
    import shutil  # noqa: PLC0415 - only the YADE fault tests need it
    import subprocess  # noqa: PLC0415 - only the YADE fault tests need it

    pid = int((Path(job_dir) / "yade.pid").read_text())
    assert not pid_alive(pid)
    if shutil.which("ss"):
        out = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, timeout=30).stdout
        assert f"pid={pid}," not in out


# ----------------------------------------------------------------------------- a fake ``yade``
#: kinds of the fake ``yade`` (:func:`write_fake_yade`)
YADE_KINDS = ("error", "hang", "cut", "drop-particle")
#: kinds that run the real ``yade`` underneath
YADE_REAL_KINDS = ("cut", "drop-particle")

_YADE_SCRIPT = (
    r"""#!{python}
# fake yade, kind {kind!r} (tests/faults/fakes.py)
import os, socket, subprocess, sys, time
from pathlib import Path
KIND, REAL, PIDS, PORT = {kind!r}, {real!r}, {pids!r}, {port!r}
"""
    + _RECORD
    + r"""if args == ["--version"]:
    print(f"Yade version: 2023.02a-fake-{{KIND}}")
    sys.exit(0)
def real_run():
    p = subprocess.Popen([REAL, *args], stdout=subprocess.PIPE, text=True)
    rec("real", p.pid)
    for line in p.stdout:  # the banner marked, so a manifest of a fake run never reads like a real one
        sys.stdout.write(line.replace("Welcome to Yade 2023.02a", f"Welcome to Yade 2023.02a-fake-{{KIND}}", 1))
    return p.wait()
if KIND == "error":
    print(f"Welcome to Yade 2023.02a-fake-{{KIND}}")
    print("Traceback (most recent call last):", file=sys.stderr)
    print('  File "yade_job.py", line 1, in <module>', file=sys.stderr)
    print("RuntimeError: fake failure (the fake yade of kind 'error')", file=sys.stderr)
    sys.exit(1)
if KIND == "hang":
    print(f"Welcome to Yade 2023.02a-fake-{{KIND}}", flush=True)
    server = socket.socket()  # a listening port, as YADE's own servers would open one
    server.bind(("127.0.0.1", 0))
    server.listen()
    Path(PORT).write_text(str(server.getsockname()[1]))
    g = subprocess.Popen(["sh", "-c", "trap '' TERM; exec sleep 1000"])
    rec("grandchild", g.pid)
    time.sleep(1000)
    sys.exit(0)
rc = real_run()
for out in Path(".").glob("*.out"):
    lines = out.read_text().splitlines(keepends=True)
    if KIND == "cut":
        text = "".join(lines)
        out.write_text(text[: len(text) // 2])
    elif KIND == "drop-particle":
        rows = [k for k, ln in enumerate(lines) if ln.startswith("P ")]
        if len(rows) > 1:
            del lines[rows[1]]  # the second particle of the first frame
            out.write_text("".join(lines))
sys.exit(rc)
"""
)


@dataclass(frozen=True)
class FakeYade(FakeLiggghts):
    """A fake ``yade``: as :class:`FakeLiggghts`, and ``port_file``, where the ``hang`` kind writes
    the TCP port it listens on."""

    port_file: Path = Path()

    def port(self) -> int | None:
        """The port the ``hang`` kind opened (None before it did)."""
        try:
            return int(self.port_file.read_text())
        except (OSError, ValueError):
            return None


def write_fake_yade(bindir, kind: str, real: str | None = None) -> FakeYade:
    """Write the fake ``yade`` of ``kind`` into ``bindir`` (created); ``real`` is the real binary,
    needed by :data:`YADE_REAL_KINDS`.

    Kinds: ``error`` (the banner, a Python traceback on stderr, exit 1: a script that raised);
    ``hang`` (the banner, a TCP port listening on 127.0.0.1, a grandchild in its process group that
    ignores SIGTERM, then sleeps forever); ``cut`` (the real run, then every ``*.out`` output of
    the job cut to half its length: an output cut short); ``drop-particle`` (the real run, then the
    second ``P`` row, a particle of the first frame, deleted from every ``*.out`` that has them).
    Asked for ``--version`` it prints ``Yade version: 2023.02a-fake-<kind>``; the real runs' banner
    reads ``Welcome to Yade 2023.02a-fake-<kind>``."""
    if kind not in YADE_KINDS:
        raise ValueError(f"unknown fake yade kind {kind!r}; choose one of {YADE_KINDS}")
    if kind in YADE_REAL_KINDS and not real:
        raise ValueError(f"fake yade kind {kind!r} needs the real yade binary")
    bindir = Path(bindir)
    bindir.mkdir(parents=True, exist_ok=True)
    pids, port = bindir / "pids.txt", bindir / "port.txt"
    path = bindir / "yade"
    path.write_text(_YADE_SCRIPT.format(python=sys.executable, kind=kind, real=real, pids=str(pids), port=str(port)))
    path.chmod(0o755)
    return FakeYade(kind, path, pids, port)
