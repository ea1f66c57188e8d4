"""Case ``relaxation``: the relaxed RVE's stress at a prescribed F against DEM relaxations to rest.

:class:`gransim.rve.relaxed.RelaxedMaterial` minimises the contact energy of a periodic RVE over the
periodic fluctuations at fixed F with Newton's method (Miehe & Dettmar 2004, "A framework for
micro-macro transitions in periodic particle aggregates of granular materials", sections 3-4) and
returns P = dW_rel/dF. The same minimum is the state in which a frictionless, viscously damped DEM
run of the same RVE comes to rest with its box fixed at F C: the contact law is the linear normal
spring of the potential Phi = E_n/2 <eps>^2 (kn = E_n, kt = 0, mu = 0, normal damping only), and at
rest the particles are in force balance. So at each state the relaxed Cauchy stress sigma = P F^T /
det F must equal the virial stress of the DEM at rest (sign: the codes print compression positive,
sigma = -p; units N/m in 2D, per unit thickness, gransim.paper), up to what the residual forces of
either relaxation leave.

Sides: the Newton minimiser from w = 0 (what a finite-element Gauss point gets); the native DEM
(:class:`gransim.dem.DEMEngine` in each code's flavour for the compression states,
:class:`gransim.dem.sheared.ShearEngine` for simple shear); LIGGGHTS 3.8.0 (compression states:
orthogonal periodic box) and LAMMPS 29 Sep 2021 (compression, and simple shear in a true periodic
triclinic box), from the stored jobs ``reference_runs/stored/relaxation-lattice-8x8`` and
``reference_runs/stored/relaxation-rve-70-1`` and, when the binaries are installed, live.

Each side is a run of the case and shared judges compare them (:func:`plan`): every DEM run at rest and
Newton's equilibrium against their bounds (:func:`validation.judges.analytic`), and every two equilibria's
stresses within what their residual forces leave (:func:`validation.judges.equilibria`): native vs Newton,
each code vs Newton and vs the native run in its arithmetic, Newton warm-started from the DEM vs Newton
from w = 0 (the same minimum), and LIGGGHTS vs LAMMPS.

Two RVEs: a jammed 8 x 8 perturbed lattice without rattlers (0.2-0.3% compression, simple shear
2e-3) and the standard random RVE rve-70-1 of Meier, Steinmann & Kuhl (2007, "Towards completeness:
a multiscale approach of confined particulate systems", section 4), with its rattlers (0.1%
compressions, simple shear 1e-3 after 0.1% isotropic compression). Decks, RVEs, damping and step
counts: :mod:`reference_runs.decks.relaxation`.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem.settings import Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import GransimError
from gransim.generation.standard import shipped_packing
from gransim.io import load_packing
from gransim.paper import KN_2D
from gransim.rve import TaylorMaterial
from gransim.rve.relaxed import RelaxedMaterial
from reference_runs.conventions import cauchy_from_pressure
from reference_runs.decks.relaxation import (
    DAMPING_RATIO,
    DUMP,
    ENGINE_STATES,
    NSTEPS,
    RVE_DAMPING_RATIO,
    RVE_ENGINE_STATES,
    RVE_NAME,
    RVE_NSTEPS,
    RVE_STATES,
    RVE_STORED_CASE,
    RVE_THERMO_EVERY,
    STATES,
    STORED_CASE,
    THERMO_EVERY,
    Variant,
    deformed_state,
    relaxation_settings,
    run_relaxation_job,
    state_F,
)

from ..codes import NATIVE, pair_key
from ..core import CaseResult, Context, Record, case, stored_dir, stored_job_record
from ..dem_compare import expected_steps, read_reference, run_native, trajectory_evidence
from ..judges import Bound
from ..matrix import Comparison, Failed, Outcome, Run, evaluate, stored_job
from .shear import read_lammps_shear, run_native_shear

CASE = "relaxation"
TITLE = "Relaxed RVE at a prescribed F vs frictionless damped DEM at rest: native, LIGGGHTS, LAMMPS"
#: E_n of the relaxed material and kn of every DEM (N/m): the RVE study's 2D stiffness
KN = KN_2D
CODE = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}
#: the RVEs of a run: the jammed lattice (no rattlers) and the standard random RVE rve-70-1
VARIANTS = ("lattice", RVE_NAME)

#: amplification of the relative force residual into the relative stress error (tolerance = C (rho_a +
#: rho_b) + ROUNDOFF, rho = max |net contact force on a disk| / mean contact force of each side)
C_RESIDUAL = 10.0
ROUNDOFF = 1e-12
TOL_REASON = (
    "both sides are minima of the same energy up to their residual forces r: the stress error of a state "
    "with residual r is the linear response B^T H^-1 r (H the Hessian over the fluctuations, B the mixed "
    "derivative), i.e. rho = max|r|/mean contact force times an amplification, measured on rve-70-1 over "
    "438 native snapshots at rest (every 500 steps of 100000, the three states) against Newton's stress: "
    "<= 0.62 for the codes' virial stress, <= 0.94 for the elastic (Love) stress; far less on the lattice. "
    "Tolerance C (rho_a + rho_b) + 1e-12 with C = 10 (a margin of 10); 1e-12 is the round-off of the "
    "contact sums in another order. A 1% stiffer kn moves every stress by 1%"
)
#: at rest: kinetic over elastic energy of the final frame, and the relative force residual
KE_REST = 1e-12
RHO_REST = 1e-6
REST_REASON = (
    "the damped run must end at rest: the kinetic energy of the disks in contact, in their centre-of-mass "
    "frame, over the elastic energy <= 1e-12 (lattice: ~4e-27 after 2000 of the 5000 steps, the same run "
    "without damping keeps 2.7e-7; rve-70-1: <= 1e-16 by 40000-60000 steps, ~1e-22 at 60000), and max "
    "|net force| <= 1e-6 of the mean contact force (recomputed from the final positions with the "
    "potential's law, independently of the code's own force output)"
)
FREE_REASON = (
    "information: a rattler pushed out of the affine start leaves its last contact with a velocity and, "
    "without contact, no damping acts on it (contact damping only); it crosses its void until it hits a "
    "neighbour (rve-70-1: KE/U 1e-7 to 3e-6, held for 100000+ steps; the backbone drifts with the opposite "
    "momentum, hence the centre-of-mass frame). A disk without contact carries no force and adds nothing "
    "to the stress; the state compared is that of the disks in contact"
)
#: Newton's state must be an equilibrium of every disk, rattlers included
RHO_NEWTON = 1e-8
NEWTON_REASON = (
    "a DEM at rest balances every disk; relaxed.py expels each rattler to a force-free place, but where "
    "the start loses the network (no backbone at w = 0) it falls back to holding rattlers with their forces "
    "(rve-70-1 under simple shear 5e-4 to 1e-3 from w = 0: rho 1.3-1.8, docs/validation.md). The comparison "
    "is between equilibria only if max |net force| over all disks <= 1e-8 of the mean contact force at "
    "Newton's state"
)
MINIMUM_REASON = (
    "the energy landscape is not convex: Newton from w = 0 and Newton warm-started from the DEM's final "
    "fluctuation must land in the same minimum (same stress within the residual tolerance); otherwise "
    "DEM and Newton found different local minima, and this record says so"
)
EVIDENCE_REASON = (
    "every job must be complete and readable (its thermo to the last step, the final dump frame); a cut or "
    "failed job is missing evidence, never a pass on what remains"
)
CROSS_REASON = (
    "both codes relax the same data file to rest with the same frictionless law; their stresses differ "
    "by their residuals only (tolerance C (rho_LIGGGHTS + rho_LAMMPS) + 1e-12, as against Newton)"
)


def relaxed_material(packing) -> RelaxedMaterial:
    """The relaxed RVE of the case (a hook: the tests change its stiffness to show the case fails)."""
    return RelaxedMaterial(packing, KN)


def balance(packing, x, cell, kn: float = KN) -> dict:
    """Residual forces of positions ``x`` (N, 2) in the periodic ``cell`` (columns = lattice
    vectors) under the elastic normal law f = -kn eps n (every overlapping pair, images included).

    Returns ``rho`` (max over disks of |sum of contact forces| / mean contact force), ``energy``
    (sum kn eps^2 / 2, J), ``sigma`` (2, 2) Love stress (1/A) sum f (x) l (tension positive, N/m),
    ``n_contacts``, ``in_contact`` (N,) bool (disks with at least one overlap)."""
    nl = find_neighbours(np.asarray(x, float), packing.radii, np.asarray(cell, float))
    d = np.linalg.norm(nl.branch, axis=1)
    eps = packing.radii[nl.i] + packing.radii[nl.j] - d
    f = -kn * eps[:, None] * nl.branch / d[:, None]
    net = np.zeros((packing.n, 2))
    np.add.at(net, nl.i, f)
    np.add.at(net, nl.j, -f)
    fmean = float(np.linalg.norm(f, axis=1).mean()) if len(f) else float("nan")
    touching = np.zeros(packing.n, bool)
    touching[nl.i[eps > 0]] = True
    touching[nl.j[eps > 0]] = True
    area = abs(float(np.linalg.det(cell)))
    return {
        "rho": float(np.linalg.norm(net, axis=1).max()) / fmean,
        "energy": float(0.5 * kn * np.sum(eps * eps)),
        "sigma": np.einsum("ca,cb->ab", f, nl.branch) / area,
        "n_contacts": len(f),
        "in_contact": touching,
    }


def kinetic_energy(packing, v, w) -> float:
    """Translational + rotational (I = m r^2 / 2) kinetic energy (J) of a frame."""
    m = np.pi * packing.radii**2 * packing.density
    return float(0.5 * np.sum(m * np.einsum("ij,ij->i", v, v)) + 0.25 * np.sum(m * packing.radii**2 * w * w))


def network_kinetic_energy(packing, v, w, in_contact) -> tuple[float, float]:
    """Kinetic energy (J) of the disks in contact in their centre-of-mass frame (translation relative to
    their mass-weighted mean velocity, plus rotation with I = m r^2 / 2), and the kinetic energy of the
    other disks (lab frame): ``(ke_network, ke_free)``."""
    m = np.pi * packing.radii**2 * packing.density
    c = np.asarray(in_contact, bool)
    v = np.asarray(v, float)
    w = np.asarray(w, float)
    if not c.any():
        return 0.0, kinetic_energy(packing, v, w)
    vc = v[c] - (m[c, None] * v[c]).sum(axis=0) / m[c].sum()
    rot = 0.25 * m * packing.radii**2 * w * w
    ke_net = 0.5 * np.sum(m[c] * np.einsum("ij,ij->i", vc, vc)) + np.sum(rot[c])
    f = ~c
    ke_free = 0.5 * np.sum(m[f] * np.einsum("ij,ij->i", v[f], v[f])) + np.sum(rot[f])
    return float(ke_net), float(ke_free)


def fluctuation(X, F, x, cell) -> np.ndarray:
    """Periodic fluctuation w = x - F X of final positions, each reduced to its nearest image."""
    w = np.asarray(x, float) - np.asarray(X, float) @ np.asarray(F, float).T
    n = np.round(np.linalg.solve(cell, w.T).T)
    return w - n @ np.asarray(cell, float).T


def _rel(a, b) -> float:
    """max |a - b| / max |b| over the components (sigma_xy passes through zero)."""
    scale = float(np.abs(b).max()) or 1.0
    return float(np.abs(np.asarray(a) - np.asarray(b)).max()) / scale


# ---------------------------------------------------------------------------------------- runs
@dataclass(frozen=True)
class AtRest:
    """The end of one DEM relaxation, as the judges read it (a complete run: one whose series or
    final frame is missing, whose output cannot be read or whose job failed is a
    :class:`validation.matrix.Failed`).

    label : the run's record label (its evidence and its at-rest checks).
    who : the side's name in the metrics (``native (lammps flavour)``, ``LAMMPS``).
    evidence : the run's evidence records (every series step and the final frame present).
    nsteps : the final step.
    sigma : (2, 2) virial stress the run printed at ``nsteps``, N/m, tension positive.
    rho : max |net force on a disk| / mean contact force at the final positions, recomputed with the
        potential's law (:func:`balance`).
    ke : kinetic energy of the disks in contact (their centre-of-mass frame) / elastic energy.
    ke_free : kinetic energy of the disks without contact / elastic energy.
    n_contact, n_free : the disks with and without a contact.
    w : (N, 2) periodic fluctuation of the final positions, m (:func:`fluctuation`).
    """

    label: str
    who: str
    evidence: tuple
    nsteps: int
    sigma: np.ndarray
    rho: float
    ke: float
    ke_free: float
    n_contact: int
    n_free: int
    w: np.ndarray


@dataclass(frozen=True)
class Minimum:
    """A minimiser of the relaxed material at F (:class:`gransim.rve.relaxed.RelaxedMaterial`).

    sigma : (2, 2) relaxed Cauchy stress P F^T / det F, N/m, tension positive.
    rho : max |net force| / mean contact force over all disks, rattlers included (:func:`balance`).
    energy : W_rel, J.
    n_rattlers, n_held : rattlers, and those of them held with their forces.
    """

    sigma: np.ndarray
    rho: float
    energy: float
    n_rattlers: int
    n_held: int


def _native(packing, F, engine: str, v):
    """Native DEM relaxation of one state of variant ``v`` in ``engine``'s flavour: a Trajectory
    (stress compression positive) with frames at 0 and ``v.nsteps``."""
    q, kind = deformed_state(packing, F)
    s = relaxation_settings(packing, KN, flavour=engine, damping_ratio=v.damping_ratio)
    if kind == "orthogonal":
        return run_native(q, s, Loading(), v.nsteps, v.nsteps, thermo_every=v.thermo_every), q
    return run_native_shear(q, s, ShearLoading(), v.nsteps, v.nsteps, thermo_every=v.thermo_every), q


def _read(job_dir, kind: str):
    """A Trajectory of a code's job (thermo + final frame); raises on an unreadable output."""
    if kind == "orthogonal":
        return read_reference(job_dir / "log.lammps", job_dir / DUMP)
    return read_lammps_shear(job_dir / "log.lammps", job_dir / DUMP)


