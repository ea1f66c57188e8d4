"""The scalar normal contact law of eqs (3)-(5) (gransim.contacts.law), tested alone."""

from __future__ import annotations

import numpy as np
import pytest

from gransim.contacts.law import force_magnitude, overlap, potential, stiffness

KN = 3.0e6


def test_overlap_definition():
    assert overlap(1.0e-3, 2.0e-3, 2.5e-3) == pytest.approx(0.5e-3, rel=1e-15)
    assert overlap(1.0e-3, 2.0e-3, 3.5e-3) < 0  # a gap of 0.5 mm


@pytest.mark.parametrize("eps", [1e-6, 3e-5, 2e-4])
def test_derivatives_by_central_differences(eps):
    """dPhi/deps = force magnitude and d^2Phi/deps^2 = stiffness (Phi is quadratic: the central
    difference is exact up to round-off, hence 1e-8)."""
    h = 1e-3 * eps
    assert (potential(eps + h, KN) - potential(eps - h, KN)) / (2 * h) == pytest.approx(
        force_magnitude(eps, KN), rel=1e-8
    )
    assert (force_magnitude(eps + h, KN) - force_magnitude(eps - h, KN)) / (2 * h) == pytest.approx(
        stiffness(eps, KN), rel=1e-8
    )
    assert potential(eps, KN) == pytest.approx(0.5 * KN * eps**2, rel=1e-15)


def test_heaviside_no_tension():
    """No energy, force or stiffness without overlap (eq 4: H(eps)); continuous at eps = 0."""
    for eps in (-1e-3, -1e-12, 0.0):
        assert potential(eps, KN) == 0.0 and force_magnitude(eps, KN) == 0.0
        assert stiffness(eps, KN) == 0.0
    tiny = np.nextafter(0.0, 1.0)
    assert force_magnitude(tiny, KN) == KN * tiny
    assert stiffness(tiny, KN) == KN
