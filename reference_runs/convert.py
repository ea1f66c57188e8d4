"""Parsed LIGGGHTS output -> gransim quantities (tension-positive stress series, particle series).

Helpers for deck-specific readers (Taylor, biaxial): they apply the sign convention of
:mod:`reference_runs.conventions` and stack dump frames into time series, checking that every
frame holds the same particles.
"""

from __future__ import annotations

import numpy as np

from gransim.errors import ResultFileError

from .conventions import cauchy_from_pressure
from .parsers import ThermoRun


def stress_series(
    runs, pxx: str = "c_p[1]", pyy: str = "c_p[2]", pxy: str = "c_p[4]", drop_repeated: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Cauchy stress series (tension positive, N/m) from the ``compute pressure`` thermo columns.

    Parameters
    ----------
    runs : a :class:`ThermoRun` or a sequence of them (consecutive ``run`` commands).
    pxx, pyy, pxy : thermo column names of the xx, yy, xy pressure components.
    drop_repeated : drop a row whose step equals the previous row's (each ``run`` repeats the
        last step of the previous one in its first row).

    Returns
    -------
    ``(steps (T,) int64, sigma (T, 2, 2))`` with sigma = -p.
    """
    if isinstance(runs, ThermoRun):
        runs = [runs]
    steps, sig = [], []
    for run in runs:
        s = run.steps
        p = cauchy_from_pressure(run[pxx], run[pyy], run[pxy])
        for a in range(len(s)):
            if drop_repeated and steps and s[a] == steps[-1]:
                continue
            steps.append(int(s[a]))
            sig.append(p[a])
    return np.array(steps, np.int64), np.array(sig).reshape(len(sig), 2, 2)


def particle_series(frames, columns) -> tuple[np.ndarray, np.ndarray, dict]:
    """Stack ``dump custom`` frames into (T, N) arrays per column.

    Returns ``(steps (T,), ids (N,), {column: (T, N)})``. Raises ResultFileError if the frames
    do not hold the same particle ids (e.g. lost atoms).
    """
    if not frames:
        raise ResultFileError("no dump frames")
    ids = frames[0]["id"]
    for fr in frames[1:]:
        if len(fr) != len(ids) or not np.array_equal(fr["id"], ids):
            raise ResultFileError(
                f"dump frame at step {fr.step} holds other particles than step "
                f"{frames[0].step} ({len(fr)} vs {len(ids)} atoms)"
            )
    out = {c: np.stack([fr[c] for fr in frames]) for c in columns}
    return np.array([fr.step for fr in frames], np.int64), ids.copy(), out


__all__ = ["particle_series", "stress_series"]
