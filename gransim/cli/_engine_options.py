"""The engine options that ``gransim biaxial`` and ``gransim shear`` share, defined once:
``--order``, ``--threads``, ``--checkpoint-every``, ``--resume`` (docs/dem.md, "One engine")."""

from __future__ import annotations

#: the orderings (gransim.dem.engine.ORDERS, repeated here so that the parser needs no numba)
ORDERS = ("code", "fast")


def add_engine_options(p, threads_help: str) -> None:
    """Add the shared engine options to the sub-parser ``p``; ``threads_help``: what runs on threads."""
    p.add_argument(
        "--order",
        choices=ORDERS,
        default="code",
        help="code (the code's order: bit for bit with LIGGGHTS, to round-off with LAMMPS' sheared cell; default) "
        "or fast (spatially sorted, half list, banded threads: the same physics to round-off over short "
        "horizons, within the code order's chaos envelope over long ones; docs/performance.md)",
    )
    p.add_argument("--threads", type=int, help=f"numba threads ({threads_help})")
    p.add_argument(
        "--checkpoint-every",
        type=int,
        default=50000,
        help="write a checkpoint every N steps (default 50000; 0: none but at the end or on an interruption)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the run in --output from its checkpoint (the same options; bit for bit the uninterrupted run)",
    )
