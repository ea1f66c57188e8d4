"""Data model of a validation run: records, case results, the case registry."""

from __future__ import annotations

import dataclasses
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

SUITES = ("quick", "default", "full")


@dataclass(frozen=True)
class Record:
    """One compared quantity.

    ``case`` is a case id optionally followed by a suffix (``taylor-rve/700-3/shear12``);
    ``metric`` names how ``value`` was computed (e.g. ``max_rel_diff``); ``passed`` is
    ``value <= tolerance`` unless the case states another rule in ``reason``.
    """

    case: str
    quantity: str
    metric: str
    value: float
    tolerance: float
    passed: bool
    reason: str = ""

    def to_json(self) -> dict:
        v = self.value if math.isfinite(self.value) else str(self.value)
        return {"case": self.case, "quantity": self.quantity, "metric": self.metric, "value": v,
                "tolerance": self.tolerance, "pass": bool(self.passed), "reason": self.reason}


def compare(case: str, quantity: str, metric: str, value: float, tolerance: float, reason: str) -> Record:
    """A record that passes when ``value <= tolerance`` (NaN fails)."""
    value = float(value)
    return Record(case, quantity, metric, value, float(tolerance),
                  bool(math.isfinite(value) and value <= tolerance), reason)


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

    @property
    def passed(self) -> bool:
        return self.error is None and bool(self.records) and all(r.passed for r in self.records)


@dataclass(frozen=True)
class Context:
    """Where a validation run reads and writes, and what it may use."""

    suite: str
    results: Path  # results/ root
    jobs: int = 1
    liggghts: bool = False  # binary available?

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


_REGISTRY: dict[str, Case] = {}


def case(case_id: str, title: str, suites=SUITES, order: int = 100):
    """Register a validation case (decorator)."""

    def deco(func):
        _REGISTRY[case_id] = Case(case_id, title, tuple(suites), func, order)
        return func

    return deco


def registered_cases(suite: str) -> list[Case]:
    from . import cases  # noqa: F401  (imports register the cases)

    return sorted((c for c in _REGISTRY.values() if suite in c.suites), key=lambda c: (c.order, c.id))


def liggghts_available() -> bool:
    return shutil.which("liggghts") is not None


def replace(obj, **kw):
    return dataclasses.replace(obj, **kw)
