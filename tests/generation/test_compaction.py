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
from gransim.generation import compact_packing, make_packing

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


def test_kuhn_assembly_has_the_paper_void_ratio_and_is_in_balance():
    """The standard ``kuhn-1002`` assembly against Kuhn, "Deformation measures for granular
    materials" (section 4: 1002 disks, void ratio 0.189), checked from its positions and radii:

    * the void ratio e = (A - sum pi r^2) / sum pi r^2 within 0.008 of 0.189 (seeds 1-4 of the
      request give 0.189-0.196, docs/generation.md);
    * the isotropic stress p = sum_c |l_c| kn eps_c / (2 A) equals the servo target (the trace of
      the Love stress has no tangential part);
    * force balance with Coulomb friction: the net *normal* force on a disk can only be held by
      tangential forces of at most mu fn each, so |sum_c fn_c n_c| <= mu sum_c fn_c + |F_net|; the
      excess over the Coulomb capacity, averaged over the disks in contact, must be below the
      quasi-static criterion (1e-3 of the mean contact force). A state still moving (or one
      made with another friction) carries net normal forces of the order of the contact force.
    """
    from gransim.generation import STANDARD_PACKINGS, build_standard

    req = STANDARD_PACKINGS["kuhn-1002"]
    assert req["protocol"] == "compaction" and req["n"] == 1002
    p = build_standard("kuhn-1002")
    solid = np.pi * np.sum(p.radii**2)
    area = abs(np.linalg.det(p.cell))
    assert (area - solid) / solid == pytest.approx(0.189, abs=0.008)

    kn = p.metadata["dem"]["kn"]
    mu = req["friction"]
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    fn = kn * eps[c]
    n = nl.branch[c] / nl.distance[c, None]
    assert np.sum(nl.distance[c] * fn) / (2.0 * area) == pytest.approx(req["pressure"] * kn, rel=0.015)
    F = np.zeros((p.n, 2))
    np.add.at(F, nl.i[c], -fn[:, None] * n)
    np.add.at(F, nl.j[c], fn[:, None] * n)
    cap = np.zeros(p.n)
    np.add.at(cap, nl.i[c], mu * fn)
    np.add.at(cap, nl.j[c], mu * fn)
    touching = cap > 0
    excess = np.maximum(np.linalg.norm(F, axis=1) - cap, 0.0)[touching]
    assert excess.mean() <= 1e-3 * fn.mean()
    # the tangential forces do work: without them the normal forces alone are far from balance
    assert np.linalg.norm(F, axis=1)[touching].mean() > 5e-3 * fn.mean()


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"friction": -0.1}, "friction"),
        ({"friction": 0.1, "phi_gas": 0.85}, "phi_gas"),
        ({"friction": 0.1, "pressure": 0.1}, "pressure"),
        ({"friction": 0.1, "check_every": 0}, "check_every"),
    ],
)
def test_compaction_bad_input(kw, match):
    with pytest.raises(InputError, match=match):
        compact_packing("kuhn-1002", 50, seed=1, **kw)


def test_dem_settings_for_packing_are_stable_and_damped_as_asked():
    """DEMSettings.for_packing (what the compaction uses): the time step is within the engine's
    stability limit of the lightest pair (derived independently in gransim.dem.engine), 50 steps
    resolve an undamped contact of the lightest pair, and the median pair has the damping ratio
    asked for: gamma / (2 omega) with omega = sqrt(kn / m_eff)."""
    from gransim.dem import DEMSettings, stability_limit

    p = make_packing("kuhn-1002", 60, seed=2)
    s = DEMSettings.for_packing(p, 2e5, mu=0.05, damping_ratio=0.3)
    assert s.kt == s.kn == 2e5 and s.mu == 0.05 and s.skin == pytest.approx(0.05 * p.d50)
    assert s.dt <= stability_limit(p, s)
    m = np.sort(p.masses)
    t_c = np.pi * np.sqrt(m[0] * m[1] / (m[0] + m[1]) / 2e5)  # half period of the lightest pair
    assert s.dt * 50 == pytest.approx(t_c, rel=1e-12)
    m_med = np.median(p.masses)
    assert s.gamma_n / (2 * np.sqrt(2e5 / (m_med / 2))) == pytest.approx(0.3, rel=1e-12)
    with pytest.raises(InputError, match="packing: expected a gransim.Packing"):
        DEMSettings.for_packing("kuhn.h5", 1e5)
    with pytest.raises(InputError, match="kn"):
        DEMSettings.for_packing(p, -1.0)