def _at_rest(label: str, who: str, packing, q, tr, F, v) -> AtRest | Failed:
    """The final state of trajectory ``tr`` of deformed state ``q``: every series step and the final
    frame must be present (else :class:`Failed`, naming what is missing)."""
    recs = trajectory_evidence(label, who, tr, expected_steps(v.nsteps, v.thermo_every), [0, v.nsteps])
    missing = [r.metric for r in recs if not r.passed]
    if missing:
        return Failed("; ".join(missing))
    i = int(np.flatnonzero(tr.steps == v.nsteps)[0])
    xx, yy, xy = tr.stress[i]
    fr = tr.frames[v.nsteps]
    b = balance(packing, fr["x"], q.cell)
    ke_net, ke_free = network_kinetic_energy(packing, fr["v"], fr["w"], b["in_contact"])
    n_contact = int(b["in_contact"].sum())
    return AtRest(
        label,
        who,
        tuple(recs),
        v.nsteps,
        cauchy_from_pressure(xx, yy, xy),
        b["rho"],
        ke_net / b["energy"] if b["energy"] > 0 else float("inf"),
        ke_free / b["energy"] if b["energy"] > 0 else float("inf"),
        n_contact,
        packing.n - n_contact,
        fluctuation(packing.positions, F, fr["x"], q.cell),
    )


