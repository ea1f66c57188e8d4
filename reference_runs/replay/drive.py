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

import re
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
class State:
    """The native state at one output point: after the set-up of a ``run`` (``setup`` True: the
    codes' ``Verlet::setup`` evaluation, forces without spring increment) or after a step.

    Attributes
    ----------
    step : the time step. setup : see above.
    x, v : (N, 2) positions (m), velocities (m/s); w : (N,) spins (rad/s); f : (N, 2) forces (N),
        t : (N,) torques (N m) of the evaluation; all in file order.
    lo, hi : (2,) box corners (m); xy : tilt (m). virial : (4,) xx, yy, xy, yx (N m).
    contacts : None, or the neighbour list and its history (dict of ``a``, ``b`` (M,) int,
        ``sx``, ``sy`` (M,) image shifts, ``both`` (M,) owned pair, ``hist`` (M, 2) springs, m),
        kept when the deck dumps contacts (``dump local``).
    """

    step: int
    setup: bool
    x: np.ndarray
    v: np.ndarray
    w: np.ndarray
    f: np.ndarray
    t: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    xy: float
    virial: np.ndarray
    contacts: dict | None = None


@dataclass(frozen=True, eq=False)
class NativePart:
    """The native output of one ``run``: steps ``start`` .. ``end``; per step (T = end - start + 1,
    row 0 the set-up) ``lo``, ``hi`` (T, 2), ``xy`` (T,), the virial pressure ``pressure`` (T, 6)
    (``compute pressure ... virial`` components 1..6, compression positive, N/m) and its scalar
    ``p`` (T,), ``n_contacts`` (T,), ``virial`` (T, 4) (xx, yy, xy, yx, N m); ``states`` {step:
    :class:`State`} at the set-up and at the steps the deck prints something that needs the
    particles (dump frames, kinetic thermo columns)."""

    start: int
    end: int
    lo: np.ndarray
    hi: np.ndarray
    xy: np.ndarray
    pressure: np.ndarray
    p: np.ndarray
    n_contacts: np.ndarray
    states: dict
    virial: np.ndarray | None = None


@dataclass(frozen=True, eq=False)
class NativeRun:
    """Output of the native run: one :class:`NativePart` per ``run`` of the deck.

    Attributes
    ----------
    parts : tuple of NativePart, in the order of the deck's runs.
    n_rebuilds : neighbour-list builds after the first set-up (a later run's set-up counts).
    m, r : (N,) masses (kg) and radii (m) in file order.

    The properties ``steps``, ``lo``, ``hi``, ``pressure``, ``p``, ``n_contacts``, ``xy`` join the
    parts' rows (a later run repeats its first step: its set-up); ``frames`` is {step: dump
    columns} of the first state kept at each step.
    """

    parts: tuple
    n_rebuilds: int
    m: np.ndarray
    r: np.ndarray
    ids: np.ndarray

    def _join(self, name):
        return np.concatenate([getattr(q, name) for q in self.parts])

    steps = property(lambda self: np.concatenate([np.arange(q.start, q.end + 1) for q in self.parts]))
    lo = property(lambda self: self._join("lo"))
    hi = property(lambda self: self._join("hi"))
    xy = property(lambda self: self._join("xy"))
    pressure = property(lambda self: self._join("pressure"))
    p = property(lambda self: self._join("p"))
    n_contacts = property(lambda self: self._join("n_contacts"))

    @property
    def frames(self) -> dict:
        out = {}
        for q in self.parts:
            for s, st in sorted(q.states.items()):
                out.setdefault(s, frame(st, self))
        return out


def dump_frames(deck: ReplayDeck, d) -> list:
    """(step, run index, set-up) of every frame dump ``d`` writes, in the codes' order: in each
    run it is active in, the multiples of its N from the run's first to its last step, each step
    once (the last step of a run and the first of the next give one frame, written by the first;
    a frame at a run's first step records the set-up). Measured on LIGGGHTS 3.8.0 and the rule of
    ``reference_runs.expect``."""
    out, written = [], set()
    for k, run in enumerate(deck.runs):
        if not d.active_in(k):
            continue
        e = d.every
        for s in range((run.start + e - 1) // e * e, run.end + 1, e):
            if s not in written:
                written.add(s)
                out.append((s, k, s == run.start))
    return out


def dump_steps(deck: ReplayDeck) -> list:
    """Steps at which any dump of the deck writes a frame."""
    return sorted({s for d in deck.dumps for s, _, _ in dump_frames(deck, d)})


#: thermo keywords whose value needs the particles' velocities (the others come from the box and
#: the virial of every step)
_KINETIC = ("ke", "temp", "etotal", "press", "pxx", "pyy", "pzz", "pxy", "pxz", "pyz")


def _needs_state(deck: ReplayDeck, run) -> bool:
    for kw in run.thermo_columns:
        m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[\d+\])?", kw)
        if kw.lower() in _KINETIC:
            return True
        if m and m.group(1) in deck.computes:
            c = deck.computes[m.group(1)]
            if c.style == "temp" or c.keflag:
                return True
    return False


