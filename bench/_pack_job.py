"""One ``gransim pack`` run as its own process, for bench/generation.py; prints one JSON line a stage.

``python -m bench._pack_job N SEED METHOD OUT.h5``
    Runs the ``gransim pack`` command (``gransim.cli.main``, default tolerance) on N quartz-sand
    disks with the given seed and ``--method``, and prints, as each FIRE stage of
    :func:`gransim.generation.make_packing` ends, its record of the packing's metadata ``stages``
    (stage, pressure, tol, norm, steps, builds, seconds) with the seconds since the process started
    and the 1-minute load average. So a run stopped by the caller's timeout still tells how far it
    got and where the time went; the caller times the whole process.
"""

from __future__ import annotations

import json
import os
import sys
import time

T0 = time.perf_counter()


def main(argv) -> int:
    n, seed, method, out = argv
    from gransim.cli import main as cli
    from gransim.generation import fire

    run = fire.Minimiser.run

    def logged(self, *a, **k):
        status = run(self, *a, **k)
        rec = dict(self.log[-1], status=status, residual=float(self.residual))
        rec.update(elapsed=round(time.perf_counter() - T0, 2), load=round(os.getloadavg()[0], 2))
        print(json.dumps(rec), flush=True)
        return status

    fire.Minimiser.run = logged
    return cli(["pack", "--n", n, "--seed", seed, "--method", method, "-o", out])


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
