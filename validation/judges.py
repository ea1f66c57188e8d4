"""The shared judges of the validation matrix: one function per criterion, each turning runs into records.

A case declares its runs and the comparisons between them (:mod:`validation.matrix`); these judges
compare them. Every judge first accounts for its evidence (every expected step, frame and run on
each side: :func:`validation.dem_compare.trajectory_evidence`, :func:`validation.core.evidence`),
then takes the differences over what the sides hold; a comparison over nothing is NaN, and a NaN
or inf value fails (:mod:`reference_runs.judge`). So a comparison on incomplete evidence fails.

Criteria:

* :func:`analytic`: runs against closed forms or bounds (:class:`Bound`: an error at most its
  tolerance, a rate at least its bound, or a figure for the reader), the worst over the runs.
* :func:`final_state`: two runs' ends (positions modulo the box and box), a long replay's only evidence.
* :func:`same_states`: two runs' states (an RVE's saved scenes) equal in every field, bit for bit.
* :func:`step_for_step`: two runs of one deck at every step and dump, at the round-off bounds of
  :class:`StepBounds` (native in a code's arithmetic against that code).
* :func:`frame_for_frame`: runs seen at their frames only (impacts), every frame present on each,
  and two runs' per-particle columns at the bounds of :class:`FrameBound`.
* :func:`explained_measures`: two codes' measured answers to the same closed-form checks; their
  difference must equal the native flavours' (the analytic form of :func:`explained_difference`).
* :func:`explained_difference`: two codes that differ physically on the same deck; their
  difference must equal the difference of the two native flavours (each equal to its code), and
  the raw difference is shown with the words of :func:`validation.codes.why_they_differ`.
* :func:`envelope`: a long run against a code's own chaos envelope (:class:`EnvelopeRule`, the
  one criterion of biaxial-full, biaxial-laws and simple-shear).
* :func:`band`: a curve (or a statistic along it) within a multiple of the band its perturbed runs
  span around the reference.
* :func:`chaos_envelope`: a run against a reference and the reference's perturbed runs, all made
  by the case (evidence of each, then :func:`envelope`).
* :func:`ensemble_envelope`, :func:`ensemble_cross`: a long loading, native against a code's
  :class:`Ensemble` (evidence of every run, then :func:`envelope` and :func:`band`), and two codes'
  references within the sum of their bands.
* :func:`statistics_band`, :func:`statistics_cross`: statistics of the snapshots (void cells) of a run
  within a code's band, and of two codes' references within the sum of their bands.
* :func:`cell_lists`: Kuhn's void cells of two runs' snapshots, frame by frame: the same cell lists,
  alpha and w at round-off.
* :func:`taylor_stress`, :func:`taylor_contacts`, :func:`taylor_cross`: Taylor states (no dynamics)
  of gransim and of a code, and of two codes, at round-off: the stress of every state, the contacts
  two-sided.
* :func:`equilibria`: two states at rest of one energy (a DEM run at rest, a Newton minimiser):
  their stresses within what their residual forces leave.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gransim.errors import InputError
from gransim.voidcell import VoidCells
from reference_runs.judge import JudgeError, defined_diff, defined_peak, peak
from reference_runs.store import taylor_case
from reference_runs.yade.compare import (
    CONTACT_REASON,
    STRESS_REASON,
    STRESS_RTOL,
    STRUCTURE_REASON,
    TANGENT_REASON,
    TANGENT_RTOL,
    compare_yade_taylor,
)

from .codes import why_they_differ
from .core import Record, compare, evidence, info, stored_job_record
from .dem_compare import (
    expected_frames,
    expected_steps,
    frame_differences,
    position_difference,
    reduce_sheared,
    sheared_cell,
    sheared_frame_differences,
    stress_differences,
    trajectory_evidence,
)
from .taylor_compare import PATH_NAMES, contact_records, expected_series, series_evidence


def _max(a) -> float:
    """Largest entry, NaN for an empty array or any NaN (a comparison over nothing fails)."""
    return peak([a])


# ====================================================================== analytic
#: how :func:`analytic` judges a quantity: an error within its tolerance, a figure at least a bound
#: (a convergence rate), or a figure shown for the reader
ANALYTIC_RULES = ("at_most", "at_least", "info")


@dataclass(frozen=True)
class Bound:
    """How :func:`analytic` judges one quantity.

    tolerance : the bound on the value (NaN for ``info``).
    reason : why the bound is what it is.
    rule : ``"at_most"``: the value is an error against a closed form (or the excess over a bound)
        and must not exceed ``tolerance``; ``"at_least"``: a figure that must reach ``tolerance`` (an
        observed convergence order); ``"info"``: a figure for the reader, no verdict.
    """

    tolerance: float
    reason: str
    rule: str = "at_most"

    def __post_init__(self):
        if self.rule not in ANALYTIC_RULES:
            raise ValueError(f"Bound.rule: expected one of {ANALYTIC_RULES}, got {self.rule!r}")


def _worst(vals: list, rule: str) -> float:
    """The worst of the runs' values: NaN or inf first, then the largest (``at_most``) or the
    smallest (``at_least``); ``info``: the first run's."""
    if not vals:
        return math.nan
    bad = [v for v in vals if not math.isfinite(v)]
    if bad:
        return bad[0]
    if rule == "info":
        return vals[0]
    return max(vals) if rule == "at_most" else min(vals)


def analytic(
    label: str, *runs, expected, values, bound, sides, names=None, metric=None, figure=None
) -> tuple[list, dict]:
    """Runs against closed forms or bounds, each run answering the same checks.

    expected : the ``(item, quantity)`` pairs every run must answer (item: an impact, a load
        protocol; the records' label is ``<label>/<item>``, or ``<label>`` for item ``""``).
    values : ``values(run) -> {(item, quantity): value}``: the run's error against the closed form
        (or its excess over a bound), or the figure a bound is set on (an observed order).
    bound : ``{quantity: Bound}``, or ``bound(item, quantity) -> Bound``.
    names : the runs' names in the metrics (default: ``sides`` when it names every run).
    metric : optional ``metric(item, quantity, {name: value}) -> str`` (what was computed, with the
        closed form and each run's figure); default: the quantity and each run's value.
    figure : optional ``figure(item, quantity, {name: value}) -> float``: the record's value made
        from the runs' values together (an observed order log2(e(dt)/e(dt/2)) from the errors of a
        run at dt and one at dt/2); default: the worst.

    One record per expected pair, its value the worst over the runs (the largest error, the smallest
    order; NaN or inf first), or ``figure`` of them. A pair that a run does not answer is NaN for it: the record fails,
    its metric naming the run (a comparison over missing evidence never passes). Returns (records,
    summary ``{(item, quantity): {name: value}}``)."""
    if names is None:
        names = tuple(sides) if len(sides) == len(runs) else tuple(f"run {i}" for i in range(len(runs)))
    if len(names) != len(runs):
        raise ValueError(f"analytic {label}: {len(names)} names for {len(runs)} runs")
    got = [values(r) for r in runs]
    recs, summary = [], {}
    for item, quantity in expected:
        b = bound[quantity] if isinstance(bound, dict) else bound(item, quantity)
        vals = {n: float(g.get((item, quantity), math.nan)) for n, g in zip(names, got)}
        missing = [n for n, g in zip(names, got) if (item, quantity) not in g]
        summary[(item, quantity)] = vals
        lab = f"{label}/{item}" if item else label
        text = (
            metric(item, quantity, vals)
            if metric
            else f"{quantity} ({', '.join(f'{n} {v:.6g}' for n, v in vals.items())})"
        )
        if missing:
            text += f" [no answer from {', '.join(missing)}]"
        v = figure(item, quantity, vals) if figure else _worst(list(vals.values()), b.rule)
        if b.rule == "info":
            recs.append(info(lab, quantity, text, v, b.reason))
        elif b.rule == "at_most":
            recs.append(compare(lab, quantity, text, v, b.tolerance, b.reason))
        else:
            ok = math.isfinite(v) and math.isfinite(b.tolerance) and v >= b.tolerance
            recs.append(Record(lab, quantity, f"{text} (at least {b.tolerance:g})", v, b.tolerance, ok, b.reason))
    return recs, summary


