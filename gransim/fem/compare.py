"""Two or more slope results side by side, read from their ``slope.h5`` files.

Typically the Taylor RVE (Meier, Steinmann & Kuhl 2007, "Towards completeness: a multiscale
approach of confined particulate systems", eq 1: affine, an upper bound) against the relaxed RVE
(:class:`gransim.rve.RelaxedMaterial`, docs/relaxed.md) on the same mesh and load protocol:

* :func:`read_slope`: one ``slope.h5`` (docs/schema_fem.md) as a :class:`SlopeResult`;
* :func:`newton_orders` / :func:`final_order`: observed orders of Newton's relative energy norm
  p_k = log(e_k+1 / e_k) / log(e_k / e_k-1) over the norms above round-off;
* :func:`stress_difference`: the per-Gauss-point Cauchy stress difference of two results at a
  common converged load step, d_g = |sigma_b,g - sigma_a,g|_F / max_h |sigma_a,h|_F
  (0 everywhere when both are the same result);
* :func:`compare_slopes`: the figures and the table: ``compare_load_settlement.png`` (every
  curve in one figure), ``compare_map.png`` (d over the Gauss points at the last common step,
  the points that differ most marked, and their RVEs drawn: the contact network at the Taylor
  centres x = F X and at the relaxed centres x = F X + w), ``compare.md`` (status and limit load
  of every result, the energy-norm sequences with their observed orders).

The relaxed fluctuation w of a marked Gauss point is not in ``slope.h5``: it is rebuilt by
replaying that point's history (the relaxed reference RVE at F = 1 that every slope run commits
first, then the run's checkpoint: every committed attempt's FE iterates, then the commit, exact;
without the checkpoint, the F of each converged step from ``slope.h5``) through
a fresh one-point :class:`gransim.rve.RelaxedMaterial` with the run's ``relaxed_start``, and the
replayed Cauchy stress is checked against the stored one (reported in ``compare.md``).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..contacts import find_neighbours
from ..errors import InputError, ResultFileError
from ..io import atomic_path, atomic_text, load_packing, open_result
from .checkpoint import KIND, commit_sequences, step_path
from .materials import RVEMaterial
from .run import _rve_700_paths, default_rve_packing, packings_fingerprint
from .slope import NORMAL_STIFFNESS

#: energy norms at or below this are round-off: no order is taken from them. The FE residual of the
#: Taylor slope reaches its round-off at ~1e-7 N/m of a ~5e6 N/m load increment, and e ~ (r / r_1)^2,
#: so the energy norm's round-off is ~4e-28; this floor stays four decades above it
ROUNDOFF_ENERGY = 1e-24
#: the observed order a consistent tangent reaches in the last iterations (a theorem: 2; an
#: inconsistent tangent converges linearly, order 1): the best of a step's last two orders must reach it
QUADRATIC = 1.8


@dataclass
class StepData:
    """One converged (or partial) load step of a slope result (arrays as docs/schema_fem.md)."""

    name: str
    step: int
    load: np.ndarray
    cuts: int
    F: np.ndarray
    cauchy: np.ndarray
    n_contacts: np.ndarray
    energy_norms: np.ndarray
    u: np.ndarray


@dataclass
class SlopeResult:
    """A ``slope.h5`` read back: provenance parameters, status, mesh, load-settlement, steps."""

    path: Path
    parameters: dict
    completed: bool
    message: str
    timing: dict
    nodes: np.ndarray
    elements: np.ndarray
    gauss_points: np.ndarray
    load_settlement: np.ndarray
    steps: dict = field(default_factory=dict)  # step number -> StepData (converged steps)
    partial: StepData | None = None

    @property
    def label(self) -> str:
        """``<rve> <protocol>`` from the provenance, e.g. ``relaxed service``."""
        p = self.parameters
        return f"{p.get('rve', '?')} {p.get('protocol', '?')}"

    @property
    def last_load(self) -> np.ndarray:
        """(dead load, footing) factors of the last converged state (the partial one at a limit)."""
        if self.partial is not None:
            return self.partial.load
        if self.steps:
            return self.steps[max(self.steps)].load
        return np.zeros(2)


def _attr(v):
    return v.decode() if isinstance(v, bytes) else v


def read_slope(path) -> SlopeResult:
    """Read a ``gransim slope`` result file (kind ``fem-slope``); InputError for another file."""
    path = Path(path)
    try:
        f = open_result(path, kind="fem-slope")
    except ResultFileError as exc:
        raise InputError(f"slope result: {exc}") from None
    with f:
        params = json.loads(_attr(f.attrs.get("parameters", "{}")) or "{}")
        res = SlopeResult(
            path=path,
            parameters=params,
            completed=bool(f.attrs.get("completed", False)),
            message=str(_attr(f.attrs.get("message", ""))),
            timing=json.loads(_attr(f.attrs.get("timing", "{}")) or "{}"),
            nodes=f["mesh/nodes"][()],
            elements=f["mesh/elements"][()],
            gauss_points=f["mesh/gauss_points"][()],
            load_settlement=f["load_settlement"][()],
        )
        for name in sorted(f["steps"].keys()) if "steps" in f else []:
            g = f[f"steps/{name}"]
            st = StepData(
                name=name,
                step=int(name.split("_")[0]),
                load=np.asarray(g.attrs["load"], dtype=float),
                cuts=int(g.attrs["cuts"]),
                F=g["F"][()],
                cauchy=g["cauchy"][()],
                n_contacts=g["n_contacts"][()],
                energy_norms=g["energy_norms"][()],
                u=g["u"][()],
            )
            if name.endswith("_partial"):
                res.partial = st
            else:
                res.steps[st.step] = st
    return res


def newton_orders(energy_norms, floor: float = ROUNDOFF_ENERGY) -> np.ndarray:
    """Observed orders p_k = log(e_k+1 / e_k) / log(e_k / e_k-1) over the energy norms above
    ``floor`` (round-off); empty when fewer than three are above it."""
    e = np.asarray(energy_norms, dtype=float)
    e = e[e > floor]
    if e.size < 3:
        return np.array([])
    le = np.log(e)
    return (le[2:] - le[1:-1]) / (le[1:-1] - le[:-2])


def final_order(energy_norms, floor: float = ROUNDOFF_ENERGY) -> float:
    """The best of the last two observed orders over the energy norms above round-off: the rate of
    the final iterations. nan (not judged) when fewer than four norms are above round-off: the one
    order of (1, e_2, e_3) mixes in the first iteration, which starts outside the quadratic range
    (the Taylor slope's steps that converge in three iterations above round-off show 1.0-1.4 there
    and order 2.4-3 in the next iteration, already at round-off)."""
    o = newton_orders(energy_norms, floor)
    return float(o[-2:].max()) if o.size >= 2 else float("nan")


def common_step(a: SlopeResult, b: SlopeResult) -> int:
    """The last converged load step both results hold at the same load (InputError: none, or another mesh)."""
    if a.gauss_points.shape != b.gauss_points.shape or not np.allclose(a.gauss_points, b.gauss_points):
        raise InputError(
            f"{a.path} and {b.path}: different meshes ({len(a.gauss_points)} and {len(b.gauss_points)} "
            "Gauss points); a stress map needs the same mesh"
        )
    both = [k for k in a.steps if k in b.steps and np.allclose(a.steps[k].load, b.steps[k].load)]
    if not both:
        raise InputError(f"{a.path} and {b.path}: no converged load step at the same load in both")
    return max(both)


def stress_difference(a: SlopeResult, b: SlopeResult, step: int) -> np.ndarray:
    """d_g = |sigma_b,g - sigma_a,g|_F / max_h |sigma_a,h|_F (G,) at load ``step`` (Cauchy, Pa / Pa)."""
    sa, sb = a.steps[step].cauchy, b.steps[step].cauchy
    scale = float(np.linalg.norm(sa.reshape(len(sa), -1), axis=1).max())
    d = np.linalg.norm((sb - sa).reshape(len(sa), -1), axis=1)
    return d / scale if scale > 0 else d


def most_different(d: np.ndarray, n: int = 4) -> list[int]:
    """The ``n`` Gauss points with the largest d (largest first; ties by index), none where d = 0."""
    order = np.lexsort((np.arange(len(d)), -d))
    return [int(g) for g in order[:n] if d[g] > 0]


# -- the RVEs of a Gauss point --------------------------------------------------------------------


def committed_history(result: SlopeResult, step: int, g: int) -> tuple[list, str]:
    """The history of Gauss point ``g`` up to and including load ``step``: per commit the F (n, 2, 2)
    evaluated in its attempt (the committed F last), and where they come from: the run's checkpoint
    (``<dir>/checkpoint/step_NNN.h5``: every committed sub-increment with its FE iterates,
    :func:`gransim.fem.checkpoint.commit_sequences`) when present, otherwise the converged steps of
    ``slope.h5`` (their F alone: exact for the committed start when no step up to ``step`` was cut,
    to the start-independence of the relaxation otherwise)."""
    ck = result.path.parent / "checkpoint"
    if all(step_path(ck, k).exists() for k in range(1, step + 1)):
        seqs = []
        for k in range(1, step + 1):
            with open_result(step_path(ck, k), kind=KIND) as f:
                seqs.extend(np.asarray(q[:, g], dtype=float) for q in commit_sequences(f))
        return seqs, "checkpoint commits"
    cut = [k for k in range(1, step + 1) if result.steps[k].cuts]
    note = "converged steps of slope.h5" + (f" (steps {cut} were cut: approximate)" if cut else "")
    return [np.array(result.steps[k].F[g])[None] for k in range(1, step + 1)], note


def rve_packings(result: SlopeResult, packing=None, packing_dir="results/packings") -> list:
    """The reference packings of ``result``'s RVEs: ``packing`` when given, else the standard
    700-disk packings of its assignment in ``packing_dir``; checked against the run's SHA-256
    fingerprint (InputError when they are not the run's)."""
    p = result.parameters
    if packing is not None:
        packs = [load_packing(packing) if isinstance(packing, (str, Path)) else packing]
    elif p.get("assignment") == "five":
        packs = [load_packing(q) for q in _rve_700_paths(packing_dir).values()]
    else:
        packs = [default_rve_packing(packing_dir)]
    fp = packings_fingerprint(packs)
    if p.get("packings") and fp != p["packings"]:
        raise InputError(
            f"{result.path}: its RVE packings have fingerprint {p['packings']}, the packings given have "
            f"{fp}; pass the run's packing (--packing) or its --packing-dir"
        )
    return packs


def rve_state(result: SlopeResult, step: int, g: int, packings: list) -> dict:
    """The RVE at Gauss point ``g`` in load ``step``: its packing, F, fluctuation w (N, 2) (zero for
    the Taylor RVE; for the relaxed one replayed from the committed F, :func:`committed_history`),
    and the replayed Cauchy stress (Pa) beside the stored one."""
    from ..rve import RelaxedMaterial, TaylorMaterial  # noqa: PLC0415 - start-up: numba

    p = result.parameters
    kn = float(p.get("normal_stiffness", NORMAL_STIFFNESS))
    packing = packings[g % len(packings)] if p.get("assignment") == "five" else packings[0]
    F = result.steps[step].F[g]
    source = "affine (Taylor)"
    if p.get("rve") == "relaxed":
        # the run's start rule (runs before the parameter existed started from the committed state)
        rve = RelaxedMaterial(packing, kn, warm_start=p.get("relaxed_start", "committed"))
        seqs, source = committed_history(result, step, g)
        # the run's first commit: its RVEs relaxed at F = 1 before the first load step (the relaxed
        # reference RVE, gransim.fem.solver.Problem), the start of the first step's evaluations
        rve.evaluate(np.eye(2)[None])
        rve.commit()
        for seq in seqs:
            for Fc in seq:
                rve.evaluate(Fc[None])
            rve.commit()
        w = rve.committed_fluctuation(0)
        replay = RVEMaterial(rve).evaluate(F[None])
        rve.revert()
    else:
        rve = TaylorMaterial(packing, kn)
        w = np.zeros_like(packing.positions)
        replay = RVEMaterial(rve).evaluate(F[None])
    stored = result.steps[step].cauchy[g]
    err = float(np.abs(replay.cauchy[0] - stored).max() / max(np.abs(stored).max(), 1e-300))
    return {"packing": packing, "F": F, "w": w, "kn": kn, "source": source, "replay_error": err}


def network(state: dict):
    """Contact network of an :func:`rve_state`: (segments (M, 2, 2) m, forces (M,) N/m, cell (2, 2)),
    centres x = F X + w, forces f = E_n eps (Meier et al. eq 5)."""
    p = state["packing"].deformed(state["F"])
    pos = p.positions + state["w"]
    nl = find_neighbours(pos, p.radii, p.cell, 0.0)
    eps = p.radii[nl.i] + p.radii[nl.j] - np.linalg.norm(nl.branch, axis=1)
    on = eps > 0
    xi = pos[nl.i[on]]
    return np.stack([xi, xi + nl.branch[on]], axis=1), state["kn"] * eps[on], p.cell


# -- figures and table ----------------------------------------------------------------------------


def _plt():
    import matplotlib  # noqa: PLC0415 - start-up: matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415 - start-up: matplotlib

    return plt


def plot_curves(path, results: list[SlopeResult]) -> Path:
    """Every result's footing force against the settlement of the footing centre under the footing
    load (from the dead-load state on), in one figure."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 5))
    for r in results:
        d = r.load_settlement[1:]
        if len(d) == 0:
            ax.plot([], [], "x", label=r.label + " (no converged load step)")
            continue
        status = "" if r.completed else f" (stops at {r.last_load[1]:.3f})"
        ax.plot(d[:, 1] - d[0, 1], -d[:, 0], "o-", ms=3, label=r.label + status)
    ax.set_xlabel("settlement of the footing centre under the footing load (m)")
    ax.set_ylabel("footing force (N per m)")
    ax.set_title("load-settlement: Taylor and relaxed RVE", fontsize=10)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=100, format="png")
    plt.close(fig)
    return Path(path)


def plot_map(path, a: SlopeResult, b: SlopeResult, step: int, d: np.ndarray, points, states=None) -> Path:
    """d over the Gauss points (reference positions) with ``points`` numbered, and under it the
    RVE of each at both results' states (``states``: {(label, g): rve_state}; one force scale)."""
    from matplotlib.collections import LineCollection, PolyCollection  # noqa: PLC0415 - start-up: matplotlib

    plt = _plt()
    n = len(points) if states else 0
    fig = plt.figure(figsize=(4 * max(n, 3), 5 + (6.4 if n else 0)))
    top = 5 / (5 + (6.4 if n else 0))
    ax = fig.add_axes([0.05, 1 - top + 0.06 * top, 0.9, 0.86 * top])
    ax.add_collection(PolyCollection(a.nodes[a.elements], facecolors="none", edgecolors="0.8", linewidths=0.4))
    sc = ax.scatter(a.gauss_points[:, 0], a.gauss_points[:, 1], c=d, s=14, cmap="viridis")
    fig.colorbar(sc, ax=ax, label="|sigma_b - sigma_a| / max |sigma_a|", shrink=0.8)
    for k, g in enumerate(points):
        x, y = a.gauss_points[g]
        ax.plot(x, y, "o", mfc="none", mec="red", ms=12, mew=1.5)
        ax.annotate(str(k + 1), (x, y), xytext=(6, 6), textcoords="offset points", color="red", weight="bold")
    ax.set_aspect("equal")
    ax.autoscale()
    ax.set_title(
        f"Cauchy stress difference, a = {a.label}, b = {b.label}, load step {step} "
        f"(footing {a.steps[step].load[1]:.0%}); max {d.max():.3g}",
        fontsize=10,
    )
    if n:
        nets = {key: network(s) for key, s in states.items()}
        fmax = max([float(v[1].max()) for v in nets.values() if len(v[1])] or [1.0])
        h = (1 - top) / 2
        for k, g in enumerate(points):
            for row, r in enumerate((a, b)):
                seg, f, cell = nets[(r.label, g)]
                s = states[(r.label, g)]
                ax2 = fig.add_axes([0.02 + k / n, h * (1 - row) + 0.01, 0.96 / n - 0.02, h - 0.04])
                ax2.set_xticks([])
                ax2.set_yticks([])
                ax2.add_collection(LineCollection(seg, linewidths=3.0 * f / fmax, colors="k"))
                cn = np.array([[0, 0], cell[:, 0], cell[:, 0] + cell[:, 1], cell[:, 1], [0, 0]])
                ax2.plot(cn[:, 0], cn[:, 1], "b-", lw=0.5)
                ax2.set_aspect("equal")
                ax2.autoscale()
                sig = r.steps[step].cauchy[g]
                ax2.set_title(
                    f"{k + 1}: g {g} ({a.gauss_points[g, 0]:.1f}, {a.gauss_points[g, 1]:.1f}) m, {r.label}\n"
                    f"det F {np.linalg.det(s['F']):.4f}, {len(f)} contacts\n"
                    f"sigma {sig[0, 0]:.3g} {sig[1, 1]:.3g} {sig[0, 1]:.3g} Pa (xx yy xy)",
                    fontsize=7,
                )
        fig.text(
            0.5,
            0.002,
            f"RVEs at the Gauss point's F (true scale), top: {a.label}, bottom: {b.label}; branch width "
            f"3 pt x f / {fmax:.3g} N/m, one scale for all",
            ha="center",
            fontsize=9,
        )
    with atomic_path(path, suffix=".png") as tmp:
        fig.savefig(tmp, dpi=70, format="png")
    plt.close(fig)
    return Path(path)


def _fmt_orders(o) -> str:
    return ", ".join(f"{v:.2f}" for v in o) if len(o) else "-"


def newton_table(r: SlopeResult) -> str:
    """Markdown: per converged step its load, cuts, energy norms and observed orders (above round-off)."""
    lines = [
        f"Newton, {r.label} (relative energy norm per iteration; orders over the norms above {ROUNDOFF_ENERGY:g}):",
        "",
        "| step | load (dead, footing) | cuts | energy norms | observed orders |",
        "|---|---|---|---|---|",
    ]
    steps = [r.steps[k] for k in sorted(r.steps)] + ([r.partial] if r.partial is not None else [])
    for s in steps:
        e = " ".join(f"{v:.1e}" for v in s.energy_norms)
        lines.append(
            f"| {s.name} | ({s.load[0]:.3g}, {s.load[1]:.4g}) | {s.cuts} | {e} | "
            f"{_fmt_orders(newton_orders(s.energy_norms))} |"
        )
    return "\n".join(lines)


def summary_row(r: SlopeResult) -> dict:
    """Status, limit (last converged dead load and footing fractions, footing force), iterations and
    the worst final order (:func:`final_order`) over the judged steps."""
    orders = [final_order(s.energy_norms) for s in r.steps.values()]
    judged = [o for o in orders if np.isfinite(o)]
    force = float(r.parameters.get("footing_force", float("nan")))
    return {
        "label": r.label,
        "completed": r.completed,
        "dead": float(r.last_load[0]),
        "fraction": float(r.last_load[1]),
        "force": float(r.last_load[1]) * force,
        "iterations": int(sum(len(s.energy_norms) for s in r.steps.values())),
        "min_final_order": min(judged) if judged else float("nan"),
        "steps_judged": len(judged),
        "steps": len(r.steps),
        "wall_material_s": r.timing.get("material_s", float("nan")),
    }


def compare_slopes(paths, out, n_points: int = 4, packing=None, packing_dir="results/packings") -> dict:
    """Compare slope results (``paths``: two or more ``slope.h5``; the map takes the first two, a
    and b, on the same mesh) into ``out``: ``compare_load_settlement.png``, ``compare_map.png``,
    ``compare.md``. ``packing`` / ``packing_dir``: the RVE packings of the runs (for the RVE
    pictures; checked against the runs' fingerprints; when they cannot be found the map is drawn
    without RVEs and ``compare.md`` says why).

    Returns {"results", "rows" (:func:`summary_row`), "step", "difference" (G,), "points",
    "replay_errors" {(label, g): relative}, "files" {name: Path}, "markdown"}.
    """
    if len(paths) < 2:
        raise InputError(f"slope-compare: expected at least two slope.h5 files, got {len(paths)}")
    results = [read_slope(p) for p in paths]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = {"load_settlement": plot_curves(out / "compare_load_settlement.png", results)}
    a, b = results[0], results[1]
    states, errors, rve_note, points, d, step = {}, {}, "", [], None, None
    try:
        step = common_step(a, b)
    except InputError as exc:  # e.g. one run has no converged step: curves and table only
        rve_note = f"No stress map: {exc}."
    if step is not None:
        d = stress_difference(a, b, step)
        points = most_different(d, n_points)
        try:
            packs = {r.label: rve_packings(r, packing, packing_dir) for r in (a, b)}
            for g in points:
                for r in (a, b):
                    s = rve_state(r, step, g, packs[r.label])
                    states[(r.label, g)] = s
                    errors[(r.label, g)] = (s["replay_error"], s["source"])
        except (InputError, ResultFileError, OSError) as exc:
            states, rve_note = None, f"RVEs not drawn: {exc}"
        files["map"] = plot_map(out / "compare_map.png", a, b, step, d, points, states)

    rows = [summary_row(r) for r in results]
    md = [
        "# Slope: Taylor vs relaxed RVE",
        "",
        "| result | status | last converged load (dead, footing) | footing force (N/m) | Newton iterations | "
        "steps judged | min over steps of the final order (best of the last two) |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        md.append(
            f"| {row['label']} | {'completed' if row['completed'] else 'limit'} | "
            f"({row['dead']:.4g}, {row['fraction']:.4f}) | "
            f"{row['force']:.4g} | {row['iterations']} | {row['steps_judged']} of {row['steps']} | "
            f"{row['min_final_order']:.2f} |"
        )
    if d is not None:
        md += [
            "",
            f"Stress map: a = {a.label} ({a.path}), b = {b.label} ({b.path}), load step {step}; "
            f"d = |sigma_b - sigma_a|_F / max |sigma_a|_F: max {d.max():.3g}, mean {d.mean():.3g}.",
            "",
            "| mark | Gauss point | position (m) | d | sigma_a (Pa) xx yy xy | sigma_b (Pa) xx yy xy |",
            "|---|---|---|---|---|---|",
        ]
    for k, g in enumerate(points):
        sa, sb = a.steps[step].cauchy[g], b.steps[step].cauchy[g]
        md.append(
            f"| {k + 1} | {g} | ({a.gauss_points[g, 0]:.2f}, {a.gauss_points[g, 1]:.2f}) | {d[g]:.3g} | "
            f"{sa[0, 0]:.4g} {sa[1, 1]:.4g} {sa[0, 1]:.4g} | {sb[0, 0]:.4g} {sb[1, 1]:.4g} {sb[0, 1]:.4g} |"
        )
    if errors:
        md += [
            "",
            "RVEs drawn: the stress of each replayed RVE against the stored one (relative max): "
            + "; ".join(f"{lab} g {g}: {e:.1e} ({src})" for (lab, g), (e, src) in errors.items()),
        ]
    if rve_note:
        md += ["", rve_note]
    for r in results:
        md += ["", newton_table(r)]
    text = "\n".join(md) + "\n"
    atomic_text(out / "compare.md", text)
    files["markdown"] = out / "compare.md"
    return {
        "results": results,
        "rows": rows,
        "step": step,
        "difference": d,
        "points": points,
        "replay_errors": {k: v[0] for k, v in errors.items()},
        "files": files,
        "markdown": text,
    }


__all__ = [
    "QUADRATIC",
    "ROUNDOFF_ENERGY",
    "SlopeResult",
    "StepData",
    "common_step",
    "compare_slopes",
    "final_order",
    "most_different",
    "newton_orders",
    "newton_table",
    "read_slope",
    "rve_state",
    "stress_difference",
    "summary_row",
]
