"""FIRE 2.0 minimisation of the packing enthalpy over the centres and the full cell *shape*.

The cell-shape variant of :mod:`.fire` (``make_packing(..., cell="shape")``). The cell is an
upper-triangular matrix h = [[h11, h12], [0, h22]] (columns = lattice vectors; LAMMPS' triclinic
convention, :mod:`gransim.dem.sheared`), so rigid rotations are excluded, and the enthalpy

    H(x, h) = U(x, h) + P A(h),    U = sum_c Phi(eps_c),  Phi = k_n/2 [H(eps) eps]^2,  A = det h

(eqs 3-4 of Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined
particulate systems"; reduced units k_n = 1, lengths in mean diameters) is minimised over the
centres x (N, 2) and the three entries of h. Packings minimised over the cell shape as well are
shear-stress free; Dagois-Bohy, Tighe, Simon, Henkes & van Hecke, "Soft-sphere packings at finite
pressure but unstable to shear", PRL 109, 095703 (2012), show that packings jammed at fixed cell
shape can have a negative shear modulus while these "shear-stabilised" ones cannot (their
shear-stabilisation protocol: the residual shear stress relaxed by the cell's shear degree of
freedom).

Cell degrees of freedom. A cell variation is a deformation of the current cell, dh = eps h with
eps upper triangular (e11, e12, e22), and the centres follow it affinely, dx_i = eps x_i (the
fractional coordinates s = h^-1 x are held). Every branch vector l_c = x_j - x_i + h n_c = h s_c
then changes by eps l_c, and with dPhi/dl_c = -f_c l_c / |l_c| (f_c = k_n eps_c the contact force)

    dU = -sum_c f_c (l_c . eps l_c) / |l_c| = -tr(S eps),  S = sum_c f_c l_c (x) l_c / |l_c| = A sigma,
    d(P A) = P A tr(eps),

with sigma the virial stress (compression positive, symmetric). So dH = -tr((A sigma - P A I) eps),
or, in terms of the cell matrix (eps = dh h^-1), dH/dh = -(A sigma - P A I) h^-T, and the
generalised forces on the three strain components are

    Q_11 = -dH/de11 = S_xx - P A,   Q_12 = -dH/de12 = S_xy,   Q_22 = -dH/de22 = S_yy - P A.

On the isotropic mode e11 = e22 = lambda they sum to tr S - 2 P A = sum_c f_c |l_c| - 2 P A, the
cell-scale force of :mod:`.fire`. At a stationary point sigma = P I: sigma_xx = sigma_yy = P and
sigma_xy = 0.

Integration. As in :mod:`.fire`, each strain DOF is a coordinate q = sqrt(m_e) e with the cell
"mass" m_e = N d_mean^2 (the frequency of the particle modes), velocity v_q and force
Q / sqrt(m_e). A drift over dt deforms cell and centres by G = expm(dt V / sqrt(m_e)), V the
upper-triangular matrix of the three velocities (:func:`_expm_upper`): the exact exponential, so
on the isotropic mode it is the exp(dt v_q / sqrt(m_e)) scaling of the cell-scale kernel. The
velocities are those of the current cell (a deformation rate), so no metric correction is needed.

Residual. Besides the disk residual of :mod:`.fire` (largest or rms net force over the mean
contact force), with the cell free the cell residual

    max(|sigma_xx - P|, |sigma_yy - P|, |sigma_xx - sigma_yy|, |sigma_xy|) / P

must be below the tolerance: the virial stress is isotropic and equal to P to ``ftol`` P.

Neighbour list. Rebuilt when 2 max_i |x_i - G_b x_i,build| + (1 - sigma_min(G_b)) (2 r_max + skin)
exceeds the skin, G_b = h h_build^-1 the cell deformation since the build and sigma_min its
smallest singular value (an excluded pair of gap >= skin at the build has |G_b l| >= sigma_min
|l|; the rule of :mod:`.fire` with L / L_build replaced by sigma_min). At each build the cell is
lattice-reduced (h12 -> h12 - round(h12 / h11) h11: the same lattice, |h12| <= h11 / 2) and the
centres wrapped into it, so a drifting shear cannot make the cell arbitrarily thin.

The kernel is serial (the cell-shape mode is meant for RVE-sized packings; the threaded chunks of
:mod:`.fire` are not needed there). It reuses the particle loops of :mod:`.fire`.
"""

from __future__ import annotations

