"""A user deck whose run length and dump interval are index variables with defaults, overridden by
``--var`` (the users' decks of tests/replay/decks with ``variable nsteps index 100`` and a dump every
``${...}`` steps by default 25 or 7): the code's job expects its runs and dump frames from the
command-line values (``run_job(..., variables=...)``), so the replay passes, live in both codes and
on the stored runs; evidence cut short of the overridden values is incomplete."""

import json
import shutil
import subprocess
import sys

import pytest
from replay_support import need_binary
from test_replay_user_decks import DECKS, USER

from reference_runs.replay.compare import replay
from reference_runs.runner import job_evidence, verify_job

#: engine -> (the deck's fric default line, its dump line, {variable: (default, value given)}, that
#: dump's file): nsteps and the dump's interval become index variables with these defaults
EDIT = {
    "liggghts": (
        "variable        fric index 0.3",
        "dump  snap all custom 100 dump.disks",
        {"nsteps": ("100", "300"), "snapevery": ("25", "100")},
        "dump.disks",
    ),
    "lammps": (
        "variable fric index 0.3",
        "dump d all custom 50 dump.b",
        {"nsteps": ("100", "300"), "devery": ("7", "50")},
        "dump.b",
    ),
}


def overridden_deck(tmp_path, engine):
    """(deck path, --var values): the user deck with index defaults for nsteps and a dump interval."""
    data, var, _ = USER[engine]
    fric, dump_line, defaults, _ = EDIT[engine]
    text = (DECKS / f"in.user_{engine}").read_text()
    assert text.count(fric) == 1 and text.count(dump_line) == 1 and "variable nsteps" not in text
    every = next(k for k in defaults if k != "nsteps")
    words = dump_line.split()
    words[4] = "${" + every + "}"
    head = "".join(f"\nvariable {k} index {d}" for k, (d, _) in defaults.items())
    text = text.replace(fric, fric + head).replace(dump_line, " ".join(words))
    work = tmp_path / "deck"
    work.mkdir()
    shutil.copyfile(DECKS / data, work / data)
    deck = work / f"in.over_{engine}"
    deck.write_text(text)
    return deck, {**var, **{k: given for k, (_, given) in defaults.items()}}


def stored_job(tmp_path, engine):
    """The stored run of the user deck beside the overridden deck, as a job directory without manifest."""
    deck, var = overridden_deck(tmp_path, engine)
    job = tmp_path / "stored"
    shutil.copytree(DECKS / f"ref_user_{engine}", job)
    shutil.copyfile(deck, job / f"in.{engine}")
    return job, deck, var


#: ids that are not the bare code names: tests/reference_runs/conftest.py skips every collected test
#: with a keyword ``liggghts`` where the binary is absent, and these need no binary
STORED = {"argvalues": sorted(USER), "ids": [f"{e}-stored" for e in sorted(USER)]}


@pytest.mark.parametrize("engine", **STORED)
def test_stored_run_is_complete_only_with_the_overridden_values(tmp_path, engine):
    job, deck, var = stored_job(tmp_path, engine)
    _, _, defaults, snap = EDIT[engine]
    frames = {"liggghts": 5, "lammps": 10}[engine]  # every 100 (50) steps over 0..450
    ev = job_evidence(job, engine=engine, variables=var)
    assert ev["problems"] == [] and ev["unresolved"] == [] and ev["variables"] == var
    assert ev["last_steps_expected"] == ev["last_steps_got"] == [300, 300, 450]
    assert ev["dumps"][snap]["frames_expected"] == ev["dumps"][snap]["frames_got"] == frames
    # the deck's defaults (100 steps, another interval) do not describe this run
    plain = {k: v for k, v in var.items() if k not in defaults}
    problems = verify_job(job, engine=engine, variables=plain)
    assert any("covers steps 0..300, the deck asks for 0..100" in p for p in problems), problems
    # a dump or a log cut short of what the overridden values ask for is incomplete
    text = (job / "dump.contacts_run").read_text()
    (job / "dump.contacts_run").write_text(text[: text.rfind("ITEM: TIMESTEP")])
    assert verify_job(job, engine=engine, variables=var) == ["dump.contacts_run: expected 4 frames, got 3"]
    log = (job / "log.lammps").read_text()
    (job / "log.lammps").write_text(log[: log.rfind("Loop time of")])
    assert verify_job(job, engine=engine, variables=var)[0].startswith("incomplete: log.lammps holds 2 of 3 runs")


@pytest.mark.parametrize("engine", **STORED)
def test_overridden_deck_replays_against_the_stored_run(tmp_path, engine):
    deck, var = overridden_deck(tmp_path, engine)
    res = replay(deck, outdir=tmp_path / "out", reference=DECKS / f"ref_user_{engine}", variables=var)
    assert res.passed, [c for c in res.checks if not c.passed]
    assert [r.nsteps for r in res.deck.runs] == [300, 0, 150]


@pytest.mark.parametrize("engine", [pytest.param(e, marks=getattr(pytest.mark, e)) for e in sorted(USER)])
def test_overridden_deck_replays_live_and_its_job_records_the_variables(tmp_path, engine):
    need_binary(engine)
    deck, var = overridden_deck(tmp_path, engine)
    _, _, dumps = USER[engine]
    _, _, _, snap = EDIT[engine]
    args = [x for k, v in var.items() for x in ("--var", k, v)]
    r = subprocess.run(
        [sys.executable, "-m", "gransim", "replay", str(deck), *args, "-o", str(tmp_path / "out"), "--timeout", "120"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "PASS" in r.stdout and "could not follow" not in r.stderr and "WARNING" not in r.stderr
    job = tmp_path / "out" / "job"
    m = json.loads((job / "manifest.json").read_text())
    assert m["status"] == "ok" and m["variables"] == var
    assert m["command"][-3 * len(var) :] == [x for k, v in var.items() for x in ("-var", k, v)]
    ev = m["evidence"]
    assert ev["unresolved"] == [] and ev["last_steps_expected"] == ev["last_steps_got"] == [300, 300, 450]
    assert ev["dumps"][snap]["frames_expected"] == ev["dumps"][snap]["frames_got"]
    assert verify_job(job, engine=engine, variables=var) == []
    assert verify_job(job, variables={})[0].startswith("the job was run with -var")
    # the overridden defaults ran what the stored command-line run ran, frame for frame
    for f in dumps:
        assert (job / f).read_text() == (DECKS / f"ref_user_{engine}" / f).read_text(), f
