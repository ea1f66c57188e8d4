"""Data model of a validation run: records, case results, the case registry."""

from __future__ import annotations

import dataclasses
import math
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from reference_runs import store
from reference_runs.judge import finite_problem, peak, verdict_problem, within  # noqa: F401 (peak: for the cases)
from reference_runs.runner import verify_job

from .codes import pair_codes, pairs

SUITES = ("quick", "default", "full")
#: default per-job timeout: a constant (start-up, set-up, output) plus a cost per particle-step.
#: LIGGGHTS 3.8.0 runs ~6 M particle-steps/s serially here (docs/dem.md, make bench): 3e-6 s per
#: particle-step is ~20x that, so a healthy job never meets the default.
JOB_TIMEOUT_BASE = 120.0
JOB_TIMEOUT_PER_PSTEP = 3e-6


@dataclass(frozen=True)
class Record:
    """One compared quantity.

    ``case`` is a case id optionally followed by a suffix (``taylor-rve/700-3/shear12``);
    ``metric`` names how ``value`` was computed (e.g. ``max_rel_diff``); ``passed`` is
    ``value <= tolerance`` unless the case states another rule in ``reason``. Whatever the rule, a
    check whose value or tolerance is NaN or inf (or whose tolerance is negative) is a failure:
    ``passed`` is forced to False and the metric names the problem (``... [FAIL: stress is NaN]``).

    ``kind`` is ``"check"`` (a verdict against something independent: the other code, an exact
    or analytic value, a bound) or ``"info"`` (a figure shown for the reader, never a verdict:
    :func:`info`). Only checks decide whether a case passes.
    """

    case: str
    quantity: str
    metric: str
    value: float
    tolerance: float
    passed: bool
    reason: str = ""
    kind: str = "check"
    pair: str = ""  # cell of the validation matrix (a key of PAIRS), "" for checks outside it

    def __post_init__(self):
        if self.kind not in RECORD_KINDS:
            raise ValueError(f"Record.kind: expected one of {RECORD_KINDS}, got {self.kind!r}")
        if self.pair and self.pair not in PAIRS:
            raise ValueError(f"Record.pair: expected one of {tuple(PAIRS)}, got {self.pair!r}")
        if self.kind == "check" and "[FAIL: " not in self.metric:
            # whatever rule set ``passed``, a check never passes on a NaN or inf value or tolerance
            # (``nan <= tol`` is False but ``not nan > tol`` is True; max() drops a NaN after a number)
            problem = verdict_problem(self.value, self.tolerance, self.quantity)
            if problem:
                object.__setattr__(self, "passed", False)
                object.__setattr__(self, "metric", f"{self.metric} [FAIL: {problem}]")

    @property
    def verdict(self) -> str:
        """``"pass"``, ``"FAIL"`` or ``"info"``."""
        if self.kind == "info":
            return "info"
        return "pass" if self.passed else "FAIL"

    def to_json(self) -> dict:
        v = self.value if math.isfinite(self.value) else str(self.value)
        t = self.tolerance if math.isfinite(self.tolerance) else str(self.tolerance)
        return {
            "case": self.case,
            "quantity": self.quantity,
            "metric": self.metric,
            "value": v,
            "tolerance": t,
            "pass": bool(self.passed) if self.kind == "check" else None,
            "kind": self.kind,
            "pair": self.pair,
            "reason": self.reason,
        }


RECORD_KINDS = ("check", "info")

#: the columns of the validation matrix: which two implementations a check sets against each other
#: (native vs each code of validation.codes.CODES, then each two codes)
PAIRS = pairs()
#: the reference codes (engines) a pair involves
PAIR_CODES = {p: pair_codes(p) for p in PAIRS}


def in_pair(records, pair: str) -> list:
    """The records with their matrix cell set to ``pair`` (a key of :data:`PAIRS`)."""
    if pair not in PAIRS:
        raise ValueError(f"pair: expected one of {tuple(PAIRS)}, got {pair!r}")
    return [dataclasses.replace(r, pair=pair) for r in records]


def default_job_timeout(particle_steps: float) -> float:
    """The default timeout (s) of a reference job of ``particle_steps`` (particles x steps):
    ``JOB_TIMEOUT_BASE + JOB_TIMEOUT_PER_PSTEP * particle_steps``."""
    return JOB_TIMEOUT_BASE + JOB_TIMEOUT_PER_PSTEP * float(particle_steps)