import numpy as np

from .._numba import njit
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential
from ..progress import check_interrupt
from .fire import (
    _DRIFT,
    _KICK,
    _SCAN,
    _STOP,
    CHUNKS,
    K_CELL_FREE,
    K_FTOL,
    K_MAX_STEPS,
    K_ME,
    K_P,
    K_RMAX,
    K_RMS,
    K_SKIN,
    STATUS,
    UNJAMMED_ENERGY,
    FireParameters,
    StagedMinimiser,
    _particles,
    fire_adapt,
    fire_status,
    kernel_parameters,
)

# indices of the shape kernel's state vector (float64)
T_DT, T_ALPHA, T_NPOS, T_STEPS, T_RES = range(5)
N_SHAPE_STATE = 5
#: entries of the diagnostics vector of the shape kernel: [U, W = sum f |l|, contacts, sum of
#: overlaps, max overlap, S_xx, S_yy, S_xy] with S = A sigma = sum_c f_c l_c (x) l_c / |l_c|
N_SHAPE_DIAG = 8


@njit
def shape_forces(x, r, h, pi, pj, off, f, diag):
    """Net contact forces f (N, 2) on the disks x (N, 2), r (N,) in the cell h (2, 2) (columns =
    lattice vectors) over the candidate pairs (pi, pj, image shift off), reduced units (k_n = 1),
    and diag (8,) = [U, W = sum_c f_c |l_c|, contacts, sum of overlaps, max overlap, S_xx, S_yy,
    S_xy], S = sum_c f_c l_c (x) l_c / |l_c| = A sigma (the virial of the contacts, compression
    positive). l_c = x_j - x_i + h n_c."""
    f[:, :] = 0.0
    U = 0.0
    W = 0.0
    nc = 0
    se = 0.0
    me = 0.0
    sxx = 0.0
    syy = 0.0
    sxy = 0.0
    for k in range(pi.shape[0]):
        i = pi[k]
        j = pj[k]
        o0 = float(off[k, 0])
        o1 = float(off[k, 1])
        l0 = x[j, 0] - x[i, 0] + h[0, 0] * o0 + h[0, 1] * o1
        l1 = x[j, 1] - x[i, 1] + h[1, 0] * o0 + h[1, 1] * o1
        s = r[i] + r[j]
        d2 = l0 * l0 + l1 * l1
        if d2 < s * s:
            dist = np.sqrt(d2)
            eps = overlap(r[i], r[j], dist)
            fm = force_magnitude(eps, 1.0)
            U += potential(eps, 1.0)
            W += fm * dist
            nc += 1
            se += eps
            me = max(me, eps)
            q = fm / dist
            sxx += q * l0 * l0
            syy += q * l1 * l1
            sxy += q * l0 * l1
            g0 = q * l0
            g1 = q * l1
            f[i, 0] -= g0
            f[i, 1] -= g1
            f[j, 0] += g0
            f[j, 1] += g1
    diag[0] = U
    diag[1] = W
    diag[2] = nc
    diag[3] = se
    diag[4] = me
    diag[5] = sxx
    diag[6] = syy
    diag[7] = sxy


@njit
def cell_forces(diag, P, A):
    """Generalised forces (Q_11, Q_12, Q_22) = -dH/d(e11, e12, e22) of the cell strain (module
    docstring) from the virial S = diag[5:8] at pressure P and area A (reduced units)."""
    return diag[5] - P * A, diag[7], diag[6] - P * A


@njit
def cell_residual(diag, P, A):
    """max(|s_xx - P|, |s_yy - P|, |s_xx - s_yy|, |s_xy|) / P, sigma = S / A (module docstring)."""
    sx = diag[5] / A
    sy = diag[6] / A
    sxy = diag[7] / A
    return max(max(abs(sx - P), abs(sy - P)), max(abs(sx - sy), abs(sxy))) / P


@njit
def _expm_upper(a, b, c, G):
    """G = expm([[a, b], [0, c]]) = [[e^a, b (e^a - e^c) / (a - c)], [0, e^c]] (exact; the
    divided difference as e^m sinh(d) / d, m = (a + c)/2, d = (a - c)/2, by its series for small d)."""
    ea = np.exp(a)
    ec = np.exp(c)
    d = 0.5 * (a - c)
    if abs(d) < 1e-4:
        dd = np.exp(0.5 * (a + c)) * (1.0 + d * d / 6.0)
    else:
        dd = (ea - ec) / (a - c)
    G[0, 0] = ea
    G[0, 1] = b * dd
    G[1, 0] = 0.0
    G[1, 1] = ec


