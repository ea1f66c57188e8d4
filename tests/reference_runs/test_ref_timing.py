"""reference_runs.timing: the loop-time summaries of real LIGGGHTS 3.8.0 logs (tests/reference_runs/data,
README there: a 110-disk deck of reference_runs.decks.biaxial, runs of 200 and 100 steps, 1 and 2 MPI
processes)."""

from pathlib import Path

import pytest

from gransim.errors import ResultFileError
from reference_runs.timing import parse_loop_timings

DATA = Path(__file__).resolve().parent / "data"
PARTS = ("Pair", "Neigh", "Comm", "Outpt", "Other")


@pytest.mark.parametrize("procs", [1, 2])
def test_runs_procs_steps_atoms(procs):
    runs = parse_loop_timings(DATA / f"liggghts_timing_np{procs}.log")
    assert [(t.procs, t.steps, t.atoms) for t in runs] == [(procs, 200, 110), (procs, 100, 110)]
    for t in runs:
        assert t.loop_s > 0
        assert t.particle_steps_per_s == pytest.approx(110 * t.steps / t.loop_s)
        assert t.dangerous_builds == 0


@pytest.mark.parametrize("procs", [1, 2])
def test_breakdown_adds_up_to_the_loop_time(procs):
    # LIGGGHTS prints Other = loop - the named parts, and percent = 100 time / loop, each at 6
    # significant digits: the parsed seconds must add up to the loop time and match their percents
    for t in parse_loop_timings(DATA / f"liggghts_timing_np{procs}.log"):
        assert tuple(t.breakdown) == PARTS
        assert sum(s for s, _ in t.breakdown.values()) == pytest.approx(t.loop_s, rel=2e-5)
        for name, (sec, pct) in t.breakdown.items():
            assert 100 * sec / t.loop_s == pytest.approx(pct, rel=1e-4, abs=1e-6)
            assert t.fraction(name) == pytest.approx(pct / 100, rel=1e-4, abs=1e-8)


def test_memory_estimate_belongs_to_its_run():
    text = (DATA / "liggghts_timing_np1.log").read_text()
    mems = [float(ln.split("=")[1].split()[0]) for ln in text.splitlines() if ln.startswith("Memory usage")]
    assert [t.memory_mb for t in parse_loop_timings(text)] == mems
    # a run whose set-up printed no memory line gets None, not the previous run's figure
    second = text.index("run 100")
    cut = text[:second] + "\n".join(ln for ln in text[second:].splitlines() if not ln.startswith("Memory"))
    assert [t.memory_mb for t in parse_loop_timings(cut)] == [mems[0], None]


def test_neighbour_builds_match_the_native_engine():
    # independent implementation: gransim.dem follows LIGGGHTS' rebuild rule (docs/liggghts.md), so over the
    # first run it rebuilds as often as LIGGGHTS reports (its own count includes the set-up build, which
    # LIGGGHTS leaves out)
    from bench.dem import LOADING, SETTINGS, assembly
    from gransim.dem import DEMEngine

    runs = parse_loop_timings(DATA / "liggghts_timing_np1.log")
    eng = DEMEngine(assembly(100), SETTINGS)
    eng.advance(LOADING, runs[0].steps)
    assert runs[0].neighbour_builds == eng.n_rebuilds - 1


def test_incomplete_run_and_bad_numbers():
    text = (DATA / "liggghts_timing_np2.log").read_text()
    last = text.rindex("Loop time of")
    assert len(parse_loop_timings(text[:last])) == 1  # the second run never finished
    assert parse_loop_timings("LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0)\nrun 10\n") == ()
    bad = text.replace("Pair  time (%) = ", "Pair  time (%) = x", 1)
    with pytest.raises(ResultFileError, match="line .*time 'x"):
        parse_loop_timings(bad)
