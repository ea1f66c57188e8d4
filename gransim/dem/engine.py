"""The DEM engine (:class:`Engine`): disks in a periodic cell, one state and one step loop for
every cell, law and arithmetic. The orthogonal cell (:class:`OrthogonalCell`, side lengths that
change each step) is described here; the sheared one in :mod:`gransim.dem.sheared`.

The orthogonal cell follows the step of LIGGGHTS-PUBLIC 3.8.0 (serial, ``newton off``, ``neigh_modify delay 0
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
from .._validate import as_int, check_choice
from ..contacts.laws import elastic_energy, flip_signs, law_names, law_spec, time_scale
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import kernels as K
from .settings import FLAVOURS, AxisControl, DEMSettings, Integration, Loading, PrescribedBox

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


#: the energy budget hands freed memory back only from this many particles: below, its gathered
#: contact arrays are small and the trim of the heap costs more than they held (a 400-disk RVE
#: call: every call restores the engine and resets the budget)
TRIM_MIN_PARTICLES = 20_000

#: contacts per call of the law's energy (:meth:`DEMEngine.elastic_energy`)
ENERGY_CHUNK = 1 << 16

#: the Neighbours field ``shift`` of the engine's lists (the shifts are kept as floats only)
_NO_SHIFT = np.zeros((0, 2), np.int64)

#: the arithmetics of :class:`Engine` (``flavour=``): LIGGGHTS' and LAMMPS' (the cells of this module
#: and gransim.dem.sheared, either Hooke law, any registered law) and YADE's (gransim.dem.yade_cell:
#: its own iteration, collider and Cundall and Strack's law)
ARITHMETICS = (*FLAVOURS, "yade")

#: the cells of :class:`Engine`: "orthogonal" (:class:`OrthogonalCell`, LIGGGHTS' and LAMMPS'
#: orthogonal box under ``fix deform ... remap x``) and "sheared" (:class:`gransim.dem.sheared.
#: ShearedCell`, LAMMPS' triclinic box under ``fix deform ... xy ... remap v``)
CELLS = ("orthogonal", "sheared")


def _state_array(value, shape, name: str, unit: str) -> np.ndarray:
    """A float64 copy of ``value`` with ``shape``, finite; InputError naming ``name`` otherwise."""
    try:
        a = np.array(value, np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected numbers ({unit}), got {type(value).__name__}") from None
    if a.size != int(np.prod(shape)):
        raise InputError(f"{name}: expected shape {shape} ({unit}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected finite numbers ({unit})")
    return a.reshape(shape)


class Engine:
    """The DEM engine: one state of disks in a periodic cell and one step loop (arrays updated in
    place for speed).

    Its choices are independent of one another:

    - **cell** (``cell=``): "orthogonal" (:class:`OrthogonalCell`: side lengths that change each
      step under :class:`~gransim.dem.settings.Loading` or :class:`~gransim.dem.settings.
      PrescribedBox`, LIGGGHTS' and LAMMPS' ``fix deform ... remap x``; module docstring) or
      "sheared" (:class:`gransim.dem.sheared.ShearedCell`: LAMMPS' triclinic box under
      :class:`~gransim.dem.sheared.ShearLoading`, ``fix deform ... xy ... remap v``);
    - **law** (``law=``): any registered contact law (:func:`gransim.contacts.laws.register_law`)
      of a pair function, or, with ``flavour="yade"``, YADE's Cundall-Strack law
      (:mod:`gransim.contacts.yade_cundall_strack`, run by the yade cell's interaction loop);
      None: the Hooke law of a :class:`DEMSettings` in the engine's arithmetic
      (:meth:`DEMSettings.hooke_law`);
    - **arithmetic** (``flavour=``, default ``settings.flavour``, :data:`ARITHMETICS`):
      "liggghts" or "lammps", whose step order, rebuild rule and law arithmetic the engine
      reproduces bit for bit (docs/lammps.md); or "yade", YADE's own iteration (its leapfrog,
      collider, interaction container and Cundall and Strack's law, :mod:`gransim.dem.yade_cell`);
    - **ordering** (``order=``, :data:`ORDERS`): "code", the code's order bit for bit (the
      cell classes above; the orthogonal cell's list over numba threads with ``settings.mode``
      "parallel"), or "fast" (:mod:`gransim.dem.fast`: spatially sorted structure of arrays, a
      half list, banded threads on ``threads``; both cells, the laws with a block path).

    Every combination has the divergence check (energy balance, :meth:`_check_energy`), the
    lost-particle check, the energies, :meth:`state_arrays` / :meth:`restore` (checkpoints) and
    the clean errors. A step's arithmetic lives in the cell's jitted block
    (:func:`gransim.dem.kernels.run_block`, :func:`gransim.dem.sheared_kernels.run_block`,
    :func:`gransim.dem.fast_kernels.run_steps`); the loop that drives it, the checks and the
    rebuilds between its blocks are :meth:`_run`, one for every cell and ordering. What depends
    on the cell and the ordering (the state's layout, the list, the block, the views) is the
    object ``cell_ops`` (:class:`OrthogonalCell`, :class:`gransim.dem.sheared.ShearedCell`,
    :class:`gransim.dem.fast.FastOrthogonalCell`, :class:`gransim.dem.fast.FastShearedCell`).

    Parameters
    ----------
    packing : initial packing. Orthogonal cell: the box is [0, Lx] x [0, Ly] (the LIGGGHTS data file
        gransim writes) unless ``box`` is given; sheared: its cell [[Lx, xy], [0, Ly]].
    settings : :class:`~gransim.dem.settings.Integration` (dt, skin, mode, flavour) with a ``law``,
        or :class:`DEMSettings` (the integration and the parameters of its Hooke law).
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    threads : code order: numba threads of mode "parallel" (None: numba's current count), set
        around each kernel call and restored afterwards (the orthogonal cell; the sheared cell
        runs the serial loop). Fast order: its threads (None: 1; the results do not depend on them).
    check_dt : refuse a time step above :func:`stability_limit` of the law (at the largest overlap
        after the set-up for a law whose stiffness depends on it: Hertz).
    cell_options : options of the cell's constructor (the yade cell: ``z``, the z size of YADE's
        3D cell, m; default :func:`gransim.dem.yade_arithmetic.yade_cell_z`).
    box : optional box with its own origin, as a data file's ``xlo xhi ylo yhi`` (and ``xy``) lines:
        (lo, hi) or, sheared, (lo, hi, xy); the positions are taken as they are in that box (no
        translation, which would round them). hi - lo must equal the cell's side lengths (1e-12).

    State of the code order: ``p`` (:class:`~gransim.dem.kernels.Particles`), ``nb``
    (``Neighbours``: list, history of the law's width, CSR, build positions, per-entry outputs),
    ``sc`` (``Scratch``: the virial), ``box`` (the cell's: :class:`~gransim.dem.kernels.Box`
    orthogonal, (lo_x, lo_y, hi_x, hi_y, xy) sheared), small namedtuples of arrays updated in
    place by the kernels (a rebuild replaces ``nb``); the fast order's: :mod:`gransim.dem.fast`.
    The views (x, v, w, f, t, m, r, xhold, ea, eb, xi, ...) are in the packing's particle order in
    both. After construction (the code's ``run`` set-up: list built, forces without spring
    increment): x, v, w, f, t, step, stress, virial.
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
        *,
        cell: str = "orthogonal",
        flavour: str | None = None,
        order: str = "code",
        cell_options: dict | None = None,
    ):
        self._prepare(
            packing, settings, velocities, spins, threads, check_dt, box, law, cell, flavour, order, cell_options
        )
        # the codes' ``run`` set-up: wrap, build (springs zero), forces without spring increment
        self._rebuild(carry=False)
        self._forces(update=False)
        self.stress = self.stress_tensor()
        self._check_time_step_now()
        self._reset_energy_budget()

    @classmethod
    def from_checkpoint(
        cls,
        packing: Packing,
        settings,
        arrays: dict,
        step: int,
        threads: int | None = None,
        check_dt: bool = True,
        box=None,
        law=None,
        *,
        cell: str = "orthogonal",
        flavour: str | None = None,
        order: str = "code",
        cell_options: dict | None = None,
    ) -> Engine:
        """The engine at a checkpoint (``arrays`` of :meth:`state_arrays` at ``step``) without the
        run set-up of a new engine (its list build and force evaluation, which :meth:`restore`
        would overwrite): what a resume and a Gauss point's update start from. The other
        arguments as for the constructor (the packing, settings, law, cell and ordering of the
        engine that wrote the checkpoint)."""
        eng = cls.__new__(cls)
        eng._prepare(packing, settings, None, None, threads, check_dt, box, law, cell, flavour, order, cell_options)
        eng.restore(arrays, step)
        eng._check_time_step_now()
        return eng

    def _prepare(
        self, packing, settings, velocities, spins, threads, check_dt, box, law, cell, flavour, order, cell_options
    ):
        """Everything of the constructor but the run set-up: the inputs checked, the law, the
        cell's state (:attr:`cell_ops`) with the given positions, velocities and spins."""
        check_choice(cell, "cell", CELLS)
        check_choice(order, "order", ORDERS)
        if not isinstance(packing, Packing):
            raise InputError(f"packing: expected a gransim Packing, got {type(packing).__name__}")
        if not isinstance(settings, (DEMSettings, Integration)):
            raise InputError(f"settings: expected a DEMSettings or an Integration, got {type(settings).__name__}")
        flavour = settings.flavour if flavour is None else flavour
        check_choice(flavour, "flavour", ARITHMETICS)
        ops = _cell_class(cell, order, flavour)
        ops.check(packing, settings, flavour)
        self.packing = packing
        self.settings = settings
        self.flavour = flavour
        self.order = order
        # the contact law (gransim.contacts.laws): the Hooke law of DEMSettings unless given
        self._set_law(packing, settings, law, flavour, check_dt, ops)
        ops.check_size(packing, settings)
        n = packing.n
        x = _state_array(packing.positions, (n, 2), "positions", "m")
        v = np.zeros((n, 2)) if velocities is None else _state_array(velocities, (n, 2), "velocities", "m/s")
        w = np.zeros(n) if spins is None else _state_array(spins, (n,), "spins", "rad/s")
        self.step = 0
        self.n_contacts = 0
        self.mean_overlap = 0.0
        self.n_rebuilds = 0
        self._build_step = 0
        self._failed = ""  # why a rebuild failed (the engine has no list then), or ""
        self._run_drive = None  # the loading of the current run (start_run)
        self.cell_ops = ops(self, box, threads, x, v, w, **(cell_options or {}))

    # ------------------------------------------------------------------ the law
    def _set_law(self, packing: Packing, settings, law, flavour: str, check_dt: bool, ops) -> None:
        """``law`` (None: the Hooke law of a :class:`DEMSettings` in ``flavour``,
        :meth:`DEMSettings.hooke_law`) with what the loops need of its registration (history width,
        flip signs, disk cache), its time step checked (:func:`check_time_step`, at zero overlap:
        :meth:`_check_time_step_now` checks a law whose stiffness grows with the overlap once the
        state is set up). A cell that runs its code's own interaction loop (``ops.law_code``: the
        yade cell) takes only that code's laws; the list loops take only laws with a pair function.
        InputError naming the law otherwise."""
        if law is None:
            if not isinstance(settings, DEMSettings):
                raise InputError("law: an engine with Integration settings needs its contact law (law=...)")
            law = settings.hooke_law(flavour)
        spec = law_spec(law)  # InputError for an unregistered law
        own = getattr(ops, "law_code", None)
        if own is not None and spec.code != own:
            raise InputError(
                f"law: the {flavour} arithmetic runs its own interaction loop with a {own} law "
                f"({', '.join(law_names((own,)))}), got {type(law).__name__} (a {spec.code} law)"
            )
        if own is None and spec.pair is None:
            raise InputError(
                f"law: {type(law).__name__} is a {spec.code} law without a pair function (its kernel is "
                f"{spec.code}'s interaction loop): run it with flavour='{spec.code}'"
            )
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

    # ------------------------------------------------------------------ the cell
    n = property(lambda self: self.packing.n, doc="number of particles")

    @property
    def cell_kind(self) -> str:
        """ "orthogonal" or "sheared" (:data:`CELLS`)."""
        return self.cell_ops.kind

    @property
    def cell(self) -> np.ndarray:
        """Current cell (2, 2) (m), columns the lattice vectors: diag(Lx, Ly), or [[Lx, xy], [0, Ly]]."""
        return self.cell_ops.matrix(self)

    @property
    def box_lengths(self) -> np.ndarray:
        """Current side lengths (Lx, Ly) (2,) (m)."""
        return self.cell_ops.lengths(self)

    @property
    def area(self) -> float:
        """Current cell area Lx Ly (m^2)."""
        L = self.box_lengths
        return float(L[0] * L[1])

    lo = property(lambda self: self.cell_ops.lo(self), doc="box lower corner (2,), m")
    hi = property(lambda self: self.cell_ops.hi(self), doc="box upper corner (2,), m")

    def stress_tensor(self, L=None) -> np.ndarray:
        """Love stress (eq 17 of Kuhn, "Structured deformation in granular materials", Mechanics of
        Materials 1999), compression positive, (2, 2) (N/m): sigma_ab = (1/(Lx Ly)) sum_c d_a f_b,
        d = x_i - x_j, f the force on i, over the area of the side lengths ``L`` (2,) (default: the
        current box). Not symmetric out of equilibrium; [0, 1] = sum d_x f_y is the codes'
        ``compute pressure`` component 4 (xy)."""
        own = getattr(self.cell_ops, "stress_tensor", None)
        if L is None and own is not None:  # a cell with its code's own stress (the yade cell)
            return own(self)
        if L is None:
            L = self.box_lengths
        inv = 1.0 / (L[0] * L[1])
        v = self.virial
        return np.array([[v[0] * inv, v[2] * inv], [v[3] * inv, v[1] * inv]])

    def _rebuild(self, carry: bool):
        self.cell_ops.rebuild(self, carry)

    def _forces(self, update: bool):
        """Forces, torques and the virial of the current state (``update``: the law's history
        advances, as in a step; False: the set-up evaluation of a run)."""
        nc, so = self.cell_ops.forces(self, update)
        self.n_contacts = round(nc)
        self.mean_overlap = so / nc if nc else 0.0

    def _touching(self):
        """Entries of the touching pairs, each physical contact once (a < b), and their overlaps (m),
        the images from the current box."""
        return self.cell_ops.touching(self)

    # ------------------------------------------------------------------ stepping
    def start_run(self, loading, nsteps: int):
        """Begin a run of ``nsteps`` steps under ``loading`` (the codes' ``run N`` with its ``fix
        deform``), continued by :meth:`advance` ``(k)`` calls. Orthogonal cell: a :class:`Loading`
        or :class:`PrescribedBox` measured from the current step and box (no new set-up, the state
        is untouched); sheared cell: a :class:`~gransim.dem.sheared.ShearLoading` with the run's
        set-up evaluation (:meth:`gransim.dem.sheared.ShearedCell.start_run`). Returns the stress
        (2, 2) at the start of the run."""
        nsteps = as_int(nsteps, "nsteps", 1)
        self._run_drive = self.cell_ops.start_run(self, loading, nsteps)
        return self.stress.copy()

    def advance(self, *args, **kwargs) -> dict:
        """Advance the state; returns a dict of per-step series.

        ``advance(nsteps)``: ``nsteps`` steps of the run begun by :meth:`start_run`.
        ``advance(loading, nsteps=1, phase_step0=0, phase_box0=None)`` (orthogonal cell): ``nsteps``
        steps under ``loading``, a :class:`Loading` (each axis fixed, at a rate or under a servo)
        or a :class:`PrescribedBox` (the box of every step from a table; its rows must cover steps
        step + 1 .. step + nsteps); ``phase_step0`` and ``phase_box0`` = (lo, hi): step and box at
        the start of the loading phase (``fix deform`` lo_start/hi_start: rate control measures
        its displacement from there, the servo its accumulated change; default: now).

        Returns
        -------
        dict with ``step`` (n,), ``stress`` (n, 2, 2) (Love stress, compression positive, N/m, area
        of the box after the step), ``virial`` (n, 4) (xx, yy, xy, yx: sum d_a f_b, N m), ``n_contacts``
        (n,), ``mean_overlap`` (n,) (m), ``kinetic_energy`` (n,) (J, of the lab-frame velocities),
        and the cell's: ``lengths`` (n, 2) (m) orthogonal; ``box`` (n, 5) (lx, ly, xy, ylo, yhi; m)
        sheared.

        Raises
        ------
        SimulationError naming the step and the particle, on a divergence: a non-finite position or
        kinetic energy; a kinetic-energy blow-up (more than KINETIC_ENERGY_FACTOR times the energy
        balance allows, :meth:`_check_energy`); a lost particle (moved more than
        LOST_DISPLACEMENT_SKINS skins since the last neighbour build, or left the box by more than a
        cell); a collapsed cell. These checks only read the state: the step's arithmetic is untouched.
        """
        drive, nsteps = self.cell_ops.drive(self, self._run_drive, *args, **kwargs)
        return self._run(drive, nsteps)

    def _run(self, drive, nsteps: int) -> dict:
        """The step loop of every cell and ordering: blocks of the cell's jitted block (which stops
        at a neighbour rebuild, a non-finite position or a collapsed cell), the divergence check
        over each block's steps, the lost-particle check and the rebuild between blocks."""
        if self._failed:
            raise SimulationError(
                f"the engine stopped at a failed neighbour build ({self._failed}); restore a "
                "checkpoint or make a new engine"
            )
        ops = self.cell_ops
        out = ops.series(nsteps)
        done = 0
        resume = False
        step_start = self.step
        while done < nsteps:
            before = ops.box_state(self)
            k, status, bad = ops.block(self, drive, out, done, nsteps - done, resume)
            if k:
                ops.check_divergence(self, out, done, k, before)
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
                i = ops.particle(self, bad)
                raise SimulationError(
                    f"step {self.step + 1}: particle {i} has a non-finite position "
                    f"{self.x[i].tolist()} (velocity {self.v[i].tolist()})"
                )
            elif status == 3:
                raise SimulationError(f"step {self.step + 1}: {ops.collapse_message(self)}")
            elif status > 3:
                raise SimulationError(f"step {self.step + 1}: {ops.failure_message(self, status, bad)}")
            elif k == 0 and done < nsteps:  # pragma: no cover - the block always moves or stops
                raise SimulationError(f"step {self.step + 1}: no progress")
        series = ops.result(self, out, step_start)
        if nsteps:
            self.stress = self.stress_tensor()
        return series

    # ------------------------------------------------------------------ energies and checks
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
        rolling laws add their rolling spring; docs/laws.md), in chunks of ENERGY_CHUNK contacts."""
        return self.cell_ops.elastic_energy(self)

    def peculiar_velocities(self) -> np.ndarray:
        """Sheared cell: v - u(x) (N, 2) (m/s), u the homogeneous flow of the cell
        (:meth:`gransim.dem.sheared.ShearedCell.peculiar_velocities`)."""
        if self.cell_kind != "sheared":
            raise InputError("peculiar_velocities: the sheared cell's (the orthogonal cell's velocities carry no flow)")
        return self.cell_ops.peculiar_velocities(self)

    def memory_bytes(self) -> dict:
        """Bytes held by the state's arrays, by part (the fast order: particles, list, hand-over
        table, scratch; the code order: particles, list)."""
        return self.cell_ops.memory_bytes(self)

    def _budget_kinetic_energy(self) -> float:
        """The kinetic energy the divergence check bounds (J): that of the velocities relative to the
        cell's homogeneous flow (orthogonal cell under ``remap x``: the velocities held)."""
        return self.cell_ops.budget_kinetic_energy(self)

    def _reset_energy_budget(self):
        """Start of the energy balance of the divergence check: E0 = kinetic + elastic energy now."""
        e0 = self._budget_kinetic_energy() + self.elastic_energy()
        if self.n >= TRIM_MIN_PARTICLES:
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
        i, di = self.cell_ops.largest_move(self)
        skin = self.settings.skin
        if di > LOST_DISPLACEMENT_SKINS * skin:
            raise SimulationError(
                f"step {self.step + 1}: particle {i} lost: it moved {di:.4g} m = {di / skin:.3g} "
                f"skins since the neighbour build of step {self._build_step}, more than a skin "
                f"({skin:.4g} m) in one step (velocity {self.v[i].tolist()} m/s, dt {self.settings.dt:.4g} s)"
            )

    # ------------------------------------------------------------------ diagnostics
    def contacts(self):
        """Touching pairs, each once (i < j): dict of i, j, shift (l_ij = x_j + C s - x_i), force on
        j (N; the code order: applied in the last step; the fast order: the law at the current
        state, :meth:`gransim.dem.fast.FastCell.contacts`), overlap (m), tangential spring (frame
        of i; the law's history when its width is 2, else zeros), sliding."""
        return self.cell_ops.contacts(self)

    def _shifts(self, e=slice(None)) -> np.ndarray:
        """Image shifts s (K, 2) int64 of the entries ``e`` (default all)."""
        return self.cell_ops.shifts(self, e)

    eshift = property(lambda self: self._shifts(), doc="image shift s of each entry (M, 2) int64")

    # ------------------------------------------------------------------ checkpoints
    def state_arrays(self) -> dict:
        """Everything needed to continue bit for bit (checkpoint), in the layout of the ordering:
        the code order's :data:`CHECKPOINT` and its cell's datasets
        (:meth:`CodeOrderCell.state_arrays`), the fast order's sorted state
        (:meth:`gransim.dem.fast.FastCell.state_arrays`)."""
        return self.cell_ops.state_arrays(self)

    def restore(self, arrays: dict, step: int):
        """Inverse of :meth:`state_arrays` on an engine of the same packing, settings, law, cell
        and ordering: the run continues with the bits of the run that wrote them."""
        self._build_step = self.cell_ops.restore(self, arrays, int(step))
        self._failed = ""
        self.step = int(step)
        self.stress = self.stress_tensor()
        self._reset_energy_budget()  # the divergence check's balance starts again at the checkpoint

    # ------------------------------------------------------------------ views of the state
    # in the packing's particle order; the code order's are its arrays (p, nb), the fast order's
    # copies from its sorted state
    def _view(name: str, doc: str):  # noqa: N805 - a helper of the class body
        return property(lambda self: self.cell_ops.view(self, name), doc=doc)

    x = _view("x", "positions (N, 2), m")
    v = _view("v", "velocities (N, 2), m/s")
    w = _view("w", "spins (N,), rad/s")
    f = _view("f", "forces of the last step (N, 2), N")
    t = _view("t", "torques of the last step (N,), N m")
    m = _view("m", "masses (N,), kg")
    r = _view("r", "radii (N,), m")
    xhold = _view("xhold", "positions at the last neighbour build (N, 2), m")
    ea = _view("ea", "first particle of each list entry (M,) int32")
    eb = _view("eb", "second particle of each list entry (M,) int32")
    esx = _view("esx", "s_x as float64 (M,)")
    esy = _view("esy", "s_y as float64 (M,)")
    both = _view("both", "owned pair (force on both particles) (M,) bool")
    xi = _view("xi", "per-entry history of the law (M, width); Hooke: the spring, m")
    slide = _view("slide", "Coulomb cap active at the last stored step (M,) bool")
    ef = _view("ef", "force on a of each entry at the last stored step (M, 2), N")
    start = _view("start", "CSR offsets of the entries of each a (N+1,)")
    del _view
    virial = property(lambda self: self.sc.vir, doc="virial sums xx, yy, xy, yx of the last step (4,), N m")


