"""``gransim reference taylor --engine yade``: the Taylor states of packings through YADE, compared
with numpy and gransim, stored in the HDF5 schema of the other two codes with YADE's version; a
missing ``yade`` and a failing YADE job are one-line errors (status 2 and 1)."""

import shutil

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.io import save_packing
from reference_runs.decks.taylor import PATHS
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.taylor import read_taylor_h5

needs_yade = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)


def _args(tmp_path, *more):
    save_packing(tmp_path / "rve1.h5", perturbed_lattice(6, 6, seed=1))
    return ["reference", "taylor", str(tmp_path / "rve1.h5"), "--engine", "yade", "--stride", "25", *more]


def test_missing_yade_is_one_line_error_naming_its_package(monkeypatch, capsys, tmp_path):
    args = _args(tmp_path, "--out", str(tmp_path / "o"))
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "apt-get install yade" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o" / "taylor.h5").exists()


def test_np_above_one_is_refused_before_anything_runs(capsys, tmp_path):
    assert main(_args(tmp_path, "--np", "2", "--out", str(tmp_path / "o"))) == 2
    assert "--np: a YADE job runs as one process" in capsys.readouterr().err
    assert not (tmp_path / "o" / "jobs").exists()


def test_failing_yade_job_is_status_1_with_its_message(monkeypatch, capsys, tmp_path):
    """A `yade` that prints YADE's banner and exits 3 (a script that failed): status 1, the job's
    own reason, no traceback, no results file."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "yade"
    fake.write_text("#!/bin/sh\necho 'Welcome to Yade 2023.02a'\necho 'RuntimeError: boom' >&2\nexit 3\n")
    fake.chmod(0o755)
    args = _args(tmp_path, "--out", str(tmp_path / "o"))
    monkeypatch.setenv("PATH", f"{bin_dir}:/usr/bin:/bin")
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "the YADE run failed" in err and "exited with status 3" in err and "RuntimeError: boom" in err
    assert "Traceback" not in err
    assert not (tmp_path / "o" / "taylor.h5").exists()


@needs_yade
def test_taylor_command_on_yade_writes_the_schema_with_yades_version(capsys, tmp_path):
    rc = main(_args(tmp_path, "--out", str(tmp_path / "o")))
    out = capsys.readouterr().out
    assert rc == 0, out
    assert "YADE vs numpy Taylor stress" in out and "PASS" in out and "FAIL" not in out and "contacts the same" in out
    h5 = tmp_path / "o" / "taylor.h5"
    with h5py.File(h5) as f:
        assert f.attrs["yade_version"].startswith("YADE 2023.02a (")
        assert "liggghts_version" not in f.attrs and "lammps_version" not in f.attrs
        assert f["rve1"].attrs["engine"] == "yade"
        assert '"engine": "yade"' in f.attrs["parameters"]
        assert '"engine_version": "YADE 2023.02a"' in f["rve1"].attrs["manifest"]
    d = read_taylor_h5(h5)["rve1"]
    assert set(d) == {(p, "periodic") for p in PATHS}  # YADE's periodic cell shears: every path
    for p in PATHS:
        s = d[(p, "periodic")]
        assert s["cauchy"].shape == s["cauchy_pressure"].shape == (3, 2, 2) and s["stress_atom_sum"].shape == (3, 3)
        assert np.isfinite(s["cauchy"]).all() and (np.diagonal(s["cauchy"], axis1=1, axis2=2) < 0).all()
