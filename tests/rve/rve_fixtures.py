"""Small dense periodic packings for the RVE tests (independent of gransim.generation), imported by
name (``from rve_fixtures import ...``): a bare ``from conftest import`` took whichever test
folder's conftest pytest had loaded last (tests/voidcell has one too)."""

from __future__ import annotations

import numpy as np

from gransim import Packing


def lattice_packing(
    nx: int = 8,
    ny: int = 8,
    seed: int = 0,
    shear: float = 0.0,
    spread: float = 0.08,
    swell: float = 1.04,
) -> Packing:
    """Perturbed triangular lattice (spacing 1 mm) with random radii near half the spacing.

    ``swell`` > 1 makes most neighbours overlap, the random radii (+-spread) and positions
    leave some pairs open; ``shear`` maps positions and cell by [[1, shear], [0, 1]] (a
    triclinic cell).
    """
    rng = np.random.default_rng(seed)
    a = 1e-3
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    x += rng.uniform(-0.04, 0.04, x.shape) * a
    r = 0.5 * a * swell * (1 + rng.uniform(-spread, spread, x.shape[0]))
    cell = np.array([[nx * a, 0.0], [0.0, ny * h]])
    S = np.array([[1.0, shear], [0.0, 1.0]])
    return Packing(positions=x @ S.T, radii=r, cell=S @ cell, metadata={"kind": "test-lattice", "seed": seed})


def random_packing(n: int = 60, seed: int = 1, phi: float = 0.95) -> Packing:
    """Random polydisperse disks (radius ratio 3) in a sheared cell at nominal solid fraction phi.

    Heavily overlapping with contacts in all directions; positions partly outside the cell.
    """
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.5, 1.5, n) * 1e-3
    area = np.pi * np.sum(r**2) / phi
    side = np.sqrt(area)
    cell = np.array([[side, 0.3 * side], [0.0, side]])
    s = rng.uniform(-0.2, 1.2, (n, 2))
    return Packing(positions=s @ cell.T, radii=r, cell=cell, metadata={"kind": "test-random", "seed": seed})
