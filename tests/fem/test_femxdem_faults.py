"""``gransim femxdem`` under signals and a full disk (the J2 stand-in on the quick 2 x 4 mesh).

SIGINT and SIGTERM, in process and with the Gauss points on a 2-worker LocalCluster (also Ctrl-C,
which reaches the whole process group, workers included): exit 130 / 143 after the step in
progress, one line on stderr, ``femxdem.h5`` holding the converged steps (marked incomplete), a
checkpoint that ``--resume`` continues to the same bits as an uninterrupted run, no process of the
run alive and no port of it listening afterwards, no temporary file left. A full disk is one line
naming the file (exit 1). Each run is a real ``python -m gransim femxdem``.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from gransim.fem.biaxial import BiaxialSpec
from gransim.fem.femxdem import run_femxdem
from gransim.io import open_result

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "NUMBA_CACHE_DIR": os.environ.get("NUMBA_CACHE_DIR", str(ROOT / ".venv" / "numba-cache"))}
STEPS = 30
ARGS = ["--rve", "j2", "--mesh", "2x4", "--steps", str(STEPS)]
#: what femxdem.h5 holds besides timings (curves/wall_s, curves/material_s)
COMPARED = ("curves/step", "curves/axial_strain", "curves/deviatoric_stress", "curves/volumetric_strain")
COMPARED += ("curves/newton_iterations",)


def _femxdem(out, *extra, **kw):
    cmd = [sys.executable, "-m", "gransim", "femxdem", *ARGS, "--out", str(out), *extra]
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=ENV, text=True, **kw)


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The run without a signal (in process: the command line's defaults with ARGS)."""
    d = tmp_path_factory.mktemp("whole")
    run_femxdem(BiaxialSpec(nx=2, ny=4, steps=STEPS), "j2", d)
    return d / "femxdem.h5"


def _contents(path) -> dict:
    """Every dataset of a femxdem.h5 but the timings, by name."""
    out = {}
    with open_result(path, kind="fem-biaxial") as f:
        for k in COMPARED:
            out[k] = f[k][()]

        def visit(name, obj):
            if hasattr(obj, "shape") and name.startswith(("newton/", "final/")):
                out[name] = obj[()]

        f.visititems(visit)
        out["completed"] = bool(f.attrs["completed"])
    return out


def _listening_ports() -> set[int]:
    """Local TCP ports in state LISTEN on this machine (/proc/net/tcp and tcp6)."""
    ports = set()
    for name in ("/proc/net/tcp", "/proc/net/tcp6"):
        try:
            lines = Path(name).read_text().splitlines()[1:]
        except OSError:
            continue
        for ln in lines:
            fields = ln.split()
            if fields[3] == "0A":  # TCP_LISTEN
                ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def _signal_after_step(proc, out: Path, k: int, send, timeout: float = 120) -> dict:
    """Wait until step ``k``'s checkpoint is written, then ``send()``; returns the run's processes
    ({pid: create time}) and the TCP ports they listened on, as seen during the run."""
    psutil = pytest.importorskip("psutil")
    parent = psutil.Process(proc.pid)
    seen, ports = {proc.pid: parent.create_time()}, set()
    t0 = time.monotonic()
    while not (out / "checkpoint" / f"step_{k:03d}.h5").exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() - t0 < timeout, "no checkpoint written"
        try:
            for c in [parent, *parent.children(recursive=True)]:
                seen.setdefault(c.pid, c.create_time())
                ports |= {c.laddr.port for c in c.net_connections(kind="tcp") if c.status == psutil.CONN_LISTEN}
        except psutil.NoSuchProcess:
            pass
        time.sleep(0.02)
    send()
    return {"procs": seen, "ports": ports}


def _assert_nothing_left(run: dict) -> None:
    psutil = pytest.importorskip("psutil")
    procs = []
    for pid, created in run["procs"].items():
        try:
            p = psutil.Process(pid)
            if p.create_time() == created:
                procs.append(p)
        except psutil.NoSuchProcess:
            pass
    _, alive = psutil.wait_procs(procs, timeout=10)  # the resource tracker ends on EOF from its parent
    assert not [(p.pid, p.name()) for p in alive]
    assert not run["ports"] & _listening_ports(), run["ports"]


