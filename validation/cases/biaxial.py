"""Cases ``biaxial-short`` and ``biaxial-full``: the native DEM engine against LIGGGHTS 3.8.0.

Both codes run the same deck (``reference_runs.decks.biaxial.write_biaxial_deck``: hooke/stiffness
with tangential history, the same time step, skin, rebuild rule, servo and rate loading).

* ``biaxial-short``: step for step over thousands of steps. The engine repeats LIGGGHTS'
  floating-point operations in LIGGGHTS' order, so positions, velocities, spins, per-particle
  forces and torques, the stress and the box are expected to agree bit for bit.
* ``biaxial-full``: the compression of the Kuhn assembly. Round-off differences (another CPU,
  another summation order) grow exponentially in a granular assembly, so the native-vs-LIGGGHTS
  difference is judged against LIGGGHTS' own sensitivity: the same deck with one coordinate moved
  by 1e-15 relative, and the same deck on 2 MPI processes.
"""

from __future__ import annotations

import numpy as np

from ..core import CaseResult, Context, case, compare, stored_dir, stored_job_record

POS_TOL = 1e-10  # of D50
POS_REASON = ("the engine does LIGGGHTS' floating-point operations in LIGGGHTS' order (neighbour list, "
              "ghosts, step order), so the doubles are equal; 1e-10 D50 (issue bound) leaves room for another "
              "CPU/compiler, whose round-off grows ~10x per 1000 steps (shared notes), yet is 7 decades below the "
              "8e-4 D50 that 1% stiffer contacts give within 1000 steps (measured, tests/validation)")
REL_TOL = 1e-8
STRESS_REASON = ("virial stress = sum over the same contacts in the same order: equal doubles expected; 1e-8 "
                 "relative (of the largest component, sigma_xy passes through 0) allows round-off growth on "
                 "another machine while a 1% stiffness change gives ~1e-2")
VEL_REASON = ("velocities/spins relative to the largest value: same bound as the stress, as they come from the "
              "same forces by the same kicks")
FORCE_REASON = ("per-particle force/torque applied in the step (dump fx fy tqz) relative to the largest: sums of "
                "the contact forces in the same order. Per-contact rows are not compared: LIGGGHTS' "
                "pair/gran/local re-evaluates contacts at output time (remapped positions, full-step "
                "velocities, stale ghosts: up to 3.9% off the applied force, shared notes)")
BOX_REASON = "box lengths after fix deform (servo/rate) in D50: the servo uses the stress, same bound as positions"

SHORT_KUHN_STEPS = 5000
SHORT_DUMP_EVERY = 500
LIVE_SHORT_STEPS = 1000


def _kuhn(ctx: Context):
    from gransim.generation import standard_packings
    from gransim.io import load_packing

    return load_packing(standard_packings(ctx.results / "packings", names=["kuhn-1002"])["kuhn-1002"])


def _servo(bi):
    from gransim.dem import AxisControl

    return AxisControl("servo", target=bi.confining, gain=bi.servo_gain)


def _max(a) -> float:
    """Largest entry, NaN for an empty array (a comparison over nothing fails)."""
    a = np.asarray(a, float)
    return float(a.max()) if a.size else float("nan")


