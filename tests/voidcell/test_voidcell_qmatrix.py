"""Q^m of eqs (10)-(12) and eq (7) against the boundary integral (independent formula)."""

from fractions import Fraction

import numpy as np
import pytest

from gransim.errors import InputError
from gransim.voidcell import polygon_gradient, q_matrix, q_separations


def boundary_gradient(x, v):
    """(1/A) sum_j (v^j + v^{j+1})/2 (x) b^j: the divergence theorem on the polygon, eq (2)."""
    e = np.roll(x, -1, axis=0) - x
    b = np.column_stack([e[:, 1], -e[:, 0]])
    A = 0.5 * np.sum(x[:, 0] * e[:, 1] - x[:, 1] * e[:, 0])
    vm = 0.5 * (v + np.roll(v, -1, axis=0))
    return vm.T @ b / A


def star_polygon(m, rng, convex):
    """Simple polygon, counter-clockwise: sorted angles; equal radii (convex) or random radii."""
    t = np.sort(rng.uniform(0, 2 * np.pi, m))
    t += np.linspace(0, 0.3, m)  # keep the angles distinct
    t = np.sort(t % (2 * np.pi))
    r = np.ones(m) if convex else rng.uniform(0.2, 2.0, m)
    c = rng.normal(size=2) * 5
    return c + np.column_stack([r * np.cos(t), r * np.sin(t)])


def test_table1_rows():
    # Table 1 of the paper (m = 5: the printed last entries are garbled; the recursion and the
    # antisymmetry fix them to -3/5, -9/5)
    table = {3: [0, 1, -1], 4: [0, 6 / 4, 0, -6 / 4], 5: [0, 9 / 5, 3 / 5, -3 / 5, -9 / 5], 6: [0, 2, 1, 0, -1, -2]}
    for m, row in table.items():
        np.testing.assert_allclose(q_separations(m), row, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(q_matrix(3), [[0, 1, -1], [-1, 0, 1], [1, -1, 0]])  # matrix 8_1


@pytest.mark.parametrize("m", [2, 3, 7, 12, 40])
def test_recursion_solves_to_closed_form(m):
    # closed form derived by hand from eq (11): Q^m(d) = 3 (m - 2 d) / m for d != 0
    d = np.arange(m)
    expect = np.where(d == 0, 0.0, 3.0 * (m - 2 * d) / m) if m > 2 else np.zeros(2)
    np.testing.assert_allclose(q_separations(m), expect, rtol=0, atol=1e-13)


@pytest.mark.parametrize("m", range(3, 13))
def test_consistency_and_antisymmetry(m):
    Q = q_matrix(m)
    for p in range(m):
        for q in range(m):
            assert Q[p, q] == Q[(p + 1) % m, (q + 1) % m]  # eq (10)
    np.testing.assert_allclose(Q, -Q.T, atol=1e-14)


@pytest.mark.parametrize("m", range(3, 13))
@pytest.mark.parametrize("convex", [True, False])
def test_eq7_equals_boundary_integral(m, convex):
    rng = np.random.default_rng(100 * m + convex)
    for _ in range(5):
        x = star_polygon(m, rng, convex)
        v = rng.normal(size=(m, 2))
        L7 = polygon_gradient(x, v)
        Lb = boundary_gradient(x, v)
        # round-off: O(m) products of O(1) numbers over an area of O(1)
        np.testing.assert_allclose(L7, Lb, rtol=0, atol=1e-12 * np.abs(Lb).max() * m)


@pytest.mark.parametrize("m", range(3, 13))
def test_affine_field_exact(m):
    rng = np.random.default_rng(m)
    x = star_polygon(m, rng, convex=False)
    G = rng.normal(size=(2, 2))
    v = x @ G.T + rng.normal(size=2)
    np.testing.assert_allclose(polygon_gradient(x, v), G, rtol=0, atol=1e-12)


def test_q3_nonunique_alternative_gives_same_gradient():
    # matrix 8_2 is not consistent but gives the same L for a triangle (eq 6 constraints)
    rng = np.random.default_rng(3)
    x = star_polygon(3, rng, convex=True)
    v = rng.normal(size=(3, 2))
    e = np.roll(x, -1, axis=0) - x
    b = np.column_stack([e[:, 1], -e[:, 0]])
    A = 0.5 * np.sum(x[:, 0] * e[:, 1] - x[:, 1] * e[:, 0])
    Q2 = np.array([[0, 3, 0], [-3, 0, 0], [0, 0, 0]])
    L = np.einsum("jk,jp,kq->pq", Q2, np.roll(v, -1, axis=0) - v, b) / (6 * A)
    np.testing.assert_allclose(L, polygon_gradient(x, v), atol=1e-13)


def test_exact_rationals():
    from gransim.voidcell.qmatrix import _q_row

    assert _q_row(5)[1] == Fraction(9, 5) and _q_row(5)[2] == Fraction(3, 5)


@pytest.mark.parametrize("bad", [1, 0, -3, 2.5, "x", None])
def test_bad_valence(bad):
    with pytest.raises(InputError, match="valence"):
        q_matrix(bad)
