"""``gransim shear``: simple shear of a packing in the sheared cell, its run file and its bad inputs."""

import json

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.io import save_packing
from reference_runs.decks.shear import short_case


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p, _, _, _ = short_case("constant-volume")  # 120 dense disks, Lx = 0.02 m, Ly = 0.0208 m
    path = tmp_path_factory.mktemp("shear") / "p.h5"
    save_packing(path, p)
    return path, p


def _series(path):
    with h5py.File(path, "r") as f:
        g = f["series"]
        return {k: g[k][()] for k in g}, dict(f.attrs), sorted(f["snapshots"], key=int)


def test_constant_volume_run_file_holds_the_series(packing_file, tmp_path, capsys):
    path, p = packing_file
    out = tmp_path / "run.h5"
    fig = tmp_path / "fig.png"
    assert (
        main(
            [
                "shear",
                "--packing",
                str(path),
                "--strain",
                "0.004",
                "--rate",
                "5",
                "--series-every",
                "7",
                "-o",
                str(out),
                "--plot",
                str(fig),
            ]
        )
        == 0
    )
    assert fig.stat().st_size > 0 and "wrote" in capsys.readouterr().out
    s, attrs, snaps = _series(out)
    assert attrs["kind"] == "shear-run" and attrs["complete"] and attrs["stop_reason"] == ""
    assert attrs["gransim_version"] and attrs["git_commit"] and attrs["seed"] == str(p.metadata.get("seed"))
    par = json.loads(attrs["parameters"])
    dt, n = par["dem"]["dt"], int(attrs["nsteps"])
    assert par["loading"]["xy"] == "erate" and par["loading"]["erate"] == 5.0 and par["cli"]["strain"] == 0.004
    # steps 0, 7, 14, ..., and the last; the strain reached is --strain, to less than one step
    assert n == int(np.ceil(0.004 / (5.0 * dt)))
    np.testing.assert_array_equal(s["step"], sorted(set(range(0, n + 1, 7)) | {n}))
    np.testing.assert_allclose(s["time"], s["step"] * dt, rtol=1e-15)
    assert 0.004 <= s["shear_strain"][-1] < 0.004 + 5.0 * dt
    np.testing.assert_allclose(s["shear_strain"], s["step"] * dt * 5.0, rtol=1e-9, atol=1e-15)
    assert attrs["shear_strain_reached"] == s["shear_strain"][-1]
    # constant volume: Lx, Ly fixed, the tilt grows; the box is the packing's cell at step 0
    assert np.all(s["box"][:, 0] == p.cell[0, 0]) and np.all(s["box"][:, 1] == p.cell[1, 1])
    assert s["box"][0, 2] == 0.0 and np.all(np.diff(s["box"][:, 2]) > 0)
    # tension positive: the dense packing pushes (sigma_xx, sigma_yy < 0) and positive shear gives a
    # growing positive sigma_xy
    st = s["stress"]
    assert np.all(st[:, 0, 0] < 0) and np.all(st[:, 1, 1] < 0)
    assert st[-1, 0, 1] > 0 and st[-1, 0, 1] > st[0, 0, 1]
    assert snaps == ["0", str(n)]
    with h5py.File(out, "r") as f:
        assert f["snapshots"][str(n)]["positions"].shape == (p.n, 2)
        np.testing.assert_allclose(f["snapshots"][str(n)]["cell"][0, 1], s["box"][-1, 2], rtol=0, atol=0)


def test_file_stress_is_the_engine_stress_with_tension_positive(packing_file, tmp_path):
    # the API run of the recorded settings: the file's rows are its stress with the sign flipped
    from gransim.dem import DEMSettings
    from gransim.dem.sheared import ShearLoading, simple_shear

    path, p = packing_file
    out = tmp_path / "run.h5"
    assert (
        main(
            [
                "shear",
                "--packing",
                str(path),
                "--strain",
                "0.004",
                "--rate",
                "20",
                "--series-every",
                "1",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    s, attrs, _ = _series(out)
    par = json.loads(attrs["parameters"])
    ref = simple_shear(p, DEMSettings(**par["dem"]), ShearLoading(**par["loading"]), int(attrs["nsteps"]))
    np.testing.assert_array_equal(s["stress"][0], -ref["setup_stress"])
    np.testing.assert_array_equal(s["stress"][1:], -ref["stress"])
    np.testing.assert_array_equal(s["box"][1:], ref["box"])


def test_servo_moves_y_and_is_recorded(packing_file, tmp_path):
    path, p = packing_file
    out = tmp_path / "servo.h5"
    assert (
        main(["shear", "--packing", str(path), "--strain", "0.01", "--rate", "20", "--servo", "1000", "-o", str(out)])
        == 0
    )
    s, attrs, _ = _series(out)
    par = json.loads(attrs["parameters"])
    assert par["loading"]["y"] == "servo" and par["loading"]["target"] == 1000.0
    assert np.any(s["box"][:, 1] != p.cell[1, 1])  # y moves under the servo
    assert np.all(s["box"][:, 0] == p.cell[0, 0])


@pytest.mark.parametrize(
    "argv, needle",
    [
        (["--strain", "-0.1"], "--strain: must be finite and > 0"),
        (["--strain", "0.6"], "beyond Lx/2"),
        (["--strain", "0.01", "--rate", "0"], "--rate: must be finite and > 0"),
        (["--strain", "0.01", "--servo", "-5"], "--servo: must be finite and > 0"),
        (["--strain", "0.01", "--flavour", "liggghts"], "--flavour liggghts: the sheared periodic cell"),
        (["--strain", "0.01", "--flavour", "yade"], "--flavour: expected lammps"),
        (["--strain", "0.01", "--series-every", "0"], "--series-every: expected an integer >= 1"),
        (["--strain", "0.01", "--plot", "fig.xyz"], "--plot:"),
    ],
)
def test_bad_input_one_line_exit_2(packing_file, tmp_path, capsys, argv, needle):
    path, _ = packing_file
    out = tmp_path / "run.h5"
    rc = main(["shear", "--packing", str(path), "-o", str(out), *argv])
    err = capsys.readouterr().err
    assert rc == 2 and not out.exists()
    assert err.startswith("gransim shear: error: ") and err.count("\n") == 1 and needle in err, err


def test_bad_files_one_line_exit_2(packing_file, tmp_path, capsys):
    path, _ = packing_file
    rc = main(["shear", "--packing", str(tmp_path / "missing.h5"), "--strain", "0.01", "-o", str(tmp_path / "r.h5")])
    err = capsys.readouterr().err
    assert rc == 2 and "--packing" in err and "no such file" in err and err.count("\n") == 1
    rc = main(["shear", "--packing", str(path), "--strain", "0.01", "-o", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and "-o/--output" in err and err.count("\n") == 1
    not_a_packing = tmp_path / "junk.h5"
    not_a_packing.write_text("not hdf5")
    rc = main(["shear", "--packing", str(not_a_packing), "--strain", "0.01", "-o", str(tmp_path / "r.h5")])
    err = capsys.readouterr().err
    assert rc == 2 and "junk.h5" in err and err.count("\n") == 1


def test_rate_and_inertial_number_exclude_each_other(packing_file, tmp_path):
    path, _ = packing_file
    with pytest.raises(SystemExit) as e:
        main(
            [
                "shear",
                "--packing",
                str(path),
                "--strain",
                "0.01",
                "--rate",
                "1",
                "--inertial-number",
                "1e-3",
                "-o",
                str(tmp_path / "r.h5"),
            ]
        )
    assert e.value.code == 2