def step_records(label: str, nat, lig, d50: float, nsteps: int, dump_every: int,
                 thermo_every: int = 1) -> tuple[list, list]:
    """Records (evidence of both sides, positions, velocities, spins, forces, torques, stress,
    box) and a table row.

    The expected evidence is the run's: every ``thermo_every``-th step of ``nsteps`` in the
    series and every ``dump_every``-th step as a frame, on both sides. A missing step or frame
    is a failing ``evidence`` record ("incomplete: expected N frames, got M"); the differences
    are then taken over what both sides hold, and a comparison over nothing is NaN (fails).
    """
    from ..dem_compare import (expected_frames, expected_steps, frame_differences, stress_differences,
                               trajectory_evidence)

    exp_s, exp_f = expected_steps(nsteps, thermo_every), expected_frames(nsteps, dump_every)
    recs = (trajectory_evidence(label, "native", nat, exp_s, exp_f)
            + trajectory_evidence(label, "LIGGGHTS", lig, exp_s, exp_f))
    lig_steps = set(int(s) for s in lig.steps)
    both_f = [int(s) for s in exp_f if s in nat.frames and s in lig.frames and int(s) in lig_steps]
    both_s = np.intersect1d(np.intersect1d(exp_s, nat.steps), lig.steps)
    fd = frame_differences(nat, lig, d50, steps=both_f)
    steps, rel, dl = stress_differences(nat, lig, steps=both_s)
    recs += [
        compare(label, "position", "max|dx|/D50 over frames", _max(fd["x"]), POS_TOL, POS_REASON),
        compare(label, "velocity", "max|dv|/max|v|", _max(fd["v"]), REL_TOL, VEL_REASON),
        compare(label, "spin", "max|dw|/max|w|", _max(fd["w"]), REL_TOL, VEL_REASON),
        compare(label, "particle_force", "max|df|/max|f|", _max(fd["f"]), REL_TOL, FORCE_REASON),
        compare(label, "particle_torque", "max|dT|/max|T|", _max(fd["t"]), REL_TOL, FORCE_REASON),
        compare(label, "stress", "max over steps of max|dsigma|/max|sigma|", _max(rel), REL_TOL, STRESS_REASON),
        compare(label, "box", "max|dL|/D50", _max(dl) / d50, POS_TOL, BOX_REASON),
    ]
    row = [label, int(steps[-1]) if len(steps) else -1, len(fd["steps"]), _max(fd["x"]), _max(fd["v"]),
           _max(fd["f"]), _max(rel)]
    return recs, row


@case("biaxial-short", "Biaxial test, short horizon: step for step, native vs LIGGGHTS", order=20)
def biaxial_short(ctx: Context) -> CaseResult:
    from pathlib import Path

    from gransim.dem import Loading
    from gransim.dem import default_settings as dem_defaults
    from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, short_case

    from ..dem_compare import read_liggghts, run_liggghts_job, run_native

    res = CaseResult(
        "biaxial-short", "Biaxial test, short horizon: step for step, native vs LIGGGHTS",
        "The same deck in both codes, compared at every step (stress, box) and at every dump (positions, "
        "velocities, spins, per-particle forces and torques). <i>stored-120</i>: the stored LIGGGHTS run "
        "<code>reference_runs/stored/biaxial-short</code> (120 disks on a jittered lattice, servo on x, rate on "
        "y, ~60 sliding contacts, 3000 steps). <i>live-120</i>: the same deck run now. <i>kuhn-1002</i>: the "
        "Kuhn 1002-disk assembly with the biaxial default settings (gransim.dem.default_settings), "
        f"consolidation with the servo on both axes, {SHORT_KUHN_STEPS} steps.")
    header = ["run", "steps", "frames", "max|dx|/D50", "max|dv|/max|v|", "max|df|/max|f|", "max rel stress"]
    rows = []
    p, s, ld, n = short_case()
    stored = stored_dir("biaxial-short")
    nat = run_native(p, s, ld, n, SHORT_CASE_DUMP_EVERY)
    lig = read_liggghts(stored / "log.liggghts", stored / "dump.atoms")
    res.records.append(stored_job_record("biaxial-short/stored-120", stored))
    recs, row = step_records("biaxial-short/stored-120", nat, lig, p.d50, n, SHORT_CASE_DUMP_EVERY)
    res.records += recs
    rows.append(row)
    if ctx.liggghts:
        job = ctx.work("reference", "biaxial-short", "live-120")
        lig, _ = run_liggghts_job(job, p, s, ld, LIVE_SHORT_STEPS, 250,
                                  timeout=ctx.job_timeout(p.n * LIVE_SHORT_STEPS))
        nat = run_native(p, s, ld, LIVE_SHORT_STEPS, 250)
        recs, row = step_records("biaxial-short/live-120", nat, lig, p.d50, LIVE_SHORT_STEPS, 250)
        res.records += recs
        rows.append(row)
    if ctx.suite != "quick":
        if ctx.liggghts:
            pk = _kuhn(ctx)
            dem, bi = dem_defaults(pk)
            ldk = Loading(x=_servo(bi), y=_servo(bi))
            job = ctx.work("reference", "biaxial-short", "kuhn-1002")
            lig, man = run_liggghts_job(job, pk, dem, ldk, SHORT_KUHN_STEPS, SHORT_DUMP_EVERY,
                                        timeout=ctx.job_timeout(pk.n * SHORT_KUHN_STEPS))
            nat = run_native(pk, dem, ldk, SHORT_KUHN_STEPS, SHORT_DUMP_EVERY)
            recs, row = step_records("biaxial-short/kuhn-1002", nat, lig, pk.d50, SHORT_KUHN_STEPS,
                                     SHORT_DUMP_EVERY)
            res.records += recs
            rows.append(row)
            res.notes.append(f"kuhn-1002: native {nat.elapsed:.2f} s, LIGGGHTS job {man.get('elapsed_s', 0):.2f} s "
                             f"(<code>{' '.join(man.get('command', []))}</code> in <code>{job}</code>).")
        else:
            res.notes.append("LIGGGHTS is absent: the Kuhn 1002-disk run is not compared; only the stored "
                             "120-disk reference is.")
    res.tables.append(("Largest differences per run (0 = bitwise equal)", header, rows))
    res.notes.append("Per-contact forces: the native snapshot's contact forces are not set against LIGGGHTS' "
                     "<code>compute pair/gran/local</code>, whose rows are a re-evaluation at output time "
                     "(remapped positions, full-step velocities, stale ghost state), not the applied forces "
                     "(shared notes liggghts-3.8.md). Per-particle forces are the sums of the applied contact forces "
                     "and are compared instead; with equal positions the contact lists are equal (voidcell case).")
    return res


