"""Numba kernels of the fast DEM path (:mod:`gransim.dem.fast`): no validation here.

Layout (all structure-of-arrays, particles in *sorted* order, see :func:`bin_sort`):
x, y, vx, vy, w, fx, fy, t, r, m (N,) float64; perm (N,) int32 the original index of each sorted
particle. Half neighbour list, each pair once with i < j in the sorted order, CSR by i:
start (N+1,) int32, nj (M,) int32, code (M,) uint8 the periodic image of j
(code = (sx + 1) + 3 (sy + 1), image x_j + sx Lx, y_j + sy Ly), ni (M,) int32 the owner i of each
entry (written by the list build, for the vectorised force loop), h0, h1 (M,) float64 the two
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

from .._numba import njit, pjit, prange
from ..contacts.hooke import hooke_select_liggghts


# ----------------------------------------------------------------------------------- the law
@njit(inline="always")
def hooke_select(
    delx, dely, rsq, radsum, ri, rj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gn, gt, mu, dt, s0, s1, update
):  # fmt: skip
    """LIGGGHTS' Hooke pair as the fast path sums it: the branch-free law of the bitwise engine
    (:func:`gransim.contacts.hooke.hooke_select_liggghts`: the same function), its
    force, torques and overlap masked to zero when the disks do not touch (the fast loop sums
    every entry). ``radsum`` = r_i + r_j (the law adds the radii itself, in the same order).

    Returns (touch, fx, fy, ti, tj, s0, s1, overlap): touch 1.0 when the disks touch
    (rsq < radsum^2) else 0.0 (a float, not a bool: a bool taken out of the returned tuple counts
    as an alias to numba's parfor analysis and keeps the caller's loop from vectorising), force on
    i (N; zero when apart), torques on i and j (N m), the spring (m; unchanged when apart) and the
    overlap radsum - |d| (m; zero when apart).
    """
    touch, fx, fy, ti, tj, u0, u1, _, dn = hooke_select_liggghts(
        delx, dely, rsq, ri, rj, vix, viy, vjx, vjy, wi, wj, mi, mj, kn, kt, gn, gt, mu, dt, s0, s1, update
    )
    return touch, touch * fx, touch * fy, touch * ti, touch * tj, u0, u1, touch * dn


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
    Lx,
    Ly,
    law,
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
    kn, kt, gn, gt, mu, dt = law
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
                    cap = max(cap, start[min(ia + SIMD_BLOCK, cstart[c + 1])] - start[ia])
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
                jmax = cstart[min(c + 2, nch)]
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
                    eb = start[ib]
                    for e_ in range(ea, eb):
                        e = np.uint64(e_)
                        q = np.uint64(e_ - ea)
                        i = ni[e]
                        j = nj[e]
                        cd = np.uint32(code[e])
                        sx = float(np.int32(cd % np.uint32(3)) - 1)
                        sy = float(np.int32(cd // np.uint32(3)) - 1)
                        delx = x[i] - (x[j] + sx * Lx)
                        dely = y[i] - (y[j] + sy * Ly)
                        rsq = delx * delx + dely * dely
                        touch, fxe, fye, tie, tje, s0, s1, dn = hooke_select(
                            delx,
                            dely,
                            rsq,
                            r[i] + r[j],
                            r[i],
                            r[j],
                            vx[i],
                            vy[i],
                            vx[j],
                            vy[j],
                            w[i],
                            w[j],
                            m[i],
                            m[j],
                            kn,
                            kt,
                            gn,
                            gt,
                            mu,
                            dt,
                            h0[e],
                            h1[e],
                            update,
                        )
                        h0[e] = s0
                        h1[e] = s1
                        bfx[q] = fxe
                        bfy[q] = fye
                        bti[q] = tie
                        btj[q] = tje
                        bdx[q] = delx
                        bdy[q] = dely
                        bov[q] = dn
                        bto[q] = touch
                    for i in range(ia, ib):
                        fxi = 0.0
                        fyi = 0.0
                        ti = 0.0
                        for e in range(start[i], start[i + 1]):
                            q = e - ea
                            fxe = bfx[q]
                            fye = bfy[q]
                            fxi += fxe
                            fyi += fye
                            ti += bti[q]
                            j = nj[e]
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
    deltasq,
    red,
):
    """The fused pass, band by band: [final half step (v, w) and its kinetic energy] [remap x
    affinely from box (lo_old, hi_old) to (lo_new, hi_new)] [first half step, position update,
    rebuild test |x - x_hold|^2 > deltasq, forces zeroed]. ``red[c]`` = (kinetic energy (J),
    rebuild flag, first non-finite particle + 1 or 0).

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
                    if remap:
                        px = Hx * (hx * (px - lox)) + lnx
                        py = Hy * (hy * (py - loy)) + lny
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
#: the half list (module docstring): cstart (C+1,) the bands, start (N+1,) CSR, ni, nj (M,) int32,
#: code (M,) uint8, h0, h1 (M,) the spring (m)
FastList = namedtuple("FastList", ["cstart", "start", "ni", "nj", "code", "h0", "h1"])
#: the box and its loading: lo, hi (2,) m now, lo_hold, hi_hold (2,) at the last build; modes (2,)
#: int64 (0 fixed, 1 rate), rates (2,) 1/s, lo0, hi0 (2,) m the box at the phase start, phase_step0
FastBox = namedtuple("FastBox", ["lo", "hi", "lo_hold", "hi_hold", "modes", "rates", "lo0", "hi0", "phase_step0"])
#: work arrays: sp_start (C+1,), sp_j, sp_f the spills (:func:`forces_v`), acc (C, 6), red (C, 3)
FastScratch = namedtuple("FastScratch", ["sp_start", "sp_j", "sp_f", "acc", "red"])


