"""Packing generation: jammed periodic packings, force balance, targets, statistics, errors.

Independent checks use the brute-force O(N^2) periodic search (find_neighbours_bruteforce) and plain
numpy force sums, not the generator's kernels.
"""

import dataclasses

import numpy as np
import pytest

from gransim import Packing
from gransim.contacts import find_neighbours_bruteforce
from gransim.errors import ConvergenceError, InputError
from gransim.generation import (
    get_distribution,
    make_packing,
    packing_stats,
    rattlers,
    standard_packings,
)
from gransim.generation.fire import FireParameters, Minimiser
from gransim.generation.front import FRONT_PHI, front_packing
from gransim.generation.pack import DEFAULT_MEAN_OVERLAP
from gransim.generation.standard import STANDARD_PACKINGS

N = 120  # small: a few hundred ms per packing after compilation


@pytest.fixture(scope="module")
def dense():
    return make_packing("quartz-sand", N, seed=4)


def contact_forces(p):
    """Net contact force on every disk (k_n = 1 per unit overlap, eq 5) and the contact forces."""
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    n = nl.branch / nl.distance[:, None]
    F = np.zeros((p.n, 2))
    np.add.at(F, nl.i, -eps[:, None] * n)
    np.add.at(F, nl.j, eps[:, None] * n)
    return F, eps, nl


def test_dense_packing_reaches_the_overlap_target_and_is_periodic(dense):
    p = dense
    assert isinstance(p, Packing) and p.n == N
    _, eps, nl = contact_forces(p)
    dmean = 2 * p.radii.mean()
    # the target mean overlap (relative to the mean diameter) within the 2 % tolerance
    assert eps.mean() / dmean == pytest.approx(DEFAULT_MEAN_OVERLAP, rel=0.021)
    # periodicity: the brute-force search over all images finds no overlap beyond the stated max,
    # and contacts do cross the cell boundary (shift != 0)
    assert eps.max() / p.d50 == pytest.approx(p.metadata["max_overlap_d50"], rel=1e-9)
    assert eps.max() < 10 * eps.mean()
    assert np.any(nl.shift != 0)
    # a dense state: Kuhn's and Meier's 2D assemblies are at phi ~ 0.84-0.85
    assert 0.82 < p.solid_fraction < 0.87
    frac = np.linalg.solve(p.cell, p.positions.T).T
    assert np.all((frac >= 0) & (frac < 1))  # centres wrapped into the primary cell
    s = packing_stats(p)
    assert s["n_contacts"] == eps.size
    assert 3.3 < s["coordination"] < 4.2
    # isostatic jamming: non-rattlers have ~ 2 d = 4 contacts (+ O(sqrt(p)) and finite-size excess)
    assert 3.9 < s["coordination_nonrattler"] < 4.4


def test_fire_reaches_force_balance(dense):
    F, eps, _ = contact_forces(dense)
    fmean = eps.mean()  # k_n = 1: contact force = overlap
    # the stopping criterion (max residual <= 1e-3 mean contact force), checked independently
    assert np.max(np.linalg.norm(F, axis=1)) <= 1.001e-3 * fmean
    assert np.allclose(F.sum(axis=0), 0.0, atol=1e-12 * fmean * dense.n)


def test_rms_residual_option_is_checked_independently():
    p = make_packing("quartz-sand", 400, seed=2, force_tol=1e-3, residual="rms")
    F, eps, _ = contact_forces(p)
    rms = np.sqrt(np.mean(np.sum(F**2, axis=1)))
    assert rms <= 1.001e-3 * eps.mean()
    assert p.metadata["residual_norm"] == "rms" and p.metadata["decompression_stages"] >= 1
    # the stage ladder starts near the quenched state's pressure: a few stages of factor 3
    assert p.metadata["decompression_stages"] <= 8
    with pytest.raises(InputError, match="residual"):
        make_packing("quartz-sand", 50, seed=1, residual="mean")


