"""Run one YADE job (a Python script) in its own directory, with a manifest that says whether it completed.

:func:`reference_runs.runner.run_job` hands ``engine="yade"`` jobs here: a YADE job has no
LAMMPS-style log with thermo tables to count runs in, so its evidence is its own (below).

A job directory holds the script (``yade_job.py``), its input files, the module
``gransim_yade_quiet.py`` that ``yade -L`` imports first, ``stdout.txt``/``stderr.txt``, the
outputs the script writes, the lock file ``.lock`` and, written atomically and last,
``manifest.json`` (``"status": "ok"`` only when the evidence is complete, as for LIGGGHTS and
LAMMPS jobs). The job runs ``yade -n -x -j1 -L gransim_yade_quiet yade_job.py``
(:class:`reference_runs.engines.YadeEngine`) through :func:`reference_runs.runner.start_watched`:
its own session, every process marked ``GRANSIM_JOB=<id>``, a private ``TMPDIR`` removed at the
end, a watchdog that kills the job if this process dies, and every process of the job killed on
timeout, on an exception and when it exits leaving any behind.

Nothing listening: every ``yade`` process opens, before the script runs, a Python prompt on TCP
port 9000 (or the next free one) and an XML-RPC server on 21000+, both bound to every interface
(``''``) (docs/yade.md). The quiet module replaces ``yade.remote.runServers`` before the launcher
calls it, so a job opens no port at all; the job's stderr then holds the line
:data:`QUIET_LINE` instead of YADE's ``TCP python prompt on ...`` and ``XMLRPC info provider on
...`` lines. A job whose stderr shows either server is failed (its processes are killed all the
same, so the ports close with it).

Evidence of a complete job: exit status 0, the ``Welcome to Yade VERSION`` line on stdout (the
version recorded as ``engine_version``), the quiet line and no server line on stderr, every
declared output present, and whatever ``check(job_dir)`` (the reader of the outputs) reports.
A stored ``ok`` job is reused only when its input hash, its engine, the SHA-256 of its stdout
and of every output match the manifest and ``check`` still finds nothing.
"""

from __future__ import annotations

import re
import subprocess
import time
from pathlib import Path

from ..engines import YADE, YADE_QUIET_MODULE, get_engine
from ..errors import DirectoryBusyError, ReferenceRunError
from ..locks import DirectoryLock
from ..parsers import parse_log
from ..runner import (
    CONTEXT_LINES,
    FORCE_HINT,
    MANIFEST_NAME,
    JobResult,
    _echo,
    _job_inputs,
    _kill_jobs,
    _now,
    _record_interrupted,
    _sha256,
    _sha256_file,
    _write_manifest,
    finish_watched,
    manifest_engine,
    read_manifest,
    start_watched,
)

#: the last line of a Python traceback: the exception a YADE script raised (``RuntimeError: ...``)
EXCEPTION_LINE = re.compile(r"^[A-Za-z_][\w.]*(Error|Exception|Interrupt|Exit)\b.*")


def _exception_line(stderr: list) -> str:
    """The exception a script that raised names on stderr (the last line of its traceback), or ""."""
    return next((ln.strip() for ln in reversed(stderr) if EXCEPTION_LINE.match(ln.strip())), "")


#: the line the quiet module writes to stderr instead of starting YADE's servers
QUIET_LINE = "gransim: YADE's TCP servers (python prompt, XML-RPC) not started"
#: stderr lines of YADE's servers (yade/remote.py runServers): a job that shows one opened a port
SERVER_LINES = re.compile(r"^(TCP python prompt on |XMLRPC info provider on )")
#: ``yade -L`` imports this module (from the job directory) before any of YADE's own
QUIET_MODULE_TEXT = f'''"""Imported by `yade -L {YADE_QUIET_MODULE}` before YADE's modules (written by gransim,
reference_runs.yade.job): when yade.remote is imported, its runServers (a Python prompt on TCP
port 9000+ and an XML-RPC server on 21000+, on every interface) is replaced by a function that
opens nothing and says so on stderr."""
import importlib.machinery
import sys


class _QuietRemote:
    def find_spec(self, name, path=None, target=None):
        if name != "yade.remote":
            return None
        sys.meta_path.remove(self)
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or spec.loader is None:
            return spec
        load = spec.loader.exec_module

        def exec_module(module):
            load(module)

            def runServers():
                sys.stderr.write({QUIET_LINE!r} + "\\n")
                sys.stderr.flush()

            module.runServers = runServers

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, _QuietRemote())
'''
_BANNER = re.compile(r"^Welcome to Yade (\S+)")


