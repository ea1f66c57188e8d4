"""The DEM engine: disks in an orthogonal periodic cell whose side lengths change each step.

It follows the step of LIGGGHTS-PUBLIC 3.8.0 (serial, ``newton off``, ``neigh_modify delay 0
every 1 check yes``, ``fix deform ... remap x``; docs/liggghts.md), which LAMMPS 29 Sep 2021 shares,
so that, with the same settings, trajectories agree with either code to round-off:
``DEMSettings.flavour`` picks the code's contact-law arithmetic and rebuild rule ("liggghts", the
default, or "lammps": docs/lammps.md). Step n:

1. nve/sphere first half step (kernels.initial_integrate);
2. neighbour check with the skin and the box displacement; on a rebuild: wrap into the box,
   new list, tangential springs carried over only for pairs that overlap at that moment;
3. forces with image positions from the current box (= the box of step n-1), virial;
4. second half step;
5. loading: the box moves to its value at step n (servo uses the stress of step n divided by
   the area of box n-1, as a ``fix ave/time`` of ``compute pressure`` evaluated before
   ``fix deform``), positions remapped affinely;
6. stress of step n = virial / area of box n (the thermo of either code at step n).
"""

from __future__ import annotations

import ctypes
import hashlib

import numpy as np

from .._numba import check_threads, disk_cache_off, num_threads
from ..contacts.laws import elastic_energy, flip_signs, law_spec, time_scale
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import kernels as K
from .settings import AxisControl, DEMSettings, Integration, Loading, PrescribedBox

#: the time step must not exceed contact time / this (stability of the rotational + normal modes)
STEPS_PER_CONTACT_MIN = 5.0

#: divergence: the kinetic energy may not exceed this many times the energy the run has had
#: (initial kinetic + elastic energy plus the gross work of the cell); see DEMEngine.advance
KINETIC_ENERGY_FACTOR = 10.0

#: a lost particle: moved more than this many skins since the last neighbour build (the list
#: allows skin/2 between builds, so the step that triggered the build moved it > 1 skin)
LOST_DISPLACEMENT_SKINS = 1.5


def contact_time(packing: Packing, kn: float) -> float:
    """Duration of an undamped normal contact of the two lightest disks: pi sqrt(m_eff/kn) (s)."""
    m = np.sort(packing.masses)
    meff = m[0] * m[1] / (m[0] + m[1])
    return float(np.pi * np.sqrt(meff / kn))


def _law_of(law_or_settings):
    """A law object: ``law_or_settings`` itself, or the Hooke law of a :class:`DEMSettings`."""
    if isinstance(law_or_settings, DEMSettings):
        return law_or_settings.hooke_law()
    return law_or_settings


def damping_ratio(packing: Packing, law, overlap: float = 0.0) -> float:
    """Damping ratio zeta of the contact of the two lightest disks (dimensionless), as the law
    ``law`` declares it (:func:`gransim.contacts.laws.time_scale`; a :class:`DEMSettings`: its
    Hooke law, zeta = max(gamma_n, gamma_t)/(2 omega), omega = sqrt(max(kn, kt)/m_eff)), at the
    largest overlap ``overlap`` (m) present (a law whose stiffness depends on it: Hertz)."""
    return time_scale(_law_of(law), packing, overlap)[1]


def stability_limit(packing: Packing, law, overlap: float = 0.0) -> float:
    """Largest accepted time step (s): t_c / STEPS_PER_CONTACT_MIN * (sqrt(1 + zeta^2) - zeta), with
    the contact time t_c and the damping ratio zeta that the law ``law`` declares for the two
    lightest disks at the largest overlap ``overlap`` (m) present (:func:`gransim.contacts.laws.
    time_scale`; a :class:`DEMSettings` stands for its Hooke law: t_c = pi sqrt(m_eff/max(kn, kt))).

    Derivation. The engine integrates as LIGGGHTS' nve/sphere: v(n+1/2) = v(n) + dt f(n)/2m,
    x(n+1) = x(n) + dt v(n+1/2), f(n+1) = -k x(n+1) - c v(n+1/2) (the damping sees the half-step
    velocity), v(n+1) = v(n+1/2) + dt f(n+1)/2m. For one damped spring (omega^2 = k/m_eff,
    c/m_eff = 2 zeta omega, h = omega dt, b = 2 zeta h) the map of (x(n+1), v(n+1/2)) has the
    matrix [[1 - h^2, dt (1 - b)], [-omega^2 dt, 1 - b]]: trace T = 2 - h^2 - b, determinant
    D = 1 - b. Both roots of l^2 - T l + D lie in the unit disk (Jury) iff |D| < 1 and
    1 + T + D > 0, i.e. b < 2 and h^2 + 4 zeta h - 4 < 0, so the critical step is

        dt_c = (2/omega) (sqrt(1 + zeta^2) - zeta)     (b < 2 then holds too)

    (2/omega without damping; the known limit of the central-difference method with viscous
    damping, Belytschko, Liu & Moran, "Nonlinear finite elements for continua and structures",
    2000, chapter 6). The accepted step keeps the margin of the undamped engine:
    (pi/5)/omega = contact_time/5 = 0.314 dt_c(zeta = 0), times the damping factor. The margin
    covers the tangential spring acting on the rotation (effective mass m_eff/3 for disks,
    frequency sqrt(3) omega, damping ratio sqrt(3) zeta): (pi/5) g(zeta) <= (2/sqrt 3) g(sqrt 3 zeta)
    for every zeta >= 0, g(z) = sqrt(1 + z^2) - z. The lightest pair gives the smallest limit
    (dt_c grows with 1/omega at fixed gamma). A Hertz law linearised at the overlap: its tangent
    stiffness (docs/laws.md).
    """
    tc, z = time_scale(_law_of(law), packing, overlap)
    return tc / STEPS_PER_CONTACT_MIN * (float(np.sqrt(1.0 + z * z)) - z)


