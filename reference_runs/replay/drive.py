"""Native run of a replayed deck: :class:`gransim.dem.DEMEngine` (orthogonal box) or, for a
sheared (triclinic) LAMMPS deck, :class:`gransim.dem.sheared.ShearEngine`.

Orthogonal decks. The engine is built in the deck's own box (``DEMEngine(..., box=(lo, hi))``:
the positions stay as the data file has them; translating them by -lo would round every
coordinate and change the remap arithmetic) and advanced under a
:class:`gransim.dem.settings.PrescribedBox`: the box of every step from
:func:`reference_runs.replay.deform.box_table`, applied inside the engine's step loop in its
own order (``fix deform end_of_step``: on the steps with ``ntimestep % N == 0`` the new box and
the affine ``remap x`` of all positions from the old box to it, ``lambda = (x - lo_old) /
L_old``, ``x = L_new lambda + lo_new``, as ``Domain::x2lamda``/``lamda2x``, even when the box
did not change). The stress of a step is the engine's virial of that step divided by the area
of the new box (``compute pressure`` after ``fix deform``); the scalar is (xx + yy)/2 of the
virial times 1/area, in LAMMPS' order. The run is advanced in chunks between dump steps only.

Sheared decks (LAMMPS ``change_box all triclinic`` or a data file with a tilt, and ``fix deform
N xy erate|trate|vel|final|delta ... remap v``): :func:`run_sheared` through
:class:`gransim.dem.sheared.ShearEngine` (``flavour="lammps"``), built in the deck's own box
(``box=(lo, hi, xy)``) and run under the deck's style and N as they are
(:class:`~gransim.dem.sheared.ShearLoading` ``xy``, ``value``, ``every``); the pressure of a
step is formed from the engine's per-step virial in ``compute pressure``'s order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gransim.dem import DEMEngine
from gransim.dem.settings import PrescribedBox
from gransim.dem.sheared import ShearEngine
from gransim.errors import InputError, SimulationError

from .deck import ReplayDeck
from .deform import box_table

#: dump columns the native run can produce, in its units (SI)
NATIVE_COLUMNS = (
    "id",
    "type",
    "x",
    "y",
    "z",
    "vx",
    "vy",
    "vz",
    "omegax",
    "omegay",
    "omegaz",
    "fx",
    "fy",
    "fz",
    "tqx",
    "tqy",
    "tqz",
    "mass",
    "radius",
    "diameter",
)


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
    xy : (T,) the box's xy tilt after each step (m; zeros for an orthogonal box).
    """

    steps: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    pressure: np.ndarray
    p: np.ndarray
    frames: dict
    n_rebuilds: int
    n_contacts: np.ndarray
    xy: np.ndarray | None = None


def dump_steps(deck: ReplayDeck) -> list:
    """Steps at which any dump of the deck writes a frame (0 and multiples of N up to the run)."""
    out = set()
    for d in deck.dumps:
        out.update(range(0, deck.nsteps + 1, d.every))
    return sorted(out)


def _frame(eng: DEMEngine, deck: ReplayDeck) -> dict:
    n = eng.x.shape[0]
    z = np.zeros(n)
    return {
        "id": deck.ids.copy(),
        "type": np.ones(n, np.int64),
        "x": eng.x[:, 0].copy(),
        "y": eng.x[:, 1].copy(),
        "z": z,
        "vx": eng.v[:, 0].copy(),
        "vy": eng.v[:, 1].copy(),
        "vz": z,
        "omegax": z,
        "omegay": z,
        "omegaz": eng.w.copy(),
        "fx": eng.f[:, 0].copy(),
        "fy": eng.f[:, 1].copy(),
        "fz": z,
        "tqx": z,
        "tqy": z,
        "tqz": eng.t.copy(),
        "mass": eng.m.copy(),
        "radius": eng.r.copy(),
        "diameter": 2.0 * eng.r,
    }


def _pressure(vir, lo, hi):
    L0 = hi[0] - lo[0]
    L1 = hi[1] - lo[1]
    inv = 1.0 / (L0 * L1)
    comp = np.array([vir[0] * inv, vir[1] * inv, 0.0, vir[2] * inv, 0.0, 0.0])
    scalar = (vir[0] + vir[1]) / 2.0 * inv
    return comp, scalar


def build_engine(deck: ReplayDeck, threads=None) -> DEMEngine:
    """A DEMEngine in the state of the deck's ``run`` set-up, in the deck's own box."""
    try:
        return DEMEngine(
            deck.packing,
            deck.settings,
            velocities=deck.velocities,
            spins=deck.spins,
            threads=threads,
            box=(deck.box_lo, deck.box_hi),
        )
    except InputError as exc:
        raise InputError(f"{deck.path}: the native engine refuses the deck: {exc}") from None


def _chunks(deck: ReplayDeck):
    """(start, stop) step ranges between the dump steps (and the end of the run)."""
    stops = sorted({s for s in dump_steps(deck) if 0 < s <= deck.nsteps} | {deck.nsteps})
    out, a = [], 0
    for b in stops:
        out.append((a, b))
        a = b
    return out


