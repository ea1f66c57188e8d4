"""Dense, isotropic, periodic disk packings by pressure-controlled FIRE minimisation.

Meier, Steinmann & Kuhl (section 4) generate their RVEs with an algorithm of [MKS07] that is not
available; gransim uses its own, a standard route to jammed packings of soft disks:

1. **Sizes.** N diameters are drawn from the grain size distribution (stratified, area-weighted;
   :meth:`GrainSizeDistribution.sample`), optionally after scaling the distribution to a target
   number-mean diameter. Internally lengths are measured in units of the sample mean diameter
   d_mean and the contact stiffness is k_n = 1 (the minimum of the potential does not depend on k_n).
2. **Random start.** Centres uniform at random in a square periodic cell of solid fraction
   ``phi_start`` (0.86 by default, just above jamming), relaxed at fixed cell by FIRE until the
   residual force is below 0.1 of the mean contact force (a quench from "infinite temperature", as
   in O'Hern et al. 2003; it removes the large overlaps of the random start). A start below jamming
   (e.g. 0.3) relaxes to a loose, contact-free state instead and step 3 then compacts it slowly.
3. **Pressure control by enthalpy minimisation.** The enthalpy H = U + p A of the seed's contact
   potential U = sum_c Phi(eps_c), Phi = k_n/2 [H(eps) eps]^2 (eqs 3-4 of Meier et al.,
   :mod:`gransim.contacts.law`) at an imposed pressure p is minimised with FIRE 2.0 (Bitzek et al.
   2006; Guénolé et al. 2020) over the centres *and* the cell scale L (the cell stays square:
   isotropic expansion or compression). The generalised force on ln L is sum_c f_c |l_c| - 2 p A
   (virial pressure minus imposed pressure); the cell "mass" is N d_mean^2 so that the cell mode
   has the frequency of the particle modes. The dense quenched start expands (or a loose start
   compacts) until the contact network carries exactly p.
4. **Target.** ``mean_overlap`` mode: p is rescaled by target / achieved mean overlap and step 3
   repeated from the current state until the mean overlap over the contacts (eps > 0) is within
   ``overlap_tol`` (relative) of the target; near jamming eps is nearly proportional to p, so two
   or three passes suffice. These passes stop at a residual of 1e-2; the last pass is converged
   to ``force_tol`` at the final pressure. ``solid_fraction`` mode: jam at the small mean overlap
   :data:`JAMMING_OVERLAP`, then compress affinely to the target fraction and minimise U at fixed
   cell; a target below the jamming fraction of the protocol is a :class:`ConvergenceError`
   (no contact network exists there).
5. **Stop criterion.** Largest residual force on any disk <= ``force_tol`` times the mean
   contact force and, with the cell free, |p_virial - p| <= ``force_tol`` p.

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
from dataclasses import dataclass

import numpy as np

from .._numba import njit
from .._validate import as_positive_float
from ..contacts import find_neighbours
from ..contacts.law import force_magnitude, overlap, potential
from ..errors import ConvergenceError, InputError
from ..geometry import Packing
from .gsd import _check_count, get_distribution

#: solid fractions at or above this are refused as unreachable (a 2D disk packing with small overlaps
#: stays below ~0.91; beyond 0.95 the "packing" would be mostly overlap)
MAX_SOLID_FRACTION = 0.95
#: largest mean overlap (relative to the mean diameter) accepted as a target
MAX_MEAN_OVERLAP = 0.05
#: mean overlap / mean diameter used to jam before a solid-fraction target is imposed
JAMMING_OVERLAP = 1e-4
#: default target mean overlap / mean diameter (the dense RVE state expected by the slope problem)
DEFAULT_MEAN_OVERLAP = 2.7e-4
#: residual tolerance (relative to the mean contact force) of the fixed-cell relaxation of the random start
QUENCH_TOL = 0.1
#: residual tolerance of the pressure passes before the mean overlap is on target
PASS_TOL = 1e-2
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
@njit
def _forces(x, r, L, pi, pj, off, f, diag):
    """Contact forces of the pair candidates at cell scale L (reduced units, k_n = 1).

    f (N, 2) is overwritten with the net force on every disk. diag receives
    [energy U, virial W = sum_c f_c |l_c|, contacts, sum of overlaps, max overlap].
    """
    f[:, :] = 0.0
    U = 0.0
    W = 0.0
    nc = 0
    se = 0.0
    me = 0.0
    for c in range(pi.shape[0]):
        i = pi[c]
        j = pj[c]
        l0 = x[j, 0] - x[i, 0] + L * off[c, 0]
        l1 = x[j, 1] - x[i, 1] + L * off[c, 1]
        dist = np.sqrt(l0 * l0 + l1 * l1)
        eps = overlap(r[i], r[j], dist)
        if eps > 0.0:
            fm = force_magnitude(eps, 1.0)
            U += potential(eps, 1.0)
            W += fm * dist
            nc += 1
            se += eps
            if eps > me:
                me = eps
            g0 = fm * l0 / dist
            g1 = fm * l1 / dist
            f[i, 0] -= g0
            f[i, 1] -= g1
            f[j, 0] += g0
            f[j, 1] += g1
    diag[0] = U
    diag[1] = W
    diag[2] = nc
    diag[3] = se
    diag[4] = me


@njit
def _fire(x, v, r, pi, pj, off, x_ref, st, diag, area0, P, cell_free, me, ftol, skin, rmax, max_steps,
          dt_max, dt_min, f_inc, f_dec, alpha0, f_alpha, n_delay):
    """FIRE 2.0 minimisation of H = U + P A over centres (and the cell scale when ``cell_free``).

    State ``st`` = [L, vq, dt, alpha, n_pos, steps, L_ref, residual]: cell scale, velocity of
    q = sqrt(me) ln L, FIRE time step and mixing, steps with positive power, total steps, cell
    scale at the last neighbour build, last relative residual. Runs until converged (returns 0),
    until the neighbour list must be rebuilt (1), ``max_steps`` total steps (2), or a NaN (3).
    """
    n = x.shape[0]
    f = np.zeros((n, 2))
    sq = np.sqrt(me)
    L = st[0]
    vq = st[1]
    dt = st[2]
    alpha = st[3]
    npos = int(st[4])
    steps = int(st[5])
    L_ref = st[6]
    _forces(x, r, L, pi, pj, off, f, diag)
    while True:
        # -- one pass over the current state: residual, power, |F|^2, displacement since the build --
        A = area0 * L * L
        fq = (diag[1] - 2.0 * P * A) / sq if cell_free else 0.0
        lam = L / L_ref
        fmax2 = 0.0
        dmax2 = 0.0
        power = vq * fq
        fnorm2 = fq * fq
        for i in range(n):
            a = f[i, 0] * f[i, 0] + f[i, 1] * f[i, 1]
            fnorm2 += a
            if a > fmax2:
                fmax2 = a
            power += f[i, 0] * v[i, 0] + f[i, 1] * v[i, 1]
            d0 = x[i, 0] - lam * x_ref[i, 0]
            d1 = x[i, 1] - lam * x_ref[i, 1]
            a = d0 * d0 + d1 * d1
            if a > dmax2:
                dmax2 = a
        nc = diag[2]
        fmean = diag[3] / nc if nc > 0 else 0.0  # mean contact force (k_n = 1)
        status = -1
        if not np.isfinite(diag[0]) or not np.isfinite(L):
            status = 3
        if not cell_free and diag[0] <= UNJAMMED_ENERGY * n:
            res = 0.0  # fixed cell below jamming: every overlap has vanished
        elif nc > 0:
            res = np.sqrt(fmax2) / fmean
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
            for i in range(n):  # step half back, stop
                x[i, 0] = (x[i, 0] - 0.5 * dt * v[i, 0]) * s
                x[i, 1] = (x[i, 1] - 0.5 * dt * v[i, 1]) * s
                v[i, 0] = 0.0
                v[i, 1] = 0.0
            L *= s
            vq = 0.0
        vq += dt * fq
        vnorm2 = vq * vq
        for i in range(n):
            v[i, 0] += dt * f[i, 0]
            v[i, 1] += dt * f[i, 1]
            vnorm2 += v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]
        mix = alpha * np.sqrt(vnorm2 / fnorm2) if fnorm2 > 0.0 else 0.0
        keep = 1.0 - alpha if fnorm2 > 0.0 else 1.0
        vq = keep * vq + mix * fq
        s = np.exp(dt * vq / sq) if cell_free else 1.0
        for i in range(n):
            v[i, 0] = keep * v[i, 0] + mix * f[i, 0]
            v[i, 1] = keep * v[i, 1] + mix * f[i, 1]
            x[i, 0] = (x[i, 0] + dt * v[i, 0]) * s
            x[i, 1] = (x[i, 1] + dt * v[i, 1]) * s
        L *= s
        steps += 1
        _forces(x, r, L, pi, pj, off, f, diag)


# --------------------------------------------------------------------------------------------
# the minimiser (Python side: neighbour lists, FIRE state)
# --------------------------------------------------------------------------------------------
class _Minimiser:
    """Positions, cell scale and FIRE state of a packing being minimised (reduced units)."""

    def __init__(self, x, r, L, skin: float, fire: FireParameters):
        self.x = np.ascontiguousarray(x, dtype=float)
        self.r = np.ascontiguousarray(r, dtype=float)
        self.v = np.zeros_like(self.x)
        self.L = float(L)
        self.skin = float(skin)
        self.fire = fire
        self.me = float(self.x.shape[0])  # cell "mass": N d_mean^2 (d_mean = 1)
        self.diag = np.zeros(5)
        self.steps = 0
        self.rebuilds = 0
        self.residual = np.inf

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

    def run(self, P: float, cell_free: bool, ftol: float, max_steps: int, skin: float | None = None) -> str:
        """Minimise H = U + P A (cell free) or U (cell fixed) from the current state."""
        skin = self.skin if skin is None else float(skin)
        fp = self.fire
        self.v[:] = 0.0
        st = np.array([self.L, 0.0, fp.dt_start, fp.alpha_start, 0.0, 0.0, self.L, np.inf])
        while True:
            frac = self.x / self.L
            self.x = np.ascontiguousarray((frac - np.floor(frac)) * self.L)  # wrap (square cell)
            nl = find_neighbours(self.x, self.r, self.cell, skin)
            self.rebuilds += 1
            off = np.ascontiguousarray(nl.shift, dtype=float)  # C0 = identity
            st[0] = self.L
            st[6] = self.L
            x_ref = self.x.copy()
            done = int(st[5])
            status = _fire(self.x, self.v, self.r, nl.i, nl.j, off, x_ref, st, self.diag, 1.0, float(P),
                           bool(cell_free), self.me, float(ftol), skin, float(self.r.max()),
                           int(max_steps), fp.dt_max, fp.dt_min, fp.f_inc, fp.f_dec, fp.alpha_start,
                           fp.f_alpha, int(fp.n_delay))
            self.L = float(st[0])
            self.steps += int(st[5]) - done
            self.residual = float(st[7])
            if status != 1:
                return _STATUS[status]


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def _check_seed(seed) -> int:
    try:
        ok = float(seed) == int(seed) and int(seed) >= 0
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"seed: expected an integer >= 0, got {seed!r}")
    return int(seed)


def make_packing(distribution, n: int, seed: int, solid_fraction: float | None = None,
                 mean_overlap: float | None = None, mean_diameter: float | None = None, *,
                 density: float = 2650.0, phi_start: float = 0.86, skin: float = 0.3,
                 force_tol: float = 1e-3, overlap_tol: float = 0.02, max_steps: int = 400_000,
                 max_passes: int = 12, fire: FireParameters = FireParameters()) -> Packing:
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
        Convergence: max residual force <= force_tol x mean contact force (and the pressure to the
        same relative tolerance).
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
        N < 2, unknown distribution, targets out of range, both targets given.
    ConvergenceError
        The target is not reached (the message names the achieved phi and mean overlap).
    """
    t0 = time.perf_counter()
    dist = get_distribution(distribution)
    n = _check_count(n, "n", minimum=2)
    seed = _check_seed(seed)
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
    max_steps = _check_count(max_steps, "max_steps", minimum=1)
    max_passes = _check_count(max_passes, "max_passes", minimum=1)

    # 1. sizes (reduced units: lengths in sample mean diameters)
    rng = np.random.default_rng(seed)
    d = dist.sample(n, rng)
    ell = float(d.mean())
    r = d / (2.0 * ell)
    # 2. random start
    L = float(np.sqrt(np.pi * np.sum(r**2) / phi_start))
    x = rng.random((n, 2)) * L
    m = _Minimiser(x, r, L, skin, fire)

    # 3.-4. jam at the pressure that gives the target mean overlap
    target = mean_overlap if mean_overlap is not None else JAMMING_OVERLAP
    d2 = float(np.mean((2 * r) ** 2))
    P = 4.0 * 0.84 * target / (np.pi * d2)  # p ~ z phi <eps> <l> / (pi <d^2>), z ~ 4, phi ~ 0.84
    passes = 0
    def fail(what: str):
        raise ConvergenceError(
            f"{what} (N = {n}, seed = {seed}): reached phi = {m.phi:.5f}, mean overlap = "
            f"{m.mean_overlap:.3e} d_mean, residual = {m.residual:.2e} after {m.steps} FIRE steps")

    # the random start relaxed at fixed cell (a quench from "infinite temperature"); only the large
    # overlaps of the random start need to go, so a loose tolerance suffices
    # (with a doubled skin: the disks of the random start travel far, rebuilds would dominate)
    status = m.run(0.0, False, max(force_tol, QUENCH_TOL), max_steps, skin=2 * skin)
    if status != "converged":
        fail(f"relaxation of the random start did not converge ({status})")
    # pressure passes: loose tolerance while the pressure is being adjusted, then force_tol
    loose = max(force_tol, PASS_TOL)
    tol = loose
    while True:
        passes += 1
        status = m.run(P, True, tol, max_steps)
        if status != "converged":
            fail(f"packing did not converge ({status}) at pressure {P:.3e} k_n")
        achieved = m.mean_overlap
        if achieved > 0 and abs(achieved / target - 1.0) <= overlap_tol:
            if tol == force_tol:
                break
            tol = force_tol  # on target at the loose tolerance: converge tightly at the same pressure
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
        status = m.run(0.0, False, force_tol, max_steps)
        if status != "converged":
            fail(f"packing at solid fraction {solid_fraction} did not converge ({status})")

    # back to physical units
    packing = Packing(positions=m.x * ell, radii=r * ell, cell=m.cell * ell, density=density)
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
        "overlap_tol": overlap_tol,
        "fire": dataclasses.asdict(fire),
        "pressure_reduced": P if solid_fraction is None else None,
        "phi_jamming": phi_jam,
        "passes": passes,
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
GENERATOR_VERSION = 1

