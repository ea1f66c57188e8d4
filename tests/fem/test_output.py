"""Outputs: von Mises exact cases, VTU fields, equilibrium of the stored stress, Table 2, the CLI."""

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
    summary = run_slope_case(
        "service", material=make_continuum("neo-hookean"), out=out, figures="final", geometry=SMALL_SLOPE
    )
    return out, summary


@pytest.fixture(scope="module")
def case_all(tmp_path_factory):
    out = tmp_path_factory.mktemp("slope_all")
    summary = run_slope_case(
        "service", material=make_continuum("neo-hookean"), out=out, figures="all", geometry=SMALL_SLOPE, load_steps=2
    )
    return out, summary


def test_figures_all_writes_every_step(case_all):
    out, summary = case_all
    assert summary["completed"]
    n_steps = len(setup_for("service", load_steps=2).schedule())
    for ext in ("vtu", "png"):
        assert sorted(p.name for p in out.glob(f"step_*.{ext}")) == [
            f"step_{k:03d}.{ext}" for k in range(1, n_steps + 1)
        ]
    m = meshio.read(out / f"step_{n_steps:03d}.vtu")
    assert [c.type for c in m.cells] == ["quad", "vertex"]
    G = 4 * SMALL_SLOPE.columns * SMALL_SLOPE.rows
    assert m.cell_data["von_mises"][1].shape == (G,) and m.cell_data["cauchy"][1].shape == (G, 6)
    assert m.point_data["displacement"].shape[1] == 3


def test_figures_final_writes_the_last_state_only(case):
    """The default: no per-step files; the final picture and VTU (the last converged state)."""
    out, summary = case
    assert summary["completed"]
    assert not list(out.glob("step_*"))
    for name in ("final.png", "final.vtu", "load_settlement.png", "table2.md", "report.md", "slope.h5"):
        assert (out / name).stat().st_size > 0
    assert summary["files"]["state_png"] == out / "final.png"
    m = meshio.read(out / "final.vtu")
    with h5py.File(out / "slope.h5") as f:
        u = f["steps/021/u"][()]
    assert np.array_equal(m.point_data["displacement"][: len(u), :2], u)


def _q1_internal_forces(nodes, elements, piola):
    """Nodal internal forces f_a = sum_g w_g P_g . dN_a/dX (Nn, 2) of a stored Piola field (G, 2, 2),
    with Q1 shape functions and 2 x 2 Gauss points written out here (independent of gransim.fem);
    also returns the Gauss point positions and weights it assumed."""
    g = 1 / np.sqrt(3)
    f = np.zeros((len(nodes), 2))
    pts, wts = [], []
    P = piola.reshape(len(elements), 4, 2, 2)
    for e, el in enumerate(elements):
        xe = nodes[el]
        for k, (xi, eta) in enumerate([(-g, -g), (g, -g), (g, g), (-g, g)]):
            dN = 0.25 * np.array(
                [[-(1 - eta), -(1 - xi)], [1 - eta, -(1 + xi)], [1 + eta, 1 + xi], [-(1 + eta), 1 - xi]]
            )
            N = 0.25 * np.array(
                [(1 - xi) * (1 - eta), (1 + xi) * (1 - eta), (1 + xi) * (1 + eta), (1 - xi) * (1 + eta)]
            )
            J = xe.T @ dN
            w = np.linalg.det(J)
            dNx = dN @ np.linalg.inv(J)
            f[el] += w * dNx @ P[e, k].T  # f_ai = P_iJ dN_a/dX_J
            pts.append(N @ xe)
            wts.append(w)
    return f, np.array(pts), np.array(wts)


def test_stored_stress_field_carries_the_applied_load(case):
    """Equilibrium of the output: the stored Piola stress of the final step, integrated with an
    independent Q1 quadrature, gives base reactions that carry the slope's weight (rho g times the
    analytic cross-section of the trapezoidal profile) plus the footing force, and the free nodes
    away from the footing carry only their own weight share (to round-off)."""
    from gransim.paper import DENSITY, GRAVITY

    out, _ = case
    geo = SMALL_SLOPE
    area = (
        geo.toe_height * geo.toe_x
        + 0.5 * (geo.toe_height + geo.crest_height) * (geo.crest_x - geo.toe_x)
        + geo.crest_height * (geo.length - geo.crest_x)
    )
    with h5py.File(out / "slope.h5") as f:
        assert f.attrs["kind"] == "fem-slope" and bool(f.attrs["completed"])
        nodes, elements = f["mesh/nodes"][()], f["mesh/elements"][()]
        g = f["steps/021"]
        assert np.allclose(g.attrs["load"], [1.0, 1.0])
        fint, pts, wts = _q1_internal_forces(nodes, elements, g["piola"][()])
        assert np.allclose(pts, f["mesh/gauss_points"][()], rtol=0, atol=1e-12)
        assert np.allclose(wts, f["mesh/gauss_weights"][()], rtol=1e-13)
        ls = f["load_settlement"][()]
        assert ls.shape == (len(setup_for("service").schedule()) + 1, 3)
        assert np.all(np.diff(ls[1:, 1]) > 0)  # the footing settles further with every load step
    assert wts.sum() == pytest.approx(area, rel=1e-12)
    weight = DENSITY * GRAVITY * area
    footing = setup_for("service").footing_force
    base = np.abs(nodes[:, 1]) < 1e-9
    # an interior node far from the footing: f_int balances its (exactly Q1-integrated) weight
    from gransim.fem.slope import SlopeSetup

    s = SlopeSetup(geometry=geo)
    side = (np.abs(nodes[:, 0]) < 1e-9) | (np.abs(nodes[:, 0] - geo.length) < 1e-9)
    surf = np.abs(nodes[:, 1] - geo.surface(nodes[:, 0])) < 1e-9
    footing_nodes = surf & (nodes[:, 0] > s.footing_left - 1e-9) & (nodes[:, 0] < s.footing_right + 1e-9)
    inner = np.flatnonzero(~base & ~side & ~footing_nodes)
    body = np.zeros((len(nodes), 2))
    gp = 1 / np.sqrt(3)
    for el in elements:  # consistent body force vector int N_a b dV, 2 x 2 Gauss (exact for Q1 x det J)
        xe = nodes[el]
        for xi, eta in [(-gp, -gp), (gp, -gp), (gp, gp), (-gp, gp)]:
            N = 0.25 * np.array(
                [(1 - xi) * (1 - eta), (1 + xi) * (1 - eta), (1 + xi) * (1 + eta), (1 - xi) * (1 + eta)]
            )
            dN = 0.25 * np.array(
                [[-(1 - eta), -(1 - xi)], [1 - eta, -(1 + xi)], [1 + eta, 1 + xi], [-(1 + eta), 1 - xi]]
            )
            body[el, 1] -= DENSITY * GRAVITY * N * np.linalg.det(xe.T @ dN)
    assert np.abs(fint[inner] - body[inner]).max() <= 1e-9 * np.abs(body).max()
    # vertical reactions at the base (f_int there minus the body force there) carry weight + footing
    assert body[:, 1].sum() == pytest.approx(-weight, rel=1e-12)
    reaction = fint[base, 1].sum() - body[base, 1].sum()
    assert reaction == pytest.approx(weight - footing, rel=1e-9)  # footing < 0: pushes down


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


