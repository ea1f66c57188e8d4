"""Small test assemblies: a perturbed triangular lattice of polydisperse disks (for tests and
cross-checks with LIGGGHTS and LAMMPS; the Kuhn assembly comes from gransim.generation)."""

from __future__ import annotations

import numpy as np

from .._validate import as_positive_float
from ..errors import InputError
from ..geometry import Packing


def lattice_packing(
    nx: int = 10,
    ny: int = 12,
    radius: float = 1.0e-3,
    spread: float = 0.15,
    jitter: float = 0.05,
    compression: float = 0.02,
    density: float = 2650.0,
    seed: int = 0,
) -> Packing:
    """nx * ny disks on a triangular lattice of spacing 2 ``radius`` (ny even), radii uniform in
    radius (1 - spread, 1) * (1 + compression), centres jittered by ``jitter`` radius.

    With ``compression`` > 0 neighbouring disks overlap by about 2 ``compression`` radius, so
    the assembly is in contact (also across the periodic boundary) from step 0.
    """
    if nx < 3 or ny < 4 or ny % 2:
        raise InputError(f"lattice: need nx >= 3 and ny >= 4 even, got nx={nx}, ny={ny}")
    radius = as_positive_float(radius, "radius")
    rng = np.random.default_rng(seed)
    a = 2.0 * radius
    h = a * np.sqrt(3.0) / 2.0
    ix, iy = np.meshgrid(np.arange(nx), np.arange(ny), indexing="xy")
    x = (ix + 0.5 * (iy % 2) + 0.25) * a
    y = (iy + 0.5) * h
    pos = np.stack([x.ravel(), y.ravel()], axis=1)
    pos += jitter * radius * rng.uniform(-1, 1, pos.shape)
    r = radius * (1.0 + compression) * (1.0 - spread * rng.uniform(0, 1, pos.shape[0]))
    cell = np.diag([nx * a, ny * h])
    return Packing(
        positions=pos,
        radii=r,
        cell=cell,
        density=density,
        metadata={
            "generator": "lattice_packing",
            "nx": nx,
            "ny": ny,
            "seed": seed,
            "spread": spread,
            "jitter": jitter,
            "compression": compression,
        },
    )
