"""Run one LIGGGHTS job in its own directory, with a manifest that says whether it completed.

A job directory holds the deck (``in.liggghts``), its input files (data files...), the log
(``log.lammps``), the outputs the deck writes, ``stdout.txt``/``stderr.txt`` and, written
atomically and last, ``manifest.json``. Only a manifest with ``"status": "ok"`` marks the
outputs as complete; a failed job leaves ``"status": "failed"`` with the reason, and a job
that is running or was killed has no manifest at all (it is removed before the run starts).

A job is identified by the SHA-256 of its deck and input files (``input_sha256``; the deck
alone is ``deck_sha256``): :func:`run_job` returns at once, without running, when the
directory already holds an ``ok`` manifest with the same input hash and all its outputs.
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path

from gransim.io import atomic_path, liggghts_version

from .errors import ReferenceRunError
from .parsers import LogFile, parse_log

DECK_NAME = "in.liggghts"
LOG_NAME = "log.lammps"
MANIFEST_NAME = "manifest.json"
INSTALL_HINT = ("install LIGGGHTS-PUBLIC 3.8.0 with `sudo apt-get install liggghts` (Debian/Ubuntu), "
                "or put a `liggghts` binary on PATH")
#: how many lines of log context to show in an error
CONTEXT_LINES = 12


@dataclass(frozen=True)
class JobResult:
    """Outcome of :func:`run_job`.

    Attributes
    ----------
    job_dir : the job directory.
    manifest : the manifest written (or found) as a dict.
    log : the parsed log (:class:`~reference_runs.parsers.LogFile`).
    skipped : True when the job was not run because complete outputs already existed.
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


def _now() -> str:
    return _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")


def find_liggghts() -> str:
    """Absolute path of the ``liggghts`` binary; :class:`ReferenceRunError` with how to install."""
    exe = shutil.which("liggghts")
    if exe is None:
        raise ReferenceRunError(f"the `liggghts` binary was not found on PATH; {INSTALL_HINT}")
    return exe


def read_manifest(job_dir) -> dict | None:
    """The manifest of a job directory, or None (absent or unreadable)."""
    p = Path(job_dir) / MANIFEST_NAME
    try:
        return json.loads(p.read_text())
    except (OSError, ValueError):
        return None


def is_complete(job_dir, input_sha256: str | None = None) -> bool:
    """True when ``job_dir`` has an ``ok`` manifest (with this input hash) and all its outputs."""
    m = read_manifest(job_dir)
    if not m or m.get("status") != "ok":
        return False
    if input_sha256 is not None and m.get("input_sha256") != input_sha256:
        return False
    names = [LOG_NAME, *m.get("outputs", {})]
    return all((Path(job_dir) / name).exists() for name in names)


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
            with open(self.path, "r", errors="replace") as fh:
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