@njit
def run_steps(parallel, p, nl, box, law, skin, sc, out, step0, nsteps, resume):
    """Steps step0 + 1 .. step0 + nsteps of the fast path, until a list rebuild is needed.

    ``p`` :data:`FastParticles`, ``nl`` :data:`FastList`, ``box`` :data:`FastBox` (lo, hi,
    lo_hold, hi_hold updated in place), ``law`` = (kn, kt, gamma_n, gamma_t, mu, dt) (N/m, N/m,
    1/s, 1/s, -, s), ``skin`` (m), ``sc`` :data:`FastScratch`. (The parallel kernels it calls,
    :func:`forces_v` and :func:`integrate_v`, take the arrays unpacked: gransim/_numba.py.)

    Per step: forces (even bands, odd bands, spills), then one fused pass: second half step of
    this step, the box of this step (``modes`` 0 fixed / 1 rate per axis, ``fix deform``'s
    L = L0 + rate L0 dt (step - phase_step0), centred on the phase's box lo0, hi0) with the
    positions remapped, and -- unless it is the last step -- the first half step of the next
    step with the rebuild test (displacement since the build above half the skin less the box
    displacement, LAMMPS' clamped rule). Enter with the first half step of step0 + 1 done when
    ``resume``. ``out`` (nsteps, 9) rows: virial xx, yy, xy, yx (N m), contacts, overlap sum (m),
    Lx, Ly (m) of the box after the step, kinetic energy (J).

    Returns (steps completed, status, bad): status 0 done, 1 rebuild needed before the forces of
    step step0 + completed + 1 (its first half step is done), 2 non-finite position (bad =
    sorted index).
    """
    x, y, vx, vy, w, fx, fy, t, m, r, xh, yh = p
    cstart, start, ni, nj, code, h0, h1 = nl
    lo, hi, lo_hold, hi_hold, modes, rates, lo0, hi0, phase_step0 = box
    sp_start, sp_j, sp_f, acc, red = sc
    dt = law[5]
    lo_new = np.empty(2)
    hi_new = np.empty(2)
    lo_cur = np.empty(2)
    hi_cur = np.empty(2)
    nch = cstart.shape[0] - 1
    k = 0
    if not resume:
        dsq = _deltasq(lo, hi, lo_hold, hi_hold, skin)
        integrate_v(
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
            False,
            True,
            False,
            lo,
            hi,
            lo,
            hi,
            dsq,
            red,
        )
        st = _status(red, nch)
        if st != 0:
            return 0, st, _bad(red, nch)
    while k < nsteps:
        step = step0 + k + 1
        Lx = hi[0] - lo[0]
        Ly = hi[1] - lo[1]
        forces_v(
            parallel,
            cstart,
            start,
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
            Lx,
            Ly,
            law,
            True,
            sp_start,
            sp_j,
            sp_f,
            acc,
        )
        for q in range(6):
            s = 0.0
            for c in range(nch):
                s += acc[c, q]
            out[k, q] = s
        # the box of this step (fix deform, rate style)
        remap = False
        for d in range(2):
            lo_cur[d] = lo[d]
            hi_cur[d] = hi[d]
            lo_new[d] = lo[d]
            hi_new[d] = hi[d]
            if modes[d] == 1:
                L0 = hi0[d] - lo0[d]
                dl = (rates[d] * L0 * dt) * float(step - phase_step0)
                lo_new[d] = lo0[d] - 0.5 * dl
                hi_new[d] = hi0[d] + 0.5 * dl
                if lo_new[d] != lo[d] or hi_new[d] != hi[d]:
                    remap = True
        last = k == nsteps - 1
        if remap:
            for d in range(2):
                lo[d] = lo_new[d]
                hi[d] = hi_new[d]
        dsq = _deltasq(lo, hi, lo_hold, hi_hold, skin)
        integrate_v(
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
            True,
            not last,
            remap,
            lo_cur,
            hi_cur,
            lo,
            hi,
            dsq,
            red,
        )
        ke = 0.0
        for c in range(nch):
            ke += red[c, 0]
        out[k, 6] = hi[0] - lo[0]
        out[k, 7] = hi[1] - lo[1]
        out[k, 8] = ke
        k += 1
        if not last:
            st = _status(red, nch)
            if st != 0:
                return k, st, _bad(red, nch)
    return nsteps, 0, -1


