"""Provenance of results: gransim version, git commit, time, machine, DEM code versions.

The versions of the established DEM codes (LIGGGHTS, LAMMPS) come from the binaries' own
banners (:func:`binary_version`, cached per binary path, modification time and size) and from
Debian's package database (:func:`package_version`).
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import json
import os
import platform
import re
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from .. import __version__

_REPO = Path(__file__).resolve().parents[2]


@functools.lru_cache(maxsize=1)
def git_commit() -> str:
    """Commit of the gransim source tree ('unknown' outside a checkout; '+dirty' if modified)."""
    try:
        sha = subprocess.run(
            ["git", "-C", str(_REPO), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5
        ).stdout.strip()
        if not sha:
            return "unknown"
        dirty = subprocess.run(
            ["git", "-C", str(_REPO), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=5,
        ).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


_BANNER = re.compile(r"LIGGGHTS \(Version ([^,)]*)")
#: LAMMPS' banner: ``LAMMPS (29 Sep 2021 - Update 2)`` (first line of the screen output and the log)
LAMMPS_BANNER = re.compile(r"^LAMMPS \(([^)]*)\)", re.MULTILINE)


def _die_with_parent():
    """A ``preexec_fn`` that makes the child get SIGKILL when the thread that started it ends (the
    process killed, even by SIGKILL): Linux ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, through ctypes
    (None elsewhere). The flag survives the exec of the code."""
    import ctypes  # noqa: PLC0415 - start-up: ctypes, only when a DEM code is asked for its version

    try:
        prctl = ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    parent = os.getpid()

    def preexec():
        prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
        if os.getppid() != parent:  # the parent died before the flag was set
            os.kill(os.getpid(), signal.SIGKILL)

    return preexec


def run_probe(cmd: list, cwd: str, timeout: float) -> subprocess.CompletedProcess:
    """Run a DEM code's version query (``cmd`` in the directory ``cwd``, ``timeout`` seconds) so
    that it cannot outlive gransim: in a session of its own,
    killed when gransim dies (:func:`_die_with_parent`; the ``orted`` of an MPI singleton follows
    the code), its whole process group killed on a timeout (:class:`subprocess.TimeoutExpired`),
    Open MPI's session files in ``cwd`` (a temporary directory) rather than the shared TMPDIR."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "TMPDIR": cwd, "OMPI_MCA_orte_tmpdir_base": cwd}
    proc = subprocess.Popen(
        cmd,
        cwd=cwd,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
        env=env,
        preexec_fn=_die_with_parent(),  # noqa: PLW1509 - only prctl in the child, no lock taken
    )
    try:
        out, err = proc.communicate(timeout=timeout)
    except BaseException:  # a timeout, a signal: the whole group goes
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


@functools.lru_cache(maxsize=32)
def _banner_of(path: str, mtime_ns: int, size: int, pattern: str, label: str, prefix: str) -> str:
    """What the binary at ``path`` prints about itself (one call per binary and modification)."""
    with tempfile.TemporaryDirectory(prefix="dem-version-") as tmp:
        try:
            out = run_probe([path, "-in", os.devnull, "-log", "none", "-nocite"], tmp, 20)
        except subprocess.TimeoutExpired:
            return f"unknown: `{path} -in /dev/null` did not answer within 20 s"
        except OSError as exc:
            return f"unknown: cannot run {path} ({exc.strerror or exc})"
    m = re.compile(pattern, re.MULTILINE).search(out.stdout + "\n" + out.stderr)
    if m:
        return prefix + m.group(1).strip()
    return f"unknown: no {label} banner from `{path} -in /dev/null`"


def _binary_banner(path: str, mtime_ns: int, size: int) -> str:
    """The LIGGGHTS banner version of ``path`` (kept for callers of the older name)."""
    return _banner_of(path, mtime_ns, size, _BANNER.pattern, "LIGGGHTS", "")


def binary_version(binary, default: str, pattern: str, label: str, prefix: str = "") -> str | None:
    """Version of a DEM binary as it reports itself, with its path, or None when absent.

    Runs ``BINARY -in /dev/null -log none -nocite`` (well under a second, once per binary path,
    modification time and size in a process) and returns ``prefix + group 1 of pattern`` found in
    its output, then `` (PATH)``; ``"unknown: ..."`` (with the path) when it prints no banner.

    Parameters
    ----------
    binary : path or name of the binary (None: ``default`` on PATH).
    default : the binary's usual name (``liggghts``, ``lmp``).
    pattern : regular expression of the banner, the version in group 1.
    label : the code's name, for the message of a missing banner.
    prefix : prepended to the version (``"LAMMPS "``).
    """
    found = binary_identity(binary, default)
    if found is None:
        return None
    path, mtime_ns, size = found
    return f"{_banner_of(path, mtime_ns, size, pattern, label, prefix)} ({path})"


