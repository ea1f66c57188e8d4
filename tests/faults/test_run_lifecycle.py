"""Life cycle of a DEM run file under hostile conditions: SIGINT / SIGTERM at any moment (the run
always stops, exit 130 / 143, the file incomplete and resumable to the same bits), a full disk (one
error naming the file, nothing partial left, no crash), temporaries of killed writers (removed by
the next write of that file, never a live process's), and checkpoints that write only what is new
(part files beside the run file; a kill between them loses nothing a resume needs)."""

from __future__ import annotations

import dataclasses
import os
import random
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

import gransim.dem.output as output_mod
import gransim.dem.run as run_mod
from gransim.cli import main
from gransim.dem.biaxial import biaxial_phases, default_settings
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import OutputSettings, part_paths, read_record, read_run, read_snapshot
from gransim.io import save_packing
from gransim.io.hdf5 import OutputWriteError, stale_temporaries

REPO = Path(__file__).resolve().parents[2]
#: a biaxial run of 64 disks, about 0.5 s: 4000 consolidation steps, then compression
RUN = [
    "--strain",
    "0.0004",
    "--consolidation-steps",
    "4000",
    "--allow-unsettled",
    "--checkpoint-every",
    "1000",
    "--snapshot-every",
    "2000",
]


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)


@pytest.fixture(scope="module")
def packing_file(packing, tmp_path_factory):
    return save_packing(tmp_path_factory.mktemp("pk") / "p.h5", packing)


@pytest.fixture(scope="module")
def reference(packing_file, tmp_path_factory):
    """The uninterrupted run."""
    out = tmp_path_factory.mktemp("ref") / "run.h5"
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), *RUN]) == 0
    return out


def _same_run(a, b):
    ra, rb = read_run(a), read_run(b)
    assert ra.complete and rb.complete
    for k in ra.series:
        np.testing.assert_array_equal(ra.series[k], rb.series[k], err_msg=k)
    assert ra.snapshot_steps == rb.snapshot_steps
    for step in (ra.snapshot_steps[len(ra.snapshot_steps) // 2], ra.snapshot_steps[-1]):
        sa, sb = read_snapshot(a, step), read_snapshot(b, step)
        np.testing.assert_array_equal(sa.positions, sb.positions)
        np.testing.assert_array_equal(sa.velocities, sb.velocities)
        np.testing.assert_array_equal(sa.spins, sb.spins)


def _no_temporaries(d: Path):
    left = [p.name for p in d.iterdir() if p.name.endswith(".tmp")]
    assert not left, left


# ------------------------------------------------------------------------ SIGINT at any moment
def test_sigint_at_random_moments_always_stops_and_resumes_to_the_same_bits(packing_file, reference, tmp_path, capsys):
    """SIGINT at 8 random moments of the run (in the engine, in a checkpoint's write, in h5py's
    finalizers): every time exit 130, the file incomplete with a checkpoint, and --resume ends
    with the bits of the uninterrupted run."""
    rng = random.Random(7)
    t0 = time.perf_counter()
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(tmp_path / "timing.h5"), *RUN]) == 0
    duration = time.perf_counter() - t0
    for k in range(8):
        out = tmp_path / f"run{k}.h5"
        delay = rng.uniform(0.15, 0.85) * duration
        fired = []
        timer = threading.Timer(delay, lambda f=fired: (f.append(1), os.kill(os.getpid(), signal.SIGINT)))
        timer.start()
        try:
            rc = main(["biaxial", "--packing", str(packing_file), "-o", str(out), *RUN])
        except KeyboardInterrupt:  # pragma: no cover - the signal escaped main: a failure below
            rc = "KeyboardInterrupt escaped main"
        finally:
            timer.cancel()  # the run ended first (a loaded machine): no signal into pytest
            timer.join()
        err = capsys.readouterr().err
        if rc == 0 and not fired:  # pragma: no cover - the run ended first: timing on a loaded machine
            continue
        assert rc == 130, f"SIGINT after {delay:.2f} s of {duration:.2f} s: exit {rc}, stderr {err[-500:]}"
        assert "interrupted" in err and str(out) in err
        rec = read_record(out)
        if rec.complete:  # the signal came once the run was written: the message says it is whole
            assert f"written complete before the signal: {out}" in err, err
            _same_run(reference, out)
            continue
        assert not rec.complete and "interrupted by SIGINT" in rec.stop_reason
        assert rec.checkpoint is not None
        assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), *RUN, "--resume"]) == 0
        _same_run(reference, out)
        _no_temporaries(tmp_path)
        assert part_paths(out) == []  # the finished run file holds everything


