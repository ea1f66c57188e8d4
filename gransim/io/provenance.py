"""Provenance of results: gransim version, git commit, time, machine, LIGGGHTS version."""

from __future__ import annotations

import datetime as _dt
import functools
import json
import os
import platform
import re
import shutil
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
        sha = subprocess.run(["git", "-C", str(_REPO), "rev-parse", "HEAD"], capture_output=True,
                             text=True, timeout=5).stdout.strip()
        if not sha:
            return "unknown"
        dirty = subprocess.run(["git", "-C", str(_REPO), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=5).stdout.strip()
        return sha + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


_BANNER = re.compile(r"LIGGGHTS \(Version ([^,)]*)")


@functools.lru_cache(maxsize=16)
def _binary_banner(path: str, mtime_ns: int, size: int) -> str:
    """What the binary at ``path`` prints about itself (one call per binary and modification)."""
    with tempfile.TemporaryDirectory(prefix="liggghts-version-") as tmp:
        try:
            out = subprocess.run([path, "-in", os.devnull, "-log", "none", "-nocite"], cwd=tmp,
                                 capture_output=True, text=True, timeout=20, stdin=subprocess.DEVNULL,
                                 start_new_session=True)
        except subprocess.TimeoutExpired:
            return f"unknown: `{path} -in /dev/null` did not answer within 20 s"
        except OSError as exc:
            return f"unknown: cannot run {path} ({exc.strerror or exc})"
    m = _BANNER.search(out.stdout + "\n" + out.stderr)
    if m:
        return m.group(1).strip()
    return f"unknown: no LIGGGHTS banner from `{path} -in /dev/null`"


def liggghts_version(binary=None) -> str | None:
    """Version of the LIGGGHTS binary as it reports itself, with its path, or None when absent.

    Runs ``BINARY -in /dev/null -log none -nocite`` (about 0.4 s, once per binary path and
    modification time in a process) and reads its banner ``LIGGGHTS (Version LIGGGHTS-PUBLIC
    3.8.0, compiled ...)``: e.g. ``"LIGGGHTS-PUBLIC 3.8.0 (/usr/bin/liggghts)"``. ``binary``
    defaults to ``liggghts`` on PATH. The Debian package version is
    :func:`liggghts_package_version`.
    """
    path = shutil.which(str(binary)) if binary is not None else shutil.which("liggghts")
    if path is None:
        return None
    path = os.path.abspath(path)
    try:
        st = os.stat(path)
    except OSError:
        return None
    return f"{_binary_banner(path, st.st_mtime_ns, st.st_size)} ({path})"


@functools.lru_cache(maxsize=16)
def _package_of(real: str) -> str | None:
    try:
        owner = subprocess.run(["dpkg-query", "-S", real], capture_output=True, text=True, timeout=10)
        if owner.returncode != 0 or not owner.stdout.startswith("liggghts:"):
            return None
        out = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "liggghts"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        return f"LIGGGHTS-PUBLIC {out} (Debian)" if out else None
    except (OSError, subprocess.SubprocessError):
        return None


def liggghts_package_version(binary=None) -> str | None:
    """Debian package version of the ``liggghts`` binary (e.g. ``LIGGGHTS-PUBLIC 3.8.0+repack1-9+b2
    (Debian)``), or None when it is absent or not a file of the ``liggghts`` package (a binary of
    one's own, a stand-in)."""
    path = shutil.which(str(binary)) if binary is not None else shutil.which("liggghts")
    if path is None:
        return None
    return _package_of(os.path.realpath(path))


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


def provenance(parameters: dict | None = None, seed=None, liggghts: bool = False) -> dict:
    """The provenance record stored as attributes of every results file.

    Keys: ``gransim_version``, ``git_commit``, ``created`` (UTC ISO time), ``python``,
    ``numpy``, ``numba``, ``host``, ``parameters`` (JSON), ``seed`` (JSON) and, when
    ``liggghts`` is true, ``liggghts_version``.
    """
    import numba

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
    return rec