def _native_run(label: str, packing, F, engine: str, v) -> AtRest | Failed:
    tr, q = _native(packing, F, engine, v)
    return _at_rest(label, f"native ({engine} flavour)", packing, q, tr, F, v)


def _code_run(label: str, engine: str, packing, F, v, job_dir) -> AtRest | Failed:
    """A code's job read from ``job_dir`` (stored, or run now)."""
    q, kind = deformed_state(packing, F)
    try:
        tr = _read(job_dir, kind)
    except (GransimError, OSError, ValueError, KeyError, IndexError) as exc:
        return Failed(f"unreadable {CODE[engine]} output: {exc}")
    return _at_rest(label, CODE[engine], packing, q, tr, F, v)


def _stored_run(label: str, engine: str, packing, F, v, job_dir) -> AtRest | Failed:
    """A code's stored job; when it cannot be judged, why names the job's check against its deck too
    (:func:`validation.core.stored_job_record`: what of its deck's runs, steps and frames is missing)."""
    run = _code_run(label, engine, packing, F, v, job_dir)
    if isinstance(run, Failed):
        check = stored_job_record(label, job_dir)
        if not check.passed:
            return Failed(f"{run.why}; {check.metric}")
    return run


def _live_run(ctx: Context, label: str, engine: str, name: str, packing, F, v) -> AtRest | Failed:
    """The code's relaxation of state ``name`` run now (reused when a complete job is there)."""
    job = ctx.work("reference", v.stored_case, f"{engine}-{name}")
    try:
        run_relaxation_job(
            job,
            packing,
            F,
            relaxation_settings(packing, KN, flavour=engine, damping_ratio=v.damping_ratio),
            v.nsteps,
            engine,
            ctx.job_timeout(packing.n * v.nsteps),
            v.thermo_every,
        )
    except GransimError as exc:
        return Failed(f"live {CODE[engine]} job failed: {exc}")
    return _code_run(label, engine, packing, F, v, job)


