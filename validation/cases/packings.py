"""Case ``packings``: the assemblies every other case starts from, checked against what they were
asked to be (no LIGGGHTS side: both codes read these very files).

Every check is computed here from the saved positions, independently of the generator's kernels:
contacts by the brute-force O(N^2) periodic search, forces by the linear law written out in numpy.

* RVEs (``make_packing``, frictionless): the largest net force on a disk over the mean contact
  force is at most the generator's stop criterion (1e-3); the mean overlap is within the 2 %
  tolerance of its target 2.7e-4 d_mean.
* Kuhn's assembly (``compact_packing``, frictional): tangential forces are not stored, but the trace
  of the Love stress needs only the normal forces, so the mean pressure sum |l| kn eps / (2A) must
  equal the servo target p = 1e-4 kn (1.5 %: the servo's 1 % per axis plus damping forces at rest);
  the mean indentation must be below Kuhn's 0.02 % of D50; the void ratio must be near Kuhn's 0.189
  (within 0.005; seeds 1-4 of the calibrated protocol give 0.189-0.196, the standard seed 1 0.190).
* Kuhn's assembly replayed by LIGGGHTS (when installed): :func:`gransim.generation.compaction_run`
  rebuilds the granular gas, the DEM settings and the step count from the file's metadata; the
  mirror deck of :mod:`reference_runs.decks.biaxial` runs the whole compaction (~190,000 steps) in
  LIGGGHTS 3.8.0, whose final positions and box must equal the file's (the native engine matches
  LIGGGHTS bit for bit; the tolerance admits only the rounding of the final wrap into the cell).
* Sieve curves: at every aperture of the grading, the sample's percent passing by area against
  the curve; the tolerance is the area share of the largest grain (a sample of N grains cannot
  follow a continuous curve more closely than one grain).
"""

from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from gransim import generation
from gransim.contacts import find_neighbours_bruteforce
from gransim.generation import RVE_MEAN_OVERLAP, compaction_run, get_distribution, packing_stats
from gransim.io import load_packing
from reference_runs.parsers import parse_log
from reference_runs.runner import LOG_NAME

from ..core import CaseResult, Context, case, compare, in_pair, peak
from ..dem_compare import (
    expected_frames,
    expected_steps,
    position_difference,
    run_liggghts_job,
    run_native,
    run_reference_job,
    trajectory_evidence,
)

REPLAY_REASON = (
    "the native engine, in that code's arithmetic, follows the code bit for bit (biaxial-short); "
    "over the ~190,000 steps of the compaction any difference in the last bit would grow to a visible "
    "one (chaos), so the final positions and box must be equal: 1e-10 D50 admits nothing else"
)

#: Kuhn (1997, section 4)
KUHN_PAPER = {"void_ratio": 0.189, "indentation_d50": 2e-4, "coordination_2M_N": 3.75}
KUHN_VOID_TOL = 0.005


def _contacts(p):
    nl = find_neighbours_bruteforce(p.positions, p.radii, p.cell, 0.0)
    eps = nl.overlaps(p.radii)
    c = eps > 0
    return nl.i[c], nl.j[c], nl.branch[c], nl.distance[c], eps[c]


def _sieve_error(p) -> tuple[float, float]:
    g = get_distribution(p.metadata["distribution"])
    a = (2.0 * p.radii) ** 2
    d = 2.0 * p.radii
    err = peak([abs(100.0 * a[d <= dk].sum() / a.sum() - pk) for dk, pk in zip(g.diameters, g.passing)])
    return float(err), float(100.0 * a.max() / a.sum())


