"""One slope case end to end: material, solve, per-step outputs, table, curve, HDF5, summary."""

from __future__ import annotations

import functools
import hashlib
import json
import time
from pathlib import Path

import numpy as np
import scipy.sparse.linalg as spla

from ..errors import GransimError, InputError
from ..generation import standard_packings
from ..io import atomic_path, atomic_text, load_packing
from ..parallel import DistributedMaterial
from ..progress import progress
from ..rve import RelaxedMaterial, TaylorMaterial
from ..rve.fabric import most_uniform
from ..rve.relaxed import WARM_STARTS
from .checkpoint import NAME as CKPT
from .checkpoint import clear_checkpoint, read_checkpoint, replay_history, write_checkpoint
from .constraints import DofMap
from .materials import RVE_KINDS, AssignedRVEs, NeoHookean, RVEMaterial, lame
from .mesh import rectangle_mesh
from .output import (
    TABLE2_STEPS,
    convergence_table,
    gauss_fields,
    load_settlement,
    observed_orders,
    plot_compare,
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
from .solver import NewtonFailure, Problem, history, newton, run_load_steps

#: The continuum stand-in material (tests and runs without the RVE branch).
NEO_HOOKEAN_E, NEO_HOOKEAN_NU = 3.0e7, 0.3


def _rve_700_paths(packing_dir) -> dict:
    return standard_packings(packing_dir, names=[f"rve-700-{s}" for s in range(1, 6)])


def rve_700_packings(packing_dir="results/packings") -> dict:
    """The five standard 700-particle quartz-sand RVEs {name: Packing} (generated once, then cached)."""
    return {name: load_packing(path) for name, path in _rve_700_paths(packing_dir).items()}


#: the choice of :func:`default_rve_packing`, kept beside the packings (keyed by the files' sizes and
#: modification times, so a regenerated packing is measured again)
MOST_UNIFORM_CACHE = "most_uniform_rve-700.json"


def default_rve_packing(packing_dir="results/packings"):
    """The most uniform of the five standard 700-particle RVEs (contact normal density measure of
    gransim.rve.fabric: smallest deviation from the uniform density at 20 degrees).

    The choice is computed once and kept in ``packing_dir/most_uniform_rve-700.json`` (a figure is
    measured once and reused), keyed by the five files' sizes and modification times.
    """
    paths = _rve_700_paths(packing_dir)
    key = {name: [Path(p).stat().st_size, Path(p).stat().st_mtime_ns] for name, p in paths.items()}
    cache = Path(packing_dir) / MOST_UNIFORM_CACHE
    try:
        stored = json.loads(cache.read_text())
        if stored.get("files") == key and stored.get("choice") in paths:
            return load_packing(paths[stored["choice"]])
    except (OSError, ValueError, AttributeError):
        pass

    packings = {name: load_packing(path) for name, path in paths.items()}
    name, _ = most_uniform(packings)
    try:
        with atomic_path(cache, suffix=".json") as tmp:
            Path(tmp).write_text(
                json.dumps({"files": key, "choice": name, "measure": "gransim.rve.fabric.most_uniform"}, indent=1)
            )
    except OSError:  # a read-only packing directory: measured again next time
        pass
    return packings[name]


FIGURES = ("final", "all", "none")


class SlopeInterrupted(GransimError):
    """The run stopped on purpose after a load step (``stop_after``), its checkpoint written."""

    def __init__(self, step: int, out):
        super().__init__(
            f"stopped after load step {step} as asked (--stop-after); its checkpoint is "
            f"{Path(out) / 'checkpoint'}: continue with --resume"
        )
        self.step = step


def unwrap(material):
    """The innermost material: through :class:`gransim.fem.materials.RVEMaterial` (``rve``),
    :class:`gransim.parallel.DistributedMaterial` (``template``) and
    :class:`gransim.fem.materials.AssignedRVEs` (``material``)."""
    m = material
    for _ in range(8):
        for attr in ("rve", "template", "material"):
            inner = getattr(m, attr, None)
            if inner is not None and hasattr(inner, "evaluate"):
                m = inner
                break
        else:
            return m
    return m


def fresh_material(material):
    """The same material with an empty Gauss-point history, in this process (the relaxed RVE; others
    are returned as they are): for checks on another mesh that must not start from the slope's
    history."""
    if isinstance(material, RVEMaterial):
        return RVEMaterial(fresh_material(material.rve), material.thickness)
    if isinstance(material, DistributedMaterial):
        return fresh_material(material.template)
    if isinstance(material, AssignedRVEs):
        return AssignedRVEs(fresh_material(material.material), material.rve_index)
    if not callable(getattr(material, "commit", None)):
        return material
    if callable(getattr(material, "fresh", None)):  # keeps every parameter (e.g. the confinement)
        return material.fresh()
    return type(material)(
        material.packings,
        material.normal_stiffness,
        skin_fraction=material.skin_fraction,
        force_tol=material.force_tol,
        max_iter=material.max_iter,
        min_contacts=material.min_contacts,
    )


def make_material(
    kind: str,
    packing=None,
    assignment: str = "most-uniform",
    n_gauss: int = 1520,
    packing_dir="results/packings",
    rve: str = "taylor",
    relaxed_start: str = "committed",
):
    """The material of a run: ``taylor`` (an RVE material behind the units boundary
    :class:`gransim.fem.materials.RVEMaterial`, kn = E_n x thickness = :data:`gransim.paper.KN_2D`)
    or ``neo-hookean``.

    ``rve``: ``taylor`` (:class:`gransim.rve.TaylorMaterial`, affine, Meier et al. eqs 6-12) or
    ``relaxed`` (:class:`gransim.rve.RelaxedMaterial`, periodic fluctuations minimising the energy
    at fixed F with the condensed tangent, Miehe & Dettmar 2004; Gauss-point history committed by
    the load stepper; ``relaxed_start``: where each FE iteration's relaxation starts, its
    ``warm_start``: ``committed``, the Gauss point's committed state, or ``trial``, its previous FE
    iterate of the attempt).

    ``assignment``: ``most-uniform`` (one RVE at every Gauss point: ``packing``, default the most
    uniform standard 700-particle RVE) or ``five`` (the five standard 700-particle RVEs assigned to
    the Gauss points in turn, g mod 5).
    """
    if kind == "neo-hookean":
        return NeoHookean(*lame(NEO_HOOKEAN_E, NEO_HOOKEAN_NU))
    if kind != "taylor":
        raise InputError(f"unknown material {kind!r}; choose taylor or neo-hookean")
    if rve not in RVE_KINDS:
        raise InputError(f"--rve: unknown RVE material {rve!r}; choose taylor or relaxed")

    # same constructor (packings, kn); the Taylor response at F is bitwise the same for any
    # history, block or worker (its candidate sets are sorted, gransim.rve.taylor)
    cls = TaylorMaterial
    if rve == "relaxed":
        if relaxed_start not in WARM_STARTS:
            raise InputError(f"--relaxed-start: expected one of {', '.join(WARM_STARTS)}, got {relaxed_start!r}")
        cls = functools.partial(RelaxedMaterial, warm_start=relaxed_start)

    if assignment == "five":
        five = rve_700_packings(packing_dir)
        return RVEMaterial(AssignedRVEs(cls(five, NORMAL_STIFFNESS), np.arange(n_gauss) % len(five)))
    if assignment != "most-uniform":
        raise InputError(f"unknown RVE assignment {assignment!r}; choose most-uniform or five")
    if packing is None:
        packing = default_rve_packing(packing_dir)
    elif isinstance(packing, (str, Path)):
        packing = load_packing(packing)
    return RVEMaterial(cls(packing, NORMAL_STIFFNESS))


def distribute(material, executor, n_gauss: int):
    """The material evaluated by ``executor`` (:mod:`gransim.parallel`) at ``n_gauss`` Gauss points; the
    units boundary :class:`gransim.fem.materials.RVEMaterial` stays in this process, outermost."""
    if executor is None or getattr(executor, "kind", "") == "in-process":
        return material
    if isinstance(material, RVEMaterial):
        return RVEMaterial(executor.material(material.rve, n_gauss), material.thickness)
    return executor.material(material, n_gauss)


def packing_fingerprint(material) -> str:
    """SHA-256 (16 hex digits) of the RVE packings' positions, radii and cells ("" for a continuum)."""
    packings = getattr(unwrap(material), "packings", None)
    return "" if packings is None else packings_fingerprint(packings)


def packings_fingerprint(packings) -> str:
    """SHA-256 (16 hex digits) of a sequence of packings' positions, radii and cells."""
    h = hashlib.sha256()
    for p in packings:
        for a in (p.positions, p.radii, p.cell):
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
    return h.hexdigest()[:16]


def linear_check(problem, scale: float = 1e-3) -> dict:
    """Small-load check: the Newton solution under ``scale`` of the dead load against the linear
    solution with the RVE tangent at F = 1, q_lin = -K(0)^-1 r(0) (r includes the prestress release,
    so q_lin is linear in the load). Returns the relative difference and the displacement size."""
    q0 = np.zeros(problem.dofs.n_reduced)
    r0, K0, *_ = problem.evaluate(q0, (scale, 0.0))
    q_lin = -spla.spsolve(K0, r0)
    q_nl = newton(problem, q0, (scale, 0.0)).q
    return {
        "scale": scale,
        "relative_difference": float(np.linalg.norm(q_nl - q_lin) / np.linalg.norm(q_lin)),
        "max_displacement_m": float(np.abs(q_lin).max()),
    }


def run_parameters(protocol, setup, material, rve_label, tol, min_fraction, max_iter, assignment) -> dict:
    """The parameters a slope run's results depend on (slope.h5 provenance; the checkpoint refuses others)."""
    inner = unwrap(material)
    extra = {"relaxed_start": inner.warm_start} if rve_label == "relaxed" and hasattr(inner, "warm_start") else {}
    return {
        "protocol": protocol,
        "footing_force": setup.footing_force,
        "material": type(inner).__name__,
        "rve": rve_label,
        "assignment": assignment if rve_label != "continuum" else "",
        "packings": packing_fingerprint(material),
        "tol": tol,
        "min_fraction": min_fraction,
        "max_iter": max_iter,
        "normal_stiffness": NORMAL_STIFFNESS,
        "density": setup.density,
        "gravity": setup.gravity,
        "mesh": [setup.geometry.columns, setup.geometry.rows],
        "load_steps": setup.load_steps,
        # only when not the paper's single dead-load step, so that earlier checkpoints still resume
        **({"dead_load_steps": setup.dead_load_steps} if setup.dead_load_steps != 1 else {}),
        **extra,
    }


def run_slope_case(
    protocol: str = "service",
    material="taylor",
    packing=None,
    out=None,
    figures: str = "final",
    tol: float = 1e-20,
    min_fraction: float = 1.0 / 64,
    geometry=None,
    assignment: str = "most-uniform",
    packing_dir="results/packings",
    rve: str = "taylor",
    load_steps: int = 20,
    executor=None,
    resume: bool = False,
    stop_after: int | None = None,
    checkpoint: bool = True,
    max_iter: int = 12,
    relaxed_start: str = "committed",
    dead_load_steps: int = 1,
) -> dict:
    """Solve one protocol and write its outputs to ``out`` (None: no files).

    ``figures``: ``final`` (default: the picture and VTU of the last converged state, and the
    load-settlement curve), ``all`` (also a PNG and a VTU for every converged step) or ``none`` (no
    PNG and no VTU; tables, report and slope.h5 are always written). ``executor``
    (:mod:`gransim.parallel`; default in process) evaluates the Gauss points. With ``out`` a
    checkpoint is written after every converged load step (:mod:`gransim.fem.checkpoint`);
    ``resume`` continues from it (bitwise as the uninterrupted run); ``stop_after`` = k stops after
    step k's checkpoint (raises :class:`SlopeInterrupted`, for tests of the resume).
    ``dead_load_steps`` = K applies the dead load in K equal steps before the footing (default 1,
    the paper's protocol; runs of two materials with the same K share the converged loads k/K, so
    ``gransim slope-compare`` can map them where one of them cannot carry the whole dead load).

    Returns a summary dict: ``completed``, ``message``, ``report`` (markdown), ``timing``,
    ``table`` (Table 2), ``load_settlement`` (rows force, settlement, rotation), ``steps``.
    """
    if figures not in FIGURES:
        raise InputError(f"--figures: expected one of {', '.join(FIGURES)}, got {figures!r}")
    if resume and out is None:
        raise InputError("--resume: needs the output directory of the interrupted run (--out)")
    setup = setup_for(protocol, geometry, load_steps, dead_load_steps)
    G = 4 * setup.geometry.columns * setup.geometry.rows
    if isinstance(material, str):
        mat = make_material(material, packing, assignment, G, packing_dir, rve, relaxed_start)
    else:
        mat = material
    label = rve_kind(mat)
    params = run_parameters(protocol, setup, mat, label, tol, min_fraction, max_iter, assignment)
    out = Path(out) if out is not None else None
    state, commits = None, []
    if resume:
        state, stored_commits = read_checkpoint(out / CKPT, params)  # refused before any computation
        commits = list(stored_commits)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        if not resume:
            clear_checkpoint(out / CKPT)
    mat_fe = distribute(mat, executor, G)
    problem = slope_problem(mat_fe, setup)
    interest = gauss_points_of_interest(problem, setup)
    has_history = label == "relaxed"

    def on_commit(sol):
        if has_history:  # every evaluation of the committed attempt: the replay repeats them
            commits.append(np.array(sol.iterates))

    def on_step(rec):
        if out is None:
            return
        if figures == "all":
            write_vtu(out / f"step_{rec.step:03d}.vtu", problem, rec.solution)
            render_png(
                out / f"step_{rec.step:03d}.png",
                problem,
                rec.solution,
                f"{protocol} step {rec.step}, footing {rec.load[1]:.0%}",
                mat_fe,
                interest,
            )
        if checkpoint or stop_after is not None:
            fails = [f for f in result_failures() if f[0] == rec.step]
            write_checkpoint(out / CKPT, params, rec, fails, commits[n_commits[0] :])
            n_commits[0] = len(commits)
        if stop_after is not None and rec.step >= stop_after:
            raise SlopeInterrupted(rec.step, out)

    n_commits = [len(commits)]  # commits already in the checkpoint
    failures_box = []

    def result_failures():
        return failures_box[0] if failures_box else []

    # the small-load check first: it starts from the reference history (F = 1) and commits nothing
    lc, lc_error = None, ""
    try:
        lc = [linear_check(problem, s) for s in (1e-3, 2e-3)]
    except (GransimError, RuntimeError, ValueError) as exc:  # e.g. a singular K(0): worth reporting
        lc_error = str(exc)
    history(mat_fe, "revert")
    if state is not None:
        # the Gauss-point history of the last checkpointed step; a relaxed RVE started from its
        # committed state needs only the committed F, one started from its trial every FE iterate
        replay_history(mat_fe, commits, every_iterate=params.get("relaxed_start", "trial") != "committed")
    t0 = time.perf_counter()
    bar = progress(total=len(setup.schedule()), desc=f"slope {protocol}")
    try:
        result = run_load_steps(
            problem,
            setup.schedule(),
            tol=tol,
            max_iter=max_iter,
            min_fraction=min_fraction,
            on_step=on_step,
            progress=bar,
            start=state,
            on_commit=on_commit,
            failures_out=failures_box,
        )
    finally:
        bar.close()
    wall = time.perf_counter() - t0
    message = "" if result.completed else limit_message(problem, setup, result)
    # the paper's Table 2 steps count the dead load as step 1: with K dead-load steps they are K - 1 later
    table_steps = tuple(k + setup.dead_load_steps - 1 for k in TABLE2_STEPS)
    table = convergence_table(result, table_steps)
    last = (
        result.limit["partial"]
        if (result.limit and result.limit["partial"] is not None)
        else (result.steps[-1].solution if result.steps else None)
    )
    ls = load_settlement(problem, setup, result)
    where = executor.describe() if executor is not None else "in process"
    lines = [
        (
            f"## Slope, protocol `{protocol}` (footing {setup.footing_force:.3g} N/m, material "
            f"{params['material']}, mesh {setup.geometry.columns} x "
            f"{setup.geometry.rows}, {len(setup.schedule())} steps)"
        ),
        "",
    ]
    lines.append(
        f"- status: {'completed all ' + str(len(setup.schedule())) + ' steps' if result.completed else message}"
    )
    t = result.timer
    resumed = f"; resumed after step {len(state.steps)} from the checkpoint" if state is not None else ""
    lines.append(
        f"- wall time {wall:.2f} s for {t.iterations} Newton iterations (material {t.material:.2f} s, "
        f"assembly {t.assembly:.2f} s, linear solve {t.solve:.2f} s; outputs are the rest); Gauss "
        f"points evaluated {where}{resumed}"
    )
    iters = [len(s.energy_norms) for s in result.steps]
    lines.append(f"- Newton iterations per step: {iters}; cut steps: {[s.step for s in result.steps if s.cuts]}")
    if last is not None:
        fl = gauss_fields(last)
        nc = fl["n_contacts"]
        lines.append(
            f"- final state: det F in [{fl['det_F'].min():.4f}, {fl['det_F'].max():.4f}], contacts per "
            f"Gauss point in [{nc.min()}, {nc.max()}], contact-free Gauss points {int((nc == 0).sum())}, "
            f"max von Mises {fl['von_mises'].max():.4g} Pa, settlement {ls[-1, 1]:.4g} m, "
            f"footing rotation {ls[-1, 2]:.3e} rad"
        )
    lines += ["", "Convergence (relative energy norm, Table 2):", "", table, ""]
    orders = {s.step: observed_orders(s.energy_norms) for s in result.steps if len(s.energy_norms) >= 3}
    lines.append(
        "Observed orders log(e_k+1/e_k)/log(e_k/e_k-1) in the Table 2 steps: "
        + "; ".join(f"step {k}: " + ", ".join(f"{o:.2f}" for o in orders[k]) for k in table_steps if k in orders)
    )
    lines += [
        "",
        "Load-settlement (footing force N/m, settlement m, rotation rad):",
        "",
        "| force | settlement | rotation |",
        "|---|---|---|",
    ]
    lines += [f"| {r[0] + 0.0:.4g} | {r[1] + 0.0:.5g} | {r[2] + 0.0:.4e} |" for r in ls]
    if lc is not None:
        lines += [
            "",
            (
                f"Small-load check (dead load x 1e-3 and 2e-3 against the linear solution with the RVE "
                f"tangent at F = 1): relative differences {lc[0]['relative_difference']:.3e}, "
                f"{lc[1]['relative_difference']:.3e} (max displacement {lc[0]['max_displacement_m']:.3e} m)"
            ),
        ]
    else:
        lines += ["", f"Small-load check failed: {lc_error}"]
    report = "\n".join(lines)
    files = {}
    if out is not None:
        if last is not None and figures != "none":
            tag = "final" if result.completed else "limit"
            lam = result.limit["last_converged_load"][1] if result.limit else 1.0
            files["state_png"] = render_png(
                out / f"{tag}.png", problem, last, f"{protocol}: {tag} state, footing {lam:.1%}", mat_fe, interest
            )[0]
            files["state_vtu"] = write_vtu(out / f"{tag}.vtu", problem, last)
        if result.limit and result.limit["partial"] is not None and figures == "all":
            write_vtu(out / f"step_{result.limit['step']:03d}_partial.vtu", problem, result.limit["partial"])
        if figures != "none":
            files["load_settlement_png"] = plot_load_settlement(out / "load_settlement.png", problem, setup, result)
        atomic_text(out / "table2.md", table + "\n")
        atomic_text(out / "report.md", report + "\n")
        files["h5"] = write_h5(out / "slope.h5", problem, setup, result, params, message)
    return {
        "completed": result.completed,
        "message": message,
        "report": report,
        "table": table,
        "timing": {**result.timer.as_dict(), "wall_s": wall},
        "load_settlement": ls,
        "steps": result.steps,
        "result": result,
        "problem": problem,
        "linear_check": lc,
        "linear_check_error": lc_error,
        "patch_check": patch_check(fresh_material(mat)),
        "rve": label,
        "material": mat_fe,
        "files": files,
        "resumed_after": len(state.steps) if state else 0,
    }


def rve_kind(material) -> str:
    """``relaxed`` (Gauss-point history), ``taylor`` (an RVE material) or ``continuum``."""
    m = unwrap(material)
    if callable(getattr(m, "commit", None)):
        return "relaxed"
    return "taylor" if getattr(m, "packings", None) is not None else "continuum"


def patch_check(material, F0=None) -> dict:
    """Exact case for the FE2 machinery with the slope's own material: a distorted 3 x 3 Q1 patch
    whose boundary nodes follow an affine field u = (F0 - 1) X must be solved by that affine field
    exactly, with P(F0) of the material at every Gauss point (the Q1 patch test).

    Returns the largest nodal displacement error relative to max|u| and the largest Piola stress
    error relative to max|P(F0)|: round-off (~1e-13) for a correct element, assembly and material
    interface; any error in them gives O(1).
    """
    F0 = np.array([[0.995, 0.004], [-0.002, 0.990]]) if F0 is None else np.asarray(F0, float)
    mesh = rectangle_mesh(3, 3, 2.0, 1.0, distort=0.2, seed=5)
    X = mesh.nodes
    bnd = np.flatnonzero((X[:, 0] == 0) | (X[:, 0] == 2) | (X[:, 1] == 0) | (X[:, 1] == 1))
    dofs = np.concatenate([2 * bnd, 2 * bnd + 1])
    u = X @ (F0 - np.eye(2)).T
    prob = Problem(mesh, material, DofMap.build(X, dofs, values=u.ravel()[dofs]))
    try:
        sol = newton(prob, np.zeros(prob.dofs.n_reduced), (0.0, 0.0))
    except NewtonFailure as exc:  # no solution at all: the check fails with what Newton reached
        return {"displacement": float("inf"), "stress": float("inf"), "error": str(exc)}
    P0 = material.evaluate(F0[None]).piola[0]
    return {
        "displacement": float(np.abs(sol.u - u).max() / np.abs(u).max()),
        "stress": float(np.abs(sol.material.piola - P0).max() / np.abs(P0).max()),
    }


def _finite_or_nan(value, *parts) -> float:
    """``value`` (a max or min of ``parts``), or NaN when any part is NaN or infinite: Python's
    ``max``/``min`` keep or drop a NaN depending on where it stands, so a check would pass on it."""
    return float(value) if all(np.isfinite(p) for p in parts) else float("nan")


def acceptance_figures(summary: dict) -> dict:
    """What a slope run (a :func:`run_slope_case` summary) measured of itself, for a judge to set
    against independent answers (validation/cases/slope.py holds the bounds and their reasons).

    * ``completed``: 1.0 when the load path ran to the end, else 0.0;
    * ``limit load``: the last converged footing fraction (1.0 when completed);
    * ``final energy norm``: the largest final relative energy norm over the steps (the run's own
      stopping criterion);
    * ``newton order``: over the steps with 4 or more iterations, the smallest of the best of each
      step's last two observed orders (2 for a consistent tangent, 1 for an inconsistent one); NaN
      when no step has 4 iterations or any of those orders is NaN;
    * ``small load``: |q_newton - q_linear| / |q_linear| at 1e-3 of the dead load (the linear
      solution with the tangent at F = 1); NaN when the linear check could not be made;
    * ``patch test``: the largest relative error of u and P of the Q1 patch under an affine field
      (NaN when either is NaN); absent when the run made no patch check.

    Python's ``max``/``min`` keep or drop a NaN depending on where it stands: every figure here is
    NaN when any of its parts is."""
    res = summary["result"]
    out = {
        "completed": float(summary["completed"]),
        "limit load": float(res.limit["last_converged_load"][1]) if res.limit else 1.0,
        "final energy norm": max((float(st.energy_norms[-1]) for st in res.steps), default=float("nan")),
    }
    orders = [observed_orders(st.energy_norms) for st in res.steps if len(st.energy_norms) >= 4]
    out["newton order"] = (
        _finite_or_nan(min(max(o[-2:]) for o in orders), *(v for o in orders for v in o[-2:]))
        if orders
        else float("nan")
    )
    lc = summary.get("linear_check")
    out["small load"] = float(lc[0]["relative_difference"]) if lc else float("nan")
    pc = summary.get("patch_check")
    if pc is not None:
        out["patch test"] = _finite_or_nan(max(pc["displacement"], pc["stress"]), pc["displacement"], pc["stress"])
    return out


def compare_slope(protocol: str = "service", out=None, **kwargs) -> dict:
    """Run the protocol with both RVE materials; returns {"taylor": summary, "relaxed": summary}.

    Each run writes to ``out/taylor`` and ``out/relaxed`` (:func:`run_slope_case`, ``kwargs`` as
    there); ``out`` also gets ``compare_load_settlement.png`` (both curves in one figure),
    ``compare_map.png`` (the Gauss points where the final Cauchy stresses of the two differ most,
    with both RVEs drawn at their own F) and ``compare.md``.
    """
    out = Path(out) if out is not None else None
    summaries = {}
    for kind in RVE_KINDS:
        summaries[kind] = run_slope_case(protocol, out=None if out is None else out / kind, rve=kind, **kwargs)
    if out is not None:
        plot_compare(out, summaries)
    return summaries
