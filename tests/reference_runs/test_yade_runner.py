"""YADE as an engine of reference_runs: ``run_job(..., engine="yade")`` runs a YADE script with its
own evidence, opens no TCP port, and leaves no process after a job, a timeout or a failing script."""

import json
import os
import shutil
import subprocess
import time

import pytest

import reference_runs.runner as runner
from reference_runs.engines import YADE, get_engine
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import read_manifest, run_job
from reference_runs.yade.job import QUIET_LINE

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)

#: a YADE script that records its pid, the TCP ports its own process listens on (its socket
#: inodes in /proc/self/fd among the LISTEN rows of /proc/self/net/tcp*), and starts a child that
#: ignores SIGTERM (so only a kill of the whole job ends it), then does ``{tail}``
SCRIPT = """\
import json, os, subprocess, time
def listening():
    inodes = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            t = os.readlink("/proc/self/fd/" + fd)
        except OSError:
            continue
        if t.startswith("socket:["):
            inodes.add(t[8:-1])
    ports = []
    for table in ("/proc/self/net/tcp", "/proc/self/net/tcp6"):
        try:
            rows = open(table).read().splitlines()[1:]
        except OSError:
            continue
        for row in rows:
            f = row.split()
            if f[3] == "0A" and f[9] in inodes:
                ports.append(int(f[1].rsplit(":", 1)[1], 16))
    return sorted(ports)
child = subprocess.Popen(["sh", "-c", "trap '' TERM; exec sleep 1000"])
with open("pids.json", "w") as fh:
    json.dump({{"yade": os.getpid(), "child": child.pid, "listening": listening()}}, fh)
{tail}
"""


def _alive(pid: int) -> bool:
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2 :].split()[0] not in ("Z", "X")


def _listening_pids() -> set:
    """Pids that own a listening TCP socket (``ss -ltnp``)."""
    out = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, timeout=30).stdout
    return {int(p) for p in __import__("re").findall(r"pid=(\d+)", out)}


def _assert_nothing_left(job_dir):
    pids = json.loads((job_dir / "pids.json").read_text())
    deadline = time.monotonic() + 2
    while time.monotonic() < deadline and any(_alive(p) for p in (pids["yade"], pids["child"])):
        time.sleep(0.05)
    assert not _alive(pids["yade"]) and not _alive(pids["child"]), pids
    if shutil.which("ss"):
        assert not _listening_pids() & {pids["yade"], pids["child"]}
    return pids


@pytest.fixture
def short_grace(monkeypatch):
    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)  # the child ignores SIGTERM: SIGKILL after 0.5 s


def test_yade_engine_identifies_itself():
    e = get_engine("yade")
    assert e is YADE and e.binary == "yade" and e.package == "yade"
    assert e.version().startswith("YADE 2023.02a (") and e.version().endswith(f"({shutil.which('yade')})")
    assert e.package_version().startswith("YADE 2023.02a") and e.package_version().endswith("(Debian)")
    assert e.command("s.py", exe="/x/yade") == ["/x/yade", "-n", "-x", "-j1", "-L", "gransim_yade_quiet", "s.py"]
    with pytest.raises(ReferenceRunError, match="one process"):
        e.command("s.py", np=2, exe="/x/yade")


def test_yade_job_opens_no_port_and_leaves_no_process(tmp_path, short_grace):
    job = tmp_path / "job"
    res = run_job(job, SCRIPT.format(tail="open('out.txt', 'w').write('x')"), engine="yade", outputs=["out.txt"])
    m = read_manifest(job)
    assert m["status"] == "ok" and m["engine"] == "yade" and m["engine_version"] == "YADE 2023.02a"
    assert m["engine_binary_version"].startswith("YADE 2023.02a") and m["servers"] == "not started"
    assert QUIET_LINE in (job / "stderr.txt").read_text()
    pids = _assert_nothing_left(job)  # the child it left running was killed with the job
    assert pids["listening"] == [], f"the yade process listened on {pids['listening']}"
    assert not res.skipped
    again = run_job(job, SCRIPT.format(tail="open('out.txt', 'w').write('x')"), engine="yade", outputs=["out.txt"])
    assert again.skipped and again.manifest["start"] == m["start"]
    (job / "out.txt").write_text("changed")
    third = run_job(job, SCRIPT.format(tail="open('out.txt', 'w').write('x')"), engine="yade", outputs=["out.txt"])
    assert not third.skipped and "out.txt changed" in " ".join(third.manifest["rerun_reason"])


def test_yade_job_timeout_kills_every_process(tmp_path, short_grace):
    job = tmp_path / "job"
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match="timed out after 4 s") as info:
        run_job(job, SCRIPT.format(tail="time.sleep(1000)"), engine="yade", timeout=4)
    assert info.value.timed_out and time.monotonic() - t0 < 15
    _assert_nothing_left(job)
    m = read_manifest(job)
    assert m["status"] == "failed" and "timed out" in m["error"]
    assert not [p for p in os.listdir(tmp_path) if p.startswith("gransim-job-")]


def test_yade_failing_script_is_a_failed_job_and_leaves_no_process(tmp_path, short_grace):
    job = tmp_path / "job"
    with pytest.raises(ReferenceRunError, match="yade exited with status 1") as info:
        run_job(job, SCRIPT.format(tail="raise ValueError('broken script')"), engine="yade", outputs=["out.txt"])
    assert any("ValueError: broken script" in ln for ln in info.value.log_lines)
    # the first line of the error, which the validation records quote, names the exception
    assert str(info.value).splitlines()[0].endswith("yade exited with status 1: ValueError: broken script")
    _assert_nothing_left(job)
    m = read_manifest(job)
    assert m["status"] == "failed" and m["returncode"] == 1
    assert m["error"] == "yade exited with status 1: ValueError: broken script"


def test_yade_job_refuses_runs_and_mpi(tmp_path):
    with pytest.raises(ReferenceRunError, match="one process"):
        run_job(tmp_path / "job", "pass\n", engine="yade", np=2)
    with pytest.raises(ReferenceRunError, match="no runs to expect"):
        run_job(tmp_path / "job", "pass\n", engine="yade", expected_runs=1)
