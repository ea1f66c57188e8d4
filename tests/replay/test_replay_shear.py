"""Replay of sheared LAMMPS decks (change_box all triclinic or a tilted data file, fix deform N xy
... remap v) through ShearEngine: hand-written decks d (xy erate), e (xy final, tilted data file),
f (xy trate, N = 2, tilted data file) and g (xy vel, N = 3), all with the box origin away from zero,
against stored and live LAMMPS runs; the refusals."""

import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest
from replay_support import DATA

from gransim.errors import InputError
from reference_runs.replay.compare import replay
from reference_runs.replay.deck import read_deck

DECKS = {"d": "dump.d", "e": "dump.e", "f": "dump.f", "g": "dump.g"}


@pytest.mark.parametrize("name", sorted(DECKS))
def test_sheared_replay_agrees_with_stored_lammps_run(tmp_path, name):
    res = replay(DATA / f"in.deck_{name}", outdir=tmp_path / "out", reference=DATA / f"ref_{name}")
    assert res.deck.sheared and res.deck.engine == "lammps"
    assert res.passed, [c for c in res.checks if not c.passed]
    by = {c.quantity: c for c in res.checks}
    # the tilt is compared at every thermo row, the positions at every dump frame
    assert by["thermo xy"].passed and "bitwise equal: True" in by["thermo xy"].detail
    assert by["dump d x"].value <= 1e-10 and by["dump d vx"].value <= 1e-8
    assert all(by[f"thermo c_p[{k}] (pressure, virial)"].value <= 1e-8 for k in (1, 2, 4))
    with h5py.File(tmp_path / "out" / "replay.h5") as f:
        xy = f["native/xy"][()]
        lo = f["native/box_lo"][()]
    # the box origin is away from zero and the cell really shears (xy erate 50 1/s over 600 steps of
    # 1e-6 s of Ly = 0.0069282 m: 2.078e-4 m; xy final from 2e-4 m to -1e-4 m; trate 400 1/s over
    # 500e-6 s from 2e-4 m; vel 0.35 m/s over 450e-6 s), changing on the multiples of N only
    assert lo[0, 0] == 0.25 and lo[0, 1] == -0.0417
    want = {
        "d": (0.0, 600e-6 * 50.0 * (-0.0347718 + 0.0417), 1),
        "e": (2e-4, -1e-4, 1),
        "f": (2e-4, 2e-4 * np.exp(400.0 * 500e-6), 2),
        "g": (0.0, 0.35 * 450e-6, 3),
    }[name]
    assert xy[0] == want[0] and abs(xy[-1] - want[1]) < 1e-15
    changed = np.flatnonzero(np.diff(xy) != 0) + 1
    assert np.array_equal(changed, np.arange(want[2], len(xy), want[2]))


@pytest.mark.parametrize("name", ["f", "g"])
def test_fix_deform_n_matters(name):
    # the same deck run natively with the box changed every step instead of every N: the pressure
    # is then far from LAMMPS' (so the stored comparison above does test N and h_rate)
    import dataclasses

    from reference_runs.parsers import parse_log
    from reference_runs.replay.drive import run_native

    deck = read_deck(DATA / f"in.deck_{name}")
    ref = parse_log(DATA / f"ref_{name}" / "log.lammps").runs[-1].column("c_p[4]")
    good = run_native(deck).pressure[:, 3]
    bad = run_native(dataclasses.replace(deck, shear=dataclasses.replace(deck.shear, every=1))).pressure[:, 3]
    scale = np.abs(ref).max()
    assert np.abs(good - ref).max() / scale < 1e-12
    assert np.abs(bad - ref).max() / scale > 1e-6


def _cut(tmp_path, name, what):
    ref = tmp_path / "ref"
    shutil.copytree(DATA / f"ref_{name}", ref)
    if what == "dump":
        p = ref / DECKS[name]
        t = p.read_text()
        p.write_text(t[: t.rfind("ITEM: TIMESTEP")])
    else:  # the log cut in the middle of the run
        p = ref / "log.lammps"
        lines = p.read_text().splitlines(keepends=True)
        k = next(i for i, ln in enumerate(lines) if ln.split()[:1] == ["300"])
        p.write_text("".join(lines[:k]))
    return ref


@pytest.mark.parametrize(
    "what,needle", [("dump", "incomplete: frames missing"), ("log", "incomplete: thermo rows missing")]
)
def test_truncated_reference_fails(tmp_path, what, needle):
    res = replay(DATA / "in.deck_d", outdir=tmp_path / "out", reference=_cut(tmp_path, "d", what))
    assert not res.passed
    assert any(needle in c.metric for c in res.checks if not c.passed)


def _deck(tmp_path, old, new, base="in.deck_d", data=None):
    text = (DATA / base).read_text()
    assert old in text
    p = tmp_path / base
    p.write_text(text.replace(old, new))
    for f in ("disks_a.data", "disks_b.data", "disks_e.data"):
        shutil.copyfile(DATA / f, tmp_path / f)
    if data:
        (tmp_path / data[0]).write_text((DATA / data[0]).read_text().replace(data[1], data[2]))
    return p


