"""Native run of a replayed deck with :class:`gransim.dem.DEMEngine`, step by step.

The engine steps with a fixed box (``engine.advance(Loading(), 1)``: nve/sphere, neighbour
check and rebuild, forces, second half step; a fixed box leaves positions alone); on every
step that is a multiple of the fix deform's N the driver then does what the codes' ``fix deform
end_of_step`` does (and what the engine's ``run_block`` does for its own loadings): the box of
that step from :func:`reference_runs.replay.deform.box_table` and the affine ``remap x`` of all
positions from the old box to the new one with the engine's own kernel
(:func:`gransim.dem.kernels.remap_x`, ``lambda = (x - lo_old) / L_old``, ``x = L_new lambda +
lo_new``, both axes, as ``Domain::x2lamda``/``lamda2x``). The stress of the step is the
engine's virial divided by the area of the new box (``compute pressure`` after ``fix deform``).

Box origin. The engine starts with lo = 0. Translating the packing by -lo would round every
coordinate (x - lo is not exact in general) and change the remap arithmetic, so it is not bit
for bit. Instead the engine is built on the translated packing (only to pass its checks), then
given the deck's own positions and box (``engine.x``, ``engine.lo``, ``engine.hi``, all origin-
general in the kernels) and its ``run`` set-up is redone (``engine._setup()``: wrap, neighbour
list in LIGGGHTS order, forces without spring increment). What the engine would need to make
this clean: a ``box_lo`` argument of ``DEMEngine`` (and a prescribed-box loading, see
docs/replay.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gransim.dem import DEMEngine, Loading
from gransim.dem import kernels as K
from gransim.errors import InputError

from .deck import ReplayDeck
from .deform import box_table

#: dump columns the native run can produce, in its units (SI)
NATIVE_COLUMNS = ("id", "type", "x", "y", "z", "vx", "vy", "vz", "omegax", "omegay", "omegaz",
                  "fx", "fy", "fz", "tqx", "tqy", "tqz", "mass", "radius", "diameter")


@dataclass(frozen=True, eq=False)
class NativeRun:
    """Per-step output of the native run.

    Attributes
    ----------
    steps : (T,) int64, 0..nsteps.
    lo, hi : (T, 2) box corners after each step (m).
    pressure : (T, 6) ``compute pressure ... virial`` components 1..6 (xx, yy, zz, xy, xz, yz;
        compression positive, N/m in 2D) with the virial of the step and the area of the box
        after it. p : (T,) its scalar (xx + yy)/2 in 2D.
    frames : {step: {column: (N,) array}} at the dump steps of the deck, in file order.
    n_rebuilds : neighbour-list builds after the set-up.
    n_contacts : (T,) contacts per step.
    """

    steps: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    pressure: np.ndarray
    p: np.ndarray
    frames: dict
    n_rebuilds: int
    n_contacts: np.ndarray


def dump_steps(deck: ReplayDeck) -> list:
    """Steps at which any dump of the deck writes a frame (0 and multiples of N up to the run)."""
    out = set()
    for d in deck.dumps:
        out.update(range(0, deck.nsteps + 1, d.every))
    return sorted(out)


def _frame(eng: DEMEngine, deck: ReplayDeck) -> dict:
    n = eng.x.shape[0]
    z = np.zeros(n)
    return {"id": deck.ids.copy(), "type": np.ones(n, np.int64), "x": eng.x[:, 0].copy(),
            "y": eng.x[:, 1].copy(), "z": z, "vx": eng.v[:, 0].copy(), "vy": eng.v[:, 1].copy(), "vz": z,
            "omegax": z, "omegay": z, "omegaz": eng.w.copy(), "fx": eng.f[:, 0].copy(),
            "fy": eng.f[:, 1].copy(), "fz": z, "tqx": z, "tqy": z, "tqz": eng.t.copy(),
            "mass": eng.m.copy(), "radius": eng.r.copy(), "diameter": 2.0 * eng.r}


def _pressure(vir, lo, hi):
    L0 = hi[0] - lo[0]
    L1 = hi[1] - lo[1]
    inv = 1.0 / (L0 * L1)
    comp = np.array([vir[0] * inv, vir[1] * inv, 0.0, vir[2] * inv, 0.0, 0.0])
    scalar = (vir[0] + vir[1]) / 2.0 * inv
    return comp, scalar


def build_engine(deck: ReplayDeck, threads=None) -> DEMEngine:
    """A DEMEngine in the state of the deck's ``run`` set-up, with the deck's box origin."""
    p = deck.packing
    lo, hi = np.array(deck.box_lo, float), np.array(deck.box_hi, float)
    shifted = p.replace(positions=np.asarray(p.positions) - lo)
    try:
        eng = DEMEngine(shifted, deck.settings, velocities=deck.velocities, spins=deck.spins, threads=threads)
    except InputError as exc:
        raise InputError(f"{deck.path}: the native engine refuses the deck: {exc}") from None
    eng.x[:] = np.asarray(p.positions, float)
    eng.lo[:] = lo
    eng.hi[:] = hi
    eng.n_rebuilds = 0
    eng._setup()                # the run set-up again, in the deck's own box (see module docstring)
    eng._reset_energy_budget()
    eng.n_rebuilds = 0
    return eng


def run_native(deck: ReplayDeck, progress=None) -> NativeRun:
    """Run the deck natively (see the module docstring); ``progress(k, n)`` is called now and then.

    Raises SimulationError (from the engine) naming the step on a divergence.
    """
    eng = build_engine(deck)
    n = deck.nsteps
    lo_t, hi_t = box_table(deck.deform, deck.box_lo, deck.box_hi, deck.settings.dt, n, deck.engine)
    every = deck.deform.every if deck.deform is not None else 0
    T = n + 1
    lo = np.empty((T, 2))
    hi = np.empty((T, 2))
    pres = np.empty((T, 6))
    ps = np.empty(T)
    nc = np.zeros(T, np.int64)
    lo[0], hi[0] = eng.lo, eng.hi
    pres[0], ps[0] = _pressure(eng.virial, eng.lo, eng.hi)
    nc[0] = eng.n_contacts
    want = set(dump_steps(deck))
    frames = {0: _frame(eng, deck)} if 0 in want else {}
    fixed = Loading()
    for k in range(1, n + 1):
        lo_old, hi_old = eng.lo.copy(), eng.hi.copy()
        out = eng.advance(fixed, 1)
        if every and k % every == 0:
            K.remap_x(eng.x, lo_old, hi_old, lo_t[k], hi_t[k])
            eng.lo[:] = lo_t[k]
            eng.hi[:] = hi_t[k]
            # the engine's divergence check allows kinetic energy up to a multiple of the work of
            # the cell; advance() saw a fixed box, so add this step's work as run_block would
            Lo, Ln = hi_old - lo_old, eng.hi - eng.lo
            s = out["stress"][0]
            area = Ln[0] * Ln[1]
            dw = -(s[0, 0] * area * (Ln[0] - Lo[0]) / Lo[0] + s[1, 1] * area * (Ln[1] - Lo[1]) / Lo[1])
            if hasattr(eng, "_work"):
                eng._work += abs(float(dw))
        lo[k], hi[k] = eng.lo, eng.hi
        pres[k], ps[k] = _pressure(eng.virial, eng.lo, eng.hi)
        nc[k] = out["n_contacts"][0]
        if k in want:
            frames[k] = _frame(eng, deck)
        if progress is not None and (k % 200 == 0 or k == n):
            progress(k, n)
    return NativeRun(np.arange(T), lo, hi, pres, ps, frames, int(eng.n_rebuilds), nc)
