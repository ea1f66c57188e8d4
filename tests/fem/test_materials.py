"""The continuum test materials: P = dW/dF and A = dP/dF by central differences, major symmetry."""

import numpy as np
import pytest
from fem_helpers import random_F

from gransim.errors import InputError
from gransim.fem import NeoHookean, lame


def test_stress_and_tangent_are_derivatives(continuum):
    rng = np.random.default_rng(1)
    F = random_F(rng, 6, 0.2)
    res = continuum.evaluate(F)
    h = 1e-6
    P_fd = np.zeros_like(F)
    A_fd = np.zeros((6, 2, 2, 2, 2))
    for k in range(2):
        for L in range(2):
            d = np.zeros((2, 2))
            d[k, L] = h
            rp, rm = continuum.evaluate(F + d), continuum.evaluate(F - d)
            P_fd[:, k, L] = (rp.energy - rm.energy) / (2 * h)
            A_fd[:, :, :, k, L] = (rp.piola - rm.piola) / (2 * h)
    # central differences with h = 1e-6 on O(1e7) Pa values: truncation ~1e-12, round-off ~1e-9 relative
    assert np.max(np.abs(P_fd - res.piola)) < 1e-6 * np.max(np.abs(res.piola))
    assert np.max(np.abs(A_fd - res.tangent)) < 1e-6 * np.max(np.abs(res.tangent))
    assert np.allclose(res.tangent, res.tangent.transpose(0, 3, 4, 1, 2), rtol=0, atol=1e-9 * np.abs(res.tangent).max())


def test_small_strain_limit_is_isotropic_hooke(continuum):
    lam, mu = lame(3.0e7, 0.3)
    A0 = continuum.evaluate(np.eye(2)[None]).tangent[0]
    d = np.eye(2)
    C = lam * np.einsum("ij,kl->ijkl", d, d) + mu * (np.einsum("ik,jl->ijkl", d, d) + np.einsum("il,jk->ijkl", d, d))
    assert np.allclose(A0, C, rtol=1e-14, atol=1e-14 * lam)
    assert np.allclose(continuum.evaluate(np.eye(2)[None]).piola, 0.0)


def test_bad_inputs():
    m = NeoHookean(*lame(1e7, 0.3))
    with pytest.raises(InputError, match="det F"):
        m.evaluate(np.array([[[1.0, 0.0], [0.0, -1.0]]]))
    with pytest.raises(InputError, match=r"\(G, 2, 2\)"):
        m.evaluate(np.eye(2))
    with pytest.raises(InputError, match="Poisson"):
        lame(1e7, 0.5)