# ====================================================================== same states
def differing(a, b, fields) -> list:
    """The fields of two states that differ (shape or any bit; NaN equal to NaN)."""
    bad = []
    for f in fields:
        x, y = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        if x.shape != y.shape or not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            bad.append(f)
    return bad


def same_states(
    label: str,
    a,
    b,
    *,
    fields,
    quantity: str,
    metric: str,
    reason: str,
    sides,
    what: str = "states",
    expected: int | None = None,
) -> tuple[list, dict]:
    """Two runs' states (a sequence of states each, or one state each) equal bit for bit in every
    field of ``fields`` (attributes; NaN equal to NaN), state by state over the states both hold.

    ``metric`` says what is compared; ``what`` names the states (``calls``); ``expected``: how many states each run
    must hold (default: as many as ``a``). Value: the number of (state, field) pairs that differ,
    the first named in the metric; NaN when the runs hold no common state (nothing compared fails),
    and a failing evidence record when either holds fewer than expected. Returns (records,
    summary: ``{"differing": [(state, [fields])]}``)."""
    one = not isinstance(a, list | tuple)
    sa, sb = ([a], [b]) if one else (list(a), list(b))
    n = len(sa) if expected is None else int(expected)
    recs = [] if one else [evidence(label, f"{side} {what}", n, min(len(s), n)) for side, s in zip(sides, (sa, sb))]
    both = min(len(sa), len(sb), n)
    bad = [(k, d) for k in range(both) if (d := differing(sa[k], sb[k], fields))]
    first = f"; first: {what} {bad[0][0]}: {', '.join(bad[0][1][:4])}" if bad and not one else ""
    if bad and one:
        first = f": {', '.join(bad[0][1][:6])}"
    value = float(sum(len(d) for _, d in bad)) if both else math.nan
    recs.append(compare(label, quantity, f"{metric}{first}", value, 0.0, reason))
    return recs, {"differing": bad}


# ====================================================================== final state
def final_state(
    label: str,
    a,
    b,
    *,
    step: int,
    d50: float,
    position_tol: float,
    box_tol: float,
    reason: str,
    sides,
    evidence_of=(None, None),
    position_metric: str = "max|dx|/D50 modulo the box",
    box_metric: str = "max|dL|/D50",
) -> tuple[list, dict]:
    """Two runs' states at their last step ``step``: positions modulo the box and box lengths, over
    D50 (a long run replayed, where only the end is kept: any difference in the last bit would have
    grown by chaos, so the ends must agree to their rounding).

    ``a``, ``b``: :class:`validation.dem_compare.Trajectory` (a saved packing: one frame, its cell as
    lengths). ``evidence_of``: per side, ``(expected series steps, expected frames)`` checked by
    :func:`validation.dem_compare.trajectory_evidence`, or None for a side that is a saved state
    (then only its frame at ``step`` is required). On incomplete evidence no verdict is taken (the
    failing evidence records stand alone). Returns (records, summary: x, box)."""
    recs = []
    for who, tr, ev in zip(sides, (a, b), evidence_of):
        if ev is None:
            have = [step] if step in tr.frames and len(tr.frames[step].get("x", ())) else []
            recs.append(evidence(label, f"{who} state at step {step}", [step], have))
        else:
            recs += trajectory_evidence(label, who, tr, *ev)
    if not all(r.passed for r in recs):
        return recs, {"x": math.nan, "box": math.nan}
    xa, xb = np.asarray(a.frames[step]["x"]), np.asarray(b.frames[step]["x"])
    La, Lb = np.asarray(a.lengths[-1], float), np.asarray(b.lengths[-1], float)
    dx = position_difference(xa, xb, Lb) / d50 if xa.shape == xb.shape else math.nan
    dl = float(np.abs(La - Lb).max()) / d50
    recs += [
        compare(label, "position", position_metric, dx, position_tol, reason),
        compare(label, "box", box_metric, dl, box_tol, reason),
    ]
    return recs, {"x": dx, "box": dl}


# ====================================================================== step for step
@dataclass(frozen=True)
class StepBounds:
    """Tolerances of a step-for-step comparison and why they are what they are.

    position : of D50, for positions (modulo the cell) and box lengths.
    relative : for velocities, spins, forces, torques (max |a - b| / max |b| per frame) and the
        stress (per step, relative to the largest component).
    cell : ``"orthogonal"`` (box lengths (T, 2), positions modulo the box) or ``"sheared"``
        (box (lx, ly, xy), positions modulo the sheared cell).
    """

    position: float
    relative: float
    position_reason: str
    velocity_reason: str
    force_reason: str
    stress_reason: str
    box_reason: str
    cell: str = "orthogonal"

    def __post_init__(self):
        if self.cell not in ("orthogonal", "sheared"):
            raise ValueError(f"StepBounds.cell: expected 'orthogonal' or 'sheared', got {self.cell!r}")


def _frame_diffs(a, b, d50: float, frames, cell: str) -> dict:
    if cell == "sheared":
        return sheared_frame_differences(a, b, d50, frames)
    return frame_differences(a, b, d50, steps=frames)


def step_for_step(
    label: str,
    a,
    b,
    *,
    d50: float,
    nsteps: int,
    dump_every: int,
    bounds: StepBounds,
    thermo_every: int = 1,
    sides=("native", "LIGGGHTS"),
) -> tuple[list, dict]:
    """Run ``a`` against run ``b`` (the reference) step for step: evidence of both sides, then
    positions, velocities, spins, per-particle forces and torques at every dump, the stress and
    the box at every series step.

    The expected evidence is the run's: every ``thermo_every``-th step of ``nsteps`` in the series
    and every ``dump_every``-th step as a frame, on both sides (``sides`` names them). A missing
    step or frame is a failing ``evidence`` record; the differences are then taken over what both
    sides hold (frames with the same particle count), and a comparison over nothing is NaN (fails).
    Returns (records, summary): the label, the last step and the number of frames compared and the
    largest difference of each quantity (``x``, ``v``, ``w``, ``f``, ``t``, ``stress``, ``box``), from
    which a case builds its table rows.
    """
    who_a, who_b = sides
    exp_s, exp_f = expected_steps(nsteps, thermo_every), expected_frames(nsteps, dump_every)
    recs = trajectory_evidence(label, who_a, a, exp_s, exp_f) + trajectory_evidence(label, who_b, b, exp_s, exp_f)
    have = {int(s) for s in b.steps}
    frames = [
        int(s)
        for s in exp_f
        if s in a.frames and s in b.frames and int(s) in have and len(b.frames[s]["x"]) == len(a.frames[s]["x"])
    ]
    both = np.intersect1d(np.intersect1d(exp_s, a.steps), b.steps)
    fd = _frame_diffs(a, b, d50, frames, bounds.cell)
    steps, rel, dl = stress_differences(a, b, steps=both)
    sheared = bounds.cell == "sheared"
    recs += [
        compare(
            label,
            "position",
            "max|dx|/D50 over frames" + (" (modulo the sheared cell)" if sheared else ""),
            _max(fd["x"]),
            bounds.position,
            bounds.position_reason,
        ),
        compare(label, "velocity", "max|dv|/max|v|", _max(fd["v"]), bounds.relative, bounds.velocity_reason),
        compare(label, "spin", "max|dw|/max|w|", _max(fd["w"]), bounds.relative, bounds.velocity_reason),
        compare(label, "particle_force", "max|df|/max|f|", _max(fd["f"]), bounds.relative, bounds.force_reason),
        compare(label, "particle_torque", "max|dT|/max|T|", _max(fd["t"]), bounds.relative, bounds.force_reason),
        compare(
            label,
            "stress",
            "max over steps of max|dsigma|/max|sigma|",
            _max(rel),
            bounds.relative,
            bounds.stress_reason,
            inputs={who_a: a.stress[a.at(both)], who_b: b.stress[b.at(both)]},
        ),
        compare(
            label,
            "box",
            "max|d(lx, ly, xy)|/D50 over steps" if sheared else "max|dL|/D50",
            _max(dl) / d50,
            bounds.position,
            bounds.box_reason,
        ),
    ]
    summary = {
        "label": label,
        "last_step": int(steps[-1]) if len(steps) else -1,
        "frames": len(frames),
        **{k: _max(fd[k]) for k in ("x", "v", "w", "f", "t")},
        "stress": _max(rel),
        "box": _max(dl) / d50,
    }
    return recs, summary


