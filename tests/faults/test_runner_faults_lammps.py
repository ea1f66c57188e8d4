"""Fault tests of LAMMPS jobs (``run_job(..., engine="lammps")``) through fake ``lmp`` binaries.

The fakes (tests/faults/fakes.py, ``engine="lammps"``) answer with the LAMMPS banner; the kinds
that run the real binary need ``lmp`` (skipped otherwise).
"""

import shutil
import time

import pytest
from fakes import pid_alive

from reference_runs.errors import ReferenceRunError
from reference_runs.runner import is_complete, read_manifest, run_job

needs_lmp = pytest.mark.skipif(shutil.which("lmp") is None, reason="lmp not installed (apt-get install lammps)")


def assert_not_ok(job):
    m = read_manifest(job)
    assert m is not None and m["status"] == "failed" and m.get("error")
    assert not is_complete(job)
    assert m["engine"] == "lammps" and m["deck"] == "in.lammps" and (job / "in.lammps").exists()
    return m


def test_fake_lmp_error(tmp_path, fake_lmp, small_lammps_job):
    fake = fake_lmp("error")
    deck, files, outputs = small_lammps_job()
    with pytest.raises(ReferenceRunError, match="LAMMPS job .*LAMMPS stopped with an error: ERROR: fake failure"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    m = assert_not_ok(tmp_path / "job")
    assert m["engine_version"] == "LAMMPS 29 Sep 2021 - Update 2 fake-error"
    assert m["engine_binary"] == str(fake.path) and m["engine_package"] is None
    assert "liggghts_version" not in m  # the old keys are for LIGGGHTS jobs only
    assert fake.pids() and fake.wait_gone(2) == []


def test_fake_lmp_silent(tmp_path, fake_lmp, small_lammps_job):
    fake_lmp("silent")
    deck, files, outputs = small_lammps_job()
    with pytest.raises(ReferenceRunError, match=r"incomplete: log.lammps was not written \(lmp exited"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    assert_not_ok(tmp_path / "job")


def test_fake_lmp_hang_killed(tmp_path, fake_lmp, small_lammps_job):
    fake = fake_lmp("hang")
    deck, files, outputs = small_lammps_job()
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match=r"timed out after 1.5 s \(killed\)") as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, timeout=1.5, engine="lammps")
    assert exc.value.timed_out and time.monotonic() - t0 < 8
    assert_not_ok(tmp_path / "job")
    assert [p for p in fake.pids() if pid_alive(p)] == []


@needs_lmp
def test_fake_lmp_truncated_log(tmp_path, fake_lmp, small_lammps_job):
    fake = fake_lmp("truncate-log")
    deck, files, outputs = small_lammps_job("run 40\n")
    with pytest.raises(ReferenceRunError) as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    msg = str(exc.value)
    assert "incomplete: log.lammps holds 0 of 1 runs" in msg and "stops at step 8" in msg, msg
    m = assert_not_ok(tmp_path / "job")
    assert "fake-truncate-log" in m["engine_version"]
    assert fake.wait_gone(2) == []


@needs_lmp
def test_fake_lmp_cut_dumps(tmp_path, fake_lmp, small_lammps_job):
    fake_lmp("cut-dumps")
    deck, files, outputs = small_lammps_job("run 20\n", dump_every=5)
    with pytest.raises(ReferenceRunError, match="dump.atoms: expected 5 frames, got 1"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    assert_not_ok(tmp_path / "job")


@needs_lmp
def test_fake_lmp_warning_fails_unless_allowed(tmp_path, fake_lmp, small_lammps_job):
    fake_lmp("warning")
    deck, files, outputs = small_lammps_job()
    with pytest.raises(ReferenceRunError, match="1 unexpected WARNING line"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    res = run_job(
        tmp_path / "job2",
        deck,
        files,
        outputs=outputs,
        progress=False,
        engine="lammps",
        allowed_warnings=[r"fake warning"],
    )
    assert res.manifest["status"] == "ok" and len(res.warnings) == 1


def test_liggghts_binary_is_not_taken_for_lammps(tmp_path, fake_liggghts, small_lammps_job, monkeypatch):
    # only a (fake) liggghts on PATH: a LAMMPS job asks for lmp and says how to install it
    fake = fake_liggghts("error")
    monkeypatch.setenv("PATH", str(fake.bindir))  # liggghts there, no lmp
    deck, files, outputs = small_lammps_job()
    with pytest.raises(
        ReferenceRunError,
        match=r"`lmp` binary \(LAMMPS\) was not found on PATH; "
        r"install LAMMPS with `sudo apt-get install lammps`",
    ):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, engine="lammps")
    assert read_manifest(tmp_path / "job") is None