def _start(argv, cwd):
    env = {**os.environ, "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", str(REPO / ".venv/numba-cache"))}
    return subprocess.Popen(
        [sys.executable, "-m", "gransim", *argv],
        cwd=cwd,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


@pytest.mark.parametrize(
    ("sig", "rc"), [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129), (signal.SIGKILL, -9)]
)
def test_signal_to_the_command_then_resume(packing_file, reference, tmp_path, sig, rc):
    """The real command: SIGINT / SIGTERM / SIGHUP end it with 130 / 143 / 129 and an incomplete
    file; SIGKILL
    leaves the last checkpoint (run file plus parts); --resume ends with the uninterrupted bits and
    no temporary or part file is left."""
    argv = ["biaxial", "--packing", str(packing_file), "-o", "run.h5", *RUN]
    argv[argv.index("--strain") + 1] = "0.001"  # a longer compression: the signal lands in the run
    ref = tmp_path / "ref.h5"
    assert main([*argv[:4], str(ref), *argv[5:]]) == 0
    proc = _start(argv, tmp_path)
    try:
        deadline = time.monotonic() + 60
        while not (tmp_path / "run.h5").exists() and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(random.Random(int(sig)).uniform(0.05, 0.3))
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == rc, err
    assert "Traceback" not in err and "Exception ignored" not in err, err
    assert not read_run(tmp_path / "run.h5").complete
    assert main([*argv[:4], str(tmp_path / "run.h5"), *argv[5:], "--resume"]) == 0
    _same_run(ref, tmp_path / "run.h5")
    _no_temporaries(tmp_path)
    assert part_paths(tmp_path / "run.h5") == []


def test_sigint_after_the_run_ended_says_the_file_is_complete(packing_file, reference, tmp_path, capsys, monkeypatch):
    """A signal that lands once the finished run is written (during the summary): the command
    exits 130 and its message names the run file as written complete (it is, and equals the
    uninterrupted run), instead of a bare "interrupted" that reads as a lost run."""
    write = run_mod.write_run

    def write_then_signal(path, rec):
        write(path, rec)
        if rec.complete:
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(run_mod, "write_run", write_then_signal)
    out = tmp_path / "run.h5"
    rc = main(["biaxial", "--packing", str(packing_file), "-o", str(out), *RUN])
    err = capsys.readouterr().err
    assert rc == 130, err
    assert f"written complete before the signal: {out}" in err, err
    _same_run(reference, out)
    _no_temporaries(tmp_path)


def test_sigint_after_pack_wrote_says_the_packing_is_complete(tmp_path, capsys, monkeypatch):
    """gransim pack: a signal right after the packing is saved ends the command with 130 and a
    message naming the packing as written complete (and the file loads)."""
    import gransim.io as io_mod
    from gransim.io import load_packing

    save = io_mod.save_packing

    def save_then_signal(path, packing):
        out = save(path, packing)
        os.kill(os.getpid(), signal.SIGINT)
        return out

    monkeypatch.setattr(io_mod, "save_packing", save_then_signal)
    out = tmp_path / "p.h5"
    rc = main(["pack", "--n", "40", "-o", str(out)])
    err = capsys.readouterr().err
    assert rc == 130, err
    assert f"written complete before the signal: {out}" in err, err
    assert load_packing(out).n == 40


def test_sigint_stops_shear_and_pack(packing_file, tmp_path, capsys, monkeypatch):
    """gransim shear writes its file as incomplete; gransim pack writes nothing; both exit 130.
    The signal is sent from inside the run (at its third check for signals), so it lands in the
    loop however long the start-up takes on a loaded machine."""
    import gransim.dem.sheared as sheared_mod
    import gransim.generation.compaction as compaction_mod
    import gransim.generation.fire as fire_mod

    calls = {"n": 0}

    def signal_at_third_check(real):
        def check(*a, **kw):
            calls["n"] += 1
            if calls["n"] == 3:
                os.kill(os.getpid(), signal.SIGINT)
            return real(*a, **kw)

        return check

    for mod in (sheared_mod, compaction_mod, fire_mod):
        monkeypatch.setattr(mod, "check_interrupt", signal_at_third_check(mod.check_interrupt))
    for argv, out in (
        (["shear", "--packing", str(packing_file), "--strain", "0.05", "-o", str(tmp_path / "s.h5")], "s.h5"),
        (["pack", "--n", "2000", "-o", str(tmp_path / "p.h5")], "p.h5"),
    ):
        calls["n"] = 0
        rc = main(argv)
        err = capsys.readouterr().err
        assert calls["n"] >= 3, (argv, "the run checked for signals fewer than 3 times")
        assert rc == 130, (argv, err[-2000:])
        if out == "s.h5":
            with h5py.File(tmp_path / out) as f:
                assert not f.attrs["complete"] and "interrupted by SIGINT" in f.attrs["stop_reason"]
        else:
            assert not (tmp_path / out).exists()
    _no_temporaries(tmp_path)


