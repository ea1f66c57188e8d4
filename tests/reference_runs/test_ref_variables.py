"""Command-line variables of a job (``run_job(..., variables=...)``, the codes' ``-var NAME VALUE``):
checked once naming the variable, on the code's command line, winning over the deck's ``variable
NAME index DEFAULT`` in the expected runs and dump frames, recorded in the manifest and part of the
job's identity (a job run with other variables is neither complete for these nor reused). The live
tests run a 3-disk deck in LIGGGHTS and LAMMPS and are skipped without the binary."""

import json
import shutil

import pytest

from gransim.errors import InputError
from reference_runs.engines import LAMMPS, LIGGGHTS, YADE, check_variables
from reference_runs.expect import expected_evidence
from reference_runs.runner import is_complete, job_evidence, manifest_variables, read_manifest, run_job, verify_job

#: a deck whose run length and dump interval are index variables with defaults (10 steps, every 5)
HEAD = "variable nsteps index 10\nvariable every index 5\n"
TAIL = """dump d all custom ${every} dump.tiny id x y
thermo_style custom step atoms
thermo ${every}
run ${nsteps}
run 0
"""
#: three disks far apart (no contact: the run is quick and warning-free in both codes)
DATA = """three disks far apart

3 atoms
1 atom types

-0.0123 0.0377 xlo xhi
0.0051 0.0462 ylo yhi
-0.001 0.001 zlo zhi

Atoms

1 1 0.002 2500 0.001 0.010 0
2 1 0.0024 2500 0.02 0.03 0
3 1 0.0018 2500 -0.005 0.04 0

Velocities

1 0.5 0.1 0 0 0 0
2 -0.2 0.3 0 0 0 0
3 0.1 -0.4 0 0 0 0
"""
LAW = {
    "liggghts": """communicate single vel yes
read_data data.tiny
fix k1 all property/global kn peratomtypepair 1 1e5
fix k2 all property/global kt peratomtypepair 1 7e4
fix k3 all property/global gamman peratomtypepair 1 50
fix k4 all property/global gammat peratomtypepair 1 25
fix k5 all property/global coefficientFriction peratomtypepair 1 0.5
pair_style gran model hooke/stiffness tangential history
pair_coeff * *
fix 1 all nve/sphere
""",
    "lammps": """comm_modify mode single vel yes
read_data data.tiny
set group all density/disc 2500
pair_style gran/hooke/history 1e5 7e4 50 25 0.5 1
pair_coeff * *
fix 1 all nve/sphere disc
""",
}
COMMON = """units si
dimension 2
boundary p p p
atom_style sphere
atom_modify map array sort 0 0.0
newton off
"""
REST = """neighbor 1e-4 bin
neigh_modify delay 0 every 1 check yes
timestep 1e-5
fix 2 all enforce2d
"""
VAR = {"nsteps": "12", "every": "4"}


def deck(engine: str) -> str:
    return HEAD + COMMON + LAW[engine] + REST + TAIL


# ----------------------------------------------------------------------------- without the codes
def test_the_command_line_value_wins_over_the_index_default():
    text = deck("lammps")
    d = expected_evidence(text)  # the deck's defaults: 10 steps, a frame every 5
    assert [(r.start, r.end) for r in d.runs] == [(0, 10), (10, 10)] and not d.unresolved
    assert d.dumps["dump.tiny"].steps == (0, 5, 10)
    v = expected_evidence(text, VAR)
    assert [(r.start, r.end) for r in v.runs] == [(0, 12), (12, 12)] and not v.unresolved
    assert v.dumps["dump.tiny"].steps == (0, 4, 8, 12)
    # one of them given: the other keeps its default
    assert expected_evidence(text, {"every": "3"}).dumps["dump.tiny"].steps == (0, 3, 6, 9)
    # a variable the deck never defines: known only from the command line, else named as undefined
    bare = "run ${n}\n"
    assert [r.end for r in expected_evidence(bare, {"n": "7"}).runs] == [7]
    why = expected_evidence(bare).unresolved
    assert expected_evidence(bare).runs is None and "${n}, which is not defined" in why[0] and "-var n" in why[0]
    # redefining a command-line (index) variable as equal stops the codes: not followed
    e = expected_evidence("variable n equal 3\nrun ${n}\n", {"n": "7"})
    assert e.runs is None and "given on the command line" in e.unresolved[0] and "Cannot redefine" in e.unresolved[0]
    # the value of a variable line is substituted first (the codes substitute every line)
    assert [r.end for r in expected_evidence("variable m equal ${n}\nrun ${m}\n", {"n": "5"}).runs] == [5]


