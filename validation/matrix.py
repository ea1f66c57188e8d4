"""Cases as declarations: the runs a case makes and the comparisons between them.

A case lists its runs (:class:`Run`: native in a code's arithmetic, a code from a deck, a code's
stored output) and the comparisons between them (:class:`Comparison`, by kind: a key of
:data:`JUDGES`). :func:`evaluate` makes each run once (when first needed), hands the runs of each
comparison to its judge (:mod:`validation.judges`), files the records in the matrix column of the
two runs' codes (:func:`validation.codes.pair_key`) and declares that column with the
comparison's reason. A run of a code that is not installed is not made: its stored output stands in
for it where the case declares one (``Run.fallback``), else its comparisons are left out with a
note, and a column left without any comparison is marked not applicable, saying why.

A comparison of one run (a run against closed forms: :func:`validation.judges.analytic`) or of two
runs of one code files its records outside the matrix, among the case's other checks, unless it
names its column (``Comparison.pair``).

So a case states what it compares, and adding a code adds its runs to the case's list: the
comparisons and columns follow from the same rules (see validation/cases/biaxial.py, ``short_plan``).
"""

from __future__ import annotations

import dataclasses
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field

from .codes import NATIVE, code_label, pair_key
from .core import PAIRS, CaseResult, Context, Record, in_pair, stored_job_record
from .judges import (
    analytic,
    cell_lists,
    chaos_envelope,
    ensemble_cross,
    ensemble_envelope,
    equilibria,
    explained_difference,
    explained_measures,
    final_state,
    frame_for_frame,
    same_states,
    statistics_band,
    statistics_cross,
    step_for_step,
    taylor_contacts,
    taylor_cross,
    taylor_stress,
    taylor_yade,
)

#: the judges a comparison can name (kind -> function(label, *runs, **params) -> (records, summary))
JUDGES = {
    "analytic": analytic,
    "step": step_for_step,
    "same": same_states,
    "final": final_state,
    "explained": explained_difference,
    "measures": explained_measures,
    "frames": frame_for_frame,
    "cells": cell_lists,
    "envelope": chaos_envelope,
    "statistics": statistics_band,
    "statistics_cross": statistics_cross,
    "ensemble": ensemble_envelope,
    "ensemble_cross": ensemble_cross,
    "taylor_stress": taylor_stress,
    "taylor_contacts": taylor_contacts,
    "taylor_cross": taylor_cross,
    "taylor_yade": taylor_yade,
    "equilibria": equilibria,
}


@dataclass(frozen=True)
class Run:
    """One run of a case.

    key : unique within the case (``"stored-120/lammps"``, ``"native/stored-120/lammps"``).
    code : ``"native"`` or a code of :data:`validation.codes.CODES` (who computed it).
    arithmetic : the code whose floating-point operations a native run repeats
        (``DEMSettings.flavour``); for a code's own run, the code itself.
    source : where the evidence comes from, in words (shown in the report's run table).
    make : produces the run (a :class:`validation.dem_compare.Trajectory`); called once.
    live : the run needs its code installed (a deck run now); a stored output does not.
    verify : optional ``verify(label, run) -> [records]``: evidence about the run itself (a stored
        job verified against its deck), filed with the first comparison that uses the run.
    fallback : for a live run, the key of the run (a stored output of the same code) compared in
        its place when the code is not installed; None: its comparisons are left out then.
    """

    key: str
    code: str
    arithmetic: str
    source: str
    make: Callable[[], object]
    live: bool = False
    verify: Callable[[str, object], list] | None = None
    fallback: str | None = None

    @property
    def who(self) -> str:
        """The run's side name in records: ``native`` or the code's display name."""
        return NATIVE if self.code == NATIVE else code_label(self.code)


