"""True periodic simple shear: the DEM in a sheared (triclinic) periodic cell, LAMMPS' convention.

The cell is LAMMPS' triclinic box (``change_box all triclinic``): lower corner lo, edge vectors
a1 = (Lx, 0) and a2 = (xy, Ly), h = [[Lx, xy], [0, Ly]]; the image of particle j with shift
s = (s_x, s_y) lies at x_j + s_x a1 + s_y a2. The shear is ``fix deform 1 xy erate RATE remap v``
(Lees-Edwards): positions are *not* mapped affinely when the tilt changes; instead an image seen
across the y boundary moves with v_j + s_y (d xy/dt, d Ly/dt), and a particle that crosses y is
wrapped with its x velocity changed by -/+ d xy/dt (its peculiar velocity, relative to the
homogeneous shear flow u(y) = (d xy/dt) y / Ly, is kept). The y axis is fixed (constant-volume
shear) or under a normal-stress servo expressed as LAMMPS' ``fix deform y variable v_dy v_ry``:

    del(n) = (Ly(n-1) - Ly0) + dt g (sigma_yy(n) - target) Ly(n-1),   y = y0 -/+ del/2,
    h_rate[1] = g (sigma_yy(n) - target) Ly(n-1)          (the velocity jump of the y images)

with sigma_yy(n) the virial stress of step n over the area of box n-1 (a ``fix ave/time`` of
``compute pressure NULL virial`` defined before ``fix deform``, compression positive) and g the
gain (1/(Pa s)): more stress than the target expands the cell. Only the y axis moves: the tilt
stays xy and Lx fixed.

One step, as LAMMPS 29 Sep 2021 ``Verlet::run`` (serial, ``newton off``, ``neigh_modify delay 0
every 1 check yes``, ``atom_modify sort 0 0.0``):

1. ``fix nve/sphere disc`` first half (:func:`gransim.dem.kernels.initial_integrate`);
2. neighbour decision: some |x - x_hold| > (skin - d1 - d2)/2, d1, d2 from the 8 box corners
   (``Neighbor::check_distance``);
3. on a build: springs saved (``fix neigh/history``: those of touching entries), x -> lamda,
   wrap in lamda with the velocity jumps (``Domain::pbc``), lamda -> x, new list, springs restored;
4. forces: image positions owner + shift of the current box (the box of step n-1), from lamda on
   a build step; image velocities with the Lees-Edwards jump; virial;
5. second half step;
6. ``fix deform`` end of step, on the steps that are multiples of its N (``ShearLoading.every``):
   the box of step n (xy styles erate, vel, final, delta linear over the run ``begin``..``end``:
   xy(n) = xy0 + (n - begin)/(end - begin) (xy_stop - xy0), e.g. xy_stop = xy0 + (end - begin) dt
   rate Ly0 for erate; trate xy0 exp(rate (n - begin) dt) with h_rate[5] = rate * the tilt before;
   then LAMMPS' tilt wrap), stress of step n = virial / (Lx Ly) of box n (thermo); ``advance``
   also returns the virial of every step.

The contact law is any registered law (``law=``, :func:`gransim.contacts.laws.make_law`); by
default the Hooke law of the settings in the engine's flavour: ``HookeLammps``
(``gran/hooke/history``, its spring reset when its pair does not touch) for ``flavour="lammps"``,
``HookeLiggghts`` for ``flavour="liggghts"``, which also keeps LIGGGHTS' bookkeeping (hand-over of
overlapping pairs, orthogonal wrap and box check): a zero-tilt cell then reproduces
:class:`gransim.dem.DEMEngine` (it needs zero tilt and a fixed box, the only case both can
express). The force loop is the orthogonal engine's (:func:`gransim.dem.kernels.forces_in`) with
the sheared cell's image (:data:`gransim.dem.kernels.TiltedImage`). Details and sources:
docs/shear.md.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._numba import disk_cache_off
from .._validate import as_int, check_choice
from ..errors import InputError, ResultFileError, SimulationError
from ..geometry import Packing
from ..io import atomic_h5, write_packing_group
from ..progress import Interrupted, check_interrupt, deferred_interrupts, progress
from . import kernels as K
from . import sheared_kernels as SK
from .engine import ORDERS, CodeOrderCell, Engine, fingerprint
from .settings import FLAVOURS, DEMSettings


def _number(value, name: str) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, got {value!r}") from None
    if not np.isfinite(v):
        raise InputError(f"{name}: expected a finite number, got {value!r}")
    return v


#: ``fix deform xy`` styles (LAMMPS ``FixDeform``): the number is 1/s (erate, trate), m/s (vel), m
#: (final, delta)
XY_STYLES = ("erate", "trate", "vel", "final", "delta")


@dataclass(frozen=True)
class ShearLoading:
    """Loading of the sheared cell: LAMMPS ``fix deform N xy STYLE VALUE [y variable ...] remap v``.

    Attributes
    ----------
    erate : engineering shear rate (1/s) of style ``xy erate``: d xy/dt = erate * Ly0 (Ly0 the
        height at the start of the run). 0: no shear. The same number as ``value`` for that style.
    y : "fixed" (constant volume) or "servo" (normal stress on y, see the module docstring).
    target : servo target sigma_yy, compression positive (N/m in 2D).
    gain : servo gain g (1/(Pa s)), > 0 for "servo".
    xy : the tilt style, one of :data:`XY_STYLES` (``FixDeform::init`` / ``end_of_step``; lattice
        spacing 1.0):

        - ``erate R``: tilt_stop = xy0 + (delt R) Ly0, delt = (end - begin) dt;
        - ``vel V``: tilt_stop = xy0 + delt V (m/s);
        - ``final T``: tilt_stop = T (m);  ``delta D``: tilt_stop = xy0 + D (m);
        - these four: xy = xy0 + delta (tilt_stop - xy0), delta = (step - begin)/(end - begin),
          h_rate[5] = (tilt_stop - xy0)/delt for the whole run;
        - ``trate R``: xy = xy0 exp(R (step - begin) dt) (1/s; needs xy0 != 0, as LAMMPS), and
          h_rate[5] = R * (the tilt before the step's change), 0 until the first change.
    value : the style's number; for ``xy="erate"`` it defaults to ``erate`` (give one of them, or
        the same number twice); other styles need it (and erate 0).
    every : ``fix deform N``: the box (tilt and servo) changes on the steps that are multiples of
        N only (``Modify::end_of_step``); h_rate is that of the last change (linear styles: the
        constant of ``init``).
    x_erate : ``x erate R`` (1/s): Lx(t) = Lx0 (1 + R t), lo and hi moving by -/+ half (0: x
        fixed). y_erate : ``y erate R`` (1/s) with ``y="erate"``. With ``xy erate`` these give any
        velocity gradient L = [[R_x, R_xy Ly0/Ly], [0, R_y]] of LAMMPS' upper-triangular cell
        (``FixDeform::init``: lo_stop = lo_start - 0.5 delt R (hi_start - lo_start)).
    remap : "v" (``remap v``: positions untouched, the images and a particle crossing the boundary
        move with the velocity jumps h_rate; the default) or "x" (``remap x``: every position
        mapped through lamda at each box change, no velocity jumps: an affine deformation of the
        whole assembly, as a material point driven by F(t)).
    """

    erate: float = 0.0
    y: str = "fixed"
    target: float = 0.0
    gain: float = 0.0
    xy: str = "erate"
    value: float | None = None
    every: int = 1
    x_erate: float = 0.0
    y_erate: float = 0.0
    remap: str = "v"

    def __post_init__(self):
        object.__setattr__(self, "erate", _number(self.erate, "erate"))
        check_choice(self.y, "y control", ("fixed", "servo", "erate"))
        check_choice(self.remap, "remap", ("v", "x"))
        object.__setattr__(self, "x_erate", _number(self.x_erate, "x_erate"))
        object.__setattr__(self, "y_erate", _number(self.y_erate, "y_erate"))
        if self.y_erate != 0.0 and self.y != "erate":
            raise InputError(f"y_erate: a y strain rate needs y='erate', got y={self.y!r}")
        object.__setattr__(self, "target", _number(self.target, "target"))
        object.__setattr__(self, "gain", _number(self.gain, "gain"))
        if self.y == "servo" and not self.gain > 0:
            raise InputError(f"gain: the y servo needs a gain > 0 (1/(Pa s)), got {self.gain!r}")
        check_choice(self.xy, "xy style", XY_STYLES)
        if self.xy == "erate":
            v = self.erate if self.value is None else _number(self.value, "value")
            if self.value is not None and self.erate not in (0.0, v):
                raise InputError(
                    f"value: xy erate given twice with different numbers, erate = {self.erate!r} and value = {v!r}"
                )
            object.__setattr__(self, "erate", v)
        else:
            if self.value is None:
                raise InputError(f"value: xy {self.xy} needs its number ({_UNITS[self.xy]})")
            v = _number(self.value, "value")
            if self.erate != 0.0:
                raise InputError(
                    f"erate: only for xy erate; xy {self.xy} takes its number as value, got erate = {self.erate!r}"
                )
        object.__setattr__(self, "value", v)
        object.__setattr__(self, "every", as_int(self.every, "every", 1))

    @property
    def moves_tilt(self) -> bool:
        """False when the tilt cannot change (xy erate 0)."""
        return not (self.xy == "erate" and self.value == 0.0)

    @property
    def moves_box(self) -> bool:
        """False for a fixed box (no tilt change, x and y fixed)."""
        return self.moves_tilt or self.x_erate != 0.0 or self.y != "fixed"

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


_UNITS = {"erate": "1/s", "trate": "1/s", "vel": "m/s", "final": "m", "delta": "m"}


def tilt_stop(style: str, value: float, tilt_start: float, ly_start: float, delt: float) -> float:
    """``tilt_stop`` of ``xy STYLE value`` in LAMMPS' ``FixDeform::init`` (the same double operations
    in the same order; lattice spacing 1.0): final: value; delta: start + value; vel: start +
    delt*value; erate: start + (delt*value)*(yhi_start - ylo_start); trate: start*exp(value*delt)
    (printed only: the tilt of trate is computed step by step)."""
    if style == "final":
        return value * 1.0
    if style == "delta":
        return tilt_start + value * 1.0
    if style == "vel":
        return tilt_start + delt * (value * 1.0)
    if style == "erate":
        return tilt_start + delt * value * ly_start
    if style == "trate":
        return tilt_start * math.exp(value * delt)
    raise InputError(f"xy style: expected one of {', '.join(XY_STYLES)}, got {style!r}")


def _check_box(box, Lx: float, Ly: float, xy: float):
    """(lo_x, lo_y, hi_x, hi_y, xy) of the ``box`` argument (lo, hi[, xy]), checked against the cell."""
    try:
        parts = list(box)
        if len(parts) not in (2, 3):
            raise ValueError
        lo, hi = (np.array(b, np.float64).reshape(2) for b in parts[:2])
        tilt = float(parts[2]) if len(parts) == 3 else xy
    except (TypeError, ValueError):
        raise InputError(
            f"box: expected (lo, hi) or (lo, hi, xy), lo and hi two numbers each (m), got {box!r}"
        ) from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo) and np.isfinite(tilt)):
        raise InputError(f"box: expected finite lo < hi and tilt, got lo {lo.tolist()}, hi {hi.tolist()}, xy {tilt!r}")
    L = np.array([Lx, Ly])
    if np.any(np.abs((hi - lo) - L) > 1e-12 * L):
        raise InputError(f"box: hi - lo = {(hi - lo).tolist()} m differs from the cell's side lengths {L.tolist()} m")
    if abs(tilt - xy) > 1e-12 * Lx:
        raise InputError(f"box: xy = {tilt!r} m differs from the cell's tilt cell[0, 1] = {xy!r} m")
    return np.array([lo[0], lo[1], hi[0], hi[1], tilt])


class ShearedCell(CodeOrderCell):
    """LAMMPS' triclinic periodic box under ``fix deform ... xy ... remap v`` (module docstring):
    what :class:`~gransim.dem.engine.Engine` does that depends on it. Its state on the engine:
    ``box`` (lo_x, lo_y, hi_x, hi_y, xy), ``box_hold`` (the box at the last build), ``h_rate``
    (h_rate[0], h_rate[1], h_rate[5]: the velocity jumps of the images), ``lam`` (lamda
    coordinates of the last build), ``touch`` (per entry: touching at the last force evaluation,
    ``fix neigh/history``), ``corners_hold`` (the 8 box corners at the last build), ``sc`` (the
    virial); the run of :meth:`start_run` (``fix deform`` begin, end, tilt start and stop)."""

    kind = "sheared"

    @staticmethod
    def check(packing: Packing, settings, flavour: str) -> None:
        if settings.mode != "serial":
            raise InputError(f"settings.mode: the sheared cell runs the serial loop only, got {settings.mode!r}")
        ShearedCell.check_cell(packing, flavour)

    @staticmethod
    def check_cell(packing: Packing, flavour: str) -> None:
        """LAMMPS' triclinic cell: a1 = (Lx, 0), |xy| <= Lx/2; LIGGGHTS' arithmetic: no tilt."""
        C = np.asarray(packing.cell, np.float64)
        if C[1, 0] != 0.0:
            raise InputError(
                f"packing.cell: a LAMMPS triclinic cell has a1 = (Lx, 0): cell[1, 0] must be 0, got {C[1, 0]!r}"
            )
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        if not (Lx > 0 and Ly > 0):
            raise InputError(f"packing.cell: Lx and Ly must be > 0, got {Lx!r}, {Ly!r}")
        if abs(xy) > 0.5 * Lx:
            raise InputError(
                f"packing.cell: tilt xy = {xy!r} m beyond Lx/2 = {0.5 * Lx!r} m (LAMMPS needs |xy| <= Lx/2)"
            )
        if flavour == "liggghts" and xy != 0.0:
            raise InputError(
                f"flavour 'liggghts': needs a cell without tilt (LIGGGHTS' bookkeeping is orthogonal), got xy = {xy!r}"
            )

    @staticmethod
    def check_size(packing: Packing, settings) -> None:
        C = np.asarray(packing.cell, np.float64)
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        heights = np.array([Lx * Ly / np.hypot(Ly, xy), Ly])
        cut = 2 * (2.0 * float(packing.radii.max()) + settings.skin)
        if heights.min() <= cut:
            raise InputError(
                f"packing.cell: cell heights {heights[0]:.4g}, {heights[1]:.4g} m must exceed "
                f"2 (2 r_max + skin) = {cut:.4g} m (one periodic image per pair)"
            )

    def __init__(self, eng, box, threads, x, v, w):
        if threads not in (None, 1):
            raise InputError(f"threads: the sheared cell runs the serial loop (one thread), got {threads!r}")
        C = np.asarray(eng.packing.cell, np.float64)
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        n = eng.packing.n
        eng.box = np.array([0.0, 0.0, Lx, Ly, xy]) if box is None else _check_box(box, Lx, Ly, xy)
        self.lmp = eng.flavour == "lammps"
        eng.h_rate = np.zeros(3)
        eng.lam = np.zeros((n, 2))
        eng.touch = np.zeros(0, np.bool_)
        eng.corners_hold = np.zeros((8, 2))
        eng.box_hold = eng.box.copy()
        eng.sc = K.Scratch(np.zeros(4), np.zeros((0, 4)), np.zeros((0, 2)))
        self.run = None  # the fix deform of the current run (start_run)
        self._init_state(eng, x, v, w)

    # geometry
    def matrix(self, eng) -> np.ndarray:
        b = eng.box
        return np.array([[b[2] - b[0], b[4]], [0.0, b[3] - b[1]]])

    def lengths(self, eng) -> np.ndarray:
        b = eng.box
        return np.array([b[2] - b[0], b[3] - b[1]])

    def lo(self, eng) -> np.ndarray:
        return eng.box[0:2]

    def hi(self, eng) -> np.ndarray:
        return eng.box[2:4]

    # the list
    def neighbours(self, eng, a, b, sx, sy, both, hist, xhold):
        """The :class:`~gransim.dem.kernels.Neighbours` of the list (a, b, s, both) with history
        ``hist`` and build positions ``xhold``: CSR offsets of the entries of each a (sorted by a),
        zeroed per-entry outputs (no threaded loop here: no incoming CSR)."""
        n = eng.packing.n
        start = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(a, minlength=n), out=start[1:])
        z = np.zeros(0, np.int64)
        return K.Neighbours(
            a, b, np.zeros((0, 2), np.int64), sx, sy, both, hist, start, z, z, xhold,
            np.zeros(a.size, np.bool_), np.zeros((a.size, 2)), np.zeros(0),
        )  # fmt: skip

    def rebuild(self, eng, carry: bool):
        """LAMMPS: x -> lamda, wrap in lamda with the velocity jumps, lamda -> x, new list, springs
        of the touching entries handed over (LIGGGHTS flavour: the orthogonal wrap and hand-over)."""
        if self.lmp:
            SK.x2lamda(eng.x, eng.box, eng.lam)
            bad = SK.pbc_lamda(eng.lam, eng.v, eng.h_rate, True)
            if bad >= 0:
                raise SimulationError(
                    f"step {eng.step}: particle {bad} lost (lamda {eng.lam[bad].tolist()}, "
                    f"more than a cell outside the box)"
                )
            SK.lamda2x(eng.lam, eng.box, eng.x)
        else:
            bad = K.pbc_wrap(eng.x, eng.box[0:2].copy(), eng.box[2:4].copy())
            if bad >= 0:
                raise SimulationError(f"step {eng.step}: particle {bad} lost (at {eng.x[bad].tolist()})")
            SK.x2lamda(eng.x, eng.box, eng.lam)
        a, b, sx, sy, both, selfimg = SK.build_list(eng.x, eng.lam, eng.r, eng.box, eng.settings.skin, self.lmp)
        if selfimg >= 0:
            eng._failed = f"step {eng.step}: particle {selfimg} is near its own image; the cell is too small"
            raise SimulationError(eng._failed)
        xi = np.zeros((a.size, eng._width))
        if carry and eng.ea.size:
            SK.hand_over(
                eng.x, eng.r, eng.box, a, b, sx, sy, eng.start, eng.eb, eng.both, eng.xi, eng.touch, self.lmp, xi,
                eng._flip,
            )  # fmt: skip
        eng.nb = self.neighbours(eng, a, b, sx, sy, both, xi, eng.x.copy())
        eng.touch = np.zeros(a.size, np.bool_)
        SK.box_corners(eng.box, eng.corners_hold)
        eng.box_hold = eng.box.copy()
        eng._build_step = eng.step
        eng.n_rebuilds += 1

    def _cell(self, eng):
        """The kernels' view of the cell (:class:`~gransim.dem.sheared_kernels.Cell`)."""
        return SK.Cell(eng.box, eng.box_hold, eng.h_rate, eng.lam, eng.touch, eng.corners_hold)

    def forces(self, eng, update: bool):
        """Forces with the images of the current box (from lamda, as LAMMPS on a build step)."""
        with disk_cache_off(eng._no_cache):
            return SK.forces(eng.p, eng.nb, eng.law, self._cell(eng), self.lmp, eng.settings.dt, update, eng.virial)

    def touching(self, eng):
        """Entries of the touching pairs, each once (a < b), and their overlaps (m), the images
        from the current box (:func:`gransim.dem.kernels.tilted_image`)."""
        b = eng.box
        h0, h1, h5 = b[2] - b[0], b[3] - b[1], b[4]
        a, j = eng.ea, eng.eb
        dx = eng.x[a, 0] - ((eng.x[j, 0] + eng.esx * h0) + eng.esy * h5)
        dy = eng.x[a, 1] - (eng.x[j, 1] + eng.esy * h1)
        dist = np.sqrt(dx * dx + dy * dy)
        rs = eng.r[a] + eng.r[j]
        e = np.nonzero((dist < rs) & (a < j))[0]
        return e, rs[e] - dist[e]

    def peculiar_velocities(self, eng) -> np.ndarray:
        """v - u(x) (m/s), (N, 2): u the homogeneous flow of the cell, u_x = h_rate[5] (y - ylo)/Ly,
        u_y = h_rate[1] (y - ylo)/Ly (continuous across the Lees-Edwards boundary)."""
        b = eng.box
        f = (eng.x[:, 1] - b[1]) / (b[3] - b[1])
        return eng.v - np.stack([eng.h_rate[2] * f, eng.h_rate[1] * f], axis=1)

    def budget_kinetic_energy(self, eng) -> float:
        """Kinetic energy (J) of the velocities relative to the homogeneous flow of the cell
        (:meth:`peculiar_velocities`), which the Lees-Edwards remap of a particle crossing the
        boundary leaves unchanged (the lab-frame one jumps by m v.U + m U^2/2 there, U the flow
        across the cell, work no contact did)."""
        u = self.peculiar_velocities(eng)
        return float(0.5 * np.sum(eng.m * np.einsum("ij,ij->i", u, u)) + 0.25 * np.sum(eng.m * eng.r**2 * eng.w**2))

    def flow_kinetic_energy(self, eng) -> float:
        """Kinetic energy (J) of the homogeneous flow of the cell at the particles, sum m |u(x)|^2/2."""
        u = eng.v - self.peculiar_velocities(eng)
        return float(0.5 * np.sum(eng.m * np.einsum("ij,ij->i", u, u)))

    # the loading
    def start_run(self, eng, loading, nsteps: int):
        """LAMMPS ``run nsteps`` under ``loading``: ``fix deform`` init (the start and stop tilt of the
        style over the run, :class:`ShearLoading`; h_rate[5] = (tilt_stop - tilt_start) / (nsteps
        dt) for the linear styles, 0 for trate until its first change; h_rate[1] = 0 until the first
        servo change), then the run's set-up (``Verlet::setup``: wrap with this run's h_rate, list
        with the springs handed over, forces without spring increment).

        Raises InputError for a trate on a cell without tilt (LAMMPS: "Cannot use fix deform trate
        on a box with zero tilt") and for a moving box with ``flavour="liggghts"``."""
        if not isinstance(loading, ShearLoading):
            raise InputError(f"loading: expected a ShearLoading (the sheared cell), got {type(loading).__name__}")
        if eng.flavour == "liggghts" and loading.moves_box:
            raise InputError("flavour 'liggghts': only a fixed box (xy erate 0, y fixed) is supported")
        begin = eng.step
        end = begin + nsteps
        delt = float(end - begin) * eng.settings.dt
        b = eng.box
        tilt_start = float(b[4])
        if loading.xy == "trate" and tilt_start == 0.0:
            raise InputError(
                "loading: xy trate on a cell without tilt (the tilt grows as xy0 exp(rate t); "
                "LAMMPS stops too: 'Cannot use fix deform trate on a box with zero tilt')"
            )
        stop = tilt_stop(loading.xy, loading.value, tilt_start, float(b[3] - b[1]), delt)
        vremap = loading.remap == "v"
        eng.h_rate[:] = 0.0
        if not loading.moves_tilt:
            style = SK.XY_NONE
        elif loading.xy == "trate":
            style = SK.XY_TRATE
        else:
            style = SK.XY_LINEAR
            if vremap:
                eng.h_rate[2] = (stop - tilt_start) / delt
        # x and y erate (FixDeform::init): the stop box and, with remap v, h_rate = d hi/dt - d lo/dt
        xs = _erate_stop(float(b[0]), float(b[2]), loading.x_erate, delt)
        ys = _erate_stop(float(b[1]), float(b[3]), loading.y_erate, delt)
        if vremap:
            for k, (lo, hi, (lo_stop, hi_stop)) in ((0, (b[0], b[2], xs)), (1, (b[1], b[3], ys))):
                eng.h_rate[k] = (hi_stop - hi) / delt - (lo_stop - lo) / delt
        self.run = ShearRun(
            begin, end, style, tilt_start, stop, float(b[1]), float(b[3]), float(b[3] - b[1]),
            float(b[0]), float(b[2]), loading,
        )  # fmt: skip
        eng._rebuild(carry=True)
        eng._forces(update=False)
        eng.stress = eng.stress_tensor()
        eng._reset_energy_budget()  # the divergence check's balance starts with the run
        return self.run

    def drive(self, eng, run, *args, **kwargs):
        """(Deform, nsteps) of ``advance(nsteps)`` in the run of :meth:`start_run`."""
        if run is None:
            raise InputError("advance: call start_run(loading, nsteps) first (the fix deform of the run)")
        if len(args) + len(kwargs) != 1 or (args and not isinstance(args[0], (int, np.integer, float))):
            raise InputError("advance: the sheared cell takes advance(nsteps) in the run begun by start_run")
        nsteps = args[0] if args else kwargs["nsteps"]
        nsteps = as_int(
            nsteps, "nsteps", 0, run.end - eng.step, note=f" (the run ends at step {run.end}, now at step {eng.step})"
        )
        return deform_of(run, eng.settings.dt), nsteps

    def series(self, nsteps: int):
        return SK.ShearSeries(
            np.zeros((nsteps, 4)), np.zeros((nsteps, 4)), np.zeros((nsteps, 5)), np.zeros(nsteps), np.zeros(nsteps),
            np.zeros(nsteps),
        )  # fmt: skip

    def box_state(self, eng):
        return eng.box.copy()

    def block(self, eng, dfm, out, done: int, n: int, resume: bool):
        s = eng.settings
        with disk_cache_off(eng._no_cache):
            return SK.run_block(
                eng.p, eng.nb, eng.law, self._cell(eng), dfm, SK.ShearSeries(*(a[done:] for a in out)), eng.virial,
                s.dt, s.skin, self.lmp, eng.step, n, resume,
            )  # fmt: skip

    def check_divergence(self, eng, out, done: int, k: int, box_before):
        """The divergence check (:meth:`gransim.dem.engine.Engine._check_energy`) after the k steps
        from row ``done``: every step's kinetic energy finite; the kinetic energy relative to the
        flow, known at the last of them, within the budget (which counts the kinetic energy of the
        flow at the particles too, :meth:`flow_kinetic_energy`); the work of the cell per step
        -(V_xx dLx/Lx + V_yy dLy/Ly + V_yx (dxy - xy dLx/Lx)/Ly) (V the virial of the step, N m; the
        velocity gradient of the box change dH H^-1, H = [[Lx, xy], [0, Ly]])."""
        rows = slice(done, done + k)
        b1 = out.box[rows]  # lx, ly, xy, ylo, yhi after each step
        b0 = np.vstack([[box_before[2] - box_before[0], box_before[3] - box_before[1], box_before[4]], b1[:-1, :3]])
        dlx = (b1[:, 0] - b0[:, 0]) / b0[:, 0]
        dly = (b1[:, 1] - b0[:, 1]) / b0[:, 1]
        dxy = (b1[:, 2] - b0[:, 2] - b0[:, 2] * dlx) / b0[:, 1]
        vir = out.vir[rows]
        dw = -(vir[:, 0] * dlx + vir[:, 1] * dly + vir[:, 3] * dxy)
        ke = np.full(k, np.nan)
        ke[-1] = self.budget_kinetic_energy(eng)
        eng._check_energy(eng.step + 1, out.ke[rows], ke, dw, flow=self.flow_kinetic_energy(eng))

    def collapse_message(self, eng) -> str:
        return (
            f"the cell collapsed or its tilt passed Lx/2 (box {eng.box.tolist()}; LAMMPS would flip the box, "
            "not supported)"
        )

    def cell_series(self, out) -> dict:
        return {"box": out.box}

    # checkpoints (the cell's datasets beside gransim.dem.engine.CHECKPOINT)
    def cell_arrays(self, eng) -> dict:
        """The box, its state at the last build, the image velocity jumps, the lamda coordinates, the
        touching flags of the entries and the run (begin, end, style, tilt start and stop, y lo and
        hi and Ly at the start: :class:`ShearRun`, with its loading: :func:`run_arrays`)."""
        out = {
            "box": eng.box,
            "box_hold": eng.box_hold,
            "h_rate": eng.h_rate,
            "lamda": eng.lam,
            "corners_hold": eng.corners_hold,
            "neighbours/touch": eng.touch,
        }
        return {**out, **run_arrays(self.run)}

    def cell_restore(self, eng, arrays: dict):
        eng.box = np.array(arrays["box"], np.float64).reshape(5)
        eng.box_hold = np.array(arrays["box_hold"], np.float64).reshape(5)
        eng.h_rate = np.array(arrays["h_rate"], np.float64).reshape(3)
        eng.lam = np.array(arrays["lamda"], np.float64).reshape(eng.packing.n, 2)
        eng.corners_hold = np.array(arrays["corners_hold"], np.float64).reshape(8, 2)

    def cell_restored(self, eng, arrays: dict):
        eng.touch = np.array(arrays["neighbours/touch"], np.bool_).reshape(eng.ea.size)
        self.run = run_from_arrays(arrays)
        eng._run_drive = self.run


