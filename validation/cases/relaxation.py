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
triclinic box), from the stored jobs ``reference_runs/stored/relaxation-lattice-8x8`` and, when the
binaries are installed, live. Decks and RVE: :mod:`reference_runs.decks.relaxation`.
"""

from __future__ import annotations

import numpy as np

from gransim.contacts import find_neighbours
from gransim.dem.settings import Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import GransimError
from gransim.io import load_packing
from gransim.paper import KN_2D
from gransim.rve import TaylorMaterial
from gransim.rve.relaxed import RelaxedMaterial
from reference_runs.conventions import cauchy_from_pressure
from reference_runs.decks.relaxation import (
    DUMP,
    ENGINE_STATES,
    NSTEPS,
    STATES,
    STORED_CASE,
    THERMO_EVERY,
    deformed_state,
    relaxation_settings,
    run_relaxation_job,
    state_F,
)

from ..core import (
    CaseResult,
    Context,
    Record,
    case,
    compare,
    evidence,
    in_pair,
    info,
    stored_dir,
    stored_job_record,
)
from ..dem_compare import expected_steps, read_reference, run_native, trajectory_evidence
from .shear import read_lammps_shear, run_native_shear

CASE = "relaxation"
TITLE = "Relaxed RVE at a prescribed F vs frictionless damped DEM at rest: native, LIGGGHTS, LAMMPS"
#: E_n of the relaxed material and kn of every DEM (N/m): the RVE study's 2D stiffness
KN = KN_2D
CODE = {"liggghts": "LIGGGHTS", "lammps": "LAMMPS"}

#: amplification of the relative force residual into the relative stress error (tolerance = C (rho_a +
#: rho_b) + ROUNDOFF, rho = max |net contact force on a disk| / mean contact force of each side)
C_RESIDUAL = 10.0
ROUNDOFF = 1e-12
TOL_REASON = (
    "both sides are minima of the same energy up to their residual forces r: the stress error of a state "
    "with residual r is the linear response B^T H^-1 r (H the Hessian over the fluctuations, B the mixed "
    "derivative), i.e. rho = max|r|/mean contact force times an amplification that Newton warm-started "
    "from a DEM state measures: <= 0.5 on the 70-disk random RVE rve-70-1 (soft modes, rattlers), far "
    "less on this lattice. Tolerance C (rho_a + rho_b) + 1e-12 with C = 10 (20x margin); 1e-12 is the "
    "round-off of the contact sums in another order. A 1% stiffer kn moves every stress by 1%"
)
#: at rest: kinetic over elastic energy of the final frame, and the relative force residual
KE_REST = 1e-12
RHO_REST = 1e-6
REST_REASON = (
    "the damped run must end at rest: kinetic/elastic energy <= 1e-12 (measured ~4e-27 after 2000 of the "
    "5000 steps; the same run without damping keeps 2.7e-7, the energy the relaxation releases) and max "
    "|net force| <= 1e-6 of the mean contact force (recomputed from the final positions with the "
    "potential's law, independently of the code's own force output)"
)
#: Newton's state must be an equilibrium of every disk, rattlers included
RHO_NEWTON = 1e-8
NEWTON_REASON = (
    "a DEM at rest balances every disk; relaxed.py holds rattlers at their start fluctuation (w = 0), "
    "so a rattler left overlapping a neighbour carries an unbalanced force that the DEM would push away "
    "(2.5% in stress on rve-70-1 at 0.1% compression). The comparison is between equilibria only if "
    "max |net force| over all disks <= 1e-8 of the mean contact force at Newton's state"
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
    ``n_contacts``."""
    nl = find_neighbours(np.asarray(x, float), packing.radii, np.asarray(cell, float))
    d = np.linalg.norm(nl.branch, axis=1)
    eps = packing.radii[nl.i] + packing.radii[nl.j] - d
    f = -kn * eps[:, None] * nl.branch / d[:, None]
    net = np.zeros((packing.n, 2))
    np.add.at(net, nl.i, f)
    np.add.at(net, nl.j, -f)
    fmean = float(np.linalg.norm(f, axis=1).mean()) if len(f) else float("nan")
    area = abs(float(np.linalg.det(cell)))
    return {
        "rho": float(np.linalg.norm(net, axis=1).max()) / fmean,
        "energy": float(0.5 * kn * np.sum(eps * eps)),
        "sigma": np.einsum("ca,cb->ab", f, nl.branch) / area,
        "n_contacts": len(f),
    }