# ------------------------------------------------------------------------------------ full disk
def test_full_disk_is_one_error_naming_the_file(small_disk, packing_file):
    """biaxial and pack on a full disk: exit 1, one line naming the file and the cause, no
    traceback, no crash (it was a segmentation fault), no temporary left on the disk."""
    d, wrap = small_disk
    env = {**os.environ, "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", str(REPO / ".venv/numba-cache"))}
    script = f'"$@"; rc=$?; ls -A {d} > {d}.after; exit $rc'  # what the command left on the disk
    for argv in (
        ["biaxial", "--packing", str(packing_file), "-o", str(d / "run.h5"), *RUN, "--snapshot-every", "100"],
        ["pack", "--n", "3000", "-o", str(d / "p.h5")],
    ):
        cmd = [*wrap, "sh", "-c", script, "sh", sys.executable, "-m", "gransim", *argv]
        r = subprocess.run(cmd, cwd=d.parent, env=env, capture_output=True, text=True, timeout=300)
        lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
        assert r.returncode == 1, (r.returncode, r.stderr[-3000:])
        assert len(lines) == 1, r.stderr[-3000:]
        assert "no space left on device" in lines[0] and argv[argv.index("-o") + 1] in lines[0], lines[0]
        left = Path(f"{d}.after").read_text().split()
        assert not [n for n in left if n.endswith(".tmp")], left


def test_library_write_on_a_full_disk(small_disk, packing):
    """In the library: OutputWriteError (an OSError, errno ENOSPC) naming the file; no temporary."""
    d, wrap = small_disk
    if wrap:
        pytest.skip("needs the tmpfs in this process (root)")
    big = lattice_packing(60, 60, seed=1, spread=0.1)
    with pytest.raises(OutputWriteError, match=r"cannot write .*big\.h5: no space left on device") as e:
        save_packing(d / "big.h5", big)
    assert e.value.errno == 28
    assert sorted(os.listdir(d)) == []
    save_packing(d / "small.h5", packing)  # the disk works for what fits
    assert sorted(os.listdir(d)) == ["small.h5"]


# --------------------------------------------------------------------------- stale temporaries
def _dead_pid() -> int:
    p = subprocess.Popen(["true"])
    p.wait()
    return p.pid


def test_stale_temporaries_of_the_run_are_removed_never_a_live_ones(packing, tmp_path):
    """A killed writer's temporaries of run.h5 go at the next run of it; those of a live process
    (its pid in the name), of another file, and recent ones of the older naming stay."""
    dead, live = _dead_pid(), os.getpid()
    names = {
        f".run.h5.{dead}-abcdefgh.h5.tmp": False,  # killed while writing the run file
        f"..run.h5.part-000003.h5.{dead}-x1y2z3w4.h5.tmp": False,  # ... or one of its parts
        ".run.h5.q9w8e7r6.h5.tmp": False,  # older naming, an hour old, nobody writes it
        f".run.h5.{live}-abcdefgh.h5.tmp": True,  # a live process's
        ".run.h5.k9w8e7r6.h5.tmp": True,  # older naming, just written: maybe live
        f".other.h5.{dead}-abcdefgh.h5.tmp": True,  # another file's
    }
    for n in names:
        (tmp_path / n).write_bytes(b"x" * 100)
    old = time.time() - 3600
    os.utime(tmp_path / ".run.h5.q9w8e7r6.h5.tmp", (old, old))
    assert {p.name for p in stale_temporaries(tmp_path / "run.h5")} == {
        f".run.h5.{dead}-abcdefgh.h5.tmp",
        ".run.h5.q9w8e7r6.h5.tmp",
    }
    dem, bi = default_settings(packing, kn=1e5, strain=0.0002, strain_rate=0.1)
    bi = dataclasses.replace(bi, consolidation_steps=500, check_every=250)
    run_mod.run_phases(
        packing,
        dem,
        biaxial_phases(dem, bi),
        tmp_path / "run.h5",
        OutputSettings(series_every=5, snapshot_every=0, checkpoint_every=0),
        show_progress=False,
        allow_unsettled=True,
    )
    left = {p.name for p in tmp_path.iterdir()} - {"run.h5"}
    assert left == {n for n, keep in names.items() if keep}