def test_pressure_is_isotropic_on_average(dense):
    # the cell is compressed isotropically: virial stress sigma = 1/A sum f (x) l has
    # sigma_xx ~ sigma_yy up to the finite-size fluctuation of a 120-disk network
    _, eps, nl = contact_forces(dense)
    n = nl.branch / nl.distance[:, None]
    sig = np.einsum("c,ci,cj->ij", eps, n, nl.branch) / dense.area
    assert abs(sig[0, 1] - sig[1, 0]) < 1e-12 * np.trace(sig)
    assert abs(sig[0, 0] - sig[1, 1]) < 0.25 * np.trace(sig)


def test_solid_fraction_target_is_met_exactly_with_force_balance(dense):
    phi_j = dense.metadata["phi_jamming"]
    target = round(phi_j + 0.01, 4)
    p = make_packing("quartz-sand", N, seed=4, solid_fraction=target)
    assert p.solid_fraction == pytest.approx(target, rel=1e-12)
    F, eps, _ = contact_forces(p)
    assert np.max(np.linalg.norm(F, axis=1)) <= 1.001e-3 * eps.mean()
    # compressed past jamming: overlaps grow by about (phi - phi_J) / phi of a diameter
    assert eps.mean() / (2 * p.radii.mean()) > 10 * DEFAULT_MEAN_OVERLAP


def test_packing_is_deterministic_for_a_seed():
    a = make_packing("kuhn-1002", 40, seed=2)
    b = make_packing("kuhn-1002", 40, seed=2)
    c = make_packing("kuhn-1002", 40, seed=3)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.cell, b.cell)
    assert not np.array_equal(np.sort(a.radii), np.sort(c.radii))


def test_sizes_follow_the_distribution_and_scaling():
    g = get_distribution("kuhn-1002")
    p = make_packing(g, 60, seed=1, mean_diameter=2e-3, density=1000.0)
    d = 2 * p.radii
    assert d.min() >= 0.45 * g.d50 * 2e-3 / g.mean_diameter * (1 - 1e-12)
    assert d.mean() == pytest.approx(2e-3, rel=0.02)  # the stratified sample mean of 60 grains
    assert p.density == 1000.0 and p.metadata["distribution"] == "kuhn-1002"


def test_packing_stats_exact_square_lattice():
    # 2 x 2 square lattice, spacing 1, radius 0.5 + delta: 4 contacts per disk, overlap 2 delta
    delta = 1e-3
    x = np.array([[0.5, 0.5], [1.5, 0.5], [0.5, 1.5], [1.5, 1.5]])
    p = Packing(x, np.full(4, 0.5 + delta), 2 * np.eye(2))
    s = packing_stats(p)
    assert s["n_contacts"] == 8 and s["coordination"] == 4.0 and s["n_rattlers"] == 0
    assert s["mean_overlap"] == pytest.approx(2 * delta) and s["max_overlap"] == pytest.approx(2 * delta)
    assert s["solid_fraction"] == pytest.approx(np.pi * (0.5 + delta) ** 2)
    assert s["void_ratio"] == pytest.approx((1 - s["solid_fraction"]) / s["solid_fraction"])
    assert s["fabric_anisotropy"] == pytest.approx(0.0, abs=1e-12)
    # a small disk in the hole touching only one neighbour is a rattler
    # (distance 0.566 to the disk at (0.5, 0.5) < 0.651; 0.721 to the next ones)
    q = Packing(np.vstack([x, [[0.9, 0.9]]]), np.r_[np.full(4, 0.5 + delta), 0.15], 2 * np.eye(2))
    sq = packing_stats(q)
    assert sq["n_contacts"] == 9 and sq["coordination"] == pytest.approx(18 / 5)
    assert sq["n_rattlers"] == 1 and sq["coordination_nonrattler"] == 4.0


def test_rattler_removal_is_iterative():
    # core: the complete graph on 0-3 (3 contacts each). Disks 4 and 6 have 2 contacts; once they
    # go, 5 and 7 drop below 3 as well (second round); the core keeps its 3 contacts each.
    edges = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (4, 5), (5, 6), (0, 6), (4, 7), (5, 7), (3, 7)]
    i, j = np.array(edges).T
    rat = rattlers(8, i, j, min_contacts=3)
    assert rat.tolist() == [False] * 4 + [True] * 4


