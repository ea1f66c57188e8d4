"""gransim.fem.compare (Taylor vs relaxed slope results from their slope.h5) and gransim.fem.stability.

Small real results: the reduced slope (10 x 5 Q1, 200 Gauss points), a 30-disk jittered lattice RVE
(as tests/cli/test_slope_resume.py), dead load then the service footing load in 2 steps, with the
Taylor and with the relaxed RVE (about 10 s and 30 s on a loaded 2-core machine). Checked:

* the stress map of a result against itself is zero everywhere, and a difference planted at one
  Gauss point of a copy is found there (and only there);
* the RVE pictures rebuild each marked Gauss point's RVE: the Taylor one from F alone, the relaxed
  one by replaying the committed F of the run's checkpoint; both give back the stored Cauchy
  stress to round-off (a wrong packing, F or history would not);
* observed orders on exact sequences (e_k+1 = e_k^2: 2; e_k+1 = e_k / 10: 1), round-off excluded;
* the RVE shear stiffness from the tangent equals the energy's second difference (independent);
* the CLI writes the three files and refuses a file that is not a slope result.
"""

import shutil

import h5py
import numpy as np
import pytest

from gransim import Packing
from gransim.fem import compare as cmp
from gransim.fem.mesh import SlopeGeometry


def _lattice():
    a, nx, ny = 1e-3, 5, 6
    h = a * np.sqrt(3) / 2
    ii, jj = np.meshgrid(np.arange(nx), np.arange(ny), indexing="ij")
    x = np.column_stack([(ii + 0.5 * (jj % 2)).ravel() * a, jj.ravel() * h])
    x += np.random.default_rng(1).uniform(-2e-4, 2e-4, x.shape) * a
    return Packing(positions=x, radii=np.full(len(x), 0.5 * a * 1.0005), cell=np.diag([nx * a, ny * h]))


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    from gransim.fem.run import run_slope_case
    from gransim.io import save_packing

    tmp = tmp_path_factory.mktemp("slopes")
    packing = tmp / "lattice.h5"
    save_packing(packing, _lattice())
    out = {}
    for rve in ("taylor", "relaxed"):
        s = run_slope_case(
            "service",
            packing=str(packing),
            out=tmp / rve,
            figures="none",
            geometry=SlopeGeometry(columns=10, rows=5),
            rve=rve,
            load_steps=2,
        )
        assert s["completed"], s["message"]
        out[rve] = tmp / rve / "slope.h5"
    out["packing"] = packing
    return out


def test_map_of_a_result_against_itself_is_zero(runs, tmp_path):
    a = cmp.read_slope(runs["relaxed"])
    b = cmp.read_slope(runs["relaxed"])
    step = cmp.common_step(a, b)
    assert step == 3
    d = cmp.stress_difference(a, b, step)
    assert d.shape == (200,) and np.all(d == 0)
    assert cmp.most_different(d, 4) == []
    res = cmp.compare_slopes([runs["relaxed"], runs["relaxed"]], tmp_path, packing=runs["packing"])
    assert res["points"] == [] and np.all(res["difference"] == 0)


def test_planted_difference_is_found_where_it_was_planted(runs, tmp_path):
    planted = tmp_path / "planted.h5"
    shutil.copy(runs["taylor"], planted)
    g0, g1 = 137, 12
    with h5py.File(planted, "r+") as f:
        s = f["steps/003/cauchy"]
        sig = s[()]
        scale = np.linalg.norm(sig.reshape(len(sig), -1), axis=1).max()
        sig[g0, 0, 1] += 0.3 * scale
        sig[g0, 1, 0] += 0.3 * scale
        sig[g1, 1, 1] -= 0.1 * scale
        s[...] = sig
    a, b = cmp.read_slope(runs["taylor"]), cmp.read_slope(planted)
    d = cmp.stress_difference(a, b, 3)
    assert cmp.most_different(d, 4) == [g0, g1]  # only the two planted points differ
    assert d[g0] == pytest.approx(0.3 * np.sqrt(2), rel=1e-12) and d[g1] == pytest.approx(0.1, rel=1e-12)


def test_taylor_and_relaxed_rves_are_rebuilt_with_their_stored_stress(runs, tmp_path):
    res = cmp.compare_slopes([runs["taylor"], runs["relaxed"]], tmp_path, n_points=3, packing=runs["packing"])
    assert res["step"] == 3 and len(res["points"]) == 3
    d = res["difference"]
    assert d[res["points"][0]] == d.max() > 0
    # the relaxed RVE is rebuilt from the checkpoint's committed F: the same stress as the run
    errs = res["replay_errors"]
    assert len(errs) == 6 and max(errs.values()) < 1e-10, errs
    for name in ("compare_load_settlement.png", "compare_map.png", "compare.md"):
        assert (tmp_path / name).stat().st_size > 0
    # without the checkpoint the converged steps' F replace the commits (no step was cut: the same)
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(runs["relaxed"], alone / "slope.h5")
    r = cmp.read_slope(alone / "slope.h5")
    state = cmp.rve_state(r, 3, res["points"][0], cmp.rve_packings(r, runs["packing"]))
    assert state["source"] == "converged steps of slope.h5" and state["replay_error"] < 1e-10
    assert np.abs(state["w"]).max() > 0  # the relaxed RVE has fluctuations


def test_wrong_packing_is_refused(runs):
    from gransim.io import save_packing

    r = cmp.read_slope(runs["taylor"])
    p = _lattice()
    other = Packing(positions=p.positions, radii=p.radii * 1.0001, cell=p.cell)
    path = runs["packing"].parent / "other.h5"
    save_packing(path, other)
    with pytest.raises(cmp.InputError, match="fingerprint"):
        cmp.rve_packings(r, path)


def test_observed_orders_on_exact_sequences():
    quad = [1.0, 1e-2, 1e-4, 1e-8, 1e-16, 1e-32]  # e_k+1 = e_k^2 ... then round-off (1e-32) left out
    assert np.allclose(cmp.newton_orders(quad), [1.0, 2.0, 2.0])
    assert cmp.final_order(quad) == pytest.approx(2.0)
    lin = [10.0**-k for k in range(8)]
    assert np.allclose(cmp.newton_orders(lin), 1.0)
    assert np.isnan(cmp.final_order([1.0, 1e-3, 1e-9, 1e-30]))  # one order above round-off: not judged


def test_rve_shear_stiffness_tangent_matches_energy(runs):
    from gransim.fem.stability import rve_shear_stiffness
    from gransim.io import load_packing

    p = load_packing(runs["packing"])
    for kind in ("taylor", "relaxed"):
        s = rve_shear_stiffness(p, kind)
        assert s["tangent"] > 0 and s["relative_difference"] < 1e-4, (kind, s)


def test_cli(runs, tmp_path, capsys):
    from gransim.cli import main

    rc = main(
        [
            "slope-compare",
            str(runs["taylor"]),
            str(runs["relaxed"]),
            "--out",
            str(tmp_path / "c"),
            "--packing",
            str(runs["packing"]),
            "--points",
            "2",
        ]
    )
    assert rc == 0
    text = (tmp_path / "c" / "compare.md").read_text()
    assert "taylor service" in text and "relaxed service" in text and "observed orders" in text
    capsys.readouterr()
    try:
        rc = main(["slope-compare", str(runs["taylor"]), str(runs["packing"]), "--out", str(tmp_path / "d")])
    except SystemExit as exc:
        rc = exc.code
    err = capsys.readouterr().err
    assert rc == 2 and "fem-slope" in err
