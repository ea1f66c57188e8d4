"""The fast DEM path: the physics of :class:`gransim.dem.DEMEngine` (LIGGGHTS 3.8.0 Hooke history
law, nve/sphere, periodic orthogonal cell) in an order chosen for speed, not for bitwise agreement
with LIGGGHTS or LAMMPS (docs/performance.md).

What is reordered, and what it changes:

* the particles are sorted by bin (row-major bins at least a neighbour cut-off wide) at every list
  build, the velocities, spins and the particles' history going along (``perm`` maps back: every
  output is in the original particle order);
* structure-of-arrays particle state (x, y, vx, vy, w, ... each (N,)), int32 indices, a uint8
  image code per entry, the spring history kept in float64 for the law;
* a half list, each pair once (i < j in the sorted order, LIGGGHTS keeps the pairs across the
  boundary twice), with the symmetric update (j gets minus the force on i and its torque);
* the contact law written without branches (:func:`gransim.dem.fast_kernels.hooke_select`);
* one fused pass per step: second half step, box remap, first half step of the next step,
  position update, rebuild test and forces zeroed;
* the list rebuilt in place into buffers that are reused and grown only when needed; at a
  rebuild the old list survives only as the compact table of its non-zero springs (the
  history hand-over);
* threads: bands of bin rows, many more than the threads, handed out dynamically (numba's
  dynamic scheduling with chunk size 1, :func:`dynamic_chunks`), even bands then odd bands so no
  two threads write the same particle. Sums have a fixed order: the results are the same bit for
  bit on 1 and 2 threads (and under any scheduling).

Only summation orders differ from :class:`~gransim.dem.DEMEngine`: the two agree to round-off
over short horizons, and over long ones the fast path stays within the divergence envelope of the
bitwise engine itself (tests/dem/test_fast.py).

Scope: the box is fixed or deforms at a prescribed strain rate per axis (``fix deform`` ``erate``
style with ``remap x``, :class:`~gransim.dem.Loading` with ``fixed``/``rate`` axes); no stress
servo and no prescribed box table (use :class:`~gransim.dem.DEMEngine` for those). Contact law:
the Hooke history law of the settings (``DEMSettings.flavour`` "liggghts" only). The rebuild rule
is the displacement test with the box displacement subtracted and clamped at zero (LAMMPS'
rule; LIGGGHTS squares a negative margin, which only matters once the box has moved by more than
the skin since the last build).
"""

from __future__ import annotations

import contextlib
import math

import numpy as np

from .._numba import check_threads, dynamic_chunks, num_threads
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import fast_kernels as FK
from .engine import check_time_step
from .settings import DEMSettings, Loading

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


