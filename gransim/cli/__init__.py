"""The ``gransim`` command line.

Each sub-command lives in a module ``gransim/cli/cmd_<name>.py`` exposing
``register(subparsers)``; modules are discovered here, so adding a command touches
no shared file. Heavy imports stay inside the handlers (``gransim --help`` is fast).
Errors derived from :class:`gransim.errors.GransimError` are printed as one line
and exit with status 2.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys


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


def main(argv=None) -> int:
    from ..errors import GransimError

    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        rc = args.func(args)
    except GransimError as exc:
        print(f"gransim {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"gransim {args.command}: interrupted", file=sys.stderr)
        return 130
    return int(rc or 0)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