def _minimum(mat, packing, F, start=None) -> Minimum:
    """Newton's minimiser at F from w = 0, or from the fluctuation ``start`` (N, 2)."""
    r = mat(F) if start is None else mat(F, start=start)
    b = balance(packing, packing.positions @ F.T + r.fluctuation, F @ packing.cell)
    return Minimum(np.asarray(r.cauchy), b["rho"], float(r.energy), int(np.sum(r.rattlers)), int(r.n_held))


def _warm(mat, packing, F, native) -> Minimum | Failed:
    """Newton warm-started from the final fluctuation of the native DEM run ``native()``."""
    nat = native()
    if isinstance(nat, Failed):
        return Failed(f"its start, the native DEM run, failed: {nat.why}")
    return _minimum(mat, packing, F, nat.w)


def _own_evidence(_label: str, run) -> list:
    """The ``verify`` of a DEM run: its evidence records (under the run's own label)."""
    return list(run.evidence)


def _stored_evidence(job_dir):
    """The ``verify`` of a stored job: the job against its deck, then the run's evidence."""
    check = stored_job(job_dir)

    def verify(_label: str, run) -> list:
        return check(run.label, run) + list(run.evidence)

    return verify


# ------------------------------------------------------------------------------- the judges' terms
REST_BOUNDS = {
    "at_rest": Bound(KE_REST, REST_REASON),
    "free_disks": Bound(math.nan, FREE_REASON, "info"),
    "force_balance": Bound(RHO_REST, REST_REASON),
}
TAYLOR_REASON = (
    "the affine (Taylor) stress at the same F; a DEM check passing at a tolerance far below this shows that the "
    "fluctuations were relaxed"
)
NEWTON_BOUNDS = {
    "equilibrium": Bound(RHO_NEWTON, NEWTON_REASON),
    "taylor_vs_relaxed": Bound(math.nan, TAYLOR_REASON, "info"),
}
ENERGY_BOUNDS = {"energy": Bound(math.nan, MINIMUM_REASON, "info")}


