"""Grain size distributions: the sieve curves, their statistics and sampling by area fraction."""

import numpy as np
import pytest
from scipy import stats

from gransim.errors import InputError
from gransim.generation import GrainSizeDistribution, distribution_names, get_distribution

NAMES = ["quartz-sand", "kuhn-1002"]


def area_percent_passing(d, sieve):
    """Percent of the sampled disk *area* (= mass in 2D) with diameter <= each sieve aperture."""
    a = d**2
    return np.array([100 * a[d <= s].sum() / a.sum() for s in sieve])


def test_shipped_names():
    assert set(NAMES) <= set(distribution_names())


@pytest.mark.parametrize("name", NAMES)
@pytest.mark.parametrize("stratified", [True, False])
def test_sampling_1e5_grains_reproduces_the_sieve_curve(name, stratified):
    # acceptance: within 1 percentage point at every sieve (also without stratification: the
    # number density dN ∝ dM / d^2 is right, not just the stratification)
    g = get_distribution(name)
    d = g.sample(100_000, np.random.default_rng(7), stratified=stratified)
    err = area_percent_passing(d, g.diameters) - g.passing
    assert np.max(np.abs(err)) < 1.0, err
    # and between the sieves, where the curve is interpolated (linear in ln d)
    mid = np.sqrt(g.diameters[1:] * g.diameters[:-1])
    assert np.max(np.abs(area_percent_passing(d, mid) - g.percent_passing(mid))) < 1.0


def test_stratified_70_grains_follow_the_curve():
    # one grain of 70 carries at most ~4 % of the area: the stratified sample stays within ~3 points
    g = get_distribution("quartz-sand")
    d = g.sample(70, np.random.default_rng(1))
    assert np.max(np.abs(area_percent_passing(d, g.diameters) - g.passing)) < 3.0


def test_kuhn_constraints_of_the_paper():
    # Kuhn (1999) section 4: d from 0.45 to 1.4 D50, D60/D10 = 1.7
    g = get_distribution("kuhn-1002")
    assert g.d_min / g.d50 == pytest.approx(0.45, rel=1e-12)
    assert g.d_max / g.d50 == pytest.approx(1.4, rel=1e-12)
    assert g.cu == pytest.approx(1.7, rel=1e-12)
    assert g.d50 == pytest.approx(1e-3, rel=1e-12)  # the chosen absolute size
    # the same constraints measured on a sample (area-weighted quantiles)
    d = np.sort(g.sample(100_000, np.random.default_rng(3)))
    cum = 100 * np.cumsum(d**2) / np.sum(d**2)
    D10, D50, D60 = (d[np.searchsorted(cum, q)] for q in (10, 50, 60))
    assert D60 / D10 == pytest.approx(1.7, rel=0.01)
    assert d.min() >= 0.45 * g.d50 and d.max() <= 1.4 * g.d50
    assert D50 == pytest.approx(g.d50, rel=0.01)


def test_quartz_sand_characteristic_diameters():
    g = get_distribution("quartz-sand")
    for q, mm in ((10, 0.25), (50, 0.34), (60, 0.36), (90, 0.47)):
        assert float(g.diameter(q)) == pytest.approx(mm * 1e-3, rel=1e-12)
    assert g.cu == pytest.approx(0.36 / 0.25, rel=1e-12)
    assert "Fig. 2" in g.source and "not measured" in g.source


def test_curve_inverse_and_log_linear_interpolation():
    g = GrainSizeDistribution([1.0, 2.0, 4.0], [0.0, 50.0, 100.0])
    assert g.percent_passing(np.sqrt(2.0)) == pytest.approx(25.0)  # halfway in ln d
    assert g.percent_passing(0.5) == 0.0 and g.percent_passing(5.0) == 100.0
    q = np.linspace(0, 100, 41)
    assert np.allclose(g.percent_passing(g.diameter(q)), q)
    # a flat part (gap grading): D_p is the smallest aperture
    gap = GrainSizeDistribution([1.0, 2.0, 3.0, 4.0], [0.0, 40.0, 40.0, 100.0])
    assert float(gap.diameter(40.0)) == pytest.approx(2.0)
    d = gap.sample(20_000, 1)
    assert not np.any((d > 2.0 + 1e-12) & (d < 3.0 - 1e-12))  # no grain in the gap


