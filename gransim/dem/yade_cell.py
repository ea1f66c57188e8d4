"""The ``yade`` arithmetic as the engine's cell (``Engine(..., flavour="yade")``): YADE 2023.02a's
periodic iteration (:mod:`gransim.dem.yade_arithmetic`: its cell, collider, interaction container,
Cundall and Strack's law and leapfrog, each to the bit) stepped by the one step loop of
:class:`gransim.dem.engine.Engine`, with the engine's checks, views, energies and checkpoints.

YADE's iteration k is: the cell's prologue, the collider when it is active, the interaction loop
(forces), the script's ``PyRunner`` (``getStress`` and the loading's ``velGrad`` for the next
step), ``NewtonIntegrator`` (yade_arithmetic module docstring). The engine's set-up is iteration
0 up to the stress; an engine step k is the ``PyRunner``'s control of frame k-1, Newton, then
iteration k up to its stress, so that the state after step k is YADE's frame k (the state the
``PyRunner`` of step k sees: positions x_k, velocities v_(k-1/2) with the mean field, forces of
step k). The same operations in the same order as YADE's: the control is a pure function of the
stress and the cell of frame k-1, evaluated with the script's Python arithmetic (IEEE double
operations in the same order, here compiled).

The loadings are those of the YADE decks (``reference_runs/yade/dem_script.py``): the orthogonal
cell under a :class:`~gransim.dem.settings.Loading` (each axis fixed, at an engineering rate
c = rate L0 dt with L0 the side length at the start of the run, or under the proportional stress
servo), the sheared cell under a :class:`~gransim.dem.sheared.ShearLoading` with ``xy erate``
(every step; y fixed or under the servo); and one call of Guo & Zhao's ``simDEM.shear2D`` on the
sheared cell (:class:`VelGradRun`, below). The law is the engine's, the registered
:class:`~gransim.contacts.yade_cundall_strack.YadeCundallStrack` (``DEMSettings.hooke_law("yade")``
by default: the constant stiffnesses kn, kt and the friction angle atan(mu) of a
:class:`~gransim.dem.settings.DEMSettings` whose dampings are 0, YADE's decks being undamped; or
Guo & Zhao's radius-dependent stiffnesses); its time-step limit is the law's
(:func:`~gransim.contacts.yade_cundall_strack.yade_timescale`). NewtonIntegrator's non-viscous
damping is the cell's (``cell_options={"damping": ...}``, or the saved scene's).

Guo & Zhao's RVE call (Guo & Zhao, "A coupled FEM/DEM approach for hierarchical multiscale
modelling of granular media", IJNME 99, 2014; their ``simDEM.py``:53-62 on Debian's yade
2023.02a): a scene deserialised (``Omega.stringToScene``), ``Cell.velGrad = D / (ns dt)``,
``O.run(ns, True)``, ``Cell.velGrad = 0``, the scene serialised. The engine runs it as

- the construction from the saved scene: ``Engine.from_checkpoint(..., arrays=``
  :func:`scene_checkpoint` ``(state), step=state.iteration)`` loads a
  :class:`~gransim.dem.yade_arithmetic.YadeRVEState` (YADE's serialised scene: no bound lists, only
  the real interactions) and runs the set-up, iteration ``state.iteration`` up to its forces: the
  cell's prologue with the velGrad the scene was saved with, the collider's first run (its initial
  sort: the bound lists are not saved, InsertionSortCollider.cpp:264-272) and the interaction loop
  (with no set-up that the scene overwrites, as :meth:`~gransim.dem.engine.Engine.from_checkpoint`).
  The set-up does not read the call's D (it reaches the cell through nextVelGrad, applied by the
  integrator after it, NewtonIntegrator.cpp:149-153): for a read-only scene it is kept while the
  scene lives and restored by the next loads of it (the Newton iterates of a load step, which all
  start from the committed scene);
- ``start_run(VelGradRun(D / (ns dt)), ns)``: ``Cell.velGrad`` set from Python, i.e. nextVelGrad
  and velGradChanged (core/Cell.hpp:138-142), applied by the first step's integrator;
- ``advance(ns)``: ns engine steps, each NewtonIntegrator with the damping, the disks' rotation
  theta += spin dt, then the next iteration up to its forces, except at the run's last step: the
  scene is saved after that step's integrator, where ``O.run(ns, True)`` stops;
- :meth:`YadeCell.scene`: the saved scene (``Cell.velGrad = 0`` after the run: nextVelGrad 0,
  velGradChanged; the real interactions only, in container order). A run started on an engine
  whose last run saved its scene loads that scene first, as the script's next call does.

Stress: YADE's ``utils.getStress()`` (tension positive, sum F (x) b over det(hSize)), given by the
engine compression positive, ``stress = -sig^T`` (its [0, 1] the xy virial component sum d_x f_y,
as the other cells), with YADE's own bits.
"""

from __future__ import annotations

import math
import threading
from collections import namedtuple
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from .._numba import njit
from .._validate import as_int
from ..contacts.yade_cundall_strack import yade_law
from ..errors import InputError, SimulationError
from ..geometry import Packing
from .settings import DEMSettings, Integration, Loading
from .sheared import ShearLoading
from .yade_arithmetic import (
    _FIRST_RUNS,
    _FIXED,
    _FULL,
    _RATE,
    _SERVO,
    _TIE,
    _TOO_BIG,
    RVE_STATE_FIELDS,
    VERLET_FACTOR,
    YadeRVEState,
    _cell_update,
    _collide,
    _interactions,
    _newton_damped,
    _stress,
    _unsheared_z,
    yade_cell_z,
)

#: the bodies: positions, velocities (N, 2), spins, forces, torques, masses, inertias, radii; the
#: collider's reference positions, sweep lengths, last updates and bounds
#: collider's reference positions, sweep lengths, last updates and bounds, and each disk's rotation
#: ``theta`` (rad, counter-clockwise): spin dt summed by the steps of a :class:`VelGradRun`, as
#: NewtonIntegrator turns ``State::ori`` (leapfrogSphericalRotate, pkg/dem/NewtonIntegrator.cpp:
#: 327-337: by |angVel| dt about angVel with the spin the step ends with, i.e. spin dt about z for a
#: disk whose x and y rotations are blocked); read by nothing else
YadeBodies = namedtuple(
    "YadeBodies",
    ["pos", "vel", "spin", "force", "torque", "mass", "inertia", "radius", "ref_pos", "sweep", "last_update",
     "aabb_min", "aabb_max", "theta"],
)  # fmt: skip
#: the cell: hSize, velGrad, nextVelGrad, prevVelGrad, prevHSize, velGrad prevHSize, the column
#: sizes, the unshear matrix, the skew cosines, the previous sizes, the stress of the last frame
#: (YADE's, (2, 2) N/m tension positive), ``misc`` = (z, maxVelocitySq, verletDist,
#: NewtonIntegrator.damping, the disks' z), ``changed`` (1,) velGradChanged
YadeCellState = namedtuple(
    "YadeCellState",
    ["H", "L", "nextL", "Lprev", "prevH", "VP", "size", "U", "cos", "prev_size", "sig", "misc", "changed"],
)
#: the collider's bounds and the interaction container (slot: ids -> position, n_intr (1,))
YadeContainer = namedtuple(
    "YadeContainer", ["bc", "bi", "bp", "bm", "lo_idx", "slot", "n_intr", "i_id", "i_cd", "i_real", "i_geom", "i_fs"]
)