def compare(case: str, quantity: str, metric: str, value: float, tolerance: float, reason: str, inputs=None) -> Record:
    """A record that passes when ``value <= tolerance``, both finite (and the tolerance >= 0).

    A NaN or inf value or tolerance fails (:func:`reference_runs.judge.within`), and the metric
    then says why, naming the quantity: ``max_rel_diff [stress is NaN]``. ``inputs``: optional
    ``{side: array}`` the value was computed from (e.g. ``{"native": a, "LIGGGHTS": b}``); the
    first side holding a NaN or inf is named (``stress (LIGGGHTS) is NaN at entry 3``) and the
    record fails even if the value itself came out finite (a ``max`` that dropped the NaN).
    """
    try:
        value = float(value)
    except (TypeError, ValueError):
        value = math.nan
    try:
        tol = float(tolerance)
    except (TypeError, ValueError):
        tol = math.nan
    problem = next((p for side, arr in (inputs or {}).items() if (p := finite_problem(arr, quantity, side))), None)
    if problem:
        return Record(case, quantity, f"{metric} [FAIL: {problem}]", value, tol, False, reason)
    return Record(case, quantity, metric, value, tol, within(value, tol), reason)  # NaN, inf: named by Record


def info(case: str, quantity: str, metric: str, value: float, reason: str) -> Record:
    """A figure reported for the reader, not a verdict (no tolerance; never counts as a pass)."""
    return Record(case, quantity, metric, float(value), float("nan"), True, reason, kind="info")


def evidence(case: str, what: str, expected, got, reason: str = "") -> Record:
    """The record of one piece of evidence: ``got`` of the ``expected`` items (steps, frames,
    contacts, states, runs) were present. Fails, named ``incomplete: expected N what, got M``,
    unless every expected item is there.

    ``expected`` and ``got`` are counts, or collections of item labels (then the missing ones
    are named in the metric).
    """
    if isinstance(expected, int | np.integer) and isinstance(got, int | np.integer):
        n_exp, n_got, missing = int(expected), int(got), []
    else:
        exp, have = list(expected), set(got)
        missing = [e for e in exp if e not in have]
        n_exp, n_got = len(exp), len(exp) - len(missing)
    short = max(0, n_exp - n_got)
    if short or n_exp == 0:
        metric = f"incomplete: expected {n_exp} {what}, got {n_got}"
        if missing:
            shown = ", ".join(str(m) for m in missing[:8]) + (" ..." if len(missing) > 8 else "")
            metric += f" (missing: {shown})"
        if n_exp == 0:
            metric = f"incomplete: no {what} expected or found (nothing to compare)"
    else:
        metric = f"complete: {n_got} of {n_exp} {what}"
    return Record(
        case,
        "evidence",
        metric,
        float(short if n_exp else 1),
        0.0,
        short == 0 and n_exp > 0,
        reason
        or "a comparison is only as good as its evidence: every expected item must be present "
        "on both sides (a truncated log, a cut dump or a dropped contact is a failure, "
        "never a pass on what remains)",
    )


