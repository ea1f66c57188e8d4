"""Continuum point laws for :mod:`gransim.fem.material_points` (stand-ins until a DEM RVE plugs in).

* :class:`J2Plasticity`: plane-strain von Mises plasticity with linear isotropic hardening, driven
  by the small-strain increment de = sym(f - 1) (f the step's relative deformation gradient):
  elastic predictor, radial return and the consistent (algorithmic) tangent of Simo & Hughes,
  Computational Inelasticity, 1998, Box 3.2 and eq. 3.3.12 (the stress is not rotated: a
  hypoelastic-plastic law for small increments, like Guo & Zhao's strain-increment RVE calls).
  Its state carries ``updates``, the number of updates that led to it: a state built from a
  trial iterate instead of the committed state shows up there (tests).
* :class:`HyperelasticPoint`: any batched hyperelastic material of :mod:`gransim.fem.materials`
  (``evaluate(F) -> piola, tangent``; e.g. neo-Hookean, or the Taylor RVE behind
  :class:`gransim.fem.materials.RVEMaterial`) as a point law whose state is the total
  deformation gradient F_n: F = f F_n, sigma = P F^T / det F and the exact chain rule
  d sigma_ij / d f_mn = sum_L d sigma_ij / d F_mL (F_n)_nL with
  d sigma_ij / d F_kL = (A_iMkL F_jM + P_iL d_jk) / J - sigma_ij (F^-1)_Lk.

Stress in Pa, tension positive; tangents ``[i, j, k, l] = d sigma_ij / d f_kl`` (Pa).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validate import as_positive_float
from ..errors import InputError

_I3 = np.eye(3)
_SQ23 = np.sqrt(2.0 / 3.0)


@dataclass(frozen=True, eq=False)
class J2State:
    """State of a J2 point: stress (3, 3) (Pa, sigma_zz from plane strain), equivalent plastic
    strain alpha, the point's yield stress (Pa) and the number of updates that led to it."""

    stress: np.ndarray
    alpha: float
    yield_stress: float
    updates: int = 0


@dataclass(frozen=True)
class J2Plasticity:
    """Plane-strain von Mises plasticity, yield ||s|| = sqrt(2/3) (sigma_y + H alpha) (Pa).

    ``initial_stress`` (Pa, isotropic, tension positive, e.g. -1e5 for a specimen consolidated to
    the confining pressure) is the stress of every initial state. The Gauss points ``weak_points``
    yield at ``weak_factor`` times ``yield_stress`` (an imperfection that makes the plastic flow
    heterogeneous).
    """

    youngs_modulus: float
    poisson_ratio: float
    yield_stress: float
    hardening: float = 0.0
    initial_stress: float = 0.0
    weak_points: tuple = ()
    weak_factor: float = 1.0

    def __post_init__(self):
        as_positive_float(self.youngs_modulus, "youngs_modulus")
        as_positive_float(self.yield_stress, "yield_stress")
        as_positive_float(self.hardening, "hardening", allow_zero=True)
        if not -1.0 < self.poisson_ratio < 0.5:
            raise InputError(f"poisson_ratio: must lie in (-1, 0.5), got {self.poisson_ratio!r}")

    @property
    def lame(self) -> tuple[float, float]:
        """(lambda, mu) (Pa)."""
        E, nu = self.youngs_modulus, self.poisson_ratio
        return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))

    def _elastic(self) -> np.ndarray:
        lam, mu = self.lame
        return lam * np.einsum("ij,kl->ijkl", _I3, _I3) + mu * (
            np.einsum("ik,jl->ijkl", _I3, _I3) + np.einsum("il,jk->ijkl", _I3, _I3)
        )

    def initial_state(self, g: int) -> J2State:
        """The initial (isotropic) stress, no plastic strain, the point's yield stress."""
        sy = self.yield_stress * (self.weak_factor if int(g) in self.weak_points else 1.0)
        return J2State(self.initial_stress * _I3.copy(), 0.0, sy, 0)

    def response(self, state: J2State):
        """(in-plane stress, elastic tangent) of a state."""
        return state.stress[:2, :2].copy(), self._elastic()[:2, :2, :2, :2].copy()

    def update(self, f, state: J2State):
        """Radial return from ``state`` for de = sym(f - 1) (plane strain, de_zz = 0)."""
        f = np.asarray(f, dtype=float)
        lam, mu = self.lame
        de = np.zeros((3, 3))
        de[:2, :2] = 0.5 * (f + f.T) - np.eye(2)
        trial = state.stress + lam * np.trace(de) * _I3 + 2 * mu * de
        s = trial - np.trace(trial) / 3 * _I3
        norm = float(np.sqrt(np.sum(s * s)))
        H = self.hardening
        phi = norm - _SQ23 * (state.yield_stress + H * state.alpha)
        C = self._elastic()
        if phi <= 0.0:
            return (
                trial[:2, :2].copy(),
                C[:2, :2, :2, :2].copy(),
                J2State(trial, state.alpha, state.yield_stress, state.updates + 1),
            )
        dgamma = phi / (2 * mu + 2 * H / 3)
        n = s / norm
        stress = trial - 2 * mu * dgamma * n
        theta = 1 - 2 * mu * dgamma / norm
        theta_bar = 1 / (1 + H / (3 * mu)) - (1 - theta)
        kappa = lam + 2 * mu / 3
        Isym = 0.5 * (np.einsum("ik,jl->ijkl", _I3, _I3) + np.einsum("il,jk->ijkl", _I3, _I3))
        one = np.einsum("ij,kl->ijkl", _I3, _I3)
        Cep = kappa * one + 2 * mu * theta * (Isym - one / 3) - 2 * mu * theta_bar * np.einsum("ij,kl->ijkl", n, n)
        return (
            stress[:2, :2].copy(),
            Cep[:2, :2, :2, :2].copy(),
            J2State(stress, state.alpha + _SQ23 * dgamma, state.yield_stress, state.updates + 1),
        )

    def observables(self, state: J2State) -> dict:
        """Equivalent plastic strain and update count."""
        return {"alpha": state.alpha, "updates": float(state.updates)}

    @staticmethod
    def pack_states(states) -> dict:
        """{name: array (G, ...)} of a list of states (checkpoints)."""
        return {
            "stress": np.array([s.stress for s in states]),
            "alpha": np.array([s.alpha for s in states]),
            "yield_stress": np.array([s.yield_stress for s in states]),
            "updates": np.array([s.updates for s in states], dtype=np.int64),
        }

    @staticmethod
    def unpack_states(arrays: dict) -> list:
        """The states of :meth:`pack_states`' arrays."""
        a = arrays
        return [
            J2State(np.array(a["stress"][g]), float(a["alpha"][g]), float(a["yield_stress"][g]), int(a["updates"][g]))
            for g in range(len(a["alpha"]))
        ]