def test_errors():
    with pytest.raises(InputError, match="unknown distribution 'basalt'.*quartz-sand"):
        make_packing("basalt", 50, 1)
    with pytest.raises(InputError, match="n: expected an integer >= 2"):
        make_packing("quartz-sand", 1, 1)
    with pytest.raises(InputError, match="unreachable"):
        make_packing("quartz-sand", 50, 1, solid_fraction=0.96)
    with pytest.raises(InputError, match="solid_fraction"):
        make_packing("quartz-sand", 50, 1, solid_fraction=0.0)
    with pytest.raises(InputError, match="mean_overlap"):
        make_packing("quartz-sand", 50, 1, mean_overlap=-1e-4)
    with pytest.raises(InputError, match="not both"):
        make_packing("quartz-sand", 50, 1, solid_fraction=0.85, mean_overlap=1e-4)
    with pytest.raises(InputError, match="seed"):
        make_packing("quartz-sand", 50, -1)
    # below the jamming fraction: no contact network; the message names the reached phi_J
    with pytest.raises(ConvergenceError, match=r"below the jamming fraction phi_J = 0\.8"):
        make_packing("quartz-sand", 50, 1, solid_fraction=0.5)
    # not reached within the step budget: the message names the reached state
    with pytest.raises(ConvergenceError, match=r"reached phi = 0\.\d+, mean overlap"):
        make_packing("quartz-sand", 50, 1, max_steps=20)


def test_shipped_standard_packings_are_what_the_generator_makes(tmp_path):
    """The shipped copies (gransim/generation/data/standard) are a cache of the generator, not data of
    their own: a regenerated RVE and the shipped file agree bit for bit, in every array."""
    from gransim.generation import SHIPPED_DIR, build_standard, shipped_packing
    from gransim.io import load_packing, read_provenance

    assert sorted(p.stem for p in SHIPPED_DIR.glob("*.h5")) == sorted(STANDARD_PACKINGS)
    for name in ("rve-70-1", "rve-350-3"):
        src = shipped_packing(name)
        assert src is not None, f"{name}: no shipped copy of this generator version"
        prov = read_provenance(src)
        assert prov["parameters"]["name"] == name and prov["gransim_version"]
        shipped, fresh = load_packing(src), build_standard(name)
        for field in ("positions", "radii", "cell"):
            assert np.array_equal(getattr(shipped, field), getattr(fresh, field)), (name, field)


def test_outdated_or_foreign_shipped_copy_is_regenerated(tmp_path, monkeypatch):
    """A shipped file whose provenance does not match the request (another generator version, or not
    a packing file at all) is never copied: the packing is generated instead."""
    import gransim.generation.standard as standard
    from gransim.io import load_packing, save_packing

    fake = tmp_path / "shipped"
    fake.mkdir()
    real = load_packing(standard.shipped_packing("rve-70-4"))
    moved = dataclasses.replace(real, positions=real.positions + 1e-3 * real.cell[0, 0])
    params = {**standard._request("rve-70-4"), "generator_version": standard.GENERATOR_VERSION - 1}
    save_packing(fake / "rve-70-4.h5", moved, parameters=params, seed=4)
    (fake / "rve-70-5.h5").write_bytes(b"not an HDF5 file")
    monkeypatch.setattr(standard, "SHIPPED_DIR", fake)
    assert standard.shipped_packing("rve-70-4") is None and standard.shipped_packing("rve-70-5") is None
    out = standard_packings(tmp_path / "out", names=["rve-70-4"])
    assert np.array_equal(load_packing(out["rve-70-4"]).positions, real.positions)


