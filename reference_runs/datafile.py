"""Data files for LIGGGHTS and LAMMPS written by gransim (not by LIGGGHTS' ``write_data``).

``write_data`` in 2D writes density as m / (4/3 pi r^3), which changes masses when read
back (docs/liggghts.md). LAMMPS reads the density column as 3D; its decks reset it with
``set group all density/disc`` (docs/lammps.md). Here the density column is mass per area, the
convention of ``dimension 2`` with ``atom_style sphere`` (m = pi r^2 rho), and every number is
printed with ``%.17g`` so the data file round-trips float64 exactly.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gransim.errors import InputError
from gransim.geometry import Packing
from gransim.io import atomic_path

#: half thickness of the z slab of the 2D box (m); any value > 0 works for dimension 2
Z_HALF = 0.5


def _fmt(v: float) -> str:
    return f"{v:.17g}"


def write_data_file(
    path, packing: Packing, velocities=None, omegas=None, types=None, wrap: bool = True, z_half: float | None = None
) -> Path:
    """Write ``packing`` as a LIGGGHTS ``atom_style sphere`` data file (2D), atomically
    (:func:`gransim.io.atomic_path`); the text is :func:`data_file_text`'s (same parameters).
    Returns ``path``."""
    text = data_file_text(packing, velocities=velocities, omegas=omegas, types=types, wrap=wrap, z_half=z_half)
    with atomic_path(path, suffix=".data.tmp") as tmp:
        Path(tmp).write_text(text)
    return Path(path)


def data_file_text(
    packing: Packing, velocities=None, omegas=None, types=None, wrap: bool = True, z_half: float | None = None
) -> str:
    """The text of ``packing`` as a LIGGGHTS ``atom_style sphere`` data file (2D), for a job's
    input files held in memory (a Taylor job's hundreds of states: no file, no fsync each).

    Parameters
    ----------
    packing : the packing; its cell must be orthogonal (a1 = (Lx, 0), a2 = (0, Ly)),
        because tilted boxes are broken in LIGGGHTS 3.8.0 (docs/liggghts.md).
    velocities : (N, 2) m/s, optional (written as a Velocities section with spins).
    omegas : (N,) rad/s, optional spin about z.
    types : (N,) int >= 1, optional atom types (default all 1).
    wrap : wrap centres into the box first (LIGGGHTS requires atoms inside).

    The box is [0, Lx] x [0, Ly] x [-z, z]; atom ids are 1..N in packing order.
    """
    C = packing.cell
    if abs(C[1, 0]) > 0 or abs(C[0, 1]) > 0:
        raise InputError(
            "packing.cell: LIGGGHTS data files need an orthogonal cell "
            f"(got off-diagonal entries {C[0, 1]!r}, {C[1, 0]!r})"
        )
    n = packing.n
    x = packing.wrapped().positions if wrap else packing.positions
    z = Z_HALF if z_half is None else float(z_half)
    if z <= float(packing.radii.max()):
        z = 2.0 * float(packing.radii.max())
    t = np.ones(n, np.int64) if types is None else np.asarray(types, np.int64)
    if t.shape != (n,) or t.min() < 1:
        raise InputError(f"types: expected ({n},) integers >= 1")
    lines = [
        "LIGGGHTS data file written by gransim (2D: density column = mass per area)",
        "",
        f"{n} atoms",
        f"{int(t.max())} atom types",
        "",
        f"0 {_fmt(C[0, 0])} xlo xhi",
        f"0 {_fmt(C[1, 1])} ylo yhi",
        f"{_fmt(-z)} {_fmt(z)} zlo zhi",
        "",
        "Atoms",
        "",
    ]
    d = 2.0 * packing.radii
    rho = packing.density
    # one format per row on Python floats and ints (numpy scalars format the same digits, 3x slower)
    rho_s = _fmt(rho)
    lines += [
        f"{k} {tk} {dk:.17g} {rho_s} {xk:.17g} {yk:.17g} 0"
        for k, tk, dk, (xk, yk) in zip(range(1, n + 1), t.tolist(), d.tolist(), np.asarray(x, float).tolist())
    ]
    if velocities is not None or omegas is not None:
        v = np.zeros((n, 2)) if velocities is None else np.asarray(velocities, float).reshape(n, 2)
        w = np.zeros(n) if omegas is None else np.asarray(omegas, float).reshape(n)
        lines += ["", "Velocities", ""]
        rows = zip(range(1, n + 1), v.tolist(), w.tolist())
        lines += [f"{k} {vx:.17g} {vy:.17g} 0 0 0 {wk:.17g}" for k, (vx, vy), wk in rows]
    return "\n".join(lines) + "\n"