@case(
    "packings", "Packings: the 15 RVEs and Kuhn's assembly against their targets", suites=("default", "full"), order=5
)
def packings(ctx: Context) -> CaseResult:
    res = CaseResult(
        "packings",
        "Packings: the 15 RVEs and Kuhn's assembly against their targets",
        "The standard assemblies (<code>gransim packings</code>): 5 RVEs each of 70, 350 and 700 disks of "
        "quartz-sand (FIRE, frictionless, mean overlap 2.7e-4 d_mean) and Kuhn's 1002 disks (frictional DEM "
        "compaction, preparation friction 0.05, p = 1e-4 kn). Checked from the saved files with a brute-force "
        "contact search: force balance (RVEs) or the servo pressure (Kuhn), overlaps, Kuhn's void ratio, and "
        "the sieve curve of every sample.",
    )
    paths = generation.standard_packings(ctx.results / "packings")
    _regenerated(ctx, res, paths)
    rows = []
    packs, seen = {}, {}  # loaded packings and their contacts, reused by the figure
    for name, path in paths.items():
        p = load_packing(path)
        s = packing_stats(p)
        packs[name], seen[name] = p, _contacts(p)
        i, j, branch, dist, eps = seen[name]
        err, bound = _sieve_error(p)
        res.records.append(
            compare(
                f"packings/{name}",
                "sieve curve",
                "max |sample - curve| over apertures (pp)",
                err,
                bound,
                "one grain: the area share of the largest disk",
            )
        )
        if name.startswith("rve-"):
            n = branch / dist[:, None]
            F = np.zeros((p.n, 2))
            np.add.at(F, i, -eps[:, None] * n)  # k_n = 1: force = overlap (the ratio does not depend on k_n)
            np.add.at(F, j, eps[:, None] * n)
            residual = float(np.max(np.linalg.norm(F, axis=1)) / eps.mean())
            res.records.append(
                compare(
                    f"packings/{name}",
                    "force balance",
                    "max |net force| / mean contact force",
                    residual,
                    1.001e-3,
                    "the generator's stop criterion (force_tol 1e-3, max norm)",
                )
            )
            rel = abs(eps.mean() / (2.0 * p.radii.mean()) / RVE_MEAN_OVERLAP - 1.0)
            res.records.append(
                compare(
                    f"packings/{name}",
                    "mean overlap",
                    "|<eps>/d_mean / 2.7e-4 - 1|",
                    rel,
                    0.02,
                    "overlap_tol of the request",
                )
            )
            check = f"{residual:.2e}"
        else:
            kn = p.metadata["dem"]["kn"]
            target = p.metadata["pressure_over_kn"] * kn
            pressure = float(np.sum(dist * kn * eps) / (2.0 * p.area))
            res.records.append(
                compare(
                    f"packings/{name}",
                    "servo pressure",
                    "|p_normal / p_target - 1|",
                    abs(pressure / target - 1.0),
                    0.015,
                    "trace of the Love stress from normal forces only; servo stops at 1 % per axis",
                )
            )
            res.records.append(
                compare(
                    f"packings/{name}",
                    "mean indentation",
                    "<eps> / D50",
                    s["mean_overlap_d50"],
                    KUHN_PAPER["indentation_d50"],
                    "Kuhn (1997): on average less than 0.02 % of D50",
                )
            )
            res.records.append(
                compare(
                    f"packings/{name}",
                    "void ratio",
                    "|e - 0.189|",
                    abs(s["void_ratio"] - KUHN_PAPER["void_ratio"]),
                    KUHN_VOID_TOL,
                    "Kuhn (1997): e = 0.189, 'near 0.189' asked; seeds 1-4 of the protocol give 0.189-0.196",
                )
            )
            check = f"p/p0 - 1 = {pressure / target - 1.0:+.2e}"
            if ctx.liggghts:
                res.declare(
                    "native-liggghts", "LIGGGHTS replays the compaction that made Kuhn's assembly: " + REPLAY_REASON
                )
                res.records += in_pair(_liggghts_replay(ctx, name, p, res), "native-liggghts")
            else:
                res.notes.append(f"{name}: LIGGGHTS is absent: the compaction is not replayed by it.")
            if ctx.lammps:
                res.declare(
                    "native-lammps",
                    "LAMMPS replays the same compaction beside the native engine in "
                    "LAMMPS' arithmetic: " + REPLAY_REASON,
                )
                res.records += in_pair(_lammps_replay(ctx, name, p, res), "native-lammps")
            else:
                res.notes.append(f"{name}: LAMMPS is absent: the compaction is not replayed by it.")
        rows.append(
            [
                name,
                p.n,
                f"{s['solid_fraction']:.4f}",
                f"{s['void_ratio']:.4f}",
                f"{s['coordination']:.3f}",
                f"{s['coordination_nonrattler']:.3f}",
                f"{100 * s['rattler_fraction']:.1f}",
                f"{100 * s['mean_overlap_d50']:.4f}",
                f"{s['fabric_anisotropy']:.3f}",
                f"{err:.2f}",
                check,
            ]
        )
    for pair in ("native-liggghts", "native-lammps"):
        res.skip_pair(
            pair,
            "no compaction replayed: the code is not installed here (the 190,000-step replay is not "
            "stored), or no assembly of this set was made by a DEM compaction (the RVEs are FIRE "
            "packings, checked above against their own criteria)",
        )
    res.skip_code(
        "yade",
        "no YADE run: the assemblies are judged against their own targets, and the compaction replay is a damped "
        "frictional compaction (LIGGGHTS' law) that YADE 2023.02a cannot run with the same dissipation (its damped "
        "linear law takes a periodic image's velocity with the wrong sign, ViscoelasticPM.cpp:118, docs/yade.md)",
    )
    res.skip_pair(
        "liggghts-lammps",
        "a 190,000-step compaction in two codes with slightly different laws ends in "
        "different (equally valid) packings by chaos; the codes are set against each "
        "other on the same start in biaxial-short, biaxial-full and voidcell",
    )
    rows.append(
        [
            "Kuhn (1997), paper",
            1002,
            "0.841",
            "0.189",
            "",
            "3.75 (2M/N)",
            "13.1 (131 outside the graph)",
            "< 0.02",
            "",
            "",
            "",
        ]
    )
    res.tables.append(
        (
            "The standard assemblies (rattlers: fewer than 3 contacts, removed iteratively)",
            [
                "name",
                "N",
                "phi",
                "e",
                "Z",
                "Z without rattlers",
                "rattlers %",
                "<eps>/D50 %",
                "fabric anisotropy",
                "sieve error pp",
                "balance",
            ],
            rows,
        )
    )
    shown = [n for n in ("kuhn-1002", "rve-700-1") if n in paths] or list(paths)[:1]
    res.figures.append(
        (
            _figure(ctx, {n: (packs[n], seen[n]) for n in shown}),
            f"{' and '.join(shown)}: disks and contact forces (line width proportional to the normal force)",
        )
    )
    return res


