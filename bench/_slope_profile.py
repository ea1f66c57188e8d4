"""Where the CPU time of one ``gransim slope`` process goes: a phase split.

A tool run on its own, not a bench area (no ``run()``)::

    python -m bench._slope_profile [--json FILE] -- slope --protocol service [--out DIR ...]

runs the command line in this process with wrappers around the functions that make up a run and
prints, per phase, the CPU time of the process (``time.process_time``: user + sys of all threads,
so the kernel's second thread counts) and the wall time spent in it, exclusive of the phases
nested inside it (an import inside the final picture counts as an import). Imports are timed by a
wrapper of ``builtins.__import__`` and attributed to the imported top-level package
(``gransim.<sub>`` for gransim's own); numba's cache loads by a wrapper of
``Dispatcher._compile_for_args`` (the first call of every kernel: loading from the disk cache, or
compiling when the cache misses). Everything before this module runs (the interpreter's own
start-up, about 0.03 s) is in the total only. The wrappers cost about 1 us per call.
"""

from __future__ import annotations

import argparse
import builtins
import contextlib
import io
import json
import os
import resource
import sys
import time

#: (row of the table, test on the phase name) in the order printed
GROUPS = [
    ("imports (numpy, numba, scipy, h5py, matplotlib, gransim...)", lambda k: k.startswith("import ")),
    ("numba cache loads", lambda k: k == "numba: first call (cache load)"),
    ("packings: read + most-uniform choice", lambda k: k in ("packings", "material construction")),
    ("RVE candidate sets (cell lists)", lambda k: k == "taylor: candidate sets"),
    ("Taylor kernel (1520 Gauss points a call)", lambda k: k == "taylor: kernel"),
    ("Taylor set assignment, units, rest", lambda k: k in ("taylor: set assignment", "taylor: evaluate", "units")),
    ("assembly (F, forces, stiffness, T^T K T)", lambda k: k == "assembly"),
    ("sparse LU (SuperLU)", lambda k: k == "sparse LU"),
    ("Newton bookkeeping, checks, set-up, CLI", lambda k: k in ("newton", "small-load check", "patch check", "main")),
    ("final picture (PNG)", lambda k: k == "final picture"),
    ("load-settlement PNG", lambda k: k == "load-settlement PNG"),
    ("VTU + slope.h5", lambda k: k in ("VTU", "slope.h5")),
    ("checkpoints (one HDF5 file a step, fsync)", lambda k: k == "checkpoints"),
]


class _Phases:
    """Exclusive wall and CPU time per named phase (a stack of open phases)."""

    def __init__(self):
        self.acc = {}
        self.stack = []

    def _charge(self, now):
        name, w0, c0 = self.stack[-1]
        a = self.acc.setdefault(name, [0.0, 0.0, 0])
        a[0] += now[0] - w0
        a[1] += now[1] - c0
        return a

    def enter(self, name):
        now = (time.perf_counter(), time.process_time())
        if self.stack:
            self._charge(now)
        self.stack.append([name, *now])

    def leave(self):
        now = (time.perf_counter(), time.process_time())
        self._charge(now)[2] += 1
        self.stack.pop()
        if self.stack:
            self.stack[-1][1:] = now

    def wrap(self, obj, attr, name):
        f = getattr(obj, attr)

        def wrapped(*a, **k):
            self.enter(name)
            try:
                return f(*a, **k)
            finally:
                self.leave()

        setattr(obj, attr, wrapped)


