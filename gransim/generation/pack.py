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
   compacts it slowly. ``method="front"``: the centres of the advancing front of :mod:`.front`
   (touching disks, solid fraction :data:`~gransim.generation.front.FRONT_PHI`, no overlaps but
   those of the few disks the front could not place) instead, relaxed the same way; the ladder
   of step 3 then starts at K = :data:`FRONT_LADDER`. ``method="random"`` (default) is the
   method of the standard RVEs and of the stored reference runs.
3. **Pressure control by enthalpy minimisation.** The enthalpy H = U + p A of the seed's contact
   potential U = sum_c Phi(eps_c), Phi = k_n/2 [H(eps) eps]^2 (eqs 3-4 of Meier et al.,
   :mod:`gransim.contacts.law`) at an imposed pressure p is minimised with FIRE 2.0 (Bitzek et al.
   2006; Guénolé et al. 2020) over the centres *and* the cell scale L (the cell stays square:
   isotropic expansion or compression). The generalised force on ln L is sum_c f_c |l_c| - 2 p A
   (virial pressure minus imposed pressure); the cell "mass" is N d_mean^2 so that the cell mode
   has the frequency of the particle modes. ``cell="shape"``: every stage minimises over the full
   cell shape instead (an upper-triangular cell h = [[h11, h12], [0, h22]], three strain DOFs
   conjugate to A sigma - p A I, :mod:`.fire_shape`), so that the returned packing is
   shear-stress free, sigma_virial = p I to ``force_tol`` p (the "shear-stabilised" packings of
   Dagois-Bohy, Tighe, Simon, Henkes & van Hecke, "Soft-sphere packings at finite pressure but
   unstable to shear", PRL 109, 095703, 2012); the cell then comes out sheared (not square).
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
   cell free, |p_virial - p| <= ``force_tol`` p (``cell="shape"``: |sigma_xx - p|, |sigma_yy - p|,
   |sigma_xx - sigma_yy| and |sigma_xy| all <= ``force_tol`` p, default 1e-5). The residual is the
   largest net force on any disk (``residual="max"``, default) or the root-mean-square net force
   (``residual="rms"``).

The minimiser (neighbour lists, kernels) is :mod:`.fire`, the statistics :mod:`.stats`. The
packing fraction counts disk areas without subtracting overlaps (as :class:`Packing` does).
Rattlers (:func:`gransim.generation.rattlers`) are left in place.

Cost. The last pass (the largest net force below 1e-3 of the mean contact force) dominates: at
N = 2000 it takes 12,000 of 15,000 FIRE steps whichever the start (docs/generation.md).
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from .._validate import as_int, as_positive_float, check_choice, check_memory
from ..errors import ConvergenceError, InputError
from ..geometry import Packing
from ..progress import progress
from .fire import FireParameters, Minimiser
from .fire_shape import ShapeMinimiser
from .front import FRONT_PHI, front_packing
from .gsd import get_distribution
from .stats import packing_stats

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
#: the start methods of make_packing: "random" (uniform centres at phi_start, the original method:
#: the standard RVEs and the stored references), "front" (the advancing front of :mod:`.front`)
METHODS = ("random", "front")
#: the cell degrees of freedom of make_packing: "scale" (a square cell, its side only: the standard RVEs
#: and the stored references) or "shape" (the full upper-triangular cell: shear-stress-free packings)
CELL_MODES = ("scale", "shape")
#: default force_tol of make_packing with cell="scale" (the standard RVEs)
FORCE_TOL = 1e-3
#: default force_tol with cell="shape". At 1e-3 a shape-relaxed packing can stop near a saddle of the
#: enthalpy in the cell-shear direction: the fixed-cell minimum next to it (what the relaxed RVE
#: finds) keeps a shear stress of ~1e-2 p and has a negative relaxed shear stiffness (quartz-sand,
#: seed 4, N = 120: mu = -7.4e5 N/m; N = 350, seed 1: -1.5e4 N/m). At 1e-5 the same seeds end at
#: a minimum (mu = +9.2e5, +3.2e5 N/m; shear stress after relaxation <= 2e-5 p) for 1.0-2.1x the
#: FIRE steps (docs/generation.md, "Shear-stabilised packings").
SHAPE_FORCE_TOL = 1e-5
#: the FIRE settings of make_packing (frozen: one shared instance)
DEFAULT_FIRE = FireParameters()
#: decompression stages after the advancing-front start (it is below jamming: the first stage at
#: P 3^4 compacts it where rearrangements are fast; 4 measured as good as the random start's ladder)
FRONT_LADDER = 4


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
    return check_memory(
        packing_memory_estimate(n),
        f"{name}: a packing of {n:.3g} disks",
        hint=f"estimated at {PACKING_BYTES_PER_DISK} B a disk: the measured peak of 850-1130 B a disk "
        "with a safety factor of about 2",
    )


# --------------------------------------------------------------------------------------------
# public API
# --------------------------------------------------------------------------------------------
def make_packing(
    distribution,
    n: int,
    seed: int,
    solid_fraction: float | None = None,
    mean_overlap: float | None = None,
    mean_diameter: float | None = None,
    *,
    density: float = 2650.0,
    phi_start: float = 0.86,
    skin: float = 0.3,
    force_tol: float | None = None,
    overlap_tol: float = 0.02,
    max_steps: int = 400_000,
    max_passes: int = 12,
    residual: str = "max",
    fire: FireParameters = DEFAULT_FIRE,
    method: str = "random",
    cell: str = "scale",
) -> Packing:
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
        Solid fraction of the random start, in (0, 0.95) (unused by ``method="front"``).
    skin : float
        Neighbour-list skin in mean diameters.
    force_tol : float, optional
        Convergence: residual force <= force_tol x mean contact force (and the pressure to the
        same relative tolerance). Default: :data:`FORCE_TOL` = 1e-3 with ``cell="scale"``,
        :data:`SHAPE_FORCE_TOL` = 1e-5 with ``cell="shape"`` (see there: at 1e-3 the shape
        mode can stop near a saddle of the enthalpy, unstable to shear).
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
    fire : FireParameters
        FIRE 2.0 settings of every stage.
    method : {"random", "front"}
        The start (module docstring, step 2): uniform random centres (default; the standard RVEs)
        or the advancing front of :func:`gransim.generation.front.front_packing`. Both draw the
        same sizes for a seed; the packings differ.
    cell : {"scale", "shape"}
        The cell degrees of freedom of the enthalpy minimisation (module docstring, step 3):
        ``"scale"`` (default; the standard RVEs, unchanged bit for bit) keeps the cell square and
        relaxes its side, which leaves a residual shear stress of the finite network (|sigma_xy|
        or |sigma_xx - sigma_yy| / 2 up to 0.18 p in the 70- and 350-disk standard RVEs,
        docs/generation.md); ``"shape"`` relaxes the upper-triangular cell h = [[h11, h12], [0,
        h22]] as well (:mod:`gransim.generation.fire_shape`): the virial stress is isotropic,
        sigma = p I to ``force_tol`` p, and the cell is sheared (lattice-reduced, |h12| <= h11/2).
        Both draw the same sizes and start for a seed.

    Returns
    -------
    Packing
        Positions wrapped into the cell (square with ``cell="scale"``); ``metadata`` holds the request, the algorithm
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
            raise InputError(
                f"solid_fraction: {solid_fraction} is unreachable for a disk packing with small "
                f"overlaps (must be < {MAX_SOLID_FRACTION})"
            )
    elif mean_overlap is None:
        mean_overlap = DEFAULT_MEAN_OVERLAP
    if mean_overlap is not None:
        mean_overlap = as_positive_float(mean_overlap, "mean_overlap")
        if mean_overlap > MAX_MEAN_OVERLAP:
            raise InputError(
                f"mean_overlap: {mean_overlap} is not a small overlap (must be <= "
                f"{MAX_MEAN_OVERLAP} of the mean diameter)"
            )
    if mean_diameter is not None:
        dist = dist.scaled(as_positive_float(mean_diameter, "mean_diameter"))
    density = as_positive_float(density, "density")
    phi_start = as_positive_float(phi_start, "phi_start")
    if phi_start >= MAX_SOLID_FRACTION:
        raise InputError(f"phi_start: must be < {MAX_SOLID_FRACTION}, got {phi_start}")
    skin = as_positive_float(skin, "skin")
    check_choice(cell, "cell", CELL_MODES)
    if force_tol is None:
        force_tol = FORCE_TOL if cell == "scale" else SHAPE_FORCE_TOL
    force_tol = as_positive_float(force_tol, "force_tol")
    overlap_tol = as_positive_float(overlap_tol, "overlap_tol")
    max_steps = as_int(max_steps, "max_steps", minimum=1)
    max_passes = as_int(max_passes, "max_passes", minimum=1)
    check_choice(residual, "residual", ("max", "rms"))
    check_choice(method, "method", METHODS)

    # 1. sizes (reduced units: lengths in sample mean diameters)
    rng = np.random.default_rng(seed)
    d = dist.sample(n, rng)
    ell = float(d.mean())
    r = d / (2.0 * ell)
    # 2. start: random centres at phi_start, or the advancing front at FRONT_PHI
    placed = None
    if method == "front":
        L = float(np.sqrt(np.pi * np.sum(r**2) / FRONT_PHI))
        x, placed = front_packing(r, L, rng)
    else:
        L = float(np.sqrt(np.pi * np.sum(r**2) / phi_start))
        x = rng.random((n, 2)) * L
    m = Minimiser(x, r, L, skin, fire) if cell == "scale" else ShapeMinimiser(x, r, L, skin, fire)
    if n >= PROGRESS_FROM:  # long runs: one tick per stage on a terminal (silent in CI)
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
            f"{m.mean_overlap:.3e} d_mean, residual = {m.residual:.2e} after {m.steps} FIRE steps"
        )

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
    p_quench = m.diag[1] / (2.0 * m.area)
    ladder = int(np.ceil(np.log(p_quench / P) / np.log(LADDER_FACTOR))) if p_quench > P else 0
    if method == "front":
        ladder = FRONT_LADDER  # the front is below jamming: compact under P 3^K first, then unload
    for k in range(ladder, 0, -1):
        status = m.run(
            P * LADDER_FACTOR**k, True, max(force_tol, PASS_TOL), max_steps, stage=f"decompression {k}", rms=True
        )
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
                "mean_overlap target or a larger solid fraction"
            )
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
        "algorithm": (
            ("advancing-front start" if method == "front" else "random start")
            + " + pressure-controlled FIRE 2.0 (enthalpy U + pA, "
            + ("square cell)" if cell == "scale" else "cell shape: upper-triangular cell, shear-stress free)")
        ),
        "method": method,
        "cell": cell,
        "front_placed": placed,
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


def __getattr__(name: str):
    # compatibility: the catalogue moved to .standard, which imports this module; validation/cases/packings.py
    # still reads RVE_MEAN_OVERLAP from here and docs/schema_generation.md names GENERATOR_VERSION here
    # (an access-time import, no import cycle at start-up)
    if name in ("RVE_MEAN_OVERLAP", "STANDARD_PACKINGS", "GENERATOR_VERSION"):
        from . import standard  # noqa: PLC0415 - cycle: .standard imports this module

        return getattr(standard, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
