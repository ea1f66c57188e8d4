"""LAMMPS Taylor stresses (stored in the repository, and live when ``lmp`` exists) against the
independent numpy Taylor stress, to the tolerance of the LIGGGHTS ones (test_ref_stored_taylor.py).

LAMMPS runs the periodic route on all four paths (the shear paths in a true periodic triclinic
box), so it also checks the triclinic periodic images against numpy's brute-force image sum.
"""

import json
import shutil

import numpy as np
import pytest
from deck_semantics import check_taylor_job, stored_inputs

from gransim.io import load_packing
from reference_runs.decks.taylor import PATHS, ROUTES, triclinic_state
from reference_runs.store import RVE_CASE, STORED, TAYLOR_CASE, TAYLOR_PARAMS, taylor_case
from reference_runs.taylor import read_taylor_job, run_taylor
from reference_runs.taylor_numpy import candidate_pairs, taylor_stress_numpy

RTOL = 1e-10  # the LIGGGHTS tolerance: same float64 forces summed in different orders; measured ~1e-15
KN = TAYLOR_PARAMS["kn"]
HAVE_LMP = shutil.which("lmp") is not None
CASES = [TAYLOR_CASE, RVE_CASE]


@pytest.fixture(scope="module", params=CASES)
def lammps_run(request, tmp_path_factory):
    """The LAMMPS run of a stored case: live (rerun here) when lmp exists, the stored one otherwise."""
    stored = STORED / taylor_case(request.param, "lammps")
    packing = load_packing(STORED / request.param / "packing.h5")
    if HAVE_LMP:
        p = TAYLOR_PARAMS
        run = run_taylor(
            packing,
            KN,
            tmp_path_factory.mktemp("lmp") / request.param,
            name=stored.name,
            n_steps=p["n_steps"],
            stride=p["stride"],
            max_strain=p["max_strain"],
            contacts=(request.param == TAYLOR_CASE),
            progress=False,
            engine="lammps",
        )
    else:
        run = read_taylor_job(stored, packing)
    return request.param, packing, run, candidate_pairs(packing, 0.85)


def test_every_path_has_both_routes(lammps_run):
    _, _, run, _ = lammps_run
    assert run.engine == "lammps"
    assert sorted(run.series) == sorted((p, r) for p in PATHS for r in ROUTES)
    s = run.get("shear-21", "periodic")
    assert s.k.tolist() == [0, 10, 20, 30, 40, 50]
    # F = I needs no swap; every sheared state runs with x and y swapped (first lattice vector along x)
    assert list(s.frames) == [((1.0, 0.0), (0.0, 1.0))] + [((0.0, 1.0), (1.0, 0.0))] * 5


def test_lammps_stress_equals_numpy_taylor(lammps_run):
    _, packing, run, cand = lammps_run
    for (path, route), s in run.series.items():
        for F, sig, sp in zip(s.F, s.cauchy, s.cauchy_pressure):
            ref = taylor_stress_numpy(packing, F, KN, cand)
            assert ref.n_contacts > 0
            scale = np.abs(ref.cauchy).max()
            assert np.abs(sig - ref.cauchy).max() < RTOL * scale, (path, route, F.tolist())
            if route == "periodic":  # the box virial, sigma = -p, in the triclinic box too
                assert np.abs(sp - ref.cauchy).max() < RTOL * scale, (path, route, F.tolist())


def test_lammps_shear_stress_is_not_symmetric_in_the_paths(lammps_run):
    # shear-12 and shear-21 are different states: swapping x and y back must not be a no-op
    _, _, run, _ = lammps_run
    a, b = run.get("shear-12", "periodic").cauchy[-1], run.get("shear-21", "periodic").cauchy[-1]
    assert np.abs(a - b).max() > 1e-3 * np.abs(a).max()