def test_bad_or_repeated_variables_are_refused_naming_them(tmp_path):
    with pytest.raises(InputError, match=r"^variables kn: given twice$"):
        check_variables([("kn", "1"), ("kn", "2")])
    for bad in ("k-n", "k n", "", "kø"):
        with pytest.raises(
            InputError, match=rf"^variables NAME: expected letters, digits and underscores, got {bad!r}"
        ):
            check_variables({bad: "1"})
    for value in ("", "1 2", None, True):
        with pytest.raises(InputError, match=rf"^variables kn VALUE: expected one word, got {value!r}"):
            check_variables({"kn": value})
    assert check_variables([("b", 3), ("a", -5.0)]) == {"b": "3", "a": "-5.0"}
    assert list(check_variables({"z": "1", "a": "2"})) == ["z", "a"]  # the order given
    # run_job refuses them before anything runs (no job directory, no binary needed)
    for variables, needle in (([("n", "1"), ("n", "2")], "variables n: given twice"), ({"a.b": "1"}, "'a.b'")):
        with pytest.raises(InputError, match=needle):
            run_job(tmp_path / "job", "run ${n}\n", variables=variables, progress=False)
    assert not (tmp_path / "job").exists()
    with pytest.raises(InputError, match="YADE"):
        run_job(tmp_path / "yjob", "print(1)\n", engine="yade", variables={"n": "1"})
    with pytest.raises(InputError, match="YADE"):
        YADE.command("s.py", exe="/x/yade", variables={"n": "1"})
    assert not (tmp_path / "yjob").exists()


def test_variables_end_the_command_line_in_the_order_given():
    for eng in (LIGGGHTS, LAMMPS):
        cmd = eng.command(eng.deck_name, "log.lammps", exe="/x/code", variables={"nsteps": "12", "rate": "-5.0"})
        assert cmd == [
            "/x/code",
            *("-in", eng.deck_name, "-log", "log.lammps", "-screen", "none", "-nocite"),
            *("-var", "nsteps", "12", "-var", "rate", "-5.0"),
        ]
        assert eng.command(eng.deck_name, "log.lammps", exe="/x/code") == cmd[:8]
        if shutil.which("mpirun"):
            par = eng.command(eng.deck_name, "log.lammps", np=2, exe="/x/code", variables=VAR)
            assert par[par.index("/x/code") :] == [*cmd[:8], "-var", "nsteps", "12", "-var", "every", "4"]


def test_older_manifests_give_their_variables_by_their_command():
    assert manifest_variables(None) == {} and manifest_variables({"command": ["lmp", "-in", "in.lammps"]}) == {}
    m = {"command": ["lmp", "-in", "in.lammps", "-nocite", "-var", "kn", "1e5", "-var", "rate", "-5.0"]}
    assert manifest_variables(m) == {"kn": "1e5", "rate": "-5.0"}
    assert manifest_variables({**m, "variables": {}}) == {}  # recorded: the record wins


# ----------------------------------------------------------------------------- live
def _need(engine):
    binary = {"liggghts": "liggghts", "lammps": "lmp"}[engine]
    if shutil.which(binary) is None:
        pytest.skip(f"{binary} binary not installed")


def _drop_last_frame(path):
    text = path.read_text()
    path.write_text(text[: text.rfind("ITEM: TIMESTEP")])


def _run(job, engine, variables):
    return run_job(
        job,
        deck(engine),
        {"data.tiny": DATA},
        outputs=["dump.tiny"],
        engine=engine,
        variables=variables,
        progress=False,
    )


ENGINES = [pytest.param(e, marks=getattr(pytest.mark, e)) for e in ("liggghts", "lammps")]


