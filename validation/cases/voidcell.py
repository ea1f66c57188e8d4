"""Case ``voidcell``: Kuhn's void-cell measures from native and from LIGGGHTS snapshots.

Both sides build their :class:`gransim.voidcell.Snapshot` the same way
(:func:`validation.dem_compare.snapshot`): contacts from the positions (overlapping pairs,
``find_neighbours(skin=0)``), velocities plus the affine streaming of ``remap x``, dC/dt from the
box lengths by central differences. So any difference comes from the trajectories alone.
"""

from __future__ import annotations

import csv
import functools
from pathlib import Path

import numpy as np

from gransim.io import atomic_path
from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, short_case
from reference_runs.yade.dem import short_biaxial

from .. import yade_runs
from ..codes import CODES, NATIVE
from ..core import CaseResult, Context, case, stored_dir
from ..dem_compare import expected_frames, read_reference, run_native, snapshot, trajectory_evidence
from ..judges import (  # noqa: F401 (cell_signature: the voidcell tests use it from here)
    LIST_REASON,
    cell_records,
    cell_signature,
    compare_cell_frames,
    void_cells,
)
from ..matrix import Comparison, Failed, Run, evaluate
from .biaxial import (
    CODE,
    FULL_DUMP_EVERY,
    SHORT_CODES,
    YADE_DUMP_EVERY,
    YADE_SCEN,
    _flavour,
    _stored_log,
    ensemble_labels,
    full_runs,
    lammps_ensemble_labels,
    yade_plan,
)

STATS_REASON = (
    "band = the largest deviation of the perturbed LIGGGHTS runs (one coordinate moved by 1e-15) "
    "from the reference over the frames: the statistics' own spread under round-off (instantaneous "
    "velocity fields decorrelate once positions differ by ~1e-4 D50)"
)
#: strains of the paper's statistics (Kuhn 1997, sec. 4): 0.01% and 0.16%
PAPER = {
    "mean_alpha_0.01%": 0.73,
    "alpha_le_0_0.16%": 0.22,
    "faces": 762,
    "edges": 1633,
    "vertices": 871,
    "coordination": 3.75,
}
#: compression steps of the Kuhn runs counted as the short horizon (perturbations still < 1e-10 D50)
SHORT_HORIZON = 24000


def _present(frames, *trs) -> list:
    """The expected frames that every trajectory holds."""
    return [int(k) for k in frames if all(int(k) in tr.frames for tr in trs)]


def _evidence(label, nat, lig, frames, code: str = "LIGGGHTS", first: str = "native") -> list:
    """Evidence of the frames both sides must hold (positions and velocities of every disk)."""
    recs = []
    for who, tr in ((first, nat), (code, lig)):
        if tr is not None:
            recs += trajectory_evidence(label, who, tr, None, frames)
    return recs


def _strain(tr, step) -> float:
    L = tr.lengths
    return float(-np.log(L[tr.at([step])[0], 1] / L[0, 1]))


def _maps(ctx, pairs, name) -> tuple:
    # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    # lazy: imports matplotlib (~1.5 s); only the figures need it
    from gransim.voidcell.plots import plot_alignment

    fig, axes = plt.subplots(len(pairs), 2, figsize=(12, 5.6 * len(pairs)), squeeze=False)
    for row, (title, a, b) in enumerate(pairs):
        for col, (vc, who) in enumerate(((a, "native"), (b, "LIGGGHTS"))):
            plot_alignment(vc, ax=axes[row, col])
            axes[row, col].set_title(
                f"{who}, {title}: mean alpha {vc.mean_alpha:.3f}, {100 * vc.fraction_nonpositive_alpha:.1f}% <= 0",
                fontsize=9,
            )
    fig.tight_layout()
    path = ctx.figure_path(name)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


