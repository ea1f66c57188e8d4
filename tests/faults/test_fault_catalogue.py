"""The report's list of injected faults names only tests that exist (it cannot drift from the suite)."""

from __future__ import annotations

import ast
from pathlib import Path

from validation.faults import FAULT_KINDS

REPO = Path(__file__).resolve().parents[2]


def _tests(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    return {n.name for n in tree.body if isinstance(n, ast.FunctionDef) and n.name.startswith("test_")}


def test_every_fault_names_an_existing_test():
    assert len(FAULT_KINDS) >= 20
    for k in FAULT_KINDS:
        file, name = k.test.split("::")
        assert (REPO / file).is_file(), k
        assert name in _tests(REPO / file), k
        assert k.fault and k.outcome


def test_the_report_lists_the_faults(tmp_path):
    from validation.core import CaseResult, compare
    from validation.report import write_html

    res = CaseResult("x", "x", "x", records=[compare("x", "q", "m", 0.0, 1.0, "r")])
    html = write_html(tmp_path, [res], {"liggghts_available": True}).read_text()
    for k in FAULT_KINDS:
        assert k.test in html