def _stops(deck: ReplayDeck, k: int) -> set:
    """Steps of run ``k`` (after its first) where the native state is kept."""
    run = deck.runs[k]
    want = {s for d in deck.dumps for s, kk, setup in dump_frames(deck, d) if kk == k and not setup}
    if _needs_state(deck, run):
        want.update(s for s in run.thermo_steps() if s > run.start)
    return want


def _state(eng, step: int, setup: bool, contacts: bool, xy: float = 0.0, box=None) -> State:
    lo, hi = (eng.lo, eng.hi) if box is None else box
    c = None
    if contacts:
        c = {
            "a": eng.ea.copy(),
            "b": eng.eb.copy(),
            "sx": eng.esx.copy(),
            "sy": eng.esy.copy(),
            "both": eng.both.copy(),
            "hist": eng.xi.copy(),
        }
    return State(
        int(step),
        bool(setup),
        eng.x.copy(),
        eng.v.copy(),
        eng.w.copy(),
        eng.f.copy(),
        eng.t.copy(),
        np.array(lo, float).copy(),
        np.array(hi, float).copy(),
        float(xy),
        np.array(eng.virial, float).copy(),
        c,
    )


def frame(st: State, nat) -> dict:
    """The dump custom columns of a state (file order)."""
    n = st.x.shape[0]
    z = np.zeros(n)
    return {
        "id": nat.ids.copy(),
        "type": np.ones(n, np.int64),
        "x": st.x[:, 0].copy(),
        "y": st.x[:, 1].copy(),
        "z": z,
        "vx": st.v[:, 0].copy(),
        "vy": st.v[:, 1].copy(),
        "vz": z,
        "omegax": z,
        "omegay": z,
        "omegaz": st.w.copy(),
        "fx": st.f[:, 0].copy(),
        "fy": st.f[:, 1].copy(),
        "fz": z,
        "tqx": z,
        "tqy": z,
        "tqz": st.t.copy(),
        "mass": nat.m.copy(),
        "radius": nat.r.copy(),
        "diameter": 2.0 * nat.r,
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


def setup_run(eng: DEMEngine) -> None:
    """The set-up of a further ``run`` (``Verlet::setup`` of both codes): wrap, neighbour build
    with the history hand-over of the pairs that overlap (``fix contact/history`` or ``fix
    neigh/history`` ``pre_exchange``), forces without spring increment (pair_gran.cpp:665-667;
    pair_gran_hooke_history.cpp:119-120). A ``run 0`` is this set-up alone.

    ``DEMEngine`` has no public method for it (its constructor is the first run's set-up, with
    every spring zero): this calls the engine's own rebuild and force evaluation, the same calls
    its stepping makes on a list build, unless the engine offers ``setup()``.

    LIGGGHTS leaves every spring as it is in a set-up evaluation: the Coulomb cap scales the force
    but writes the spring back only when the history is updated (tangential_model_history.h:195-200,
    ``if (update_history) shear = -Ft/kt``), and so does the native LIGGGHTS law
    (:mod:`gransim.contacts.hooke`); LAMMPS writes it in either case (pair_gran_hooke_history.cpp),
    and so does its flavour. Even so, without putting a LIGGGHTS deck's springs back after the
    set-up, the user deck of tests/replay/decks is 8e-4 off in stress from its second run on
    (measured): some other spring change of the native set-up that LIGGGHTS does not make is not
    yet found, so the springs are put back (the forces of the set-up are the same either way).
    """
    setup = getattr(eng, "setup", None)
    if callable(setup):
        setup()
        return
    eng._rebuild(carry=True)
    springs = eng.xi.copy()
    eng._forces(update=False)
    if eng.settings.flavour == "liggghts":
        eng.xi[:] = springs
    eng.stress = eng.stress_tensor(eng.box_lengths)


def run_native(deck: ReplayDeck, progress=None) -> NativeRun:
    """Run the deck natively (see the module docstring), one ``run`` after the other, each after
    its set-up (:func:`setup_run`; the first is the engine's construction); ``progress(k, n)`` is
    called now and then.

    Raises SimulationError (from the engine) naming the step on a divergence.
    """
    if deck.sheared:
        return run_sheared(deck, progress)
    eng = build_engine(deck)
    contacts = any(d.style == "local" for d in deck.dumps)
    every = deck.deform.every if deck.deform is not None else 0
    builds0 = int(eng.n_rebuilds)
    parts = []
    for k, run in enumerate(deck.runs):
        if k:
            setup_run(eng)
        n = run.nsteps
        lo, hi = box_table(deck.deform, eng.lo.copy(), eng.hi.copy(), deck.settings.dt, n, deck.engine, run.start)
        steps = np.arange(run.start, run.end + 1)
        remap = np.zeros(n + 1, np.bool_)
        if every:
            remap[1:] = steps[1:] % every == 0
        T = n + 1
        pres = np.empty((T, 6))
        ps = np.empty(T)
        nc = np.zeros(T, np.int64)
        vir = np.zeros((T, 4))
        vir[0] = eng.virial
        pres[0], ps[0] = _pressure(eng.virial, eng.lo, eng.hi)
        nc[0] = eng.n_contacts
        states = {run.start: _state(eng, run.start, True, contacts)}
        want = _stops(deck, k)
        a = run.start
        if n:
            loading = PrescribedBox(lo, hi, remap, step0=run.start)
        for b in sorted(want | {run.end}):
            if b == a:
                continue
            out = eng.advance(loading, b - a)
            for j, s in enumerate(range(a + 1 - run.start, b + 1 - run.start)):
                pres[s], ps[s] = _pressure(out["virial"][j], lo[s], hi[s])
                vir[s] = out["virial"][j]
            nc[a + 1 - run.start : b + 1 - run.start] = out["n_contacts"]
            if not (np.array_equal(eng.lo, lo[b - run.start]) and np.array_equal(eng.hi, hi[b - run.start])):
                raise SimulationError(
                    f"step {b}: the engine's box {eng.lo.tolist()}..{eng.hi.tolist()} is not the prescribed "
                    f"{lo[b - run.start].tolist()}..{hi[b - run.start].tolist()}"
                )  # pragma: no cover
            if b in want:
                states[b] = _state(eng, b, False, contacts)
            if progress is not None:
                progress(b, deck.nsteps)
            a = b
        parts.append(NativePart(run.start, run.end, lo, hi, np.zeros(T), pres, ps, nc, states, vir))
    return NativeRun(tuple(parts), int(eng.n_rebuilds) - builds0, eng.m.copy(), eng.r.copy(), deck.ids.copy())


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
    LAMMPS' order (``ComputePressure::compute_scalar``/``compute_vector``, 2D). One ``run``.
    """
    eng = build_shear_engine(deck)
    (run,) = deck.runs
    n = run.nsteps
    eng.start_run(deck.shear, n)
    builds0 = eng.n_rebuilds
    T = n + 1
    lo = np.empty((T, 2))
    hi = np.empty((T, 2))
    xy = np.empty(T)
    pres = np.zeros((T, 6))
    ps = np.empty(T)
    nc = np.zeros(T, np.int64)
    vir = np.zeros((T, np.size(eng.virial)))
    vir[0] = eng.virial
    lo[:, 0], hi[:, 0] = eng.box[0], eng.box[2]
    lo[0, 1], hi[0, 1], xy[0] = eng.box[1], eng.box[3], eng.box[4]
    pres[0], ps[0] = _pressure(eng.virial, lo[0], hi[0])
    nc[0] = eng.n_contacts
    states = {0: _state(eng, 0, True, False, xy[0], (lo[0], hi[0]))}
    want = _stops(deck, 0)
    a = 0
    for b in sorted(want | {n}):
        if b == a:
            continue
        out = eng.advance(b - a)
        box = out["box"]  # lx, ly, xy, ylo, yhi
        lo[a + 1 : b + 1, 1], hi[a + 1 : b + 1, 1], xy[a + 1 : b + 1] = box[:, 3], box[:, 4], box[:, 2]
        for j, k in enumerate(range(a + 1, b + 1)):
            pres[k], ps[k] = _pressure(out["virial"][j], lo[k], hi[k])
            vir[k] = out["virial"][j]
        nc[a + 1 : b + 1] = out["n_contacts"]
        if b in want:
            states[b] = _state(eng, b, False, False, xy[b], (lo[b], hi[b]))
        if progress is not None:
            progress(b, n)
        a = b
    part = NativePart(0, n, lo, hi, xy, pres, ps, nc, states, vir)
    return NativeRun((part,), int(eng.n_rebuilds - builds0), eng.m.copy(), eng.r.copy(), deck.ids.copy())
