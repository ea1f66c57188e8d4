"""Run one LIGGGHTS or LAMMPS job in its own directory, with a manifest that says whether it completed.

The code is chosen by ``run_job(..., engine="liggghts"|"lammps")`` (:mod:`reference_runs.engines`);
everything below holds for both. A job directory holds the deck (``in.liggghts`` or ``in.lammps``,
:attr:`~reference_runs.engines.Engine.deck_name`), its input files (data files...), the log
(``log.lammps``), the outputs the deck writes, ``stdout.txt``/``stderr.txt``, the lock file
``.lock`` and, written atomically and last, ``manifest.json``. Only a manifest with ``"status":
"ok"`` marks the outputs as complete; a failed job leaves ``"status": "failed"`` with the reason,
and a job that is running or was killed has no manifest (it is removed before the run starts) or a
``failed`` one saying it was interrupted.

A job is identified by the SHA-256 of its deck and input files (``input_sha256``; the deck
alone is ``deck_sha256``) and by its command-line variables (``run_job(..., variables={NAME:
VALUE})``, the codes' ``-var NAME VALUE``; the manifest's ``variables``): the same deck run with
other variables is another job, never reused for this one. A job is accepted (fresh or reused)
only when its evidence is complete (:mod:`reference_runs.expect`, the deck read with the job's
variables: a ``-var`` value wins over the deck's ``variable NAME index DEFAULT``): the log holds
every ``run`` of the deck, each ended by its ``Loop time`` line at the step the deck asks for,
and every ``dump`` file among the outputs holds the frames the deck asks for; the manifest
records the counts (``evidence``) and the SHA-256 of the log (``log_sha256``) and of every
output (``outputs``). :func:`run_job` reuses a directory that holds an ``ok`` manifest with the
same input hash and variables only after re-hashing the log and outputs
and re-checking the evidence (:func:`verify_job`); a job that fails this is rerun (with a
``WARNING`` line) when the code is available, and refused otherwise. The manifest records the
code (``engine``, ``engine_version`` from the job's own log banner, ``engine_binary``,
``engine_package``; LIGGGHTS jobs also keep the older ``liggghts_*`` keys): a job run by one code
is never reused as the other's (it is rerun with a ``WARNING`` when the requested code is there,
refused otherwise). Manifests without ``engine`` were written by LIGGGHTS.

One writer at a time: :func:`run_job` holds ``flock`` on ``job_dir/.lock``
(:class:`reference_runs.locks.DirectoryLock`); a second writer of the same job waits (one line
``waiting for job ...``), then finds the finished job and reuses it.

No orphans (:func:`start_watched`): the code (or ``mpirun``) runs in a new session, its
environment marked ``GRANSIM_JOB=<unique>`` (:data:`JOB_MARKER`), which every process it starts
inherits (``mpirun``'s ranks in groups of their own, the ``orted`` a serial run's MPI singleton
forks into a session of its own). The job's processes (its group, its session and the marked
processes) are killed (SIGTERM, then SIGKILL after :data:`KILL_GRACE_S`) on timeout, on any
exception, and when it exits leaving members behind; its private ``TMPDIR`` is removed. Live jobs
are registered; :func:`terminate_children` kills them all (also at interpreter exit), and
:func:`kill_children_on_signals` turns SIGTERM, SIGINT and SIGHUP into "kill the children, then
raise". A watchdog process per job, started before the code, covers what no handler can: when
this process dies with the job running (SIGKILL, a crash), it kills every marked process and
removes the private ``TMPDIR``.
"""

from __future__ import annotations

import atexit
import contextlib
import datetime as _dt
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from gransim.errors import InputError
from gransim.io import atomic_path
from gransim.progress import progress as _progress

from .engines import ENGINES, LIGGGHTS, check_variables, get_engine, variables_text
from .errors import DirectoryBusyError, ReferenceRunError
from .expect import check_evidence, expected_evidence
from .locks import DirectoryLock
from .parsers import LogFile, parse_log

#: deck file name of LIGGGHTS jobs (LAMMPS jobs: ``in.lammps``; see :attr:`Engine.deck_name`)
DECK_NAME = LIGGGHTS.deck_name
DECK_NAMES = tuple(e.deck_name for e in ENGINES.values())
LOG_NAME = "log.lammps"
MANIFEST_NAME = "manifest.json"
INSTALL_HINT = LIGGGHTS.install_hint
FORCE_HINT = (
    "`--force` (`gransim reference run|taylor --force`, `run_job(force=True)`) discards the "
    "stored outputs and runs the code again; it needs the binary too"
)
#: how many lines of log context to show in an error
CONTEXT_LINES = 12