# ====================================================================== explained difference
def explained_difference(
    label: str,
    a,
    b,
    nat_a,
    nat_b,
    *,
    d50: float,
    nsteps: int,
    dump_every: int,
    position_tol: float,
    relative_tol: float,
    reason: str,
    pair: str,
    thermo_every: int = 1,
    sides=("LIGGGHTS", "LAMMPS"),
    cell: str = "orthogonal",
) -> tuple[list, dict]:
    """Two codes ``a`` and ``b`` on one deck whose laws differ physically: the evidence of both,
    the raw differences (info, with the words of :func:`validation.codes.why_they_differ` for
    ``pair``) and the check that they equal the difference of the native runs in the two codes'
    arithmetic (``nat_a`` = code a's, ``nat_b`` = code b's): stress every series step, positions
    (modulo the box of ``a``) at every dump, at the step-for-step bounds. ``cell``: ``orthogonal``
    (box lengths (T, 2)) or ``sheared`` (box (lx, ly, xy), positions modulo the sheared cell)."""
    na, nb = sides
    exp_s, exp_f = expected_steps(nsteps, thermo_every), expected_frames(nsteps, dump_every)
    recs = trajectory_evidence(label, na, a, exp_s, exp_f) + trajectory_evidence(label, nb, b, exp_s, exp_f)
    trs = (a, b, nat_a, nat_b)
    steps = exp_s
    for t in trs:
        steps = np.intersect1d(steps, t.steps)
    frames = [int(f) for f in exp_f if all(int(f) in t.frames for t in trs) and int(f) in set(steps.tolist())]

    def sig(t):
        return t.stress[t.at(steps)]

    scale = np.abs(sig(a)).max(axis=1)
    scale = np.where(scale > 0, scale, 1.0)
    raw = np.abs(sig(a) - sig(b)).max(axis=1) / scale
    expl = np.abs((sig(a) - sig(b)) - (sig(nat_a) - sig(nat_b))).max(axis=1) / scale

    raw_x, expl_x = [], []
    for f in frames:
        L = a.lengths[a.at([f])[0]]
        xa, xb = a.frames[f]["x"], b.frames[f]["x"]
        ya, yb = nat_a.frames[f]["x"], nat_b.frames[f]["x"]
        if cell == "sheared":
            h = sheared_cell(L)
            d_codes, d_nat = reduce_sheared(xa - xb, h), reduce_sheared(ya - yb, h)
            raw_x.append(float(np.abs(d_codes).max()) / d50)
        else:
            raw_x.append(position_difference(xa, xb, L) / d50)
            d_codes = xa - xb - np.round((xa - xb) / L) * L
            d_nat = ya - yb - np.round((ya - yb) / L) * L
        expl_x.append(float(np.abs(d_codes - d_nat).max()) / d50)
    why = why_they_differ(pair)
    shown = "the raw cross-code difference (the size of the law differences), shown for the reader"
    recs += [
        info(
            label,
            "stress",
            f"{na} vs {nb}: max over steps of max|dsigma|/max|sigma|",
            _max(raw),
            f"{shown}. Why: {why}" if why else shown,
        ),
        info(
            label,
            "position",
            f"{na} vs {nb}: max|dx|/D50 over frames",
            _max(raw_x),
            f"{shown}. Why: {why}" if why else shown,
        ),
        compare(
            label,
            "stress",
            f"max|({na} - {nb}) - (native {na.lower()} - native {nb.lower()})|/max|sigma|",
            _max(expl),
            relative_tol,
            reason,
        ),
        compare(
            label,
            "position",
            f"max|({na} - {nb}) - (native {na.lower()} - native {nb.lower()})|/D50",
            _max(expl_x),
            position_tol,
            reason,
        ),
    ]
    summary = {
        "label": label,
        "last_step": int(steps[-1]) if len(steps) else -1,
        "frames": len(frames),
        "raw_x": _max(raw_x),
        "raw_stress": _max(raw),
        "unexplained_x": _max(expl_x),
        "unexplained_stress": _max(expl),
    }
    return recs, summary


# ====================================================================== envelope
@dataclass(frozen=True)
class EnvelopeRule:
    """The one envelope criterion: a long native run against a code's own chaos envelope.

    The reference is the code's serial run; its envelope members are runs of the same deck under
    a round-off perturbation (a coordinate moved by 1e-15 relative, 2 MPI processes, ...). With
    D(t) the native run's divergence from the reference (positions per dump, in D50; the stress
    per series step, relative) and E(t) the members' largest divergence at t:

        D(t) <= factor * max(E_w(t), floor / factor)   at every output step t,

    where E_w(t) is the largest E within ``window`` steps of t (0: E(t) itself) and ``floor`` the
    step-for-step bound of the quantity (0: none), i.e. a divergence below the short-horizon
    bound never fails. The value of a record is max_t D(t) / max(E_w(t), floor / factor); a step
    where D > 0 and the envelope is 0 gives inf, a NaN anywhere or no step at all NaN: both fail.

    Curves along the loading (deviator, volumetric strain, void-cell statistics) are judged by
    :func:`band`: within ``curve_factor`` times the largest deviation of a member from the
    reference.

    Parameters as the cases declare them (``reason`` says why):

    * :data:`BITWISE_RULE` (biaxial-full, biaxial-laws): factor 10, no window, no floor, curve
      factor 1: the native run repeats the code's arithmetic bit for bit (measured: D = 0 at every
      step), so the pointwise rule applies and no allowance for a later onset is needed.
    * :data:`ROUNDOFF_RULE` (simple-shear): factor 10, window one dump interval (3000 steps),
      floors 1e-10 D50 / 1e-8, curve factor 2: the sheared-cell native run differs from LAMMPS by
      the summation order (2.5e-13 D50 in 3000 steps), so it is seeded at every step, not by one
      kick, and meets a slip event up to ~1000 steps before or after a member does.
    """

    factor: float
    window: int
    position_floor: float
    stress_floor: float
    curve_factor: float
    reason: str

    def metric(self, quantity: str) -> str:
        """The record's metric: ``max_t D_native(t)/E(t)`` or, with a window or a floor,
        ``max_t D_native(t)/max(E_w(t), 1e-10/10)``."""
        d, e = ("D", "E") if quantity == "position" else ("S", "E_S")
        floor = self.position_floor if quantity == "position" else self.stress_floor
        if not self.window and not floor:
            return f"max_t {d}_native(t)/{e}(t)"
        env = f"{e},w(t)" if quantity != "position" and self.window else (f"{e}_w(t)" if self.window else f"{e}(t)")
        return f"max_t {d}_native(t)/max({env}, {_short(floor)}/{self.factor:g})"


def _short(x: float) -> str:
    """1e-08 -> ``1e-8`` (how the metrics write a bound)."""
    m, e = f"{x:e}".split("e")
    return f"{m.rstrip('0').rstrip('.')}e{int(e)}"


ENVELOPE_FACTOR = 10.0
BITWISE_RULE_REASON = (
    "chaos: the code's own divergence under a round-off perturbation (one coordinate moved by "
    "1e-15 relative, two runs; full suite also 2 MPI processes and twice the neighbour skin) is the envelope E(t) "
    "= max over those runs at each output step; native-vs-CODE must stay within 10 E(t) at every step (a factor "
    "10 = one decade of exponential growth, i.e. the perturbations' onset is uncertain to that); no time window "
    "and no floor, as the native run repeats CODE's arithmetic bit for bit (validation.judges.EnvelopeRule)"
)
BITWISE_RULE = EnvelopeRule(
    factor=ENVELOPE_FACTOR, window=0, position_floor=0.0, stress_floor=0.0, curve_factor=1.0, reason=BITWISE_RULE_REASON
)


def windowed_max(steps, e, window: int) -> np.ndarray:
    """For every step t: max of ``e`` over the series steps within |t' - t| <= ``window``."""
    steps = np.asarray(steps, np.int64)
    e = np.asarray(e, float)
    if not window:
        return e
    lo = np.searchsorted(steps, steps - window, side="left")
    hi = np.searchsorted(steps, steps + window, side="right")
    return np.array([e[a:b].max() for a, b in zip(lo, hi)]) if len(e) else e


