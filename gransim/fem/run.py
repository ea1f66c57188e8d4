"""One slope case end to end: material, solve, per-step outputs, table, curve, HDF5, summary."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..errors import GransimError, InputError
from .materials import NeoHookean, lame
from .output import (
    TABLE2_STEPS,
    convergence_table,
    gauss_fields,
    load_settlement,
    observed_orders,
    plot_load_settlement,
    render_png,
    write_h5,
    write_vtu,
)
from .slope import (
    NORMAL_STIFFNESS,
    gauss_points_of_interest,
    limit_message,
    setup_for,
    slope_problem,
)
from .solver import run_load_steps

#: The continuum stand-in material (tests and runs without the RVE branch).
NEO_HOOKEAN_E, NEO_HOOKEAN_NU = 3.0e7, 0.3


def rve_700_packings(packing_dir="results/packings") -> dict:
    """The five standard 700-particle quartz-sand RVEs {name: Packing} (generated once, then cached)."""
    try:
        from ..generation import standard_packings
    except ImportError as exc:
        raise InputError(f"the standard RVEs need gransim.generation ({exc}); pass --packing FILE.h5 "
                         "or --material neo-hookean") from None
    from ..io import load_packing

    paths = standard_packings(packing_dir, names=[f"rve-700-{s}" for s in range(1, 6)])
    return {name: load_packing(path) for name, path in paths.items()}


def default_rve_packing(packing_dir="results/packings"):
    """The most uniform of the five standard 700-particle RVEs (contact normal density measure of
    gransim.rve.fabric: smallest deviation from the uniform density at 20 degrees)."""
    from ..rve.fabric import most_uniform

    packings = rve_700_packings(packing_dir)
    name, _ = most_uniform(packings)
    return packings[name]


def make_material(kind: str, packing=None, assignment: str = "most-uniform", n_gauss: int = 1520,
                  packing_dir="results/packings"):
    """The material of a run: ``taylor`` (Taylor RVE, E_n = 2.8e7 N/m^2) or ``neo-hookean``.

    ``assignment``: ``most-uniform`` (one RVE at every Gauss point: ``packing``, default the most
    uniform standard 700-particle RVE) or ``five`` (the five standard 700-particle RVEs assigned to
    the Gauss points in turn, g mod 5).
    """
    if kind == "neo-hookean":
        return NeoHookean(*lame(NEO_HOOKEAN_E, NEO_HOOKEAN_NU))
    if kind != "taylor":
        raise InputError(f"unknown material {kind!r}; choose taylor or neo-hookean")
    from ..rve import TaylorMaterial

    if assignment == "five":
        from .materials import AssignedRVEs

        five = rve_700_packings(packing_dir)
        return AssignedRVEs(TaylorMaterial(five, NORMAL_STIFFNESS), np.arange(n_gauss) % len(five))
    if assignment != "most-uniform":
        raise InputError(f"unknown RVE assignment {assignment!r}; choose most-uniform or five")
    if packing is None:
        packing = default_rve_packing(packing_dir)
    elif isinstance(packing, (str, Path)):
        from ..io import load_packing

        packing = load_packing(packing)
    return TaylorMaterial(packing, NORMAL_STIFFNESS)


def linear_check(problem, scale: float = 1e-3) -> dict:
    """Small-load check: the Newton solution under ``scale`` of the dead load against the linear
    solution with the RVE tangent at F = 1, q_lin = -K(0)^-1 r(0) (r includes the prestress release,
    so q_lin is linear in the load). Returns the relative difference and the displacement size."""
    import scipy.sparse.linalg as spla

    from .solver import newton

    q0 = np.zeros(problem.dofs.n_reduced)
    r0, K0, *_ = problem.evaluate(q0, (scale, 0.0))
    q_lin = -spla.spsolve(K0, r0)
    q_nl = newton(problem, q0, (scale, 0.0)).q
    return {"scale": scale, "relative_difference": float(np.linalg.norm(q_nl - q_lin) / np.linalg.norm(q_lin)),
            "max_displacement_m": float(np.abs(q_lin).max())}


def run_slope_case(protocol: str = "service", material="taylor", packing=None, out=None,
                   figures: str = "all", tol: float = 1e-20, min_fraction: float = 1.0 / 64,
                   geometry=None, assignment: str = "most-uniform", packing_dir="results/packings") -> dict:
    """Solve one protocol and write its outputs to ``out`` (None: no files).

    Returns a summary dict: ``completed``, ``message``, ``report`` (markdown), ``timing``,
    ``table`` (Table 2), ``load_settlement`` (rows force, settlement, rotation), ``steps``.
    """
    from ..progress import progress

    setup = setup_for(protocol, geometry)
    if isinstance(material, str):
        from .mesh import SlopeGeometry

        g = geometry or SlopeGeometry()
        mat = make_material(material, packing, assignment, 4 * g.columns * g.rows, packing_dir)
    else:
        mat = material
    out = Path(out) if out is not None else None
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
    problem = slope_problem(mat, setup)
    interest = gauss_points_of_interest(problem, setup)

    def on_step(rec):
        if out is None:
            return
        write_vtu(out / f"step_{rec.step:03d}.vtu", problem, rec.solution)
        if figures == "all":
            render_png(out / f"step_{rec.step:03d}.png", problem, rec.solution,
                       f"{protocol} step {rec.step}, footing {rec.load[1]:.0%}", mat, interest)

    t0 = time.perf_counter()
    bar = progress(total=len(setup.schedule()), desc=f"slope {protocol}")
    result = run_load_steps(problem, setup.schedule(), tol=tol, min_fraction=min_fraction, on_step=on_step,
                            progress=bar)
    bar.close()
    wall = time.perf_counter() - t0
    message = "" if result.completed else limit_message(problem, setup, result)
    table = convergence_table(result, TABLE2_STEPS)
    last = (result.limit["partial"] if (result.limit and result.limit["partial"] is not None)
            else (result.steps[-1].solution if result.steps else None))
    ls = load_settlement(problem, setup, result)
    lines = [(f"## Slope, protocol `{protocol}` (footing {setup.footing_force:.3g} N/m, material "
             f"{type(mat).__name__})"), ""]
    lines.append(f"- status: {'completed all ' + str(len(setup.schedule())) + ' steps' if result.completed else message}")
    t = result.timer
    lines.append(f"- wall time {wall:.2f} s for {t.iterations} Newton iterations (material {t.material:.2f} s, "
                 f"assembly {t.assembly:.2f} s, linear solve {t.solve:.2f} s; outputs are the rest)")
    iters = [len(s.energy_norms) for s in result.steps]
    lines.append(f"- Newton iterations per step: {iters}; cut steps: "
                 f"{[s.step for s in result.steps if s.cuts]}")
    if last is not None:
        fl = gauss_fields(last)
        nc = fl["n_contacts"]
        lines.append(f"- final state: det F in [{fl['det_F'].min():.4f}, {fl['det_F'].max():.4f}], contacts per "
                     f"Gauss point in [{nc.min()}, {nc.max()}], contact-free Gauss points {int((nc == 0).sum())}, "
                     f"max von Mises {fl['von_mises'].max():.4g} Pa, settlement {ls[-1, 1]:.4g} m, "
                     f"footing rotation {ls[-1, 2]:.3e} rad")
    lines += ["", "Convergence (relative energy norm, Table 2):", "", table, ""]
    orders = {s.step: observed_orders(s.energy_norms) for s in result.steps if len(s.energy_norms) >= 3}
    lines.append("Observed orders log(e_k+1/e_k)/log(e_k/e_k-1) in the Table 2 steps: " + "; ".join(
        f"step {k}: " + ", ".join(f"{o:.2f}" for o in orders[k]) for k in TABLE2_STEPS if k in orders))
    lines += ["", "Load-settlement (footing force N/m, settlement m, rotation rad):", "",
              "| force | settlement | rotation |", "|---|---|---|"]
    lines += [f"| {r[0] + 0.0:.4g} | {r[1] + 0.0:.5g} | {r[2] + 0.0:.4e} |" for r in ls]
    try:
        lc = [linear_check(problem, s) for s in (1e-3, 2e-3)]
        lines += ["", (f"Small-load check (dead load x 1e-3 and 2e-3 against the linear solution with the RVE "
                      f"tangent at F = 1): relative differences {lc[0]['relative_difference']:.3e}, "
                      f"{lc[1]['relative_difference']:.3e} (max displacement {lc[0]['max_displacement_m']:.3e} m)")]
    except (GransimError, RuntimeError, ValueError) as exc:  # e.g. a singular K(0): worth reporting
        lines += ["", f"Small-load check failed: {exc}"]
    report = "\n".join(lines)
    if out is not None:
        if last is not None and figures != "none":
            tag = "final" if result.completed else "limit"
            render_png(out / f"{tag}.png", problem, last, f"{protocol}: {tag} state, footing "
                       f"{(result.limit['last_converged_load'][1] if result.limit else 1.0):.1%}", mat,
                       interest)
        if result.limit and result.limit["partial"] is not None:
            write_vtu(out / f"step_{result.limit['step']:03d}_partial.vtu", problem, result.limit["partial"])
        plot_load_settlement(out / "load_settlement.png", problem, setup, result)
        (out / "table2.md").write_text(table + "\n")
        (out / "report.md").write_text(report + "\n")
        params = {"protocol": protocol, "footing_force": setup.footing_force, "material": type(mat).__name__,
                  "tol": tol, "min_fraction": min_fraction, "normal_stiffness": NORMAL_STIFFNESS,
                  "density": setup.density, "gravity": setup.gravity}
        write_h5(out / "slope.h5", problem, setup, result, params, message)
    return {"completed": result.completed, "message": message, "report": report, "table": table,
            "timing": {**result.timer.as_dict(), "wall_s": wall}, "load_settlement": ls,
            "steps": result.steps, "result": result, "problem": problem}


def acceptance_records(summaries: dict) -> list[dict]:
    """Validation-style records {case, quantity, metric, value, tolerance, pass, note} of slope runs.

    ``summaries`` maps protocol -> :func:`run_slope_case` summary. Checks: the service protocol
    completes; the paper protocol stops at a limit below the full load with contact-free Gauss points
    named; every converged step ends at e <= 1e-20 or round-off; the last observed Newton order of each
    step is near 2 (> 1.5); the small-load solution is linear in the load.
    """
    from .output import observed_orders

    out = []
    for prot, s in summaries.items():
        case = f"slope/{prot}"
        res = s["result"]
        if prot == "service":
            out.append({"case": case, "quantity": "load path", "metric": "completed", "value": float(s["completed"]),
                        "tolerance": 1.0, "pass": bool(s["completed"]), "note": "-5e6 N/m must run to the end"})
        if prot == "paper":
            lam = res.limit["last_converged_load"][1] if res.limit else 1.0
            ok = (not s["completed"]) and "Gauss points without contacts" in s["message"]
            out.append({"case": case, "quantity": "limit load", "metric": "last converged footing fraction",
                        "value": float(lam), "tolerance": 1.0, "pass": bool(ok and lam < 1.0),
                        "note": "the Taylor RVE carries no tension: a crest mechanism near 92% is expected"})
        last_e = max(float(st.energy_norms[-1]) for st in res.steps)
        out.append({"case": case, "quantity": "newton", "metric": "largest final relative energy norm",
                    "value": last_e, "tolerance": 1e-11, "pass": last_e <= 1e-11,
                    "note": "tol 1e-20, or the residual at round-off (the last increment's e is then recorded)"})
        orders = [observed_orders(st.energy_norms) for st in res.steps if len(st.energy_norms) >= 4]
        worst = min(max(o[-2:]) for o in orders) if orders else float("nan")
        out.append({"case": case, "quantity": "newton", "metric": "min over steps of the best of the last two orders",
                    "value": float(worst), "tolerance": 1.5, "pass": bool(worst > 1.5),
                    "note": "quadratic convergence: observed order near 2 in the last iterations"})
    return out
