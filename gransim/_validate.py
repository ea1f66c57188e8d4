"""Input checks at the Python boundary (freud-style ``_convert_array``).

Kernels assume contiguous float64/int64 arrays of the right shape; these helpers
produce them or raise :class:`~gransim.errors.InputError` naming what is wrong.
"""

from __future__ import annotations

import os

import numpy as np

from .errors import InputError


def as_array(value, name: str, shape: tuple, dtype=np.float64, finite: bool = True) -> np.ndarray:
    """Convert ``value`` to a C-contiguous array of ``dtype`` with the given shape.

    ``shape`` entries may be ``None`` (any length). Raises :class:`InputError` for a
    wrong number of dimensions, a wrong length, a non-numeric dtype or (when
    ``finite``) NaN/inf entries.
    """
    try:
        arr = np.asarray(value)
    except Exception as exc:  # pragma: no cover - exotic objects
        raise InputError(f"{name}: cannot convert to an array ({exc})") from None
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{name}: expected a numeric array, got dtype {arr.dtype}")
    if np.issubdtype(np.dtype(dtype), np.integer) and arr.dtype.kind == "f":
        if arr.size and not np.all(np.isfinite(arr) & (arr == np.round(arr))):
            raise InputError(f"{name}: expected integer values")
    want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
    if arr.ndim != len(shape):
        raise InputError(f"{name}: expected shape {want}, got {arr.shape}")
    for got, exp in zip(arr.shape, shape):
        if exp is not None and got != exp:
            raise InputError(f"{name}: expected shape {want}, got {arr.shape}")
    arr = np.ascontiguousarray(arr, dtype=dtype)
    if finite and arr.dtype.kind == "f" and not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name}: contains NaN or inf (first at index {tuple(int(b) for b in bad)})")
    return arr


def as_positive_float(value, name: str, allow_zero: bool = False) -> float:
    """A finite positive scalar (or non-negative with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        rel = ">= 0" if allow_zero else "> 0"
        raise InputError(f"{name}: must be finite and {rel}, got {v!r}")
    return v


def as_int(value, name: str, minimum: int, maximum: int | None = None, note: str = "") -> int:
    """An integral number (int, or a float with an integral value) in [minimum, maximum]; ``note``
    is appended to the range in the error (e.g. where the maximum comes from)."""
    try:
        ok = float(value) == int(value)
    except (TypeError, ValueError, OverflowError):
        ok = False
    ok = ok and int(value) >= minimum and (maximum is None or int(value) <= maximum)
    if not ok:
        want = f">= {minimum}" if maximum is None else f"from {minimum} to {maximum}"
        raise InputError(f"{name}: expected an integer {want}{note}, got {value!r}")
    return int(value)


def check_choice(value: str, name: str, choices) -> str:
    """``value`` must be one of ``choices``; the error lists them."""
    if value not in choices:
        raise InputError(f"unknown {name} {value!r}; choose one of: {', '.join(sorted(choices))}")
    return value


def available_memory() -> int | None:
    """Bytes a new allocation can still get (None when unknown).

    The smallest of: ``MemAvailable`` in /proc/meminfo (free plus reclaimable memory), the
    physical memory (``os.sysconf('SC_PHYS_PAGES') * SC_PAGE_SIZE``) and the cgroup v2 limit
    ``memory.max`` minus ``memory.current`` (containers).
    """
    found = []
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    found.append(int(line.split()[1]) * 1024)
                    break
    except (OSError, ValueError, IndexError):
        pass
    try:
        found.append(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        pass
    try:
        with open("/sys/fs/cgroup/memory.max") as fh:
            limit = fh.read().strip()
        if limit != "max":
            with open("/sys/fs/cgroup/memory.current") as fh:
                found.append(int(limit) - int(fh.read().strip()))
    except (OSError, ValueError):
        pass
    found = [v for v in found if v > 0]
    return min(found) if found else None


def format_bytes(n: float) -> str:
    """``n`` bytes as a short human figure (``3.2 GB``)."""
    for unit, size in (("PB", 1e15), ("TB", 1e12), ("GB", 1e9), ("MB", 1e6), ("kB", 1e3)):
        if abs(n) >= size:
            return f"{n / size:.3g} {unit}"
    return f"{n:.0f} B"


def check_memory(estimate: float, what: str, hint: str = "", available: int | None = None) -> float:
    """Refuse a computation whose estimated peak memory (bytes) exceeds the available memory.

    Returns the fraction estimate / available (0 when the available memory is unknown), so a
    caller can warn above, say, 0.5. ``what`` names the input (e.g. ``"n = 1e+09 disks"``),
    ``hint`` says how to make it smaller.
    """
    avail = available_memory() if available is None else available
    if avail is None:
        return 0.0
    if not np.isfinite(estimate) or estimate > avail:
        raise InputError(
            f"{what} needs about {format_bytes(estimate)} of memory, more than the "
            f"{format_bytes(avail)} available{'; ' + hint if hint else ''}"
        )
    return float(estimate) / avail
