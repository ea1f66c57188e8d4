"""The shared bin-stencil walk (gransim.geometry.bins) against an independent O(N^2 K^2) search
over all image shifts, in the full (label) and the half (bin) stencil, on random periodic point
sets in sheared, rotated and tiny cells (several images of one partner, a point's own image)."""

import numpy as np
import pytest

from gransim.geometry.bins import bin_layout, pairs_within, wrap_fractional


def brute_pairs(xw, reach, C, skin):
    """Set of (i, j, t1, t2) with i < j, or i == j and t > 0, |xw_j + C t - xw_i| < cut (numpy)."""
    cut = reach[:, None] + reach[None, :] + skin
    K = int(np.ceil(2 * cut.max() / np.min(np.abs(np.linalg.det(C)) / np.linalg.norm(C, axis=0)))) + 2
    out = set()
    for t1 in range(-K, K + 1):
        for t2 in range(-K, K + 1):
            d = xw[None, :, :] + C @ np.array([t1, t2], float) - xw[:, None, :]
            hit = np.einsum("ijk,ijk->ij", d, d) < cut**2
            for i, j in zip(*np.nonzero(hit)):
                if i < j or (i == j and (t1 > 0 or (t1 == 0 and t2 > 0))):
                    out.add((int(i), int(j), t1, t2))
    return out


def canonical(i, j, t):
    """Orient each pair as i < j (or i == j with t > 0): (j, i, -t) is the same pair."""
    out = []
    for a, b, (t1, t2) in zip(i.tolist(), j.tolist(), t.tolist()):
        if a > b or (a == b and not (t1 > 0 or (t1 == 0 and t2 > 0))):
            a, b, t1, t2 = b, a, -t1, -t2
        out.append((a, b, t1, t2))
    return out


def random_cell(rng, kind):
    a, b = rng.uniform(1.0, 3.0, 2)
    if kind == 0:
        return np.diag([a, b])
    if kind == 1:
        return np.array([[a, rng.uniform(-1.5, 1.5) * b], [0.0, b]])
    th = rng.uniform(0, 2 * np.pi)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return R @ np.array([[a, rng.uniform(-0.8, 0.8) * b], [0.0, b]])


@pytest.mark.parametrize("half", [False, True])
@pytest.mark.parametrize("block", range(3))
def test_pair_sets_equal_brute_force(half, block):
    rng = np.random.default_rng(50 + block)
    for case in range(20):
        C = random_cell(rng, case % 3)
        n = int(rng.integers(1, 50))
        x = rng.uniform(-1.5, 2.5, (n, 2)) @ C.T  # centres outside the primary cell too
        reach = rng.uniform(0.02, 0.15) * rng.uniform(1.0, 4.0, n)
        if case % 5 == 0:
            reach *= 5.0  # reach beyond the cell: several images, self-images
        skin = [0.0, 0.1][case % 2]
        i, j, t, d = pairs_within(x, reach, C, skin, half=half)
        xw, _, _ = wrap_fractional(x, C)
        got = canonical(i, j, t)
        assert len(got) == len(set(got)), "a pair (and image) visited twice"
        assert set(got) == brute_pairs(xw, reach, C, skin), (block, case)
        # d is the separation of that image, and within reach
        np.testing.assert_allclose(d, xw[j] + t @ C.T - xw[i], rtol=0, atol=1e-12)
        assert np.all(np.hypot(d[:, 0], d[:, 1]) < reach[i] + reach[j] + skin)
        if not half:  # the label rule of the full stencil: j > i, or j == i with t > 0
            assert np.all((j > i) | ((j == i) & ((t[:, 0] > 0) | ((t[:, 0] == 0) & (t[:, 1] > 0)))))


def test_layout_bins_reach_the_cutoff_in_a_sheared_cell():
    # k bins of width h/nb cover the cutoff in each lattice direction, for any shear
    for shear in (0.0, 0.7, -2.3):
        C = np.array([[10.0, shear * 8.0], [0.0, 8.0]])
        h = np.abs(np.linalg.det(C)) / np.linalg.norm(C, axis=0)[::-1]
        for cutoff in (0.3, 1.0, 3.7, 25.0):
            nb1, nb2, k1, k2 = bin_layout(C, cutoff, 1000)
            assert k1 * h[0] / nb1 >= cutoff * (1 - 1e-12) and k2 * h[1] / nb2 >= cutoff * (1 - 1e-12)
            assert nb1 * nb2 <= 4000
