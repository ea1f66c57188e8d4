"""Checkpoints of the sheared cell: a run stopped, saved and continued ends with the bits of the
uninterrupted run (the engine's state arrays, the run file's /checkpoint and ``gransim shear
--resume``, also after SIGKILL), and a resume refuses a file of another run."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.dem.sheared import ShearEngine, ShearLoading, run_shear_file
from gransim.errors import ResultFileError
from gransim.io import save_packing
from reference_runs.decks.shear import short_case

SERVO = ShearLoading(erate=2.5, y="servo", target=1000.0, gain=1e-2)


def _state(eng):
    return [eng.x, eng.v, eng.w, eng.f, eng.t, eng.box, eng.h_rate, eng.xi, eng.virial]


@pytest.mark.parametrize("loading", [ShearLoading(erate=2.5), SERVO], ids=["constant-volume", "servo"])
def test_restored_engine_continues_bit_for_bit(loading):
    p, s, _, _ = short_case("constant-volume")
    ref = ShearEngine(p, s)
    ref.start_run(loading, 900)
    ref.advance(900)
    assert ref.n_rebuilds >= 2  # the continuation crosses list rebuilds
    a = ShearEngine(p, s)
    a.start_run(loading, 900)
    a.advance(377)
    saved = {k: np.array(v) for k, v in a.state_arrays().items()}
    b = ShearEngine(p, s)  # a new engine: its own set-up, replaced by the checkpoint
    b.restore({**saved, "loading": loading}, 377)
    out = b.advance(523)
    assert out["step"][-1] == 900 and b.step == 900
    for got, want in zip(_state(b), _state(ref), strict=True):
        np.testing.assert_array_equal(got, want)


def test_a_checkpoint_carries_the_loading_of_its_run():
    p, s, _, _ = short_case("constant-volume")
    a = ShearEngine(p, s)
    a.start_run(SERVO, 50)
    a.advance(20)
    ck = a.state_arrays()
    b = ShearEngine(p, s)
    b.restore(ck, 20)  # the loading from the checkpoint's JSON
    np.testing.assert_array_equal(b.advance(30)["stress"], a.advance(30)["stress"])
    ck.pop("run_loading_json")
    with pytest.raises(Exception, match="needs its loading"):
        ShearEngine(p, s).restore(ck, 20)


def _file(path):
    with h5py.File(path, "r") as f:
        series = {k: f["series"][k][()] for k in f["series"]}
        snaps = {k: {d: f["snapshots"][k][d][()] for d in f["snapshots"][k]} for k in f["snapshots"]}
        return series, snaps, dict(f.attrs)


def test_run_file_in_pieces_equals_the_whole_run(tmp_path):
    p, s, _, _ = short_case("constant-volume")
    kw = {"series_every": 25, "snapshot_every": 200, "show_progress": False, "checkpoint_every": 150}
    whole = tmp_path / "whole.h5"
    run_shear_file(p, s, SERVO, 700, whole, **kw)
    pieces = tmp_path / "pieces.h5"
    run_shear_file(p, s, SERVO, 700, pieces, stop_at_step=310, **kw)
    _, _, attrs = _file(pieces)
    assert not attrs["complete"] and "stop_at_step" in attrs["stop_reason"]
    run_shear_file(p, s, SERVO, 700, pieces, resume=True, stop_at_step=520, **kw)
    summary = run_shear_file(p, s, SERVO, 700, pieces, resume=True, **kw)
    assert summary["steps"] == 700
    (sw, nw, aw), (sp, np_, ap) = _file(whole), _file(pieces)
    assert ap["complete"] and ap["stop_reason"] == ""
    assert sorted(sw) == sorted(sp) and sorted(nw) == sorted(np_)
    for k in sw:
        np.testing.assert_array_equal(sp[k], sw[k], err_msg=k)
    for k in nw:
        for d in nw[k]:
            np.testing.assert_array_equal(np_[k][d], nw[k][d], err_msg=f"{k}/{d}")
    assert ap["n_rebuilds"] == aw["n_rebuilds"]
    # a resume of the complete file changes nothing
    run_shear_file(p, s, SERVO, 700, pieces, resume=True, **kw)
    np.testing.assert_array_equal(_file(pieces)[0]["stress"], sw["stress"])


def test_resume_refuses_another_run(tmp_path):
    p, s, _, _ = short_case("constant-volume")
    kw = {"series_every": 25, "show_progress": False}
    f = tmp_path / "r.h5"
    run_shear_file(p, s, SERVO, 300, f, stop_at_step=100, checkpoint_every=50, **kw)
    with pytest.raises(ResultFileError, match="belongs to another run"):
        run_shear_file(p, s, ShearLoading(erate=2.5), 300, f, resume=True, **kw)
    with pytest.raises(ResultFileError, match="belongs to another run"):
        run_shear_file(p, s, SERVO, 300, f, resume=True, series_every=5, show_progress=False)


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p, _, _, _ = short_case("constant-volume")
    path = tmp_path_factory.mktemp("shear-resume") / "p.h5"
    save_packing(path, p)
    return path


# 80,000 steps of 120 disks (about a second): a checkpoint every 2,000 steps leaves time to kill it
ARGS = ["--strain", "0.4", "--rate", "2.5", "--servo", "1000", "--series-every", "200", "--snapshot-every", "20000"]


@pytest.mark.parametrize("order", [[], ["--order", "fast", "--threads", "2"]], ids=["code", "fast-2-threads"])
def test_cli_killed_and_resumed_equals_the_uninterrupted_run(packing_file, tmp_path, order):
    whole = tmp_path / "whole.h5"
    args = [*ARGS, *order]
    assert main(["shear", "--packing", str(packing_file), *args, "--checkpoint-every", "2000", "-o", str(whole)]) == 0
    killed = tmp_path / "killed.h5"
    cmd = [sys.executable, "-m", "gransim", "shear", "--packing", str(packing_file), *args]
    cmd += ["--checkpoint-every", "2000", "-o", str(killed)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    deadline = time.monotonic() + 300
    try:
        # SIGKILL once a checkpoint is in the file and before the run ends
        while time.monotonic() < deadline and proc.poll() is None:
            if killed.exists():
                try:
                    with h5py.File(killed, "r") as f:
                        ready = "checkpoint" in f and not f.attrs["complete"]
                except OSError:
                    ready = False
                if ready:
                    os.killpg(proc.pid, signal.SIGKILL)
                    break
            time.sleep(0.02)
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    if proc.returncode == 0:
        pytest.skip("the run ended before a checkpoint could be caught (a loaded machine)")
    assert proc.returncode == -signal.SIGKILL
    with h5py.File(killed, "r") as f:
        assert not f.attrs["complete"] and "continue with resume" in f.attrs["stop_reason"]
    resumed = ["shear", "--packing", str(packing_file), *args, "--checkpoint-every", "2000", "--resume"]
    assert main([*resumed, "-o", str(killed)]) == 0
    (sw, nw, _), (sk, nk, ak) = _file(whole), _file(killed)
    assert ak["complete"]
    for k in sw:
        np.testing.assert_array_equal(sk[k], sw[k], err_msg=k)
    assert sorted(nw) == sorted(nk)
    for k in nw:
        for d in nw[k]:
            np.testing.assert_array_equal(nk[k][d], nw[k][d], err_msg=f"{k}/{d}")


def test_cli_resume_without_a_file_is_a_usage_error(packing_file, tmp_path, capsys):
    rc = main(["shear", "--packing", str(packing_file), *ARGS, "--resume", "-o", str(tmp_path / "none.h5")])
    assert rc == 2 and "--resume" in capsys.readouterr().err
