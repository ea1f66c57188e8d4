"""The enthalpy Hessian of a packing (gransim.generation.stiffness): derivative consistency against
finite differences of an independent energy sum, the rigid-translation null space, stability of a
FIRE minimum, and the quadratic convergence of Newton's method on a frozen contact network."""

import numpy as np
import pytest

from gransim.generation import make_packing
from gransim.generation.stiffness import backbone, contact_pairs, enthalpy_derivatives, newton_step


@pytest.fixture(scope="module")
def state():
    p = make_packing("quartz-sand", 60, seed=3)
    ell = 2 * p.radii.mean()
    return p.positions / ell, p.radii / ell, p.cell[0, 0] / ell, p.metadata["pressure_reduced"]


def energy(x, r, L, P, pairs):
    """H = sum 1/2 (r_i + r_j - |l|)^2 + P L^2 over the given pairs (plain numpy, independent)."""
    i, j, s = pairs
    l = x[j] - x[i] + L * s
    return 0.5 * np.sum((r[i] + r[j] - np.linalg.norm(l, axis=1)) ** 2) + P * L * L


def test_derivatives_match_finite_differences(state):
    x, r, L, P = state
    pairs = contact_pairs(x, r, L)
    # away from equilibrium (at the minimum the gradient is ~1e-6 and a difference quotient would
    # test its own truncation error): the contacts frozen, the centres moved by ~1e-3
    rng = np.random.default_rng(0)
    x = x + 1e-3 * rng.standard_normal(x.shape)
    der = enthalpy_derivatives(x, r, L, P, pairs=pairs)
    assert der.energy == pytest.approx(energy(x, r, L, P, pairs), rel=1e-14)
    v = rng.standard_normal(x.shape)
    h = 1e-6
    # gradient along v and along the affine mode (x, L) -> (1 + t)(x, L)
    # (P A does not change with x: left out of this difference, which would only add round-off)
    fd = (energy(x + h * v, r, L, 0.0, pairs) - energy(x - h * v, r, L, 0.0, pairs)) / (2 * h)
    assert der.gradient @ v.ravel() == pytest.approx(fd, rel=1e-6)
    fl = (energy(x * (1 + h), r, L * (1 + h), P, pairs) - energy(x * (1 - h), r, L * (1 - h), P, pairs)) / (2 * h)
    assert der.cell_gradient == pytest.approx(fl, rel=1e-5)
    # Hessian times v and the coupling: central differences of the analytic gradient
    gp = enthalpy_derivatives(x + h * v, r, L, P, pairs=pairs)
    gm = enthalpy_derivatives(x - h * v, r, L, P, pairs=pairs)
    Kv = der.K @ v.ravel()
    assert np.allclose(Kv, (gp.gradient - gm.gradient) / (2 * h), rtol=1e-6, atol=1e-9 * np.abs(Kv).max())
    ap = enthalpy_derivatives(x * (1 + h), r, L * (1 + h), P, pairs=pairs)
    am = enthalpy_derivatives(x * (1 - h), r, L * (1 - h), P, pairs=pairs)
    c = der.coupling
    assert np.allclose(c, (ap.gradient - am.gradient) / (2 * h), rtol=1e-5, atol=1e-8 * np.abs(c).max())
    # cell_gradient at the scaled state is (1 + t) dH/dt: its derivative is h + dH/dt
    fd_h = (ap.cell_gradient - am.cell_gradient) / (2 * h) - der.cell_gradient
    assert der.h == pytest.approx(fd_h, rel=1e-6)
    assert abs(der.K - der.K.T).max() <= 1e-15 * abs(der.K).max()  # symmetric (to the order of the sums)


def test_rigid_translations_are_zero_modes_and_a_fire_minimum_is_stable(state):
    x, r, L, P = state
    der = enthalpy_derivatives(x, r, L, P)
    t = np.tile([1.0, 0.0], x.shape[0])
    assert np.abs(der.K @ t).max() < 1e-12
    # the disks of the backbone (rattlers removed): at the FIRE minimum the Hessian restricted to
    # them has exactly two zero modes (translations) and no negative eigenvalue
    bb = backbone(x.shape[0], der.i, der.j)
    keep = bb[der.i] & bb[der.j]
    net = enthalpy_derivatives(x, r, L, P, pairs=(der.i[keep], der.j[keep], der.shift[keep]))
    dof = np.repeat(bb, 2)
    w = np.linalg.eigvalsh(net.K[dof][:, dof].toarray())
    assert np.all(np.abs(w[:2]) < 1e-12)
    assert w[2] > 0.0


def test_newton_converges_quadratically_on_a_frozen_network(state):
    """Contacts frozen as springs (H smooth): at its minimum perturbed by delta, one Newton step
    leaves a residual r1 ~ C r0^2, so the observed order (slope of log r1 against log r0 over
    delta = 1e-3 ... 6e-5) is 2. A Hessian missing a term (e.g. the geometric one) gives slope 1."""
    x, r, L, P = state
    i, j, s = contact_pairs(x, r, L)
    bb = backbone(x.shape[0], i, j)
    keep = bb[i] & bb[j]
    pairs = (i[keep], j[keep], s[keep])

    def residual(x, L):
        der = enthalpy_derivatives(x, r, L, P, pairs=pairs)
        return der, np.sqrt(np.sum(der.gradient**2) + der.cell_gradient**2)

    for _ in range(10):  # the minimum of the frozen network, to round-off
        der, res = residual(x, L)
        if res < 1e-13:
            break
        dx, lam = newton_step(der, free=bb)
        x, L = x + dx + lam * x, L * (1 + lam)
    assert res < 1e-13
    v = np.random.default_rng(1).standard_normal(x.shape) * bb[:, None]
    r0, r1 = [], []
    for delta in 1e-3 / 2.0 ** np.arange(5):
        xd, Ld = x + delta * v, L * (1 + delta)
        der, res0 = residual(xd, Ld)
        dx, lam = newton_step(der, free=bb)
        r0.append(res0)
        r1.append(residual(xd + dx + lam * xd, Ld * (1 + lam))[1])
    order = np.polyfit(np.log(r0), np.log(r1), 1)[0]
    assert order == pytest.approx(2.0, abs=0.1)
