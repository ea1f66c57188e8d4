"""Checks of command-line values made before any long computation.

Every sub-command that writes a file calls :func:`check_output` (or :func:`check_figure`,
:func:`check_output_dir`) on its option right after parsing, so a run of minutes never ends in
"is a directory", "permission denied" or "unknown image format" (a file is created and removed in
the target directory: the only test that holds for root, read-only mounts and ACLs alike), and
:func:`check_distinct` on its outputs and inputs, so no output overwrites an input or another
output, however the two are spelt (``./x.h5`` and ``x.h5``, a symbolic or a hard link).
:func:`integer`, :func:`number`, :func:`check_number` and :func:`check_count` check numeric
options (finite, in range, a count that fits in 64 bits) with the option's name in the message;
:func:`check_executor_options` checks ``--workers`` / ``--scheduler`` (:mod:`gransim.parallel`).
Each command calls them once, at the top of its handler (tests/foundation/test_cli_options.py
checks every option of every command).
"""

from __future__ import annotations

import argparse
import math
import os
import tempfile
from pathlib import Path

from ..errors import InputError

#: the largest count an option may give: it reaches numpy and numba as a signed 64-bit integer
INT64_MAX = 2**63 - 1

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


def _path_text(path, option: str, what: str = "a file name") -> None:
    """``path`` is a name (argparse of Python 3.11 gives [] for ``--option=--``)."""
    if not isinstance(path, (str, os.PathLike)):
        raise InputError(f"{option}: expected {what}, got {path!r}")


def check_output(path, option: str, suffixes=None) -> Path:
    """``path`` as a writable output file named by ``option`` (e.g. ``"-o/--output"``).

    Raises :class:`InputError` when the path is an existing directory or other non-regular
    file, its parent is not a directory or is not writable (a file is created and removed there),
    or (with ``suffixes``) its suffix is not one of them.
    """
    _path_text(path, option)
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
    if p.exists() and not p.is_file():
        # a device, pipe or socket: the atomic write would replace the node itself (-o /dev/full)
        raise InputError(f"{option}: {str(p)!r} exists and is not a regular file; expected a file name")
    if p.exists() and not os.access(p, os.W_OK):
        raise InputError(f"{option}: {str(p)!r} exists and is not writable")
    _probe_directory(anc, option, p)
    return p