class CodeOrderCell:
    """What the code order's cells (:class:`OrthogonalCell`, :class:`gransim.dem.sheared.
    ShearedCell`) share: the state in the code's layout on the engine, ``p``
    (:class:`~gransim.dem.kernels.Particles`) and ``nb`` (``Neighbours``: the list with the law's
    history, CSR offsets, build positions, per-entry outputs), its views, energies, contacts and
    checkpoints. A cell adds its box (``neighbours``, ``rebuild``, ``forces``, ``block``, ...) and
    its checkpoint datasets (``cell_arrays``, ``cell_restore``, ``cell_restored``)."""

    order = "code"

    #: view name -> (state object, field)
    VIEWS = {
        "x": ("p", "x"), "v": ("p", "v"), "w": ("p", "w"), "f": ("p", "f"), "t": ("p", "t"), "m": ("p", "m"),
        "r": ("p", "r"), "xhold": ("nb", "xhold"), "ea": ("nb", "a"), "eb": ("nb", "b"), "esx": ("nb", "sx"),
        "esy": ("nb", "sy"), "both": ("nb", "both"), "xi": ("nb", "hist"), "slide": ("nb", "slide"),
        "ef": ("nb", "ef"), "start": ("nb", "start"),
    }  # fmt: skip

    def _init_state(self, eng, x, v, w):
        """``p`` and an empty ``nb`` (the set-up's build fills it)."""
        r = np.ascontiguousarray(eng.packing.radii, np.float64)
        # ((pi r) r) rho: the order LIGGGHTS and LAMMPS use reading the data file (Packing.masses
        # may differ in the last bit)
        m = np.pi * r * r * float(eng.packing.density)
        n = eng.packing.n
        eng.p = K.Particles(x, v, w, np.zeros((n, 2)), np.zeros(n), m, r)
        i0 = np.zeros(0, np.int32)
        eng.nb = self.neighbours(
            eng, i0, i0.copy(), np.zeros(0), np.zeros(0), np.zeros(0, np.bool_), np.zeros((0, eng._width)), x.copy()
        )

    def view(self, eng, name: str):
        obj, field = self.VIEWS[name]
        return getattr(getattr(eng, obj), field)

    def particle(self, eng, i: int) -> int:
        """The particle (packing order) of the state's index ``i``: the same."""
        return int(i)

    def largest_move(self, eng):
        """(particle, distance (m)) of the largest displacement since the last list build."""
        i, di = K.largest_displacement(eng.x, eng.xhold)
        return int(i), float(di)

    def elastic_energy(self, eng) -> float:
        """:meth:`Engine.elastic_energy` on the code's layout."""
        e, ov = eng._touching()
        # in chunks of ENERGY_CHUNK contacts (the law's energy takes gathered (K,) arrays: at 1e6
        # disks all of them at once were the peak memory of a run); one chunk: the plain sum
        total = 0.0
        for k in range(0, e.size, ENERGY_CHUNK):
            c = e[k : k + ENERGY_CHUNK]
            total += elastic_energy(eng.law, ov[k : k + ENERGY_CHUNK], eng.xi[c], eng.r[eng.ea[c]], eng.r[eng.eb[c]])
        return total

    def contacts(self, eng):
        """Touching pairs, each once (i < j): dict of i, j, shift (l_ij = x_j + C s - x_i), force on
        j applied in the last step (N), overlap (m), tangential spring (frame of i; the law's history
        when its width is 2, else zeros), sliding."""
        nb = eng.nb
        e, ov = eng._touching()
        spring = nb.hist[e].copy() if eng._width == 2 else np.zeros((e.size, 2))
        return {
            "i": nb.a[e].astype(np.int64),
            "j": nb.b[e].astype(np.int64),
            "shift": self.shifts(eng, e),
            "force": -nb.ef[e],
            "overlap": ov,
            "tangential_spring": spring,
            "sliding": nb.slide[e].copy(),
        }

    def shifts(self, eng, e=slice(None)) -> np.ndarray:
        """Image shifts s (K, 2) int64 of the entries ``e`` (default all), from ``nb.sx, nb.sy``."""
        out = np.empty((eng.nb.sx[e].size, 2), np.int64)
        out[:, 0] = eng.nb.sx[e]
        out[:, 1] = eng.nb.sy[e]
        return out

    def state_arrays(self, eng) -> dict:
        """Everything needed to continue bit for bit (checkpoint; copies): the particles, the list
        with the law's history, the build positions, the virial (:data:`CHECKPOINT`), and the cell's state
        (:meth:`OrthogonalCell.cell_arrays`, :meth:`gransim.dem.sheared.ShearedCell.cell_arrays`)."""
        own = {
            name: getattr(eng if obj == "self" else getattr(eng, obj), field)
            for name, (obj, field, _) in CHECKPOINT.items()
        }
        # copies: a checkpoint does not change when the engine steps on
        return {k: np.array(v) for k, v in {**own, **self.cell_arrays(eng)}.items()}

    def restore(self, eng, arrays: dict, step: int) -> int:
        """Inverse of :meth:`state_arrays`: new state objects from ``arrays`` (the derived arrays of
        the list, CSR offsets and the threaded loop's incoming CSR, rebuilt from them); returns the
        step of the list build (the checkpoint's)."""
        got = {name: np.array(arrays[name], dtype) for name, (_, _, dtype) in CHECKPOINT.items()}
        n = eng.packing.n
        p = eng.p
        eng.p = K.Particles(
            got["positions"].reshape(n, 2),
            got["velocities"].reshape(n, 2),
            got["spins"].reshape(n),
            got["forces"].reshape(n, 2),
            got["torques"].reshape(n),
            p.m,
            p.r,
        )
        self.cell_restore(eng, arrays)
        a = got["neighbours/a"].reshape(-1)
        shift = got["neighbours/shift"].reshape(-1, 2)
        eng.nb = self.neighbours(
            eng,
            a,
            got["neighbours/b"].reshape(-1),
            np.ascontiguousarray(shift[:, 0], np.float64),
            np.ascontiguousarray(shift[:, 1], np.float64),
            got["neighbours/owned_both"].reshape(-1),
            got["neighbours/xi"].reshape(a.size, eng._width),
            got["x_hold"].reshape(n, 2),
        )
        self.cell_restored(eng, arrays)
        eng.sc.vir[:] = got["virial"].reshape(4)
        return int(step)  # the list was built at the checkpoint's step (its build positions)

    def result(self, eng, out, first: int) -> dict:
        """The series of :meth:`Engine.advance` from the step loop's ``out`` (``first``: the step
        before its first row); the contacts and mean overlap of the last step on the engine."""
        nsteps = out.nc.size
        if nsteps:
            eng.n_contacts = round(out.nc[-1])
            eng.mean_overlap = float(out.ov[-1])
        st = np.empty((nsteps, 2, 2))
        st[:, 0, 0] = out.stress[:, 0]
        st[:, 1, 1] = out.stress[:, 1]
        st[:, 0, 1] = out.stress[:, 2]
        st[:, 1, 0] = out.stress[:, 3]
        return {
            "step": np.arange(first + 1, first + nsteps + 1),
            "stress": st,
            "virial": out.vir,
            "n_contacts": np.rint(out.nc).astype(np.int64),
            "mean_overlap": out.ov,
            "kinetic_energy": out.ke,
            **self.cell_series(out),
        }

    def memory_bytes(self, eng) -> dict:
        """Bytes held by the particles' and the list's arrays."""
        return {"particles": sum(a.nbytes for a in eng.p), "list": sum(a.nbytes for a in eng.nb)}


