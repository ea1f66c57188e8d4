"""The LIGGGHTS job runner under faults: it never accepts or reuses incomplete evidence, bounds time,
leaves no process behind, and lets one writer at a time into a job directory."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from fakes import pid_alive, write_fake

from gransim.io.provenance import liggghts_package_version, liggghts_version
from reference_runs.errors import DirectoryBusyError, ReferenceRunError
from reference_runs.expect import dump_frame_steps, expected_evidence
from reference_runs.locks import DirectoryLock
from reference_runs.runner import is_complete, read_manifest, run_job, verify_job

STORED = Path(__file__).resolve().parents[2] / "reference_runs" / "stored"
REPO = Path(__file__).resolve().parents[2]

# measured on LIGGGHTS-PUBLIC 3.8.0 (Debian): frames of `dump ... custom 7` and `dump ... local 3`
# for this tail: 0 7 14 28 and 0 3 6 9 12 15 24 27 30 (d2 undumped before the last run)
MULTI_TAIL = """\
variable n equal 10
variable m index 5
run ${n}
run 0
run $m
reset_timestep 23
run 4
run 30 upto
undump d2
run 3
"""


def assert_not_ok(job):
    m = read_manifest(job)
    assert m is not None and m["status"] == "failed", m
    assert not is_complete(job)
    return m


# ----------------------------------------------------------------------------- the deck reader
def test_deck_reader_refuses_to_guess():
    e = expected_evidence("variable n equal 2*5\nrun ${n}\n")
    assert e.runs is None and "not a plain number" in e.unresolved[0] and "line 2" in e.unresolved[0]
    e = expected_evidence("label a\nrun 10\njump SELF a\n")
    assert e.runs is None and "label" in e.unresolved[0]
    e = expected_evidence("dump d all custom 10 dump.*.x id x\nrun 20\n")
    assert e.n_runs == 1 and e.dumps["dump.*.x"].frames is None and "one file per step" in e.unresolved[0]
    # index variables keep their first value; & continues a line; comments are ignored
    e = expected_evidence("variable k index 4\nvariable k index 9\nrun &\n ${k} # four\nrun 6 upto\n")
    assert [(r.start, r.end) for r in e.runs] == [(0, 4), (4, 6)]


def test_stored_references_verify_and_truncations_are_named(tmp_path):
    assert verify_job(STORED / "biaxial-short") == []  # no manifest: deck in.biaxial, log.liggghts
    assert verify_job(STORED / "taylor-lattice-6x6") == []  # 36 runs, 36 contact dumps
    assert verify_job(STORED / "taylor-rve-70-1") == []
    job = tmp_path / "short"
    shutil.copytree(STORED / "biaxial-short", job)
    steps, cut = dump_frame_steps(job / "dump.atoms")
    assert steps == (0, 500, 1000, 1500, 2000, 2500, 3000) and cut is None
    text = (job / "dump.atoms").read_text()
    (job / "dump.atoms").write_text(text[: text.index("ITEM: TIMESTEP", 1)])
    assert verify_job(job) == ["dump.atoms: expected 7 frames, got 1"]
    lines = (job / "log.liggghts").read_text().splitlines()
    head = next(k for k, ln in enumerate(lines) if ln.split()[:1] == ["Step"])
    (job / "log.liggghts").write_text("\n".join(lines[: head + 13]) + "\n")  # 12 of 3000 steps
    problems = verify_job(job)
    assert problems[0].startswith("incomplete: log.liggghts holds 0 of 1 runs")
    assert "stops at step 11" in problems[0]
    taylor = tmp_path / "taylor"
    shutil.copytree(STORED / "taylor-lattice-6x6", taylor)
    text = (taylor / "log.lammps").read_text()
    (taylor / "log.lammps").write_text(text[: text.rindex("Loop time of")])
    assert any("holds 35 of 36 runs" in p for p in verify_job(taylor))
    # the stored cases carry every hash; a manifest of an older runner (no log_sha256) is named
    assert verify_job(STORED / "taylor-lattice-6x6", require_hashes=True) == []
    old = tmp_path / "old-manifest"
    shutil.copytree(STORED / "taylor-lattice-6x6", old)
    manifest = json.loads((old / "manifest.json").read_text())
    del manifest["log_sha256"]
    (old / "manifest.json").write_text(json.dumps(manifest))
    assert any("log.lammps cannot be checked" in p for p in verify_job(old, require_hashes=True))


@pytest.mark.liggghts
def test_frames_and_runs_of_a_multi_run_deck_match_real_liggghts(tmp_path, small_liggghts_job):
    deck, files, outputs = small_liggghts_job(MULTI_TAIL, dump_every=7, local_every=3)
    res = run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    assert dump_frame_steps(res.path("dump.atoms"))[0] == (0, 7, 14, 28)
    assert dump_frame_steps(res.path("dump.contacts"))[0] == (0, 3, 6, 9, 12, 15, 24, 27, 30)
    ev = res.manifest["evidence"]
    assert ev["runs_expected"] == ev["runs_complete"] == 6
    assert ev["last_steps_expected"] == ev["last_steps_got"] == [10, 10, 15, 27, 30, 33]
    assert ev["dumps"]["dump.atoms"]["frames_expected"] == ev["dumps"]["dump.atoms"]["frames_got"] == 4
    assert ev["dumps"]["dump.contacts"]["frames_expected"] == ev["dumps"]["dump.contacts"]["frames_got"] == 9
    assert res.manifest["liggghts_version"] == "LIGGGHTS-PUBLIC 3.8.0" and res.manifest["log_sha256"]


@pytest.mark.liggghts
def test_our_biaxial_and_taylor_decks_give_the_expected_frames(tmp_path):
    from reference_runs.decks.biaxial import run_liggghts, short_case, write_biaxial_deck
    from reference_runs.demo_packings import perturbed_lattice
    from reference_runs.taylor import run_taylor

    p, s, ld, _ = short_case()
    deck = write_biaxial_deck(tmp_path / "bi", p, s, ld, 120, thermo_every=1, dump_every=50)
    run_liggghts(deck, timeout=120)
    m = read_manifest(tmp_path / "bi")
    assert m["evidence"]["dumps"]["dump.atoms"] == {
        "style": "custom",
        "every": 50,
        "frames_expected": 3,
        "frames_got": 3,
    }
    assert dump_frame_steps(tmp_path / "bi" / "dump.atoms")[0] == (0, 50, 100)
    run = run_taylor(
        perturbed_lattice(4, 4, seed=2),
        2.8e7,
        tmp_path / "ta",
        paths=("compression-11",),
        routes=("periodic",),
        n_steps=2,
        contacts=True,
        progress=False,
        timeout=120,
    )
    ev = run.manifest["evidence"]
    assert ev["runs_expected"] == ev["runs_complete"] == 3 and ev["last_steps_got"] == [0, 1, 2]
    assert sorted(v["frames_got"] for v in ev["dumps"].values()) == [1, 1, 1]


# ----------------------------------------------------------------------------- each fake
def test_fake_error(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("error")
    deck, files, outputs = small_liggghts_job()
    with pytest.raises(ReferenceRunError, match="LIGGGHTS stopped with an error: ERROR: fake failure") as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    assert exc.value.job_dir == tmp_path / "job" and not exc.value.timed_out
    m = assert_not_ok(tmp_path / "job")
    assert m["liggghts_version"] == "LIGGGHTS-PUBLIC 3.8.0 fake-error"
    assert m["liggghts_binary"] == str(fake.path)
    assert m["liggghts_package"] is None
    assert fake.pids() and fake.wait_gone(2) == []


def test_fake_silent(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("silent")
    deck, files, outputs = small_liggghts_job()
    with pytest.raises(ReferenceRunError, match="incomplete: log.lammps was not written"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    m = assert_not_ok(tmp_path / "job")
    assert m["evidence"]["runs_expected"] == 1 and m["evidence"]["runs_found"] == 0
    assert fake.wait_gone(2) == []


def test_fake_silent_without_runs_still_needs_a_log(tmp_path, fake_liggghts):
    fake_liggghts("silent")
    with pytest.raises(ReferenceRunError, match="log.lammps was not written"):
        run_job(tmp_path / "job", "units si\n", progress=False)
    assert_not_ok(tmp_path / "job")


def test_fake_hang_times_out_and_leaves_no_process(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("hang")
    deck, files, outputs = small_liggghts_job()
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match=r"timed out after 1.5 s \(killed\)") as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, timeout=1.5)
    assert time.monotonic() - t0 < 8
    assert exc.value.timed_out and exc.value.job_dir == tmp_path / "job"
    assert_not_ok(tmp_path / "job")
    assert len(fake.pids("grandchild")) == 1  # the grandchild ignores SIGTERM: needs SIGKILL
    assert [p for p in fake.pids() if pid_alive(p)] == []


@pytest.mark.liggghts
def test_fake_truncate_log(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("truncate-log")
    deck, files, outputs = small_liggghts_job("run 40\n")
    with pytest.raises(ReferenceRunError) as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    msg = str(exc.value)
    assert "incomplete: log.lammps holds 0 of 1 runs" in msg and "stops at step 8" in msg, msg
    m = assert_not_ok(tmp_path / "job")
    assert m["evidence"]["runs_complete"] == 0 and m["evidence"]["last_steps_expected"] == [40]
    assert "fake-truncate-log" in m["liggghts_version"]
    assert fake.wait_gone(2) == []


@pytest.mark.liggghts
def test_fake_cut_dumps(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("cut-dumps")
    deck, files, outputs = small_liggghts_job("run 10\nrun 20\n", dump_every=5, local_every=10)
    with pytest.raises(ReferenceRunError, match="dump.atoms: expected 7 frames, got 1") as exc:
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    assert "dump.contacts: expected 4 frames, got 1" in str(exc.value)
    m = assert_not_ok(tmp_path / "job")
    assert m["evidence"]["dumps"]["dump.atoms"]["frames_expected"] == 7
    assert m["evidence"]["dumps"]["dump.atoms"]["frames_got"] == 1
    assert fake.wait_gone(2) == []


@pytest.mark.liggghts
def test_fake_warning(tmp_path, fake_liggghts, small_liggghts_job):
    fake = fake_liggghts("warning")
    deck, files, outputs = small_liggghts_job()
    with pytest.raises(ReferenceRunError, match="1 unexpected WARNING line.*fake warning inserted"):
        run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False)
    assert_not_ok(tmp_path / "job")
    ok = run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, allowed_warnings=["fake warning"])
    assert ok.manifest["status"] == "ok" and len(ok.warnings) == 1
    assert fake.wait_gone(2) == []


# ----------------------------------------------------------------------------- reuse
@pytest.mark.liggghts
def test_reuse_verifies_hashes_and_evidence(tmp_path, small_liggghts_job, capsys, monkeypatch):
    job = tmp_path / "job"
    deck, files, outputs = small_liggghts_job("run 10\nrun 0\nrun 20\n", dump_every=5)
    first = run_job(job, deck, files, outputs=outputs, progress=False)
    assert run_job(job, deck, files, outputs=outputs, progress=False).skipped  # honest job: reused
    # an edited log (same length, one digit changed) is not reused: rerun with a WARNING
    text = (job / "log.lammps").read_text()
    k = text.index("Loop time of ") + len("Loop time of ")
    (job / "log.lammps").write_text(text[:k] + ("1" if text[k] != "1" else "2") + text[k + 1 :])
    capsys.readouterr()
    again = run_job(job, deck, files, outputs=outputs, progress=False)
    err = capsys.readouterr().err
    assert not again.skipped and "WARNING" in err and "log.lammps changed since the job ran" in err
    assert again.manifest["rerun_reason"] == [
        "log.lammps changed since the job ran (SHA-256 differs from the manifest)"
    ]
    assert again.manifest["input_sha256"] == first.manifest["input_sha256"]
    # a dump cut to one frame whose hash is made to match: the evidence check still refuses it
    text = (job / "dump.atoms").read_text()
    (job / "dump.atoms").write_text(text[: text.index("ITEM: TIMESTEP", 1)])
    m = read_manifest(job)
    import hashlib

    m["outputs"]["dump.atoms"] = hashlib.sha256((job / "dump.atoms").read_bytes()).hexdigest()
    (job / "manifest.json").write_text(json.dumps(m))
    assert verify_job(job) == ["dump.atoms: expected 7 frames, got 1"] and not is_complete(job)
    # without LIGGGHTS it is refused, saying why and naming --force
    monkeypatch.setenv("PATH", str(tmp_path / "nothing"))
    with pytest.raises(ReferenceRunError) as exc:
        run_job(job, deck, files, outputs=outputs, progress=False)
    msg = str(exc.value)
    assert "fails verification: dump.atoms: expected 7 frames, got 1" in msg and "--force" in msg
    assert "not found on PATH" in msg and exc.value.problems == ("dump.atoms: expected 7 frames, got 1",)


@pytest.mark.liggghts
def test_reuse_of_a_log_cut_to_12_steps_reruns(tmp_path, small_liggghts_job, capsys):
    job = tmp_path / "job"
    deck, files, outputs = small_liggghts_job("thermo 1\nrun 1000\n", dump_every=500)
    run_job(job, deck, files, outputs=outputs, progress=False)
    lines = (job / "log.lammps").read_text().splitlines()
    head = next(k for k, ln in enumerate(lines) if ln.split()[:1] == ["Step"])
    (job / "log.lammps").write_text("\n".join(lines[: head + 13]) + "\n")
    problems = verify_job(job)
    assert problems[0] == "log.lammps changed since the job ran (SHA-256 differs from the manifest)"
    assert problems[1].startswith(
        "incomplete: log.lammps holds 0 of 1 runs; run 1 (deck line 25, steps 0..1000) stops at step 11"
    )
    res = run_job(job, deck, files, outputs=outputs, progress=False)
    assert not res.skipped and res.log.runs[0].steps[-1] == 1000 and verify_job(job) == []
    assert "holds 0 of 1 runs" in capsys.readouterr().err


@pytest.mark.liggghts
def test_manifest_without_log_hash_is_rerun(tmp_path, small_liggghts_job):
    job = tmp_path / "job"
    deck, files, outputs = small_liggghts_job()
    run_job(job, deck, files, outputs=outputs, progress=False)
    m = read_manifest(job)
    del m["log_sha256"]
    (job / "manifest.json").write_text(json.dumps(m))
    res = run_job(job, deck, files, outputs=outputs, progress=False)
    assert not res.skipped and "no log_sha256" in res.manifest["rerun_reason"][0]


def test_expected_runs_must_match_the_deck(tmp_path):
    with pytest.raises(ReferenceRunError, match="the deck has 2 run commands but expected_runs=1"):
        run_job(tmp_path / "job", "run 0\nrun 0\n", expected_runs=1, progress=False)


# ----------------------------------------------------------------------------- signals and orphans
_SIGNAL_SCRIPT = """
import sys
import reference_runs.runner as runner
runner.KILL_GRACE_S = 0.5
sys.path.insert(0, {faults!r})
from fakes import small_deck
deck, files, outputs = small_deck()
with runner.kill_children_on_signals():
    runner.run_job({job!r}, deck, files, outputs=outputs, progress=False, timeout=600)