CROSS_STATS_REASON = (
    "LIGGGHTS and LAMMPS differ in their laws (docs/lammps.md), so their instantaneous cells differ "
    "once positions decorrelate; if both follow the same statistics, each code's reference lies within "
    "its own band (its perturbed runs' largest deviation), so the two differ by at most the sum of "
    "the two bands"
)
CROSS_SHORT_REASON = (
    "on the 3000-step stored runs the two codes' positions differ by the documented law differences "
    "(docs/lammps.md; the lever arm alone moves them by 1.6e-2 D50), enough to change cells: shown "
    "for the reader, not judged; the codes' cells are judged by their statistics on the Kuhn "
    "assembly, against each code's own band"
)


def cells_plan(ctx: Context) -> tuple[list, list]:
    """The short horizon of the case: per code of biaxial-short's :data:`SHORT_CODES`, the void
    cells of its stored run's every dump against those of the native run in its arithmetic
    (:func:`validation.judges.cell_lists`)."""
    p, s, ld, n = short_case()
    frames = expected_frames(n, SHORT_CASE_DUMP_EVERY)
    runs, comps = [], []
    for code in CODES:
        if code not in SHORT_CODES:
            continue
        d = stored_dir(SHORT_CODES[code].stored)
        runs += [
            Run(
                f"native/stored-120/{code}",
                NATIVE,
                code,
                f"native, {code} arithmetic",
                functools.partial(run_native, p, _flavour(s, code), ld, n, SHORT_CASE_DUMP_EVERY),
            ),
            Run(
                f"stored-120/{code}",
                code,
                code,
                f"stored {d.name}",
                functools.partial(read_reference, _stored_log(d), d / "dump.atoms"),
            ),
        ]
        comps.append(
            Comparison(
                "cells",
                f"voidcell/stored-120/{code}",
                (f"native/stored-120/{code}", f"stored-120/{code}"),
                LIST_REASON,
                {"frames": frames, "radii": p.radii, "dt": s.dt, "snapshot": snapshot},
            )
        )
    # every two codes' own snapshots: the same cells on the short horizon? (shown: their laws differ)
    here = [c for c in CODES if c in SHORT_CODES]
    for i, a in enumerate(here):
        for b in here[i + 1 :]:
            comps.append(
                Comparison(
                    "cells", f"voidcell/stored-120/{a}-{b}", (f"stored-120/{a}", f"stored-120/{b}"), CROSS_SHORT_REASON,
                    {"frames": frames, "radii": p.radii, "dt": s.dt, "snapshot": snapshot,
                     "as_info": CROSS_SHORT_REASON},
                    pair="",
                )
            )  # fmt: skip
    # YADE's run of the undamped short case (biaxial-short's yade-120 runs: live, or its stored output)
    y_runs, y_comps = yade_plan(ctx, {}, codes=())
    if y_comps:
        py, sy, _, ny = short_biaxial()
        runs += y_runs
        comps.append(
            Comparison(
                "cells",
                f"voidcell/{YADE_SCEN}/yade",
                (f"native/{YADE_SCEN}/yade", f"{YADE_SCEN}/yade"),
                YADE_CELLS_REASON,
                {
                    "frames": expected_frames(ny, YADE_DUMP_EVERY),
                    "radii": py.radii,
                    "dt": sy.dt,
                    "snapshot": yade_runs.yade_snapshot,
                },
            )
        )
    return runs, comps


YADE_CELLS_REASON = (
    "native in YADE's arithmetic repeats YADE 2023.02a's run to the bit (biaxial-short/yade-120), so the same "
    "snapshots give the same cells; the cell lists must be identical and alpha, w within 1e-6 (the judge's bounds)"
)


