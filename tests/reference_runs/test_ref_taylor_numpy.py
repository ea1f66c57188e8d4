"""The independent numpy Taylor stress: exact cases, energy derivative, Meier's two forms."""

import numpy as np
import pytest

from gransim.errors import InputError
from gransim.geometry import Packing
from reference_runs.demo_packings import perturbed_lattice
from reference_runs.taylor_numpy import candidate_pairs, taylor_stress_numpy

KN = 2.8e7


def two_disks(d=1.0e-3, r=0.55e-3, L=4e-3, angle=0.0):
    c = np.array([L / 2, L / 2])
    e = np.array([np.cos(angle), np.sin(angle)])
    return Packing(np.array([c - 0.5 * d * e, c + 0.5 * d * e]), np.array([r, r]), np.diag([L, L]))


@pytest.mark.parametrize("angle", [0.0, 0.3, 1.2])
def test_two_disks_exact(angle):
    d, r, L = 1.0e-3, 0.55e-3, 4e-3
    res = taylor_stress_numpy(two_disks(d, r, L, angle), np.eye(2), KN)
    n = np.array([np.cos(angle), np.sin(angle)])
    delta = 2 * r - d
    # one contact: sigma = (1/A) f (x) l with f = -kn delta n (on i), l = d n: compressive
    assert res.n_contacts == 1
    assert np.allclose(res.cauchy, -KN * delta * d * np.outer(n, n) / L**2, rtol=1e-12, atol=0)


def test_two_disks_across_the_boundary():
    # the same pair split by the periodic boundary gives the same stress
    L, r, d = 4e-3, 0.55e-3, 1.0e-3
    p = Packing(np.array([[0.2e-3, 2e-3], [0.2e-3 - d, 2e-3]]), np.array([r, r]), np.diag([L, L]))
    res = taylor_stress_numpy(p, np.eye(2), KN)
    assert res.n_contacts == 1 and res.shift.tolist() in ([[-1, 0]], [[1, 0]])
    assert np.isclose(res.cauchy[0, 0], -KN * (2 * r - d) * d / L**2, rtol=1e-12)


def _energy(p, F, cand):
    res = taylor_stress_numpy(p, F, KN, cand)
    return 0.5 * KN * np.sum(res.overlap**2) / p.area


def test_piola_is_energy_derivative():
    p = perturbed_lattice(8, 8, seed=5)
    cand = candidate_pairs(p, 0.8)
    rng = np.random.default_rng(0)
    F = np.eye(2) + 0.05 * rng.standard_normal((2, 2))
    P = taylor_stress_numpy(p, F, KN, cand).piola
    h = 1e-7
    P_fd = np.zeros((2, 2))
    for a in range(2):
        for b in range(2):
            E = np.zeros((2, 2))
            E[a, b] = h
            P_fd[a, b] = (_energy(p, F + E, cand) - _energy(p, F - E, cand)) / (2 * h)
    # P = dW/dF (Meier, Steinmann & Kuhl 2007, eq 10); central differences, error O(h^2)
    assert np.allclose(P, P_fd, rtol=1e-6, atol=1e-6 * np.abs(P).max())


def test_meier_forms_agree_and_objectivity():
    p = perturbed_lattice(8, 8, seed=6)
    rng = np.random.default_rng(1)
    for _ in range(5):
        F = np.eye(2) + 0.08 * rng.standard_normal((2, 2))
        res = taylor_stress_numpy(p, F, KN)
        assert np.allclose(res.cauchy, res.cauchy_from_piola, rtol=0, atol=1e-12 * np.abs(res.cauchy).max())
        assert np.allclose(res.cauchy, res.cauchy.T, rtol=0, atol=1e-12 * np.abs(res.cauchy).max())
        t = rng.uniform(0, 2 * np.pi)
        Q = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        rot = taylor_stress_numpy(p, Q @ F, KN)
        assert np.allclose(rot.cauchy, Q @ res.cauchy @ Q.T, rtol=0, atol=1e-11 * np.abs(res.cauchy).max())


def test_candidates_cover_all_contacts():
    # brute force over a wider image range (|n| <= 2) finds no extra contact
    p = perturbed_lattice(6, 6, seed=2)
    F = np.array([[0.9, 0.1], [0.0, 1.0]])
    res = taylor_stress_numpy(p, F, KN)
    X = p.wrapped().positions
    x = X @ F.T
    c = F @ p.cell
    count = 0
    for i in range(p.n):
        for j in range(p.n):
            for n1 in range(-2, 3):
                for n2 in range(-2, 3):
                    if i == j and n1 == 0 and n2 == 0:
                        continue
                    l = x[j] + c @ [n1, n2] - x[i]
                    count += np.hypot(*l) < p.radii[i] + p.radii[j]
    assert count == 2 * res.n_contacts


def test_no_overlap_zero_stress():
    p = perturbed_lattice(6, 6, seed=2, r_range=(0.3, 0.4))
    res = taylor_stress_numpy(p, np.eye(2), KN)
    assert res.n_contacts == 0 and np.all(res.cauchy == 0)


def test_bad_input():
    p = perturbed_lattice(6, 6, seed=2)
    with pytest.raises(InputError, match="det F"):
        taylor_stress_numpy(p, [[1, 0], [0, -1]], KN)
    with pytest.raises(InputError, match="det F"):
        taylor_stress_numpy(p, np.eye(3), KN)
    with pytest.raises(InputError, match="kn"):
        taylor_stress_numpy(p, np.eye(2), 0.0)
    with pytest.raises(InputError, match="cell too small"):
        candidate_pairs(perturbed_lattice(4, 4, seed=1, a=1e-3, r_range=(1.5, 1.6)))
