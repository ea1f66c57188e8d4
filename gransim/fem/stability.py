"""Is the slope's reference state stable with a given RVE material? (why the relaxed slope stops)

Two measures, both at the reference state F = 1 where every Gauss point holds the same RVE (so one
RVE evaluation serves all of them):

* :func:`rve_shear_stiffness`: the RVE's stiffness in pure shear, mu = D:A:D with
  D = (e1 x e2 + e2 x e1) / 2 (N/m), from the tangent A (Meier, Steinmann & Kuhl 2007, "Towards
  completeness: a multiscale approach of confined particulate systems", eq 12 for the Taylor RVE;
  the condensed tangent of docs/relaxed.md (R5) for the relaxed one), checked against the energy's
  second difference, an independent measure that needs no tangent (central:
  [W(1 + g D) + W(1 - g D) - 2 W(1)] / g^2, error O(g^2 / eps^2) with
  eps the overlap strain, ~1e-5 at g = 1e-6). mu <= 0 means the relaxed packing offers no
  resistance to shear at F = 1.
* :func:`reference_stability`: the reduced FE tangent K(0) of the slope (Q1 mesh, supports and
  footing of :func:`gransim.fem.slope.slope_problem`) with that RVE's A(F = 1) at every Gauss
  point: its negative eigenvalues (dense symmetric eigensolver; 749 unknowns on the 20 x 19 mesh)
  and the linear dead-load solution q = -K(0)^-1 r(0): its largest displacement and the
  shear strains (Mohr radius of the symmetric strain, sqrt(((E11 - E22) / 2)^2 + E12^2)) it asks
  of the RVEs, to set beside the RVE's overlap strain. A K(0) with negative eigenvalues has no
  stable equilibrium near the reference state: Newton's first iterates under the dead load then
  leave every RVE's elastic range.
"""

from __future__ import annotations

import numpy as np

from ..contacts import find_neighbours
from .materials import MaterialResult, RVEMaterial
from .slope import NORMAL_STIFFNESS, setup_for, slope_problem

#: pure shear direction D (F = 1 + g D, g the engineering shear strain)
SHEAR = np.array([[0.0, 0.5], [0.5, 0.0]])


def mean_overlap_strain(packing) -> float:
    """Mean overlap eps / (r_i + r_j) of the packing's active contacts at F = 1 (1)."""
    nl = find_neighbours(packing.positions, packing.radii, packing.cell, 0.0)
    c = packing.radii[nl.i] + packing.radii[nl.j]
    eps = c - np.linalg.norm(nl.branch, axis=1)
    on = eps > 0
    return float(np.mean(eps[on] / c[on])) if on.any() else 0.0


def rve_shear_stiffness(packing, rve: str = "relaxed", gamma: float = 1e-6, kn: float = NORMAL_STIFFNESS) -> dict:
    """mu = D:A:D (N/m) of one RVE at F = 1 and the energy's second difference at shear ``gamma``.

    ``rve``: ``taylor`` or ``relaxed`` (stateless, from w = 0 at F = 1, then warm from that
    minimum at F = 1 +- gamma D); the second difference is central. Returns {"tangent",
    "second_difference", "relative_difference", "pressure" (-tr P / 2, N/m), "n_held" (relaxed:
    rattlers held at the sheared states)}.
    """
    from ..rve import RelaxedMaterial, TaylorMaterial  # noqa: PLC0415 - start-up: numba

    Fp, Fm = np.eye(2) + gamma * SHEAR, np.eye(2) - gamma * SHEAR
    if rve == "relaxed":
        m = RelaxedMaterial(packing, kn)
        r0 = m(np.eye(2))
        rp, rm = m(Fp, start=r0), m(Fm, start=r0)
        W0, P0, A, Wp, Wm, held = r0.energy, r0.piola, r0.tangent, rp.energy, rm.energy, max(rp.n_held, rm.n_held)
    else:
        b = TaylorMaterial(packing, kn).evaluate(np.stack([np.eye(2), Fp, Fm]))
        W0, P0, A, Wp, Wm, held = b.energy[0], b.piola[0], b.tangent[0], b.energy[1], b.energy[2], 0
    mu = float(np.einsum("ij,ijkl,kl", SHEAR, np.asarray(A), SHEAR))
    second = float((Wp + Wm - 2.0 * W0) / gamma**2)
    return {
        "tangent": mu,
        "second_difference": second,
        "relative_difference": abs(second - mu) / max(abs(mu), 1e-300),
        "pressure": float(-0.5 * np.trace(np.asarray(P0))),
        "n_held": int(held),
    }


class _Uniform:
    """The response at F = 1 of one RVE, the same at every Gauss point (K(0) needs nothing else)."""

    def __init__(self, material):
        self.r = material.evaluate(np.eye(2)[None])

    def evaluate(self, F):
        def b(a):
            a = np.atleast_1d(np.asarray(a))
            return np.broadcast_to(a[0], (len(F),) + a.shape[1:]).copy()

        r = self.r
        return MaterialResult(
            piola=b(r.piola), tangent=b(r.tangent), cauchy=b(r.cauchy), energy=b(r.energy), n_contacts=b(r.n_contacts)
        )


def reference_stability(packing, rve: str = "relaxed", protocol: str = "service", geometry=None) -> dict:
    """K(0) of the slope with ``packing``'s RVE (``taylor`` or ``relaxed``) at every Gauss point:
    {"n_unknowns", "n_negative" (eigenvalues < 0), "smallest" (3 smallest eigenvalues, N/m^2 per m),
    "max_displacement" (m), "shear_max", "shear_median" (Mohr radius of the linear dead-load strain),
    "volumetric" (min, max of tr E)}."""
    import scipy.sparse.linalg as spla  # noqa: PLC0415 - start-up: scipy

    from ..rve import RelaxedMaterial, TaylorMaterial  # noqa: PLC0415 - start-up: numba

    cls = RelaxedMaterial if rve == "relaxed" else TaylorMaterial
    setup = setup_for(protocol, geometry)
    prob = slope_problem(_Uniform(RVEMaterial(cls(packing, NORMAL_STIFFNESS))), setup)
    r, K, *_ = prob.evaluate(np.zeros(prob.dofs.n_reduced), (1.0, 0.0))
    Kd = K.toarray()
    ev = np.linalg.eigvalsh(0.5 * (Kd + Kd.T))
    q = -spla.spsolve(K, r)
    u = prob.dofs.displacement(q)
    F = prob.geometry.deformation_gradient(u)
    E = 0.5 * (F + np.swapaxes(F, 1, 2)) - np.eye(2)
    shear = np.sqrt(0.25 * (E[:, 0, 0] - E[:, 1, 1]) ** 2 + E[:, 0, 1] ** 2)
    vol = E[:, 0, 0] + E[:, 1, 1]
    return {
        "n_unknowns": int(len(ev)),
        "n_negative": int((ev < 0).sum()),
        "smallest": [float(v) for v in ev[:3]],
        "max_displacement": float(np.abs(u).max()),
        "shear_max": float(shear.max()),
        "shear_median": float(np.median(shear)),
        "volumetric": (float(vol.min()), float(vol.max())),
    }


__all__ = ["SHEAR", "mean_overlap_strain", "reference_stability", "rve_shear_stiffness"]
