"""Checks of command-line values made before any long computation.

Every sub-command that writes a file calls :func:`check_output` (or :func:`check_figure`,
:func:`check_output_dir`) on its option right after parsing, so a run of minutes never ends in
"is a directory" or "unknown image format". :func:`integer`, :func:`number` and
:func:`check_number` check numeric options (finite, in range) with the option's name in the
message.
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from ..errors import InputError

#: image formats matplotlib's Agg/pdf/svg/ps backends write (matplotlib.figure.Figure.savefig)
FIGURE_SUFFIXES = (
    ".png",
    ".pdf",
    ".svg",
    ".svgz",
    ".eps",
    ".ps",
    ".jpg",
    ".jpeg",
    ".tif",
    ".tiff",
    ".webp",
    ".pgf",
    ".raw",
    ".rgba",
)


def check_output(path, option: str, suffixes=None) -> Path:
    """``path`` as a writable output file named by ``option`` (e.g. ``"-o/--output"``).

    Raises :class:`InputError` when the path is an existing directory, its parent is not a
    directory or is not writable, or (with ``suffixes``) its suffix is not one of them.
    """
    p = Path(path)
    if str(path).strip() == "":
        raise InputError(f"{option}: expected a file name, got an empty string")
    if p.is_dir():
        raise InputError(f"{option}: {str(p)!r} is a directory; expected a file name")
    if suffixes is not None and p.suffix.lower() not in suffixes:
        raise InputError(
            f"{option}: {str(p)!r} has suffix {p.suffix or '(none)'!r}; expected one of {', '.join(suffixes)}"
        )
    parent = p.parent if str(p.parent) else Path(".")
    anc = parent
    while not anc.exists():  # the first existing ancestor must be a writable directory
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"{option}: cannot create {str(p)!r}: {str(anc)!r} is not a directory")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"{option}: cannot write {str(p)!r}: directory {str(anc)!r} is not writable")
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"{option}: {str(p)!r} exists and is not writable")
    return p


def check_figure(path, option: str = "--plot") -> Path:
    """``path`` as an image file matplotlib can write (by its suffix)."""
    return check_output(path, option, FIGURE_SUFFIXES)


def check_output_dir(path, option: str) -> Path:
    """``path`` as an output directory named by ``option``: an existing directory, or a path that
    can be created (its first existing ancestor is a writable directory)."""
    if str(path).strip() == "":
        raise InputError(f"{option}: expected a directory name, got an empty string")
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise InputError(f"{option}: {str(p)!r} exists and is not a directory")
    anc = p
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise InputError(f"{option}: cannot create {str(p)!r}: {str(anc)!r} is not a directory")
    if not os.access(anc, os.W_OK | os.X_OK):
        raise InputError(f"{option}: cannot write into {str(p)!r}: directory {str(anc)!r} is not writable")
    return p


def check_input(path, option: str) -> Path:
    """``path`` as an existing regular file named by ``option``."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"{option}: {str(p)!r}: no such file")
    if p.is_dir():
        raise InputError(f"{option}: {str(p)!r} is a directory; expected a file")
    if not os.access(p, os.R_OK):
        raise InputError(f"{option}: {str(p)!r} is not readable")
    return p


def check_number(
    value, option: str, low=None, high=None, low_open: bool = False, high_open: bool = False, integer: bool = False
):
    """``value`` (already parsed, or None = not given) finite and within [low, high]; ``low_open``
    / ``high_open`` exclude the bound. Raises :class:`InputError` naming ``option``."""
    if value is None:
        return None
    v = float(value)
    bad = not math.isfinite(v)
    bad |= low is not None and (v < low or (low_open and v == low))
    bad |= high is not None and (v > high or (high_open and v == high))
    if bad:
        lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
        hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}"
        want = " and ".join(x for x in (lo, hi) if x)
        kind = "an integer" if integer else "a finite number"
        raise InputError(f"{option}: expected {kind}{' ' + want if want else ''}, got {value!r}")
    return value


def integer(text: str) -> int:
    """argparse ``type`` of a count: an integer, also written as ``1e5`` or ``100_000`` when its
    value is integral (``1.5`` and ``nan`` are refused)."""
    t = str(text).strip()
    try:
        return int(t)
    except ValueError:
        pass
    try:
        v = float(t)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not math.isfinite(v) or v != math.floor(v):
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
    return int(v)  # the handler checks the range, with the option's name


def number(text: str) -> float:
    """argparse ``type`` of a real option: a finite float (``nan``, ``inf`` refused)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return v