class ShearRun(NamedTuple):
    """The ``fix deform`` of one LAMMPS run: steps begin..end, the tilt style (sheared_kernels.XY_*),
    the tilt at the start and at the end (m), y lo and hi and Ly at the start (m), x lo and hi at
    the start (m), the loading."""

    begin: int
    end: int
    style: int
    tilt_start: float
    tilt_stop: float
    y_lo: float
    y_hi: float
    ly0: float
    x_lo: float
    x_hi: float
    loading: ShearLoading


#: the numbers of a ShearRun in a checkpoint's ``run`` dataset (all but the loading)
RUN_NUMBERS = 10


def run_arrays(run: ShearRun | None) -> dict:
    """The checkpoint datasets of a sheared cell's run (none without a run): ``run`` (its
    :data:`RUN_NUMBERS` numbers) and ``run_loading_json`` (its loading as JSON bytes, uint8)."""
    if run is None:
        return {}
    text = json.dumps(run.loading.to_dict(), sort_keys=True)
    return {
        "run": np.array(run[:RUN_NUMBERS], np.float64),
        "run_loading_json": np.frombuffer(text.encode(), np.uint8).copy(),
    }


def run_from_arrays(arrays: dict) -> ShearRun | None:
    """Inverse of :func:`run_arrays` (None without ``run``); the loading is ``arrays["loading"]``
    when given (a run file's), else the checkpoint's JSON."""
    if "run" not in arrays:
        return None
    r = np.asarray(arrays["run"], np.float64).reshape(RUN_NUMBERS)
    loading = arrays.get("loading")
    if not isinstance(loading, ShearLoading):
        if "run_loading_json" not in arrays:
            raise InputError("restore: a sheared checkpoint in a run needs its loading (arrays['loading'])")
        loading = ShearLoading(**json.loads(np.asarray(arrays["run_loading_json"], np.uint8).tobytes().decode()))
    return ShearRun(int(r[0]), int(r[1]), int(r[2]), *(float(v) for v in r[3:]), loading)


