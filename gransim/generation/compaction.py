"""Frictional isotropic compaction with the DEM: dense assemblies at a chosen void ratio.

A frictionless jammed packing (:func:`gransim.generation.make_packing`) is as dense as a random
packing of its grading gets (for ``kuhn-1002``: void ratio e = 0.177-0.184). Laboratory and DEM
assemblies are looser: friction stops the rearrangements before the frictionless limit. Kuhn's
1002-disk assembly (Kuhn, "Deformation measures for granular materials", section 4: e = 0.189,
effective coordination 2M/N = 3.75, 131 disks outside the particle graph) is such an assembly.
The usual way to make one (e.g. Thornton 2000; Agnolin & Roux 2007) is to compact a granular gas
isotropically with a *preparation* friction coefficient, lower than the friction of the test,
chosen for the density wanted:

1. **Sizes**: N diameters drawn from the grading exactly as :func:`make_packing` draws them (same
   seed, same diameters).
2. **Gas**: centres uniform at random in a square periodic cell at solid fraction ``phi_gas``
   (0.70, below jamming); the overlaps of the random start are removed by frictionless FIRE at
   fixed cell, which leaves a contact-free state (energy < 1e-16 per disk in units of kn d_mean^2:
   overlaps ~ 1e-8 d_mean).
3. **Compaction**: the DEM of :mod:`gransim.dem` (Kuhn's contact law: linear normal and tangential
   springs kt = kn, Coulomb friction ``friction``, viscous damping ratio 0.3; the engine that
   matches LIGGGHTS 3.8.0 bit for bit) with both axes servo-controlled to the isotropic stress
   p = ``pressure`` kn (N/m in 2D). The servo gain 0.01/(kn dt) shrinks the box at an engineering
   strain of 0.01 p/kn per step while the gas carries no stress, and stops it when the
   network carries p.
4. **Stop**: every ``check_every`` steps, both normal stresses within ``stress_tol`` of p and the
   unbalanced force ratio (mean |net force| over disks with a contact / mean contact force
   magnitude) at most ``unbalanced_tol``.

The mean overlap is set by p: a mean contact force ~ p D50/2 over kn gives ~ 0.5 p/kn D50
(measured 0.88e-4 D50 at p = 1e-4 kn on ``kuhn-1002``). The void ratio is set by the preparation
friction: on ``kuhn-1002`` (N = 1002) e = 0.177 at friction 0, 0.189-0.196 at 0.05 (seeds 1-4),
0.205 at 0.1, 0.213 at 0.2 and 0.239 at 0.5 (docs/generation.md has the table and the command).
"""

from __future__ import annotations

import time

import numpy as np

from .._validate import as_int, as_positive_float
from ..dem.engine import DEMEngine
from ..dem.settings import AxisControl, DEMSettings, Loading
from ..errors import ConvergenceError, InputError
from ..geometry import Packing
from ..progress import check_interrupt, progress
from .fire import UNJAMMED_ENERGY, FireParameters, Minimiser
from .gsd import get_distribution
from .stats import packing_stats

#: stress (relative to kn) of the compaction: mean overlap ~ 0.9e-4 D50
DEFAULT_PRESSURE = 1e-4
#: solid fraction of the granular gas the compaction starts from
DEFAULT_PHI_GAS = 0.70
#: contact law of the compaction: viscous damping ratio of a median pair, time steps per contact
#: duration of the lightest pair, neighbour skin in D50 (:meth:`gransim.dem.DEMSettings.for_packing`)
DAMPING_RATIO = 0.3
STEPS_PER_CONTACT = 50.0
SKIN_D50 = 0.05
#: servo gain times kn dt: the box reacts over ~100 steps
SERVO_GAIN_KN_DT = 0.01


def _gas(r: np.ndarray, phi: float, rng) -> tuple[np.ndarray, float]:
    """Contact-free random centres (reduced units: radii r in mean diameters) in a square cell of
    solid fraction phi: uniform placement, overlaps removed by frictionless FIRE at fixed cell."""
    L = float(np.sqrt(np.pi * np.sum(r**2) / phi))
    x = rng.random((r.shape[0], 2)) * L
    m = Minimiser(x, r, L, 0.3, FireParameters())
    status = m.run(0.0, False, 0.1, 200_000, skin=0.6)
    if status != "converged" or m.diag[0] > UNJAMMED_ENERGY * r.shape[0]:
        raise ConvergenceError(
            f"the granular gas at phi = {phi} is not contact-free after {m.steps} FIRE steps "
            f"({status}, energy {m.diag[0]:.2e} in reduced units); use a smaller phi_gas"
        )
    return m.in_original_order()[0], L


