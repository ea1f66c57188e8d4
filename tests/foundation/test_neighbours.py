"""Cell-list neighbour search against an independent brute-force search (all image shifts)."""

import numpy as np
import pytest

from gransim.contacts import find_neighbours, find_neighbours_bruteforce
from gransim.errors import InputError


def _random_cell(rng, kind):
    a = rng.uniform(1.0, 3.0)
    b = rng.uniform(1.0, 3.0)
    if kind == 0:
        return np.diag([a, b])
    if kind == 1:  # a2 tilted (simple shear in x)
        return np.array([[a, rng.uniform(-1.5, 1.5) * b], [0.0, b]])
    if kind == 2:  # a1 tilted
        return np.array([[a, 0.0], [rng.uniform(-1.0, 1.0) * a, b]])
    # general cell, rotated
    th = rng.uniform(0, 2 * np.pi)
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    return R @ np.array([[a, rng.uniform(-0.8, 0.8) * b], [0.0, b]])


@pytest.mark.parametrize("block", range(8))
def test_cell_list_equals_bruteforce_on_200_random_cases(block):
    rng = np.random.default_rng(1000 + block)
    for case in range(25):  # 8 blocks x 25 = 200 cases
        C = _random_cell(rng, case % 4)
        n = int(rng.integers(2, 60))
        s = rng.uniform(-1.5, 2.5, size=(n, 2))  # many centres outside the primary cell
        x = s @ C.T
        rmin = rng.uniform(0.03, 0.15)
        r = rmin * rng.uniform(1.0, 4.0, size=n)  # radius ratio up to 4
        if case % 7 == 0:
            r *= 4.0  # tiny cell relative to the disks: several images of one partner, self-images
        skin = [0.0, 0.05, 0.2][case % 3]
        a = find_neighbours(x, r, C, skin=skin)
        b = find_neighbours_bruteforce(x, r, C, skin=skin)
        assert np.array_equal(a.sorted_keys(), b.sorted_keys()), (block, case, len(a), len(b))
        # branch vectors: same image, so they agree to round-off
        ka = {tuple(k): l for k, l in zip(np.column_stack([a.i, a.j, a.shift]).tolist(), a.branch)}
        for k, l in zip(np.column_stack([b.i, b.j, b.shift]).tolist(), b.branch):
            np.testing.assert_allclose(ka[tuple(k)], l, rtol=0, atol=1e-12 * np.abs(C).max() * 10)


def test_branch_vector_definition_and_pairs_across_boundary():
    C = np.diag([1.0, 1.0])
    x = np.array([[0.05, 0.5], [0.95, 0.5]])
    nl = find_neighbours(x, [0.06, 0.06], C)
    assert len(nl) == 1
    assert (nl.i[0], nl.j[0]) == (0, 1)
    np.testing.assert_array_equal(nl.shift[0], [-1, 0])
    np.testing.assert_allclose(nl.branch[0], x[1] + C @ nl.shift[0] - x[0])
    np.testing.assert_allclose(nl.overlaps(np.array([0.06, 0.06])), [0.02])


def test_self_image_in_a_cell_smaller_than_a_disk():
    C = np.diag([1.0, 5.0])
    nl = find_neighbours([[0.5, 0.5], [0.5, 3.0]], [0.6, 0.1], C)
    keys = {tuple(k) for k in nl.sorted_keys().tolist()}
    assert (0, 0, 1, 0) in keys  # disk 0 touches its own image one cell to the right
    assert (0, 0, -1, 0) not in keys  # each pair once


def test_sheared_cell_matches_unsheared_equivalent_lattice():
    # the same lattice described by two different bases gives the same contacts
    rng = np.random.default_rng(5)
    C1 = np.diag([2.0, 2.0])
    C2 = C1 @ np.array([[1.0, 2.0], [0.0, 1.0]])  # a2' = a2 + 2 a1: same lattice
    x = rng.uniform(0, 2, (40, 2))
    r = rng.uniform(0.1, 0.25, 40)
    d1 = np.sort(find_neighbours(x, r, C1).distance)
    d2 = np.sort(find_neighbours(x, r, C2).distance)
    np.testing.assert_allclose(d1, d2, rtol=1e-12)


@pytest.mark.parametrize(
    "positions, radii, cell, match",
    [
        ([[0, 0], [1, 1]], [0.1, -0.1], np.eye(2), "radii"),
        ([[0, 0], [1, 1]], [0.1, 0.0], np.eye(2), "radii"),
        ([[0, np.nan], [1, 1]], [0.1, 0.1], np.eye(2), "NaN"),
        ([[0, 0, 0], [1, 1, 1]], [0.1, 0.1], np.eye(2), "shape"),
        ([[0, 0], [1, 1]], [0.1, 0.1, 0.1], np.eye(2), "radii"),
        ([[0, 0], [1, 1]], [0.1, 0.1], [[1, 2], [1, 2]], "degenerate"),
        ([[0, 0], [1, 1]], [0.1, 0.1], [[0, 1], [1, 0]], "right-handed"),
    ],
)
def test_bad_input_is_named(positions, radii, cell, match):
    with pytest.raises(InputError, match=match):
        find_neighbours(positions, radii, cell)