@dataclass(frozen=True, eq=False)
class HyperState:
    """State of a hyperelastic point: its total deformation gradient F (2, 2) and update count."""

    F: np.ndarray
    updates: int = 0


def cauchy_and_tangent(P: np.ndarray, A: np.ndarray, F: np.ndarray, Fn: np.ndarray):
    """sigma (2, 2) and d sigma / d f (2, 2, 2, 2) from P, A = dP/dF at F = f Fn (module docstring)."""
    J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    sigma = P @ F.T / J
    Fi = np.linalg.inv(F)
    dsdF = (np.einsum("iMkL,jM->ijkL", A, F) + np.einsum("iL,jk->ijkL", P, np.eye(2))) / J - np.einsum(
        "ij,Lk->ijkL", sigma, Fi
    )
    return sigma, np.einsum("ijmL,nL->ijmn", dsdF, Fn)


@dataclass(frozen=True, eq=False)
class HyperelasticPoint:
    """A batched hyperelastic material (``evaluate(F)`` with ``piola``, ``tangent`` in Pa) as a point
    law with state F_n; every point starts at ``F0`` (2, 2) (default the identity)."""

    material: object
    F0: np.ndarray = field(default_factory=lambda: np.eye(2))

    def initial_state(self, g: int) -> HyperState:
        """F = F0."""
        return HyperState(np.array(self.F0, dtype=float), 0)

    def _at(self, F, Fn):
        m = self.material.evaluate(np.ascontiguousarray(F[None]))
        return cauchy_and_tangent(np.asarray(m.piola)[0], np.asarray(m.tangent)[0], F, Fn)

    def response(self, state: HyperState):
        """sigma and d sigma / d f at f = 1."""
        return self._at(state.F, state.F)

    def update(self, f, state: HyperState):
        """F = f F_n."""
        F = np.asarray(f, dtype=float) @ state.F
        sigma, tangent = self._at(F, state.F)
        return sigma, tangent, HyperState(F, state.updates + 1)

    def observables(self, state: HyperState) -> dict:
        """det F and the update count."""
        F = state.F
        return {"det_F": float(F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]), "updates": float(state.updates)}

    @staticmethod
    def pack_states(states) -> dict:
        """{name: array (G, ...)} of a list of states (checkpoints)."""
        return {"F": np.array([s.F for s in states]), "updates": np.array([s.updates for s in states], dtype=np.int64)}

    @staticmethod
    def unpack_states(arrays: dict) -> list:
        """The states of :meth:`pack_states`' arrays."""
        return [HyperState(np.array(arrays["F"][g]), int(arrays["updates"][g])) for g in range(len(arrays["updates"]))]


__all__ = ["HyperState", "HyperelasticPoint", "J2Plasticity", "J2State", "cauchy_and_tangent"]