#: columns of the block's per-step rows: YADE's stress (00, 01, 10, 11), real interactions, the sum
#: of their penetrations, the kinetic energy, hSize (00, 01, 10, 11), the velGrad of the step
#: (00, 01, 10, 11)
OUT_COLUMNS = 19

#: the checkpoint datasets of the yade cell: name -> (state object, field)
CHECKPOINT = {
    **{f"yade/{f}": ("bodies", f) for f in YadeBodies._fields if f not in ("mass", "inertia", "radius")},
    **{f"yade/{f}": ("cell", f) for f in YadeCellState._fields},
    **{f"yade/{f}": ("container", f) for f in YadeContainer._fields if f != "slot"},
}


@njit
def control_rate(mode, a, b, h, p, dt):
    """``axis_rate`` of the deck's script (reference_runs/yade/dem_script.py) in its Python
    arithmetic: fixed 0; rate a / (dt h), a = rate L0 dt; servo a (p - b) / dt, a = dt gain,
    b the target, p the stress (compression positive) (1/s)."""
    if mode == _FIXED:
        return 0.0
    if mode == _RATE:
        return a / (dt * h)
    return a * (p - b) / dt


@njit
def control_grad(ctl, H, sig, dt, out):
    """The velGrad (2, 2) the script sets after the stress ``sig`` of a frame with the cell ``H``:
    ``ctl`` = (mode_x, a_x, b_x, mode_y, a_y, b_y, erate, L0y)."""
    gxx = control_rate(int(ctl[0]), ctl[1], ctl[2], H[0, 0], -sig[0, 0], dt)
    gyy = control_rate(int(ctl[3]), ctl[4], ctl[5], H[1, 1], -sig[1, 1], dt)
    erate = ctl[6]
    gxy = erate * ctl[7] / H[1, 1] if erate != 0.0 else 0.0
    out[0, 0] = gxx
    out[0, 1] = gxy
    out[1, 0] = 0.0
    out[1, 1] = gyy


#: the law's parameters as the kernels read them (:func:`law_array`): kn, ks, tan(friction angle),
#: young, poisson, avoidGranularRatcheting (1.0 or 0.0)
LAW_KN, LAW_KS, LAW_TAN, LAW_YOUNG, LAW_POISSON, LAW_AGR = range(6)


def law_array(law) -> np.ndarray:
    """(6,) float64 of a :class:`~gransim.contacts.yade_cundall_strack.YadeCundallStrack` for the
    kernels: kn, ks, tan(friction_angle) (``std::tan``, glibc's, as ``math.tan``: FrictPhys.cpp:
    39-41), young, poisson, 1.0 if avoid_granular_ratcheting else 0.0."""
    return np.array(
        [law.kn, law.ks, math.tan(law.friction_angle), law.young, law.poisson,
         1.0 if law.avoid_granular_ratcheting else 0.0],
        float,
    )  # fmt: skip


@njit(inline="always")
def _iteration_rest(it, first, b, c, q, lp, dt, stress):
    """Iteration ``it`` of YADE after Newton: prologue, the collider when active (``first``: its
    initial sort), the interactions with the law ``lp`` (:func:`law_array`), the stress when
    ``stress``. Returns (error, axis) of the collider."""
    z = c.misc[0]
    has_shear = _cell_update(c.H, z, c.L, dt, c.prevH, c.VP, c.size, c.U, c.cos)
    max_v2 = c.misc[1]
    err, axis = 0, -1
    if first or max_v2 >= 1.0 or max_v2 == 0.0:  # InsertionSortCollider::isActivated
        zc = _unsheared_z(c.H, c.size, c.misc[4])  # +0.0 for disks at z = 0
        err, axis = _collide(
            it, first, b.pos, b.radius, has_shear, c.U, c.cos, c.size, c.misc[2], b.ref_pos, b.sweep, b.last_update,
            b.aabb_min, b.aabb_max, q.bc, q.bi, q.bp, q.bm, q.lo_idx, q.slot, q.n_intr, q.i_id, q.i_cd, q.i_real,
            q.i_geom, q.i_fs, zc,
        )  # fmt: skip
        if err != 0:
            return err, axis
    _interactions(
        b.pos, b.vel, b.spin, b.radius, c.H, c.VP, lp[LAW_KN], lp[LAW_KS], lp[LAW_TAN], lp[LAW_YOUNG],
        lp[LAW_POISSON], dt, lp[LAW_AGR] != 0.0, q.n_intr, q.i_id, q.i_cd, q.i_real, q.i_geom, q.i_fs, b.force,
        b.torque,
    )  # fmt: skip
    if stress:
        _stress(b.pos, c.H, z, q.n_intr, q.i_id, q.i_cd, q.i_real, q.i_geom, q.i_fs, c.sig)
    return 0, -1


@njit(inline="always")
def _cell_columns(c, out, s):
    """Row ``s`` of the block's rows: hSize (00, 01, 10, 11) and the step's velGrad (00, 01, 10, 11),
    columns 7-14 of :data:`OUT_COLUMNS`."""
    out[s, 7] = c.H[0, 0]
    out[s, 8] = c.H[0, 1]
    out[s, 9] = c.H[1, 0]
    out[s, 10] = c.H[1, 1]
    out[s, 11] = c.L[0, 0]
    out[s, 12] = c.L[0, 1]
    out[s, 13] = c.L[1, 0]
    out[s, 14] = c.L[1, 1]


@njit
def _row(b, c, q, out, s):
    """The per-step row ``s`` of ``out`` (:data:`OUT_COLUMNS`) after a frame."""
    out[s, 0] = c.sig[0, 0]
    out[s, 1] = c.sig[0, 1]
    out[s, 2] = c.sig[1, 0]
    out[s, 3] = c.sig[1, 1]
    nc = 0
    pen = 0.0
    for k in range(q.n_intr[0]):
        if q.i_real[k]:
            nc += 1
            pen += q.i_geom[k, 2]
    out[s, 4] = nc
    out[s, 5] = pen
    ke = 0.0
    for i in range(b.pos.shape[0]):
        ke += 0.5 * b.mass[i] * (b.vel[i, 0] * b.vel[i, 0] + b.vel[i, 1] * b.vel[i, 1])
        ke += 0.5 * b.inertia[i] * b.spin[i] * b.spin[i]
    out[s, 6] = ke
    _cell_columns(c, out, s)


