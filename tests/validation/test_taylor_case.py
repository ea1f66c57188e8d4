"""taylor-rve as a declaration (validation.cases.taylor.taylor_plan): with the codes absent, each
code's stored outputs stand in for its live jobs, every column is filled, and the records keep one
label per RVE, path and route (``taylor-rve/<code>/<RVE>/<path>/<route>``, the contacts
``.../<path>/k<k>``, the two codes ``taylor-rve/liggghts-lammps/...``; YADE's
``taylor-rve/yade/<RVE>/<path>``, tests/validation/test_yade_columns.py)."""

from __future__ import annotations

import re

import validation.runner as vrunner
from validation.runner import run_validation


def test_stored_outputs_stand_in_and_the_labels_name_code_rve_path_route(tmp_path, monkeypatch):
    monkeypatch.setattr(vrunner, "liggghts_available", lambda: False)
    monkeypatch.setattr(vrunner, "lammps_available", lambda: False)
    monkeypatch.setattr(vrunner, "_available", lambda code: False)
    ok, results = run_validation("quick", tmp_path / "results", only=["taylor-rve"], log=lambda *a: None)
    (res,) = results
    assert ok and res.passed, [r for r in res.records if not r.passed]
    assert {p: res.cell(p)["state"] for p in res.matrix} == {
        "native-liggghts": "pass",
        "native-lammps": "pass",
        "liggghts-lammps": "pass",
        "native-yade": "pass",
    }
    # states and contacts of LIGGGHTS and LAMMPS, YADE's states
    assert sum("stored output" in n and "compared instead" in n for n in res.notes) == 5
    stress = [r.case for r in res.checks if r.quantity == "stress" and r.pair != "native-yade"]
    code_rx = re.compile(r"^taylor-rve/(liggghts|lammps)/[\w.-]+/(compression|shear)(11|22|12|21)/(images|periodic)$")
    cross_rx = re.compile(r"^taylor-rve/liggghts-lammps/[\w.-]+/(compression|shear)(11|22|12|21)/(images|periodic)$")
    assert stress and all(code_rx.match(c) or cross_rx.match(c) for c in stress), stress
    assert any(cross_rx.match(c) for c in stress) and any(code_rx.match(c) for c in stress)
    forces = [r.case for r in res.checks if r.quantity == "contact_force"]
    assert forces and all(re.match(r"^taylor-rve/(liggghts|lammps)/[\w.-]+/\w+/k\d+$", c) for c in forces), forces
    assert all(r.pair == "native-liggghts" for r in res.records if r.case.startswith("taylor-rve/liggghts/"))