def _rest_values(run: AtRest) -> dict:
    got = {("", "at_rest"): run.ke, ("", "force_balance"): run.rho}
    if run.n_free:
        got[("", "free_disks")] = run.ke_free
    return got


def _rest_params(make):
    """The ``analytic`` terms of a DEM run at rest (``make``: the run's cached make): the kinetic
    energy of the disks in contact and the force residual within their bounds, the free disks'
    kinetic energy (rattlers; information) where there are any."""

    def params() -> dict:
        st = make()
        texts = {
            "at_rest": f"{st.who}: kinetic energy of the {st.n_contact} disks in contact (their centre-of-mass "
            f"frame) / elastic energy at step {st.nsteps} (not at rest if above)",
            "free_disks": f"{st.who}: kinetic energy of the {st.n_free} disks without contact / elastic energy at "
            f"step {st.nsteps}",
            "force_balance": f"{st.who}: max |net force| / mean contact force at step {st.nsteps}",
        }
        expected = [("", "at_rest")] + ([("", "free_disks")] if st.n_free else []) + [("", "force_balance")]
        return {"expected": expected, "values": _rest_values, "bound": REST_BOUNDS, "metric": lambda i, q, v: texts[q]}

    return params


def _newton_params(make, taylor, F, n: int):
    """The ``analytic`` terms of Newton's minimiser from w = 0: an equilibrium of every disk, and how
    far the affine (Taylor) stress lies from it (information)."""

    def params() -> dict:
        m = make()
        t = taylor.evaluate(F[None]).cauchy[0]
        texts = {
            "equilibrium": f"Newton from w = 0: max |net force| / mean contact force over all {n} disks "
            f"({m.n_rattlers} rattlers, {m.n_held} of them held)",
            "taylor_vs_relaxed": "max|sigma_Taylor - sigma_relaxed| / max|sigma_relaxed| (what the checks tell apart)",
        }
        return {
            "expected": [("", "equilibrium"), ("", "taylor_vs_relaxed")],
            "values": lambda r: {("", "equilibrium"): r.rho, ("", "taylor_vs_relaxed"): _rel(t, r.sigma)},
            "bound": NEWTON_BOUNDS,
            "metric": lambda i, q, v: texts[q],
        }

    return params