DEFORM = "fix 3 all deform 1 xy erate 50.0 remap v"


@pytest.mark.parametrize(
    "new,needle",
    [
        ("fix 3 all deform 1 xy trate 50.0 remap v", "xy trate on a box without tilt"),
        ("fix 3 all deform 1 xy erate 50.0 remap x", "remap x: ShearEngine runs the Lees-Edwards"),
        ("fix 3 all deform 1 x erate 1.0 xy erate 50.0 remap v", "fix deform x erate on a sheared"),
        ("fix 3 all deform 1 y vel 0.01 remap v", "fix deform y vel on a sheared"),
        ("fix 3 all deform 1 xy erate 2000.0 remap v", "beyond Lx/2"),
        ("fix 3 all deform 1 xy wiggle 1e-4 1e-3 remap v", "xy wiggle: not in the subset"),
        ("fix 3 all deform 1 xz erate 1.0 remap v", "no xz tilt"),
    ],
)
def test_what_shear_engine_cannot_express_is_refused_naming_the_line(tmp_path, new, needle):
    p = _deck(tmp_path, DEFORM, new)
    lineno = p.read_text().splitlines().index(new) + 1
    with pytest.raises(InputError) as e:
        read_deck(p)
    assert f"{p}:{lineno}:" in str(e.value) and needle in str(e.value)


def test_tilt_without_triclinic_box_and_remap_v_on_orthogonal_box(tmp_path):
    p = _deck(tmp_path, "change_box all triclinic\n", "")
    with pytest.raises(InputError, match=r"in.deck_d:\d+: fix deform xy needs a triclinic box"):
        read_deck(p)
    p = _deck(tmp_path, "change_box all triclinic\n" + "", "", base="in.deck_d")
    p.write_text(p.read_text().replace(DEFORM, "fix 3 all deform 1 x erate 1.0 remap v"))
    with pytest.raises(InputError, match="remap v on an orthogonal box"):
        read_deck(p)


def test_liggghts_deck_with_a_tilt_is_refused_with_the_reason(tmp_path):
    p = _deck(tmp_path, "x erate -5.0 y trate 3.0 remap x", "xy erate 1.0 remap v", base="in.deck_a")
    lineno = next(k for k, ln in enumerate(p.read_text().splitlines(), 1) if "xy erate 1.0" in ln)
    with pytest.raises(InputError) as e:
        read_deck(p)
    assert f":{lineno}:" in str(e.value) and "loses the periodic ghosts" in str(e.value)
    # a tilted data file under a LIGGGHTS deck: the data file is named
    p = _deck(
        tmp_path,
        "x erate -5.0",
        "x erate -5.0",
        base="in.deck_a",
        data=("disks_a.data", "zlo zhi\n", "zlo zhi\n1e-4 0 0 xy xz yz\n"),
    )
    with pytest.raises(InputError) as e:
        read_deck(p)
    assert "disks_a.data" in str(e.value) and "LIGGGHTS 3.8.0's triclinic box" in str(e.value)


def test_triclinic_data_file_errors(tmp_path):
    p = _deck(tmp_path, "disks_b.data", "disks_e.data", data=("disks_e.data", "0.0002 0 0 xy", "0.0002 1e-4 0 xy"))
    with pytest.raises(InputError, match=r"disks_e.data:\d+: xz = 1e-4, yz = 0"):
        read_deck(p)
    p = _deck(tmp_path, "disks_b.data", "disks_e.data", data=("disks_e.data", "0.0002 0 0 xy", "0.0039 0 0 xy"))
    with pytest.raises(InputError, match="outside the tilted box"):
        read_deck(p)


def test_styles_and_n_pass_to_the_engine_as_written(tmp_path):
    # no erate search any more: the deck's style, number and N reach ShearLoading unchanged
    d = read_deck(DATA / "in.deck_e")
    assert d.sheared and d.tilt == 2e-4 and d.packing.cell[0, 1] == 2e-4
    assert (d.shear.xy, d.shear.value, d.shear.every, d.shear.erate) == ("final", -1e-4, 1, 0.0)
    p = _deck(tmp_path, DEFORM, "fix 3 all deform 3 xy erate 50.0 remap v")
    d = read_deck(p)
    assert (d.shear.xy, d.shear.value, d.shear.every) == ("erate", 50.0, 3)


@pytest.mark.lammps
@pytest.mark.parametrize("name", sorted(DECKS))
def test_sheared_replay_agrees_with_live_lammps(tmp_path, name):
    work = tmp_path / "deck"
    work.mkdir()
    for f in (f"in.deck_{name}", "disks_b.data", "disks_e.data"):
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
    from reference_runs.parsers import parse_log

    live = parse_log(tmp_path / "out" / "job" / "log.lammps").runs[-1]
    stored = parse_log(DATA / f"ref_{name}" / "log.lammps").runs[-1]
    assert np.array_equal(live.data, stored.data)