# ------------------------------------------------------------------------- cheap checkpoints
class _Killed(BaseException):
    """Stands for SIGKILL: no except clause of the run catches it, nothing is written after it."""


def _biaxial_run(packing, out, every, resume=False):
    dem, bi = default_settings(packing, kn=1e5, strain=0.0006, strain_rate=0.1)
    bi = dataclasses.replace(bi, consolidation_steps=2000, check_every=500)
    return run_mod.run_phases(
        packing,
        dem,
        biaxial_phases(dem, bi),
        out,
        OutputSettings(series_every=5, snapshot_every=200, checkpoint_every=every),
        show_progress=False,
        allow_unsettled=True,
        resume=resume,
    )


def test_checkpoints_append_parts_and_a_kill_between_them_resumes_bitwise(packing, tmp_path, monkeypatch):
    """40 checkpoints rewrite the run file a few times only (each time its data grew by half),
    the others write a part with what is new; after a kill the run file alone is a
    consistent, readable incomplete run, and a resume picks up the parts and ends bit for bit
    where the uninterrupted run ends."""
    ref = tmp_path / "ref.h5"
    _biaxial_run(packing, ref, 0)
    n_steps = int(read_run(ref).series["step"][-1])
    every = n_steps // 40

    whole = []
    real = output_mod.write_run

    def counting(path, rec, *a, **k):
        whole.append(int(rec.checkpoint["step"]) if rec.checkpoint else -1)
        return real(path, rec, *a, **k)

    monkeypatch.setattr(output_mod, "write_run", counting)
    monkeypatch.setattr(run_mod, "write_run", counting)
    real_advance = run_mod._advance
    kill_at = (n_steps * 3) // 4 + every // 2

    def advance(eng, loading, nsteps, *a):
        out = real_advance(eng, loading, min(nsteps, kill_at - eng.step) if eng.step < kill_at else nsteps, *a)
        if eng.step >= kill_at:
            raise _Killed
        return out

    monkeypatch.setattr(run_mod, "_advance", advance)
    out = tmp_path / "run.h5"
    with pytest.raises(_Killed):
        _biaxial_run(packing, out, every)
    n_ck = kill_at // every
    assert n_ck >= 25
    assert len(whole) <= n_ck // 4, f"the run file was rewritten at {len(whole)} of {n_ck} checkpoints: {whole}"
    parts = part_paths(out)
    assert parts, "no checkpoint part beside the run file"
    # the run file alone: a consistent incomplete run for every reader (up to its last rewrite)
    alone = read_run(out)
    assert not alone.complete and max(whole) - 5 < alone.series["step"][-1] <= max(whole)
    with h5py.File(out) as f:
        assert f["checkpoint"].attrs["step"] == max(whole)
    # a resume reads the parts too: it continues from the last checkpoint before the kill
    rec = read_record(out)
    assert rec.checkpoint["step"] == n_ck * every
    monkeypatch.setattr(run_mod, "_advance", real_advance)
    _biaxial_run(packing, out, every, resume=True)
    _same_run(ref, out)
    assert part_paths(out) == []
    _no_temporaries(tmp_path)


def test_parts_of_another_write_are_ignored(packing, tmp_path):
    """A part left from an earlier write of the run file (killed between the rewrite and the
    removal of the parts), or another run's, is not applied."""
    out = tmp_path / "run.h5"
    _biaxial_run(packing, out, 300)
    rec = read_record(out)
    stray = tmp_path / f".{out.name}.part-000001.h5"
    shutil.copy(out, stray)
    with h5py.File(stray, "r+") as f:
        f.attrs["kind"] = output_mod.PART_KIND
        f.attrs["base_token"] = "0123456789abcdef"
        f.attrs["seq"] = 1
        f.attrs["row0"] = len(rec.series["step"])
    again = read_record(out)
    assert len(again.series["step"]) == len(rec.series["step"])
    assert again.checkpoint["step"] == rec.checkpoint["step"]
