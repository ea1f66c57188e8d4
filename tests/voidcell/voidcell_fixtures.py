"""Builders of test snapshots for the void-cell analysis (imported by conftest and tests)."""

import numpy as np

from gransim.contacts import find_neighbours


def lattice_packing(nx=12, ny=12, noise=0.03, seed=0, shear=0.0):
    """Perturbed triangular lattice (spacing 1 m) with random radii; returns positions, radii, cell.

    Radii r = 0.5 (1 + u), u ~ U(-0.03, 0.07), so roughly two thirds of the lattice neighbours
    touch and faces of valence 3 to ~8 occur; second neighbours (distance sqrt 3) never touch.
    """
    rng = np.random.default_rng(seed)
    h = np.sqrt(3) / 2
    i, j = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(i + 0.5 * (j % 2)).ravel(), (h * j).ravel()]).astype(float)
    x += rng.uniform(-noise, noise, x.shape)
    cell = np.array([[nx, shear * ny * h], [0.0, ny * h]])
    x = x @ np.array([[1.0, shear], [0.0, 1.0]]).T
    r = 0.5 * (1 + rng.uniform(-0.03, 0.07, len(x)))
    return x, r, cell


def relaxed_packing(n=300, phi=0.84, seed=1, steps=120):
    """Random bidisperse disks relaxed by overlap repulsion, then inflated 0.5% to form contacts."""
    rng = np.random.default_rng(seed)
    r = np.where(rng.random(n) < 0.5, 0.5, 0.7)
    L = np.sqrt(np.pi * np.sum(r**2) / phi)
    cell = np.array([[L, 0.0], [0.0, L]])
    x = rng.random((n, 2)) * L
    for _ in range(steps):
        nl = find_neighbours(x, r, cell, skin=0.0)
        d = nl.distance
        push = (r[nl.i] + r[nl.j] - d)[:, None] * nl.branch / d[:, None] * 0.5
        dx = np.zeros_like(x)
        np.add.at(dx, nl.i, -push)
        np.add.at(dx, nl.j, push)
        x = x + dx
    return x, r * 1.005, cell


def contacts(x, r, cell):
    nl = find_neighbours(x, r, cell, skin=0.0)
    return nl.i, nl.j, nl.shift


def square_lattice(n=4):
    """n x n square lattice of spacing 1 on an n x n torus: positions, edges (i, j, shift)."""
    idx = lambda a, b: (a % n) * n + (b % n)  # noqa: E731
    pos = np.array([[a + 0.5, b + 0.5] for a in range(n) for b in range(n)])
    edges = []
    for a in range(n):
        for b in range(n):
            edges.append((idx(a, b), idx(a + 1, b), (1 if a == n - 1 else 0, 0)))
            edges.append((idx(a, b), idx(a, b + 1), (0, 1 if b == n - 1 else 0)))
    return pos, edges