def _energy_params(newton) -> dict:
    """The ``analytic`` figure of a warm-started minimiser: its energy against Newton's from w = 0."""
    return {
        "expected": [("", "energy")],
        "values": lambda warm: {("", "energy"): warm.energy / newton().energy - 1.0},
        "bound": ENERGY_BOUNDS,
        "metric": lambda i, q, v: (
            "W_rel from the DEM state / W_rel from w = 0 - 1 (negative: the DEM found a lower minimum)"
        ),
    }


def _equilibria(metric: str, names=None, **kw) -> dict:
    """The ``equilibria`` terms: the case's amplification of the residuals and round-off."""
    return {"metric": metric, "names": names, "amplification": C_RESIDUAL, "roundoff": ROUNDOFF, **kw}


def _labels(v) -> tuple[str, str]:
    """The label prefix of variant ``v`` (``relaxation``, ``relaxation/rve-70-1``) and its tag in the table."""
    return (CASE, "") if v.key == "lattice" else (f"{CASE}/{v.key}", f"{v.key}/")


def _variants() -> list:
    """The variants of this run, read at call time (the tests restrict them): the lattice from this
    module's STATES / ENGINE_STATES / NSTEPS / STORED_CASE, the standard RVE from RVE_*."""
    out = []
    for key in VARIANTS:
        if key == "lattice":
            out.append(Variant(key, STORED_CASE, STATES, ENGINE_STATES, DAMPING_RATIO, NSTEPS, THERMO_EVERY))
        else:
            out.append(
                Variant(
                    key,
                    RVE_STORED_CASE,
                    RVE_STATES,
                    RVE_ENGINE_STATES,
                    RVE_DAMPING_RATIO,
                    RVE_NSTEPS,
                    RVE_THERMO_EVERY,
                )
            )
    return out