def unbalanced_force_ratio(engine) -> float:
    """Mean |net force| over the disks that touch another / mean contact force magnitude (0 when
    there is no contact): the usual quasi-static criterion of a DEM assembly."""
    c = engine.contacts()
    if c["i"].size == 0:
        return 0.0
    fc = np.linalg.norm(c["force"], axis=1).mean()
    touching = np.bincount(c["i"], minlength=engine.r.size) + np.bincount(c["j"], minlength=engine.r.size) > 0
    fnet = np.linalg.norm(engine.f[touching], axis=1).mean()
    return float(fnet / fc) if fc > 0 else 0.0


def _setup(dist, n, seed, friction, pressure, phi_gas, density, kn):
    """The granular gas, the DEM settings and the servo loading of a compaction (steps 1-3)."""
    rng = np.random.default_rng(seed)
    d = dist.sample(n, rng)
    ell = float(d.mean())
    r = d / (2.0 * ell)
    x, L = _gas(r, phi_gas, rng)
    gas = Packing(positions=x * ell, radii=r * ell, cell=np.eye(2) * L * ell, density=density)  # as make_packing
    dem = DEMSettings.for_packing(
        gas, kn, mu=friction, damping_ratio=DAMPING_RATIO, steps_per_contact=STEPS_PER_CONTACT, skin_d50=SKIN_D50
    )
    servo = AxisControl("servo", target=pressure * kn, gain=SERVO_GAIN_KN_DT / (kn * dem.dt))
    return gas, dem, Loading(x=servo, y=servo)


def compaction_run(packing: Packing):
    """The DEM run that made a packing of :func:`compact_packing`, from its metadata.

    Returns (gas, settings, loading, nsteps): the initial granular gas (Packing), the
    :class:`~gransim.dem.DEMSettings`, the servo :class:`~gransim.dem.Loading` and the number of
    steps, so that the compaction can be replayed, e.g. by LIGGGHTS (validation case ``packings``).
    The final state of that run, wrapped into [0, L), is the packing.
    """
    m = packing.metadata
    if m.get("generator") != "gransim.generation.compact_packing":
        raise InputError(f"packing: not made by compact_packing (metadata 'generator' is {m.get('generator')!r})")
    dist = get_distribution(m["distribution"])
    if m.get("mean_diameter_target") is not None:
        dist = dist.scaled(m["mean_diameter_target"])
    gas, dem, loading = _setup(
        dist, m["n"], m["seed"], m["friction"], m["pressure_over_kn"], m["phi_gas"], packing.density, m["dem"]["kn"]
    )
    # packings written before DEMSettings had a flavour were made in LIGGGHTS' arithmetic (the only one)
    if dem.to_dict() != {"flavour": "liggghts", **m["dem"]}:
        raise InputError(
            "packing: the DEM settings rebuilt from its metadata differ from the stored ones "
            "(made by another gransim version?)"
        )
    return gas, dem, loading, int(m["dem_steps"])