@dataclass(frozen=True)
class Comparison:
    """One comparison of two (or more) runs by a shared judge.

    kind : a key of :data:`JUDGES` (``step``, ``explained``, ``analytic``, ...).
    label : the records' case label (``biaxial-short/stored-120/lammps``).
    runs : keys of the runs, in the judge's order (one run or more).
    reason : why this comparison's tolerances are what they are (the column's declared reason).
    params : the judge's keyword arguments (bounds, expected steps and frames, ...), or a callable
        returning them, called when the comparison is judged (after its runs are made: a D50 of a
        packing the runs generate).
    view : optional ``view(run) -> object``: how the judge sees each run (the calls of an RVE as a
        :class:`validation.dem_compare.Trajectory` for the step judge); None: the run itself.
    pair : the matrix column its records go to: None (default) the column of the first two runs'
        codes when they differ, else ``""``: outside the matrix, among the case's other checks (a
        run against closed forms, two runs of one code); or a column named explicitly (a code's
        run against closed forms whose evidence that code's column owes).
    """

    kind: str
    label: str
    runs: tuple[str, ...]
    reason: str
    params: dict | Callable[[], dict] = field(default_factory=dict)
    view: Callable[[object], object] | None = None
    pair: str | None = None

    def __post_init__(self):
        if self.kind not in JUDGES:
            raise ValueError(f"Comparison.kind: expected one of {tuple(JUDGES)}, got {self.kind!r}")
        if not self.runs:
            raise ValueError(f"comparison {self.label}: no run to judge")
        if self.pair and self.pair not in PAIRS:
            raise ValueError(f"Comparison.pair: expected one of {tuple(PAIRS)} or '', got {self.pair!r}")

    def column(self, codes: tuple[str, ...]) -> str:
        """The matrix column of the comparison, given its runs' codes (see ``pair``)."""
        if self.pair is not None:
            return self.pair
        if len(codes) >= 2 and codes[0] != codes[1]:
            return pair_key(codes[0], codes[1])
        return ""


@dataclass(frozen=True)
class Failed:
    """What a run's ``make`` returns when its job failed or its output cannot be read (``why``, in
    words): every comparison of that run then records failing evidence naming the run and why,
    instead of a verdict, and the case goes on with its other comparisons."""

    why: str


def stored_job(job_dir) -> Callable[[str, object], list]:
    """The ``verify`` of a run read from a stored job directory: the job checked against its own
    deck (:func:`validation.core.stored_job_record`: every run, step and frame it asked for)."""

    def verify(label: str, _run) -> list:
        return [stored_job_record(label, job_dir)]

    return verify


@dataclass
class Outcome:
    """What :func:`evaluate` made: the runs (key -> trajectory; :meth:`run` resolves a stand-in), the
    summary of every comparison made (label -> the judge's summary) and the comparisons left out
    (label -> why)."""

    runs: dict = field(default_factory=dict)
    summaries: dict = field(default_factory=dict)
    skipped: dict = field(default_factory=dict)
    #: live run key -> the key of the stored run compared in its place (its code absent)
    stand_in: dict = field(default_factory=dict)
    #: (label, kind) -> the judge's summary (comparisons of one label by different judges)
    by_kind: dict = field(default_factory=dict)

    def run(self, key: str):
        """The run made for ``key``: the run itself, or the stored run that stood in for it."""
        return self.runs[self.stand_in.get(key, key)]


