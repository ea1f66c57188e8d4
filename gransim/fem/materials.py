"""The batched material interface of the FE solver and two hyperelastic test materials.

A material is any object with ``evaluate(F) -> MaterialResult`` taking the deformation gradients of
all Gauss points at once, F (G, 2, 2), and returning (G = number of Gauss points)

* ``piola``   (G, 2, 2)        first Piola stress P (Pa = N/m^2 for unit thickness),
* ``tangent`` (G, 2, 2, 2, 2)  A[g, i, J, k, L] = dP_iJ / dF_kL (Pa),
* ``cauchy``  (G, 2, 2)        sigma = P F^T / det F (Pa),
* ``energy``  (G,)             strain energy per reference area (J/m^2 per m of thickness),
* ``n_contacts`` (G,) int      active contacts (the Taylor RVE; continuum materials report -1).

The real material is :class:`gransim.rve.TaylorMaterial` (Meier et al. eqs 6-12). The two
continuum materials here exist for the element tests (patch test, stiffness check, Newton rate,
linear elastic limit): both are plane-strain hyperelastic with P(1) = 0 and the isotropic
small-strain tangent C = lam 1 (x) 1 + 2 mu I_sym at F = 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import paper
from .._validate import as_positive_float
from ..errors import InputError
from ..paper import stress_2d_to_pa, tangent_2d_to_pa

_I2 = np.eye(2)

#: the RVE materials of the FE2 slope (``--rve``): the affine Taylor RVE and the relaxed RVE (here, not
#: in gransim.fem.run, so that ``gransim slope`` checks its options without importing the run's modules)
RVE_KINDS = ("taylor", "relaxed")


@dataclass(frozen=True, eq=False)
class MaterialResult:
    """Batched constitutive response (see module docstring for shapes and units)."""

    piola: np.ndarray
    tangent: np.ndarray
    cauchy: np.ndarray
    energy: np.ndarray
    n_contacts: np.ndarray


def _check_F(F) -> tuple[np.ndarray, np.ndarray]:
    F = np.asarray(F, dtype=float)
    if F.ndim != 3 or F.shape[1:] != (2, 2):
        raise InputError(f"F: expected shape (G, 2, 2), got {F.shape}")
    J = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
    if not np.all(np.isfinite(J)) or np.any(J <= 0):
        g = int(np.argmax(~(J > 0)))
        raise InputError(f"F: det F must be > 0 at every Gauss point, got {J[g]!r} at point {g}")
    return F, J


def _cauchy(P, F, J):
    return np.einsum("giJ,gkJ->gik", P, F) / J[:, None, None]


def lame(E: float, nu: float) -> tuple[float, float]:
    """Plane-strain Lame constants (lam, mu) from Young's modulus E (Pa) and Poisson's ratio nu."""
    E = as_positive_float(E, "E")
    if not -1.0 < nu < 0.5:
        raise InputError(f"nu: Poisson's ratio must lie in (-1, 0.5), got {nu!r}")
    return E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))


@dataclass(frozen=True)
class NeoHookean:
    """Compressible neo-Hookean, W = mu/2 (tr C - 2) - mu ln J + lam/2 (ln J)^2 (plane strain).

    P = mu (F - F^-T) + lam ln J F^-T;
    A_iJkL = mu d_ik d_JL + (mu - lam ln J) Finv_Jk Finv_Li + lam Finv_Ji Finv_Lk.
    """

    lam: float
    mu: float

    def evaluate(self, F) -> MaterialResult:
        """Batched P, A, sigma, W for F (G, 2, 2)."""
        F, J = _check_F(F)
        Fi = np.linalg.inv(F)  # Finv[g, J, i]
        FiT = np.swapaxes(Fi, 1, 2)
        lnJ = np.log(J)
        P = self.mu * (F - FiT) + (self.lam * lnJ)[:, None, None] * FiT
        A = (
            self.mu * np.einsum("ik,JL->iJkL", _I2, _I2)[None]
            + (self.mu - self.lam * lnJ)[:, None, None, None, None] * np.einsum("gJk,gLi->giJkL", Fi, Fi)
            + self.lam * np.einsum("gJi,gLk->giJkL", Fi, Fi)
        )
        W = 0.5 * self.mu * (np.einsum("giJ,giJ->g", F, F) - 2) - self.mu * lnJ + 0.5 * self.lam * lnJ**2
        return MaterialResult(P, A, _cauchy(P, F, J), W, np.full(len(F), -1, dtype=np.int64))


@dataclass(frozen=True)
class StVenantKirchhoff:
    """St Venant-Kirchhoff, W = lam/2 (tr E)^2 + mu E:E with E = (F^T F - 1)/2 (plane strain).

    S = lam tr E 1 + 2 mu E; P = F S;
    A_iJkL = d_ik S_JL + F_iM C_MJNL F_kN with C_MJNL = lam d_MJ d_NL + mu (d_MN d_JL + d_ML d_JN).
    """

    lam: float
    mu: float

    def evaluate(self, F) -> MaterialResult:
        """Batched P, A, sigma, W for F (G, 2, 2)."""
        F, J = _check_F(F)
        E = 0.5 * (np.einsum("gkI,gkJ->gIJ", F, F) - _I2)
        trE = E[:, 0, 0] + E[:, 1, 1]
        S = self.lam * trE[:, None, None] * _I2 + 2 * self.mu * E
        P = np.einsum("giM,gMJ->giJ", F, S)
        C = self.lam * np.einsum("MJ,NL->MJNL", _I2, _I2) + self.mu * (
            np.einsum("MN,JL->MJNL", _I2, _I2) + np.einsum("ML,JN->MJNL", _I2, _I2)
        )
        A = np.einsum("ik,gJL->giJkL", _I2, S) + np.einsum("giM,MJNL,gkN->giJkL", F, C, F)
        W = 0.5 * self.lam * trE**2 + self.mu * np.einsum("gIJ,gIJ->g", E, E)
        return MaterialResult(P, A, _cauchy(P, F, J), W, np.full(len(F), -1, dtype=np.int64))


class AssignedRVEs:
    """Several RVEs of one Taylor or relaxed material assigned to the Gauss points: ``rve_index[g]`` (G,) int.

    ``evaluate(F)`` forwards to ``material.evaluate(F, rve_index)`` (one batched kernel call);
    e.g. ``AssignedRVEs(TaylorMaterial(five_packings, E_n), np.arange(G) % 5)`` assigns the five
    RVEs in turn.
    """

    def __init__(self, material, rve_index):
        self.material = material
        self.rve_index = np.ascontiguousarray(rve_index, dtype=np.int64)

    @property
    def packings(self):
        """The RVEs' reference packings."""
        return self.material.packings

    @property
    def normal_stiffness(self) -> float:
        """E_n of the contact law."""
        return self.material.normal_stiffness

    def evaluate(self, F):
        """Batched response at all Gauss points."""
        if len(F) != self.rve_index.size:
            raise InputError(f"F: expected {self.rve_index.size} Gauss points (one per RVE index), got {len(F)}")
        return self.material.evaluate(F, self.rve_index)

    def commit(self) -> None:
        """Commit the wrapped material's Gauss-point history (no-op for a history-free material)."""
        fn = getattr(self.material, "commit", None)
        if callable(fn):
            fn()

    def revert(self) -> None:
        """Revert the wrapped material's trial history (no-op for a history-free material)."""
        fn = getattr(self.material, "revert", None)
        if callable(fn):
            fn()

    def committed_fluctuation(self, g: int):
        """The committed fluctuation (N, 2) of Gauss point g, or None (Taylor: always None)."""
        fn = getattr(self.material, "committed_fluctuation", None)
        return fn(g) if callable(fn) else None


