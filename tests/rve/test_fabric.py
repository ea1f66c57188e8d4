"""Contact normal density, uniformity and fabric anisotropy (gransim.rve.fabric)."""

from __future__ import annotations

import numpy as np
import pytest
from rve_fixtures import lattice_packing, random_packing

from gransim import InputError
from gransim.rve.fabric import (
    anisotropy,
    contact_normal_angles,
    contact_normal_density,
    fabric_tensor,
    most_uniform,
    normal_density,
    plot_normal_densities,
    uniformity,
)


def test_density_normalised_and_pi_periodic():
    rng = np.random.default_rng(0)
    tc = rng.uniform(0, 2 * np.pi, 137)
    theta = np.linspace(0, 2 * np.pi, 20000, endpoint=False)
    for delta in np.radians([10, 20, 30, 90]):
        rho = normal_density(tc, delta, theta)
        assert np.mean(rho) * 2 * np.pi == pytest.approx(1.0, abs=2e-3)  # Riemann sum of a step function
        np.testing.assert_array_equal(rho, normal_density(tc, delta, theta + np.pi))
        assert np.all(rho >= 0)


def test_single_direction_closed_form():
    """One normal (two directions): 2 pi rho = pi/(2 delta) on 4 delta of the circle, else 0, so
    U^2 = [4 delta (pi/(2 delta) - 1)^2 + 2 pi - 4 delta] / (2 pi)."""
    for deg in (10, 20, 30, 45):
        d = np.radians(deg)
        want = np.sqrt((4 * d * (np.pi / (2 * d) - 1) ** 2 + 2 * np.pi - 4 * d) / (2 * np.pi))
        assert uniformity([0.3], d) == pytest.approx(want, rel=1e-12)
    assert anisotropy([0.3]) == pytest.approx(2.0)


def test_evenly_spread_normals_are_uniform():
    """M normals at spacing pi/M: with delta a multiple of the spacing every window holds the same
    count, so U = 0 and Phi = I/2 (a = 0)."""
    M = 36
    tc = np.arange(M) * np.pi / M + 0.01
    # window edges coincide with other normals up to round-off: slivers of width ~1e-16 rad with an
    # off-by-one count contribute sqrt(1e-16)-sized terms, hence 1e-6 rather than 1e-12
    assert uniformity(tc, 4 * np.pi / M) < 1e-6
    assert uniformity(tc, 4.25 * np.pi / M) > 0.05  # width 8.5 spacings: windows hold 8 or 9
    np.testing.assert_allclose(fabric_tensor(tc), np.eye(2) / 2, atol=1e-15)
    assert anisotropy(tc) < 1e-14


def test_anisotropy_of_cosine_density():
    """Sample rho = (1 + a cos 2 theta)/(2 pi) by inverse CDF: the fabric anisotropy is a."""
    a = 0.4
    u = (np.arange(200000) + 0.5) / 200000
    th = np.linspace(0, np.pi, 400001)
    cdf = (th + a / 2 * np.sin(2 * th)) / np.pi
    tc = np.interp(u, cdf, th)
    assert anisotropy(tc) == pytest.approx(a, rel=1e-4)


def test_ranking_prefers_random_over_lattice():
    """A triangular lattice has normals in three directions only; a random dense packing is more
    uniform and is selected; the measure decreases with the angle of influence."""
    lat, rnd = lattice_packing(8, 8, seed=0, spread=0.02), random_packing(200, seed=2, phi=0.9)
    best, scores = most_uniform({"lattice": lat, "random": rnd})
    assert best == "random"
    assert scores["lattice"][0] > 2 * scores["random"][0]
    d = contact_normal_density(rnd)
    assert d.n_contacts == contact_normal_angles(rnd).size > 100
    assert np.all(np.diff(d.uniformity) < 0)
    np.testing.assert_allclose(np.trace(d.fabric), 1.0)


def test_angles_are_those_of_the_deformed_contacts():
    """The fabric sees the same contact set as the homogenization at x = F X."""
    from gransim.rve import contact_state

    p = random_packing(200, seed=2, phi=0.8)
    F = np.array([[1.0, 0.05], [0.0, 0.9]])
    n = contact_state(p, F, 1e7).normals
    want = np.sort(np.mod(np.arctan2(n[:, 1], n[:, 0]), 2 * np.pi))
    np.testing.assert_allclose(np.sort(contact_normal_angles(p, F)), want, atol=1e-12)


def test_plot_writes_png(tmp_path):
    ds = {f"r{k}": contact_normal_density(random_packing(60, seed=k)) for k in range(3)}
    out = plot_normal_densities(ds, tmp_path / "fabric.png", ncols=2, title="test")
    assert (tmp_path / "fabric.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert out == tmp_path / "fabric.png"


def test_bad_input():
    p = random_packing(60)
    with pytest.raises(InputError, match="angle of influence"):
        contact_normal_density(p, angles_deg=[0.0])
    with pytest.raises(InputError, match="angle of influence"):
        contact_normal_density(p, angles_deg=[120.0])
    with pytest.raises(InputError, match="no overlapping pairs"):
        contact_normal_density(lattice_packing(4, 4, swell=0.8))
    with pytest.raises(InputError, match="det F"):
        contact_normal_angles(p, np.diag([1.0, -1.0]))
    with pytest.raises(InputError, match="Packing"):
        contact_normal_angles("p")
