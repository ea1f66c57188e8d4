"""The numeric judge every comparison shares: the worst difference, and never a pass on NaN or inf.

Python's ``max(0.0, nan)`` is 0.0, ``nan <= tol`` and ``nan > tol`` are both False, ``np.nanmax``
drops NaN and ``float("nan") or 1.0`` keeps NaN: each of these, in a verdict, turns a NaN out of
a code into a pass. The functions here are the one place where numbers become a verdict's value:

* :func:`finite_problem` / :func:`require_finite`: a message naming the quantity, the side and
  the first bad entry (``stress of state 3 of lattice-8x8-seed1 (liggghts) is NaN``) when an
  array holds NaN or inf;
* :func:`worst`: the largest of some values, refusing an empty set and any NaN or inf;
  :func:`peak`: the same as a value, NaN instead of a refusal (for a record that then fails);
* :func:`max_rel_diff`: max |a - b| / scale over two arrays, refusing empty or mismatched
  arrays and NaN or inf on either side or in the scale;
* :func:`within`: ``value <= tolerance``, False for a NaN or inf value or a non-finite or negative
  tolerance.

A refusal is a :class:`JudgeError` (:class:`NonFiniteError`, :class:`NoEvidenceError`): the caller
turns it into a failing verdict with that message. It is not a :class:`gransim.errors.GransimError`
on purpose: it means the evidence failed, not that the user's input was bad (exit 1, not 2).
"""

from __future__ import annotations

import math

import numpy as np


class JudgeError(ValueError):
    """The evidence cannot be judged: a failure, whose message names the quantity."""


class NonFiniteError(JudgeError):
    """A value, a reference value, a scale or a tolerance is NaN or inf."""


class NoEvidenceError(JudgeError):
    """Nothing to compare (zero states, rows, frames): never a pass."""


def _side(side) -> str:
    return f" ({side})" if side else ""


def _word(x: float) -> str:
    return "NaN" if math.isnan(x) else ("+inf" if x > 0 else "-inf")


def finite_problem(values, quantity: str, side: str | None = None) -> str | None:
    """None when every entry of ``values`` is finite, else one line naming the quantity, the side,
    what the first bad entry is (NaN, +inf, -inf), where it is (for more than one entry) and how
    many entries are bad. Values that are not numbers at all count as bad (named as such)."""
    try:
        a = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        return f"{quantity}{_side(side)} is not a number ({values!r:.60})"
    bad = ~np.isfinite(a)
    if not bad.any():
        return None
    if a.ndim == 0:
        return f"{quantity}{_side(side)} is {_word(float(a))}"
    first = tuple(int(i) for i in np.argwhere(bad)[0])
    where = first[0] if len(first) == 1 else first
    n = int(bad.sum())
    more = f" ({n} of {a.size} entries non-finite)" if n > 1 else ""
    return f"{quantity}{_side(side)} is {_word(float(a[first]))} at entry {where}{more}"


def require_finite(values, quantity: str, side: str | None = None) -> np.ndarray:
    """``values`` as a float array; :class:`NonFiniteError` (see :func:`finite_problem`) when any
    entry is NaN or inf."""
    msg = finite_problem(values, quantity, side)
    if msg:
        raise NonFiniteError(msg)
    return np.asarray(values, dtype=float)


def worst(values, quantity: str) -> float:
    """The largest of ``values`` (any iterable of numbers or arrays, flattened).

    :class:`NoEvidenceError` when there is none, :class:`NonFiniteError` when any is NaN or inf:
    unlike ``max()`` (which keeps a 0.0 before a NaN) and ``np.nanmax`` (which drops NaN)."""
    parts = [np.ravel(np.asarray(v, dtype=float)) for v in values]
    a = np.concatenate(parts) if parts else np.zeros(0)
    if a.size == 0:
        raise NoEvidenceError(f"{quantity}: nothing to compare (no values)")
    require_finite(a, quantity)
    return float(a.max())