#: target mean overlap of the standard RVEs (relative to d_mean): the dense state of the slope problem
RVE_MEAN_OVERLAP = 2.7e-4
#: The Kuhn assembly: a dilute random start (phi_start = 0.3) compacted under the small pressure, which
#: jams about 0.003 looser than the default quench (mean phi 0.8478 over seeds 1-8 against ~0.851), and
#: seed 1. A frictionless jammed packing of this grading cannot reach Kuhn's void ratio 0.189 (phi 0.841):
#: measured void ratios are 0.177-0.184 over seeds 1-8. Kuhn's assembly was made by a frictional DEM (its
#: effective coordination 3.75 is below the frictionless isostatic value 4), which jams looser.
KUHN_PHI_START = 0.3
KUHN_SEED = 1
#: target mean overlap of the Kuhn assembly (relative to d_mean): below Kuhn's 0.02 % of D50
KUHN_MEAN_OVERLAP = 1e-4


def _standard_requests() -> dict:
    req = {}
    for n in (70, 350, 700):
        for seed in range(1, 6):
            req[f"rve-{n}-{seed}"] = {"distribution": "quartz-sand", "n": n, "seed": seed,
                                      "mean_overlap": RVE_MEAN_OVERLAP}
    req["kuhn-1002"] = {"distribution": "kuhn-1002", "n": 1002, "seed": KUHN_SEED,
                        "mean_overlap": KUHN_MEAN_OVERLAP, "phi_start": KUHN_PHI_START}
    return req


#: the 16 standard assemblies: name -> make_packing arguments. RVEs of Meier et al. section 4 (5 each
#: of 70, 350, 700 disks of quartz-sand, seeds 1-5) and Kuhn's 1002-disk assembly (seed 1).
STANDARD_PACKINGS = _standard_requests()


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
        packing = make_packing(**req)
        save_packing(path, packing, parameters=params, seed=req["seed"])
        out[name] = path
    return out
