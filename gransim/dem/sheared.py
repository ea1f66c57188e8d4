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

import numpy as np

from .._numba import disk_cache_off
from .._validate import as_int, check_choice
from ..errors import InputError, SimulationError
from ..geometry import Packing
from ..io import atomic_h5, write_packing_group
from ..progress import Interrupted, check_interrupt, deferred_interrupts, progress
from . import kernels as K
from . import sheared_kernels as SK
from .engine import EngineCore
from .settings import FLAVOURS, DEMSettings, Integration


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
    """

    erate: float = 0.0
    y: str = "fixed"
    target: float = 0.0
    gain: float = 0.0
    xy: str = "erate"
    value: float | None = None
    every: int = 1

    def __post_init__(self):
        object.__setattr__(self, "erate", _number(self.erate, "erate"))
        check_choice(self.y, "y control", ("fixed", "servo"))
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


class ShearEngine(EngineCore):
    """State and stepping of one DEM run in a sheared periodic cell (arrays updated in place).

    Parameters
    ----------
    packing : initial packing; its cell [[Lx, xy], [0, Ly]] (a1 = (Lx, 0), a2 = (xy, Ly), |xy| <=
        Lx/2, as a LAMMPS triclinic box); the box is [0, Lx] x [0, Ly] with tilt xy unless ``box``
        is given.
    settings : :class:`~gransim.dem.settings.Integration` with a ``law``, or DEMSettings (its Hooke
        law: kn, kt, gamma_n, gamma_t, mu); dt, skin; ``mode`` must be "serial".
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    flavour : "lammps" (default) or "liggghts" (see the module docstring).
    check_dt : refuse a time step above :func:`gransim.dem.engine.stability_limit` of the law.
    box : optional (lo, hi) or (lo, hi, xy), lo and hi (2,) (m): the box with its own origin, as a
        LAMMPS data file's ``xlo xhi ylo yhi`` (and ``xy xz yz``) lines. The values are used as
        given (bit for bit, like ``DEMEngine(box=...)``) and the positions are taken as they are
        in that box (no translation, which would round them). hi - lo must equal the diagonal of
        ``packing.cell`` and xy its cell[0, 1] (to 1e-12 relative).
    law : optional contact law object (a registered law, :func:`gransim.contacts.laws.make_law`);
        None: the Hooke law of a DEMSettings in this engine's ``flavour``. The time-step check
        (``check_dt``) asks the law (:func:`gransim.dem.engine.check_time_step`).

    Attributes (after construction = LAMMPS ``run`` set-up: list built, forces without spring
    increment): x (N, 2), v, w, f, t, box (lo_x, lo_y, hi_x, hi_y, xy), h_rate (h_rate[0],
    h_rate[1], h_rate[5]), step, virial (xx, yy, xy, yx), stress (2, 2, compression positive).
    """

    def __init__(
        self,
        packing: Packing,
        settings: DEMSettings,
        velocities=None,
        spins=None,
        flavour: str = "lammps",
        check_dt: bool = True,
        box=None,
        law=None,
    ):
        check_choice(flavour, "flavour", FLAVOURS)
        if not isinstance(settings, (DEMSettings, Integration)):
            raise InputError(f"settings: expected a DEMSettings or an Integration, got {type(settings).__name__}")
        if settings.mode != "serial":
            raise InputError(f"settings.mode: the sheared cell runs the serial loop only, got {settings.mode!r}")
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
        s = settings
        self.packing = packing
        self.settings = s
        # the contact law (gransim.contacts.laws): Hooke in this engine's flavour unless given
        self._set_law(packing, s, law, flavour, check_dt)
        heights = np.array([Lx * Ly / np.hypot(Ly, xy), Ly])
        cut = 2 * (2.0 * float(packing.radii.max()) + s.skin)
        if heights.min() <= cut:
            raise InputError(
                f"packing.cell: cell heights {heights[0]:.4g}, {heights[1]:.4g} m must exceed "
                f"2 (2 r_max + skin) = {cut:.4g} m (one periodic image per pair)"
            )
        self.flavour = flavour
        self._lmp = flavour == "lammps"
        n = packing.n
        r = np.ascontiguousarray(packing.radii, np.float64)
        m = np.pi * r * r * float(packing.density)  # LAMMPS set density/disc: MY_PI*r*r*rho
        x = np.array(packing.positions, np.float64)
        v = np.zeros((n, 2)) if velocities is None else np.array(velocities, np.float64).reshape(n, 2)
        w = np.zeros(n) if spins is None else np.array(spins, np.float64).reshape(n)
        for name, a in (("positions", x), ("velocities", v), ("spins", w)):
            if not np.all(np.isfinite(a)):
                raise InputError(f"{name}: expected finite numbers")
        self.p = K.Particles(x, v, w, np.zeros((n, 2)), np.zeros(n), m, r)
        self.box = np.array([0.0, 0.0, Lx, Ly, xy]) if box is None else _check_box(box, Lx, Ly, xy)
        self.h_rate = np.zeros(3)
        self.lam = np.zeros((n, 2))
        self.step = 0
        self.virial = np.zeros(4)
        self.n_contacts = 0
        self.mean_overlap = 0.0
        self.n_rebuilds = 0
        self._build_step = 0
        self.nb = self._neighbours(
            np.zeros(0, np.int32),
            np.zeros(0, np.int32),
            np.zeros(0),
            np.zeros(0),
            np.zeros(0, np.bool_),
            np.zeros((0, self._width)),
        )
        self.touch = np.zeros(0, np.bool_)
        self.corners_hold = np.zeros((8, 2))
        self.box_hold = self.box.copy()
        self._run = None  # (begin, end, loading) of the current fix deform run
        self._rebuild(carry=False)
        self._forces(update=False, use_lam=self._lmp)
        self.stress = self.stress_tensor()
        self._check_time_step_now()

    # ------------------------------------------------------------------ geometry
    @property
    def cell(self) -> np.ndarray:
        """Current cell [[Lx, xy], [0, Ly]] (m), columns the lattice vectors."""
        b = self.box
        return np.array([[b[2] - b[0], b[4]], [0.0, b[3] - b[1]]])

    @property
    def area(self) -> float:
        b = self.box
        return float((b[2] - b[0]) * (b[3] - b[1]))

    def stress_tensor(self) -> np.ndarray:
        """Love stress sigma_ab = (1/(Lx Ly)) sum d_a f_b (compression positive, N/m), (2, 2);
        [0, 1] = sum d_x f_y is LAMMPS' ``compute pressure`` component 4 (xy)."""
        inv = 1.0 / ((self.box[2] - self.box[0]) * (self.box[3] - self.box[1]))
        v = self.virial
        return np.array([[v[0] * inv, v[2] * inv], [v[3] * inv, v[1] * inv]])

    # ------------------------------------------------------------------ neighbours
    def _rebuild(self, carry: bool):
        if self._lmp:
            SK.x2lamda(self.x, self.box, self.lam)
            bad = SK.pbc_lamda(self.lam, self.v, self.h_rate, True)
            if bad >= 0:
                raise SimulationError(
                    f"step {self.step}: particle {bad} lost (lamda {self.lam[bad].tolist()}, "
                    f"more than a cell outside the box)"
                )
            SK.lamda2x(self.lam, self.box, self.x)
        else:
            bad = K.pbc_wrap(self.x, self.box[0:2].copy(), self.box[2:4].copy())
            if bad >= 0:
                raise SimulationError(f"step {self.step}: particle {bad} lost (at {self.x[bad].tolist()})")
            SK.x2lamda(self.x, self.box, self.lam)
        a, b, sx, sy, both, selfimg = SK.build_list(self.x, self.lam, self.r, self.box, self.settings.skin, self._lmp)
        if selfimg >= 0:
            raise SimulationError(f"step {self.step}: particle {selfimg} is near its own image; the cell is too small")
        xi = np.zeros((a.size, self._width))
        if carry and self.ea.size:
            SK.hand_over(
                self.x,
                self.r,
                self.box,
                a,
                b,
                sx,
                sy,
                self.start,
                self.eb,
                self.both,
                self.xi,
                self.touch,
                self._lmp,
                xi,
                self._flip,
            )
        self.nb = self._neighbours(a, b, sx, sy, both, xi)
        self.touch = np.zeros(a.size, np.bool_)
        SK.box_corners(self.box, self.corners_hold)
        self.box_hold = self.box.copy()
        self._build_step = self.step
        self.n_rebuilds += 1

    def _neighbours(self, a, b, sx, sy, both, xi):
        """The :class:`~gransim.dem.kernels.Neighbours` of the list (a, b, s, both) with history
        ``xi``: CSR offsets of the entries of each a (sorted by a), the build positions (the
        current ones), zeroed per-entry outputs (no threaded loop here: no incoming CSR)."""
        n = self.packing.n
        start = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(a, minlength=n), out=start[1:])
        z = np.zeros(0, np.int64)
        return K.Neighbours(
            a, b, np.zeros((0, 2), np.int64), sx, sy, both, xi, start, z, z, self.x.copy(),
            np.zeros(a.size, np.bool_), np.zeros((a.size, 2)), np.zeros(0),
        )  # fmt: skip

    def _state(self):
        """The kernels' view of the state: (Particles, Neighbours, Cell)."""
        cell = SK.Cell(self.box, self.box_hold, self.h_rate, self.lam, self.touch, self.corners_hold)
        return self.p, self.nb, cell

    def _forces(self, update: bool, use_lam: bool):
        p, nb, cell = self._state()
        with disk_cache_off(self._no_cache):
            nc, so = SK.forces(p, nb, self.law, cell, use_lam, self.settings.dt, update, self.virial)
        self.n_contacts = round(nc)
        self.mean_overlap = so / nc if nc else 0.0

    def _touching(self):
        """Entries of the touching pairs, each physical contact once (a < b), and their overlaps
        (m), the images from the current box (:func:`gransim.dem.kernels.tilted_image`)."""
        b = self.box
        h0, h1, h5 = b[2] - b[0], b[3] - b[1], b[4]
        a, j = self.ea, self.eb
        dx = self.x[a, 0] - ((self.x[j, 0] + self.esx * h0) + self.esy * h5)
        dy = self.x[a, 1] - (self.x[j, 1] + self.esy * h1)
        dist = np.sqrt(dx * dx + dy * dy)
        rs = self.r[a] + self.r[j]
        e = np.nonzero((dist < rs) & (a < j))[0]
        return e, rs[e] - dist[e]

    def _budget_kinetic_energy(self) -> float:
        """Kinetic energy (J) of the velocities relative to the homogeneous flow of the cell
        (:meth:`peculiar_velocities`), which the Lees-Edwards remap of a particle crossing the
        boundary leaves unchanged (the lab-frame one jumps by m v.U + m U^2/2 there, U the flow
        across the cell, work no contact did)."""
        u = self.peculiar_velocities()
        return float(0.5 * np.sum(self.m * np.einsum("ij,ij->i", u, u)) + 0.25 * np.sum(self.m * self.r**2 * self.w**2))

    def _flow_kinetic_energy(self) -> float:
        """Kinetic energy (J) of the homogeneous flow of the cell at the particles, sum m |u(x)|^2/2
        (u of :meth:`peculiar_velocities`)."""
        u = self.v - self.peculiar_velocities()
        return float(0.5 * np.sum(self.m * np.einsum("ij,ij->i", u, u)))

    def _check_divergence(self, done, k, out_ke, out_vir, out_box, box_before):
        """The divergence check (:meth:`gransim.dem.engine.EngineCore._check_energy`) after the k
        steps from row ``done`` of the outputs: every step's kinetic energy finite; the kinetic
        energy relative to the flow, known at the last of them, within the budget (which counts
        the kinetic energy of the flow at the particles too, :meth:`_flow_kinetic_energy`); the work of the
        cell per step -(V_xx dLx/Lx + V_yy dLy/Ly + V_yx (dxy - xy dLx/Lx)/Ly) (V the virial of
        the step, N m; the velocity gradient of the box change dH H^-1, H = [[Lx, xy], [0, Ly]])."""
        rows = slice(done, done + k)
        b1 = out_box[rows]  # lx, ly, xy, ylo, yhi after each step
        b0 = np.vstack([[box_before[2] - box_before[0], box_before[3] - box_before[1], box_before[4]], b1[:-1, :3]])
        dlx = (b1[:, 0] - b0[:, 0]) / b0[:, 0]
        dly = (b1[:, 1] - b0[:, 1]) / b0[:, 1]
        dxy = (b1[:, 2] - b0[:, 2] - b0[:, 2] * dlx) / b0[:, 1]
        vir = out_vir[rows]
        dw = -(vir[:, 0] * dlx + vir[:, 1] * dly + vir[:, 3] * dxy)
        ke = np.full(k, np.nan)
        ke[-1] = self._budget_kinetic_energy()
        self._check_energy(self.step + 1, out_ke[rows], ke, dw, flow=self._flow_kinetic_energy())

    # ------------------------------------------------------------------ stepping
    def start_run(self, loading: ShearLoading, nsteps: int):
        """Begin a LAMMPS ``run nsteps`` under ``loading``: ``fix deform`` init (the start and stop
        tilt of the style over the run, see :class:`ShearLoading`; h_rate[5] = (tilt_stop -
        tilt_start) / (nsteps dt) for the linear styles, 0 for trate until its first change;
        h_rate[1] = 0 until the first servo change), then the run's set-up evaluation
        (``Verlet::setup``). Returns the set-up stress (2, 2), LAMMPS' thermo at the first step of
        the run.

        Raises InputError for a trate on a cell without tilt (LAMMPS: "Cannot use fix deform trate
        on a box with zero tilt") and for a moving box with ``flavour="liggghts"``.
        """
        if not isinstance(loading, ShearLoading):
            raise InputError(f"loading: expected a ShearLoading, got {type(loading).__name__}")
        nsteps = as_int(nsteps, "nsteps", 1)
        if self.flavour == "liggghts" and (loading.moves_tilt or loading.y != "fixed"):
            raise InputError("flavour 'liggghts': only a fixed box (xy erate 0, y fixed) is supported")
        s = self.settings
        begin = self.step
        end = begin + nsteps
        delt = float(end - begin) * s.dt
        b = self.box
        tilt_start = float(b[4])
        if loading.xy == "trate" and tilt_start == 0.0:
            raise InputError(
                "loading: xy trate on a cell without tilt (the tilt grows as xy0 exp(rate t); "
                "LAMMPS stops too: 'Cannot use fix deform trate on a box with zero tilt')"
            )
        stop = tilt_stop(loading.xy, loading.value, tilt_start, float(b[3] - b[1]), delt)
        self.h_rate[:] = 0.0
        if not loading.moves_tilt:
            style = SK.XY_NONE
        elif loading.xy == "trate":
            style = SK.XY_TRATE
        else:
            style = SK.XY_LINEAR
            self.h_rate[2] = (stop - tilt_start) / delt
        self._run = {
            "begin": begin,
            "end": end,
            "loading": loading,
            "style": style,
            "tilt_start": tilt_start,
            "tilt_stop": stop,
            "y_lo": float(b[1]),
            "y_hi": float(b[3]),
            "ly0": float(b[3] - b[1]),
        }
        # Verlet::setup after fix deform init: wrap (with this run's h_rate), list build with the
        # springs handed over, forces without spring increment (images see the run's h_rate)
        self._rebuild(carry=True)
        self._forces(update=False, use_lam=self._lmp)
        self.stress = self.stress_tensor()
        self._reset_energy_budget()  # the divergence check's balance starts with the run
        return self.stress.copy()

    def advance(self, nsteps: int) -> dict:
        """Advance ``nsteps`` steps of the current run (:meth:`start_run`); returns per-step series.

        Returns
        -------
        dict with ``step`` (n,), ``stress`` (n, 2, 2) (compression positive, N/m; virial / area of
        the box after the step), ``virial`` (n, 4) (xx, yy, xy, yx: sum 0.5 d (x) f of the step
        over the half list, N m; stress times the area, LAMMPS' ``virial`` before ``compute
        pressure`` divides it), ``box`` (n, 5) (lx, ly, xy, ylo, yhi; m), ``n_contacts`` (n,),
        ``mean_overlap`` (n,) (m), ``kinetic_energy`` (n,) (J, of the full velocities).

        Raises
        ------
        InputError when no run was started or the run would be passed. SimulationError naming the
        step on a non-finite position, a lost particle, a collapsed cell or a tilt beyond Lx/2.
        """
        if self._run is None:
            raise InputError("advance: call start_run(loading, nsteps) first (the fix deform of the run)")
        run = self._run
        nsteps = as_int(
            nsteps,
            "nsteps",
            0,
            run["end"] - self.step,
            note=f" (the run ends at step {run['end']}, now at step {self.step})",
        )
        s = self.settings
        ld = run["loading"]
        out_stress = np.zeros((nsteps, 4))
        out_vir = np.zeros((nsteps, 4))
        out_box = np.zeros((nsteps, 5))
        out_nc = np.zeros(nsteps)
        out_ov = np.zeros(nsteps)
        out_ke = np.zeros(nsteps)
        step_start = self.step
        done = 0
        resume = False
        dfm = SK.Deform(
            int(run["begin"]),
            int(run["end"]),
            int(ld.every),
            int(run["style"]),
            float(run["tilt_start"]),
            float(run["tilt_stop"]),
            float(ld.value),
            ld.y == "servo",
            float(run["y_lo"]),
            float(run["y_hi"]),
            float(run["ly0"]),
            s.dt * ld.gain,
            float(ld.gain),
            float(ld.target),
        )
        while done < nsteps:
            box_before = self.box.copy()
            p, nb, cell = self._state()
            series = SK.ShearSeries(
                out_stress[done:], out_vir[done:], out_box[done:], out_nc[done:], out_ov[done:], out_ke[done:]
            )
            with disk_cache_off(self._no_cache):
                k, status, bad = SK.run_block(
                    p,
                    nb,
                    self.law,
                    cell,
                    dfm,
                    series,
                    self.virial,
                    s.dt,
                    s.skin,
                    self._lmp,
                    self.step,
                    nsteps - done,
                    resume,
                )
            if k:
                self._check_divergence(done, k, out_ke, out_vir, out_box, box_before)
            done += k
            self.step += k
            resume = False
            if status == 1:
                self._check_lost()
                self.step += 1
                self._rebuild(carry=True)
                self.step -= 1
                resume = True
            elif status == 2:
                raise SimulationError(
                    f"step {self.step + 1}: particle {bad} has a non-finite position "
                    f"{self.x[bad].tolist()} (velocity {self.v[bad].tolist()})"
                )
            elif status == 3:
                raise SimulationError(
                    f"step {self.step + 1}: the cell collapsed or its tilt passed Lx/2 "
                    f"(box {self.box.tolist()}; LAMMPS would flip the box, not supported)"
                )
            if done < nsteps and k == 0 and not resume:
                raise SimulationError(f"step {self.step + 1}: no progress")  # pragma: no cover
        if nsteps:
            self.n_contacts = round(out_nc[-1])
            self.mean_overlap = float(out_ov[-1])
            self.stress = self.stress_tensor()
        st = np.empty((nsteps, 2, 2))
        st[:, 0, 0] = out_stress[:, 0]
        st[:, 1, 1] = out_stress[:, 1]
        st[:, 0, 1] = out_stress[:, 2]
        st[:, 1, 0] = out_stress[:, 3]
        return {
            "step": np.arange(step_start + 1, step_start + nsteps + 1),
            "stress": st,
            "virial": out_vir,
            "box": out_box,
            "n_contacts": np.rint(out_nc).astype(np.int64),
            "mean_overlap": out_ov,
            "kinetic_energy": out_ke,
        }

    # ------------------------------------------------------------------ diagnostics
    def peculiar_velocities(self) -> np.ndarray:
        """v - u(x) (m/s), (N, 2): u the homogeneous flow of the cell, u_x = h_rate[5] (y - ylo)/Ly,
        u_y = h_rate[1] (y - ylo)/Ly (continuous across the Lees-Edwards boundary)."""
        b = self.box
        f = (self.x[:, 1] - b[1]) / (b[3] - b[1])
        return self.v - np.stack([self.h_rate[2] * f, self.h_rate[1] * f], axis=1)


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
        the provenance (absent for the default Hooke law, whose run files stay as they were).

    Returns a summary dict (steps, shear strain reached, final stresses tension positive, builds).
    A SimulationError is re-raised after the file was written with ``complete`` False and the
    message as ``stop_reason``. Stresses in the file are tension positive (the engine's are
    compression positive: ``sigma_file = -stress``).
    """
    nsteps = as_int(nsteps, "nsteps", 1)
    series_every = as_int(series_every, "series_every", 1)
    snapshot_every = as_int(snapshot_every, "snapshot_every", 0)
    eng = ShearEngine(packing, settings, flavour=flavour, law=law)
    ly0, xy0 = float(eng.box[3] - eng.box[1]), float(eng.box[4])
    setup = eng.start_run(loading, nsteps)
    rows = {k: [] for k in ("step", "box", "stress", "n_contacts", "kinetic_energy")}

    def row(step, box, stress, nc, ke):
        rows["step"].append(step)
        rows["box"].append(box)
        rows["stress"].append(-np.asarray(stress))
        rows["n_contacts"].append(nc)
        rows["kinetic_energy"].append(ke)

    b = eng.box
    row(0, [b[2] - b[0], b[3] - b[1], b[4], b[1], b[3]], setup, eng.n_contacts, eng.kinetic_energy())
    snaps = {}

    def snap():
        snaps[eng.step] = {
            "positions": eng.x.copy(),
            "velocities": eng.v.copy(),
            "spins": eng.w.copy(),
            "cell": eng.cell,
            "box_lo": eng.box[0:2].copy(),
        }

    snap()
    stops = set(range(series_every, nsteps + 1, series_every)) | {nsteps}
    if snapshot_every:
        stops |= set(range(snapshot_every, nsteps + 1, snapshot_every))
    stops = sorted(stops)
    reason = ""
    interrupted = None
    bar = progress(total=nsteps, desc="shear") if show_progress else None
    try:
        # SIGINT / SIGTERM are acted on between two series rows (gransim.progress): the file is
        # then written with the rows so far, complete = False
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
            check_interrupt()
    except SimulationError as exc:
        reason = str(exc)
    except KeyboardInterrupt as exc:
        interrupted = exc
        how = exc.signal_name if isinstance(exc, Interrupted) else "SIGINT"
        reason = f"interrupted by {how} at step {eng.step} of {nsteps} (a shear run has no resume: rerun it)"
    finally:
        if bar is not None:
            bar.close()
    box = np.array(rows["box"], np.float64).reshape(-1, 5)
    strain = (box[:, 2] - xy0) / ly0
    info = {"dem": settings.to_dict(), "loading": loading.to_dict(), "nsteps": nsteps, "flavour": flavour}
    if law is not None:
        info["law"] = dict(law_options) if law_options else {"name": type(law).__name__, "params": dict(law._asdict())}
    text = json.dumps(info, sort_keys=True)
    params = {**info, **(parameters or {})}
    with atomic_h5(
        out_path, kind=SHEAR_RUN_KIND, parameters=params, seed=packing.metadata.get("seed"), lammps=False
    ) as f:
        f.attrs["settings"] = text
        f.attrs["n_particles"] = packing.n
        f.attrs["nsteps"] = nsteps
        f.attrs["complete"] = not reason
        f.attrs["stop_reason"] = reason
        f.attrs["stress_sign"] = "tension positive"
        f.attrs["shear_strain_reached"] = float(strain[-1])
        write_packing_group(f.create_group("packing"), packing)
        g = f.create_group("series")
        g["step"] = np.array(rows["step"], np.int64)
        g["time"] = g["step"][()] * settings.dt
        g["box"] = box
        g["shear_strain"] = strain
        g["stress"] = np.array(rows["stress"], np.float64).reshape(-1, 2, 2)
        g["n_contacts"] = np.array(rows["n_contacts"], np.int64)
        g["kinetic_energy"] = np.array(rows["kinetic_energy"], np.float64)
        sg = f.create_group("snapshots")
        for step, d in snaps.items():
            h = sg.create_group(str(step))
            h.attrs["step"] = step
            for k, v in d.items():
                h[k] = v
    if interrupted is not None:
        raise Interrupted(
            getattr(interrupted, "signum", 2), f"{out_path}: {reason} (an incomplete run file, complete = False)"
        ) from None
    if reason:
        raise SimulationError(f"{reason} (the run file {out_path} holds the steps before, complete = False)")
    last = rows["stress"][-1]
    return {
        "steps": nsteps,
        "shear_strain": float(strain[-1]),
        "sigma_xy": float(last[0][1]),
        "sigma_yy": float(last[1][1]),
        "sigma_xx": float(last[0][0]),
        "ly": float(box[-1, 1]),
        "n_rebuilds": int(eng.n_rebuilds),
    }


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
