"""The ``gransim`` command line.

Each sub-command lives in a module ``gransim/cli/cmd_<name>.py`` exposing
``register(subparsers)``; modules are discovered here, so adding a command touches
no shared file. Heavy imports stay inside the handlers (``gransim --help`` is fast).
Errors derived from :class:`gransim.errors.GransimError` are printed as one line
and exit with status 2; any other exception is one line too (``internal error``, status 1; the
traceback with ``GRANSIM_TRACEBACK=1``); a closed output pipe ends quietly (status 141).
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
import traceback


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="gransim",
        description="Micromechanics of 2D granular materials: packings, Taylor RVEs, DEM, void cells, "
                    "LIGGGHTS cross-checks.")
    parser.add_argument("--version", action="version", version=f"gransim {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name.startswith("cmd_"):
            importlib.import_module(f"{__name__}.{info.name}").register(sub)
    return parser


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
        print(f"gransim {command}: error: out of memory ({type(exc).__name__}: {str(exc) or 'no details'}); "
              "reduce the problem size or free memory", file=sys.stderr)
    elif isinstance(exc, OSError) and exc.errno is not None:
        # the system refused something (disk full, permissions changed during the run...): not a bug
        print(f"gransim {command}: error: {type(exc).__name__}: {exc}", file=sys.stderr)
    else:
        print(f"gransim {command}: internal error: {type(exc).__name__}: {exc} (rerun with "
              "GRANSIM_TRACEBACK=1 for the traceback; please report it)", file=sys.stderr)
    return 1


def _main(argv) -> int:
    from ..errors import GransimError

    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit:
        sys.stdout.flush()  # --help / --version into a closed pipe: BrokenPipeError, handled in main
        raise
    try:
        rc = args.func(args)
        sys.stdout.flush()
    except GransimError as exc:
        print(f"gransim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"gransim {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        raise
    except Exception as exc:  # noqa: BLE001 - no traceback reaches a user (see _internal_error)
        return _internal_error(args.command, exc)
    return int(rc or 0)


def main(argv=None) -> int:
    """Run the command line; returns the exit status.

    0 success, 1 failure of the computation (or an internal error, printed as one line), 2 bad
    input (:class:`~gransim.errors.GransimError`, argparse usage errors), 130 interrupted, 141
    output pipe closed by the reader (``gransim ... | head``: stops quietly, like SIGPIPE).
    """
    try:
        return _main(argv)
    except BrokenPipeError:
        _quiet_stdout()
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