def envelope_ratio(d, env, factor: float, floor: float = 0.0) -> float:
    """max_t d(t) / max(env(t), floor / factor): <= factor iff d <= max(factor env, floor) at every
    step. A step with d = 0 counts 0 (whatever the envelope), d > 0 over a zero envelope inf; NaN
    (a failing value) when there is no step or d or the envelope holds a NaN or inf."""
    d, env = np.asarray(d, float), np.asarray(env, float)
    if not len(d) or d.shape != env.shape or not (np.isfinite(d).all() and np.isfinite(env).all()):
        return float("nan")
    den = np.maximum(env, floor / factor)
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(d > 0, d / np.where(den > 0, den, 1.0), 0.0)
        r = np.where((d > 0) & (den <= 0), np.inf, r)
    return float(np.max(r))


def decade_steps(steps, env, level: float = 1e-4) -> float:
    """Steps per decade of the envelope's mean growth: from its first positive value to the first
    step where it reaches ``level`` (NaN when it never does)."""
    steps, env = np.asarray(steps), np.asarray(env, float)
    pos = np.flatnonzero(env > 0)
    hit = np.flatnonzero(env >= level)
    if not len(pos) or not len(hit) or hit[0] <= pos[0]:
        return float("nan")
    a, b = pos[0], hit[0]
    return float((steps[b] - steps[a]) / np.log10(env[b] / env[a]))


def envelope(
    label: str,
    code: str,
    nat,
    ref,
    members: dict,
    *,
    frames,
    steps,
    d50: float,
    rule: EnvelopeRule,
    cell: str = "orthogonal",
) -> tuple[list, dict, dict]:
    """The divergence of ``nat`` from ``code``'s serial reference ``ref`` judged against the
    code's own envelope (its perturbed runs ``members``, {label: trajectory}) by ``rule``.

    ``frames``: the dump steps to compare positions at (empty: positions not compared, e.g. a
    stored series without frames); ``steps``: the series steps of the stress. The evidence of
    every run must have been checked before (the cases make no envelope verdict on incomplete
    evidence). Returns (records, div, sdiv) with div/sdiv = {name: (steps, values)} of positions
    (per frame) and stress (per series step) of the native run and of every member."""
    runs = {f"native vs {code}": nat, **{f"{code} {k}": t for k, t in members.items()}}
    me = f"native vs {code}"
    div, sdiv = {}, {}
    for name, tr in runs.items():
        if len(frames):
            fd = _frame_diffs(tr, ref, d50, frames, cell)
            div[name] = (fd["steps"], fd["x"])
        st, rel, _ = stress_differences(tr, ref, steps=steps)
        sdiv[name] = (st, rel)
    ens = [k for k in runs if k != me]
    reason = rule.reason.replace("CODE", code)
    recs = []
    if len(frames):
        env_x = windowed_max(div[me][0], np.max([div[k][1] for k in ens], axis=0), rule.window)
        recs.append(
            compare(
                label,
                "position",
                rule.metric("position"),
                envelope_ratio(div[me][1], env_x, rule.factor, rule.position_floor),
                rule.factor,
                reason,
            )
        )
    env0 = np.max([sdiv[k][1] for k in ens], axis=0)
    env_s = windowed_max(sdiv[me][0], env0, rule.window)
    recs.append(
        compare(
            label,
            "stress",
            rule.metric("stress"),
            envelope_ratio(sdiv[me][1], env_s, rule.factor, rule.stress_floor),
            rule.factor,
            reason,
        )
    )
    if rule.window:  # what the window changes, and the time scale it rests on
        recs.append(
            info(
                label,
                "stress",
                f"max_t S_native(t)/max(E_S(t), {_short(rule.stress_floor)}/{rule.factor:g}) without the time window",
                envelope_ratio(sdiv[me][1], env0, rule.factor, rule.stress_floor),
                "shown for the reader: the pointwise ratio, dominated by slip events met at slightly other steps",
            )
        )
        recs.append(
            info(
                label,
                "stress",
                "steps per decade of the envelope's mean growth (to 1e-4)",
                decade_steps(sdiv[me][0], env0),
                f"the time scale behind the envelope's window of +/- {rule.window} steps",
            )
        )
    return recs, div, sdiv


def max_abs_diff(x, y) -> float:
    """max |x - y| of two curves (NaN when either holds one)."""
    return float(np.abs(np.asarray(x, float) - np.asarray(y, float)).max())


def band_width(reference, members, diff=max_abs_diff) -> float:
    """The band of an envelope around ``reference``: the largest ``diff`` of a member's curve from
    it (NaN stays NaN)."""
    return peak(diff(m, reference) for m in members)


def band(
    label: str,
    quantity: str,
    metric: str,
    native,
    reference,
    members: list,
    *,
    factor: float,
    reason: str,
    diff=None,
):
    """A curve of the native run within ``factor`` times the band of the code's envelope: the
    value is max |native - reference| along the curve, the tolerance ``factor`` x the largest
    deviation of a member's curve from the reference's (NaN stays NaN: fails). ``diff(a, b)``:
    the largest difference of two curves (default max |a - b|; the void-cell statistics use
    :func:`reference_runs.judge.defined_diff`, where NaN marks a frame without cells)."""
    diff = diff or max_abs_diff
    return compare(
        label, quantity, metric, diff(native, reference), factor * band_width(reference, members, diff), reason
    )


# ====================================================================== statistics of snapshots
def statistics_band(
    label: str,
    nat,
    ref,
    *members,
    frames,
    statistics,
    checks,
    factor: float,
    reason: str,
    sides,
    member_names=(),
    diff=None,
    without_frames: str = "",
) -> tuple[list, dict]:
    """Statistics of a run's snapshots against a code's: ``statistics(trajectory) -> (F, k)`` array
    over the expected ``frames``; for each check ``(col, quantity)`` the run's column within
    ``factor`` times the band of the code's perturbed runs (``members``) around its reference
    (:func:`band`). ``ref`` may be an :class:`Ensemble` (its reference and members). First the
    evidence of every run (every expected frame, and every expected member of an ensemble); on
    incomplete evidence no verdict. No frames at all (runs that keep none, a stored series): an
    info record saying ``without_frames``, no verdict. Returns (records, summary: complete, stats
    {name: array}, bands {quantity})."""
    recs = []
    if isinstance(ref, Ensemble):
        recs.append(evidence(label, f"perturbed {sides[1]} runs (the band)", list(ref.expected), list(ref.members)))
        members, member_names, ref = tuple(ref.members.values()), list(ref.members), ref.reference
    if not len(frames):
        recs.append(info(label, "statistics", "not compared: no frames", math.nan, without_frames))
        return recs, {"complete": False}
    names = member_names or [f"member {i}" for i in range(len(members))]
    named = [(sides[0], nat), (sides[1], ref), *((f"{sides[1]} {n}", t) for n, t in zip(names, members))]
    for who, tr in named:
        recs += trajectory_evidence(label, who, tr, None, frames)
    if not all(r.passed for r in recs):
        return recs, {"complete": False}
    st = {who: statistics(tr) for who, tr in named}
    mem = [st[who] for who, _ in named[2:]]
    bands = {}
    for col, quantity in checks:
        bands[quantity] = band_width(st[sides[1]][:, col], [m[:, col] for m in mem], diff or max_abs_diff)
        recs.append(
            band(
                label,
                quantity,
                f"max over {len(frames)} frames |{sides[0]} - {sides[1]}|",
                st[sides[0]][:, col],
                st[sides[1]][:, col],
                [m[:, col] for m in mem],
                factor=factor,
                reason=reason,
                diff=diff,
            )  # fmt: skip
        )
    return recs, {"complete": True, "stats": st, "bands": bands}


