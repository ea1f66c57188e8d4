"""gransim's Taylor stress and the material part of its tangent against YADE's, state by state.

YADE (:mod:`reference_runs.yade.taylor`) gives per state, in a periodic cell of z size ``z``:
``getStress()`` and the stress and 6 x 6 tangent of ``getStressAndTangent()``, all divided by the
3D volume det(hSize) = z det F V (docs/yade.md), and every real interaction (ids, ``cellDist``).
gransim (:class:`gransim.rve.TaylorMaterial`, Meier, Steinmann & Kuhl, "Towards completeness, a
multiscale approach of confined particulate systems" (2007), eqs 10-12) gives the Cauchy stress
sigma and the tangent A_iJkL = dP_iJ/dF_kL = 1/V sum [a n_i n_k + b delta_ik] L_J L_L with, for
the linear normal law, a = kn (r_i + r_j)/d = kn + kn eps/d and b = -kn eps/d (eq 12).

YADE's tangent is the contact-stiffness sum of Kruyt and Rothenburg in the current configuration
(YADE's pkg/dem/Shop_02.cpp, ``Shop::getStressAndTangent``; docs/yade.md),
D = 1/v sum kn sym(n (x) l) sym(n (x) l) (ks = 0 here), with no geometric term and no eps/d
term. So gransim's side is the material part with its eps/d terms removed,

    K_iJkL = A_iJkL - 1/V sum (kn eps/d)(n_i n_k - delta_ik) L_J L_L = 1/V sum kn n_i n_k L_J L_L,

pushed forward, k_ijkl = F_jJ F_lL K_iJkL / det F = 1/(det F V) sum kn n_i l_j n_k l_l, and
symmetrised in (i, j) and (k, l); in YADE's Voigt order (xx, yy, zz, yz, xz, xy, tensor shear
components) its rows and columns 0, 1, 5 are z D. YADE fills the upper triangle only (its
``symmetry`` argument is ignored), so the upper triangles are compared and the lower one of YADE's
must be zero, as must every z row and column (disks).

:func:`compare_yade_taylor` returns per state: the contacts of each side without a partner on the
other (by particle pair and image), and the relative differences (scale: gransim's largest entry)
of both YADE stresses and of the tangent; it refuses (:class:`reference_runs.judge.JudgeError`)
NaN or inf on either side and a run without states, so that no number it returns can pass on
missing evidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gransim.rve.taylor import TaylorMaterial, contact_state

from ..decks.taylor import _wrapped_reference
from ..judge import NoEvidenceError, max_rel_diff, require_finite

#: tolerance of YADE's stresses against gransim's (relative to gransim's largest entry per state)
STRESS_RTOL = 1e-10
STRESS_REASON = (
    "both codes sum kn eps n (x) l over the same contacts of the same centres; eps = r_i + r_j - d "
    "cancels (d/eps up to 4e7, 7e4 on average, at the reference state of the standard RVEs, mean overlap "
    "2.7e-4 D), so a rounding of the branch vector at u (|x_i| + |x_j| + d), as the two codes form it in "
    "different orders, moves the stress by at most 3.2e-11 of its largest entry (that first-order bound "
    "summed over the contacts, u = 2^-53, worst over the 15 RVEs at every 5th state); measured 1.4e-13. "
    "1e-10 covers the bound and is 10^4 below what the weakest contact of a state contributes (>= 1e-6)"
)
#: tolerance of YADE's tangent against the material part of gransim's (relative to its largest entry)
TANGENT_RTOL = 1e-12
TANGENT_REASON = (
    "YADE's kn sym(n l) sym(n l) has no overlap in it; gransim's material part minus its eps/d terms "
    "carries their rounding, kn u |x|/d per contact (|x|/d <= 60 on the 700-disk RVEs: < 1e-14 of kn), "
    "and two sums of <= 1605 terms in different orders (<= 1605 u = 1.8e-13 of the largest entry); "
    "measured 4.8e-15 on the 15 RVEs. 1e-12 covers both and is 10^8 below one contact (>= 1/1605)"
)
STRUCTURE_REASON = (
    "disks have no z component, and YADE sums the upper triangle only (Shop_02.cpp): every z row and "
    "column and the lower triangle of YADE's tangent are exactly 0"
)
CONTACT_REASON = (
    "both codes test the same centres for r_i + r_j - d > 0: the same pairs and images (YADE's cellDist "
    "of body 2 is gransim's image of j), none unmatched on either side"
)

#: YADE's Voigt rows of the in-plane components xx, yy, xy, and those pairs of indices
VOIGT_ROWS = (0, 1, 5)
VOIGT_2D = ((0, 0), (1, 1), (0, 1))
#: YADE's Voigt rows with a z index (yz, xz, zz): zero for disks
Z_ROWS = (2, 3, 4)


@dataclass(frozen=True, eq=False)
class YadeTaylorComparison:
    """gransim against YADE on every state of one packing's Taylor job.

    Attributes
    ----------
    name : the packing. states : the job's state list ``{index, path, k, F}``.
    n_gransim, n_yade : (T,) contacts of each side.
    unmatched_gransim, unmatched_yade : (T,) contacts of one side that the other lacks
        (pair i < j and image of j, :func:`wrap_offsets`).
    stress : (T,) max |z getStress - sigma| / max |sigma| over the in-plane entries (sigma:
        gransim's Cauchy stress, N/m).
    stress_tangent_call : (T,) the same for the stress of ``getStressAndTangent``.
    tangent : (T,) max over the upper triangle |z D - k| / max |k| (k: gransim's material part,
        pushed forward, in Voigt form).
    structure : (T,) largest |entry| of z D that must be zero (z rows and columns, lower
        triangle), relative to max |k|.
    """

    name: str
    states: tuple
    n_gransim: np.ndarray
    n_yade: np.ndarray
    unmatched_gransim: np.ndarray
    unmatched_yade: np.ndarray
    stress: np.ndarray
    stress_tangent_call: np.ndarray
    tangent: np.ndarray
    structure: np.ndarray

    @property
    def contacts_match(self) -> bool:
        """Both sides have the same contacts in every state (and at least one state)."""
        return (
            len(self.states) > 0
            and not self.unmatched_gransim.any()
            and not self.unmatched_yade.any()
            and bool(np.all(self.n_gransim == self.n_yade))
        )


def material_tangent_voigt(packing, F, kn: float, tangent, contacts=None) -> np.ndarray:
    """gransim's Taylor tangent without its eps/d terms, pushed forward, in YADE's Voigt form.

    ``tangent``: (2, 2, 2, 2) A_iJkL of gransim at ``F`` (N/m); ``contacts``: its
    :func:`gransim.rve.taylor.contact_state` at ``F`` (computed when None). Returns the (3, 3)
    matrix of k_ijkl (N/m) in the rows and columns xx, yy, xy, symmetrised in (i, j) and (k, l)
    (the module doc: K = A - 1/V sum (kn eps/d)(n n - I) L L, k = F F K / det F).
    """
    F = np.asarray(F, float)
    cs = contact_state(packing, F, kn) if contacts is None else contacts
    V = abs(float(np.linalg.det(packing.cell)))
    d = np.linalg.norm(cs.branch, axis=1)
    n = cs.branch / d[:, None]
    L = cs.reference_branch
    w = kn * cs.overlap / d
    nn_minus_I = n[:, :, None] * n[:, None, :] - np.eye(2)[None]
    K = np.asarray(tangent, float) - np.einsum("c,cik,cJ,cL->iJkL", w, nn_minus_I, L, L) / V
    k = np.einsum("jJ,lL,iJkL->ijkl", F, F, K) / np.linalg.det(F)
    return np.array(
        [
            [0.25 * (k[i, j, p, q] + k[j, i, p, q] + k[i, j, q, p] + k[j, i, q, p]) for (p, q) in VOIGT_2D]
            for (i, j) in VOIGT_2D
        ]
    )


def _pairs(i, j, shift) -> set:
    return {(int(a), int(b), int(s[0]), int(s[1])) for a, b, s in zip(i, j, shift)}


def wrap_offsets(packing) -> np.ndarray:
    """(N, 2) integers m with X_wrapped = X + C m: YADE gets the centres wrapped into the reference
    cell (:func:`reference_runs.decks.taylor._wrapped_reference`), gransim keeps the packing's own
    X, so gransim's image n of j is YADE's ``cellDist`` n + m_i - m_j."""
    _, Xw = _wrapped_reference(packing)
    m = np.linalg.solve(packing.cell, (Xw - packing.positions).T).T
    return np.rint(m).astype(np.int64)


def compare_yade_taylor(run, material: TaylorMaterial | None = None) -> YadeTaylorComparison:
    """Compare a :class:`reference_runs.yade.taylor.YadeTaylorRun` with gransim (module doc).

    ``material``: gransim's :class:`TaylorMaterial` of the run's packing and kn (built when None).
    Raises :class:`reference_runs.judge.JudgeError` naming the state and the side when an entry
    is NaN or inf, :class:`~reference_runs.judge.NoEvidenceError` for a run without states.
    """
    T = len(run.states)
    name = run.job_dir.name
    if T == 0 or len(run.raw) != T:
        raise NoEvidenceError(f"YADE Taylor states of {name}: {len(run.raw)} read for {T} asked")
    mat = TaylorMaterial(run.packing, run.kn) if material is None else material
    ours = mat.evaluate(np.asarray(run.F, float))
    m = wrap_offsets(run.packing)
    out = {k: np.zeros(T) for k in ("stress", "stress_t", "tangent", "structure")}
    n_g, n_y, un_g, un_y = (np.zeros(T, np.int64) for _ in range(4))
    for t, (st, raw, F) in enumerate(zip(run.states, run.raw, run.F)):
        where = f"state {t} ({st['path']}, k = {st['k']}) of {name}"
        cs = contact_state(run.packing, F, run.kn)
        g_pairs = _pairs(cs.i, cs.j, cs.shift + m[cs.i] - m[cs.j])
        y_pairs = _pairs(raw.ids[:, 0], raw.ids[:, 1], raw.cell_dist[:, :2])
        n_g[t], n_y[t] = len(cs), raw.n_contacts
        un_g[t], un_y[t] = len(g_pairs - y_pairs), len(y_pairs - g_pairs)
        sigma = require_finite(ours.cauchy[t], f"Cauchy stress {where}", "gransim")
        sides = ("YADE", "gransim")
        out["stress"][t] = max_rel_diff(run.cauchy[t], sigma, f"getStress {where}", sides)
        out["stress_t"][t] = max_rel_diff(
            raw.stress_t[:2, :2] * run.z, sigma, f"getStressAndTangent stress {where}", sides
        )
        want = material_tangent_voigt(run.packing, F, run.kn, ours.tangent[t], cs)
        D = require_finite(run.tangent[t], f"getStressAndTangent tangent {where}", "YADE")
        got = D[np.ix_(VOIGT_ROWS, VOIGT_ROWS)]
        up = np.triu_indices(3)
        out["tangent"][t] = max_rel_diff(got[up], want[up], f"tangent {where}", sides, scale=np.abs(want).max())
        zero = np.concatenate([D[list(Z_ROWS)].ravel(), D[:, list(Z_ROWS)].ravel(), got[np.tril_indices(3, -1)]])
        out["structure"][t] = float(np.abs(zero).max()) / float(np.abs(want).max())
    return YadeTaylorComparison(
        name,
        tuple(run.states),
        n_g,
        n_y,
        un_g,
        un_y,
        out["stress"],
        out["stress_t"],
        out["tangent"],
        out["structure"],
    )


__all__ = [
    "CONTACT_REASON",
    "STRESS_REASON",
    "STRESS_RTOL",
    "STRUCTURE_REASON",
    "TANGENT_REASON",
    "TANGENT_RTOL",
    "VOIGT_2D",
    "VOIGT_ROWS",
    "YadeTaylorComparison",
    "compare_yade_taylor",
    "material_tangent_voigt",
    "wrap_offsets",
]
