"""Taylor (affine) homogenization of a periodic disk RVE: Meier, Steinmann & Kuhl, eqs (1)-(12).

Every particle centre and the cell follow the macroscopic deformation gradient F (eq 1),
x_i = F X_i, so a pair (i, j, image n) has the reference branch vector
L_ij = X_j + C n - X_i and the current one l_ij = F L_ij (eq 2). With d = |l_ij|,
n_ij = l_ij / d and the overlap eps_ij = r_i + r_j - d (eq 3), the normal law of
:mod:`gransim.contacts.law` (eqs 4-5) gives, per reference area V_rve = det C_ref,

* energy density (eqs 6-7)       W(F) = 1/V sum_pairs Phi(eps)                              (J/m^2)
* first Piola stress (eqs 9-10)  P_iJ = 1/V sum_pairs f_i L_J,  f = -Phi'(eps) n            (N/m)
* tangent (eqs 11-12)            A_iJkL = dP_iJ/dF_kL
                                        = 1/V sum_pairs [a n_i n_k + b delta_ik] L_J L_L
  with a = Phi''(eps) + Phi'(eps)/d (= E_n (r_i + r_j)/d, the "material" part) and
  b = -Phi'(eps)/d (= -E_n eps/d, the "geometric" part);
* Cauchy stress                  sigma = P F^T / det F                                       (N/m)

Every pair is counted once (the paper's double sum with its factor 1/2). Units are those
of a 2D model: E_n in N/m, so stresses are forces per length (N/m) and W is J/m^2.

**Sign convention: tension positive** (continuum mechanics): a compressed RVE has negative
normal stresses. ``compute pressure`` of LIGGGHTS and of LAMMPS is compression positive, p = -tr(sigma)/2.

**Tangent index convention:** ``A[i, J, k, L] = dP[i, J] / dF[k, L]``; it has the major
symmetry A_iJkL = A_kLiJ (it is the Hessian of W).

Contact candidates (cache rule)
-------------------------------
Contacts are found in the deformed configuration, so the contact set changes with F. A
candidate set is built once for an *anchor* F0 by the periodic cell list: all pairs with
|F0 L| < (1 + f) (r_i + r_j), a skin proportional to each pair's contact distance
(f = ``skin_fraction``; proportional rather than uniform, so that in a polydisperse packing
the small pairs do not carry the skin the largest pair needs). Every pair outside the set
has |F0 L| >= (1 + f)(r_i + r_j), and for any F, with G = F F0^{-1},

    |F L| = |G F0 L| >= sigma_min(G) |F0 L| >= sigma_min(G) (1 + f) (r_i + r_j),

so no pair outside the set can touch at F when

    sigma_min(F F0^{-1}) >= 1 / (1 + f)                    (validity rule)

(tested with a relative safety margin of 1e-12). The set is then reused; otherwise a new
set anchored at F is built (a state may use any cached set the rule accepts). Stretching
never invalidates a set, only compression along some direction does. For F0 = I the rule
implies the displacement bound |(F - I) L| <= f/(1 + f) |L| of every candidate-excluded
pair, and it is sharper than bounding |(F - I) L| by the norm of F - I.

Every set is sorted by (i, j, image shift n). Two sets that cover F differ only in pairs out of
contact at F, which the kernel skips, so they sum the same contacts in the same order: W, P and A
at F are bitwise the same whatever was evaluated before (whichever set the cache picks), in
any batch, block or worker.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .._numba import njit, pjit, prange
from .._validate import as_array, as_positive_float, check_memory, format_bytes
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential, stiffness
from ..contacts.neighbours import bin_layout
from ..errors import InputError, SimulationError
from ..geometry import Packing

#: relative safety margin of the candidate validity rule (round-off in sigma_min)
VALIDITY_MARGIN = 1e-12
#: default skin as a fraction of each pair's contact distance r_i + r_j
DEFAULT_SKIN_FRACTION = 0.1
#: most candidate sets kept per RVE (oldest dropped first)
MAX_SETS_PER_RVE = 32
#: peak bytes per candidate pair of one build: the neighbour list (i, j, shift, branch: 48 B), the
#: shift and filter temporaries (~70 B), the kept set (L, r_i, r_j, i, j, shift: 64 B) and its copy
#: in the flattened arrays (32 B), rounded up
BYTES_PER_CANDIDATE = 300
#: most pair-distance tests of one cell-list scan (about a minute on one core)
MAX_SCAN_TESTS = 5e10


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------
@njit
def _taylor_point(F, L, ri, rj, lo, hi, kn, inv_area, g, W, P, A, nc):
    """W, P, A and the contact count of one deformation F (2, 2) over candidates lo:hi.

    L (M, 2) reference branch vectors, ri/rj (M,) radii; results go to row g of
    W (G,), P (G, 2, 2), A (G, 2, 2, 2, 2), nc (G,).
    """
    f00 = F[0, 0]
    f01 = F[0, 1]
    f10 = F[1, 0]
    f11 = F[1, 1]
    w = 0.0
    p00 = p01 = p10 = p11 = 0.0
    # material part: sum a (n n)_ik (L L)_JL, both symmetric -> 3 x 3 accumulators
    m00_00 = m00_01 = m00_11 = 0.0
    m01_00 = m01_01 = m01_11 = 0.0
    m11_00 = m11_01 = m11_11 = 0.0
    # geometric part: sum b (L L)_JL
    g00 = g01 = g11 = 0.0
    count = 0
    for m in range(lo, hi):
        L0 = L[m, 0]
        L1 = L[m, 1]
        l0 = f00 * L0 + f01 * L1
        l1 = f10 * L0 + f11 * L1
        d2 = l0 * l0 + l1 * l1
        c = ri[m] + rj[m]
        if d2 >= c * c:
            continue
        d = np.sqrt(d2)
        eps = overlap(ri[m], rj[m], d)
        if eps <= 0.0:  # d2 < c^2 but sqrt rounded up to c: not in contact (H(0) = 0)
            continue
        fm = force_magnitude(eps, kn)
        k = stiffness(eps, kn)
        count += 1
        n0 = l0 / d
        n1 = l1 / d
        w += potential(eps, kn)
        p00 -= fm * n0 * L0
        p01 -= fm * n0 * L1
        p10 -= fm * n1 * L0
        p11 -= fm * n1 * L1
        a = k + fm / d
        b = -fm / d
        LL00 = L0 * L0
        LL01 = L0 * L1
        LL11 = L1 * L1
        an00 = a * n0 * n0
        an01 = a * n0 * n1
        an11 = a * n1 * n1
        m00_00 += an00 * LL00
        m00_01 += an00 * LL01
        m00_11 += an00 * LL11
        m01_00 += an01 * LL00
        m01_01 += an01 * LL01
        m01_11 += an01 * LL11
        m11_00 += an11 * LL00
        m11_01 += an11 * LL01
        m11_11 += an11 * LL11
        g00 += b * LL00
        g01 += b * LL01
        g11 += b * LL11
    s = inv_area
    W[g] = w * s
    P[g, 0, 0] = p00 * s
    P[g, 0, 1] = p01 * s
    P[g, 1, 0] = p10 * s
    P[g, 1, 1] = p11 * s
    nn = (
        (m00_00, m00_01, m00_11),
        (m01_00, m01_01, m01_11),
        (m01_00, m01_01, m01_11),
        (m11_00, m11_01, m11_11),
    )
    gg = (g00, g01, g11)
    for i in range(2):
        for k in range(2):
            row = nn[2 * i + k]
            for J in range(2):
                for Lx in range(2):
                    q = J + Lx  # 0: (0,0), 1: (0,1)/(1,0), 2: (1,1)
                    v = row[q]
                    if i == k:
                        v += gg[q]
                    A[g, i, J, k, Lx] = v * s
    nc[g] = count


@njit
def _taylor_single(F, L, ri, rj, lo, hi, kn, inv_area):
    """One state: returns (W (1,), P (1, 2, 2), A (1, 2, 2, 2, 2), nc (1,), sigma (2, 2))."""
    W = np.empty(1)
    P = np.empty((1, 2, 2))
    A = np.empty((1, 2, 2, 2, 2))
    nc = np.empty(1, np.int64)
    _taylor_point(F, L, ri, rj, lo, hi, kn, inv_area, 0, W, P, A, nc)
    J = F[0, 0] * F[1, 1] - F[0, 1] * F[1, 0]
    sig = np.empty((2, 2))
    for i in range(2):
        for k in range(2):
            sig[i, k] = (P[0, i, 0] * F[k, 0] + P[0, i, 1] * F[k, 1]) / J
    return W, P, A, nc, sig


#: states evaluated together by one pass over their shared candidate set (:func:`_taylor_block`)
LANES = 8


@njit
def _taylor_block(F, gs, L, ri, rj, lo, hi, kn, inv_area, W, P, A, nc):
    """:func:`_taylor_point` for up to LANES states gs (n,) sharing the candidates lo:hi, in one pass.

    The loop over the states inside the loop over the candidates has no dependence between its
    iterations, so the compiler evaluates the states in SIMD lanes (8 doubles with AVX-512, measured
    2.4x less CPU time than one state after the other on the slope's states). Each state adds the
    same terms in the same (candidate) order as :func:`_taylor_point`, so the results are bitwise
    the same: a candidate out of contact adds -0.0 to a sum (x + -0.0 = x for every x, +0.0
    included) and subtracts +0.0 from a difference, where the serial kernel skips it. No
    fused multiply-add: gransim compiles without fastmath.

    ``acc`` holds the sums, one row per quantity and one column per state (rows 0 W, 1-4 P, 5-13
    the material part of A, 14-16 its geometric part, 17 the contact count, 20-23 F): one array,
    so that the compiler proves the lanes independent with one alias check.
    """
    n = gs.shape[0]
    acc = np.zeros((24, LANES))
    for b in range(LANES):
        g = gs[min(b, n - 1)]  # unused lanes repeat the last state; their sums are not stored
        acc[20, b] = F[g, 0, 0]
        acc[21, b] = F[g, 0, 1]
        acc[22, b] = F[g, 1, 0]
        acc[23, b] = F[g, 1, 1]
    for m in range(lo, hi):
        L0 = L[m, 0]
        L1 = L[m, 1]
        rim = ri[m]
        rjm = rj[m]
        c = rim + rjm
        cc = c * c
        LL00 = L0 * L0
        LL01 = L0 * L1
        LL11 = L1 * L1
        for b in range(LANES):
            l0 = acc[20, b] * L0 + acc[21, b] * L1
            l1 = acc[22, b] * L0 + acc[23, b] * L1
            d2 = l0 * l0 + l1 * l1
            d = np.sqrt(d2)
            eps = overlap(rim, rjm, d)
            on = (d2 < cc) & (eps > 0.0)  # the two tests by which _taylor_point skips a candidate
            fm = force_magnitude(eps, kn)
            k = stiffness(eps, kn)
            n0 = l0 / d
            n1 = l1 / d
            a = k + fm / d
            bg = -fm / d
            an00 = a * n0 * n0
            an01 = a * n0 * n1
            an11 = a * n1 * n1
            acc[0, b] += potential(eps, kn) if on else -0.0
            acc[1, b] -= fm * n0 * L0 if on else 0.0
            acc[2, b] -= fm * n0 * L1 if on else 0.0
            acc[3, b] -= fm * n1 * L0 if on else 0.0
            acc[4, b] -= fm * n1 * L1 if on else 0.0
            acc[5, b] += an00 * LL00 if on else -0.0
            acc[6, b] += an00 * LL01 if on else -0.0
            acc[7, b] += an00 * LL11 if on else -0.0
            acc[8, b] += an01 * LL00 if on else -0.0
            acc[9, b] += an01 * LL01 if on else -0.0
            acc[10, b] += an01 * LL11 if on else -0.0
            acc[11, b] += an11 * LL00 if on else -0.0
            acc[12, b] += an11 * LL01 if on else -0.0
            acc[13, b] += an11 * LL11 if on else -0.0
            acc[14, b] += bg * LL00 if on else -0.0
            acc[15, b] += bg * LL01 if on else -0.0
            acc[16, b] += bg * LL11 if on else -0.0
            acc[17, b] += 1.0 if on else 0.0
    s = inv_area
    for b in range(n):
        g = gs[b]
        W[g] = acc[0, b] * s
        P[g, 0, 0] = acc[1, b] * s
        P[g, 0, 1] = acc[2, b] * s
        P[g, 1, 0] = acc[3, b] * s
        P[g, 1, 1] = acc[4, b] * s
        for i in range(2):
            for k in range(2):
                r0 = 5 + 3 * (i + k)  # the rows of (n n)_ik: 00 -> 5, 01 and 10 -> 8, 11 -> 11
                for J in range(2):
                    for Lx in range(2):
                        q = J + Lx  # 0: (0,0), 1: (0,1)/(1,0), 2: (1,1)
                        v = acc[r0 + q, b]
                        if i == k:
                            v += acc[14 + q, b]
                        A[g, i, J, k, Lx] = v * s
        nc[g] = int(acc[17, b])


@pjit
def _taylor_batch(F, order, block_starts, block_set, starts, L, ri, rj, kn, inv_area, W, P, A, nc):
    """All states in parallel, in blocks of up to LANES states that share a candidate set: block k
    holds the states order[block_starts[k]:block_starts[k+1]], all of set s = block_set[k] (rows
    starts[s]:starts[s+1])."""
    for k in prange(block_set.shape[0]):
        s = block_set[k]
        gs = order[block_starts[k] : block_starts[k + 1]]
        _taylor_block(F, gs, L, ri, rj, starts[s], starts[s + 1], kn, inv_area[s], W, P, A, nc)


def _blocks(set_of: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(order, block_starts, block_set): the states grouped by candidate set, cut into blocks of at
    most LANES states of one set (:func:`_taylor_batch`)."""
    order = np.argsort(set_of, kind="stable")
    so = set_of[order]
    new_run = np.flatnonzero(np.r_[True, so[1:] != so[:-1]])  # first state of each set's run
    run_of = np.cumsum(np.r_[True, so[1:] != so[:-1]]) - 1
    first = np.flatnonzero((np.arange(so.size) - new_run[run_of]) % LANES == 0)
    return order, np.append(first, so.size).astype(np.int64), so[first]


# ----------------------------------------------------------------------------------------------
# results
# ----------------------------------------------------------------------------------------------
def _ro(a):
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class TaylorResult:
    """Homogenized response of one RVE at one F (tension positive).

    Attributes
    ----------
    energy : float
        W(F), energy per reference area (J/m^2), eqs (6)-(7).
    piola : (2, 2) float64
        First Piola stress P = dW/dF (N/m), eq (10).
    tangent : (2, 2, 2, 2) float64
        A[i, J, k, L] = dP_iJ/dF_kL (N/m), eqs (11)-(12).
    cauchy : (2, 2) float64
        sigma = P F^T / det F (N/m), symmetric.
    n_contacts : int
        Number of overlapping pairs (eps > 0) in the deformed configuration.
    """

    energy: float
    piola: np.ndarray
    tangent: np.ndarray
    cauchy: np.ndarray
    n_contacts: int


@dataclass(frozen=True)
class TaylorBatch:
    """Homogenized response at G states; fields as :class:`TaylorResult` with a leading (G,) axis.

    Attributes
    ----------
    energy : (G,)  piola : (G, 2, 2)  tangent : (G, 2, 2, 2, 2)  cauchy : (G, 2, 2)
    n_contacts : (G,) int64
    n_candidates : (G,) int64
        Candidate pairs scanned for each state (the "contact evaluations").
    """

    energy: np.ndarray
    piola: np.ndarray
    tangent: np.ndarray
    cauchy: np.ndarray
    n_contacts: np.ndarray
    n_candidates: np.ndarray

    def __len__(self) -> int:
        return self.energy.shape[0]

    def __getitem__(self, g: int) -> TaylorResult:
        return TaylorResult(
            energy=float(self.energy[g]),
            piola=self.piola[g],
            tangent=self.tangent[g],
            cauchy=self.cauchy[g],
            n_contacts=int(self.n_contacts[g]),
        )


# ----------------------------------------------------------------------------------------------
# input checks
# ----------------------------------------------------------------------------------------------
def check_deformation_gradients(F, name: str = "F") -> np.ndarray:
    """Validate F of shape (2, 2) or (G, 2, 2): finite with det F > 0. Returns (G, 2, 2) float64."""
    arr = np.asarray(F) if not isinstance(F, np.ndarray) else F
    if getattr(arr, "ndim", 0) == 2:
        arr = as_array(arr, name, (2, 2))[None]
    else:
        arr = as_array(arr, name, (None, 2, 2))
    if arr.shape[0] == 0:
        raise InputError(f"{name}: no deformation gradients (shape {arr.shape})")
    det = arr[:, 0, 0] * arr[:, 1, 1] - arr[:, 0, 1] * arr[:, 1, 0]
    bad = np.flatnonzero(~(det > 0))
    if bad.size:
        g = int(bad[0])
        where = "" if arr.shape[0] == 1 else f" at index {g}"
        raise InputError(f"{name}: det F must be > 0 (the map must keep orientation), got det F = {det[g]:.6g}{where}")
    return arr


def _check_single_F(F) -> np.ndarray:
    """Fast check of one F (2, 2): finite, det > 0; the general check handles anything else."""
    if type(F) is np.ndarray and F.shape == (2, 2) and F.dtype == np.float64:
        a, b, c, d = F.ravel().tolist()
        if math.isfinite(a + b + c + d) and a * d - b * c > 0:
            return F if F.flags.c_contiguous else np.ascontiguousarray(F)
    G = check_deformation_gradients(F)
    if G.shape[0] != 1:
        raise InputError(f"F: expected shape (2, 2) for one state, got {np.shape(F)}")
    return G[0]


def _smallest_singular_value(G: np.ndarray) -> np.ndarray:
    """sigma_min of 2x2 matrices (..., 2, 2), closed form."""
    a, b, c, d = G[..., 0, 0], G[..., 0, 1], G[..., 1, 0], G[..., 1, 1]
    s1 = a * a + b * b + c * c + d * d
    det = a * d - b * c
    disc = np.sqrt(np.maximum(s1 * s1 - 4.0 * det * det, 0.0))
    # sigma_min^2 = (s1 - disc)/2 = 2 det^2 / (s1 + disc): the second form has no cancellation
    return np.sqrt(2.0 * det * det / (s1 + disc))


def shortest_lattice_vector(cell: np.ndarray) -> np.ndarray:
    """The shortest non-zero vector C n of the lattice of ``cell`` (2, 2) (Lagrange-Gauss reduction)."""
    u, v = np.array(cell[:, 0], float), np.array(cell[:, 1], float)
    if u @ u > v @ v:
        u, v = v, u
    for _ in range(200):  # each pass shrinks |v| geometrically; 200 passes cover any float cell
        if not u @ u > 0:
            break
        v = v - np.round((u @ v) / (u @ u)) * u
        if v @ v >= u @ u:
            break
        u, v = v, u
    return u


def estimate_candidates(packing: Packing, F, skin_fraction: float = DEFAULT_SKIN_FRACTION) -> dict:
    """Size of the candidate search of :class:`TaylorMaterial` anchored at F, before running it.

    The periodic images of the N disks in the deformed cell F C form N lattices of density
    1 / det(F C); a disk has on average pi c^2 N / det(F C) partner images within the search
    distance c = r_i + r_j + 2 f r_max, so the list holds about
    ``N^2 pi <c^2> / (2 det(F C)) + N c_max / |b_1|`` pairs, the second term counting the images of
    a disk of itself along the shortest deformed lattice vector b_1 (they dominate when F squeezes
    the cell below a disk diameter). The cell-list scan tests N (2 k_1 + 1)(2 k_2 + 1) N / n_bins
    distances (:func:`gransim.contacts.neighbours.bin_layout`).

    Returns {"pairs", "bytes", "scan_tests", "shortest_vector" (m), "max_contact_distance" (m)}.
    """
    F = _check_single_F(F)
    r = packing.radii
    n = r.size
    Cd = F @ packing.cell
    area = float(np.linalg.det(Cd))
    skin = 2.0 * float(skin_fraction) * float(r.max())
    m1, m2 = float(r.mean()), float(np.mean(r**2))
    c2 = 2.0 * m2 + 2.0 * m1**2 + 2.0 * skin * 2.0 * m1 + skin**2  # <(r_i + r_j + skin)^2>
    cmax = 2.0 * float(r.max()) + skin
    b1 = float(np.linalg.norm(shortest_lattice_vector(Cd)))
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):
        pairs = n * n * math.pi * c2 / (2.0 * area) + n * cmax / b1
        try:
            nb1, nb2, k1, k2 = bin_layout(Cd, cmax, n)
            tests = float(n) * (2 * k1 + 1) * (2 * k2 + 1) * n / (nb1 * nb2)
        except (OverflowError, ValueError, ZeroDivisionError):
            tests = math.inf
    if not math.isfinite(pairs) or not area > 0:
        pairs = math.inf
    return {
        "pairs": pairs,
        "bytes": pairs * BYTES_PER_CANDIDATE,
        "scan_tests": tests,
        "shortest_vector": b1,
        "max_contact_distance": float(2.0 * r.max()),
    }