"""


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGHUP])
def test_signal_to_python_kills_the_job_group(tmp_path, fake_liggghts, sig):
    code = 128 + sig
    fake = fake_liggghts("hang")
    job = tmp_path / "job"
    script = _SIGNAL_SCRIPT.format(faults=str(Path(__file__).parent), job=str(job))
    env = {**os.environ, "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", str(tmp_path / "nc"))}
    py = subprocess.Popen([sys.executable, "-c", script], cwd=REPO, env=env, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 30
        while not fake.pids("grandchild") and time.monotonic() < deadline and py.poll() is None:
            time.sleep(0.05)
        assert fake.pids("grandchild"), py.stderr.read() if py.poll() is not None else "no grandchild"
        py.send_signal(sig)
        rc = py.wait(timeout=20)
    finally:
        if py.poll() is None:
            py.kill()
    assert rc == code
    assert fake.wait_gone(2) == []
    m = read_manifest(job)
    assert m["status"] == "failed" and "interrupted (Terminated" in m["error"]


def test_terminate_children_kills_a_running_job(tmp_path, fake_liggghts, small_liggghts_job):
    from reference_runs.runner import live_children, terminate_children

    fake = fake_liggghts("hang")
    deck, files, outputs = small_liggghts_job()
    box = {}

    def work():
        try:
            run_job(tmp_path / "job", deck, files, outputs=outputs, progress=False, timeout=60)
        except ReferenceRunError as exc:
            box["exc"] = exc

    t = threading.Thread(target=work)
    t.start()
    deadline = time.monotonic() + 20
    while not fake.pids("grandchild") and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(live_children()) == 1
    assert terminate_children() == 1
    t.join(20)
    assert not t.is_alive() and "exited with status" in str(box["exc"])
    assert fake.wait_gone(2) == [] and live_children() == []


# ----------------------------------------------------------------------------- locks
def test_directory_lock_fail_fast_names_holder_and_directory(tmp_path):
    with DirectoryLock(tmp_path / "results"):
        with pytest.raises(DirectoryBusyError) as exc:
            with DirectoryLock(tmp_path / "results"):
                pass
    msg = str(exc.value)
    assert f"pid {os.getpid()}" in msg and str(tmp_path / "results") in msg
    assert exc.value.holder_pid == os.getpid()
    with DirectoryLock(tmp_path / "results"):  # released: free again
        pass


def test_lock_cleans_stray_temporaries(tmp_path):
    d = tmp_path / "job"
    d.mkdir()
    stray = [d / ".manifest.json.k2j3h4.json.tmp", d / ".taylor.h5.x8f7.h5.tmp", d / ".a.txt.abc.tmp"]
    for p in stray:
        p.write_text("half")
    keep = d / "notes.tmp"
    keep.write_text("mine")
    with DirectoryLock(d, clean_tmp=True) as lock:
        assert sorted(lock.removed) == sorted(stray)
    assert not any(p.exists() for p in stray) and keep.exists()


def test_second_writer_waits_at_most_its_timeout(tmp_path, capsys):
    job = tmp_path / "job"
    with DirectoryLock(job):
        t0 = time.monotonic()
        with pytest.raises(ReferenceRunError, match=f"gave up waiting for job .* pid {os.getpid()}") as exc:
            run_job(job, "run 0\n", timeout=0.5, progress=False)
        assert 0.5 <= time.monotonic() - t0 < 5 and exc.value.timed_out
    assert f"waiting for job {job} (pid {os.getpid()}" in capsys.readouterr().err
    assert read_manifest(job) is None


@pytest.mark.liggghts
def test_second_writer_waits_then_reuses(tmp_path, fake_liggghts, small_liggghts_job, capsys, monkeypatch):
    fake = fake_liggghts("slow")
    monkeypatch.setenv("FAKE_LIGGGHTS_DELAY", "1.5")
    deck, files, outputs = small_liggghts_job()
    job = tmp_path / "job"
    out = {}

    def first():
        out["first"] = run_job(job, deck, files, outputs=outputs, progress=False)

    t = threading.Thread(target=first)
    t.start()
    deadline = time.monotonic() + 10
    while not fake.pids("fake") and time.monotonic() < deadline:
        time.sleep(0.02)
    second = run_job(job, deck, files, outputs=outputs, progress=False, timeout=60)
    t.join(30)
    assert out["first"].manifest["status"] == "ok" and not out["first"].skipped
    assert second.skipped and second.manifest == out["first"].manifest
    assert len(fake.pids("fake")) == 1  # LIGGGHTS ran once
    assert f"waiting for job {job} (pid {os.getpid()}" in capsys.readouterr().err


@pytest.mark.liggghts
def test_stray_tmp_in_job_dir_removed_when_job_runs(tmp_path, small_liggghts_job):
    job = tmp_path / "job"
    job.mkdir()
    stray = job / ".manifest.json.q1w2e3.json.tmp"
    stray.write_text("{half")
    deck, files, outputs = small_liggghts_job()
    run_job(job, deck, files, outputs=outputs, progress=False)
    assert not stray.exists()


# ----------------------------------------------------------------------------- version
def test_version_is_what_the_binary_says(tmp_path, monkeypatch):
    fake = write_fake(tmp_path / "bin", "error")
    v = liggghts_version(fake.path)
    assert v == f"LIGGGHTS-PUBLIC 3.8.0 fake-error ({fake.path})"
    assert liggghts_package_version(fake.path) is None
    monkeypatch.setenv("PATH", f"{fake.bindir}{os.pathsep}{os.environ['PATH']}")
    assert liggghts_version() == v
    real = "/usr/bin/liggghts"
    if os.path.exists(real):
        assert liggghts_version(real) == f"LIGGGHTS-PUBLIC 3.8.0 ({real})"
        assert liggghts_version(real) != v


@pytest.mark.liggghts
def test_concurrent_jobs_get_private_temporary_directories(tmp_path, small_liggghts_job, monkeypatch):
    """Two jobs started together (``--jobs 2``) must not share Open MPI's session directory under
    $TMPDIR (a race on creating it made a job exit 1 in a fresh ``make run``): each job runs with
    its own TMPDIR and orte_tmpdir_base, which exist while it runs and are removed after."""
    real = shutil.which("liggghts")
    bindir = tmp_path / "bin"
    bindir.mkdir()
    wrapper = bindir / "liggghts"
    wrapper.write_text(
        "#!/bin/sh\n"
        'if [ "$1" = "-in" ] && [ "$2" = "/dev/null" ]; then exec "' + real + '" "$@"; fi\n'
        'test -d "$TMPDIR" && echo "$TMPDIR $OMPI_MCA_orte_tmpdir_base" >> "' + str(tmp_path / "seen.txt") + '"\n'
        'exec "' + real + '" "$@"\n'
    )
    wrapper.chmod(0o755)
    monkeypatch.setenv("PATH", f"{bindir}{os.pathsep}{os.environ['PATH']}")
    deck, files, outputs = small_liggghts_job("run 10\n", dump_every=5)
    errors = []

    def one(k):
        try:
            run_job(tmp_path / f"job{k}", deck, files, outputs=outputs, progress=False)
        except Exception as exc:  # reported below
            errors.append(exc)

    threads = [threading.Thread(target=one, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors, errors
    seen = [line.split() for line in (tmp_path / "seen.txt").read_text().splitlines()]
    assert len(seen) == 2 and all(a == b for a, b in seen)
    dirs = {a for a, _ in seen}
    assert len(dirs) == 2 and not any(Path(d).exists() for d in dirs)
