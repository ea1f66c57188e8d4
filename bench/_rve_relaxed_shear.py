"""Relaxed RVE under simple shear F = [[1, g], [0, 1]] from w = 0 against a warm path in steps of 1e-4.

For each standard RVE and g: rho = max net contact force on a disk / mean contact force (an
independent numpy force sum at x = F X + w*), the energy W_rel (J/m^2), held and rattler counts,
Newton iterations and wall time of the cold call; then the same for the warm path and the relative
differences of W_rel and P. Usage: ``PYTHONPATH=. python bench/_rve_relaxed_shear.py rve-70-1 rve-70-2``.
"""

import sys
import tempfile
import time

import numpy as np

from gransim.contacts import find_neighbours
from gransim.generation import standard_packings
from gransim.io import load_packing
from gransim.rve import RelaxedMaterial

KN = 2.8e7  # N/m, the slope problem's E_n


def rho(p, F, r) -> float:
    """Largest net contact force on a disk over the mean contact force at x = F X + w*."""
    x = p.positions @ F.T + r.fluctuation
    nl = find_neighbours(x, p.radii, F @ p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    f = -KN * eps[c, None] * nl.branch[c] / nl.distance[c, None]
    net = np.zeros((p.n, 2))
    np.add.at(net, nl.i[c], f)
    np.add.at(net, nl.j[c], -f)
    return float(np.max(np.abs(net)) / (KN * eps[c].mean()))


def line(p, F, r) -> str:
    return (
        f"rho={rho(p, F, r):.2e} W={r.energy:.6f} held={r.n_held} rattlers={int(r.rattlers.sum())} newton={r.n_newton}"
    )


def main(names) -> None:
    paths = standard_packings(tempfile.mkdtemp(), names=names)
    for name in names:
        p = load_packing(paths[name])
        mat = RelaxedMaterial(p, KN)
        mat(np.eye(2))  # compile
        for g in (5e-4, 7e-4, 1e-3, 2e-3):
            F = np.array([[1.0, g], [0.0, 1.0]])
            t0 = time.perf_counter()
            r = mat(F)
            dt = time.perf_counter() - t0
            w = None
            for gg in np.arange(1, round(g / 1e-4) + 1) * 1e-4:
                w = mat(np.array([[1.0, gg], [0.0, 1.0]]), start=w)
            dW = abs(r.energy - w.energy) / w.energy
            dP = np.max(np.abs(r.piola - w.piola)) / np.max(np.abs(w.piola))
            print(f"{name} g={g:.0e} cold: {line(p, F, r)} {dt * 1e3:.1f} ms | warm: {line(p, F, w)}")
            print(f"    cold vs warm: dW/W={dW:.1e} dP/|P|={dP:.1e}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["rve-70-1"])