def test_lammps_contacts_equal_numpy(lammps_run):
    case, packing, run, cand = lammps_run
    if case != TAYLOR_CASE:
        pytest.skip("the RVE case stores no contacts")
    for (path, route), s in sorted(run.series.items()):
        for k, F in zip(s.k, s.F):
            fr = run.contacts(path, route, int(k))
            ref = taylor_stress_numpy(packing, F, KN, cand)
            fscale = np.abs(ref.force).max()
            pairs = {}
            for i, j, f, eps in zip(ref.i, ref.j, ref.force, ref.overlap):
                pairs[(int(i) + 1, int(j) + 1)] = (f, eps)
            if route == "periodic":
                assert len(fr) == ref.n_contacts  # every periodic contact once
                for a, b, fx, fy, d in zip(fr["id1"], fr["id2"], fr["fx"], fr["fy"], fr["delta"]):
                    key = (min(a, b), max(a, b))
                    f, eps = pairs[key]
                    f_on_id1 = f if a == key[0] else -f
                    assert np.abs(np.array([fx, fy]) - f_on_id1).max() < RTOL * fscale, (path, k, key)
                    assert abs(d - eps) < 1e-12 * packing.radii.max()
            else:
                n = packing.n
                central = (fr["id1"] <= n).astype(int) + (fr["id2"] <= n).astype(int)
                weight = np.where(central == 2, 1.0, np.where(central == 1, 0.5, 0.0))
                assert weight.sum() == ref.n_contacts
                # each row with a central particle has the force of a numpy contact of that pair
                src = run._image_sources(path, route, int(k)) + 1  # atom id -> particle id
                for a, b, fx, fy in zip(fr["id1"], fr["id2"], fr["fx"], fr["fy"]):
                    if a > n and b > n:
                        continue
                    key = (min(src[a - 1], src[b - 1]), max(src[a - 1], src[b - 1]))
                    assert key in pairs, (path, k, key)
                    f = pairs[key][0]
                    mag = np.hypot(fx, fy)
                    assert abs(mag - np.hypot(*f)) < RTOL * fscale or key in _multi(ref), (path, k, key)


def _multi(ref):
    """Pairs in contact through more than one image (their rows cannot be matched by id)."""
    seen, multi = set(), set()
    for i, j in zip(ref.i, ref.j):
        key = (int(i) + 1, int(j) + 1)
        (multi if key in seen else seen).add(key)
    return multi


@pytest.mark.parametrize("case", CASES)
def test_stored_lammps_deck_sets_the_documented_physics(case):
    """The LAMMPS deck as run means the documented states (tests/reference_runs/deck_semantics.py):
    gran/hooke with kn = E_n and zero kt, damping and friction, density/disc = the packing's mass
    per area; atoms = the packing mapped by F in the engine frame (x/y swapped for shear-21), box =
    the deformed cell, the triclinic one on the shear paths; LAMMPS's thermo shows every atom and the
    box, and every dumped contact has |f| = kn delta."""
    d = STORED / taylor_case(case, "lammps")
    packing = load_packing(STORED / case / "packing.h5")
    m = json.loads((d / "manifest.json").read_text())
    assert m["engine"] == "lammps" and m["engine_version"].startswith("LAMMPS 29 Sep 2021")
    assert not (d / "in.liggghts").exists()
    n = check_taylor_job(d, packing, KN, "lammps", stored_inputs(d, packing, engine="lammps"))
    assert n > 0 if case == TAYLOR_CASE else n == 0


@pytest.mark.parametrize("case", CASES)
def test_stored_lammps_equals_stored_liggghts(case):
    # the two codes on the states both ran (compression periodic, all images): same stress
    packing = load_packing(STORED / case / "packing.h5")
    lig = read_taylor_job(STORED / case, packing)
    lmp = read_taylor_job(STORED / taylor_case(case, "lammps"), packing)
    assert set(lig.series) < set(lmp.series)
    for key, s in lig.series.items():
        scale = np.abs(s.cauchy).max()
        assert np.abs(lmp.series[key].cauchy - s.cauchy).max() < RTOL * scale, key


def test_triclinic_state_boxes():
    from reference_runs.demo_packings import perturbed_lattice

    p = perturbed_lattice(4, 4, seed=2)
    Lx, Ly = p.cell[0, 0], p.cell[1, 1]
    _, box, Q = triclinic_state(p, [[1.0, 0.1], [0.0, 1.0]])
    assert box == (Lx, Ly, 0.1 * Ly) and np.array_equal(Q, np.eye(2))
    _, box21, Q21 = triclinic_state(p, [[1.0, 0.0], [0.1, 1.0]])
    assert box21 == (Ly, Lx, 0.1 * Lx) and Q21[0, 1] == 1.0
    from gransim.errors import InputError

    with pytest.raises(InputError, match="zero off-diagonal entry"):
        triclinic_state(p, [[1.0, 0.1], [0.1, 1.0]])