def _erate_stop(lo: float, hi: float, rate: float, delt: float):
    """(lo_stop, hi_stop) of ``erate rate`` over ``delt`` s from [lo, hi] (``FixDeform::init``:
    lo_start - 0.5 delt rate (hi_start - lo_start), the same operations in the same order)."""
    return lo - 0.5 * delt * rate * (hi - lo), hi + 0.5 * delt * rate * (hi - lo)


def deform_of(run: ShearRun, dt: float):
    """The :data:`gransim.dem.sheared_kernels.Deform` of a run begun by ``start_run`` with time
    step ``dt`` (s): what every ordering's step loop reads of the run's ``fix deform``."""
    ld = run.loading
    delt = float(run.end - run.begin) * dt
    xs = _erate_stop(run.x_lo, run.x_hi, ld.x_erate, delt)
    ys = _erate_stop(run.y_lo, run.y_hi, ld.y_erate, delt)
    return SK.Deform(
        int(run.begin), int(run.end), int(ld.every), int(run.style), float(run.tilt_start), float(run.tilt_stop),
        float(ld.value), ld.y == "servo", float(run.y_lo), float(run.y_hi), float(run.ly0), dt * ld.gain,
        float(ld.gain), float(ld.target), ld.x_erate != 0.0, float(run.x_lo), float(run.x_hi), xs[0], xs[1],
        ld.y == "erate", ys[0], ys[1], ld.remap == "x",
    )  # fmt: skip


