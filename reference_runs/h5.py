"""Parsed LIGGGHTS output into gransim HDF5 files (layout in docs/schema_reference_runs.md).

Written with :func:`gransim.io.atomic_h5` (``liggghts=True``: the LIGGGHTS version joins the
provenance attributes). Values are stored exactly as LIGGGHTS printed them (no sign flip);
the kind-specific writers (e.g. :mod:`reference_runs.decks.taylor`) store converted
quantities next to them with the convention of :mod:`reference_runs.conventions`.

Layout of ``write_output_h5``::

    /thermo/run_000/<column>      (T,) float64; attrs columns (JSON list), complete, header_line
    /dumps/<name>/frame_000000/<column>   (n,) ; attrs step, box (3,2), boundary
    root attrs: format, kind, provenance..., liggghts_log_version, n_errors, n_warnings
"""

from __future__ import annotations

import json
import types

import numpy as np

from gransim.errors import ResultFileError
from gransim.io import atomic_h5, open_result

from .parsers import DumpFrame, LogFile, ThermoRun


def _h5name(col: str) -> str:
    return col.replace("/", "|")


def write_log_group(group, log: LogFile) -> None:
    """Store the thermo runs of ``log`` under ``group`` (one sub-group per run)."""
    group.attrs["version"] = log.version or "unknown"
    group.attrs["n_runs"] = len(log.runs)
    group.attrs["warnings"] = json.dumps([str(w) for w in log.warnings])
    for r, run in enumerate(log.runs):
        g = group.create_group(f"run_{r:03d}")
        g.attrs["columns"] = json.dumps(list(run.columns))
        g.attrs["complete"] = bool(run.complete)
        g.attrs["header_line"] = int(run.header_line)
        for k, c in enumerate(run.columns):
            g.create_dataset(_h5name(c), data=run.data[:, k])


def write_frames_group(group, frames) -> None:
    """Store dump frames (custom or local) under ``group``, one sub-group per frame."""
    group.attrs["n_frames"] = len(frames)
    for f, fr in enumerate(frames):
        g = group.create_group(f"frame_{f:06d}")
        g.attrs["step"] = int(fr.step)
        g.attrs["box"] = fr.box
        g.attrs["boundary"] = fr.boundary
        g.attrs["columns"] = json.dumps(list(fr.names))
        for c in fr.names:
            g.create_dataset(_h5name(c), data=fr[c])


def write_output_h5(
    path,
    log: LogFile | None = None,
    dumps: dict | None = None,
    kind: str = "liggghts-output",
    parameters: dict | None = None,
    seed=None,
):
    """Write a parsed log and dumps to ``path`` atomically; returns the path.

    ``dumps`` maps a name (e.g. ``"particles"``, ``"contacts"``) to a tuple of
    :class:`~reference_runs.parsers.DumpFrame`.
    """
    with atomic_h5(path, kind=kind, parameters=parameters, seed=seed, liggghts=True) as f:
        if log is not None:
            write_log_group(f.create_group("thermo"), log)
            f.attrs["n_errors"] = len(log.errors)
            f.attrs["n_warnings"] = len(log.warnings)
        for name, frames in (dumps or {}).items():
            write_frames_group(
                f.create_group("dumps").require_group(name) if "dumps" not in f else f["dumps"].create_group(name),
                frames,
            )
    return path


def read_thermo_h5(path) -> tuple:
    """The thermo runs stored by :func:`write_output_h5`, as :class:`ThermoRun` objects."""
    with open_result(path) as f:
        if "thermo" not in f:
            raise ResultFileError(f"{path}: no /thermo group")
        runs = []
        for name in sorted(f["thermo"]):
            g = f["thermo"][name]
            cols = tuple(json.loads(g.attrs["columns"]))
            data = np.column_stack([g[_h5name(c)][()] for c in cols]) if cols else np.zeros((0, 0))
            runs.append(ThermoRun(cols, data, bool(g.attrs["complete"]), int(g.attrs["header_line"])))
        return tuple(runs)


def read_frames_h5(path, name: str) -> tuple:
    """The dump frames stored under ``/dumps/<name>`` by :func:`write_output_h5`."""
    with open_result(path) as f:
        if "dumps" not in f or name not in f["dumps"]:
            raise ResultFileError(f"{path}: no /dumps/{name} group")
        out = []
        for fname in sorted(f["dumps"][name]):
            g = f["dumps"][name][fname]
            cols = json.loads(g.attrs["columns"])
            out.append(
                DumpFrame(
                    int(g.attrs["step"]),
                    g.attrs["box"][()],
                    None,
                    str(g.attrs["boundary"]),
                    types.MappingProxyType({c: g[_h5name(c)][()] for c in cols}),
                )
            )
        return tuple(out)


__all__ = ["read_frames_h5", "read_thermo_h5", "write_frames_group", "write_log_group", "write_output_h5"]