def _echo(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


# ----------------------------------------------------------------------------- children
#: environment variable that marks every process of a job: the code, ``mpirun`` and its ranks (in
#: process groups of their own), Open MPI's ``orted`` (forked by a serial run's MPI singleton into a
#: session of its own). Its value is unique per job, so each process is found in
#: ``/proc/<pid>/environ`` wherever it went.
JOB_MARKER = "GRANSIM_JOB"


def _grace_from_env() -> float:
    """:data:`KILL_GRACE_S` from ``GRANSIM_KILL_GRACE_S`` (seconds >= 0), else 5."""
    text = os.environ.get("GRANSIM_KILL_GRACE_S", "").strip()
    if not text:
        return 5.0
    try:
        v = float(text)
    except ValueError:
        v = -1.0
    if not 0.0 <= v < float("inf"):
        _echo(f"WARNING: GRANSIM_KILL_GRACE_S={text!r} is not a number of seconds >= 0; using 5")
        return 5.0
    return v


#: seconds between SIGTERM and SIGKILL when a job's processes are killed (``GRANSIM_KILL_GRACE_S``)
KILL_GRACE_S = _grace_from_env()

#: the watchdog of one job, run as ``python -I -S -c _WATCHDOG MARKER DIR``: it reads its stdin, a
#: pipe whose only writer is the process that started the job. ``done`` then end of file: the job
#: ended normally. End of file without ``done``: that process died (SIGKILL, a crash) with the job
#: running, so every process marked ``GRANSIM_JOB=MARKER`` is killed (again and again until none is
#: seen for 0.25 s: a process forked but not yet executed carries the mark only after its exec) and
#: DIR, the job's private temporary directory, is removed.
_WATCHDOG = r"""
import os, shutil, signal, sys, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGHUP, signal.SIG_IGN)
want = ("GRANSIM_JOB=" + sys.argv[1]).encode()
said = b""
while True:
    try:
        chunk = os.read(0, 64)
    except OSError:
        break
    if not chunk:
        break
    said += chunk
if said.endswith(b"done"):
    sys.exit(0)
def marked():
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit() and int(name) != os.getpid():
            try:
                with open("/proc/" + name + "/environ", "rb") as fh:
                    if want in fh.read().split(b"\0"):
                        out.append(int(name))
            except OSError:
                pass
    return out
quiet, deadline = 0, time.monotonic() + 60
while quiet < 5 and time.monotonic() < deadline:
    pids = marked()
    for pid in pids:
        try:
            os.kill(pid, signal.SIGKILL)
        except OSError:
            pass
    quiet = 0 if pids else quiet + 1
    time.sleep(0.05)
if sys.argv[2]:
    shutil.rmtree(sys.argv[2], ignore_errors=True)
"""


class _Job:
    """A started (or starting) child of this process: its mark, its Popen (None until started),
    its watchdog and the private directory the watchdog removes."""

    def __init__(self, tmp: Path | None = None, prefix: str = "gransim-job-"):
        self.marker = os.urandom(6).hex()  # short: Open MPI's socket paths below TMPDIR must fit 107 bytes
        self.proc: subprocess.Popen | None = None
        self.tmp = tmp if tmp is None else Path(tmp) / f"{prefix}{self.marker}"
        self.watchdog: subprocess.Popen | None = None

    @property
    def pgid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def env(self, env: dict) -> dict:
        return {**env, JOB_MARKER: self.marker}


_LIVE: dict = {}  # marker -> _Job, from before its process is started until it is cleaned up
_LIVE_LOCK = threading.Lock()
_STOPPING = threading.Event()  # set by the signal handler: a job started from now on is killed at once


class Terminated(SystemExit):
    """Raised by :func:`kill_children_on_signals` on SIGTERM or SIGHUP, after the children were
    killed. A :class:`SystemExit` with code 128 + signal number (what a shell reports for a
    process killed by that signal); ``signum`` is the signal."""

    def __init__(self, signum: int):
        super().__init__(128 + int(signum))
        self.signum = int(signum)

    def __str__(self) -> str:
        return f"terminated by {signal.Signals(self.signum).name}"


def _job_pids(pgid: int | None, marker: str | None) -> list:
    """Live (non-zombie) processes of a job: those of process group or session ``pgid`` (the code
    or ``mpirun`` leads a session of its own) and those whose environment holds
    ``GRANSIM_JOB=marker``. Without ``/proc``: ``[pgid]`` while the group exists."""
    if not Path("/proc").is_dir():
        try:
            os.killpg(pgid, 0)
            return [pgid]
        except (ProcessLookupError, PermissionError, TypeError):
            return []
    want = f"{JOB_MARKER}={marker}".encode() if marker else None
    me, group = os.getpid(), str(pgid)
    out = []
    for d in os.scandir("/proc"):
        if not d.name.isdigit() or int(d.name) == me:
            continue
        try:
            with open(f"/proc/{d.name}/stat") as fh:
                stat = fh.read()
        except OSError:
            continue
        fields = stat[stat.rfind(")") + 2 :].split()  # state ppid pgrp session ...
        if len(fields) < 4 or fields[0] in ("Z", "X"):
            continue
        if pgid is not None and group in (fields[2], fields[3]):
            out.append(int(d.name))
        elif want is not None:
            try:
                with open(f"/proc/{d.name}/environ", "rb") as fh:
                    if want in fh.read().split(b"\0"):
                        out.append(int(d.name))
            except OSError:
                continue
    return out


def _group_alive(pgid: int, marker: str | None = None) -> bool:
    """True while any non-zombie process of group or session ``pgid`` (or marked ``marker``) exists."""
    return bool(_job_pids(pgid, marker))


def _signal_job(job: _Job, sig: int) -> list:
    pids = _job_pids(job.pgid, job.marker)
    if job.pgid is not None:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.killpg(job.pgid, sig)
    for pid in pids:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(pid, sig)
    return pids


def _kill_jobs(jobs, grace: float | None = None) -> None:
    """SIGTERM every process of ``jobs`` (their groups, sessions and marked processes: ``mpirun``'s
    ranks, ``orted``), wait up to ``grace`` s for all of them (reaping the leaders), then SIGKILL
    whatever is left, until nothing is left."""
    grace = KILL_GRACE_S if grace is None else grace
    jobs = list(jobs)
    for job in jobs:
        _signal_job(job, signal.SIGTERM)
    deadline = time.monotonic() + grace
    while True:
        for job in jobs:
            if job.proc is not None:
                job.proc.poll()
        left = [j for j in jobs if _job_pids(j.pgid, j.marker)]
        if not left or time.monotonic() > deadline:
            break
        time.sleep(0.05)
    for _ in range(100):  # a member may fork while it is being killed
        left = [j for j in left if _signal_job(j, signal.SIGKILL)]
        for job in jobs:
            if job.proc is not None:
                with contextlib.suppress(subprocess.TimeoutExpired):
                    job.proc.wait(timeout=0.05 if left else 5)
        if not left:
            break
        time.sleep(0.02)


def _start_watchdog(job: _Job) -> None:
    exe = sys.executable
    if not exe or not Path("/proc").is_dir():
        return
    job.watchdog = subprocess.Popen(
        [exe, "-I", "-S", "-c", _WATCHDOG, job.marker, str(job.tmp or "")],
        stdin=subprocess.PIPE,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        cwd="/",
        start_new_session=True,  # the terminal's Ctrl-C or a kill of our group does not reach it
    )


def _release_watchdog(job: _Job) -> None:
    w = job.watchdog
    if w is None:
        return
    with contextlib.suppress(OSError, ValueError):
        w.stdin.write(b"done")
    with contextlib.suppress(OSError, ValueError):
        w.stdin.close()
    try:
        w.wait(timeout=5)
    except subprocess.TimeoutExpired:
        w.kill()
        w.wait()


def start_watched(cmd, *, env: dict | None = None, private_tmp: bool = False, **popen_kw) -> _Job:
    """Start ``cmd`` so that no process of it can outlive this process.

    The program runs in a session of its own (``start_new_session``), its environment marked
    ``GRANSIM_JOB=<unique>`` (inherited by everything it starts). Before it starts, a watchdog
    process is started that kills every marked process (and removes the private directory) when
    this process dies before :func:`finish_watched` (SIGKILL, a crash). The job is registered, so
    :func:`terminate_children` (signals, exit) kills it. ``private_tmp``: the program's
    ``TMPDIR`` (and Open MPI's ``orte_tmpdir_base``) is a new directory
    ``$TMPDIR/gransim-job-<mark>`` (``job.tmp``), removed at the end. Debian's codes are Open MPI
    programs: even a serial run starts an MPI singleton that creates a session directory
    ``$TMPDIR/ompi.<host>.<uid>``, and two jobs starting at the same moment (``--jobs 2``) raced
    on creating a shared one ("A call to mkdir was unable to create the desired directory ...
    File exists", the job exits 1; seen in a fresh ``make run``).
    ``popen_kw`` go to :class:`subprocess.Popen`. Returns the job; its ``proc`` is the Popen.
    End it with :func:`finish_watched` in a ``finally``.
    """
    job = _Job((_OUTER_TMP or tempfile.gettempdir()) if private_tmp else None)
    with _LIVE_LOCK:
        _LIVE[job.marker] = job  # from here on a signal kills whatever carries the mark
    try:
        _start_watchdog(job)  # first: whatever happens from here on, it cleans up
        env = dict(os.environ if env is None else env)
        if job.tmp is not None:
            job.tmp.mkdir(mode=0o700)
            env["TMPDIR"] = str(job.tmp)
            env["OMPI_MCA_orte_tmpdir_base"] = str(job.tmp)
        job.proc = subprocess.Popen(cmd, env=job.env(env), start_new_session=True, **popen_kw)
        if _STOPPING.is_set():  # a signal arrived while it started (this thread is not the main one)
            _kill_jobs([job])
    except BaseException:
        finish_watched(job)
        raise
    return job


def finish_watched(job: _Job, grace: float | None = None) -> None:
    """End a job of :func:`start_watched`: kill whatever of it is left (with ``grace``), remove its
    private directory, release its watchdog, unregister it."""
    try:
        if job.proc is not None and _job_pids(job.pgid, job.marker):
            _kill_jobs([job], grace)
        if job.tmp is not None:
            shutil.rmtree(job.tmp, ignore_errors=True)
    finally:
        _release_watchdog(job)
        with _LIVE_LOCK:
            _LIVE.pop(job.marker, None)


_OUTER_TMP: str | None = None  # the temporary directory outside :func:`private_tempdir`


@contextlib.contextmanager
def private_tempdir(prefix: str = "gransim-"):
    """Within the block, Python's temporary files and directories (:mod:`tempfile`: decks written
    before a job, scratch copies) go to a new directory ``$TMPDIR/<prefix><mark>``, removed at the
    end and, by a watchdog process, when this process dies inside the block (SIGKILL) and cannot
    remove them itself. Yields the directory. Jobs' private ``TMPDIR`` stay beside it (not below:
    Open MPI's socket paths must stay short)."""
    global _OUTER_TMP
    job = _Job(tempfile.gettempdir(), prefix=prefix)
    _start_watchdog(job)
    old, outer = tempfile.tempdir, _OUTER_TMP
    try:
        job.tmp.mkdir(mode=0o700)
        _OUTER_TMP, tempfile.tempdir = tempfile.gettempdir(), str(job.tmp)
        yield job.tmp
    finally:
        tempfile.tempdir, _OUTER_TMP = old, outer
        shutil.rmtree(job.tmp, ignore_errors=True)
        _release_watchdog(job)


def run_watched(cmd, timeout: float | None = None, **kw) -> subprocess.CompletedProcess:
    """:func:`subprocess.run` (``capture_output``, ``text``...) through :func:`start_watched`: on a
    timeout every process of the program is killed (not just the first), and none outlives this
    process. Raises :class:`subprocess.TimeoutExpired` on a timeout."""
    capture = kw.pop("capture_output", False)
    if capture:
        kw["stdout"] = kw["stderr"] = subprocess.PIPE
    kw.setdefault("stdin", subprocess.DEVNULL)
    job = start_watched(cmd, **kw)
    try:
        try:
            out, err = job.proc.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            _kill_jobs([job], 0.5)
            job.proc.communicate()
            raise
        return subprocess.CompletedProcess(job.proc.args, job.proc.returncode, out, err)
    finally:
        finish_watched(job, 0.5)


def live_children() -> list:
    """Process group ids of the LIGGGHTS and LAMMPS jobs this process is running."""
    with _LIVE_LOCK:
        return [j.pgid for j in _LIVE.values() if j.pgid is not None]


def terminate_children(grace: float | None = None) -> int:
    """Kill every process of every live job of this process (SIGTERM, then SIGKILL after ``grace``
    s, default :data:`KILL_GRACE_S`), also one still starting. Returns how many jobs were
    signalled. Safe to call from a signal handler or at exit; also registered with :mod:`atexit`."""
    with _LIVE_LOCK:
        jobs = list(_LIVE.values())
    if jobs:
        _kill_jobs(jobs, grace)
    return len(jobs)


atexit.register(terminate_children)


@contextlib.contextmanager
def kill_children_on_signals(signals=(signal.SIGTERM, signal.SIGINT, signal.SIGHUP)):
    """Within the block, SIGTERM, SIGINT and SIGHUP kill the live LIGGGHTS and LAMMPS jobs
    (:func:`terminate_children`) and then raise: :class:`KeyboardInterrupt` for SIGINT,
    :class:`Terminated` (a ``SystemExit(128 + signum)``) for the others. A job another thread
    starts after the signal is killed at once. The previous handlers are restored on exit. Off the
    main thread (where Python cannot install handlers) it does nothing.

    Usage::

        with kill_children_on_signals():
            run_job(...)
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        _STOPPING.set()
        terminate_children()
        if signum == signal.SIGINT:
            raise KeyboardInterrupt
        raise Terminated(signum)

    old = {}
    try:
        for s in signals:
            old[s] = signal.signal(s, handler)
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        _STOPPING.clear()


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True)
class JobResult:
    """Outcome of :func:`run_job`.

    Attributes
    ----------
    job_dir : the job directory.
    manifest : the manifest written (or found) as a dict.
    log : the parsed log (:class:`~reference_runs.parsers.LogFile`).
    skipped : True when the job was not run because complete, verified outputs already existed.
    warnings : the WARNING lines of the log (allowed ones; others fail the job).
    """

    job_dir: Path
    manifest: dict
    log: LogFile
    skipped: bool = False
    warnings: tuple = field(default=())

    @property
    def log_path(self) -> Path:
        return self.job_dir / LOG_NAME

    def path(self, name: str) -> Path:
        """Path of an output or input file of the job."""
        return self.job_dir / name


def _sha256(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def find_liggghts() -> str:
    """Absolute path of the ``liggghts`` binary; :class:`ReferenceRunError` with how to install
    (``get_engine("liggghts").find()``)."""
    return LIGGGHTS.find()


def find_engine(engine: str = "liggghts") -> str:
    """Absolute path of the binary of ``engine``; :class:`ReferenceRunError` with its install hint,
    :class:`~gransim.errors.InputError` for an unknown engine name."""
    return get_engine(engine).find()


def manifest_engine(manifest: dict | None) -> str:
    """The code that ran a job (``engine`` of its manifest; older manifests: ``liggghts``)."""
    return str((manifest or {}).get("engine") or "liggghts")


def manifest_variables(manifest: dict | None) -> dict:
    """The command-line variables a job was run with: ``variables`` of its manifest; a manifest
    without that key: the ``-var NAME VALUE`` triples of its ``command`` (none in older jobs)."""
    m = manifest or {}
    if "variables" in m:
        return {str(k): str(v) for k, v in dict(m["variables"] or {}).items()}
    cmd = [str(c) for c in m.get("command") or ()]
    return {cmd[k + 1]: cmd[k + 2] for k in range(len(cmd) - 2) if cmd[k] == "-var"}


def read_manifest(job_dir) -> dict | None:
    """The manifest of a job directory, or None (absent or unreadable)."""
    p = Path(job_dir) / MANIFEST_NAME
    try:
        m = json.loads(p.read_text())
    except (OSError, ValueError):
        return None
    return m if isinstance(m, dict) else None


# ----------------------------------------------------------------------------- verification
def _only(job_dir: Path, pattern: str) -> str | None:
    found = sorted(p.name for p in job_dir.glob(pattern) if p.is_file() and not p.name.endswith(".tmp"))
    return found[0] if len(found) == 1 else None


def _verify(
    job_dir: Path,
    manifest: dict | None,
    deck_text: str | None,
    log_name: str,
    outputs,
    require_hashes: bool,
    variables: dict,
) -> tuple[dict, list]:
    """(evidence, problems) of a job directory: hashes in the manifest, then the deck's evidence
    (the deck read with the job's command-line ``variables``)."""
    problems: list = []
    outputs = list(dict.fromkeys(outputs))
    if manifest is not None:
        if manifest.get("status") != "ok":
            problems.append(
                f"manifest status is {manifest.get('status')!r}"
                + (f" ({manifest['error']})" if manifest.get("error") else "")
            )
        hashes = dict(manifest.get("outputs") or {})
        want_log = manifest.get("log_sha256")
        log_path = job_dir / log_name
        if want_log is None:
            if require_hashes:
                problems.append(
                    f"the manifest has no log_sha256 (written by an older runner): {log_name} "
                    "cannot be checked against it"
                )
        elif not log_path.exists():
            pass  # reported by the evidence check
        elif _sha256_file(log_path) != want_log:
            problems.append(f"{log_name} changed since the job ran (SHA-256 differs from the manifest)")
        for name in outputs:
            p = job_dir / name
            if name not in hashes:
                if require_hashes:
                    problems.append(f"output {name} is not recorded in the manifest")
                if not p.exists():
                    problems.append(f"output {name} is missing")
            elif not p.exists():
                problems.append(f"output {name} is missing")
            elif _sha256_file(p) != hashes[name]:
                problems.append(f"output {name} changed since the job ran (SHA-256 differs from the manifest)")
    elif require_hashes:
        problems.append(f"no {MANIFEST_NAME}")
    if deck_text is None:
        problems.append(
            f"no deck ({' or '.join(DECK_NAMES)} or a single in.* file) in {job_dir} to derive "
            "the expected runs and dump frames from"
        )
        return {"problems": list(problems)}, problems
    expect = expected_evidence(deck_text, variables)
    log_path = job_dir / log_name
    log = parse_log(log_path) if log_path.exists() else None
    ev, evp = check_evidence(expect, log, log_name, job_dir, outputs)
    problems += evp
    if manifest is None:
        problems += [f"output {f} is missing" for f in outputs if not (job_dir / f).exists()]
    ev["problems"] = list(problems)
    return ev, problems


def job_evidence(
    job_dir,
    deck=None,
    log=None,
    outputs=None,
    require_hashes: bool = False,
    engine: str | None = None,
    variables=None,
) -> dict:
    """The evidence record of a job directory (what :func:`verify_job` checks), with its problems.

    Same parameters as :func:`verify_job`. Returns a JSON-able dict: ``runs_expected``,
    ``runs_found``, ``runs_complete``, ``last_steps_expected``, ``last_steps_got``, ``dumps``
    ({file: {``frames_expected``, ``frames_got``, ``every``, ``style``}}), ``unresolved`` (what
    the deck reader could not follow), ``problems`` (list of str, empty when the job is sound),
    ``variables`` (the command-line variables the deck was read with), and ``deck``, ``log``,
    ``outputs`` (the names used).
    """
    job_dir = Path(job_dir)
    want_vars = None if variables is None else check_variables(variables)
    m = read_manifest(job_dir)
    # the deck is read with the variables the job was run with (its manifest), else the caller's
    run_vars = manifest_variables(m) if m is not None else dict(want_vars or {})
    deck_name = (
        deck
        or (m or {}).get("deck")
        or next((d for d in DECK_NAMES if (job_dir / d).exists()), None)
        or _only(job_dir, "in.*")
    )
    log_name = log or (LOG_NAME if (job_dir / LOG_NAME).exists() else _only(job_dir, "log.*") or LOG_NAME)
    deck_text, pre = None, []
    if deck_name and (job_dir / deck_name).exists():
        deck_text = (job_dir / deck_name).read_text(errors="replace")
        want = (m or {}).get("deck_sha256")
        if want and _sha256(deck_text.encode()) != want:
            pre.append(f"deck {deck_name} changed since the job ran (SHA-256 differs from the manifest)")
    if outputs is None:
        if m is not None:
            outputs = list(m.get("outputs") or {})
        else:  # a stored job without manifest: every dump file of the deck
            outputs = list(expected_evidence(deck_text, run_vars).dumps) if deck_text is not None else []
    if engine is not None and m is not None and manifest_engine(m) != get_engine(engine).name:
        pre.append(f"the job was run by {manifest_engine(m)}, not {get_engine(engine).name}")
    if want_vars is not None and run_vars != want_vars:
        pre.append(f"the job was run with {variables_text(run_vars)}, not {variables_text(want_vars)}")
    ev, problems = _verify(job_dir, m, deck_text, log_name, outputs, require_hashes, run_vars)
    if engine is not None and m is None and (job_dir / LOG_NAME).exists():
        who = parse_log(job_dir / log_name).engine if (job_dir / log_name).exists() else None
        if who is not None and who != get_engine(engine).name:
            pre.append(f"{log_name} was written by {who}, not {get_engine(engine).name}")
    ev["problems"] = pre + problems
    ev.update(deck=deck_name, log=log_name, outputs=list(outputs), variables=run_vars)
    return ev


def verify_job(
    job_dir,
    deck=None,
    log=None,
    outputs=None,
    require_hashes: bool = False,
    engine: str | None = None,
    variables=None,
) -> list:
    """Problems of a finished job directory (empty list: the job is complete and unchanged).

    Checks, when a ``manifest.json`` is present: status ``ok``, the SHA-256 of the deck, of the
    log (``log_sha256``) and of every output against the manifest; always: the log holds every
    ``run`` of the deck, complete (``Loop time`` line) and ending at the expected step, and every
    ``dump`` file of the deck among the outputs holds the expected frames
    (:mod:`reference_runs.expect`).

    Parameters
    ----------
    job_dir : the job directory (a :func:`run_job` directory, or a stored reference such as
        ``reference_runs/stored/biaxial-short`` without manifest).
    deck : deck file name in ``job_dir`` (default: the manifest's, else ``in.liggghts`` or
        ``in.lammps``, else the only ``in.*`` file).
    log : log file name (default ``log.lammps``, else the only ``log.*`` file).
    outputs : output names to check (default: those of the manifest; without a manifest the
        deck's dump files, each of which must exist).
    require_hashes : also report a missing manifest, a manifest without ``log_sha256`` and
        outputs the manifest does not hash (what :func:`run_job` requires for reuse).
    engine : when given (``liggghts``, ``lammps``), also report a job run by the other code
        (manifest ``engine``; without a manifest, the log's banner).
    variables : when given ({NAME: VALUE}, ``{}`` for none), also report a job run with other
        command-line variables (``the job was run with -var n 12, not -var n 10``). The deck's
        runs and dump frames are derived with the variables the job was run with (its
        manifest's), and without a manifest with these.

    Returns
    -------
    list of str, one message per problem (e.g. ``incomplete: log.lammps holds 2 of 3 runs``,
    ``dump.atoms: expected 7 frames, got 1``, ``log.lammps changed since the job ran ...``).
    """
    return job_evidence(job_dir, deck, log, outputs, require_hashes, engine, variables)["problems"]


def is_complete(job_dir, input_sha256: str | None = None, engine: str | None = None, variables=None) -> bool:
    """True when ``job_dir`` has an ``ok`` manifest (with this input hash, run by ``engine`` and
    with these command-line ``variables`` when given; ``{}``: none) whose log and outputs are
    unchanged and complete (:func:`verify_job` with ``require_hashes=True`` finds nothing)."""
    m = read_manifest(job_dir)
    if not m or m.get("status") != "ok":
        return False
    if input_sha256 is not None and m.get("input_sha256") != input_sha256:
        return False
    return not verify_job(job_dir, require_hashes=True, engine=engine, variables=variables)


def _record_interrupted(job, job_dir: Path, manifest: dict, t0: float, exc: BaseException, killed: str) -> None:
    """A job interrupted by ``exc`` (a signal, an error of the caller): kill its processes and
    write its manifest as failed, saying what interrupted it and ``killed`` (what was killed)."""
    _kill_jobs([job])
    manifest.update(
        status="failed",
        end=_now(),
        elapsed_s=round(time.monotonic() - t0, 3),
        returncode=job.proc.returncode,
        error=f"interrupted ({type(exc).__name__}{': ' + str(exc) if str(exc) else ''}); {killed}",
    )
    with contextlib.suppress(Exception):
        _write_manifest(job_dir, manifest)


def _write_manifest(job_dir: Path, manifest: dict) -> None:
    with atomic_path(job_dir / MANIFEST_NAME, suffix=".json.tmp") as tmp:
        Path(tmp).write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def _context(lines: list, linenos, before: int = 3, after: int = 2) -> list:
    keep = set()
    for n in linenos:
        keep.update(range(max(1, n - before), min(len(lines), n + after) + 1))
    return [f"{n}: {lines[n - 1]}" for n in sorted(keep)]


class _LogTail:
    """Follows log.lammps while the job runs; counts finished runs and the last thermo step."""

    _step = re.compile(r"^\s*(\d+)\s")

    def __init__(self, path: Path):
        self.path, self.pos, self.buf = path, 0, ""
        self.runs_done, self.last_step = 0, None

    def poll(self) -> None:
        try:
            with open(self.path, errors="replace") as fh:
                fh.seek(self.pos)
                chunk = fh.read()
                self.pos = fh.tell()
        except OSError:
            return
        self.buf += chunk
        *full, self.buf = self.buf.split("\n")
        for line in full:
            if line.startswith("Loop time of"):
                self.runs_done += 1
            else:
                m = self._step.match(line)
                if m:
                    self.last_step = int(m.group(1))


def _job_inputs(deck, files):
    if isinstance(deck, Path) or (isinstance(deck, str) and "\n" not in deck and Path(deck).is_file()):
        deck_text = Path(deck).read_text()
    else:
        deck_text = str(deck)
    blobs = {}
    for name, src in (files or {}).items():
        if isinstance(src, bytes):
            blobs[name] = src
        elif isinstance(src, Path) or (isinstance(src, str) and "\n" not in src and Path(src).is_file()):
            blobs[name] = Path(src).read_bytes()
        else:
            blobs[name] = str(src).encode()
    h = hashlib.sha256(deck_text.encode())
    for name in sorted(blobs):
        h.update(b"\0" + name.encode() + b"\0" + _sha256(blobs[name]).encode())
    return deck_text, blobs, _sha256(deck_text.encode()), h.hexdigest()


def run_job(
    job_dir,
    deck,
    files: dict | None = None,
    np: int = 1,
    timeout: float | None = 600.0,
    progress: bool = True,
    outputs=(),
    expected_runs: int | None = None,
    allowed_warnings=(),
    force: bool = False,
    desc: str | None = None,
    engine: str = "liggghts",
    variables=None,
) -> JobResult:
    """Run a LIGGGHTS or LAMMPS deck in ``job_dir`` and check that it succeeded and left complete
    evidence.

    Parameters
    ----------
    job_dir : directory of the job (created).
    deck : the deck text, or a path (Path, or a one-line str naming an existing file) to a deck;
        written to ``job_dir/in.liggghts`` (LAMMPS: ``in.lammps``).
    files : input files the deck reads, ``{name in job_dir: source}``; a source is a path (Path, or
        a one-line str naming an existing file: copied), bytes or text (written). They are part
        of the job's hash.
    np : MPI processes; > 1 runs under ``mpirun -np N`` (with ``--allow-run-as-root`` as root).
    timeout : seconds before the job is killed (None: no limit); also the longest wait for
        another process writing the same job.
    progress : show a progress bar of finished ``run`` commands (quiet off a terminal).
    outputs : names of files the deck must produce (relative to ``job_dir``); checked and hashed;
        the deck's ``dump`` files among them must hold the expected frames.
    expected_runs : number of ``run`` commands in the deck (progress bar total); checked against
        the deck, and used as the expected count when the deck cannot be followed.
    allowed_warnings : regular expressions of WARNING lines that do not fail the job; any other
        WARNING line fails it (granular decks should run warning-free).
    force : run even when complete outputs already exist.
    engine : the code, ``"liggghts"`` (default) or ``"lammps"`` (:func:`reference_runs.engines.get_engine`;
        :class:`~gransim.errors.InputError` for another name). ``"yade"``: ``deck`` is a YADE
        Python script, run by :func:`reference_runs.yade.job.run_yade_job` (its own evidence:
        exit status, banner, no TCP server opened, the outputs; ``progress``, ``allowed_warnings``
        and ``desc`` do not apply).
    variables : command-line variables of the code, {NAME: VALUE} or (NAME, VALUE) pairs
        (:func:`reference_runs.engines.check_variables`: :class:`~gransim.errors.InputError`
        naming a bad or repeated name), passed as ``-var NAME VALUE`` (index style: a deck's
        ``variable NAME index DEFAULT`` keeps the command-line value). The deck's runs and dump
        frames are expected with them; they are part of the job's identity (a job run with other
        variables is rerun, never reused) and recorded in the manifest (``variables``).

    Returns
    -------
    :class:`JobResult`. Its manifest records ``evidence`` (expected and found runs, last steps
    and dump frames), ``variables``, ``command`` (with its ``-var`` arguments), ``log_sha256``,
    ``outputs`` (SHA-256 of each), ``engine``, ``engine_version`` (from the job's own log
    banner), ``engine_binary``, ``engine_package`` (Debian package version of the binary, or
    None), for LIGGGHTS also ``liggghts_version``, ``liggghts_binary``, ``liggghts_package``
    and, after an automatic rerun, ``rerun_reason``.

    Raises
    ------
    ReferenceRunError
        binary missing (with how to install it), non-zero exit, ERROR or unexpected WARNING lines,
        lost atoms, timeout (``timed_out=True``), a log without the code's banner, incomplete
        evidence (``incomplete: log.lammps holds 2 of 3 runs``, ``dump.atoms: expected 7 frames,
        got 1``) or a missing output; the message quotes the relevant log lines and the manifest
        then has ``"status": "failed"`` (never ``"ok"``). Also when a stored job fails
        verification, or was run by the other code, and the code is not there to rerun it (the
        message names ``--force``).
    InputError
        an unknown engine; a variable with a bad name or value, or given twice (naming it),
        before anything runs; variables for a YADE job.
    """
    eng = get_engine(engine)
    variables = check_variables(variables)
    if eng.name == "yade":  # a Python script with no LAMMPS-style log: YADE's own job accounting
        if variables:
            raise InputError("variables: a YADE job is a Python script; it takes no -var NAME VALUE")
        if expected_runs is not None or int(np) != 1:
            raise ReferenceRunError(f"YADE job {job_dir}: a script has no runs to expect and runs as one process")
        from .yade.job import run_yade_job  # noqa: PLC0415 - import cycle (reference_runs.yade.job uses this module)

        return run_yade_job(job_dir, deck, files, timeout=timeout, outputs=outputs, force=force, engine=eng)
    job_dir = Path(job_dir)
    deck_text, blobs, deck_sha, input_sha = _job_inputs(deck, files)
    outputs = [str(o) for o in outputs]
    expect = expected_evidence(deck_text, variables)
    if expected_runs is not None and expect.runs is not None and len(expect.runs) != expected_runs:
        raise ReferenceRunError(
            f"{eng.label} job {job_dir}: the deck has {len(expect.runs)} run commands but "
            f"expected_runs={expected_runs} (deck and caller disagree)",
            job_dir=job_dir,
        )
    job_dir.mkdir(parents=True, exist_ok=True)
    lock = DirectoryLock(job_dir, fail_fast=False, timeout=timeout, what=f"job {job_dir}", clean_tmp=True, echo=_echo)
    try:
        lock.acquire()
    except DirectoryBusyError as exc:
        raise ReferenceRunError(f"{eng.label} job {job_dir}: {exc}", job_dir=job_dir, timed_out=exc.timed_out) from None
    try:
        return _run_locked(
            job_dir,
            deck_text,
            blobs,
            deck_sha,
            input_sha,
            expect,
            np,
            timeout,
            progress,
            outputs,
            expected_runs,
            allowed_warnings,
            force,
            desc,
            eng,
            variables,
        )
    finally:
        lock.release()


def _run_locked(
    job_dir,
    deck_text,
    blobs,
    deck_sha,
    input_sha,
    expect,
    np,
    timeout,
    progress,
    outputs,
    expected_runs,
    allowed_warnings,
    force,
    desc,
    eng,
    variables,
) -> JobResult:
    rerun_reason = None
    label = eng.label
    m = None if force else read_manifest(job_dir)
    # the same job: deck, input files and command-line variables (other variables: another job, run)
    if m and m.get("status") == "ok" and m.get("input_sha256") == input_sha and manifest_variables(m) == variables:
        names = list(dict.fromkeys([*(m.get("outputs") or {}), *outputs]))
        _, problems = _verify(job_dir, m, deck_text, LOG_NAME, names, require_hashes=True, variables=variables)
        if manifest_engine(m) != eng.name:
            problems = [f"the job was run by {manifest_engine(m)}, not {eng.name}", *problems]
        if not problems:
            return JobResult(
                job_dir, m, parse_log(job_dir / LOG_NAME), skipped=True, warnings=tuple(m.get("warnings", ()))
            )
        if not eng.available():
            raise ReferenceRunError(
                f"stored {label} job {job_dir} is marked ok but fails verification: {'; '.join(problems)}. "
                f"It cannot be rerun here: the `{eng.binary}` binary was not found on PATH ({eng.install_hint}); "
                f"with {label} installed it is rerun automatically, or use {FORCE_HINT}",
                job_dir=job_dir,
                problems=problems,
            )
        rerun_reason = problems
        _echo(
            f"WARNING: {label} job {job_dir} is marked ok but fails verification ({'; '.join(problems)}): rerunning it"
        )

    exe = eng.find()
    (job_dir / MANIFEST_NAME).unlink(missing_ok=True)  # nothing complete-looking while we run
    for stale in [LOG_NAME, *outputs, *expect.dumps, *DECK_NAMES]:
        if "*" not in stale and "%" not in stale:
            (job_dir / stale).unlink(missing_ok=True)
    (job_dir / eng.deck_name).write_text(deck_text)
    for name, data in blobs.items():
        (job_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (job_dir / name).write_bytes(data)

    cmd = eng.command(eng.deck_name, LOG_NAME, np, exe=exe, variables=variables)
    package = eng.package_version(exe)
    manifest = {
        "status": "running",
        "command": cmd,
        "job_dir": str(job_dir.resolve()),
        "deck": eng.deck_name,
        "deck_sha256": deck_sha,
        "input_sha256": input_sha,
        "inputs": {name: _sha256(b) for name, b in sorted(blobs.items())},
        "variables": dict(variables),
        "engine": eng.name,
        "engine_binary": exe,
        "engine_package": package,
        "np": int(np),
        "start": _now(),
        "timeout": timeout,
    }
    if eng.name == "liggghts":
        manifest.update(liggghts_binary=exe, liggghts_package=package)
    if rerun_reason:
        manifest["rerun_reason"] = rerun_reason
    total = expected_runs if expected_runs is not None else expect.n_runs
    t0 = time.monotonic()
    tail = _LogTail(job_dir / LOG_NAME)
    bar = None
    if progress:
        bar = _progress(total=total, desc=desc or f"{eng.name} {job_dir.name}", unit="run")
    timed_out = False
    with open(job_dir / "stdout.txt", "wb") as out, open(job_dir / "stderr.txt", "wb") as err:
        # own session, marked, watched: no process of the job outlives this one, whatever ends it
        job = start_watched(
            cmd, cwd=job_dir, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=eng.env(np), private_tmp=True
        )
        proc = job.proc
        try:
            while True:
                try:
                    proc.wait(timeout=0.2)
                    break
                except subprocess.TimeoutExpired:
                    pass
                if bar is not None:
                    done = tail.runs_done
                    tail.poll()
                    if tail.runs_done > done:
                        bar.update(tail.runs_done - done)
                    if tail.last_step is not None:
                        bar.set_postfix_str(f"step {tail.last_step}", refresh=False)
                if timeout is not None and time.monotonic() - t0 > timeout:
                    timed_out = True
                    break
        except BaseException as exc:
            _record_interrupted(job, job_dir, manifest, t0, exc, f"the {label} process group was killed")
            raise
        finally:
            if bar is not None:
                bar.close()
            if timed_out:
                _kill_jobs([job])
            finish_watched(job)  # members it left behind, its private TMPDIR, the watchdog
    rc = proc.returncode
    manifest["end"] = _now()
    manifest["elapsed_s"] = round(time.monotonic() - t0, 3)
    manifest["returncode"] = rc

    log_path = job_dir / LOG_NAME
    have_log = log_path.exists()
    log = parse_log(log_path) if have_log else parse_log("")
    lines = log_path.read_text(errors="replace").splitlines() if have_log else []
    stderr = (job_dir / "stderr.txt").read_text(errors="replace").strip().splitlines()
    allowed = [re.compile(p) for p in allowed_warnings]
    bad_warn = [w for w in log.warnings if not any(p.search(w.text) for p in allowed)]
    manifest["warnings"] = [str(w) for w in log.warnings]
    own_version = log.version if log.engine == eng.name else None
    manifest["engine_version"] = own_version
    if eng.name == "liggghts":
        manifest["liggghts_version"] = own_version
        manifest["liggghts_log_version"] = own_version
    evidence, ev_problems = check_evidence(expect, log if have_log else None, LOG_NAME, job_dir, outputs)
    if expect.runs is None and expected_runs is not None and have_log:
        done = sum(r.complete for r in log.runs)
        evidence["runs_expected"] = expected_runs
        if done != expected_runs:
            ev_problems.append(f"incomplete: {LOG_NAME} holds {done} of {expected_runs} runs")
    if expect.unresolved:
        _echo(
            f"WARNING: {label} job {job_dir}: the deck reader could not follow the deck "
            f"({'; '.join(expect.unresolved)}); only what could be derived is checked"
        )
    evidence["problems"] = list(ev_problems)
    manifest["evidence"] = evidence

    def tail_lines():
        return [f"{n}: {t}" for n, t in enumerate(lines, 1)][-CONTEXT_LINES:]

    problem, where = None, []
    if timed_out:
        problem = f"timed out after {timeout:g} s (killed)"
        where = tail_lines()
    elif log.errors:
        problem = f"{label} stopped with an error: {log.errors[0].text}"
        where = _context(lines, [e.lineno for e in log.errors])
    elif log.lost_atoms:
        problem = "atoms were lost (the Atoms thermo column dropped or a 'Lost atoms' line)"
        where = [f"{n}: {t}" for n, t in enumerate(lines, 1) if "Lost atoms" in t][:CONTEXT_LINES]
        where = where or tail_lines()
    elif rc != 0:
        problem = f"{eng.binary} exited with status {rc}"
        where = tail_lines()
    elif not have_log:
        problem = f"incomplete: {LOG_NAME} was not written ({eng.binary} exited with status 0)"
    elif own_version is None:
        other = f" (it is a {log.engine} log)" if log.engine else ""
        problem = f"incomplete: {LOG_NAME} has no {label} banner line{other} (is `{exe}` {label}?)"
        where = tail_lines()
    elif bad_warn:
        problem = f"{len(bad_warn)} unexpected WARNING line(s): {bad_warn[0].text}"
        where = _context(lines, [w.lineno for w in bad_warn[:5]])
    elif ev_problems:
        problem = "; ".join(ev_problems)
        where = tail_lines()
    else:
        missing = [o for o in outputs if not (job_dir / o).exists()]
        if missing:
            problem = f"expected output(s) not written: {missing}"
    if problem is not None:
        if stderr:
            where = where + ["(stderr)"] + stderr[-CONTEXT_LINES:]
        manifest.update(status="failed", error=problem, log_lines=where)
        _write_manifest(job_dir, manifest)
        raise ReferenceRunError(
            f"{label} job {job_dir}: {problem}",
            job_dir=job_dir,
            log_lines=where,
            timed_out=timed_out,
            problems=ev_problems or [problem],
        )

    manifest["log_sha256"] = _sha256_file(log_path)
    manifest["outputs"] = {o: _sha256_file(job_dir / o) for o in outputs}
    manifest["n_runs"] = len(log.runs)
    manifest["status"] = "ok"
    _write_manifest(job_dir, manifest)  # last: marks the outputs complete
    return JobResult(job_dir, manifest, log, skipped=False, warnings=tuple(manifest["warnings"]))


__all__ = [
    "DECK_NAMES",
    "FORCE_HINT",
    "JobResult",
    "KILL_GRACE_S",
    "ReferenceRunError",
    "Terminated",
    "find_engine",
    "find_liggghts",
    "is_complete",
    "manifest_engine",
    "manifest_variables",
    "job_evidence",
    "kill_children_on_signals",
    "live_children",
    "private_tempdir",
    "run_watched",
    "start_watched",
    "finish_watched",
    "read_manifest",
    "run_job",
    "terminate_children",
    "verify_job",
]