# ====================================================================== biaxial-full
FULL_CONSOLIDATION_STEPS = 6000
FULL_DUMP_EVERY = 2000  # steps: 2.8e-5 axial strain at the default rate
FULL_THERMO_EVERY = 10
PERTURB_REL = 1e-15
ENVELOPE_FACTOR = 10.0
ENVELOPE_REASON = ("chaos: LIGGGHTS' own divergence under a round-off perturbation (one coordinate moved by "
                   "1e-15 relative, two runs; full suite also 1 vs 2 MPI processes) is the envelope E(t) = max over those runs at each output step; "
                   "native-vs-LIGGGHTS must stay within 10 E(t) at every step (a factor 10 = one decade of "
                   "exponential growth, i.e. the perturbations' onset is uncertain to that)")
CURVE_REASON = ("band = the largest deviation of the perturbed LIGGGHTS runs from the reference along the "
                "curve (their spread is the uncertainty of a curve under round-off), in units of the confining p")


def _settings_by_suite(suite: str) -> dict:
    if suite == "full":
        return {"strain": 0.01, "np2": True}
    return {"strain": 0.005, "np2": False}


_FULL_CACHE: dict = {}


def ensemble_labels(n: int, np2: bool) -> list[str]:
    """Labels of the perturbed LIGGGHTS runs of :func:`full_runs` for ``n`` disks."""
    out = ["x of disk 1 moved by +1e-15 rel", f"y of disk {n // 2 + 1} moved by -1e-15 rel"]
    return out + (["2 MPI processes"] if np2 else [])


