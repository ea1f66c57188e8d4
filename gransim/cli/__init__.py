"""The ``gransim`` command line.

Each built-in sub-command lives in a module ``gransim/cli/cmd_<name>.py`` exposing
``register(subparsers)``; modules are discovered here, so adding a command touches no shared file.
Packages above gransim (``reference_runs``: ``reference``, ``replay``; ``validation``:
``validate``) add theirs as plug-ins: a ``register(subparsers)`` callable named in the
entry-point group :data:`ENTRY_POINT_GROUP` of their distribution's metadata (``pyproject.toml``,
``[project.entry-points."gransim.commands"]``), read with :mod:`importlib.metadata`. gransim itself
never imports them (tests/test_boundaries.py). A plug-in that fails to load is named on stderr and
left out; the other commands work.

Heavy imports (numpy, numba, h5py, matplotlib: every ``cmd_*`` module is imported by ``gransim --help``
and by every command) stay inside the handlers, each marked ``# noqa: PLC0415 - start-up: <module>``;
the light ones (the standard library, :mod:`gransim.errors`, ``_paths``) are at the top.
Errors derived from :class:`gransim.errors.GransimError` are printed as one line
and exit with status 2; any other exception is one line too (``internal error``, status 1; the
traceback with ``GRANSIM_TRACEBACK=1``); a closed output pipe ends quietly (status 141).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import os
import pkgutil
import sys
import traceback

from .. import __version__
from ..errors import GransimError
from ..progress import stop_signals, written_results

#: the entry-point group in which packages register ``gransim`` sub-commands: each entry point is a
#: callable ``register(subparsers)`` that adds one sub-command (its name is the entry point's)
ENTRY_POINT_GROUP = "gransim.commands"


def build_parser(argv=None) -> argparse.ArgumentParser:
    """The parser of every command: the built-in ``cmd_*`` modules, then the plug-ins of
    :data:`ENTRY_POINT_GROUP`. With ``argv`` whose command is a built-in one the plug-ins are not
    read (reading the installed distributions' metadata is most of a plug-in's start-up cost)."""
    parser = argparse.ArgumentParser(
        prog="gransim",
        description="Micromechanics of 2D granular materials: packings, Taylor RVEs, DEM, void cells, "
        "LIGGGHTS and LAMMPS cross-checks.",
    )
    parser.add_argument("--version", action="version", version=f"gransim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{info.name}").register(sub)
    command = next((a for a in (argv or ()) if not str(a).startswith("-")), None)
    if argv is not None and command in sub.choices:
        return parser
    for ep in plugin_commands():
        if ep.name in sub.choices:
            print(
                f"gransim: warning: command plug-in {ep.name!r} ({ep.value}) left out: a command of that name exists",
                file=sys.stderr,
            )
            continue
        try:
            register = ep.load()
            register(sub)
        except Exception as exc:  # noqa: BLE001 - a broken plug-in must not take the other commands down
            sub.choices.pop(ep.name, None)
            print(
                f"gransim: warning: command plug-in {ep.name!r} ({ep.value}) failed to load: "
                f"{type(exc).__name__}: {exc}",
                file=sys.stderr,
            )
    return parser


def plugin_commands() -> list:
    """The entry points of :data:`ENTRY_POINT_GROUP` in the installed distributions, by name
    (:class:`importlib.metadata.EntryPoint`; one per name, the first distribution's)."""
    from importlib.metadata import entry_points  # noqa: PLC0415 - start-up: only when the plug-ins are read

    seen = {}
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        seen.setdefault(ep.name, ep)
    return [seen[k] for k in sorted(seen)]


def _quiet_stdout() -> None:
    """Point file descriptor 1 at /dev/null after a broken pipe, so that the interpreter's final
    flush does not raise again (Python docs, "Note on SIGPIPE" in the ``signal`` module)."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # stdout without a descriptor (captured)
        pass


def _internal_error(command: str, exc: BaseException) -> int:
    """One line for an exception gransim did not raise on purpose (status 1); the traceback
    only with ``GRANSIM_TRACEBACK=1``."""
    if os.environ.get("GRANSIM_TRACEBACK", "").strip() not in ("", "0"):
        traceback.print_exception(type(exc), exc, exc.__traceback__, file=sys.stderr)
    if isinstance(exc, MemoryError):
        print(
            f"gransim {command}: error: out of memory ({type(exc).__name__}: {str(exc) or 'no details'}); "
            "reduce the problem size or free memory",
            file=sys.stderr,
        )
    elif isinstance(exc, OSError) and type(exc).__name__ == "OutputWriteError":
        print(f"gransim {command}: error: {exc}", file=sys.stderr)  # names the file and the cause
    elif isinstance(exc, OSError) and exc.errno is not None:
        # the system refused something (disk full, permissions changed during the run...): not a bug
        print(f"gransim {command}: error: {type(exc).__name__}: {exc}", file=sys.stderr)
    else:
        print(
            f"gransim {command}: internal error: {type(exc).__name__}: {exc} (rerun with "
            "GRANSIM_TRACEBACK=1 for the traceback; please report it)",
            file=sys.stderr,
        )
    return 1


def _main(argv) -> int:
    parser = build_parser(sys.argv[1:] if argv is None else argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit:
        sys.stdout.flush()  # --help / --version into a closed pipe: BrokenPipeError, handled in main
        raise
    try:
        with stop_signals():
            rc = args.func(args)
        sys.stdout.flush()
    except GransimError as exc:
        print(f"gransim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        # SIGINT (Ctrl-C), SIGTERM or SIGHUP: 128 + the signal's number, what a shell reports for it
        signum = getattr(exc, "signum", 2)
        msg = getattr(exc, "message", "")
        done = written_results()
        if done:  # the signal came after the result was written: it is whole
            msg = (msg + "; " if msg else "") + f"written complete before the signal: {', '.join(done)}"
        print(f"gransim {args.command}: interrupted" + (f": {msg}" if msg else ""), file=sys.stderr)
        return 128 + int(signum)
    except BrokenPipeError:
        raise
    except Exception as exc:  # noqa: BLE001 - no traceback reaches a user (see _internal_error)
        return _internal_error(args.command, exc)
    return int(rc or 0)


def main(argv=None) -> int:
    """Run the command line; returns the exit status.

    0 success, 1 failure of the computation (or an internal error, printed as one line; a full
    disk), 2 bad input (:class:`~gransim.errors.GransimError`, argparse usage errors), 130
    interrupted (SIGINT, Ctrl-C), 143 terminated (SIGTERM), 129 hang-up of its terminal (SIGHUP),
    141 output pipe closed by the reader (``gransim ... | head``: stops quietly, like SIGPIPE). A
    DEM run stopped by SIGINT, SIGTERM or SIGHUP
    writes its file as an incomplete run with a checkpoint at the step it stopped at
    (:mod:`gransim.progress`: the signal is acted on between chunks of steps, never lost).
    """
    try:
        return _main(argv)
    except BrokenPipeError:
        _quiet_stdout()
        return 141


def entry() -> None:
    """The ``gransim`` console script and ``python -m gransim``: :func:`main`, then exit.

    Before the interpreter's teardown every object still alive is moved to the collector's
    permanent generation (:func:`gc.freeze`), so the final collections do not walk numba's
    hundreds of thousands of objects: 0.10-0.20 s of the exit at 1e5 disks, measured
    (docs/startup.md). Unlike ``os._exit`` it keeps the rest of the exit: ``atexit`` handlers
    run, non-daemon threads are joined, standard streams are flushed, objects freed by reference
    counting are finalized. What it gives up is finalizing objects caught in reference cycles
    (a file object left open inside a cycle would not be flushed); gransim writes every result
    atomically and closes it before returning, so no result depends on that. Only :func:`main` is
    for in-process callers (tests): freezing belongs to the process's end.
    """
    rc = main()
    gc.freeze()
    sys.exit(rc)


if __name__ == "__main__":  # pragma: no cover
    entry()