def kinetic_energy(packing, v, w) -> float:
    """Translational + rotational (I = m r^2 / 2) kinetic energy (J) of a frame."""
    m = np.pi * packing.radii**2 * packing.density
    return float(0.5 * np.sum(m * np.einsum("ij,ij->i", v, v)) + 0.25 * np.sum(m * packing.radii**2 * w * w))


def fluctuation(X, F, x, cell) -> np.ndarray:
    """Periodic fluctuation w = x - F X of final positions, each reduced to its nearest image."""
    w = np.asarray(x, float) - np.asarray(X, float) @ np.asarray(F, float).T
    n = np.round(np.linalg.solve(cell, w.T).T)
    return w - n @ np.asarray(cell, float).T


def _rel(a, b) -> float:
    """max |a - b| / max |b| over the components (sigma_xy passes through zero)."""
    scale = float(np.abs(b).max()) or 1.0
    return float(np.abs(np.asarray(a) - np.asarray(b)).max()) / scale


def _native(packing, F, engine: str):
    """Native DEM relaxation of one state in ``engine``'s flavour: a Trajectory (stress compression
    positive) with frames at 0 and NSTEPS."""
    q, kind = deformed_state(packing, F)
    s = relaxation_settings(packing, KN, flavour=engine)
    if kind == "orthogonal":
        return run_native(q, s, Loading(), NSTEPS, NSTEPS, thermo_every=THERMO_EVERY), q
    return run_native_shear(q, s, ShearLoading(), NSTEPS, NSTEPS, thermo_every=THERMO_EVERY), q


def _read(job_dir, kind: str):
    """A Trajectory of a code's job (thermo + final frame); raises on an unreadable output."""
    if kind == "orthogonal":
        return read_reference(job_dir / "log.lammps", job_dir / DUMP)
    return read_lammps_shear(job_dir / "log.lammps", job_dir / DUMP)


def _side(label: str, who: str, packing, q, tr, F) -> tuple[list, dict | None]:
    """Evidence and at-rest records of one DEM run; its final state (or None when incomplete):
    sigma (tension positive), rho, KE/U, fluctuation w."""
    recs = trajectory_evidence(label, who, tr, expected_steps(NSTEPS, THERMO_EVERY), [0, NSTEPS])
    if not all(r.passed for r in recs):
        return recs, None
    i = int(np.flatnonzero(tr.steps == NSTEPS)[0])
    xx, yy, xy = tr.stress[i]
    sigma = cauchy_from_pressure(xx, yy, xy)
    fr = tr.frames[NSTEPS]
    b = balance(packing, fr["x"], q.cell)
    ke = kinetic_energy(packing, fr["v"], fr["w"])
    ratio = ke / b["energy"] if b["energy"] > 0 else float("inf")
    recs.append(
        compare(
            label,
            "at_rest",
            f"{who}: kinetic / elastic energy at step {NSTEPS} (not at rest if above)",
            ratio,
            KE_REST,
            REST_REASON,
        )
    )
    recs.append(
        compare(
            label,
            "force_balance",
            f"{who}: max |net force| / mean contact force at step {NSTEPS}",
            b["rho"],
            RHO_REST,
            REST_REASON,
        )
    )
    w = fluctuation(packing.positions, F, fr["x"], q.cell)
    return recs, {"sigma": sigma, "rho": b["rho"], "ke": ratio, "w": w, "love": b["sigma"]}


def _stress_record(label, what, a, b, rho_a, rho_b, reason=TOL_REASON) -> tuple[Record, float, float]:
    d = _rel(a["sigma"] if isinstance(a, dict) else a, b)
    tol = C_RESIDUAL * (rho_a + rho_b) + ROUNDOFF
    return compare(label, "stress", what, d, tol, reason), d, tol


