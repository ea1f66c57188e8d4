"""The fast ordering of the DEM: the physics of :class:`gransim.dem.engine.Engine` (its orthogonal
cell and its sheared cell under any upper-triangular velocity gradient, ``remap v`` with
Lees-Edwards images or ``remap x``) with any registered contact law that offers a branch-free
block path, in an order chosen for speed, not for bitwise agreement with LIGGGHTS or
LAMMPS (docs/performance.md).

What is reordered, and what it changes:

* the particles are sorted by bin (row-major bins at least a neighbour cut-off wide, in the cell's
  lamda coordinates) at every list build, the velocities, spins and the particles' history going
  along (``perm`` maps back: every public view is in the original particle order);
* structure-of-arrays particle state (x, y, vx, vy, w, ... each (N,)), int32 indices, a uint8
  image code per entry, the law's history (width 2: the spring) in float64;
* a half list, each pair once (i < j in the sorted order; LIGGGHTS keeps the pairs across the
  boundary twice, LAMMPS' sheared cell too), with the symmetric update (j gets minus the force on
  i and its torque);
* the contact law's block path (``LawSpec.select``, :func:`gransim.contacts.laws.pair_select`:
  the same function the code order's SIMD loops run), every entry evaluated and masked;
* one fused pass per step: second half step, box remap (per axis, or through lamda in the
  sheared cell with ``remap x``), first half step of the next step, position update, rebuild test
  and forces zeroed;
* the list rebuilt in place into buffers that are reused and grown only when needed; at a
  rebuild the old list survives only as the compact table of its non-zero springs (the
  history hand-over);
* threads: bands of bin rows, many more than the threads, handed out dynamically (numba's
  dynamic scheduling with chunk size 1, :func:`dynamic_chunks`), even bands then odd bands so no
  two threads write the same particle. Sums have a fixed order: the results are the same bit for
  bit on 1 and 2 threads (and under any scheduling).

Only summation orders differ from the code order: the two agree to round-off over short
horizons, and over long ones the fast ordering stays within the divergence envelope of the code
order itself (tests/dem/test_fast.py, test_fast_backend.py).

What is the code order's, unchanged: the step (nve/sphere), the box of every step (the loadings
of :class:`~gransim.dem.Loading` with fixed, rate and servo axes through
:func:`gransim.dem.kernels.box_target`, a :class:`~gransim.dem.PrescribedBox`, or the sheared
cell's ``fix deform``, begun by :meth:`gransim.dem.sheared.ShearedCell.start_run` and stepped by
:func:`gransim.dem.sheared_kernels.deform_end_of_step`), the
rebuild rule of the flavour (``DEMSettings.flavour``: LAMMPS clamps a negative margin at zero,
LIGGGHTS squares it; the sheared cell in LAMMPS' arithmetic takes the margin from the 8 box
corners), the hand-over of the springs (pairs that overlap at the build keep a spring that is not
zero: LIGGGHTS' rule, and LAMMPS', whose laws zero the spring of a pair that stops touching), the
checks of :class:`gransim.dem.engine.Engine` (divergence, lost particles) and its energies.

Not offered: laws without a block path (Hertz, the rolling laws: their history is wider than the
spring, or their pair has branches), which the code order runs (InputError names them).
"""

from __future__ import annotations

import contextlib
import json
import math

import numpy as np

from .._numba import check_threads, disk_cache_off, dynamic_chunks, num_threads
from .._validate import as_int, check_choice
from ..contacts.laws import elastic_energy, offers_select
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import fast_kernels as FK
from . import sheared_kernels as SK
from .engine import ENERGY_CHUNK, LOST_DISPLACEMENT_SKINS, Engine, _control
from .settings import DEMSettings, Integration, Loading, PrescribedBox
from .sheared import _RUN_NUMBERS, ShearedCell, ShearLoading, _ShearRun, deform_of

#: the cells of the fast ordering
CELLS = ("orthogonal", "sheared")

#: bands of bin rows wanted per list build (the chunks of the threaded loops; fixed by N, not by
#: the thread count, so that results do not depend on the threads)
TARGET_BANDS = 64

#: the threaded kernels run only with at least this many particles per thread (below, a step is
#: too short for the start-up and the end barriers of the parallel regions: with the SIMD kernels
#: 2 threads on 10,058 disks ran at 0.92x of one thread, quiet machine); the results do not
#: depend on it (the serial and the threaded kernels sum in the same order)
MIN_PER_THREAD = 20000

#: growth factor of the list buffers when a build needs more room than they have
GROWTH = 1.25

#: the threaded list build gives each band room for its particles times the last list's entries
#: per particle times BAND_SLACK, plus BAND_PAD entries; a band that needs more sends the build to
#: the count and fill passes
BAND_SLACK = 1.05
BAND_PAD = 64


class _RunHolder:
    """Where :meth:`gransim.dem.sheared.ShearedCell.start_run` keeps the run it begins (its ``run``)."""

    run = None


def _series(out: np.ndarray, first: int) -> dict:
    """The per-step series both cells return (``Engine.advance``'s keys) from the step loop's rows
    ``out`` (n, >= 9): virial xx, yy, xy, yx, contacts, overlap sum, kinetic energy, then the box
    (Lx, Ly first); ``first`` the step before the first row."""
    n = out.shape[0]
    area = out[:, 7] * out[:, 8]
    st = np.empty((n, 2, 2))
    st[:, 0, 0] = out[:, 0] / area
    st[:, 1, 1] = out[:, 1] / area
    st[:, 0, 1] = out[:, 2] / area
    st[:, 1, 0] = out[:, 3] / area
    nc = out[:, 4]
    return {
        "step": np.arange(first + 1, first + n + 1),
        "stress": st,
        "virial": out[:, :4].copy(),
        "n_contacts": np.rint(nc).astype(np.int64),
        "mean_overlap": np.divide(out[:, 5], nc, out=np.zeros(n), where=nc > 0),
        "kinetic_energy": out[:, 6].copy(),
    }