def ShearEngine(
    packing: Packing,
    settings: DEMSettings,
    velocities=None,
    spins=None,
    flavour: str = "lammps",
    check_dt: bool = True,
    box=None,
    law=None,
) -> Engine:
    """The :class:`~gransim.dem.engine.Engine` with the sheared cell (LAMMPS' triclinic box), in the
    arithmetic ``flavour``: "lammps" (the default: the triclinic box is LAMMPS') or "liggghts" (a
    cell without tilt under a fixed box, LIGGGHTS' bookkeeping: it reproduces the orthogonal cell).
    ``box``: (lo, hi) or (lo, hi, xy) as a LAMMPS data file's box lines (used as given, bit for bit)."""
    return Engine(packing, settings, velocities, spins, None, check_dt, box, law, cell="sheared", flavour=flavour)


def simple_shear(
    packing: Packing,
    settings: DEMSettings,
    loading: ShearLoading,
    nsteps: int,
    velocities=None,
    spins=None,
    flavour: str = "lammps",
    every: int | None = None,
    callback=None,
    box=None,
) -> dict:
    """Simple shear of ``packing`` for ``nsteps`` steps (one LAMMPS ``run``); per-step series.

    ``loading`` (:class:`ShearLoading`): constant-volume shear (``y="fixed"``) or shear under
    the y normal-stress servo. ``callback(engine)`` is called every ``every`` steps (and at the end),
    e.g. to record positions; ``box`` is passed to :class:`ShearEngine`. Returns the dict of
    :meth:`ShearEngine.advance` plus ``setup_stress``
    (2, 2) (the set-up evaluation, LAMMPS' thermo at step 0), ``shear_strain`` (n,) ((xy - xy0) / Ly0) and
    ``engine`` (the final state).
    """
    nsteps = as_int(nsteps, "nsteps", 1)
    if every is not None:
        every = as_int(every, "every", 1)
    eng = ShearEngine(packing, settings, velocities=velocities, spins=spins, flavour=flavour, box=box)
    ly0 = float(eng.box[3] - eng.box[1])
    xy0 = float(eng.box[4])
    setup = eng.start_run(loading, nsteps)
    parts = []
    chunk = every or nsteps
    while eng.step < nsteps:
        parts.append(eng.advance(min(chunk, nsteps - eng.step)))
        if callback is not None:
            callback(eng)
    out = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    out["setup_stress"] = setup
    out["shear_strain"] = (out["box"][:, 2] - xy0) / ly0
    out["engine"] = eng
    return out


