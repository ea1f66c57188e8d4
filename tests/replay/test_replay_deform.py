"""fix deform box arithmetic (reference_runs/replay/deform.py) bit for bit against each code.

Tiny decks (tests/replay/replay_support.py: 3 disks far apart, box origin away from zero) print
lx xlo xhi ly ylo yhi at %.17g every step, for every style and several N. The logs of the
Debian binaries are stored in data/deform (README there); the live tests rerun the binaries.
"""

import subprocess

import numpy as np
import pytest
from replay_support import BINARIES, CASES, DATA, need_binary, write

from reference_runs.parsers import parse_log
from reference_runs.replay.deck import read_deck
from reference_runs.replay.deform import AxisDeform, DeformSpec, box_table

PARAMS = [(e, c) for e in ("liggghts", "lammps") for c in CASES]


def _check(log_path, deck_path):
    deck = read_deck(deck_path)
    lo, hi = box_table(deck.deform, deck.box_lo, deck.box_hi, deck.settings.dt, deck.nsteps, deck.engine)
    run = parse_log(log_path).runs[-1]
    steps = run.steps
    assert steps.tolist() == list(range(deck.nsteps + 1))
    for name, arr in (
        ("xlo", lo[:, 0]),
        ("xhi", hi[:, 0]),
        ("ylo", lo[:, 1]),
        ("yhi", hi[:, 1]),
        ("lx", hi[:, 0] - lo[:, 0]),
        ("ly", hi[:, 1] - lo[:, 1]),
    ):
        col = run.column(name)
        bad = np.flatnonzero(col != arr)
        assert bad.size == 0, f"{name} differs first at step {steps[bad[0]]}: {col[bad[0]]!r} vs {arr[bad[0]]!r}"
    # the box really moves, and only on the fix's steps
    every = deck.deform.every
    moved = np.flatnonzero(np.any(np.diff(lo, axis=0) != 0, axis=1)) + 1
    assert moved.size > 0 and np.all(moved % every == 0)


@pytest.mark.parametrize("engine,case", PARAMS)
def test_box_table_matches_stored_log(tmp_path, engine, case):
    deck = write(tmp_path, engine, case)
    _check(DATA / "deform" / f"{engine}-{case}.log", deck)


@pytest.mark.parametrize("engine,case", [pytest.param(e, c, marks=getattr(pytest.mark, e)) for e, c in PARAMS])
def test_box_table_matches_live_code(tmp_path, engine, case):
    need_binary(engine)
    deck = write(tmp_path, engine, case)
    r = subprocess.run(
        [BINARIES[engine], "-in", deck.name, "-log", "log.out", "-screen", "none", "-nocite"],
        cwd=tmp_path,
        timeout=60,
        check=False,
    )
    assert r.returncode == 0
    _check(tmp_path / "log.out", deck)


def test_trate_uses_scalar_exp_and_erate_the_stop_interpolation():
    """Hand arithmetic of one step (independent of the stored logs)."""
    import math

    lo0, hi0 = np.array([-1.0, 2.0]), np.array([3.0, 2.5])
    spec = DeformSpec(1, (AxisDeform("erate", (0.1,)), AxisDeform("trate", (0.2,))))
    lo, hi = box_table(spec, lo0, hi0, 0.01, 10)
    # erate: lo_stop = -1 - 0.5*0.1*0.1*4 = -1.02, half way at step 5
    assert lo[5, 0] == -1.0 + 0.5 * (-1.02 - -1.0)
    e = math.exp(0.2 * (5 * 0.01))
    assert hi[5, 1] == 0.5 * (2.0 + 2.5) + 0.5 * (0.5 * e)
    # fixed box without a spec; a collapsing erate is refused
    lo2, hi2 = box_table(None, lo0, hi0, 0.01, 3)
    assert np.all(lo2 == lo0) and np.all(hi2 == hi0)
    from gransim.errors import InputError

    with pytest.raises(InputError, match="final box dimension"):
        box_table(DeformSpec(1, (AxisDeform("erate", (-200.0,)), None)), lo0, hi0, 0.01, 10)
