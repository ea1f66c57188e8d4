"""The DEM engine: disks in an orthogonal periodic cell whose side lengths change each step.

It follows the step of LIGGGHTS-PUBLIC 3.8.0 (serial, ``newton off``, ``neigh_modify delay 0
every 1 check yes``, ``fix deform ... remap x``) so that, with the same settings, trajectories
agree to round-off (shared notes liggghts-3.8.md). Step n:

1. nve/sphere first half step (kernels.initial_integrate);
2. neighbour check with the skin and the box displacement; on a rebuild: wrap into the box,
   new list, tangential springs carried over only for pairs that overlap at that moment;
3. forces with image positions from the current box (= the box of step n-1), virial;
4. second half step;
5. loading: the box moves to its value at step n (servo uses the stress of step n divided by
   the area of box n-1, as a ``fix ave/time`` of ``compute pressure`` evaluated before
   ``fix deform``), positions remapped affinely;
6. stress of step n = virial / area of box n (LIGGGHTS thermo at step n).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from .._numba import check_threads, num_threads
from ..errors import InputError, SimulationError
from ..geometry import Packing
from . import kernels as K
from .settings import AxisControl, DEMSettings, Loading, PrescribedBox

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


def damping_ratio(packing: Packing, settings: DEMSettings) -> float:
    """Damping ratio zeta of the normal contact of the two lightest disks (dimensionless).

    ``gamma_n`` (like ``gamma_t``) is a mass-scaled rate (1/s): the damping coefficient of a
    contact is c = m_eff gamma (LIGGGHTS ``gamman``), so the relative normal motion obeys
    m_eff d'' + m_eff gamma d' + k d = 0, i.e. d'' + 2 zeta omega d' + omega^2 d = 0 with
    omega = sqrt(k/m_eff) and zeta = gamma / (2 omega). The larger of gamma_n, gamma_t and of
    kn, kt are used (the conservative choice for the limit below).
    """
    m = np.sort(packing.masses)
    meff = m[0] * m[1] / (m[0] + m[1])
    omega = np.sqrt(max(settings.kn, settings.kt) / meff)
    return float(max(settings.gamma_n, settings.gamma_t) / (2.0 * omega))


def stability_limit(packing: Packing, settings: DEMSettings) -> float:
    """Largest accepted time step (s): contact_time / STEPS_PER_CONTACT_MIN * (sqrt(1 + zeta^2) - zeta).

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
    (dt_c grows with 1/omega at fixed gamma), zeta from :func:`damping_ratio`.
    """
    k = max(settings.kn, settings.kt)
    z = damping_ratio(packing, settings)
    return contact_time(packing, k) / STEPS_PER_CONTACT_MIN * (float(np.sqrt(1.0 + z * z)) - z)


@dataclass(frozen=True)
class StepRecord:
    """Scalar output of one step."""

    step: int
    stress: np.ndarray  # (2, 2) Love stress, compression positive (N/m in 2D)
    n_contacts: int
    mean_overlap: float


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
        raise InputError(f"box: hi - lo = {(hi - lo).tolist()} m differs from the cell's side lengths "
                         f"{L.tolist()} m")
    return lo, hi


class DEMEngine:
    """State and stepping of one DEM run (arrays are updated in place for speed).

    Parameters
    ----------
    packing : initial packing (orthogonal cell; the box is [0, Lx] x [0, Ly] as in the
        LIGGGHTS data file gransim writes, unless ``box`` is given).
    settings : DEMSettings.
    velocities : (N, 2) m/s, optional. spins : (N,) rad/s, optional.
    threads : numba threads of mode "parallel" (None: numba's current count), set around each kernel
        call and restored afterwards, so an engine leaves the process's thread count alone.
    box : optional (lo, hi), each (2,) (m): the box with its own origin, as a data file's ``xlo xhi
        ylo yhi`` (the positions are taken as they are, in that box; no translation, which would
        round them). hi - lo must equal the diagonal of ``packing.cell`` (to 1e-12 relative).

    Attributes (after construction = LIGGGHTS ``run`` set-up: forces evaluated without
    spring increment): x, v, w, f, t, lo, hi, step, stress, virial.
    """

    def __init__(self, packing: Packing, settings: DEMSettings, velocities=None, spins=None,
                 threads: int | None = None, check_dt: bool = True, box=None):
        C = packing.cell
        if C[0, 1] != 0 or C[1, 0] != 0:
            raise InputError("packing.cell: the DEM engine needs an orthogonal cell "
                             f"(off-diagonal entries {C[0, 1]!r}, {C[1, 0]!r})")
        self.packing = packing
        self.settings = s = settings
        n = packing.n
        if check_dt:
            lim = stability_limit(packing, s)
            if s.dt > lim:
                z = damping_ratio(packing, s)
                raise InputError(f"dt = {s.dt:.4g} s is above the stability limit {lim:.4g} s "
                                 f"(contact time pi sqrt(m_eff/k) = {contact_time(packing, max(s.kn, s.kt)):.4g}"
                                 f" s of the two lightest disks, / {STEPS_PER_CONTACT_MIN:g}, times "
                                 f"sqrt(1 + zeta^2) - zeta = {np.sqrt(1 + z * z) - z:.4g} for the "
                                 f"damping ratio "
                                 f"zeta = {z:.4g})")
        cut = 2 * 2.0 * float(packing.radii.max()) + 2 * s.skin
        if min(C[0, 0], C[1, 1]) <= cut:
            raise InputError(f"packing.cell: side lengths {C[0, 0]:.4g}, {C[1, 1]:.4g} m must exceed "
                             f"2 (2 r_max + skin) = {cut:.4g} m (one periodic image per pair)")
        self.r = np.ascontiguousarray(packing.radii, np.float64)
        # ((pi r) r) rho: the order LIGGGHTS uses reading the data file (Packing.masses may differ
        # in the last bit)
        self.m = np.pi * self.r * self.r * float(packing.density)
        self.x = np.array(packing.positions, np.float64)
        self.v = np.zeros((n, 2)) if velocities is None else np.array(velocities, np.float64).reshape(n, 2)
        self.w = np.zeros(n) if spins is None else np.array(spins, np.float64).reshape(n)
        self.f = np.zeros((n, 2))
        self.t = np.zeros(n)
        self.lo = np.zeros(2)
        self.hi = np.array([C[0, 0], C[1, 1]], np.float64)
        if box is not None:
            self.lo, self.hi = _check_box(box, C)
        self.step = 0
        self.virial = np.zeros(4)
        self.n_contacts = 0
        self.mean_overlap = 0.0
        self.n_rebuilds = 0
        self._parallel = s.mode == "parallel"
        # LAMMPS' arithmetic in the force loop (DEMSettings.flavour, docs/lammps.md)
        self._lammps = s.flavour == "lammps"
        # numba threads of this engine's kernels, set around each call and restored after
        self._threads = check_threads(threads) if self._parallel else None
        self._pvir = np.zeros((n, 4))
        self._pcont = np.zeros((n, 2))
        # neighbour list (empty; built in setup)
        self.ea = np.zeros(0, np.int32)  # int32: memory traffic of the force loop
        self.eb = np.zeros(0, np.int32)
        self.esx = np.zeros(0)
        self.esy = np.zeros(0)
        self.eshift = np.zeros((0, 2), np.int64)
        self.both = np.zeros(0, np.bool_)
        self.xi = np.zeros((0, 2))
        self.slide = np.zeros(0, np.bool_)
        self.ef = np.zeros((0, 2))
        self.start = np.zeros(n + 1, np.int64)
        self._build_step = 0
        self._setup()
        self._reset_energy_budget()

    # ------------------------------------------------------------------ neighbours
    @property
    def box_lengths(self) -> np.ndarray:
        return self.hi - self.lo

    @property
    def cell(self) -> np.ndarray:
        L = self.box_lengths
        return np.diag(L)

    def _rebuild(self, carry: bool):
        bad = K.pbc_wrap(self.x, self.lo, self.hi)
        if bad >= 0:
            raise SimulationError(f"step {self.step}: particle {bad} lost (at {self.x[bad].tolist()}, "
                                  f"box {self.lo.tolist()}..{self.hi.tolist()})")
        L = self.box_lengths
        a, b, esx, esy, both, selfimg = K.build_list_liggghts(self.x, self.r, self.lo, self.hi,
                                                              self.settings.skin)
        if selfimg != -1:
            raise SimulationError(f"step {self.step}: particle {selfimg} is near its own image (or too many ghosts); "
                                  "the cell is too small")
        xi = np.zeros((a.size, 2))
        if carry and self.ea.size:
            K.hand_over(self.x, self.r, a, b, esx, esy, L[0], L[1], self.start, self.eb, self.both, self.xi, xi)
        s = np.stack([esx, esy], axis=1).astype(np.int64)
        self.ea, self.eb, self.esx, self.esy, self.both, self.xi = a, b, esx, esy, both, xi
        self.eshift = s
        self.slide = np.zeros(a.size, np.bool_)
        self.ef = np.zeros((a.size, 2))
        self.start = np.zeros(self.packing.n + 1, np.int64)  # CSR offsets of the entries of each a (sorted)
        np.cumsum(np.bincount(a, minlength=self.packing.n), out=self.start[1:])
        self._set_parallel_scratch()
        self.xhold = self.x.copy()
        self.lo_hold = self.lo.copy()
        self.hi_hold = self.hi.copy()
        self._build_step = self.step
        self.n_rebuilds += 1

    def _set_parallel_scratch(self):
        if self._parallel:
            with num_threads(self._threads):
                self._in_start, self._in_e = K.incoming(self.eb, self.both, self.packing.n)
        else:
            self._in_start, self._in_e = np.zeros(self.packing.n + 1, np.int64), np.zeros(0, np.int64)
        self._tb = np.zeros(self.ea.size)

    def _forces(self, update: bool):
        s = self.settings
        L = self.box_lengths
        if self._parallel:
            with num_threads(self._threads):
                K.forces_parallel(self.x, self.v, self.w, self.r, self.m, self.start, self.eb, self.esx, self.esy,
                                  self.both, self.xi, L[0], L[1], s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt,
                                  update, self.f, self.t, self._pvir, self.slide, self.ef, self._tb, self._pcont,
                                  self._in_start, self._in_e, True, self._lammps)
            self.virial[:] = self._pvir.sum(axis=0)
            nc, so = self._pcont.sum(axis=0)
        else:
            nc, so = K.forces_half(self.x, self.v, self.w, self.r, self.m, self.ea, self.eb, self.esx,
                                   self.esy, self.both, self.xi, L[0], L[1], s.kn, s.kt, s.gamma_n,
                                   s.gamma_t, s.mu, s.dt, update, self.f, self.t, self.virial, self.slide,
                                   self.ef, True, self._lammps)
        self.n_contacts = round(nc)
        self.mean_overlap = so / nc if nc else 0.0

    def elastic_energy(self) -> float:
        """Energy stored in the contact springs, sum 0.5 kn overlap^2 + 0.5 kt |xi|^2 (J)."""
        c = self.contacts()
        s = self.settings
        return float(0.5 * s.kn * np.sum(c["overlap"] ** 2)
                     + 0.5 * s.kt * np.sum(c["tangential_spring"] ** 2))

    def _reset_energy_budget(self):
        """Start of the energy balance of the divergence check: E0 = kinetic + elastic energy now."""
        e0 = self.kinetic_energy() + self.elastic_energy()
        self._energy0 = e0 if np.isfinite(e0) else np.inf  # a non-finite state is caught as NaN
        self._work = 0.0

    def _check_divergence(self, step1, ke, stress, lengths, L_before):
        """Kinetic-energy blow-up over the completed steps step1, step1 + 1, ... (divergence check).

        Energy balance of the run: d(KE + U)/dt = P_cell - D with D >= 0 (viscous damping and
        Coulomb sliding only dissipate, U >= 0 the spring energy), so KE(n) <= E0 + W(n), E0 the
        kinetic + elastic energy at the start and W the work of the cell, per step
        -(V_xx dLx/Lx + V_yy dLy/Ly) with V the virial (stress times area, compression positive).
        The check sums |work| (tangential springs do not follow the affine remap exactly, so the
        virial work is only close to the true one) and allows KINETIC_ENERGY_FACTOR times that
        budget: velocity Verlet below its stability limit keeps the energy within a few ten percent
        (shadow energy), an unstable integration grows exponentially and crosses it in a few steps.
        """
        if not np.all(np.isfinite(ke)):
            k = int(np.flatnonzero(~np.isfinite(ke))[0])
            bad = np.flatnonzero(~np.all(np.isfinite(self.v), axis=1))
            who = f" (particle {int(bad[0])} has velocity {self.v[bad[0]].tolist()})" if bad.size else ""
            raise SimulationError(f"step {step1 + k}: the kinetic energy is not finite{who}")
        L_old = np.vstack([L_before[None], lengths[:-1]])
        area = lengths[:, 0] * lengths[:, 1]
        dw = -(stress[:, 0] * area * (lengths[:, 0] - L_old[:, 0]) / L_old[:, 0]
               + stress[:, 1] * area * (lengths[:, 1] - L_old[:, 1]) / L_old[:, 1])
        work = self._work + np.cumsum(np.abs(dw))
        budget = KINETIC_ENERGY_FACTOR * (self._energy0 + work)
        over = np.flatnonzero(ke > budget)
        if over.size:
            k = int(over[0])
            raise SimulationError(
                f"step {step1 + k}: kinetic energy blow-up: {ke[k]:.4g} J exceeds {KINETIC_ENERGY_FACTOR:g} "
                f"times the energy the run has had ({self._energy0:.4g} J kinetic + elastic at the start, "
                f"{work[k]:.4g} J gross work of the cell; damping and friction only dissipate): the "
                f"integration is unstable (time step {self.settings.dt:.4g} s too large for the stiffness "
                "and damping?)")
        if work.size:
            self._work = float(work[-1])

    def _check_lost(self):
        """Before a rebuild: a particle that moved more than LOST_DISPLACEMENT_SKINS skins since the
        last build crossed more than a skin in one step (the build rule allows skin/2 in between)."""
        d = np.sqrt(np.einsum("ij,ij->i", self.x - self.xhold, self.x - self.xhold))
        i = int(np.argmax(d)) if d.size else 0
        skin = self.settings.skin
        if d.size and d[i] > LOST_DISPLACEMENT_SKINS * skin:
            raise SimulationError(
                f"step {self.step + 1}: particle {i} lost: it moved {d[i]:.4g} m = {d[i] / skin:.3g} "
                f"skins since "
                f"the neighbour build of step {self._build_step}, more than a skin ({skin:.4g} m) in "
                f"one step "
                f"(velocity {self.v[i].tolist()} m/s, dt {self.settings.dt:.4g} s)")

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
        the box after the step), ``lengths`` (n, 2), ``n_contacts`` (n,), ``mean_overlap`` (n,), ``kinetic_energy`` (n,),
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
        nsteps = int(nsteps)
        if phase_box0 is None:
            phase_box0 = (self.lo.copy(), self.hi.copy())
        lo0 = np.array(phase_box0[0], np.float64)
        hi0 = np.array(phase_box0[1], np.float64)
        presc = isinstance(loading, PrescribedBox)
        if presc:
            if nsteps and not (loading.step0 <= self.step and self.step + nsteps <= loading.last_step):
                raise InputError(f"prescribed box: the table covers steps {loading.step0 + 1}.."
                                 f"{loading.last_step}, the run needs {self.step + 1}..{self.step + nsteps}")
            modes = np.zeros(2, np.int64)
            rates = targets = gains = np.zeros(2)
            # writeable copies: one compiled signature of run_block for both loadings
            p_lo, p_hi = np.array(loading.lo), np.array(loading.hi)
            p_remap, p_step0 = np.array(loading.remap), loading.step0
        elif isinstance(loading, Loading):
            code = {"fixed": 0, "rate": 1, "servo": 2}
            modes = np.array([code[loading.x.mode], code[loading.y.mode]], np.int64)
            rates = np.array([loading.x.rate, loading.y.rate])
            targets = np.array([loading.x.target, loading.y.target])
            gains = np.array([loading.x.gain, loading.y.gain])
            p_lo = p_hi = np.zeros((1, 2))
            p_remap = np.zeros(1, np.bool_)
            p_step0 = 0
        else:
            raise InputError(f"loading: expected a Loading or a PrescribedBox, got {type(loading).__name__}")
        out_stress = np.zeros((nsteps, 4))
        out_L = np.zeros((nsteps, 2))
        out_nc = np.zeros(nsteps)
        out_ov = np.zeros(nsteps)
        out_ke = np.zeros(nsteps)
        out_vir = np.zeros((nsteps, 4))
        done = 0
        resume = False
        step_start = self.step
        while done < nsteps:
            L_before = self.box_lengths.copy()
            with num_threads(self._threads):
                k, status, bad = K.run_block(
                    self.x, self.v, self.w, self.f, self.t, self.r, self.m, self.ea, self.eb, self.esx, self.esy,
                    self.both, self.xi, self.slide, self.ef, self.xhold, self.lo, self.hi, self.lo_hold,
                    self.hi_hold, self.virial, s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt, s.skin, self.step,
                    nsteps - done, resume, modes, rates, targets, gains, lo0, hi0, phase_step0,
                    out_stress[done:], out_L[done:], out_nc[done:], out_ov[done:], out_ke[done:],
                    self._parallel, self.start, self._pvir, self._pcont, self._tb, self._in_start, self._in_e,
                    self._lammps, presc, p_lo, p_hi, p_remap, p_step0, out_vir[done:])
            if k:
                self._check_divergence(self.step + 1, out_ke[done:done + k], out_stress[done:done + k],
                                       out_L[done:done + k], L_before)
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
                raise SimulationError(f"step {self.step + 1}: particle {bad} has a non-finite position "
                                      f"{self.x[bad].tolist()} (velocity {self.v[bad].tolist()})")
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
        return {"step": np.arange(step_start + 1, step_start + nsteps + 1), "stress": st, "lengths": out_L,
                "n_contacts": np.rint(out_nc).astype(np.int64), "mean_overlap": out_ov, "kinetic_energy": out_ke,
                "virial": out_vir}

    # ------------------------------------------------------------------ diagnostics
    def kinetic_energy(self) -> float:
        """Translational + rotational (I = m r^2/2) kinetic energy (J)."""
        return float(0.5 * np.sum(self.m * np.einsum("ij,ij->i", self.v, self.v))
                     + 0.25 * np.sum(self.m * self.r**2 * self.w**2))

    def contacts(self):
        """Touching pairs, each once (i < j): dict of i, j, shift (l_ij = x_j + C n - x_i), force on
        j applied in the last step (N), overlap (m), tangential spring (frame of i), sliding."""
        L = self.box_lengths
        touch = K.overlapping(self.x, self.r, self.ea, self.eb, self.esx, self.esy, L[0], L[1])
        keep = touch & (self.ea < self.eb)
        e = np.nonzero(keep)[0]
        a, b = self.ea[e], self.eb[e]
        d = self.x[a] - (self.x[b] + self.eshift[e] * L)
        ov = self.r[a] + self.r[b] - np.sqrt(np.einsum("ij,ij->i", d, d))
        # entry (a, b, s): b's image is x_b + s L, so l_ab = x_b + C s - x_a (the schema's shift)
        return {"i": a.astype(np.int64), "j": b.astype(np.int64), "shift": self.eshift[e].astype(np.int64), "force": -self.ef[e],
                "overlap": ov, "tangential_spring": self.xi[e].copy(), "sliding": self.slide[e].copy()}

    def state_arrays(self) -> dict:
        """Everything needed to continue bit for bit (checkpoint)."""
        return {"positions": self.x, "velocities": self.v, "spins": self.w, "forces": self.f,
                "torques": self.t, "box_lo": self.lo, "box_hi": self.hi, "x_hold": self.xhold,
                "box_lo_hold": self.lo_hold, "box_hi_hold": self.hi_hold,
                "neighbours/a": self.ea, "neighbours/b": self.eb, "neighbours/shift": self.eshift,
                "neighbours/owned_both": self.both, "neighbours/xi": self.xi,
                "virial": self.virial}

    def restore(self, arrays: dict, step: int):
        """Inverse of :meth:`state_arrays`."""
        self.x = np.array(arrays["positions"])
        self.v = np.array(arrays["velocities"])
        self.w = np.array(arrays["spins"])
        self.f = np.array(arrays["forces"])
        self.t = np.array(arrays["torques"])
        self.lo = np.array(arrays["box_lo"])
        self.hi = np.array(arrays["box_hi"])
        self.xhold = np.array(arrays["x_hold"])
        self.lo_hold = np.array(arrays["box_lo_hold"])
        self.hi_hold = np.array(arrays["box_hi_hold"])
        self.ea = np.array(arrays["neighbours/a"], np.int32)
        self.eb = np.array(arrays["neighbours/b"], np.int32)
        self.eshift = np.array(arrays["neighbours/shift"], np.int64).reshape(-1, 2)
        self.esx = np.ascontiguousarray(self.eshift[:, 0], np.float64)
        self.esy = np.ascontiguousarray(self.eshift[:, 1], np.float64)
        self.both = np.array(arrays["neighbours/owned_both"], np.bool_)
        self.xi = np.array(arrays["neighbours/xi"]).reshape(-1, 2)
        self.virial = np.array(arrays["virial"])
        self.slide = np.zeros(self.ea.size, np.bool_)
        self.ef = np.zeros((self.ea.size, 2))
        self.start = np.searchsorted(self.ea, np.arange(self.packing.n + 1)).astype(np.int64)
        self._set_parallel_scratch()
        self.step = int(step)
        self.stress = self.stress_tensor(self.box_lengths)
        self._build_step = self.step
        self._reset_energy_budget()


__all__ = [
    "STEPS_PER_CONTACT_MIN",
    "AxisControl",
    "DEMEngine",
    "DEMSettings",
    "Loading",
    "PrescribedBox",
    "contact_time",
    "damping_ratio",
    "fingerprint",
    "stability_limit",
]
