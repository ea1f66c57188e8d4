"""Does the trial start end where the committed start would? Measured at every commit of a slope run.

Runs ``gransim.fem.run.run_slope_case`` in process with the relaxed RVE started from the previous
FE iterate's trial (``RelaxedMaterial(warm_start="trial")``). At every commit (a converged
(sub-)increment) the committed F is evaluated again by a second material holding the same
committed history, started from the committed state (``warm_start="committed"``), and the two are
compared per Gauss point: max |P_trial - P_committed| / max |P|, the same for A, the number of
points whose P differs by more than 1e-10 and 1e-6 (another energy minimum), the extreme relative
energy differences (W_trial - W_committed) / |W_committed| (negative: the trial start found the
lower minimum), and the RVE Newton iterations of both. One JSON line per commit.

    PYTHONPATH=. python bench/_slope_start_dependence.py PACKING.h5 [--mesh 10x5] [--load-steps 4]
        [--protocol service|paper]
"""

from __future__ import annotations

import argparse
import json


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("packing")
    ap.add_argument("--mesh", default="10x5")
    ap.add_argument("--load-steps", type=int, default=4)
    ap.add_argument("--protocol", default="service", choices=["service", "paper"])
    args = ap.parse_args(argv)

    import numpy as np

    import gransim.fem.run as run
    from gransim.fem.materials import RVEMaterial
    from gransim.fem.mesh import SlopeGeometry
    from gransim.io import load_packing
    from gransim.rve import RelaxedMaterial

    cols, rows = (int(v) for v in args.mesh.split("x"))
    pk = load_packing(args.packing)
    inner = RelaxedMaterial(pk, run.NORMAL_STIFFNESS, warm_start="trial")
    shadow = RelaxedMaterial(pk, run.NORMAL_STIFFNESS, warm_start="committed")
    last = {}
    evaluate, commit = inner.evaluate, inner.commit

    def rec_evaluate(F, *a, **k):
        b = evaluate(F, *a, **k)
        last["F"], last["b"] = np.array(F), b
        return b

    def rec_commit():
        shadow._committed = dict(inner._committed)  # the same committed history (immutable states)
        s = shadow.evaluate(last["F"])
        shadow.revert()
        b = last["b"]
        dP = np.abs(s.piola - b.piola).max(axis=(1, 2)) / np.abs(b.piola).max()
        dA = np.abs(s.tangent - b.tangent).reshape(len(dP), -1).max(axis=1) / np.abs(b.tangent).max()
        dW = (b.energy - s.energy) / np.abs(s.energy)
        rec = {
            "points": len(dP),
            "P_rel_max": float(dP.max()),
            "A_rel_max": float(dA.max()),
            "n_P_above_1e-10": int((dP > 1e-10).sum()),
            "n_P_above_1e-6": int((dP > 1e-6).sum()),
            "dW_rel_min": float(dW.min()),
            "dW_rel_max": float(dW.max()),
            "rve_newton_trial": int(b.n_newton.sum()),
            "rve_newton_committed": int(s.n_newton.sum()),
        }
        print(json.dumps(rec), flush=True)
        commit()

    inner.evaluate, inner.commit = rec_evaluate, rec_commit
    s = run.run_slope_case(
        args.protocol,
        material=RVEMaterial(inner),
        geometry=SlopeGeometry(columns=cols, rows=rows),
        load_steps=args.load_steps,
        out=None,
        figures="none",
    )
    print(json.dumps({"completed": bool(s["completed"]), "message": s["message"][:300]}))


if __name__ == "__main__":
    main()