def check_time_step(packing: Packing, dt: float, law, overlap: float = 0.0) -> None:
    """InputError when ``dt`` (s) is above :func:`stability_limit` of ``law`` (the check of every
    engine, before any step), naming the law's contact time and damping ratio."""
    law = _law_of(law)
    tc, z = time_scale(law, packing, overlap)
    lim = stability_limit(packing, law, overlap)
    if dt > lim:
        at = f" at the largest overlap {overlap:.4g} m" if overlap > 0 else ""
        raise InputError(
            f"dt = {dt:.4g} s is above the stability limit {lim:.4g} s "
            f"(contact time {tc:.4g} s of the two lightest disks with the law {type(law).__name__}{at}, "
            f"/ {STEPS_PER_CONTACT_MIN:g}, times sqrt(1 + zeta^2) - zeta = {np.sqrt(1 + z * z) - z:.4g} "
            f"for the damping ratio zeta = {z:.4g})"
        )


def fingerprint(packing: Packing, settings_text: str) -> str:
    """sha256 of the initial packing and of the settings text: identifies a run."""
    h = hashlib.sha256()
    for a in (packing.positions, packing.radii, packing.cell):
        h.update(np.ascontiguousarray(a, np.float64).tobytes())
    h.update(repr(float(packing.density)).encode())
    h.update(settings_text.encode())
    return h.hexdigest()


def _check_box(box, C):
    """(lo, hi) float64 (2,) of the ``box`` argument, checked against the cell ``C``."""
    try:
        lo, hi = (np.array(b, np.float64).reshape(2) for b in box)
    except (TypeError, ValueError):
        raise InputError(f"box: expected (lo, hi) with two numbers each (m), got {box!r}") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise InputError(f"box: expected finite lo < hi, got lo {lo.tolist()}, hi {hi.tolist()}")
    L = np.array([C[0, 0], C[1, 1]], np.float64)
    if np.any(np.abs((hi - lo) - L) > 1e-12 * L):
        raise InputError(f"box: hi - lo = {(hi - lo).tolist()} m differs from the cell's side lengths {L.tolist()} m")
    return lo, hi


def _c_malloc_trim():
    """The C library's ``malloc_trim`` (glibc), or None where there is none."""
    try:
        fn = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return fn


_MALLOC_TRIM = _c_malloc_trim()


