"""YADE's Taylor stresses against gransim's numpy Taylor stress on the demo packings, at round-off.

Tolerance: YADE's 2D stress is z times its 3D one (``getStress`` divides by the 3D cell volume);
z is a power of two, so that product is exact, and what remains is the rounding of YADE's
det(hSize) against numpy's det F V_ref (a few ulp) and of two sums of ~100-200 contact terms taken
in different orders (each term rounded at eps = 2.2e-16; the sum's error is bounded by
n_contacts * eps * sum |terms|, all terms of one sign on the diagonal). Measured worst: 2.2e-15 of
max |sigma| over the states below; the check is 1e-13 of max |sigma| per state, 45 times that and
still 10^10 times below what one contact more or less changes (~1/180 of sigma).
Overlaps: both codes compute r_i + r_j - |x_j + shift - x_i| from the same centres (|x| < 1e-2 m,
rounded at ~2e-18 m); measured worst 2.4e-18 m, checked at 2e-17 m.
"""

import shutil

import numpy as np
import pytest

from gransim.paper import KN_2D
from reference_runs.decks.taylor import PATHS
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.taylor_numpy import taylor_stress_numpy
from reference_runs.yade.taylor import cell_z, read_yade_taylor, run_yade_taylor

needs_yade = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
STRESS_RTOL = 1e-13
OVERLAP_ATOL = 2e-17  # m


@needs_yade
@pytest.mark.parametrize("nx,ny,seed", [(8, 8, 3), (6, 8, 11), (12, 10, 5)])
def test_yade_taylor_stress_matches_numpy_at_round_off(nx, ny, seed, tmp_path):
    packing = perturbed_lattice(nx, ny, seed=seed)
    run = run_yade_taylor(packing, KN_2D, tmp_path / "job", n_steps=4)  # 4 paths x 5 states, one YADE job
    assert run.manifest["status"] == "ok" and run.manifest["engine_version"] == "YADE 2023.02a"
    assert [s["path"] for s in run.states[::5]] == list(PATHS) and len(run.states) == 20
    assert run.z == cell_z(packing) and run.z > 4 * packing.radii.max() / 2
    for t, F in enumerate(run.F):
        ref = taylor_stress_numpy(packing, F, KN_2D)
        where = f"state {t} ({run.states[t]['path']}, k = {run.states[t]['k']})"
        assert run.n_contacts[t] == ref.n_contacts, where
        scale = np.abs(ref.cauchy).max()
        assert np.abs(run.cauchy[t] - ref.cauchy).max() <= STRESS_RTOL * scale, where
        raw = run.raw[t]
        assert np.abs(np.sort(raw.penetration) - np.sort(ref.overlap)).max() <= OVERLAP_ATOL, where
        # the same contacts: YADE's (id1 < id2, cellDist of body 2) is numpy's (i < j, shift n of j)
        yade_pairs = sorted((int(a), int(b), int(c[0]), int(c[1])) for (a, b), c in zip(raw.ids, raw.cell_dist))
        np_pairs = sorted((int(i), int(j), int(n[0]), int(n[1])) for i, j, n in zip(ref.i, ref.j, ref.shift))
        assert yade_pairs == np_pairs, where
        # the normal force is kn times the overlap, no tangential force (ks = 0)
        fn = np.linalg.norm(raw.normal_force, axis=1)
        assert np.allclose(fn, KN_2D * raw.penetration, rtol=1e-15, atol=0), where
        assert not raw.shear_force.any(), where
    assert read_yade_taylor(tmp_path / "job" / "taylor.out", 20)[-1].index == 19
