"""The benchmark DEM deck: law, loading and assembly, shared by bench/dem.py (the driver) and
bench/_dem_job.py (the measured native job).

Kept apart from bench/dem.py so that the measured job imports what a user's script would
(``gransim.dem``) and not the driver's deck writers (``reference_runs``: 0.03 s of every
whole-process figure before, docs/startup.md).
"""

from __future__ import annotations

import math

from gransim.dem import DEMSettings, Loading
from gransim.dem.lattice import lattice_packing

SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
# fixed box: under a strain rate or servo the box displacement eats the skin (LIGGGHTS' rebuild
# rule) faster in larger boxes, so rebuilds per step would grow with N in both codes alike
LOADING = Loading()


def assembly(n: int):
    """The benchmark assembly nearest to ``n`` disks (triangular lattice, even rows)."""
    nx = max(3, round(math.sqrt(n * 2 / math.sqrt(3))))
    ny = max(4, round(n / nx))
    ny += ny % 2
    return lattice_packing(nx, ny, seed=1, spread=0.1, compression=0.08)