def _judged(summary, protocol="service"):
    """The slope case's records of one run (validation/cases/slope.py: its bounds, the shared
    analytic judge) from the figures the run measured of itself."""
    from gransim.fem.run import acceptance_figures
    from validation.cases.slope import BOUNDS, CHECKED, REPORTED
    from validation.judges import analytic

    expected = [("", q) for q in (*REPORTED[protocol], *CHECKED)]
    values = {("", q): v for q, v in acceptance_figures(summary).items()}
    return analytic(f"slope/{protocol}", values, expected=expected, values=dict, bound=BOUNDS, sides=("native",))[0]


def test_acceptance_figures_of_a_completed_run(case):
    recs = _judged(case[1])
    checks = [r for r in recs if r.kind == "check"]
    assert {r.quantity for r in checks} == {"newton order", "small load", "patch test"}
    assert all(r.passed for r in checks), checks
    # what only restates the run's own stopping rules is information, never a verdict
    assert {r.quantity for r in recs if r.kind == "info"} == {"completed", "final energy norm"}


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
    s = run_slope_case(
        "service", material=_WrongTangent(make_continuum("neo-hookean")), out=None, figures="none", geometry=SMALL_SLOPE
    )
    bad = {r.quantity for r in _judged(s) if r.kind == "check" and not r.passed}
    assert {"newton order", "small load"} <= bad, bad


def test_cli_slope_end_to_end(tmp_path, capsys):
    """`gransim slope` on the full 380-element mesh with the continuum stand-in: exit 0, all outputs;
    ``--figures none`` writes no picture and no VTU."""
    rc = main(["slope", "--material", "neo-hookean", "--figures", "none", "--out", str(tmp_path)])
    assert rc == 0
    assert "completed all 21 steps" in capsys.readouterr().out
    assert not list(tmp_path.glob("*.vtu")) and not list(tmp_path.glob("*.png"))
    assert (tmp_path / "slope.h5").exists() and (tmp_path / "checkpoint" / "step_021.h5").exists()


def test_table2_columns_follow_the_dead_load_steps(case):
    """With K dead-load steps the paper's Table 2 steps (2, 6, 10, 15, 18: step 1 is the dead load)
    are run steps K - 1 later, and the footing's load-settlement rows are those of one dead-load step
    (a hyperelastic material: the same equilibria)."""
    _, one = case
    three = run_slope_case(
        "service", material=make_continuum("neo-hookean"), out=None, geometry=SMALL_SLOPE, dead_load_steps=3
    )
    assert three["completed"]
    head = [ln for ln in three["table"].splitlines() if ln.startswith("| iter")][0]
    assert head == "| iter | step 4 | step 8 | step 12 | step 17 | step 20 |"
    assert [ln for ln in one["table"].splitlines() if ln.startswith("| iter")][0].startswith("| iter | step 2 |")
    a, b = np.asarray(one["load_settlement"]), np.asarray(three["load_settlement"])
    assert len(b) == len(a) + 2
    np.testing.assert_allclose(b[3:], a[1:], rtol=1e-8, atol=1e-12)


@pytest.mark.parametrize("where", ["displacement", "stress", "order"])
def test_acceptance_checks_fail_on_a_nan(case, where):
    """A NaN in a patch-test error or a Newton order fails its check: Python's max() keeps the
    finite of (finite, NaN) in that order, so a NaN stress error behind a finite displacement
    error would have passed."""
    import copy

    s = copy.deepcopy(case[1])
    if where == "order":
        step = next(st for st in s["result"].steps if len(st.energy_norms) >= 4)
        step.energy_norms[-1] = float("nan")  # the last observed order is NaN
        quantity = "newton order"
    else:
        s["patch_check"] = dict(s["patch_check"], **{where: float("nan")})
        quantity = "patch test"
    rec = next(r for r in _judged(s) if r.quantity == quantity)
    assert not rec.passed and rec.value != rec.value, rec


def test_a_run_without_its_linear_check_fails_the_small_load_check(case):
    """A check that could not be made is a failure, never a pass on nothing."""
    s = dict(case[1], linear_check=None, linear_check_error="singular tangent")
    rec = next(r for r in _judged(s) if r.quantity == "small load")
    assert not rec.passed
