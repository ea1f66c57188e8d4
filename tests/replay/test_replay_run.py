"""The whole replay: hand-written LIGGGHTS and LAMMPS decks (box origins away from zero, every
fix deform style between them) run natively and compared with the codes' runs, stored (data/ref_*)
and live; incomplete or wrong evidence fails."""

import shutil
import subprocess
import sys

import numpy as np
import pytest
from replay_support import DATA, need_binary

from gransim.cli import main
from reference_runs.replay.compare import replay

DECKS = {"a": ("liggghts", "dump.disks"), "b": ("lammps", "dump.b"), "c": ("lammps", "dump.c")}


@pytest.mark.parametrize("name", sorted(DECKS))
def test_replay_agrees_with_stored_code_run(tmp_path, name):
    res = replay(DATA / f"in.deck_{name}", outdir=tmp_path / "out", reference=DATA / f"ref_{name}")
    assert res.passed, [c for c in res.checks if not c.passed]
    q = {c.quantity for c in res.checks}
    assert {"thermo xlo", "thermo yhi"} <= q and any("pressure" in x for x in q)
    assert any(x.startswith("thermo steps (run 1") for x in q)
    assert any(x.endswith(" x") for x in q) and any(x.endswith(" vx") for x in q)
    for f in ("report.html", "report.md", "replay.h5"):
        assert (tmp_path / "out" / f).stat().st_size > 0
    import h5py

    with h5py.File(tmp_path / "out" / "replay.h5") as f:
        assert f.attrs["kind"] == "replay" and bool(f.attrs["passed"])
        assert "git_commit" in f.attrs
        # tension positive in files: the compressed assembly has negative sigma_xx
        assert f["native/stress"][-1, 0] < 0


def _mutated_reference(tmp_path, name, edit_log=None, edit_dump=None):
    ref = tmp_path / "ref"
    shutil.copytree(DATA / f"ref_{name}", ref)
    dump = ref / DECKS[name][1]
    if edit_log:
        (ref / "log.lammps").write_text(edit_log((ref / "log.lammps").read_text()))
    if edit_dump:
        dump.write_text(edit_dump(dump.read_text()))
    return ref


def _drop_last_frame(text):
    k = text.rfind("ITEM: TIMESTEP")
    return text[:k]


def _drop_thermo_row(text):
    lines = text.splitlines(keepends=True)
    k = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["250"])
    return "".join(lines[:k] + lines[k + 1 :])


def _nudge_position(text):
    # the x of the first atom of the frame at step 300, moved by 1e-9 m (5e-7 D50)
    k = text.find("ITEM: TIMESTEP\n300\n")
    k = text.find("ITEM: ATOMS", k)
    e = text.find("\n", k) + 1
    row = text[e : text.find("\n", e)].split()
    row[1] = repr(float(row[1]) + 1e-9)
    return text[:e] + " ".join(row) + text[text.find("\n", e) :]


@pytest.mark.parametrize(
    "how,needle",
    [
        ("frame", "incomplete: frames missing"),
        ("thermo", "incomplete: thermo rows missing"),
        ("nudge", "dump snap x"),
    ],
)
def test_incomplete_or_wrong_evidence_fails(tmp_path, how, needle):
    ref = _mutated_reference(
        tmp_path,
        "a",
        edit_dump=_drop_last_frame if how == "frame" else _nudge_position if how == "nudge" else None,
        edit_log=_drop_thermo_row if how == "thermo" else None,
    )
    res = replay(DATA / "in.deck_a", outdir=tmp_path / "out", reference=ref)
    assert not res.passed
    bad = [c for c in res.checks if not c.passed]
    assert any(needle in c.metric or needle in c.quantity for c in bad), bad
    assert "FAIL" in (tmp_path / "out" / "report.md").read_text().splitlines()[0]


def test_cli_exit_status_and_one_line_errors(tmp_path, capsys):
    out = tmp_path / "o"
    assert main(["replay", str(DATA / "in.deck_c"), "--reference", str(DATA / "ref_c"), "-o", str(out)]) == 0
    assert "PASS" in capsys.readouterr().out
    ref = _mutated_reference(tmp_path, "a", edit_dump=_drop_last_frame)
    assert main(["replay", str(DATA / "in.deck_a"), "--reference", str(ref), "-o", str(out)]) == 1
    assert "incomplete" in capsys.readouterr().out
    bad = tmp_path / "in.bad"
    bad.write_text((DATA / "in.deck_a").read_text().replace("run             500", "fix w all wall/gran\nrun 5"))
    assert main(["replay", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("gransim replay: error:") and f"{bad}:" in err[0]
    assert "fix style `wall/gran`" in err[0]
    assert main(["replay", str(tmp_path / "missing.in")]) == 2
    assert main(["replay", str(DATA / "in.deck_a"), "--timeout", "-1", "-o", str(out)]) == 2


@pytest.mark.parametrize("name", [pytest.param(n, marks=getattr(pytest.mark, DECKS[n][0])) for n in sorted(DECKS)])
def test_replay_agrees_with_live_code(tmp_path, name):
    engine, _ = DECKS[name]
    need_binary(engine)
    work = tmp_path / "deck"
    work.mkdir()
    for f in (f"in.deck_{name}", "disks_a.data", "disks_b.data"):
        shutil.copyfile(DATA / f, work / f)
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "gransim",
            "replay",
            str(work / f"in.deck_{name}"),
            "-o",
            str(tmp_path / "out"),
            "--timeout",
            "120",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    # the live log is the stored one, step for step
    from reference_runs.parsers import parse_log

    live = parse_log(tmp_path / "out" / "job" / "log.lammps").runs[-1]
    stored = parse_log(DATA / f"ref_{name}" / "log.lammps").runs[-1]
    assert np.array_equal(live.data, stored.data)
