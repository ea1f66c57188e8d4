"""Faults of YADE Taylor jobs: an output cut short or with a state or contact missing is refused as
incomplete (by the reader and as the job's verdict: manifest ``failed``, never ``ok``), and a hung
YADE job is killed at its timeout with nothing left running or listening."""

import json
import shutil
import subprocess
import time

import pytest

import reference_runs.runner as runner
from gransim.paper import KN_2D
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import read_manifest
from reference_runs.yade.job import run_yade_job
from reference_runs.yade.script import TAYLOR_SCRIPT
from reference_runs.yade.taylor import check_output, read_yade_taylor, run_yade_taylor, yade_taylor_job

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
PACKING = perturbed_lattice(4, 4, seed=2)
PATHS = ("compression-11", "shear-12")
N_STATES = 4  # 2 paths x (k = 0, 1)
PID_PREFIX = "import os\nopen('yade.pid', 'w').write(str(os.getpid()))\n"


@pytest.fixture(scope="module")
def output_lines(tmp_path_factory):
    job = tmp_path_factory.mktemp("yade-taylor") / "job"
    run_yade_taylor(PACKING, KN_2D, job, paths=PATHS, n_steps=1)
    lines = (job / "taylor.out").read_text().splitlines(keepends=True)
    assert len(read_yade_taylor(job / "taylor.out", N_STATES)) == N_STATES
    return lines


def _kinds(lines):
    return [ln.split()[0] for ln in lines]


def _cut_mid_line(lines):
    text = "".join(lines)
    return text[: len(text) // 2]


def _no_end(lines):
    return "".join(lines[:-1])


def _after_second_state(lines):
    s = [i for i, k in enumerate(_kinds(lines)) if k == "S"]
    return "".join(lines[: s[1] + 1])


def _one_contact_missing(lines):
    c = _kinds(lines).index("C")
    return "".join(lines[:c] + lines[c + 1 :])


def _one_state_missing(lines):
    s = [i for i, k in enumerate(_kinds(lines)) if k == "S"]
    return "".join(lines[: s[0] + 1] + lines[s[1] + 1 :])  # state 1: its contacts and its S row


def _state_row_missing(lines):
    s = [i for i, k in enumerate(_kinds(lines)) if k == "S"]
    return "".join(lines[: s[2]] + lines[s[2] + 1 :])


@pytest.mark.parametrize(
    "damage,message",
    [
        (_cut_mid_line, "cut short"),
        (_no_end, r"cut short after 4 of 4 states \(no END line\)"),
        (_after_second_state, r"cut short after 2 of 4 states"),
        (_one_contact_missing, r"state 0: \d+ contact rows for n_contacts = \d+"),
        (_one_state_missing, "a contact of state 2 where state 1 is due"),
        (_state_row_missing, "a contact of state 3 where state 2 is due"),
    ],
)
def test_damaged_yade_output_is_refused_as_incomplete(output_lines, damage, message, tmp_path):
    p = tmp_path / "taylor.out"
    p.write_text(damage(output_lines))
    with pytest.raises(ReferenceRunError, match="incomplete: .*" + message):
        read_yade_taylor(p, N_STATES)
    (tmp_path / "input.json").write_text(json.dumps({"states": [{}] * N_STATES}))
    assert check_output(tmp_path) and "incomplete" in check_output(tmp_path)[0]


def test_fewer_states_than_the_job_asked_for_are_refused(output_lines, tmp_path):
    p = tmp_path / "taylor.out"
    p.write_text("".join(output_lines))
    with pytest.raises(ReferenceRunError, match="announces 4 states, the job has 5"):
        read_yade_taylor(p, 5)


def test_yade_job_with_a_truncated_output_fails_never_ok(tmp_path):
    script, files, _ = yade_taylor_job(PACKING, KN_2D, paths=PATHS, n_steps=1)
    cut = script + "\ntext = open('taylor.out').read()\nopen('taylor.out', 'w').write(text[: len(text) // 3])\n"
    with pytest.raises(ReferenceRunError, match="incomplete: .*taylor.out") as info:
        run_yade_job(tmp_path / "job", cut, files, outputs=["taylor.out"], check=check_output)
    assert not info.value.timed_out
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "incomplete" in m["error"] and "outputs" not in m


def _alive(pid: int) -> bool:
    try:
        stat = open(f"/proc/{pid}/stat").read()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2 :].split()[0] not in ("Z", "X")


def test_hung_yade_job_is_killed_with_nothing_left(tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)
    script, files, _ = yade_taylor_job(PACKING, KN_2D, paths=PATHS, n_steps=1)
    hung = PID_PREFIX + "import time\ntime.sleep(1000)\n" + script
    assert script == TAYLOR_SCRIPT
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match="timed out after 4 s") as info:
        run_yade_job(tmp_path / "job", hung, files, timeout=4, outputs=["taylor.out"], check=check_output)
    assert info.value.timed_out and time.monotonic() - t0 < 15
    pid = int((tmp_path / "job" / "yade.pid").read_text())
    assert not _alive(pid)
    if shutil.which("ss"):
        out = subprocess.run(["ss", "-ltnpH"], capture_output=True, text=True, timeout=30).stdout
        assert f"pid={pid}," not in out
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "timed out" in m["error"]