def evaluate(res: CaseResult, ctx: Context, runs: list[Run], comparisons: list[Comparison]) -> Outcome:
    """Make the runs, judge the comparisons, file the records in their matrix columns (declared
    with each comparison's reason) and return the :class:`Outcome`.

    A live run of a code not installed is not made: its stored stand-in (``Run.fallback``) is
    compared instead, or else its comparisons are left out (a note says which) and a column that
    thereby has no comparison at all is marked not applicable. A run whose ``make`` returns
    :class:`Failed` gives each of its comparisons a failing evidence record; a run that raises
    raises out of here: the case did not run."""
    by_key = {r.key: r for r in runs}
    if len(by_key) != len(runs):
        raise ValueError("Run.key: two runs of the case share a key")
    out = Outcome()
    verified: set[str] = set()
    absent = [r for r in runs if r.live and r.code != NATIVE and not ctx.has(r.code)]
    for r in absent:
        instead = f"; its stored output {r.fallback} is compared instead" if r.fallback else ""
        res.notes.append(f"{code_label(r.code)} is absent: the run {r.key} ({r.source}) is not made{instead}.")
    missing = {r.key for r in absent if not r.fallback}
    stand_in = {r.key: r.fallback for r in absent if r.fallback}
    out.stand_in = dict(stand_in)
    pairs_made, pairs_left = set(), {}
    for c in comparisons:
        unknown = [k for k in (*c.runs, *stand_in.values()) if k not in by_key]
        if unknown:
            raise ValueError(f"comparison {c.label}: no run {unknown[0]!r} declared")
        c = dataclasses.replace(c, runs=tuple(stand_in.get(k, k) for k in c.runs))
        pair = c.column(tuple(by_key[k].code for k in c.runs))
        gone = [k for k in c.runs if k in missing]
        if gone:
            why = f"{code_label(by_key[gone[0]].code)} is not installed ({gone[0]} not made)"
            out.skipped[c.label] = why
            if pair:
                pairs_left.setdefault(pair, why)
            continue
        for k in c.runs:
            if k not in out.runs:
                out.runs[k] = by_key[k].make()
        recs = []
        failed = [k for k in c.runs if isinstance(out.runs[k], Failed)]
        if failed:
            got = [
                Record(c.label, "evidence", f"incomplete: {by_key[k].who} ({k}): {out.runs[k].why}", 1.0, 0.0, False)
                for k in failed
            ]
            _file(res, pair, c.reason, got, pairs_made)
            continue
        for k in c.runs:
            if by_key[k].verify is not None and k not in verified:
                verified.add(k)
                recs += by_key[k].verify(c.label, out.runs[k])
        kw = {"sides": tuple(by_key[k].who for k in c.runs[:2]), **(c.params() if callable(c.params) else c.params)}
        takes = inspect.signature(JUDGES[c.kind]).parameters
        if "pair" in takes:
            kw.setdefault("pair", pair)
        if "reason" in takes:  # a judge that states why its tolerance is what it is: the comparison's reason
            kw.setdefault("reason", c.reason)
        view = c.view or (lambda run: run)
        got, summary = JUDGES[c.kind](c.label, *(view(out.runs[k]) for k in c.runs), **kw)
        _file(res, pair, c.reason, recs + got, pairs_made)
        out.summaries[c.label] = summary
        out.by_kind[(c.label, c.kind)] = summary
    for pair, why in pairs_left.items():
        if pair not in pairs_made:
            res.skip_pair(pair, f"{why}, and no stored output of it is compared")
    for r in runs:
        if r.key in out.runs and isinstance(out.runs[r.key], Failed):
            status = f"failed: {out.runs[r.key].why}"
        elif r.key in out.runs:
            status = "made"
        elif r.key in stand_in:
            status = f"not made ({code_label(r.code)} absent): {stand_in[r.key]} compared instead"
        elif r.key in missing:
            status = f"not made ({code_label(r.code)} absent)"
        else:
            status = "not needed"
        res.runs.append((r.key, r.who, code_label(r.arithmetic) if r.arithmetic else "", r.source, status))
    return out


def _file(res: CaseResult, pair: str, reason: str, records: list, pairs_made: set) -> None:
    """File ``records`` in the matrix column ``pair`` (declared with ``reason``), or among the
    case's other checks when ``pair`` is ``""``."""
    if pair:
        res.declare(pair, res.matrix.get(pair) or reason)
        res.records += in_pair(records, pair)
        pairs_made.add(pair)
    else:
        res.records += records
