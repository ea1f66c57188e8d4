"""fast-order: the fast ordering against the code's order, within the code order's own chaos envelope.

The fast ordering (:class:`gransim.dem.fast.FastEngine`: particles sorted by bin at every list
build, a half list with the symmetric update, the branch-free law, banded threads) has the physics
of the code's order (:class:`gransim.dem.engine.Engine`, bit for bit with LIGGGHTS or LAMMPS) and
only sums in another order, so it departs from it by round-off at every step, which the chaos of a
dense assembly then amplifies. The envelope of that amplification is the code order's own: two runs
of it with one coordinate moved by 1e-15 relative. Both cells, through the calls ``gransim biaxial
--order fast`` and ``gransim shear --order fast`` make (:func:`gransim.dem.engine.make_engine`):

* orthogonal: the biaxial short case (120 disks, a stress servo on x, compression along y,
  LIGGGHTS' arithmetic), :data:`NSTEPS` steps;
* sheared: the simple-shear short case (the same disks, xy erate 2.5 1/s, a y stress servo,
  LAMMPS' arithmetic), :data:`NSTEPS` steps.

In the full suite (the default suite's time goes to the codes: the case costs about 40 s there, most
of it compiling the fast kernels of both cells). The fast run, on 2 threads, is judged against the
code order's serial run as a native run is
judged against a code's envelope (:class:`validation.judges.EnvelopeRule`: positions at every dump
and the stress at every step within 10 times the envelope, with the step-for-step floors, as the
sheared cell against LAMMPS). No code runs: every matrix column is not applicable.
"""

from __future__ import annotations

import time

import numpy as np

from gransim.dem.engine import make_engine
from reference_runs.decks.biaxial import short_case as biaxial_short
from reference_runs.decks.shear import short_case as shear_short
from reference_runs.decks.shear import wrapped_packing

from ..codes import CODES, NATIVE
from ..core import CaseResult, Context, case
from ..dem_compare import Trajectory
from ..judges import ENVELOPE_FACTOR, EnvelopeRule
from ..matrix import Comparison, Run, evaluate

CASE = "fast-order"
TITLE = "The fast ordering against the code's order, within the code order's own chaos envelope (both cells)"
#: steps of each run, and the dump interval of the position comparison
NSTEPS = 20000
DUMP_EVERY = 1000
#: the relative move of one coordinate that makes an envelope member (as the codes' envelopes)
PERTURB_REL = 1e-15
REASON = (
    "chaos: the code order's own divergence under a round-off perturbation (one coordinate moved by 1e-15 "
    "relative, two runs) is the envelope E(t); the fast ordering differs from the code's by the summation "
    "order at every step, so, as the sheared cell against LAMMPS, it must stay within 10 E(t) within one "
    "dump interval, or below the step-for-step bounds 1e-10 D50 / 1e-8 (validation.judges.EnvelopeRule)"
)
RULE = EnvelopeRule(
    factor=ENVELOPE_FACTOR, window=DUMP_EVERY, position_floor=1e-10, stress_floor=1e-8, curve_factor=2.0, reason=REASON
)


def _frame(eng) -> dict:
    return {"x": eng.x.copy(), "v": eng.v.copy(), "w": eng.w.copy(), "f": eng.f.copy(), "t": eng.t.copy()}


def run(packing, settings, loading, cell: str, order: str, threads=None) -> Trajectory:
    """One run of :data:`NSTEPS` steps as a trajectory: the stress (xx, yy, xy, compression
    positive) every step from the set-up, the box (lengths, or lx, ly, xy sheared), a frame every
    :data:`DUMP_EVERY` steps. One ``start_run`` and ``advance`` pieces, as the commands do."""
    t0 = time.perf_counter()
    eng = make_engine(packing, settings, cell=cell, order=order, threads=threads)
    s0 = eng.start_run(loading, NSTEPS)
    st = [np.array([[s0[0, 0], s0[1, 1], s0[0, 1]]])]
    box = [_box(eng, cell)]
    frames = {0: _frame(eng)}
    while eng.step < NSTEPS:
        out = eng.advance(min(DUMP_EVERY, NSTEPS - eng.step))
        s = out["stress"]
        st.append(np.stack([s[:, 0, 0], s[:, 1, 1], s[:, 0, 1]], axis=1))
        box.append(out["box"][:, :3] if cell == "sheared" else out["lengths"])
        frames[eng.step] = _frame(eng)
    return Trajectory(np.arange(NSTEPS + 1), np.concatenate(st), np.concatenate(box), frames, time.perf_counter() - t0)