def release_free_memory() -> None:
    """Hand the heap's free pages back to the system (glibc ``malloc_trim(0)``; elsewhere nothing).

    A list rebuild frees arrays of 3-21 MiB at 1e6 disks and allocates new ones of about the same
    sizes; glibc serves arrays below its (rising) mmap threshold from the heap, whose freed pages
    stay resident, so the peak memory grew by about 80 MiB over 13 rebuilds. Called at the steps
    of a rebuild where the most memory has just been freed, it keeps the peak at the live arrays
    (docs/performance.md, "The bitwise engine's memory"). It frees nothing that is in use and
    changes no result. Also after the energy budget of the divergence check (its gathered
    contact arrays)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


#: contacts per call of the law's energy (:meth:`DEMEngine.elastic_energy`)
ENERGY_CHUNK = 1 << 16

#: the Neighbours field ``shift`` of the engine's lists (the shifts are kept as floats only)
_NO_SHIFT = np.zeros((0, 2), np.int64)


class EngineCore:
    """What the engines of :mod:`gransim.dem` (:class:`DEMEngine`, the orthogonal cell, and
    :class:`gransim.dem.sheared.ShearEngine`, the sheared one) do the same way, written once: the
    contact law and its time-step check, the kinetic and elastic energies, the divergence check
    (energy balance) and the lost-particle check.

    A subclass holds ``packing``, ``settings``, ``law``, ``step``, ``_build_step`` and the state
    ``p`` (:class:`~gransim.dem.kernels.Particles`) and ``nb`` (``Neighbours``), whose arrays the
    views below name (x, v, w, ..., ea, eb, xi, ...), and defines ``_touching()`` -> (entries of
    the touching pairs, each once, and their overlaps (m)) for its cell.
    """

    def _set_law(self, packing: Packing, settings, law, flavour: str, check_dt: bool) -> None:
        """``law`` (None: the Hooke law of a :class:`DEMSettings` in ``flavour``) with what the
        loops need of its registration (history width, flip signs, disk cache), its time step
        checked (:func:`check_time_step`, at zero overlap: :meth:`_check_time_step_now` checks a
        law whose stiffness grows with the overlap once the state is set up)."""
        if law is None:
            if not isinstance(settings, DEMSettings):
                raise InputError("law: an engine with Integration settings needs its contact law (law=...)")
            law = settings.hooke_law(flavour)
        spec = law_spec(law)  # InputError for an unregistered law
        if check_dt:
            check_time_step(packing, settings.dt, law)
        self.law = law
        self._check_dt = bool(check_dt)
        self._width = spec.width
        self._flip = flip_signs(law)
        # kernels compiled for a law of a test module / script stay out of the disk cache
        self._no_cache = not spec.cache

    def _check_time_step_now(self) -> None:
        """After the set-up: a law that sets no limit at zero overlap (Hertz) is checked at the
        largest overlap present (:func:`check_time_step`)."""
        if self._check_dt and not np.isfinite(time_scale(self.law, self.packing)[0]):
            _, ov = self._touching()
            check_time_step(self.packing, self.settings.dt, self.law, float(ov.max()) if ov.size else 0.0)

    def kinetic_energy(self) -> float:
        """Translational + rotational (I = m r^2/2) kinetic energy (J) of the velocities held (the
        lab frame)."""
        return float(
            0.5 * np.sum(self.m * np.einsum("ij,ij->i", self.v, self.v)) + 0.25 * np.sum(self.m * self.r**2 * self.w**2)
        )

    def elastic_energy(self) -> float:
        """Energy stored in the touching contacts (J): the law's ``energy`` with each contact's
        overlap, history and radii (:func:`gransim.contacts.laws.elastic_energy`; Hooke: sum 0.5 kn
        overlap^2 + 0.5 kt |xi|^2, Hertz: 8/15 Y* sqrt(R*) delta^(5/2) + k_t(delta) |xi|^2/2, the
        rolling laws add their rolling spring; docs/laws.md)."""
        e, ov = self._touching()
        # in chunks of ENERGY_CHUNK contacts (the law's energy takes gathered (K,) arrays: at 1e6
        # disks all of them at once were the peak memory of a run); one chunk: the plain sum
        total = 0.0
        for k in range(0, e.size, ENERGY_CHUNK):
            c = e[k : k + ENERGY_CHUNK]
            total += elastic_energy(
                self.law, ov[k : k + ENERGY_CHUNK], self.xi[c], self.r[self.ea[c]], self.r[self.eb[c]]
            )
        return total

    def _budget_kinetic_energy(self) -> float:
        """The kinetic energy the divergence check bounds (J): :meth:`kinetic_energy` of the
        velocities held (a sheared cell: of the velocities relative to its homogeneous flow)."""
        return self.kinetic_energy()

    def _reset_energy_budget(self):
        """Start of the energy balance of the divergence check: E0 = kinetic + elastic energy now."""
        e0 = self._budget_kinetic_energy() + self.elastic_energy()
        release_free_memory()  # the gathered contact arrays of the energy
        self._energy0 = e0 if np.isfinite(e0) else np.inf  # a non-finite state is caught as NaN
        self._work = 0.0

    def _check_energy(self, step1, ke_all, ke, dw, flow=0.0):
        """Kinetic-energy blow-up over the completed steps step1, step1 + 1, ... (divergence check).

        ``ke_all`` (n,): the kinetic energy (J) of each step (checked finite); ``ke`` (n,): the
        kinetic energy the check bounds at each step, NaN where not known (a sheared cell knows
        the one relative to its flow at the last step only); ``dw`` (n,): the work of the cell in
        each step (J); ``flow`` (J): the kinetic energy of the cell's homogeneous flow at the
        particles (a sheared cell: disks at rest in the lab move relative to the flow with it, and
        a flow that changes, ``fix deform trate``, changes it without any work), added to the
        budget.

        Energy balance of the run: d(KE + U)/dt = P_cell - D with D >= 0 (viscous damping and
        Coulomb sliding only dissipate, U >= 0 the spring energy), so KE(n) <= E0 + W(n), E0 the
        kinetic + elastic energy at the start and W the work of the cell. The check sums |work|
        (tangential springs do not follow the affine remap exactly, so the virial work is only
        close to the true one) and allows KINETIC_ENERGY_FACTOR times that budget: velocity Verlet
        below its stability limit keeps the energy within a few ten percent (shadow energy), an
        unstable integration grows exponentially and crosses it in a few steps.
        """
        if not np.all(np.isfinite(ke_all)):
            k = int(np.flatnonzero(~np.isfinite(ke_all))[0])
            bad = np.flatnonzero(~np.all(np.isfinite(self.v), axis=1))
            who = f" (particle {int(bad[0])} has velocity {self.v[bad[0]].tolist()})" if bad.size else ""
            raise SimulationError(f"step {step1 + k}: the kinetic energy is not finite{who}")
        work = self._work + np.cumsum(np.abs(dw))
        budget = KINETIC_ENERGY_FACTOR * (self._energy0 + work + flow)
        over = np.flatnonzero(ke > budget)
        if over.size:
            k = int(over[0])
            raise SimulationError(
                f"step {step1 + k}: kinetic energy blow-up: {ke[k]:.4g} J exceeds {KINETIC_ENERGY_FACTOR:g} "
                f"times the energy the run has had ({self._energy0:.4g} J kinetic + elastic at the start, "
                f"{work[k]:.4g} J gross work of the cell"
                + (f", {flow:.4g} J kinetic energy of the cell's flow" if flow else "")
                + "; damping and friction only dissipate): the "
                f"integration is unstable (time step {self.settings.dt:.4g} s too large for the stiffness "
                "and damping?)"
            )
        if work.size:
            self._work = float(work[-1])

    def _check_lost(self):
        """Before a rebuild: a particle that moved more than LOST_DISPLACEMENT_SKINS skins since the
        last build crossed more than a skin in one step (the build rule allows skin/2 in between)."""
        i, di = K.largest_displacement(self.x, self.xhold)
        skin = self.settings.skin
        if di > LOST_DISPLACEMENT_SKINS * skin:
            raise SimulationError(
                f"step {self.step + 1}: particle {i} lost: it moved {di:.4g} m = {di / skin:.3g} "
                f"skins since the neighbour build of step {self._build_step}, more than a skin "
                f"({skin:.4g} m) in one step (velocity {self.v[i].tolist()} m/s, dt {self.settings.dt:.4g} s)"
            )

    # ------------------------------------------------------------------ views of the state
    # ``p`` (:class:`~gransim.dem.kernels.Particles`) and ``nb`` (``Neighbours``: the list, the
    # law's history, CSR, build positions, per-entry outputs), the state of every engine
    x = property(lambda self: self.p.x, doc="positions (N, 2), m")
    v = property(lambda self: self.p.v, doc="velocities (N, 2), m/s")
    w = property(lambda self: self.p.w, doc="spins (N,), rad/s")
    f = property(lambda self: self.p.f, doc="forces of the last step (N, 2), N")
    t = property(lambda self: self.p.t, doc="torques of the last step (N,), N m")
    m = property(lambda self: self.p.m, doc="masses (N,), kg")
    r = property(lambda self: self.p.r, doc="radii (N,), m")
    xhold = property(lambda self: self.nb.xhold, doc="positions at the last neighbour build (N, 2), m")
    ea = property(lambda self: self.nb.a, doc="first particle of each list entry (M,) int32")
    eb = property(lambda self: self.nb.b, doc="second particle of each list entry (M,) int32")
    esx = property(lambda self: self.nb.sx, doc="s_x as float64 (M,)")
    esy = property(lambda self: self.nb.sy, doc="s_y as float64 (M,)")
    both = property(lambda self: self.nb.both, doc="owned pair (force on both particles) (M,) bool")
    xi = property(lambda self: self.nb.hist, doc="per-entry history of the law (M, width); Hooke: the spring, m")
    slide = property(lambda self: self.nb.slide, doc="Coulomb cap active at the last stored step (M,) bool")
    ef = property(lambda self: self.nb.ef, doc="force on a of each entry at the last stored step (M, 2), N")
    start = property(lambda self: self.nb.start, doc="CSR offsets of the entries of each a (N+1,)")


class DEMEngine(EngineCore):
    """State and stepping of one DEM run (arrays are updated in place for speed).

    Parameters
    ----------
    packing : initial packing (orthogonal cell; the box is [0, Lx] x [0, Ly] as in the
        LIGGGHTS data file gransim writes, unless ``box`` is given).
    settings : :class:`~gransim.dem.settings.Integration` (dt, skin, mode, flavour) with a ``law``,
        or :class:`DEMSettings` (the integration and the parameters of its Hooke law).
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    threads : numba threads of mode "parallel" (None: numba's current count), set around each kernel
        call and restored afterwards, so an engine leaves the process's thread count alone; one
        thread when the packing fits in one task (``kernels.PARTICLE_BLOCK`` disks), which gives
        the same result.
    box : optional (lo, hi), each (2,) (m): the box with its own origin, as a data file's ``xlo xhi
        ylo yhi`` (the positions are taken as they are, in that box; no translation, which would
        round them). hi - lo must equal the diagonal of ``packing.cell`` (to 1e-12 relative).
    law : optional contact law object (an instance of a class registered with
        :func:`gransim.contacts.laws.register_law`); None: the Hooke law of a :class:`DEMSettings`
        in its ``flavour`` (:meth:`DEMSettings.hooke_law`). The time-step check (``check_dt``,
        :func:`check_time_step`) asks the law for its contact time and damping ratio, at the
        largest overlap after the set-up for a law whose stiffness depends on it (Hertz).

    State: ``p`` (:class:`~gransim.dem.kernels.Particles`), ``nb`` (``Neighbours``: list, history of
    the law's width, CSR), ``box`` (``Box``), ``sc`` (``Scratch``: the virial), small namedtuples of
    arrays updated in place by the kernels (a rebuild replaces ``nb``); :meth:`state_arrays` /
    :meth:`restore` save and load them. Attributes (after construction = LIGGGHTS ``run`` set-up:
    forces evaluated without spring increment): x, v, w, f, t, lo, hi, step, stress, virial (views of
    those objects' arrays).
    """

    def __init__(
        self,
        packing: Packing,
        settings: DEMSettings,
        velocities=None,
        spins=None,
        threads: int | None = None,
        check_dt: bool = True,
        box=None,
        law=None,
    ):
        C = packing.cell
        if C[0, 1] != 0 or C[1, 0] != 0:
            raise InputError(
                f"packing.cell: the DEM engine needs an orthogonal cell (off-diagonal entries {C[0, 1]!r}, {C[1, 0]!r})"
            )
        self.packing = packing
        self.settings = s = settings
        n = packing.n
        # the contact law (gransim.contacts.laws): the Hooke law of DEMSettings unless given
        self._set_law(packing, s, law, s.flavour, check_dt)
        cut = 2 * 2.0 * float(packing.radii.max()) + 2 * s.skin
        if min(C[0, 0], C[1, 1]) <= cut:
            raise InputError(
                f"packing.cell: side lengths {C[0, 0]:.4g}, {C[1, 1]:.4g} m must exceed "
                f"2 (2 r_max + skin) = {cut:.4g} m (one periodic image per pair)"
            )
        r = np.ascontiguousarray(packing.radii, np.float64)
        # ((pi r) r) rho: the order LIGGGHTS uses reading the data file (Packing.masses may differ
        # in the last bit)
        m = np.pi * r * r * float(packing.density)
        x = np.array(packing.positions, np.float64)
        v = np.zeros((n, 2)) if velocities is None else np.array(velocities, np.float64).reshape(n, 2)
        w = np.zeros(n) if spins is None else np.array(spins, np.float64).reshape(n)
        self.p = K.Particles(x, v, w, np.zeros((n, 2)), np.zeros(n), m, r)
        lo = np.zeros(2)
        hi = np.array([C[0, 0], C[1, 1]], np.float64)
        if box is not None:
            lo, hi = _check_box(box, C)
        self.box = K.Box(lo, hi, lo.copy(), hi.copy())
        self.step = 0
        self.n_contacts = 0
        self.mean_overlap = 0.0
        self.n_rebuilds = 0
        self._parallel = s.mode == "parallel"
        # the rebuild rule of LAMMPS (check_rebuild clamp; DEMSettings.flavour, docs/lammps.md)
        self._clamp = s.flavour == "lammps"
        # numba threads of this engine's kernels, set around each call and restored after; serial
        # mode on one: its SIMD force loop (kernels._serial_block_loop) is a one-iteration parallel
        # loop, and a second OpenMP thread would spin-wait beside every step (libgomp's default
        # policy), burning a core that the user's other work (the codes' jobs) needs
        self._threads = check_threads(threads) if self._parallel else 1
        # (numba's static schedule: the tasks handed out dynamically, gransim._numba.dynamic_chunks,
        # made the step 1.3x and the threaded list build 3x slower at 1e5 disks, measured)
        if self._parallel and n <= K.PARTICLE_BLOCK:
            # one task of the threaded kernels: the result is the same on any thread count, and a
            # second thread would only wait at every loop's end (0.6x of one thread at 1,020 disks)
            self._threads = 1
        # the per-particle sums of the threaded loop exist in mode "parallel" only
        m = n if self._parallel else 0
        self.sc = K.Scratch(np.zeros(4), np.zeros((m, 4)), np.zeros((m, 2)))
        self.nb = self._neighbours(
            np.zeros(0, np.int32),
            np.zeros(0, np.int32),
            np.zeros((0, 2), np.int64),
            np.zeros(0, np.bool_),
            np.zeros((0, self._width)),
            x.copy(),
        )
        self._build_step = 0
        self._failed = ""  # why a rebuild failed (the engine has no list then), or ""
        self._setup()
        self._check_time_step_now()
        self._reset_energy_budget()

    # ------------------------------------------------------------------ neighbours
    @property
    def box_lengths(self) -> np.ndarray:
        return self.hi - self.lo

    @property
    def cell(self) -> np.ndarray:
        L = self.box_lengths
        return np.diag(L)

    def _neighbours(self, a, b, shift, both, hist, xhold, sx=None, sy=None):
        """A :class:`~gransim.dem.kernels.Neighbours` of the list (a, b, shift, both) with history
        ``hist`` and build positions ``xhold``: the image shifts as floats ``sx``, ``sy`` (given by
        the list build; else from the integer ``shift`` (M, 2), a checkpoint's), CSR offsets of
        the entries of each a (sorted by a), the incoming CSR and the per-entry torques of the
        threaded loop (mode "parallel" only), zeroed per-entry outputs."""
        n = self.packing.n
        if sx is None:  # from the integer shifts (a checkpoint)
            shift = np.ascontiguousarray(shift, np.int64).reshape(-1, 2)
            sx = np.ascontiguousarray(shift[:, 0], np.float64)
            sy = np.ascontiguousarray(shift[:, 1], np.float64)
        start = np.zeros(n + 1, np.int64)  # CSR offsets of the entries of each a (sorted)
        np.cumsum(np.bincount(a, minlength=n), out=start[1:])
        if self._parallel:
            with num_threads(self._threads):
                in_start, in_e = K.incoming(b, both, n)
        else:
            in_start, in_e = np.zeros(n + 1, np.int64), np.zeros(0, np.int64)
        return K.Neighbours(
            a,
            b,
            _NO_SHIFT,  # the integer shifts are sx, sy (:attr:`eshift`): not stored twice
            sx,
            sy,
            both,
            hist,
            start,
            in_start,
            in_e,
            xhold,
            np.zeros(a.size, np.bool_),
            np.zeros((a.size, 2)),
            np.zeros(a.size if self._parallel else 0),
        )

    def _rebuild(self, carry: bool):
        bad = K.pbc_wrap(self.x, self.lo, self.hi)
        if bad >= 0:
            raise SimulationError(
                f"step {self.step}: particle {bad} lost (at {self.x[bad].tolist()}, "
                f"box {self.lo.tolist()}..{self.hi.tolist()})"
            )
        L = self.box_lengths
        # the old list keeps only what the hand-over reads (CSR, partners, owned flags, history):
        # its other arrays and the build positions are released before the new list exists (the
        # peak memory of a run at 1e6 disks is a rebuild's). A SimulationError below leaves the
        # engine without a list: advance refuses it until restore (``_failed``)
        old = self.nb
        keep = (old.start, old.b, old.both, old.hist) if carry and old.a.size else None
        z = np.zeros(0)
        self.nb = old = old._replace(
            a=np.zeros(0, old.a.dtype), shift=np.zeros((0, 2), np.int64), sx=z, sy=z,
            in_e=np.zeros(0, np.int64), slide=np.zeros(0, np.bool_), ef=np.zeros((0, 2)), tb=z,
            xhold=np.zeros((0, 2)),
        )  # fmt: skip
        release_free_memory()  # the old list's released arrays
        with num_threads(self._threads):  # mode "parallel": the pair passes on the threads
            a, b, esx, esy, both, selfimg = K.build_list_liggghts(
                self.x, self.r, self.lo, self.hi, self.settings.skin, self._parallel
            )
        if selfimg != -1:
            self._failed = (
                f"step {self.step}: particle {selfimg} is near its own image (or too many ghosts); "
                "the cell is too small"
            )
            raise SimulationError(self._failed)
        release_free_memory()  # the build's ghosts and bins
        hist = np.zeros((a.size, self._width))
        if keep is not None:
            K.hand_over_history(self.x, self.r, a, b, esx, esy, L[0], L[1], *keep, hist, self._flip)
        del old, keep
        self.nb = None
        release_free_memory()  # the rest of the old list
        self.nb = self._neighbours(a, b, None, both, hist, self.x.copy(), esx, esy)
        release_free_memory()  # the new list's temporaries
        self.box.lo_hold[:] = self.lo
        self.box.hi_hold[:] = self.hi
        self._build_step = self.step
        self.n_rebuilds += 1

    def _forces(self, update: bool):
        dt = self.settings.dt
        L = self.box_lengths
        if self._parallel:
            with num_threads(self._threads), disk_cache_off(self._no_cache):
                K.forces_threaded(self.p, self.nb, self.law, L[0], L[1], dt, update, self.sc.pvir, self.sc.pcont, True)
            self.virial[:] = self.sc.pvir.sum(axis=0)
            nc, so = self.sc.pcont.sum(axis=0)
        else:
            with disk_cache_off(self._no_cache):
                nc, so = K.forces(self.p, self.nb, self.law, L[0], L[1], dt, update, self.virial, True)
        self.n_contacts = round(nc)
        self.mean_overlap = so / nc if nc else 0.0

    def _check_divergence(self, step1, ke, stress, lengths, L_before):
        """The divergence check (:meth:`EngineCore._check_energy`) over the completed steps step1,
        step1 + 1, ... with the work of the orthogonal cell per step -(V_xx dLx/Lx + V_yy dLy/Ly),
        V the virial (stress (n, 4) times the area of the box lengths ``lengths`` (n, 2) after each
        step, compression positive; ``L_before`` the lengths before the first)."""
        L_old = np.vstack([L_before[None], lengths[:-1]])
        area = lengths[:, 0] * lengths[:, 1]
        dw = -(
            stress[:, 0] * area * (lengths[:, 0] - L_old[:, 0]) / L_old[:, 0]
            + stress[:, 1] * area * (lengths[:, 1] - L_old[:, 1]) / L_old[:, 1]
        )
        self._check_energy(step1, ke, ke, dw)

    def _setup(self):
        """LIGGGHTS ``run`` set-up: wrap, build (springs zero), forces without spring increment."""
        self._rebuild(carry=False)
        self._forces(update=False)
        self.stress = self.stress_tensor(self.box_lengths)

    # ------------------------------------------------------------------ stepping
    def stress_tensor(self, L) -> np.ndarray:
        """Love stress (eq 17 of Kuhn 002), compression positive, (2, 2):
        sigma_ab = (1/(Lx Ly)) sum_c d_a f_b, d = x_i - x_j, f the force on i. Not symmetric out of
        equilibrium; [0, 1] = sum d_x f_y is LIGGGHTS' ``compute pressure`` component 4 (xy)."""
        inv = 1.0 / (L[0] * L[1])
        v = self.virial
        return np.array([[v[0] * inv, v[2] * inv], [v[3] * inv, v[1] * inv]])

    def advance(self, loading: Loading, nsteps: int = 1, phase_step0: int = 0, phase_box0=None):
        """Advance ``nsteps`` steps under ``loading``; returns a dict of per-step series.

        ``loading``: a :class:`Loading` (each axis fixed, at a rate or under a servo) or a
        :class:`PrescribedBox` (the box of every step from a table; its rows must cover steps
        step + 1 .. step + nsteps). ``phase_step0`` and ``phase_box0`` = (lo, hi): step and box at
        the start of the loading phase (LIGGGHTS ``fix deform`` lo_start/hi_start: rate control
        measures its displacement from there, the servo its accumulated change; not used by a
        PrescribedBox).

        Returns
        -------
        dict with ``step`` (n,), ``stress`` (n, 2, 2) (Love stress, compression positive, area of
        the box after the step), ``lengths`` (n, 2), ``n_contacts`` (n,), ``mean_overlap`` (n,),
        ``kinetic_energy`` (n,),
        ``virial`` (n, 4) (xx, yy, xy, yx: sum d_a f_b, N m in 2D; stress times area).

        Raises
        ------
        SimulationError naming the step and the particle, on a divergence: a non-finite position or
        kinetic energy; a kinetic-energy blow-up (more than KINETIC_ENERGY_FACTOR times the energy
        balance allows, :meth:`_check_divergence`); a lost particle (moved more than
        LOST_DISPLACEMENT_SKINS skins since the last neighbour build, or left the box by more than a
        cell); a collapsed cell. These checks only read the state: the step's arithmetic is untouched.
        """
        s = self.settings
        if self._failed:
            raise SimulationError(
                f"the engine stopped at a failed neighbour build ({self._failed}); restore a "
                "checkpoint or make a new engine"
            )
        nsteps = int(nsteps)
        if phase_box0 is None:
            phase_box0 = (self.lo.copy(), self.hi.copy())
        lo0 = np.array(phase_box0[0], np.float64)
        hi0 = np.array(phase_box0[1], np.float64)
        ctl = _control(loading, self.step, nsteps, lo0, hi0, phase_step0)
        out = K.Series(
            np.zeros((nsteps, 4)),
            np.zeros((nsteps, 2)),
            np.zeros(nsteps),
            np.zeros(nsteps),
            np.zeros(nsteps),
            np.zeros((nsteps, 4)),
        )
        out_stress, out_L, out_nc, out_ov, out_ke, out_vir = out
        done = 0
        resume = False
        step_start = self.step
        while done < nsteps:
            L_before = self.box_lengths.copy()
            with num_threads(self._threads), disk_cache_off(self._no_cache):
                k, status, bad = K.run_block(
                    self.p,
                    self.nb,
                    self.box,
                    ctl,
                    self.law,
                    self.sc,
                    K.Series(*(a[done:] for a in out)),
                    s.dt,
                    s.skin,
                    self._clamp,
                    self._parallel,
                    self.step,
                    nsteps - done,
                    resume,
                )
            if k:
                self._check_divergence(
                    self.step + 1,
                    out_ke[done : done + k],
                    out_stress[done : done + k],
                    out_L[done : done + k],
                    L_before,
                )
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
                raise SimulationError(f"step {self.step + 1}: the cell collapsed")
        if nsteps:
            self.n_contacts = round(out_nc[-1])
            self.mean_overlap = float(out_ov[-1])
            self.stress = self.stress_tensor(self.box_lengths)
        st = np.empty((nsteps, 2, 2))
        st[:, 0, 0] = out_stress[:, 0]
        st[:, 1, 1] = out_stress[:, 1]
        st[:, 0, 1] = out_stress[:, 2]
        st[:, 1, 0] = out_stress[:, 3]
        return {
            "step": np.arange(step_start + 1, step_start + nsteps + 1),
            "stress": st,
            "lengths": out_L,
            "n_contacts": np.rint(out_nc).astype(np.int64),
            "mean_overlap": out_ov,
            "kinetic_energy": out_ke,
            "virial": out_vir,
        }

    # ------------------------------------------------------------------ diagnostics
    def _touching(self):
        """Entries of the touching pairs, each physical contact once (a < b), and their overlaps (m)."""
        nb = self.nb
        L = self.box_lengths
        return K.touching_overlaps(self.x, self.r, nb.a, nb.b, nb.sx, nb.sy, L[0], L[1])

    def contacts(self):
        """Touching pairs, each once (i < j): dict of i, j, shift (l_ij = x_j + C n - x_i), force on
        j applied in the last step (N), overlap (m), tangential spring (frame of i; the law's history
        when its width is 2, else zeros), sliding."""
        nb = self.nb
        e, ov = self._touching()
        # entry (a, b, s): b's image is x_b + s L, so l_ab = x_b + C s - x_a (the schema's shift)
        spring = nb.hist[e].copy() if self._width == 2 else np.zeros((e.size, 2))
        return {
            "i": nb.a[e].astype(np.int64),
            "j": nb.b[e].astype(np.int64),
            "shift": self._shifts(e),
            "force": -nb.ef[e],
            "overlap": ov,
            "tangential_spring": spring,
            "sliding": nb.slide[e].copy(),
        }

    def state_arrays(self) -> dict:
        """Everything needed to continue bit for bit (checkpoint): the saved fields of the state
        objects ``p``, ``box``, ``nb``, ``sc`` under their dataset names (:data:`CHECKPOINT`)."""
        return {
            name: getattr(self if obj == "self" else getattr(self, obj), field)
            for name, (obj, field, _) in CHECKPOINT.items()
        }

    def restore(self, arrays: dict, step: int):
        """Inverse of :meth:`state_arrays`: new state objects from ``arrays`` (the derived arrays of
        the list, CSR offsets and the threaded loop's incoming CSR, rebuilt from them)."""
        got = {name: np.array(arrays[name], dtype) for name, (_, _, dtype) in CHECKPOINT.items()}
        n = self.packing.n
        p = self.p
        self.p = K.Particles(
            got["positions"].reshape(n, 2),
            got["velocities"].reshape(n, 2),
            got["spins"].reshape(n),
            got["forces"].reshape(n, 2),
            got["torques"].reshape(n),
            p.m,
            p.r,
        )
        self.box = K.Box(
            got["box_lo"].reshape(2),
            got["box_hi"].reshape(2),
            got["box_lo_hold"].reshape(2),
            got["box_hi_hold"].reshape(2),
        )
        a = got["neighbours/a"].reshape(-1)
        hist = got["neighbours/xi"].reshape(a.size, self._width)
        self.nb = self._neighbours(
            a,
            got["neighbours/b"].reshape(-1),
            got["neighbours/shift"],
            got["neighbours/owned_both"].reshape(-1),
            hist,
            got["x_hold"].reshape(n, 2),
        )
        self.sc.vir[:] = got["virial"].reshape(4)
        self._failed = ""
        self.step = int(step)
        self.stress = self.stress_tensor(self.box_lengths)
        self._build_step = self.step
        self._reset_energy_budget()

    # ------------------------------------------------------------------ views of the state
    lo = property(lambda self: self.box.lo, doc="box lower corner (2,), m")
    hi = property(lambda self: self.box.hi, doc="box upper corner (2,), m")
    lo_hold = property(lambda self: self.box.lo_hold, doc="lo at the last neighbour build (2,), m")
    hi_hold = property(lambda self: self.box.hi_hold, doc="hi at the last neighbour build (2,), m")
    eshift = property(lambda self: self._shifts(), doc="image shift s of each entry (M, 2) int64")

    def _shifts(self, e=slice(None)) -> np.ndarray:
        """Image shifts s (K, 2) int64 of the entries ``e`` (default all), from ``nb.sx, nb.sy``."""
        out = np.empty((self.nb.sx[e].size, 2), np.int64)
        out[:, 0] = self.nb.sx[e]
        out[:, 1] = self.nb.sy[e]
        return out

    virial = property(lambda self: self.sc.vir, doc="virial sums xx, yy, xy, yx of the last step (4,), N m")


#: checkpoint datasets (docs/schema_dem.md ``/checkpoint``): name -> (state object, field, dtype);
#: object "self": a property of the engine (the integer shifts, derived from ``nb.sx``, ``nb.sy``)
CHECKPOINT = {
    "positions": ("p", "x", np.float64),
    "velocities": ("p", "v", np.float64),
    "spins": ("p", "w", np.float64),
    "forces": ("p", "f", np.float64),
    "torques": ("p", "t", np.float64),
    "box_lo": ("box", "lo", np.float64),
    "box_hi": ("box", "hi", np.float64),
    "x_hold": ("nb", "xhold", np.float64),
    "box_lo_hold": ("box", "lo_hold", np.float64),
    "box_hi_hold": ("box", "hi_hold", np.float64),
    "neighbours/a": ("nb", "a", np.int32),
    "neighbours/b": ("nb", "b", np.int32),
    "neighbours/shift": ("self", "eshift", np.int64),
    "neighbours/owned_both": ("nb", "both", np.bool_),
    "neighbours/xi": ("nb", "hist", np.float64),
    "virial": ("sc", "vir", np.float64),
}


def _control(loading, step: int, nsteps: int, lo0, hi0, phase_step0: int):
    """The :class:`~gransim.dem.kernels.Control` of ``loading`` (a Loading or a PrescribedBox whose
    rows cover steps step + 1 .. step + nsteps). Both kinds give the same numba type (writeable
    copies of the same dtypes): one compiled run_block per law."""
    if isinstance(loading, PrescribedBox):
        if nsteps and not (loading.step0 <= step and step + nsteps <= loading.last_step):
            raise InputError(
                f"prescribed box: the table covers steps {loading.step0 + 1}.."
                f"{loading.last_step}, the run needs {step + 1}..{step + nsteps}"
            )
        z = np.zeros(2)
        return K.Control(
            np.zeros(2, np.int64),
            z,
            z,
            z,
            lo0,
            hi0,
            int(phase_step0),
            True,
            np.array(loading.lo),
            np.array(loading.hi),
            np.array(loading.remap),
            int(loading.step0),
        )
    if isinstance(loading, Loading):
        code = {"fixed": 0, "rate": 1, "servo": 2}
        ax = (loading.x, loading.y)
        return K.Control(
            np.array([code[a.mode] for a in ax], np.int64),
            np.array([a.rate for a in ax]),
            np.array([a.target for a in ax]),
            np.array([a.gain for a in ax]),
            lo0,
            hi0,
            int(phase_step0),
            False,
            np.zeros((1, 2)),
            np.zeros((1, 2)),
            np.zeros(1, np.bool_),
            0,
        )
    raise InputError(f"loading: expected a Loading or a PrescribedBox, got {type(loading).__name__}")


__all__ = [
    "STEPS_PER_CONTACT_MIN",
    "AxisControl",
    "Integration",
    "DEMEngine",
    "DEMSettings",
    "EngineCore",
    "Loading",
    "check_time_step",
    "PrescribedBox",
    "contact_time",
    "damping_ratio",
    "fingerprint",
    "stability_limit",
]
