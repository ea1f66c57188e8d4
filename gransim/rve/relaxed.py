"""Relaxed periodic RVE: fluctuations minimise the contact energy at fixed F, condensed tangent.

Beyond the Taylor assumption of Meier, Steinmann & Kuhl ("Towards completeness: a multiscale
approach of confined particulate systems", eq 1: x_i = F X_i, "we do not consider any kind of
micro fluctuations") along the construction of Miehe & Dettmar ("A framework for micro-macro
transitions in periodic particle aggregates of granular materials", CMAME 193, 2004, sections 3-4):
the particle centres follow the macroscopic deformation *plus a periodic fluctuation*,

    x_i = F X_i + w_i,       w (N, 2) (m), the same for every periodic image of particle i,

so the branch vector of the pair (i, j, image n) with L_ij = X_j + C n - X_i (eq 2) becomes

    l_ij(F, w) = F L_ij + w_j - w_i.                                                       (R1)

With the overlap eps_ij = r_i + r_j - |l_ij| (eq 3) and the potential Phi (eqs 4-5) the RVE energy
per reference area V = det C (eqs 6-7) is

    W(F, w) = 1/V sum_pairs Phi(eps_ij(l_ij(F, w)))                                   (J/m^2) (R2)

and the relaxed energy density is its minimum over the fluctuations at fixed F (Miehe & Dettmar's
principle of minimum energy over the periodic fluctuation field, their eq for the "relaxed" RVE):

    W_rel(F) = min_w W(F, w),      W_w(F, w*) = 0 at the minimiser w* = w*(F).             (R3)

Since w = 0 is admissible, W_rel(F) <= W_Taylor(F) = W(F, 0) (the Taylor bound).

Derivatives (per pair, g = dPhi/dl = -Phi'(eps) n, K = d^2 Phi/dl dl = a n n + b 1 with
a = Phi'' + Phi'/d, b = -Phi'/d as in eqs 11-12; dl/dF_kL = e_k L_L, dl/dw_j = 1, dl/dw_i = -1):

* residual (out-of-balance forces)  W_w:   (W_w)_j = 1/V sum_{pairs of j} s_j g      s_i = -1, s_j = +1
* Hessian                            W_ww:  blocks s_a s_b K at (a, b) in {i, j}^2  (sparse, 2N x 2N)
* mixed                              W_wF:  (W_wF)_{a p, kL} = 1/V sum s_a K_pk L_L   (2N x 4)
* Taylor part                        W_FF:  eq (12), 1/V sum K_ik L_J L_L             (4 x 4)

A pair of a disk with its own image (i = j) has l = F L, independent of w: it enters W, P and W_FF
only. Stress and tangent at the minimiser (Miehe & Dettmar's condensation):

    P = dW_rel/dF = W_F(F, w*)  (= 1/V sum g (x) L, eq 10 at the relaxed l)          (N/m) (R4)
    A = d^2 W_rel/dF dF = W_FF - W_Fw (W_ww)^-1 W_wF                                  (N/m) (R5)

(R4) holds because W_w = 0 at w*; (R5) differentiates W_w(F, w*(F)) = 0:
dw*/dF = -(W_ww)^-1 W_wF. Both use the sparse LDL^T factorisation of W_ww at w* of the last Newton
iterate (Davis' up-looking algorithm on 2 x 2 blocks, numba, in a minimum-degree order of the
candidate graph) when W_ww is positive definite there, else a sparse LU of W_ww (below).
``A[i, J, k, L] = dP_iJ/dF_kL`` with index pairs (iJ) -> 2 i + J; A has the major symmetry (it is
a Hessian; the computed A is not symmetrised, it is symmetric to the round-off of the solve).

Gauge and rattlers
------------------
W is invariant under a rigid translation w -> w + c (every pair depends on w_j - w_i), so W_ww
is singular. The translation is removed by **fixing one particle** (the lowest index of the
backbone keeps its w). Rattlers are found in the current configuration at every Newton iterate:
disks with fewer than ``min_contacts`` (default 3, d + 1 in 2D) active contacts are removed
repeatedly with their contacts (a disk with two contacts has no tangential stiffness, the
geometric term b is even negative under compression); of the remaining disks only the largest
connected component of the contact graph (the backbone) is in the Newton solve, smaller clusters
(floating, further zero modes) count as rattlers. ``RelaxedResult.rattlers`` reports them.

**Rattlers are expelled to zero force** at every Newton iterate and at every line-search trial
(:func:`_expel`): a rattler's minimum-energy position, the backbone held, is force-free when its
cage has room, so a rattler that overlaps something is moved (a 2 x 2 Newton step on its own
contact energy with the contact distance widened by a clearance of 1e-6 (r_i + r_j): one contact
is left in one step, the corner of two in a few; a disk pinched between two opposite neighbours
leaves along its negative curvature). Rattlers that touch each other move together (a group of
<= 16, one small dense Newton). A group without room (jammed outside the backbone) is moved to
the minimum of its true energy instead: its disks then carry force through >= 3 contacts each
and join the backbone at the next classification. At the converged state no rattler carries a
force, so W, P and A do not depend on where the rattlers are (they are somewhere in their void,
which depends on the start) and P is a function of F alone (for the same backbone minimum);
P and A are the exact derivatives of W_rel. A rattler without any contact keeps its w.

Held rattlers (fallback). Where the network falls apart (extension beyond the overlap strain:
no backbone, one large group of touching rattlers) each disk is freed alone where it has room and
the others are **held** with their contact forces (``n_held``, ``held_force``): there W_rel is
that of the held contacts, above the separated minimum, P depends on the start and is only
piecewise smooth in F. Rattlers in a small group that cannot reach its minimum in one expulsion
are held too; the Newton iteration continues until their net force is below the tolerance.

Continuation. A start can lose the backbone although the relaxed network at F has one (simple
shear F = [[1, g], [0, 1]] with g/2 above the mean overlap: the stretched contacts open at w = 0
and the rattler cascade empties the network). A relaxation that ends with held rattlers or no
backbone is therefore redone along F(t) = F0 + t (F - F0), t in [0, 1], from the warm start's
(F0, w0), else from (1, 0): adaptive sub-steps (first 1/CONT_FIRST, doubled after success, halved
after a sub-step with held rattlers), each from the previous minimiser. Its result is kept if it
holds no rattler and its energy is not higher; it is the minimiser at F (the path chooses the
basin only), so P is the same as along any other path into that basin.

Contact changes and Newton
--------------------------
Phi = E_n/2 <eps>^2 is C1 in l with a jump of Phi'' at eps = 0 (H(eps) in eq 4), so W is C1 and
piecewise smooth: contacts open and close during the relaxation. Newton's method is applied to the
current active set (the Hessian of the contacts with eps > 0) and globalised by an Armijo
backtracking line search on W itself (with the rattlers expelled at the trial point); no disk
moves by more than a quarter of the skin per step; an indefinite W_ww (compressive contacts have
negative tangential stiffness b, buckling) is shifted, W_ww + mu diag|W_ww|, mu = 1e-8, x10 (from
a tenth of the previous iterate's shift), until every 2 x 2 pivot block of the LDL^T is positive
definite (Sylvester's inertia; a Levenberg-Marquardt / trust-region step). Once the active set
settles the iteration is plain Newton and converges quadratically. W itself is known only to
about E_n eps ulp(c) per contact (the overlap eps = c - |l| cancels), ~1e-12 relative: a full
Newton step whose energy change is below that is taken without the Armijo test.
Convergence: max |W_w| V <= max(force_tol * mean contact force, 8 eps_machine E_n c_max) over
the backbone, and no rattler left with a net force above it. At the converged state the
factorisation of the unshifted W_ww gives A; if it is not positive definite (an equilibrium that is
not a strict minimum: compressive contacts' negative tangential stiffness) ``stable`` is False and
A still condenses with W_ww itself, by a sparse LU with pivoting (SuperLU): (R5) needs W_ww only
non-singular, and the shifted matrix of the Newton steps would give a tangent that is not dP/dF
(measured: 1e-5 to 1e-2 off central differences, and a linear FE Newton; docs/slope.md). Only a
singular W_ww (a zero mode, no unique branch w*(F)) keeps the smallest shift that is definite.

Contact candidates (skin)
-------------------------
Candidates are built by the periodic cell list at an anchor (F0, w0): all pairs with
|l0| < r_i + r_j + s, s = 2 f r_max (f = ``skin_fraction``). With G = F F0^-1 and
delta_1 >= delta_2 the two largest moves |w_k - G w0_k|, every excluded pair has
l = G l0 + (w_j - G w0_j) - (w_i - G w0_i), so

    |l| >= sigma_min(G) (c + s) - (delta_1 + delta_2) >= c      for all c = r_i + r_j in [c_min, c_max]

when (sigma_min - 1) c + sigma_min s - (delta_1 + delta_2) >= 0 at c = c_min and c = c_max
(validity rule; linear in c; one expelled rattler moving far does not invalidate the set). A
candidate set is reused while the rule holds at the trial (F, w) of every line-search step,
otherwise rebuilt there; ``n_builds`` counts the builds.

Gauss-point history
-------------------
:meth:`RelaxedMaterial.evaluate` (the FE interface) keeps every converged state g as a *trial*;
:meth:`RelaxedMaterial.commit` makes the trials the history (call it when the global load step
has converged), :meth:`RelaxedMaterial.revert` drops them. Where a state starts
(``warm_start``): ``"committed"`` (default) from the committed state of slot g; ``"trial"``
from slot g's trial of the previous :meth:`evaluate` since the last commit or revert (the
previous FE Newton iterate of the same attempt, whose F differs by the last FE correction only),
else from the committed state. Both add the first-order predictor dw*/dF : (F - F_start) of the
start. In one energy basin the two give the same minimiser w*(F), so P and A agree to the
start-independence of the relaxation (~1e-12); the trial start needs 1-2 Newton iterations near
FE convergence where the committed start needs as many as the whole load increment asks. Where
the RVE rearranges (another basin between the committed F and F), the trial start ends in the
basin the FE iterates led it to: the response is then no longer a function of (committed state,
F) alone but of the FE iterate path, which differs from one Gauss point to the next (a patch
under an affine boundary field then gets different stresses at its Gauss points). Hence the
committed start is the default.
The history of a step is reproduced by evaluating the same sequence of F (the accepted
attempt's FE iterates) and committing (:func:`gransim.fem.checkpoint.replay_history`). A warm
start that ends above the Taylor energy W(F, 0) by more than 1e-12 relative (another local
minimum) is redone from w = 0, so W_rel <= W_Taylor (1 + 1e-12) always.
:meth:`RelaxedMaterial.__call__` is stateless: it starts from a given fluctuation and returns the
converged one in the result.

Units: E_n in N/m, W in J/m^2, P and A in N/m (2D), as :mod:`gransim.rve.taylor`. Tension positive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from .._numba import njit
from .._validate import as_array, as_int, as_positive_float
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential, stiffness
from ..errors import ConvergenceError, InputError
from .taylor import (
    DEFAULT_SKIN_FRACTION,
    _as_packings,
    _check_single_F,
    _ro,
    _smallest_singular_value,
    check_deformation_gradients,
)

#: default Newton tolerance: max |W_w| V relative to the mean contact force
DEFAULT_FORCE_TOL = 1e-12
#: round-off floor of the tolerance, times E_n c_max (N): the overlap eps = c - |l| of a contact
#: carries the rounding of |l| ~ c, so a net force is not known better than a few E_n ulp(c)
FORCE_FLOOR = 8 * np.finfo(float).eps
#: clearance (relative to r_i + r_j) a rattler is given from every candidate when it is expelled
RATTLER_CLEARANCE = 1e-6
#: most Gauss-Newton steps of one rattler and passes over the rattlers per expulsion
RATTLER_LOCAL_ITER = 30
RATTLER_PASSES = 30
#: largest group of touching rattlers moved together (a larger one: the network fell apart)
RATTLER_GROUP = 16
#: default most Newton iterations per state
DEFAULT_MAX_ITER = 200
#: where :meth:`RelaxedMaterial.evaluate` starts a Gauss point (``warm_start``): its trial of the
#: previous evaluate (the previous FE iterate of the attempt), or its committed state
WARM_STARTS = ("committed", "trial")
#: default fewest contacts of a non-rattler (d + 1 in 2D)
DEFAULT_MIN_CONTACTS = 3
#: continuation in F where the start has no backbone: first sub-steps (of t in [0, 1]), smallest
#: sub-step 1/2**CONT_DEPTH, most relaxations per continuation
CONT_FIRST = 8
CONT_DEPTH = 8
CONT_STEPS = 64
#: Armijo constant of the line search
ARMIJO = 1e-4
#: relative energy change below which a step counts as round-off (accepted if |W_w| shrinks)
ENERGY_ROUNDOFF = 1e-13


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------
@njit
def _active(F, w, ci, cj, L, csum):
    """(M,) bool: candidate m is in contact (eps > 0) at x = F X + w."""
    M = ci.shape[0]
    out = np.zeros(M, np.bool_)
    for m in range(M):
        i = ci[m]
        j = cj[m]
        l0 = F[0, 0] * L[m, 0] + F[0, 1] * L[m, 1] + w[j, 0] - w[i, 0]
        l1 = F[1, 0] * L[m, 0] + F[1, 1] * L[m, 1] + w[j, 1] - w[i, 1]
        d2 = l0 * l0 + l1 * l1
        c = csum[m]
        if d2 < c * c and c - np.sqrt(d2) > 0.0:
            out[m] = True
    return out


@njit
def _energy(F, w, ci, cj, L, ri, rj, kn):
    """sum_pairs Phi(eps) (J) at x = F X + w, eqs (3)-(4) with (R1)."""
    e = 0.0
    for m in range(ci.shape[0]):
        i = ci[m]
        j = cj[m]
        l0 = F[0, 0] * L[m, 0] + F[0, 1] * L[m, 1] + w[j, 0] - w[i, 0]
        l1 = F[1, 0] * L[m, 0] + F[1, 1] * L[m, 1] + w[j, 1] - w[i, 1]
        d2 = l0 * l0 + l1 * l1
        c = ri[m] + rj[m]
        if d2 >= c * c:
            continue
        e += potential(overlap(ri[m], rj[m], np.sqrt(d2)), kn)
    return e


@njit
def _assemble(F, w, ci, cj, L, ri, rj, kn, dof, ndof):
    """Energy, W_F, W_FF, W_w, W_wF and W_ww in 2 x 2 blocks (all times V, i.e. plain sums).

    dof (N,) int64: first unknown of a relaxed disk (2 per disk, block dof // 2) or -1 (fixed /
    rattler). W_ww is returned as its diagonal blocks Hd (nb, 2, 2) and the strictly upper
    off-diagonal blocks in block-CSC form (Ap (nb + 1,), Ai, Ax (., 2, 2); duplicates allowed,
    they add). Returns W, P (2, 2), WFF (4, 4), grad (ndof,), B (ndof, 4), Hd, Ap, Ai, Ax,
    n_contacts, fsum (the sum of the contact force magnitudes, N).
    """
    M = ci.shape[0]
    nb = ndof // 2
    W = 0.0
    P = np.zeros((2, 2))
    WFF = np.zeros((4, 4))
    grad = np.zeros(ndof)
    B = np.zeros((ndof, 4))
    Hd = np.zeros((nb, 2, 2))
    Ks = np.empty((M, 2, 2))
    off = np.zeros(M, np.bool_)
    Ap = np.zeros(nb + 1, np.int64)
    g = np.empty(2)
    Lm = np.empty(2)
    count = 0
    fsum = 0.0
    for m in range(M):
        i = ci[m]
        j = cj[m]
        Lm[0] = L[m, 0]
        Lm[1] = L[m, 1]
        l0 = F[0, 0] * Lm[0] + F[0, 1] * Lm[1] + w[j, 0] - w[i, 0]
        l1 = F[1, 0] * Lm[0] + F[1, 1] * Lm[1] + w[j, 1] - w[i, 1]
        d2 = l0 * l0 + l1 * l1
        c = ri[m] + rj[m]
        if d2 >= c * c:
            continue
        d = np.sqrt(d2)
        eps = overlap(ri[m], rj[m], d)
        if eps <= 0.0:
            continue
        count += 1
        fm = force_magnitude(eps, kn)
        fsum += fm
        a = stiffness(eps, kn) + fm / d
        b = -fm / d
        n0 = l0 / d
        n1 = l1 / d
        g[0] = -fm * n0
        g[1] = -fm * n1
        K = Ks[m]
        K[0, 0] = a * n0 * n0 + b
        K[0, 1] = a * n0 * n1
        K[1, 0] = K[0, 1]
        K[1, 1] = a * n1 * n1 + b
        W += potential(eps, kn)
        for p in range(2):
            for J in range(2):
                P[p, J] += g[p] * Lm[J]
                for q in range(2):
                    for Lx in range(2):
                        WFF[2 * p + J, 2 * q + Lx] += K[p, q] * Lm[J] * Lm[Lx]
        if i == j:
            continue
        for side in range(2):
            da = dof[i] if side == 0 else dof[j]
            if da < 0:
                continue
            sa = -1.0 if side == 0 else 1.0
            ba = da // 2
            for p in range(2):
                grad[da + p] += sa * g[p]
                for q in range(2):
                    Hd[ba, p, q] += K[p, q]
                    for Lx in range(2):
                        B[da + p, 2 * q + Lx] += sa * K[p, q] * Lm[Lx]
        if dof[i] >= 0 and dof[j] >= 0:
            off[m] = True
            Ap[max(dof[i], dof[j]) // 2 + 1] += 1
    for k in range(nb):
        Ap[k + 1] += Ap[k]
    Ai = np.empty(Ap[nb], np.int64)
    Ax = np.empty((Ap[nb], 2, 2))
    fill = Ap[:nb].copy()
    for m in range(M):
        if off[m]:
            bi = dof[ci[m]] // 2
            bj = dof[cj[m]] // 2
            col = max(bi, bj)
            p = fill[col]
            fill[col] += 1
            Ai[p] = min(bi, bj)
            for r in range(2):
                for c2 in range(2):
                    Ax[p, r, c2] = -Ks[m, r, c2]  # s_i s_j K, K symmetric
    return W, P, WFF, grad, B, Hd, Ap, Ai, Ax, count, fsum


@njit
def _classify_kernel(N, ci, cj, active, min_contacts, order):
    """Rattlers, backbone and unknowns of the active contact graph (see "Gauge and rattlers").

    Returns rat (N,) bool (rattlers and disks off the largest component), dof (N,) int64 (first
    unknown, numbered along ``order``; -1 if not relaxed), the fixed disk (-1: none) and ndof."""
    deg = np.zeros(N, np.int64)
    for m in range(ci.shape[0]):
        if active[m] and ci[m] != cj[m]:
            deg[ci[m]] += 1
            deg[cj[m]] += 1
    start = np.zeros(N + 1, np.int64)
    for k in range(N):
        start[k + 1] = start[k] + deg[k]
    nbr = np.empty(start[N], np.int64)
    fill = start[:N].copy()
    for m in range(ci.shape[0]):
        if active[m] and ci[m] != cj[m]:
            nbr[fill[ci[m]]] = cj[m]
            fill[ci[m]] += 1
            nbr[fill[cj[m]]] = ci[m]
            fill[cj[m]] += 1
    # repeated removal of disks with fewer than min_contacts contacts (a queue)
    rat = np.zeros(N, np.bool_)
    queue = np.empty(N, np.int64)
    head = 0
    tail = 0
    for k in range(N):
        if deg[k] < min_contacts:
            rat[k] = True
            queue[tail] = k
            tail += 1
    while head < tail:
        k = queue[head]
        head += 1
        for p in range(start[k], start[k + 1]):
            q = nbr[p]
            if not rat[q]:
                deg[q] -= 1
                if deg[q] < min_contacts:
                    rat[q] = True
                    queue[tail] = q
                    tail += 1
    # connected components of the rest (breadth first); keep the largest
    lab = np.full(N, -1, np.int64)
    best = -1
    best_size = 0
    ncomp = 0
    for s0 in range(N):
        if rat[s0] or lab[s0] >= 0:
            continue
        lab[s0] = ncomp
        head = 0
        tail = 1
        queue[0] = s0
        while head < tail:
            k = queue[head]
            head += 1
            for p in range(start[k], start[k + 1]):
                q = nbr[p]
                if not rat[q] and lab[q] < 0:
                    lab[q] = ncomp
                    queue[tail] = q
                    tail += 1
        if tail > best_size:
            best_size = tail
            best = ncomp
        ncomp += 1
    dof = np.full(N, -1, np.int64)
    fixed = -1
    for k in range(N):
        if lab[k] != best or best < 0:
            rat[k] = True
        elif fixed < 0:
            fixed = k
    ndof = 0
    for t in range(N):
        k = order[t]
        if not rat[k] and k != fixed:
            dof[k] = ndof
            ndof += 2
    return rat, dof, fixed, ndof


@njit
def _adjacency(N, ci, cj):
    """Candidates of each disk in CSR form (self-image pairs i = j left out: they do not depend
    on w). Returns aptr (N + 1,), am (nnz,) candidate index, asg (nnz,) +-1: the disk's sign s in
    l = F L + w_j - w_i (-1 on the i side, +1 on the j side)."""
    aptr = np.zeros(N + 1, np.int64)
    for m in range(ci.shape[0]):
        if ci[m] != cj[m]:
            aptr[ci[m] + 1] += 1
            aptr[cj[m] + 1] += 1
    for k in range(N):
        aptr[k + 1] += aptr[k]
    am = np.empty(aptr[N], np.int64)
    asg = np.empty(aptr[N], np.float64)
    fill = aptr[:N].copy()
    for m in range(ci.shape[0]):
        i = ci[m]
        j = cj[m]
        if i == j:
            continue
        am[fill[i]] = m
        asg[fill[i]] = -1.0
        fill[i] += 1
        am[fill[j]] = m
        asg[fill[j]] = 1.0
        fill[j] += 1
    return aptr, am, asg


@njit
def _disk_terms(F, w, k, aptr, am, asg, ci, cj, L, csum, grow, out):
    """Contact terms of disk k against its candidates (the others held) for the contact distance
    c' = c (1 + grow) (grow = 0: the true contacts; grow > 0 widens each by a clearance).

    With r = <c' - d> per pair (m) and the energy e = 1/2 sum r^2 (m^2; E_n e is the disk's
    contact energy for grow = 0), writes out[0] = e, out[1:3] = de/dw_k = -sum r s n (m),
    out[3:6] = the Hessian d^2 e/dw_k^2 = sum (1 + r/d) n n^T - (r/d) 1 (H00, H01, H11; its
    tangential part is negative under compression), out[6] = max r / c (0 when nothing overlaps),
    out[7] = the c of that pair (m)."""
    for q in range(8):
        out[q] = 0.0
    for p in range(aptr[k], aptr[k + 1]):
        m = am[p]
        s = asg[p]
        i = ci[m]
        j = cj[m]
        l0 = F[0, 0] * L[m, 0] + F[0, 1] * L[m, 1] + w[j, 0] - w[i, 0]
        l1 = F[1, 0] * L[m, 0] + F[1, 1] * L[m, 1] + w[j, 1] - w[i, 1]
        d = np.sqrt(l0 * l0 + l1 * l1)
        c = csum[m]
        r = c * (1.0 + grow) - d
        if r <= 0.0 or d == 0.0:
            continue
        n0 = l0 / d
        n1 = l1 / d
        q = r / d
        out[0] += 0.5 * r * r
        out[1] -= r * s * n0
        out[2] -= r * s * n1
        out[3] += (1.0 + q) * n0 * n0 - q
        out[4] += (1.0 + q) * n0 * n1
        out[5] += (1.0 + q) * n1 * n1 - q
        if r > out[6] * c:
            out[6] = r / c
            out[7] = c


@njit
def _group_terms(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, grow, g, H):
    """Contact terms of a group of disks (members (n,), pos (N,) their index in the group or -1)
    against their candidates, the other disks held, for the contact distance c' = c (1 + grow).

    With r = <c' - d> per pair (m), returns e = 1/2 sum r^2 (m^2; E_n e is the group's contact
    energy for grow = 0) and the largest r / c (0 when nothing overlaps); writes the gradient
    g (2n,) = de/dw (m) and the Hessian H (2n, 2n) (dimensionless; per pair K = (1 + r/d) n n^T -
    (r/d) 1 in the blocks s_a s_b K, its tangential part negative under compression)."""
    g[:] = 0.0
    H[:, :] = 0.0
    e = 0.0
    rel = 0.0
    for t in range(members.shape[0]):
        k = members[t]
        for p in range(aptr[k], aptr[k + 1]):
            m = am[p]
            s = asg[p]
            i = ci[m]
            j = cj[m]
            o = j if s < 0.0 else i
            if pos[o] >= 0 and s > 0.0:
                continue  # a pair inside the group: counted once, from its i side
            l0 = F[0, 0] * L[m, 0] + F[0, 1] * L[m, 1] + w[j, 0] - w[i, 0]
            l1 = F[1, 0] * L[m, 0] + F[1, 1] * L[m, 1] + w[j, 1] - w[i, 1]
            d = np.sqrt(l0 * l0 + l1 * l1)
            c = csum[m]
            r = c * (1.0 + grow) - d
            if r <= 0.0 or d == 0.0:
                continue
            n0 = l0 / d
            n1 = l1 / d
            q = r / d
            e += 0.5 * r * r
            rel = max(rel, r / c)
            k00 = (1.0 + q) * n0 * n0 - q
            k01 = (1.0 + q) * n0 * n1
            k11 = (1.0 + q) * n1 * n1 - q
            for side in range(2):
                a = pos[i] if side == 0 else pos[j]
                if a < 0:
                    continue
                sa = -1.0 if side == 0 else 1.0
                g[2 * a] -= r * sa * n0
                g[2 * a + 1] -= r * sa * n1
                for side2 in range(2):
                    b = pos[i] if side2 == 0 else pos[j]
                    if b < 0:
                        continue
                    sab = 1.0 if side == side2 else -1.0
                    H[2 * a, 2 * b] += sab * k00
                    H[2 * a, 2 * b + 1] += sab * k01
                    H[2 * a + 1, 2 * b] += sab * k01
                    H[2 * a + 1, 2 * b + 1] += sab * k11
    return e, rel


@njit
def _group_min(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, grow, cap, gtol, max_local):
    """Minimise the contact energy e of a group of disks (:func:`_group_terms`, the others held)
    over their w, in place: Newton steps with the Hessian's eigenvalues replaced by their absolute
    values (floored at 1e-8 of the largest; a descent direction that meets one contact exactly
    in one step and the corner of two quadratically), a step along the most negative curvature
    where the gradient vanishes at a saddle (a disk pinched between two opposite neighbours leaves
    sideways), no disk moved by more than ``cap`` (m) per step, Armijo backtracking.

    Returns 1 when nothing overlaps by more than half the widening (grow > 0) or at all
    (grow = 0); 0 at a local minimum with overlaps (|de/dw| <= gtol (m), no negative curvature)
    or when no step decreases e."""
    n2 = 2 * members.shape[0]
    g = np.empty(n2)
    H = np.empty((n2, n2))
    gt = np.empty(n2)
    Ht = np.empty((n2, n2))
    x0 = np.empty(n2)
    for _ in range(max_local):
        e, rel = _group_terms(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, grow, g, H)
        if rel <= 0.5 * grow:
            return 1
        lam, V = np.linalg.eigh(H)
        floor = 1e-8 * max(abs(lam[0]), abs(lam[n2 - 1]))
        gv = V.T @ g
        d = np.zeros(n2)
        for q in range(n2):
            d -= (gv[q] / max(abs(lam[q]), floor)) * V[:, q]
        if np.sqrt(np.sum(g * g)) <= gtol:
            if lam[0] >= -floor:
                return 0  # a local minimum with overlaps: held
            # a saddle: leave along the most negative curvature, as far as opens the deepest overlap
            a = np.sqrt(2.0 * rel) * np.max(csum)
            u = V[:, 0]
            d = (-a if gv[0] > 0.0 else a) * u / max(np.max(np.abs(u)), 1e-300)
        longest = 0.0
        for t in range(members.shape[0]):
            longest = max(longest, np.sqrt(d[2 * t] ** 2 + d[2 * t + 1] ** 2))
        if longest > cap:
            d *= cap / longest
        slope = min(np.sum(g * d), 0.0)
        for t in range(members.shape[0]):
            x0[2 * t] = w[members[t], 0]
            x0[2 * t + 1] = w[members[t], 1]
        step = 1.0
        ok = False
        for _h in range(40):
            for t in range(members.shape[0]):
                w[members[t], 0] = x0[2 * t] + step * d[2 * t]
                w[members[t], 1] = x0[2 * t + 1] + step * d[2 * t + 1]
            et, _r = _group_terms(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, grow, gt, Ht)
            if et < e and et <= e + 1e-4 * step * slope:
                ok = True
                break
            step *= 0.5
        if not ok:
            for t in range(members.shape[0]):
                w[members[t], 0] = x0[2 * t]
                w[members[t], 1] = x0[2 * t + 1]
            return 0
    return 0


@njit
def _expel(F, w, ci, cj, L, csum, aptr, am, asg, rat, kn, ftol, clear, cap, max_local, max_pass, max_group):
    """Relax the rattlers (rat (N,) bool) that overlap something, in place on w (N, 2), the other
    disks held.

    The overlapping rattlers are grouped by their overlaps with each other (a group moves
    together: a chain of rattlers in one cage). Each group is first moved to where it clears
    every candidate by ``clear`` (relative to r_i + r_j; :func:`_group_min` on the widened
    contacts): a rattler with room in its cage ends force-free (eps < 0 everywhere), one contact
    in one Newton step, two in a few. A group without room (a jammed group outside the backbone)
    is moved to the minimum of its true contact energy instead, |net force| <= ftol / 10 (N); its
    disks then carry force through >= 3 contacts each and join the backbone at the next
    classification. No group move raises the energy, so W never rises. The passes repeat (up to
    ``max_pass``) while a move created new overlaps with other rattlers.
    Returns (moved, held, residual): groups moved, rattlers left overlapping ("held") and the
    largest net contact force on one (N)."""
    N = w.shape[0]
    buf = np.empty(8)
    ov = np.zeros(N, np.bool_)
    pos = np.full(N, -1, np.int64)
    lab = np.full(N, -1, np.int64)
    queue = np.empty(N, np.int64)
    moved = 0
    gtol = 0.1 * ftol / kn  # (m): stationarity of a held group, below the Newton tolerance
    big = np.zeros(N, np.bool_)  # disks of a group larger than max_group
    g2 = np.empty(2 * max_group)
    H2 = np.empty((2 * max_group, 2 * max_group))
    for it in range(max_pass):
        n_ov = 0
        for k in range(N):
            ov[k] = False
            if rat[k] and aptr[k + 1] > aptr[k]:
                _disk_terms(F, w, k, aptr, am, asg, ci, cj, L, csum, 0.0, buf)
                if buf[6] > 0.0 and (it == 0 or kn * np.sqrt(buf[1] * buf[1] + buf[2] * buf[2]) > ftol):
                    ov[k] = True
                    n_ov += 1
        if n_ov == 0:
            break
        lab[:] = -1
        changed = 0
        for s0 in range(N):
            if not ov[s0] or lab[s0] >= 0:
                continue
            # the group of s0: overlapping rattlers connected through overlaps
            lab[s0] = s0
            head = 0
            tail = 1
            queue[0] = s0
            while head < tail:
                k = queue[head]
                head += 1
                for p in range(aptr[k], aptr[k + 1]):
                    m = am[p]
                    o = cj[m] if asg[p] < 0.0 else ci[m]
                    if not rat[o] or lab[o] >= 0:
                        continue
                    i = ci[m]
                    j = cj[m]
                    l0 = F[0, 0] * L[m, 0] + F[0, 1] * L[m, 1] + w[j, 0] - w[i, 0]
                    l1 = F[1, 0] * L[m, 0] + F[1, 1] * L[m, 1] + w[j, 1] - w[i, 1]
                    if l0 * l0 + l1 * l1 < csum[m] * csum[m]:
                        lab[o] = s0
                        queue[tail] = o
                        tail += 1
            members = queue[:tail].copy()
            for t in range(tail):
                pos[members[t]] = t
            old = np.empty((tail, 2))
            for t in range(tail):
                old[t, 0] = w[members[t], 0]
                old[t, 1] = w[members[t], 1]
            if tail <= max_group:
                e0, _r = _group_terms(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, 0.0, g2, H2)
                if _group_min(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, clear, cap, 0.0, max_local) == 0:
                    _group_min(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, 0.0, cap, gtol, max_local)
                e1, _r = _group_terms(F, w, members, pos, aptr, am, asg, ci, cj, L, csum, 0.0, g2, H2)
                if e1 > e0:  # never raise the energy
                    for t in range(tail):
                        w[members[t], 0] = old[t, 0]
                        w[members[t], 1] = old[t, 1]
            else:
                # a large group (the network fell apart): each disk is freed alone where it has room,
                # the others stay where they are (held)
                one = np.empty(1, np.int64)
                for t in range(tail):
                    k = members[t]
                    pos[k] = -1
                for t in range(tail):
                    k = members[t]
                    one[0] = k
                    pos[k] = 0
                    if _group_min(F, w, one, pos, aptr, am, asg, ci, cj, L, csum, clear, cap, 0.0, max_local) == 0:
                        w[k, 0] = old[t, 0]
                        w[k, 1] = old[t, 1]
                    pos[k] = -1
                for t in range(tail):
                    big[members[t]] = True
                    pos[members[t]] = t
            same = True
            for t in range(tail):
                if w[members[t], 0] != old[t, 0] or w[members[t], 1] != old[t, 1]:
                    same = False
            for t in range(tail):
                pos[members[t]] = -1
            if not same:
                changed += 1
        moved += changed
        if changed == 0:
            break
    held = 0
    res = 0.0
    for k in range(N):
        if rat[k] and aptr[k + 1] > aptr[k]:
            _disk_terms(F, w, k, aptr, am, asg, ci, cj, L, csum, 0.0, buf)
            if buf[6] > 0.0:
                held += 1
                if not big[k]:
                    res = max(res, kn * np.sqrt(buf[1] * buf[1] + buf[2] * buf[2]))
    return moved, held, res


# ----------------------------------------------------------------------------------------------
# results and state
# ----------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RelaxedResult:
    """Relaxed response of one RVE at one F (tension positive).

    Attributes
    ----------
    energy : float
        W_rel(F) = min_w W(F, w) (J/m^2), (R3).
    piola : (2, 2)
        P = dW_rel/dF (N/m), (R4).
    tangent : (2, 2, 2, 2)
        A[i, J, k, L] = dP_iJ/dF_kL, condensed (R5) (N/m).
    cauchy : (2, 2)
        sigma = P F^T / det F (N/m).
    n_contacts : int
        Active contacts at the minimiser.
    fluctuation : (N, 2)
        w* (m); x_i = F X_i + w_i.
    rattlers : (N,) bool
        Disks excluded from the solve (rattlers and floating clusters); they kept their start w.
    n_newton : int
        Newton iterations (factorisations of W_ww, the final one for A included).
    residual : float
        max |W_w| * V over the relaxed disks at w* (N).
    stable : bool
        W_ww (translation fixed) was positive definite at w*.
    fixed : int
        Index of the disk fixed against rigid translation (-1: nothing relaxed).
    n_held : int
        Rattlers that could not be expelled (no room in their cage: held where the expulsion left
        them, with their contact forces; 0 normally, see "Gauge and rattlers").
    held_force : float
        Largest net contact force on a held rattler (N; 0 when none is held).
    """

    energy: float
    piola: np.ndarray
    tangent: np.ndarray
    cauchy: np.ndarray
    n_contacts: int
    fluctuation: np.ndarray
    rattlers: np.ndarray
    n_newton: int
    residual: float
    stable: bool
    fixed: int
    n_held: int = 0
    held_force: float = 0.0


@dataclass(frozen=True)
class RelaxedBatch:
    """Relaxed response at G states; fields as :class:`RelaxedResult` with a leading (G,) axis.

    energy (G,), piola (G, 2, 2), tangent (G, 2, 2, 2, 2), cauchy (G, 2, 2), n_contacts (G,),
    n_newton (G,), n_rattlers (G,), residual (G,) (N), stable (G,) bool, n_held (G,) (rattlers
    that could not be expelled).
    """

    energy: np.ndarray
    piola: np.ndarray
    tangent: np.ndarray
    cauchy: np.ndarray
    n_contacts: np.ndarray
    n_newton: np.ndarray
    n_rattlers: np.ndarray
    residual: np.ndarray
    stable: np.ndarray
    n_held: np.ndarray | None = None

    def __len__(self) -> int:
        return self.energy.shape[0]


def _particle_order(n, i, j) -> np.ndarray:
    """Minimum-degree order (n,) of the candidate graph (SuperLU's MMD on A^T + A of the graph
    Laplacian + 1): the unknowns of W_ww are numbered along it, which keeps the fill of L small
    for every active subset of the candidates."""
    keep = i != j
    g = sp.coo_matrix((np.ones(int(keep.sum())), (i[keep], j[keep])), shape=(n, n)).tocsr()
    g = g + g.T
    lap = sp.diags(np.asarray(abs(g).sum(axis=1)).ravel() + 1.0) - g
    # perm_c[k] is the position of unknown k in SuperLU's order, so the elimination order is its
    # inverse (measured on rve-700-1: 36 k entries in L, against 161 k with perm_c itself)
    return np.argsort(splu(lap.tocsc(), permc_spec="MMD_AT_PLUS_A").perm_c).astype(np.int64)


class _Candidates:
    """Contact candidates anchored at (F0, w0) with absolute skin s (see the module docstring)."""

    __slots__ = (
        "F0inv",
        "L",
        "aptr",
        "am",
        "asg",
        "ci",
        "cj",
        "cmax",
        "cmin",
        "csum",
        "_order",
        "ri",
        "rj",
        "s",
        "w0",
        "n",
    )

    def __init__(self, rve, F0, w0):
        s = rve.skin
        x = rve.X @ F0.T + w0
        nl = find_neighbours(x, rve.r, F0 @ rve.C, s)
        self.F0inv = np.linalg.inv(F0)
        self.w0 = w0.copy()
        self.ci = np.ascontiguousarray(nl.i)
        self.cj = np.ascontiguousarray(nl.j)
        self.L = np.ascontiguousarray(rve.X[nl.j] + nl.shift @ rve.C.T - rve.X[nl.i])
        self.ri = rve.r[nl.i].copy()
        self.rj = rve.r[nl.j].copy()
        self.csum = self.ri + self.rj
        self.s = s
        self.cmin = 2.0 * float(rve.r.min())
        self.cmax = 2.0 * float(rve.r.max())
        self.n = rve.n
        self._order = None
        self.aptr, self.am, self.asg = _adjacency(rve.n, self.ci, self.cj)

    @property
    def order(self) -> np.ndarray:
        """Minimum-degree order (N,) of the candidate graph (computed on first use)."""
        if self._order is None:
            self._order = _particle_order(self.n, self.ci, self.cj)
        return self._order

    def valid(self, F, w) -> bool:
        G = F @ self.F0inv
        sig = float(_smallest_singular_value(G))
        dw = w - self.w0 @ G.T
        d2 = np.einsum("ij,ij->i", dw, dw)
        if d2.size >= 2:  # the two largest moves bound |dw_i| + |dw_j| of any pair
            top = np.partition(d2, d2.size - 2)[-2:]
            delta2 = math.sqrt(float(top[0])) + math.sqrt(float(top[1]))
        else:
            delta2 = 2.0 * math.sqrt(float(d2.max())) if d2.size else 0.0
        margin = 1e-12 * self.cmax
        for c in (self.cmin, self.cmax):
            if (sig - 1.0) * c + sig * self.s - delta2 < margin:
                return False
        return True


@dataclass(frozen=True)
class _State:
    """A converged (or start) fluctuation w (N, 2) at F with its candidates and dw*/dF (N, 2, 4)."""

    w: np.ndarray
    cand: _Candidates | None
    F: np.ndarray | None = None
    S: np.ndarray | None = None

    def predict(self, F) -> np.ndarray:
        """First-order predictor w*(F) ~ w + dw*/dF : (F - F_state) (the warm start)."""
        if self.S is None:
            return self.w
        return self.w + self.S @ (F - self.F).reshape(4)


class _RVE:
    def __init__(self, packing, skin_fraction):
        self.packing = packing
        self.X = np.ascontiguousarray(packing.positions)
        self.C = np.ascontiguousarray(packing.cell)
        self.r = np.ascontiguousarray(packing.radii)
        self.n = self.r.size
        self.area = float(np.linalg.det(self.C))
        self.skin = 2.0 * skin_fraction * float(self.r.max())
        self.cmax = 2.0 * float(self.r.max())
        self.cand0 = None  # candidates anchored at w = 0 (the Taylor check of a warm start)


@njit
def _ldl_symbolic(n, Ap, Ai):
    """Elimination tree and column pointers of L from the strictly upper pattern (Ap, Ai).

    T. A. Davis, "Algorithm 849: a concise sparse Cholesky factorization package", ACM TOMS 31
    (2005), ldl_symbolic, here on 2 x 2 blocks (one node per disk). Returns parent, Lp (n + 1,)."""
    parent = np.full(n, -1, np.int64)
    lnz = np.zeros(n, np.int64)
    flag = np.empty(n, np.int64)
    for k in range(n):
        flag[k] = k
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            while flag[i] != k:
                if parent[i] == -1:
                    parent[i] = k
                lnz[i] += 1
                flag[i] = k
                i = parent[i]
    Lp = np.zeros(n + 1, np.int64)
    for k in range(n):
        Lp[k + 1] = Lp[k] + lnz[k]
    return parent, Lp


@njit
def _ldl_numeric(n, Ap, Ai, Ax, Hd, shift, parent, Lp, Li, Lx, Dinv):
    """Block LDL^T of H + shift diag|H| (2 x 2 blocks, no pivoting), Davis' up-looking ldl_numeric.

    Row k of L solves L y = H[:k, k] with y_i = D_i L_ki^T, so L_ki = y_i^T D_i^-1 and
    D_k = H_kk - sum_i L_ki y_i. Returns the number of positive definite pivot blocks D_k
    (n: H is positive definite, Sylvester's law of inertia); Dinv (n, 2, 2) receives D_k^-1."""
    Y = np.zeros((n, 2, 2))
    pattern = np.empty(n, np.int64)
    flag = np.empty(n, np.int64)
    lnz = np.zeros(n, np.int64)
    for k in range(n):
        top = n
        flag[k] = k
        lnz[k] = 0
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            Y[i, 0, 0] += Ax[p, 0, 0]
            Y[i, 0, 1] += Ax[p, 0, 1]
            Y[i, 1, 0] += Ax[p, 1, 0]
            Y[i, 1, 1] += Ax[p, 1, 1]
            ln = 0
            while flag[i] != k:
                pattern[ln] = i
                ln += 1
                flag[i] = k
                i = parent[i]
            while ln > 0:
                top -= 1
                ln -= 1
                pattern[top] = pattern[ln]
        d00 = Hd[k, 0, 0] * (1.0 + shift)
        d01 = Hd[k, 0, 1]
        d10 = Hd[k, 1, 0]
        d11 = Hd[k, 1, 1] * (1.0 + shift)
        while top < n:
            i = pattern[top]
            y00 = Y[i, 0, 0]
            y01 = Y[i, 0, 1]
            y10 = Y[i, 1, 0]
            y11 = Y[i, 1, 1]
            Y[i, 0, 0] = 0.0
            Y[i, 0, 1] = 0.0
            Y[i, 1, 0] = 0.0
            Y[i, 1, 1] = 0.0
            p2 = Lp[i] + lnz[i]
            for p in range(Lp[i], p2):
                r = Li[p]
                a00 = Lx[p, 0, 0]
                a01 = Lx[p, 0, 1]
                a10 = Lx[p, 1, 0]
                a11 = Lx[p, 1, 1]
                Y[r, 0, 0] -= a00 * y00 + a01 * y10
                Y[r, 0, 1] -= a00 * y01 + a01 * y11
                Y[r, 1, 0] -= a10 * y00 + a11 * y10
                Y[r, 1, 1] -= a10 * y01 + a11 * y11
            e00 = Dinv[i, 0, 0]
            e01 = Dinv[i, 0, 1]
            e10 = Dinv[i, 1, 0]
            e11 = Dinv[i, 1, 1]
            # L_ki = y^T Dinv_i
            l00 = y00 * e00 + y10 * e10
            l01 = y00 * e01 + y10 * e11
            l10 = y01 * e00 + y11 * e10
            l11 = y01 * e01 + y11 * e11
            d00 -= l00 * y00 + l01 * y10
            d01 -= l00 * y01 + l01 * y11
            d10 -= l10 * y00 + l11 * y10
            d11 -= l10 * y01 + l11 * y11
            Li[p2] = k
            Lx[p2, 0, 0] = l00
            Lx[p2, 0, 1] = l01
            Lx[p2, 1, 0] = l10
            Lx[p2, 1, 1] = l11
            lnz[i] += 1
            top += 1
        off = 0.5 * (d01 + d10)
        det = d00 * d11 - off * off
        if not (d00 > 0.0 and det > 0.0):
            return k
        Dinv[k, 0, 0] = d11 / det
        Dinv[k, 1, 1] = d00 / det
        Dinv[k, 0, 1] = -off / det
        Dinv[k, 1, 0] = -off / det
    return n


@njit
def _ldl_solve(Lp, Li, Lx, Dinv, X):
    """Solve (L D L^T) X = X in place; X (n, 2, m) (unknown 2 k + c is X[k, c])."""
    n = Dinv.shape[0]
    m = X.shape[2]
    for j in range(n):
        for p in range(Lp[j], Lp[j + 1]):
            r = Li[p]
            for c in range(m):
                x0 = X[j, 0, c]
                x1 = X[j, 1, c]
                X[r, 0, c] -= Lx[p, 0, 0] * x0 + Lx[p, 0, 1] * x1
                X[r, 1, c] -= Lx[p, 1, 0] * x0 + Lx[p, 1, 1] * x1
    for j in range(n):
        for c in range(m):
            x0 = X[j, 0, c]
            x1 = X[j, 1, c]
            X[j, 0, c] = Dinv[j, 0, 0] * x0 + Dinv[j, 0, 1] * x1
            X[j, 1, c] = Dinv[j, 1, 0] * x0 + Dinv[j, 1, 1] * x1
    for j in range(n - 1, -1, -1):
        for p in range(Lp[j], Lp[j + 1]):
            r = Li[p]
            for c in range(m):
                x0 = X[r, 0, c]
                x1 = X[r, 1, c]
                X[j, 0, c] -= Lx[p, 0, 0] * x0 + Lx[p, 1, 0] * x1
                X[j, 1, c] -= Lx[p, 0, 1] * x0 + Lx[p, 1, 1] * x1


def _block_matrix(Hd, Ap, Ai, Ax) -> sp.csc_matrix:
    """W_ww (ndof, ndof) as a scipy sparse matrix from the blocks of :func:`_assemble` (diagonal
    blocks Hd, strictly upper blocks Ax in block-CSC form Ap, Ai, duplicates added, and their
    transposes below the diagonal)."""
    nb = Hd.shape[0]
    bi = np.concatenate([np.arange(nb), Ai, np.repeat(np.arange(nb), np.diff(Ap))])  # block rows
    bj = np.concatenate([np.arange(nb), np.repeat(np.arange(nb), np.diff(Ap)), Ai])  # block columns
    vals = np.concatenate([Hd, Ax, np.transpose(Ax, (0, 2, 1))])  # (blocks, 2, 2)
    p = np.arange(2)
    rows = 2 * bi[:, None, None] + p[None, :, None]
    cols = 2 * bj[:, None, None] + p[None, None, :]
    rows, cols = np.broadcast_arrays(rows, cols)
    return sp.coo_matrix((vals.ravel(), (rows.ravel(), cols.ravel())), shape=(2 * nb, 2 * nb)).tocsc()


def _condensation_solve(lu: _LDL, Hd, Ap, Ai, Ax, B) -> np.ndarray:
    """(W_ww)^-1 W_wF (ndof, 4) of the condensed tangent (R5) at the converged state.

    The factorisation of the last Newton iterate serves when it needed no shift. A shifted one
    (W_ww at w* not positive definite: an equilibrium that is not a strict minimum, a buckling
    mode of compressive contacts) is not the derivative of the equilibrium branch: (R5)
    differentiates W_w(F, w*(F)) = 0 and needs W_ww itself, definite or not. It is then solved by
    a sparse LU with pivoting (SuperLU), which needs W_ww only to be non-singular; where that LU
    finds it singular (a zero mode: no unique branch), the shifted factorisation stays.
    Measured on the reduced FE2 slope's relaxed service run: the shifted solve gave tangents off
    their central differences of P by up to 8e-3 at 5 of 200 Gauss points, and the FE Newton
    converged linearly in its last step (docs/slope.md)."""
    if not lu.shifted:
        return lu.solve(B)
    try:
        return splu(_block_matrix(Hd, Ap, Ai, Ax)).solve(np.asarray(B, np.float64))
    except RuntimeError:  # SuperLU: "Factor is exactly singular"
        return lu.solve(B)


class _LDL:
    """Sparse block LDL^T of the symmetric W_ww (2 x 2 blocks per disk), no pivoting.

    The disks are numbered along a minimum-degree order of the candidate graph (see
    :func:`_particle_order`), so no further permutation is needed. If W_ww is not positive
    definite (a pivot block D_k not positive definite) it is shifted, W_ww + mu diag|W_ww| with
    mu = 1e-8, 1e-7, ... (a Levenberg-Marquardt / trust-region step); ``shifted`` records it.
    The ladder starts at a tenth of ``mu_hint`` (the shift the previous iterate needed) when given.
    """

    def __init__(self, Hd, Ap, Ai, Ax, mu_hint: float = 0.0):
        n = Hd.shape[0]
        parent, Lp = _ldl_symbolic(n, Ap, Ai)
        self.Lp = Lp
        self.Li = np.empty(Lp[-1], np.int64)
        self.Lx = np.empty((Lp[-1], 2, 2))
        self.Dinv = np.empty((n, 2, 2))
        self.shifted = False
        self.mu = 0.0
        mu = 0.0
        while _ldl_numeric(n, Ap, Ai, Ax, Hd, mu, parent, Lp, self.Li, self.Lx, self.Dinv) < n:
            self.shifted = True
            mu = max(1e-8, 0.1 * mu_hint) if mu == 0.0 else 10.0 * mu
            self.mu = mu
            if mu > 1e12:
                raise ConvergenceError("relaxed RVE: no positive definite shift of W_ww found")

    def solve(self, b):
        """x = W_ww^-1 b for b (ndof,) or (ndof, m)."""
        one = np.ndim(b) == 1
        X = np.array(b, dtype=float, order="C")  # a copy, solved in place
        shape = X.shape
        X = X.reshape(-1, 2, 1 if one else shape[1])
        _ldl_solve(self.Lp, self.Li, self.Lx, self.Dinv, X)
        return X.reshape(shape)


# ----------------------------------------------------------------------------------------------
# the compute object
# ----------------------------------------------------------------------------------------------
class RelaxedMaterial:
    """Relaxed (periodic-fluctuation) homogenized material of one or several RVEs.

    Parameters
    ----------
    packings : Packing, sequence of Packing or mapping name -> Packing
        Reference RVEs (as :class:`gransim.rve.TaylorMaterial`).
    normal_stiffness : float
        E_n of eq (4) (N/m), > 0.
    skin_fraction : float
        Candidate skin s = 2 f r_max (module docstring), > 0.
    force_tol : float
        Newton tolerance: max |W_w| V <= force_tol * mean contact force, > 0.
    max_iter : int
        Most Newton iterations per state.
    min_contacts : int
        Fewest active contacts of a relaxed disk (rattler rule), 2 or 3.
    warm_start : {"committed", "trial"}
        Where :meth:`evaluate` starts Gauss point g: ``"committed"`` (default) from its committed
        state, ``"trial"`` from its trial of the previous evaluate since the last commit or revert
        (else the committed state) (module docstring, "Gauss-point history").

    :meth:`evaluate` (G states, Gauss-point history with :meth:`commit` / :meth:`revert`) and
    :meth:`stress_and_tangent` are the FE interface; :meth:`__call__` is one stateless state;
    :meth:`energy` evaluates W(F, w) at any fluctuation.
    """

    def __init__(
        self,
        packings,
        normal_stiffness: float,
        skin_fraction: float = DEFAULT_SKIN_FRACTION,
        force_tol: float = DEFAULT_FORCE_TOL,
        max_iter: int = DEFAULT_MAX_ITER,
        min_contacts: int = DEFAULT_MIN_CONTACTS,
        warm_start: str = "committed",
    ):
        self.names, items = _as_packings(packings)
        self.normal_stiffness = as_positive_float(normal_stiffness, "normal_stiffness")
        self.skin_fraction = as_positive_float(skin_fraction, "skin_fraction")
        self.force_tol = as_positive_float(force_tol, "force_tol")
        self.max_iter = as_int(max_iter, "max_iter", 1)
        self.min_contacts = as_int(min_contacts, "min_contacts", 2, 3)
        if warm_start not in WARM_STARTS:
            raise InputError(f"warm_start: expected one of {', '.join(WARM_STARTS)}, got {warm_start!r}")
        self.warm_start = warm_start
        self._rves = [_RVE(p, self.skin_fraction) for p in items]
        self.n_builds = 0
        self._committed: dict[int, tuple[int, _State]] = {}
        self._trial: dict[int, tuple[int, _State]] | None = None

    @property
    def n_rve(self) -> int:
        """Number of RVEs."""
        return len(self._rves)

    @property
    def packings(self):
        """The reference packings, in RVE-index order."""
        return [r.packing for r in self._rves]

    # -- helpers ------------------------------------------------------------------------------
    def _rve_index(self, rve, G: int) -> np.ndarray:
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

    def _check_w(self, w, R: _RVE, name: str) -> np.ndarray:
        return as_array(w, name, (R.n, 2))

    def _cand(self, R, F, w, cand):
        if cand is None or not cand.valid(F, w):
            cand = _Candidates(R, F, w)
            self.n_builds += 1
        return cand

    def _classify(self, R, F, w, cand):
        """Rattler mask (N,), dof map (N,), fixed disk and unknowns of the current active set."""
        act = _active(F, w, cand.ci, cand.cj, cand.L, cand.csum)
        return _classify_kernel(R.n, cand.ci, cand.cj, act, self.min_contacts, cand.order)

    # -- the relaxation -------------------------------------------------------------------------
    def _expel_rattlers(self, R: _RVE, F, w, cand, rat, ftol):
        """Rattlers out of contact at (F, w), in place on w (see "Gauge and rattlers"); a move that
        invalidates the candidates rebuilds them and expels again with the new set.
        Returns (cand, held, residual): held rattlers and the largest net force on one (N)."""
        held, res = 0, 0.0
        for _ in range(4):
            moved, held, res = _expel(
                F,
                w,
                cand.ci,
                cand.cj,
                cand.L,
                cand.csum,
                cand.aptr,
                cand.am,
                cand.asg,
                rat,
                self.normal_stiffness,
                ftol,
                RATTLER_CLEARANCE,
                0.25 * R.skin,
                RATTLER_LOCAL_ITER,
                RATTLER_PASSES,
                RATTLER_GROUP,
            )
            if moved == 0 or cand.valid(F, w):
                break
            cand = self._cand(R, F, w, None)
        return self._cand(R, F, w, cand), int(held), float(res)

    def _relax(self, R: _RVE, F, w, cand):
        """Newton on (R3) from w; returns the result fields and the final state."""
        kn = self.normal_stiffness
        w = w.copy()
        n_newton = 0
        shifted_final = False
        cap = 0.25 * R.skin  # longest step of one disk (m): keeps a step inside the skin
        floor = FORCE_FLOOR * kn * R.cmax  # round-off of one disk's net force (N)
        lu = None
        tol = max(self.force_tol * kn * 1e-3 * R.cmax, floor)  # until the first assembly
        for it in range(self.max_iter + 1):
            cand = self._cand(R, F, w, cand)
            rat, dof, fixed, ndof = self._classify(R, F, w, cand)
            cand, held, rres = self._expel_rattlers(R, F, w, cand, rat, tol)
            W, P, WFF, grad, B, Hd, Ap, Ai, Ax, nc, fsum = _assemble(
                F, w, cand.ci, cand.cj, cand.L, cand.ri, cand.rj, kn, dof, ndof
            )
            gmax = float(np.max(np.abs(grad))) if ndof else 0.0
            tol = max(self.force_tol * (fsum / nc if nc else 1.0), floor)
            if ndof == 0:
                lu = None
                if rres <= tol or it == self.max_iter:
                    break
                continue
            lu = _LDL(Hd, Ap, Ai, Ax, lu.mu if lu is not None else 0.0)
            n_newton += 1
            if gmax <= tol and rres <= tol:
                shifted_final = lu.shifted
                break
            if it == self.max_iter:
                raise ConvergenceError(
                    f"relaxed RVE: Newton did not converge in max_iter = {self.max_iter} iterations "
                    f"(max |W_w| V = {gmax:.3g} N, tolerance {tol:.3g} N)"
                )
            step = -lu.solve(grad).reshape(-1, 2)
            longest = float(np.sqrt(np.max(np.einsum("ij,ij->i", step, step))))
            if longest > cap:
                step *= cap / longest
            free = np.flatnonzero(dof >= 0)
            step = step[dof[free] // 2]  # (n_free, 2) in the order of free
            slope = float(np.sum(grad.reshape(-1, 2)[dof[free] // 2] * step))
            t = 1.0
            W0 = W
            # round-off of W (J): each overlap eps = c - |l| carries the rounding of |l| ~ c, so
            # E_n eps^2 / 2 is known to E_n eps ulp(c): a few eps_machine c_max times the force sum
            w_round = max(FORCE_FLOOR * R.cmax * fsum, ENERGY_ROUNDOFF * abs(W0))
            while True:
                wt = w.copy()
                wt[free] += t * step
                ct = self._cand(R, F, wt, cand)
                ct, _, _ = self._expel_rattlers(R, F, wt, ct, rat, tol)  # W with the rattlers relaxed
                Wt = _energy(F, wt, ct.ci, ct.cj, ct.L, ct.ri, ct.rj, kn)
                if Wt <= W0 + ARMIJO * t * slope:
                    break
                if t == 1.0 and -slope <= w_round and abs(Wt - W0) <= w_round:
                    break  # W cannot resolve the step (round-off): take the Newton step (quadratic phase)
                t *= 0.5
                if t < 1e-12:
                    raise ConvergenceError(
                        f"relaxed RVE: the line search found no decrease of W at iteration {it} "
                        f"(max |W_w| V = {gmax:.3g} N, tolerance {tol:.3g} N)"
                    )
            w, cand = wt, ct
        inv = 1.0 / R.area
        S = np.zeros((R.n, 2, 4))
        if lu is None:
            A4 = WFF
        else:
            X = _condensation_solve(lu, Hd, Ap, Ai, Ax, B)  # (W_ww)^-1 W_wF, (ndof, 4)
            A4 = WFF - B.T @ X
            free = np.flatnonzero(dof >= 0)
            S[free, 0] = -X[dof[free]]
            S[free, 1] = -X[dof[free] + 1]
        A = (A4 * inv).reshape(2, 2, 2, 2)
        P = P * inv
        res = {
            "energy": W * inv,
            "piola": P,
            "tangent": A,
            "n_contacts": int(nc),
            "fluctuation": w,
            "rattlers": rat,
            "n_newton": n_newton,
            "residual": gmax,
            "stable": not shifted_final,
            "fixed": fixed,
            "n_held": held,
            "held_force": rres,
        }
        return res, _State(w, cand, F.copy(), S)

    def _solve(self, R, F, start: _State | None):
        """Relax from the start state; redo from w = 0 if the result exceeds W(F, 0); continue in F
        (:meth:`_continue`) where the start has no backbone."""
        if start is None:
            res, st = self._relax(R, F, np.zeros((R.n, 2)), None)
        else:
            res, st = self._relax(R, F, start.predict(F), start.cand)
            zero = np.zeros((R.n, 2))
            c0 = R.cand0 = self._cand(R, F, zero, R.cand0)  # anchored at w = 0, kept for the next check
            W_taylor = _energy(F, zero, c0.ci, c0.cj, c0.L, c0.ri, c0.rj, self.normal_stiffness) / R.area
            if res["energy"] > W_taylor * (1.0 + ENERGY_ROUNDOFF * 10):  # another, higher minimum
                res, st = self._relax(R, F, zero, c0)
        if res["n_held"] > 0 or (res["n_contacts"] > 0 and bool(np.all(res["rattlers"]))):
            anchors = [start] if start is not None and start.F is not None else []
            for anchor in [*anchors, None]:
                got = self._continue(R, F, anchor)
                if got is not None and got[0]["energy"] <= res["energy"] * (1.0 + ENERGY_ROUNDOFF * 10):
                    got[0]["n_newton"] += res["n_newton"]
                    res, st = got
                    break
        return res, st

    def _continue(self, R, F, anchor: _State | None):
        """Continuation in F from the anchor's (F0, w0) (None: F0 = 1, w0 = 0), see "Continuation".

        F(t) = F0 + t (F - F0), t from 0 to 1 in sub-steps, each relaxed from the previous minimiser
        (with the first-order predictor); a sub-step that ends with held rattlers or without a
        backbone is halved (down to 1/2**CONT_DEPTH). Returns (res, state) at F, or None when no
        sub-step path without held rattlers was found within CONT_STEPS relaxations."""
        F0 = np.eye(2) if anchor is None else anchor.F
        st = _State(np.zeros((R.n, 2)), None, F0.copy()) if anchor is None else anchor
        t, dt, n, its = 0.0, 1.0 / CONT_FIRST, 0, 0
        while t < 1.0:
            dt = min(dt, 1.0 - t)
            Ft = F0 + (t + dt) * (F - F0)
            res, new = self._relax(R, Ft, st.predict(Ft), st.cand)
            n += 1
            its += res["n_newton"]
            ok = res["n_held"] == 0 and not (res["n_contacts"] > 0 and bool(np.all(res["rattlers"])))
            if ok:
                t = 1.0 if t + dt >= 1.0 else t + dt
                st = new
                dt *= 2.0
                if t >= 1.0:
                    res["n_newton"] = its  # every Newton iteration of the path
                    return res, new
            else:
                dt *= 0.5
                if dt < 0.5**CONT_DEPTH:
                    return None
            if n >= CONT_STEPS:
                return None
        return None

    # -- public -------------------------------------------------------------------------------
    def __call__(self, F, rve: int = 0, start=None) -> RelaxedResult:
        """One state, stateless: relax from ``start`` ((N, 2) fluctuation (m), a previous
        :class:`RelaxedResult`, or None for w = 0)."""
        F = _check_single_F(F)
        k = int(self._rve_index(rve, 1)[0])
        R = self._rves[k]
        st = None
        if isinstance(start, RelaxedResult):
            start = start.fluctuation
        if start is not None:
            st = _State(self._check_w(start, R, "start"), None)
        res, _ = self._solve(R, F, st)
        return self._result(F, res)

    @staticmethod
    def _result(F, res) -> RelaxedResult:
        P = res["piola"]
        sig = P @ F.T / float(np.linalg.det(F))
        return RelaxedResult(
            energy=float(res["energy"]),
            piola=_ro(P),
            tangent=_ro(res["tangent"]),
            cauchy=_ro(sig),
            n_contacts=res["n_contacts"],
            fluctuation=_ro(res["fluctuation"]),
            rattlers=_ro(res["rattlers"]),
            n_newton=res["n_newton"],
            residual=float(res["residual"]),
            stable=bool(res["stable"]),
            fixed=res["fixed"],
            n_held=int(res["n_held"]),
            held_force=float(res["held_force"]),
        )

    def evaluate(self, F, rve=None, cauchy: bool = True) -> RelaxedBatch:
        """W, P, A, sigma at G Gauss points, each warm-started from its committed fluctuation or
        (``warm_start`` = "trial") its trial of the previous evaluate since the last commit or revert.

        Parameters
        ----------
        F : (G, 2, 2) or (2, 2)
            Deformation gradients, det F > 0. State g is history slot g.
        rve : None, int or (G,) int
            RVE index of each state (a slot whose RVE changed starts from w = 0).
        cauchy : bool
            Also compute sigma = P F^T / det F.

        The converged fluctuations become trials; :meth:`commit` keeps them.
        """
        F = check_deformation_gradients(F)
        G = F.shape[0]
        idx = self._rve_index(rve, G)
        out = {
            k: []
            for k in (
                "energy",
                "piola",
                "tangent",
                "n_contacts",
                "n_newton",
                "n_rattlers",
                "residual",
                "stable",
                "n_held",
            )
        }
        trial = {}
        chain = self._trial if (self.warm_start == "trial" and self._trial is not None) else {}
        for g in range(G):
            k = int(idx[g])
            prev = chain.get(g)
            if prev is None or prev[0] != k:
                prev = self._committed.get(g)
            start = prev[1] if prev is not None and prev[0] == k else None
            res, st = self._solve(self._rves[k], F[g], start)
            trial[g] = (k, st)
            for key in ("energy", "piola", "tangent", "n_contacts", "n_newton", "residual", "stable", "n_held"):
                out[key].append(res[key])
            out["n_rattlers"].append(int(np.count_nonzero(res["rattlers"])))
        self._trial = trial
        P = np.asarray(out["piola"]).reshape(G, 2, 2)
        if cauchy:
            J = F[:, 0, 0] * F[:, 1, 1] - F[:, 0, 1] * F[:, 1, 0]
            sig = np.einsum("giJ,gkJ->gik", P, F) / J[:, None, None]
        else:
            sig = np.full((G, 2, 2), np.nan)
        return RelaxedBatch(
            energy=_ro(np.asarray(out["energy"], float)),
            piola=_ro(P),
            tangent=_ro(np.asarray(out["tangent"]).reshape(G, 2, 2, 2, 2)),
            cauchy=_ro(sig),
            n_contacts=_ro(np.asarray(out["n_contacts"], np.int64)),
            n_newton=_ro(np.asarray(out["n_newton"], np.int64)),
            n_rattlers=_ro(np.asarray(out["n_rattlers"], np.int64)),
            residual=_ro(np.asarray(out["residual"], float)),
            stable=_ro(np.asarray(out["stable"], bool)),
            n_held=_ro(np.asarray(out["n_held"], np.int64)),
        )

    def fresh(self) -> RelaxedMaterial:
        """The same material (RVEs and every parameter) with an empty Gauss-point history."""
        return type(self)(
            dict(zip(self.names, self.packings, strict=True)),
            self.normal_stiffness,
            skin_fraction=self.skin_fraction,
            force_tol=self.force_tol,
            max_iter=self.max_iter,
            min_contacts=self.min_contacts,
            warm_start=self.warm_start,
        )

    def reset(self) -> None:
        """Forget the Gauss-point history (committed and trial fluctuations): every state starts
        from w = 0 again."""
        self._committed = {}
        self._trial = None

    def commit(self) -> None:
        """Make the fluctuations of the last :meth:`evaluate` the Gauss-point history."""
        if self._trial is None:
            raise InputError("commit: no trial state (call evaluate first, or it was reverted)")
        self._committed.update(self._trial)
        self._trial = None

    def revert(self) -> None:
        """Drop the trial fluctuations: the trial goes back to the committed state, the next
        :meth:`evaluate` starts from the committed fluctuations."""
        self._trial = None

    def committed_fluctuation(self, g: int) -> np.ndarray | None:
        """The committed w (N, 2) of history slot g (None before the first commit)."""
        prev = self._committed.get(int(g))
        return None if prev is None else _ro(prev[1].w.copy())

    def stress_and_tangent(self, F, rve=None) -> tuple[np.ndarray, np.ndarray]:
        """(P (G, 2, 2), A (G, 2, 2, 2, 2)) for a finite-element solver."""
        b = self.evaluate(F, rve, cauchy=False)
        return b.piola, b.tangent

    def energy(self, F, w, rve: int = 0) -> float:
        """W(F, w) of (R2) (J/m^2) at any fluctuation w (N, 2) (m), from a fresh candidate set."""
        F = _check_single_F(F)
        R = self._rves[int(self._rve_index(rve, 1)[0])]
        w = self._check_w(w, R, "w")
        c = _Candidates(R, F, w)
        return _energy(F, w, c.ci, c.cj, c.L, c.ri, c.rj, self.normal_stiffness) / R.area