def full_runs(ctx: Context) -> dict:
    """The compression runs of ``biaxial-full`` (cached per results dir and suite): native, LIGGGHTS
    reference and perturbed LIGGGHTS runs from one common consolidated state.

    Design: the native engine consolidates the Kuhn assembly (both axes servo-controlled to p,
    ``FULL_CONSOLIDATION_STEPS``: the short case shows this phase bit for bit); its final state
    (positions shifted to a box at the origin, velocities, spins) is the packing both codes
    start the compression from (LIGGGHTS reads it as a data file, which carries no contact
    history, and the native engine starts with zero springs too). Compression: y at the default
    rate, sigma_11 = p held by the servo, up to the suite's strain.
    """
    from gransim.dem import AxisControl, DEMEngine, Loading
    from gransim.dem import default_settings as dem_defaults
    from gransim.geometry import Packing

    from ..dem_compare import run_liggghts_job, run_native

    key = (str(ctx.results.resolve()), ctx.suite, ctx.liggghts)
    if key in _FULL_CACHE:
        return _FULL_CACHE[key]
    cfg = _settings_by_suite(ctx.suite)
    if not ctx.liggghts:  # only the stored series can be compared: run to its strain
        cfg["strain"] = _settings_by_suite("default")["strain"]
    pk = _kuhn(ctx)
    dem, bi = dem_defaults(pk, strain=cfg["strain"])
    servo = _servo(bi)
    eng = DEMEngine(pk, dem)
    out = eng.advance(Loading(x=servo, y=servo), FULL_CONSOLIDATION_STEPS, phase_step0=0,
                      phase_box0=(eng.lo.copy(), eng.hi.copy()))
    cons_err = float(np.abs(out["stress"][-1000:, [0, 1], [0, 1]].mean(axis=0) / bi.confining - 1).max())
    x = eng.x - eng.lo
    L = eng.box_lengths
    common = Packing(positions=x, radii=pk.radii, cell=np.diag(L), density=pk.density, metadata={})
    v, w = eng.v.copy(), eng.w.copy()
    loading = Loading(x=servo, y=AxisControl("rate", rate=-bi.strain_rate))
    nsteps = int(np.ceil(bi.strain / (bi.strain_rate * dem.dt) / FULL_DUMP_EVERY)) * FULL_DUMP_EVERY
    r = {"packing": common, "settings": dem, "biaxial": bi, "loading": loading, "nsteps": nsteps,
         "consolidation_error": cons_err, "velocities": v, "spins": w}
    te = FULL_THERMO_EVERY
    r["native"] = run_native(common, dem, loading, nsteps, FULL_DUMP_EVERY, velocities=v, spins=w, thermo_every=te)
    if ctx.liggghts:
        base = ctx.work("reference", "biaxial-full", f"strain{bi.strain:g}")
        to = ctx.job_timeout(common.n * nsteps)
        lig, man = run_liggghts_job(base / "reference", common, dem, loading, nsteps, FULL_DUMP_EVERY, v, w,
                                    thermo_every=te, timeout=to)
        ens = {}
        n = common.n
        for label, k, ax, sign in (("x of disk 1 moved by +1e-15 rel", 0, 0, 1.0),
                                   (f"y of disk {n // 2 + 1} moved by -1e-15 rel", n // 2, 1, -1.0)):
            xp = np.array(common.positions)
            xp[k, ax] *= 1.0 + sign * PERTURB_REL
            pert = Packing(positions=xp, radii=pk.radii, cell=common.cell, density=pk.density, metadata={})
            ens[label], _ = run_liggghts_job(base / f"perturbed-{k}-{ax}", pert, dem, loading, nsteps,
                                             FULL_DUMP_EVERY, v, w, thermo_every=te, timeout=to)
        if cfg["np2"]:
            ens["2 MPI processes"], _ = run_liggghts_job(base / "np2", common, dem, loading, nsteps, FULL_DUMP_EVERY,
                                                         v, w, np_procs=2, thermo_every=te, timeout=to)
        r.update(liggghts=lig, manifest=man, ensemble=ens, expected_ensemble=ensemble_labels(n, cfg["np2"]))
        # the reference job in the native run-file schema (read by gransim.dem / gransim voidcells)
        from reference_runs.native_schema import trajectory_to_run_file

        r["liggghts_run_file"] = trajectory_to_run_file(
            base / "reference" / "liggghts-run.h5", common, lig.steps, lig.stress, lig.lengths, lig.frames,
            dem.dt, settings=dem.to_dict(), source=str(base / "reference"))
    _FULL_CACHE[key] = r
    return r


def curves(tr, p: float):
    """Axial strain -ln(Ly/Ly0), deviator (sigma_22 - sigma_11, compression positive, / p) and volumetric
    strain ln(A/A0) (dilation positive) of a trajectory."""
    L = tr.lengths
    ea = -np.log(L[:, 1] / L[0, 1])
    q = (tr.stress[:, 1] - tr.stress[:, 0]) / p
    ev = np.log(L[:, 0] * L[:, 1] / (L[0, 0] * L[0, 1]))
    return ea, q, ev


def _ratio(d: np.ndarray, env: np.ndarray) -> float:
    """max over steps of d/env where d > 0 (inf when the envelope is 0 there)."""
    m = d > 0
    if not np.any(m):
        return 0.0
    with np.errstate(divide="ignore"):
        return float(np.max(np.where(env[m] > 0, d[m] / np.where(env[m] > 0, env[m], 1.0), np.inf)))


def _plots(ctx, div, sdiv, cur) -> list:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    figs = []
    floor = 1e-18
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (steps, d) in div.items():
        zero = " (exactly 0 at every dump)" if len(d) and not np.any(d) else ""
        axes[0].semilogy(steps, np.maximum(d, floor), "-" if name != "native vs LIGGGHTS" else "o-", ms=3,
                         label=name + zero)
    axes[0].set_xlabel("step of the compression phase")
    axes[0].set_ylabel("max |x_a - x_b| / D50  (0 drawn at 1e-18)")
    axes[0].legend(fontsize=8)
    for name, (steps, d) in sdiv.items():
        zero = " (exactly 0 at every step)" if len(d) and not np.any(d) else ""
        axes[1].semilogy(steps, np.maximum(d, floor), lw=0.8, label=name + zero)
    axes[1].set_xlabel("step of the compression phase")
    axes[1].set_ylabel("max |sigma_a - sigma_b| / max |sigma_b|  (0 drawn at 1e-18)")
    axes[1].legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("biaxial_full_divergence.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    figs.append((path, "Divergence against LIGGGHTS (serial, reference) over time: native, and LIGGGHTS itself "
                       "under a round-off perturbation (the envelope). Left: positions at every dump; right: "
                       f"stress every {FULL_THERMO_EVERY} steps."))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for name, (ea, q, ev) in cur.items():
        ls = "--" if name == "native" else "-"
        axes[0].plot(100 * ea, q, ls, lw=1, label=name)
        axes[1].plot(100 * ea, 100 * ev, ls, lw=1, label=name)
    axes[0].set_xlabel("axial strain -ln(Ly/Ly0) (%)")
    axes[0].set_ylabel("(sigma_22 - sigma_11) / p  (compression positive)")
    axes[1].set_xlabel("axial strain -ln(Ly/Ly0) (%)")
    axes[1].set_ylabel("volumetric strain ln(A/A0) (%), dilation positive")
    for ax in axes:
        ax.legend(fontsize=8)
    fig.tight_layout()
    path = ctx.figure_path("biaxial_full_curves.png")
    fig.savefig(path, dpi=110)
    plt.close(fig)
    figs.append((path, "Stress-strain and volumetric curves of the Kuhn assembly: native (dashed) and LIGGGHTS "
                       "runs (the perturbed runs lie on top: their spread is the band)."))
    return figs


@case("biaxial-full", "Biaxial test, full loading: divergence envelope and stress-strain curves",
      suites=("default", "full"), order=30)
def biaxial_full(ctx: Context) -> CaseResult:
    from ..core import evidence
    from ..dem_compare import (Trajectory, expected_frames, expected_steps, frame_differences,
                               stress_differences, trajectory_evidence)

    r = full_runs(ctx)
    bi, dem, pk = r["biaxial"], r["settings"], r["packing"]
    res = CaseResult(
        "biaxial-full", "Biaxial test, full loading: divergence envelope and stress-strain curves",
        f"Kuhn 1002-disk assembly, default biaxial settings (kn = kt = {dem.kn:g} N/m, mu = {dem.mu:g}, "
        f"dt = {dem.dt:.3g} s, p = {bi.confining:g} N/m, strain rate {bi.strain_rate:.3g} 1/s: inertial "
        f"number 5e-5). Consolidation ({FULL_CONSOLIDATION_STEPS} steps, servo on both axes) in the native engine; "
        "from its final state (written as the LIGGGHTS data file with velocities and spins; no contact history "
        "on either side) both codes run the compression (sigma_11 = p by the servo, y at constant rate) to "
        f"{100 * bi.strain:g}% axial strain ({r['nsteps']} steps). Divergence = max |x_a - x_b| / D50 at every "
        f"dump ({FULL_DUMP_EVERY} steps) and the relative stress difference every {FULL_THERMO_EVERY} steps "
        "(thermo), against the serial "
        "LIGGGHTS run.")
    res.notes.append(f"Consolidation: mean sigma_11, sigma_22 over its last 1000 steps within "
                     f"{100 * r['consolidation_error']:.2f}% of p. Native compression: {r['native'].elapsed:.1f} s.")
    if "liggghts_run_file" in r:
        res.notes.append("The LIGGGHTS compression job, parsed into the native run-file schema (docs/schema_dem.md; "
                         f"readable by <code>gransim voidcells</code>, <code>gransim dem-export</code>): "
                         f"<code>{r['liggghts_run_file']}</code>.")
    nat = r["native"]
    p = bi.confining
    if "liggghts" not in r:
        stored = load_stored_full(bi.strain)
        if stored is None:
            res.notes.append("<b>LIGGGHTS is absent</b> and no stored reference exists for this strain: nothing "
                             "to compare (see biaxial-short for the stored step-for-step reference).")
            res.error = "LIGGGHTS absent: no full-loading reference stored for this suite"
            return res
        if stored["input_sha256"] != input_fingerprint(ctx):
            res.error = ("the stored LIGGGHTS series was made from another Kuhn assembly than the one generated "
                         "here (input fingerprint differs: the packing generator changed); regenerate it with "
                         "validation.cases.biaxial.store_full_reference where LIGGGHTS is installed")
            return res
        r = {**r, **stored}
        res.notes.append("<b>LIGGGHTS is absent</b>: compared with the stored series "
                         f"<code>{STORED_FULL}/strain{bi.strain:g}.npz</code> (stress and box every "
                         f"{STORED_EVERY} steps of the reference and perturbed LIGGGHTS runs); positions are not "
                         "stored, so only the stress divergence and the curves are checked.")
    lig = r["liggghts"]
    # evidence: the series (and frames, live) of every run the envelope needs, complete
    stored_run = "manifest" not in r
    every = STORED_EVERY if stored_run else FULL_THERMO_EVERY
    exp_s = expected_steps(r["nsteps"], every)
    exp_f = None if stored_run else expected_frames(r["nsteps"], FULL_DUMP_EVERY)
    res.records += trajectory_evidence("biaxial-full/evidence", "native", nat, expected_steps(r["nsteps"],
                                       FULL_THERMO_EVERY), expected_frames(r["nsteps"], FULL_DUMP_EVERY))
    res.records += trajectory_evidence("biaxial-full/evidence", "LIGGGHTS reference", lig, exp_s, exp_f)
    want = r.get("expected_ensemble") or ensemble_labels(pk.n, ctx.suite == "full" and not stored_run)
    res.records.append(evidence("biaxial-full/evidence", "perturbed LIGGGHTS runs (the envelope)", want,
                                list(r["ensemble"])))
    for k, t in r["ensemble"].items():
        res.records += trajectory_evidence("biaxial-full/evidence", f"LIGGGHTS {k}", t, exp_s, exp_f)
    if not all(x.passed for x in res.records if x.quantity == "evidence"):
        res.notes.append("<b>Incomplete evidence</b>: a run the comparison needs is missing steps, frames or "
                         "ensemble members (records above); no envelope verdict is made on what remains.")
        return res
    runs = {"native vs LIGGGHTS": nat, **{f"LIGGGHTS {k}": t for k, t in r["ensemble"].items()}}
    div, sdiv = {}, {}
    frames = exp_f if exp_f is not None else []
    for name, tr in runs.items():
        fd = frame_differences(tr, lig, pk.d50, steps=frames)
        div[name] = (fd["steps"], fd["x"])
        st, rel, _ = stress_differences(tr, lig, steps=exp_s)
        sdiv[name] = (st, rel)
    ens = [k for k in div if k != "native vs LIGGGHTS"]
    env_s = np.max([sdiv[k][1] for k in ens], axis=0)
    rs = _ratio(sdiv["native vs LIGGGHTS"][1], env_s)
    if len(div["native vs LIGGGHTS"][0]):
        env_x = np.max([div[k][1] for k in ens], axis=0)
        rx = _ratio(div["native vs LIGGGHTS"][1], env_x)
        res.records.append(compare("biaxial-full/divergence", "position", "max_t D_native(t)/E(t)", rx,
                                   ENVELOPE_FACTOR, ENVELOPE_REASON))
    res.records.append(compare("biaxial-full/divergence", "stress", "max_t S_native(t)/E_S(t)", rs, ENVELOPE_FACTOR,
                               ENVELOPE_REASON))
    if len(nat.steps) != len(lig.steps):  # stored series: every STORED_EVERY steps
        nat = Trajectory(lig.steps, nat.stress[nat.at(lig.steps)], nat.lengths[nat.at(lig.steps)], {})
    cur = {"LIGGGHTS": curves(lig, p), "native": curves(nat, p),
           **{f"LIGGGHTS {k}": curves(t, p) for k, t in r["ensemble"].items()}}
    ea_l, q_l, ev_l = cur["LIGGGHTS"]
    _, q_n, ev_n = cur["native"]  # same thermo steps on both sides (FULL_THERMO_EVERY)
    band_q = max(float(np.abs(cur[f"LIGGGHTS {k}"][1] - q_l).max()) for k in r["ensemble"])
    band_v = max(float(np.abs(cur[f"LIGGGHTS {k}"][2] - ev_l).max()) for k in r["ensemble"])
    res.records.append(compare("biaxial-full/curve", "deviator", "max|dq|/p along the curve",
                               np.abs(q_n - q_l).max(), band_q, CURVE_REASON))
    res.records.append(compare("biaxial-full/curve", "volumetric_strain", "max|d eps_v| along the curve",
                               np.abs(ev_n - ev_l).max(), band_v, CURVE_REASON.replace(", in units of the "
                                                                                      "confining p", "")))
    rows = []
    steps = div["native vs LIGGGHTS"][0] if len(div["native vs LIGGGHTS"][0]) else []
    for k in range(0, len(steps), max(1, len(steps) // 12)):
        rows.append([int(steps[k]), float(100 * ea_l[lig.at([steps[k]])[0]]), *[float(div[n][1][k]) for n in div]])
    res.tables.append(("Divergence max|dx|/D50 against the serial LIGGGHTS run (selected dumps)",
                       ["step", "axial strain %", *div.keys()], rows))
    k_end = len(q_l) - 1
    res.tables.append(("End of compression", ["run", "axial strain %", "q/p", "eps_v %", "peak q/p"],
                       [[n, float(100 * c[0][k_end]), float(c[1][k_end]), float(100 * c[2][k_end]),
                         float(c[1].max())] for n, c in cur.items()]))
    res.figures += _plots(ctx, div, sdiv, cur)
    if "manifest" not in r:
        return res
    man = r["manifest"]
    res.notes.append(f"LIGGGHTS reference: <code>{' '.join(man.get('command', []))}</code> "
                     f"({man.get('liggghts_version', '')}), job <code>{man.get('job_dir', '')}</code>, "
                     f"{man.get('elapsed_s', 0):.1f} s.")
    final = {n: float(d[1][-1]) for n, d in div.items()}
    res.notes.append("Divergence at the last dump: " + ", ".join(f"{n} {v:.2e} D50" for n, v in final.items()) + ".")
    return res


# -- stored reference of biaxial-full (for machines without LIGGGHTS) ------------------------
STORED_FULL = "reference_runs/stored/biaxial-full"
STORED_EVERY = 100


def _stored_dir():
    from pathlib import Path

    return stored_dir("biaxial-full")


def store_full_reference(ctx: Context) -> None:
    """Store the stress and box series (every STORED_EVERY steps) of the LIGGGHTS runs of
    biaxial-full (reference and perturbed) with a README: the comparison made without LIGGGHTS.

    Run: ``python -c "from pathlib import Path; from validation.core import Context;
    from validation.cases.biaxial import store_full_reference;
    store_full_reference(Context('default', Path('results'), liggghts=True))"``.
    """
    import datetime
    import json

    r = full_runs(ctx)
    d = _stored_dir()
    d.mkdir(parents=True, exist_ok=True)
    lig = r["liggghts"]
    steps = lig.steps[lig.steps % STORED_EVERY == 0]
    arrays = {"steps": steps, "reference/stress": lig.stress[lig.at(steps)],
              "reference/lengths": lig.lengths[lig.at(steps)]}
    names = []
    for k, (name, tr) in enumerate(r["ensemble"].items()):
        arrays[f"ensemble{k}/stress"] = tr.stress[tr.at(steps)]
        arrays[f"ensemble{k}/lengths"] = tr.lengths[tr.at(steps)]
        names.append(name)
    strain = r["biaxial"].strain
    arrays["input_sha256"] = np.array(input_fingerprint(ctx))
    np.savez_compressed(d / f"strain{strain:g}.npz", names=np.array(json.dumps(names)), **arrays)
    man = r["manifest"]
    (d / f"strain{strain:g}.md").write_text(
        f"# biaxial-full reference series, axial strain {strain:g}\n\n"
        f"- Written by `validation.cases.biaxial.store_full_reference` on "
        f"{datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}.\n"
        f"- LIGGGHTS: `{' '.join(man.get('command', []))}` ({man.get('liggghts_version', '')}), serial; "
        f"deck sha256 {man.get('deck_sha256', '')}; the deck is `reference_runs.decks.biaxial.write_biaxial_deck` "
        "of the compression phase of `validation.cases.biaxial.full_runs` (Kuhn 1002-disk assembly consolidated "
        "by the native engine, default biaxial settings).\n"
        f"- Runs: reference and {', '.join(names)}.\n"
        f"- Arrays (npz): `steps` (every {STORED_EVERY} steps), `<run>/stress` (T, 3) xx yy xy of `compute "
        "pressure ... virial` (compression positive, N/m), `<run>/lengths` (T, 2) box lengths (m); `names` = "
        "JSON list of the ensemble runs.\n")


def input_fingerprint(ctx: Context) -> str:
    """SHA-256 of the assembly the full runs start from (positions, radii, cell, density).

    Stored with the reference series: a series made from another assembly (e.g. after a change
    of the packing generator) is refused with a clear message instead of failing numerically.
    """
    import hashlib

    p = _kuhn(ctx)
    h = hashlib.sha256()
    for a in (p.positions, p.radii, p.cell, np.array([p.density])):
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    return h.hexdigest()


def load_stored_full(strain: float):
    """The stored series as trajectories (no frames), or None."""
    import json

    from ..dem_compare import Trajectory

    path = _stored_dir() / f"strain{strain:g}.npz"
    if not path.exists():
        return None
    z = np.load(path)
    steps = z["steps"]
    lig = Trajectory(steps, z["reference/stress"], z["reference/lengths"], {})
    names = json.loads(str(z["names"]))
    ens = {n: Trajectory(steps, z[f"ensemble{k}/stress"], z[f"ensemble{k}/lengths"], {}) for k, n in enumerate(names)}
    return {"liggghts": lig, "ensemble": ens,
            "input_sha256": str(z["input_sha256"]) if "input_sha256" in z else None}