def _probe_directory(directory: Path, option: str, target: Path) -> None:
    """Create and remove a file in ``directory``: :func:`os.access` says yes to root on a read-only
    mount or a pseudo file system (/sys, /proc), where the write would fail after the run."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".gransim-probe-", dir=directory)
    except OSError as exc:
        why = exc.strerror or type(exc).__name__
        raise InputError(f"{option}: cannot write {str(target)!r}: directory {str(directory)!r}: {why}") from None
    os.close(fd)
    try:
        os.unlink(probe)
    except OSError:  # pragma: no cover - removed by someone else
        pass


def check_figure(path, option: str = "--plot") -> Path:
    """``path`` as an image file matplotlib can write (by its suffix)."""
    return check_output(path, option, FIGURE_SUFFIXES)


def check_output_dir(path, option: str) -> Path:
    """``path`` as an output directory named by ``option``: an existing directory, or a path that
    can be created (its first existing ancestor is a writable directory)."""
    _path_text(path, option, "a directory name")
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
    _probe_directory(anc, option, p)
    return p


def same_file(a, b) -> bool:
    """Whether the paths ``a`` and ``b`` name one file: the same inode when both exist (symbolic
    and hard links, ``./x`` and ``x``, ``d/../x``), else the same resolved path."""
    try:
        return os.path.samefile(a, b)
    except OSError:  # one of them does not exist (yet)
        return os.path.normcase(os.path.realpath(a)) == os.path.normcase(os.path.realpath(b))


def check_distinct(outputs, inputs=()) -> None:
    """No output is an input or another output. ``outputs`` and ``inputs`` hold ``(option, path)``
    pairs (a path None is skipped; one option may appear with several paths, e.g. the files a
    command writes into its output directory). Raises :class:`InputError` naming both options."""
    outs = [(o, p) for o, p in outputs if p is not None]
    ins = [(o, p) for o, p in inputs if p is not None]
    for k, (oo, po) in enumerate(outs):
        for oi, pi in ins:
            if same_file(po, pi):
                raise InputError(
                    f"{oo}: {str(po)!r} is the input file of {oi} ({str(pi)!r}); writing it would "
                    "overwrite the input: choose another output name"
                )
        for oo2, po2 in outs[k + 1 :]:
            if same_file(po, po2):
                raise InputError(f"{oo2} and {oo} name the same file {str(po2)!r}; give each output its own name")


def check_input(path, option: str) -> Path:
    """``path`` as an existing regular file named by ``option``."""
    _path_text(path, option)
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
    try:
        v = float(value)
    except OverflowError:  # an integer beyond the float range
        v = math.inf if value > 0 else -math.inf
    except (TypeError, ValueError):  # argparse of Python 3.11 gives [] for "--option=--"
        raise InputError(f"{option}: expected a number, got {value!r}") from None
    bad = not math.isfinite(v)
    if integer and isinstance(value, int) and not bad:  # exact: 2**63 is not <= 2**63 - 1 as floats are
        bad |= low is not None and (value < low or (low_open and value == low))
        bad |= high is not None and (value > high or (high_open and value == high))
    bad |= low is not None and (v < low or (low_open and v == low))
    bad |= high is not None and (v > high or (high_open and v == high))
    if bad:
        lo = "" if low is None else f"{'>' if low_open else '>='} {low:g}"
        hi = "" if high is None else f"{'<' if high_open else '<='} {high:g}"
        want = " and ".join(x for x in (lo, hi) if x)
        kind = "an integer" if integer else "a finite number"
        raise InputError(f"{option}: expected {kind}{' ' + want if want else ''}, got {value!r}")
    return value


def check_count(value, option: str, low: int = 0, high: int | None = None):
    """``value`` (already parsed, or None = not given) an integer in [low, high]; ``high``
    defaults to :data:`INT64_MAX`, shown in the message only when given. Raises
    :class:`InputError` naming ``option``."""
    if value is None:
        return None
    ok = isinstance(value, int) and not isinstance(value, bool)
    ok = ok and value >= low and value <= (INT64_MAX if high is None else high)
    if not ok:
        if high is not None:
            want = f"from {low} to {high}"
        elif isinstance(value, int) and value > INT64_MAX:
            want = f">= {low} and < 2**63 (a 64-bit count)"
        else:
            want = f">= {low}"
        raise InputError(f"{option}: expected an integer {want}, got {value!r}")
    return value


def check_given_values(args, lists=("law_param",)) -> None:
    """No option holds the empty list argparse (Python 3.11) makes of ``--option=--`` (appended
    to a list for an ``append`` option): read as "not given" (``if args.plot:``) it would be
    silently ignored. ``lists``: the options whose default is an empty list."""
    for dest, value in vars(args).items():
        if not isinstance(value, list):
            continue
        if (not value and dest not in lists) or any(isinstance(v, list) and not v for v in value):
            raise InputError(
                f"--{dest.replace('_', '-')}: expected a value, got '--' (the end of the options to argparse)"
            )


def check_executor_options(workers, scheduler) -> None:
    """``--workers N`` (1 to 4x the CPUs, at least 8: a LocalCluster starts N processes) and
    ``--scheduler ADDRESS``, one of them at most (gransim.parallel.add_options)."""
    if workers is not None and scheduler is not None:
        raise InputError(
            "--workers and --scheduler: give one of them (a LocalCluster of N workers, or an "
            "existing cluster's scheduler address)"
        )
    if workers is not None:
        most = max(8, 4 * (os.cpu_count() or 1))
        if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= most:
            raise InputError(
                f"--workers: expected an integer from 1 to {most} (Dask worker processes, at most 4 "
                f"per CPU of this machine), got {workers!r}"
            )
    if scheduler is not None and ("://" not in scheduler and ":" not in scheduler):
        raise InputError(f"--scheduler: expected a scheduler address such as tcp://host:8786, got {scheduler!r}")


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
