"""No reference code outlives the ``gransim`` process that started it, whatever ends that process.

SIGTERM, SIGINT and SIGKILL are sent to ``gransim replay``, ``gransim reference run`` and
``gransim validate`` while the code runs (the fake ``liggghts`` of kind ``hang``: a process that
sleeps, with a grandchild in its group that ignores SIGTERM), and to a job of the real codes
(LIGGGHTS, whose MPI singleton starts Open MPI's ``orted`` in a session of its own; LAMMPS on two
ranks under ``mpirun``, whose ranks sit in process groups of their own). Afterwards no process of
the code is alive and the job's private temporary directory is gone: every command runs with
``TMPDIR`` pointing at a directory of the test, which must be left empty.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from fakes import pid_alive

REPO = Path(__file__).resolve().parents[2]
FAULTS = Path(__file__).resolve().parent
REPLAY_DATA = REPO / "tests" / "replay" / "data"
SIGNALS = [signal.SIGTERM, signal.SIGINT, signal.SIGKILL]
#: how long gransim may take to reach the fake code's job: ``validate`` runs the case's native
#: engine and the other codes' jobs first (71 s measured on a 2-core machine at load 7)
START_TIMEOUT_S = 240.0
#: exit status of gransim for each signal (SIGKILL: the kernel's -9)
RC = {signal.SIGTERM: 128 + signal.SIGTERM, signal.SIGINT: 130, signal.SIGKILL: -signal.SIGKILL}


def _commands(tmp_path: Path) -> dict:
    return {
        "replay": ["replay", str(REPLAY_DATA / "in.deck_a"), "-o", str(tmp_path / "replay")],
        "reference": ["reference", "run", "taylor-demo", "--out", str(tmp_path / "ref")],
        "validate": ["validate", "--suite", "quick", "--case", "biaxial-short", "--results", str(tmp_path / "res")],
    }


#: the user's Open MPI setting that restores the singleton's ``orted`` for a serial job (by default a
#: serial job runs as a lone singleton, reference_runs.engines.SERIAL_MPI_ENV: no ``orted``)
WITH_ORTED = {"OMPI_MCA_ess_singleton_isolated": "0"}


def _env(tmp_path: Path, extra: dict | None = None) -> tuple[dict, Path]:
    """The environment of the gransim process: its own TMPDIR, a short SIGTERM-to-SIGKILL grace
    (and ``extra``)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    return {**os.environ, "TMPDIR": str(tmp), "GRANSIM_KILL_GRACE_S": "0.5", **(extra or {})}, tmp


def _wait_for(cond, timeout: float, proc: subprocess.Popen) -> None:
    """Wait until ``cond()``; gransim is killed if it does not come (a failed test leaves nothing
    running)."""
    deadline = time.monotonic() + timeout
    while not cond():
        if proc.poll() is not None:
            raise AssertionError(f"gransim ended (status {proc.returncode}) before the code ran: {proc.stderr.read()}")
        if time.monotonic() > deadline:
            proc.kill()
            proc.wait()
            raise AssertionError(f"the code did not start within {timeout:g} s")
        time.sleep(0.05)


def _signal_and_wait(proc: subprocess.Popen, sig: int) -> str:
    try:
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return err


def _left_in(tmp: Path, timeout: float = 5.0) -> list:
    """What is still in ``tmp`` after up to ``timeout`` s (the watchdog removes it after a SIGKILL)."""
    deadline = time.monotonic() + timeout
    while True:
        left = sorted(p.name for p in tmp.iterdir())
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.05)