# ------------------------------------------------------------------------------------ the plan
def plan(ctx: Context, v, packing) -> tuple[list, list]:
    """The runs and comparisons of variant ``v`` (its RVE ``packing`` read from its stored case).

    Runs, per state: Newton from w = 0 (``<state>/newton``); per code that runs the state, the native
    DEM in that code's arithmetic (``<state>/native-<code>``), Newton warm-started from its final
    fluctuation (``.../newton-warm``), the code's stored job (``<state>/<code>/stored``, verified
    against its deck) and its live run (``<state>/<code>/live``, when installed; no stand-in: the
    stored job is compared in any case). Comparisons: Newton's equilibrium and its distance from
    Taylor (``analytic``); every DEM run at rest (``analytic``, the code's in its native column);
    the stresses of two equilibria (``equilibria``): native vs Newton (``/vs-newton``), warm Newton
    vs Newton (same minimum), each code's run vs Newton (``/vs-newton``) and vs the native run in its
    arithmetic (``/vs-native``), and the two codes' runs (``<state>/cross/<stored|live>``).
    Labels are prefixed ``relaxation/`` (lattice) or ``relaxation/<rve>/``."""
    pre, _ = _labels(v)
    d = stored_dir(v.stored_case)
    mat = relaxed_material(packing)
    taylor = TaylorMaterial(packing, KN)
    runs, comps = [], []
    for i, name in enumerate(v.states):
        F = state_F(name, v.states)
        lab = f"{pre}/{name}"
        newton_key = f"{lab}/newton"
        newton = functools.cache(functools.partial(_minimum, mat, packing, F))
        same = None
        if i == 0 and v.key != "lattice":  # the stored RVE is the standard one: evidence filed once

            def same(_label, _run, pre=pre, name=v.key):
                return [_same_rve_record(pre, packing, name)]

        runs.append(Run(newton_key, NATIVE, "", "Newton from w = 0 (the relaxed material)", newton, verify=same))
        comps.append(
            Comparison(
                "analytic", newton_key, (newton_key,), NEWTON_REASON, _newton_params(newton, taylor, F, packing.n)
            )
        )
        for engine, code in CODE.items():
            if name not in v.engine_states[engine]:
                continue
            column = pair_key(NATIVE, engine)
            nat_key, warm_key = f"{lab}/native-{engine}", f"{lab}/native-{engine}/newton-warm"
            native = functools.cache(functools.partial(_native_run, nat_key, packing, F, engine, v))
            runs += [
                Run(
                    nat_key,
                    NATIVE,
                    engine,
                    f"native DEM, {code} arithmetic, {v.nsteps} steps",
                    native,
                    verify=_own_evidence,
                ),
                Run(
                    warm_key,
                    NATIVE,
                    "",
                    f"Newton from the final fluctuation of {nat_key}",
                    functools.partial(_warm, mat, packing, F, native),
                ),
            ]
            comps += [
                Comparison("analytic", nat_key, (nat_key,), REST_REASON, _rest_params(native)),
                Comparison(
                    "equilibria",
                    f"{nat_key}/vs-newton",
                    (nat_key, newton_key),
                    TOL_REASON,
                    _equilibria("native DEM at rest vs Newton (w = 0): max_rel_diff", ("native DEM", "Newton")),
                ),
                Comparison(
                    "equilibria",
                    warm_key,
                    (warm_key, newton_key),
                    MINIMUM_REASON,
                    _equilibria(
                        "Newton from the DEM state vs Newton from w = 0 (same minimum): max_rel_diff",
                        ("Newton from the DEM state", "Newton"),
                    ),
                ),
                Comparison("analytic", f"{warm_key}/energy", (warm_key,), MINIMUM_REASON, _energy_params(newton)),
            ]
            for how in ("stored", "live"):
                key = f"{lab}/{engine}/{how}"
                stored = f"stored {v.stored_case}/{engine}-{name}"
                if how == "stored":
                    job = d / f"{engine}-{name}"
                    make = functools.cache(functools.partial(_stored_run, key, engine, packing, F, v, job))
                    runs.append(
                        Run(
                            key,
                            engine,
                            engine,
                            stored,
                            make,
                            verify=_stored_evidence(job),
                        )
                    )
                else:
                    make = functools.cache(functools.partial(_live_run, ctx, key, engine, name, packing, F, v))
                    runs.append(
                        Run(
                            key,
                            engine,
                            engine,
                            f"{code} deck run now; {stored} is compared in any case",
                            make,
                            live=True,
                            verify=_own_evidence,
                        )
                    )
                comps += [
                    Comparison("analytic", key, (key,), TOL_REASON, _rest_params(make), pair=column),
                    Comparison(
                        "equilibria",
                        f"{key}/vs-newton",
                        (key, newton_key),
                        TOL_REASON,
                        _equilibria(f"{code} at rest vs relaxed (Newton, w = 0): max_rel_diff", (code, "Newton")),
                    ),
                    Comparison(
                        "equilibria",
                        f"{key}/vs-native",
                        (key, nat_key),
                        TOL_REASON,
                        _equilibria(
                            f"{code} at rest vs native DEM ({engine} flavour) at rest: max_rel_diff",
                            (code, "native DEM"),
                        ),
                    ),
                ]
        # every two codes that run the state: stored against stored, live against live (both installed)
        both = [e for e in CODE if name in v.engine_states[e]]
        for j, a in enumerate(both):
            for b in both[j + 1 :]:
                for how in ("stored", "live"):
                    comps.append(
                        Comparison(
                            "equilibria",
                            f"{lab}/cross/{how}",
                            (f"{lab}/{a}/{how}", f"{lab}/{b}/{how}"),
                            CROSS_REASON,
                            _equilibria(f"{CODE[a]} vs {CODE[b]} at rest: max_rel_diff", record_evidence=True),
                        )
                    )
    return runs, comps


@case("relaxation", TITLE, suites=("default", "full"), order=12)
def relaxation(ctx: Context) -> CaseResult:
    res = CaseResult(CASE, TITLE, __doc__.split("\n\n", 1)[1].replace("\n", " "))
    runs, comps, made = [], [], []
    for v in _variants():
        d = stored_dir(v.stored_case)
        try:
            packing = load_packing(d / "packing.h5")
        except (GransimError, OSError) as exc:
            res.records.append(
                Record(
                    _labels(v)[0],
                    "evidence",
                    f"incomplete: the RVE {d / 'packing.h5'} is unreadable: {exc}",
                    1.0,
                    0.0,
                    False,
                    EVIDENCE_REASON,
                )
            )
            continue
        r, c = plan(ctx, v, packing)
        runs += r
        comps += c
        made.append((v, packing))
    out = evaluate(res, ctx, runs, comps)
    res.skip_code(
        "yade",
        "no YADE run: the DEM sides relax with contact damping (ratio 8, the decks' mass-scaled dashpot), which YADE "
        "2023.02a's periodic damped law gets wrong across the boundary (ViscoelasticPM.cpp:118, docs/yade.md); a "
        "relaxation under Cundall's non-viscous damping is not declared",
    )
    header = ["state", "side", "sigma_xx", "sigma_yy", "sigma_xy", "rho", "KE/U", "vs relaxed", "tolerance"]
    rows: list = []
    for v, packing in made:
        rows += _rows(out, v)
        res.notes.append(_note(out, v, packing))
    res.tables.append(
        (
            "Stress at rest per state and side (tension positive, N/m), relative residual rho, kinetic energy of "
            "the disks in contact / elastic energy, and the difference from the relaxed (Newton) stress with its "
            "tolerance",
            header,
            rows,
        )
    )
    return res