@njit
def _deform(G, x, h):
    """x_i <- G x_i (N, 2) and h <- G h in place (G upper triangular)."""
    for i in range(x.shape[0]):
        a = x[i, 0]
        b = x[i, 1]
        x[i, 0] = G[0, 0] * a + G[0, 1] * b
        x[i, 1] = G[1, 1] * b
    for k in range(2):
        a = h[0, k]
        b = h[1, k]
        h[0, k] = G[0, 0] * a + G[0, 1] * b
        h[1, k] = G[1, 1] * b


@njit
def _sigma_min(G):
    """Smallest singular value of a 2 x 2 matrix (without cancellation)."""
    s1 = G[0, 0] ** 2 + G[0, 1] ** 2 + G[1, 0] ** 2 + G[1, 1] ** 2
    det = G[0, 0] * G[1, 1] - G[0, 1] * G[1, 0]
    disc = np.sqrt(max(s1 * s1 - 4.0 * det * det, 0.0))
    return np.sqrt(2.0 * det * det / (s1 + disc)) if s1 > 0.0 else 0.0


@njit
def _fire_run_shape(x, v, r, pi, pj, off, x_ref, h, h_ref, hv, st, prm, diag):
    """FIRE 2.0 minimisation of H = U + P det h over centres (and the cell strain when cell free).

    x, v (N, 2) centres and velocities, r (N,) radii, (pi, pj, off) the pair candidates, x_ref
    (N, 2) the centres at the build, h (2, 2) the cell (updated in place), h_ref the cell at the
    build, hv (3,) the velocities of q = sqrt(m_e) (e11, e12, e22) (in place), st the state
    (T_* indices, in place), prm :func:`gransim.generation.fire.kernel_parameters`, diag (8,)
    :func:`shape_forces`. Returns 0 converged, 1 rebuild, 2 step budget, 3 NaN (as :mod:`.fire`).
    """
    n = x.shape[0]
    f = np.zeros((n, 2))
    part = np.zeros((CHUNKS, 4))
    x_aff = np.empty_like(x)
    G = np.zeros((2, 2))
    Gb = np.zeros((2, 2))
    P = prm[K_P]
    cell_free = prm[K_CELL_FREE] != 0.0
    sq = np.sqrt(prm[K_ME])
    ftol = prm[K_FTOL]
    rms = prm[K_RMS] != 0.0
    skin = prm[K_SKIN]
    rmax = prm[K_RMAX]
    max_steps = int(prm[K_MAX_STEPS])
    dt = st[T_DT]
    alpha = st[T_ALPHA]
    npos = int(st[T_NPOS])
    steps = int(st[T_STEPS])
    # inverse of the build cell (upper triangular)
    i00 = 1.0 / h_ref[0, 0]
    i11 = 1.0 / h_ref[1, 1]
    i01 = -h_ref[0, 1] * i00 * i11
    fc = np.zeros(3)
    shape_forces(x, r, h, pi, pj, off, f, diag)
    while True:
        A = h[0, 0] * h[1, 1] - h[0, 1] * h[1, 0]
        if cell_free:
            q11, q12, q22 = cell_forces(diag, P, A)
            fc[0] = q11 / sq
            fc[1] = q12 / sq
            fc[2] = q22 / sq
        # the cell deformation since the build and the affine image of the build centres
        Gb[0, 0] = h[0, 0] * i00
        Gb[0, 1] = h[0, 0] * i01 + h[0, 1] * i11
        Gb[1, 0] = h[1, 0] * i00
        Gb[1, 1] = h[1, 0] * i01 + h[1, 1] * i11
        for i in range(n):
            x_aff[i, 0] = Gb[0, 0] * x_ref[i, 0] + Gb[0, 1] * x_ref[i, 1]
            x_aff[i, 1] = Gb[1, 0] * x_ref[i, 0] + Gb[1, 1] * x_ref[i, 1]
        _particles(False, _SCAN, x, v, f, x_aff, part, 1.0, 0.0, 1.0, 0.0)
        power = hv[0] * fc[0] + hv[1] * fc[1] + hv[2] * fc[2]
        fnorm2 = 0.0
        fmax2 = 0.0
        dmax2 = 0.0
        for c in range(CHUNKS):
            fnorm2 += part[c, 0]
            power += part[c, 2]
            fmax2 = max(fmax2, part[c, 1])
            dmax2 = max(dmax2, part[c, 3])
        fpart2 = fnorm2
        fnorm2 += fc[0] * fc[0] + fc[1] * fc[1] + fc[2] * fc[2]
        nc = diag[2]
        fmean = diag[3] / nc if nc > 0 else 0.0
        status = -1
        if not np.isfinite(diag[0]) or not np.isfinite(A):
            status = 3
        if not cell_free and diag[0] <= UNJAMMED_ENERGY * n:
            res = 0.0
        elif nc > 0:
            res = np.sqrt(fpart2 / n if rms else fmax2) / fmean
            if cell_free:
                res = max(res, cell_residual(diag, P, A))
        else:
            res = 0.0 if not cell_free else np.inf
        st[T_RES] = res
        smin = _sigma_min(Gb)
        shrink = (1.0 - smin) * (2.0 * rmax + skin) if smin < 1.0 else 0.0
        status = fire_status(status, res, ftol, dmax2, shrink, skin, steps, max_steps)
        if status >= 0:
            st[T_DT] = dt
            st[T_ALPHA] = alpha
            st[T_NPOS] = npos
            st[T_STEPS] = steps
            return status
        # -- one FIRE 2.0 step (semi-implicit Euler, unit masses) --
        npos, dt, alpha, uphill = fire_adapt(power, npos, dt, alpha, prm)
        if uphill:
            _particles(False, _STOP, x, v, f, x_aff, part, 0.0, 0.0, 1.0, dt)  # step half back, stop
            if cell_free:
                w = -0.5 * dt / sq
                _expm_upper(w * hv[0], w * hv[1], w * hv[2], G)
                _deform(G, x, h)
            hv[:] = 0.0
        for k in range(3):
            hv[k] += dt * fc[k]
        _particles(False, _KICK, x, v, f, x_aff, part, 0.0, 0.0, 1.0, dt)
        vnorm2 = hv[0] * hv[0] + hv[1] * hv[1] + hv[2] * hv[2]
        for c in range(CHUNKS):
            vnorm2 += part[c, 0]
        mix = alpha * np.sqrt(vnorm2 / fnorm2) if fnorm2 > 0.0 else 0.0
        keep = 1.0 - alpha if fnorm2 > 0.0 else 1.0
        for k in range(3):
            hv[k] = keep * hv[k] + mix * fc[k]
        _particles(False, _DRIFT, x, v, f, x_aff, part, keep, mix, 1.0, dt)
        if cell_free:
            w = dt / sq
            _expm_upper(w * hv[0], w * hv[1], w * hv[2], G)
            _deform(G, x, h)
        steps += 1
        shape_forces(x, r, h, pi, pj, off, f, diag)


