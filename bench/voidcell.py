"""Benchmark of the void-cell analysis: particle graph, faces and measures for 1e4..1e6 disks.

Target: what ``gransim voidcells`` computes per snapshot -- the pruned particle
graph, the DCEL with its checks (crossings, closure, areas, Euler) and the measures (eqs 3, 7,
18-21), ``VoidCells().compute`` -- for 1,000,000 disks in under 2 s after compilation. The kernel
figures (graph, faces + checks, measures) are reported beside the whole call, the first call of
the process (numba compilation, or loading it from the disk cache) apart, and the load average
beside every figure (a shared 2-core machine).
Run: ``python -m bench --only voidcell`` (or ``python -m bench.voidcell [--quick]``).
"""

from __future__ import annotations

import os
import time

import numpy as np

from gransim.contacts import find_neighbours
from gransim.voidcell import Snapshot, VoidCells
from gransim.voidcell.dcel import build_dcel
from gransim.voidcell.graph import build_graph
from gransim.voidcell.measures import face_gradients, halfedge_velocities

TARGET_S = 2.0


def lattice_snapshot(n_target: int, seed: int = 0):
    """A dense periodic packing of about n_target disks: a perturbed triangular lattice (spacing
    1 m) with radii 0.5 (1 + u), u ~ U(-0.03, 0.07) (about 2/3 of neighbours touch, void cells of
    valence 3..~10), contacts from the cell list, and random velocities plus an affine part."""
    rng = np.random.default_rng(seed)
    nx = round(np.sqrt(n_target))
    ny = 2 * max(1, round(n_target / nx / 2))
    h = np.sqrt(3) / 2
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(i + 0.5 * (j % 2)).ravel(), (h * j).ravel()]).astype(float)
    x += rng.uniform(-0.03, 0.03, x.shape)
    cell = np.array([[float(nx), 0.0], [0.0, ny * h]])
    r = 0.5 * (1 + rng.uniform(-0.03, 0.07, len(x)))
    nl = find_neighbours(x, r, cell, skin=0.0)
    G = np.array([[0.0, 0.0], [0.0, -1.0]])
    v = x @ G.T + 0.1 * rng.normal(size=x.shape)
    return Snapshot(x, cell, nl.i, nl.j, nl.shift, v, cell_velocity=G @ cell, radii=r)


def time_compute(snap, repeat: int = 3) -> dict:
    """Best of ``repeat`` for the whole ``VoidCells().compute`` and for its three stages, with the
    largest load average seen."""
    best = {"total": np.inf, "graph": np.inf, "faces": np.inf, "measures": np.inf}
    load = os.getloadavg()[0]
    for _ in range(repeat):
        t0 = time.perf_counter()
        vc = VoidCells().compute(snap)
        t1 = time.perf_counter()
        best["total"] = min(best["total"], t1 - t0)
        t0 = time.perf_counter()
        g = build_graph(snap.n_particles, snap.contacts_i, snap.contacts_j, snap.contacts_shift)
        t1 = time.perf_counter()
        d = build_dcel(snap.positions, snap.cell, g.edge_i, g.edge_j, g.edge_shift, g.n_vertices)
        t2 = time.perf_counter()
        dv = halfedge_velocities(d.origin, d.dest, d.shift, snap.velocities, snap.cell_velocity)
        face_gradients(d.face_ptr, d.face_halfedges, d.vec, dv, d.face_area)
        t3 = time.perf_counter()
        best["graph"] = min(best["graph"], t1 - t0)
        best["faces"] = min(best["faces"], t2 - t1)
        best["measures"] = min(best["measures"], t3 - t2)
        load = max(load, os.getloadavg()[0])
    best["summary"] = vc.summary()
    best["load"] = load
    return best


def run(quick: bool = False) -> list[dict]:
    """Records {"name", "value", "unit", "target", "note", "load"} for the bench suite."""
    sizes = [10_000, 100_000] if quick else [10_000, 100_000, 1_000_000]
    t0 = time.perf_counter()
    time_compute(lattice_snapshot(500), repeat=1)  # compile (cached on disk afterwards)
    first = time.perf_counter() - t0
    out = []
    for n in sizes:
        snap = lattice_snapshot(n)
        t = time_compute(snap, repeat=2 if n >= 1_000_000 else 3)
        s = t["summary"]
        note = (
            f"N={snap.n_particles}, M={snap.n_contacts}, F={s['faces']}, E={s['edges']}, "
            f"V={s['vertices']}; graph {t['graph']:.2f} s, faces+checks {t['faces']:.2f} s, "
            f"measures (eqs 5, 7) {t['measures']:.2f} s; best of repeats, after compilation; "
            f"load average {t['load']:.1f} on {os.cpu_count()} cores"
        )
        big = n == 1_000_000
        out.append(
            {
                "name": f"voidcell_compute_{n}",
                "value": round(t["total"], 3),
                "unit": "s",
                "target": f"< {TARGET_S:g} s" if big else None,
                "meets": (t["total"] < TARGET_S) if big else None,
                "load": t["load"],
                "note": note,
            }
        )
    out.append(
        {
            "name": "voidcell first call (compile or cache load)",
            "value": round(first, 2),
            "unit": "s",
            "target": None,
            "meets": None,
            "load": os.getloadavg()[0],
            "note": "500-disk snapshot, first call of the process: excluded from the figures",
        }
    )
    return out


if __name__ == "__main__":
    import json
    import sys

    for rec in run(quick="--quick" in sys.argv):
        print(json.dumps(rec))