#: the assemblies the default suite regenerates to check the files it uses (the full suite: all 16)
REGENERATED_DEFAULT = ("rve-70-1", "rve-350-2")


def _regenerated(ctx: Context, res: CaseResult, paths: dict) -> None:
    """Regenerate some standard assemblies and compare them with the files every case reads.

    A missing file is copied from the copies shipped with the package (``standard_packings``), so
    the generator must be shown to make them: positions, radii and cell equal bit for bit.
    """
    names = list(paths) if ctx.suite == "full" else [n for n in REGENERATED_DEFAULT if n in paths]
    for name in names:
        have, fresh = load_packing(paths[name]), generation.build_standard(name)
        same_shape = all(getattr(have, f).shape == getattr(fresh, f).shape for f in ("positions", "radii", "cell"))
        if same_shape:
            d50 = float(np.median(2.0 * fresh.radii))
            diff = peak(np.abs(getattr(have, f) - getattr(fresh, f)) / d50 for f in ("positions", "radii", "cell"))
        else:
            diff = float("inf")
        res.records.append(
            compare(
                f"packings/{name}",
                "regenerated by the generator vs the file in use (shipped or cached)",
                "max |difference| of positions, radii and cell / D50",
                diff,
                0.0,
                "the generator is deterministic (fixed seed, fixed summation order), so the file the "
                "other cases read must be what it makes, bit for bit",
            )
        )
    res.notes.append(
        f"Regenerated and compared bit for bit with the files in use: {', '.join(names)}"
        + ("" if ctx.suite == "full" else " (the full suite regenerates all 16)")
        + "."
    )