def run_job(job_dir, deck, files: dict | None = None, np: int = 1, timeout: float | None = 600.0,
            progress: bool = True, outputs=(), expected_runs: int | None = None,
            allowed_warnings=(), force: bool = False, desc: str | None = None) -> JobResult:
    """Run a LIGGGHTS deck in ``job_dir`` and check that it succeeded.

    Parameters
    ----------
    job_dir : directory of the job (created).
    deck : the deck text, or a path (Path, or a one-line str naming an existing file) to a deck;
        written to ``job_dir/in.liggghts``.
    files : input files the deck reads, ``{name in job_dir: source}``; a source is a path (Path, or
        a one-line str naming an existing file: copied), bytes or text (written). They are part
        of the job's hash.
    np : MPI processes; > 1 runs under ``mpirun -np N`` (with ``--allow-run-as-root`` as root).
    timeout : seconds before the job is killed (None: no limit).
    progress : show a progress bar of finished ``run`` commands (quiet off a terminal).
    outputs : names of files the deck must produce (relative to ``job_dir``); checked and hashed.
    expected_runs : number of ``run`` commands in the deck (progress bar total).
    allowed_warnings : regular expressions of WARNING lines that do not fail the job; any other
        WARNING line fails it (granular decks should run warning-free).
    force : run even when complete outputs already exist.

    Returns
    -------
    :class:`JobResult`.

    Raises
    ------
    ReferenceRunError
        binary missing, non-zero exit, ERROR or unexpected WARNING lines, lost atoms, timeout,
        or a missing output; the message quotes the relevant log lines. The manifest then has
        ``"status": "failed"`` (never ``"ok"``).
    """
    job_dir = Path(job_dir)
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
    deck_sha = _sha256(deck_text.encode())
    h = hashlib.sha256(deck_text.encode())
    for name in sorted(blobs):
        h.update(b"\0" + name.encode() + b"\0" + _sha256(blobs[name]).encode())
    input_sha = h.hexdigest()

    if not force and is_complete(job_dir, input_sha):
        m = read_manifest(job_dir)
        return JobResult(job_dir, m, parse_log(job_dir / LOG_NAME), skipped=True,
                         warnings=tuple(m.get("warnings", ())))

    exe = find_liggghts()
    job_dir.mkdir(parents=True, exist_ok=True)
    (job_dir / MANIFEST_NAME).unlink(missing_ok=True)  # nothing complete-looking while we run
    for stale in [LOG_NAME, *outputs]:
        (job_dir / stale).unlink(missing_ok=True)
    (job_dir / DECK_NAME).write_text(deck_text)
    for name, data in blobs.items():
        (job_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (job_dir / name).write_bytes(data)

    cmd = [exe, "-in", DECK_NAME, "-log", LOG_NAME, "-screen", "none", "-nocite"]
    if np > 1:
        mpirun = shutil.which("mpirun")
        if mpirun is None:
            raise ReferenceRunError("np > 1 needs `mpirun` on PATH (OpenMPI: `apt-get install openmpi-bin`)")
        extra = ["--allow-run-as-root"] if hasattr(os, "geteuid") and os.geteuid() == 0 else []
        cmd = [mpirun, *extra, "-np", str(int(np)), *cmd]

    manifest = {
        "status": "running", "command": cmd, "job_dir": str(job_dir.resolve()),
        "deck": DECK_NAME, "deck_sha256": deck_sha, "input_sha256": input_sha,
        "inputs": {name: _sha256(b) for name, b in sorted(blobs.items())},
        "liggghts_binary": exe, "liggghts_version": liggghts_version(), "np": int(np),
        "start": _now(), "timeout": timeout,
    }
    t0 = time.monotonic()
    tail = _LogTail(job_dir / LOG_NAME)
    bar = None
    if progress:
        from gransim.progress import progress as _progress

        bar = _progress(total=expected_runs, desc=desc or f"liggghts {job_dir.name}", unit="run")
    timed_out = False
    with open(job_dir / "stdout.txt", "wb") as out, open(job_dir / "stderr.txt", "wb") as err:
        proc = subprocess.Popen(cmd, cwd=job_dir, stdout=out, stderr=err, stdin=subprocess.DEVNULL,
                                start_new_session=True)
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
                    _kill(proc)
                    break
        except BaseException:
            _kill(proc)
            raise
        finally:
            if bar is not None:
                bar.close()
    rc = proc.returncode
    manifest["end"] = _now()
    manifest["elapsed_s"] = round(time.monotonic() - t0, 3)
    manifest["returncode"] = rc

    log = parse_log(job_dir / LOG_NAME) if (job_dir / LOG_NAME).exists() else parse_log("")
    lines = (job_dir / LOG_NAME).read_text(errors="replace").splitlines() if (job_dir / LOG_NAME).exists() else []
    stderr = (job_dir / "stderr.txt").read_text(errors="replace").strip().splitlines()
    allowed = [re.compile(p) for p in allowed_warnings]
    bad_warn = [w for w in log.warnings if not any(p.search(w.text) for p in allowed)]
    manifest["warnings"] = [str(w) for w in log.warnings]
    manifest["liggghts_log_version"] = log.version

    problem, where = None, []
    if timed_out:
        problem = f"timed out after {timeout:g} s (killed)"
        where = [f"{n}: {t}" for n, t in enumerate(lines, 1)][-CONTEXT_LINES:]
    elif log.errors:
        problem = f"LIGGGHTS stopped with an error: {log.errors[0].text}"
        where = _context(lines, [e.lineno for e in log.errors])
    elif log.lost_atoms:
        problem = "atoms were lost (the Atoms thermo column dropped or a 'Lost atoms' line)"
        where = [f"{n}: {t}" for n, t in enumerate(lines, 1) if "Lost atoms" in t][:CONTEXT_LINES] or \
            [f"{n}: {t}" for n, t in enumerate(lines, 1)][-CONTEXT_LINES:]
    elif rc != 0:
        problem = f"liggghts exited with status {rc}"
        where = [f"{n}: {t}" for n, t in enumerate(lines, 1)][-CONTEXT_LINES:]
    elif bad_warn:
        problem = f"{len(bad_warn)} unexpected WARNING line(s): {bad_warn[0].text}"
        where = _context(lines, [w.lineno for w in bad_warn[:5]])
    elif any(not run.complete for run in log.runs):
        problem = "a run did not finish (no 'Loop time' line)"
        where = [f"{n}: {t}" for n, t in enumerate(lines, 1)][-CONTEXT_LINES:]
    else:
        missing = [o for o in outputs if not (job_dir / o).exists()]
        if missing:
            problem = f"expected output(s) not written: {missing}"
    if problem is not None:
        if stderr:
            where = where + ["(stderr)"] + stderr[-CONTEXT_LINES:]
        manifest.update(status="failed", error=problem, log_lines=where)
        _write_manifest(job_dir, manifest)
        raise ReferenceRunError(f"LIGGGHTS job {job_dir}: {problem}", job_dir=job_dir, log_lines=where)

    manifest["outputs"] = {o: _sha256((job_dir / o).read_bytes()) for o in outputs}
    manifest["n_runs"] = len(log.runs)
    manifest["status"] = "ok"
    _write_manifest(job_dir, manifest)  # last: marks the outputs complete
    return JobResult(job_dir, manifest, log, skipped=False, warnings=tuple(manifest["warnings"]))


def _kill(proc: subprocess.Popen) -> None:
    """Terminate the job's own process group (it was started in a new session)."""
    if proc.poll() is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    except ProcessLookupError:
        pass


__all__ = ["JobResult", "ReferenceRunError", "find_liggghts", "is_complete", "read_manifest", "run_job"]