@case("relaxation", TITLE, suites=("default", "full"), order=12)
def relaxation(ctx: Context) -> CaseResult:
    res = CaseResult(CASE, TITLE, __doc__.split("\n\n", 1)[1].replace("\n", " "))
    res.declare("native-liggghts", TOL_REASON)
    res.declare("native-lammps", TOL_REASON)
    res.declare("liggghts-lammps", CROSS_REASON)
    d = stored_dir(STORED_CASE)
    try:
        packing = load_packing(d / "packing.h5")
    except (GransimError, OSError) as exc:
        res.records.append(
            Record(
                CASE,
                "evidence",
                f"incomplete: the RVE {d / 'packing.h5'} is unreadable: {exc}",
                1.0,
                0.0,
                False,
                EVIDENCE_REASON,
            )
        )
        return res
    mat = relaxed_material(packing)
    taylor = TaylorMaterial(packing, KN)
    X = packing.positions

    # Newton from w = 0 at every state: the relaxed material's answer
    newton = {}
    for name in STATES:
        F = state_F(name)
        r = mat(F)
        b = balance(packing, X @ F.T + r.fluctuation, F @ packing.cell)
        newton[name] = {"r": r, "rho": b["rho"], "sigma": np.asarray(r.cauchy)}
        res.records.append(
            compare(
                f"{CASE}/{name}/newton",
                "equilibrium",
                f"Newton from w = 0: max |net force| / mean contact force over all {packing.n} disks "
                f"({int(np.sum(r.rattlers))} rattlers held)",
                b["rho"],
                RHO_NEWTON,
                NEWTON_REASON,
            )
        )
        t = taylor.evaluate(F[None]).cauchy[0]
        res.records.append(
            info(
                f"{CASE}/{name}/newton",
                "taylor_vs_relaxed",
                "max|sigma_Taylor - sigma_relaxed| / max|sigma_relaxed| (what the checks tell apart)",
                _rel(t, r.cauchy),
                "the affine (Taylor) stress at the same F; a DEM check passing at a tolerance far below this "
                "shows that the fluctuations were relaxed",
            )
        )

    header = ["state", "side", "sigma_xx", "sigma_yy", "sigma_xy", "rho", "KE/U", "vs relaxed", "tolerance"]
    rows = []
    for name in STATES:
        n = newton[name]
        s = n["sigma"]
        rows.append([name, "relaxed (Newton, w = 0)", s[0, 0], s[1, 1], s[0, 1], n["rho"], "", "", ""])

    finals: dict = {}  # (side, state) -> final state dict
    for engine in ("liggghts", "lammps"):
        code = CODE[engine]
        pair = f"native-{engine}"
        recs, other = [], []
        for name in ENGINE_STATES[engine]:
            F = state_F(name)
            nw = newton[name]
            # native DEM in this code's flavour
            tr, q = _native(packing, F, engine)
            lab = f"{CASE}/{name}/native-{engine}"
            r_ev, nat = _side(lab, f"native ({engine} flavour)", packing, q, tr, F)
            other += r_ev
            if nat is not None:
                finals[(f"native-{engine}", name)] = nat
                rec, dd, tol = _stress_record(
                    lab,
                    "native DEM at rest vs Newton (w = 0): max_rel_diff",
                    nat,
                    nw["sigma"],
                    nat["rho"],
                    nw["rho"],
                )
                other.append(rec)
                rows.append([name, f"native DEM ({engine})", *_row(nat), dd, tol])
                # Newton warm-started from the DEM's fluctuation: which minimum did the DEM find?
                warm = mat(F, start=nat["w"])
                bw = balance(packing, X @ F.T + warm.fluctuation, F @ packing.cell)
                rec, dd, tol = _stress_record(
                    lab,
                    "Newton from the DEM state vs Newton from w = 0 (same minimum): max_rel_diff",
                    np.asarray(warm.cauchy),
                    nw["sigma"],
                    bw["rho"],
                    nw["rho"],
                    MINIMUM_REASON,
                )
                other.append(rec)
                other.append(
                    info(
                        lab,
                        "energy",
                        "W_rel from the DEM state / W_rel from w = 0 - 1 (negative: the DEM found a lower minimum)",
                        warm.energy / nw["r"].energy - 1.0,
                        MINIMUM_REASON,
                    )
                )
            # the code: stored job, and a live run when installed
            runs = [("stored", d / f"{engine}-{name}")]
            if getattr(ctx, engine):
                job = ctx.work("reference", "relaxation", f"{engine}-{name}")
                try:
                    run_relaxation_job(
                        job,
                        packing,
                        F,
                        relaxation_settings(packing, KN, flavour=engine),
                        NSTEPS,
                        engine,
                        ctx.job_timeout(packing.n * NSTEPS),
                    )
                except GransimError as exc:
                    recs.append(
                        Record(
                            f"{CASE}/{name}/{engine}/live",
                            "evidence",
                            f"live {code} job failed: {exc}",
                            1.0,
                            0.0,
                            False,
                            EVIDENCE_REASON,
                        )
                    )
                else:
                    runs.append(("live", job))
            else:
                res.notes.append(f"{code} is absent: {name} is compared with its stored run only.")
            for how, jd in runs:
                lab = f"{CASE}/{name}/{engine}/{how}"
                if how == "stored":
                    recs.append(stored_job_record(lab, jd))
                try:
                    ctr = _read(jd, deformed_state(packing, F)[1])
                except (GransimError, OSError, ValueError, KeyError, IndexError) as exc:
                    recs.append(
                        Record(
                            lab,
                            "evidence",
                            f"incomplete: unreadable {code} output: {exc}",
                            1.0,
                            0.0,
                            False,
                            EVIDENCE_REASON,
                        )
                    )
                    continue
                r_ev, fin = _side(lab, code, packing, q, ctr, F)
                recs += r_ev
                if fin is None:
                    continue
                finals[(f"{engine}-{how}", name)] = fin
                rec, dd, tol = _stress_record(
                    lab,
                    f"{code} at rest vs relaxed (Newton, w = 0): max_rel_diff",
                    fin,
                    nw["sigma"],
                    fin["rho"],
                    nw["rho"],
                )
                recs.append(rec)
                rows.append([name, f"{code} ({how})", *_row(fin), dd, tol])
                if nat is not None:
                    rec, _, _ = _stress_record(
                        lab,
                        f"{code} at rest vs native DEM ({engine} flavour) at rest: max_rel_diff",
                        fin,
                        nat["sigma"],
                        fin["rho"],
                        nat["rho"],
                    )
                    recs.append(rec)
        res.records += in_pair(recs, pair)
        res.records += other
    # LIGGGHTS vs LAMMPS on the states both ran (stored, and live when both ran live)
    recs = []
    for how in ("stored", "live"):
        for name in ENGINE_STATES["liggghts"]:
            a, b = finals.get((f"liggghts-{how}", name)), finals.get((f"lammps-{how}", name))
            if how == "live" and (a is None or b is None) and not (ctx.liggghts and ctx.lammps):
                continue
            lab = f"{CASE}/{name}/cross/{how}"
            recs.append(
                evidence(
                    lab, "codes at rest", ["LIGGGHTS", "LAMMPS"], [c for c, v in (("LIGGGHTS", a), ("LAMMPS", b)) if v]
                )
            )
            if a is not None and b is not None:
                recs.append(
                    _stress_record(
                        lab, "LIGGGHTS vs LAMMPS at rest: max_rel_diff", a, b["sigma"], a["rho"], b["rho"], CROSS_REASON
                    )[0]
                )
    res.records += in_pair(recs, "liggghts-lammps")
    res.tables.append(
        (
            "Stress at rest per state and side (tension positive, N/m), relative residual rho, kinetic/elastic "
            "energy, and the difference from the relaxed (Newton) stress with its tolerance",
            header,
            rows,
        )
    )
    res.notes.append(
        f"RVE: {STORED_CASE}/packing.h5 ({packing.n} disks, every disk with >= 3 contacts, no rattlers); kn = E_n = "
        f"{KN:.3g} N/m; {NSTEPS} steps per relaxation, damping ratio 2 (normal contacts only). States: "
        + "; ".join(f"{k}: F = {np.array(v).tolist()}" for k, v in STATES.items())
        + ". LIGGGHTS runs the compression states only (its triclinic boxes lose their periodic ghosts)."
    )
    return res


def _row(fin) -> list:
    s = fin["sigma"]
    return [s[0, 0], s[1, 1], s[0, 1], fin["rho"], fin["ke"]]


__all__ = ["balance", "fluctuation", "kinetic_energy", "relaxation", "relaxed_material"]
