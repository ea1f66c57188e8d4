"""Numba kernels of the fast DEM path (:mod:`gransim.dem.fast`): no validation here.

Layout (all structure-of-arrays, particles in *sorted* order, see :func:`bin_sort`):
x, y, vx, vy, w, fx, fy, t, r, m (N,) float64; perm (N,) int32 the original index of each sorted
particle. Half neighbour list, each pair once with i < j in the sorted order, by i: the entries of
particle i are ``start[i]..stop[i]`` (start (N+1,), stop (N,) int32; a list built in one pass is
plain CSR, stop = start[1:]; the threaded build leaves a gap after each band's entries, so stop
of a band's last particle is not the next band's start, :func:`pairs_banded`), nj (M,) int32,
code (M,) uint8 the periodic image of j (code = (sx + 1) + 3 (sy + 1), image x_j + sx Lx,
y_j + sy Ly), ni (M,) int32 the owner i of each entry (written by the list build, for the
vectorised force loop), h0, h1 (M,) float64 the two
components of the tangential spring in the frame of i (m; two arrays, not one (M, 2): a strided
pair of loads and stores stops LLVM's loop vectoriser).

Chunks. The particles are grouped in bands of whole bin rows (``cstart`` (C+1,) int32): the bins
are at least a neighbour cut-off wide, so every partner j > i of a particle of band c lies in band
c or c + 1, except the pairs across the periodic y boundary (i in the first bin row, j in the
last), which are *spilled*: their j-side force goes to a small buffer scattered serially after
the force loop. The force loop (:func:`forces_v`) runs the even bands, then the odd bands (two
``prange`` regions; serially, one region of one iteration):
within a region no two bands write the same particle, so the symmetric (Newton's third law)
update needs no atomics and no per-thread copy of the force arrays. Every sum has a fixed order
(band by band, entry by entry, spills last, per-band partial sums reduced in band order), so the
results do not depend on the number of threads or on the scheduling: the chunks are many more
than the threads and are handed out dynamically (:func:`gransim._numba.dynamic_chunks`), so a
descheduled thread holds back only the band it is working on.

Contact law: LIGGGHTS 3.8.0 ``hooke/stiffness`` + ``tangential history``, its branch-free
arithmetic :func:`gransim.contacts.hooke.hooke_liggghts` (the bitwise engine's block path; eq (5)
of Meier et al. for the elastic normal part): the touch test and the Coulomb cap are selects, so
the loop has no data-dependent jump (an entry that does not touch computes a force that is masked
to zero and keeps its spring, as LIGGGHTS keeps it until the next list build). That is what lets
the law run as SIMD code over the entries of a block (:func:`forces_v`). Each pair is the bitwise
engine's, bit for bit; the sums run in another order.
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np
from numba.extending import overload

from .._numba import njit, pjit, prange
from ..contacts.laws import pair_select
from . import kernels as K
from . import sheared_kernels as SK

# ------------------------------------------------------------------------------- the cells
# The image of the cell in the force loop, a plain tuple of floats: (Lx, Ly) for an orthogonal
# cell, the image of j with shift s at x_j + (s_x Lx, s_y Ly) moving with v_j (``fix deform ...
# remap x``); (Lx, Ly, xy, ux, uy, wx) for a sheared (LAMMPS triclinic) cell, the tilt xy (m) and
# the velocity jumps across the y boundary ux = h_rate[5], uy = h_rate[1] and across the x boundary
# wx = h_rate[0] (m/s): the image at x_j + s_x (Lx, 0) + s_y (xy, Ly) moving with
# v_j + s_x (wx, 0) + s_y (ux, uy) (Lees-Edwards, ``remap v``; all zero with ``remap x``).
# Its length picks the arithmetic at compile time.


def image(img, xj, yj, vxj, vyj, sx, sy):
    """Position and velocity of the image (s_x, s_y) of a particle at (xj, yj) moving with
    (vxj, vyj) in the cell ``img`` ((Lx, Ly) or (Lx, Ly, xy, ux, uy, wx), above): (x, y, vx, vy)
    in m and m/s, in the operation order of :func:`gransim.dem.kernels.tilted_image` and
    ``image_velocity`` (x_j + s_x Lx, then + s_y xy). Interpreted fallback of the overload."""
    if len(img) == 2:
        return xj + sx * img[0], yj + sy * img[1], vxj, vyj
    return (
        (xj + sx * img[0]) + sy * img[2], yj + sy * img[1], (vxj + sx * img[5]) + sy * img[3], vyj + sy * img[4]
    )  # fmt: skip


def _kind(ty):
    return getattr(ty, "instance_class", None)


@overload(image, inline="always")
def _ov_image(img, xj, yj, vxj, vyj, sx, sy):
    n = getattr(img, "count", None)
    if n == 2:

        def ortho(img, xj, yj, vxj, vyj, sx, sy):
            return xj + sx * img[0], yj + sy * img[1], vxj, vyj

        return ortho
    if n == 6:

        def tilted(img, xj, yj, vxj, vyj, sx, sy):
            return (
                (xj + sx * img[0]) + sy * img[2], yj + sy * img[1], (vxj + sx * img[5]) + sy * img[3],
                vyj + sy * img[4],
            )  # fmt: skip

        return tilted
    return None


# ----------------------------------------------------------------------------------- forces
@njit
def _scatter(sp_j, sp_f, fx, fy, t):
    for k in range(sp_j.shape[0]):
        j = sp_j[k]
        fx[j] += sp_f[k, 0]
        fy[j] += sp_f[k, 1]
        t[j] += sp_f[k, 2]


# ------------------------------------------------------------------- forces, vectorised (SIMD)
#: particles per block of the vectorised force loop: the block's per-entry results (8 float64 per
#: entry, about 2.7 entries per particle) stay in the first-level caches between the two loops
SIMD_BLOCK = 128


@pjit
def forces_v(
    parallel,
    cstart,
    start,
    stop,
    ni,
    nj,
    code,
    h0,
    h1,
    x,
    y,
    vx,
    vy,
    w,
    r,
    m,
    fx,
    fy,
    t,
    img,
    law,
    dt,
    update,
    sp_start,
    sp_j,
    sp_f,
    acc,
):
    """All forces: the even bands, then the odd bands (a ``prange`` over each colour), then the
    spills (:func:`_scatter`). Each band in two loops per block of :data:`SIMD_BLOCK` particles:
    the pair law over the block's entries as one flat loop (``ni`` (M,) int32 the owner i of each entry) with
    no dependence between iterations, which LLVM turns into SIMD code (gathers of the partners,
    vector square roots and divisions: IEEE operations, so each lane gives the bits of the scalar
    law), results into block buffers; then the sums, entry by entry in list order: the i side in
    registers, the j side into fx/fy/t when j lies in band c or c + 1, else into the spill rows
    ``sp_start[c]..``; ``acc[c]`` receives the band's virial sums xx, yy, xy, yx (N m), contacts
    and overlap sum. The sums have a fixed order, so the results do not depend on the thread count
    (the serial engine runs this kernel on one thread), and they are those of the scalar loop that
    computed and summed each entry in turn (before commit "vectorised force loop") bit for bit.
    ``law`` = (kn, kt, gamma_n, gamma_t, mu, dt) (N/m, N/m, 1/s, 1/s, -, s). ``fx``, ``fy``, ``t``
    zero on entry.

    Why it is written this way: the law loop vectorises only inside a ``parallel=True`` kernel
    (numba marks the array arguments of a parallel loop body ``noalias`` when it finds no alias
    among them; in a plain ``njit`` kernel the gathers might alias the stores), only when the loop
    body is not an ``inline="always"`` function taking arrays (the inlined argument copies count
    as aliases), with unsigned indices (no negative-index wrap-around) and with the spring in two
    (M,) arrays (a stride-2 pair of loads and stores is not vectorised). Checked by
    tests/dem/test_fast.py (the SIMD instructions in the compiled kernel)."""
    nch = cstart.shape[0] - 1
    ne = (nch + 1) // 2  # even bands
    ncol = 2 if parallel else 1
    nper = 1 if parallel else nch
    for colour in range(ncol):
        # parallel: one task per band of this colour; serial: one task, every band (even then odd)
        ntask = (nch - colour + 1) // 2 if parallel else 1
        for h in prange(ntask):
            # block buffers, once per task (on one thread: once per call, not per band; at 1e3
            # disks 8 allocations per band were a tenth of a step)
            cap = 0
            for b in range(nper):
                c = 2 * h + colour if parallel else b
                for ia in range(cstart[c], cstart[c + 1], SIMD_BLOCK):
                    cap = max(cap, stop[min(ia + SIMD_BLOCK, cstart[c + 1]) - 1] - start[ia])
            bfx = np.empty(cap)
            bfy = np.empty(cap)
            bti = np.empty(cap)
            btj = np.empty(cap)
            bdx = np.empty(cap)
            bdy = np.empty(cap)
            bov = np.empty(cap)
            bto = np.empty(cap)
            for b in range(nper):
                if parallel:
                    c = 2 * h + colour
                elif b < ne:
                    c = 2 * b
                else:
                    c = 2 * (b - ne) + 1
                i0 = cstart[c]
                i1 = cstart[c + 1]
                jmax = np.uint64(cstart[min(c + 2, nch)])
                k = sp_start[c]
                v0 = 0.0
                v1 = 0.0
                v2 = 0.0
                v3 = 0.0
                nc = 0.0
                ov = 0.0
                for ia in range(i0, i1, SIMD_BLOCK):
                    ib = min(ia + SIMD_BLOCK, i1)
                    ea = start[ia]
                    eb = stop[ib - 1]
                    for e_ in range(ea, eb):
                        e = np.uint64(e_)
                        q = np.uint64(e_ - ea)
                        i = np.uint64(ni[e])
                        j = np.uint64(nj[e])
                        cd = np.uint32(code[e])
                        sx = float(np.int32(cd % np.uint32(3)) - 1)
                        sy = float(np.int32(cd // np.uint32(3)) - 1)
                        xj, yj, vxj, vyj = image(img, x[j], y[j], vx[j], vy[j], sx, sy)
                        delx = x[i] - xj
                        dely = y[i] - yj
                        rsq = delx * delx + dely * dely
                        touch, fxe, fye, tie, tje, s0, s1, _, dn = pair_select(
                            law, delx, dely, rsq, r[i], r[j], vx[i], vy[i], vxj, vyj, w[i], w[j], m[i], m[j],
                            dt, h0[e], h1[e], update,
                        )  # fmt: skip
                        h0[e] = s0
                        h1[e] = s1
                        # an entry that does not touch adds nothing (the law's values there are
                        # not forces): masked, not branched, so the loop stays SIMD code
                        bfx[q] = touch * fxe
                        bfy[q] = touch * fye
                        bti[q] = touch * tie
                        btj[q] = touch * tje
                        bdx[q] = delx
                        bdy[q] = dely
                        bov[q] = touch * dn
                        bto[q] = touch
                    for i in range(ia, ib):
                        fxi = 0.0
                        fyi = 0.0
                        ti = 0.0
                        for e_ in range(start[i], stop[i]):
                            e = np.uint64(e_)
                            q = np.uint64(e_ - ea)
                            fxe = bfx[q]
                            fye = bfy[q]
                            fxi += fxe
                            fyi += fye
                            ti += bti[q]
                            j = np.uint64(nj[e])
                            if j < jmax:
                                fx[j] -= fxe
                                fy[j] -= fye
                                t[j] += btj[q]
                            else:
                                sp_j[k] = j
                                sp_f[k, 0] = -fxe
                                sp_f[k, 1] = -fye
                                sp_f[k, 2] = btj[q]
                                k += 1
                            delx = bdx[q]
                            dely = bdy[q]
                            v0 += delx * fxe
                            v1 += dely * fye
                            v2 += delx * fye
                            v3 += dely * fxe
                            nc += bto[q]
                            ov += bov[q]
                        fx[i] += fxi
                        fy[i] += fyi
                        t[i] += ti
                acc[c, 0] = v0
                acc[c, 1] = v1
                acc[c, 2] = v2
                acc[c, 3] = v3
                acc[c, 4] = nc
                acc[c, 5] = ov
    _scatter(sp_j, sp_f, fx, fy, t)


@pjit
def integrate_v(
    parallel,
    cstart,
    x,
    y,
    vx,
    vy,
    w,
    fx,
    fy,
    t,
    m,
    r,
    xh,
    yh,
    dt,
    final,
    initial,
    remap,
    lo_old,
    hi_old,
    lo_new,
    hi_new,
    xy_old,
    xy_new,
    deltasq,
    red,
):
    """The fused pass, band by band: [final half step (v, w) and its kinetic energy] [positions
    mapped affinely from the box (lo_old, hi_old) to (lo_new, hi_new): ``remap`` 1, per axis as
    :func:`gransim.dem.kernels.remap_x`; 2, through lamda in the sheared boxes of tilts xy_old,
    xy_new (m) as :func:`gransim.dem.sheared_kernels.remap_positions`; 0, not] [first half step,
    position update, rebuild test |x - x_hold|^2 > deltasq, forces zeroed]. ``red[c]`` = (kinetic
    energy (J), rebuild flag, first non-finite particle + 1 or 0).

    Written as SIMD code: per block of :data:`SIMD_BLOCK` particles one loop whose only
    reductions are integer ones (the rebuild flag, a non-finite flag), the kinetic energies into a
    block buffer summed afterwards in particle order, the first non-finite particle of a band
    looked up only when there is one; the arithmetic and its order are those of the scalar pass
    before it, bit for bit. ``parallel`` True: the bands spread over the threads; False: one task
    holding every band in order (a parallel kernel on one thread: only there does the loop
    vectorise, :func:`forces_v`)."""
    nch = cstart.shape[0] - 1
    dtf = 0.5 * dt
    dtfrot = dtf / 0.5
    hx = 1.0 / (hi_old[0] - lo_old[0])
    hy = 1.0 / (hi_old[1] - lo_old[1])
    Hx = hi_new[0] - lo_new[0]
    Hy = hi_new[1] - lo_new[1]
    lox = lo_old[0]
    loy = lo_old[1]
    lnx = lo_new[0]
    lny = lo_new[1]
    i5 = -xy_old / ((hi_old[0] - lo_old[0]) * (hi_old[1] - lo_old[1]))
    ntask = nch if parallel else 1
    nper = 1 if parallel else nch
    for h in prange(ntask):
        bke = np.empty(SIMD_BLOCK)
        for b in range(nper):
            c = h + b  # one of the two is 0
            i0 = cstart[c]
            i1 = cstart[c + 1]
            ke = 0.0
            flag = 0
            nonfinite = 0
            for ia in range(i0, i1, SIMD_BLOCK):
                ib = min(ia + SIMD_BLOCK, i1)
                for i_ in range(ia, ib):
                    i = np.uint64(i_)
                    q = np.uint64(i_ - ia)
                    dtfm = dtf / m[i]
                    rot = dtfrot / (r[i] * r[i] * m[i])
                    a = vx[i]
                    bv = vy[i]
                    sp = w[i]
                    kei = 0.0
                    if final:
                        a += dtfm * fx[i]
                        bv += dtfm * fy[i]
                        sp += rot * t[i]
                        kei = 0.5 * m[i] * (a * a + bv * bv) + 0.25 * m[i] * r[i] * r[i] * sp * sp
                    bke[q] = kei
                    px = x[i]
                    py = y[i]
                    if remap == 1:
                        px = Hx * (hx * (px - lox)) + lnx
                        py = Hy * (hy * (py - loy)) + lny
                    elif remap == 2:
                        d0 = px - lox
                        d1 = py - loy
                        l0 = hx * d0 + i5 * d1
                        l1 = hy * d1
                        px = ((Hx * l0 + xy_new * l1) + 0.0) + lnx
                        py = (Hy * l1 + 0.0) + lny
                    if initial:
                        a += dtfm * fx[i]
                        bv += dtfm * fy[i]
                        px += dt * a
                        py += dt * bv
                        sp += rot * t[i]
                        fx[i] = 0.0
                        fy[i] = 0.0
                        t[i] = 0.0
                        dx = px - xh[i]
                        dy = py - yh[i]
                        d2 = dx * dx + dy * dy
                        flag |= 1 if d2 > deltasq else 0
                        nonfinite |= 0 if (math.isfinite(px) and math.isfinite(py)) else 1
                    vx[i] = a
                    vy[i] = bv
                    w[i] = sp
                    x[i] = px
                    y[i] = py
                if final:
                    for k in range(ib - ia):
                        ke += bke[k]
            bad = 0.0
            if nonfinite:
                for i in range(i0, i1):
                    if not (math.isfinite(x[i]) and math.isfinite(y[i])):
                        bad = float(i + 1)
                        break
            red[c, 0] = ke
            red[c, 1] = float(flag)
            red[c, 2] = bad


#: the particles of the fast path in sorted order (:func:`run_steps`), each (N,) float64: x, y (m),
#: vx, vy (m/s), w (rad/s), fx, fy (N), t (N m), m (kg), r (m), xh, yh (m) the positions at the
#: last list build
FastParticles = namedtuple("FastParticles", ["x", "y", "vx", "vy", "w", "fx", "fy", "t", "m", "r", "xh", "yh"])
#: the half list (module docstring): cstart (C+1,) the bands, start (N+1,), stop (N,) the entries
#: of each particle, ni, nj (M,) int32, code (M,) uint8, h0, h1 (M,) the spring (m)
FastList = namedtuple("FastList", ["cstart", "start", "stop", "ni", "nj", "code", "h0", "h1"])
#: work arrays: sp_start (C+1,), sp_j, sp_f the spills (:func:`forces_v`), acc (C, 6), red (C, 3)
FastScratch = namedtuple("FastScratch", ["sp_start", "sp_j", "sp_f", "acc", "red"])
#: the orthogonal cell (:func:`run_steps`): lo, hi (2,) m now, lo_hold, hi_hold (2,) at the last
#: list build (updated in place); its loading is a :data:`gransim.dem.kernels.Control`
OrthoCell = namedtuple("OrthoCell", ["lo", "hi", "lo_hold", "hi_hold"])
#: the sheared cell (:func:`run_steps`): box (5,) = (lo_x, lo_y, hi_x, hi_y, xy) m and box_hold
#: (5,) at the last build, hr (3,) = (h_rate[0], h_rate[1], h_rate[5]) m/s, corners_hold (8, 2) m
#: the box corners at the last build (:func:`gransim.dem.sheared_kernels.box_corners`); its
#: loading is a :data:`gransim.dem.sheared_kernels.Deform`
ShearCell = namedtuple("ShearCell", ["box", "box_hold", "hr", "corners_hold"])
#: columns of a row of :func:`run_steps`' output: virial xx, yy, xy, yx (N m), contacts, sum of
#: overlaps (m), kinetic energy (J), then the box after the step: lx, ly, xy, ylo, yhi (m)
OUT_COLUMNS = 12


# The cell as a compile-time plug-in of :func:`run_steps` (the type of ``cell`` picks the
# functions, as the contact law's type picks its pair function): its image in the force loop, its
# rebuild margin, its change at the end of a step and the box columns of the output rows. Each
# Python function below is the interpreted fallback (NUMBA_DISABLE_JIT) of its overload.
def cell_image(cell):
    """The image tuple of the force loop ((Lx, Ly) or (Lx, Ly, xy, ux, uy, wx), :func:`image`) for the
    current box of ``cell``."""
    if isinstance(cell, OrthoCell):
        return _ortho_image(cell)
    return _tilted_image(cell)


def cell_deltasq(cell, skin, clamp, corners):
    """delta^2 (m^2) of the rebuild test |x - x_hold|^2 > delta^2 for the current box of ``cell``
    (``corners`` (8, 2) scratch): :func:`_ortho_deltasq`, :func:`_tilted_deltasq`."""
    if isinstance(cell, OrthoCell):
        return _ortho_deltasq(cell, skin, clamp, corners)
    return _tilted_deltasq(cell, skin, clamp, corners)


def cell_end_of_step(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp):
    """The box of step ``step`` from the loading ``ctl`` and the virial ``vir`` (4,) of the step:
    :func:`_ortho_end`, :func:`_tilted_end`. Returns (status, remap): status 0, or 3 for a collapsed
    cell (or, sheared, a tilt past Lx/2); remap the mode of :func:`integrate_v` (0 none, 1 per axis,
    2 through lamda) with the boxes (lo_old, hi_old) and (lo_new, hi_new) written, and for mode 2
    the tilts tmp[0, 0] (old) and tmp[0, 1] (new)."""
    if isinstance(cell, OrthoCell):
        return _ortho_end(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp)
    return _tilted_end(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp)


def cell_row(cell, out, k):
    """out[k, 7:12] = lx, ly, xy, ylo, yhi (m) of the current box of ``cell``."""
    if isinstance(cell, OrthoCell):
        _ortho_row(cell, out, k)
    else:
        _tilted_row(cell, out, k)


@njit(inline="always")
def _ortho_image(cell):
    return (cell.hi[0] - cell.lo[0], cell.hi[1] - cell.lo[1])


@njit(inline="always")
def _tilted_image(cell):
    b = cell.box
    return (b[2] - b[0], b[3] - b[1], b[4], cell.hr[2], cell.hr[1], cell.hr[0])


@njit(inline="always")
def _ortho_deltasq(cell, skin, clamp, corners):
    # Neighbor::check_distance of an orthogonal box: the flavour's clamp (kernels.rebuild_deltasq)
    return K.rebuild_deltasq(cell.lo, cell.hi, cell.lo_hold, cell.hi_hold, skin, clamp)


#: the triclinic rebuild rule, the code order's (:func:`gransim.dem.sheared_kernels.corner_deltasq`)
corner_deltasq = SK.corner_deltasq


@njit(inline="always")
def _tilted_deltasq(cell, skin, clamp, corners):
    # LAMMPS (clamp): the triclinic rule of :func:`corner_deltasq`; LIGGGHTS (no clamp, a box that
    # does not move): the orthogonal rule on the box corners lo, hi
    b = cell.box
    h = cell.box_hold
    if not clamp:
        return K.rebuild_deltasq(b[0:2], b[2:4], h[0:2], h[2:4], skin, False)
    return corner_deltasq(b, cell.corners_hold, skin, corners)


@njit(inline="always")
def _ortho_end(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp):
    # the box step of kernels.run_block: a prescribed table row, or each axis's loading
    # (kernels.box_target: fixed, rate, servo on the stress of this step over the area of the
    # box before it); the positions remapped when the box changes (a table row: always)
    lo = cell.lo
    hi = cell.hi
    Lx = hi[0] - lo[0]
    Ly = hi[1] - lo[1]
    inv = 1.0 / (Lx * Ly)
    L_old = tmp[0]
    sig = tmp[1]
    L_old[0] = Lx
    L_old[1] = Ly
    sig[0] = vir[0] * inv
    sig[1] = vir[1] * inv
    for d in range(2):
        lo_old[d] = lo[d]
        hi_old[d] = hi[d]
        lo_new[d] = lo[d]
        hi_new[d] = hi[d]
    remap = False
    if ctl.presc:
        row = step - ctl.presc_step0
        if ctl.presc_remap[row]:
            remap = True
            for d in range(2):
                lo_new[d] = ctl.presc_lo[row, d]
                hi_new[d] = ctl.presc_hi[row, d]
    else:
        K.box_target(step, L_old, sig, dt, ctl, lo_new, hi_new)
        if lo_new[0] != lo[0] or lo_new[1] != lo[1] or hi_new[0] != hi[0] or hi_new[1] != hi[1]:
            remap = True
    if remap:
        if not (hi_new[0] - lo_new[0] > 0.0 and hi_new[1] - lo_new[1] > 0.0):
            return 3, 0
        for d in range(2):
            lo[d] = lo_new[d]
            hi[d] = hi_new[d]
        return 0, 1
    return 0, 0


@njit(inline="always")
def _tilted_end(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp):
    # fix deform end_of_step on the steps that are multiples of its N
    # (sheared_kernels.deform_end_of_step): with ``remap v`` the positions are not mapped, the
    # image velocities jump instead; with ``remap x`` every position follows the box through lamda
    if step % ctl.every == 0:
        b = cell.box
        tmp[0, 0] = b[4]
        for d in range(2):
            lo_old[d] = b[d]
            hi_old[d] = b[2 + d]
        if not SK.deform_end_of_step(step, ctl, b, cell.hr, vir, dt):
            return 3, 0
        if ctl.remap_x:
            tmp[0, 1] = b[4]
            for d in range(2):
                lo_new[d] = b[d]
                hi_new[d] = b[2 + d]
            return 0, 2
    return 0, 0


@njit(inline="always")
def _ortho_row(cell, out, k):
    out[k, 7] = cell.hi[0] - cell.lo[0]
    out[k, 8] = cell.hi[1] - cell.lo[1]
    out[k, 9] = 0.0
    out[k, 10] = cell.lo[1]
    out[k, 11] = cell.hi[1]


@njit(inline="always")
def _tilted_row(cell, out, k):
    b = cell.box
    out[k, 7] = b[2] - b[0]
    out[k, 8] = b[3] - b[1]
    out[k, 9] = b[4]
    out[k, 10] = b[1]
    out[k, 11] = b[3]


def _pick(cell, ortho, tilted):
    """The implementation of a cell plug-in for the numba type ``cell`` (None: not a cell)."""
    if _kind(cell) is OrthoCell:
        return getattr(ortho, "py_func", ortho)
    if _kind(cell) is ShearCell:
        return getattr(tilted, "py_func", tilted)
    return None


@overload(cell_image, inline="always")
def _ov_cell_image(cell):
    return _pick(cell, _ortho_image, _tilted_image)


@overload(cell_deltasq, inline="always")
def _ov_cell_deltasq(cell, skin, clamp, corners):
    return _pick(cell, _ortho_deltasq, _tilted_deltasq)


@overload(cell_end_of_step, inline="always")
def _ov_cell_end_of_step(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp):
    return _pick(cell, _ortho_end, _tilted_end)


@overload(cell_row, inline="always")
def _ov_cell_row(cell, out, k):
    return _pick(cell, _ortho_row, _tilted_row)


@njit
def run_steps(parallel, p, nl, cell, ctl, law, dt, skin, clamp, sc, out, step0, nsteps, resume, update):
    """Steps step0 + 1 .. step0 + nsteps of the fast path, until a list rebuild is needed.

    ``p`` :data:`FastParticles`, ``nl`` :data:`FastList`, ``cell`` :data:`OrthoCell` (loading
    ``ctl`` a :data:`gransim.dem.kernels.Control`: fixed, rate, servo or a prescribed table) or
    :data:`ShearCell` (``ctl`` a :data:`gransim.dem.sheared_kernels.Deform`), updated in place;
    ``law`` a registered contact law with a block path (``LawSpec.select``; each law and cell type
    compiles its own copy), ``dt`` (s), ``skin`` (m), ``clamp`` LAMMPS' rebuild rule (a negative
    margin clamped at zero), ``sc`` :data:`FastScratch`, ``update`` True (the springs incremented:
    a run-time bool from the caller, not a constant here: with the constant True numba compiles a
    second force kernel, which ran at half the speed, measured with numba 0.68). (The parallel
    kernels it calls, :func:`forces_v` and :func:`integrate_v`, take the arrays unpacked:
    gransim/_numba.py.)

    Per step: forces (even bands, odd bands, spills) with the cell's image, the box of this step
    from the virial of the step (:func:`cell_end_of_step`), then one fused pass: second half step
    of this step, the positions remapped (orthogonal cell, when its box changed), and -- unless it
    is the last step -- the first half step of the next step with the rebuild test
    (:func:`cell_deltasq`). Enter with the first half step of step0 + 1 done when ``resume``.
    ``out`` (nsteps, :data:`OUT_COLUMNS`) rows.

    Returns (steps completed, status, bad): status 0 done, 1 rebuild needed before the forces of
    step step0 + completed + 1 (its first half step is done), 2 non-finite position (bad = sorted
    index), 3 collapsed cell (or a tilt past Lx/2) at step step0 + completed + 1.
    """
    x, y, vx, vy, w, fx, fy, t, m, r, xh, yh = p
    cstart, start, stop, ni, nj, code, h0, h1 = nl
    sp_start, sp_j, sp_f, acc, red = sc
    lo_old = np.zeros(2)
    hi_old = np.ones(2)
    lo_new = np.zeros(2)
    hi_new = np.ones(2)
    tmp = np.empty((2, 2))
    corners = np.empty((8, 2))
    vir = np.empty(4)
    nch = cstart.shape[0] - 1
    k = 0
    if not resume:
        dsq = cell_deltasq(cell, skin, clamp, corners)
        integrate_v(
            parallel, cstart, x, y, vx, vy, w, fx, fy, t, m, r, xh, yh, dt,
            False, True, 0, lo_old, hi_old, lo_new, hi_new, 0.0, 0.0, dsq, red,
        )  # fmt: skip
        st = _status(red, nch)
        if st != 0:
            return 0, st, _bad(red, nch)
    while k < nsteps:
        step = step0 + k + 1
        forces_v(
            parallel, cstart, start, stop, ni, nj, code, h0, h1, x, y, vx, vy, w, r, m, fx, fy, t,
            cell_image(cell), law, dt, update, sp_start, sp_j, sp_f, acc,
        )  # fmt: skip
        for q in range(6):
            s = 0.0
            for c in range(nch):
                s += acc[c, q]
            out[k, q] = s
        for q in range(4):
            vir[q] = out[k, q]
        st, remap = cell_end_of_step(cell, ctl, step, vir, dt, lo_old, hi_old, lo_new, hi_new, tmp)
        if st != 0:
            return k, st, -1
        last = k == nsteps - 1
        dsq = cell_deltasq(cell, skin, clamp, corners)
        integrate_v(
            parallel, cstart, x, y, vx, vy, w, fx, fy, t, m, r, xh, yh, dt,
            True, not last, remap, lo_old, hi_old, lo_new, hi_new, tmp[0, 0], tmp[0, 1], dsq, red,
        )  # fmt: skip
        ke = 0.0
        for c in range(nch):
            ke += red[c, 0]
        out[k, 6] = ke
        cell_row(cell, out, k)
        k += 1
        if not last:
            st = _status(red, nch)
            if st != 0:
                return k, st, _bad(red, nch)
    return nsteps, 0, -1


@njit
def _status(red, nch):
    st = 0
    for c in range(nch):
        if red[c, 2] != 0.0:
            return 2
        if red[c, 1] != 0.0:
            st = 1
    return st


@njit
def _bad(red, nch):
    for c in range(nch):
        if red[c, 2] != 0.0:
            return int(red[c, 2]) - 1
    return -1


# ----------------------------------------------------------------------------------- rebuild
@njit(inline="always")
def _wrap_axis(a, i, lo, hi, prd):
    """Domain::pbc of particle ``i`` on one axis (x < lo: += L; x >= hi: -= L, then max(x, lo));
    True when it is still outside after the wrap."""
    if a[i] < lo:
        a[i] += prd
    if a[i] >= hi:
        a[i] -= prd
        a[i] = max(a[i], lo)
    return a[i] < lo or a[i] >= hi


@pjit
def wrap(x, y, lo, hi):
    """Domain::pbc per axis; returns a particle still outside after one wrap (sorted index: the
    first outside along x, else the first along y) or -1. The particles are spread over the
    threads (one thread: in order): each particle's wrap is its own, so the positions and the
    particle returned do not depend on the threads."""
    n = x.shape[0]
    bx = n
    by = n
    px = hi[0] - lo[0]
    py = hi[1] - lo[1]
    for i in prange(n):
        if _wrap_axis(x, i, lo[0], hi[0], px):
            bx = min(bx, i)
        if _wrap_axis(y, i, lo[1], hi[1], py):
            by = min(by, i)
    return bx if bx < n else (by if by < n else -1)


@njit(inline="always")
def _wrap_tilted_one(x, y, vx, vy, i, box, hr, vremap, Lx, Ly, xy, tl):
    """Domain::pbc of particle ``i`` in the sheared cell (:func:`wrap_tilted`); True when it is
    still outside after the wrap."""
    lx = box[0]
    ly = box[1]
    if y[i] < ly:
        y[i] += Ly
        x[i] += xy
        if vremap:
            vx[i] += hr[2]
            vy[i] += hr[1]
    if y[i] >= box[3]:
        y[i] -= Ly
        y[i] = max(y[i], ly)
        x[i] -= xy
        if vremap:
            vx[i] -= hr[2]
            vy[i] -= hr[1]
    off = (x[i] - lx) - tl * (y[i] - ly)
    if off < 0.0:
        x[i] += Lx
        if vremap:
            vx[i] += hr[0]
    elif off >= Lx:
        x[i] -= Lx
        if vremap:
            vx[i] -= hr[0]
    off = (x[i] - lx) - tl * (y[i] - ly)
    return not (0.0 <= off < Lx and ly <= y[i] < box[3])


@pjit
def wrap_tilted(x, y, vx, vy, box, hr, vremap):
    """Domain::pbc of the sheared cell ``box`` (5,) = (lo_x, lo_y, hi_x, hi_y, xy) m: a particle
    below lo_y moves by a2 = (xy, Ly), above hi_y by -a2, with its velocity changed by
    +/-(h_rate[5], h_rate[1]) when ``vremap`` (Lees-Edwards: the peculiar velocity is kept;
    ``hr`` (3,) = (h_rate[0], h_rate[1], h_rate[5]) m/s); then along x by +/-a1 = (Lx, 0), its x
    velocity by +/-h_rate[0], when its offset from the cell's left edge, (x - lo_x) - (xy/Ly)
    (y - lo_y), is outside [0, Lx). Returns
    a particle still outside after one wrap (sorted index) or -1. The particles are spread over
    the threads (one thread: in order): the result does not depend on them."""
    n = x.shape[0]
    Lx = box[2] - box[0]
    Ly = box[3] - box[1]
    tl = box[4] / Ly
    bad = n
    for i in prange(n):
        if _wrap_tilted_one(x, y, vx, vy, i, box, hr, vremap, Lx, Ly, box[4], tl):
            bad = min(bad, i)
    return bad if bad < n else -1


@njit
def bin_sort(x, y, lo, hi, xy, nbx, nby, order, binstart, key):
    """Counting sort of the particles by bin (row-major: bin = bx + nbx by): ``order`` (N,) int32
    the current index of each particle in the new order (stable within a bin), ``binstart``
    (nbx nby + 1,) int32 the first sorted particle of each bin; ``key`` (N,) int32 scratch.

    The bins are those of the cell's lamda coordinates: rows of height Ly/nby, and along x the
    offset from the cell's left edge through the particle, (x - lo_x) - (xy/Ly)(y - lo_y), in
    steps of Lx/nbx (``xy`` the tilt, m; 0 for an orthogonal cell, whose bins are then the plain
    x bins)."""
    n = x.shape[0]
    nbins = nbx * nby
    sx = nbx / (hi[0] - lo[0])
    sy = nby / (hi[1] - lo[1])
    tl = xy / (hi[1] - lo[1])
    for b in range(nbins + 1):
        binstart[b] = 0
    for i in range(n):
        bx = min(max(int(((x[i] - lo[0]) - tl * (y[i] - lo[1])) * sx), 0), nbx - 1)
        by = min(max(int((y[i] - lo[1]) * sy), 0), nby - 1)
        key[i] = bx + nbx * by
        binstart[key[i] + 1] += 1
    for b in range(nbins):
        binstart[b + 1] += binstart[b]
    for i in range(n):
        b = key[i]
        order[binstart[b]] = i
        binstart[b] += 1
    for b in range(nbins, 0, -1):
        binstart[b] = binstart[b - 1]
    binstart[0] = 0


@njit
def gather_f(a, order, out):
    """out[:] = a[order] (float64): the permuted array in a second buffer (the caller swaps them)."""
    for i in range(order.shape[0]):
        out[i] = a[order[i]]


@njit
def permute_i(a, order, tmp):
    """a[:] = a[order] through the scratch ``tmp`` (int32)."""
    for i in range(order.shape[0]):
        tmp[i] = a[order[i]]
    for i in range(order.shape[0]):
        a[i] = tmp[i]


@njit
def count_history(start, h0, h1, n):
    """Entries of the list whose spring is not zero (the size of the hand-over table)."""
    m = start[n]
    return _nonzero_springs(h0[:m], h1[:m])


@njit
def compact_history(start, stop, nj, h0, h1, n, hstart, hj, hh):
    """The hand-over table: the entries of the current list whose spring is not zero, CSR by i
    (``hstart`` (N+1,) int32, ``hj`` int32, ``hh`` (K, 2)); returns K. Only these can pass a
    spring on (an entry with a zero spring hands over zero)."""
    k = _compact_band(0, n, 0, start, stop, nj, h0, h1, hstart, hj, hh)
    hstart[n] = k
    return k


@njit(inline="always")
def _band_pairs(
    c,
    fill,
    e0,
    cstart,
    binstart,
    x,
    y,
    r,
    lo,
    hi,
    xy,
    nbx,
    nby,
    skin,
    cnt,
    start,
    ni,
    nj,
    code,
    h0,
    h1,
    sp_cnt,
    order,
    hstart,
    hj,
    hh,
):
    """Partners j > i of the particles of band ``c`` within r_i + r_j + skin (the 9 bins around
    i's bin, periodic). ``fill`` 0: per-particle counts into ``cnt`` and the band's spill count
    into ``sp_cnt[c]``; 1: the entries (owner ``ni``, partner ``nj``, image ``code``) at
    ``start[i]..`` with the spring handed over from the
    old list when the pair touches now (old indices ``order``, table hstart/hj/hh; a pair stored
    as (j, i) before takes minus the spring); 2: counting and filling in one pass, the entries
    from ``e0`` on (``start[i]`` written), returns the next free entry or -1 when the buffers are
    full. Modes 0 and 1 return 0."""
    Lx = hi[0] - lo[0]
    Ly = hi[1] - lo[1]
    sx = nbx / Lx
    sy = nby / Ly
    tl = xy / Ly
    nch = cstart.shape[0] - 1
    jmax = cstart[min(c + 2, nch)]
    nsp = 0
    cap = nj.shape[0]
    e = e0
    for i in range(cstart[c], cstart[c + 1]):
        bx = min(max(int(((x[i] - lo[0]) - tl * (y[i] - lo[1])) * sx), 0), nbx - 1)
        by = min(max(int((y[i] - lo[1]) * sy), 0), nby - 1)
        if fill == 1:
            e = start[i]
        elif fill == 2:
            start[i] = e
        ncount = 0
        for oy in range(-1, 2):
            qy = by + oy
            iy = 0
            if qy < 0:
                qy += nby
                iy = -1
            elif qy >= nby:
                qy -= nby
                iy = 1
            for ox in range(-1, 2):
                qx = bx + ox
                ix = 0
                if qx < 0:
                    qx += nbx
                    ix = -1
                elif qx >= nbx:
                    qx -= nbx
                    ix = 1
                b = qx + nbx * qy
                j0 = max(binstart[b], i + 1)
                for j in range(j0, binstart[b + 1]):
                    delx = x[i] - ((x[j] + ix * Lx) + iy * xy)
                    dely = y[i] - (y[j] + iy * Ly)
                    rs = r[i] + r[j]
                    cut = rs + skin
                    rsq = delx * delx + dely * dely
                    if rsq <= cut * cut:
                        ncount += 1
                        if j >= jmax:
                            nsp += 1
                        if fill != 0:
                            if e >= cap:
                                return -1
                            ni[e] = i
                            nj[e] = j
                            code[e] = (ix + 1) + 3 * (iy + 1)
                            g0 = 0.0
                            g1 = 0.0
                            if rsq < rs * rs and hstart.shape[0] > 1:
                                oi = order[i]
                                oj = order[j]
                                a = min(oi, oj)
                                bb = max(oi, oj)
                                sg = 1.0 if oi < oj else -1.0
                                for q in range(hstart[a], hstart[a + 1]):
                                    if hj[q] == bb:
                                        g0 = sg * hh[q, 0]
                                        g1 = sg * hh[q, 1]
                                        break
                            h0[e] = g0
                            h1[e] = g1
                            e += 1
        if fill == 0:
            cnt[i] = ncount
    if fill != 1:
        sp_cnt[c] = nsp
    return e if fill == 2 else 0


@njit
def pairs_direct(
    cstart,
    binstart,
    x,
    y,
    r,
    lo,
    hi,
    xy,
    nbx,
    nby,
    skin,
    start,
    ni,
    nj,
    code,
    h0,
    h1,
    sp_cnt,
    order,
    hstart,
    hj,
    hh,
):
    """The list in one pass (:func:`_band_pairs` mode 2 over all bands, in band order: the same
    list as the count and fill passes); returns the number of entries, or -1 when the buffers are
    too small (then count, grow and fill)."""
    e = 0
    n = x.shape[0]
    for c in range(cstart.shape[0] - 1):
        e = _band_pairs(
            c,
            2,
            e,
            cstart,
            binstart,
            x,
            y,
            r,
            lo,
            hi,
            xy,
            nbx,
            nby,
            skin,
            start,
            start,
            ni,
            nj,
            code,
            h0,
            h1,
            sp_cnt,
            order,
            hstart,
            hj,
            hh,
        )
        if e < 0:
            return -1
    start[n] = e
    return e


@njit
def pairs_serial(
    fill,
    cstart,
    binstart,
    x,
    y,
    r,
    lo,
    hi,
    xy,
    nbx,
    nby,
    skin,
    cnt,
    start,
    ni,
    nj,
    code,
    h0,
    h1,
    sp_cnt,
    order,
    hstart,
    hj,
    hh,
):
    """:func:`_band_pairs` over all bands."""
    for c in range(cstart.shape[0] - 1):
        _band_pairs(
            c,
            fill,
            0,
            cstart,
            binstart,
            x,
            y,
            r,
            lo,
            hi,
            xy,
            nbx,
            nby,
            skin,
            cnt,
            start,
            ni,
            nj,
            code,
            h0,
            h1,
            sp_cnt,
            order,
            hstart,
            hj,
            hh,
        )


@pjit
def pairs_parallel(
    fill,
    cstart,
    binstart,
    x,
    y,
    r,
    lo,
    hi,
    xy,
    nbx,
    nby,
    skin,
    cnt,
    start,
    ni,
    nj,
    code,
    h0,
    h1,
    sp_cnt,
    order,
    hstart,
    hj,
    hh,
):
    """:func:`pairs_serial` with the bands spread over the threads."""
    for c in prange(cstart.shape[0] - 1):
        _band_pairs(
            c,
            fill,
            0,
            cstart,
            binstart,
            x,
            y,
            r,
            lo,
            hi,
            xy,
            nbx,
            nby,
            skin,
            cnt,
            start,
            ni,
            nj,
            code,
            h0,
            h1,
            sp_cnt,
            order,
            hstart,
            hj,
            hh,
        )


@pjit
def pairs_banded(
    cstart,
    binstart,
    x,
    y,
    r,
    lo,
    hi,
    xy,
    nbx,
    nby,
    skin,
    start,
    stop,
    ni,
    nj,
    code,
    h0,
    h1,
    sp_cnt,
    order,
    hstart,
    hj,
    hh,
    base,
    used,
):
    """The list in one pass per band with the bands spread over the threads (the threaded
    counterpart of :func:`pairs_direct`, which walks each stencil once where the count and fill
    passes of :func:`pairs_parallel` walk it twice): band c fills its own region
    ``base[c]..base[c + 1]`` of the buffers (``base`` (C+1,) int64) and writes the ``start`` and
    ``stop`` of its particles; ``used[c]`` (C,) int64 receives its entries, or -1 when the region
    is too small (its starts and stops are then not written). When every band fits, the list is
    that of :func:`pairs_direct` entry for entry, each band's entries moved up to its region with
    a gap after them (the force loop and the hand-over read the bands as they are;
    :func:`close_gaps` moves them together for the readers of the whole list)."""
    for c in prange(cstart.shape[0] - 1):
        b0 = base[c]
        b1 = base[c + 1]
        u = _band_pairs(
            c,
            2,
            0,
            cstart,
            binstart,
            x,
            y,
            r,
            lo,
            hi,
            xy,
            nbx,
            nby,
            skin,
            start,
            start,
            ni[b0:b1],
            nj[b0:b1],
            code[b0:b1],
            h0[b0:b1],
            h1[b0:b1],
            sp_cnt,
            order,
            hstart,
            hj,
            hh,
        )
        used[c] = u
        if u >= 0:  # the band's starts were written from 0: from b0, and its stops
            i0 = cstart[c]
            i1 = cstart[c + 1]
            for i in range(i0, i1):
                start[i] += b0
            for i in range(i0, i1 - 1):
                stop[i] = start[i + 1]
            if i1 > i0:
                stop[i1 - 1] = b0 + u


@njit
def close_gaps(cstart, base, used, start, ni, nj, code, h0, h1):
    """The list of :func:`pairs_banded` (band c's entries at ``base[c]..base[c] + used[c]``)
    made plain CSR: each band's entries moved down to follow the previous band's (a forward copy,
    the destination never above the source), ``start`` moved with them and ``start[N]`` the
    total, which is returned (the stops are then ``start[1:]``)."""
    nch = cstart.shape[0] - 1
    off = 0
    for c in range(nch):
        b0 = base[c]
        m = used[c]
        if off != b0:
            for k in range(m):
                ni[off + k] = ni[b0 + k]
                nj[off + k] = nj[b0 + k]
                code[off + k] = code[b0 + k]
                h0[off + k] = h0[b0 + k]
                h1[off + k] = h1[b0 + k]
        for i in range(cstart[c], cstart[c + 1]):
            start[i] += off - b0
        off += m
    start[cstart[nch]] = off
    return off


@njit
def _nonzero_springs(h0, h1):
    # over whole (sliced) arrays: the same loop written as range(e0, e1) over the full arrays
    # compiled to code 3x slower (1.6 ms against 5.3 ms for 2.6e6 entries, measured)
    k = 0
    for e in range(h0.shape[0]):
        if h0[e] != 0.0 or h1[e] != 0.0:
            k += 1
    return k


@pjit
def history_counts(cstart, start, stop, h0, h1, bcount):
    """Per band of the current list, the entries whose spring is not zero (``bcount`` (C,) int64;
    their sum is :func:`count_history`), the bands on the threads."""
    for c in prange(cstart.shape[0] - 1):
        if cstart[c + 1] > cstart[c]:
            e0 = start[cstart[c]]
            e1 = stop[cstart[c + 1] - 1]
            bcount[c] = _nonzero_springs(h0[e0:e1], h1[e0:e1])
        else:
            bcount[c] = 0


@pjit
def compact_history_banded(cstart, start, stop, nj, h0, h1, bcount, hstart, hj, hh):
    """:func:`compact_history` with the bands on the threads (the same table, entry for entry):
    band c writes from the sum of the counts ``bcount`` of the bands before it."""
    nch = cstart.shape[0] - 1
    off = np.zeros(nch + 1, np.int64)
    for c in range(nch):
        off[c + 1] = off[c] + bcount[c]
    for c in prange(nch):
        _compact_band(cstart[c], cstart[c + 1], off[c], start, stop, nj, h0, h1, hstart, hj, hh)
    hstart[cstart[nch]] = off[nch]
    return off[nch]


@njit
def _compact_band(i0, i1, k, start, stop, nj, h0, h1, hstart, hj, hh):
    # the rows i0..i1 of the hand-over table from entry k on; returns the next free entry (a plain
    # kernel, also inside the parallel loop: see _nonzero_springs)
    for i in range(i0, i1):
        hstart[i] = k
        for e in range(start[i], stop[i]):
            if h0[e] != 0.0 or h1[e] != 0.0:
                hj[k] = nj[e]
                hh[k, 0] = h0[e]
                hh[k, 1] = h1[e]
                k += 1
    return k


@njit
def prefix(cnt, start):
    """start[0] = 0, start[i + 1] = start[i] + cnt[i]; returns the total."""
    s = 0
    start[0] = 0
    for i in range(cnt.shape[0]):
        s += cnt[i]
        start[i + 1] = s
    return s


@njit
def unsort_f(a, perm, out):
    """out[perm[k]] = a[k]: an array of the sorted order in the original order."""
    for k in range(perm.shape[0]):
        out[perm[k]] = a[k]


@njit
def entry_forces(law, img, dt, ni, nj, code, h0, h1, x, y, vx, vy, w, r, m, out):
    """The law at the current state for each list entry, its springs left as they are (a set-up
    evaluation, ``update`` False): ``out`` (M, 4) receives the force on i (N; zero when apart),
    the sliding flag and the touch flag (1.0 or 0.0)."""
    for e in range(ni.shape[0]):
        i = ni[e]
        j = nj[e]
        sx = float(code[e] % 3) - 1.0
        sy = float(code[e] // 3) - 1.0
        xj, yj, vxj, vyj = image(img, x[j], y[j], vx[j], vy[j], sx, sy)
        delx = x[i] - xj
        dely = y[i] - yj
        rsq = delx * delx + dely * dely
        touch, fxe, fye, _, _, _, _, sl, _ = pair_select(
            law, delx, dely, rsq, r[i], r[j], vx[i], vy[i], vxj, vyj, w[i], w[j], m[i], m[j], dt, h0[e], h1[e], False
        )
        out[e, 0] = touch * fxe
        out[e, 1] = touch * fye
        out[e, 2] = touch * sl
        out[e, 3] = touch


@njit
def flow_energies(y, vx, vy, w, m, r, ylo, ly, ux, uy):
    """(kinetic energy relative to the cell's homogeneous flow, kinetic energy of the flow) (J) in
    one pass, without temporaries: the flow at a particle u = (ux, uy) (y - ylo)/ly (the sheared
    cell's h_rate[5], h_rate[1] in m/s; zero for the orthogonal cell, whose first value is then the
    kinetic energy), translational m |v - u|^2/2 plus rotational m r^2 w^2/4 (I = m r^2/2)."""
    rel = 0.0
    rot = 0.0
    flow = 0.0
    for i in range(y.shape[0]):
        f = (y[i] - ylo) / ly
        fx = ux * f
        fy = uy * f
        px = vx[i] - fx
        py = vy[i] - fy
        rel += m[i] * (px * px + py * py)
        rot += m[i] * r[i] * r[i] * w[i] * w[i]
        flow += m[i] * (fx * fx + fy * fy)
    return 0.5 * rel + 0.25 * rot, 0.5 * flow


@njit
def largest_move(x, y, xh, yh):
    """(i, |x_i - xh_i|) (m) of the particle that moved most since the last build, the first of
    equal moves, a NaN distance first (:func:`gransim.dem.kernels.largest_displacement` on the
    structure of arrays)."""
    best = -1.0
    k = 0
    for i in range(x.shape[0]):
        dx = x[i] - xh[i]
        dy = y[i] - yh[i]
        d = math.sqrt(dx * dx + dy * dy)
        if d != d:
            return i, d
        if d > best:
            best = d
            k = i
    return k, best


@njit(inline="always")
def _entry_gap(img, ni, nj, code, x, y, r, e):
    """(|d|, r_i + r_j) of list entry ``e``, the image of j from the cell ``img`` (m)."""
    i = ni[e]
    j = nj[e]
    xj, yj, _, _ = image(img, x[j], y[j], 0.0, 0.0, float(code[e] % 3) - 1.0, float(code[e] // 3) - 1.0)
    dx = x[i] - xj
    dy = y[i] - yj
    return math.sqrt(dx * dx + dy * dy), r[i] + r[j]


@njit
def touching_entries(img, ni, nj, code, x, y, r):
    """The list entries whose disks touch (|d| < r_i + r_j, the image of j from the cell ``img``,
    :func:`image`) and their overlaps (m): (K,) int64 and (K,) float64, in list order, without
    (M,) temporaries (two passes: count, fill)."""
    k = 0
    for e in range(ni.shape[0]):
        d, rs = _entry_gap(img, ni, nj, code, x, y, r, e)
        if d < rs:
            k += 1
    idx = np.empty(k, np.int64)
    ov = np.empty(k)
    k = 0
    for e in range(ni.shape[0]):
        d, rs = _entry_gap(img, ni, nj, code, x, y, r, e)
        if d < rs:
            idx[k] = e
            ov[k] = rs - d
            k += 1
    return idx, ov