def _box(eng, cell: str) -> np.ndarray:
    if cell == "sheared":
        b = eng.box
        return np.array([[b[2] - b[0], b[3] - b[1], b[4]]])
    return eng.box_lengths.copy()[None]


def _perturbed(packing, k: int, ax: int, sign: float):
    x = np.array(packing.positions)
    x[k, ax] *= 1.0 + sign * PERTURB_REL
    return packing.replace(positions=x)


def cases():
    """(label, packing, settings, loading, cell) of the two cells."""
    p, s, ld, _ = biaxial_short()
    q, t, sld, _ = shear_short("servo")
    t = t.__class__(**{**t.to_dict(), "flavour": "lammps"})
    return [("orthogonal", p, s, ld, "orthogonal"), ("sheared", wrapped_packing(q), t, sld, "sheared")]


def plan() -> tuple[list, list]:
    """Per cell: the code order's run, two perturbed runs of it (its envelope) and the fast run on 2
    threads, all native; the fast run judged against the code order's envelope (``envelope``)."""
    runs, comps = [], []
    for name, p, s, ld, cell in cases():
        members = [(f"x[{k}, {ax}] {'+' if sign > 0 else '-'}1e-15", k, ax, sign)
                   for k, ax, sign in ((7, 0, 1.0), (p.n // 2, 1, -1.0))]  # fmt: skip
        runs += [
            Run(f"{name}/code", NATIVE, s.flavour, f"{cell} cell, code order",
                lambda p=p, s=s, ld=ld, cell=cell: run(p, s, ld, cell, "code")),
            *(Run(f"{name}/{m}", NATIVE, s.flavour, f"{cell} cell, code order, {m}",
                  lambda p=p, s=s, ld=ld, cell=cell, k=k, ax=ax, sign=sign: run(_perturbed(p, k, ax, sign), s, ld,
                                                                                cell, "code"))
              for m, k, ax, sign in members),
            Run(f"{name}/fast", NATIVE, s.flavour, f"{cell} cell, fast order, 2 threads",
                lambda p=p, s=s, ld=ld, cell=cell: run(p, s, ld, cell, "fast", threads=2)),
        ]  # fmt: skip
        comps.append(
            Comparison(
                "envelope", f"{CASE}/{name}", (f"{name}/fast", f"{name}/code", *(f"{name}/{m[0]}" for m in members)),
                REASON,
                {"member_names": [m[0] for m in members], "nsteps": NSTEPS, "dump_every": DUMP_EVERY,
                 "d50": float(2 * np.median(p.radii)), "rule": RULE, "cell": cell, "run_name": "fast order"},
            )
        )  # fmt: skip
    return runs, comps


@case(CASE, TITLE, suites=("full",), order=36)
def fast_order(ctx: Context) -> CaseResult:
    res = CaseResult(CASE, TITLE, __doc__.split("\n\n", 1)[1].replace("\n", " "))
    for code in CODES:
        res.skip_code(code, "no code runs: the fast ordering is judged against the code's order, natively")
    runs, comps = plan()
    out = evaluate(res, ctx, runs, comps)
    rows = []
    for c in comps:
        sm = out.summaries.get(c.label)
        if not sm or not sm["complete"]:
            continue
        div, sdiv = sm["div"], sm["sdiv"]
        me = "native vs code order"
        env = np.max([div[k][1] for k in div if k != me], axis=0)
        name = c.label.split("/", 1)[1]
        ref, fast = out.runs[c.runs[1]], out.runs[c.runs[0]]
        rows.append(
            [name, NSTEPS, f"{div[me][1].max():.2e}", f"{env.max():.2e}", f"{sdiv[me][1].max():.2e}",
             f"{ref.elapsed:.2f}", f"{fast.elapsed:.2f}"]
        )  # fmt: skip
    res.tables.append(
        (
            "Fast order against the code order (largest divergence over the run; the envelope of the perturbed runs)",
            ["cell", "steps", "max|dx|/D50 fast", "max|dx|/D50 envelope", "stress fast", "code s", "fast s"],
            rows,
        )
    )
    return res
