"""Dense, isotropic, periodic disk packings by pressure-controlled FIRE minimisation.

Meier, Steinmann & Kuhl (section 4) generate their RVEs with an algorithm of [MKS07] that is not
available; gransim uses its own, a standard route to jammed packings of soft disks:

1. **Sizes.** N diameters are drawn from the grain size distribution (stratified, area-weighted;
   :meth:`GrainSizeDistribution.sample`), optionally after scaling the distribution to a target
   number-mean diameter. Internally lengths are measured in units of the sample mean diameter
   d_mean and the contact stiffness is k_n = 1 (the minimum of the potential does not depend on k_n).
2. **Random start.** Centres uniform at random in a square periodic cell of solid fraction
   ``phi_start`` (0.86 by default, just above jamming), relaxed at fixed cell by FIRE until the
   root-mean-square residual force is below 0.1 of the mean contact force (a quench from "infinite
   temperature", as in O'Hern et al. 2003; it removes the large overlaps of the random start). A
   start below jamming (e.g. 0.3) relaxes to a loose, contact-free state instead and step 4 then
   compacts it slowly.
3. **Pressure control by enthalpy minimisation.** The enthalpy H = U + p A of the seed's contact
   potential U = sum_c Phi(eps_c), Phi = k_n/2 [H(eps) eps]^2 (eqs 3-4 of Meier et al.,
   :mod:`gransim.contacts.law`) at an imposed pressure p is minimised with FIRE 2.0 (Bitzek et al.
   2006; Guénolé et al. 2020) over the centres *and* the cell scale L (the cell stays square:
   isotropic expansion or compression). The generalised force on ln L is sum_c f_c |l_c| - 2 p A
   (virial pressure minus imposed pressure); the cell "mass" is N d_mean^2 so that the cell mode
   has the frequency of the particle modes.
   **Decompression ladder**: H is minimised at p_k = p 3^k, k = K, ..., 1 (rms residual <= 1e-2
   each), p_K the first at or above the virial pressure of the quenched state: the well-connected
   compressed network is unloaded step by step, which is nearly elastic. Expanding the quenched
   state to p in one go overshoots into a loose state that then creeps back very slowly (84,000
   FIRE steps at 1e5 disks against ~4,000 for the whole ladder; docs/generation.md).
4. **Target.** ``mean_overlap`` mode: p is rescaled by target / achieved mean overlap and step 3
   repeated at p from the current state until the mean overlap over the contacts (eps > 0) is within
   ``overlap_tol`` (relative) of the target; near jamming eps is nearly proportional to p, so two
   or three passes suffice. These passes stop at an rms residual of 1e-2; the last pass is
   converged to ``force_tol`` at the final pressure. ``solid_fraction`` mode: jam at the small mean
   overlap :data:`JAMMING_OVERLAP`, then compress affinely to the target fraction and minimise U at
   fixed cell; a target below the jamming fraction of the protocol is a :class:`ConvergenceError`
   (no contact network exists there).
5. **Stop criterion.** Residual force <= ``force_tol`` times the mean contact force and, with the
   cell free, |p_virial - p| <= ``force_tol`` p. The residual is the largest net force on any disk
   (``residual="max"``, default) or the root-mean-square net force (``residual="rms"``).

Neighbour candidates come from :func:`gransim.contacts.find_neighbours` with a skin; the list is
rebuilt when 2 max_i |non-affine displacement_i| + (1 - L/L_build)(2 r_max + skin) exceeds the
skin, which guarantees that no contact is ever missed.

The packing fraction counts disk areas without subtracting overlaps (as :class:`Packing` does).
Rattlers (disks with fewer than 3 contacts after iteratively removing other rattlers; 3 is the
minimum for a frictionless disk in 2D) are left in place.
"""

from __future__ import annotations

import dataclasses
import time
import types
from dataclasses import dataclass

import numpy as np

from .._numba import njit, pjit, prange
from .._validate import as_int, as_positive_float, check_choice, check_memory
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential
from ..errors import ConvergenceError, InputError
from ..geometry import Packing
from .gsd import get_distribution