def run_native(deck: ReplayDeck, progress=None) -> NativeRun:
    """Run the deck natively (see the module docstring); ``progress(k, n)`` is called now and then.

    Raises SimulationError (from the engine) naming the step on a divergence.
    """
    if deck.sheared:
        return run_sheared(deck, progress)
    eng = build_engine(deck)
    n = deck.nsteps
    lo, hi = box_table(deck.deform, deck.box_lo, deck.box_hi, deck.settings.dt, n, deck.engine)
    every = deck.deform.every if deck.deform is not None else 0
    remap = np.zeros(n + 1, np.bool_)
    if every:
        remap[every::every] = True
    loading = PrescribedBox(lo, hi, remap, step0=0)
    T = n + 1
    pres = np.empty((T, 6))
    ps = np.empty(T)
    nc = np.zeros(T, np.int64)
    pres[0], ps[0] = _pressure(eng.virial, eng.lo, eng.hi)
    nc[0] = eng.n_contacts
    want = set(dump_steps(deck))
    frames = {0: _frame(eng, deck)} if 0 in want else {}
    for a, b in _chunks(deck):
        out = eng.advance(loading, b - a)
        for j, k in enumerate(range(a + 1, b + 1)):
            pres[k], ps[k] = _pressure(out["virial"][j], lo[k], hi[k])
        nc[a + 1 : b + 1] = out["n_contacts"]
        if not (np.array_equal(eng.lo, lo[b]) and np.array_equal(eng.hi, hi[b])):
            raise SimulationError(
                f"step {b}: the engine's box {eng.lo.tolist()}..{eng.hi.tolist()} is not "
                f"the prescribed {lo[b].tolist()}..{hi[b].tolist()}"
            )  # pragma: no cover
        if b in want:
            frames[b] = _frame(eng, deck)
        if progress is not None:
            progress(b, n)
    return NativeRun(np.arange(T), lo, hi, pres, ps, frames, int(eng.n_rebuilds) - 1, nc)


def build_shear_engine(deck: ReplayDeck):
    """A ShearEngine (LAMMPS flavour) in the deck's own box (``box=(lo, hi, xy)``: the data file's
    positions and box as they are), before the ``run`` set-up (:meth:`start_run`)."""
    box = (np.array(deck.box_lo, float), np.array(deck.box_hi, float), float(deck.tilt))
    try:
        return ShearEngine(
            deck.packing, deck.settings, velocities=deck.velocities, spins=deck.spins, flavour="lammps", box=box
        )
    except InputError as exc:
        raise InputError(f"{deck.path}: the sheared-cell engine refuses the deck: {exc}") from None


def run_sheared(deck: ReplayDeck, progress=None) -> NativeRun:
    """Run a sheared (triclinic) LAMMPS deck through ShearEngine (see :func:`build_shear_engine`).

    The pressure of a step is ``compute pressure ... virial`` of the engine's virial of that step
    (:meth:`~gransim.dem.sheared.ShearEngine.advance` returns it per step) and the box after the
    step: components virial[k] * (1/(Lx Ly)), scalar (virial_xx + virial_yy)/2 * (1/(Lx Ly)), in
    LAMMPS' order (``ComputePressure::compute_scalar``/``compute_vector``, 2D).
    """
    eng = build_shear_engine(deck)
    n = deck.nsteps
    eng.start_run(deck.shear, n)
    builds0 = eng.n_rebuilds
    T = n + 1
    lo = np.empty((T, 2))
    hi = np.empty((T, 2))
    xy = np.empty(T)
    pres = np.zeros((T, 6))
    ps = np.empty(T)
    nc = np.zeros(T, np.int64)
    lo[:, 0], hi[:, 0] = eng.box[0], eng.box[2]
    lo[0, 1], hi[0, 1], xy[0] = eng.box[1], eng.box[3], eng.box[4]
    pres[0], ps[0] = _pressure(eng.virial, lo[0], hi[0])
    nc[0] = eng.n_contacts
    want = set(dump_steps(deck))
    frames = {0: _frame(eng, deck)} if 0 in want else {}
    for a, b in _chunks(deck):
        out = eng.advance(b - a)
        box = out["box"]  # lx, ly, xy, ylo, yhi
        lo[a + 1 : b + 1, 1], hi[a + 1 : b + 1, 1], xy[a + 1 : b + 1] = box[:, 3], box[:, 4], box[:, 2]
        for j, k in enumerate(range(a + 1, b + 1)):
            pres[k], ps[k] = _pressure(out["virial"][j], lo[k], hi[k])
        nc[a + 1 : b + 1] = out["n_contacts"]
        if b in want:
            frames[b] = _frame(eng, deck)
        if progress is not None:
            progress(b, n)
    return NativeRun(np.arange(T), lo, hi, pres, ps, frames, int(eng.n_rebuilds - builds0), nc, xy)
