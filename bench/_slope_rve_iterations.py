"""RVE Newton iterations per FE Newton iteration of a relaxed slope run (docs/slope.md).

Runs ``gransim.fem.run.run_slope_case`` in process (no output files) with the relaxed RVE and
counts, at every material evaluation of the load path (one per FE Newton iteration), the Newton
iterations of the Gauss points' RVE relaxations (``RelaxedBatch.n_newton``), grouped by the
position of the evaluation in its attempt (1st FE iterate, 2nd, ...; an attempt ends at a commit
or a revert). Prints one JSON line: status, FE iterations, the RVE Newton iterations per point
(mean over the points) by FE iterate, the totals, and the wall and CPU time of the load path.

    PYTHONPATH=. python bench/_slope_rve_iterations.py PACKING.h5 [--mesh 10x5] [--load-steps 4]
        [--protocol service|paper] [--start trial|committed] [--workers N]

``--start`` sets ``RelaxedMaterial(warm_start=...)`` (absent on code before the option: then the
material's own rule). Not a timed test: a measurement with its command.
"""

from __future__ import annotations

import argparse
import json
import os
import time


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packing")
    ap.add_argument("--mesh", default="10x5")
    ap.add_argument("--load-steps", type=int, default=4)
    ap.add_argument("--protocol", default="service", choices=["service", "paper"])
    ap.add_argument("--start", default=None, choices=["trial", "committed"])
    args = ap.parse_args(argv)

    import numpy as np

    import gransim.fem.run as run
    from gransim.fem.materials import RVEMaterial
    from gransim.fem.mesh import SlopeGeometry
    from gransim.io import load_packing
    from gransim.rve import RelaxedMaterial

    cols, rows = (int(v) for v in args.mesh.split("x"))
    kw = {} if args.start is None else {"warm_start": args.start}
    inner = RelaxedMaterial(load_packing(args.packing), run.NORMAL_STIFFNESS, **kw)
    mat = RVEMaterial(inner)
    phase = {"path": False}
    attempt: list = []  # per evaluation of the current attempt: (mean, max) RVE Newton iterations
    attempts: list = []  # (committed?, [(mean, max), ...])
    evaluate, commit, revert = inner.evaluate, inner.commit, inner.revert

    def rec_evaluate(F, *a, **k):
        b = evaluate(F, *a, **k)
        if phase["path"]:
            attempt.append((float(np.mean(b.n_newton)), int(np.max(b.n_newton)), int(np.sum(b.n_newton))))
        return b

    def close(committed):
        if phase["path"] and attempt:
            attempts.append((committed, list(attempt)))
        attempt.clear()

    def rec_commit():
        close(True)
        commit()

    def rec_revert():
        close(False)
        revert()

    inner.evaluate, inner.commit, inner.revert = rec_evaluate, rec_commit, rec_revert
    path = run.run_load_steps

    def rec_path(*a, **k):
        phase["path"] = True
        c0 = os.times()
        t0 = time.perf_counter()
        try:
            return path(*a, **k)
        finally:
            c1 = os.times()
            phase["wall"] = time.perf_counter() - t0
            phase["cpu"] = (c1.user - c0.user) + (c1.system - c0.system)
            phase["path"] = False

    run.run_load_steps = rec_path
    t0 = time.perf_counter()
    s = run.run_slope_case(
        args.protocol,
        material=mat,
        geometry=SlopeGeometry(columns=cols, rows=rows),
        load_steps=args.load_steps,
        out=None,
        figures="none",
    )
    total = time.perf_counter() - t0
    close(False)
    by_pos: dict[int, list] = {}
    for _, evs in attempts:
        for k, ev in enumerate(evs):
            by_pos.setdefault(k + 1, []).append(ev[0])
    conv = [evs for c, evs in attempts if c]
    out = {
        "packing": os.path.basename(args.packing),
        "mesh": args.mesh,
        "protocol": args.protocol,
        "start": args.start or "default",
        "completed": bool(s["completed"]),
        "message": s["message"][:200],
        "fe_iterations": int(s["timing"]["newton_iterations"]),
        "fe_evaluations": sum(len(e) for _, e in attempts),
        "attempts": len(attempts),
        "committed_attempts": len(conv),
        "rve_newton_total": sum(ev[2] for _, e in attempts for ev in e),
        "rve_newton_per_point_per_fe_evaluation": (
            sum(ev[0] for _, e in attempts for ev in e) / max(1, sum(len(e) for _, e in attempts))
        ),
        "mean_per_point_by_fe_iterate": {k: round(float(np.mean(v)), 2) for k, v in sorted(by_pos.items())},
        "last_fe_iterate_of_committed_attempts_mean_max": [
            round(float(np.mean([e[-1][0] for e in conv])), 2) if conv else None,
            max((e[-1][1] for e in conv), default=None),
        ],
        "load_path_wall_s": round(phase.get("wall", float("nan")), 2),
        "load_path_cpu_s": round(phase.get("cpu", float("nan")), 2),
        "material_s": round(float(s["timing"]["material_s"]), 2),
        "whole_case_wall_s": round(total, 2),
        "newton_per_step": [len(st.energy_norms) for st in s["steps"]],
        "energy_norms": [[float(f"{e:.3g}") for e in st.energy_norms] for st in s["steps"]],
        "limit": s["result"].limit and {k: str(v)[:120] for k, v in s["result"].limit.items() if k != "partial"},
    }
    print(json.dumps(out), flush=True)
    return out


if __name__ == "__main__":
    main()