def _version_of_stdout(path: Path) -> str | None:
    try:
        with open(path, errors="replace") as fh:
            for line in fh:
                m = _BANNER.match(line.strip())
                if m:
                    return "YADE " + m.group(1)
    except OSError:
        return None
    return None


def _lines(path: Path) -> list:
    try:
        return path.read_text(errors="replace").splitlines()
    except OSError:
        return []


def _verify(job_dir: Path, m: dict, outputs, check) -> list:
    problems = []
    hashes = dict(m.get("outputs") or {})
    for name in dict.fromkeys([*hashes, *outputs]):
        p = job_dir / name
        if not p.exists():
            problems.append(f"output {name} is missing")
        elif name not in hashes:
            problems.append(f"output {name} is not recorded in the manifest")
        elif _sha256_file(p) != hashes[name]:
            problems.append(f"output {name} changed since the job ran (SHA-256 differs from the manifest)")
    out = job_dir / "stdout.txt"
    if not out.exists() or m.get("stdout_sha256") != _sha256_file(out):
        problems.append("stdout.txt is missing or changed since the job ran")
    if not problems and check is not None:
        problems += list(check(job_dir))
    return problems


def run_yade_job(
    job_dir,
    script,
    files: dict | None = None,
    timeout: float | None = 600.0,
    outputs=(),
    force: bool = False,
    check=None,
    engine=YADE,
) -> JobResult:
    """Run a YADE script in ``job_dir`` and check that it succeeded and left complete evidence.

    Parameters
    ----------
    job_dir : directory of the job (created).
    script : the script text, or a path to it; written to ``job_dir/yade_job.py``.
    files : input files, ``{name in job_dir: source}`` as for :func:`reference_runs.runner.run_job`
        (part of the job's hash, with the script and the quiet module).
    timeout : seconds before every process of the job is killed (None: no limit); also the
        longest wait for another process writing the same job.
    outputs : names of files the script must write (checked and hashed).
    force : run even when a complete, verified job is stored.
    check : ``check(job_dir) -> list of problems`` of the outputs (e.g. a reader's
        completeness check); any problem fails the job (``incomplete: ...``).

    Returns
    -------
    :class:`reference_runs.runner.JobResult` (its ``log`` is empty: YADE writes no LAMMPS log).
    The manifest records ``engine`` (``yade``), ``engine_version`` (from the job's own ``Welcome
    to Yade`` line), ``engine_binary``, ``engine_binary_version`` (``yade --version``),
    ``engine_package`` (Debian), ``servers`` (``not started``), ``outputs`` and
    ``stdout_sha256``.

    Raises
    ------
    ReferenceRunError
        binary missing (with how to install it), non-zero exit (the script's traceback quoted),
        timeout (``timed_out=True``), no banner, a server opened, a missing output or a problem
        ``check`` found; the manifest then has ``"status": "failed"``.
    """
    eng = get_engine(engine)
    job_dir = Path(job_dir)
    blobs_in = dict(files or {})
    blobs_in[f"{YADE_QUIET_MODULE}.py"] = QUIET_MODULE_TEXT
    script_text, blobs, script_sha, input_sha = _job_inputs(script, blobs_in)
    outputs = [str(o) for o in outputs]
    job_dir.mkdir(parents=True, exist_ok=True)
    lock = DirectoryLock(job_dir, fail_fast=False, timeout=timeout, what=f"job {job_dir}", clean_tmp=True, echo=_echo)
    try:
        lock.acquire()
    except DirectoryBusyError as exc:
        raise ReferenceRunError(f"{eng.label} job {job_dir}: {exc}", job_dir=job_dir, timed_out=exc.timed_out) from None
    try:
        return _run_locked(job_dir, eng, script_text, blobs, script_sha, input_sha, timeout, outputs, force, check)
    finally:
        lock.release()