def _install(ph: _Phases) -> None:
    real_import = builtins.__import__

    def timed_import(name, globals=None, locals=None, fromlist=(), level=0):
        full = name
        if level > 0 and globals is not None:  # relative: within the importing package
            full = globals.get("__package__") or name
        parts = full.split(".")
        cat = "import " + (".".join(parts[:2]) if parts[0] == "gransim" else parts[0])
        if ph.stack and ph.stack[-1][0] == cat:
            return real_import(name, globals, locals, fromlist, level)
        ph.enter(cat)
        try:
            return real_import(name, globals, locals, fromlist, level)
        finally:
            ph.leave()

    builtins.__import__ = timed_import
    import numba.core.dispatcher as nd  # noqa: PLC0415 - after the import wrapper: counted

    import gransim.fem.materials as materials  # noqa: PLC0415 - after the import wrapper: counted
    import gransim.fem.run as run  # noqa: PLC0415 - after the import wrapper: counted
    import gransim.fem.solver as solver  # noqa: PLC0415 - after the import wrapper: counted
    import gransim.rve.taylor as taylor  # noqa: PLC0415 - after the import wrapper: counted

    ph.wrap(nd.Dispatcher, "_compile_for_args", "numba: first call (cache load)")
    ph.wrap(run, "default_rve_packing", "packings")
    ph.wrap(run, "make_material", "material construction")
    ph.wrap(taylor._RVE, "build", "taylor: candidate sets")
    ph.wrap(taylor.TaylorMaterial, "_assign", "taylor: set assignment")
    ph.wrap(taylor, "_taylor_batch", "taylor: kernel")
    ph.wrap(taylor.TaylorMaterial, "evaluate", "taylor: evaluate")
    ph.wrap(materials.RVEMaterial, "evaluate", "units")
    ph.wrap(solver.Problem, "evaluate", "assembly")
    ph.wrap(solver, "_solve", "sparse LU")
    ph.wrap(solver, "newton", "newton")
    ph.wrap(run, "linear_check", "small-load check")
    ph.wrap(run, "patch_check", "patch check")
    ph.wrap(run, "write_checkpoint", "checkpoints")
    ph.wrap(run, "render_png", "final picture")
    ph.wrap(run, "write_vtu", "VTU")
    ph.wrap(run, "plot_load_settlement", "load-settlement PNG")
    ph.wrap(run, "write_h5", "slope.h5")


def profile(argv) -> dict:
    """Run ``gransim`` with ``argv`` in this process; {phase: {"wall", "cpu", "calls"}, "_total": ...}."""
    w0, c0 = time.perf_counter(), time.process_time()
    ph = _Phases()
    ph.enter("main")
    _install(ph)
    from gransim.cli import main  # noqa: PLC0415 - after the import wrapper: counted

    with contextlib.redirect_stdout(io.StringIO()):  # the command's report
        rc = main(argv)
    ph.leave()
    ru = resource.getrusage(resource.RUSAGE_SELF)
    out = {k: {"wall": v[0], "cpu": v[1], "calls": v[2]} for k, v in ph.acc.items()}
    out["_total"] = {
        "wall": time.perf_counter() - w0,
        "cpu": time.process_time() - c0,
        "cpu_with_interpreter": ru.ru_utime + ru.ru_stime,
        "exit": rc,
    }
    return out


def table(res: dict) -> str:
    """The grouped split (markdown): CPU and wall seconds per group."""
    lines = ["| phase | CPU (s) | wall (s) |", "|---|---|---|"]
    seen = set()
    for label, test in GROUPS:
        keys = [k for k in res if k != "_total" and test(k)]
        seen.update(keys)
        cpu = sum(res[k]["cpu"] for k in keys)
        wall = sum(res[k]["wall"] for k in keys)
        lines.append(f"| {label} | {cpu:.2f} | {wall:.2f} |")
    rest = [k for k in res if k != "_total" and k not in seen]
    if rest:
        lines.append(
            f"| other ({', '.join(sorted(rest))}) | {sum(res[k]['cpu'] for k in rest):.2f} | "
            f"{sum(res[k]['wall'] for k in rest):.2f} |"
        )
    t = res["_total"]
    lines.append(f"| **whole process** | **{t['cpu_with_interpreter']:.2f}** | **{t['wall']:.2f}** |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench._slope_profile", description=__doc__.split("\n")[0])
    ap.add_argument("--json", help="also write the per-phase figures here")
    ap.add_argument("command", nargs=argparse.REMAINDER, help="-- slope --protocol P ... (gransim's arguments)")
    args = ap.parse_args(argv)
    cmd = [a for a in args.command if a != "--"] or ["slope", "--protocol", "service"]
    load0 = " ".join(f"{v:.2f}" for v in os.getloadavg())
    res = profile(cmd)
    load1 = " ".join(f"{v:.2f}" for v in os.getloadavg())
    print(f"gransim {' '.join(cmd)}: exit {res['_total']['exit']}; load average {load0} -> {load1}", file=sys.stderr)
    print(table(res))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
