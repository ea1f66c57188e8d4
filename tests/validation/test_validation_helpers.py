"""The comparison helpers of the validation layer: exact cases."""

from __future__ import annotations

import numpy as np

from gransim.dem.lattice import lattice_packing
from validation.cases.voidcell import cell_signature
from validation.dem_compare import Trajectory, frame_differences, position_difference, snapshot


def test_position_difference_is_modulo_the_box():
    rng = np.random.default_rng(3)
    L = np.array([2.0, 3.0])
    x = rng.uniform(0, 1, (20, 2)) * L
    y = x.copy()
    y[4, 0] += L[0]  # the same particle wrapped by one code, not the other
    y[7, 1] -= L[1]
    assert position_difference(x, y, L) == 0.0
    y[2, 1] += 1e-3
    assert abs(position_difference(x, y, L) - 1e-3) < 1e-15


def test_frame_differences_relative_to_the_reference():
    x = np.array([[0.1, 0.2], [0.5, 0.6]])
    fr = {"x": x, "v": np.array([[1.0, 0.0], [0.0, -2.0]]), "w": np.array([1.0, 4.0]),
          "f": np.ones((2, 2)), "t": np.array([1.0, -1.0])}
    other = {k: v.copy() for k, v in fr.items()}
    other["v"][1, 1] = -2.2  # 0.2 / max|v| = 0.1
    a = Trajectory(np.array([0]), np.zeros((1, 3)), np.array([[1.0, 1.0]]), {0: other})
    b = Trajectory(np.array([0]), np.zeros((1, 3)), np.array([[1.0, 1.0]]), {0: fr})
    d = frame_differences(a, b, d50=0.1)
    assert np.isclose(d["v"][0], 0.1) and d["x"][0] == 0 and d["f"][0] == 0


def test_affine_box_motion_gives_perfect_alignment():
    # particles at rest in a box deformed with remap x: the snapshot adds the affine streaming,
    # so every void cell deforms with the mean gradient: alpha = 1 and w = 0 (eqs 18-20)
    from gransim.voidcell import VoidCells

    p = lattice_packing(10, 12, seed=1, spread=0.02, compression=0.08)  # ~3 contacts per disk
    L0 = np.diag(p.cell)
    dt = 1e-3
    lengths = np.array([L0 * (1 + 1e-3 * k * np.array([0.5, -1.0])) for k in range(3)])
    fr = {"x": np.array(p.positions), "v": np.zeros((p.n, 2)), "w": np.zeros(p.n), "f": np.zeros((p.n, 2)),
          "t": np.zeros(p.n)}
    tr = Trajectory(np.arange(3), np.zeros((3, 3)), lengths, {1: fr})
    snap = snapshot(tr, 1, p.radii, dt)
    vc = VoidCells().compute(snap)
    assert vc.n_faces > 10
    np.testing.assert_allclose(vc.alpha, 1.0, atol=1e-9)
    np.testing.assert_allclose(vc.w, 0.0, atol=1e-9)
    # the cell list does not depend on the order the contacts are given in
    perm = np.random.default_rng(0).permutation(snap.n_contacts)
    snap2 = snap.replace(contacts_i=snap.contacts_i[perm], contacts_j=snap.contacts_j[perm],
                         contacts_shift=snap.contacts_shift[perm])
    assert cell_signature(VoidCells().compute(snap2)) == cell_signature(vc)
