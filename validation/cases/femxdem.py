"""femxdem-short: a Gauss point of Guo & Zhao's FEM x DEM biaxial test replayed in YADE (bit for bit)
and in LAMMPS (round-off).

The biaxial specimen of Guo & Zhao (*A coupled FEM/DEM approach for hierarchical multiscale
modelling of granular media*, Int. J. Numer. Meth. Engng 99 (2014) 789-818; biaxialSmooth.py of
Debian's yade 2023.02a) on a 2 x 4 Q8 mesh (32 Gauss points), 2 load steps of 1e-4 m, each Gauss
point a 400-disk DEM RVE in YADE's arithmetic (``gransim femxdem --rve dem``). The committed strain
history of the most strained Gauss point (one increment per load step) is replayed in YADE 2023.02a
(``prepareRVE.py`` run afresh, then ``simDEM.shear2D`` per increment, each call through
``stringToScene``/``sceneToString``: :mod:`reference_runs.yade.rve`) and the native RVE driven by the
same increments is compared with YADE's after every call by the shared step-for-step judge
(positions, velocities, spins, the contact forces summed per disk, the stress, the cell) and field by
field over everything the saved scene keeps, all at zero tolerance. The same history drives the
RVE in LAMMPS' arithmetic (:mod:`gransim.fem.lammps_rve`: prepareRVE.py's disks with LAMMPS' Hooke
history law, each increment one ``run`` under ``fix deform x/y/xy erate remap x``) natively and in
LAMMPS 29 Sep 2021 (:mod:`reference_runs.femxdem.lammps_replay`), compared after every call by the
same judge at round-off. A code's output cut short or missing a call is incomplete evidence and fails;
a code absent, there is no evidence and the case says so.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import h5py
import numpy as np

from gransim.dem.yade_arithmetic import RVE_STATE_FIELDS, rve_run, rve_stress_tangent
from gransim.fem.biaxial import BiaxialSpec
from gransim.fem.dem_rve import DemRVE, load_rve_state
from gransim.fem.femxdem import run_femxdem
from gransim.fem.lammps_rve import LammpsRVE
from reference_runs.engines import LAMMPS, YADE
from reference_runs.errors import ReferenceRunError
from reference_runs.femxdem.lammps_replay import replay_in_lammps
from reference_runs.yade.rve import prepare_job, run_rve_job, state_of

from ..core import CaseResult, Context, case
from ..dem_compare import Trajectory
from ..judges import StepBounds, differing
from ..matrix import Comparison, Failed, Run, evaluate

CASE = "femxdem-short"
TITLE = "FEM x DEM (Guo & Zhao): a Gauss point's strain history replayed in YADE, bit for bit"
SPEC = BiaxialSpec(nx=2, ny=4, steps=2)
REASON = (
    "bit for bit: the native yade arithmetic repeats YADE 2023.02a's operations in YADE's order "
    "(docs/yade.md, docs/femxdem.md), so every double is equal; any difference is a defect"
)
BOUNDS = StepBounds(0.0, 0.0, REASON, REASON, REASON, REASON, REASON)
LAMMPS_REASON = (
    "round-off: the sheared cell repeats LAMMPS' step (fix deform, remap x, the list and the Hooke "
    "law) and sums the forces of a disk in another order (docs/shear.md)"
)
#: the sheared cell's step-for-step standard against LAMMPS (tests/dem/test_sheared.py)
LAMMPS_BOUNDS = StepBounds(
    1e-10, 1e-8, LAMMPS_REASON, LAMMPS_REASON, LAMMPS_REASON, LAMMPS_REASON, LAMMPS_REASON, cell="sheared"
)
#: RVE calls a YADE replay job costs, as particle-steps for its time-out (prepareRVE's consolidation
#: is about 1.4e4 steps of 400 disks, each call 100-300 steps)
PREPARE_PSTEPS = 400 * 14_000


def contact_sums(state) -> tuple[np.ndarray, np.ndarray]:
    """Per disk (N, 2) the sum of the normal and shear forces of its contacts (on body 2 +, on body 1
    -) and (N,) the sum of r (n x f_s) (the same function for both runs: a summary of the contact
    forces, not either engine's force array)."""
    n = state.n
    f = np.asarray(state.normal_force) + np.asarray(state.shear_force)
    i, j = state.ids[:, 0], state.ids[:, 1]
    F = np.zeros((n, 2))
    np.add.at(F, j, f)
    np.add.at(F, i, -f)
    nrm, fs = np.asarray(state.normal), np.asarray(state.shear_force)
    cross = nrm[:, 0] * fs[:, 1] - nrm[:, 1] * fs[:, 0]
    T = np.zeros(n)
    np.add.at(T, i, -state.radii[i] * cross)
    np.add.at(T, j, -state.radii[j] * cross)
    return F, T


def trajectory(states) -> Trajectory:
    """The calls' states (call 0 the loaded RVE) as a trajectory of the shared judges: series step =
    call, stress (xx, yy, xy of getStress, Pa), box = the cell vectors' lengths, a frame per call."""
    stress, lengths, frames = [], [], {}
    for k, s in enumerate(states):
        sig, _ = rve_stress_tangent(s)
        stress.append([sig[0, 0], sig[1, 1], sig[0, 1]])
        lengths.append(np.linalg.norm(np.asarray(s.hsize), axis=0))
        F, T = contact_sums(s)
        frames[k] = {
            "x": np.asarray(s.positions),
            "v": np.asarray(s.velocities),
            "w": np.asarray(s.spins),
            "f": F,
            "t": T,
        }
    return Trajectory(np.arange(len(states), dtype=np.int64), np.array(stress), np.array(lengths), frames)


def differing_fields(a, b) -> list:
    """The fields of two RVE states that differ (NaN equal to NaN: YADE's unsaved penetration)."""
    return differing(a, b, RVE_STATE_FIELDS)


def native_history(out, spec: BiaxialSpec = SPEC):
    """(summary of the native run in ``out``, Gauss point g, its committed state): g the most
    strained point at the last step; the state read from the run's checkpoint."""
    summary = run_femxdem(spec, rve="dem", out=out, field_steps=(spec.steps,), rve_pictures=())
    g = int(np.argmax(summary["fields"][spec.steps]["deviatoric_strain"]))
    with h5py.File(Path(out) / "checkpoint" / f"states_{spec.steps:03d}.h5", "r") as f:
        states = DemRVE.unpack_states({k: np.array(v) for k, v in f["states"].items()})
    return summary, g, states[g]


def _figures(res: CaseResult, ctx: Context, out: Path) -> None:
    """The native run's curves first, then its maps (the report section leads with the curves)."""
    figs = [
        ("curves.png", "2 x 4 mesh with DEM RVEs: q and volumetric strain against axial strain", True),
        (f"maps_{SPEC.steps:03d}.png", f"deviatoric strain, void ratio and mean particle rotation at step {SPEC.steps}"
         " (each Gauss point's sub-cell; the rotation: spin dt summed over every DEM step, docs/femxdem.md)", False),
    ]  # fmt: skip
    for name, cap, head in figs:
        if (out / name).exists():
            res.add_figure(ctx.copy_figure(out / name, f"femxdem_short_{name}"), cap, data=out / "femxdem.h5",
                           headline=head)  # fmt: skip


def native_calls(increments) -> list:
    """The stored RVE, then the state after each native call of ``increments`` (K, 2, 2)."""
    out = [load_rve_state()[0]]
    for D in increments:
        out.append(rve_run(out[-1], D))
    return out


def yade_available() -> bool:
    """Whether YADE's binary is installed (tests replace it)."""
    return YADE.available()


def yade_replay(job_dir, increments, timeout: float):
    """YADE's states after every call of ``increments`` (K, 2, 2) from prepareRVE.py's RVE."""
    recs, manifest = run_rve_job(job_dir, *prepare_job(increments=np.reshape(increments, (-1, 4))), timeout=timeout)
    return [state_of(r) for r in recs], manifest


def lammps_trajectory(states) -> Trajectory:
    """The LAMMPS RVE's states (call 0 the set-up) as a trajectory of the shared judges: series step
    = call, stress (xx, yy, xy, Pa), box (lx, ly, xy), a frame per call."""
    stress = [[s["stress"][0, 0], s["stress"][1, 1], s["stress"][0, 1]] for s in states]
    box = [[s["box"][2] - s["box"][0], s["box"][3] - s["box"][1], s["box"][4]] for s in states]
    frames = {
        k: {"x": s["positions"], "v": s["velocities"], "w": s["spins"], "f": s["forces"], "t": s["torques"]}
        for k, s in enumerate(states)
    }
    return Trajectory(np.arange(len(states), dtype=np.int64), np.array(stress), np.array(box), frames)


def lammps_available() -> bool:
    """Whether LAMMPS' binary is installed (tests replace it)."""
    return LAMMPS.available()


def plan(ctx: Context, replay) -> tuple[list, list, dict]:
    """The runs and comparisons of the case, and what they share (``info``: the FE run's summary,
    the Gauss point g, its committed state, its output directory; YADE's version once replayed).

    Runs: the native FE run (2 x 4 mesh, DEM RVEs in YADE's arithmetic), whose most strained Gauss
    point's committed RVE is one run and whose strain history drives the others: a single native
    RVE (YADE's arithmetic), YADE's replay (``replay``), the native LAMMPS RVE and LAMMPS' replay.
    Comparisons: the Gauss point against the single RVE (every field); the single RVE against
    YADE after every call (the step judge at zero tolerance, then every saved field) and YADE's
    prepared RVE against the stored one; the native LAMMPS RVE against LAMMPS at round-off."""
    out = ctx.work("femxdem-short", "native")
    summary, g, committed = native_history(out)  # made first: its Gauss point chooses the history
    info = {"summary": summary, "g": g, "committed": committed, "out": out}
    lab = f"{CASE}/gp{g}"
    inc = np.asarray(committed.increments)
    calls = len(inc) + 1
    lammps_rve = functools.cache(LammpsRVE.guo_zhao)

    def yade():
        try:
            states, manifest = replay(ctx.work("reference", "femxdem-short"), inc, ctx.job_timeout(PREPARE_PSTEPS))
        except ReferenceRunError as exc:  # a failed job or an output cut short: missing evidence, named
            return Failed(f"YADE job failed: {str(exc).splitlines()[0]}")
        info["yade_version"] = manifest.get("engine_version")
        return states

    def lammps():
        try:
            return replay_in_lammps(
                ctx.work("reference", "femxdem-short-lammps"), lammps_rve(), inc, ctx.job_timeout(400 * 1000)
            )
        except ReferenceRunError as exc:
            return Failed(f"LAMMPS job failed: {str(exc).splitlines()[0]}")

    runs = [
        Run("native/gauss-point", "native", "yade", "the committed RVE of the FE run's most strained Gauss point",
            lambda: committed.rve),
        Run("native/rve", "native", "yade", "a single RVE driven by the Gauss point's increments",
            lambda: native_calls(inc)),
        Run("yade/rve", "yade", "yade", "prepareRVE.py, then simDEM.shear2D per increment, in YADE now", yade,
            live=True),
        Run("native/lammps-rve", "native", "lammps", "the LAMMPS RVE driven by the increments",
            lambda: lammps_rve().replay(inc)),
        Run("lammps/rve", "lammps", "lammps", "the LAMMPS RVE's deck, one run per increment, in LAMMPS now", lammps,
            live=True),
    ]  # fmt: skip

    comps = [
        Comparison(
            "same", lab, ("native/gauss-point", "native/rve"),
            "a Gauss point's RVE is a single RVE driven by its strain history (the FE run only chooses it)",
            {"fields": RVE_STATE_FIELDS, "quantity": "gauss_point", "metric": "fields of the Gauss point's "
             "committed RVE that differ from a single RVE driven by its increments"},
            view=lambda r: r[-1] if isinstance(r, list) else r,
        ),
        Comparison(
            "same", lab, ("native/rve", "yade/rve"), REASON,
            {"fields": RVE_STATE_FIELDS, "quantity": "prepared_rve", "metric": "fields of prepareRVE.py's RVE run now "
             "that differ from the stored one"},
            view=lambda r: r[0] if r else r,
        ),
        Comparison(
            "step", lab, ("native/rve", "yade/rve"), REASON,
            lambda: {"d50": float(2 * np.median(load_rve_state()[0].radii)), "nsteps": calls - 1, "dump_every": 1,
                     "bounds": BOUNDS},
            view=trajectory,
        ),
        Comparison(
            "same", lab, ("native/rve", "yade/rve"), REASON,
            {"fields": RVE_STATE_FIELDS, "quantity": "saved_scene", "what": "calls", "expected": calls,
             "metric": "calls whose saved scene differs in any field (positions ... shear forces, in container "
             "order), counted per field"},
        ),
        Comparison(
            "step", lab, ("native/lammps-rve", "lammps/rve"), LAMMPS_REASON,
            lambda: {"d50": float(2 * np.median(lammps_rve().packing.radii)), "nsteps": calls - 1,
                     "dump_every": 1, "bounds": LAMMPS_BOUNDS},
            view=lammps_trajectory,
        ),
    ]  # fmt: skip
    return runs, comps, info


def _table(res: CaseResult, pair: str, g: int, calls: int) -> list:
    """The row of the step-for-step records in ``pair``: Gauss point, calls, the largest differences."""
    by_q = {r.quantity: r.value for r in res.records if r.pair == pair}
    return [g, calls, *(f"{by_q.get(q, float('nan')):.1e}" for q in ("position", "velocity", "spin", "stress", "box"))]


@case(CASE, TITLE, suites=("default", "full"), order=60)
def femxdem_short(ctx: Context, replay=yade_replay) -> CaseResult:
    """``replay(job_dir, increments, timeout) -> (states, manifest)``: YADE's side (tests swap it).
    The case needs both codes: one absent, there is no evidence of its replay and the case says so
    (an error: it did not run what it is for)."""
    res = CaseResult(CASE, TITLE, __doc__.split("\n\n", 1)[1].replace("\n", " "))
    res.skip_code("liggghts", "no LIGGGHTS run: the Gauss point replays in YADE and LAMMPS (a LAMMPS sheared cell)")
    res.skip_code(
        "lammps", "the LAMMPS RVE has LAMMPS' Hooke law, YADE's its own: the two codes run different materials"
    )
    have = {"yade": yade_available(), "lammps": lammps_available()}
    avail = {c for c in ctx.available if c not in have} | {c for c, ok in have.items() if ok}
    ctx = dataclasses.replace(ctx, lammps=have["lammps"], available=frozenset(avail))
    runs, comps, info = plan(ctx, replay)
    out = evaluate(res, ctx, runs, comps)
    summary, g = info["summary"], info["g"]
    dev = summary["fields"][SPEC.steps]["deviatoric_strain"]
    _figures(res, ctx, info["out"])
    res.notes.append(
        f"2 x 4 Q8 mesh, {SPEC.steps} steps: q = "
        + ", ".join(f"{r.deviatoric_stress / 1e3:.2f} kPa" for r in summary["steps"])
        + f"; Newton iterations {[len(r.errors) for r in summary['steps']]}; replayed: Gauss point {g} "
        f"(deviatoric strain {dev[g]:.4g}, the largest of {dev.min():.4g} to {dev.max():.4g})."
    )
    calls = len(info["committed"].increments)
    if "lammps/rve" in out.runs:
        res.tables.append(
            (
                "Native RVE in LAMMPS' arithmetic against LAMMPS after every call (round-off)",
                ["Gauss point", "calls", "max|dx|/D50", "max|dv|/max|v|", "max|dw|/max|w|", "stress", "cell"],
                [_table(res, "native-lammps", g, calls)],
            )
        )
    if "yade/rve" in out.runs:
        res.notes.append(f"YADE: {info.get('yade_version')}; {calls} calls replayed.")
        res.tables.append(
            (
                "Native RVE against YADE after every call (0 = bitwise equal)",
                ["Gauss point", "calls", "max|dx|/D50", "max|dv|/max|v|", "max|dw|/max|w|", "stress", "cell"],
                [_table(res, "native-yade", g, calls)],
            )
        )
    absent = [(c, e) for c, e in (("yade", YADE), ("lammps", LAMMPS)) if not have[c]]
    if absent:
        why = [f"{e.label} is not installed: no evidence of its replay (no stored replay of this history; "
               f"{e.install_hint})" for _, e in absent]  # fmt: skip
        res.notes += why
        res.error = "; ".join(why)
    return res