class OrthogonalCell(CodeOrderCell):
    """The orthogonal periodic box of LIGGGHTS 3.8.0 and LAMMPS 29 Sep 2021 (``fix deform ... remap
    x``): what :class:`Engine` does that depends on it (module docstring). Its state on the engine:
    ``box`` (:class:`~gransim.dem.kernels.Box`: lo, hi and their values at the last build) and
    ``sc`` (the virial, and the per-particle sums of mode "parallel")."""

    kind = "orthogonal"

    @staticmethod
    def check(packing: Packing, settings, flavour: str) -> None:
        C = packing.cell
        if C[0, 1] != 0 or C[1, 0] != 0:
            raise InputError(
                f"packing.cell: the orthogonal cell needs an orthogonal packing cell (off-diagonal entries "
                f"{C[0, 1]!r}, {C[1, 0]!r}; a tilted cell: cell='sheared')"
            )

    @staticmethod
    def check_size(packing: Packing, settings) -> None:
        C = packing.cell
        cut = 2 * 2.0 * float(packing.radii.max()) + 2 * settings.skin
        if min(C[0, 0], C[1, 1]) <= cut:
            raise InputError(
                f"packing.cell: side lengths {C[0, 0]:.4g}, {C[1, 1]:.4g} m must exceed "
                f"2 (2 r_max + skin) = {cut:.4g} m (one periodic image per pair)"
            )

    def __init__(self, eng: Engine, box, threads, x, v, w):
        s = eng.settings
        C = eng.packing.cell
        n = eng.packing.n
        lo = np.zeros(2)
        hi = np.array([C[0, 0], C[1, 1]], np.float64)
        if box is not None:
            lo, hi = _check_box(box, C)
        eng.box = K.Box(lo, hi, lo.copy(), hi.copy())
        self.parallel = s.mode == "parallel"
        # the rebuild rule of LAMMPS (check_rebuild clamp; docs/lammps.md)
        self.clamp = eng.flavour == "lammps"
        # numba threads of this engine's kernels, set around each call and restored after; serial
        # mode on one: its SIMD force loop (kernels._serial_block_loop) is a one-iteration parallel
        # loop, and a second OpenMP thread would spin-wait beside every step (libgomp's default
        # policy), burning a core that the user's other work (the codes' jobs) needs
        self.threads = check_threads(threads) if self.parallel else 1
        # (numba's static schedule: the tasks handed out dynamically, gransim._numba.dynamic_chunks,
        # made the step 1.3x and the threaded list build 3x slower at 1e5 disks, measured)
        if self.parallel and n <= K.PARTICLE_BLOCK:
            # one task of the threaded kernels: the result is the same on any thread count, and a
            # second thread would only wait at every loop's end (0.6x of one thread at 1,020 disks)
            self.threads = 1
        m = n if self.parallel else 0  # the per-particle sums of the threaded loop (mode "parallel")
        eng.sc = K.Scratch(np.zeros(4), np.zeros((m, 4)), np.zeros((m, 2)))
        self._init_state(eng, x, v, w)

    # geometry
    def matrix(self, eng) -> np.ndarray:
        return np.diag(self.lengths(eng))

    def lengths(self, eng) -> np.ndarray:
        return eng.box.hi - eng.box.lo

    def lo(self, eng) -> np.ndarray:
        return eng.box.lo

    def hi(self, eng) -> np.ndarray:
        return eng.box.hi

    # the list
    def neighbours(self, eng, a, b, sx, sy, both, hist, xhold):
        """A :class:`~gransim.dem.kernels.Neighbours` of the list (a, b, image shifts sx, sy as
        floats, both) with history ``hist`` and build positions ``xhold``: CSR offsets of the
        entries of each a (sorted by a), the incoming CSR and the per-entry torques of the threaded
        loop (mode "parallel" only), zeroed per-entry outputs."""
        n = eng.packing.n
        start = np.zeros(n + 1, np.int64)  # CSR offsets of the entries of each a (sorted)
        np.cumsum(np.bincount(a, minlength=n), out=start[1:])
        if self.parallel:
            with num_threads(self.threads):
                in_start, in_e = K.incoming(b, both, n)
        else:
            in_start, in_e = np.zeros(n + 1, np.int64), np.zeros(0, np.int64)
        return K.Neighbours(
            a, b, _NO_SHIFT, sx, sy, both, hist, start, in_start, in_e, xhold,
            np.zeros(a.size, np.bool_), np.zeros((a.size, 2)), np.zeros(a.size if self.parallel else 0),
        )  # fmt: skip

    def rebuild(self, eng, carry: bool):
        """Wrap into the box, new list (LIGGGHTS' bins and ghosts), history handed over to the
        entries that overlap now (LIGGGHTS' ``fix contacthistory``)."""
        bad = K.pbc_wrap(eng.x, eng.lo, eng.hi)
        if bad >= 0:
            raise SimulationError(
                f"step {eng.step}: particle {bad} lost (at {eng.x[bad].tolist()}, "
                f"box {eng.lo.tolist()}..{eng.hi.tolist()})"
            )
        L = self.lengths(eng)
        # the old list keeps only what the hand-over reads (CSR, partners, owned flags, history):
        # its other arrays and the build positions are released before the new list exists (the
        # peak memory of a run at 1e6 disks is a rebuild's). A SimulationError below leaves the
        # engine without a list: advance refuses it until restore (``_failed``)
        old = eng.nb
        keep = (old.start, old.b, old.both, old.hist) if carry and old.a.size else None
        z = np.zeros(0)
        eng.nb = old = old._replace(
            a=np.zeros(0, old.a.dtype), shift=np.zeros((0, 2), np.int64), sx=z, sy=z,
            in_e=np.zeros(0, np.int64), slide=np.zeros(0, np.bool_), ef=np.zeros((0, 2)), tb=z,
            xhold=np.zeros((0, 2)),
        )  # fmt: skip
        release_free_memory()  # the old list's released arrays
        with num_threads(self.threads):  # mode "parallel": the pair passes on the threads
            a, b, esx, esy, both, selfimg = K.build_list_liggghts(
                eng.x, eng.r, eng.lo, eng.hi, eng.settings.skin, self.parallel
            )
        if selfimg != -1:
            eng._failed = (
                f"step {eng.step}: particle {selfimg} is near its own image (or too many ghosts); the cell is too small"
            )
            raise SimulationError(eng._failed)
        release_free_memory()  # the build's ghosts and bins
        hist = np.zeros((a.size, eng._width))
        if keep is not None:
            K.hand_over_history(eng.x, eng.r, a, b, esx, esy, L[0], L[1], *keep, hist, eng._flip)
        del old, keep
        eng.nb = None
        release_free_memory()  # the rest of the old list
        eng.nb = self.neighbours(eng, a, b, esx, esy, both, hist, eng.x.copy())
        release_free_memory()  # the new list's temporaries
        eng.box.lo_hold[:] = eng.lo
        eng.box.hi_hold[:] = eng.hi
        eng._build_step = eng.step
        eng.n_rebuilds += 1

    def forces(self, eng, update: bool):
        dt = eng.settings.dt
        L = self.lengths(eng)
        if self.parallel:
            with num_threads(self.threads), disk_cache_off(eng._no_cache):
                K.forces_threaded(eng.p, eng.nb, eng.law, L[0], L[1], dt, update, eng.sc.pvir, eng.sc.pcont, True)
            eng.virial[:] = eng.sc.pvir.sum(axis=0)
            nc, so = eng.sc.pcont.sum(axis=0)
        else:
            with disk_cache_off(eng._no_cache):
                nc, so = K.forces(eng.p, eng.nb, eng.law, L[0], L[1], dt, update, eng.virial, True)
        return nc, so

    def touching(self, eng):
        nb = eng.nb
        L = self.lengths(eng)
        return K.touching_overlaps(eng.x, eng.r, nb.a, nb.b, nb.sx, nb.sy, L[0], L[1])

    def budget_kinetic_energy(self, eng) -> float:
        return eng.kinetic_energy()

    # the loading
    def start_run(self, eng, loading, nsteps: int):
        if not isinstance(loading, (Loading, PrescribedBox)):
            raise InputError(
                f"loading: expected a Loading or a PrescribedBox (the orthogonal cell), got {type(loading).__name__}"
            )
        return (loading, eng.step, eng.step + nsteps, (eng.lo.copy(), eng.hi.copy()))

    def drive(self, eng, run, *args, **kwargs):
        """(Control, nsteps) of ``advance(loading, nsteps=1, phase_step0=0, phase_box0=None)`` or of
        ``advance(nsteps)`` in the run of :meth:`start_run`."""
        if not (len(args) == 1 and not kwargs and isinstance(args[0], (int, np.integer))) and not (
            not args and set(kwargs) == {"nsteps"}
        ):
            return self._drive(eng, *args, **kwargs)  # advance(loading, nsteps, ...): checks the loading
        if run is None:
            raise InputError(
                "advance: give the loading (advance(loading, nsteps)) or call start_run(loading, nsteps) first"
            )
        loading, step0, end, box0 = run
        (nsteps,) = args or (kwargs.pop("nsteps"),)
        nsteps = as_int(
            nsteps, "nsteps", 0, end - eng.step, note=f" (the run ends at step {end}, now at step {eng.step})"
        )
        return self._drive(eng, loading, nsteps, step0, box0)

    def _drive(self, eng, loading, nsteps: int = 1, phase_step0: int = 0, phase_box0=None):
        nsteps = as_int(nsteps, "nsteps", 0)
        if phase_box0 is None:
            phase_box0 = (eng.lo.copy(), eng.hi.copy())
        lo0 = np.array(phase_box0[0], np.float64)
        hi0 = np.array(phase_box0[1], np.float64)
        return _control(loading, eng.step, nsteps, lo0, hi0, phase_step0), nsteps

    def series(self, nsteps: int):
        return K.Series(
            np.zeros((nsteps, 4)), np.zeros((nsteps, 2)), np.zeros(nsteps), np.zeros(nsteps), np.zeros(nsteps),
            np.zeros((nsteps, 4)),
        )  # fmt: skip

    def box_state(self, eng):
        return self.lengths(eng).copy()

    def block(self, eng, ctl, out, done: int, n: int, resume: bool):
        s = eng.settings
        with num_threads(self.threads), disk_cache_off(eng._no_cache):
            return K.run_block(
                eng.p, eng.nb, eng.box, ctl, eng.law, eng.sc, K.Series(*(a[done:] for a in out)), s.dt, s.skin,
                self.clamp, self.parallel, eng.step, n, resume,
            )  # fmt: skip

    def check_divergence(self, eng, out, done: int, k: int, L_before):
        """The divergence check (:meth:`Engine._check_energy`) over the k steps from row ``done``,
        with the work of the orthogonal cell per step -(V_xx dLx/Lx + V_yy dLy/Ly), V the virial
        (stress times the area of the box lengths after each step, compression positive;
        ``L_before`` the lengths before the first)."""
        rows = slice(done, done + k)
        lengths = out.L[rows]
        stress = out.stress[rows]
        L_old = np.vstack([L_before[None], lengths[:-1]])
        area = lengths[:, 0] * lengths[:, 1]
        dw = -(
            stress[:, 0] * area * (lengths[:, 0] - L_old[:, 0]) / L_old[:, 0]
            + stress[:, 1] * area * (lengths[:, 1] - L_old[:, 1]) / L_old[:, 1]
        )
        ke = out.ke[rows]
        eng._check_energy(eng.step + 1, ke, ke, dw)

    def collapse_message(self, eng) -> str:
        return "the cell collapsed"

    def cell_series(self, out) -> dict:
        return {"lengths": out.L}

    # checkpoints (docs/schema_dem.md ``/checkpoint``)
    def cell_arrays(self, eng) -> dict:
        b = eng.box
        return {"box_lo": b.lo, "box_hi": b.hi, "box_lo_hold": b.lo_hold, "box_hi_hold": b.hi_hold}

    def cell_restore(self, eng, arrays: dict):
        eng.box = K.Box(
            *(np.array(arrays[k], np.float64).reshape(2) for k in ("box_lo", "box_hi", "box_lo_hold", "box_hi_hold"))
        )

    def cell_restored(self, eng, arrays: dict):
        pass


