"""The validation matrix: every declared cell needs a check; the report leads with its summary."""

from __future__ import annotations

import pytest

from validation.core import PAIRS, CaseResult, Record, compare, in_pair, info
from validation.report import matrix_html, write_html


def _res(case="c") -> CaseResult:
    return CaseResult(case, "title", "description")


def test_a_declared_cell_without_a_check_fails_the_case():
    res = _res()
    res.declare("native-liggghts", "bitwise")
    res.declare("native-lammps", "bitwise")
    res.records += in_pair([compare("c", "stress", "m", 0.0, 1e-8, "r")], "native-liggghts")
    assert res.cell("native-liggghts")["state"] == "pass"
    assert res.cell("native-lammps")["state"] == "empty"
    assert res.empty_cells == ["native-lammps"]
    assert not res.passed  # all its checks pass, but one cell has none
    res.records += in_pair([compare("c", "stress", "m", 0.0, 1e-8, "r")], "native-lammps")
    assert res.passed


def test_an_info_record_does_not_fill_a_cell():
    res = _res()
    res.declare("liggghts-lammps", "explained")
    res.records += in_pair([info("c", "stress", "raw", 3e-4, "shown")], "liggghts-lammps")
    res.records.append(compare("c", "other", "m", 0.0, 1.0, "r"))
    assert res.cell("liggghts-lammps")["state"] == "empty" and not res.passed


def test_a_failing_check_fails_its_cell_only():
    res = _res()
    for p in ("native-liggghts", "native-lammps"):
        res.declare(p, "why")
    res.records += in_pair([compare("c", "x", "m", 2.0, 1.0, "r")], "native-lammps")
    res.records += in_pair([compare("c", "x", "m", 0.5, 1.0, "r")], "native-liggghts")
    assert res.cell("native-lammps")["state"] == "FAIL"
    assert res.cell("native-liggghts")["state"] == "pass"
    assert res.cell("native-liggghts")["tolerances"] == [1.0]
    assert not res.passed


def test_not_applicable_cells_carry_their_reason_and_unknown_pairs_are_refused():
    res = _res()
    res.skip_pair("liggghts-lammps", "no code solves this")
    c = res.cell("liggghts-lammps")
    assert c["state"] == "n/a" and c["reason"] == "no code solves this"
    with pytest.raises(ValueError, match="pair"):
        res.declare("native-nosuchcode", "x")
    with pytest.raises(ValueError, match="pair"):
        Record("c", "q", "m", 0.0, 1.0, True, pair="lammps-nosuchcode")
    with pytest.raises(ValueError, match="pair"):
        in_pair([], "native")


def test_report_leads_with_its_summary_then_the_matrix(tmp_path):
    a, b = _res("alpha"), _res("beta")
    a.declare("native-lammps", "REASON-A")
    a.records += in_pair([compare("alpha", "x", "m", 0.0, 1e-10, "r")], "native-lammps")
    b.declare("native-liggghts", "REASON-B")  # declared, left empty
    b.skip_pair("liggghts-lammps", "REASON-NA")
    index = write_html(tmp_path, [a, b], {"liggghts_available": True, "lammps_available": False})
    text = index.read_text()
    m = text.index("Validation matrix")
    summary = text.index("<h2>Summary</h2>")
    assert text.index("LAMMPS is not installed") < summary < m  # the answer first, the matrix next
    assert "1 of 2 cases FAIL: beta" in text[summary:m]  # beta's declared cell holds no check
    for word in ("REASON-A", "REASON-B", "REASON-NA", "FAIL: no check", "1.000e-10"):
        assert word in text, word
    rows = "".join(matrix_html([a, b]))
    assert rows.count("<tr>") == 3  # header + one row per case
    for label in PAIRS.values():
        assert label in rows
