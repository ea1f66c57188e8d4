"""Every ``fix deform N xy`` style through the sheared-cell engine, bit for bit in the tilt LAMMPS prints.

Tiny LAMMPS decks (tests/replay/replay_support.py: 3 disks far apart in a tilted box whose origin is
away from zero, ``remap v``) print lx ly xy xlo xhi ylo yhi at %.17g every step, for xy erate,
trate, vel, final and delta with N = 1 and N > 1. The logs of the Debian binary (LAMMPS 29 Sep 2021
- Update 2) are stored in data/deform/lammps-xy-*.log (README there); the live test reruns ``lmp``.
The native side is the replay driver (``ShearEngine(box=(lo, hi, xy))`` and ``ShearLoading(xy=style,
value=..., every=N)``), so this checks the engine's own tilt arithmetic, not a table.
"""

import math
import subprocess

import numpy as np
import pytest
from replay_support import DATA, TILT_CASES, need_binary, write_tilt

from reference_runs.parsers import parse_log
from reference_runs.replay.deck import read_deck
from reference_runs.replay.drive import run_native


def _check(log_path, deck_path):
    deck = read_deck(deck_path)
    nat = run_native(deck)
    run = parse_log(log_path).runs[-1]
    assert run.steps.tolist() == list(range(deck.nsteps + 1))
    for name, arr in (
        ("xy", nat.xy),
        ("xlo", nat.lo[:, 0]),
        ("xhi", nat.hi[:, 0]),
        ("ylo", nat.lo[:, 1]),
        ("yhi", nat.hi[:, 1]),
        ("lx", nat.hi[:, 0] - nat.lo[:, 0]),
        ("ly", nat.hi[:, 1] - nat.lo[:, 1]),
    ):
        col = run.column(name)
        bad = np.flatnonzero(col != arr)
        assert bad.size == 0, f"{name} differs first at step {bad[0]}: {col[bad[0]]!r} vs {arr[bad[0]]!r}"
    # the tilt really moves, and only on the steps that are multiples of N
    every = deck.deform.every
    moved = np.flatnonzero(np.diff(nat.xy) != 0) + 1
    assert moved.size >= deck.nsteps // every - 1 and np.all(moved % every == 0)
    return deck, nat


@pytest.mark.parametrize("case", sorted(TILT_CASES))
def test_tilt_matches_stored_lammps_log(tmp_path, case):
    _check(DATA / "deform" / f"lammps-xy-{case}.log", write_tilt(tmp_path, case))


@pytest.mark.lammps
@pytest.mark.parametrize("case", sorted(TILT_CASES))
def test_tilt_matches_live_lammps(tmp_path, case):
    need_binary("lammps")
    deck = write_tilt(tmp_path, case)
    r = subprocess.run(
        ["lmp", "-in", deck.name, "-log", "log.out", "-screen", "none", "-nocite"],
        cwd=tmp_path,
        timeout=60,
        check=False,
    )
    assert r.returncode == 0
    _check(tmp_path / "log.out", deck)


def test_trate_and_final_by_hand(tmp_path):
    """Independent of the logs: the end tilt of trate is xy0 exp(R t) and that of final its value
    (to the last bits LAMMPS' wrap may change), and N > 1 holds the tilt between the changes."""
    _, nat = _check(DATA / "deform" / "lammps-xy-trate-4.log", write_tilt(tmp_path, "trate-4"))
    assert nat.xy[40] == pytest.approx(0.003 * math.exp(-7.5 * 40 * 1e-5), rel=1e-15, abs=0)
    assert nat.xy[41] == nat.xy[40] and nat.xy[3] == 0.003 and nat.xy[4] < 0.003
    _, nat = _check(DATA / "deform" / "lammps-xy-final-5.log", write_tilt(tmp_path, "final-5"))
    assert abs(nat.xy[-1] - -0.004) <= np.spacing(0.05)  # the wrap adds and subtracts Lx = 0.05 m
    assert nat.xy[20] == pytest.approx(0.003 + 0.5 * (-0.004 - 0.003), rel=1e-14)
