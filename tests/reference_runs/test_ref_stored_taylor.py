"""LIGGGHTS Taylor stresses stored in the repository against the independent numpy Taylor stress.

Runs without LIGGGHTS. Tolerance RTOL = 1e-10 relative to the largest stress component of each
state (see conftest): both sides evaluate the same float64 forces, summed in different orders.
"""

import json

import numpy as np
import pytest
from deck_semantics import check_taylor_job, stored_inputs

from gransim.io import load_packing
from reference_runs.conventions import cauchy_from_pressure
from reference_runs.parsers import parse_dump_local
from reference_runs.store import RVE_CASE, STORED, TAYLOR_CASE, TAYLOR_PARAMS, stored_taylor_packing
from reference_runs.taylor import read_taylor_job
from reference_runs.taylor_numpy import candidate_pairs, taylor_stress_numpy

RTOL = 1e-10  # same float64 forces summed in different orders; measured ~1e-15

STORE = STORED / TAYLOR_CASE
KN = TAYLOR_PARAMS["kn"]


@pytest.fixture(scope="module")
def stored():
    packing = load_packing(STORE / "packing.h5")
    run = read_taylor_job(STORE, packing)
    return packing, run, candidate_pairs(packing, 0.85)


def test_stored_packing_is_the_documented_one():
    a, b = load_packing(STORE / "packing.h5"), stored_taylor_packing()
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.radii, b.radii)


def test_all_paths_and_routes_present(stored):
    _, run, _ = stored
    assert sorted(run.series) == sorted(
        [
            ("compression-11", "images"),
            ("compression-11", "periodic"),
            ("compression-22", "images"),
            ("compression-22", "periodic"),
            ("shear-12", "images"),
            ("shear-21", "images"),
        ]
    )
    s = run.get("shear-21")
    assert s.k.tolist() == [0, 10, 20, 30, 40, 50]
    assert np.allclose(s.F[:, 1, 0], np.linspace(0, 0.1, 6), rtol=0, atol=1e-15)


@pytest.fixture(scope="module", params=[TAYLOR_CASE, RVE_CASE])
def any_stored(request):
    d = STORED / request.param
    packing = load_packing(d / "packing.h5")
    return d, packing, read_taylor_job(d, packing), candidate_pairs(packing, 0.85)


def test_stored_deck_sets_the_documented_physics(any_stored):
    """The deck as run and its data files mean the documented states: kn = E_n, no tangential
    spring, damping or friction; the atoms are the packing mapped by F (radii, density, x = F X up
    to periods) in the box F C; and the code's output shows it read them so: every atom and the
    box in its thermo row, |f| = kn delta along the line of centres for every dumped contact."""
    d, packing, _, _ = any_stored
    n = check_taylor_job(d, packing, KN, "liggghts", stored_inputs(d, packing))
    assert n > 0 if d.name == TAYLOR_CASE else n == 0


def test_the_deck_check_fails_on_a_wrong_state(any_stored):
    """The semantic check is not vacuous: the data files of another state, or a different kn,
    fail it."""
    d, packing, _, _ = any_stored
    files = stored_inputs(d, packing)
    names = sorted(k for k in files if k.endswith(".data") and "compression-11/periodic" in k)
    swapped = {**files, names[0]: files[names[-1]]}
    with pytest.raises(AssertionError):
        check_taylor_job(d, packing, KN, "liggghts", swapped)
    with pytest.raises(AssertionError):
        check_taylor_job(d, packing, 1.01 * KN, "liggghts", files)


def test_stored_stress_equals_numpy_taylor(any_stored):
    _, packing, run, cand = any_stored
    worst = 0.0
    for (path, route), s in run.series.items():
        for F, sig in zip(s.F, s.cauchy):
            ref = taylor_stress_numpy(packing, F, KN, cand)
            assert ref.n_contacts > 0
            err = np.abs(sig - ref.cauchy).max() / np.abs(ref.cauchy).max()
            worst = max(worst, err)
            assert err < RTOL, (path, route, F.tolist(), err)
    assert worst < RTOL


