"""Faults of YADE jobs (Taylor states and the periodic DEM runs): an output cut short or with a state,
step, frame, particle or contact missing is refused as incomplete (by the reader and as the job's
verdict: manifest ``failed``, never ``ok``), and a hung YADE job is killed at its timeout with
nothing left running or listening."""

import json
import shutil
import time

import pytest
from fakes import YADE_PID_PREFIX, assert_yade_gone

import reference_runs.runner as runner
from gransim.paper import KN_2D
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import read_manifest
from reference_runs.yade.dem import biaxial_job, read_yade_dem, run_yade_dem, short_biaxial
from reference_runs.yade.job import run_yade_job
from reference_runs.yade.script import TAYLOR_SCRIPT
from reference_runs.yade.taylor import check_output, read_yade_taylor, run_yade_taylor, yade_taylor_job

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
PACKING = perturbed_lattice(4, 4, seed=2)
PATHS = ("compression-11", "shear-12")
N_STATES = 4  # 2 paths x (k = 0, 1)


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


def test_hung_yade_job_is_killed_with_nothing_left(tmp_path, monkeypatch):
    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)
    script, files, _ = yade_taylor_job(PACKING, KN_2D, paths=PATHS, n_steps=1)
    hung = YADE_PID_PREFIX + "import time\ntime.sleep(1000)\n" + script
    assert script == TAYLOR_SCRIPT
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match="timed out after 4 s") as info:
        run_yade_job(tmp_path / "job", hung, files, timeout=4, outputs=["taylor.out"], check=check_output)
    assert info.value.timed_out and time.monotonic() - t0 < 15
    assert_yade_gone(tmp_path / "job")
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "timed out" in m["error"]


# --- the periodic DEM runs (reference_runs.yade.dem): a missing step, frame, particle or contact is
# incomplete, a job whose output is cut short fails, a hung run is killed with nothing left


@pytest.fixture(scope="module")
def dem_lines(tmp_path_factory):
    p, s, ld, _ = short_biaxial()
    script, files = biaxial_job(p, s, ld, DEM_STEPS, thermo_every=1, dump_every=10)
    job = tmp_path_factory.mktemp("yade-dem") / "job"
    out, _ = run_yade_dem(job, script, files)
    assert sorted(out.frames) == [0, 10, 20, 30, 40] and len(out.step) == DEM_STEPS + 1
    return (job / "dem.out").read_text().splitlines(keepends=True)


DEM_STEPS = 40
DEM_EXPECT = {"n_particles": 120, "n_steps": DEM_STEPS, "thermo_every": 1, "dump_every": 10}


def _without(lines, pick):
    i = pick([ln.split()[0] for ln in lines], lines)
    return "".join(lines[:i] + lines[i + 1 :])


def _second(kind):
    return lambda kinds, _lines: [i for i, k in enumerate(kinds) if k == kind][1]


def _frame_missing(lines):
    kinds = [ln.split()[0] for ln in lines]
    f = [i for i, k in enumerate(kinds) if k == "F"]
    end = next(i for i in range(f[2] + 1, len(lines)) if kinds[i] not in ("P", "C"))
    return "".join(lines[: f[2]] + lines[end:])  # the frame of step 20, its header and rows


def _particle_replaced(lines):
    kinds = [ln.split()[0] for ln in lines]
    i = [k for k, kind in enumerate(kinds) if kind == "P"][5]
    return "".join(lines[:i] + [lines[i - 1]] + lines[i + 1 :])  # particle 4 twice, 5 gone


@pytest.mark.parametrize(
    "damage,message",
    [
        (lambda ls: "".join(ls)[: len("".join(ls)) // 2], "cut short"),
        (lambda ls: "".join(ls[:-1]), r"cut short after 41 of 41 thermo steps and 5 of 5 frames \(no END line\)"),
        (lambda ls: _without(ls, _second("T")), "thermo step 2 where step 1 is due"),
        (_frame_missing, "frame of step 30 where step 20 is due"),
        (lambda ls: _without(ls, _second("P")), r"frame of step 0 has 119 of 120 particles"),
        (lambda ls: _without(ls, _second("C")), r"frame of step 0 has 120 of 120 particles and \d+ of \d+ contacts"),
        (_particle_replaced, r"particle ids are not 0..119 in order \(missing \[5\]\)"),
    ],
)
def test_damaged_yade_dem_output_is_refused_as_incomplete(dem_lines, damage, message, tmp_path):
    (tmp_path / "dem.out").write_text(damage(dem_lines))
    with pytest.raises(ReferenceRunError, match="incomplete: .*" + message):
        read_yade_dem(tmp_path / "dem.out", DEM_EXPECT)


def test_yade_dem_output_of_another_run_is_refused(dem_lines, tmp_path):
    (tmp_path / "dem.out").write_text("".join(dem_lines))
    with pytest.raises(ReferenceRunError, match="the header has n_steps = 40, the job 50"):
        read_yade_dem(tmp_path / "dem.out", {**DEM_EXPECT, "n_steps": 50})


def test_yade_dem_job_whose_output_is_cut_short_fails_never_ok(tmp_path):
    p, s, ld, _ = short_biaxial()
    script, files = biaxial_job(p, s, ld, 20, thermo_every=1, dump_every=10)
    cut = script + "\ntext = open('dem.out').read()\nopen('dem.out', 'w').write(text[: len(text) - 200])\n"
    with pytest.raises(ReferenceRunError, match="incomplete: .*dem.out"):
        run_yade_dem(tmp_path / "job", cut, files)
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "incomplete" in m["error"] and "outputs" not in m


def test_hung_yade_dem_run_is_killed_with_nothing_left_listening(tmp_path, monkeypatch):
    """The run hangs inside YADE's step (in the PyRunner's Python, step 5): killed at the timeout,
    its process gone, no port of it listening."""
    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)
    p, s, ld, _ = short_biaxial()
    script, files = biaxial_job(p, s, ld, 1000, thermo_every=1, dump_every=100)
    hook = "def control():\n    k = O.iter\n"
    assert hook in script
    hung = YADE_PID_PREFIX + script.replace(
        hook, hook + "    if k == 5:\n        import time\n        time.sleep(1000)\n"
    )
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match="timed out after 4 s") as info:
        run_yade_dem(tmp_path / "job", hung, files, timeout=4)
    assert info.value.timed_out and time.monotonic() - t0 < 15
    assert_yade_gone(tmp_path / "job")
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "timed out" in m["error"]
    assert "\nT 0 " in (tmp_path / "job" / "dem.out").read_text()  # it had started stepping: the hang was mid-run