class RVEMaterial:
    """The one place an RVE material enters the FE code: its 2D response converted to plane-strain Pa.

    The RVE codes (:class:`gransim.rve.TaylorMaterial`, :class:`gransim.rve.RelaxedMaterial`,
    optionally wrapped by :class:`AssignedRVEs` or evaluated on a cluster by
    :class:`gransim.parallel.DistributedMaterial`) give the 2D first Piola stress and tangent per
    unit out-of-plane thickness (N/m) and the energy per reference area (J/m^2); the FE code works
    in Pa and J/m^3. ``evaluate`` converts with :func:`gransim.paper.stress_2d_to_pa` and
    :func:`gransim.paper.tangent_2d_to_pa` (sigma_Pa = sigma_2D / thickness, :mod:`gransim.paper`)
    and returns a :class:`MaterialResult`. Gauss-point history (``commit`` / ``revert``) and the
    attributes the pictures need (``packings``, ``normal_stiffness``, ``rve_index``,
    ``committed_fluctuation``) are forwarded to the wrapped RVE material ``rve``.
    """

    def __init__(self, rve, thickness: float | None = None):
        self.rve = rve
        self.thickness = paper.THICKNESS if thickness is None else as_positive_float(thickness, "thickness")

    @property
    def packings(self):
        """The RVEs' reference packings."""
        return self.rve.packings

    @property
    def normal_stiffness(self) -> float:
        """kn of the RVE contact law (N/m)."""
        return self.rve.normal_stiffness

    @property
    def rve_index(self):
        """RVE index per Gauss point (G,) when several RVEs are assigned, else None."""
        return getattr(self.rve, "rve_index", None)

    @property
    def has_history(self) -> bool:
        """True when the wrapped RVE keeps Gauss-point history (the relaxed RVE)."""
        m = getattr(self.rve, "template", self.rve)
        m = getattr(m, "material", m)
        return callable(getattr(m, "commit", None))

    def evaluate(self, F) -> MaterialResult:
        """Batched response in Pa (piola (G,2,2), tangent (G,2,2,2,2), cauchy (G,2,2)), J/m^3, contacts."""
        b = self.rve.evaluate(F)
        t = self.thickness
        return MaterialResult(
            piola=stress_2d_to_pa(b.piola, t),
            tangent=tangent_2d_to_pa(b.tangent, t),
            cauchy=stress_2d_to_pa(b.cauchy, t),
            energy=np.asarray(b.energy, float) / t,
            n_contacts=np.asarray(b.n_contacts),
        )

    def commit(self) -> None:
        """Commit the RVE's Gauss-point history (no-op for a history-free RVE)."""
        fn = getattr(self.rve, "commit", None)
        if callable(fn):
            fn()

    def revert(self) -> None:
        """Revert the RVE's trial history (no-op for a history-free RVE)."""
        fn = getattr(self.rve, "revert", None)
        if callable(fn):
            fn()

    def committed_fluctuation(self, g: int):
        """The committed fluctuation (N, 2) (m) of Gauss point g, or None (Taylor: always None)."""
        fn = getattr(self.rve, "committed_fluctuation", None)
        return fn(g) if callable(fn) else None
