"""Faults of YADE impact jobs (reference_runs.yade.impacts): an output cut short or with a frame or a
particle missing is refused as incomplete, by the reader and as the job's verdict (manifest
``failed``, never ``ok``); a hung job is killed at its timeout with its process gone and nothing of
it listening."""

import shutil
import time

import pytest
from fakes import YADE_PID_PREFIX, assert_yade_gone

import reference_runs.runner as runner
from reference_runs.errors import ReferenceRunError
from reference_runs.runner import read_manifest
from reference_runs.yade.impacts import impact_job, read_yade_impact, run_yade_impact
from validation.cases import impacts as I

pytestmark = pytest.mark.skipif(
    shutil.which("yade") is None, reason="yade binary not installed (apt-get install yade; make engines)"
)
STEPS, EVERY = 40, 10


def _job(n_steps=STEPS):
    sc = next(s for s in I.scenes("quick") if s.name == "normal-z0")  # 4 disks
    p, v, w, _, _ = I.layout(sc)
    return impact_job(p, v, w, sc.law, I.DT, n_steps, EVERY)


EXPECT = {"n_particles": 4, "n_steps": STEPS, "every": EVERY}


@pytest.fixture(scope="module")
def lines(tmp_path_factory):
    job = tmp_path_factory.mktemp("yade-impact") / "job"
    script, files = _job()
    out, _ = run_yade_impact(job, script, files)
    assert list(out.steps) == [0, 10, 20, 30, 40]
    return (job / "impact.out").read_text().splitlines(keepends=True)


def _frame_missing(ls):
    f = [i for i, ln in enumerate(ls) if ln.startswith("F ")]
    return "".join(ls[: f[2]] + ls[f[3] :])  # the frame of step 20 with its rows


def _particle_missing(ls):
    p = [i for i, ln in enumerate(ls) if ln.startswith("P ")]
    return "".join(ls[: p[1]] + ls[p[1] + 1 :])


def _particle_replaced(ls):
    p = [i for i, ln in enumerate(ls) if ln.startswith("P ")]
    return "".join(ls[: p[2]] + [ls[p[1]]] + ls[p[2] + 1 :])  # particle 1 twice, 2 gone


@pytest.mark.parametrize(
    "damage,message",
    [
        (lambda ls: "".join(ls)[: len("".join(ls)) // 2], "cut short"),
        (lambda ls: "".join(ls[:-1]), r"cut short after 5 of 5 frames \(no END line\)"),
        (lambda ls: "".join(ls[:11]), r"cut short after 2 of 5 frames"),
        (_frame_missing, "frame of step 30 where step 20 is due"),
        (_particle_missing, r"frame of step 0 has 3 of 4 particles"),
        (_particle_replaced, r"particle ids are not 0..3 in order \(missing \[2\]\)"),
        (lambda ls: "".join(ls).replace(ls[3].split()[2], "nan", 1), "NaN or inf"),
    ],
)
def test_damaged_impact_output_is_refused_as_incomplete(lines, damage, message, tmp_path):
    (tmp_path / "impact.out").write_text(damage(lines))
    with pytest.raises(ReferenceRunError, match="incomplete: .*" + message):
        read_yade_impact(tmp_path / "impact.out", EXPECT)


def test_output_of_another_run_is_refused(lines, tmp_path):
    (tmp_path / "impact.out").write_text("".join(lines))
    with pytest.raises(ReferenceRunError, match="the header has n_steps = 40, the job 50"):
        read_yade_impact(tmp_path / "impact.out", {**EXPECT, "n_steps": 50})


def test_job_whose_output_is_cut_short_fails_never_ok(tmp_path):
    script, files = _job()
    cut = script + "\ntext = open('impact.out').read()\nopen('impact.out', 'w').write(text[: len(text) - 100])\n"
    with pytest.raises(ReferenceRunError, match="incomplete: .*impact.out") as info:
        run_yade_impact(tmp_path / "job", cut, files)
    assert not info.value.timed_out
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "incomplete" in m["error"] and "outputs" not in m


def test_hung_impact_job_is_killed_with_nothing_left_listening(tmp_path, monkeypatch):
    """The run hangs inside YADE's step (the PyRunner's Python, step 5): killed at the timeout, its
    process gone, no port of it listening."""
    monkeypatch.setattr(runner, "KILL_GRACE_S", 0.5)
    script, files = _job(1000)
    hook = "def dump():\n    k = O.iter\n"
    assert hook in script
    hung = YADE_PID_PREFIX + script.replace(
        hook, hook + "    if k == 5:\n        import time\n        time.sleep(1000)\n"
    )
    t0 = time.monotonic()
    with pytest.raises(ReferenceRunError, match="timed out after 4 s") as info:
        run_yade_impact(tmp_path / "job", hung, files, timeout=4)
    assert info.value.timed_out and time.monotonic() - t0 < 15
    assert_yade_gone(tmp_path / "job")
    m = read_manifest(tmp_path / "job")
    assert m["status"] == "failed" and "timed out" in m["error"]
    assert "\nF 0 4\n" in (tmp_path / "job" / "impact.out").read_text()  # it had started stepping
