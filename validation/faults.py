"""The fault kinds ``tests/faults`` injects, listed in the report.

A verdict is worth something only if it can fail. Each entry names a fault (a broken reference
code, cut evidence, a perturbed native path, bad input), the outcome the suite requires (a
failing verdict or a clear error, never a pass, and no process left behind), and the test that
shows it (``tests/faults/<file>::<test>``; ``tests/faults/test_fault_catalogue.py`` checks that
every test named here exists).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FaultKind:
    fault: str
    outcome: str
    test: str


FAULT_KINDS: tuple[FaultKind, ...] = ()