class FastEngine:
    """State and stepping of a DEM run in the fast ordering (module docstring).

    Parameters
    ----------
    packing : initial packing. ``cell="orthogonal"``: an orthogonal cell, the box [0, Lx] x
        [0, Ly]; ``cell="sheared"``: a cell [[Lx, xy], [0, Ly]] with |xy| <= Lx/2 (LAMMPS'
        triclinic box), the box [0, Lx] x [0, Ly] with tilt xy.
    settings : :class:`~gransim.dem.DEMSettings` (the integration and its Hooke law) or
        :class:`~gransim.dem.Integration` with ``law``; dt, skin, flavour ("liggghts" or
        "lammps": the rebuild rule, and the Hooke law of a DEMSettings); ``mode`` is not used
        (``threads`` decides).
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    threads : 1 (one thread) or more (the threaded kernels on that many numba threads, set around
        each call and restored; with fewer than :data:`MIN_PER_THREAD` particles per thread one
        thread runs, with the same result bit for bit).
    check_dt : refuse a time step above the law's stability limit
        (:func:`gransim.dem.engine.check_time_step`).
    law : a registered contact law that offers a block path (``LawSpec.select``: the Hooke laws
        ``hooke-liggghts``, ``hooke-lammps``); None: the Hooke law of a DEMSettings in its flavour.
    cell : "orthogonal" or "sheared" (the cells of :class:`gransim.dem.engine.Engine`:
        :meth:`start_run` and :meth:`advance` as there).

    After construction (the codes' ``run`` set-up: first list build, forces without spring
    increment) :meth:`advance` steps the state. Views (x, v, w, f, t, m, r, contacts(), ...) are
    in the original particle order; :meth:`state_arrays` / :meth:`restore` save and load the state
    (sorted order) so that a restored run continues bit for bit.
    """

    # what every ordering does the same way, the code order's own functions: the law and its
    # time-step check, the kinetic energy, the energy balance of the divergence check
    _set_law = Engine._set_law
    _check_time_step_now = Engine._check_time_step_now
    kinetic_energy = Engine.kinetic_energy
    _reset_energy_budget = Engine._reset_energy_budget
    _check_energy = Engine._check_energy

    def __init__(
        self,
        packing: Packing,
        settings,
        velocities=None,
        spins=None,
        threads: int = 1,
        check_dt: bool = True,
        law=None,
        cell: str = "orthogonal",
    ):
        if not isinstance(packing, Packing):
            raise InputError(f"packing: expected a gransim Packing, got {type(packing).__name__}")
        if not isinstance(settings, (DEMSettings, Integration)):
            raise InputError(f"settings: expected a DEMSettings or an Integration, got {type(settings).__name__}")
        check_choice(cell, "cell", CELLS)
        self._sheared = cell == "sheared"
        C = np.asarray(packing.cell, np.float64)
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        if self._sheared:
            if C[1, 0] != 0.0:
                raise InputError(
                    f"packing.cell: a LAMMPS triclinic cell has a1 = (Lx, 0): cell[1, 0] must be 0, got {C[1, 0]!r}"
                )
            if abs(xy) > 0.5 * Lx:
                raise InputError(
                    f"packing.cell: tilt xy = {xy!r} m beyond Lx/2 = {0.5 * Lx!r} m (LAMMPS needs |xy| <= Lx/2)"
                )
        elif xy != 0.0 or C[1, 0] != 0.0:
            raise InputError(
                f"packing.cell: cell 'orthogonal' needs an orthogonal cell (off-diagonal entries {xy!r}, "
                f"{C[1, 0]!r}); a tilted cell runs with cell='sheared'"
            )
        s = self.settings = settings
        self.packing = packing
        self.flavour = s.flavour
        self._lmp = s.flavour == "lammps"
        if self._sheared and not self._lmp and xy != 0.0:
            raise InputError(
                f"flavour 'liggghts': needs a cell without tilt (LIGGGHTS' bookkeeping is orthogonal), got xy = {xy!r}"
            )
        # the contact law (gransim.contacts.laws), its time step checked (Engine._set_law)
        self._set_law(packing, s, law, s.flavour, check_dt)
        if not offers_select(type(self.law)):
            raise InputError(
                f"law: the fast ordering runs laws that offer a branch-free block path (LawSpec.select: "
                f"the Hooke laws), got {type(self.law).__name__}; run it in the code's order"
            )
        t = check_threads(threads)
        self._threads = 1 if t is None else t
        n = self.n = packing.n
        self._parallel = self._threads > 1 and n >= MIN_PER_THREAD * self._threads
        self._clamp = self._lmp  # the rebuild rule of LAMMPS (kernels.rebuild_deltasq)
        self._cut = 2.0 * float(packing.radii.max()) + s.skin
        heights = (Lx * Ly / math.hypot(Ly, xy), Ly)
        if min(heights) < 3.0 * self._cut:
            raise InputError(
                f"packing.cell: cell heights {heights[0]:.4g}, {heights[1]:.4g} m must be at least "
                f"3 (2 r_max + skin) = {3 * self._cut:.4g} m (three bins per axis)"
            )
        f64 = np.float64
        pos = np.asarray(packing.positions, f64)
        if velocities is None:
            vel = np.zeros((n, 2))
        else:
            vel = np.asarray(velocities, f64)
            if vel.shape != (n, 2):
                raise InputError(f"velocities: expected shape ({n}, 2) (m/s), got {vel.shape}")
        if spins is None:
            w = np.zeros(n)
        else:
            w = np.array(spins, f64)
            if w.shape != (n,):
                raise InputError(f"spins: expected shape ({n},) (rad/s), got {w.shape}")
        for name, a in (("positions", pos), ("velocities", vel), ("spins", w)):
            if not np.all(np.isfinite(a)):
                raise InputError(f"{name}: expected finite numbers")
        # the radii and masses in the original order are the packing's (not held twice: 16 MB at
        # 1e6 disks); the sorted ones are gathered from them
        r = self._radii0()
        self.ps = FK.FastParticles(
            pos[:, 0].copy(), pos[:, 1].copy(), vel[:, 0].copy(), vel[:, 1].copy(), w,
            np.zeros(n), np.zeros(n), np.zeros(n), self._masses0(r), r.copy(), np.zeros(n), np.zeros(n),
        )  # fmt: skip
        self.perm = np.arange(n, dtype=np.int32)
        if self._sheared:
            self.box = np.array([0.0, 0.0, Lx, Ly, xy])
            self.h_rate = np.zeros(3)
            self._cell = FK.ShearCell(self.box, self.box.copy(), self.h_rate, np.zeros((8, 2)))
            self._run = None  # the fix deform of the current run (start_run)
        else:
            self.lo = np.zeros(2)
            self.hi = np.array([Lx, Ly], f64)
            self._cell = FK.OrthoCell(self.lo, self.hi, self.lo.copy(), self.hi.copy())
            self._run = None  # (loading, begin step, end step, (lo, hi) at the begin) of start_run
        # rebuild scratch (reused): new order, bin keys, permutation buffers
        self._order = np.zeros(n, np.int32)
        self._key = np.zeros(n, np.int32)
        self._tmpf = np.zeros(n)
        self._tmpi = np.zeros(n, np.int32)
        self._cnt = np.zeros(n, np.int32)
        self._start = np.zeros(n + 1, np.int32)
        self._binstart = np.zeros(1, np.int32)
        # the list (capacity grows) and the hand-over table
        self._ni = np.zeros(0, np.int32)
        self._nj = np.zeros(0, np.int32)
        self._code = np.zeros(0, np.uint8)
        self._hist = np.zeros((2, 0))  # rows: the two spring components (h0, h1 of fast_kernels)
        self._hstart = np.zeros(n + 1, np.int32)
        self._hj = np.zeros(0, np.int32)
        self._hh = np.zeros((0, 2))
        self._sp_j = np.zeros(0, np.int32)
        self._sp_f = np.zeros((0, 3))
        self.n_entries = 0
        self.step = 0
        self.n_rebuilds = 0
        self.n_banded_builds = 0  # threaded builds done in one pass per band (the others: count and fill)
        self._build_step = 0
        self.virial = np.zeros(4)
        self.n_contacts = 0
        self.mean_overlap = 0.0
        self._rows = max(1, round(math.floor(Ly / self._cut) / TARGET_BANDS))
        self._rebuild(carry=False)
        self._forces(update=False)
        self._check_time_step_now()
        self._reset_energy_budget()

    # ------------------------------------------------------------------ internals
    @contextlib.contextmanager
    def _kernels(self):
        # the force kernel is a parallel one even when serial (fast_kernels.forces_v): one thread;
        # the kernels of a law of a test module or script stay out of the disk cache
        with num_threads(self._threads if self._parallel else 1), dynamic_chunks(1), disk_cache_off(self._no_cache):
            yield

    def _list(self):
        return FK.FastList(self._cstart, self._start, self._ni, self._nj, self._code, self._hist[0], self._hist[1])

    def _image(self):
        """The image plug-in of the force loop for the current box."""
        if self._sheared:
            b = self.box
            hr = self.h_rate
            return (float(b[2] - b[0]), float(b[3] - b[1]), float(b[4]), float(hr[2]), float(hr[1]), float(hr[0]))
        return (float(self.hi[0] - self.lo[0]), float(self.hi[1] - self.lo[1]))

    def _forces(self, update: bool):
        """The forces of the current state (``update`` False: the set-up evaluation of a run,
        springs not incremented): virial, contacts, mean overlap and stress. (The images from
        the positions; the code order's sheared cell takes them from the lamda coordinates after
        a build: round-off.)"""
        p = self.ps
        for a in (p.fx, p.fy, p.t):
            a[:] = 0.0
        with self._kernels():
            FK.forces_v(
                self._parallel, self._cstart, self._start, self._ni, self._nj, self._code, self._hist[0],
                self._hist[1], p.x, p.y, p.vx, p.vy, p.w, p.r, p.m, p.fx, p.fy, p.t, self._image(), self.law,
                self.settings.dt, update, self._sp_start, *self._spill(), self._acc,
            )  # fmt: skip
        tot = np.zeros(6)
        for c in range(self._acc.shape[0]):  # the band order of run_steps
            tot += self._acc[c]
        self.virial[:] = tot[:4]
        self.n_contacts = round(float(tot[4]))
        self.mean_overlap = float(tot[5] / tot[4]) if tot[4] else 0.0
        self.stress = self.stress_tensor()

    def _box_corners(self):
        """(lo (2,), hi (2,), xy) of the current box."""
        if self._sheared:
            b = self.box
            return b[0:2], b[2:4], float(b[4])
        return self.lo, self.hi, 0.0

    def _rebuild(self, carry: bool):
        """Wrap (a sheared cell: with the Lees-Edwards velocity jump), sort by bin (state and
        history permuted), new list in place, springs handed over for the pairs that touch now (as
        the code order)."""
        n = self.n
        p = self.ps
        lo, hi, xy = self._box_corners()
        if self._sheared:
            bad = FK.wrap_tilted(p.x, p.y, p.vx, p.vy, self.box, self.h_rate, True)
        else:
            bad = FK.wrap(p.x, p.y, lo, hi)
        if bad >= 0:
            raise SimulationError(
                f"step {self.step}: particle {int(self.perm[bad])} lost (at "
                f"{[p.x[bad], p.y[bad]]}, box {lo.tolist()}..{hi.tolist()}, tilt {xy})"
            )
        L = hi - lo
        # bins at least a cut-off wide across: along x the distance between the lamda_x lines,
        # Lx Ly/|a2| (a2 = (xy, Ly)); the orthogonal cell's plain Lx // cut
        wide = L[0] * L[1] / math.hypot(L[1], xy) if xy else L[0]
        nbx, nby = int(wide // self._cut), int(L[1] // self._cut)
        if min(nbx, nby) < 3:
            raise SimulationError(
                f"step {self.step}: the box {L.tolist()} m (tilt {xy} m) holds fewer than 3 bins of the "
                f"cut-off {self._cut:.4g} m per axis"
            )
        if self._binstart.size < nbx * nby + 1:
            self._binstart = np.zeros(nbx * nby + 1, np.int32)
        binstart = self._binstart[: nbx * nby + 1]
        FK.bin_sort(p.x, p.y, lo, hi, xy, nbx, nby, self._order, binstart, self._key)
        # hand-over table of the current list (old order; on the threads by the old list's bands)
        if carry and self.n_entries:
            h0, h1 = self._hist
            if self._parallel:
                bcount = np.zeros(self._cstart.size - 1, np.int64)
                with self._kernels():
                    FK.history_counts(self._cstart, self._start, h0, h1, bcount)
                k = int(bcount.sum())
            else:
                k = FK.count_history(self._start, h0, h1, n)
            if self._hj.size < k:
                cap = int(k * GROWTH) + 16
                self._hj, self._hh = np.zeros(cap, np.int32), np.zeros((cap, 2))
            h = (self._hstart, self._hj, self._hh)
            if self._parallel:
                with self._kernels():
                    FK.compact_history_banded(self._cstart, self._start, self._nj, h0, h1, bcount, *h)
            else:
                FK.compact_history(self._start, self._nj, h0, h1, n, *h)
        else:
            self._hstart[:] = 0
        # entries per particle of each band of the last list (the threaded build sizes its regions
        # with them: the first band also holds the pairs across the periodic y boundary)
        per_band = None
        if self._parallel and self.n_entries:
            per_band = np.diff(self._start[self._cstart]) / np.maximum(np.diff(self._cstart), 1)
        o = self._order
        # each array gathered into the scratch, which then takes its place (one pass, not a gather
        # and a copy back); serial also on threads: seven short parallel regions cost more than
        # they saved (measured)
        new = {}
        for name in ("x", "y", "vx", "vy", "w", "r", "m"):  # f, t are zero here
            a = getattr(p, name)
            FK.gather_f(a, o, self._tmpf)
            new[name] = self._tmpf
            self._tmpf = a
        self.ps = p = p._replace(**new)
        FK.permute_i(self.perm, o, self._tmpi)
        rows = self._rows
        nb = -(-nby // rows)
        self._cstart = np.ascontiguousarray(binstart[np.minimum(np.arange(nb + 1) * rows, nby) * nbx], np.int32)
        self._sp_start = np.zeros(nb + 1, np.int64)
        sp_cnt = np.zeros(nb, np.int64)
        self._acc = np.zeros((nb, 6))
        self._red = np.zeros((nb, 3))
        pairs = FK.pairs_parallel if self._parallel else FK.pairs_serial
        args = (self._cstart, binstart, p.x, p.y, p.r, lo, hi, xy, nbx, nby, self.settings.skin, self._cnt, self._start)

        def tail():  # the list buffers (replaced when they grow) and the hand-over table
            return (self._ni, self._nj, self._code, *self._hist, sp_cnt, o, self._hstart, self._hj, self._hh)

        m = -1
        if not self._parallel:  # one pass into the buffers as they are; -1: too small
            m = FK.pairs_direct(*args[:-2], self._start, *tail())
        elif per_band is not None:
            # one pass per band on the threads, each band into a region sized from the last list's
            # entries per particle of that band (of the whole list when the bands changed) times
            # BAND_SLACK plus BAND_PAD, then the bands moved together; a band that does not fit
            # sends the whole build to the count and fill passes below
            per = per_band if per_band.size == nb else np.full(nb, self.n_entries / n)
            cap = (np.diff(self._cstart) * (per * BAND_SLACK)).astype(np.int64) + BAND_PAD
            base = np.zeros(nb + 1, np.int64)
            np.cumsum(cap, out=base[1:])
            if self._nj.size < base[-1]:
                self._grow(int(base[-1] * GROWTH) + 16)
            used = np.zeros(nb, np.int64)
            with self._kernels():
                FK.pairs_banded(*args[:-2], self._start, *tail(), base, used)
            if used.min() >= 0:
                m = FK.close_gaps(self._cstart, base, used, self._start, self._ni, self._nj, self._code, *self._hist)
                self.n_banded_builds += 1
        if m < 0:
            with self._kernels():
                pairs(0, *args, *tail())  # count
                m = FK.prefix(self._cnt, self._start)
                if self._nj.size < m:
                    self._grow(int(m * GROWTH) + 16)
                pairs(1, *args, *tail())  # fill
        np.cumsum(sp_cnt, out=self._sp_start[1:])
        self._size_spill()
        self.n_entries = int(m)
        p.xh[:] = p.x
        p.yh[:] = p.y
        self._hold()
        self._build_step = self.step
        self.n_rebuilds += 1

    def _hold(self):
        """The box at this list build (the rebuild test measures the box's motion from it)."""
        c = self._cell
        if self._sheared:
            c.box_hold[:] = self.box
            SK.box_corners(self.box, c.corners_hold)
        else:
            c.lo_hold[:] = self.lo
            c.hi_hold[:] = self.hi

    def _size_spill(self):
        ns = int(self._sp_start[-1])
        if self._sp_j.size < ns:
            cap = int(ns * GROWTH) + 16
            self._sp_j, self._sp_f = np.zeros(cap, np.int32), np.zeros((cap, 3))
        self._nspill = ns

    def _grow(self, cap: int):
        """New list buffers of ``cap`` entries (the old list is not needed any more: its springs
        are in the hand-over table). The old buffers are released first, so the two never
        coexist (the peak memory of a build that grows the list)."""
        self._ni = self._nj = self._code = self._hist = None
        self._ni = np.zeros(cap, np.int32)
        self._nj = np.zeros(cap, np.int32)
        self._code = np.zeros(cap, np.uint8)
        self._hist = np.zeros((2, cap))

    def _spill(self):
        return self._sp_j[: self._nspill], self._sp_f[: self._nspill]

    # ------------------------------------------------------------------ stepping
    def _steps(self, ctl, nsteps: int, check) -> np.ndarray:
        """``nsteps`` steps under the loading ``ctl`` (the cell's: kernels.Control or
        sheared_kernels.Deform), list rebuilds in between; ``check(out, done, k, box_before)``
        runs the divergence check after each block of k steps. Returns the rows of
        :func:`fast_kernels.run_steps` ((nsteps, OUT_COLUMNS))."""
        s = self.settings
        out = np.zeros((nsteps, FK.OUT_COLUMNS))
        done, resume = 0, False
        while done < nsteps:
            before = self.box.copy() if self._sheared else (self.hi - self.lo)
            sp_j, sp_f = self._spill()
            with self._kernels():
                k, status, bad = FK.run_steps(
                    self._parallel, self.ps, self._list(), self._cell, ctl, self.law, s.dt, s.skin, self._clamp,
                    FK.FastScratch(self._sp_start, sp_j, sp_f, self._acc, self._red), out[done:], self.step,
                    nsteps - done, resume, True,
                )  # fmt: skip
            if k:
                check(out, done, k, before)
            done += k
            self.step += k
            resume = False
            if status == 1:
                self._check_lost()
                self.step += 1  # the build belongs to the next step (the messages name it)
                self._rebuild(carry=True)
                self.step -= 1
                resume = True
            elif status == 2:
                i = int(self.perm[bad])
                raise SimulationError(
                    f"step {self.step + 1}: particle {i} has a non-finite position "
                    f"{[self.ps.x[bad], self.ps.y[bad]]} (velocity {[self.ps.vx[bad], self.ps.vy[bad]]})"
                )
            elif status == 3:
                what = (
                    f"the cell collapsed or its tilt passed Lx/2 (box {self.box.tolist()}; LAMMPS would flip "
                    "the box, not supported)"
                    if self._sheared
                    else "the cell collapsed"
                )
                raise SimulationError(f"step {self.step + 1}: {what}")
        if nsteps:
            self.virial[:] = out[-1, :4]
            self.n_contacts = round(float(out[-1, 4]))
            self.mean_overlap = float(out[-1, 5] / out[-1, 4]) if out[-1, 4] else 0.0
            self.stress = self.stress_tensor()
        return out

    def advance(self, *args, **kwargs) -> dict:
        """Advance the state; the semantics and the returned series of
        :meth:`gransim.dem.engine.Engine.advance`.

        ``advance(nsteps)``: ``nsteps`` steps of the run begun by :meth:`start_run`.
        ``advance(loading, nsteps=1, phase_step0=0, phase_box0=None)`` (orthogonal cell): ``nsteps``
        steps under a :class:`~gransim.dem.Loading` (fixed, rate or servo axes) or a
        :class:`~gransim.dem.PrescribedBox`, the phase measured from ``phase_step0`` and the box
        ``phase_box0`` = (lo, hi) (default: now). Returns ``step``, ``stress`` (n, 2, 2),
        ``virial`` (n, 4), ``n_contacts``, ``mean_overlap``, ``kinetic_energy`` and the cell's
        ``lengths`` (n, 2) (orthogonal) or ``box`` (n, 5) (sheared: lx, ly, xy, ylo, yhi)."""
        if self._sheared:
            return self._advance_sheared(*args, **kwargs)
        if (args and isinstance(args[0], (Loading, PrescribedBox))) or "loading" in kwargs:
            return self._advance_orthogonal(*args, **kwargs)
        if self._run is None:
            raise InputError(
                "advance: give the loading (advance(loading, nsteps)) or call start_run(loading, nsteps) first"
            )
        if len(args) + len(kwargs) != 1:
            raise InputError("advance: in a run begun by start_run, advance(nsteps)")
        loading, step0, end, box0 = self._run
        nsteps = args[0] if args else kwargs["nsteps"]
        nsteps = as_int(
            nsteps, "nsteps", 0, end - self.step, note=f" (the run ends at step {end}, now at step {self.step})"
        )
        return self._advance_orthogonal(loading, nsteps, step0, box0)

    def _advance_orthogonal(self, loading, nsteps=1, phase_step0=0, phase_box0=None) -> dict:
        if not isinstance(loading, (Loading, PrescribedBox)):
            raise InputError(f"loading: expected a Loading or a PrescribedBox, got {type(loading).__name__}")
        nsteps = as_int(nsteps, "nsteps", 0)
        if phase_box0 is None:
            phase_box0 = (self.lo.copy(), self.hi.copy())
        lo0 = np.array(phase_box0[0], np.float64).reshape(2)
        hi0 = np.array(phase_box0[1], np.float64).reshape(2)
        ctl = _control(loading, self.step, nsteps, lo0, hi0, int(phase_step0))
        first = self.step

        out = self._steps(ctl, nsteps, self._check_orthogonal)
        return {**_series(out, first), "lengths": out[:, 7:9].copy()}

    def start_run(self, loading, nsteps: int):
        """Begin a run of ``nsteps`` steps under ``loading``, continued by :meth:`advance` ``(k)``
        calls (:meth:`gransim.dem.engine.Engine.start_run`). Orthogonal cell: a Loading or a
        PrescribedBox measured from the current step and box (no new set-up; returns the stress).
        Sheared cell: a :class:`~gransim.dem.sheared.ShearLoading` (xy styles, x and y erate, the y
        servo, remap v or x), a LAMMPS ``run nsteps`` by the code order's own
        :meth:`gransim.dem.sheared.ShearedCell.start_run` on this engine (``fix deform`` init:
        the start and stop boxes, h_rate; then the run's set-up: wrap with this run's h_rate, list
        with the springs handed over, forces without spring increment). Returns the set-up stress
        (2, 2), compression positive."""
        nsteps = as_int(nsteps, "nsteps", 1)
        if not self._sheared:
            if not isinstance(loading, (Loading, PrescribedBox)):
                raise InputError(
                    "loading: expected a Loading or a PrescribedBox (the orthogonal cell), got "
                    f"{type(loading).__name__}"
                )
            self._run = (loading, self.step, self.step + nsteps, (self.lo.copy(), self.hi.copy()))
            return self.stress.copy()
        holder = _RunHolder()  # ShearedCell.start_run keeps its run on the cell: here, on this holder
        self._run = ShearedCell.start_run(holder, self, loading, nsteps)
        return self.stress.copy()

    def _advance_sheared(self, nsteps) -> dict:
        if self._run is None:
            raise InputError("advance: call start_run(loading, nsteps) first (the fix deform of the run)")
        run = self._run
        note = f" (the run ends at step {run.end}, now at step {self.step})"
        nsteps = as_int(nsteps, "nsteps", 0, run.end - self.step, note=note)
        first = self.step

        out = self._steps(deform_of(run, self.settings.dt), nsteps, self._check_sheared)
        return {**_series(out, first), "box": out[:, 7:12].copy()}

    # ------------------------------------------------------------------ checks and energies
    def _check_orthogonal(self, out, done: int, k: int, L_before):
        """The divergence check (the energy balance of the code order's ``_check_energy``) over the
        k steps from row ``done`` of ``out``, with the work of the orthogonal cell per step
        -(V_xx dLx/Lx + V_yy dLy/Ly) (V the virial of the step, N m; ``L_before`` the lengths
        before the first), the orthogonal cell's of the code order."""
        rows = out[done : done + k]
        L1 = rows[:, 7:9]
        L0 = np.vstack([np.asarray(L_before)[None], L1[:-1]])
        dw = -(rows[:, 0] * (L1[:, 0] - L0[:, 0]) / L0[:, 0] + rows[:, 1] * (L1[:, 1] - L0[:, 1]) / L0[:, 1])
        self._check_energy(self.step + 1, rows[:, 6], rows[:, 6], dw)

    def _check_sheared(self, out, done: int, k: int, box_before):
        """The divergence check of the sheared cell (the code order's): every step's kinetic energy
        finite, the one relative to the flow at the last step within the budget that counts the
        flow's kinetic energy too, the work of the cell per step -(V_xx dLx/Lx + V_yy dLy/Ly +
        V_yx (dxy - xy dLx/Lx)/Ly) (the velocity gradient dH H^-1 of the box change, H = [[Lx,
        xy], [0, Ly]])."""
        rows = out[done : done + k]
        b1 = rows[:, 7:10]  # lx, ly, xy after each step
        b = box_before
        b0 = np.vstack([[b[2] - b[0], b[3] - b[1], b[4]], b1[:-1]])
        dlx = (b1[:, 0] - b0[:, 0]) / b0[:, 0]
        dly = (b1[:, 1] - b0[:, 1]) / b0[:, 1]
        dxy = (b1[:, 2] - b0[:, 2] - b0[:, 2] * dlx) / b0[:, 1]
        dw = -(rows[:, 0] * dlx + rows[:, 1] * dly + rows[:, 3] * dxy)
        ke = np.full(k, np.nan)
        ke[-1], flow = self._energies()
        self._check_energy(self.step + 1, rows[:, 6], ke, dw, flow=flow)

    def _check_lost(self):
        """Before a rebuild: a particle that moved more than LOST_DISPLACEMENT_SKINS skins since
        the last build (Engine._check_lost, on the sorted state)."""
        p = self.ps
        i, di = FK.largest_move(p.x, p.y, p.xh, p.yh)
        skin = self.settings.skin
        if di > LOST_DISPLACEMENT_SKINS * skin:
            raise SimulationError(
                f"step {self.step + 1}: particle {int(self.perm[i])} lost: it moved {di:.4g} m = {di / skin:.3g} "
                f"skins since the neighbour build of step {self._build_step}, more than a skin "
                f"({skin:.4g} m) in one step (velocity {[p.vx[i], p.vy[i]]} m/s, dt {self.settings.dt:.4g} s)"
            )

    def _flow(self):
        """(u_x, u_y) (N,) of the sheared cell's homogeneous flow at the sorted particles (m/s)."""
        b = self.box
        f = (self.ps.y - b[1]) / (b[3] - b[1])
        return self.h_rate[2] * f, self.h_rate[1] * f

    def _energies(self):
        """(kinetic energy relative to the cell's flow, kinetic energy of the flow) (J), one pass
        (:func:`fast_kernels.flow_energies`; the orthogonal cell has no flow)."""
        p = self.ps
        if self._sheared:
            b, hr = self.box, self.h_rate
            return FK.flow_energies(p.y, p.vx, p.vy, p.w, p.m, p.r, b[1], b[3] - b[1], hr[2], hr[1])
        return FK.flow_energies(p.y, p.vx, p.vy, p.w, p.m, p.r, 0.0, 1.0, 0.0, 0.0)

    def _budget_kinetic_energy(self) -> float:
        """The kinetic energy the divergence check bounds (J): a sheared cell's relative to its
        flow (ShearedCell.budget_kinetic_energy), an orthogonal cell's as it is."""
        return float(self._energies()[0])

    def _flow_kinetic_energy(self) -> float:
        """Kinetic energy (J) of the sheared cell's flow at the particles (ShearedCell.flow_kinetic_energy)."""
        return float(self._energies()[1])

    def peculiar_velocities(self) -> np.ndarray:
        """Sheared cell: v - u(x) (m/s), (N, 2), original order (ShearedCell.peculiar_velocities)."""
        ux, uy = self._flow()
        return self._orig(self.ps.vx - ux, self.ps.vy - uy)

    def _shifts(self, e) -> np.ndarray:
        """Image shifts s (K, 2) int64 of the entries ``e``: j's image at x_j + C s."""
        c = self._code[e].astype(np.int64)
        return np.stack((c % 3 - 1, c // 3 - 1), axis=1)

    def _touching(self):
        """Entries of the touching pairs (each pair once) and their overlaps (m), the images from
        the current box (:func:`fast_kernels.touching_entries`)."""
        m = self.n_entries
        p = self.ps
        return FK.touching_entries(self._image(), self._ni[:m], self._nj[:m], self._code[:m], p.x, p.y, p.r)

    def elastic_energy(self) -> float:
        """Energy stored in the touching contacts (J): the law's ``energy``
        (:func:`gransim.contacts.laws.elastic_energy`) with each contact's overlap, spring and radii,
        in chunks of ENERGY_CHUNK contacts as the code order's ``Engine.elastic_energy`` (here on
        the sorted state: its ``ea``/``eb`` views, gathered for every chunk, cost 11 MB each at 1e6
        disks)."""
        e, ov = self._touching()
        p = self.ps
        total = 0.0
        for k in range(0, e.size, ENERGY_CHUNK):
            c = e[k : k + ENERGY_CHUNK]
            total += elastic_energy(
                self.law, ov[k : k + ENERGY_CHUNK], self._hist[:, c].T, p.r[self._ni[c]], p.r[self._nj[c]]
            )
        return total

    def contacts(self):
        """Touching pairs, each once (i < j, original indices): dict of i, j, shift (l_ij = x_j +
        C shift - x_i), force on j (N), overlap (m), tangential spring (frame of i, m), sliding.

        The force is the law's at the current state with the springs as they are (a set-up
        evaluation), not the one applied in the last step as the code order stores it: the fast
        ordering keeps no per-entry forces (memory: 24 B a list entry); the elastic part is the
        same, the damping part differs by the velocity change of the last half step."""
        m = self.n_entries
        p = self.ps
        f = np.zeros((m, 4))
        with disk_cache_off(self._no_cache):
            FK.entry_forces(
                self.law, self._image(), self.settings.dt, self._ni[:m], self._nj[:m], self._code[:m],
                self._hist[0, :m], self._hist[1, :m], p.x, p.y, p.vx, p.vy, p.w, p.r, p.m, f,
            )  # fmt: skip
        e, ov = self._touching()
        i = self.perm[self._ni[e]].astype(np.int64)
        j = self.perm[self._nj[e]].astype(np.int64)
        shift = self._shifts(e)
        force = -f[e, :2]  # on j
        spring = self._hist[:, e].T.copy()
        swap = i > j
        i[swap], j[swap] = j[swap], i[swap]
        shift[swap] *= -1
        force[swap] *= -1.0
        spring[swap] *= -1.0
        return {
            "i": i,
            "j": j,
            "shift": shift,
            "force": force,
            "overlap": ov,
            "tangential_spring": spring,
            "sliding": f[e, 2] != 0.0,
        }

    # ------------------------------------------------------------------ checkpoint
    def state_arrays(self) -> dict:
        """Everything needed to continue bit for bit (a checkpoint), in the sorted order inside:
        the particles, their permutation, the list with its springs, the bands, the box and its
        value at the last build, the virial; a sheared cell also its h_rate, the corners at the
        build and its run (the fix deform's parameters, the loading as JSON bytes)."""
        p = self.ps
        m = self.n_entries
        out = {f"sorted/{k}": getattr(p, k) for k in ("x", "y", "vx", "vy", "w", "fx", "fy", "t", "xh", "yh")}
        out.update(
            {
                "sorted/perm": self.perm,
                "list/cstart": self._cstart,
                "list/start": self._start,
                "list/ni": self._ni[:m],
                "list/nj": self._nj[:m],
                "list/code": self._code[:m],
                "list/h0": self._hist[0, :m],
                "list/h1": self._hist[1, :m],
                "list/spill_start": self._sp_start,
                "virial": self.virial,
                "build_step": np.array(self._build_step, np.int64),
            }
        )
        c = self._cell
        if self._sheared:
            out.update({"box": self.box, "box_hold": c.box_hold, "h_rate": self.h_rate, "corners_hold": c.corners_hold})
            if self._run is not None:  # the numbers of the run (as the code order's) and its loading
                out["run"] = np.array(self._run[:_RUN_NUMBERS], np.float64)
                text = json.dumps(self._run.loading.to_dict(), sort_keys=True)
                out["run_loading_json"] = np.frombuffer(text.encode(), np.uint8)
        else:
            out.update({"box_lo": self.lo, "box_hi": self.hi, "box_lo_hold": c.lo_hold, "box_hi_hold": c.hi_hold})
        return {k: np.array(v) for k, v in out.items()}

    def restore(self, arrays: dict, step: int):
        """Inverse of :meth:`state_arrays` on an engine of the same packing, settings, law and
        cell: the run continues with the bits of the run that wrote them (on any thread count)."""
        n = self.n
        try:
            got = {k: np.asarray(v) for k, v in arrays.items()}
            perm = np.array(got["sorted/perm"], np.int32).reshape(n)
            fields = {k: np.array(got[f"sorted/{k}"], np.float64).reshape(n) for k in ("x", "y", "vx", "vy", "w")}
            fields.update({k: np.array(got[f"sorted/{k}"], np.float64).reshape(n) for k in ("fx", "fy", "t")})
            fields.update({k: np.array(got[f"sorted/{k}"], np.float64).reshape(n) for k in ("xh", "yh")})
            ni = np.array(got["list/ni"], np.int32).reshape(-1)
            m = ni.size
            nj = np.array(got["list/nj"], np.int32).reshape(m)
            code = np.array(got["list/code"], np.uint8).reshape(m)
            h0 = np.array(got["list/h0"], np.float64).reshape(m)
            h1 = np.array(got["list/h1"], np.float64).reshape(m)
            cstart = np.array(got["list/cstart"], np.int32).reshape(-1)
            start = np.array(got["list/start"], np.int32).reshape(n + 1)
            sp_start = np.array(got["list/spill_start"], np.int64).reshape(cstart.size)
            virial = np.array(got["virial"], np.float64).reshape(4)
            build_step = int(got["build_step"])
        except KeyError as exc:
            raise InputError(
                f"restore: the checkpoint lacks {exc.args[0]!r} (not a fast-ordering checkpoint?)"
            ) from None
        except ValueError as exc:
            raise InputError(f"restore: the checkpoint does not fit this engine ({n} particles): {exc}") from None
        if np.any(np.sort(perm) != np.arange(n)):
            raise InputError("restore: sorted/perm is not a permutation of the particles")
        self.perm = perm
        self.ps = FK.FastParticles(
            fields["x"], fields["y"], fields["vx"], fields["vy"], fields["w"], fields["fx"], fields["fy"],
            fields["t"], self._masses0()[perm], self._radii0()[perm], fields["xh"], fields["yh"],
        )  # fmt: skip
        self._grow(int(m * GROWTH) + 16)
        self._ni[:m], self._nj[:m], self._code[:m] = ni, nj, code
        self._hist[0, :m], self._hist[1, :m] = h0, h1
        self._cstart, self._start, self._sp_start = cstart, start, sp_start
        self._acc = np.zeros((cstart.size - 1, 6))
        self._red = np.zeros((cstart.size - 1, 3))
        self._size_spill()
        self.n_entries = m
        c = self._cell
        if self._sheared:
            self.box[:] = np.asarray(got["box"], np.float64).reshape(5)
            c.box_hold[:] = np.asarray(got["box_hold"], np.float64).reshape(5)
            self.h_rate[:] = np.asarray(got["h_rate"], np.float64).reshape(3)
            c.corners_hold[:] = np.asarray(got["corners_hold"], np.float64).reshape(8, 2)
            self._run = None
            if "run" in got:
                r = np.asarray(got["run"], np.float64).reshape(_RUN_NUMBERS)
                loading = arrays.get("loading")
                if not isinstance(loading, ShearLoading):
                    text = np.asarray(got["run_loading_json"], np.uint8).tobytes().decode()
                    loading = ShearLoading(**json.loads(text))
                self._run = _ShearRun(int(r[0]), int(r[1]), int(r[2]), *(float(v) for v in r[3:]), loading)
        else:
            self.lo[:] = np.asarray(got["box_lo"], np.float64).reshape(2)
            self.hi[:] = np.asarray(got["box_hi"], np.float64).reshape(2)
            c.lo_hold[:] = np.asarray(got["box_lo_hold"], np.float64).reshape(2)
            c.hi_hold[:] = np.asarray(got["box_hi_hold"], np.float64).reshape(2)
        self.virial[:] = virial
        self.step = int(step)
        self._build_step = build_step
        self.stress = self.stress_tensor()
        self._reset_energy_budget()

    # ------------------------------------------------------------------ views (original order)
    def _orig(self, *arrays) -> np.ndarray:
        out = np.empty((self.n, len(arrays)))
        col = np.empty(self.n)
        for k, a in enumerate(arrays):
            FK.unsort_f(a, self.perm, col)
            out[:, k] = col
        return out

    x = property(lambda self: self._orig(self.ps.x, self.ps.y), doc="positions (N, 2), m, original order (a copy)")
    v = property(lambda self: self._orig(self.ps.vx, self.ps.vy), doc="velocities (N, 2), m/s (a copy)")
    w = property(lambda self: self._orig(self.ps.w)[:, 0], doc="spins (N,), rad/s (a copy)")
    f = property(lambda self: self._orig(self.ps.fx, self.ps.fy), doc="forces of the last step (N, 2), N (a copy)")
    t = property(lambda self: self._orig(self.ps.t)[:, 0], doc="torques of the last step (N,), N m (a copy)")
    m = property(lambda self: self._masses0(), doc="masses (N,), kg, original order")
    r = property(lambda self: self._radii0(), doc="radii (N,), m, original order")

    def _radii0(self) -> np.ndarray:
        """The packing's radii (N,) float64, original order (m)."""
        return np.asarray(self.packing.radii, np.float64)

    def _masses0(self, r=None) -> np.ndarray:
        """Masses (N,) (kg), original order: (pi r) r rho, the order of the code order and of
        both codes' data files (Packing.masses may differ in the last bit)."""
        r = self._radii0() if r is None else r
        return np.pi * r * r * float(self.packing.density)

    xhold = property(lambda self: self._orig(self.ps.xh, self.ps.yh), doc="positions at the last build (N, 2), m")
    ea = property(lambda self: self.perm[self._ni[: self.n_entries]], doc="first particle of each entry (M,)")
    eb = property(lambda self: self.perm[self._nj[: self.n_entries]], doc="second particle of each entry (M,)")
    xi = property(lambda self: self._hist[:, : self.n_entries].T, doc="spring of each entry (M, 2), m, frame of ea")

    @property
    def box_lengths(self) -> np.ndarray:
        lo, hi, _ = self._box_corners()
        return hi - lo

    @property
    def cell(self) -> np.ndarray:
        """Current cell (2, 2), m, the lattice vectors as columns."""
        L = self.box_lengths
        return np.array([[L[0], self.box[4] if self._sheared else 0.0], [0.0, L[1]]])

    @property
    def area(self) -> float:
        L = self.box_lengths
        return float(L[0] * L[1])

    def stress_tensor(self, L=None) -> np.ndarray:
        """Love stress of the virial held (2, 2), compression positive (N/m in 2D): virial / the
        area of the box lengths ``L`` (default: the current box)."""
        L = self.box_lengths if L is None else L
        v = self.virial / (L[0] * L[1])
        return np.array([[v[0], v[2]], [v[3], v[1]]])

    def memory_bytes(self) -> dict:
        """Bytes held by the engine's arrays: particles, list (capacity), hand-over table, rest."""
        part = sum(a.nbytes for a in self.ps) + self.perm.nbytes
        lst = self._ni.nbytes + self._nj.nbytes + self._code.nbytes + self._hist.nbytes + self._start.nbytes
        hand = self._hj.nbytes + self._hh.nbytes + self._hstart.nbytes
        rest = sum(
            a.nbytes
            for a in (self._order, self._key, self._tmpf, self._tmpi, self._cnt, self._binstart, self._sp_j, self._sp_f)
        )
        return {"particles": part, "list": lst, "hand_over": hand, "scratch": rest}


__all__ = ["CELLS", "FastEngine", "dynamic_chunks"]