def kuhn_plan(ctx: Context, r: dict, frames) -> tuple[list, list, dict]:
    """The Kuhn assembly's runs (biaxial-full's: :func:`validation.cases.biaxial.full_runs` ``r``):
    per code, the native run in its arithmetic, the code's reference and its perturbed runs, each
    expected member a run (a member missing is failing evidence); the comparisons: the cell lists of
    the first :data:`SHORT_HORIZON` steps (``cells``), the statistics along the compression within
    the code's band (``statistics``), and the two codes' references within the sum of their bands
    (``statistics_cross``). Returns (runs, comparisons, the statistics of every run, filled as they
    are computed: {name: (F, 6)})."""
    pk, dem = r["packing"], r["settings"]
    steps = [int(k) for k in frames]
    st: dict = {}
    cache: dict = {}

    def stats(tr):
        if id(tr) not in cache:
            rows = []
            for k in steps:
                vc = void_cells(snapshot(tr, k, pk.radii, dem.dt))
                rows.append([vc.mean_alpha, vc.fraction_nonpositive_alpha, vc.n_faces, vc.n_edges, vc.n_vertices,
                             vc.coordination])  # fmt: skip
            cache[id(tr)] = (tr, np.array(rows))
        return cache[id(tr)][1]

    def named(name, tr):
        st[name] = stats(tr)
        return st[name]

    sides = {}
    if "liggghts" in r:
        sides["liggghts"] = (r["native"], r["liggghts"], r["ensemble"],
                             r.get("expected_ensemble") or ensemble_labels(pk.n, ctx.suite == "full"))  # fmt: skip
    if "lammps" in r:
        lm = r["lammps"]
        sides["lammps"] = (lm["native"], lm["reference"], lm["ensemble"],
                           lm.get("expected_ensemble") or lammps_ensemble_labels(pk.n, ctx.suite))  # fmt: skip
    runs, comps = [], []
    checks = ((0, "mean_alpha"), (1, "fraction_alpha_le_0"))
    early = [k for k in frames if k <= SHORT_HORIZON]
    for engine in ("liggghts", "lammps"):
        if engine not in sides:  # the code is absent: biaxial-full made no run of it (a note says so)
            continue
        nat, ref, ens, want = sides[engine]
        code = CODE[engine]
        runs += [
            Run(f"kuhn-1002/native-{engine}", NATIVE, engine, "biaxial-full's native run",
                lambda nat=nat: nat),
            Run(f"kuhn-1002/{engine}", engine, engine, f"biaxial-full's {code} reference", lambda ref=ref: ref),
            *(Run(f"kuhn-1002/{engine}/{m}", engine, engine, f"biaxial-full's {code} run {m}",
                  lambda m=m, ens=ens: ens[m] if m in ens else Failed(f"the perturbed run {m} is missing"))
              for m in want),
        ]  # fmt: skip
        lab = f"voidcell/kuhn-1002/{engine}"
        comps += [
            Comparison("cells", f"{lab}/first {SHORT_HORIZON} steps",
                       (f"kuhn-1002/native-{engine}", f"kuhn-1002/{engine}"), STATS_REASON.replace("LIGGGHTS", code),
                       {"frames": early, "radii": pk.radii, "dt": dem.dt, "snapshot": snapshot}),
            Comparison("statistics", f"{lab}/full test", (f"kuhn-1002/native-{engine}", f"kuhn-1002/{engine}",
                                                          *(f"kuhn-1002/{engine}/{m}" for m in want)),
                       STATS_REASON.replace("LIGGGHTS", code),
                       {"frames": frames, "checks": checks, "factor": 1.0, "member_names": list(want),
                        "statistics": lambda tr, engine=engine, nat=nat, ref=ref, ens=ens: named(
                            _stat_name(tr, engine, nat, ref, ens), tr)}),
        ]  # fmt: skip
    if len(sides) == 2:
        wl, wm = sides["liggghts"][3], sides["lammps"][3]
        comps.append(
            Comparison("statistics_cross", "voidcell/kuhn-1002/cross", ("kuhn-1002/liggghts", "kuhn-1002/lammps",
                       *(f"kuhn-1002/liggghts/{m}" for m in wl), *(f"kuhn-1002/lammps/{m}" for m in wm)),
                       CROSS_STATS_REASON, {"n_a": len(wl), "frames": frames, "checks": checks, "statistics": stats})
        )  # fmt: skip
    return runs, comps, st


