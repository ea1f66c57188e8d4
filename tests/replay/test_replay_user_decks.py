"""Decks as users write them (tests/replay/decks/README.md): command-line variables, diagnostics
computes, contact rows of dump local, undump, several runs with run 0, thermo keywords beyond the
pressure; stored code runs and live ones (skipped without the binaries), bit for bit; incomplete
or wrong evidence fails; what changes the physics between runs is refused naming its line."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from replay_support import need_binary

from gransim.cli import main
from gransim.errors import InputError
from reference_runs.parsers import parse_log
from reference_runs.replay.compare import replay
from reference_runs.replay.deck import read_deck

DECKS = Path(__file__).parent / "decks"
#: name -> (engine, data file, --var values, dumps)
USER = {
    "liggghts": (
        "disks_a.data",
        {"kn": "1e5", "rate": "-5.0", "nsteps": "300", "fric": "0.4"},
        ("dump.disks", "dump.contacts", "dump.contacts_run"),
    ),
    "lammps": (
        "disks_b.data",
        {"kn": "1e5", "vel": "-0.02", "nsteps": "300", "fric": "0.4"},
        ("dump.b", "dump.contacts", "dump.contacts_run"),
    ),
}


def _deck(engine):
    return DECKS / f"in.user_{engine}"


def _ref(tmp_path, engine, edit=None):
    """A copy of the stored job; ``edit(name, text) -> text`` changes its files."""
    ref = tmp_path / "ref"
    shutil.copytree(DECKS / f"ref_user_{engine}", ref)
    if edit is not None:
        for f in ref.iterdir():
            f.write_text(edit(f.name, f.read_text()))
    return ref


@pytest.mark.parametrize("engine", sorted(USER))
def test_user_deck_agrees_bit_for_bit_with_stored_code_run(tmp_path, engine):
    _, var, _ = USER[engine]
    res = replay(_deck(engine), outdir=tmp_path / "out", reference=DECKS / f"ref_user_{engine}", variables=var)
    assert res.passed, [c for c in res.checks if not c.passed]
    q = {c.quantity: c for c in res.checks}
    # every run's thermo table, every thermo keyword the natively evaluated ones among them
    assert {f"thermo steps (run {k}" for k in (1, 2, 3)} <= {x[: len("thermo steps (run 1")] for x in q}
    kinetic = ["thermo ke", "thermo c_mytemp", "thermo time", "thermo vol"]
    if engine == "lammps":
        kinetic += ["thermo temp", "thermo pe", "thermo etotal", "thermo press", "thermo pxx", "thermo c_mytemp[4]"]
        kinetic += ["thermo c_pke (pressure, kinetic)", "thermo c_pfull (pressure, kinetic + virial)"]
        contact = ["dump snapc dist", "dump snapc force", "dump snapc eng", "dump runc dist", "dump runc force"]
    else:
        kinetic += ["thermo c_pfull (pressure, kinetic + virial)", "thermo c_press[4] (pressure, virial)"]
        contact = ["dump snapc " + c for c in ("fx", "fy", "tqz", "h1", "h2", "delta", "area", "x2", "vx2")]
        contact += ["dump runc fx", "dump runc h1", "dump runc delta"]
    props = ["dump " + ("snap" if engine == "liggghts" else "d") + f" c_props[{k}]" for k in (1, 2, 3)]
    for name in kinetic + contact + props:
        assert name in q, (name, sorted(q))
    # bit for bit: every compared value equal, not only within tolerance
    compared = [c for c in res.checks if "bitwise equal" in c.detail]
    assert len(compared) >= 30
    assert all("bitwise equal: True" in c.detail for c in compared), [c for c in compared if "False" in c.detail]
    # the contact snapshot of run 0 compares every row, periodic ones included (a set-up frame)
    assert "presence only" not in q["dump snapc rows without a native contact"].detail
    assert "presence only" in q["dump runc rows without a native contact"].detail


@pytest.mark.parametrize("engine", sorted(USER))
def test_command_line_variables_are_substituted_natively(engine):
    _, var, _ = USER[engine]
    d = read_deck(_deck(engine), variables=var)
    assert d.settings.mu == 0.4  # the deck's `variable fric index 0.3` default overridden
    assert [r.nsteps for r in d.runs] == [300, 0, 150] and d.nsteps == 450
    assert [r.thermo_every for r in d.runs] == [50, 50, 25]
    assert d.variables == var
    d3 = read_deck(_deck(engine), variables={**var, "fric": "0.3", "nsteps": "120"})
    assert d3.settings.mu == 0.3 and [r.nsteps for r in d3.runs] == [120, 0, 150]
    with pytest.raises(InputError, match=r"in.user_\w+:\d+: \$\{kn\}: no variable 'kn'.*--var"):
        read_deck(_deck(engine), variables={k: v for k, v in var.items() if k != "kn"})
    for bad, needle in (({"k n": "1"}, "letters, digits"), ({**var, "rate": "1 2"}, "one word")):
        with pytest.raises(InputError, match=needle):
            read_deck(_deck(engine), variables=bad)


def test_cli_var_options_are_checked(tmp_path, capsys):
    deck = str(_deck("lammps"))
    assert main(["replay", deck, "--var", "k-n", "1", "-o", str(tmp_path / "o")]) == 2
    assert "--var NAME" in capsys.readouterr().err
    assert main(["replay", deck, "--var", "kn", "1", "--var", "kn", "2", "-o", str(tmp_path / "o")]) == 2
    assert "given twice" in capsys.readouterr().err
    # without --var the deck's ${kn} is undefined: refused naming the line (no run started)
    assert main(["replay", deck, "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "no variable 'kn'" in err and f"{deck}:" in err
    assert not (tmp_path / "o" / "job").exists()


def _drop_frame(step):
    def edit(name, text):
        if name != "dump.contacts_run":
            return text
        k = text.find(f"ITEM: TIMESTEP\n{step}\n")
        e = text.find("ITEM: TIMESTEP", k + 1)
        return text[:k] + (text[e:] if e > 0 else "")

    return edit


def _drop_contact_row(name, text):
    if name != "dump.contacts":
        return text
    lines = text.splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("ITEM: ENTRIES")) + 1
    n = next(i for i, ln in enumerate(lines) if ln.startswith("ITEM: NUMBER OF ENTRIES")) + 1
    lines[n] = f"{int(lines[n]) - 1}\n"
    # the first row with a force (a contact the native run has)
    force = 4 if "index" in lines[k - 1] else 15
    row = next(i for i in range(k, len(lines)) if float(lines[i].split()[force]) != 0.0)
    return "".join(lines[:row] + lines[row + 1 :])


def _drop_last_run(name, text):
    if name != "log.lammps":
        return text
    k = text.rfind("Setting up run") if "Setting up run" in text else text.rfind("Per MPI rank memory")
    return text[:k]


def _nudge_contact_force(name, text):
    if name != "dump.contacts":
        return text
    lines = text.splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln.startswith("ITEM: ENTRIES")) + 1
    force = 4 if "index" in lines[k - 1] else 15
    row = next(i for i in range(k, len(lines)) if float(lines[i].split()[force]) != 0.0)
    w = lines[row].split()
    w[force] = repr(float(w[force]) * (1 + 1e-6))
    lines[row] = " ".join(w) + "\n"
    return "".join(lines)


@pytest.mark.parametrize("engine", sorted(USER))
@pytest.mark.parametrize(
    "edit,needle",
    [
        (_drop_frame(400), "incomplete: frames missing"),
        (_drop_contact_row, "incomplete: rows or frames missing"),
        (_drop_last_run, "incomplete: thermo tables missing"),
        (_nudge_contact_force, "dump snapc f"),
    ],
)
def test_incomplete_or_wrong_contact_and_run_evidence_fails(tmp_path, engine, edit, needle):
    _, var, _ = USER[engine]
    ref = _ref(tmp_path, engine, edit)
    res = replay(_deck(engine), outdir=tmp_path / "out", reference=ref, variables=var)
    assert not res.passed
    bad = [c for c in res.checks if not c.passed]
    assert any(needle in c.metric or c.quantity.startswith(needle) for c in bad), bad


def _edited(tmp_path, engine, old, new):
    data, _, _ = USER[engine]
    shutil.copyfile(DECKS / data, tmp_path / data)
    text = _deck(engine).read_text()
    assert old in text
    p = tmp_path / f"in.edited_{engine}"
    p.write_text(text.replace(old, new, 1))
    lineno = next(k for k, ln in enumerate(p.read_text().splitlines(), 1) if new.splitlines()[-1] in ln)
    return p, lineno


@pytest.mark.parametrize(
    "engine,old,new,needle",
    [
        # physics changed between runs
        ("liggghts", "run             0\n", "run 0\ntimestep 2e-6\n", "`timestep` after a `run`"),
        ("lammps", "run 0\n", "run 0\nfix 4 all gravity 9.81 vector 0 -1 0\n", "`fix` after a `run`"),
        ("lammps", "run 0\n", "run 0\nunfix 3\n", "command `unfix`"),
        ("liggghts", "run             0\n", "run 0\ncompute late all pair/gran/local id force\n", "before first run"),
        # outside the subset or refused by the code itself
        ("liggghts", "thermo          25\n", "thermo_style custom step temp\n", "no such keyword"),
        ("lammps", "compute pke all pressure mytemp ke", "compute pke all pressure NULL ke", "needs a temperature"),
        (
            "lammps",
            "compute pke all pressure mytemp ke",
            "compute pke all pressure props",
            "no `compute props all temp`",
        ),
        ("lammps", "compute pke all pressure mytemp ke", "compute pke all pressure mytemp bond", "keywords bond"),
        ("lammps", "run 150", "run 150 upto", "without keywords"),
        ("lammps", "variable gn equal 50", "variable fric equal 0.5", "different style"),
        ("lammps", "variable gn equal 50", "variable gn equal $(2*25)", "immediate variables"),
        ("liggghts", "undump          snapc", "undump          nodump", "no dump 'nodump'"),
        ("lammps", "compute ploc all property/local patom1 patom2", "compute ploc all property/local batom1", "batom1"),
    ],
)
def test_refusals_name_the_line_and_why(tmp_path, engine, old, new, needle):
    _, var, _ = USER[engine]
    p, lineno = _edited(tmp_path, engine, old, new)
    with pytest.raises(InputError) as e:
        read_deck(p, variables=var)
    msg = str(e.value)
    assert needle in msg, msg
    assert f"{p}:{lineno}:" in msg, msg


def test_output_commands_between_runs_are_accepted(tmp_path):
    _, var, _ = USER["lammps"]
    p, _ = _edited(
        tmp_path,
        "lammps",
        "run 0\n",
        "run 0\nthermo_style custom step atoms ke c_p\nthermo_modify format float %.17g norm no\n"
        "compute t2 all temp\nvariable late equal 3\n",
    )
    d = read_deck(p, variables=var)
    assert d.runs[2].thermo_columns == ("step", "atoms", "ke", "c_p") and "t2" in d.computes


@pytest.mark.parametrize("engine", [pytest.param(e, marks=getattr(pytest.mark, e)) for e in sorted(USER)])
def test_user_deck_replays_live_through_the_command_line(tmp_path, engine):
    need_binary(engine)
    data, var, dumps = USER[engine]
    work = tmp_path / "deck"
    work.mkdir()
    for f in (f"in.user_{engine}", data):
        shutil.copyfile(DECKS / f, work / f)
    args = [x for k, v in var.items() for x in ("--var", k, v)]
    cmd = [sys.executable, "-m", "gransim", "replay", str(work / f"in.user_{engine}"), *args]
    r = subprocess.run(
        [*cmd, "-o", str(tmp_path / "out"), "--timeout", "120"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert "PASS" in r.stdout
    job = tmp_path / "out" / "job"
    # the variables reached the code's command line, and the deck ran unchanged
    command = json.loads((job / "manifest.json").read_text())["command"]
    assert command[-3 * len(var) :] == [x for k, v in var.items() for x in ("-var", k, v)]
    assert (job / f"in.{engine}").read_text() == (DECKS / f"in.user_{engine}").read_text()
    # the live run is the stored one, run for run and frame for frame
    live, stored = parse_log(job / "log.lammps").runs, parse_log(DECKS / f"ref_user_{engine}" / "log.lammps").runs
    assert len(live) == len(stored) == 3
    for a, b in zip(live, stored):
        keep = [k for k, c in enumerate(a.columns) if c.lower() != "cpu"]
        assert np.array_equal(a.data[:, keep], b.data[:, keep])
    for f in dumps:
        assert (job / f).read_text() == (DECKS / f"ref_user_{engine}" / f).read_text(), f