#: solid fractions at or above this are refused as unreachable (a 2D disk packing with small overlaps
#: stays below ~0.91; beyond 0.95 the "packing" would be mostly overlap)
MAX_SOLID_FRACTION = 0.95
#: largest mean overlap (relative to the mean diameter) accepted as a target
MAX_MEAN_OVERLAP = 0.05
#: mean overlap / mean diameter used to jam before a solid-fraction target is imposed
JAMMING_OVERLAP = 1e-4
#: default target mean overlap / mean diameter (the dense RVE state expected by the slope problem)
DEFAULT_MEAN_OVERLAP = 2.7e-4
#: residual tolerance (rms, relative to the mean contact force) of the fixed-cell relaxation of the random start
QUENCH_TOL = 0.1
#: residual tolerance (rms) of the decompression stages and of the pressure passes before the mean
#: overlap is on target
PASS_TOL = 1e-2
#: from this many disks make_packing shows a progress bar (one tick per minimisation stage)
PROGRESS_FROM = 20_000
#: pressure ratio of successive decompression stages
LADDER_FACTOR = 3.0
#: energy per disk (reduced units, k_n = d_mean = 1) below which a fixed-cell state counts as
#: unjammed (overlaps ~ 1e-8 d_mean)
UNJAMMED_ENERGY = 1e-16
#: minimum number of contacts of a non-rattler (frictionless disks in 2D: d + 1)
MIN_CONTACTS = 3

_STATUS = {0: "converged", 1: "rebuild", 2: "max_steps", 3: "diverged"}


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


# --------------------------------------------------------------------------------------------
# kernels
# --------------------------------------------------------------------------------------------
#: The pair list and the particle loops are cut into this many chunks, summed in a fixed order, so
#: the result does not depend on the number of threads (or on the serial/parallel choice below).
CHUNKS = 2
#: from this many disks the minimiser runs its chunks on numba threads (below, thread start-up per
#: step would cost more than the work)
PARALLEL_FROM = 20_000


def _forces_py(x, r, L, pi, pj, off, pcut, fb, f, dg, diag):
    """Contact forces of the pair candidates at cell scale L (reduced units, k_n = 1).

    Pairs pcut[c]:pcut[c+1] are chunk c; each accumulates into its own fb[c] (CHUNKS, N, 2) and
    dg[c]; f (N, 2) receives their sum (chunk 0 + chunk 1 + ...). diag receives
    [energy U, virial W = sum_c f_c |l_c|, contacts, sum of overlaps, max overlap].
    A candidate is a contact when |l|^2 < (r_i + r_j)^2; only then is the square root taken.
    """
    n = x.shape[0]
    for c in prange(CHUNKS):
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
                if eps > me:
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
    for c in prange(CHUNKS):
        lo = (n * c) // CHUNKS
        hi = (n * (c + 1)) // CHUNKS
        for i in range(lo, hi):
            a0 = fb[0, i, 0]
            a1 = fb[0, i, 1]
            for q in range(1, CHUNKS):
                a0 += fb[q, i, 0]
                a1 += fb[q, i, 1]
            f[i, 0] = a0
            f[i, 1] = a1
    diag[:] = 0.0
    for c in range(CHUNKS):
        for q in range(4):
            diag[q] += dg[c, q]
        if dg[c, 4] > diag[4]:
            diag[4] = dg[c, 4]