@pytest.mark.parametrize("engine", ENGINES)
def test_overridden_defaults_run_complete_and_are_recorded(tmp_path, capsys, engine):
    _need(engine)
    job = tmp_path / "job"
    res = _run(job, engine, VAR)
    m = res.manifest
    assert not res.skipped and m["status"] == "ok"
    assert m["variables"] == VAR and m["command"][-6:] == ["-var", "nsteps", "12", "-var", "every", "4"]
    assert json.loads((job / "manifest.json").read_text())["variables"] == VAR
    # the runs and frames were expected from the command-line values, and the code wrote them
    ev = m["evidence"]
    assert ev["last_steps_expected"] == ev["last_steps_got"] == [12, 12] and ev["unresolved"] == []
    assert ev["dumps"]["dump.tiny"]["frames_expected"] == ev["dumps"]["dump.tiny"]["frames_got"] == 4
    assert [int(s) for s in res.log.runs[0].steps][-1] == 12
    assert "could not follow" not in capsys.readouterr().err
    # complete for these variables (in any order), not for others nor for none
    assert verify_job(job) == [] and verify_job(job, variables={"every": "4", "nsteps": "12"}, engine=engine) == []
    assert is_complete(job, engine=engine, variables={"every": "4", "nsteps": "12"})
    assert not is_complete(job, variables={}) and not is_complete(job, variables={"nsteps": "12"})
    assert verify_job(job, variables={"nsteps": "10", "every": "4"}) == [
        "the job was run with -var every 4 -var nsteps 12, not -var every 4 -var nsteps 10"
    ]
    assert verify_job(job, variables={}) == ["the job was run with -var every 4 -var nsteps 12, not no -var"]
    assert job_evidence(job)["variables"] == VAR

    # the same variables: reused; other variables or none: another job, run again
    assert _run(job, engine, dict(reversed(VAR.items()))).skipped
    other = _run(job, engine, {"nsteps": "8", "every": "4"})
    assert not other.skipped and other.manifest["variables"] == {"nsteps": "8", "every": "4"}
    assert other.manifest["evidence"]["last_steps_got"] == [8, 8] and "rerun_reason" not in other.manifest
    assert other.manifest["evidence"]["dumps"]["dump.tiny"]["frames_got"] == 3
    plain = _run(job, engine, None)
    assert not plain.skipped and plain.manifest["variables"] == {} and "-var" not in plain.manifest["command"]
    assert plain.manifest["evidence"]["last_steps_got"] == [10, 10]  # the deck's defaults
    assert plain.manifest["evidence"]["dumps"]["dump.tiny"]["frames_got"] == 3  # 0, 5, 10
    assert is_complete(job, variables={}) and not is_complete(job, variables=VAR)


@pytest.mark.parametrize("engine", ENGINES)
def test_output_cut_short_of_the_overridden_values_is_incomplete(tmp_path, capsys, engine):
    _need(engine)
    job = tmp_path / "job"
    _run(job, engine, VAR)
    # the outputs without their manifest: the expectation comes from the variables given
    bare = tmp_path / "bare"
    bare.mkdir()
    for f in (f"in.{engine}", "log.lammps", "dump.tiny"):
        shutil.copyfile(job / f, bare / f)
    assert verify_job(bare, variables=VAR) == []
    # read with the deck's defaults instead, the same outputs are not the deck's (10 steps, not 12)
    line = deck(engine).splitlines().index("run ${nsteps}") + 1
    assert verify_job(bare) == [
        f"log.lammps: run 1 (deck line {line}) covers steps 0..12, the deck asks for 0..10",
        "dump.tiny: expected 3 frames, got 4",
    ]
    _drop_last_frame(bare / "dump.tiny")
    assert verify_job(bare, variables=VAR) == ["dump.tiny: expected 4 frames, got 3"]
    log = (bare / "log.lammps").read_text()
    (bare / "log.lammps").write_text(log[: log.rfind("Loop time of")])
    assert verify_job(bare, variables=VAR)[0].startswith("incomplete: log.lammps holds 1 of 2 runs")
    # the job itself, its dump cut short after it ran: incomplete, and rerun on reuse
    _drop_last_frame(job / "dump.tiny")
    problems = verify_job(job)
    assert "dump.tiny: expected 4 frames, got 3" in problems and not is_complete(job, variables=VAR)
    again = _run(job, engine, VAR)
    assert not again.skipped and "dump.tiny: expected 4 frames, got 3" in again.manifest["rerun_reason"]
    assert "fails verification" in capsys.readouterr().err
    assert is_complete(job, variables=VAR) and read_manifest(job)["evidence"]["dumps"]["dump.tiny"]["frames_got"] == 4