def max_rel_diff(
    a,
    b,
    quantity: str,
    sides=("native", "reference"),
    scale=None,
    zero_scale: str = "absolute",
) -> float:
    """max |a - b| / scale over every entry (a 0-d, 1-d or n-d pair of equal shape).

    ``scale`` defaults to max |b| (``b`` is the reference side). ``zero_scale`` says what a zero
    scale means: ``"absolute"`` (the difference itself is returned: both sides must then be zero
    to within the tolerance) or ``"fail"`` (:class:`NoEvidenceError`: nothing to be relative to).

    Refuses (:class:`JudgeError`, naming ``quantity`` and the side from ``sides``) empty arrays,
    arrays of different shapes, and NaN or inf in ``a``, ``b`` or ``scale``; so the value returned
    is always finite and a ``<= tolerance`` on it means what it says.
    """
    if zero_scale not in ("absolute", "fail"):
        raise ValueError(f"zero_scale: expected 'absolute' or 'fail', got {zero_scale!r}")
    a_name, b_name = sides
    x = require_finite(a, quantity, a_name)
    y = require_finite(b, quantity, b_name)
    if x.shape != y.shape:
        raise JudgeError(f"{quantity}: {a_name} has shape {x.shape} but {b_name} has {y.shape}")
    if x.size == 0:
        raise NoEvidenceError(f"{quantity}: nothing to compare (no values on either side)")
    d = float(np.abs(x - y).max())
    s = float(np.abs(y).max()) if scale is None else float(require_finite(scale, f"scale of {quantity}"))
    if not math.isfinite(d):  # finite inputs whose difference overflows
        raise NonFiniteError(f"{quantity}: |{a_name} - {b_name}| is {_word(d)}")
    if s > 0:
        return d / s
    if zero_scale == "fail":
        raise NoEvidenceError(f"{quantity}: the scale is {s!r}, nothing to be relative to")
    return d


def peak(values) -> float:
    """The largest of ``values`` (numbers or arrays, flattened) as a verdict's value
    (``validation.core.compare``): NaN when any is NaN or when there is none, inf when any is
    +-inf, so the verdict fails and never passes vacuously; unlike ``max()`` (keeps a 0.0 before
    a NaN) and ``np.nanmax`` (drops NaN)."""
    parts = [np.ravel(np.asarray(v, dtype=float)) for v in values]
    a = np.concatenate(parts) if parts else np.zeros(0)
    if a.size == 0 or np.isnan(a).any():
        return math.nan
    if not np.isfinite(a).all():  # a -inf would be dropped by max() just the same
        return math.inf
    return float(a.max())


def defined_diff(a, b) -> float:
    """max |a - b| over the entries both sides define, for quantities where NaN means "undefined"
    by definition (the void-cell alignment of a cell whose gradient is zero): NaN (a failing value)
    when the two sides leave different entries undefined or none is defined, inf when an entry is
    inf, so a NaN on one side only is never dropped the way ``np.nanmax`` drops it."""
    x, y = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if x.shape != y.shape:
        return math.nan
    nx, ny = np.isnan(x), np.isnan(y)
    if (nx != ny).any() or nx.all():
        return math.nan
    return peak([np.abs(x[~nx] - y[~ny])])


def defined_peak(values) -> float:
    """max |values| over the defined (non-NaN) entries: the scale of a quantity judged with
    :func:`defined_diff`; NaN when none is defined, inf when one is inf."""
    x = np.abs(np.asarray(values, dtype=float))
    x = x[~np.isnan(x)]
    return peak([x])


def within(value, tolerance) -> bool:
    """``value <= tolerance``, False for a NaN or inf value or a NaN, inf or negative tolerance."""
    try:
        v, t = float(value), float(tolerance)
    except (TypeError, ValueError):
        return False
    return math.isfinite(v) and math.isfinite(t) and t >= 0 and v <= t


def verdict_problem(value, tolerance, quantity: str) -> str | None:
    """None when ``value`` and ``tolerance`` can be judged, else why not (naming ``quantity``)."""
    return finite_problem(value, quantity) or (
        finite_problem(tolerance, f"tolerance of {quantity}")
        or (f"tolerance of {quantity} is negative ({float(tolerance)!r})" if float(tolerance) < 0 else None)
    )


__all__ = [
    "JudgeError",
    "NoEvidenceError",
    "NonFiniteError",
    "defined_diff",
    "defined_peak",
    "finite_problem",
    "max_rel_diff",
    "peak",
    "require_finite",
    "verdict_problem",
    "within",
    "worst",
]