#: ``kind`` of the run file of :func:`write_shear_run` (layout: docs/shear.md)
SHEAR_RUN_KIND = "shear-run"


def run_shear_file(
    packing: Packing,
    settings: DEMSettings,
    loading: ShearLoading,
    nsteps: int,
    out_path,
    series_every: int = 10,
    snapshot_every: int = 0,
    parameters: dict | None = None,
    show_progress: bool = True,
    flavour: str = "lammps",
    law=None,
    law_options: dict | None = None,
    checkpoint_every: int = 0,
    resume: bool = False,
    stop_at_step: int | None = None,
    order: str = "code",
    threads: int | None = None,
) -> dict:
    """Simple shear of ``packing`` for ``nsteps`` steps, written to an HDF5 run file (kind
    :data:`SHEAR_RUN_KIND`, layout in docs/shear.md) atomically with the provenance.

    Parameters
    ----------
    series_every : a row of ``/series`` every this many steps (and step 0 = the set-up, and the
        last step). snapshot_every : ``/snapshots/<step>`` every this many steps (0: the first and
        the last only). parameters : extra provenance (stored beside the settings and loading).
    show_progress : a progress bar on a terminal (silent otherwise).
    law : optional contact law object (:class:`ShearEngine`); law_options : its {"name", "params"}
        (:func:`gransim.dem.biaxial.law_settings`), recorded as ``law`` in the settings JSON and
        the provenance (absent for the default Hooke law).
    checkpoint_every : every this many steps (0: never) the file is written with the rows so far,
        ``complete`` False and ``/checkpoint`` (the engine's state, :meth:`~gransim.dem.engine.
        Engine.state_arrays`); an interruption (SIGINT, SIGTERM, SIGHUP) writes one at the step
        it stops at.
    resume : continue the run of ``out_path`` (same fingerprint: packing, settings, loading, steps,
        sampling) from its checkpoint; the result equals the uninterrupted run bit for bit. A
        complete file is returned as it is.
    stop_at_step : end this call at that step with a checkpoint (a piece of a longer run).
    order, threads : the engine's ordering, "code" (one thread) or "fast" (``threads`` threads;
        :func:`gransim.dem.engine.make_engine`); "fast" is recorded in the settings JSON and the
        fingerprint.

    Returns a summary dict (steps, shear strain reached, final stresses tension positive, builds).
    A SimulationError is re-raised after the file was written with ``complete`` False and the
    message as ``stop_reason`` (with the last checkpoint, if any). Stresses in the file are tension
    positive (the engine's are compression positive: ``sigma_file = -stress``).
    """
    nsteps = as_int(nsteps, "nsteps", 1)
    series_every = as_int(series_every, "series_every", 1)
    snapshot_every = as_int(snapshot_every, "snapshot_every", 0)
    checkpoint_every = as_int(checkpoint_every, "checkpoint_every", 0)
    if stop_at_step is not None:
        stop_at_step = as_int(stop_at_step, "stop_at_step", 1)
    out_path = Path(out_path)
    check_choice(order, "order", ORDERS)
    info = {"dem": settings.to_dict(), "loading": loading.to_dict(), "nsteps": nsteps, "flavour": flavour}
    if order != "code":
        info["order"] = order
    if law is not None:
        info["law"] = dict(law_options) if law_options else {"name": type(law).__name__, "params": dict(law._asdict())}
    text = json.dumps(info, sort_keys=True)
    sampling = {"series_every": series_every, "snapshot_every": snapshot_every}
    fp = fingerprint(packing, json.dumps({**info, **sampling}, sort_keys=True))
    # the engine's choices (the code order's sheared cell runs one thread)
    choices = {"cell": "sheared", "order": order, "threads": threads if order == "fast" else None, "law": law}
    C = np.asarray(packing.cell, np.float64)
    ly0, xy0 = float(C[1, 1]), float(C[0, 1])
    rows = {k: [] for k in ("step", "box", "stress", "n_contacts", "kinetic_energy")}
    snaps = {}
    checkpoint = None

    def row(step, box, stress, nc, ke):
        rows["step"].append(step)
        rows["box"].append(np.asarray(box, np.float64))
        rows["stress"].append(-np.asarray(stress))
        rows["n_contacts"].append(nc)
        rows["kinetic_energy"].append(ke)

    def snap():
        snaps[eng.step] = {
            "positions": eng.x.copy(),
            "velocities": eng.v.copy(),
            "spins": eng.w.copy(),
            "cell": eng.cell,
            "box_lo": eng.box[0:2].copy(),
        }

    def take_checkpoint():
        return {"step": eng.step, "arrays": {k: np.array(v) for k, v in eng.state_arrays().items()}}

    stored = _read_shear_resume(out_path, fp) if resume and out_path.exists() else None
    if stored is not None and stored["complete"]:
        return _shear_summary(stored["rows"], xy0, ly0, nsteps, stored["n_rebuilds"])
    if stored is not None:
        checkpoint = stored["checkpoint"]
        try:  # the engine straight from the checkpoint (no set-up of a new engine to overwrite)
            eng = Engine.from_checkpoint(
                packing, settings, {**checkpoint["arrays"], "loading": loading}, checkpoint["step"], flavour=flavour,
                **choices,
            )  # fmt: skip
        except (KeyError, ValueError, TypeError) as exc:
            raise ResultFileError(f"{out_path}: its checkpoint does not fit this run ({exc!r})") from None
        rows, snaps = stored["rows"], stored["snapshots"]
        eng.n_rebuilds = stored["n_rebuilds"]
    else:
        eng = Engine(packing, settings, flavour=flavour, **choices)
        setup = eng.start_run(loading, nsteps)
        b = eng.box
        row(0, [b[2] - b[0], b[3] - b[1], b[4], b[1], b[3]], setup, eng.n_contacts, eng.kinetic_energy())
        snap()
    stops = set(range(series_every, nsteps + 1, series_every)) | {nsteps}
    for every in (snapshot_every, checkpoint_every):
        if every:
            stops |= set(range(every, nsteps + 1, every))
    if stop_at_step is not None and stop_at_step < nsteps:
        stops.add(stop_at_step)
    stops = sorted(s for s in stops if s > eng.step)
    reason = ""
    paused = False  # stopped at stop_at_step
    interrupted = None
    bar = progress(total=nsteps, desc="shear") if show_progress else None
    if bar is not None and eng.step:
        bar.update(eng.step)
    try:
        # SIGINT / SIGTERM / SIGHUP are acted on between two stops (gransim.progress): the file is
        # then written with the rows so far and a checkpoint at that step, complete = False
        with deferred_interrupts():
            for stop in stops:
                check_interrupt()
                out = eng.advance(stop - eng.step)
                if bar is not None:
                    bar.update(len(out["step"]))
                if stop % series_every == 0 or stop == nsteps:
                    row(stop, out["box"][-1], out["stress"][-1], out["n_contacts"][-1], out["kinetic_energy"][-1])
                if (snapshot_every and stop % snapshot_every == 0) or stop == nsteps:
                    snap()
                if stop < nsteps and ((checkpoint_every and stop % checkpoint_every == 0) or stop == stop_at_step):
                    checkpoint = take_checkpoint()
                    if stop == stop_at_step:
                        paused = True
                        reason = (
                            f"stopped at step {stop} by stop_at_step (a piece of a longer run; continue with resume)"
                        )
                        break
                    _write_shear_file(
                        out_path, packing, text, {**info, **(parameters or {})}, fp, sampling, rows, snaps,
                        f"run in progress, or killed: last checkpoint at step {stop} (continue with resume)",
                        checkpoint, eng.n_rebuilds, xy0, ly0, nsteps, settings.dt,
                    )  # fmt: skip
            check_interrupt()
    except SimulationError as exc:
        reason = str(exc)
    except KeyboardInterrupt as exc:
        interrupted = exc
        how = exc.signal_name if isinstance(exc, Interrupted) else "SIGINT"
        checkpoint = take_checkpoint()  # between two stops: a state the run continues from
        reason = f"interrupted by {how} at step {eng.step} of {nsteps} (continue with resume)"
    finally:
        if bar is not None:
            bar.close()
    _write_shear_file(
        out_path, packing, text, {**info, **(parameters or {})}, fp, sampling, rows, snaps, reason,
        checkpoint if reason else None, eng.n_rebuilds, xy0, ly0, nsteps, settings.dt,
    )  # fmt: skip
    if interrupted is not None:
        raise Interrupted(
            getattr(interrupted, "signum", 2), f"{out_path}: {reason} (an incomplete run file, complete = False)"
        ) from None
    if reason and not paused:
        after = (
            f"; resume continues from the checkpoint at step {checkpoint['step']}"
            if checkpoint is not None
            else "; no checkpoint: rerun it without resume"
        )
        raise SimulationError(f"{reason} (the run file {out_path} holds the steps before, complete = False{after})")
    return _shear_summary(rows, xy0, ly0, nsteps, eng.n_rebuilds)