def binary_identity(binary, default: str) -> tuple[str, int, int] | None:
    """``(absolute path, modification time in ns, size in bytes)`` of a code's binary (``binary``:
    a path or name; None: ``default`` on PATH), or None when absent. Version probes are cached on
    this triple: a binary replaced in place is asked again."""
    path = shutil.which(str(binary)) if binary is not None else shutil.which(default)
    if path is None:
        return None
    path = os.path.abspath(path)
    try:
        st = os.stat(path)
    except OSError:
        return None
    return path, st.st_mtime_ns, st.st_size


def liggghts_version(binary=None) -> str | None:
    """Version of the LIGGGHTS binary as it reports itself, with its path, or None when absent.

    Runs ``BINARY -in /dev/null -log none -nocite`` (about 0.4 s, once per binary path and
    modification time in a process) and reads its banner ``LIGGGHTS (Version LIGGGHTS-PUBLIC
    3.8.0, compiled ...)``: e.g. ``"LIGGGHTS-PUBLIC 3.8.0 (/usr/bin/liggghts)"``. ``binary``
    defaults to ``liggghts`` on PATH. The Debian package version is
    :func:`liggghts_package_version`.
    """
    return binary_version(binary, "liggghts", _BANNER.pattern, "LIGGGHTS")


def lammps_version(binary=None) -> str | None:
    """Version of the LAMMPS binary as it reports itself, with its path, or None when absent.

    Reads the banner ``LAMMPS (29 Sep 2021 - Update 2)`` of ``BINARY -in /dev/null``: e.g.
    ``"LAMMPS 29 Sep 2021 - Update 2 (/usr/bin/lmp)"``. ``binary`` defaults to ``lmp`` on PATH.
    """
    return binary_version(binary, "lmp", LAMMPS_BANNER.pattern, "LAMMPS", prefix="LAMMPS ")


@functools.lru_cache(maxsize=16)
def _package_of(real: str, package: str = "liggghts", label: str = "LIGGGHTS-PUBLIC") -> str | None:
    try:
        owner = subprocess.run(["dpkg-query", "-S", real], capture_output=True, text=True, timeout=10)
        if owner.returncode != 0 or not owner.stdout.startswith(f"{package}:"):
            return None
        out = subprocess.run(
            ["dpkg-query", "-W", "-f=${Version}", package], capture_output=True, text=True, timeout=10
        ).stdout.strip()
        return f"{label} {out} (Debian)" if out else None
    except (OSError, subprocess.SubprocessError):
        return None


def package_version(binary, default: str, package: str, label: str) -> str | None:
    """Debian package version of a binary (``"<label> <version> (Debian)"``), or None when the
    binary is absent or not a file of Debian package ``package`` (a binary of one's own, a
    stand-in). ``binary`` None means ``default`` on PATH."""
    path = shutil.which(str(binary)) if binary is not None else shutil.which(default)
    if path is None:
        return None
    return _package_of(os.path.realpath(path), package, label)


def liggghts_package_version(binary=None) -> str | None:
    """Debian package version of the ``liggghts`` binary (e.g. ``LIGGGHTS-PUBLIC 3.8.0+repack1-9+b2
    (Debian)``), or None when it is absent or not a file of the ``liggghts`` package (a binary of
    one's own, a stand-in)."""
    return package_version(binary, "liggghts", "liggghts", "LIGGGHTS-PUBLIC")


def lammps_package_version(binary=None) -> str | None:
    """Debian package version of the ``lmp`` binary (e.g. ``LAMMPS 20220106.git7586adbb6a+ds1-2+b2
    (Debian)``), or None when it is absent or not a file of the ``lammps`` package."""
    return package_version(binary, "lmp", "lammps", "LAMMPS")


def _jsonable(v):
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return float(v)
    if isinstance(v, Path):
        return str(v)
    if isinstance(v, dict):
        return {str(k): _jsonable(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_jsonable(x) for x in v]
    if hasattr(v, "items"):
        return {str(k): _jsonable(x) for k, x in v.items()}
    return v


def provenance(parameters: dict | None = None, seed=None, liggghts: bool = False, lammps: bool = False) -> dict:
    """The provenance record stored as attributes of every results file.

    Keys: ``gransim_version``, ``git_commit``, ``created`` (UTC ISO time), ``python``,
    ``numpy``, ``numba``, ``host``, ``parameters`` (JSON), ``seed`` (JSON) and, when
    ``liggghts`` is true, ``liggghts_version``; when ``lammps`` is true, ``lammps_version``
    (``"absent"`` when the binary is not installed).
    """
    import numba  # noqa: PLC0415 - start-up: keeps numba out of import gransim.io

    rec = {
        "gransim_version": __version__,
        "git_commit": git_commit(),
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "host": platform.node(),
        "parameters": json.dumps(_jsonable(parameters or {}), sort_keys=True),
        "seed": json.dumps(_jsonable(seed)),
    }
    if liggghts:
        rec["liggghts_version"] = liggghts_version() or "absent"
    if lammps:
        rec["lammps_version"] = lammps_version() or "absent"
    return rec
