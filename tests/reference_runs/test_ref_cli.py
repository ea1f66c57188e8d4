"""``gransim reference`` command line."""

import shutil

import pytest

from gransim.cli import main
from gransim.io import save_packing
from reference_runs.demo_packings import perturbed_lattice


def test_list(capsys):
    assert main(["reference", "list"]) == 0
    assert "taylor-demo" in capsys.readouterr().out


def test_unknown_case_and_no_packings(capsys, tmp_path):
    assert main(["reference", "run", "no-such-case", "--out", str(tmp_path)]) == 2
    assert "unknown reference case 'no-such-case'" in capsys.readouterr().err
    assert main(["reference", "taylor", "--out", str(tmp_path)]) == 2
    assert "no packings" in capsys.readouterr().err


def test_missing_binary_is_one_line_error(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert main(["reference", "taylor", "--demo", "--out", str(tmp_path / "o"), "--stride", "50"]) == 2
    err = capsys.readouterr().err
    assert "apt-get install liggghts" in err


@pytest.mark.liggghts
def test_taylor_command_on_packing_files(capsys, tmp_path):
    for s in (1, 2):
        save_packing(tmp_path / f"rve{s}.h5", perturbed_lattice(8, 8, seed=s))
    rc = main(["reference", "taylor", "--rves", str(tmp_path), "--stride", "25", "--out", str(tmp_path / "o")])
    out = capsys.readouterr().out
    assert rc == 0 and "PASS" in out and "rve1" in out and "rve2" in out
    assert (tmp_path / "o" / "taylor.h5").exists()
    from reference_runs.taylor import read_taylor_h5

    d = read_taylor_h5(tmp_path / "o" / "taylor.h5")
    assert set(d) == {"rve1", "rve2"} and d["rve1"][("shear-21", "images")]["cauchy"].shape == (3, 2, 2)


@pytest.mark.liggghts
@pytest.mark.skipif(shutil.which("mpirun") is None, reason="mpirun not installed")
def test_taylor_under_mpirun(tmp_path):
    import numpy as np

    from reference_runs.cases import compare_taylor
    from reference_runs.taylor import run_taylor

    run = run_taylor(perturbed_lattice(12, 12, seed=4), 2.8e7, tmp_path / "j", stride=25, np_procs=2, progress=False)
    assert run.manifest["command"][0].endswith("mpirun") and run.manifest["np"] == 2
    assert max(compare_taylor(run).values()) < 1e-10
    assert np.isfinite(run.get("shear-12").cauchy).all()


def test_missing_lammps_binary_names_its_package(monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    rc = main(["reference", "taylor", "--demo", "--engine", "lammps", "--out", str(tmp_path / "o"), "--stride", "50"])
    assert rc == 2
    err = capsys.readouterr().err
    assert "apt-get install lammps" in err and "Traceback" not in err


@pytest.mark.skipif(shutil.which("lmp") is None, reason="LAMMPS (lmp) not installed")
def test_taylor_command_on_lammps_records_its_version(capsys, tmp_path):
    import h5py

    save_packing(tmp_path / "rve1.h5", perturbed_lattice(8, 8, seed=1))
    rc = main(
        [
            "reference",
            "taylor",
            "--rves",
            str(tmp_path),
            "--stride",
            "25",
            "--engine",
            "lammps",
            "--out",
            str(tmp_path / "o"),
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0 and "LAMMPS vs numpy" in out and "PASS" in out
    with h5py.File(tmp_path / "o" / "taylor.h5") as f:
        assert f.attrs["lammps_version"].startswith("LAMMPS ")
        assert "liggghts_version" not in f.attrs
        assert f["rve1"].attrs["engine"] == "lammps"
        assert '"engine": "lammps"' in f.attrs["parameters"]