def test_standard_packings_set_and_cheap_rerun(tmp_path):
    assert len(STANDARD_PACKINGS) == 16 and "kuhn-1002" in STANDARD_PACKINGS
    assert sum(k.startswith("rve-") for k in STANDARD_PACKINGS) == 15
    out = standard_packings(tmp_path, names=["rve-70-2"])
    path = out["rve-70-2"]
    from gransim.io import load_packing, read_provenance

    p = load_packing(path)
    assert p.n == 70 and read_provenance(path)["parameters"]["seed"] == 2
    mtime = path.stat().st_mtime_ns
    standard_packings(tmp_path, names=["rve-70-2"])  # up to date: kept
    assert path.stat().st_mtime_ns == mtime
    standard_packings(tmp_path, names=["rve-70-2"], force=True)
    assert path.stat().st_mtime_ns != mtime
    assert np.array_equal(load_packing(path).positions, p.positions)  # deterministic
    with pytest.raises(InputError, match="unknown standard packing"):
        standard_packings(tmp_path, names=["rve-71-1"])


def test_threaded_minimiser_gives_the_serial_result_bit_for_bit():
    """The chunked kernels sum in a fixed order: the threaded build (used from PARALLEL_FROM disks)
    must reproduce the serial one exactly, whatever the thread count."""
    rng = np.random.default_rng(5)
    r = get_distribution("quartz-sand").sample(300, rng)
    r = r / (2 * r.mean())
    L = float(np.sqrt(np.pi * np.sum(r**2) / 0.86))
    x = rng.random((300, 2)) * L
    out = []
    for parallel in (False, True):
        m = Minimiser(x, r, L, 0.3, FireParameters(), parallel=parallel)
        assert m.run(0.0, False, 0.1, 100_000) == "converged"
        assert m.run(2e-3, True, 1e-3, 100_000) == "converged"
        out.append((m.in_original_order(), m.L, m.steps))
    (xs, rs), Ls, ns = out[0]
    (xp, rp), Lp, npar = out[1]
    assert np.array_equal(rs, r) and np.array_equal(rp, r)
    assert np.array_equal(xs, xp) and Ls == Lp and ns == npar


def test_front_start_places_touching_disks_without_overlap():
    """The advancing front (Feng, Han & Owen 2003) places each disk in contact with the front and
    never overlapping a placed disk: checked by the brute-force periodic search."""
    rng = np.random.default_rng(7)
    d = get_distribution("quartz-sand").sample(500, rng)
    r = d / (2 * d.mean())
    L = float(np.sqrt(np.pi * np.sum(r**2) / FRONT_PHI))
    x, placed = front_packing(r, L, rng)
    assert placed >= 0.95 * r.size  # nearly all disks fit at the growth density
    nl = find_neighbours_bruteforce(x[:placed], r[:placed], L * np.eye(2), 1e-6)
    gap = -nl.overlaps(r[:placed])
    assert gap.min() > -1e-9  # no overlap among the placed disks
    touching = np.zeros(placed, dtype=bool)
    t = gap < 1e-9
    touching[nl.i[t]] = True
    touching[nl.j[t]] = True
    assert touching.mean() > 0.95  # placed in contact (first-layer ends and a few retired disks aside)
    frac = x / L
    assert np.all((frac >= 0) & (frac < 1))


def test_front_method_meets_the_targets_of_the_random_start():
    """method="front": the same sizes as the random start, a different packing, and the same
    targets checked independently (mean overlap, largest residual, jammed coordination)."""
    p = make_packing("quartz-sand", 300, seed=5, method="front")
    q = make_packing("quartz-sand", 300, seed=5)
    assert np.array_equal(np.sort(p.radii), np.sort(q.radii))
    assert not np.array_equal(p.positions, q.positions)
    F, eps, _ = contact_forces(p)
    assert eps.mean() / (2 * p.radii.mean()) == pytest.approx(DEFAULT_MEAN_OVERLAP, rel=0.021)
    assert np.max(np.linalg.norm(F, axis=1)) <= 1.001e-3 * eps.mean()
    assert 0.82 < p.solid_fraction < 0.87
    s = packing_stats(p)
    assert 3.9 < s["coordination_nonrattler"] < 4.4
    assert p.metadata["method"] == "front" and p.metadata["front_placed"] >= 280
    with pytest.raises(InputError, match="method"):
        make_packing("quartz-sand", 50, seed=1, method="lattice")