def _run_locked(job_dir, eng, script_text, blobs, script_sha, input_sha, timeout, outputs, force, check):
    label = eng.label
    rerun_reason = None
    m = None if force else read_manifest(job_dir)
    if m and m.get("status") == "ok" and m.get("input_sha256") == input_sha:
        problems = _verify(job_dir, m, outputs, check)
        if manifest_engine(m) != eng.name:
            problems = [f"the job was run by {manifest_engine(m)}, not {eng.name}", *problems]
        if not problems:
            return JobResult(job_dir, m, parse_log(""), skipped=True)
        if not eng.available():
            raise ReferenceRunError(
                f"stored {label} job {job_dir} is marked ok but fails verification: {'; '.join(problems)}. "
                f"It cannot be rerun here: the `{eng.binary}` binary was not found on PATH ({eng.install_hint}); "
                f"with {label} installed it is rerun automatically, or use {FORCE_HINT}",
                job_dir=job_dir,
                problems=problems,
            )
        rerun_reason = problems
        _echo(f"WARNING: {label} job {job_dir} is marked ok but fails verification ({'; '.join(problems)}): rerun")

    exe = eng.find()
    (job_dir / MANIFEST_NAME).unlink(missing_ok=True)  # nothing complete-looking while it runs
    for stale in [*outputs, eng.deck_name, "stdout.txt", "stderr.txt"]:
        (job_dir / stale).unlink(missing_ok=True)
    (job_dir / eng.deck_name).write_text(script_text)
    for name, data in blobs.items():
        (job_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (job_dir / name).write_bytes(data)
    cmd = eng.command(eng.deck_name, exe=exe)
    manifest = {
        "status": "running",
        "command": cmd,
        "job_dir": str(job_dir.resolve()),
        "deck": eng.deck_name,
        "deck_sha256": script_sha,
        "input_sha256": input_sha,
        "inputs": {name: _sha256(b) for name, b in sorted(blobs.items())},
        "engine": eng.name,
        "engine_binary": exe,
        "engine_binary_version": eng.version(exe),
        "engine_package": eng.package_version(exe),
        "np": 1,
        "start": _now(),
        "timeout": timeout,
    }
    if rerun_reason:
        manifest["rerun_reason"] = rerun_reason
    t0 = time.monotonic()
    timed_out = False
    with open(job_dir / "stdout.txt", "wb") as out, open(job_dir / "stderr.txt", "wb") as err:
        job = start_watched(
            cmd, cwd=job_dir, stdout=out, stderr=err, stdin=subprocess.DEVNULL, env=eng.env(), private_tmp=True
        )
        proc = job.proc
        try:
            try:
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                timed_out = True
                _kill_jobs([job])
        except BaseException as exc:
            _record_interrupted(job, job_dir, manifest, t0, exc, f"the {label} processes were killed")
            raise
        finally:
            finish_watched(job)  # members it left behind, its private TMPDIR, the watchdog
    rc = proc.returncode
    manifest.update(end=_now(), elapsed_s=round(time.monotonic() - t0, 3), returncode=rc)
    stdout, stderr = _lines(job_dir / "stdout.txt"), _lines(job_dir / "stderr.txt")
    version = _version_of_stdout(job_dir / "stdout.txt")
    manifest["engine_version"] = version
    servers = [ln for ln in stderr if SERVER_LINES.match(ln)]
    manifest["servers"] = "opened" if servers else ("not started" if QUIET_LINE in stderr else "unknown")

    def tail():
        return stdout[-CONTEXT_LINES:] + (["(stderr)"] + stderr[-CONTEXT_LINES:] if stderr else [])

    problem, where = None, []
    if timed_out:
        problem, where = f"timed out after {timeout:g} s (killed)", tail()
    elif rc != 0:
        raised = _exception_line(stderr)
        problem, where = f"{eng.binary} exited with status {rc}" + (f": {raised}" if raised else ""), tail()
    elif version is None:
        problem, where = f"incomplete: stdout.txt has no 'Welcome to Yade' line (is `{exe}` YADE?)", tail()
    elif servers:
        problem, where = f"YADE opened its TCP servers ({servers[0]}); they must stay closed", servers
    elif QUIET_LINE not in stderr:
        problem, where = (
            f"incomplete: stderr.txt lacks the line of {YADE_QUIET_MODULE} (was it imported before YADE's servers?)",
            tail(),
        )
    else:
        missing = [o for o in outputs if not (job_dir / o).exists()]
        if missing:
            problem = f"expected output(s) not written: {missing}"
        elif check is not None:
            found = list(check(job_dir))
            if found:
                problem, where = "; ".join(found), tail()
    if problem is not None:
        manifest.update(status="failed", error=problem, log_lines=where)
        _write_manifest(job_dir, manifest)
        raise ReferenceRunError(
            f"{label} job {job_dir}: {problem}",
            job_dir=job_dir,
            log_lines=where,
            timed_out=timed_out,
            problems=[problem],
        )
    manifest["stdout_sha256"] = _sha256_file(job_dir / "stdout.txt")
    manifest["outputs"] = {o: _sha256_file(job_dir / o) for o in outputs}
    manifest["status"] = "ok"
    _write_manifest(job_dir, manifest)  # last: marks the outputs complete
    return JobResult(job_dir, manifest, parse_log(""), skipped=False)


__all__ = ["QUIET_LINE", "QUIET_MODULE_TEXT", "run_yade_job"]
