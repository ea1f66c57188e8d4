"""The fast ordering of the DEM (``Engine(..., order="fast")``): the physics of the code order
(:class:`gransim.dem.engine.Engine` with its orthogonal cell and its sheared cell under any
upper-triangular velocity gradient, ``remap v`` with Lees-Edwards images or ``remap x``) with any
registered contact law that offers a branch-free block path, in an order chosen for speed, not for
bitwise agreement with LIGGGHTS or LAMMPS (docs/performance.md). :class:`FastOrthogonalCell` and
:class:`FastShearedCell` are the engine's ``cell_ops`` of this ordering: the state's layout, the
list, the block of steps, the views; the engine keeps the loop, the checks and the energies.

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
* the list rebuilt in place into buffers that are reused and grown only when needed (on threads
  each band into its own region, the gaps between the regions left in place: the steps read the
  list band by band); at a rebuild the old list survives only as the compact table of its non-zero
  springs (the history hand-over);
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
import math

import numpy as np

from .._numba import check_threads, disk_cache_off, dynamic_chunks, num_threads
from ..contacts.laws import elastic_energy, offers_select
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import fast_kernels as FK
from . import kernels as K
from . import sheared_kernels as SK
from .engine import ENERGY_CHUNK, Engine, OrthogonalCell, _check_box
from .sheared import ShearedCell, run_arrays, run_from_arrays
from .sheared import _check_box as _check_sheared_box

#: bands of bin rows wanted per list build (the chunks of the threaded loops; fixed by N, not by
#: the thread count, so that results do not depend on the threads)
TARGET_BANDS = 64

#: the threaded kernels run only with at least this many particles per thread (below, a step is
#: too short for the start-up and the end barriers of the parallel regions: with the SIMD kernels
#: 2 threads on 10,058 disks ran at 0.92x of one thread, quiet machine); the results do not
#: depend on it (the serial and the threaded kernels sum in the same order)
MIN_PER_THREAD = 20000

#: particles per chunk of the threaded loops over particles (the wrap at a list build): large
#: enough that handing out chunks costs nothing beside the work, small enough that a descheduled
#: thread holds back little
PARTICLE_CHUNK = 4096

#: growth factor of the list buffers when a build needs more room than they have
GROWTH = 1.25

#: the threaded list build gives each band room for its particles times the last list's entries
#: per particle times BAND_SLACK, plus BAND_PAD entries; a band that needs more sends the build to
#: the count and fill passes
BAND_SLACK = 1.05
BAND_PAD = 64


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


def _checkpoint_array(arrays: dict, name: str, size: int) -> np.ndarray:
    """The float64 dataset ``name`` of a fast-ordering checkpoint, flattened to ``size`` numbers;
    InputError when it is missing or of another size."""
    if name not in arrays:
        raise InputError(f"restore: the checkpoint lacks {name!r} (not a fast-ordering checkpoint of this cell?)")
    a = np.asarray(arrays[name], np.float64).reshape(-1)
    if a.size != size:
        raise InputError(f"restore: {name} has {a.size} numbers, expected {size}")
    return a


class FastCell:
    """The fast ordering's state and block of steps, for :class:`gransim.dem.engine.Engine`
    (module docstring). Its state on the engine: ``ps`` (:data:`fast_kernels.FastParticles`,
    sorted by bin), ``perm`` (sorted index -> particle), the list (``_cstart``, ``_start``,
    ``_stop``, ``_ni``, ``_nj``, ``_code``, ``_hist``: capacity grows; ``_gaps`` the regions of a
    banded build, :meth:`_flat`), the hand-over table, the spill rows,
    ``sc`` (the virial), ``box`` (orthogonal: :data:`fast_kernels.OrthoCell`, lo, hi and their
    values at the last build; sheared: (lo_x, lo_y, hi_x, hi_y, xy) with ``box_hold``,
    ``h_rate``, ``corners_hold``). Its own: the threads (``threads`` 1 or more: the threaded
    kernels with at least :data:`MIN_PER_THREAD` particles per thread; the results do not depend
    on them), the rebuild rule of the flavour, the bands."""

    order = "fast"

    @staticmethod
    def check_size(packing: Packing, settings) -> None:
        C = np.asarray(packing.cell, np.float64)
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        cut = 2.0 * float(packing.radii.max()) + settings.skin
        heights = (Lx * Ly / math.hypot(Ly, xy), Ly)
        if min(heights) < 3.0 * cut:
            raise InputError(
                f"packing.cell: cell heights {heights[0]:.4g}, {heights[1]:.4g} m must be at least "
                f"3 (2 r_max + skin) = {3 * cut:.4g} m (three bins per axis)"
            )

    def __init__(self, eng, box, threads, x, v, w):
        if not offers_select(type(eng.law)):
            raise InputError(
                f"law: the fast ordering runs laws that offer a branch-free block path (LawSpec.select: "
                f"the Hooke laws), got {type(eng.law).__name__}; run it in the code's order"
            )
        t = check_threads(threads)
        self._threads = 1 if t is None else t
        n = eng.packing.n
        self._parallel = self._threads > 1 and n >= MIN_PER_THREAD * self._threads
        self._clamp = eng.flavour == "lammps"  # the rebuild rule of LAMMPS (kernels.rebuild_deltasq)
        self._cut = 2.0 * float(eng.packing.radii.max()) + eng.settings.skin
        self.run = None  # the fix deform of the current run (sheared cell: ShearedCell.start_run)
        # the radii and masses in the original order are the packing's (not held twice: 16 MB at
        # 1e6 disks); the sorted ones are gathered from them
        r = self._radii0(eng)
        eng.ps = FK.FastParticles(
            x[:, 0].copy(), x[:, 1].copy(), v[:, 0].copy(), v[:, 1].copy(), w.copy(),
            np.zeros(n), np.zeros(n), np.zeros(n), self._masses0(eng, r), r.copy(), np.zeros(n), np.zeros(n),
        )  # fmt: skip
        eng.perm = np.arange(n, dtype=np.int32)
        eng.sc = K.Scratch(np.zeros(4), np.zeros((0, 4)), np.zeros((0, 2)))
        self._init_box(eng, box)
        # rebuild scratch (reused): new order, bin keys, permutation buffers
        eng._order = np.zeros(n, np.int32)
        eng._key = np.zeros(n, np.int32)
        eng._tmpf = np.zeros(n)
        eng._tmpi = np.zeros(n, np.int32)
        eng._cnt = np.zeros(n, np.int32)
        eng._start = np.zeros(n + 1, np.int32)
        eng._stopbuf = np.zeros(n, np.int32)  # the stops of a banded build (_plain: start[1:])
        self._plain(eng)
        eng._binstart = np.zeros(1, np.int32)
        # the list (capacity grows) and the hand-over table
        eng._ni = np.zeros(0, np.int32)
        eng._nj = np.zeros(0, np.int32)
        eng._code = np.zeros(0, np.uint8)
        eng._hist = np.zeros((2, 0))  # rows: the two spring components (h0, h1 of fast_kernels)
        eng._hstart = np.zeros(n + 1, np.int32)
        eng._hj = np.zeros(0, np.int32)
        eng._hh = np.zeros((0, 2))
        eng._sp_j = np.zeros(0, np.int32)
        eng._sp_f = np.zeros((0, 3))
        eng.n_entries = 0
        eng.n_banded_builds = 0  # threaded builds done in one pass per band (the others: count and fill)
        Ly = float(eng.packing.cell[1, 1])
        self._rows = max(1, round(math.floor(Ly / self._cut) / TARGET_BANDS))

    # ------------------------------------------------------------------ internals
    @contextlib.contextmanager
    def _kernels(self, eng):
        # the force kernel is a parallel one even when serial (fast_kernels.forces_v): one thread;
        # the kernels of a law of a test module or script stay out of the disk cache
        with num_threads(self._threads if self._parallel else 1), dynamic_chunks(1), disk_cache_off(eng._no_cache):
            yield

    @contextlib.contextmanager
    def _particle_kernels(self):
        # a loop over particles (the wrap): on the threads in chunks of PARTICLE_CHUNK particles
        # when threaded, else on one
        with num_threads(self._threads if self._parallel else 1), dynamic_chunks(PARTICLE_CHUNK):
            yield

    def _list(self, eng):
        return FK.FastList(eng._cstart, eng._start, eng._stop, eng._ni, eng._nj, eng._code, *eng._hist)

    @staticmethod
    def _plain(eng):
        """The list's stops those of plain CSR, ``start[1:]``, and no gaps (``_gaps`` (base, used) of
        a banded build whose bands are not moved together)."""
        eng._stop, eng._gaps = eng._start[1:], None

    def _flat(self, eng):
        """The list as plain CSR (``_ni[:n_entries]`` etc. the whole list, ``start[N]`` its size)
        for the readers of the whole list (contacts, energies, views, checkpoints): a banded
        build leaves a gap after each band (:func:`fast_kernels.pairs_banded`), closed here, once
        (the steps read the bands where they are). The entries and their order stay the same."""
        if eng._gaps is not None:
            base, used = eng._gaps
            FK.close_gaps(eng._cstart, base, used, eng._start, eng._ni, eng._nj, eng._code, *eng._hist)
            self._plain(eng)

    def forces(self, eng, update: bool):
        """The forces of the current state (``update`` False: the set-up evaluation of a run,
        springs not incremented): the virial on the engine; returns (contacts, overlap sum). (The images from
        the positions; the code order's sheared cell takes them from the lamda coordinates after
        a build: round-off.)"""
        p = eng.ps
        for a in (p.fx, p.fy, p.t):
            a[:] = 0.0
        with self._kernels(eng):
            FK.forces_v(
                self._parallel, eng._cstart, eng._start, eng._stop, eng._ni, eng._nj, eng._code, eng._hist[0],
                eng._hist[1], p.x, p.y, p.vx, p.vy, p.w, p.r, p.m, p.fx, p.fy, p.t, self._image(eng), eng.law,
                eng.settings.dt, update, eng._sp_start, *self._spill(eng), eng._acc,
            )  # fmt: skip
        tot = np.zeros(6)
        for c in range(eng._acc.shape[0]):  # the band order of run_steps
            tot += eng._acc[c]
        eng.virial[:] = tot[:4]
        return float(tot[4]), float(tot[5])

    def rebuild(self, eng, carry: bool):
        """Wrap (a sheared cell: with the Lees-Edwards velocity jump), sort by bin (state and
        history permuted), new list in place, springs handed over for the pairs that touch now (as
        the code order)."""
        n = eng.n
        p = eng.ps
        lo, hi, xy = self._box_corners(eng)
        bad = self._wrap(eng)
        if bad >= 0:
            raise SimulationError(
                f"step {eng.step}: particle {int(eng.perm[bad])} lost (at "
                f"{[p.x[bad], p.y[bad]]}, box {lo.tolist()}..{hi.tolist()}, tilt {xy})"
            )
        L = hi - lo
        # bins at least a cut-off wide across: along x the distance between the lamda_x lines,
        # Lx Ly/|a2| (a2 = (xy, Ly)); the orthogonal cell's plain Lx // cut
        wide = L[0] * L[1] / math.hypot(L[1], xy) if xy else L[0]
        nbx, nby = int(wide // self._cut), int(L[1] // self._cut)
        if min(nbx, nby) < 3:
            raise SimulationError(
                f"step {eng.step}: the box {L.tolist()} m (tilt {xy} m) holds fewer than 3 bins of the "
                f"cut-off {self._cut:.4g} m per axis"
            )
        if eng._binstart.size < nbx * nby + 1:
            eng._binstart = np.zeros(nbx * nby + 1, np.int32)
        binstart = eng._binstart[: nbx * nby + 1]
        FK.bin_sort(p.x, p.y, lo, hi, xy, nbx, nby, eng._order, binstart, eng._key)
        # hand-over table of the current list (old order; on the threads by the old list's bands)
        if carry and eng.n_entries:
            h0, h1 = eng._hist
            if self._parallel:
                bcount = np.zeros(eng._cstart.size - 1, np.int64)
                with self._kernels(eng):
                    FK.history_counts(eng._cstart, eng._start, eng._stop, h0, h1, bcount)
                k = int(bcount.sum())
            else:
                self._flat(eng)
                k = FK.count_history(eng._start, h0, h1, n)
            if eng._hj.size < k:
                cap = int(k * GROWTH) + 16
                eng._hj, eng._hh = np.zeros(cap, np.int32), np.zeros((cap, 2))
            h = (eng._hstart, eng._hj, eng._hh)
            if self._parallel:
                with self._kernels(eng):
                    FK.compact_history_banded(eng._cstart, eng._start, eng._stop, eng._nj, h0, h1, bcount, *h)
            else:
                FK.compact_history(eng._start, eng._stop, eng._nj, h0, h1, n, *h)
        else:
            eng._hstart[:] = 0
        # entries per particle of each band of the last list (the threaded build sizes its regions
        # with them: the first band also holds the pairs across the periodic y boundary)
        per_band = None
        if self._parallel and eng.n_entries:
            entries = eng._gaps[1] if eng._gaps is not None else np.diff(eng._start[eng._cstart])
            per_band = entries / np.maximum(np.diff(eng._cstart), 1)
        o = eng._order
        # each array gathered into the scratch, which then takes its place (one pass, not a gather
        # and a copy back); serial also on threads: seven short parallel regions cost more than
        # they saved (measured)
        new = {}
        for name in ("x", "y", "vx", "vy", "w", "r", "m"):  # f, t are zero here
            a = getattr(p, name)
            FK.gather_f(a, o, eng._tmpf)
            new[name] = eng._tmpf
            eng._tmpf = a
        eng.ps = p = p._replace(**new)
        FK.permute_i(eng.perm, o, eng._tmpi)
        rows = self._rows
        nb = -(-nby // rows)
        eng._cstart = np.ascontiguousarray(binstart[np.minimum(np.arange(nb + 1) * rows, nby) * nbx], np.int32)
        eng._sp_start = np.zeros(nb + 1, np.int64)
        sp_cnt = np.zeros(nb, np.int64)
        eng._acc = np.zeros((nb, 6))
        eng._red = np.zeros((nb, 3))
        pairs = FK.pairs_parallel if self._parallel else FK.pairs_serial
        args = (eng._cstart, binstart, p.x, p.y, p.r, lo, hi, xy, nbx, nby, eng.settings.skin, eng._cnt, eng._start)

        def tail():  # the list buffers (replaced when they grow) and the hand-over table
            return (eng._ni, eng._nj, eng._code, *eng._hist, sp_cnt, o, eng._hstart, eng._hj, eng._hh)

        m = -1
        self._plain(eng)  # the old list is in the hand-over table
        if not self._parallel:  # one pass into the buffers as they are; -1: too small
            m = FK.pairs_direct(*args[:-2], eng._start, *tail())
        elif per_band is not None:
            # one pass per band on the threads, each band into a region sized from the last list's
            # entries per particle of that band (of the whole list when the bands changed) times
            # BAND_SLACK plus BAND_PAD, the gap after its entries left in place (the steps read
            # band by band; moving the bands together was 3% of the two-thread time at 1e5 disks);
            # a band that does not fit sends the whole build to the count and fill passes below
            per = per_band if per_band.size == nb else np.full(nb, eng.n_entries / n)
            cap = (np.diff(eng._cstart) * (per * BAND_SLACK)).astype(np.int64) + BAND_PAD
            base = np.zeros(nb + 1, np.int64)
            np.cumsum(cap, out=base[1:])
            if eng._nj.size < base[-1]:
                self._grow(eng, int(base[-1] * GROWTH) + 16)
            used = np.zeros(nb, np.int64)
            with self._kernels(eng):
                FK.pairs_banded(*args[:-2], eng._start, eng._stopbuf, *tail(), base, used)
            if used.min() >= 0:
                m = int(used.sum())
                eng._start[n] = base[nb - 1] + used[nb - 1]
                eng._stop, eng._gaps = eng._stopbuf, (base, used)
                eng.n_banded_builds += 1
        if m < 0:
            with self._kernels(eng):
                pairs(0, *args, *tail())  # count
                m = FK.prefix(eng._cnt, eng._start)
                if eng._nj.size < m:
                    self._grow(eng, int(m * GROWTH) + 16)
                pairs(1, *args, *tail())  # fill
        np.cumsum(sp_cnt, out=eng._sp_start[1:])
        self._size_spill(eng)
        eng.n_entries = int(m)
        p.xh[:] = p.x
        p.yh[:] = p.y
        self._hold(eng)
        eng._build_step = eng.step
        eng.n_rebuilds += 1

    def _size_spill(self, eng):
        ns = int(eng._sp_start[-1])
        if eng._sp_j.size < ns:
            cap = int(ns * GROWTH) + 16
            eng._sp_j, eng._sp_f = np.zeros(cap, np.int32), np.zeros((cap, 3))
        eng._nspill = ns

    def _grow(self, eng, cap: int):
        """New list buffers of ``cap`` entries (the old list is not needed any more: its springs
        are in the hand-over table). The old buffers are released first, so the two never
        coexist (the peak memory of a build that grows the list)."""
        eng._ni = eng._nj = eng._code = eng._hist = None
        eng._ni = np.zeros(cap, np.int32)
        eng._nj = np.zeros(cap, np.int32)
        eng._code = np.zeros(cap, np.uint8)
        eng._hist = np.zeros((2, cap))

    def _spill(self, eng):
        return eng._sp_j[: eng._nspill], eng._sp_f[: eng._nspill]

    # ------------------------------------------------------------------ the block of steps
    def series(self, nsteps: int) -> np.ndarray:
        return np.zeros((nsteps, FK.OUT_COLUMNS))

    def block(self, eng, ctl, out, done: int, n: int, resume: bool):
        """Up to ``n`` steps of :func:`fast_kernels.run_steps` into the rows ``done..`` of ``out``
        (stops at a rebuild, a non-finite position or a collapsed cell): (steps, status, index)."""
        s = eng.settings
        sp_j, sp_f = self._spill(eng)
        with self._kernels(eng):
            return FK.run_steps(
                self._parallel, eng.ps, self._list(eng), self._kernel_cell(eng), ctl, eng.law, s.dt, s.skin,
                self._clamp, FK.FastScratch(eng._sp_start, sp_j, sp_f, eng._acc, eng._red), out[done:], eng.step, n,
                resume, True,
            )  # fmt: skip

    def result(self, eng, out: np.ndarray, first: int) -> dict:
        """The series of :meth:`Engine.advance` from the rows of :func:`fast_kernels.run_steps`
        (``first``: the step before the first row); the virial, contacts and mean overlap of the
        last step on the engine."""
        if out.shape[0]:
            eng.virial[:] = out[-1, :4]
            eng.n_contacts = round(float(out[-1, 4]))
            eng.mean_overlap = float(out[-1, 5] / out[-1, 4]) if out[-1, 4] else 0.0
        return {**_series(out, first), **self.cell_series(out)}

    def particle(self, eng, i: int) -> int:
        """The particle (packing order) of the sorted index ``i``."""
        return int(eng.perm[i])

    def largest_move(self, eng):
        """(particle, distance (m)) of the largest displacement since the last list build."""
        p = eng.ps
        i, di = FK.largest_move(p.x, p.y, p.xh, p.yh)
        return int(eng.perm[i]), float(di)

    #: the views of the engine (packing order, copies)
    VIEWS = {
        "x": lambda c, e: c._orig(e, e.ps.x, e.ps.y),
        "v": lambda c, e: c._orig(e, e.ps.vx, e.ps.vy),
        "w": lambda c, e: c._orig(e, e.ps.w)[:, 0],
        "f": lambda c, e: c._orig(e, e.ps.fx, e.ps.fy),
        "t": lambda c, e: c._orig(e, e.ps.t)[:, 0],
        "m": lambda c, e: c._masses0(e),
        "r": lambda c, e: c._radii0(e),
        "xhold": lambda c, e: c._orig(e, e.ps.xh, e.ps.yh),
        "ea": lambda c, e: e.perm[e._ni[: e.n_entries]],
        "eb": lambda c, e: e.perm[e._nj[: e.n_entries]],
        "xi": lambda c, e: e._hist[:, : e.n_entries].T,
    }

    def view(self, eng, name: str):
        if name in ("ea", "eb", "xi"):
            self._flat(eng)
        try:
            return self.VIEWS[name](self, eng)
        except KeyError:
            raise AttributeError(
                f"{name}: the fast ordering keeps no such array (its list is a half list with image codes: "
                "contacts() gives the touching pairs)"
            ) from None

    def _flow(self, eng):
        """(u_x, u_y) (N,) of the sheared cell's homogeneous flow at the sorted particles (m/s)."""
        b = eng.box
        f = (eng.ps.y - b[1]) / (b[3] - b[1])
        return eng.h_rate[2] * f, eng.h_rate[1] * f

    def _energies(self, eng):
        """(kinetic energy relative to the cell's flow, kinetic energy of the flow) (J), one pass
        (:func:`fast_kernels.flow_energies`; the orthogonal cell has no flow)."""
        p = eng.ps
        return FK.flow_energies(p.y, p.vx, p.vy, p.w, p.m, p.r, *self._flow_field(eng))

    def budget_kinetic_energy(self, eng) -> float:
        """The kinetic energy the divergence check bounds (J): a sheared cell's relative to its
        flow (ShearedCell.budget_kinetic_energy), an orthogonal cell's as it is."""
        return float(self._energies(eng)[0])

    def flow_kinetic_energy(self, eng) -> float:
        """Kinetic energy (J) of the sheared cell's flow at the particles (ShearedCell.flow_kinetic_energy)."""
        return float(self._energies(eng)[1])

    def peculiar_velocities(self, eng) -> np.ndarray:
        """Sheared cell: v - u(x) (m/s), (N, 2), original order (ShearedCell.peculiar_velocities)."""
        ux, uy = self._flow(eng)
        return self._orig(eng, eng.ps.vx - ux, eng.ps.vy - uy)

    def shifts(self, eng, e=slice(None)) -> np.ndarray:
        """Image shifts s (K, 2) int64 of the entries ``e`` of the whole list (default all, in the
        order of the ``ea``/``eb`` views): j's image at x_j + C s."""
        self._flat(eng)
        c = eng._code[: eng.n_entries][e].astype(np.int64)
        return np.stack((c % 3 - 1, c // 3 - 1), axis=1)

    def touching(self, eng):
        """Entries of the touching pairs (each pair once) and their overlaps (m), the images from
        the current box (:func:`fast_kernels.touching_entries`)."""
        self._flat(eng)
        m = eng.n_entries
        p = eng.ps
        return FK.touching_entries(self._image(eng), eng._ni[:m], eng._nj[:m], eng._code[:m], p.x, p.y, p.r)

    def elastic_energy(self, eng) -> float:
        """Energy stored in the touching contacts (J): the law's ``energy``
        (:func:`gransim.contacts.laws.elastic_energy`) with each contact's overlap, spring and radii,
        in chunks of ENERGY_CHUNK contacts as the code order's ``Engine.elastic_energy`` (here on
        the sorted state: its ``ea``/``eb`` views, gathered for every chunk, cost 11 MB each at 1e6
        disks)."""
        e, ov = self.touching(eng)
        p = eng.ps
        total = 0.0
        for k in range(0, e.size, ENERGY_CHUNK):
            c = e[k : k + ENERGY_CHUNK]
            total += elastic_energy(
                eng.law, ov[k : k + ENERGY_CHUNK], eng._hist[:, c].T, p.r[eng._ni[c]], p.r[eng._nj[c]]
            )
        return total

    def contacts(self, eng):
        """Touching pairs, each once (i < j, original indices): dict of i, j, shift (l_ij = x_j +
        C shift - x_i), force on j (N), overlap (m), tangential spring (frame of i, m), sliding.

        The force is the law's at the current state with the springs as they are (a set-up
        evaluation), not the one applied in the last step as the code order stores it: the fast
        ordering keeps no per-entry forces (memory: 24 B a list entry); the elastic part is the
        same, the damping part differs by the velocity change of the last half step."""
        self._flat(eng)
        m = eng.n_entries
        p = eng.ps
        f = np.zeros((m, 4))
        with disk_cache_off(eng._no_cache):
            FK.entry_forces(
                eng.law, self._image(eng), eng.settings.dt, eng._ni[:m], eng._nj[:m], eng._code[:m],
                eng._hist[0, :m], eng._hist[1, :m], p.x, p.y, p.vx, p.vy, p.w, p.r, p.m, f,
            )  # fmt: skip
        e, ov = self.touching(eng)
        i = eng.perm[eng._ni[e]].astype(np.int64)
        j = eng.perm[eng._nj[e]].astype(np.int64)
        shift = self.shifts(eng, e)
        force = -f[e, :2]  # on j
        spring = eng._hist[:, e].T.copy()
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
    def state_arrays(self, eng) -> dict:
        """Everything needed to continue bit for bit (a checkpoint), in the sorted order inside:
        the particles, their permutation, the list with its springs, the bands, the box and its
        value at the last build, the virial; a sheared cell also its h_rate, the corners at the
        build and its run (the fix deform's parameters, the loading as JSON bytes)."""
        self._flat(eng)
        p = eng.ps
        m = eng.n_entries
        out = {f"sorted/{k}": getattr(p, k) for k in ("x", "y", "vx", "vy", "w", "fx", "fy", "t", "xh", "yh")}
        out.update(
            {
                "sorted/perm": eng.perm,
                "list/cstart": eng._cstart,
                "list/start": eng._start,
                "list/ni": eng._ni[:m],
                "list/nj": eng._nj[:m],
                "list/code": eng._code[:m],
                "list/h0": eng._hist[0, :m],
                "list/h1": eng._hist[1, :m],
                "list/spill_start": eng._sp_start,
                "virial": eng.virial,
                "build_step": np.array(eng._build_step, np.int64),
            }
        )
        out.update(self._box_arrays(eng))
        return {k: np.array(v) for k, v in out.items()}

    def restore(self, eng, arrays: dict, step: int) -> int:
        """Inverse of :meth:`state_arrays` on an engine of the same packing, settings, law and
        cell: the run continues with the bits of the run that wrote them (on any thread count).
        Returns the step of the list build."""
        n = eng.n
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
        eng.perm = perm
        eng.ps = FK.FastParticles(
            fields["x"], fields["y"], fields["vx"], fields["vy"], fields["w"], fields["fx"], fields["fy"],
            fields["t"], self._masses0(eng)[perm], self._radii0(eng)[perm], fields["xh"], fields["yh"],
        )  # fmt: skip
        self._grow(eng, int(m * GROWTH) + 16)
        eng._ni[:m], eng._nj[:m], eng._code[:m] = ni, nj, code
        eng._hist[0, :m], eng._hist[1, :m] = h0, h1
        eng._cstart, eng._start, eng._sp_start = cstart, start, sp_start
        self._plain(eng)
        eng._acc = np.zeros((cstart.size - 1, 6))
        eng._red = np.zeros((cstart.size - 1, 3))
        self._size_spill(eng)
        eng.n_entries = m
        self._restore_box(eng, arrays)
        eng.virial[:] = virial
        return build_step

    def _orig(self, eng, *arrays) -> np.ndarray:
        """The sorted arrays ``arrays`` (N,) as the columns of an (N, k) array in the packing's order."""
        out = np.empty((eng.n, len(arrays)))
        col = np.empty(eng.n)
        for k, a in enumerate(arrays):
            FK.unsort_f(a, eng.perm, col)
            out[:, k] = col
        return out

    def _radii0(self, eng) -> np.ndarray:
        """The packing's radii (N,) float64, original order (m)."""
        return np.asarray(eng.packing.radii, np.float64)

    def _masses0(self, eng, r=None) -> np.ndarray:
        """Masses (N,) (kg), original order: (pi r) r rho, the order of the code order and of
        both codes' data files (Packing.masses may differ in the last bit)."""
        r = self._radii0(eng) if r is None else r
        return np.pi * r * r * float(eng.packing.density)

    def memory_bytes(self, eng) -> dict:
        """Bytes held by the engine's arrays: particles, list (capacity), hand-over table, rest."""
        part = sum(a.nbytes for a in eng.ps) + eng.perm.nbytes
        lst = eng._ni.nbytes + eng._nj.nbytes + eng._code.nbytes + eng._hist.nbytes + eng._start.nbytes
        lst += eng._stopbuf.nbytes
        hand = eng._hj.nbytes + eng._hh.nbytes + eng._hstart.nbytes
        rest = sum(
            a.nbytes
            for a in (eng._order, eng._key, eng._tmpf, eng._tmpi, eng._cnt, eng._binstart, eng._sp_j, eng._sp_f)
        )
        return {"particles": part, "list": lst, "hand_over": hand, "scratch": rest}


class FastOrthogonalCell(FastCell):
    """The orthogonal cell in the fast ordering: the box, loadings and checks of
    :class:`gransim.dem.engine.OrthogonalCell`."""

    kind = "orthogonal"
    check = staticmethod(OrthogonalCell.check)
    matrix = OrthogonalCell.matrix
    lengths = OrthogonalCell.lengths
    lo = OrthogonalCell.lo
    hi = OrthogonalCell.hi
    start_run = OrthogonalCell.start_run
    drive = OrthogonalCell.drive
    _drive = OrthogonalCell._drive
    collapse_message = OrthogonalCell.collapse_message

    def _init_box(self, eng, box):
        C = eng.packing.cell
        lo, hi = (np.zeros(2), np.array([C[0, 0], C[1, 1]], np.float64)) if box is None else _check_box(box, C)
        eng.box = FK.OrthoCell(lo, hi, lo.copy(), hi.copy())

    def _kernel_cell(self, eng):
        return eng.box

    def _image(self, eng):
        """The image plug-in of the force loop for the current box: (Lx, Ly)."""
        return (float(eng.hi[0] - eng.lo[0]), float(eng.hi[1] - eng.lo[1]))

    def _box_corners(self, eng):
        """(lo (2,), hi (2,), xy) of the current box."""
        return eng.lo, eng.hi, 0.0

    def _wrap(self, eng):
        """Domain::pbc per axis; a particle still outside (sorted index) or -1."""
        p = eng.ps
        with self._particle_kernels():
            return FK.wrap(p.x, p.y, eng.lo, eng.hi)

    def _hold(self, eng):
        """The box at this list build (the rebuild test measures the box's motion from it)."""
        eng.box.lo_hold[:] = eng.lo
        eng.box.hi_hold[:] = eng.hi

    def _flow_field(self, eng):
        """(y_lo, L_y, u_x rate, u_y rate) of :func:`fast_kernels.flow_energies`: no flow."""
        return 0.0, 1.0, 0.0, 0.0

    def _box_arrays(self, eng) -> dict:
        b = eng.box
        return {"box_lo": b.lo, "box_hi": b.hi, "box_lo_hold": b.lo_hold, "box_hi_hold": b.hi_hold}

    def _restore_box(self, eng, arrays: dict):
        b = eng.box
        for name, a in (("box_lo", b.lo), ("box_hi", b.hi), ("box_lo_hold", b.lo_hold), ("box_hi_hold", b.hi_hold)):
            a[:] = _checkpoint_array(arrays, name, 2)

    def box_state(self, eng):
        return self.lengths(eng).copy()

    def cell_series(self, out) -> dict:
        return {"lengths": out[:, 7:9].copy()}

    def check_divergence(self, eng, out, done: int, k: int, L_before):
        """The divergence check (:meth:`Engine._check_energy`) over the k steps from row ``done``,
        with the work of the orthogonal cell per step -(V_xx dLx/Lx + V_yy dLy/Ly) (V the virial
        of the step, N m; ``L_before`` the lengths before the first)."""
        rows = out[done : done + k]
        L1 = rows[:, 7:9]
        L0 = np.vstack([np.asarray(L_before)[None], L1[:-1]])
        dw = -(rows[:, 0] * (L1[:, 0] - L0[:, 0]) / L0[:, 0] + rows[:, 1] * (L1[:, 1] - L0[:, 1]) / L0[:, 1])
        eng._check_energy(eng.step + 1, rows[:, 6], rows[:, 6], dw)


class FastShearedCell(FastCell):
    """The sheared cell in the fast ordering: the box, ``fix deform`` runs and checks of
    :class:`gransim.dem.sheared.ShearedCell` (whose ``start_run`` begins a run on this cell too:
    the fix deform's init, then this ordering's set-up)."""

    kind = "sheared"
    check = staticmethod(lambda packing, settings, flavour: ShearedCell.check_cell(packing, flavour))
    matrix = ShearedCell.matrix
    lengths = ShearedCell.lengths
    lo = ShearedCell.lo
    hi = ShearedCell.hi
    start_run = ShearedCell.start_run
    drive = ShearedCell.drive
    collapse_message = ShearedCell.collapse_message

    def _init_box(self, eng, box):
        C = np.asarray(eng.packing.cell, np.float64)
        Lx, Ly, xy = float(C[0, 0]), float(C[1, 1]), float(C[0, 1])
        eng.box = np.array([0.0, 0.0, Lx, Ly, xy]) if box is None else _check_sheared_box(box, Lx, Ly, xy)
        eng.h_rate = np.zeros(3)
        eng.box_hold = eng.box.copy()
        eng.corners_hold = np.zeros((8, 2))

    def _kernel_cell(self, eng):
        return FK.ShearCell(eng.box, eng.box_hold, eng.h_rate, eng.corners_hold)

    def _image(self, eng):
        """The image plug-in of the force loop for the current box: (Lx, Ly, xy, and the velocity
        jumps h_rate[5], h_rate[1], h_rate[0] of the images)."""
        b = eng.box
        hr = eng.h_rate
        return (float(b[2] - b[0]), float(b[3] - b[1]), float(b[4]), float(hr[2]), float(hr[1]), float(hr[0]))

    def _box_corners(self, eng):
        """(lo (2,), hi (2,), xy) of the current box."""
        b = eng.box
        return b[0:2], b[2:4], float(b[4])

    def _wrap(self, eng):
        """Domain::pbc of the tilted box with the Lees-Edwards velocity jump; a particle still
        outside (sorted index) or -1."""
        p = eng.ps
        with self._particle_kernels():
            return FK.wrap_tilted(p.x, p.y, p.vx, p.vy, eng.box, eng.h_rate, True)

    def _hold(self, eng):
        """The box and its 8 corners at this list build (LAMMPS' triclinic rebuild rule)."""
        eng.box_hold[:] = eng.box
        SK.box_corners(eng.box, eng.corners_hold)

    def _flow_field(self, eng):
        """(y_lo, L_y, u_x rate, u_y rate) of :func:`fast_kernels.flow_energies`: the cell's flow."""
        b, hr = eng.box, eng.h_rate
        return b[1], b[3] - b[1], hr[2], hr[1]

    def _box_arrays(self, eng) -> dict:
        """The box, its state at the last build, h_rate, the corners, and the run (the numbers
        and the loading, as the code order's: :func:`gransim.dem.sheared.run_arrays`)."""
        return {
            "box": eng.box, "box_hold": eng.box_hold, "h_rate": eng.h_rate, "corners_hold": eng.corners_hold,
            **run_arrays(self.run),
        }  # fmt: skip

    def _restore_box(self, eng, arrays: dict):
        eng.box[:] = _checkpoint_array(arrays, "box", 5)
        eng.box_hold[:] = _checkpoint_array(arrays, "box_hold", 5)
        eng.h_rate[:] = _checkpoint_array(arrays, "h_rate", 3)
        eng.corners_hold[:] = _checkpoint_array(arrays, "corners_hold", 16).reshape(8, 2)
        self.run = run_from_arrays(arrays)
        eng._run_drive = self.run

    def box_state(self, eng):
        return eng.box.copy()

    def cell_series(self, out) -> dict:
        return {"box": out[:, 7:12].copy()}

    def check_divergence(self, eng, out, done: int, k: int, box_before):
        """The divergence check of the sheared cell (:meth:`gransim.dem.sheared.ShearedCell.
        check_divergence`): every step's kinetic energy finite, the one relative to the flow at
        the last step within the budget that counts the flow's kinetic energy too, the work of
        the cell per step -(V_xx dLx/Lx + V_yy dLy/Ly + V_yx (dxy - xy dLx/Lx)/Ly)."""
        rows = out[done : done + k]
        b1 = rows[:, 7:10]  # lx, ly, xy after each step
        b = box_before
        b0 = np.vstack([[b[2] - b[0], b[3] - b[1], b[4]], b1[:-1]])
        dlx = (b1[:, 0] - b0[:, 0]) / b0[:, 0]
        dly = (b1[:, 1] - b0[:, 1]) / b0[:, 1]
        dxy = (b1[:, 2] - b0[:, 2] - b0[:, 2] * dlx) / b0[:, 1]
        dw = -(rows[:, 0] * dlx + rows[:, 1] * dly + rows[:, 3] * dxy)
        ke = np.full(k, np.nan)
        ke[-1], flow = self._energies(eng)
        eng._check_energy(eng.step + 1, rows[:, 6], ke, dw, flow=flow)


def FastEngine(
    packing: Packing,
    settings,
    velocities=None,
    spins=None,
    threads: int | None = 1,
    check_dt: bool = True,
    law=None,
    cell: str = "orthogonal",
) -> Engine:
    """The :class:`~gransim.dem.engine.Engine` in the fast ordering (``order="fast"``) on
    ``threads`` threads, in the arithmetic of ``settings.flavour``."""
    return Engine(packing, settings, velocities, spins, threads, check_dt, None, law, cell=cell, order="fast")


__all__ = ["FastCell", "FastEngine", "FastOrthogonalCell", "FastShearedCell", "dynamic_chunks"]
