"""``python -m reference_runs.femxdem``: Guo & Zhao's FEM x DEM biaxial test run by their own code.

Sub-commands::

    run     prepare the RVE (or reuse --rve) and run biaxialSmooth.py; writes OUT/femxdem.h5
    prepare prepareRVE.py only, into OUT (reusable with run --rve OUT)
    plot    q and eps_v against the axial strain, from one or more femxdem.h5, into a PNG

Exit status: 0 done; 1 the run failed or its outputs are incomplete (one message naming the stage,
the file and the job directory); 2 bad usage or Debian's yade / python3-escript missing; 130 / 143
interrupted (SIGINT / SIGTERM: every process of the job is killed first).
"""

from __future__ import annotations

import argparse
import sys

from gransim.errors import GransimError, InputError

from ..errors import ReferenceRunError
from ..runner import Terminated, kill_children_on_signals
from .port import PortError


def _steps_list(text: str) -> tuple:
    try:
        return tuple(int(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated step numbers, got {text!r}") from None


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m reference_runs.femxdem",
        description="Guo & Zhao's FEM x DEM biaxial test, run by their code from Debian's YADE 2023.02a + escript 5.6.",
    )
    sub = p.add_subparsers(dest="command", required=True)

    def rve_options(q):
        q.add_argument("--n-disks", type=int, default=400, help="disks per RVE (400: the benchmark)")
        q.add_argument("--seed", type=int, default=1, help="makeCloud's seed (1: the benchmark)")
        q.add_argument("--timeout", type=float, default=None, help="seconds for the whole command (default: none)")

    r = sub.add_parser("run", help="prepare the RVE and run biaxialSmooth.py")
    r.add_argument("--out", required=True, help="output folder: rve/, job/, femxdem.h5")
    r.add_argument("--nx", type=int, default=8, help="elements across (8: the benchmark)")
    r.add_argument("--ny", type=int, default=16, help="elements along (16: the benchmark)")
    r.add_argument("--steps", type=int, default=100, help="load steps of 1e-4 m (100: the benchmark)")
    r.add_argument("--workers", type=int, default=2, help="processes of msFEM2D's pool (>= 2; the paper: 16)")
    r.add_argument(
        "--field-steps",
        type=_steps_list,
        default=None,
        help="steps whose Gauss-point fields are kept (default: 0 and the last)",
    )
    r.add_argument("--rve", default=None, help="a folder written by `prepare` (default: OUT/rve, prepared or reused)")
    rve_options(r)

    q = sub.add_parser("prepare", help="prepareRVE.py only")
    q.add_argument("--out", required=True, help="folder for 0.yade.gz and rve.txt")
    rve_options(q)

    g = sub.add_parser("plot", help="q and eps_v against the axial strain")
    g.add_argument("h5", nargs="+", help="femxdem.h5 files (one curve each)")
    g.add_argument("-o", "--output", required=True, help="PNG path")
    return p


def _params(a):
    from .run import FemxdemParams

    if a.command == "prepare":
        return FemxdemParams(n_disks=a.n_disks, seed=a.seed, steps=1, field_steps=())
    fs = a.field_steps if a.field_steps is not None else (0, a.steps)
    return FemxdemParams(
        nx=a.nx, ny=a.ny, steps=a.steps, workers=a.workers, field_steps=fs, n_disks=a.n_disks, seed=a.seed
    )


def _check_timeout(t):
    if t is not None and not (t > 0 and t < float("inf")):
        raise InputError(f"--timeout: expected seconds > 0, got {t!r}")
    return t


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    try:
        with kill_children_on_signals():
            if a.command == "plot":
                from .plot import plot_curves

                print(plot_curves(a.h5, a.output))
                return 0
            params = _params(a).checked()
            timeout = _check_timeout(a.timeout)
            from .run import check_installed, prepare_rve, run_biaxial

            check_installed()
            if a.command == "prepare":
                rec, wall = prepare_rve(a.out, params, timeout, reuse=False)
                s = rec.stress
                print(
                    f"{a.out}: {rec.n_bodies} disks, {rec.n_contacts} contacts, "
                    f"stress xx yy {s[0, 0]:.6g} {s[1, 1]:.6g} Pa"
                )
                return 0
            print(run_biaxial(a.out, params, a.rve, timeout))
            return 0
    except InputError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except PortError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except ReferenceRunError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except GransimError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("interrupted: every process of the job killed", file=sys.stderr)
        return 130
    except Terminated as exc:
        print(f"{exc}: every process of the job killed", file=sys.stderr)
        return int(exc.code)


__all__ = ["build_parser", "main"]