def _shear_summary(rows: dict, xy0: float, ly0: float, nsteps: int, n_rebuilds: int) -> dict:
    box = np.array(rows["box"], np.float64).reshape(-1, 5)
    last = rows["stress"][-1]
    return {
        "steps": int(rows["step"][-1]),
        "shear_strain": float((box[-1, 2] - xy0) / ly0),
        "sigma_xy": float(last[0][1]),
        "sigma_yy": float(last[1][1]),
        "sigma_xx": float(last[0][0]),
        "ly": float(box[-1, 1]),
        "n_rebuilds": int(n_rebuilds),
    }


def _write_shear_file(
    out_path, packing, text, params, fp, sampling, rows, snaps, reason, checkpoint, n_rebuilds, xy0, ly0, nsteps, dt
) -> None:
    """The shear run file (docs/shear.md), atomically: the rows and snapshots so far, ``complete``
    when ``reason`` is empty, and ``/checkpoint`` (step, the engine's state arrays) when given."""
    box = np.array(rows["box"], np.float64).reshape(-1, 5)
    strain = (box[:, 2] - xy0) / ly0
    with atomic_h5(
        out_path, kind=SHEAR_RUN_KIND, parameters=params, seed=packing.metadata.get("seed"), lammps=False
    ) as f:
        f.attrs["settings"] = text
        f.attrs["fingerprint"] = fp
        f.attrs["sampling"] = json.dumps(sampling, sort_keys=True)
        f.attrs["n_particles"] = packing.n
        f.attrs["nsteps"] = nsteps
        f.attrs["n_rebuilds"] = int(n_rebuilds)
        f.attrs["complete"] = not reason
        f.attrs["stop_reason"] = reason
        f.attrs["stress_sign"] = "tension positive"
        f.attrs["shear_strain_reached"] = float(strain[-1])
        write_packing_group(f.create_group("packing"), packing)
        g = f.create_group("series")
        g["step"] = np.array(rows["step"], np.int64)
        g["time"] = g["step"][()] * dt
        g["box"] = box
        g["shear_strain"] = strain
        g["stress"] = np.array(rows["stress"], np.float64).reshape(-1, 2, 2)
        g["n_contacts"] = np.array(rows["n_contacts"], np.int64)
        g["kinetic_energy"] = np.array(rows["kinetic_energy"], np.float64)
        sg = f.create_group("snapshots")
        for step, d in sorted(snaps.items()):
            h = sg.create_group(str(step))
            h.attrs["step"] = step
            for k, v in d.items():
                h[k] = v
        if checkpoint is not None:
            ck = f.create_group("checkpoint")
            ck.attrs["step"] = int(checkpoint["step"])
            for k, v in checkpoint["arrays"].items():
                ck.create_dataset(k, data=np.asarray(v))