def statistics_cross(
    label: str, ref_a, ref_b, *members, n_a: int, frames, statistics, checks, reason: str, sides, diff=None
) -> tuple[list, dict]:
    """Two codes' references by their snapshots' statistics: each lies within its own band (the
    largest deviation of a perturbed run from its reference: ``members``, the first ``n_a`` of
    code a), so their columns must differ by at most the sum of the two bands. Evidence of every
    run first; no verdict on incomplete evidence."""
    na, nb = sides
    runs = [(na, ref_a), (nb, ref_b), *((f"{na if i < n_a else nb} member {i}", t) for i, t in enumerate(members))]
    recs = []
    for who, tr in runs:
        recs += trajectory_evidence(label, who, tr, None, frames)
    both = int(n_a > 0) + int(n_a < len(members))
    recs.append(evidence(label, "codes with perturbed runs (their bands)", 2, both))
    if not all(r.passed for r in recs):
        return recs, {"complete": False}
    d = diff or max_abs_diff
    sa, sb = statistics(ref_a), statistics(ref_b)
    ma, mb = [statistics(t) for t in members[:n_a]], [statistics(t) for t in members[n_a:]]
    for col, quantity in checks:
        width = band_width(sa[:, col], [m[:, col] for m in ma], d) + band_width(sb[:, col], [m[:, col] for m in mb], d)
        recs.append(compare(label, quantity, f"max over {len(frames)} frames |{na} - {nb}|", d(sa[:, col], sb[:, col]),
                            width, reason))  # fmt: skip
    return recs, {"complete": True}


# ====================================================================== Taylor states
@dataclass(frozen=True)
class TaylorStates:
    """A code's Taylor jobs as one run of the taylor-rve case: ``runs`` {RVE name: TaylorRun},
    ``stored`` (read from reference_runs/stored rather than run now), ``source`` in words."""

    runs: dict
    stored: bool
    source: str


