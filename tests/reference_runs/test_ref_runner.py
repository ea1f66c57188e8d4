"""The job runner: success, skipping, and failing jobs reported with log lines and no complete manifest."""

import numpy as np
import pytest

from reference_runs.datafile import write_data_file
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import is_complete, read_manifest, run_job

SETUP = """\
units si
atom_style sphere
dimension 2
boundary {boundary} p
newton off
communicate single vel yes
atom_modify map array sort 0 0.0
read_data p.data
neighbor 1e-5 bin
{neigh}
fix m1 all property/global kn peratomtypepair 1 1e6
fix m2 all property/global kt peratomtypepair 1 0
fix m3 all property/global gamman peratomtypepair 1 0
fix m4 all property/global gammat peratomtypepair 1 0
fix m5 all property/global coefficientFriction peratomtypepair 1 0
pair_style gran model hooke/stiffness tangential no_history
pair_coeff * *
fix 2d all enforce2d
thermo_style custom step atoms
thermo_modify lost error
"""


def deck(boundary="p p", neigh="neigh_modify delay 0", tail="run 0\n"):
    return SETUP.format(boundary=boundary, neigh=neigh) + tail


@pytest.fixture
def data(tmp_path):
    p = perturbed_lattice(6, 6, seed=1)
    path = tmp_path / "p.data"
    v = np.zeros((p.n, 2))
    v[:, 0] = 50.0  # fast enough to leave an open box within a few steps
    write_data_file(path, p, velocities=v)
    return path


def assert_failed(job, exc, *needles):
    msg = str(exc.value)
    for n in needles:
        assert n in msg, msg
    assert "relevant log lines" in msg
    m = read_manifest(job)
    assert m is not None and m["status"] == "failed" and not is_complete(job)


def test_missing_binary(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    with pytest.raises(ReferenceRunError, match="apt-get install liggghts"):
        run_job(tmp_path / "job", "run 0\n", progress=False)
    assert read_manifest(tmp_path / "job") is None


@pytest.mark.liggghts
def test_ok_then_skipped_then_rerun_on_new_input(tmp_path, data):
    job = tmp_path / "job"
    r1 = run_job(job, deck(), {"p.data": data}, progress=False)
    assert not r1.skipped and r1.manifest["status"] == "ok" and is_complete(job)
    assert "3.8.0" in r1.manifest["liggghts_version"] and r1.manifest["command"][0].endswith("liggghts")
    assert len(r1.log.runs) == 1 and r1.log.runs[0]["Atoms"][0] == 36
    r2 = run_job(job, deck(), {"p.data": data}, progress=False)
    assert r2.skipped and r2.manifest == r1.manifest
    r3 = run_job(job, deck(), {"p.data": data.read_bytes() + b"\n"}, progress=False)
    assert not r3.skipped
    (job / "log.lammps").unlink()  # a complete job needs its log
    assert not is_complete(job)
    r4 = run_job(job, deck(), {"p.data": str(data)}, progress=False)  # str path: copied
    assert not r4.skipped and r4.manifest["input_sha256"] == r1.manifest["input_sha256"]
    assert not r3.skipped and r3.manifest["input_sha256"] != r1.manifest["input_sha256"]


@pytest.mark.liggghts
def test_bad_deck(tmp_path, data):
    job = tmp_path / "job"
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, deck(tail="run 0\nfrobnicate all\n"), {"p.data": data}, progress=False)
    assert_failed(job, exc, "Unknown command: frobnicate all", "frobnicate")


@pytest.mark.liggghts
def test_lost_atoms(tmp_path, data):
    job = tmp_path / "job"
    tail = "fix i all nve/sphere\ntimestep 1e-5\nthermo 1\nrun 200\n"
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, deck(boundary="f f", tail=tail), {"p.data": data}, progress=False)
    assert_failed(job, exc, "Lost atoms")


@pytest.mark.liggghts
def test_timeout(tmp_path, data):
    job = tmp_path / "job"
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, deck(tail="run 0\nshell sleep 30\n"), {"p.data": data}, timeout=1.0, progress=False)
    assert_failed(job, exc, "timed out")


@pytest.mark.liggghts
def test_unexpected_warning_fails_unless_allowed(tmp_path, data):
    job = tmp_path / "job"
    d = deck(neigh="", tail="fix i all nve/sphere\ntimestep 1e-9\nrun 1\n")
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, d, {"p.data": data}, progress=False)
    assert_failed(job, exc, "WARNING", "neigh_modify delay 0")
    ok = run_job(job, d, {"p.data": data}, progress=False, allowed_warnings=[r"neigh_modify delay 0"])
    assert ok.manifest["status"] == "ok" and len(ok.warnings) == 1


@pytest.mark.liggghts
def test_missing_output(tmp_path, data):
    job = tmp_path / "job"
    with pytest.raises(ReferenceRunError, match="not written"):
        run_job(job, deck(), {"p.data": data}, outputs=["never.dump"], progress=False)
    assert not is_complete(job)


def test_nonzero_exit_without_error_line(monkeypatch, tmp_path):
    # a stand-in binary that crashes (as a segfault would): no ERROR line, exit status 139
    bindir = tmp_path / "bin"
    bindir.mkdir()
    fake = bindir / "liggghts"
    fake.write_text(
        "#!/bin/sh\necho 'LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, stand-in)' > log.lammps\n"
        "echo 'Step Atoms' >> log.lammps\necho '0 36' >> log.lammps\n"
        "echo 'Signal: Segmentation fault (11)' >&2\nexit 139\n"
    )
    fake.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}:/usr/bin:/bin")
    job = tmp_path / "job"
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, "run 0\n", progress=False)
    assert_failed(job, exc, "exited with status 139", "Segmentation fault", "0 36")