def check_candidate_budget(packing: Packing, F, skin_fraction: float = DEFAULT_SKIN_FRACTION, name: str = "F") -> dict:
    """Refuse (:class:`InputError` naming ``name``) an F whose candidate search would not fit into
    the available memory or would scan more than :data:`MAX_SCAN_TESTS` distances."""
    est = estimate_candidates(packing, F, skin_fraction)
    what = (
        f"{name}: the contact candidates of {est['pairs']:.3g} periodic image pairs (deformed cell's "
        f"shortest lattice vector {est['shortest_vector']:.3g} m, largest contact distance "
        f"{est['max_contact_distance']:.3g} m)"
    )
    check_memory(est["bytes"], what, hint="the deformation squeezes the cell too much")
    if not est["scan_tests"] <= MAX_SCAN_TESTS:
        raise InputError(
            f"{name}: the contact search of this deformation would test about "
            f"{est['scan_tests']:.3g} distances (more than {MAX_SCAN_TESTS:.3g}); the "
            f"deformed cell is too thin or too sheared (shortest lattice vector "
            f"{est['shortest_vector']:.3g} m, candidates {est['pairs']:.3g}, about "
            f"{format_bytes(est['bytes'])})"
        )
    return est


# ----------------------------------------------------------------------------------------------
# the compute object
# ----------------------------------------------------------------------------------------------
class _RVE:
    """Reference data and candidate sets of one packing."""

    def __init__(self, packing: Packing, skin_fraction: float):
        self.packing = packing
        self.X = np.ascontiguousarray(packing.positions)
        self.C = np.ascontiguousarray(packing.cell)
        self.r = np.ascontiguousarray(packing.radii)
        self.area = float(np.linalg.det(self.C))
        self.f = skin_fraction
        self.threshold = 1.0 / (1.0 + skin_fraction) * (1.0 + VALIDITY_MARGIN)
        self.sets = []  # list of (F0inv (2,2), L, ri, rj, i, j, shift)
        self.used = []  # call counter of each set's last use (least recently used are pruned)
        self.clock = 0

    def build(self, F0: np.ndarray):
        """Candidate set anchored at F0: pairs with |F0 L| < (1 + f)(r_i + r_j)."""
        check_candidate_budget(self.packing, F0, self.f)
        # the cell list takes one absolute skin: the largest pair's, then filter per pair
        skin = self.f * 2.0 * float(self.r.max())
        nl = find_neighbours(self.X @ F0.T, self.r, F0 @ self.C, skin)
        c = (1.0 + self.f) * (self.r[nl.i] + self.r[nl.j])
        keep = np.einsum("ij,ij->i", nl.branch, nl.branch) < c * c
        # canonical order (i, j, n1, n2): the kernel sums a state's active contacts in the set's
        # order, and the cell list's order follows the bins at F0. Sorted, every set that covers F
        # lists its active contacts in one order (the inactive extras are skipped), so the response
        # at F is bitwise the same whichever anchor's set evaluates it: independent of what was
        # evaluated before, of the batch, block or worker (gransim.parallel, checkpoint/resume).
        # The key is canonical: find_neighbours returns each pair once (i < j, or i == j with
        # n lexicographically positive) with n relative to the fixed reference positions X.
        keep = np.flatnonzero(keep)
        keep = keep[np.lexsort((nl.shift[keep, 1], nl.shift[keep, 0], nl.j[keep], nl.i[keep]))]
        i, j, shift = nl.i[keep], nl.j[keep], nl.shift[keep]
        L = self.X[j] + shift @ self.C.T - self.X[i]
        zero = np.flatnonzero(~np.any(L != 0.0, axis=1))
        if zero.size:  # l = F L = 0 for every F: no contact normal, P = nan
            q = int(zero[0])
            raise InputError(
                f"packing: disks {int(i[q])} and {int(j[q])} have coincident centres "
                f"{self.X[i[q]].tolist()} (image shift {shift[q].tolist()}); a contact needs a non-zero "
                f"branch vector ({zero.size} such pair(s))"
            )
        entry = (
            np.linalg.inv(F0),
            np.ascontiguousarray(L),
            self.r[i].copy(),
            self.r[j].copy(),
            i,
            j,
            shift,
        )
        self.sets.append(entry)
        self.used.append(self.clock)

    def prune(self):
        """Beyond MAX_SETS_PER_RVE sets keep the MAX/2 most recently used (between calls only)."""
        if len(self.sets) <= MAX_SETS_PER_RVE:
            return False
        keep = np.sort(np.argsort(self.used, kind="stable")[-(MAX_SETS_PER_RVE // 2) :])
        self.sets = [self.sets[k] for k in keep]
        self.used = [self.used[k] for k in keep]
        return True

    def valid(self, F: np.ndarray) -> np.ndarray:
        """(G, S) bool: set s covers F[g] by the validity rule."""
        if not self.sets:
            return np.zeros((F.shape[0], 0), bool)
        B = np.stack([s[0] for s in self.sets])  # F0^-1 of every set (S, 2, 2)
        # G = F F0^-1 (G, S, 2, 2) component by component (an einsum of 2 x 2 products is ~10x slower)
        f = [F[:, i, j][:, None] for i in range(2) for j in range(2)]
        b = [B[:, i, j][None, :] for i in range(2) for j in range(2)]
        G = np.empty((F.shape[0], B.shape[0], 2, 2))
        G[..., 0, 0] = f[0] * b[0] + f[1] * b[2]
        G[..., 0, 1] = f[0] * b[1] + f[1] * b[3]
        G[..., 1, 0] = f[2] * b[0] + f[3] * b[2]
        G[..., 1, 1] = f[2] * b[1] + f[3] * b[3]
        return _smallest_singular_value(G) >= self.threshold


def _as_packings(packings) -> tuple[list[str], list[Packing]]:
    if isinstance(packings, Packing):
        return ["rve"], [packings]
    if isinstance(packings, Mapping):
        names, items = list(map(str, packings.keys())), list(packings.values())
    elif isinstance(packings, Sequence):
        items = list(packings)
        names = [f"rve-{k}" for k in range(len(items))]
    else:
        raise InputError(
            f"packings: expected a Packing, a sequence or a mapping of Packings, got {type(packings).__name__}"
        )
    if not items:
        raise InputError("packings: at least one packing is needed")
    for name, p in zip(names, items):
        if not isinstance(p, Packing):
            raise InputError(f"packings[{name!r}]: expected a Packing, got {type(p).__name__}")
    return names, items


class TaylorMaterial:
    """Taylor-homogenized material law of one or several periodic RVEs (factory + compute object).

    Parameters
    ----------
    packings : Packing, sequence of Packing or mapping name -> Packing
        The RVEs in their reference configuration.
    normal_stiffness : float
        E_n of eq (4) (N/m), > 0.
    skin_fraction : float
        Skin of the cached contact candidates as a fraction of each pair's contact
        distance r_i + r_j (see the module docstring for the reuse rule). Larger: fewer
        rebuilds, more candidates per call.

    Use :meth:`evaluate` for many states in one parallel call (G Gauss points, each with an
    RVE index), :meth:`__call__` for one state. Candidate sets are cached and rebuilt only
    when the validity rule fails; :attr:`n_builds` counts the builds.
    """

    def __init__(self, packings, normal_stiffness: float, skin_fraction: float = DEFAULT_SKIN_FRACTION):
        self.names, items = _as_packings(packings)
        self.normal_stiffness = as_positive_float(normal_stiffness, "normal_stiffness")
        self.skin_fraction = as_positive_float(skin_fraction, "skin_fraction")
        self._rves = [_RVE(p, self.skin_fraction) for p in items]
        self.n_builds = 0
        self._flat = None  # concatenated candidate arrays, rebuilt when a set is added
        self._last = {}  # rve -> global set index of the last single-state call
        self._last_batch = None  # (F, rve index, cauchy, TaylorBatch) of the last evaluate call
        self._out = {}

    # -- bookkeeping ------------------------------------------------------------------------
    @property
    def n_rve(self) -> int:
        """Number of RVEs."""
        return len(self._rves)

    @property
    def packings(self) -> list[Packing]:
        """The reference packings, in RVE-index order."""
        return [r.packing for r in self._rves]

    def _flatten(self):
        Ls, ris, rjs, starts, inv_area, owner = [], [], [], [0], [], []
        for k, rve in enumerate(self._rves):
            for s in rve.sets:
                Ls.append(s[1])
                ris.append(s[2])
                rjs.append(s[3])
                starts.append(starts[-1] + s[1].shape[0])
                inv_area.append(1.0 / rve.area)
                owner.append(k)
        self._flat = (
            np.ascontiguousarray(np.concatenate(Ls).reshape(-1, 2)),
            np.concatenate(ris),
            np.concatenate(rjs),
            np.asarray(starts, np.int64),
            np.asarray(inv_area),
            np.asarray(owner),
        )

    def _assign(self, F: np.ndarray, rve: np.ndarray) -> np.ndarray:
        """Global candidate-set index for every state, building sets where none is valid."""
        set_of = np.empty(F.shape[0], np.int64)
        changed = False
        for R in self._rves:
            changed |= R.prune()
        for k in np.unique(rve):
            sel = np.flatnonzero(rve == k)
            R = self._rves[k]
            Fk = F[sel]
            ok = R.valid(Fk)
            while True:
                missing = np.flatnonzero(~ok.any(axis=1)) if ok.shape[1] else np.arange(sel.size)
                if missing.size == 0:
                    break
                R.build(Fk[missing[0]])
                self.n_builds += 1
                changed = True
                ok = R.valid(Fk)
            # latest valid set (the most recently built covers the current neighbourhood best)
            local = ok.shape[1] - 1 - np.argmax(ok[:, ::-1], axis=1)
            R.clock += 1
            for q in np.unique(local):
                R.used[q] = R.clock
            set_of[sel] = local + sum(len(r.sets) for r in self._rves[:k])
        if changed or self._flat is None:
            self._flatten()
            self._last = {}
        return set_of

    def _check_rve_index(self, rve, G: int) -> np.ndarray:
        if rve is None:
            if self.n_rve == 1:
                return np.zeros(G, np.int64)
            raise InputError(f"rve: this material holds {self.n_rve} RVEs; pass an RVE index per state")
        if np.ndim(rve) == 0:
            rve = np.full(G, rve)
        idx = as_array(rve, "rve", (None,), dtype=np.int64)
        if idx.shape[0] != G:
            raise InputError(f"rve: expected shape ({G},) (one index per F), got {idx.shape}")
        if idx.size and (idx.min() < 0 or idx.max() >= self.n_rve):
            raise InputError(f"rve: indices must lie in [0, {self.n_rve}), got range [{idx.min()}, {idx.max()}]")
        return idx

    # -- evaluation ---------------------------------------------------------------------------
    def evaluate(self, F, rve=None, cauchy: bool = True) -> TaylorBatch:
        """W, P, A, sigma at many states in one parallel kernel call.

        Parameters
        ----------
        F : (G, 2, 2) or (2, 2) array
            Deformation gradients, det F > 0.
        rve : None, int or (G,) int array
            RVE index of every state (None allowed with one RVE).
        cauchy : bool
            Also compute sigma = P F^T / det F.
        """
        F = check_deformation_gradients(F)
        G = F.shape[0]
        idx = self._check_rve_index(rve, G)
        last = self._last_batch
        if (
            last is not None
            and last[0].shape == F.shape
            and last[2] == cauchy
            and np.array_equal(last[0], F)
            and np.array_equal(last[1], idx)
        ):
            # the response depends on F alone (module docstring): the same states again (a Newton
            # solve starting where the previous one converged: 20% of the slope's evaluations)
            # give the same read-only arrays
            return last[3]
        set_of = self._assign(F, idx)
        L, ri, rj, starts, inv_area, _ = self._flat
        W = np.empty(G)
        P = np.empty((G, 2, 2))
        A = np.empty((G, 2, 2, 2, 2))
        nc = np.empty(G, np.int64)
        _taylor_batch(F, *_blocks(set_of), starts, L, ri, rj, self.normal_stiffness, inv_area, W, P, A, nc)
        if cauchy:
            J = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
            sig = np.einsum("giJ,gkJ->gik", P, F) / J[:, None, None]
        else:
            sig = np.full((G, 2, 2), np.nan)
        ncand = starts[set_of + 1] - starts[set_of]
        res = TaylorBatch(
            energy=_ro(W),
            piola=_ro(P),
            tangent=_ro(A),
            cauchy=_ro(sig),
            n_contacts=_ro(nc),
            n_candidates=_ro(ncand),
        )
        self._last_batch = (F.copy(), idx.copy(), cauchy, res)
        return res

    def __call__(self, F, rve: int = 0) -> TaylorResult:
        """One state: F (2, 2) of RVE ``rve`` (serial kernel, no thread start-up).

        Fast path for repeated calls: the last used candidate set of the RVE is re-checked
        with the validity rule in scalar arithmetic before the general assignment.
        """
        F = _check_single_F(F)
        if not (type(rve) is int and 0 <= rve < len(self._rves)):
            rve = int(self._check_rve_index(rve, 1)[0])
        s = self._last.get(rve)
        if s is None or self._flat is None or not self._still_valid(F, rve, s):
            s = int(self._assign(F[None], np.full(1, rve, np.int64))[0])
            self._last = {rve: s}
        L, ri, rj, starts, inv_area, _ = self._flat
        W, P, A, nc, sig = _taylor_single(F, L, ri, rj, starts[s], starts[s + 1], self.normal_stiffness, inv_area[s])
        return TaylorResult(
            energy=float(W[0]),
            piola=_ro(P[0]),
            tangent=_ro(A[0]),
            cauchy=_ro(sig),
            n_contacts=int(nc[0]),
        )

    def _still_valid(self, F, rve: int, s: int) -> bool:
        """Validity rule for global set index s (still of RVE rve) in scalar arithmetic."""
        R = self._rves[rve]
        first = sum(len(r.sets) for r in self._rves[:rve])
        local = s - first
        if not 0 <= local < len(R.sets):
            return False
        (g00, g01), (g10, g11) = (F @ R.sets[local][0]).tolist()
        s1 = g00 * g00 + g01 * g01 + g10 * g10 + g11 * g11
        det = g00 * g11 - g01 * g10
        disc = math.sqrt(max(s1 * s1 - 4.0 * det * det, 0.0))
        if math.sqrt(2.0 * det * det / (s1 + disc)) < R.threshold:
            return False
        R.clock += 1
        R.used[local] = R.clock
        return True

    def stress_and_tangent(self, F, rve=None) -> tuple[np.ndarray, np.ndarray]:
        """(P (G, 2, 2), A (G, 2, 2, 2, 2)) for a finite-element solver."""
        b = self.evaluate(F, rve, cauchy=False)
        return b.piola, b.tangent


# ----------------------------------------------------------------------------------------------
# functional front end
# ----------------------------------------------------------------------------------------------
_MATERIALS: weakref.WeakKeyDictionary[Packing, dict] = weakref.WeakKeyDictionary()


def material_for(packing: Packing, normal_stiffness: float) -> TaylorMaterial:
    """The cached :class:`TaylorMaterial` of one packing (kept while the packing lives)."""
    if not isinstance(packing, Packing):
        raise InputError(f"packing: expected a gransim.Packing, got {type(packing).__name__}")
    kn = as_positive_float(normal_stiffness, "normal_stiffness")
    per = _MATERIALS.setdefault(packing, {})
    mat = per.get(kn)
    if mat is None:
        mat = per[kn] = TaylorMaterial(packing, kn)
    return mat


def homogenize(packing: Packing, F, normal_stiffness: float) -> TaylorResult:
    """W, P, A, sigma and the contact count of ``packing`` deformed affinely by F (2, 2).

    Contact candidates are cached per packing (see the module docstring), so repeated
    calls on one packing cost only the kernel. Eqs (6)-(12) of Meier, Steinmann & Kuhl.
    """
    res = material_for(packing, normal_stiffness)(F)
    if not (math.isfinite(res.energy) and np.all(np.isfinite(res.piola)) and np.all(np.isfinite(res.tangent))):
        raise SimulationError(
            f"homogenize: non-finite result at F = {np.asarray(F).tolist()} (W = {res.energy!r}, "
            f"P = {res.piola.tolist()}); the contact stiffness or F is out of the range of float64"
        )
    return res


@dataclass(frozen=True)
class ContactState:
    """Contacts of an affinely deformed RVE (for per-contact comparisons and plots).

    Attributes
    ----------
    i, j : (M,) int64 particle indices; shift : (M, 2) int64 image of j.
    branch : (M, 2) current branch vectors l_ij = F L_ij (m).
    reference_branch : (M, 2) L_ij (m).
    overlap : (M,) eps_ij > 0 (m).
    force : (M, 2) force on particle i, f_ij = -E_n eps n_ij (N), eq (5).
    """

    i: np.ndarray
    j: np.ndarray
    shift: np.ndarray
    branch: np.ndarray
    reference_branch: np.ndarray
    overlap: np.ndarray
    force: np.ndarray

    def __len__(self) -> int:
        return self.i.shape[0]

    @property
    def normals(self) -> np.ndarray:
        """Unit contact normals n_ij (M, 2), from i to j."""
        return self.branch / np.linalg.norm(self.branch, axis=1)[:, None]


def contact_state(packing: Packing, F, normal_stiffness: float) -> ContactState:
    """The active contacts (eps > 0) of ``packing`` at x = F X, with their forces (eq 5)."""
    F = check_deformation_gradients(F)
    if F.shape[0] != 1:
        raise InputError("F: expected shape (2, 2)")
    F = F[0]
    kn = as_positive_float(normal_stiffness, "normal_stiffness")
    mat = material_for(packing, kn)
    s = int(mat._assign(F[None], np.zeros(1, np.int64))[0])
    _, L, ri, rj, i, j, shift = mat._rves[0].sets[s]
    l = L @ F.T
    d = np.linalg.norm(l, axis=1)
    hit = d < ri + rj
    eps = (ri + rj - d)[hit]
    n = l[hit] / d[hit, None]
    return ContactState(
        i=i[hit],
        j=j[hit],
        shift=shift[hit],
        branch=l[hit],
        reference_branch=L[hit],
        overlap=eps,
        force=-kn * eps[:, None] * n,
    )