def _liggghts_replay(ctx: Context, name: str, p, res: CaseResult) -> list:
    """LIGGGHTS runs the compaction that made ``p`` from the same gas; final positions and box compared."""
    gas, dem, loading, nsteps = compaction_run(p)
    job = ctx.work("reference", "packings", name)
    thermo = max(nsteps // 100, 1)
    lig, man = run_liggghts_job(
        job, gas, dem, loading, nsteps, dump_every=nsteps, thermo_every=thermo, timeout=ctx.job_timeout(gas.n * nsteps)
    )
    ev = trajectory_evidence(
        f"packings/{name}",
        "LIGGGHTS replay",
        lig,
        [s for s in expected_steps(nsteps, thermo)],
        expected_frames(nsteps, nsteps),
    )
    if not all(r.passed for r in ev):
        return ev
    run = parse_log(job / LOG_NAME).runs[-1]
    lo = np.array([run["xlo"][-1], run["ylo"][-1]])
    L = lig.lengths[-1]
    x = lig.frames[nsteps]["x"] - lo  # the packing is the final state shifted to the origin, wrapped
    tol = 4 * float(np.spacing(L.max()))
    res.notes.append(
        f"{name}: LIGGGHTS 3.8.0 replayed the {nsteps}-step compaction from the same gas in "
        f"{float(man.get('elapsed_s', 0.0)):.1f} s (job {job}; 0.0 s: an identical job was reused)."
    )
    return ev + [
        compare(
            f"packings/{name}",
            "LIGGGHTS replay: position",
            "max|dx| (m) modulo the box",
            position_difference(x, p.positions, L),
            tol,
            "the engine matches LIGGGHTS bit for bit; only the final wrap into the cell rounds (4 ulp of L)",
        ),
        compare(
            f"packings/{name}",
            "LIGGGHTS replay: box",
            "max|dL| (m)",
            float(np.abs(L - np.diag(p.cell)).max()),
            0.0,
            "the box is the same double in both codes",
        ),
    ]


def _lammps_replay(ctx: Context, name: str, p, res: CaseResult) -> list:
    """LAMMPS runs the compaction that made ``p`` from the same gas while the native engine runs it
    in LAMMPS' arithmetic (``flavour="lammps"``); final positions and box compared. (The packing file
    itself was made in LIGGGHTS' arithmetic: :func:`_liggghts_replay` checks it.)"""
    gas, dem, loading, nsteps = compaction_run(p)
    dem = dataclasses.replace(dem, flavour="lammps")
    job = ctx.work("reference", "packings", f"{name}-lammps")
    thermo = max(nsteps // 100, 1)
    with ThreadPoolExecutor(max_workers=1) as pool:
        fut = pool.submit(
            run_reference_job,
            job,
            gas,
            dem,
            loading,
            nsteps,
            dump_every=nsteps,
            thermo_every=thermo,
            timeout=ctx.job_timeout(gas.n * nsteps),
            engine="lammps",
        )
        nat = run_native(gas, dem, loading, nsteps, nsteps, thermo_every=thermo)
        lmp, man = fut.result()
    exp_s, exp_f = expected_steps(nsteps, thermo), expected_frames(nsteps, nsteps)
    ev = trajectory_evidence(f"packings/{name}", "LAMMPS replay", lmp, exp_s, exp_f) + trajectory_evidence(
        f"packings/{name}", "native replay (lammps)", nat, exp_s, exp_f
    )
    if not all(r.passed for r in ev):
        return ev
    L = lmp.lengths[-1]
    res.notes.append(
        f"{name}: LAMMPS replayed the {nsteps}-step compaction from the same gas in "
        f"{float(man.get('elapsed_s', 0.0)):.1f} s (job {job}; 0.0 s: an identical job was reused), the "
        f"native engine in LAMMPS' arithmetic in {nat.elapsed:.1f} s."
    )
    return ev + [
        compare(
            f"packings/{name}",
            "LAMMPS replay: position",
            "max|dx|/D50 modulo the box, native (lammps) vs LAMMPS",
            position_difference(nat.frames[nsteps]["x"], lmp.frames[nsteps]["x"], L) / p.d50,
            1e-10,
            REPLAY_REASON,
        ),
        compare(
            f"packings/{name}",
            "LAMMPS replay: box",
            "max|dL|/D50, native (lammps) vs LAMMPS",
            float(np.abs(L - nat.lengths[-1]).max()) / p.d50,
            1e-10,
            REPLAY_REASON,
        ),
    ]


def _figure(ctx: Context, shown: dict):
    """Disks and contact force lines of ``shown`` = {name: (packing, contacts of _contacts)}."""
    # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection, PatchCollection
    from matplotlib.patches import Circle

    fig, axes = plt.subplots(1, len(shown), figsize=(6.5 * len(shown), 6.5), squeeze=False)
    for ax, (name, (p, (i, _j, branch, _dist, eps))) in zip(axes[0], shown.items()):
        ax.add_collection(
            PatchCollection(
                [Circle(xy, r) for xy, r in zip(p.positions, p.radii)],
                facecolor="0.88",
                edgecolor="0.6",
                linewidths=0.3,
            )
        )
        seg = np.stack([p.positions[i], p.positions[i] + branch], axis=1)
        ax.add_collection(LineCollection(seg, linewidths=0.3 + 3.0 * eps / eps.max(), colors="k"))
        L = np.diag(p.cell)
        ax.plot([0, L[0], L[0], 0, 0], [0, 0, L[1], L[1], 0], color="tab:blue", lw=0.8)
        ax.set_xlim(-0.03 * L[0], 1.03 * L[0])
        ax.set_ylim(-0.03 * L[1], 1.03 * L[1])
        ax.set_aspect("equal")
        ax.set_axis_off()
        ax.set_title(f"{name}: N = {p.n}, e = {(1 - p.solid_fraction) / p.solid_fraction:.4f}")
    out = ctx.figure_path("packings_force_chains.png")
    fig.savefig(out, dpi=110, bbox_inches="tight")
    plt.close(fig)
    return out