def taylor_stress(
    label: str, material, states: TaylorStates, *, expected_rves, sides, tolerance: float, reason: str
) -> tuple[list, dict]:
    """gransim's Taylor stress against a code's virial stress, state by state.

    ``material(packing)`` is gransim's Taylor material of an RVE (``.evaluate(F).cauchy``). The
    evidence: every RVE of ``expected_rves`` run (live jobs), each stored job verified against its
    deck (stored), every expected (path, route) series with every expected state
    (:func:`validation.taylor_compare.series_evidence`); records labelled ``label/<RVE>/...``
    (``label`` = ``taylor-rve/<code>``). Then per series: max over states of
    max |sigma_native - sigma_code| / max |sigma_code| <= ``tolerance``. Returns (records, {"rows":
    [code, RVE, path, route, states, value]})."""
    code = sides[1]
    recs, rows = [], []
    if not states.stored:
        recs.append(evidence(label, f"RVEs run by {code}", sorted(expected_rves), sorted(states.runs)))
    for name, run in states.runs.items():
        lab = f"{label}/{name.replace('rve-', '')}"
        if states.stored:
            recs.append(stored_job_record(lab, run.job_dir))
        recs += series_evidence(lab, run)
    for name, run in states.runs.items():
        mat = material(run.packing)  # one material (and candidate cache) per RVE, all paths
        for (path, route), ser in sorted(run.series.items()):
            sig_n = mat.evaluate(np.asarray(ser.F)).cauchy
            scale = np.abs(ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
            diff = np.abs(sig_n - ser.cauchy).reshape(len(ser.F), -1).max(axis=1)
            rel = peak([diff / np.where(scale > 0, scale, 1.0)])
            lab = f"{label}/{name.replace('rve-', '')}/{PATH_NAMES[path]}/{route}"
            inputs = {"native": sig_n, code: ser.cauchy}
            recs.append(compare(lab, "stress", "max_rel_diff", rel, tolerance, reason, inputs=inputs))
            rows.append([code, name, path, route, len(ser.F), rel])
    return recs, {"rows": rows}


def taylor_contacts(label: str, material, states: TaylorStates, *, route: str, match, sides) -> tuple[list, dict]:
    """gransim's contacts against a code's contact rows of every state of the contact route,
    two-sided (``match(packing, F, frame)``: the code's output form; the records of
    :func:`validation.taylor_compare.contact_records`), after the evidence of every expected state.
    ``label`` = ``taylor-rve/<code>/contacts``: records ``taylor-rve/<code>/<RVE>/contacts`` (evidence)
    and ``taylor-rve/<code>/<RVE>/<path>/k<k>``."""
    code = sides[1]
    base = label.removesuffix("/contacts")
    recs = []
    for name, run in states.runs.items():
        short = name.replace("rve-", "")
        exp = {k: v for k, v in expected_series(run).items() if k[1] == route}
        recs += series_evidence(f"{base}/{short}/contacts", run, exp)
        for (path, r), ser in sorted(run.series.items()):
            if r != route:
                continue
            for k, F in zip(ser.k, ser.F):
                cmp = match(run.packing, F, run.contacts(path, r, int(k)))
                recs += contact_records(f"{base}/{short}/{PATH_NAMES[path]}/k{k}", cmp, code)
    return recs, {}


def taylor_cross(
    label: str, a: TaylorStates, b: TaylorStates, *, engines, sides, tolerance: float, reason: str
) -> tuple[list, dict]:
    """Two codes' virial stresses of the same Taylor states (same RVE, path, route, k): every
    series of code a must be in code b's jobs with every state; round-off only (both evaluate
    the same closed-form sum on the same positions)."""
    na, nb = sides
    recs, n_states = [], 0
    for name, run in a.runs.items():
        other = b.runs.get(name) or b.runs.get(taylor_case(name, engines[1]))
        if other is None:
            recs.append(evidence(f"{label}/{name}", f"{nb} run of the RVE {na} ran", [name], []))
            continue
        for key, ser in sorted(run.series.items()):
            if key not in other.series:
                recs.append(evidence(f"{label}/{name}", f"{nb} series of the {na} series", [f"{key[0]}/{key[1]}"], []))
                continue
            o = other.series[key]
            common = np.intersect1d(ser.k, o.k)
            recs.append(
                evidence(
                    f"{label}/{name}/{PATH_NAMES[key[0]]}/{key[1]}",
                    "states of both codes",
                    [int(k) for k in ser.k],
                    [int(k) for k in common],
                )
            )
            ia, ib = np.searchsorted(ser.k, common), np.searchsorted(o.k, common)
            x, y = ser.cauchy[ia], o.cauchy[ib]
            scale = np.abs(x).reshape(len(x), -1).max(axis=1)
            rel = np.abs(x - y).reshape(len(x), -1).max(axis=1) / np.where(scale > 0, scale, 1.0)
            recs.append(
                compare(
                    f"{label}/{name.replace('rve-', '')}/{PATH_NAMES[key[0]]}/{key[1]}",
                    "stress",
                    f"max_rel_diff {na} vs {nb}",
                    peak([rel]),
                    tolerance,
                    reason,
                    inputs={na: x, nb: y},
                )
            )
            n_states += len(common)
    return recs, {"states": n_states}


def yade_taylor_records(label: str, cmp, sel) -> list:
    """The checks of one RVE and path (states ``sel`` of :func:`reference_runs.yade.compare.compare_yade_taylor`'s
    comparison): YADE's two stresses, its tangent against gransim's material part, the entries that must be
    zero and the contacts (docs/yade.md, "The 15 study RVEs")."""
    sides = "gransim (native) vs YADE"
    un_g, un_y = int(cmp.unmatched_gransim[sel].sum()), int(cmp.unmatched_yade[sel].sum())
    n_g, n_y = int(cmp.n_gransim[sel].sum()), int(cmp.n_yade[sel].sum())
    return [
        compare(
            label, "stress", f"max_rel_diff getStress, {sides}", peak([cmp.stress[sel]]), STRESS_RTOL, STRESS_REASON
        ),
        compare(
            label,
            "stress",
            f"max_rel_diff stress of getStressAndTangent, {sides}",
            peak([cmp.stress_tangent_call[sel]]),
            STRESS_RTOL,
            STRESS_REASON,
        ),
        compare(
            label,
            "tangent",
            "max_rel_diff of the upper triangle, gransim's material part pushed forward vs YADE",
            peak([cmp.tangent[sel]]),
            TANGENT_RTOL,
            TANGENT_REASON,
        ),
        compare(
            label,
            "tangent_zero_entries",
            "max |z rows, z columns, lower triangle of YADE's tangent| / max |tangent|",
            peak([cmp.structure[sel]]),
            0.0,
            STRUCTURE_REASON,
        ),
        Record(
            label,
            "contacts",
            f"contacts without a partner (gransim {un_g} of {n_g}, YADE {un_y} of {n_y}, summed over states)",
            float(un_g + un_y + abs(n_g - n_y)),
            0.0,
            un_g == 0 and un_y == 0 and n_g == n_y and n_g > 0,
            CONTACT_REASON,
        ),
    ]


def taylor_yade(label: str, material, runs: dict, *, expected_rves, expected_ks, sides) -> tuple[list, dict]:
    """gransim's Taylor stress, the material part of its tangent and its contacts against YADE's
    ``getStress``, ``getStressAndTangent`` and interactions, state by state.

    ``runs``: {RVE: :class:`reference_runs.yade.taylor.YadeTaylorRun`, or the message of a job or a
    stored output that failed or is incomplete}. Evidence first: every RVE of ``expected_rves`` run,
    a failed one an ``incomplete`` record naming it, every state k of ``expected_ks`` on every path;
    then the checks of :func:`yade_taylor_records` per RVE and path (labels ``label/<RVE>/<path>``).
    Returns (records, {"rows": [RVE, N, states, contacts, getStress, stress of getStressAndTangent,
    tangent, YADE's seconds (its manifest's elapsed_s)], "versions": the YADE versions of the runs'
    manifests})."""
    recs = [
        evidence(
            label,
            "RVEs run by YADE",
            sorted(expected_rves),
            sorted(k for k, r in runs.items() if not isinstance(r, str)),
        )
    ]
    rows, versions = [], set()
    for name, run in sorted(runs.items()):
        short = name.replace("rve-", "")
        if isinstance(run, str):
            recs.append(Record(f"{label}/{short}", "evidence", f"incomplete: YADE job failed: {run}", 1.0, 0.0, False))
            continue
        versions.add(str(run.manifest.get("engine_version", "unknown")))
        paths = sorted({st["path"] for st in run.states}, key=list(PATH_NAMES).index)
        for path in PATH_NAMES:
            have = [st["k"] for st in run.states if st["path"] == path]
            recs.append(evidence(f"{label}/{short}/{PATH_NAMES[path]}", "YADE states", list(expected_ks), have))
        try:
            cmp = compare_yade_taylor(run, material(run.packing))
        except JudgeError as exc:  # NaN or inf on a side, no state: a failure, named
            recs.append(Record(f"{label}/{short}", "evidence", f"cannot be judged: {exc}", math.nan, 0.0, False))
            continue
        for path in paths:
            sel = np.array([st["path"] == path for st in run.states])
            recs += yade_taylor_records(f"{label}/{short}/{PATH_NAMES[path]}", cmp, sel)
        rows.append(
            [
                name,
                run.packing.n,
                len(run.states),
                f"{int(cmp.n_gransim.min())}-{int(cmp.n_gransim.max())}",
                f"{float(cmp.stress.max()):.2e}",
                f"{float(cmp.stress_tangent_call.max()):.2e}",
                f"{float(cmp.tangent.max()):.2e}",
                f"{float(run.manifest.get('elapsed_s', 0.0)):.1f}",
            ]
        )
    return recs, {"rows": rows, "versions": sorted(versions)}


# ====================================================================== equilibria
def equilibria(
    label: str,
    a,
    b,
    *,
    sides,
    metric: str,
    reason: str,
    amplification: float,
    roundoff: float,
    names=None,
    record_evidence: bool = False,
) -> tuple[list, dict]:
    """Two states at rest of one energy (a DEM run at rest, a Newton minimiser) compared by their
    stresses, within what their residual forces leave.

    Each side is an object with ``sigma`` ((2, 2) Cauchy stress, N/m in 2D, tension positive) and
    ``rho`` (max over disks of |net contact force| / mean contact force); None, or ``sigma`` None,
    when the side's evidence is incomplete. Both sides minimise the same energy up to their residual
    forces r, and a residual r moves the stress by the linear response B^T H^-1 r (H the Hessian over
    the periodic fluctuations, B the mixed derivative: Miehe & Dettmar 2004, "A framework for
    micro-macro transitions in periodic particle aggregates of granular materials", sections 3-4),
    so the stresses must agree within ``amplification * (rho_a + rho_b) + roundoff``.

    Value: max |sigma_a - sigma_b| / max |sigma_b| over the components (``b`` the reference; the
    largest component scales, sigma_xy passing through zero). A missing side is a failing
    ``evidence`` record naming it, and no stress is judged on what remains; a NaN or inf in a stress
    or a residual fails the stress record (named). ``names``: the two sides' names in the records
    (default ``sides``; they must differ). ``record_evidence``: the evidence is recorded when complete
    too (a column that holds no other record of its runs' evidence, two codes' runs whose own
    evidence is filed in their native columns). Returns (records, summary: ``value``, ``tolerance``,
    ``sigma`` and ``rho`` (per side, in order), ``missing`` (the names of the sides missing))."""
    names = tuple(sides) if names is None else tuple(names)
    if len(names) != 2 or names[0] == names[1]:
        raise ValueError(f"equilibria {label}: two distinct side names expected, got {names!r}")
    states = (a, b)
    present = [n for n, s in zip(names, states) if s is not None and getattr(s, "sigma", None) is not None]
    missing = [n for n in names if n not in present]
    ev = evidence(label, "equilibria at rest", list(names), present)
    if missing:
        return [ev], {"value": math.nan, "tolerance": math.nan, "sigma": (), "rho": (), "missing": missing}
    sa, sb = (np.asarray(s.sigma, float) for s in states)
    ra, rb = (float(s.rho) for s in states)
    scale = float(np.abs(sb).max()) or 1.0
    value = float(np.abs(sa - sb).max()) / scale
    tol = amplification * (ra + rb) + roundoff
    rec = compare(label, "stress", metric, value, tol, reason, inputs={names[0]: sa, names[1]: sb})
    summary = {"value": value, "tolerance": tol, "sigma": (sa, sb), "rho": (ra, rb), "missing": []}
    return ([ev] if record_evidence else []) + [rec], summary


# ====================================================================== void cells
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


def void_cells(snap):
    """Kuhn's void cells of a snapshot (:class:`gransim.voidcell.VoidCells`)."""
    return VoidCells().compute(snap)


def _face_cycles(vc) -> list:
    d = vc.dcel
    out = []
    for f in range(d.n_faces):
        cyc = [int(v) for v in d.origin[d.face_halfedges[d.face_ptr[f] : d.face_ptr[f + 1]]]]
        k = int(np.argmin(cyc))
        out.append(tuple(cyc[k:] + cyc[:k]))
    return out


def cell_signature(vc) -> tuple:
    """Faces as sorted tuples of particle cycles (canonical rotation), with valences and counts."""
    d = vc.dcel
    return (d.n_faces, d.n_edges, d.n_vertices, tuple(sorted(_face_cycles(vc))))


def face_order(vc) -> np.ndarray:
    """The faces in the order of their canonical particle cycles (to pair the faces of two codes)."""
    sig = _face_cycles(vc)
    return np.array(sorted(range(len(sig)), key=lambda i: sig[i]))


def compare_cell_frames(a, b, steps, radii, dt, snapshot) -> dict:
    """Per frame of ``steps``: the same cell list?, max |d alpha|, max |d w| / max |w| and both
    void-cell sets, from snapshots of both runs built by one function ``snapshot(tr, step, radii,
    dt)`` (:func:`validation.dem_compare.snapshot` for ``remap x`` boxes, the sheared-cell one for
    ``remap v``). A frame without a framework spanning the cell must be so on both sides
    (``no_tessellation``); on one side only it is a different cell list."""
    out = {"steps": [], "same": [], "alpha": [], "w": [], "vc": [], "no_tessellation": []}
    for s in steps:
        vcs = []
        for tr in (a, b):
            try:
                vcs.append(void_cells(snapshot(tr, s, radii, dt)))
            except InputError as exc:  # no framework spanning the cell: must then hold on both sides
                vcs.append(str(exc))
        x, y = vcs
        if isinstance(x, str) or isinstance(y, str):
            if x == y:
                out["no_tessellation"].append(int(s))
                continue
            same, x, y = False, None, None
        else:
            same = cell_signature(x) == cell_signature(y)
        da = dw = float("inf")
        if same:
            ia, ib = face_order(x), face_order(y)
            # NaN marks a cell whose alignment is undefined (zero gradient): it must be so on both sides
            da = defined_diff(x.alpha[ia], y.alpha[ib])
            dw = defined_diff(x.w[ia], y.w[ib]) / (defined_peak(y.w) or 1.0)
        out["steps"].append(int(s))
        out["same"].append(same)
        out["alpha"].append(da)
        out["w"].append(dw)
        out["vc"].append((x, y))
    return out


def cell_records(label: str, cmp: dict) -> list:
    """Records of :func:`compare_cell_frames`: frames with different cell lists (0), max |d alpha|
    and max |d w| / max |w| (:data:`ALPHA_TOL`); no frame with a tessellation is a failure."""
    ndiff = sum(not s for s in cmp["same"])
    if not cmp["same"]:
        return [compare(label, "cell_list", "frames with a tessellation", 0, -1, LIST_REASON)]
    return [
        compare(label, "cell_list", f"frames with different cell lists (of {len(cmp['same'])})", ndiff, 0, LIST_REASON),
        compare(label, "alpha", "max|d alpha| over cells and frames", peak(cmp["alpha"]), ALPHA_TOL, ALPHA_REASON),
        compare(label, "w", "max|d w|/max|w| over frames", peak(cmp["w"]), ALPHA_TOL, W_REASON),
    ]


def cell_lists(label: str, a, b, *, frames, radii, dt, snapshot, sides, as_info: str = "") -> tuple[list, dict]:
    """Kuhn's void cells of two runs, frame by frame: the evidence of every expected frame on both
    sides, then :func:`cell_records` over the frames both hold (with their series step); or, with
    ``as_info`` (why the runs need not agree: two codes whose laws differ), only the number of
    frames whose cell lists differ, an info record with that reason. Returns (records, the
    :func:`compare_cell_frames` dict)."""
    recs = trajectory_evidence(label, sides[0], a, None, frames) + trajectory_evidence(label, sides[1], b, None, frames)
    sa, sb = {int(s) for s in a.steps}, {int(s) for s in b.steps}
    present = [int(k) for k in frames if k in a.frames and k in b.frames and int(k) in sa and int(k) in sb]
    cmp = compare_cell_frames(a, b, present, radii, dt, snapshot)
    if as_info:
        n = len(cmp["same"])
        ndiff = sum(not x for x in cmp["same"]) if n else math.nan
        what = f"frames with different cell lists, {sides[0]} vs {sides[1]} (of {n})"
        return recs + [info(label, "cell_list", what, ndiff, as_info)], cmp
    return recs + cell_records(label, cmp), cmp


# ====================================================================== a long loading: a code's ensemble
@dataclass(frozen=True)
class Ensemble:
    """A code's runs of one long loading, as one run of a declared case: its serial reference and
    its envelope members (runs of the same deck under a round-off perturbation).

    expected : the member labels the envelope needs. every : the series interval of the runs
    (thermo, or that of a stored series). stored : read from reference_runs/stored (series
    only: no frames). refused : why a stored series cannot be used ("" when it can), e.g. made
    from another assembly; it then fails as evidence."""

    reference: object
    members: dict
    expected: tuple
    every: int
    stored: bool
    source: str
    manifest: dict | None = None
    refused: str = ""


@dataclass(frozen=True)
class CurveCheck:
    """A curve along the loading judged by :func:`band`: column ``col`` of the case's
    ``curves_of(trajectory)`` tuple, with its quantity, metric and reason."""

    col: int
    quantity: str
    metric: str
    reason: str


def chaos_envelope(
    label: str,
    nat,
    ref,
    *members,
    member_names,
    nsteps: int,
    dump_every: int,
    d50: float,
    rule: EnvelopeRule,
    sides,
    thermo_every: int = 1,
    cell: str = "orthogonal",
    run_name: str = "native",
    reference_name: str = "code order",
) -> tuple[list, dict]:
    """A run (``run_name``) against a reference (``reference_name``) and the reference's own
    perturbed runs (``members``, named by ``member_names``), all made by the case: the evidence of
    every run (every ``thermo_every``-th step of ``nsteps`` in the series, a frame every
    ``dump_every`` steps), then, only on complete evidence, :func:`envelope` by ``rule``. Returns
    (records, summary: complete, div, sdiv)."""
    steps, frames = expected_steps(nsteps, thermo_every), expected_frames(nsteps, dump_every)
    named = ((run_name, nat), (reference_name, ref), *zip(member_names, members))
    recs = []
    for who, tr in named:
        recs += trajectory_evidence(label, who, tr, steps, frames)
    if not all(r.passed for r in recs):  # no envelope verdict on incomplete evidence (it fails)
        return recs, {"complete": False}
    got, div, sdiv = envelope(
        label, reference_name, nat, ref, dict(zip(member_names, members)), frames=frames, steps=steps, d50=d50,
        rule=rule, cell=cell,
    )  # fmt: skip
    return recs + got, {"complete": True, "div": div, "sdiv": sdiv}


def ensemble_envelope(
    label: str,
    nat,
    ens: Ensemble,
    *,
    nsteps: int,
    native_every: int,
    dump_every: int,
    d50: float,
    rule: EnvelopeRule,
    curves_of,
    checks: tuple,
    sides,
    cell: str = "orthogonal",
    native_name: str = "native",
) -> tuple[list, dict]:
    """A native run of a long loading against a code's :class:`Ensemble`: the evidence of every run
    (the native run's every ``native_every``-th step and every dump; the code's reference and every
    expected member at its series interval, with frames unless stored), then, only on complete
    evidence, :func:`envelope` by ``rule`` and the curves of ``checks`` by :func:`band` (within
    ``rule.curve_factor`` times the members' band). Labels: ``<label>`` is ``<case>/<code>``;
    records go to ``<case>/evidence/<code>``, ``<case>/divergence/<code>``, ``<case>/curve/<code>``.
    Returns (records, summary: complete, div, sdiv, curves {run: curves_of(run)}, bands {quantity})."""
    case_, engine = label.rsplit("/", 1)
    code = sides[1]
    exp_s = expected_steps(nsteps, ens.every)
    exp_f = None if ens.stored else expected_frames(nsteps, dump_every)
    lab = f"{case_}/evidence/{engine}"
    recs = trajectory_evidence(
        lab, native_name, nat, expected_steps(nsteps, native_every), expected_frames(nsteps, dump_every)
    )
    if ens.refused:
        recs.append(evidence(lab, f"{code} series usable here ({ens.refused})", 1, 0))
        return recs, {"complete": False}
    recs += trajectory_evidence(lab, f"{code} reference", ens.reference, exp_s, exp_f)
    recs.append(evidence(lab, f"perturbed {code} runs (the envelope)", list(ens.expected), list(ens.members)))
    for k, t in ens.members.items():
        recs += trajectory_evidence(lab, f"{code} {k}", t, exp_s, exp_f)
    if not all(r.passed for r in recs):  # no verdict on what remains
        return recs, {"complete": False}
    ref = ens.reference
    got, div, sdiv = envelope(
        f"{case_}/divergence/{engine}",
        code,
        nat,
        ref,
        ens.members,
        frames=exp_f if exp_f is not None else [],
        steps=exp_s,
        d50=d50,
        rule=rule,
        cell=cell,
    )
    recs += got
    if len(nat.steps) != len(ref.steps):  # a series sampled less often (stored): the native run at its steps
        nat = type(nat)(ref.steps, nat.stress[nat.at(ref.steps)], nat.lengths[nat.at(ref.steps)], {})
    cur = {
        code: curves_of(ref),
        native_name: curves_of(nat),
        **{f"{code} {k}": curves_of(t) for k, t in ens.members.items()},
    }
    bands = {}
    for c in checks:
        members = [cur[f"{code} {k}"][c.col] for k in ens.members]
        bands[c.quantity] = band_width(cur[code][c.col], members)  # NaN stays NaN
        recs.append(
            band(
                f"{case_}/curve/{engine}",
                c.quantity,
                c.metric,
                cur[native_name][c.col],
                cur[code][c.col],
                members,
                factor=rule.curve_factor,
                reason=c.reason,
            )
        )
    return recs, {"complete": True, "div": div, "sdiv": sdiv, "curves": cur, "bands": bands}


def ensemble_cross(
    label: str,
    a: Ensemble,
    b: Ensemble,
    *,
    nsteps: int,
    curves_of,
    checks: tuple,
    reason: str,
    sides,
    pair: str = "",
) -> tuple[list, dict]:
    """Two codes' references of one long loading: they differ by their laws (no step-for-step
    verdict; the raw stress difference is shown, with why), and each lies within its own band of the
    curve, so the two curves of every check must differ by at most the sum of the two codes' bands
    (the largest deviation of a member from its reference). Evidence: every run of both ensembles
    complete on the steps they share with the expected series (else no verdict, a failing record)."""
    na, nb = sides
    n_exp = len(expected_steps(nsteps, max(a.every, b.every)))
    usable = not (a.refused or b.refused)
    complete = usable and all(
        set(expected_steps(nsteps, e.every).tolist()) <= {int(s) for s in t.steps} and set(e.expected) <= set(e.members)
        for e in (a, b)
        for t in (e.reference, *e.members.values())
    )
    if not complete:
        return [evidence(label, f"complete runs of both codes ({na}, {nb}) for their bands", 1, 0)], {}
    ra, rb = a.reference, b.reference
    steps = np.intersect1d(ra.steps, rb.steps)
    recs = [evidence(label, f"common series steps of {na} and {nb}", n_exp, min(len(steps), n_exp))]

    def at(e, t):
        s = np.intersect1d(e.reference.steps, steps)
        return type(t)(s, t.stress[t.at(s)], t.lengths[t.at(s)], {})

    ca, cb = curves_of(at(a, ra)), curves_of(at(b, rb))
    for c in checks:
        wa = band_width(ca[c.col], [curves_of(at(a, t))[c.col] for t in a.members.values()])
        wb = band_width(cb[c.col], [curves_of(at(b, t))[c.col] for t in b.members.values()])
        recs.append(
            compare(
                label,
                c.quantity,
                c.metric,
                float(np.abs(ca[c.col] - cb[c.col]).max()) if len(steps) else float("nan"),
                wa + wb,
                reason,
            )
        )
    _, rel, _ = stress_differences(at(a, ra), at(b, rb))
    why = why_they_differ(pair)
    recs.append(
        info(
            label,
            "stress",
            f"{na} vs {nb}: max over steps of max|dsigma|/max|sigma|",
            float(rel.max()) if rel.size else float("nan"),
            "the codes' laws differ (docs/lammps.md): their step-by-step divergence starts at the law "
            "difference, far above the 1e-15 perturbations, so it is shown, not judged; the curves are"
            + (f". Why: {why}" if why else ""),
        )
    )
    return recs, {}


# ====================================================================== frame for frame
@dataclass(frozen=True)
class FrameBound:
    """One per-particle quantity of :func:`frame_for_frame`.

    key : the frame column (``x``, ``v``, ``w``, ``f``, ``t``).
    quantity, metric : the record's names; ``metric`` may name ``{a}``, ``{b}`` (the two sides) and
        ``{n}`` (the number of frames compared).
    tolerance : the bound on max |a - b| / scale over the frames and particles.
    reason : why the bound is what it is.
    scale : a length (m) or a speed (m/s) the difference is divided by; None: the largest |b| over
        the frames compared (1 when that is 0), i.e. a relative difference.
    """

    key: str
    quantity: str
    metric: str
    tolerance: float
    reason: str
    scale: float | None = None


def frame_for_frame(label: str, *runs, frames, bounds=(), sides) -> tuple[list, dict]:
    """Runs seen at their frames only (positions, velocities, spins, forces, torques every dump; no
    stress series), frame by frame.

    Evidence first: every frame of ``frames`` (expected steps) present and whole on each run
    (:func:`validation.dem_compare.trajectory_evidence`). Then, for two runs ``a`` and ``b`` (the
    reference), each quantity of ``bounds`` (:class:`FrameBound`) over the expected frames both hold
    with the same particle count; none in common is NaN (fails). With one run only its evidence is
    recorded (a code's run whose column owes its evidence, judged against closed forms elsewhere).
    Returns (records, summary ``{quantity: value, "frames": compared}``)."""
    if len(runs) not in (1, 2) or len(sides) < len(runs):
        raise ValueError(f"frame_for_frame {label}: one or two runs, each named in sides")
    recs = []
    for who, tr in zip(sides, runs):
        recs += trajectory_evidence(label, who, tr, None, frames)
    summary = {"frames": 0}
    if len(runs) == 1:
        return recs, summary
    a, b = runs
    common = [
        int(s) for s in frames if s in a.frames and s in b.frames and len(a.frames[s]["x"]) == len(b.frames[s]["x"])
    ]
    summary["frames"] = len(common)
    for fb in bounds:
        if common:
            scale = fb.scale if fb.scale is not None else (peak(np.abs(b.frames[s][fb.key]) for s in common) or 1.0)
            value = peak(np.abs(a.frames[s][fb.key] - b.frames[s][fb.key]) for s in common) / scale  # NaN stays NaN
        else:
            value = math.nan
        summary[fb.quantity] = value
        metric = fb.metric.format(a=sides[0], b=sides[1], n=len(common))
        recs.append(compare(label, fb.quantity, metric, value, fb.tolerance, fb.reason))
    return recs, summary


# ====================================================================== explained measures
def explained_measures(
    label: str,
    a,
    b,
    nat_a,
    nat_b,
    *,
    expected,
    values,
    tolerance: float,
    reason: str,
    sides,
    absolute=(),
    agree=None,
    why: str = "",
    pair: str = "",
) -> tuple[list, dict]:
    """Two codes' answers to the same closed-form checks, their laws differing: measures (a contact
    time, a restitution, an exit slip of each impact) rather than trajectories, the analytic form of
    :func:`explained_difference`.

    expected : the ``(item, quantity)`` pairs each run answers; values : ``values(run) -> {(item,
    quantity): measured value}``. Per quantity, over its items (A, B the codes' values, nA, nB the
    native runs' in the two codes' arithmetic):

    * the raw difference max |A - B| / |A| (absolute for the quantities of ``absolute``: slips and
      spins that pass through zero), shown for the reader with ``why`` (default: the words of
      :func:`validation.codes.why_they_differ` for ``pair``);
    * the check that it is the two laws' difference and nothing else: max |(A - B) - (nA - nB)| / |A|
      at most ``tolerance`` (``reason``);
    * for the quantities of ``agree`` (``{quantity: Bound}``: both codes lie within the same
      analytic tolerance, so they differ by at most twice it), max |A - B| within the bound.

    A missing answer is NaN (the check fails). Returns (records, summary ``{quantity: {"raw",
    "unexplained"}}``)."""
    na, nb = sides
    got = [values(r) for r in (a, b, nat_a, nat_b)]
    quantities = list(dict.fromkeys(q for _, q in expected))
    why = why or why_they_differ(pair)
    recs, summary = [], {}
    for q in quantities:
        items = [it for it, qq in expected if qq == q]
        arr = np.array([[float(g.get((it, q), math.nan)) for g in got] for it in items], float).reshape(-1, 4)
        big = np.maximum(np.abs(arr[:, 0]), 1e-300)
        scale = np.ones_like(big) if q in absolute else big
        d = np.abs(arr[:, 0] - arr[:, 1]) / scale
        u = np.abs((arr[:, 0] - arr[:, 1]) - (arr[:, 2] - arr[:, 3])) / big
        raw = float(np.max(d)) if d.size and np.all(np.isfinite(d)) else math.nan
        un = float(np.max(u)) if u.size and np.all(np.isfinite(u)) else math.nan
        summary[q] = {"raw": raw, "unexplained": un}
        recs += [
            info(
                label,
                f"{q}: {na} - {nb}",
                "raw max difference (" + ("absolute" if q in absolute else "relative") + f" over {len(items)} items)",
                raw,
                why,
            ),
            compare(
                label,
                f"{q}: difference explained by the native flavours",
                f"max |({na} - {nb}) - (native {na.lower()} - native {nb.lower()})| / |value|",
                un,
                tolerance,
                reason,
            ),
        ]
        if agree and q in agree:
            recs.append(compare(label, f"{q}: {na} vs {nb}", f"max |{na} - {nb}| over items", raw, agree[q].tolerance,
                                agree[q].reason))  # fmt: skip
    return recs, summary
