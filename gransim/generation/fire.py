"""FIRE 2.0 minimisation of the enthalpy of a periodic disk packing (reduced units).

The minimiser of :func:`gransim.generation.make_packing` and of the gas of
:func:`gransim.generation.compact_packing`: H = U + P A over the disk centres and, when the cell is
free, the scale L of a square cell, with U = sum_c Phi(eps_c), Phi = k_n/2 [H(eps) eps]^2 (eqs 3-4
of Meier, Steinmann & Kuhl, "Towards completeness, a multiscale approach of confined particulate
systems"; :mod:`gransim.contacts.law`), by FIRE 2.0 (Bitzek et al., "Structural relaxation made
simple", 2006; Guénolé et al., "Assessment and optimization of the fast inertial relaxation engine
(FIRE) for energy minimization in atomistic simulations and its implementation in LAMMPS", 2020).

Reduced units: lengths in mean diameters, k_n = 1, unit masses. The generalised force on
q = sqrt(m_e) ln L is (sum_c f_c |l_c| - 2 P A) / sqrt(m_e) (virial minus imposed pressure), with
the cell "mass" m_e = N d_mean^2 so that the cell mode has the frequency of the particle modes.

Neighbour candidates come from :func:`gransim.contacts.find_neighbours` with a skin; the list is
rebuilt when 2 max_i |non-affine displacement_i| + (1 - L/L_build)(2 r_max + skin) exceeds the
skin, which guarantees that no contact is ever missed.

Kernels. The pair list and the particle loops are cut into :data:`CHUNKS` chunks whose partial sums
are combined in chunk order, so the result does not depend on the number of threads. One driver
(:func:`_fire_run`) calls either the serial or the threaded sweep of each chunked loop; the loop
bodies are shared ``inline="always"`` kernels (the pattern of :mod:`gransim.dem.kernels`), so both
sweeps do the same operations in the same order and give the same result bit for bit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from .._numba import njit, pjit, prange
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential
from ..progress import check_interrupt

#: The pair list and the particle loops are cut into this many chunks, summed in a fixed order.
CHUNKS = 2
#: from this many disks the minimiser runs its chunks on numba threads (below, thread start-up per
#: step would cost more than the work)
PARALLEL_FROM = 20_000
#: energy per disk (reduced units, k_n = d_mean = 1) below which a fixed-cell state counts as
#: unjammed (overlaps ~ 1e-8 d_mean)
UNJAMMED_ENERGY = 1e-16

#: outcome of :func:`_fire_run` (its return code) as :meth:`Minimiser.run` reports it
STATUS = {0: "converged", 1: "rebuild", 2: "max_steps", 3: "diverged"}

# indices of the FIRE state vector (float64, :class:`FireState`)
S_L, S_VQ, S_DT, S_ALPHA, S_NPOS, S_STEPS, S_LREF, S_RES = range(8)
N_STATE = 8
# indices of the kernel parameter vector (float64, :func:`kernel_parameters`)
(
    K_AREA0,
    K_P,
    K_CELL_FREE,
    K_ME,
    K_FTOL,
    K_RMS,
    K_SKIN,
    K_RMAX,
    K_MAX_STEPS,
    K_DT_MAX,
    K_DT_MIN,
    K_F_INC,
    K_F_DEC,
    K_ALPHA0,
    K_F_ALPHA,
    K_N_DELAY,
) = range(16)
N_PARAMS = 16
# operations of the chunked particle sweep (_particle_chunk)
_SCAN, _STOP, _KICK, _DRIFT = range(4)


@dataclass(frozen=True)
class FireParameters:
    """FIRE 2.0 settings (reduced units: k_n = 1, unit masses, lengths in mean diameters)."""

    dt_start: float = 0.05
    dt_max: float = 0.4
    dt_min: float = 1e-3
    f_inc: float = 1.1
    f_dec: float = 0.5
    alpha_start: float = 0.1
    f_alpha: float = 0.99
    n_delay: int = 5


class FireState:
    """The state of one FIRE minimisation between kernel calls: a float64 vector the kernel
    updates in place, with named access.

    ``L`` cell scale, ``vq`` velocity of q = sqrt(m_e) ln L, ``dt`` FIRE time step, ``alpha``
    FIRE mixing, ``n_pos`` steps with positive power, ``steps`` total steps, ``L_ref`` cell scale
    at the last neighbour build, ``residual`` last relative residual.
    """

    _names = ("L", "vq", "dt", "alpha", "n_pos", "steps", "L_ref", "residual")

    def __init__(self, L: float, fire: FireParameters):
        self.vector = np.array([L, 0.0, fire.dt_start, fire.alpha_start, 0.0, 0.0, L, np.inf])

    def __getattr__(self, name):
        if name in FireState._names:
            return float(self.vector[FireState._names.index(name)])
        raise AttributeError(name)


def kernel_parameters(
    P: float,
    cell_free: bool,
    me: float,
    ftol: float,
    rms: bool,
    skin: float,
    rmax: float,
    max_steps: int,
    fire: FireParameters,
    area0: float = 1.0,
) -> np.ndarray:
    """The constant inputs of one minimisation as the kernel's parameter vector (N_PARAMS,):
    imposed pressure P (k_n), cell free, cell mass m_e, tolerance, rms or max residual, skin and
    largest radius (d_mean), step budget, the FIRE settings, and the cell area at L = 1."""
    v = np.empty(N_PARAMS)
    v[K_AREA0] = area0
    v[K_P] = P
    v[K_CELL_FREE] = 1.0 if cell_free else 0.0
    v[K_ME] = me
    v[K_FTOL] = ftol
    v[K_RMS] = 1.0 if rms else 0.0
    v[K_SKIN] = skin
    v[K_RMAX] = rmax
    v[K_MAX_STEPS] = max_steps
    v[K_DT_MAX] = fire.dt_max
    v[K_DT_MIN] = fire.dt_min
    v[K_F_INC] = fire.f_inc
    v[K_F_DEC] = fire.f_dec
    v[K_ALPHA0] = fire.alpha_start
    v[K_F_ALPHA] = fire.f_alpha
    v[K_N_DELAY] = fire.n_delay
    return v


# --------------------------------------------------------------------------------------------
# shared loop bodies (inlined into the serial and the threaded sweeps)
# --------------------------------------------------------------------------------------------
@njit(inline="always")
def _pair_chunk(c, x, r, L, pi, pj, off, pcut, fb, dg):
    """Contact forces of pairs pcut[c]:pcut[c+1] at cell scale L into fb[c] (N, 2) (reduced
    units, k_n = 1), and dg[c] = [energy U, virial W = sum f_c |l_c|, contacts, sum of overlaps,
    max overlap]. A candidate is a contact when |l|^2 < (r_i + r_j)^2; only then is the square
    root taken."""
    g = fb[c]
    g[:, :] = 0.0
    U = 0.0
    W = 0.0
    nc = 0
    se = 0.0
    me = 0.0
    for k in range(pcut[c], pcut[c + 1]):
        i = pi[k]
        j = pj[k]
        l0 = x[j, 0] - x[i, 0] + L * off[k, 0]
        l1 = x[j, 1] - x[i, 1] + L * off[k, 1]
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
            if eps > me:  # noqa: PLR1730 (the comparison of the original kernel, kept bit for bit)
                me = eps
            g0 = fm * l0 / dist
            g1 = fm * l1 / dist
            g[i, 0] -= g0
            g[i, 1] -= g1
            g[j, 0] += g0
            g[j, 1] += g1
    dg[c, 0] = U
    dg[c, 1] = W
    dg[c, 2] = nc
    dg[c, 3] = se
    dg[c, 4] = me


@njit(inline="always")
def _gather_chunk(c, fb, f):
    """f[i] = fb[0, i] + fb[1, i] + ... (chunk order) for the disks of chunk c."""
    n = f.shape[0]
    for i in range((n * c) // CHUNKS, (n * (c + 1)) // CHUNKS):
        a0 = fb[0, i, 0]
        a1 = fb[0, i, 1]
        for q in range(1, CHUNKS):
            a0 += fb[q, i, 0]
            a1 += fb[q, i, 1]
        f[i, 0] = a0
        f[i, 1] = a1


@njit(inline="always")
def _reduce_diag(dg, diag):
    """diag = chunk sums of dg (energy, virial, contacts, overlap sum) and the largest overlap."""
    diag[:] = 0.0
    for c in range(CHUNKS):
        for q in range(4):
            diag[q] += dg[c, q]
        if dg[c, 4] > diag[4]:  # noqa: PLR1730 (the comparison of the original kernel, kept bit for bit)
            diag[4] = dg[c, 4]


@njit(inline="always")
def _particle_chunk(op, c, x, v, f, x_ref, part, a, b, s, dt):
    """One chunked particle loop of a FIRE step over the disks of chunk c.

    _SCAN: part[c] = [sum |f|^2, max |f|^2, power f.v, max |x - a x_ref|^2] (a = L/L_build);
    _STOP: step half back and stop, x = (x - dt v/2) s, v = 0;
    _KICK: v += dt f, part[c, 0] = sum |v|^2;
    _DRIFT: v = a v + b f (a = 1 - alpha, b the FIRE mix), x = (x + dt v) s.
    """
    n = x.shape[0]
    lo = (n * c) // CHUNKS
    hi = (n * (c + 1)) // CHUNKS
    if op == _SCAN:
        fmax2c = 0.0
        dmax2c = 0.0
        powc = 0.0
        fn2c = 0.0
        for i in range(lo, hi):
            q = f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1]
            fn2c += q
            if q > fmax2c:  # noqa: PLR1730 (the comparison of the original kernel, kept bit for bit)
                fmax2c = q
            powc += f[i, 0] * v[i, 0] + f[i, 1] * v[i, 1]
            d0 = x[i, 0] - a * x_ref[i, 0]
            d1 = x[i, 1] - a * x_ref[i, 1]
            q = d0 * d0 + d1 * d1
            if q > dmax2c:  # noqa: PLR1730 (the comparison of the original kernel, kept bit for bit)
                dmax2c = q
        part[c, 0] = fn2c
        part[c, 1] = fmax2c
        part[c, 2] = powc
        part[c, 3] = dmax2c
    elif op == _STOP:
        for i in range(lo, hi):
            x[i, 0] = (x[i, 0] - 0.5 * dt * v[i, 0]) * s
            x[i, 1] = (x[i, 1] - 0.5 * dt * v[i, 1]) * s
            v[i, 0] = 0.0
            v[i, 1] = 0.0
    elif op == _KICK:
        vn2c = 0.0
        for i in range(lo, hi):
            v[i, 0] += dt * f[i, 0]
            v[i, 1] += dt * f[i, 1]
            vn2c += v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
        part[c, 0] = vn2c
    else:
        for i in range(lo, hi):
            v[i, 0] = a * v[i, 0] + b * f[i, 0]
            v[i, 1] = a * v[i, 1] + b * f[i, 1]
            x[i, 0] = (x[i, 0] + dt * v[i, 0]) * s
            x[i, 1] = (x[i, 1] + dt * v[i, 1]) * s


# --------------------------------------------------------------------------------------------
# serial and threaded sweeps (the same bodies)
# --------------------------------------------------------------------------------------------
@njit
def _forces_serial(x, r, L, pi, pj, off, pcut, fb, f, dg, diag):
    for c in range(CHUNKS):
        _pair_chunk(c, x, r, L, pi, pj, off, pcut, fb, dg)
    for c in range(CHUNKS):
        _gather_chunk(c, fb, f)
    _reduce_diag(dg, diag)


@pjit
def _forces_threaded(x, r, L, pi, pj, off, pcut, fb, f, dg, diag):
    for c in prange(CHUNKS):
        _pair_chunk(c, x, r, L, pi, pj, off, pcut, fb, dg)
    for c in prange(CHUNKS):
        _gather_chunk(c, fb, f)
    _reduce_diag(dg, diag)


@njit
def _particles_serial(op, x, v, f, x_ref, part, a, b, s, dt):
    for c in range(CHUNKS):
        _particle_chunk(op, c, x, v, f, x_ref, part, a, b, s, dt)


@pjit
def _particles_threaded(op, x, v, f, x_ref, part, a, b, s, dt):
    for c in prange(CHUNKS):
        _particle_chunk(op, c, x, v, f, x_ref, part, a, b, s, dt)


@njit
def _forces(parallel, x, r, L, pi, pj, off, pcut, fb, f, dg, diag):
    if parallel:
        _forces_threaded(x, r, L, pi, pj, off, pcut, fb, f, dg, diag)
    else:
        _forces_serial(x, r, L, pi, pj, off, pcut, fb, f, dg, diag)


@njit
def _particles(parallel, op, x, v, f, x_ref, part, a, b, s, dt):
    if parallel:
        _particles_threaded(op, x, v, f, x_ref, part, a, b, s, dt)
    else:
        _particles_serial(op, x, v, f, x_ref, part, a, b, s, dt)


@njit(inline="always")
def fire_status(status, res, ftol, dmax2, shrink, skin, steps, max_steps):
    """The stop decision of a FIRE pass, before each step: 3 (non-finite state, kept), 0 converged
    (``res`` <= ``ftol``), 1 list rebuild needed (twice the largest displacement since the build
    plus the cell's ``shrink`` of the cut-off above the ``skin``), 2 out of steps, else
    ``status`` (-1: go on). Shared by the square-cell and the cell-shape kernels."""
    if status == 3:
        return 3
    if res <= ftol:
        return 0
    if 2.0 * np.sqrt(dmax2) + shrink > skin:
        return 1
    if steps >= max_steps:
        return 2
    return status


@njit(inline="always")
def fire_adapt(power, npos, dt, alpha, prm):
    """FIRE 2.0's time step and mixing adaptation (Guenole et al. 2020, Algorithm 2): with P =
    F.v > 0 count the downhill steps and, after ``n_delay`` of them, grow dt (to dt_max) and
    shrink alpha; else reset the count, shrink dt (not below dt_min) and restart alpha. Returns
    (npos, dt, alpha, uphill): ``uphill`` True when the caller must step half back and stop the
    motion (that part differs between the square-cell and the cell-shape kernels)."""
    if power > 0.0:
        npos += 1
        if npos > int(prm[K_N_DELAY]):
            dt = min(dt * prm[K_F_INC], prm[K_DT_MAX])
            alpha *= prm[K_F_ALPHA]
        return npos, dt, alpha, False
    if dt * prm[K_F_DEC] >= prm[K_DT_MIN]:
        dt *= prm[K_F_DEC]
    return 0, dt, prm[K_ALPHA0], True


@njit
def _fire_run(x, v, r, pi, pj, off, pcut, x_ref, st, prm, diag, parallel):
    """FIRE 2.0 minimisation of H = U + P A over centres (and the cell scale when cell free).

    x, v (N, 2) centres and velocities, r (N,) radii, pi, pj, off, pcut the pair candidates (chunk
    c = pcut[c]:pcut[c+1]) with image shifts, x_ref (N, 2) the centres at the list build; st the
    FIRE state (:class:`FireState`, updated in place), prm the parameters
    (:func:`kernel_parameters`), diag (5,) receives [U, W, contacts, sum of overlaps, max
    overlap]. Runs until converged (returns 0), until the neighbour list must be rebuilt (1),
    the step budget (2), or a NaN (3). The residual is the largest (or root-mean-square) net force
    on a disk over the mean contact force, and with the cell free at least |W - 2 P A|/(2 P A).
    """
    n = x.shape[0]
    f = np.zeros((n, 2))
    fb = np.zeros((CHUNKS, n, 2))
    dg = np.zeros((CHUNKS, 5))
    part = np.zeros((CHUNKS, 4))
    area0 = prm[K_AREA0]
    P = prm[K_P]
    cell_free = prm[K_CELL_FREE] != 0.0
    me = prm[K_ME]
    ftol = prm[K_FTOL]
    rms = prm[K_RMS] != 0.0
    skin = prm[K_SKIN]
    rmax = prm[K_RMAX]
    max_steps = int(prm[K_MAX_STEPS])
    sq = np.sqrt(me)
    L = st[S_L]
    vq = st[S_VQ]
    dt = st[S_DT]
    alpha = st[S_ALPHA]
    npos = int(st[S_NPOS])
    steps = int(st[S_STEPS])
    L_ref = st[S_LREF]
    _forces(parallel, x, r, L, pi, pj, off, pcut, fb, f, dg, diag)
    while True:
        # -- one pass over the current state: residual, power, |F|^2, displacement since the build --
        A = area0 * L * L
        fq = (diag[1] - 2.0 * P * A) / sq if cell_free else 0.0
        lam = L / L_ref
        _particles(parallel, _SCAN, x, v, f, x_ref, part, lam, 0.0, 1.0, 0.0)
        power = vq * fq
        fnorm2 = 0.0
        fmax2 = 0.0
        dmax2 = 0.0
        for c in range(CHUNKS):
            fnorm2 += part[c, 0]
            power += part[c, 2]
            fmax2 = max(fmax2, part[c, 1])
            dmax2 = max(dmax2, part[c, 3])
        fpart2 = fnorm2  # disks only
        fnorm2 += fq * fq
        nc = diag[2]
        fmean = diag[3] / nc if nc > 0 else 0.0  # mean contact force (k_n = 1)
        status = -1
        if not np.isfinite(diag[0]) or not np.isfinite(L):
            status = 3
        if not cell_free and diag[0] <= UNJAMMED_ENERGY * n:
            res = 0.0  # fixed cell below jamming: every overlap has vanished
        elif nc > 0:
            res = np.sqrt(fpart2 / n if rms else fmax2) / fmean
            if cell_free:
                res = max(res, abs(diag[1] - 2.0 * P * A) / (2.0 * P * A))
        else:
            res = 0.0 if not cell_free else np.inf
        st[S_RES] = res
        shrink = (1.0 - lam) * (2.0 * rmax + skin) if lam < 1.0 else 0.0
        status = fire_status(status, res, ftol, dmax2, shrink, skin, steps, max_steps)
        if status >= 0:
            st[S_L] = L
            st[S_VQ] = vq
            st[S_DT] = dt
            st[S_ALPHA] = alpha
            st[S_NPOS] = npos
            st[S_STEPS] = steps
            return status
        # -- one FIRE 2.0 step (semi-implicit Euler, unit masses) --
        npos, dt, alpha, uphill = fire_adapt(power, npos, dt, alpha, prm)
        if uphill:
            s = np.exp(-0.5 * dt * vq / sq) if cell_free else 1.0
            _particles(parallel, _STOP, x, v, f, x_ref, part, 0.0, 0.0, s, dt)  # step half back, stop
            L *= s
            vq = 0.0
        vq += dt * fq
        _particles(parallel, _KICK, x, v, f, x_ref, part, 0.0, 0.0, 1.0, dt)
        vnorm2 = vq * vq
        for c in range(CHUNKS):
            vnorm2 += part[c, 0]
        mix = alpha * np.sqrt(vnorm2 / fnorm2) if fnorm2 > 0.0 else 0.0
        keep = 1.0 - alpha if fnorm2 > 0.0 else 1.0
        vq = keep * vq + mix * fq
        s = np.exp(dt * vq / sq) if cell_free else 1.0
        _particles(parallel, _DRIFT, x, v, f, x_ref, part, keep, mix, s, dt)
        L *= s
        steps += 1
        _forces(parallel, x, r, L, pi, pj, off, pcut, fb, f, dg, diag)


# --------------------------------------------------------------------------------------------
# the minimiser (Python side: neighbour lists, FIRE state)
# --------------------------------------------------------------------------------------------
class StagedMinimiser:
    """The stage loop shared by :class:`Minimiser` and
    :class:`gransim.generation.fire_shape.ShapeMinimiser`: :meth:`run` times one FIRE stage of
    the subclass's ``_run`` and records it (the subclass keeps ``steps``, ``rebuilds``, ``bar`` and
    ``log``)."""

    def run(
        self,
        P: float,
        cell_free: bool,
        ftol: float,
        max_steps: int,
        skin: float | None = None,
        stage: str = "",
        rms: bool = False,
    ) -> str:
        """Minimise H = U + P A (cell free) or U (cell fixed) from the current state, until the
        largest (or, with ``rms``, the root-mean-square) net force is below ``ftol`` times the
        mean contact force; returns "converged", "max_steps" or "diverged" (:data:`STATUS`).

        Appends {stage, pressure, tol, residual norm, steps, builds, seconds} to ``self.log``."""
        t0 = time.perf_counter()
        s0, b0 = self.steps, self.rebuilds
        if self.bar is not None:
            self.bar.set_postfix_str(f"{stage}, {self.steps} FIRE steps so far")
        status = self._run(P, cell_free, ftol, max_steps, skin, rms)
        self.log.append(
            {
                "stage": stage,
                "pressure": float(P),
                "tol": float(ftol),
                "norm": "rms" if rms else "max",
                "steps": self.steps - s0,
                "builds": self.rebuilds - b0,
                "seconds": round(time.perf_counter() - t0, 4),
            }
        )
        if self.bar is not None:
            self.bar.update(1)
        return status


class Minimiser(StagedMinimiser):
    """Positions, cell scale and FIRE state of a packing being minimised (reduced units).

    Parameters
    ----------
    x : (N, 2) array
        Centres (mean diameters).
    r : (N,) array
        Radii (mean diameters).
    L : float
        Side of the square cell (mean diameters).
    skin : float
        Neighbour-list skin (mean diameters).
    fire : FireParameters
    parallel : bool, optional
        Threaded sweeps (default: from :data:`PARALLEL_FROM` disks); the result is the same.

    The disks are kept in cell-list order (sorted by the bin of their centre at every neighbour
    build) so that the force loop walks memory nearly in order; ``order[k]`` is the original index
    of the disk in slot k, and :meth:`in_original_order` undoes the permutation. ``diag`` holds
    [U, W, contacts, sum of overlaps, max overlap] of the last state, ``log`` one record a stage.
    """

    def __init__(self, x, r, L, skin: float, fire: FireParameters, parallel: bool | None = None):
        self.x = np.ascontiguousarray(x, dtype=float)
        self.r = np.ascontiguousarray(r, dtype=float)
        self.v = np.zeros_like(self.x)
        self.order = np.arange(self.x.shape[0])
        self.L = float(L)
        self.skin = float(skin)
        self.fire = fire
        self.parallel = self.x.shape[0] >= PARALLEL_FROM if parallel is None else bool(parallel)
        self.me = float(self.x.shape[0])  # cell "mass": N d_mean^2 (d_mean = 1)
        self.diag = np.zeros(5)
        self.steps = 0
        self.rebuilds = 0
        self.residual = np.inf
        self.log = []
        self.bar = None  # optional progress bar (one tick per stage)

    @property
    def cell(self) -> np.ndarray:
        return np.array([[self.L, 0.0], [0.0, self.L]])

    @property
    def area(self) -> float:
        """Cell area L^2 (mean diameters squared)."""
        return self.L**2

    @property
    def phi(self) -> float:
        return float(np.pi * np.sum(self.r**2) / self.L**2)

    @property
    def mean_overlap(self) -> float:
        return float(self.diag[3] / self.diag[2]) if self.diag[2] > 0 else 0.0

    def scale_to(self, L: float) -> None:
        """Affine rescaling of centres and cell to scale L."""
        self.x *= L / self.L
        self.L = float(L)

    def in_original_order(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions, radii) in the order the disks were given."""
        inv = np.empty_like(self.order)
        inv[self.order] = np.arange(self.order.size)
        return self.x[inv], self.r[inv]

    def _sort(self, skin: float) -> None:
        """Wrap into the cell and renumber the disks by cell-list bin (row by row)."""
        frac = self.x / self.L
        frac -= np.floor(frac)
        nb = max(1, int(self.L / (2.0 * float(self.r.max()) + skin)))
        b = np.minimum((frac * nb).astype(np.int64), nb - 1)
        perm = np.argsort(b[:, 1] * nb + b[:, 0], kind="stable")
        self.x = np.ascontiguousarray(frac[perm] * self.L)
        self.v = np.ascontiguousarray(self.v[perm])
        self.r = np.ascontiguousarray(self.r[perm])
        self.order = self.order[perm]

    def _run(self, P, cell_free, ftol, max_steps, skin, rms):
        skin = self.skin if skin is None else float(skin)
        self.v[:] = 0.0
        state = FireState(self.L, self.fire)
        st = state.vector
        while True:
            check_interrupt()  # SIGINT / SIGTERM: stop between two neighbour builds
            self._sort(skin)
            nl = find_neighbours(self.x, self.r, self.cell, skin)
            self.rebuilds += 1
            # compact pair data (12 bytes a pair): the force loop is bound by memory traffic
            pi = nl.i.astype(np.int32)
            pj = nl.j.astype(np.int32)
            off = nl.shift.astype(np.int16)  # C0 = identity; |n| <= 2 unless the cell is tiny
            if not np.array_equal(off, nl.shift):
                off = np.ascontiguousarray(nl.shift)
            pcut = (np.arange(CHUNKS + 1) * pi.shape[0]) // CHUNKS
            st[S_L] = self.L
            st[S_LREF] = self.L
            x_ref = self.x.copy()
            done = int(st[S_STEPS])
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
            status = _fire_run(self.x, self.v, self.r, pi, pj, off, pcut, x_ref, st, prm, self.diag, self.parallel)
            self.L = state.L
            self.steps += int(st[S_STEPS]) - done
            self.residual = state.residual
            if status != 1:
                return STATUS[status]