def _fire_py(x, v, r, pi, pj, off, pcut, x_ref, st, diag, area0, P, cell_free, me, ftol, rms, skin, rmax,
             max_steps, dt_max, dt_min, f_inc, f_dec, alpha0, f_alpha, n_delay):
    """FIRE 2.0 minimisation of H = U + P A over centres (and the cell scale when ``cell_free``).

    State ``st`` = [L, vq, dt, alpha, n_pos, steps, L_ref, residual]: cell scale, velocity of
    q = sqrt(me) ln L, FIRE time step and mixing, steps with positive power, total steps, cell
    scale at the last neighbour build, last relative residual. Runs until converged (returns 0),
    until the neighbour list must be rebuilt (1), ``max_steps`` total steps (2), or a NaN (3).
    The residual is the largest (``rms`` False) or the root-mean-square (``rms`` True) net force
    on a disk over the mean contact force. Particle loops run in CHUNKS chunks (partial sums combined in chunk order).
    """
    n = x.shape[0]
    f = np.zeros((n, 2))
    fb = np.zeros((CHUNKS, n, 2))
    dg = np.zeros((CHUNKS, 5))
    part = np.zeros((CHUNKS, 4))
    sq = np.sqrt(me)
    L = st[0]
    vq = st[1]
    dt = st[2]
    alpha = st[3]
    npos = int(st[4])
    steps = int(st[5])
    L_ref = st[6]
    _forces(x, r, L, pi, pj, off, pcut, fb, f, dg, diag)
    while True:
        # -- one pass over the current state: residual, power, |F|^2, displacement since the build --
        A = area0 * L * L
        fq = (diag[1] - 2.0 * P * A) / sq if cell_free else 0.0
        lam = L / L_ref
        for c in prange(CHUNKS):
            fmax2c = 0.0
            dmax2c = 0.0
            powc = 0.0
            fn2c = 0.0
            for i in range((n * c) // CHUNKS, (n * (c + 1)) // CHUNKS):
                a = f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1]
                fn2c += a
                if a > fmax2c:
                    fmax2c = a
                powc += f[i, 0] * v[i, 0] + f[i, 1] * v[i, 1]
                d0 = x[i, 0] - lam * x_ref[i, 0]
                d1 = x[i, 1] - lam * x_ref[i, 1]
                a = d0 * d0 + d1 * d1
                if a > dmax2c:
                    dmax2c = a
            part[c, 0] = fn2c
            part[c, 1] = fmax2c
            part[c, 2] = powc
            part[c, 3] = dmax2c
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
        st[7] = res
        shrink = (1.0 - lam) * (2.0 * rmax + skin) if lam < 1.0 else 0.0
        if status == 3:
            pass
        elif res <= ftol:
            status = 0
        elif 2.0 * np.sqrt(dmax2) + shrink > skin:
            status = 1
        elif steps >= max_steps:
            status = 2
        if status >= 0:
            st[0] = L
            st[1] = vq
            st[2] = dt
            st[3] = alpha
            st[4] = npos
            st[5] = steps
            return status
        # -- one FIRE 2.0 step (semi-implicit Euler, unit masses) --
        if power > 0.0:
            npos += 1
            if npos > n_delay:
                dt = min(dt * f_inc, dt_max)
                alpha *= f_alpha
        else:
            npos = 0
            if dt * f_dec >= dt_min:
                dt *= f_dec
            alpha = alpha0
            s = np.exp(-0.5 * dt * vq / sq) if cell_free else 1.0
            for c in prange(CHUNKS):  # step half back, stop
                for i in range((n * c) // CHUNKS, (n * (c + 1)) // CHUNKS):
                    x[i, 0] = (x[i, 0] - 0.5 * dt * v[i, 0]) * s
                    x[i, 1] = (x[i, 1] - 0.5 * dt * v[i, 1]) * s
                    v[i, 0] = 0.0
                    v[i, 1] = 0.0
            L *= s
            vq = 0.0
        vq += dt * fq
        for c in prange(CHUNKS):
            vn2c = 0.0
            for i in range((n * c) // CHUNKS, (n * (c + 1)) // CHUNKS):
                v[i, 0] += dt * f[i, 0]
                v[i, 1] += dt * f[i, 1]
                vn2c += v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
            part[c, 0] = vn2c
        vnorm2 = vq * vq
        for c in range(CHUNKS):
            vnorm2 += part[c, 0]
        mix = alpha * np.sqrt(vnorm2 / fnorm2) if fnorm2 > 0.0 else 0.0
        keep = 1.0 - alpha if fnorm2 > 0.0 else 1.0
        vq = keep * vq + mix * fq
        s = np.exp(dt * vq / sq) if cell_free else 1.0
        for c in prange(CHUNKS):
            for i in range((n * c) // CHUNKS, (n * (c + 1)) // CHUNKS):
                v[i, 0] = keep * v[i, 0] + mix * f[i, 0]
                v[i, 1] = keep * v[i, 1] + mix * f[i, 1]
                x[i, 0] = (x[i, 0] + dt * v[i, 0]) * s
                x[i, 1] = (x[i, 1] + dt * v[i, 1]) * s
        L *= s
        steps += 1
        _forces(x, r, L, pi, pj, off, pcut, fb, f, dg, diag)


def _variant(fn, name: str, **overrides):
    """A copy of the Python function ``fn`` named ``name`` whose globals are overridden (numba
    resolves the kernels it calls through its globals; the new name gives it its own cache file)."""
    g = dict(fn.__globals__)
    g.update(overrides)
    out = types.FunctionType(fn.__code__, g, name, fn.__defaults__, fn.__closure__)
    out.__qualname__ = name
    return out


# serial and threaded builds of the same code: the same arithmetic (fixed chunks), the same results
_forces = njit(_variant(_forces_py, "_forces"))
_fire = njit(_variant(_fire_py, "_fire", _forces=_forces))
_forces_par = pjit(_variant(_forces_py, "_forces_par"))
_fire_par = pjit(_variant(_fire_py, "_fire_par", _forces=_forces_par))


# --------------------------------------------------------------------------------------------
# the minimiser (Python side: neighbour lists, FIRE state)
# --------------------------------------------------------------------------------------------
class _Minimiser:
    """Positions, cell scale and FIRE state of a packing being minimised (reduced units).

    The disks are kept in cell-list order (sorted by the bin of their centre at every neighbour
    build) so that the force loop walks memory nearly in order; ``order[k]`` is the original index
    of the disk in slot k, and :meth:`in_original_order` undoes the permutation.
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

    def run(self, P: float, cell_free: bool, ftol: float, max_steps: int, skin: float | None = None,
            stage: str = "", rms: bool = False) -> str:
        """Minimise H = U + P A (cell free) or U (cell fixed) from the current state, until the
        largest (or, with ``rms``, the root-mean-square) net force is below ``ftol``.

        Appends {stage, pressure, tol, residual norm, steps, builds, seconds} to ``self.log``."""
        t0 = time.perf_counter()
        s0, b0 = self.steps, self.rebuilds
        if self.bar is not None:
            self.bar.set_postfix_str(f"{stage}, {self.steps} FIRE steps so far")
        status = self._run(P, cell_free, ftol, max_steps, skin, rms)
        self.log.append({"stage": stage, "pressure": float(P), "tol": float(ftol),
                         "norm": "rms" if rms else "max", "steps": self.steps - s0,
                         "builds": self.rebuilds - b0, "seconds": round(time.perf_counter() - t0, 4)})
        if self.bar is not None:
            self.bar.update(1)
        return status

    def _run(self, P, cell_free, ftol, max_steps, skin, rms):
        skin = self.skin if skin is None else float(skin)
        fp = self.fire
        fire = _fire_par if self.parallel else _fire
        self.v[:] = 0.0
        st = np.array([self.L, 0.0, fp.dt_start, fp.alpha_start, 0.0, 0.0, self.L, np.inf])
        while True:
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
            st[0] = self.L
            st[6] = self.L
            x_ref = self.x.copy()
            done = int(st[5])
            status = fire(self.x, self.v, self.r, pi, pj, off, pcut, x_ref, st, self.diag, 1.0, float(P),
                          bool(cell_free), self.me, float(ftol), bool(rms), skin, float(self.r.max()),
                          int(max_steps), fp.dt_max, fp.dt_min, fp.f_inc, fp.f_dec, fp.alpha_start,
                          fp.f_alpha, int(fp.n_delay))
            self.L = float(st[0])
            self.steps += int(st[5]) - done
            self.residual = float(st[7])
            if status != 1:
                return _STATUS[status]


#: peak memory of make_packing per disk (bytes), with a safety factor. Measured: peak resident set
#: (VmHWM, bench._memory.own_peak_kib) of a process after a JIT warm-up at N = 200, minus that
#: baseline, for quartz-sand, seed 1, residual="rms", force_tol=1e-2, divided by N: 851 B at
#: N = 1e4, 1130 B at 3e4, 910 B at 1e5 (tracemalloc peak of the numpy arrays alone: 725-808 B;
#: numba's own allocations are not traced). The largest figure times 2.2 covers the cell-list
#: rebuilds of a denser start, the statistics and the file write.
PACKING_BYTES_PER_DISK = 2500
#: above this fraction of the available memory the CLI warns before packing
MEMORY_WARN_FRACTION = 0.5


def packing_memory_estimate(n: int) -> float:
    """Estimated peak memory (bytes) of :func:`make_packing` for ``n`` disks (beyond the
    interpreter itself): :data:`PACKING_BYTES_PER_DISK` x n."""
    return float(PACKING_BYTES_PER_DISK) * float(n)


def check_packing_memory(n, name: str = "n") -> float:
    """Refuse (:class:`InputError`, with the estimate) a packing of ``n`` disks that would not fit
    into the available memory; returns estimate / available (for a warning above 0.5)."""
    n = as_int(n, name, minimum=2)
    return check_memory(packing_memory_estimate(n), f"{name}: a packing of {n:.3g} disks",
                        hint=f"estimated at {PACKING_BYTES_PER_DISK} B a disk: the measured peak of 850-1130 B a disk "
                             "with a safety factor of about 2")


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def make_packing(distribution, n: int, seed: int, solid_fraction: float | None = None,
                 mean_overlap: float | None = None, mean_diameter: float | None = None, *,
                 density: float = 2650.0, phi_start: float = 0.86, skin: float = 0.3,
                 force_tol: float = 1e-3, overlap_tol: float = 0.02, max_steps: int = 400_000,
                 max_passes: int = 12, residual: str = "max", fire: FireParameters = FireParameters()) -> Packing:
    """A dense, isotropic, periodic packing of ``n`` disks (algorithm: module docstring).

    Parameters
    ----------
    distribution : str or GrainSizeDistribution
        A shipped name (``quartz-sand``, ``kuhn-1002``) or a sieve curve.
    n : int, >= 2
        Number of disks.
    seed : int, >= 0
        Seed of the random sizes and start positions; the result is deterministic for a seed.
    solid_fraction : float, optional
        Target packing fraction phi = sum pi r^2 / A, in (0, 0.95). Must be at or above the jamming
        fraction of the protocol (else :class:`ConvergenceError`).
    mean_overlap : float, optional
        Target mean contact overlap <eps> / d_mean (dimensionless, relative to the number-mean
        diameter of the disks), in (0, 0.05]. Default (when neither target is given):
        :data:`DEFAULT_MEAN_OVERLAP` = 2.7e-4.
    mean_diameter : float, optional
        Scale the distribution to this number-mean diameter (m) first; default: its own size.
    density : float
        Mass per area of the disks (kg/m^2); default 2650 = quartz 2650 kg/m^3 x unit thickness 1 m.
    phi_start : float
        Solid fraction of the random start, in (0, 0.8].
    skin : float
        Neighbour-list skin in mean diameters.
    force_tol : float
        Convergence: residual force <= force_tol x mean contact force (and the pressure to the
        same relative tolerance).
    residual : {"max", "rms"}
        The residual of ``force_tol``: the largest net force on any disk (default: every disk in
        balance) or the root-mean-square net force over all disks. The largest of N fluctuating
        forces grows with N, so at 1e5 disks the max criterion asks far more of each disk than at
        1e3; "rms" is the same demand at every N (docs/generation.md has the measured cost).
    overlap_tol : float
        Relative tolerance on the mean overlap target.
    max_steps : int
        FIRE steps allowed per minimisation pass.
    max_passes : int
        Pressure-rescaling passes allowed to reach the mean overlap target.

    Returns
    -------
    Packing
        Positions wrapped into the square cell; ``metadata`` holds the request, the algorithm
        parameters and the achieved state (phi, mean overlap relative to d_mean and D50,
        coordination with and without rattlers, FIRE steps, residual).

    Raises
    ------
    InputError
        N < 2, unknown distribution, targets out of range, both targets given, or N disks that
        would not fit into the available memory (:func:`check_packing_memory`).
    ConvergenceError
        The target is not reached (the message names the achieved phi and mean overlap).
    """
    t0 = time.perf_counter()
    dist = get_distribution(distribution)
    n = as_int(n, "n", minimum=2)
    seed = as_int(seed, "seed", minimum=0, maximum=2**63 - 1)
    check_packing_memory(n)
    if solid_fraction is not None and mean_overlap is not None:
        raise InputError("give either solid_fraction or mean_overlap as the target, not both")
    if solid_fraction is not None:
        solid_fraction = as_positive_float(solid_fraction, "solid_fraction")
        if solid_fraction >= MAX_SOLID_FRACTION:
            raise InputError(f"solid_fraction: {solid_fraction} is unreachable for a disk packing with small "
                             f"overlaps (must be < {MAX_SOLID_FRACTION})")
    elif mean_overlap is None:
        mean_overlap = DEFAULT_MEAN_OVERLAP
    if mean_overlap is not None:
        mean_overlap = as_positive_float(mean_overlap, "mean_overlap")
        if mean_overlap > MAX_MEAN_OVERLAP:
            raise InputError(f"mean_overlap: {mean_overlap} is not a small overlap (must be <= "
                             f"{MAX_MEAN_OVERLAP} of the mean diameter)")
    if mean_diameter is not None:
        dist = dist.scaled(as_positive_float(mean_diameter, "mean_diameter"))
    density = as_positive_float(density, "density")
    phi_start = as_positive_float(phi_start, "phi_start")
    if phi_start >= MAX_SOLID_FRACTION:
        raise InputError(f"phi_start: must be < {MAX_SOLID_FRACTION}, got {phi_start}")
    skin = as_positive_float(skin, "skin")
    force_tol = as_positive_float(force_tol, "force_tol")
    overlap_tol = as_positive_float(overlap_tol, "overlap_tol")
    max_steps = as_int(max_steps, "max_steps", minimum=1)
    max_passes = as_int(max_passes, "max_passes", minimum=1)
    check_choice(residual, "residual", ("max", "rms"))

    # 1. sizes (reduced units: lengths in sample mean diameters)
    rng = np.random.default_rng(seed)
    d = dist.sample(n, rng)
    ell = float(d.mean())
    r = d / (2.0 * ell)
    # 2. random start
    L = float(np.sqrt(np.pi * np.sum(r**2) / phi_start))
    x = rng.random((n, 2)) * L
    m = _Minimiser(x, r, L, skin, fire)
    if n >= PROGRESS_FROM:  # long runs: one tick per stage on a terminal (silent in CI)
        from ..progress import progress

        m.bar = progress(total=None, desc=f"packing {n} disks", unit="stage")

    # 3.-4. jam at the pressure that gives the target mean overlap
    target = mean_overlap if mean_overlap is not None else JAMMING_OVERLAP
    d2 = float(np.mean((2 * r) ** 2))
    P = 4.0 * 0.84 * target / (np.pi * d2)  # p ~ z phi <eps> <l> / (pi <d^2>), z ~ 4, phi ~ 0.84
    passes = 0
    def fail(what: str):
        if m.bar is not None:
            m.bar.close()
        raise ConvergenceError(
            f"{what} (N = {n}, seed = {seed}): reached phi = {m.phi:.5f}, mean overlap = "
            f"{m.mean_overlap:.3e} d_mean, residual = {m.residual:.2e} after {m.steps} FIRE steps")

    # the random start relaxed at fixed cell (a quench from "infinite temperature"); only the large
    # overlaps of the random start need to go, so a loose tolerance on the rms residual suffices
    # (with a doubled skin: the disks of the random start travel far, rebuilds would dominate)
    # preparatory stages use the rms residual; the last pass uses the requested norm
    status = m.run(0.0, False, max(force_tol, QUENCH_TOL), max_steps, skin=2 * skin, stage="quench", rms=True)
    if status != "converged":
        fail(f"relaxation of the random start did not converge ({status})")
    # decompression ladder: from the first p 3^k at or above the pressure of the quenched state (the
    # first stage compacts it a little, which is fast under a high pressure) down to the target by
    # factors of LADDER_FACTOR, each stage relaxed to PASS_TOL (rms). Unloading a relaxed network is
    # nearly elastic; expanding the quenched state in one go overshoots into a loose state that then
    # creeps back slowly (at 1e5 disks: 84,000 steps instead of ~4,000).
    p_quench = m.diag[1] / (2.0 * m.L**2)
    ladder = int(np.ceil(np.log(p_quench / P) / np.log(LADDER_FACTOR))) if p_quench > P else 0
    for k in range(ladder, 0, -1):
        status = m.run(P * LADDER_FACTOR**k, True, max(force_tol, PASS_TOL), max_steps, stage=f"decompression {k}",
                       rms=True)
        if status != "converged":
            fail(f"decompression stage at pressure {P * LADDER_FACTOR**k:.3e} k_n did not converge ({status})")
    # pressure passes at the target: rms PASS_TOL while the pressure is adjusted, then force_tol in the
    # requested norm
    tol, rms = max(force_tol, PASS_TOL), True
    while True:
        passes += 1
        status = m.run(P, True, tol, max_steps, stage=f"pressure pass {passes}", rms=rms)
        if status != "converged":
            fail(f"packing did not converge ({status}) at pressure {P:.3e} k_n")
        achieved = m.mean_overlap
        if achieved > 0 and abs(achieved / target - 1.0) <= overlap_tol:
            if tol == force_tol and rms == (residual == "rms"):
                break
            # on target at the loose tolerance: converge tightly at the same pressure, requested norm
            tol, rms = force_tol, residual == "rms"
            continue
        if passes >= max_passes:
            fail(f"mean overlap target {target:.3e} d_mean not reached in {max_passes} passes")
        P *= target / achieved if achieved > 0 else 4.0
    phi_jam = m.phi

    # 4'. solid fraction target: affine compression and minimisation at fixed cell
    if solid_fraction is not None:
        if solid_fraction < phi_jam:
            raise ConvergenceError(
                f"solid_fraction {solid_fraction} is below the jamming fraction phi_J = {phi_jam:.5f} reached by "
                f"this protocol (N = {n}, seed = {seed}): no contact network exists there; ask for a "
                "mean_overlap target or a larger solid fraction")
        m.scale_to(np.sqrt(np.pi * np.sum(r**2) / solid_fraction))
        status = m.run(0.0, False, force_tol, max_steps, stage="solid fraction", rms=residual == "rms")
        if status != "converged":
            fail(f"packing at solid fraction {solid_fraction} did not converge ({status})")

    if m.bar is not None:
        m.bar.close()
    # back to physical units
    xo, ro = m.in_original_order()
    packing = Packing(positions=xo * ell, radii=ro * ell, cell=m.cell * ell, density=density)
    stats = packing_stats(packing)
    meta = {
        "generator": "gransim.generation.make_packing",
        "algorithm": "random start + pressure-controlled FIRE 2.0 (enthalpy U + pA, square cell)",
        "distribution": dist.name,
        "distribution_d50": dist.d50,
        "n": n,
        "seed": seed,
        "target_solid_fraction": solid_fraction,
        "target_mean_overlap": mean_overlap,
        "mean_diameter_target": mean_diameter,
        "phi_start": phi_start,
        "skin": skin,
        "force_tol": force_tol,
        "residual_norm": residual,
        "overlap_tol": overlap_tol,
        "fire": dataclasses.asdict(fire),
        "pressure_reduced": P if solid_fraction is None else None,
        "phi_jamming": phi_jam,
        "passes": passes,
        "decompression_stages": ladder,
        "stages": m.log,
        "fire_steps": m.steps,
        "neighbour_builds": m.rebuilds,
        "residual": m.residual,
        "solid_fraction": stats["solid_fraction"],
        "void_ratio": stats["void_ratio"],
        "mean_overlap_dmean": stats["mean_overlap_dmean"],
        "mean_overlap_d50": stats["mean_overlap_d50"],
        "max_overlap_d50": stats["max_overlap_d50"],
        "coordination": stats["coordination"],
        "coordination_nonrattler": stats["coordination_nonrattler"],
        "rattler_fraction": stats["rattler_fraction"],
        "seconds": time.perf_counter() - t0,
    }
    return packing.replace(metadata=meta)


def contact_counts(n: int, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Contacts per disk (N,) from contact pairs (a contact with its own image counts twice)."""
    return np.bincount(i, minlength=n) + np.bincount(j, minlength=n)


def rattlers(n: int, i: np.ndarray, j: np.ndarray, min_contacts: int = MIN_CONTACTS) -> np.ndarray:
    """Boolean mask (N,) of rattlers: disks left with fewer than ``min_contacts`` contacts after
    repeatedly discarding rattlers and their contacts."""
    rat = np.zeros(n, dtype=bool)
    keep = np.ones(i.shape[0], dtype=bool)
    while True:
        z = contact_counts(n, i[keep], j[keep])
        new = (z < min_contacts) & ~rat
        if not new.any():
            return rat
        rat |= new
        keep &= ~(rat[i] | rat[j])


def packing_stats(packing: Packing) -> dict:
    """Geometry and contact statistics of a packing.

    Contacts are the pairs (with periodic image) with overlap eps = r_i + r_j - |l_ij| > 0 (eq 3 of
    Meier et al.). Returns a dict with

    ``n``, ``cell`` (2x2 list, m), ``area`` (m^2), ``solid_fraction`` phi (overlaps not subtracted),
    ``void_ratio`` e = (1 - phi)/phi, ``n_contacts``, ``coordination`` Z = 2 N_c / N,
    ``n_rattlers``, ``rattler_fraction``, ``coordination_nonrattler`` (2 N_c' / N' over the
    non-rattlers; Kuhn's "effective coordination number" 2M/N), ``mean_overlap``/``max_overlap``
    (m), the same relative to D50 (``*_d50``) and to the number-mean diameter (``*_dmean``),
    ``d50`` (area-weighted median, m), ``mean_diameter``, ``d_min``, ``d_max`` (m) and
    ``fabric_anisotropy`` a = 2 (lambda_1 - lambda_2) of the contact-normal fabric
    F = <n (x) n> (0 for an isotropic network).
    """
    if not isinstance(packing, Packing):
        raise InputError(f"packing: expected a gransim.Packing, got {type(packing).__name__}")
    nl = find_neighbours(packing.positions, packing.radii, packing.cell, 0.0)
    eps = nl.overlaps(packing.radii)
    c = eps > 0
    i, j, eps = nl.i[c], nl.j[c], eps[c]
    N = packing.n
    rat = rattlers(N, i, j)
    keep = ~(rat[i] | rat[j])
    n_nr = int(N - rat.sum())
    d = 2 * packing.radii
    d50 = packing.d50
    dmean = float(d.mean())
    mean_eps = float(eps.mean()) if eps.size else 0.0
    max_eps = float(eps.max()) if eps.size else 0.0
    if eps.size:
        nrm = nl.branch[c] / np.linalg.norm(nl.branch[c], axis=1)[:, None]
        lam = np.linalg.eigvalsh(nrm.T @ nrm / nrm.shape[0])
        aniso = float(2 * (lam[1] - lam[0]))
    else:
        aniso = 0.0
    phi = packing.solid_fraction
    return {
        "n": N,
        "cell": packing.cell.tolist(),
        "area": packing.area,
        "solid_fraction": phi,
        "void_ratio": (1 - phi) / phi,
        "n_contacts": int(eps.size),
        "coordination": 2 * eps.size / N,
        "n_rattlers": int(rat.sum()),
        "rattler_fraction": float(rat.mean()),
        "coordination_nonrattler": 2 * int(keep.sum()) / n_nr if n_nr else 0.0,
        "mean_overlap": mean_eps,
        "max_overlap": max_eps,
        "mean_overlap_d50": mean_eps / d50,
        "max_overlap_d50": max_eps / d50,
        "mean_overlap_dmean": mean_eps / dmean,
        "max_overlap_dmean": max_eps / dmean,
        "d50": d50,
        "mean_diameter": dmean,
        "d_min": float(d.min()),
        "d_max": float(d.max()),
        "fabric_anisotropy": aniso,
    }


# --------------------------------------------------------------------------------------------
# the standard assemblies of the papers
# --------------------------------------------------------------------------------------------
#: bump when the algorithm changes results, so that :func:`standard_packings` regenerates files
GENERATOR_VERSION = 3  # 2: decompression ladder, rms preparatory stages, cell-list order, chunked sums;
#                       3: the Kuhn compaction is one servo phase (as one LIGGGHTS run)

#: target mean overlap of the standard RVEs (relative to d_mean): the dense state of the slope problem
RVE_MEAN_OVERLAP = 2.7e-4
#: The Kuhn assembly (002, section 4: void ratio 0.189, effective coordination 3.75, mean indentation
#: below 0.02 % of D50) is made by frictional DEM compaction (:func:`gransim.generation.compact_packing`):
#: a frictionless jammed packing of this grading is denser (e = 0.177-0.184 over seeds 1-8) and
#: better connected than Kuhn's. The preparation friction 0.05 gives e = 0.190, 0.189, 0.195, 0.196
#: for seeds 1-4 (docs/generation.md); the seed is 1. Compaction stress 1e-4 kn: mean overlap 0.9e-4 D50.
KUHN_SEED = 1
KUHN_FRICTION = 0.05
KUHN_PRESSURE = 1e-4


def _standard_requests() -> dict:
    req = {}
    for n in (70, 350, 700):
        for seed in range(1, 6):
            req[f"rve-{n}-{seed}"] = {"distribution": "quartz-sand", "n": n, "seed": seed,
                                      "mean_overlap": RVE_MEAN_OVERLAP}
    req["kuhn-1002"] = {"protocol": "compaction", "distribution": "kuhn-1002", "n": 1002, "seed": KUHN_SEED,
                        "friction": KUHN_FRICTION, "pressure": KUHN_PRESSURE}
    return req


#: the 16 standard assemblies: name -> request. RVEs of Meier et al. section 4 (5 each of 70, 350,
#: 700 disks of quartz-sand, seeds 1-5; :func:`make_packing` arguments) and Kuhn's 1002-disk
#: assembly (seed 1; ``protocol: compaction`` = :func:`gransim.generation.compact_packing` arguments).
STANDARD_PACKINGS = _standard_requests()


def build_standard(name: str) -> Packing:
    """Generate one standard assembly of :data:`STANDARD_PACKINGS` (no file written)."""
    if name not in STANDARD_PACKINGS:
        raise InputError(f"unknown standard packing {name!r}; choose from: {', '.join(STANDARD_PACKINGS)}")
    req = dict(STANDARD_PACKINGS[name])
    if req.pop("protocol", "fire") == "compaction":
        from .compaction import compact_packing

        return compact_packing(**req)
    return make_packing(**req)


def standard_packings(out_dir="results/packings", names=None, force: bool = False) -> dict:
    """Generate the standard assemblies into ``out_dir/<name>.h5`` (HDF5, :func:`gransim.io.save_packing`).

    A file that exists with the same request parameters (and generator version) is kept, so a
    rerun is cheap; ``force`` regenerates. ``names`` restricts the set (default: all 16 of
    :data:`STANDARD_PACKINGS`). Returns {name: Path} in the order of :data:`STANDARD_PACKINGS`.
    """
    from pathlib import Path

    from ..errors import ResultFileError
    from ..io import read_provenance, save_packing
    from ..progress import progress

    out_dir = Path(out_dir)
    names = list(STANDARD_PACKINGS) if names is None else list(names)
    for name in names:
        if name not in STANDARD_PACKINGS:
            raise InputError(f"unknown standard packing {name!r}; choose from: {', '.join(STANDARD_PACKINGS)}")
        if (out_dir / f"{name}.h5").is_dir():
            raise InputError(f"{out_dir / f'{name}.h5'} is a directory; the packing {name!r} is "
                             "written there")
    out = {}
    bar = progress(names, total=len(names), desc="packings")
    for name in bar:
        req = STANDARD_PACKINGS[name]
        params = {"name": name, "generator_version": GENERATOR_VERSION, **req}
        path = out_dir / f"{name}.h5"
        if path.exists() and not force:
            try:
                if read_provenance(path).get("parameters") == params:
                    out[name] = path
                    continue
            except ResultFileError:
                pass  # unreadable or foreign: regenerate
        packing = build_standard(name)
        save_packing(path, packing, parameters=params, seed=req["seed"])
        out[name] = path
    return out