def _stat_name(tr, engine: str, nat, ref, ens) -> str:
    """The name a run's statistics carry in the figure: native (code), the code, or code member."""
    if tr is nat:
        return f"native ({engine})"
    if tr is ref:
        return CODE[engine]
    return next((f"{CODE[engine]} {k}" for k, t in ens.items() if t is tr), CODE[engine])


@case(
    "voidcell",
    "Void-cell measures (Kuhn) from native, LIGGGHTS and LAMMPS snapshots",
    order=40,
    uses=("biaxial-full",),
)
def voidcell(ctx: Context) -> CaseResult:
    res = CaseResult(
        "voidcell",
        "Void-cell measures (Kuhn) from native, LIGGGHTS and LAMMPS snapshots",
        "Particle graph, void cells, alignment alpha (eqs 18-19) and normalised vorticity w (eq 20) of Kuhn "
        "(1997), computed by gransim.voidcell from snapshots of every code built identically: contacts = "
        "overlapping pairs of the dumped positions, velocities = dumped v + (dC/dt) C^-1 x (every code uses "
        "<code>remap x</code>, whose velocities exclude the box's affine motion), dC/dt by central differences of "
        "the box lengths. <i>stored-120</i>: every dump of the stored 120-disk biaxial-short runs (LIGGGHTS and "
        "LAMMPS; the native engine in each code's arithmetic). <i>kuhn-1002</i> (default suite, with the codes "
        "installed): the compression of biaxial-full.",
    )
    if ctx.suite != "quick" and ctx.liggghts and ctx.lammps:
        res.declare("liggghts-lammps", CROSS_STATS_REASON)
    else:
        res.skip_pair(
            "liggghts-lammps",
            "the codes' cells are judged by their statistics over the Kuhn compression, "
            "which needs both codes live (default and full suites); " + CROSS_SHORT_REASON,
        )
    p, s, ld, n = short_case()
    frames = expected_frames(n, SHORT_CASE_DUMP_EVERY)
    runs, comps = cells_plan(ctx)
    out = evaluate(res, ctx, runs, comps)
    res.skip_code(
        "yade",
        "YADE runs the deck undamped, the codes' stored runs are damped: their cells are of different runs "
        "(biaxial-short sets YADE against LIGGGHTS and LAMMPS on the undamped deck)",
    )
    for c in comps:
        cmp, code = out.summaries.get(c.label), c.runs[1].split("/")[-1]
        if cmp is None or not c.runs[0].startswith("native/"):  # native against a code's own run
            continue
        if cmp["no_tessellation"]:
            res.notes.append(
                f"stored-120 ({CODE[code]}): steps {cmp['no_tessellation']} have no framework spanning "
                "the cell (the pruned graph does not wrap the torus) on either side: identical outcome, no "
                "cells to compare there."
            )
        if cmp["vc"] and cmp["vc"][-1][0] is not None and code == CODES[0]:
            a, b = cmp["vc"][-1]
            res.figures.append(
                (
                    _maps(ctx, [(f"step {cmp['steps'][-1]}", a, b)], "voidcell_stored120.png"),
                    f"stored-120, last compared dump: cells shaded by alpha (white <= 0), native left, {CODE[code]} "
                    "right",
                )
            )
    if ctx.suite == "quick":
        return res

    if not (ctx.liggghts or ctx.lammps):
        res.notes.append("LIGGGHTS and LAMMPS are absent: the Kuhn-assembly comparison (full test) is not made.")
        return res
    r = full_runs(ctx)
    pk, dem = r["packing"], r["settings"]
    frames = expected_frames(r["nsteps"], FULL_DUMP_EVERY)
    steps = [int(k) for k in frames]
    k_runs, k_comps, st = kuhn_plan(ctx, r, frames)
    out = evaluate(res, ctx, k_runs, k_comps)
    for c in k_comps:
        sm = out.summaries.get(c.label)
        if c.kind == "statistics" and sm is not None and not sm["complete"]:
            res.notes.append(
                f"<b>Incomplete evidence</b> for the Kuhn assembly ({c.label}; records above): no statistics "
                "are compared on what remains."
            )
    sides = {e: True for e in ("liggghts", "lammps") if e in r}
    for e in ("liggghts", "lammps"):
        if e not in r:
            res.notes.append(f"{CODE[e]} is absent: its Kuhn-assembly comparison is not made.")
    complete = {
        e: bool(out.summaries.get(f"voidcell/kuhn-1002/{e}/full test", {}).get("complete"))
        for e in ("liggghts", "lammps")
    }
    if "liggghts" in sides and complete.get("liggghts"):
        nat, lig = r["native"], r["liggghts"]
        strains = np.array([_strain(lig, k) for k in steps])
        rows = []
        pairs = []
        for target, tag in ((1e-4, "0.01%"), (1.6e-3, "0.16%")):
            k = int(np.argmin(np.abs(strains - target)))
            vn = void_cells(snapshot(nat, steps[k], pk.radii, dem.dt))
            vl = void_cells(snapshot(lig, steps[k], pk.radii, dem.dt))
            pairs.append((f"strain {100 * strains[k]:.3f}% (step {steps[k]})", vn, vl))
            for who, vc in (("native", vn), ("LIGGGHTS", vl)):
                rows.append(
                    [
                        f"{who} @ {tag}",
                        float(100 * strains[k]),
                        vc.mean_alpha,
                        float(100 * vc.fraction_nonpositive_alpha),
                        vc.n_faces,
                        vc.n_edges,
                        vc.n_vertices,
                        vc.coordination,
                    ]
                )
        rows.append(["Kuhn (1997): 0.01% / 0.16%", "", "0.73 (0.01%)", "about 22 (0.16%)", 762, 1633, 871, 3.75])
        res.tables.append(
            (
                "Beside the paper (reported, not pass/fail: another packing, another contact law)",
                ["source", "strain %", "mean alpha", "alpha <= 0 (%)", "faces", "edges", "vertices", "2M/N"],
                rows,
            )
        )
        maps = _maps(ctx, pairs, "voidcell_kuhn_maps.png")
        res.add_figure(
            maps,
            "Kuhn assembly: cells shaded by alignment alpha (Fig. 8 of Kuhn; white <= 0) at the "
            "frames nearest 0.01% and 0.16% axial strain; native left, LIGGGHTS right",
            data=_maps_data(maps, pairs),
            headline=True,
        )
        res.figures.append(
            (
                _stats_plot(ctx, strains, st),
                "Mean alpha and fraction alpha <= 0 over the compression: "
                "native, LIGGGHTS, LAMMPS and the perturbed runs",
            )
        )
    return res