def test_routes_agree_and_pressure_equals_stress_atom(stored):
    _, run, _ = stored
    for path in ("compression-11", "compression-22"):
        per, img = run.get(path, "periodic"), run.get(path, "images")
        scale = np.abs(per.cauchy).max()
        assert np.abs(per.cauchy - img.cauchy).max() < RTOL * scale
        # the box virial (sigma = -p) and the central stress/atom sum agree in the periodic box
        assert np.abs(per.cauchy_pressure - per.cauchy).max() < RTOL * scale


def test_sign_convention_compression_negative(stored):
    _, run, _ = stored
    s = run.get("compression-11", "periodic")
    # a dense packing pushed together: compressive (negative) normal stresses growing with strain
    assert np.all(s.cauchy[:, 0, 0] < 0) and np.all(np.diff(s.cauchy[:, 0, 0]) < 0)
    # and LIGGGHTS' own pressure column is positive in compression
    log_p = -s.cauchy_pressure[:, 0, 0]
    assert np.all(log_p > 0)
    assert np.allclose(cauchy_from_pressure(log_p, 0, 0)[:, 0, 0], s.cauchy_pressure[:, 0, 0], rtol=0, atol=0)


def _numpy_pairs(ref):
    out = {}
    for i, j, f, eps in zip(ref.i, ref.j, ref.force, ref.overlap):
        key = (int(i) + 1, int(j) + 1)
        assert key not in out  # no pair touches through two images in this packing
        out[key] = (f, eps)
    return out


def test_stored_contacts_periodic_route(stored):
    packing, run, cand = stored
    meta = json.loads((STORE / "states.json").read_text())
    names = tuple(meta["contact_columns"])
    for path in ("compression-11", "compression-22"):
        s = run.get(path, "periodic")
        for _k, F, cf in zip(s.k, s.F, s.contact_files):
            (fr,) = parse_dump_local(STORE / cf, names=names)
            ref = taylor_stress_numpy(packing, F, KN, cand)
            pairs = _numpy_pairs(ref)
            assert len(fr) == ref.n_contacts
            fscale = np.abs(ref.force).max()
            for a, b, fx, fy, d in zip(fr["id1"], fr["id2"], fr["fx"], fr["fy"], fr["delta"]):
                key = (min(a, b), max(a, b))
                f, eps = pairs[key]
                f_on_id1 = f if a == key[0] else -f  # numpy f acts on i (the smaller index)
                assert np.abs(np.array([fx, fy]) - f_on_id1).max() < RTOL * fscale
                assert abs(d - eps) < 1e-12 * packing.radii.max()


def test_stored_contacts_images_route_count_each_contact_once(stored):
    packing, run, cand = stored
    meta = json.loads((STORE / "states.json").read_text())
    names = tuple(meta["contact_columns"])
    n = packing.n
    s = run.get("shear-12", "images")
    for F, cf in zip(s.F, s.contact_files):
        (fr,) = parse_dump_local(STORE / cf, names=names)
        central = (fr["id1"] <= n).astype(int) + (fr["id2"] <= n).astype(int)
        # central-central rows once, central-image rows twice (from both ends): weights 1 and 1/2
        weight = np.where(central == 2, 1.0, np.where(central == 1, 0.5, 0.0))
        assert weight.sum() == taylor_stress_numpy(packing, F, KN, cand).n_contacts


@pytest.mark.liggghts
def test_stored_output_reproduces(stored, tmp_path):
    # regenerating the stored case with the installed binary gives the stored stresses (serial
    # LIGGGHTS runs are deterministic; identical deck and data files)
    from reference_runs.store import regenerate_taylor

    packing, run, _ = stored
    new = read_taylor_job(regenerate_taylor(tmp_path / "again"), packing)
    assert (tmp_path / "again" / "in.liggghts").read_text() == (STORE / "in.liggghts").read_text()
    for key, s in run.series.items():
        assert np.array_equal(new.series[key].stress_atom_sum, s.stress_atom_sum), key
