"""Shared helpers of the fem tests (imported as a plain module: tests/fem has no __init__)."""

import numpy as np

from gransim.fem import NeoHookean, StVenantKirchhoff, lame
from gransim.fem.mesh import SlopeGeometry

#: A reduced slope (10 x 5 elements) with the same footing, slope and supports as the full one.
SMALL_SLOPE = SlopeGeometry(columns=10, rows=5)


def make_continuum(kind):
    """Neo-Hookean or St Venant-Kirchhoff with E = 3e7 Pa, nu = 0.3."""
    lam, mu = lame(3.0e7, 0.3)
    return NeoHookean(lam, mu) if kind == "neo-hookean" else StVenantKirchhoff(lam, mu)


def random_F(rng, n, scale=0.1):
    """Random deformation gradients near identity with det F > 0."""
    F = np.eye(2) + scale * rng.uniform(-1, 1, size=(n, 2, 2))
    assert np.all(np.linalg.det(F) > 0)
    return F
