"""Frictional DEM compaction (gransim.generation.compact_packing): the target stress is carried, the
assembly is quasi-static, friction makes it looser, same sizes as make_packing, bad input.

The pressure check is independent of the engine: the trace of the Love stress involves only the
normal contact forces (a tangential force is orthogonal to its branch vector), so
p = sum_c |l_c| kn eps_c / (2 A) over the brute-force O(N^2) contacts must equal the servo target.
"""

import numpy as np
import pytest

from gransim.contacts import find_neighbours_bruteforce
from gransim.errors import InputError
from gransim.generation import compact_packing, get_distribution, make_packing

N = 150
KN = 1e5


@pytest.fixture(scope="module")
def pair():
    return {mu: compact_packing("kuhn-1002", N, seed=3, friction=mu, kn=KN) for mu in (0.0, 0.5)}


def mean_normal_pressure(p) -> float:
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    return float(np.sum(nl.distance[c] * KN * eps[c]) / (2.0 * p.area))


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_compaction_carries_the_servo_pressure_and_is_quasi_static(pair, mu):
    p = pair[mu]
    m = p.metadata
    target = m["pressure_over_kn"] * KN
    assert mean_normal_pressure(p) == pytest.approx(target, rel=0.015)
    assert m["unbalanced_force_ratio"] <= 1e-3
    assert np.all((p.positions >= 0) & (p.positions < np.diag(p.cell)))
    # small overlaps: mean contact force ~ p D50 / 2 over kn
    assert 0.2e-4 < m["mean_overlap_d50"] < 2e-4


def test_friction_makes_the_assembly_looser_and_less_connected(pair):
    loose, dense = pair[0.5].metadata, pair[0.0].metadata
    assert loose["void_ratio"] > dense["void_ratio"] + 0.02
    assert loose["coordination"] < dense["coordination"] - 0.3


def test_compaction_draws_the_sizes_of_make_packing_and_is_deterministic(pair):
    fire = make_packing("kuhn-1002", N, seed=3)
    assert np.array_equal(np.sort(pair[0.0].radii), np.sort(fire.radii))
    again = compact_packing("kuhn-1002", N, seed=3, friction=0.0, kn=KN)
    assert np.array_equal(again.positions, pair[0.0].positions)
    assert np.array_equal(again.cell, pair[0.0].cell)


def test_compaction_replays_from_its_metadata(pair):
    """compaction_run rebuilds the gas, settings and step count from the file's metadata: one
    uninterrupted engine run of that many steps ends exactly on the saved packing (what the
    validation case replays in LIGGGHTS)."""
    from gransim.dem import DEMEngine
    from gransim.generation import compaction_run

    p = pair[0.5]
    gas, dem, loading, nsteps = compaction_run(p)
    eng = DEMEngine(gas, dem)
    eng.advance(loading, nsteps, phase_step0=0, phase_box0=(eng.lo.copy(), eng.hi.copy()))
    L = eng.box_lengths
    assert np.array_equal(np.diag(p.cell), L)
    d = (eng.x - eng.lo) - p.positions
    d -= np.round(d / L) * L
    assert np.abs(d).max() <= 4 * np.spacing(L.max())  # the same run; only Packing.wrapped() rounds
    with pytest.raises(InputError, match="not made by compact_packing"):
        compaction_run(make_packing("quartz-sand", 30, seed=1))


def test_kuhn_request_is_frictional_compaction_near_the_paper_void_ratio():
    from gransim.generation.pack import STANDARD_PACKINGS

    req = STANDARD_PACKINGS["kuhn-1002"]
    assert req["protocol"] == "compaction" and req["n"] == 1002
    assert get_distribution(req["distribution"]).cu == pytest.approx(1.7, abs=0.02)


@pytest.mark.parametrize("kw, match", [
    ({"friction": -0.1}, "friction"),
    ({"friction": 0.1, "phi_gas": 0.85}, "phi_gas"),
    ({"friction": 0.1, "pressure": 0.1}, "pressure"),
    ({"friction": 0.1, "check_every": 0}, "check_every"),
])
def test_compaction_bad_input(kw, match):
    with pytest.raises(InputError, match=match):
        compact_packing("kuhn-1002", 50, seed=1, **kw)