def _rows(out: Outcome, v) -> list:
    """The table rows of variant ``v``: Newton's state per state, then per code and state the native
    run and the code's runs that came to a verdict against Newton (their stress, rho, KE/U, and the
    difference from Newton's stress with its tolerance)."""
    pre, tag = _labels(v)
    rows = []
    for name in v.states:
        m = out.runs.get(f"{pre}/{name}/newton")
        if isinstance(m, Minimum):
            rows.append(
                [tag + name, "relaxed (Newton, w = 0)", m.sigma[0, 0], m.sigma[1, 1], m.sigma[0, 1], m.rho, "", "", ""]
            )
    for engine, code in CODE.items():
        for name in v.engine_states[engine]:
            lab = f"{pre}/{name}"
            sides = [(f"{lab}/native-{engine}", f"native DEM ({engine})")]
            sides += [(f"{lab}/{engine}/{how}", f"{code} ({how})") for how in ("stored", "live")]
            for key, side in sides:
                vs, rest = out.summaries.get(f"{key}/vs-newton"), out.summaries.get(key)
                if not vs or vs["missing"] or not rest:
                    continue
                (ke,) = rest[("", "at_rest")].values()
                s = vs["sigma"][0]
                rows.append(
                    [tag + name, side, s[0, 0], s[1, 1], s[0, 1], vs["rho"][0], ke, vs["value"], vs["tolerance"]]
                )
    return rows


def _note(out: Outcome, v, packing) -> str:
    """What variant ``v`` ran: its RVE, Newton's rattlers, stiffness, steps, damping and states."""
    pre, _ = _labels(v)
    mins = [out.runs.get(f"{pre}/{k}/newton") for k in v.states]
    n_ratt = sorted({m.n_rattlers for m in mins if isinstance(m, Minimum)})
    return (
        f"RVE {v.key}: {v.stored_case}/packing.h5 ({packing.n} disks; Newton's rattlers per state: "
        f"{', '.join(map(str, n_ratt))}); kn = E_n = {KN:.3g} N/m; {v.nsteps} steps per relaxation, damping ratio "
        f"{v.damping_ratio:g} (normal contacts only). States: "
        + "; ".join(f"{k}: F = {np.array(f).tolist()}" for k, f in v.states.items())
        + ". LIGGGHTS runs the compression states only (its triclinic boxes lose their periodic ghosts)."
    )


def _same_rve_record(label: str, packing, name: str) -> Record:
    """Evidence that the stored RVE is the shipped standard RVE ``name`` (centres, radii, cell, density
    bit for bit): the case runs on the RVE of the Taylor and FE2 studies, not on a look-alike."""
    path = shipped_packing(name)
    if path is None:
        return Record(
            label,
            "evidence",
            f"the shipped standard packing {name} is missing or outdated: the stored RVE cannot be identified",
            1.0,
            0.0,
            False,
            EVIDENCE_REASON,
        )
    ref = load_packing(path)
    same = (
        ref.n == packing.n
        and np.array_equal(ref.positions, packing.positions)
        and np.array_equal(ref.radii, packing.radii)
        and np.array_equal(ref.cell, packing.cell)
        and ref.density == packing.density
    )
    return Record(
        label,
        "evidence",
        f"stored packing.h5 is the shipped standard RVE {name} bit for bit (centres, radii, cell, density)",
        0.0 if same else 1.0,
        0.0,
        bool(same),
        EVIDENCE_REASON,
    )


__all__ = [
    "AtRest",
    "Minimum",
    "balance",
    "fluctuation",
    "kinetic_energy",
    "network_kinetic_energy",
    "plan",
    "relaxation",
    "relaxed_material",
]