def _maps_data(png, pairs):
    """The per-cell alignment alpha behind a map figure, as CSV beside it (frame, code, cell, alpha)."""
    path = Path(png).with_suffix(".csv")
    with atomic_path(path, suffix=".csv.tmp") as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["frame", "code", "cell", "alpha"])
            for title, a, b in pairs:
                for who, vc in (("native", a), ("LIGGGHTS", b)):
                    for k, al in enumerate(np.asarray(vc.alpha, float)):
                        w.writerow([title, who, k, f"{al:.17g}"])
    return path


def _stats_plot(ctx, strains, st):
    # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for name, a in st.items():
        ls = "--" if name.startswith("native") else "-"
        axes[0].plot(100 * strains, a[:, 0], ls, lw=1, label=name)
        axes[1].plot(100 * strains, 100 * a[:, 1], ls, lw=1, label=name)
    axes[0].axhline(0.73, color="0.6", lw=0.8, ls=":")
    axes[1].axhline(22, color="0.6", lw=0.8, ls=":")
    axes[0].set_ylabel("mean alpha (paper 0.73 at 0.01%)")
    axes[1].set_ylabel("alpha <= 0 (%) (paper ~22 at 0.16%)")
    for ax in axes:
        ax.set_xlabel("axial strain (%)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = ctx.figure_path("voidcell_kuhn_stats.png")
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
