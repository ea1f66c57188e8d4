"""Case ``voidcell``: Kuhn's void-cell measures from native and from LIGGGHTS snapshots.

Both sides build their :class:`gransim.voidcell.Snapshot` the same way
(:func:`validation.dem_compare.snapshot`): contacts from the positions (overlapping pairs,
``find_neighbours(skin=0)``), velocities plus the affine streaming of ``remap x``, dC/dt from the
box lengths by central differences. So any difference comes from the trajectories alone.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from gransim.errors import InputError
from gransim.io import atomic_path
from gransim.voidcell import VoidCells
from reference_runs.decks.biaxial import SHORT_CASE_DUMP_EVERY, short_case
from reference_runs.judge import defined_diff, defined_peak

from ..core import CaseResult, Context, case, compare, evidence, in_pair, info, peak, stored_dir
from ..dem_compare import expected_frames, read_reference, run_native, snapshot, trajectory_evidence
from .biaxial import (
    CODE,
    FULL_DUMP_EVERY,
    _flavour,
    _stored_log,
    ensemble_labels,
    full_runs,
    lammps_ensemble_labels,
)

ALPHA_TOL = 1e-6
ALPHA_REASON = (
    "same inputs give the same cells; 1e-6 (alpha in [-1, 1]) admits the velocity tolerance of "
    "biaxial-short (1e-8 of max|v|) amplified by the ratio max|v| / (velocity difference across a "
    "cell) ~ 1e2"
)
W_REASON = "w relative to max|w|: as alpha"
LIST_REASON = (
    "cell lists (faces as particle cycles, valences, edges, vertices) must be identical: a contact "
    "differs only if positions differ by the overlap's round-off, which biaxial-short excludes"
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


def _cells(snap):
    return VoidCells().compute(snap)


def cell_signature(vc) -> tuple:
    """Faces as sorted tuples of particle cycles (canonical rotation), with valences and counts."""
    d = vc.dcel
    faces = []
    for f in range(d.n_faces):
        cyc = [int(v) for v in d.origin[d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]]]
        k = int(np.argmin(cyc))
        faces.append(tuple(cyc[k:] + cyc[:k]))
    return (d.n_faces, d.n_edges, d.n_vertices, tuple(sorted(faces)))


def _face_order(vc) -> np.ndarray:
    sig = []
    d = vc.dcel
    for f in range(d.n_faces):
        cyc = [int(v) for v in d.origin[d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]]]
        k = int(np.argmin(cyc))
        sig.append(tuple(cyc[k:] + cyc[:k]))
    return np.array(sorted(range(len(sig)), key=lambda i: sig[i]))


def compare_frames(nat, lig, steps, radii, dt) -> dict:
    """Per frame: same cell list?, max|d alpha|, max|d w|/max|w|, and both VoidCells."""
    out = {"steps": [], "same": [], "alpha": [], "w": [], "vc": [], "no_tessellation": []}
    for s in steps:
        try:
            a = _cells(snapshot(nat, s, radii, dt))
        except InputError as exc:  # no framework spanning the cell: must then hold on both sides
            a = str(exc)
        try:
            b = _cells(snapshot(lig, s, radii, dt))
        except InputError as exc:
            b = str(exc)
        if isinstance(a, str) or isinstance(b, str):
            same = a == b
            if same:
                out["no_tessellation"].append(int(s))
                continue
            a = b = None
        else:
            same = cell_signature(a) == cell_signature(b)
        da = dw = float("inf")
        if same:
            ia, ib = _face_order(a), _face_order(b)
            # NaN marks a cell whose alignment is undefined (zero gradient): it must be so on both sides
            da = defined_diff(a.alpha[ia], b.alpha[ib])
            wscale = defined_peak(b.w) or 1.0
            dw = defined_diff(a.w[ia], b.w[ib]) / wscale
        out["steps"].append(int(s))
        out["same"].append(same)
        out["alpha"].append(da)
        out["w"].append(dw)
        out["vc"].append((a, b))
    return out


def _records(label, cmp) -> list:
    ndiff = sum(not s for s in cmp["same"])
    if not cmp["same"]:
        return [compare(label, "cell_list", "frames with a tessellation", 0, -1, LIST_REASON)]
    return [
        compare(label, "cell_list", f"frames with different cell lists (of {len(cmp['same'])})", ndiff, 0, LIST_REASON),
        compare(label, "alpha", "max|d alpha| over cells and frames", peak(cmp["alpha"]), ALPHA_TOL, ALPHA_REASON),
        compare(label, "w", "max|d w|/max|w| over frames", peak(cmp["w"]), ALPHA_TOL, W_REASON),
    ]


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


@case("voidcell", "Void-cell measures (Kuhn) from native, LIGGGHTS and LAMMPS snapshots", order=40)
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
    res.declare("native-liggghts", LIST_REASON)
    res.declare("native-lammps", LIST_REASON)
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
    refs = {}
    for engine, stored_name, pair in (
        ("liggghts", "biaxial-short", "native-liggghts"),
        ("lammps", "biaxial-short-lammps", "native-lammps"),
    ):
        stored = stored_dir(stored_name)
        nat = run_native(p, _flavour(s, engine), ld, n, SHORT_CASE_DUMP_EVERY)
        ref = read_reference(_stored_log(stored), stored / "dump.atoms")
        refs[engine] = ref
        label = f"voidcell/stored-120/{engine}"
        recs = _evidence(label, nat, ref, frames, CODE[engine])
        cmp = compare_frames(nat, ref, _present(frames, nat, ref), p.radii, s.dt)
        recs += _records(label, cmp)
        res.records += in_pair(recs, pair)
        if cmp["no_tessellation"]:
            res.notes.append(
                f"stored-120 ({CODE[engine]}): steps {cmp['no_tessellation']} have no framework spanning "
                "the cell (the pruned graph does not wrap the torus) on either side: identical outcome, no "
                "cells to compare there."
            )
        if cmp["vc"] and cmp["vc"][-1][0] is not None and engine == "liggghts":
            a, b = cmp["vc"][-1]
            res.figures.append(
                (
                    _maps(ctx, [(f"step {cmp['steps'][-1]}", a, b)], "voidcell_stored120.png"),
                    "stored-120, last compared dump: cells shaded by alpha (white <= 0), native left, LIGGGHTS right",
                )
            )
    # the two codes' own snapshots: the same cells on the short horizon
    cmp = compare_frames(
        refs["liggghts"], refs["lammps"], _present(frames, refs["liggghts"], refs["lammps"]), p.radii, s.dt
    )
    ndiff = sum(not x for x in cmp["same"])

    res.records += in_pair(
        [
            info(
                "voidcell/stored-120/cross",
                "cell_list",
                f"frames with different cell lists, LIGGGHTS vs LAMMPS (of {len(cmp['same'])})",
                ndiff if cmp["same"] else float("nan"),
                CROSS_SHORT_REASON,
            )
        ],
        "liggghts-lammps",
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
    sides = {}
    if "liggghts" in r:
        sides["liggghts"] = (
            r["native"],
            r["liggghts"],
            r["ensemble"],
            r.get("expected_ensemble") or ensemble_labels(pk.n, ctx.suite == "full"),
        )
    else:
        res.notes.append("LIGGGHTS is absent: its Kuhn-assembly comparison is not made.")
    if "lammps" in r:
        lm = r["lammps"]
        sides["lammps"] = (
            lm["native"],
            lm["reference"],
            lm["ensemble"],
            lm.get("expected_ensemble") or lammps_ensemble_labels(pk.n, ctx.suite),
        )
    else:
        res.notes.append("LAMMPS is absent: its Kuhn-assembly comparison is not made.")

    def stats(tr):
        rows = []
        for k in steps:
            vc = _cells(snapshot(tr, k, pk.radii, dem.dt))
            rows.append(
                [vc.mean_alpha, vc.fraction_nonpositive_alpha, vc.n_faces, vc.n_edges, vc.n_vertices, vc.coordination]
            )
        return np.array(rows)

    st, bands, complete = {}, {}, {}
    pair = {"liggghts": "native-liggghts", "lammps": "native-lammps"}
    for engine, (nat, ref, ens, want) in sides.items():
        code = CODE[engine]
        lab = f"voidcell/kuhn-1002/{engine}"
        recs = _evidence(lab, nat, ref, frames, code)
        recs.append(evidence(lab, f"perturbed {code} runs (the statistics' band)", want, list(ens)))
        for name, tr in ens.items():
            recs += _evidence(f"{lab}/{name}", None, tr, frames, code)
        res.records += in_pair(recs, pair[engine])
        complete[engine] = all(x.passed for x in recs)
        if not complete[engine]:
            res.notes.append(
                f"<b>Incomplete evidence</b> for the Kuhn assembly ({code}; records above): no statistics "
                "are compared on what remains."
            )
            continue
        cmp = compare_frames(nat, ref, [k for k in steps if k <= SHORT_HORIZON], pk.radii, dem.dt)
        recs = _records(f"{lab}/first {SHORT_HORIZON} steps", cmp)
        st[f"native ({engine})"] = stats(nat)
        st[code] = stats(ref)
        pert = []
        for name, tr in ens.items():
            st[f"{code} {name}"] = stats(tr)
            pert.append(f"{code} {name}")
        bands[engine] = {}
        for col, qty in ((0, "mean_alpha"), (1, "fraction_alpha_le_0")):
            band = peak(np.abs(st[k][:, col] - st[code][:, col]) for k in pert)  # NaN stays NaN
            bands[engine][qty] = band
            diff = float(np.abs(st[f"native ({engine})"][:, col] - st[code][:, col]).max())
            recs.append(
                compare(
                    f"{lab}/full test",
                    qty,
                    f"max over {len(steps)} frames |native - {code}|",
                    diff,
                    band,
                    STATS_REASON.replace("LIGGGHTS", code),
                )
            )
        res.records += in_pair(recs, pair[engine])
    if len(bands) == 2:
        recs = []
        for col, qty in ((0, "mean_alpha"), (1, "fraction_alpha_le_0")):
            band = bands["liggghts"][qty] + bands["lammps"][qty]
            diff = float(np.abs(st["LIGGGHTS"][:, col] - st["LAMMPS"][:, col]).max())
            recs.append(
                compare(
                    "voidcell/kuhn-1002/cross",
                    qty,
                    f"max over {len(steps)} frames |LIGGGHTS - LAMMPS|",
                    diff,
                    band,
                    CROSS_STATS_REASON,
                )
            )
        res.records += in_pair(recs, "liggghts-lammps")
    if "liggghts" in sides and complete.get("liggghts"):
        nat, lig = sides["liggghts"][0], sides["liggghts"][1]
        strains = np.array([_strain(lig, k) for k in steps])
        rows = []
        pairs = []
        for target, tag in ((1e-4, "0.01%"), (1.6e-3, "0.16%")):
            k = int(np.argmin(np.abs(strains - target)))
            vn = _cells(snapshot(nat, steps[k], pk.radii, dem.dt))
            vl = _cells(snapshot(lig, steps[k], pk.radii, dem.dt))
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
