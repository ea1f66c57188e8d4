"""Small dense periodic packings for tests, stored reference outputs and demos.

A perturbed triangular lattice (spacing ``a``) with random radii slightly above a/2, so that
neighbours overlap: a dense, contact-rich periodic packing built in microseconds, without
the packing generator (gransim.generation). Deterministic for a given seed.
"""

from __future__ import annotations

import numpy as np

from gransim.errors import InputError
from gransim.geometry import Packing


def perturbed_lattice(
    nx: int = 8,
    ny: int = 8,
    seed: int = 1,
    a: float = 1e-3,
    jitter: float = 0.04,
    r_range=(0.5, 0.58),
    density: float = 2650.0,
) -> Packing:
    """Triangular lattice of nx x ny disks in an orthogonal periodic cell, perturbed.

    Parameters
    ----------
    nx, ny : disks per row and rows (ny even, so the lattice is periodic), >= 4.
    seed : random seed.
    a : lattice spacing (m).
    jitter : uniform position perturbation, in units of a.
    r_range : radii drawn uniformly in this range, in units of a (> 0.5 gives overlaps).
    density : mass per area (kg/m^2).
    """
    if nx < 4 or ny < 4 or ny % 2:
        raise InputError(f"nx >= 4 and even ny >= 4 needed, got nx={nx}, ny={ny}")
    rng = np.random.default_rng(seed)
    j, i = np.divmod(np.arange(nx * ny), nx)
    pts = np.column_stack([i + 0.5 * (j % 2), j * np.sqrt(3) / 2])
    pts += rng.uniform(-jitter, jitter, pts.shape)
    r = rng.uniform(*r_range, nx * ny)
    cell = np.diag([float(nx), ny * np.sqrt(3) / 2])
    return Packing(
        pts * a,
        r * a,
        cell * a,
        density=density,
        metadata={
            "generator": "perturbed_lattice",
            "nx": nx,
            "ny": ny,
            "seed": seed,
            "a": a,
            "jitter": jitter,
            "r_range": list(r_range),
        },
    )