def enthalpy_and_cell_forces(x, r, cell, P: float, skin: float = 0.0):
    """H = U + P det h and the generalised cell forces (Q_11, Q_12, Q_22) = -dH/d(e11, e12, e22)
    of the shape kernel at centres x (N, 2), radii r (N,), upper-triangular cell h (2, 2), pressure
    P (reduced units, k_n = 1), with the net forces (N, 2) and the diagnostics of
    :func:`shape_forces` (for tests and analysis: the same compiled code as the minimiser)."""
    x = np.ascontiguousarray(x, dtype=float)
    r = np.ascontiguousarray(r, dtype=float)
    h = np.ascontiguousarray(cell, dtype=float)
    nl = find_neighbours(x, r, h, skin)
    f = np.zeros_like(x)
    diag = np.zeros(N_SHAPE_DIAG)
    shape_forces(x, r, h, nl.i.astype(np.int32), nl.j.astype(np.int32), np.ascontiguousarray(nl.shift), f, diag)
    A = float(np.linalg.det(h))
    return float(diag[0] + P * A), np.array(cell_forces(diag, float(P), A)), f, diag


class ShapeMinimiser(StagedMinimiser):
    """Centres, cell matrix and FIRE state of a packing minimised over the cell shape (reduced units).

    The interface of :class:`gransim.generation.fire.Minimiser` (``run``, ``cell``, ``phi``,
    ``area``, ``mean_overlap``, ``scale_to``, ``in_original_order``, ``diag``, ``log``, ``steps``,
    ``rebuilds``, ``residual``, ``bar``), with ``h`` (2, 2) the upper-triangular cell instead of a
    side L; ``diag`` has the 8 entries of :func:`shape_forces`. The start cell is the square L I.
    """

    def __init__(self, x, r, L, skin: float, fire: FireParameters):
        self.x = np.ascontiguousarray(x, dtype=float)
        self.r = np.ascontiguousarray(r, dtype=float)
        self.v = np.zeros_like(self.x)
        self.order = np.arange(self.x.shape[0])
        self.h = float(L) * np.eye(2)
        self.skin = float(skin)
        self.fire = fire
        self.me = float(self.x.shape[0])  # cell "mass": N d_mean^2 (d_mean = 1), as in .fire
        self.diag = np.zeros(N_SHAPE_DIAG)
        self.steps = 0
        self.rebuilds = 0
        self.residual = np.inf
        self.log = []
        self.bar = None

    @property
    def cell(self) -> np.ndarray:
        return self.h.copy()

    @property
    def area(self) -> float:
        return float(self.h[0, 0] * self.h[1, 1] - self.h[0, 1] * self.h[1, 0])

    @property
    def phi(self) -> float:
        return float(np.pi * np.sum(self.r**2) / self.area)

    @property
    def mean_overlap(self) -> float:
        return float(self.diag[3] / self.diag[2]) if self.diag[2] > 0 else 0.0

    @property
    def stress(self) -> np.ndarray:
        """Virial stress sigma (2, 2) of the last state (k_n per d_mean, compression positive)."""
        s = self.diag[5:8] / self.area
        return np.array([[s[0], s[2]], [s[2], s[1]]])

    def scale_to(self, L: float) -> None:
        """Affine isotropic rescaling of centres and cell to the area L^2 (the shape kept)."""
        s = float(L) / np.sqrt(self.area)
        self.x *= s
        self.h *= s

    def in_original_order(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions wrapped into the cell, radii) in the order the disks were given."""
        inv = np.empty_like(self.order)
        inv[self.order] = np.arange(self.order.size)
        frac = np.linalg.solve(self.h, self.x.T).T
        frac -= np.floor(frac)
        return (frac @ self.h.T)[inv], self.r[inv]

    def _sort(self, skin: float) -> None:
        """Lattice-reduce the cell, wrap the centres into it and renumber them by bin (row by row)."""
        k = np.round(self.h[0, 1] / self.h[0, 0])
        if k != 0.0:
            self.h[:, 1] -= k * self.h[:, 0]
        frac = np.linalg.solve(self.h, self.x.T).T
        frac -= np.floor(frac)
        nb = max(1, int(np.sqrt(self.area) / (2.0 * float(self.r.max()) + skin)))
        b = np.minimum((frac * nb).astype(np.int64), nb - 1)
        perm = np.argsort(b[:, 1] * nb + b[:, 0], kind="stable")
        self.x = np.ascontiguousarray(frac[perm] @ self.h.T)
        self.v = np.ascontiguousarray(self.v[perm])
        self.r = np.ascontiguousarray(self.r[perm])
        self.order = self.order[perm]

    def _run(self, P, cell_free, ftol, max_steps, skin, rms):
        skin = self.skin if skin is None else float(skin)
        self.v[:] = 0.0
        hv = np.zeros(3)
        st = np.array([self.fire.dt_start, self.fire.alpha_start, 0.0, 0.0, np.inf])
        while True:
            check_interrupt()  # SIGINT / SIGTERM: stop between two neighbour builds
            self._sort(skin)
            nl = find_neighbours(self.x, self.r, self.h, skin)
            self.rebuilds += 1
            pi = nl.i.astype(np.int32)
            pj = nl.j.astype(np.int32)
            off = np.ascontiguousarray(nl.shift)
            x_ref = self.x.copy()
            h_ref = self.h.copy()
            done = int(st[T_STEPS])
            prm = kernel_parameters(
                float(P),
                bool(cell_free),
                self.me,
                float(ftol),
                bool(rms),
                skin,
                float(self.r.max()),
                int(max_steps),
                self.fire,
            )
            status = _fire_run_shape(self.x, self.v, self.r, pi, pj, off, x_ref, self.h, h_ref, hv, st, prm, self.diag)
            self.steps += int(st[T_STEPS]) - done
            self.residual = float(st[T_RES])
            if status != 1:
                return STATUS[status]