class FastEngine:
    """State and stepping of a DEM run on the fast path.

    Parameters
    ----------
    packing : initial packing (orthogonal cell; the box is [0, Lx] x [0, Ly]).
    settings : :class:`~gransim.dem.DEMSettings` (kn, kt, gamma_n, gamma_t, mu, dt, skin; flavour
        "liggghts"; ``mode`` is not used: ``threads`` decides).
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    threads : 1 (serial kernels) or more (threaded kernels on that many numba threads, set around
        each call and restored; with fewer than :data:`MIN_PER_THREAD` particles per thread the
        serial kernels run, with the same result bit for bit).
    check_dt : refuse a time step above :func:`gransim.dem.stability_limit`.

    After construction (LIGGGHTS ``run`` set-up: first list build, forces without spring
    increment) :meth:`advance` steps the state. Outputs (:attr:`positions`, :attr:`velocities`,
    :attr:`spins`, :attr:`forces`, :attr:`torques`, :attr:`stress`) are in the original particle
    order and units of :class:`~gransim.dem.DEMEngine`.
    """

    def __init__(
        self,
        packing: Packing,
        settings: DEMSettings,
        velocities=None,
        spins=None,
        threads: int = 1,
        check_dt: bool = True,
    ):
        if not isinstance(packing, Packing):
            raise InputError(f"packing: expected a gransim Packing, got {type(packing).__name__}")
        if not isinstance(settings, DEMSettings):
            raise InputError(f"settings: expected a DEMSettings, got {type(settings).__name__}")
        C = packing.cell
        if C[0, 1] != 0 or C[1, 0] != 0:
            raise InputError(
                "packing.cell: the fast DEM path needs an orthogonal cell "
                f"(off-diagonal entries {C[0, 1]!r}, {C[1, 0]!r})"
            )
        if settings.flavour != "liggghts":
            raise InputError(
                f"settings.flavour: the fast DEM path implements the LIGGGHTS Hooke history "
                f"law only, expected 'liggghts', got {settings.flavour!r} (use DEMEngine)"
            )
        t = check_threads(threads)
        self._threads = 1 if t is None else t
        s = self.settings = settings
        n = self.n = packing.n
        self._parallel = self._threads > 1 and n >= MIN_PER_THREAD * self._threads
        if check_dt:
            check_time_step(packing, s.dt, s)
        self._cut = 2.0 * float(packing.radii.max()) + s.skin
        if min(C[0, 0], C[1, 1]) < 3.0 * self._cut:
            raise InputError(
                f"packing.cell: side lengths {C[0, 0]:.4g}, {C[1, 1]:.4g} m must be at least "
                f"3 (2 r_max + skin) = {3 * self._cut:.4g} m (three bins per axis)"
            )
        f64 = np.float64
        pos = np.asarray(packing.positions, f64)
        self.x = pos[:, 0].copy()
        self.y = pos[:, 1].copy()
        if velocities is None:
            self.vx, self.vy = np.zeros(n), np.zeros(n)
        else:
            v = np.asarray(velocities, f64)
            if v.shape != (n, 2):
                raise InputError(f"velocities: expected shape ({n}, 2) (m/s), got {v.shape}")
            self.vx, self.vy = v[:, 0].copy(), v[:, 1].copy()
        if spins is None:
            self.w = np.zeros(n)
        else:
            w = np.asarray(spins, f64)
            if w.shape != (n,):
                raise InputError(f"spins: expected shape ({n},) (rad/s), got {w.shape}")
            self.w = w.copy()
        self.r = np.array(packing.radii, f64)
        self.m = np.pi * self.r * self.r * float(packing.density)  # the order of DEMEngine
        self.fx, self.fy, self.t = np.zeros(n), np.zeros(n), np.zeros(n)
        self.xh, self.yh = np.zeros(n), np.zeros(n)
        self.perm = np.arange(n, dtype=np.int32)
        self.lo = np.zeros(2)
        self.hi = np.array([C[0, 0], C[1, 1]], f64)
        self.lo_hold, self.hi_hold = self.lo.copy(), self.hi.copy()
        # rebuild scratch (reused): new order, bin keys, permutation buffers
        self._order = np.zeros(n, np.int32)
        self._key = np.zeros(n, np.int32)
        self._tmpf = np.zeros(n)
        self._tmpi = np.zeros(n, np.int32)
        self._cnt = np.zeros(n, np.int32)
        self.start = np.zeros(n + 1, np.int32)
        self._binstart = np.zeros(1, np.int32)
        # the list (capacity grows) and the hand-over table
        self.nj = np.zeros(0, np.int32)
        self.code = np.zeros(0, np.uint8)
        self.ni = np.zeros(0, np.int32)
        self.hist = np.zeros((2, 0))  # rows: the two spring components (h0, h1 of fast_kernels)
        self._hstart = np.zeros(n + 1, np.int32)
        self._hj = np.zeros(0, np.int32)
        self._hh = np.zeros((0, 2))
        self._sp_j = np.zeros(0, np.int32)
        self._sp_f = np.zeros((0, 3))
        self.n_entries = 0
        self.step = 0
        self.n_rebuilds = 0
        self.n_banded_builds = 0  # threaded builds done in one pass per band (the others: count and fill)
        ny = math.floor(C[1, 1] / self._cut)
        self._rows = max(1, round(ny / TARGET_BANDS))
        self._rebuild(carry=False)
        with self._kernels():
            self._forces(update=False)
        self._vir = self._acc[:, :4].sum(axis=0)
        self._last = {"contacts": round(float(self._acc[:, 4].sum()))}

    # ------------------------------------------------------------------ internals
    @contextlib.contextmanager
    def _kernels(self):
        # the force kernel is a parallel one even when serial (fast_kernels.forces_v): one thread
        with num_threads(self._threads if self._parallel else 1), dynamic_chunks(1):
            yield

    def _forces(self, update: bool):
        L = self.hi - self.lo
        s = self.settings
        FK.forces_v(
            self._parallel,
            self.cstart,
            self.start,
            self.ni,
            self.nj,
            self.code,
            self.hist[0],
            self.hist[1],
            self.x,
            self.y,
            self.vx,
            self.vy,
            self.w,
            self.r,
            self.m,
            self.fx,
            self.fy,
            self.t,
            L[0],
            L[1],
            (s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt),
            update,
            self._sp_start,
            *self._spill(),
            self._acc,
        )

    def _rebuild(self, carry: bool):
        """Wrap, sort by bin (state and history permuted), new list in place, springs handed over
        for the pairs that touch now (as DEMEngine: LIGGGHTS' rule)."""
        n = self.n
        bad = FK.wrap(self.x, self.y, self.lo, self.hi)
        if bad >= 0:
            raise SimulationError(
                f"step {self.step}: particle {int(self.perm[bad])} lost (at "
                f"{[self.x[bad], self.y[bad]]}, box {self.lo.tolist()}..{self.hi.tolist()})"
            )
        L = self.hi - self.lo
        nbx, nby = int(L[0] // self._cut), int(L[1] // self._cut)
        if min(nbx, nby) < 3:
            raise SimulationError(
                f"step {self.step}: the box {L.tolist()} m holds fewer than 3 bins of the "
                f"cut-off {self._cut:.4g} m per axis"
            )
        if self._binstart.size < nbx * nby + 1:
            self._binstart = np.zeros(nbx * nby + 1, np.int32)
        binstart = self._binstart[: nbx * nby + 1]
        FK.bin_sort(self.x, self.y, self.lo, self.hi, nbx, nby, self._order, binstart, self._key)
        # hand-over table of the current list (old order; on the threads by the old list's bands)
        if carry and self.n_entries:
            if self._parallel:
                bcount = np.zeros(self.cstart.size - 1, np.int64)
                with self._kernels():
                    FK.history_counts(self.cstart, self.start, self.hist[0], self.hist[1], bcount)
                k = int(bcount.sum())
            else:
                k = FK.count_history(self.start, self.hist[0], self.hist[1], n)
            if self._hj.size < k:
                cap = int(k * GROWTH) + 16
                self._hj, self._hh = np.zeros(cap, np.int32), np.zeros((cap, 2))
            if self._parallel:
                with self._kernels():
                    h = (self._hstart, self._hj, self._hh)
                    FK.compact_history_banded(self.cstart, self.start, self.nj, *self.hist, bcount, *h)
            else:
                FK.compact_history(self.start, self.nj, self.hist[0], self.hist[1], n, self._hstart, self._hj, self._hh)
        else:
            self._hstart[:] = 0
        # entries per particle of each band of the last list (the threaded build sizes its regions
        # with them: the first band also holds the pairs across the periodic y boundary)
        per_band = None
        if self._parallel and self.n_entries:
            per_band = np.diff(self.start[self.cstart]) / np.maximum(np.diff(self.cstart), 1)
        o = self._order
        # each array gathered into the scratch, which then takes its place (one pass, not a gather
        # and a copy back); serial also on threads: seven short parallel regions cost more than
        # they saved (measured)
        for name in ("x", "y", "vx", "vy", "w", "r", "m"):  # f, t are zero here
            a = getattr(self, name)
            FK.gather_f(a, o, self._tmpf)
            setattr(self, name, self._tmpf)
            self._tmpf = a
        FK.permute_i(self.perm, o, self._tmpi)
        rows = self._rows
        nb = -(-nby // rows)
        self.cstart = np.ascontiguousarray(binstart[np.minimum(np.arange(nb + 1) * rows, nby) * nbx], np.int32)
        self._sp_start = np.zeros(nb + 1, np.int64)
        sp_cnt = np.zeros(nb, np.int64)
        self._acc = np.zeros((nb, 6))
        self._red = np.zeros((nb, 3))
        pairs = FK.pairs_parallel if self._parallel else FK.pairs_serial
        args = (
            self.cstart,
            binstart,
            self.x,
            self.y,
            self.r,
            self.lo,
            self.hi,
            nbx,
            nby,
            self.settings.skin,
            self._cnt,
            self.start,
        )

        def tail():  # the list buffers (replaced when they grow) and the hand-over table
            return (self.ni, self.nj, self.code, *self.hist, sp_cnt, o, self._hstart, self._hj, self._hh)

        m = -1
        if not self._parallel:  # one pass into the buffers as they are; -1: too small
            m = FK.pairs_direct(*args[:-2], self.start, *tail())
        elif per_band is not None:
            # one pass per band on the threads, each band into a region sized from the last list's
            # entries per particle of that band (of the whole list when the bands changed) times
            # BAND_SLACK plus BAND_PAD, then the bands moved together; a band that does not fit
            # sends the whole build to the count and fill passes below
            per = per_band if per_band.size == nb else np.full(nb, self.n_entries / n)
            cap = (np.diff(self.cstart) * (per * BAND_SLACK)).astype(np.int64) + BAND_PAD
            base = np.zeros(nb + 1, np.int64)
            np.cumsum(cap, out=base[1:])
            if self.nj.size < base[-1]:
                self._grow(int(base[-1] * GROWTH) + 16)
            used = np.zeros(nb, np.int64)
            with self._kernels():
                FK.pairs_banded(*args[:-2], self.start, *tail(), base, used)
            if used.min() >= 0:
                m = FK.close_gaps(self.cstart, base, used, self.start, self.ni, self.nj, self.code, *self.hist)
                self.n_banded_builds += 1
        if m < 0:
            with self._kernels():
                pairs(0, *args, *tail())  # count
                m = FK.prefix(self._cnt, self.start)
                if self.nj.size < m:
                    self._grow(int(m * GROWTH) + 16)
                pairs(1, *args, *tail())  # fill
        np.cumsum(sp_cnt, out=self._sp_start[1:])
        ns = int(self._sp_start[-1])
        if self._sp_j.size < ns:
            cap = int(ns * GROWTH) + 16
            self._sp_j, self._sp_f = np.zeros(cap, np.int32), np.zeros((cap, 3))
        self.n_entries = int(m)
        self._nspill = ns
        self.xh[:] = self.x
        self.yh[:] = self.y
        self.lo_hold[:] = self.lo
        self.hi_hold[:] = self.hi
        self.n_rebuilds += 1

    def _grow(self, cap: int):
        """New list buffers of ``cap`` entries (the old list is not needed any more: its springs
        are in the hand-over table). The old buffers are released first, so the two never
        coexist (the peak memory of a build that grows the list)."""
        self.ni = self.nj = self.code = self.hist = None
        self.ni = np.zeros(cap, np.int32)
        self.nj = np.zeros(cap, np.int32)
        self.code = np.zeros(cap, np.uint8)
        self.hist = np.zeros((2, cap))

    def _spill(self):
        return self._sp_j[: self._nspill], self._sp_f[: self._nspill]

    # ------------------------------------------------------------------ stepping
    def advance(
        self,
        nsteps: int,
        loading: Loading | None = None,
        phase_step0: int | None = None,
        phase_box0=None,
    ) -> dict:
        """Advance ``nsteps`` steps; returns per-step series as :meth:`DEMEngine.advance`.

        ``loading``: None (fixed box) or a :class:`~gransim.dem.Loading` whose axes are ``fixed``
        or ``rate`` (L = L0 + rate L0 dt (step - phase_step0) per axis, centred on the box of the
        phase start ``phase_box0`` = (lo, hi) at ``phase_step0``; defaults: this call's start).

        Returns
        -------
        dict: ``step`` (n,), ``stress`` (n, 2, 2) Love stress (compression positive, N/m in 2D,
        virial / area of the box after the step), ``lengths`` (n, 2) m, ``n_contacts`` (n,),
        ``mean_overlap`` (n,) m, ``kinetic_energy`` (n,) J, ``virial`` (n, 4) N m (xx, yy, xy,
        yx), ``rebuilds`` (int, list builds during the call).
        """
        try:
            nsteps = int(nsteps)
        except (TypeError, ValueError):
            raise InputError(f"nsteps: expected a whole number of steps >= 0, got {nsteps!r}") from None
        if nsteps < 0:
            raise InputError(f"nsteps: expected a whole number of steps >= 0, got {nsteps}")
        if loading is None:
            loading = Loading()
        if not isinstance(loading, Loading):
            raise InputError(
                f"loading: expected None or a Loading with fixed/rate axes, got "
                f"{type(loading).__name__} (a PrescribedBox needs DEMEngine)"
            )
        axes = (loading.x, loading.y)
        if any(a.mode == "servo" for a in axes):
            raise InputError(
                "loading: the fast DEM path has no stress servo (axis mode 'servo'); use "
                "'fixed' or 'rate', or DEMEngine"
            )
        modes = np.array([1 if a.mode == "rate" else 0 for a in axes], np.int64)
        rates = np.array([a.rate for a in axes], np.float64)
        step0 = self.step if phase_step0 is None else int(phase_step0)
        lo0, hi0 = (
            (self.lo.copy(), self.hi.copy())
            if phase_box0 is None
            else (
                np.array(phase_box0[0], np.float64).reshape(2),
                np.array(phase_box0[1], np.float64).reshape(2),
            )
        )
        s = self.settings
        out = np.zeros((nsteps, 9))
        done, resume, r0, first = 0, False, self.n_rebuilds, self.step
        while done < nsteps:
            sp_j, sp_f = self._spill()
            with self._kernels():
                k, status, bad = FK.run_steps(
                    self._parallel,
                    FK.FastParticles(
                        self.x, self.y, self.vx, self.vy, self.w, self.fx, self.fy, self.t, self.m, self.r,
                        self.xh, self.yh,
                    ),
                    FK.FastList(self.cstart, self.start, self.ni, self.nj, self.code, self.hist[0], self.hist[1]),
                    FK.FastBox(self.lo, self.hi, self.lo_hold, self.hi_hold, modes, rates, lo0, hi0, step0),
                    (s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt),
                    s.skin,
                    FK.FastScratch(self._sp_start, sp_j, sp_f, self._acc, self._red),
                    out[done:],
                    self.step,
                    nsteps - done,
                    resume,
                )  # fmt: skip
            done += k
            self.step += k
            if status == 1:
                self._rebuild(carry=True)
                resume = True
            elif status == 2:
                raise SimulationError(f"step {self.step + 1}: particle {int(self.perm[bad])} has a non-finite position")
            else:
                resume = False
        area = out[:, 6] * out[:, 7]
        st = np.empty((nsteps, 2, 2))
        st[:, 0, 0] = out[:, 0] / area
        st[:, 1, 1] = out[:, 1] / area
        st[:, 0, 1] = out[:, 2] / area
        st[:, 1, 0] = out[:, 3] / area
        if nsteps:
            self._vir = out[-1, :4].copy()
            self._last = {"contacts": round(float(out[-1, 4]))}
        nc = out[:, 4]
        return {
            "step": np.arange(first + 1, first + nsteps + 1),
            "stress": st,
            "lengths": out[:, 6:8].copy(),
            "n_contacts": np.rint(nc).astype(np.int64),
            "mean_overlap": np.divide(out[:, 5], nc, out=np.zeros(nsteps), where=nc > 0),
            "kinetic_energy": out[:, 8].copy(),
            "virial": out[:, :4].copy(),
            "rebuilds": self.n_rebuilds - r0,
        }

    # ------------------------------------------------------------------ outputs (original order)
    def _orig(self, *arrays) -> np.ndarray:
        out = np.empty((self.n, len(arrays)))
        col = np.empty(self.n)
        for k, a in enumerate(arrays):
            FK.unsort_f(a, self.perm, col)
            out[:, k] = col
        return out

    @property
    def positions(self) -> np.ndarray:
        """(N, 2) m, original particle order, inside the box [lo, hi) after the last list build."""
        return self._orig(self.x, self.y)

    @property
    def velocities(self) -> np.ndarray:
        """(N, 2) m/s, original order."""
        return self._orig(self.vx, self.vy)

    @property
    def spins(self) -> np.ndarray:
        """(N,) rad/s, original order."""
        return self._orig(self.w)[:, 0]

    @property
    def forces(self) -> np.ndarray:
        """(N, 2) N of the last step, original order."""
        return self._orig(self.fx, self.fy)

    @property
    def torques(self) -> np.ndarray:
        """(N,) N m of the last step, original order."""
        return self._orig(self.t)[:, 0]

    @property
    def box_lengths(self) -> np.ndarray:
        return self.hi - self.lo

    @property
    def stress(self) -> np.ndarray:
        """Love stress of the last step (2, 2), compression positive (N/m in 2D), as DEMEngine.stress."""
        L = self.box_lengths
        v = self._vir / (L[0] * L[1])
        return np.array([[v[0], v[2]], [v[3], v[1]]])

    @property
    def n_contacts(self) -> int:
        return self._last["contacts"]

    def kinetic_energy(self) -> float:
        """Translational + rotational (I = m r^2/2) kinetic energy (J)."""
        return float(0.5 * np.sum(self.m * (self.vx**2 + self.vy**2)) + 0.25 * np.sum(self.m * self.r**2 * self.w**2))

    def memory_bytes(self) -> dict:
        """Bytes held by the engine's arrays: particles, list (capacity), hand-over table, rest."""
        part = sum(
            a.nbytes
            for a in (
                self.x,
                self.y,
                self.vx,
                self.vy,
                self.w,
                self.fx,
                self.fy,
                self.t,
                self.r,
                self.m,
                self.xh,
                self.yh,
                self.perm,
            )
        )
        lst = self.ni.nbytes + self.nj.nbytes + self.code.nbytes + self.hist.nbytes + self.start.nbytes
        hand = self._hj.nbytes + self._hh.nbytes + self._hstart.nbytes
        rest = sum(
            a.nbytes
            for a in (
                self._order,
                self._key,
                self._tmpf,
                self._tmpi,
                self._cnt,
                self._binstart,
                self._sp_j,
                self._sp_f,
            )
        )
        return {"particles": part, "list": lst, "hand_over": hand, "scratch": rest}


__all__ = ["FastEngine", "dynamic_chunks"]