@pytest.mark.parametrize("sig", SIGNALS, ids=lambda s: signal.Signals(s).name)
@pytest.mark.parametrize("command", ["replay", "reference", "validate"])
def test_signal_to_gransim_leaves_no_code_and_no_temporary_directory(tmp_path, fake_liggghts, command, sig):
    fake = fake_liggghts("hang")
    env, tmp = _env(tmp_path)
    argv = [sys.executable, "-m", "gransim", *_commands(tmp_path)[command]]
    proc = subprocess.Popen(argv, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for(lambda: fake.pids("grandchild"), START_TIMEOUT_S, proc)
    err = _signal_and_wait(proc, sig)
    assert proc.returncode == RC[sig], err
    if sig != signal.SIGKILL:
        assert "Traceback" not in err and all(len(line) < 300 for line in err.splitlines()), err
    assert fake.wait_gone(5) == [], f"still running after {signal.Signals(sig).name} to gransim {command}"
    assert _left_in(tmp) == []


# ----------------------------------------------------------------------------- the real codes
def _job_processes(tmp: Path) -> list:
    """Live processes whose environment has TMPDIR below ``tmp`` (each job's private TMPDIR: the
    code, mpirun, its ranks, orted), with their command names."""
    want = str(tmp).encode()
    out = []
    for d in Path("/proc").iterdir():
        if not d.name.isdigit() or int(d.name) == os.getpid():
            continue
        try:
            env = (d / "environ").read_bytes().split(b"\0")
            name = (d / "comm").read_text().strip()
        except OSError:
            continue
        if any(e.startswith(b"TMPDIR=" + want + b"/") for e in env) and pid_alive(int(d.name)):
            out.append((int(d.name), name))
    return out


def _still_running(tmp: Path, timeout: float = 5.0) -> list:
    deadline = time.monotonic() + timeout
    while True:
        left = _job_processes(tmp)
        if not left or time.monotonic() > deadline:
            return left
        time.sleep(0.05)


_RUN_FOREVER = """\
import sys
sys.path.insert(0, {faults!r})
from fakes import small_deck, small_lammps_deck
from reference_runs.runner import run_job
make = small_lammps_deck if {engine!r} == "lammps" else small_deck
deck, files, _ = make(tail="run 1000000000\\n", dump_every=None)
run_job({job!r}, deck, files, np={np}, engine={engine!r}, progress=False, timeout=None)
"""


def _kill_a_running_job(tmp_path, engine: str, np: int, want: set, extra: dict | None = None, absent=()) -> list:
    """Start a job that runs forever, wait for the processes named ``want``, SIGKILL its starter:
    nothing of the job may be left. ``absent``: names that must not be among its processes (looked
    for once ``want`` is there and again 1 s later). Returns the processes seen."""
    env, tmp = _env(tmp_path, extra)
    script = _RUN_FOREVER.format(faults=str(FAULTS), engine=engine, job=str(tmp_path / "job"), np=np)
    proc = subprocess.Popen(
        [sys.executable, "-c", script], cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        _wait_for(lambda: want <= {n for _, n in _job_processes(tmp)}, 60, proc)
        seen = _job_processes(tmp)
        if absent:
            time.sleep(1.0)
            seen = sorted(set(seen) | set(_job_processes(tmp)))
            assert not {n for _, n in seen} & set(absent), seen
        _signal_and_wait(proc, signal.SIGKILL)
        assert _still_running(tmp) == [], f"alive after SIGKILL of their starter (of {seen})"
        assert _left_in(tmp) == []
    finally:
        for pid, _ in _job_processes(tmp):
            os.kill(pid, signal.SIGKILL)
    return seen


@pytest.mark.liggghts
def test_sigkill_leaves_neither_liggghts_nor_its_orted(tmp_path):
    """LIGGGHTS' MPI singleton, with Open MPI's own settings (the user's), forks ``orted`` into a
    session of its own: measured alive, reparented to PID 1, after the starter was killed, before
    the watchdog."""
    _kill_a_running_job(tmp_path, "liggghts", 1, {"liggghts", "orted"}, extra=WITH_ORTED)


@pytest.mark.liggghts
def test_a_serial_job_starts_no_orted_and_sigkill_leaves_nothing(tmp_path):
    """By default a serial job is a lone MPI singleton (reference_runs.engines.SERIAL_MPI_ENV): no
    ``orted`` beside LIGGGHTS, and nothing left after a SIGKILL of the starter."""
    seen = _kill_a_running_job(tmp_path, "liggghts", 1, {"liggghts"}, absent=("orted",))
    assert [n for _, n in seen] == ["liggghts"]


def test_sigkill_leaves_no_mpirun_and_no_rank(tmp_path):
    import shutil

    if shutil.which("lmp") is None or shutil.which("mpirun") is None:
        pytest.skip("needs lmp and mpirun (apt-get install lammps)")
    _kill_a_running_job(tmp_path, "lammps", 2, {"mpirun", "lmp"})


@pytest.mark.liggghts
def test_sigterm_to_replay_leaves_neither_liggghts_nor_orted(tmp_path):
    """The reported case: ``gransim replay`` of a long LIGGGHTS deck, SIGTERM while it runs."""
    import shutil

    text = (REPLAY_DATA / "in.deck_a").read_text().replace("run             500", "run 1000000000")
    (tmp_path / "in.long").write_text(text)
    shutil.copy(REPLAY_DATA / "disks_a.data", tmp_path / "disks_a.data")
    env, tmp = _env(tmp_path, WITH_ORTED)
    argv = [sys.executable, "-m", "gransim", "replay", str(tmp_path / "in.long"), "-o", str(tmp_path / "out")]
    proc = subprocess.Popen(argv, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: {"liggghts", "orted"} <= {n for _, n in _job_processes(tmp)}, 60, proc)
        err = _signal_and_wait(proc, signal.SIGTERM)
        assert proc.returncode == 128 + signal.SIGTERM, err
        assert _still_running(tmp) == []
        assert _left_in(tmp) == []
    finally:
        for pid, _ in _job_processes(tmp):
            os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize(
    ("binary", "script"),
    [
        ("liggghts", "from gransim.io import liggghts_version; liggghts_version()"),
        ("yade", "from reference_runs.engines import ENGINES; ENGINES['yade'].version()"),
    ],
)
def test_sigkill_during_a_version_probe_leaves_no_probe(tmp_path, binary, script):
    """The version query of a code (``liggghts -in /dev/null``, ``yade --version``) that does not
    answer dies with the process that asked, SIGKILL included (before: it ran on, up to its
    timeout and beyond; YADE's for 60 s)."""
    bindir = tmp_path / "bin"
    bindir.mkdir()
    pids = tmp_path / "pids.txt"
    fake = bindir / binary
    fake.write_text(f'#!/bin/sh\necho $$ >> "{pids}"\nexec sleep 1000\n')
    fake.chmod(0o755)
    env = {**os.environ, "PATH": f"{bindir}{os.pathsep}{os.environ['PATH']}"}
    proc = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
    try:
        _wait_for(lambda: pids.exists() and pids.read_text().strip(), 30, proc)
        probe = int(pids.read_text().split()[0])
        _signal_and_wait(proc, signal.SIGKILL)
        deadline = time.monotonic() + 5
        while pid_alive(probe) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not pid_alive(probe)
    finally:
        for p in pids.read_text().split() if pids.exists() else []:
            if pid_alive(int(p)):
                os.kill(int(p), signal.SIGKILL)


def test_run_watched_timeout_kills_the_whole_tree(tmp_path):
    """What the report check runs Chromium through: on a timeout every process of the program goes
    (``subprocess.run`` kills only the first: the two background sleeps here would run on)."""
    from reference_runs.runner import run_watched

    pids = tmp_path / "pids.txt"
    cmd = ["sh", "-c", f'sleep 1000 & echo $! >> "{pids}"; setsid sleep 1000 & echo $! >> "{pids}"; wait']
    t0 = time.monotonic()
    with pytest.raises(subprocess.TimeoutExpired):
        run_watched(cmd, capture_output=True, timeout=0.5)
    left = [int(p) for p in pids.read_text().split() if pid_alive(int(p))]
    for p in left:
        os.kill(p, signal.SIGKILL)
    assert len(pids.read_text().split()) == 2 and left == []
    assert time.monotonic() - t0 < 5