@njit
def yade_block(b, c, q, ctl, lp, dt, dt2, step0, n, out):
    """Up to ``n`` engine steps from frame ``step0`` (module docstring: the control of the last
    frame, Newton, then the next iteration up to its stress), a row of ``out`` each. Returns
    (steps done, status, index): status 0 done, 2 a non-finite position (index: the body), 4 a
    bound spans over half of the cell, 5 the container is full, 6 the initial sort reached
    libstdc++'s heap-sort branch (index: the axis)."""
    for s in range(n):
        control_grad(ctl, c.H, c.sig, dt, c.nextL)  # Cell.velGrad set: nextVelGrad, velGradChanged
        c.changed[0] = True
        c.misc[1] = _newton_damped(
            b.pos, b.vel, b.spin, b.mass, b.inertia, b.force, b.torque, c.L, c.nextL, c.changed, c.Lprev, c.size,
            c.prev_size, dt, dt2, b.ref_pos, b.sweep, c.misc[3],
        )  # fmt: skip
        for i in range(b.pos.shape[0]):
            if not (math.isfinite(b.pos[i, 0]) and math.isfinite(b.pos[i, 1])):
                return s, 2, i
        err, axis = _iteration_rest(step0 + s + 1, False, b, c, q, lp, dt, True)
        if err != 0:
            return s, 3 + err, axis
        _row(b, c, q, out, s)
    return n, 0, -1


@njit
def rve_block(b, c, q, lp, dt, dt2, step0, n, end, out):
    """Up to ``n`` engine steps of a :class:`VelGradRun` from step ``step0`` of a run that ends at
    step ``end`` (module docstring): NewtonIntegrator with the cell's damping, each disk's rotation
    theta += spin dt (after the integrator, with the spin the step ends with), then the next
    iteration up to its forces unless the step is the run's last. No per-step stress: the rows
    of ``out`` (:data:`OUT_COLUMNS`) hold the cell and the velGrad of each step, and the last one
    also YADE's getStress(), the real interactions, the penetrations and the kinetic energy at
    the block's end (the others NaN). Returns (steps done, status, index) as :func:`yade_block`;
    the positions are checked finite at the block's end only (status 2 at its last step: a check
    per step cost 2 % of a call, and a non-finite position stays non-finite)."""
    nb = b.pos.shape[0]
    for s in range(n):
        c.misc[1] = _newton_damped(
            b.pos, b.vel, b.spin, b.mass, b.inertia, b.force, b.torque, c.L, c.nextL, c.changed, c.Lprev, c.size,
            c.prev_size, dt, dt2, b.ref_pos, b.sweep, c.misc[3],
        )  # fmt: skip
        for i in range(nb):  # NewtonIntegrator.cpp:329-335: ori turned by the step's final spin, times dt
            b.theta[i] += b.spin[i] * dt
        if step0 + s + 1 < end:
            err, axis = _iteration_rest(step0 + s + 1, False, b, c, q, lp, dt, False)
            if err != 0:
                return s, 3 + err, axis
        for k in range(7):
            out[s, k] = np.nan
        _cell_columns(c, out, s)
    for i in range(nb):  # a non-finite position stays so (the collider meets no overlap with it)
        if not (math.isfinite(b.pos[i, 0]) and math.isfinite(b.pos[i, 1])):
            return n - 1, 2, i
    if n:
        _stress(b.pos, c.H, c.misc[0], q.n_intr, q.i_id, q.i_cd, q.i_real, q.i_geom, q.i_fs, c.sig)
        _row(b, c, q, out, n - 1)
    return n, 0, -1


def _energies(b, c, q):
    """:func:`_energy_sums` of the engine's state objects."""
    return _energy_sums(b.pos, b.vel, b.spin, b.mass, b.inertia, c.Lprev, q.n_intr, q.i_real, q.i_geom, q.i_fs)


@njit
def _energy_sums(pos, vel, spin, mass, inertia, L, n_intr, i_real, i_geom, i_fs):
    """(kinetic energy relative to the cell's mean field, elastic energy, kinetic energy of the mean
    field) (J) of the state, one pass each (the divergence check's, called per block and per loaded
    scene): 1/2 m |v - Lprev x|^2 + 1/2 I w^2 summed over the disks; |F_n|^2 / 2 kn + |F_s|^2 / 2 ks
    over the real interactions (a zero ks stores nothing); 1/2 m |L x|^2, L = prevVelGrad. The
    arrays as :data:`YadeBodies`, :data:`YadeContainer` (passed one by one: a call with the state's
    namedtuples unboxes all their 38 arrays, 18 us)."""
    ke = 0.0
    flow = 0.0
    for i in range(pos.shape[0]):
        ux = L[0, 0] * pos[i, 0] + L[0, 1] * pos[i, 1]
        uy = L[1, 0] * pos[i, 0] + L[1, 1] * pos[i, 1]
        vx = vel[i, 0] - ux
        vy = vel[i, 1] - uy
        ke += 0.5 * mass[i] * (vx * vx + vy * vy) + 0.5 * inertia[i] * spin[i] * spin[i]
        flow += 0.5 * mass[i] * (ux * ux + uy * uy)
    el = 0.0
    for k in range(n_intr[0]):
        if i_real[k]:
            el += (i_geom[k, 3] * i_geom[k, 3] + i_geom[k, 4] * i_geom[k, 4]) / (2.0 * i_geom[k, 5])
            if i_geom[k, 6] > 0.0:
                el += (i_fs[k, 0] * i_fs[k, 0] + i_fs[k, 1] * i_fs[k, 1]) / (2.0 * i_geom[k, 6])
    return ke, el, flow


@njit
def _reset_bounds(bc, bi, bp, bm, lo_idx):
    """The bound lists of a new collider, unsorted (a loaded scene has none: its first run sorts)."""
    m = bc.shape[1]
    for a in range(3):
        lo_idx[a] = 0
        for k in range(m):
            bi[a, k] = k // 2
            bm[a, k] = k % 2 == 0
            bp[a, k] = 0
            bc[a, k] = 0.0


@dataclass(frozen=True)
class VelGradRun:
    """One call of Guo & Zhao's ``simDEM.shear2D`` as a run of the sheared yade cell
    (``start_run(VelGradRun(vel_grad), ns)``, module docstring): ``Cell.velGrad = vel_grad`` set
    from Python before the run (kept in nextVelGrad with velGradChanged, core/Cell.hpp:138-142,
    applied by the first step's integrator; the first step's cell update uses the velGrad the cell
    held), then ``O.run(ns, True)``: the run ends after its last step's integrator, where the
    scene is saved (:meth:`YadeCell.scene`). ``vel_grad`` (2, 2) 1/s: D / (ns dt) for Guo & Zhao's
    strain increment D."""

    vel_grad: np.ndarray

    def __post_init__(self):
        try:
            L = np.array(self.vel_grad, float).reshape(2, 2)
        except (TypeError, ValueError):
            raise InputError(f"vel_grad: expected a (2, 2) velocity gradient (1/s), got {self.vel_grad!r}") from None
        if not np.all(np.isfinite(L)):
            raise InputError(f"vel_grad: the velocity gradient must be finite, got {L.tolist()}")
        object.__setattr__(self, "vel_grad", L)


#: the control of a :class:`VelGradRun` on the engine: its step of the saved scene
RVEControl = namedtuple("RVEControl", ["end"])