def test_one_segment_number_distribution_is_uniform_in_inverse_square_diameter():
    # exact case: on a log-linear segment dN ∝ d^-2 dln d, i.e. t = d^-2 is uniform by number
    g = GrainSizeDistribution([1.0, 3.0], [0.0, 100.0])
    d = g.sample(20_000, np.random.default_rng(5), stratified=False)
    t = d**-2.0
    assert stats.kstest((t - 1 / 9) / (1 - 1 / 9), "uniform").pvalue > 1e-3
    # analytic number mean 2 / (1/d0 + 1/d1) = 1.5, and the number CDF
    assert g.mean_diameter == pytest.approx(1.5)
    assert g.number_fraction_below(2.0) == pytest.approx((1 - 0.25) / (1 - 1 / 9))
    assert d.mean() == pytest.approx(1.5, abs=4 * d.std() / np.sqrt(d.size))


@pytest.mark.parametrize("name", NAMES)
def test_number_statistics_agree_with_iid_samples(name):
    g = get_distribution(name)
    d = g.sample(200_000, np.random.default_rng(11), stratified=False)
    assert d.mean() == pytest.approx(g.mean_diameter, abs=4 * d.std() / np.sqrt(d.size))
    s = g.diameters[1:-1]
    p = g.number_fraction_below(s)
    assert np.all(np.abs(np.array([np.mean(d <= x) for x in s]) - p) < 4 * np.sqrt(p * (1 - p) / d.size) + 1e-12)


def test_scaling_keeps_the_grading():
    g = get_distribution("quartz-sand")
    h = g.scaled(1e-3)
    assert h.mean_diameter == pytest.approx(1e-3, rel=1e-12)
    k = h.mean_diameter / g.mean_diameter
    assert h.cu == pytest.approx(g.cu) and h.d50 == pytest.approx(k * g.d50)
    assert np.allclose(h.percent_passing(k * g.diameters), g.passing)
    with pytest.raises(InputError, match="mean_diameter"):
        g.scaled(-1.0)


def test_sampling_is_deterministic_for_a_seed():
    g = get_distribution("kuhn-1002")
    assert np.array_equal(g.sample(500, 42), g.sample(500, 42))
    assert not np.array_equal(g.sample(500, 42), g.sample(500, 43))


def test_errors():
    with pytest.raises(InputError, match="unknown distribution 'granite'.*kuhn-1002.*quartz-sand"):
        get_distribution("granite")
    with pytest.raises(InputError, match="strictly increasing"):
        GrainSizeDistribution([1.0, 1.0, 2.0], [0, 50, 100])
    with pytest.raises(InputError, match="non-decreasing"):
        GrainSizeDistribution([1.0, 2.0, 3.0], [0, 60, 50])
    with pytest.raises(InputError, match="start at 0 and end at 100"):
        GrainSizeDistribution([1.0, 2.0], [0, 90])
    with pytest.raises(InputError, match="must be > 0"):
        GrainSizeDistribution([-1.0, 2.0], [0, 100])
    with pytest.raises(InputError, match="NaN"):
        GrainSizeDistribution([1.0, np.nan], [0, 100])
    with pytest.raises(InputError, match="n: expected an integer >= 1"):
        get_distribution("quartz-sand").sample(0)
    with pytest.raises(InputError, match="percent"):
        get_distribution("quartz-sand").diameter(120)


def test_csv_round_trip(tmp_path):
    f = tmp_path / "mine.csv"
    f.write_text("# my sand\ndiameter_mm,percent_passing\n0.1,0\n0.2,30\n0.4,100\n")
    g = get_distribution(str(f))
    assert g.name == "mine" and g.source == "my sand"
    assert g.d_min == pytest.approx(1e-4) and float(g.diameter(30)) == pytest.approx(2e-4)
    bad = tmp_path / "bad.csv"
    bad.write_text("diameter_mm,percent_passing\n0.1,0,1\n")
    with pytest.raises(InputError, match="bad.csv"):
        GrainSizeDistribution.from_csv(bad)
    with pytest.raises(InputError, match="cannot read"):
        GrainSizeDistribution.from_csv(tmp_path / "missing.csv")