@dataclass
class CaseResult:
    """What a case produced: records (pass/fail), figures, tables and prose for the report."""

    case: str
    title: str
    description: str
    records: list[Record] = field(default_factory=list)
    figures: list[tuple[Path, str]] = field(default_factory=list)  # (png path, caption)
    tables: list[tuple[str, list[str], list[list]]] = field(default_factory=list)  # (caption, header, rows)
    notes: list[str] = field(default_factory=list)
    error: str | None = None  # set when the case could not run: counts as a failure
    #: cells of the validation matrix this case owes: pair -> why its tolerances are what they are
    matrix: dict[str, str] = field(default_factory=dict)
    #: cells that do not apply to this case: pair -> why not
    not_applicable: dict[str, str] = field(default_factory=dict)
    #: figure path (str) -> the data file it was drawn from (linked beside the figure in the report)
    figure_data: dict[str, Path] = field(default_factory=dict)
    #: figure paths (str) shown in the report's one-screen summary (its headline figures)
    headline: list[str] = field(default_factory=list)
    #: wall time of the case (s), set by the runner
    seconds: float | None = None
    #: the runs a declared case made or left out: (run, code, arithmetic, source, status) rows
    #: (validation.matrix.evaluate), shown in the report
    runs: list = field(default_factory=list)

    def add_figure(self, path, caption: str, data=None, headline: bool = False) -> Path:
        """Add a figure with ``caption``; ``data``: the file it was drawn from (HDF5, CSV, JSON),
        linked beside it in the report; ``headline``: also shown in the report's summary."""
        path = Path(path)
        self.figures.append((path, caption))
        if data is not None:
            self.figure_data[str(path)] = Path(data)
        if headline:
            self.headline.append(str(path))
        return path

    def worst_check(self) -> Record | None:
        """The check closest to (or furthest past) its tolerance: the largest value / tolerance
        among checks with a finite positive tolerance (failing checks first), else the first
        failing check, else None."""
        checks = self.checks
        failing = [r for r in checks if not r.passed]
        pool = failing or checks
        ratios = [
            (abs(r.value) / r.tolerance, i)
            for i, r in enumerate(pool)
            if math.isfinite(r.value) and math.isfinite(r.tolerance) and r.tolerance > 0
        ]
        if ratios:
            return pool[max(ratios)[1]]
        return failing[0] if failing else None

    def declare(self, pair: str, reason: str) -> None:
        """This case owes the matrix cell ``pair``: it fails unless at least one check of that
        pair is recorded (a declared cell left empty is missing evidence, not a pass)."""
        if pair not in PAIRS:
            raise ValueError(f"pair: expected one of {tuple(PAIRS)}, got {pair!r}")
        self.matrix[pair] = reason
        self.not_applicable.pop(pair, None)

    def skip_pair(self, pair: str, reason: str) -> None:
        """The matrix cell ``pair`` does not apply to this case (shown with ``reason``)."""
        if pair not in PAIRS:
            raise ValueError(f"pair: expected one of {tuple(PAIRS)}, got {pair!r}")
        if pair not in self.matrix:
            self.not_applicable[pair] = reason

    def skip_code(self, code: str, reason: str) -> None:
        """Every matrix column of ``code`` (native against it and it against each other code) that
        this case has not declared does not apply, for ``reason`` (a case without a run of that code)."""
        for pair in PAIRS:
            if code in pair.split("-") and pair not in self.matrix:
                self.skip_pair(pair, reason)

    @property
    def checks(self) -> list[Record]:
        """The records that are verdicts (``kind == "check"``)."""
        return [r for r in self.records if r.kind == "check"]

    def pair_checks(self, pair: str) -> list[Record]:
        return [r for r in self.checks if r.pair == pair]

    @property
    def empty_cells(self) -> list[str]:
        """Declared matrix cells without a single check."""
        return [p for p in self.matrix if not self.pair_checks(p)]

    @property
    def passed(self) -> bool:
        """No error, at least one check, every check passed (info records do not count), and
        every declared matrix cell holds at least one check."""
        checks = self.checks
        return self.error is None and bool(checks) and all(r.passed for r in checks) and not self.empty_cells

    def cell(self, pair: str) -> dict:
        """One cell of the validation matrix: ``state`` ("pass", "FAIL", "empty", "n/a", "absent"),
        the counts, the tolerances used and the reason."""
        if pair in self.not_applicable:
            return {"state": "n/a", "reason": self.not_applicable[pair], "n": 0, "ok": 0, "tolerances": []}
        if pair not in self.matrix:
            return {"state": "absent", "reason": "", "n": 0, "ok": 0, "tolerances": []}
        rs = self.pair_checks(pair)
        tols = sorted({r.tolerance for r in rs if r.quantity != "evidence" and math.isfinite(r.tolerance)})
        ok = sum(r.passed for r in rs)
        state = "empty" if not rs else ("pass" if ok == len(rs) else "FAIL")
        return {"state": state, "reason": self.matrix[pair], "n": len(rs), "ok": ok, "tolerances": tols}