def _assert_stopped(out: Path, rc: int, err: str, signum: int) -> int:
    """The signal's exit status, one line, the converged steps in femxdem.h5, no temporary."""
    name = signal.Signals(signum).name
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 128 + signum, err[-3000:]
    assert len(lines) == 1 and f"interrupted: stopped by {name} after load step" in lines[0], err[-3000:]
    assert "--resume" in lines[0]
    with open_result(out / "femxdem.h5", kind="fem-biaxial") as f:
        steps = list(f["curves/step"][()])
        assert not f.attrs["completed"] and name in f.attrs["stopped"]
    assert 3 <= len(steps) < STEPS and steps == list(range(1, len(steps) + 1))
    assert "STOPPED" in (out / "report.md").read_text()
    assert not [p for p in out.rglob("*") if p.name.startswith(".") or p.name.endswith(".tmp")]
    return len(steps)


def _assert_resumes_to_the_same_bits(out: Path, uninterrupted: Path, *extra) -> None:
    proc = _femxdem(out, "--resume", *extra)
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, err[-3000:]
    a, b = _contents(out / "femxdem.h5"), _contents(uninterrupted)
    assert a["completed"] and sorted(a) == sorted(b)
    for k in b:
        assert np.array_equal(a[k], b[k]), k
    assert not [p for p in out.rglob("*") if p.name.startswith(".") or p.name.endswith(".tmp")]


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_signal_in_process_stops_cleanly_and_resumes_bit_for_bit(signum, tmp_path, uninterrupted):
    proc = _femxdem(tmp_path)
    run = _signal_after_step(proc, tmp_path, 3, lambda: proc.send_signal(signum))
    _, err = proc.communicate(timeout=120)
    _assert_stopped(tmp_path, proc.returncode, err, signum)
    _assert_nothing_left(run)
    if signum == signal.SIGINT:  # one resume is enough in process: the Dask case resumes too
        _assert_resumes_to_the_same_bits(tmp_path, uninterrupted)


@pytest.mark.parametrize(("signum", "group"), [(signal.SIGTERM, False), (signal.SIGINT, True)], ids=["term", "ctrl-c"])
def test_signal_on_a_local_cluster_leaves_no_worker_and_resumes(signum, group, tmp_path, uninterrupted):
    """SIGTERM to gransim, and SIGINT to its process group as Ctrl-C sends it (the workers get it
    too: before, they died at once and gransim waited 30 s per lost connection, then exit 1)."""
    pytest.importorskip("distributed")
    proc = _femxdem(tmp_path, "--workers", "2", start_new_session=True)
    send = (lambda: os.killpg(proc.pid, signum)) if group else (lambda: proc.send_signal(signum))
    run = _signal_after_step(proc, tmp_path, 3, send)
    _, err = proc.communicate(timeout=120)
    _assert_stopped(tmp_path, proc.returncode, err, signum)
    assert len(run["procs"]) >= 3 and run["ports"]  # the workers and the scheduler were seen
    _assert_nothing_left(run)
    if group:  # onto the Gauss points in process: the same bits
        _assert_resumes_to_the_same_bits(tmp_path, uninterrupted)


# --------------------------------------------------------------------------- full disk
def test_full_disk_is_one_error_naming_the_file(small_disk):
    """The checkpoint files of 30 steps do not fit in 64 kB: exit 1, one line naming the file and
    the cause, no traceback, no temporary left on the disk."""
    d, wrap = small_disk
    out = d / "fx"
    script = f'"$@"; rc=$?; ls -AR {d} > {d}.after; exit $rc'  # what the command left on the disk
    cmd = [*wrap, "sh", "-c", script, "sh", sys.executable, "-m", "gransim", "femxdem", *ARGS, "--out", str(out)]
    r = subprocess.run(cmd, cwd=d.parent, env=ENV, capture_output=True, text=True, timeout=300)
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 1, (r.returncode, r.stderr[-3000:])
    assert len(lines) == 1, r.stderr[-3000:]
    assert "no space left on device" in lines[0] and f"cannot write {out}/" in lines[0], lines[0]
    left = Path(f"{d}.after").read_text().split()
    assert not [n for n in left if n.endswith(".tmp")], left