@njit
def _deltasq(lo, hi, lo_hold, hi_hold, skin):
    dx = lo[0] - lo_hold[0]
    dy = lo[1] - lo_hold[1]
    d1 = math.sqrt(dx * dx + dy * dy)
    dx = hi[0] - hi_hold[0]
    dy = hi[1] - hi_hold[1]
    d2 = math.sqrt(dx * dx + dy * dy)
    delta = max(0.5 * (skin - (d1 + d2)), 0.0)
    return delta * delta


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
@njit
def wrap(x, y, lo, hi):
    """Domain::pbc per axis (x < lo: += L; x >= hi: -= L, then max(x, lo)); returns a particle
    still outside after one wrap (sorted index) or -1."""
    bad = -1
    for d in range(2):
        a = x if d == 0 else y
        prd = hi[d] - lo[d]
        for i in range(a.shape[0]):
            if a[i] < lo[d]:
                a[i] += prd
            if a[i] >= hi[d]:
                a[i] -= prd
                a[i] = max(a[i], lo[d])
            if (a[i] < lo[d] or a[i] >= hi[d]) and bad < 0:
                bad = i
    return bad


@njit
def bin_sort(x, y, lo, hi, nbx, nby, order, binstart, key):
    """Counting sort of the particles by bin (row-major: bin = bx + nbx by): ``order`` (N,) int32
    the current index of each particle in the new order (stable within a bin), ``binstart``
    (nbx nby + 1,) int32 the first sorted particle of each bin; ``key`` (N,) int32 scratch."""
    n = x.shape[0]
    nbins = nbx * nby
    sx = nbx / (hi[0] - lo[0])
    sy = nby / (hi[1] - lo[1])
    for b in range(nbins + 1):
        binstart[b] = 0
    for i in range(n):
        bx = min(max(int((x[i] - lo[0]) * sx), 0), nbx - 1)
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
def compact_history(start, nj, h0, h1, n, hstart, hj, hh):
    """The hand-over table: the entries of the current list whose spring is not zero, CSR by i
    (``hstart`` (N+1,) int32, ``hj`` int32, ``hh`` (K, 2)); returns K. Only these can pass a
    spring on (an entry with a zero spring hands over zero)."""
    k = _compact_band(0, n, 0, start, nj, h0, h1, hstart, hj, hh)
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
    nch = cstart.shape[0] - 1
    jmax = cstart[min(c + 2, nch)]
    nsp = 0
    cap = nj.shape[0]
    e = e0
    for i in range(cstart[c], cstart[c + 1]):
        bx = min(max(int((x[i] - lo[0]) * sx), 0), nbx - 1)
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
                    delx = x[i] - (x[j] + ix * Lx)
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
    base,
    used,
):
    """The list in one pass per band with the bands spread over the threads (the threaded
    counterpart of :func:`pairs_direct`, which walks each stencil once where the count and fill
    passes of :func:`pairs_parallel` walk it twice): band c fills its own region
    ``base[c]..base[c + 1]`` of the buffers (``base`` (C+1,) int64), ``start[i]`` relative to
    ``base[c]``; ``used[c]`` (C,) int64 receives its entries, or -1 when the region is too small.
    :func:`close_gaps` then moves the bands together: the list is that of :func:`pairs_direct`,
    entry for entry."""
    for c in prange(cstart.shape[0] - 1):
        b0 = base[c]
        b1 = base[c + 1]
        used[c] = _band_pairs(
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


@njit
def close_gaps(cstart, base, used, start, ni, nj, code, h0, h1):
    """After :func:`pairs_banded`: each band's entries moved down to follow the previous band's
    (a forward copy, the destination never above the source), ``start`` made absolute and
    ``start[N]`` the total, which is returned."""
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
            start[i] += off
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
def history_counts(cstart, start, h0, h1, bcount):
    """Per band of the current list, the entries whose spring is not zero (``bcount`` (C,) int64;
    their sum is :func:`count_history`), the bands on the threads."""
    for c in prange(cstart.shape[0] - 1):
        e0 = start[cstart[c]]
        e1 = start[cstart[c + 1]]
        bcount[c] = _nonzero_springs(h0[e0:e1], h1[e0:e1])


@pjit
def compact_history_banded(cstart, start, nj, h0, h1, bcount, hstart, hj, hh):
    """:func:`compact_history` with the bands on the threads (the same table, entry for entry):
    band c writes from the sum of the counts ``bcount`` of the bands before it."""
    nch = cstart.shape[0] - 1
    off = np.zeros(nch + 1, np.int64)
    for c in range(nch):
        off[c + 1] = off[c] + bcount[c]
    for c in prange(nch):
        _compact_band(cstart[c], cstart[c + 1], off[c], start, nj, h0, h1, hstart, hj, hh)
    hstart[cstart[nch]] = off[nch]
    return off[nch]


@njit
def _compact_band(i0, i1, k, start, nj, h0, h1, hstart, hj, hh):
    # the rows i0..i1 of the hand-over table from entry k on; returns the next free entry (a plain
    # kernel, also inside the parallel loop: see _nonzero_springs)
    for i in range(i0, i1):
        hstart[i] = k
        for e in range(start[i], start[i + 1]):
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