@dataclass(frozen=True)
class Context:
    """Where a validation run reads and writes, and what it may use."""

    suite: str
    results: Path  # results/ root
    jobs: int = 1
    liggghts: bool = False  # binary available?
    lammps: bool = False  # `lmp` available?
    timeout: float | None = None  # s per reference job (None: scaled with the job's work)
    #: the codes of validation.codes.CODES installed here (besides the two flags above)
    available: frozenset = frozenset()
    #: the worker pool the cases' background work shares (``Case.prefetch``: ``jobs - 1`` threads,
    #: each running a code process or a native run, first submitted first run), made and shut down
    #: by the runner; None: a case's prefetch makes a pool of its own, or starts nothing
    background: object = field(default=None, compare=False)

    def has(self, code: str) -> bool:
        """Whether the reference code ``code`` (a name of validation.codes.CODES) is installed."""
        return code in self.available or bool(getattr(self, code, False))

    def job_timeout(self, particle_steps: float) -> float:
        """Seconds a reference job of ``particle_steps`` (particles x steps, summed over its runs)
        may take before it is killed: ``--timeout`` when given, else
        ``JOB_TIMEOUT_BASE + JOB_TIMEOUT_PER_PSTEP * particle_steps`` (about 20 times LIGGGHTS'
        serial speed on this kind of machine, so only a hung or runaway job reaches it)."""
        if self.timeout is not None:
            return float(self.timeout)
        return default_job_timeout(particle_steps)

    @property
    def report_dir(self) -> Path:
        return self.results / "report"

    def work(self, *parts) -> Path:
        p = self.results.joinpath(*parts)
        p.mkdir(parents=True, exist_ok=True)
        return p

    def figure_path(self, name: str) -> Path:
        d = self.report_dir / "figures"
        d.mkdir(parents=True, exist_ok=True)
        return d / name

    def copy_figure(self, src, name: str) -> Path:
        """Copy a figure a computation wrote elsewhere into the report (as figures/<name>)."""
        dest = self.figure_path(name)
        dest.write_bytes(Path(src).read_bytes())
        return dest


@dataclass(frozen=True)
class Case:
    id: str
    title: str
    suites: tuple[str, ...]
    func: Callable[[Context], CaseResult]
    order: int
    #: starts the case's long background work (reference jobs) at the beginning of a run, so that
    #: it overlaps the cases before it; the case collects it (None: nothing to start early)
    prefetch: Callable[[Context], None] | None = None
    #: cancels what ``prefetch`` started and the case did not collect (a run that ends early)
    cancel: Callable[[], None] | None = None
    #: ids of the cases whose runs this case reads (from their caches): it waits for their work, so
    #: a run with a background pool makes it after them (validation.runner.execution_order)
    uses: tuple[str, ...] = ()


_REGISTRY: dict[str, Case] = {}


def case(case_id: str, title: str, suites=SUITES, order: int = 100, prefetch=None, cancel=None, uses=()):
    """Register a validation case (decorator); ``prefetch``/``cancel``/``uses``: :class:`Case`."""

    def deco(func):
        _REGISTRY[case_id] = Case(case_id, title, tuple(suites), func, order, prefetch, cancel, tuple(uses))
        return func

    return deco


def registered_cases(suite: str) -> list[Case]:
    # lazy: cycle with validation.cases (each case module imports validation.core at its top)
    from . import cases  # noqa: F401  (imports register the cases)

    return sorted((c for c in _REGISTRY.values() if suite in c.suites), key=lambda c: (c.order, c.id))


def stored_dir(name: str) -> Path:
    """Directory of a stored reference job (``reference_runs/stored/<name>``), looked up at call
    time so that the fault tests can point the cases at a damaged copy."""
    return Path(store.STORED) / name


def stored_job_record(label: str, job_dir) -> Record:
    """Evidence record of a stored reference job: :func:`reference_runs.runner.verify_job` on its
    directory (runs, last steps and dump frames against its own deck; hashes where a manifest has
    them). Fails, listing the problems, when the stored job is incomplete or was edited."""
    problems = verify_job(job_dir)
    metric = (
        "stored job verified against its deck"
        if not problems
        else "incomplete stored job: " + "; ".join(str(p) for p in problems[:3]) + (" ..." if len(problems) > 3 else "")
    )
    return Record(
        label,
        "evidence",
        metric,
        float(len(problems)),
        0.0,
        not problems,
        "a stored reference counts only if it holds every run, step and frame its deck asked for "
        "(reference_runs.runner.verify_job)",
    )


def liggghts_available() -> bool:
    return shutil.which("liggghts") is not None


def lammps_available() -> bool:
    return shutil.which("lmp") is not None


def replace(obj, **kw):
    return dataclasses.replace(obj, **kw)