def _read_shear_resume(path: Path, fp: str) -> dict:
    """What a resume of the shear run file ``path`` continues from: its rows and snapshots up to its
    checkpoint, the checkpoint, ``complete``; ResultFileError for a file of another run (another
    fingerprint) or one without a checkpoint."""
    import h5py  # noqa: PLC0415 - start-up: h5py

    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("kind") != SHEAR_RUN_KIND:
                raise ResultFileError(
                    f"{path}: not a shear run file (kind {f.attrs.get('kind')!r}); refusing to resume"
                )
            have = f.attrs.get("fingerprint")
            if have != fp:
                raise ResultFileError(
                    f"{path}: belongs to another run (fingerprint {str(have)[:12]} != {fp[:12]}: different "
                    "packing, settings, loading, steps or sampling); refusing to resume"
                )
            g = f["series"]
            rows = {
                "step": [int(s) for s in g["step"][()]],
                "box": list(g["box"][()]),
                "stress": list(g["stress"][()]),
                "n_contacts": [int(c) for c in g["n_contacts"][()]],
                "kinetic_energy": [float(k) for k in g["kinetic_energy"][()]],
            }
            complete = bool(f.attrs["complete"])
            out = {"complete": complete, "rows": rows, "n_rebuilds": int(f.attrs.get("n_rebuilds", 0))}
            if complete:
                return out
            if "checkpoint" not in f:
                raise ResultFileError(f"{path}: no checkpoint to resume from; rerun without --resume")
            ck = f["checkpoint"]
            step = int(ck.attrs["step"])
            arrays = {}
            ck.visititems(lambda name, obj: arrays.__setitem__(name, obj[()]) if hasattr(obj, "shape") else None)
            keep = [k for k, s in enumerate(rows["step"]) if s <= step]
            rows = {k: [v[i] for i in keep] for k, v in rows.items()}
            snaps = {}
            for h in f["snapshots"].values():
                if int(h.attrs["step"]) <= step:
                    snaps[int(h.attrs["step"])] = {k: h[k][()] for k in h}
    except (OSError, KeyError) as exc:
        if isinstance(exc, ResultFileError):
            raise
        raise ResultFileError(f"{path}: cannot resume from it ({exc})") from None
    out.update(rows=rows, snapshots=snaps, checkpoint={"step": step, "arrays": arrays})
    return out


__all__ = [
    "FLAVOURS",
    "SHEAR_RUN_KIND",
    "XY_STYLES",
    "ShearEngine",
    "ShearLoading",
    "run_shear_file",
    "simple_shear",
    "tilt_stop",
]