#: the orderings of a run: "code" (the code's order, bit for bit with it: :class:`OrthogonalCell`,
#: :class:`gransim.dem.sheared.ShearedCell`) or "fast" (:mod:`gransim.dem.fast`: spatially sorted,
#: half list, banded threads; the same physics to round-off over short horizons, within the chaos
#: envelope over long ones)
ORDERS = ("code", "fast")


def _cell_class(cell: str, order: str, flavour: str):
    """The class of :attr:`Engine.cell_ops` for ``cell``, ``order`` and ``flavour`` (imported on
    first use: each holds its own jitted kernels)."""
    if flavour == "yade":
        if order != "code":
            raise InputError("order: the yade arithmetic runs in YADE's own order (order='code')")
        from .yade_cell import YadeOrthogonalCell, YadeShearedCell  # noqa: PLC0415 - start-up: its kernels

        return YadeOrthogonalCell if cell == "orthogonal" else YadeShearedCell
    if order == "fast":
        from .fast import FastOrthogonalCell, FastShearedCell  # noqa: PLC0415 - start-up: the fast kernels

        return FastOrthogonalCell if cell == "orthogonal" else FastShearedCell
    if cell == "orthogonal":
        return OrthogonalCell
    from .sheared import ShearedCell  # noqa: PLC0415 - start-up: the sheared kernels

    return ShearedCell


