"""RVE studies (Figs 3-5) and the rve CLI commands."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from rve_fixtures import random_packing

from gransim import InputError
from gransim.cli import main
from gransim.io import save_packing
from gransim.rve import homogenize
from gransim.rve.reference import homogenize_bruteforce
from gransim.rve.study import DRIVING, PATHS, RVEStudy, load_path, run_study

KN = 2.8e7


@pytest.fixture(scope="module")
def small_set():
    return {f"s{n}-{k}": random_packing(n, seed=10 * n + k, phi=0.9) for n in (30, 60) for k in range(3)}


def test_load_paths():
    d, F = load_path("compression11", steps=50)
    assert F.shape == (51, 2, 2) and d[0] == 1.0 and d[-1] == pytest.approx(0.9)
    np.testing.assert_array_equal(F[:, 1, 1], 1.0)
    d, F = load_path("shear21", steps=10, shear=0.1)
    assert d[-1] == pytest.approx(0.1) and np.all(F[:, 0, 1] == 0) and np.all(F[:, 1, 0] == d)
    with pytest.raises(InputError, match="unknown load path"):
        load_path("shear13")
    with pytest.raises(InputError, match="compression"):
        load_path("compression22", compression=1.5)


def test_study_values_and_statistics(small_set, tmp_path):
    res, h5, pngs = run_study(small_set, tmp_path, normal_stiffness=KN, steps=8)
    assert res.cauchy.shape == (6, 4, 9, 2, 2)
    # spot check against the independent brute force (end of each path, one RVE per size)
    for r in (0, 3):
        for q, _p in enumerate(PATHS):
            ref = homogenize_bruteforce(res.packings[res.names[r]], res.F[q, -1], KN)
            np.testing.assert_allclose(
                res.cauchy[r, q, -1],
                ref["cauchy"],
                rtol=0,
                atol=1e-12 * np.abs(ref["cauchy"]).max(),
            )
            assert res.n_contacts[r, q, -1] == ref["n_contacts"]
    # compression makes every normal stress more compressive (tension positive: more negative)
    for q in (0, 1):
        i = DRIVING[PATHS[q]][0]
        assert np.all(np.diff(res.cauchy[:, q, :, i, i], axis=1) < 0)
    mean, std, count = res.summary()[30]
    np.testing.assert_allclose(mean, res.cauchy[:3].mean(axis=0))
    np.testing.assert_allclose(std, res.cauchy[:3].std(axis=0, ddof=1))
    assert count == 3
    with h5py.File(h5) as f:
        assert f.attrs["kind"] == "rve-study"
        np.testing.assert_array_equal(f["paths/shear12/cauchy"][()], res.cauchy[:, 2])
        np.testing.assert_array_equal(f["summary/compression22/60/cauchy_std"][()], res.summary()[60][1][1])
        assert f["fabric/density"].shape == (6, 3, 720)
        assert f["fabric"].attrs["most_uniform_60"] == res.most_uniform(60)
    assert sorted(p.name for p in pngs) == ["compression.png", "fabric.png", "shear.png"]
    assert all(p.read_bytes()[:4] == b"\x89PNG" for p in pngs)


def test_study_compute_object_guards(small_set):
    s = RVEStudy(small_set, steps=2)
    with pytest.raises(InputError, match="run"):
        _ = s.result
    with pytest.raises(InputError, match="mapping"):
        RVEStudy({})


def test_cli_rve_stress_and_check(tmp_path, capsys):
    p = random_packing(40, seed=3, phi=0.9)
    f = save_packing(tmp_path / "p.h5", p)
    assert main(["rve-stress", str(f), "--F", "0.98", "0.02", "0", "1.01", "--kn", "1e7"]) == 0
    out = capsys.readouterr().out
    want = homogenize(p, np.array([[0.98, 0.02], [0.0, 1.01]]), 1e7)
    assert f"active contacts: {want.n_contacts}" in out
    assert f"W (J/m^2) = {want.energy:.12g}" in out
    assert main(["rve-stress", str(f), "--F", "1", "0", "0", "-1"]) == 2
    assert "det F must be > 0" in capsys.readouterr().err
    assert main(["rve-stress", str(tmp_path / "missing.h5")]) == 2
    assert main(["rve-check", "--packings", str(f)]) == 0
    assert "contact counts equal: True" in capsys.readouterr().out


def test_cli_rve_study(tmp_path, capsys, small_set):
    files = [str(save_packing(tmp_path / f"{k}.h5", p)) for k, p in list(small_set.items())[:2]]
    assert main(["rve-study", "--packings", *files, "--steps", "4", "-o", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "rve_study.h5").exists() and (tmp_path / "out" / "shear.png").exists()
    assert main(["rve-stress", str(tmp_path / "out" / "rve_study.h5")]) == 2
    assert "--rve NAME" in capsys.readouterr().err
    assert main(["rve-stress", str(tmp_path / "out" / "rve_study.h5"), "--rve", "nope"]) == 2


def test_study_on_a_two_worker_cluster_is_bitwise_in_process(small_set, tmp_path, capsys):
    """`gransim rve-study --workers 2`: one task per RVE on a LocalCluster (processes, 1 thread each,
    no dashboard) gives the in-process batched numbers bit for bit (each RVE's candidate sets come
    from its own states in the same order), including the fabric."""
    pytest.importorskip("distributed")
    from gransim.parallel import make_executor

    ref = RVEStudy(small_set, normal_stiffness=KN, steps=6).run().result
    ex = make_executor(workers=2)
    try:
        res = RVEStudy(small_set, normal_stiffness=KN, steps=6, executor=ex).run().result
    finally:
        ex.close()
    for k in ("cauchy", "piola", "energy", "n_contacts"):
        np.testing.assert_array_equal(getattr(res, k), getattr(ref, k))
    for name in ref.names:
        np.testing.assert_array_equal(res.fabric[name].density, ref.fabric[name].density)
    f = str(save_packing(tmp_path / "p.h5", next(iter(small_set.values()))))
    assert main(["rve-study", "--workers", "0", "--packings", f, "-o", str(tmp_path / "o")]) == 2
    assert "--workers" in capsys.readouterr().err