class YadeCell:
    """YADE's periodic cell for :class:`gransim.dem.engine.Engine` (module docstring). Its state on
    the engine: ``yb`` (:data:`YadeBodies`), ``yc`` (:data:`YadeCellState`), ``yq``
    (:data:`YadeContainer`), ``sc`` (the virial of the last frame in the engine's convention)."""

    order = "code"
    #: the engine gives this cell only laws of YADE's arithmetic (gransim.dem.engine.Engine._set_law)
    law_code = "yade"

    @staticmethod
    def check(packing: Packing, settings, flavour: str) -> None:
        if isinstance(settings, DEMSettings) and (settings.gamma_n != 0 or settings.gamma_t != 0):
            raise InputError(
                f"settings.gamma_n, gamma_t: the yade arithmetic runs Cundall and Strack's undamped law, got "
                f"{settings.gamma_n!r}, {settings.gamma_t!r}"
            )

    @staticmethod
    def check_size(packing: Packing, settings) -> None:
        pass  # the collider stops on a bound over half of the cell (status 4), as YADE does

    def __init__(self, eng, box, threads, x, v, w, z=None, damping=0.0):
        if box is not None:
            raise InputError("box: the yade arithmetic's cell is the packing's, from the origin (box=None)")
        if threads not in (None, 1):
            raise InputError(f"threads: the yade arithmetic runs one thread, got {threads!r}")
        p = eng.packing
        n = p.n
        s = eng.settings
        self.z = yade_cell_z(p.radii) if z is None else float(z)
        radius = np.array(p.radii, float)
        rho = float(p.density)
        mass = np.array([rho * math.pi * r * r for r in radius])  # the script: rho * math.pi * r * r
        inertia = np.array([0.5 * m * r * r for m, r in zip(mass, radius)])  # 0.5 * m * r * r
        self.lp = law_array(eng.law)
        damping = float(damping)
        if not (0.0 <= damping < 1.0):
            raise InputError(f"damping: NewtonIntegrator's non-viscous damping is in [0, 1), got {damping!r}")
        self.dt = float(s.dt)
        self.dt2 = self.dt * self.dt  # pow(dt, 2) (NewtonIntegrator.cpp:164), folded into dt * dt by GCC
        eng.yb = YadeBodies(
            x.copy(), v.copy(), w.copy(), np.zeros((n, 2)), np.zeros(n), mass, inertia, radius,
            np.full((n, 2), np.nan), np.zeros(n), np.zeros(n, np.int64), np.zeros((n, 3)), np.zeros((n, 3)),
            np.zeros(n),
        )  # fmt: skip
        C = np.asarray(p.cell, float)
        misc = np.array([self.z, 0.0, VERLET_FACTOR * float(radius.min()), damping, 0.0])
        eng.yc = YadeCellState(
            C.copy(), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)), np.zeros((2, 2)),
            np.zeros(3), np.zeros((2, 2)), np.zeros(3), np.full(3, np.nan), np.zeros((2, 2)), misc,
            np.zeros(1, np.bool_),
        )  # fmt: skip
        m = 2 * n
        cap = min(n * (n - 1) // 2, 64 * n)
        eng.yq = YadeContainer(
            np.zeros((3, m)), np.tile(np.repeat(np.arange(n, dtype=np.int64), 2), (3, 1)),
            np.zeros((3, m), np.int64), np.tile(np.array([True, False] * n), (3, 1)), np.zeros(3, np.int64),
            np.full((n, n), -1, np.int64), np.zeros(1, np.int64), np.zeros((cap, 2), np.int64),
            np.zeros((cap, 2), np.int64), np.zeros(cap, np.bool_), np.zeros((cap, 8)), np.zeros((cap, 2)),
        )  # fmt: skip
        eng.sc = _Scratch(np.zeros(4))
        self._set_up = False
        self.run = None
        self.saved = False  # the last run ended with its scene saved (a VelGradRun): the next run loads it
        self._rve_rows = False  # the last block was a VelGradRun's (rve_block's rows)
        self._scene = None  # the loaded scene's radii, mass, inertia (handed on by scene())

    # geometry: YADE's hSize
    def matrix(self, eng) -> np.ndarray:
        return eng.yc.H.copy()

    def lengths(self, eng) -> np.ndarray:
        H = eng.yc.H
        return np.array([H[0, 0], H[1, 1]])

    def lo(self, eng) -> np.ndarray:
        return np.zeros(2)

    def hi(self, eng) -> np.ndarray:
        return self.lengths(eng)

    # the set-up: iteration 0 up to its stress
    def rebuild(self, eng, carry: bool):
        pass  # YADE's collider runs inside the iteration

    def forces(self, eng, update: bool):
        if not self._set_up:
            self._set_up_iteration(eng, 0)
        self._set_virial(eng)
        return self._counts(eng)

    def _set_up_iteration(self, eng, it: int) -> None:
        """Iteration ``it`` up to its stress with the collider's initial sort (a new engine's set-up,
        or a loaded scene's); SimulationError naming the step when the collider stops."""
        err, axis = _iteration_rest(it, True, eng.yb, eng.yc, eng.yq, self.lp, self.dt, True)
        if err:
            raise SimulationError(f"step {it}: {self.failure_message(eng, 3 + err, axis)}")
        self._set_up = True

    def _counts(self, eng):
        q = eng.yq
        real = q.i_real[: q.n_intr[0]]
        return float(real.sum()), float(q.i_geom[: q.n_intr[0], 2][real].sum())

    def _set_virial(self, eng):
        """The engine's virial (xx, yy, xy, yx: sum d_a f_b, N m) of YADE's stress of the frame."""
        sig = eng.yc.sig
        H = eng.yc.H
        a = H[0, 0] * H[1, 1] - H[1, 0] * H[0, 1]
        eng.sc.vir[:] = -a * np.array([sig[0, 0], sig[1, 1], sig[1, 0], sig[0, 1]])

    def stress_tensor(self, eng) -> np.ndarray:
        """YADE's getStress() of the last frame, compression positive: -sig^T (2, 2) N/m."""
        return -eng.yc.sig.T.copy()

    def touching(self, eng):
        q = eng.yq
        m = q.n_intr[0]
        e = np.flatnonzero(q.i_real[:m])
        return e, q.i_geom[e, 2].copy()

    def budget_kinetic_energy(self, eng) -> float:
        """Kinetic energy (J) of the velocities relative to the cell's mean field (the velGrad of
        the last step) and of the spins (:func:`_energies`)."""
        return _energies(eng.yb, eng.yc, eng.yq)[0]

    def peculiar_velocities(self, eng) -> np.ndarray:
        """v - L x (m/s), (N, 2): the velocities without the cell's mean field (the velGrad of the
        last step)."""
        b = eng.yb
        return b.vel - b.pos @ eng.yc.Lprev.T

    def flow_kinetic_energy(self, eng) -> float:
        """Kinetic energy (J) of the cell's mean field at the disks (:func:`_energies`)."""
        return _energies(eng.yb, eng.yc, eng.yq)[2]

    # the loading
    LOADINGS = (Loading, ShearLoading)

    def control(self, eng, loading) -> np.ndarray:
        """(mode_x, a_x, b_x, mode_y, a_y, b_y, erate, L0y) of the script's control() for ``loading``
        from the current cell."""
        H, dt = eng.yc.H, self.dt
        if isinstance(loading, Loading) and self.kind == "orthogonal":

            def axis(a, L0):
                if a.mode == "fixed":
                    return (_FIXED, 0.0, 0.0)
                if a.mode == "rate":
                    return (_RATE, a.rate * L0 * dt, 0.0)  # the decks' literal c = rate L0 dt
                return (_SERVO, dt * a.gain, float(a.target))

            return np.array([*axis(loading.x, H[0, 0]), *axis(loading.y, H[1, 1]), 0.0, H[1, 1]], float)
        if isinstance(loading, ShearLoading) and self.kind == "sheared":
            if loading.xy != "erate" or loading.every != 1 or loading.x_erate or loading.y == "erate":
                raise InputError(
                    "loading: the yade arithmetic shears at a constant xy erate changed every step, y fixed or "
                    f"under the servo, got xy {loading.xy!r}, every {loading.every}, x_erate {loading.x_erate}, "
                    f"y {loading.y!r}"
                )
            y = (_SERVO, dt * loading.gain, float(loading.target)) if loading.y == "servo" else (_FIXED, 0.0, 0.0)
            return np.array([_FIXED, 0.0, 0.0, *y, float(loading.erate), H[1, 1]], float)
        want = "a Loading" if self.kind == "orthogonal" else "a ShearLoading"
        raise InputError(f"loading: the yade arithmetic's {self.kind} cell takes {want}, got {type(loading).__name__}")

    def start_run(self, eng, loading, nsteps: int):
        if self.saved:  # the script's next call loads the scene the last one saved
            self._load_scene(eng, self.scene(eng), eng.yb.theta.copy(), eng.step)
            eng.stress = eng.stress_tensor()
        if isinstance(loading, VelGradRun):
            if self.kind != "sheared":
                raise InputError("loading: a VelGradRun (Guo & Zhao's call) runs on the sheared yade cell")
            c = eng.yc
            c.nextL[...] = loading.vel_grad  # Cell.velGrad set from Python: nextVelGrad, velGradChanged
            c.changed[0] = True
            self.run = (RVEControl(eng.step + nsteps), eng.step + nsteps)
            return self.run
        self.run = (self.control(eng, loading), eng.step + nsteps)
        return self.run

    def drive(self, eng, run, *args, **kwargs):
        """(control, nsteps) of ``advance(nsteps)`` in the run of :meth:`start_run`, or of
        ``advance(loading, nsteps)``."""
        if args and isinstance(args[0], self.LOADINGS):
            loading, *rest = args
            nsteps = rest[0] if rest else kwargs.get("nsteps", 1)
            return self.control(eng, loading), as_int(nsteps, "nsteps", 0)
        if run is None:
            raise InputError("advance: call start_run(loading, nsteps) first, or advance(loading, nsteps)")
        nsteps = args[0] if args else kwargs.get("nsteps")
        nsteps = as_int(
            nsteps, "nsteps", 0, run[1] - eng.step, note=f" (the run ends at step {run[1]}, now at step {eng.step})"
        )
        return run[0], nsteps

    def vel_grad(self, eng, control) -> np.ndarray:
        """The velGrad (2, 2) (1/s) the script sets at the current frame under ``control``."""
        out = np.zeros((2, 2))
        control_grad(control, eng.yc.H, eng.yc.sig, self.dt, out)
        return out

    # the block of steps
    def series(self, nsteps: int) -> np.ndarray:
        return np.zeros((nsteps, OUT_COLUMNS))

    def box_state(self, eng):
        return eng.yc.H.copy()

    def block(self, eng, ctl, out, done: int, n: int, resume: bool):
        self._rve_rows = isinstance(ctl, RVEControl)
        if self._rve_rows:
            k, status, index = rve_block(
                eng.yb, eng.yc, eng.yq, self.lp, self.dt, self.dt2, eng.step, n, ctl.end, out[done:]
            )
            self.saved = status == 0 and eng.step + k == ctl.end
            return k, status, index
        return yade_block(eng.yb, eng.yc, eng.yq, ctl, self.lp, self.dt, self.dt2, eng.step, n, out[done:])

    def check_divergence(self, eng, out, done: int, k: int, H_before):
        """The divergence check (:meth:`gransim.dem.engine.Engine._check_energy`) after the k steps
        from row ``done``: every step's kinetic energy finite; the one without the mean field at
        the last step within the budget, which counts the kinetic energy of the mean field too;
        the work of the cell per step A dt sig:L (YADE's stress, tension positive, the area of
        the frame, its velGrad)."""
        rows = out[done : done + k]
        area = rows[:, 7] * rows[:, 10] - rows[:, 9] * rows[:, 8]
        if self._rve_rows:
            # a VelGradRun keeps no per-step stress: the work of each step with the stress at the
            # block's end (its last row), the kinetic energy there only
            sig = rows[-1, 0:4]
            dw = area * self.dt * (sig[0] * rows[:, 11] + sig[1] * rows[:, 12] + sig[2] * rows[:, 13]
                                   + sig[3] * rows[:, 14])  # fmt: skip
            eng._check_energy(
                eng.step + k, rows[-1:, 6], np.array([self.budget_kinetic_energy(eng)]), np.array([np.sum(dw)]),
                flow=self.flow_kinetic_energy(eng),
            )  # fmt: skip
            return
        dw = area * self.dt * (rows[:, 0] * rows[:, 11] + rows[:, 1] * rows[:, 12] + rows[:, 2] * rows[:, 13]
                               + rows[:, 3] * rows[:, 14])  # fmt: skip
        ke = np.full(k, np.nan)
        ke[-1] = self.budget_kinetic_energy(eng)
        eng._check_energy(eng.step + 1, rows[:, 6], ke, dw, flow=self.flow_kinetic_energy(eng))

    def failure_message(self, eng, status: int, index: int) -> str:
        if status == 3 + _TOO_BIG:
            return "a bound spans over half of the cell (YADE throws here too)"
        if status == 3 + _FULL:
            return f"more than {eng.yq.i_id.shape[0]} potential interactions"
        if status == 3 + _TIE:
            return (
                f"the initial sort of the bounds on axis {index} reached libstdc++'s depth limit: its heap-sort "
                "branch is not reproduced"
            )
        return f"the yade cell stopped (status {status})"

    def collapse_message(self, eng) -> str:
        return "the cell collapsed"

    def result(self, eng, out: np.ndarray, first: int) -> dict:
        n = out.shape[0]
        self._set_virial(eng)
        if self._rve_rows:
            # a VelGradRun: the cell and the velGrad of every step; its stress, contacts and kinetic
            # energy at the end only (Engine.stress, n_contacts, mean_overlap)
            if n:
                eng.n_contacts = round(float(out[-1, 4]))
                eng.mean_overlap = float(out[-1, 5] / out[-1, 4]) if out[-1, 4] else 0.0
            return {
                "step": np.arange(first + 1, first + n + 1),
                "cell": out[:, 7:11].reshape(n, 2, 2).copy(),
                "vel_grad": out[:, 11:15].reshape(n, 2, 2).copy(),
            }
        if n:
            eng.n_contacts = round(float(out[-1, 4]))
            eng.mean_overlap = float(out[-1, 5] / out[-1, 4]) if out[-1, 4] else 0.0
        st = np.empty((n, 2, 2))
        st[:, 0, 0] = -out[:, 0]
        st[:, 0, 1] = -out[:, 2]
        st[:, 1, 0] = -out[:, 1]
        st[:, 1, 1] = -out[:, 3]
        area = out[:, 7] * out[:, 10] - out[:, 9] * out[:, 8]
        vir = -area[:, None] * out[:, [0, 3, 2, 1]]
        cell = {
            "lengths": out[:, [7, 10]].copy()
            if self.kind == "orthogonal"
            else np.stack([out[:, 7], out[:, 10], out[:, 8], np.zeros(n), out[:, 10]], axis=1)
        }
        return {
            "step": np.arange(first + 1, first + n + 1),
            "stress": st,
            "virial": vir,
            "n_contacts": np.rint(out[:, 4]).astype(np.int64),
            "mean_overlap": np.divide(out[:, 5], out[:, 4], out=np.zeros(n), where=out[:, 4] > 0),
            "kinetic_energy": out[:, 6].copy(),
            **({"lengths": cell["lengths"]} if self.kind == "orthogonal" else {"box": cell["lengths"]}),
        }

    def particle(self, eng, i: int) -> int:
        return int(i)

    def largest_move(self, eng):
        return 0, 0.0  # no neighbour list to outrun: YADE's collider follows the bodies

    # views
    VIEWS = {
        "x": ("yb", "pos"), "v": ("yb", "vel"), "w": ("yb", "spin"), "f": ("yb", "force"), "t": ("yb", "torque"),
        "m": ("yb", "mass"), "r": ("yb", "radius"),
    }  # fmt: skip

    def view(self, eng, name: str):
        q = eng.yq
        m = q.n_intr[0]
        real = q.i_real[:m]
        if name in self.VIEWS:
            obj, field = self.VIEWS[name]
            return getattr(getattr(eng, obj), field)
        if name == "ea":
            return q.i_id[:m, 0][real]
        if name == "eb":
            return q.i_id[:m, 1][real]
        if name == "xi":
            return q.i_fs[:m][real]
        raise AttributeError(f"{name}: the yade arithmetic keeps no such array (contacts() gives its interactions)")

    def contacts(self, eng) -> dict:
        """The real interactions in YADE's container order: i, j (ids), shift (cellDist: l_ij = x_j
        + H shift - x_i), force on j (F_n + F_s, N), overlap (penetrationDepth, m), shear force
        (N) as ``shear_force`` and its spring ``tangential_spring`` = -F_s / ks (m), sliding (the
        Coulomb cap reached: |F_s| = tan(phi) |F_n| to 1e-12)."""
        q = eng.yq
        m = q.n_intr[0]
        e = np.flatnonzero(q.i_real[:m])
        fn = q.i_geom[e, 3:5]
        fs = q.i_fs[e]
        ks = q.i_geom[e, 6]
        cap = np.linalg.norm(fs, axis=1) >= (1.0 - 1e-12) * q.i_geom[e, 7] * np.linalg.norm(fn, axis=1)
        return {
            "i": q.i_id[e, 0].copy(),
            "j": q.i_id[e, 1].copy(),
            "shift": q.i_cd[e].copy(),
            "force": fn + fs,
            "overlap": q.i_geom[e, 2].copy(),
            "tangential_spring": -fs / np.where(ks > 0, ks, 1.0)[:, None],
            "shear_force": fs.copy(),
            "sliding": cap & (np.linalg.norm(fs, axis=1) > 0),
        }

    def shifts(self, eng, e=slice(None)) -> np.ndarray:
        q = eng.yq
        m = q.n_intr[0]
        return q.i_cd[:m][q.i_real[:m]][e].copy()

    def elastic_energy(self, eng) -> float:
        """Energy stored in the real interactions (J): |F_n|^2 / 2 kn + |F_s|^2 / 2 ks
        (:func:`_energies`)."""
        return _energies(eng.yb, eng.yc, eng.yq)[1]

    # checkpoints
    def state_arrays(self, eng) -> dict:
        """The bodies, the cell, the collider's bounds and the container (copies; the slot table is
        derived from the ids), the set-up flag and the run's control."""
        objs = {"bodies": eng.yb, "cell": eng.yc, "container": eng.yq}
        out = {k: np.array(getattr(objs[o], f)) for k, (o, f) in CHECKPOINT.items()}
        out["yade/set_up"] = np.array(self._set_up)
        out["yade/scene_saved"] = np.array(self.saved)
        if self.run is not None:
            if isinstance(self.run[0], RVEControl):
                out["yade/run_vel_grad_run"] = np.array(True)
            else:
                out["yade/run_control"] = self.run[0].copy()
            out["yade/run_end"] = np.array(self.run[1], np.int64)
        return out

    def restore(self, eng, arrays: dict, step: int) -> int:
        """The engine's checkpoint (:meth:`state_arrays`), or YADE's saved scene
        (:func:`scene_checkpoint`: loaded, then its set-up run or restored)."""
        if "yade/scene" in arrays:
            self._load_scene(eng, arrays["yade/scene"], arrays.get("yade/scene_rotation"), int(step))
            return int(step)
        objs = {"bodies": eng.yb, "cell": eng.yc, "container": eng.yq}
        try:
            for k, (o, f) in CHECKPOINT.items():
                dst = getattr(objs[o], f)
                src = np.asarray(arrays[k])
                if f in ("i_id", "i_cd", "i_real", "i_geom", "i_fs") and src.shape[0] != dst.shape[0]:
                    raise ValueError(f"{k}: {src.shape} for {dst.shape}")
                dst[...] = src.reshape(dst.shape)
        except KeyError as exc:
            raise InputError(f"restore: the checkpoint lacks {exc.args[0]!r} (not a yade checkpoint?)") from None
        except ValueError as exc:
            raise InputError(f"restore: the checkpoint does not fit this engine: {exc}") from None
        q = eng.yq
        q.slot[:] = -1
        m = q.n_intr[0]
        q.slot[q.i_id[:m, 0], q.i_id[:m, 1]] = np.arange(m)
        self._set_up = bool(arrays["yade/set_up"])
        self.saved = bool(arrays.get("yade/scene_saved", False))
        self.run = None
        if "yade/run_control" in arrays:
            self.run = (np.array(arrays["yade/run_control"], float), int(arrays["yade/run_end"]))
        elif "yade/run_vel_grad_run" in arrays:
            end = int(arrays["yade/run_end"])
            self.run = (RVEControl(end), end)
        eng._run_drive = self.run
        self._set_virial(eng)
        return int(step)

    # YADE's saved scene (Guo & Zhao's RVE between calls)
    def _load_scene(self, eng, state: YadeRVEState, rotation, step: int) -> None:
        """Load the saved scene ``state`` (what ``Omega.stringToScene`` restores: the bodies with their
        bounds' refPos, sweepLength, lastUpdateIter; the cell; NewtonIntegrator's prevVelGrad,
        prevCellSize, damping; the real interactions in container order; no bound lists) and run its
        set-up, iteration ``state.iteration`` up to its forces (module docstring), or restore it when
        kept for this read-only scene. ``rotation`` (N,) rad: the disks' rotations carried on (None:
        0)."""
        if not isinstance(state, YadeRVEState):
            raise InputError(f"restore: yade/scene must be a YadeRVEState, got {type(state).__name__}")
        b, c, q = eng.yb, eng.yc, eng.yq
        n = b.pos.shape[0]
        if state.n != n or not np.array_equal(state.radii, b.radius):
            raise InputError(f"restore: the scene's {state.n} disks are not this engine's {n} (radii differ)")
        law = eng.law
        mat = (float(state.young), float(state.poisson), float(state.friction_angle))
        if mat != (law.young, law.poisson, law.friction_angle) or float(state.dt) != self.dt:
            raise InputError(
                f"restore: the scene's material (young, poisson, friction angle) {mat} and dt {state.dt!r} are not "
                f"the engine's law {(law.young, law.poisson, law.friction_angle)} and dt {self.dt!r}"
            )
        if int(step) != int(state.iteration):
            raise InputError(f"restore: a saved scene is restored at its iteration {state.iteration}, got step {step}")
        m0 = len(state.kn)
        if m0 >= q.i_id.shape[0]:
            raise InputError(f"restore: the scene's {m0} interactions exceed the container ({q.i_id.shape[0]})")
        k = int(q.n_intr[0])  # the pair index of the last content cleared
        q.slot[q.i_id[:k, 0], q.i_id[:k, 1]] = -1
        b.pos[...] = state.positions
        b.vel[...] = state.velocities
        b.spin[...] = state.spins
        b.mass[...] = state.mass
        b.inertia[...] = state.inertia
        b.ref_pos[...] = state.bound_ref
        b.sweep[...] = state.sweep
        b.last_update[...] = state.last_update
        b.theta[...] = 0.0 if rotation is None else rotation
        c.H[...] = state.hsize
        c.L[...] = state.vel_grad
        c.nextL[...] = state.next_vel_grad
        c.changed[0] = bool(state.vel_grad_changed)
        c.Lprev[...] = state.newton_prev_vel_grad
        c.prev_size[...] = state.prev_cell_size
        c.misc[:] = (state.z, 0.0, state.verlet, state.damping, state.z_pos)
        self.z = float(state.z)
        self._scene = (state.radii, state.mass, state.inertia)
        kept = _FIRST_RUNS.get(state)
        if kept is not None:
            kept.restore(b, c, q)
        else:
            q.n_intr[0] = m0
            q.i_id[:m0] = state.ids
            q.i_cd[:m0] = state.cell_dist
            q.i_real[:m0] = True
            g = q.i_geom
            g[:m0, 0:2] = state.normal
            g[:m0, 2] = 0.0  # penetrationDepth: NaN in a loaded scene, recomputed before it is read
            g[:m0, 3:5] = state.normal_force
            g[:m0, 5] = state.kn
            g[:m0, 6] = state.ks
            g[:m0, 7] = state.tan_phi
            q.i_fs[:m0] = state.shear_force
            q.slot[state.ids[:, 0], state.ids[:, 1]] = np.arange(m0)
            _reset_bounds(q.bc, q.bi, q.bp, q.bm, q.lo_idx)
            self._set_up_iteration(eng, int(state.iteration))
            if _read_only(state):
                _FIRST_RUNS[state] = _SetUp.of(b, c, q)
        self._set_up = True
        self.saved = False
        self.run = None
        eng._run_drive = None
        self._set_virial(eng)

    def scene(self, eng) -> YadeRVEState:
        """The scene a :class:`VelGradRun` saved at its end, as Guo & Zhao's script serialises it
        after ``Cell.velGrad = 0`` (simDEM.py:61: nextVelGrad 0, velGradChanged): the real
        interactions only, in container order (core/InteractionContainer.cpp:174-181). New arrays
        (the radii, mass and inertia those of the loaded scene). InputError before a run saved it."""
        if not self.saved:
            raise InputError("scene: no saved scene (the engine's last run was not a VelGradRun that ended)")
        b, c, q = eng.yb, eng.yc, eng.yq
        if not _size_is_prev_size(c.H, self.z, c.prev_size):
            raise SimulationError(f"step {eng.step}: the cell's size is not NewtonIntegrator.prevCellSize")
        ids, cd, normal, kn, ks, tan_phi, fn, fs = _saved_interactions(q.n_intr, q.i_id, q.i_cd, q.i_real, q.i_geom,
                                                                       q.i_fs)  # fmt: skip
        radii, mass, inertia = self._scene or (b.radius.copy(), b.mass.copy(), b.inertia.copy())
        law = eng.law
        misc = c.misc.tolist()
        return YadeRVEState(
            iteration=int(eng.step), dt=self.dt, z=self.z, z_pos=misc[4], radii=radii, mass=mass,
            inertia=inertia, positions=b.pos.copy(), velocities=b.vel.copy(), spins=b.spin.copy(),
            bound_ref=b.ref_pos.copy(), sweep=b.sweep.copy(), last_update=b.last_update.copy(), hsize=c.H.copy(),
            vel_grad=c.L.copy(), next_vel_grad=np.zeros((2, 2)), vel_grad_changed=True,
            newton_prev_vel_grad=c.Lprev.copy(), prev_cell_size=c.prev_size.copy(), verlet=misc[2],
            damping=misc[3], young=law.young, poisson=law.poisson, friction_angle=law.friction_angle,
            ids=ids, cell_dist=cd, normal=normal, kn=kn, ks=ks, tan_phi=tan_phi, normal_force=fn, shear_force=fs,
        )  # fmt: skip

    def memory_bytes(self, eng) -> dict:
        return {
            "bodies": sum(a.nbytes for a in eng.yb),
            "cell": sum(a.nbytes for a in eng.yc),
            "container": sum(a.nbytes for a in eng.yq),
        }


@njit
def _size_is_prev_size(H, z, prev_size):
    """Whether the cell's column sizes (sqrt of each column's squares, and |z|) are
    NewtonIntegrator's prevCellSize, bit for bit."""
    return (
        math.sqrt(H[0, 0] * H[0, 0] + H[1, 0] * H[1, 0]) == prev_size[0]
        and math.sqrt(H[0, 1] * H[0, 1] + H[1, 1] * H[1, 1]) == prev_size[1]
        and math.sqrt(z * z) == prev_size[2]
    )


@njit
def _saved_interactions(n_intr, i_id, i_cd, i_real, i_geom, i_fs):
    """The real interactions of the container, in container order, as a saved scene holds them
    (core/InteractionContainer.cpp:174-181): ids, cellDist (M, 2); normal (M, 2); kn, ks,
    tan(friction angle) (M,); normal and shear force (M, 2). New arrays."""
    n = n_intr[0]
    m = 0
    for e in range(n):
        if i_real[e]:
            m += 1
    ids = np.empty((m, 2), i_id.dtype)
    cd = np.empty((m, 2), i_cd.dtype)
    normal = np.empty((m, 2))
    kn = np.empty(m)
    ks = np.empty(m)
    tan_phi = np.empty(m)
    fn = np.empty((m, 2))
    fs = np.empty((m, 2))
    k = 0
    for e in range(n):
        if i_real[e]:
            for a in range(2):
                ids[k, a] = i_id[e, a]
                cd[k, a] = i_cd[e, a]
                normal[k, a] = i_geom[e, a]
                fn[k, a] = i_geom[e, 3 + a]
                fs[k, a] = i_fs[e, a]
            kn[k] = i_geom[e, 5]
            ks[k] = i_geom[e, 6]
            tan_phi[k] = i_geom[e, 7]
            k += 1
    return ids, cd, normal, kn, ks, tan_phi, fn, fs


#: the engine's ``sc`` of the yade cell: the virial only
_Scratch = namedtuple("_Scratch", ["vir"])


class YadeOrthogonalCell(YadeCell):
    """YADE's cell under a :class:`~gransim.dem.settings.Loading` (the biaxial decks), from an
    orthogonal packing cell."""

    kind = "orthogonal"

    @staticmethod
    def check(packing: Packing, settings, flavour: str) -> None:
        YadeCell.check(packing, settings, flavour)
        C = np.asarray(packing.cell, float)
        if C[0, 1] != 0.0 or C[1, 0] != 0.0:
            raise InputError(
                f"packing.cell: the yade arithmetic's orthogonal cell starts from an orthogonal cell, got {C.tolist()}"
            )


class YadeShearedCell(YadeCell):
    """YADE's cell (any hSize) under a :class:`~gransim.dem.sheared.ShearLoading` (the simple-shear
    decks) or a :class:`VelGradRun` (Guo & Zhao's call)."""

    kind = "sheared"


# ------------------------------------------------------------------------------ Guo & Zhao's RVE


def _read_only(state: YadeRVEState) -> bool:
    """Whether every array of ``state`` is read-only (then its set-up can be kept)."""
    for name in RVE_STATE_FIELDS:
        v = getattr(state, name)
        if isinstance(v, np.ndarray) and v.flags.writeable:
            return False
    return True


@dataclass(frozen=True, eq=False)
class _SetUp:
    """What a loaded scene's set-up (:meth:`YadeCell._load_scene`) writes: the bounds' ref_pos,
    sweep, last_update, the forces and torques; the cell's H, prevH, VP, size, U, cos and stress;
    the sorted bound lists and the interaction container (its first ``n`` entries)."""

    bodies: tuple
    cell: tuple
    bounds: tuple
    container: tuple

    BODIES = ("ref_pos", "sweep", "last_update", "force", "torque")
    CELL = ("H", "prevH", "VP", "size", "U", "cos", "sig")
    BOUNDS = ("bc", "bi", "bp", "bm", "lo_idx")
    CONTAINER = ("i_id", "i_cd", "i_real", "i_geom", "i_fs")

    @classmethod
    def of(cls, b, c, q) -> _SetUp:
        n = int(q.n_intr[0])
        return cls(
            tuple(getattr(b, f).copy() for f in cls.BODIES), tuple(getattr(c, f).copy() for f in cls.CELL),
            tuple(getattr(q, f).copy() for f in cls.BOUNDS), tuple(getattr(q, f)[:n].copy() for f in cls.CONTAINER),
        )  # fmt: skip

    def restore(self, b, c, q) -> None:
        parts = ((b, self.BODIES, self.bodies), (c, self.CELL, self.cell), (q, self.BOUNDS, self.bounds))
        for obj, names, vals in parts:
            for f, v in zip(names, vals):
                getattr(obj, f)[...] = v
        n = len(self.container[0])
        for f, v in zip(self.CONTAINER, self.container):
            getattr(q, f)[:n] = v
        q.n_intr[0] = n
        ids = self.container[0]
        q.slot[ids[:, 0], ids[:, 1]] = np.arange(n)


def scene_checkpoint(state: YadeRVEState, rotation=None) -> dict:
    """The checkpoint ``arrays`` of :meth:`gransim.dem.engine.Engine.from_checkpoint` (or
    ``restore``) that load YADE's saved scene ``state`` into the sheared yade cell, at step
    ``state.iteration``; ``rotation`` (N,) rad: the disks' rotations carried on (default 0)."""
    return {"yade/scene": state, "yade/scene_rotation": rotation}


def scene_law(state: YadeRVEState):
    """The law of a saved scene's material: Guo & Zhao's radius-dependent stiffnesses (young,
    poisson), its friction angle, ``avoidGranularRatcheting`` (prepareRVE.py keeps Ig2's default)."""
    return yade_law(state.friction_angle, young=state.young, poisson=state.poisson, avoid_granular_ratcheting=True)


def scene_engine(state: YadeRVEState, rotation=None):
    """A new engine (sheared yade cell) holding the saved scene ``state`` after its set-up
    (:meth:`~gransim.dem.engine.Engine.from_checkpoint` with :func:`scene_checkpoint`). Its packing:
    the scene's positions, radii and cell, the density of the first disk's mass. The time step is
    YADE's (the scene's: 0.5 of YADE's P-wave step in prepareRVE.py), reproduced and not checked
    against the engine's stability limit, which is stricter."""
    from .engine import Engine  # noqa: PLC0415 - cycle: engine -> yade_cell

    r = np.asarray(state.radii, float)
    packing = Packing(
        np.asarray(state.positions, float), r, np.asarray(state.hsize, float),
        float(state.mass[0]) / (math.pi * r[0] * r[0]),
    )  # fmt: skip
    return Engine.from_checkpoint(
        packing, Integration(dt=float(state.dt)), scene_checkpoint(state, rotation), int(state.iteration),
        check_dt=False, law=scene_law(state), cell="sheared", flavour="yade", cell_options={"z": float(state.z)},
    )  # fmt: skip


_LOCAL = threading.local()


@contextmanager
def rve_engine(state: YadeRVEState, rotation=None):
    """The calling thread's engine holding the saved scene ``state`` after its set-up: made once
    per thread (:func:`scene_engine`) and restored with each scene of the same disks, material and
    dt (allocating its arrays afresh, the 1.3 MB pair index among them, cost about a tenth of a
    100-step call of 400 disks). Not shared with a nested call while in use; dropped when the call
    fails."""
    eng = getattr(_LOCAL, "engine", None)
    _LOCAL.engine = None
    if eng is not None:
        law = eng.law
        fits = (
            eng.n == state.n and eng.cell_ops.dt == float(state.dt)
            and (law.young, law.poisson, law.friction_angle)
            == (float(state.young), float(state.poisson), float(state.friction_angle))
            and np.array_equal(eng.yb.radius, state.radii)
        )  # fmt: skip
        if fits:
            eng.restore(scene_checkpoint(state, rotation), int(state.iteration))
        else:
            eng = None
    if eng is None:
        eng = scene_engine(state, rotation)
    yield eng  # a failure propagates from here: the engine is dropped
    _LOCAL.engine = eng


__all__ = [
    "OUT_COLUMNS",
    "VelGradRun",
    "YadeCell",
    "YadeOrthogonalCell",
    "YadeShearedCell",
    "control_grad",
    "rve_block",
    "rve_engine",
    "scene_checkpoint",
    "scene_engine",
    "scene_law",
    "yade_block",
]