def compact_packing(
    distribution,
    n: int,
    seed: int,
    friction: float,
    *,
    pressure: float = DEFAULT_PRESSURE,
    phi_gas: float = DEFAULT_PHI_GAS,
    mean_diameter: float | None = None,
    density: float = 2650.0,
    kn: float = 1e5,
    stress_tol: float = 0.01,
    unbalanced_tol: float = 1e-3,
    check_every: int = 2000,
    max_steps: int = 2_000_000,
) -> Packing:
    """A dense periodic assembly made by frictional isotropic DEM compaction (module docstring).

    Parameters
    ----------
    distribution : str or GrainSizeDistribution
        Grading (``quartz-sand``, ``kuhn-1002`` or a sieve curve).
    n : int, >= 2
        Number of disks.
    seed : int, >= 0
        Seed of the sizes and the gas; the result is deterministic for a seed.
    friction : float, >= 0
        Preparation friction coefficient (sets the density: more friction, looser).
    pressure : float
        Isotropic stress of the compaction relative to kn (dimensionless; p = pressure kn, N/m).
    phi_gas : float
        Solid fraction of the gas, in (0, 0.8).
    mean_diameter : float, optional
        Scale the grading to this number-mean diameter (m) first.
    density : float
        Mass per area (kg/m^2).
    kn : float
        Normal (= tangential) contact stiffness (N/m); the result depends only on pressure = p/kn.
    stress_tol, unbalanced_tol : float
        Stop criterion (step 4).
    check_every : int
        Steps between checks of the criterion.
    max_steps : int
        DEM steps allowed (else :class:`ConvergenceError`).

    Returns
    -------
    Packing
        Positions wrapped into the orthogonal cell of the final state; ``metadata`` holds the
        request, the DEM settings, the steps, the unbalanced force ratio and the statistics of
        :func:`packing_stats` (void ratio, coordination, overlaps).
    """
    t0 = time.perf_counter()
    dist = get_distribution(distribution)
    n = as_int(n, "n", minimum=2)
    seed = as_int(seed, "seed", minimum=0)
    friction = as_positive_float(friction, "friction", allow_zero=True)
    pressure = as_positive_float(pressure, "pressure")
    if pressure > 1e-2:
        raise InputError(f"pressure: {pressure} kn is not a small-overlap state (must be <= 1e-2)")
    phi_gas = as_positive_float(phi_gas, "phi_gas")
    if phi_gas >= 0.8:
        raise InputError(f"phi_gas: must be < 0.8 (a gas below jamming), got {phi_gas}")
    if mean_diameter is not None:
        dist = dist.scaled(as_positive_float(mean_diameter, "mean_diameter"))
    density = as_positive_float(density, "density")
    kn = as_positive_float(kn, "kn")
    stress_tol = as_positive_float(stress_tol, "stress_tol")
    unbalanced_tol = as_positive_float(unbalanced_tol, "unbalanced_tol")
    check_every = as_int(check_every, "check_every", minimum=1)
    max_steps = as_int(max_steps, "max_steps", minimum=1)

    gas, dem, loading = _setup(dist, n, seed, friction, pressure, phi_gas, density, kn)
    p = pressure * kn
    eng = DEMEngine(gas, dem)
    box0 = (eng.lo.copy(), eng.hi.copy())  # one servo phase from step 0, as one LIGGGHTS `run`
    ubf = np.inf
    blocks = -(-max_steps // check_every)
    bar = progress(range(blocks), total=blocks, desc="compaction")
    for _ in bar:
        check_interrupt()  # SIGINT / SIGTERM: stop between two checks
        eng.advance(loading, check_every, phase_step0=0, phase_box0=box0)
        s = eng.stress
        on_target = abs(s[0, 0] / p - 1.0) <= stress_tol and abs(s[1, 1] / p - 1.0) <= stress_tol
        if on_target:
            ubf = unbalanced_force_ratio(eng)
            if ubf <= unbalanced_tol:
                break
    else:
        raise ConvergenceError(
            f"compaction (N = {n}, seed = {seed}, friction = {friction}) not quasi-static after {eng.step} steps: "
            f"stresses {s[0, 0] / p:.4f} p, {s[1, 1] / p:.4f} p, unbalanced force ratio {ubf:.2e}"
        )
    Lx, Ly = eng.box_lengths
    cell = np.diag([Lx, Ly])
    pk = Packing(positions=eng.x - eng.lo, radii=gas.radii, cell=cell, density=density).wrapped()
    stats = packing_stats(pk)
    meta = {
        "generator": "gransim.generation.compact_packing",
        "algorithm": "granular gas + isotropic servo compaction by the frictional DEM (gransim.dem)",
        "distribution": dist.name,
        "distribution_d50": dist.d50,
        "n": n,
        "seed": seed,
        "friction": friction,
        "pressure_over_kn": pressure,
        "phi_gas": phi_gas,
        "mean_diameter_target": mean_diameter,
        "stress_tol": stress_tol,
        "unbalanced_tol": unbalanced_tol,
        "dem": dem.to_dict(),
        "servo_gain": loading.x.gain,
        "dem_steps": int(eng.step),
        "unbalanced_force_ratio": ubf,
        "stress_over_p": [float(eng.stress[0, 0] / p), float(eng.stress[1, 1] / p)],
        **{
            k: stats[k]
            for k in (
                "solid_fraction",
                "void_ratio",
                "mean_overlap_dmean",
                "mean_overlap_d50",
                "max_overlap_d50",
                "coordination",
                "coordination_nonrattler",
                "rattler_fraction",
            )
        },
        "seconds": time.perf_counter() - t0,
    }
    return pk.replace(metadata=meta)
