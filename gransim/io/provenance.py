"""Provenance of results: gransim version, git commit, time, machine, LIGGGHTS version."""

from __future__ import annotations

import datetime as _dt
import functools
import json
import platform
import shutil
import subprocess
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


@functools.lru_cache(maxsize=1)
def liggghts_version() -> str | None:
    """Version of the installed Debian ``liggghts`` package, or None when absent."""
    if shutil.which("liggghts") is None:
        return None
    try:
        out = subprocess.run(["dpkg-query", "-W", "-f=${Version}", "liggghts"], capture_output=True,
                             text=True, timeout=10).stdout.strip()
        return f"LIGGGHTS-PUBLIC {out} (Debian)" if out else "LIGGGHTS (version unknown)"
    except (OSError, subprocess.SubprocessError):
        return "LIGGGHTS (version unknown)"


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
