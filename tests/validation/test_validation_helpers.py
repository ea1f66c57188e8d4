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
    fr = {
        "x": x,
        "v": np.array([[1.0, 0.0], [0.0, -2.0]]),
        "w": np.array([1.0, 4.0]),
        "f": np.ones((2, 2)),
        "t": np.array([1.0, -1.0]),
    }
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
    fr = {
        "x": np.array(p.positions),
        "v": np.zeros((p.n, 2)),
        "w": np.zeros(p.n),
        "f": np.zeros((p.n, 2)),
        "t": np.zeros(p.n),
    }
    tr = Trajectory(np.arange(3), np.zeros((3, 3)), lengths, {1: fr})
    snap = snapshot(tr, 1, p.radii, dt)
    vc = VoidCells().compute(snap)
    assert vc.n_faces > 10
    np.testing.assert_allclose(vc.alpha, 1.0, atol=1e-9)
    np.testing.assert_allclose(vc.w, 0.0, atol=1e-9)
    # the cell list does not depend on the order the contacts are given in
    perm = np.random.default_rng(0).permutation(snap.n_contacts)
    snap2 = snap.replace(
        contacts_i=snap.contacts_i[perm], contacts_j=snap.contacts_j[perm], contacts_shift=snap.contacts_shift[perm]
    )
    assert cell_signature(VoidCells().compute(snap2)) == cell_signature(vc)


def test_envelope_members_of_each_code(tmp_path):
    """The reference jobs of biaxial-full: each code's reference and its envelope members; the full
    suite adds 2 MPI processes and twice the neighbour skin (a numerical setting) for both codes."""
    import numpy as np

    from gransim.dem import DEMSettings
    from reference_runs.demo_packings import perturbed_lattice
    from validation.cases.biaxial import SKIN_LABEL, reference_jobs
    from validation.core import Context

    p = perturbed_lattice(6, 6, seed=1)
    dem = DEMSettings(skin=3e-5)
    full = reference_jobs(Context("full", tmp_path, liggghts=True, lammps=True), p, dem, "t", True)
    for engine in ("liggghts", "lammps"):
        labels = {lab for e, lab in full if e == engine}
        assert labels == {
            "reference",
            "x of disk 1 moved by +1e-15 rel",
            "y of disk 19 moved by -1e-15 rel",
            "2 MPI processes",
            SKIN_LABEL,
        }, (engine, labels)
        for (e, lab), kw in full.items():
            if e != engine:
                continue
            assert kw["settings"].flavour == engine
            assert kw["settings"].skin == (6e-5 if lab == SKIN_LABEL else 3e-5)
            assert kw.get("np_procs", 1) == (2 if lab == "2 MPI processes" else 1)
            moved = np.argwhere(kw["packing"].positions != p.positions)
            if "moved" in lab:
                ((k, ax),) = moved
                rel = kw["packing"].positions[k, ax] / p.positions[k, ax] - 1
                assert 0 < abs(rel) < 3e-15
            else:
                assert moved.size == 0
    dirs = [kw["job_dir"] for kw in full.values()]
    assert len(set(dirs)) == len(dirs)  # no two jobs share a directory
    default = reference_jobs(Context("default", tmp_path, liggghts=True, lammps=False), p, dem, "t", False)
    assert {lab for _, lab in default} == {
        "reference",
        "x of disk 1 moved by +1e-15 rel",
        "y of disk 19 moved by -1e-15 rel",
    }
    assert {e for e, _ in default} == {"liggghts"}
