"""Numba kernels of the DEM step (contiguous float64/int64 arrays; no validation here).

Order of one step (LIGGGHTS 3.8.0 ``verlet.cpp``, serial; docs/liggghts.md; LAMMPS' is the same):
``initial_integrate`` -> ``check_rebuild`` (-> ``pbc_wrap`` + new list) -> ``forces`` ->
``final_integrate`` -> box change with ``remap_x``. Mode "parallel" runs the same step on numba's
threads in tasks of :data:`PARTICLE_BLOCK` particles: ``initial_check_threaded`` ->
(``pbc_wrap`` + new list, its pair passes threaded) -> ``forces_threaded`` -> ``final_threaded``
-> ``remap_x``; the same arithmetic per particle and pair, the sums in another (fixed) order.

The step loop :func:`run_block` and the force loops take a few namedtuples of arrays
(:class:`Particles`, :class:`Neighbours`, :class:`Box`, :class:`Control`, :class:`Scratch`,
:class:`Series`) and a contact-law object (:mod:`gransim.contacts.laws`): the law is called
through ``pair_force(law, ...)``, resolved at compile time by the law's type, so each law gets its
own compiled (and disk-cached) loop and a new law needs no edit here. The LAMMPS 29Sep2021
arithmetic (``DEMSettings(flavour="lammps")``, docs/lammps.md) is the law "hooke-lammps" (its
spring reset to zero whenever its pair does not touch) plus the clamped rebuild rule
(:func:`check_rebuild`); the integrator, the box deformation and the neighbour list are the same
in both codes.

The force loops have one skeleton: evaluate the law on the list entries, then accumulate in the
order the ordering requires. Evaluation: entry by entry (:func:`_pair`, the law's pair function,
any law, either cell) or, for a law that offers a branch-free block path (``LawSpec.select``: the
Hooke laws), over blocks of :data:`ENTRY_BLOCK` entries as SIMD code (:func:`_select_block`);
the choice is made at compile time from the law's registration (:func:`_serial_dispatch`,
:func:`_threaded_dispatch`), no class is named here. Accumulation: the codes' serial order (force
on a, on b for an owned pair, virial per owner, contacts, overlap, entry by entry in list order:
:func:`_tally_serial`, written out in :func:`_serial_loop`, where the inlined helper cost the
sheared cell's loop 13 %, bench.ab_dem --mode sheared) or the threaded order
(:func:`_tally_particle`: each particle's own sums, then the incoming entries,
:func:`_incoming_forces`). So four loops, each an evaluation and an accumulation:
:func:`_serial_loop` (entries; the loop of the sheared cell too, whose image is a second
compile-time plug-in: :data:`OrthoImage`, :data:`TiltedImage`,
:func:`image_branch`, :func:`image_velocity`), :func:`_serial_block_loop` (blocks),
:func:`_threaded_scalar_loop` (entries) and :func:`_threaded_block_loop` (blocks); the block and
the threaded loops are ``parallel=True`` kernels on unpacked arrays (gransim/_numba.py, "Unpacked
arrays"). Every evaluation of a contact is the same operations in the same order, so all loops
give each contact's force bit for bit alike (tests/dem/test_simd_bitwise.py,
test_threaded_bitwise.py).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba.extending import overload

from .._numba import njit, pjit, prange
from ..contacts.laws import make_law, offers_select, pair_apart, pair_force_split, pair_select

#: particle state: x (N, 2) m, v (N, 2) m/s, w (N,) rad/s, f (N, 2) N, t (N,) N m, m (N,) kg, r (N,) m
Particles = namedtuple("Particles", ["x", "v", "w", "f", "t", "m", "r"])
#: neighbour/contact state of one list build (M entries (a, b, s): b's image x_b + s L seen from a):
#: a, b (M,) int32; shift (M, 2) int64 = s, sx, sy (M,) float64 its columns; both (M,) bool (owned
#: pair, s = 0: the force acts on both); hist (M, width) the law's per-contact history (frame of a);
#: start (N+1,) int64 CSR of the entries of each a; in_start (N+1,), in_e the owned entries by b
#: (threaded loop only, else empty); xhold (N, 2) positions at the build; slide (M,) bool, ef (M, 2)
#: N, tb (M,) N m: per-entry outputs of the last force evaluation (cap flag, force on a, torque on b)
Neighbours = namedtuple(
    "Neighbours",
    ["a", "b", "shift", "sx", "sy", "both", "hist", "start", "in_start", "in_e", "xhold", "slide", "ef", "tb"],
)
#: the box: lo, hi (2,) m now; lo_hold, hi_hold (2,) at the last neighbour build (updated in place)
Box = namedtuple("Box", ["lo", "hi", "lo_hold", "hi_hold"])
#: loading of the box (:func:`box_target`, :func:`run_block`): modes (2,) int64 0 fixed / 1 rate /
#: 2 servo, rates (2,) 1/s, targets (2,) N/m, gains (2,) 1/(Pa s), lo0, hi0 (2,) m the box at the
#: phase start, phase_step0 int; presc bool: the box from the table presc_lo, presc_hi (T, 2) m on
#: the rows with presc_remap (T,) bool, row 0 = step presc_step0
Control = namedtuple(
    "Control",
    [
        "modes",
        "rates",
        "targets",
        "gains",
        "lo0",
        "hi0",
        "phase_step0",
        "presc",
        "presc_lo",
        "presc_hi",
        "presc_remap",
        "presc_step0",
    ],
)
#: per-step work arrays: vir (4,) virial xx, yy, xy, yx (N m); pvir (N, 4), pcont (N, 2) the
#: per-particle virial and (contacts, overlap) sums of the threaded loop
Scratch = namedtuple("Scratch", ["vir", "pvir", "pcont"])
#: per-step output rows of :func:`run_block`: stress (n, 4) N/m, L (n, 2) m, nc (n,), ov (n,) m,
#: ke (n,) J, vir (n, 4) N m
Series = namedtuple("Series", ["stress", "L", "nc", "ov", "ke", "vir"])


@njit
def initial_integrate(x, v, w, f, t, m, r, dt):
    """nve/sphere first half: v += dt/2 f/m; x += dt v; w += dt/2 T/I with I = m r^2/2."""
    for i in range(x.shape[0]):
        _first_half(i, x, v, w, f, t, m, r, dt)


@njit(inline="always")
def _first_half(i, x, v, w, f, t, m, r, dt):
    # particle i's first half step (initial_integrate, initial_check_threaded)
    dtf = 0.5 * dt
    dtfm = dtf / m[i]
    v[i, 0] += dtfm * f[i, 0]
    v[i, 1] += dtfm * f[i, 1]
    x[i, 0] += dt * v[i, 0]
    x[i, 1] += dt * v[i, 1]
    w[i] += (dtf / 0.5) / (r[i] * r[i] * m[i]) * t[i]


@njit(inline="always")
def _second_half(i, v, w, f, t, m, r, dt):
    # particle i's second half step and its kinetic energy (J) (final_integrate, final_threaded)
    dtf = 0.5 * dt
    dtfm = dtf / m[i]
    v[i, 0] += dtfm * f[i, 0]
    v[i, 1] += dtfm * f[i, 1]
    w[i] += (dtf / 0.5) / (r[i] * r[i] * m[i]) * t[i]
    return 0.5 * m[i] * (v[i, 0] * v[i, 0] + v[i, 1] * v[i, 1]) + 0.25 * m[i] * r[i] * r[i] * w[i] * w[i]


@njit
def final_integrate(v, w, f, t, m, r, dt):
    """nve/sphere second half: v += dt/2 f/m; w += dt/2 T/I. Returns the kinetic energy
    sum m v^2/2 + m r^2 w^2/4 (J) of the full-step velocities."""
    ke = 0.0
    for i in range(v.shape[0]):
        ke += _second_half(i, v, w, f, t, m, r, dt)
    return ke


@njit
def rebuild_deltasq(lo, hi, lo_hold, hi_hold, skin, clamp):
    """delta^2 of :func:`check_rebuild`: delta = 0.5 (skin - |d lo| - |d hi|) (m), 0 when negative
    and ``clamp`` (LAMMPS)."""
    dx = lo[0] - lo_hold[0]
    dy = lo[1] - lo_hold[1]
    d1 = math.sqrt(dx * dx + dy * dy)
    dx = hi[0] - hi_hold[0]
    dy = hi[1] - hi_hold[1]
    d2 = math.sqrt(dx * dx + dy * dy)
    delta = 0.5 * (skin - (d1 + d2))
    if clamp and delta < 0.0:
        delta = 0.0
    return delta * delta


#: particles per task of the threaded kernels of mode "parallel" (:func:`initial_check_threaded`,
#: :func:`final_threaded`, :func:`_threaded_block_loop`, :func:`_threaded_scalar_loop`,
#: :func:`_incoming_forces`, :func:`_liggghts_pairs_threaded`): fixed, so that the results do not
#: depend on the thread count (the engine runs a packing of one task on one thread)
PARTICLE_BLOCK = 1024


@pjit
def initial_check_threaded(x, v, w, f, t, m, r, dt, xhold, deltasq):
    """:func:`initial_integrate` then the particle test of :func:`check_rebuild` in one pass,
    tasks of :data:`PARTICLE_BLOCK` particles over the threads: the same arithmetic per particle
    (positions and velocities bit for bit those of the two serial kernels) and the same answer
    (rebuild, first non-finite particle or -1)."""
    n = x.shape[0]
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    flags = np.zeros(ntask, np.int64)
    bads = np.full(ntask, -1, np.int64)
    for c in prange(ntask):
        fl = 0
        bad = -1
        for i in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            _first_half(i, x, v, w, f, t, m, r, dt)
            if bad < 0 and not (math.isfinite(x[i, 0]) and math.isfinite(x[i, 1])):
                bad = i
            dx = x[i, 0] - xhold[i, 0]
            dy = x[i, 1] - xhold[i, 1]
            if dx * dx + dy * dy > deltasq:
                fl = 1
        flags[c] = fl
        bads[c] = bad
    for c in range(ntask):
        if bads[c] >= 0:
            return True, bads[c]
    return flags.sum() > 0, -1


@pjit
def final_threaded(v, w, f, t, m, r, dt, pvir, pcont, vir):
    """:func:`final_integrate` (velocities bit for bit) and the sums of the per-particle virial
    ``pvir`` (N, 4) into ``vir`` (4,) and of ``pcont`` (N, 2), tasks of :data:`PARTICLE_BLOCK`
    particles over the threads, each task's partial sums added in task order (deterministic; the
    order differs from the serial sums: round-off). Returns (kinetic energy (J), contacts, sum of
    overlaps (m))."""
    n = v.shape[0]
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    part = np.zeros((ntask, 7))
    for c in prange(ntask):
        ke = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        s3 = 0.0
        nc = 0.0
        so = 0.0
        for i in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            ke += _second_half(i, v, w, f, t, m, r, dt)
            s0 += pvir[i, 0]
            s1 += pvir[i, 1]
            s2 += pvir[i, 2]
            s3 += pvir[i, 3]
            nc += pcont[i, 0]
            so += pcont[i, 1]
        part[c, 0] = ke
        part[c, 1] = s0
        part[c, 2] = s1
        part[c, 3] = s2
        part[c, 4] = s3
        part[c, 5] = nc
        part[c, 6] = so
    tot = np.zeros(7)
    for c in range(ntask):
        for k in range(7):
            tot[k] += part[c, k]
    for k in range(4):
        vir[k] = tot[1 + k]
    return tot[0], tot[5], tot[6]


@njit
def check_rebuild(x, xhold, lo, hi, lo_hold, hi_hold, skin, clamp=True):
    """Neighbor::check_distance with box check. Returns (rebuild, bad particle or -1).

    Trigger: some |x - x_hold|^2 > delta^2 (strictly), delta = 0.5 (skin - |d lo| - |d hi|).
    ``clamp``: LAMMPS sets a negative delta (the box moved more than the skin since the build) to
    0, so every step then rebuilds (29Sep2021 neighbor.cpp:2133-2135); LIGGGHTS 3.8.0 squares the
    negative delta as it is (neighbor.cpp:1400-1401): pass ``clamp=False`` for its flavour. A NaN
    or infinite coordinate returns its particle index as ``bad``.
    """
    deltasq = rebuild_deltasq(lo, hi, lo_hold, hi_hold, skin, clamp)
    flag = False
    for i in range(x.shape[0]):
        if not (math.isfinite(x[i, 0]) and math.isfinite(x[i, 1])):
            return True, i
        dx = x[i, 0] - xhold[i, 0]
        dy = x[i, 1] - xhold[i, 1]
        if dx * dx + dy * dy > deltasq:
            flag = True
    return flag, -1


@njit
def largest_displacement(x, xhold):
    """(i, |x_i - xhold_i|) of the particle that moved most (m), the first one of equal moves; a
    NaN distance wins, as in ``numpy.argmax`` (the engine's lost-particle check, without (N, 2)
    temporaries)."""
    best = -1.0
    k = 0
    for i in range(x.shape[0]):
        dx = x[i, 0] - xhold[i, 0]
        dy = x[i, 1] - xhold[i, 1]
        d = math.sqrt(dx * dx + dy * dy)
        if d != d:
            return i, d
        if d > best:
            best = d
            k = i
    return k, best


@njit
def pbc_wrap(x, lo, hi):
    """Domain::pbc: x < lo -> x += L; x >= hi -> x -= L, then max(x, lo). Returns a lost
    particle (still outside after one wrap) or -1."""
    bad = -1
    for d in range(2):
        prd = hi[d] - lo[d]
        for i in range(x.shape[0]):
            if x[i, d] < lo[d]:
                x[i, d] += prd
            if x[i, d] >= hi[d]:
                x[i, d] -= prd
                x[i, d] = max(x[i, d], lo[d])
            if (x[i, d] < lo[d] or x[i, d] >= hi[d]) and bad < 0:
                bad = i
    return bad


@njit
def remap_x(x, lo_old, hi_old, lo_new, hi_new):
    """fix deform ``remap x``: lambda = (x - lo_old)/L_old; x = L_new lambda + lo_new (per axis)."""
    for d in range(2):
        hinv = 1.0 / (hi_old[d] - lo_old[d])
        h = hi_new[d] - lo_new[d]
        for i in range(x.shape[0]):
            lam = hinv * (x[i, d] - lo_old[d])
            x[i, d] = h * lam + lo_new[d]


@njit
def overlapping(x, r, ea, eb, esx, esy, Lx, Ly):
    """For each list entry (a, b, s): does a touch the image x_b + s L? (LIGGGHTS' rsq < radsum^2)."""
    out = np.zeros(ea.shape[0], np.bool_)
    for e in range(ea.shape[0]):
        a = ea[e]
        b = eb[e]
        delx = x[a, 0] - (x[b, 0] + esx[e] * Lx)
        dely = x[a, 1] - (x[b, 1] + esy[e] * Ly)
        radsum = r[a] + r[b]
        out[e] = delx * delx + dely * dely < radsum * radsum
    return out


@njit
def touching_overlaps(x, r, ea, eb, esx, esy, Lx, Ly):
    """The touching entries with a < b (each physical contact once; :func:`overlapping`'s test)
    and their overlaps r_a + r_b - |x_a - (x_b + s L)| (m), in list order: (entries (K,) int64,
    overlaps (K,)). Two passes over the list and no (K, 2) temporaries (the engine's contact
    queries at 1e6 disks held about 170 MiB of them)."""
    k = 0
    for e in range(ea.shape[0]):
        a = ea[e]
        b = eb[e]
        delx = x[a, 0] - (x[b, 0] + esx[e] * Lx)
        dely = x[a, 1] - (x[b, 1] + esy[e] * Ly)
        radsum = r[a] + r[b]
        if a < b and delx * delx + dely * dely < radsum * radsum:
            k += 1
    idx = np.empty(k, np.int64)
    ov = np.empty(k)
    k = 0
    for e in range(ea.shape[0]):
        a = ea[e]
        b = eb[e]
        delx = x[a, 0] - (x[b, 0] + esx[e] * Lx)
        dely = x[a, 1] - (x[b, 1] + esy[e] * Ly)
        rsq = delx * delx + dely * dely
        radsum = r[a] + r[b]
        if a < b and rsq < radsum * radsum:
            idx[k] = e
            ov[k] = radsum - math.sqrt(rsq)
            k += 1
    return idx, ov


#: the image of an orthogonal cell (:func:`forces`): side lengths Lx, Ly (m); image of (b, s) at
#: x_b + (s_x Lx, s_y Ly), moving with v_b (``fix deform ... remap x``)
OrthoImage = namedtuple("OrthoImage", ["Lx", "Ly"])
#: the image of LAMMPS' sheared (triclinic) cell (:func:`tilted_image`): box (5,) = (lo_x, lo_y,
#: hi_x, hi_y, xy) m; hr (3,) = (h_rate[0], h_rate[1], h_rate[5]) m/s; lam (N, 2) lamda
#: coordinates and use_lam (images from lamda: the step of a list build); touch (M,) bool receives
#: the contact flag of every entry (LAMMPS' ``fix neigh/history`` keeps the touching ones)
TiltedImage = namedtuple("TiltedImage", ["box", "hr", "lam", "use_lam", "touch"])


@njit(inline="always")
def tilted_image(b, sx, sy, x, lam, use_lam, box):
    """Position of the image (b, s) in the sheared cell: from lamda (LAMMPS borders + lamda2x, the
    step of a list build) or owner + shift of the current box (LAMMPS forward_comm, other steps):
    x_b + s_x (Lx, 0) + s_y (xy, Ly), in LAMMPS' order (docs/shear.md)."""
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    h5 = box[4]
    if use_lam:
        l0 = lam[b, 0] + sx
        l1 = lam[b, 1] + sy
        return ((h0 * l0 + h5 * l1) + 0.0) + box[0], (h1 * l1 + 0.0) + box[1]
    return (x[b, 0] + sx * h0) + sy * h5, x[b, 1] + sy * h1


def image_branch(img, x, a, b, sx, sy):
    """Branch d = x_a - image of (b, s) in the cell ``img`` (:data:`OrthoImage` or
    :data:`TiltedImage`; resolved at compile time by its type). Interpreted fallback."""
    if isinstance(img, OrthoImage):
        return x[a, 0] - (x[b, 0] + sx * img.Lx), x[a, 1] - (x[b, 1] + sy * img.Ly)
    xb, yb = tilted_image(b, sx, sy, x, img.lam, img.use_lam, img.box)
    return x[a, 0] - xb, x[a, 1] - yb


def image_velocity(img, v, b, sx, sy):
    """Velocity of the image (b, s): v_b in the orthogonal cell; v_b + s_x (h_rate[0], 0) + s_y
    (h_rate[5], h_rate[1]) in the sheared one (``pack_comm_vel`` with ``deform_vremap``)."""
    if isinstance(img, OrthoImage):
        return v[b, 0], v[b, 1]
    hr = img.hr
    return (v[b, 0] + sx * hr[0]) + sy * hr[2], v[b, 1] + sy * hr[1]


def image_mark(img, e, touch):
    """Record the contact flag of entry ``e`` (the sheared cell's ``touch``; nothing otherwise)."""
    if not isinstance(img, OrthoImage):
        img.touch[e] = touch


def _is_ortho(img):
    return getattr(img, "instance_class", None) is OrthoImage


@overload(image_branch, inline="always")
def _ov_image_branch(img, x, a, b, sx, sy):
    if _is_ortho(img):

        def ortho(img, x, a, b, sx, sy):
            return x[a, 0] - (x[b, 0] + sx * img.Lx), x[a, 1] - (x[b, 1] + sy * img.Ly)

        return ortho

    def tilted(img, x, a, b, sx, sy):
        xb, yb = tilted_image(b, sx, sy, x, img.lam, img.use_lam, img.box)
        return x[a, 0] - xb, x[a, 1] - yb

    return tilted


@overload(image_velocity, inline="always")
def _ov_image_velocity(img, v, b, sx, sy):
    if _is_ortho(img):

        def ortho(img, v, b, sx, sy):
            return v[b, 0], v[b, 1]

        return ortho

    def tilted(img, v, b, sx, sy):
        hr = img.hr
        return (v[b, 0] + sx * hr[0]) + sy * hr[2], v[b, 1] + sy * hr[1]

    return tilted


@overload(image_mark, inline="always")
def _ov_image_mark(img, e, touch):
    if _is_ortho(img):

        def ortho(img, e, touch):
            return None

        return ortho

    def tilted(img, e, touch):
        img.touch[e] = touch

    return tilted


@njit(inline="always")
def _pair(law, img, e, a, b, x, v, w, r, m, sx, sy, hist, dt, update):
    """One list entry (a, b, s) in the cell ``img``: branch d = x_a - image of (b, s)
    (:func:`image_branch`), and when the disks touch (rsq < radsum^2, the test of both codes) the
    pair function of ``law`` (:func:`gransim.contacts.laws.pair_force`) with the image's velocity
    (:func:`image_velocity`) and the history row ``hist[e]`` updated in place; otherwise the law's
    ``apart`` (LAMMPS: the history zeroed, ``PairGranHookeHistory::compute``; LIGGGHTS keeps it
    until the next list build).

    Returns (touch, delx, dely, rsq, radsum, fx, fy, torque on a, torque on b, sliding, second
    torque on a, second torque on b); the force (fx, fy) acts on a; the second torques are added
    after the first (``LawSpec.split_torque``: LAMMPS' rolling torque; -0.0 for the other laws).
    Shared by the serial loop of both cells and the threaded loop: the same operations in the same
    order, so all evaluate every contact identically.
    """
    delx, dely = image_branch(img, x, a, b, sx, sy)
    rsq = delx * delx + dely * dely
    radsum = r[a] + r[b]
    if rsq < radsum * radsum:
        vbx, vby = image_velocity(img, v, b, sx, sy)
        fx, fy, tqa, tqb, sl, _, tqa2, tqb2 = pair_force_split(
            law, hist, e, delx, dely, rsq, r[a], r[b], v[a, 0], v[a, 1], vbx, vby, w[a], w[b], m[a], m[b], dt, update
        )
        return True, delx, dely, rsq, radsum, fx, fy, tqa, tqb, sl, tqa2, tqb2
    pair_apart(law, hist, e)
    return False, delx, dely, rsq, radsum, 0.0, 0.0, 0.0, 0.0, False, -0.0, -0.0


@njit(inline="always")
def _entry(law, e, a, b, x, v, w, r, m, esx, esy, hist, Lx, Ly, dt, update):
    """:func:`_pair` of the orthogonal cell with side lengths (Lx, Ly): image x_b + s L."""
    return _pair(law, OrthoImage(Lx, Ly), e, a, b, x, v, w, r, m, esx[e], esy[e], hist, dt, update)


@njit
def forces(p, nb, law, Lx, Ly, dt, update, vir, store):
    """Serial force loop over the half list ``nb`` (LIGGGHTS ``newton off``) with the contact law
    ``law`` (any registered law: :mod:`gransim.contacts.laws`; one compiled copy per law type) in
    the orthogonal cell of side lengths (Lx, Ly) (m): :func:`forces_in` with :data:`OrthoImage`,
    or, for a law that offers a branch-free block path (``LawSpec.select``: the Hooke laws), the
    same loop as SIMD code (:func:`_serial_block_loop`, bit for bit the same results)."""
    return _serial_dispatch(p, nb, law, Lx, Ly, dt, update, vir, store)


def _serial_blocks(p, nb, law, Lx, Ly, dt, update, vir, store):
    acc = np.empty(2)
    _serial_block_loop(
        p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.a, nb.b, nb.sx, nb.sy, nb.both.view(np.uint8), nb.hist,
        nb.slide.view(np.uint8), nb.ef,
        law, Lx, Ly, dt, update, vir, store, acc,
    )  # fmt: skip
    return acc[0], acc[1]


def _serial_entries(p, nb, law, Lx, Ly, dt, update, vir, store):
    return _serial_loop(p, nb, law, OrthoImage(Lx, Ly), dt, update, vir, store)


def _serial_dispatch(p, nb, law, Lx, Ly, dt, update, vir, store):
    """The serial orthogonal-cell force loop for ``law`` (resolved at compile time by its type):
    :func:`_serial_block_loop` for a law that offers a block path, the entry-by-entry
    :func:`_serial_loop` otherwise. Interpreted (NUMBA_DISABLE_JIT): the same choice."""
    fn = _serial_blocks if offers_select(type(law)) else _serial_entries
    return fn(p, nb, law, Lx, Ly, dt, update, vir, store)


# not inline="always": inlined at numba's IR level, this overload doubled the compile time of every
# law's step loop (hertz-liggghts' biaxial run 12-14 s -> 21 s of CPU, measured); as a call it adds
# nothing measurable per step
@overload(_serial_dispatch)
def _ov_serial_dispatch(p, nb, law, Lx, Ly, dt, update, vir, store):
    return _serial_blocks if offers_select(law) else _serial_entries


@njit(inline="always")
def _tally_serial(a, b, owned, fx, fy, ta, tb, ta2, tb2, delx, dely, ov, f, t, v0, v1, v2, v3, nc, so):
    """One touching entry (a, b) summed in the codes' order (``newton off``): force and torque on
    a, minus the force and b's torque on b when the pair is owned (``owned``; a boundary copy acts
    on its owner a only), the second torques after the first (``LawSpec.split_torque``; -0.0, an
    exact no-op, for the other laws), the virial 0.5 d (x) f per owner (``ev_tally_xyz``; N m) and
    the contact weight (1 owned, 1/2 a boundary copy) and its overlap ``ov`` (m). Returns the sums
    (v0, v1, v2, v3, contacts, overlap). The accumulation of :func:`_serial_block_loop`
    (:func:`_serial_loop` has the same operations written out)."""
    f[a, 0] += fx
    f[a, 1] += fy
    t[a] += ta
    t[a] += ta2
    wgt = 0.5
    if owned:
        f[b, 0] += -fx
        f[b, 1] += -fy
        t[b] += tb
        t[b] += tb2
        v0 += 0.5 * (delx * fx)
        v1 += 0.5 * (dely * fy)
        v2 += 0.5 * (delx * fy)
        v3 += 0.5 * (dely * fx)
        wgt = 1.0
    v0 += 0.5 * (delx * fx)
    v1 += 0.5 * (dely * fy)
    v2 += 0.5 * (delx * fy)
    v3 += 0.5 * (dely * fx)
    return v0, v1, v2, v3, nc + wgt, so + wgt * ov


@njit(inline="always")
def _tally_particle(owned, fx, fy, ta, ta2, delx, dely, ov, fxa, fya, tqa, v0, v1, v2, v3, nc, so):
    """One touching entry of particle a summed into a's own sums (the first pass of the threaded
    loops, particle by particle): force, torque (then the second torque), virial weighted 1 for an
    owned pair and 1/2 for a boundary copy (a's share; b's comes with its incoming entries),
    contacts and overlap. Returns (fxa, fya, tqa, v0, v1, v2, v3, contacts, overlap). The
    accumulation of both threaded loops."""
    fxa += fx
    fya += fy
    tqa += ta
    tqa += ta2
    wgt = 1.0 if owned else 0.5
    v0 += wgt * (delx * fx)
    v1 += wgt * (dely * fy)
    v2 += wgt * (delx * fy)
    v3 += wgt * (dely * fx)
    return fxa, fya, tqa, v0, v1, v2, v3, nc + wgt, so + wgt * ov


#: list entries per block of the SIMD force loops (:func:`_serial_block_loop`,
#: :func:`_threaded_block_loop`)
ENTRY_BLOCK = 256


@njit(inline="always")
def _select_block(
    law, e0, e1, ea, eb, x, v, w, r, m, esx, esy, Lx, Ly, dt, update, hist,
    bh0, bh1, bfx, bfy, bta, btb, bdx, bdy, bov, bto, bsl,
):  # fmt: skip
    """The law's block path over the list entries e0..e1 (at most :data:`ENTRY_BLOCK`) as one flat
    loop into the block buffers (:func:`gransim.contacts.laws.pair_select`: every entry evaluated,
    contact and cap as selects), which LLVM turns into SIMD code: force, torques on a and b,
    branch, overlap, contact and cap flags, and the new spring in ``bh0``, ``bh1`` (not yet written
    back to ``hist``). The block evaluation of both SIMD force loops."""
    # the spring in two contiguous block buffers: the (M, 2) rows' stride-2 loads and stores keep
    # LLVM from vectorising the law loop (measured in the compiled code)
    for e in range(e0, e1):
        bh0[e - e0] = hist[e, 0]
        bh1[e - e0] = hist[e, 1]
    for e_ in range(e0, e1):
        u = np.uint64(e_)
        q = np.uint64(e_ - e0)
        a = np.uint64(ea[u])
        b = np.uint64(eb[u])
        delx = x[a, 0] - (x[b, 0] + esx[u] * Lx)
        dely = x[a, 1] - (x[b, 1] + esy[u] * Ly)
        rsq = delx * delx + dely * dely
        touch, fx, fy, ta, tb, s0, s1, sl, dn = pair_select(
            law, delx, dely, rsq, r[a], r[b], v[a, 0], v[a, 1], v[b, 0], v[b, 1], w[a], w[b], m[a], m[b],
            dt, bh0[q], bh1[q], update,
        )  # fmt: skip
        bh0[q] = s0
        bh1[q] = s1
        bfx[q] = fx
        bfy[q] = fy
        bta[q] = ta
        btb[q] = tb
        bdx[q] = delx
        bdy[q] = dely
        bov[q] = dn
        bto[q] = touch
        bsl[q] = sl


@pjit
def _serial_block_loop(
    x, v, w, f, t, m, r, ea, eb, esx, esy, both, hist, slide, ef, law, Lx, Ly, dt, update, vir, store, acc
):
    """:func:`_serial_loop` of the orthogonal cell for a law with a block path, as SIMD code, bit
    for bit.

    Per block of :data:`ENTRY_BLOCK` list entries: the pair law over the block as one flat loop
    (:func:`_select_block`: every entry evaluated, contact and Coulomb cap as selects, spring
    written back unconditionally) into block buffers, which LLVM turns into SIMD code (gathers of
    both partners, packed square roots and divisions: IEEE operations, so each lane has the bits
    of the scalar law); then the sums of the touching entries in list order, exactly as
    :func:`_serial_loop` adds them (force and torque on a, on b for an owned pair, the virial, the
    contact count and overlap). Touching entries get the same values in the same order and the
    others contribute nothing there either, so forces, torques, springs, virial and the two sums
    are those of :func:`_serial_loop` bit for bit (tests/dem/test_simd_bitwise.py).

    The one-iteration ``prange`` is what lets the law loop vectorise: numba marks the arrays of a
    parallel loop body ``noalias`` when it finds no alias among them (in a plain ``njit`` kernel
    the gathers might alias the stores), docs/performance.md "The SIMD force loop". The arrays are
    arguments (not taken out of namedtuples: gransim/_numba.py, "Unpacked arrays"), the bool arrays
    ``both`` and ``slide`` as uint8 views (reading a bool array argument turns numba's ``noalias``
    off, measured in the compiled code), the spring copied through two contiguous block buffers.
    ``acc`` (2,) receives (contacts, sum of overlaps); ``vir`` (4,) the virial.
    """
    n = x.shape[0]
    ne = ea.shape[0]
    for _ in prange(1):
        for i in range(n):
            f[i, 0] = 0.0
            f[i, 1] = 0.0
            t[i] = 0.0
        bfx = np.empty(ENTRY_BLOCK)
        bfy = np.empty(ENTRY_BLOCK)
        bta = np.empty(ENTRY_BLOCK)
        btb = np.empty(ENTRY_BLOCK)
        bdx = np.empty(ENTRY_BLOCK)
        bdy = np.empty(ENTRY_BLOCK)
        bov = np.empty(ENTRY_BLOCK)
        bto = np.empty(ENTRY_BLOCK)
        bsl = np.empty(ENTRY_BLOCK)
        bh0 = np.empty(ENTRY_BLOCK)
        bh1 = np.empty(ENTRY_BLOCK)
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        v3 = 0.0
        ncontact = 0.0
        sum_overlap = 0.0
        for e0 in range(0, ne, ENTRY_BLOCK):
            e1 = min(e0 + ENTRY_BLOCK, ne)
            _select_block(
                law, e0, e1, ea, eb, x, v, w, r, m, esx, esy, Lx, Ly, dt, update, hist,
                bh0, bh1, bfx, bfy, bta, btb, bdx, bdy, bov, bto, bsl,
            )  # fmt: skip
            for e in range(e0, e1):
                k = e - e0
                hist[e, 0] = bh0[k]
                hist[e, 1] = bh1[k]
                if bto[k] != 0.0:
                    gx = bfx[k]
                    gy = bfy[k]
                    if store:
                        slide[e] = 1 if bsl[k] != 0.0 else 0
                        ef[e, 0] = gx
                        ef[e, 1] = gy
                    # no second torques (a law with a block path splits none): -0.0, folded away
                    v0, v1, v2, v3, ncontact, sum_overlap = _tally_serial(
                        ea[e], eb[e], both[e] != 0, gx, gy, bta[k], btb[k], -0.0, -0.0, bdx[k], bdy[k], bov[k],
                        f, t, v0, v1, v2, v3, ncontact, sum_overlap,
                    )  # fmt: skip
                elif store:
                    slide[e] = 0
                    ef[e, 0] = 0.0
                    ef[e, 1] = 0.0
        vir[0] = v0
        vir[1] = v1
        vir[2] = v2
        vir[3] = v3
        acc[0] = ncontact
        acc[1] = sum_overlap


@njit
def forces_in(p, nb, law, img, dt, update, vir, store):
    """Serial force loop over the half list ``nb`` with the contact law ``law`` in the cell ``img``
    (:func:`_serial_loop`, the loop of :func:`forces` too)."""
    return _serial_loop(p, nb, law, img, dt, update, vir, store)


@njit(inline="always")
def _serial_loop(p, nb, law, img, dt, update, vir, store):
    """Serial force loop over the half list ``nb`` with the contact law ``law`` in the cell ``img``
    (inlined into :func:`forces` and :func:`forces_in`, so that the orthogonal image is a few local
    values there, not a structure passed to a call).

    ``p`` :class:`Particles` (forces ``p.f`` and torques ``p.t`` overwritten), ``nb``
    :class:`Neighbours` (``sx``, ``sy``, ``both``, ``hist``, ``slide``, ``ef`` read). Entries
    (a, b, s): b's image, :data:`OrthoImage` x_b + s L (L the current box lengths) or
    :data:`TiltedImage` (the sheared cell, its Lees-Edwards image velocities; the image's
    ``touch`` receives the contact flags). ``both`` entries (s = 0, both owned) apply the force to
    a and -force to b; entries across the boundary exist once per owner, each with its own history
    copy, and act on a only. ``vir`` (4,) receives the virial sums xx, yy, xy, yx of d (x) f_i
    (0.5 per owner as ``ev_tally_xyz``, N m); ``nb.ef`` (M, 2) the force on a of each entry,
    ``nb.slide`` (M,) the Coulomb cap flag (written only when ``store``: memory traffic; the
    orthogonal engine stores them at the last step of each ``advance``). Returns (contacts, sum of
    overlaps) counting each physical contact once.
    """
    x, v, w, f, t, m, r = p.x, p.v, p.w, p.f, p.t, p.m, p.r
    ea, eb, esx, esy, both, hist, slide, ef = nb.a, nb.b, nb.sx, nb.sy, nb.both, nb.hist, nb.slide, nb.ef
    n = x.shape[0]
    for i in range(n):
        f[i, 0] = 0.0
        f[i, 1] = 0.0
        t[i] = 0.0
    vir[0] = 0.0
    vir[1] = 0.0
    vir[2] = 0.0
    vir[3] = 0.0
    ncontact = 0.0
    sum_overlap = 0.0
    for e in range(ea.shape[0]):
        a = ea[e]
        b = eb[e]
        touch, delx, dely, rsq, radsum, fx, fy, ta, tb, sl, ta2, tb2 = _pair(
            law, img, e, a, b, x, v, w, r, m, esx[e], esy[e], hist, dt, update
        )
        image_mark(img, e, touch)
        if touch:
            if store:
                slide[e] = sl
                ef[e, 0] = fx
                ef[e, 1] = fy
            f[a, 0] += fx
            f[a, 1] += fy
            t[a] += ta
            t[a] += ta2
            wgt = 0.5
            if both[e]:
                f[b, 0] += -fx
                f[b, 1] += -fy
                t[b] += tb
                t[b] += tb2
                vir[0] += 0.5 * (delx * fx)
                vir[1] += 0.5 * (dely * fy)
                vir[2] += 0.5 * (delx * fy)
                vir[3] += 0.5 * (dely * fx)
                wgt = 1.0
            vir[0] += 0.5 * (delx * fx)
            vir[1] += 0.5 * (dely * fy)
            vir[2] += 0.5 * (delx * fy)
            vir[3] += 0.5 * (dely * fx)
            ncontact += wgt
            sum_overlap += wgt * (radsum - math.sqrt(rsq))
        elif store:
            slide[e] = False
            ef[e, 0] = 0.0
            ef[e, 1] = 0.0
    return ncontact, sum_overlap


@njit
def forces_threaded(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store):
    """Threaded force loop over the same half list as :func:`forces` (CSR by a: entries of a in
    ``nb.start[a]:nb.start[a+1]``; ``nb.in_e[nb.in_start[q]:nb.in_start[q+1]]`` the owned entries
    whose b is q). Pass 1 (threads over a): each entry once (history update, force on a ``nb.ef``,
    torque on b ``nb.tb``), own sums; pass 2 (threads over q): minus the forces and the torques of
    incoming entries. No two threads write the same particle; deterministic; the summation order
    differs from the serial loop (round-off). ``pvir`` (N, 4), ``pcont`` (N, 2) per-particle
    virial and contact count/overlap sums (owned pairs weight 1, boundary copies 1/2). For a law
    with a block path (the Hooke laws) the pair law runs as SIMD code (:func:`_threaded_block_loop`,
    the same results bit for bit), for the other laws entry by entry (:func:`_threaded_scalar_loop`).
    """
    _threaded_dispatch(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store)


@pjit
def _threaded_scalar_loop(
    x,
    v,
    w,
    f,
    t,
    m,
    r,
    start,
    eb,
    esx,
    esy,
    both,
    hist,
    slide,
    ef,
    tb,
    in_start,
    in_e,
    law,
    Lx,
    Ly,
    dt,
    update,
    pvir,
    pcont,
    store,
):
    """:func:`forces_threaded` entry by entry, on the unpacked arrays (gransim/_numba.py,
    "Unpacked arrays": taken out of the namedtuples inside this ``parallel=True`` function, the
    torques on b came out wrong)."""
    n = x.shape[0]
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for c in prange(ntask):
        for a in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            _threaded_particle(
                a, x, v, w, f, t, m, r, start, eb, esx, esy, both, hist, slide, ef, tb, law, Lx, Ly, dt, update,
                pvir, pcont, store,
            )  # fmt: skip
    _incoming_forces(f, t, ef, tb, in_start, in_e)


@njit(inline="always")
def _threaded_particle(
    a, x, v, w, f, t, m, r, start, eb, esx, esy, both, hist, slide, ef, tb, law, Lx, Ly, dt, update, pvir, pcont, store
):
    # the first pass of _threaded_scalar_loop for particle a: its entries, its sums
    fxa = 0.0
    fya = 0.0
    ta = 0.0
    v0 = 0.0
    v1 = 0.0
    v2 = 0.0
    v3 = 0.0
    nca = 0.0
    ova = 0.0
    for e in range(start[a], start[a + 1]):
        b = eb[e]
        touch, delx, dely, rsq, radsum, fx, fy, tq, tqb, sl, tq2, tqb2 = _entry(
            law, e, a, b, x, v, w, r, m, esx, esy, hist, Lx, Ly, dt, update
        )
        if touch:
            if store:
                slide[e] = sl
            ef[e, 0] = fx
            ef[e, 1] = fy
            tb[e] = tqb + tqb2
            fxa, fya, ta, v0, v1, v2, v3, nca, ova = _tally_particle(
                both[e], fx, fy, tq, tq2, delx, dely, radsum - math.sqrt(rsq), fxa, fya, ta, v0, v1, v2, v3, nca, ova
            )
        else:
            if store:
                slide[e] = False
            ef[e, 0] = 0.0
            ef[e, 1] = 0.0
            tb[e] = 0.0
    _put_sums(a, f, t, pvir, pcont, fxa, fya, ta, v0, v1, v2, v3, nca, ova)


@njit(inline="always")
def _put_sums(a, f, t, pvir, pcont, fx, fy, ta, v0, v1, v2, v3, nc, ov):
    # particle a's sums of the first pass of the threaded force loops: force, torque, virial
    # (xx, yy, xy, yx), contacts and overlap
    f[a, 0] = fx
    f[a, 1] = fy
    t[a] = ta
    pvir[a, 0] = v0
    pvir[a, 1] = v1
    pvir[a, 2] = v2
    pvir[a, 3] = v3
    pcont[a, 0] = nc
    pcont[a, 1] = ov


@pjit
def _incoming_forces(f, t, ef, tb, in_start, in_e):
    """The second pass of the threaded force loops: minus the forces and plus the torques of the
    owned entries whose b is q, particle by particle, in tasks of :data:`PARTICLE_BLOCK`. A
    function of its own, not a second loop in the caller: numba's parfor pass may fuse two
    ``prange`` loops of one length in one function, and this one reads what every task of the
    first pass wrote."""
    n = f.shape[0]
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for c in prange(ntask):
        for q in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            fx = 0.0
            fy = 0.0
            tq = 0.0
            for k in range(in_start[q], in_start[q + 1]):
                e = in_e[k]
                fx += ef[e, 0]
                fy += ef[e, 1]
                tq += tb[e]
            f[q, 0] -= fx
            f[q, 1] -= fy
            t[q] += tq


@pjit
def _threaded_block_loop(
    x, v, w, f, t, m, r, ea, start, eb, esx, esy, both, hist, slide, ef, tb, in_start, in_e,
    law, Lx, Ly, dt, update, pvir, pcont, store,
):  # fmt: skip
    """:func:`_threaded_scalar_loop` for a law with a block path, its pair law as SIMD code, bit
    for bit.

    Tasks of :data:`PARTICLE_BLOCK` particles spread over the threads; in each, the entries of its
    particles (contiguous: the list is sorted by a) in blocks of :data:`ENTRY_BLOCK`: the
    branch-free law over the block into block buffers (:func:`_select_block`, as
    :func:`_serial_block_loop`), then the block's entries in list order: the per-entry outputs, and
    the sums of each particle a (force, torque, virial, contacts, overlap) in the order and with
    the operations of :func:`_threaded_scalar_loop`, written when its last entry is passed. The
    second pass (minus the forces and torques of the incoming entries) is that of
    :func:`_threaded_scalar_loop`. The results equal :func:`_threaded_scalar_loop`'s bit for bit
    (tests/dem/test_simd_bitwise.py); ``both`` and ``slide`` as uint8 views (see
    :func:`_serial_block_loop`)."""
    n = x.shape[0]
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for c in prange(ntask):
        a0 = c * PARTICLE_BLOCK
        a1 = min(a0 + PARTICLE_BLOCK, n)
        bfx = np.empty(ENTRY_BLOCK)
        bfy = np.empty(ENTRY_BLOCK)
        bta = np.empty(ENTRY_BLOCK)
        btb = np.empty(ENTRY_BLOCK)
        bdx = np.empty(ENTRY_BLOCK)
        bdy = np.empty(ENTRY_BLOCK)
        bov = np.empty(ENTRY_BLOCK)
        bto = np.empty(ENTRY_BLOCK)
        bsl = np.empty(ENTRY_BLOCK)
        bh0 = np.empty(ENTRY_BLOCK)
        bh1 = np.empty(ENTRY_BLOCK)
        # particles without entries get zero sums: every particle of the task written first
        for a in range(a0, a1):
            f[a, 0] = 0.0
            f[a, 1] = 0.0
            t[a] = 0.0
            pvir[a, 0] = 0.0
            pvir[a, 1] = 0.0
            pvir[a, 2] = 0.0
            pvir[a, 3] = 0.0
            pcont[a, 0] = 0.0
            pcont[a, 1] = 0.0
        cur = a0
        fxa = 0.0
        fya = 0.0
        ta = 0.0
        v0 = 0.0
        v1 = 0.0
        v2 = 0.0
        v3 = 0.0
        nca = 0.0
        ova = 0.0
        for e0 in range(start[a0], start[a1], ENTRY_BLOCK):
            e1 = min(e0 + ENTRY_BLOCK, start[a1])
            _select_block(
                law, e0, e1, ea, eb, x, v, w, r, m, esx, esy, Lx, Ly, dt, update, hist,
                bh0, bh1, bfx, bfy, bta, btb, bdx, bdy, bov, bto, bsl,
            )  # fmt: skip
            for e in range(e0, e1):
                k = e - e0
                hist[e, 0] = bh0[k]
                hist[e, 1] = bh1[k]
                ia = ea[e]
                if ia != cur:  # the entries of cur are done
                    _put_sums(cur, f, t, pvir, pcont, fxa, fya, ta, v0, v1, v2, v3, nca, ova)
                    cur = ia
                    fxa = 0.0
                    fya = 0.0
                    ta = 0.0
                    v0 = 0.0
                    v1 = 0.0
                    v2 = 0.0
                    v3 = 0.0
                    nca = 0.0
                    ova = 0.0
                if bto[k] != 0.0:
                    gx = bfx[k]
                    gy = bfy[k]
                    if store:
                        slide[e] = 1 if bsl[k] != 0.0 else 0
                    ef[e, 0] = gx
                    ef[e, 1] = gy
                    tb[e] = btb[k]
                    # no second torques (a law with a block path splits none): -0.0, folded away
                    fxa, fya, ta, v0, v1, v2, v3, nca, ova = _tally_particle(
                        both[e] != 0,
                        gx,
                        gy,
                        bta[k],
                        -0.0,
                        bdx[k],
                        bdy[k],
                        bov[k],
                        fxa,
                        fya,
                        ta,
                        v0,
                        v1,
                        v2,
                        v3,
                        nca,
                        ova,
                    )
                else:
                    if store:
                        slide[e] = 0
                    ef[e, 0] = 0.0
                    ef[e, 1] = 0.0
                    tb[e] = 0.0
        if start[a1] > start[a0]:  # the last particle with entries
            _put_sums(cur, f, t, pvir, pcont, fxa, fya, ta, v0, v1, v2, v3, nca, ova)
    _incoming_forces(f, t, ef, tb, in_start, in_e)


def _threaded_blocks(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store):
    _threaded_block_loop(
        p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.a, nb.start, nb.b, nb.sx, nb.sy, nb.both.view(np.uint8),
        nb.hist, nb.slide.view(np.uint8), nb.ef, nb.tb, nb.in_start, nb.in_e,
        law, Lx, Ly, dt, update, pvir, pcont, store,
    )  # fmt: skip


def _threaded_entries(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store):
    _threaded_scalar_loop(
        p.x, p.v, p.w, p.f, p.t, p.m, p.r, nb.start, nb.b, nb.sx, nb.sy, nb.both, nb.hist, nb.slide, nb.ef,
        nb.tb, nb.in_start, nb.in_e, law, Lx, Ly, dt, update, pvir, pcont, store,
    )  # fmt: skip


def _threaded_dispatch(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store):
    """The threaded force loop for ``law`` (resolved at compile time by its type, as
    :func:`_serial_dispatch`): :func:`_threaded_block_loop` for a law that offers a block path,
    :func:`_threaded_scalar_loop` otherwise."""
    fn = _threaded_blocks if offers_select(type(law)) else _threaded_entries
    fn(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store)


@overload(_threaded_dispatch)
def _ov_threaded_dispatch(p, nb, law, Lx, Ly, dt, update, pvir, pcont, store):
    return _threaded_blocks if offers_select(law) else _threaded_entries


def forces_half(
    x, v, w, r, m, ea, eb, esx, esy, both, xi, Lx, Ly, kn, kt, gn, gt, mu, dt, update, f, t, vir, slide, ef, store,
    lammps=False,
):  # fmt: skip
    """The Hooke force loop with unpacked arguments (a profile of bench/_dem_job.py and
    tests/dem/test_lammps.py call it): :func:`forces` with the law "hooke-lammps" when ``lammps``,
    else "hooke-liggghts", built by name; the same arithmetic bit for bit. Returns (contacts, sum
    of overlaps)."""
    law = make_law("hooke-lammps" if lammps else "hooke-liggghts", kn=kn, kt=kt, gamma_n=gn, gamma_t=gt, mu=mu)
    p = Particles(x, v, w, f, t, m, r)
    z = np.zeros(0, np.int64)
    nb = Neighbours(
        ea, eb, np.zeros((0, 2), np.int64), esx, esy, both, xi, z, z, z, np.zeros((0, 2)), slide, ef,
        np.zeros(ea.shape[0]),
    )  # fmt: skip
    return forces(p, nb, law, Lx, Ly, dt, update, vir, store)


@njit
def incoming(eb, both, n):
    """CSR of owned entries by their second particle: (in_start (n+1,), in_e)."""
    cnt = np.zeros(n + 1, np.int64)
    for e in range(eb.shape[0]):
        if both[e]:
            cnt[eb[e] + 1] += 1
    for p in range(n):
        cnt[p + 1] += cnt[p]
    pos = cnt[:-1].copy()
    in_e = np.empty(cnt[n], np.int64)
    for e in range(eb.shape[0]):
        if both[e]:
            in_e[pos[eb[e]]] = e
            pos[eb[e]] += 1
    return cnt, in_e


@njit
def box_target(step, L_old, sig_servo, dt, ctl, lo, hi):
    """Box of step ``step`` from the loading ``ctl`` (:data:`Control`) of each axis (fix deform
    variable style), the box lengths ``L_old`` (2,) and the servo stresses ``sig_servo`` (2,) of
    the step; written to ``lo``, ``hi`` (2,).

    modes: 0 fixed, 1 rate (del = rate L0 dt (step - step0)), 2 servo
    (del = (L - L0) + dt gain (sigma - target) L); lo = lo0 - del/2, hi = hi0 + del/2."""
    modes, rates, targets, gains, lo0, hi0, phase_step0 = (
        ctl.modes, ctl.rates, ctl.targets, ctl.gains, ctl.lo0, ctl.hi0, ctl.phase_step0
    )  # fmt: skip
    for d in range(2):
        if modes[d] == 0:
            continue
        L0 = hi0[d] - lo0[d]
        if modes[d] == 1:
            c = rates[d] * L0 * dt
            dl = c * float(step - phase_step0)
        else:
            k = dt * gains[d]
            dl = (L_old[d] - L0) + k * (sig_servo[d] - targets[d]) * L_old[d]
        lo[d] = lo0[d] - 0.5 * dl
        hi[d] = hi0[d] + 0.5 * dl


@njit
def run_block(p, nb, box, ctl, law, sc, out, dt, skin, clamp, parallel, step0, nsteps, resume):
    """Steps step0+1 .. step0+nsteps until a neighbour rebuild is needed.

    Parameters
    ----------
    p : :class:`Particles`; nb : :class:`Neighbours` (list, history of the law's width, CSR);
    box : :class:`Box` (lo, hi and their values at the last build; updated in place);
    ctl : :class:`Control` (the loading of the box); law : a registered contact law
    (:mod:`gransim.contacts.laws`): each law type compiles its own copy of this loop;
    sc : :class:`Scratch` (virial (4,), per-particle sums of the threaded loop);
    out : :class:`Series` (rows >= nsteps); dt (s), skin (m); clamp : the rebuild rule of LAMMPS
    (:func:`check_rebuild`); parallel : the threaded kernels (:func:`initial_check_threaded`,
    :func:`forces_threaded`, :func:`final_threaded`) instead of the serial ones (same list, same
    arithmetic per particle and pair, summation order differs).

    Box of each step: with ``ctl.presc`` False from the loading of each axis (:func:`box_target`;
    the positions are remapped only when the box changes). With ``ctl.presc`` True from the table
    ``presc_lo``/``presc_hi`` (T, 2), row ``step - presc_step0`` (the box after that step), on
    the steps whose ``presc_remap`` row is True (a ``fix deform`` step: ``remap x`` from the
    old box to the new one even when the box is unchanged, as ``FixDeform::end_of_step``); the
    other steps keep the box. The caller guarantees the rows exist.

    Returns (steps completed, status, bad particle): status 0 done, 1 rebuild needed (the step
    step0+completed+1 has done its first half step; call again with ``resume`` True after the
    rebuild), 2 non-finite position, 3 collapsed cell. Per completed step k the outputs hold
    stress (xx, yy, xy, yx; virial / area of the new box), box lengths, contacts, mean overlap,
    kinetic energy, and ``out.vir`` the virial (xx, yy, xy, yx; N m in 2D) itself.
    """
    x, v, w, f, t, m, r = p.x, p.v, p.w, p.f, p.t, p.m, p.r
    lo, hi = box.lo, box.hi
    vir, pvir, pcont = sc.vir, sc.pvir, sc.pcont
    L_old = np.empty(2)
    sig = np.empty(2)
    lo_new = np.empty(2)
    hi_new = np.empty(2)
    for k in range(nsteps):
        step = step0 + k + 1
        if not (resume and k == 0):
            if parallel:
                dsq = rebuild_deltasq(lo, hi, box.lo_hold, box.hi_hold, skin, clamp)
                rebuild, bad = initial_check_threaded(x, v, w, f, t, m, r, dt, nb.xhold, dsq)
            else:
                initial_integrate(x, v, w, f, t, m, r, dt)
                rebuild, bad = check_rebuild(x, nb.xhold, lo, hi, box.lo_hold, box.hi_hold, skin, clamp)
            if bad >= 0:
                return k, 2, bad
            if rebuild:
                return k, 1, -1
        Lx = hi[0] - lo[0]
        Ly = hi[1] - lo[1]
        if parallel:
            forces_threaded(p, nb, law, Lx, Ly, dt, True, pvir, pcont, k == nsteps - 1)
            ke, nc, so = final_threaded(v, w, f, t, m, r, dt, pvir, pcont, vir)
        else:
            nc, so = forces(p, nb, law, Lx, Ly, dt, True, vir, k == nsteps - 1)
            ke = final_integrate(v, w, f, t, m, r, dt)
        inv = 1.0 / (Lx * Ly)
        L_old[0] = Lx
        L_old[1] = Ly
        sig[0] = vir[0] * inv
        sig[1] = vir[1] * inv
        lo_new[0] = lo[0]
        lo_new[1] = lo[1]
        hi_new[0] = hi[0]
        hi_new[1] = hi[1]
        remap = False
        if ctl.presc:
            row = step - ctl.presc_step0
            if ctl.presc_remap[row]:
                remap = True
                lo_new[0] = ctl.presc_lo[row, 0]
                lo_new[1] = ctl.presc_lo[row, 1]
                hi_new[0] = ctl.presc_hi[row, 0]
                hi_new[1] = ctl.presc_hi[row, 1]
        else:
            box_target(step, L_old, sig, dt, ctl, lo_new, hi_new)
            if lo_new[0] != lo[0] or lo_new[1] != lo[1] or hi_new[0] != hi[0] or hi_new[1] != hi[1]:
                remap = True
        if remap:
            if not (hi_new[0] - lo_new[0] > 0.0 and hi_new[1] - lo_new[1] > 0.0):
                return k, 3, -1
            remap_x(x, lo, hi, lo_new, hi_new)
            lo[0] = lo_new[0]
            lo[1] = lo_new[1]
            hi[0] = hi_new[0]
            hi[1] = hi_new[1]
        Lx = hi[0] - lo[0]
        Ly = hi[1] - lo[1]
        inv = 1.0 / (Lx * Ly)
        out.stress[k, 0] = vir[0] * inv
        out.stress[k, 1] = vir[1] * inv
        out.stress[k, 2] = vir[2] * inv
        out.stress[k, 3] = vir[3] * inv
        for c in range(4):
            out.vir[k, c] = vir[c]
        out.L[k, 0] = Lx
        out.L[k, 1] = Ly
        out.nc[k] = nc
        out.ov[k] = so / nc if nc > 0 else 0.0
        out.ke[k] = ke
    return nsteps, 0, -1


@njit
def _find(start, eb, a, b):
    """Index of entry (a, b) in a list grouped by a (CSR ``start``), or -1 (linear: few entries)."""
    for k in range(start[a], start[a + 1]):
        if eb[k] == b:
            return k
    return -1


@njit
def hand_over(x, r, a_new, b_new, sx_new, sy_new, L0, L1, start_old, eb_old, both_old, xi_old, xi_new):
    """LIGGGHTS history hand-over at a rebuild (neigh_gran.cpp, fix_contact_history.cpp).

    A new entry (a, b) takes the spring stored with partner b in a's old list (or minus the one
    of an owned pair stored as (b, a)), only if it overlaps now (rsq < radsum^2); else zero.
    Every column of ``xi_old`` (M, W) is handed over (and negated for a (b, a) entry):
    :func:`hand_over_history` with all flip signs -1.
    """
    flip = -np.ones(xi_old.shape[1])
    hand_over_history(x, r, a_new, b_new, sx_new, sy_new, L0, L1, start_old, eb_old, both_old, xi_old, xi_new, flip)


@njit
def hand_over_history(x, r, a_new, b_new, sx_new, sy_new, L0, L1, start_old, eb_old, both_old, h_old, h_new, flip):
    """:func:`hand_over` for a history of any width W: ``h_old`` (M_old, W), ``h_new`` (M, W)
    (written), ``flip`` (W,) the sign of each column seen from the other particle (a new entry
    (a, b) whose pair was stored as an owned (b, a) takes ``flip * h_old``)."""
    nw = h_new.shape[1]
    for e in range(a_new.shape[0]):
        a = a_new[e]
        b = b_new[e]
        for c in range(nw):
            h_new[e, c] = 0.0
        delx = x[a, 0] - (x[b, 0] + sx_new[e] * L0)
        dely = x[a, 1] - (x[b, 1] + sy_new[e] * L1)
        radsum = r[a] + r[b]
        if not (delx * delx + dely * dely < radsum * radsum):
            continue
        k = _find(start_old, eb_old, a, b)
        if k >= 0:
            for c in range(nw):
                h_new[e, c] = h_old[k, c]
        else:
            k = _find(start_old, eb_old, b, a)
            if k >= 0 and both_old[k]:
                for c in range(nw):
                    h_new[e, c] = flip[c] * h_old[k, c]


@njit(inline="always")
def _liggghts_partners(a, fill, m, n, xa, r, gown, gsx, gsy, binhead, bins, ibin, stencil, skin, ao, bo, sxo, syo, bto):
    """The entries of owned atom ``a`` in LIGGGHTS' order (:func:`build_list_liggghts`): partners
    j > a (ghosts after owned atoms) in stencil order then bin-list order, kept when
    rsq <= (r_a + r_j + skin)^2; written from entry ``m`` on when ``fill``. Returns m + their
    count. The loop body of :func:`_liggghts_pairs_threaded` (:func:`_liggghts_pairs_serial` has
    it written out)."""
    for k in range(stencil.shape[0]):
        j = binhead[ibin[a] + stencil[k]]
        while j >= 0:
            if j > a:
                delx = xa[a, 0] - xa[j, 0]
                dely = xa[a, 1] - xa[j, 1]
                rj = r[j] if j < n else r[gown[j - n]]
                radsum = r[a] + rj
                cutsq = (radsum + skin) * (radsum + skin)
                if delx * delx + dely * dely <= cutsq:
                    if fill:
                        ao[m] = a
                        if j < n:
                            bo[m] = j
                            sxo[m] = 0.0
                            syo[m] = 0.0
                            bto[m] = True
                        else:
                            bo[m] = gown[j - n]
                            sxo[m] = gsx[j - n]
                            syo[m] = gsy[j - n]
                            bto[m] = False
                    m += 1
            j = bins[j]
    return m


@njit
def _liggghts_pairs_serial(n, xa, r, gown, gsx, gsy, binhead, bins, ibin, stencil, skin):
    """The pair passes of :func:`build_list_liggghts`: count, then fill, atom after atom.
    Returns (a, b, sx, sy, both). The walk of :func:`_liggghts_partners` written out here: as a
    call of the inlined helper the serial build was 5-15 % slower (measured at 1e5 disks)."""
    ns = stencil.shape[0]
    m = 0
    for pass_ in range(2):
        if pass_ == 1:
            a_out = np.empty(m, np.int32)
            b_out = np.empty(m, np.int32)
            sx_out = np.empty(m)
            sy_out = np.empty(m)
            both_out = np.empty(m, np.bool_)
        m = 0
        for a in range(n):
            for k in range(ns):
                j = binhead[ibin[a] + stencil[k]]
                while j >= 0:
                    if j > a:
                        delx = xa[a, 0] - xa[j, 0]
                        dely = xa[a, 1] - xa[j, 1]
                        rj = r[j] if j < n else r[gown[j - n]]
                        radsum = r[a] + rj
                        cutsq = (radsum + skin) * (radsum + skin)
                        if delx * delx + dely * dely <= cutsq:
                            if pass_ == 1:
                                a_out[m] = a
                                if j < n:
                                    b_out[m] = j
                                    sx_out[m] = 0.0
                                    sy_out[m] = 0.0
                                    both_out[m] = True
                                else:
                                    b_out[m] = gown[j - n]
                                    sx_out[m] = gsx[j - n]
                                    sy_out[m] = gsy[j - n]
                                    both_out[m] = False
                            m += 1
                    j = bins[j]
    return a_out, b_out, sx_out, sy_out, both_out


@pjit
def _liggghts_pairs_threaded(n, xa, r, gown, gsx, gsy, binhead, bins, ibin, stencil, skin):
    """:func:`_liggghts_pairs_serial` on numba's threads: each atom's count (tasks of
    :data:`PARTICLE_BLOCK` atoms), their prefix sums, then each atom's entries from its offset:
    the same list, entry for entry."""
    cnt = np.zeros(n + 1, np.int64)
    ao = np.empty(0, np.int32)
    bo = np.empty(0, np.int32)
    sxo = np.empty(0)
    syo = np.empty(0)
    bto = np.empty(0, np.bool_)
    ntask = (n + PARTICLE_BLOCK - 1) // PARTICLE_BLOCK
    for c in prange(ntask):
        for a in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            cnt[a + 1] = _liggghts_partners(
                a, False, 0, n, xa, r, gown, gsx, gsy, binhead, bins, ibin, stencil, skin, ao, bo, sxo, syo, bto
            )
    for a in range(n):
        cnt[a + 1] += cnt[a]
    m = cnt[n]
    a_out = np.empty(m, np.int32)
    b_out = np.empty(m, np.int32)
    sx_out = np.empty(m)
    sy_out = np.empty(m)
    both_out = np.empty(m, np.bool_)
    for c in prange(ntask):
        for a in range(c * PARTICLE_BLOCK, min((c + 1) * PARTICLE_BLOCK, n)):
            _liggghts_partners(
                a, True, cnt[a], n, xa, r, gown, gsx, gsy, binhead, bins, ibin, stencil, skin,
                a_out, b_out, sx_out, sy_out, both_out,
            )  # fmt: skip
    return a_out, b_out, sx_out, sy_out, both_out


@njit
def _liggghts_ghosts(x, lo, cutghost, sub_hi0, sub_hi1, prd0, prd1, cap):
    """The ghost atoms of ``Comm::borders`` (:func:`build_list_liggghts`) with room for ``cap``:
    (owner (cap,) int64, shift x, shift y (cap,), coordinates of atoms then ghosts (N + cap, 2),
    ghost count, or -1 when they do not fit)."""
    n = x.shape[0]
    gown = np.empty(cap, np.int64)
    gsx = np.empty(cap, np.float64)
    gsy = np.empty(cap, np.float64)
    xa = np.empty((n + cap, 2))
    for i in range(n):
        xa[i, 0] = x[i, 0]
        xa[i, 1] = x[i, 1]
    ng = 0
    for dim in range(2):
        nlast = n + ng
        for ineed in range(2):
            if ineed == 0:
                slo = -1.0e20
                shi = (lo[dim] if dim == 0 else lo[1]) + cutghost
                pbc = 1.0
            else:
                shi = 1.0e20
                slo = (sub_hi0 if dim == 0 else sub_hi1) - cutghost
                pbc = -1.0
            prd = prd0 if dim == 0 else prd1
            for i in range(nlast):
                c = xa[i, dim]
                if c >= slo and c <= shi:
                    if ng == cap:
                        return gown, gsx, gsy, xa, -1
                    g = n + ng
                    if i < n:
                        gown[ng] = i
                        gsx[ng] = 0.0
                        gsy[ng] = 0.0
                    else:
                        gown[ng] = gown[i - n]
                        gsx[ng] = gsx[i - n]
                        gsy[ng] = gsy[i - n]
                    if dim == 0:
                        gsx[ng] += pbc
                        xa[g, 0] = xa[i, 0] + pbc * prd
                        xa[g, 1] = xa[i, 1]
                    else:
                        gsy[ng] += pbc
                        xa[g, 0] = xa[i, 0]
                        xa[g, 1] = xa[i, 1] + pbc * prd
                    ng += 1
    return gown, gsx, gsy, xa, ng


@njit
def build_list_liggghts(x, r, lo, hi, skin, threaded=False, ghost_room=-1):
    """The neighbour list of LIGGGHTS 3.8.0 (1 process, ``newton off``, ``bin``), in its order.

    Ghost atoms as ``Comm::borders`` makes them (x swaps then y swaps; slab tests with <=/>=;
    candidates: owned atoms for x, owned + x ghosts for y), bins as ``Neighbor::setup_bins`` and
    ``coord2bin`` (bin size half the neighbour cutoff 2 r_max + skin), the full 2D stencil
    of ``half/bin/newtoff`` and, per owned atom a, partners j > a (ghosts after owned atoms) in
    stencil order then index order, kept when rsq <= (r_a + r_j + skin)^2. Matching this order
    makes the force sums (and so trajectories) agree with LIGGGHTS to the last bit.
    Returns (a, b, sx, sy, both, self_image): entry (a, b, s) is b's image x_b + s L; ``both``
    for owned pairs (s = 0); self_image >= 0 a particle near its own image (cell too small), -2
    when the ghost buffer overflowed. ``threaded``: the pair passes on numba's threads
    (:func:`_liggghts_pairs_threaded`; the ghosts and bins stay serial), the same list entry for
    entry. ``ghost_room``: the first room for ghosts (-1: N/8 + 1024), doubled until they fit.
    """
    n = x.shape[0]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    cutneighmax = (rmax + rmax) + skin
    cutghost = cutneighmax
    prd0 = hi[0] - lo[0]
    prd1 = hi[1] - lo[1]
    sub_hi0 = lo[0] + prd0 * 1.0
    sub_hi1 = lo[1] + prd1 * 1.0
    # ghosts: owner index, shift, coordinates. Room first for the ghosts a cut-off strip along
    # the boundaries holds (a guess), doubled until they fit, at most LIGGGHTS' 4 N + 16: the
    # same ghosts in the same order, without holding 5 N coordinates for 1 % of them
    cap_max = 4 * n + 16
    cap = min(cap_max, n // 8 + 1024 if ghost_room < 0 else max(ghost_room, 1))
    while True:
        gown, gsx, gsy, xa, ng = _liggghts_ghosts(x, lo, cutghost, sub_hi0, sub_hi1, prd0, prd1, cap)
        if ng >= 0 or cap == cap_max:
            break
        cap = min(cap_max, 2 * cap)
    if ng < 0:
        return (
            np.empty(0, np.int32),
            np.empty(0, np.int32),
            np.empty(0),
            np.empty(0),
            np.empty(0, np.bool_),
            -2,
        )
    nall = n + ng
    # bins (Neighbor::setup_bins, orthogonal box, one process)
    small = 1.0e-6
    binsize_opt = 0.5 * cutneighmax
    binsizeinv = 1.0 / binsize_opt
    nb = np.empty(2, np.int64)
    binsz = np.empty(2)
    bininv = np.empty(2)
    mlo = np.empty(2, np.int64)
    mb = np.empty(2, np.int64)
    for d in range(2):
        bbox = hi[d] - lo[d]
        nbd = int(bbox * binsizeinv)
        if nbd == 0:
            nbd = 1
        nb[d] = nbd
        binsz[d] = bbox / nbd
        bininv[d] = 1.0 / binsz[d]
        sublo = lo[d]
        subhi = sub_hi0 if d == 0 else sub_hi1
        coord = (sublo - cutghost) - small * bbox
        m_lo = int((coord - lo[d]) * bininv[d])
        if coord < lo[d]:
            m_lo -= 1
        coord = (subhi + cutghost) + small * bbox
        m_hi = int((coord - lo[d]) * bininv[d])
        m_lo -= 1
        m_hi += 1
        mlo[d] = m_lo
        mb[d] = m_hi - m_lo + 1
    binhead = -np.ones(mb[0] * mb[1], np.int32)  # int32: indices < 2^31 (4 bytes a particle less)
    bins = -np.ones(nall, np.int32)
    ibin = np.empty(nall, np.int32)
    for i in range(nall - 1, -1, -1):
        idx = 0
        for d in range(2):
            c = xa[i, d]
            if c >= hi[d]:
                ix = int((c - hi[d]) * bininv[d]) + nb[d]
            elif c >= lo[d]:
                ix = min(int((c - lo[d]) * bininv[d]), nb[d] - 1)
            else:
                ix = int((c - lo[d]) * bininv[d]) - 1
            if d == 0:
                idx += ix - mlo[0]
            else:
                idx += (ix - mlo[1]) * mb[0]
        ibin[i] = idx
        bins[i] = binhead[idx]
        binhead[idx] = i
    # full 2D stencil (half/bin/newtoff)
    sxn = int(cutneighmax * bininv[0])
    if sxn * binsz[0] < cutneighmax:
        sxn += 1
    syn = int(cutneighmax * bininv[1])
    if syn * binsz[1] < cutneighmax:
        syn += 1
    cutsq_max = cutneighmax * cutneighmax
    stencil = np.empty((2 * sxn + 1) * (2 * syn + 1), np.int64)
    ns = 0
    for j in range(-syn, syn + 1):
        for i in range(-sxn, sxn + 1):
            dx = (i - 1) * binsz[0] if i > 0 else (0.0 if i == 0 else (i + 1) * binsz[0])
            dy = (j - 1) * binsz[1] if j > 0 else (0.0 if j == 0 else (j + 1) * binsz[1])
            if dx * dx + dy * dy < cutsq_max:
                stencil[ns] = j * mb[0] + i
                ns += 1
    # pairs: count, then fill in LIGGGHTS order (on the threads: counts per a, then each a's
    # entries filled from its offset, the same list)
    st = stencil[:ns]
    if threaded:
        out = _liggghts_pairs_threaded(n, xa, r, gown, gsx, gsy, binhead, bins, ibin, st, skin)
    else:
        out = _liggghts_pairs_serial(n, xa, r, gown, gsx, gsy, binhead, bins, ibin, st, skin)
    a_out, b_out, sx_out, sy_out, both_out = out
    m = a_out.shape[0]
    self_image = -1
    for e in range(m):
        if a_out[e] == b_out[e]:
            self_image = a_out[e]
            break
    return a_out, b_out, sx_out, sy_out, both_out, self_image