def make_engine(
    packing: Packing,
    settings,
    *,
    cell: str = "orthogonal",
    order: str = "code",
    threads: int | None = None,
    law=None,
    flavour: str | None = None,
    velocities=None,
    spins=None,
    check_dt: bool = True,
) -> Engine:
    """The :class:`Engine` of a run: ``cell`` (:data:`CELLS`), ``order`` (:data:`ORDERS`),
    ``threads`` (code order: the threads of mode "parallel", orthogonal cell; fast order: its
    threads), ``law`` (None: the Hooke law of a DEMSettings), ``flavour`` (None:
    ``settings.flavour``)."""
    return Engine(
        packing, settings, velocities, spins, threads, check_dt, None, law, cell=cell, flavour=flavour, order=order
    )


def DEMEngine(
    packing: Packing,
    settings: DEMSettings,
    velocities=None,
    spins=None,
    threads: int | None = None,
    check_dt: bool = True,
    box=None,
    law=None,
) -> Engine:
    """The :class:`Engine` with the orthogonal cell, in the arithmetic of ``settings.flavour``."""
    return Engine(packing, settings, velocities, spins, threads, check_dt, box, law, cell="orthogonal")


#: checkpoint datasets of every cell (docs/schema_dem.md ``/checkpoint``; the cell adds its own, e.g.
#: ``box_lo``): name -> (state object, field, dtype); object "self": a property of the engine (the
#: integer shifts, derived from ``nb.sx``, ``nb.sy``)
CHECKPOINT = {
    "positions": ("p", "x", np.float64),
    "velocities": ("p", "v", np.float64),
    "spins": ("p", "w", np.float64),
    "forces": ("p", "f", np.float64),
    "torques": ("p", "t", np.float64),
    "x_hold": ("nb", "xhold", np.float64),
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
    "CELLS",
    "ORDERS",
    "DEMEngine",
    "DEMSettings",
    "Engine",
    "OrthogonalCell",
    "Loading",
    "check_time_step",
    "PrescribedBox",
    "contact_time",
    "damping_ratio",
    "fingerprint",
    "make_engine",
    "stability_limit",
]
