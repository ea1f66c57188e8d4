"""Outputs: von Mises exact cases, VTU fields, HDF5 layout, Table 2, the CLI end to end (continuum)."""

import h5py
import meshio
import numpy as np
import pytest
from fem_helpers import SMALL_SLOPE, make_continuum

from gransim.cli import main
from gransim.errors import InputError
from gransim.fem.output import observed_orders, von_mises
from gransim.fem.run import run_slope_case
from gransim.fem.slope import setup_for


def test_von_mises_exact_cases():
    s = np.zeros((3, 2, 2))
    s[0, 0, 0] = -5.0  # uniaxial: |s|
    s[1, 0, 1] = s[1, 1, 0] = 2.0  # pure shear: sqrt(3) tau
    s[2] = 7.0 * np.eye(2)  # equibiaxial (sigma_33 = 0): |s|
    assert np.allclose(von_mises(s), [5.0, np.sqrt(3) * 2.0, 7.0])


def test_observed_orders_of_a_quadratic_sequence():
    e = np.array([1.0, 1e-2, 1e-4, 1e-8, 1e-16])
    assert np.allclose(observed_orders(e)[1:], 2.0)


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    out = tmp_path_factory.mktemp("slope")
    summary = run_slope_case("service", material=make_continuum("neo-hookean"), out=out, figures="final",
                             geometry=SMALL_SLOPE)
    return out, summary


def test_run_writes_every_step(case):
    out, summary = case
    assert summary["completed"]
    n_steps = len(setup_for("service").schedule())
    assert sorted(p.name for p in out.glob("step_*.vtu")) == [f"step_{k:03d}.vtu" for k in range(1, n_steps + 1)]
    for name in ("final.png", "load_settlement.png", "table2.md", "report.md", "slope.h5"):
        assert (out / name).stat().st_size > 0
    m = meshio.read(out / "step_021.vtu")
    assert [c.type for c in m.cells] == ["quad", "vertex"]
    G = 4 * SMALL_SLOPE.columns * SMALL_SLOPE.rows
    assert m.cell_data["von_mises"][1].shape == (G,) and m.cell_data["cauchy"][1].shape == (G, 6)
    assert m.point_data["displacement"].shape[1] == 3


def test_hdf5_layout_matches_schema(case):
    out, _ = case
    with h5py.File(out / "slope.h5") as f:
        assert f.attrs["kind"] == "fem-slope" and bool(f.attrs["completed"])
        g = f["steps/021"]
        G = f["mesh/gauss_points"].shape[0]
        for k, shape in (("F", (G, 2, 2)), ("cauchy", (G, 2, 2)), ("von_mises", (G,)), ("det_F", (G,)),
                         ("n_contacts", (G,))):
            assert g[k].shape == shape
        assert np.allclose(g.attrs["load"], [1.0, 1.0])
        # the stored Cauchy stress is P F^T / det F of the stored P and F
        P, F = g["piola"][()], g["F"][()]
        sig = np.einsum("giJ,gkJ->gik", P, F) / np.linalg.det(F)[:, None, None]
        assert np.allclose(sig, g["cauchy"][()])
        ls = f["load_settlement"][()]
        assert ls.shape == (len(setup_for("service").schedule()) + 1, 3)
        assert np.all(np.diff(ls[1:, 1]) > 0)  # the footing settles further with every load step


def test_table2_lists_the_paper_steps(case):
    _, summary = case
    table = summary["table"]
    assert table.splitlines()[0].split("|")[2:7] == [" step 2 ", " step 6 ", " step 10 ", " step 15 ", " step 18 "]
    assert "| 1 | 1.000E+00 |" in table


def test_cli_rejects_bad_input(capsys):
    with pytest.raises(SystemExit):
        main(["slope", "--protocol", "nonsense"])
    with pytest.raises(InputError, match="protocol"):
        setup_for("nonsense")


def test_acceptance_records_of_a_completed_run(case):
    from gransim.fem.run import acceptance_records

    recs = acceptance_records({"service": case[1]})
    checks = [r for r in recs if r["kind"] == "check"]
    assert {r["quantity"] for r in checks} == {"newton", "small load", "patch test"}
    assert all(r["pass"] for r in checks), checks
    # what only restates the run's own stopping rules is information, never a verdict
    info = {r["metric"] for r in recs if r["kind"] == "info"}
    assert info == {"completed (1 = yes)", "largest final relative energy norm"}


class _WrongTangent:
    """A material whose tangent is 20% off its stress derivative (an inconsistent linearisation)."""

    def __init__(self, base):
        self.base = base

    def evaluate(self, F):
        import dataclasses

        r = self.base.evaluate(F)
        return dataclasses.replace(r, tangent=0.8 * r.tangent)


def test_acceptance_checks_fail_for_an_inconsistent_tangent():
    """The same slope with a tangent 20% off: Newton loses its quadratic rate, the small-load
    solution no longer matches the linear one, so the checks fail (they are not a restatement of
    the solver's own convergence)."""
    from gransim.fem.run import acceptance_records

    s = run_slope_case("service", material=_WrongTangent(make_continuum("neo-hookean")), out=None,
                       figures="none", geometry=SMALL_SLOPE)
    bad = {(r["quantity"], r["metric"][:20]) for r in acceptance_records({"service": s})
           if r["kind"] == "check" and not r["pass"]}
    assert ("newton", "min over steps of th") in bad
    assert any(q == "small load" for q, _ in bad), bad


def test_cli_slope_end_to_end(tmp_path, capsys):
    """`gransim slope` on the full 380-element mesh with the continuum stand-in: exit 0, all outputs."""
    rc = main(["slope", "--material", "neo-hookean", "--figures", "none", "--out", str(tmp_path)])
    assert rc == 0
    assert "completed all 21 steps" in capsys.readouterr().out
    assert len(list(tmp_path.glob("step_*.vtu"))) == 21 and (tmp_path / "slope.h5").exists()
