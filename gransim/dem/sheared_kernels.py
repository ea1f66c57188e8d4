"""Numba kernels of the sheared (triclinic) periodic cell, in the arithmetic of LAMMPS.

The cell is LAMMPS' 2D triclinic box: lo = (lo_x, lo_y), h = [[Lx, xy], [0, Ly]] (``h[0]``,
``h[1]``, ``h[5]`` of ``Domain``), stored as ``box = [lo_x, lo_y, hi_x, hi_y, xy]``. The image of
particle j with shift s = (s_x, s_y) lies at x_j + s_x (Lx, 0) + s_y (xy, Ly); under ``fix deform
... remap v`` (Lees-Edwards) it moves with v_j + s_x (h_rate[0], 0) + s_y (h_rate[5], h_rate[1]).
``hr = [h_rate[0], h_rate[1], h_rate[5]]`` (m/s). The floating-point operations follow LAMMPS
29 Sep 2021 (``src/domain.cpp`` ``x2lamda``/``lamda2x``/``pbc``/``lamda_box_corners``,
``src/atom_vec*.cpp`` ``pack_comm_vel``/``pack_border_vel``, ``src/neighbor.cpp``
``check_distance``, ``src/fix_deform.cpp`` ``end_of_step``, ``src/fix_neigh_history.cpp``); see
docs/shear.md. The time integration is :func:`gransim.dem.kernels.initial_integrate` /
:func:`~gransim.dem.kernels.final_integrate` (LAMMPS' ``fix nve/sphere disc`` is the same
arithmetic).

The contact law is any registered law (:mod:`gransim.contacts.laws`): the force loop is
:func:`gransim.dem.kernels.forces_in` with the sheared cell's image
(:data:`gransim.dem.kernels.TiltedImage`: the tilted minimum image and the Lees-Edwards image
velocity are the only differences from the orthogonal cell), so each law type compiles its own
copy of :func:`run_block` (kept in numba's disk cache like the orthogonal kernels).
"""

from __future__ import annotations

import math
from collections import namedtuple

import numpy as np

from .._numba import njit
from . import kernels as K

#: the fix deform parameters of a run (:func:`deform_end_of_step`): begin, end (steps), every
#: (``fix deform N``), xy_style, tilt_start, tilt_stop (m), rate (the style's number), servo_on,
#: y_lo_start, y_hi_start, ly0 (m), kgain = dt gain (1/Pa), gain (1/(Pa s)), target (N/m);
#: x_on (``x erate``), x_lo_start, x_hi_start, x_lo_stop, x_hi_stop (m); y_erate_on (``y erate``),
#: y_lo_stop, y_hi_stop (m); remap_x (``remap x``: positions mapped through lamda at each box
#: change, no velocity jumps; else ``remap v``)
Deform = namedtuple(
    "Deform",
    [
        "begin",
        "end",
        "every",
        "xy_style",
        "tilt_start",
        "tilt_stop",
        "rate",
        "servo_on",
        "y_lo_start",
        "y_hi_start",
        "ly0",
        "kgain",
        "gain",
        "target",
        "x_on",
        "x_lo_start",
        "x_hi_start",
        "x_lo_stop",
        "x_hi_stop",
        "y_erate_on",
        "y_lo_stop",
        "y_hi_stop",
        "remap_x",
    ],
    defaults=(False, 0.0, 0.0, 0.0, 0.0, False, 0.0, 0.0, False),
)
#: the sheared cell's state besides particles and list: box (5,), box_hold (5,) at the last build,
#: hr (3,) h_rate, lam (N, 2), touch (M,) the contact flags of the last force evaluation,
#: corners_hold (8, 2) the box corners at the last build
Cell = namedtuple("Cell", ["box", "box_hold", "hr", "lam", "touch", "corners_hold"])
#: per-step outputs of :func:`run_block`: stress (n, 4), vir (n, 4), box (n, 5), nc (n,), ov (n,), ke (n,)
ShearSeries = namedtuple("ShearSeries", ["stress", "vir", "box", "nc", "ov", "ke"])


# --------------------------------------------------------------------------- box arithmetic
@njit
def x2lamda(x, box, lam):
    """Domain::x2lamda for 2D (h_inv[5] = -xy/(Lx Ly)); the z terms add signed zeros only."""
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    hi0 = 1.0 / h0
    hi1 = 1.0 / h1
    hi5 = -box[4] / (h0 * h1)
    for i in range(x.shape[0]):
        d0 = x[i, 0] - box[0]
        d1 = x[i, 1] - box[1]
        lam[i, 0] = hi0 * d0 + hi5 * d1
        lam[i, 1] = hi1 * d1


@njit
def lamda2x(lam, box, x):
    """Domain::lamda2x for 2D: x = (Lx l0 + xy l1) + lo_x, y = Ly l1 + lo_y."""
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    h5 = box[4]
    for i in range(x.shape[0]):
        x[i, 0] = ((h0 * lam[i, 0] + h5 * lam[i, 1]) + 0.0) + box[0]
        x[i, 1] = (h1 * lam[i, 1] + 0.0) + box[1]


@njit
def pbc_lamda(lam, v, hr, vremap):
    """Domain::pbc in lamda coordinates (period 1): x first, then y; with ``vremap`` a particle
    crossing y changes its velocity by -/+ (h_rate[5], h_rate[1]), crossing x by -/+ h_rate[0].
    Returns a particle still outside [0, 1) after one wrap (lost), or -1."""
    bad = -1
    for i in range(lam.shape[0]):
        if lam[i, 0] < 0.0:
            lam[i, 0] += 1.0
            if vremap:
                v[i, 0] += hr[0]
        if lam[i, 0] >= 1.0:
            lam[i, 0] -= 1.0
            lam[i, 0] = max(lam[i, 0], 0.0)
            if vremap:
                v[i, 0] -= hr[0]
        if lam[i, 1] < 0.0:
            lam[i, 1] += 1.0
            if vremap:
                v[i, 0] += hr[2]
                v[i, 1] += hr[1]
        if lam[i, 1] >= 1.0:
            lam[i, 1] -= 1.0
            lam[i, 1] = max(lam[i, 1], 0.0)
            if vremap:
                v[i, 0] -= hr[2]
                v[i, 1] -= hr[1]
        if bad < 0 and not (0.0 <= lam[i, 0] < 1.0 and 0.0 <= lam[i, 1] < 1.0):
            bad = i
    return bad


@njit
def box_corners(box, out):
    """Domain::lamda_box_corners (8 corners, x fastest, then y, then z) of the 2D box: (8, 2)."""
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    h5 = box[4]
    for c in range(8):
        a = 1.0 if c & 1 else 0.0
        b = 1.0 if c & 2 else 0.0
        out[c, 0] = ((h0 * a + h5 * b) + 0.0) + box[0]
        out[c, 1] = (h1 * b + 0.0) + box[1]


@njit
def corner_deltasq(box, corners_hold, skin, corners):
    """delta^2 (m^2) of LAMMPS' triclinic ``Neighbor::check_distance``: the skin reduced by the
    largest and the 'second' displacement of the 8 box corners since the build (LAMMPS' if /
    else-if, kept as it is), clamped at zero; ``corners`` (8, 2) scratch. Both orderings' rule."""
    box_corners(box, corners)
    d1 = 0.0
    d2 = 0.0
    for c in range(8):
        dx = corners[c, 0] - corners_hold[c, 0]
        dy = corners[c, 1] - corners_hold[c, 1]
        d = math.sqrt(dx * dx + dy * dy + 0.0)
        if d > d1:
            d1 = d
        elif d > d2:
            d2 = d
    delta = max(0.5 * (skin - (d1 + d2)), 0.0)
    return delta * delta


@njit
def check_rebuild_corners(x, xhold, box, corners_hold, skin):
    """Neighbor::check_distance of a triclinic box: the skin is reduced by the largest and the
    'second' displacement of the 8 corners (LAMMPS' if / else-if, kept as it is), trigger
    |x - x_hold|^2 > (0.5 (skin - (d1 + d2)))^2. Returns (rebuild, non-finite particle or -1)."""
    deltasq = corner_deltasq(box, corners_hold, skin, np.empty((8, 2)))
    flag = False
    for i in range(x.shape[0]):
        if not (math.isfinite(x[i, 0]) and math.isfinite(x[i, 1])):
            return True, i
        dx = x[i, 0] - xhold[i, 0]
        dy = x[i, 1] - xhold[i, 1]
        if dx * dx + dy * dy + 0.0 > deltasq:
            flag = True
    return flag, -1


#: xy styles of :func:`deform_end_of_step`: no tilt control, linear between tilt_start and
#: tilt_stop (erate, vel, final, delta), exponential (trate)
XY_NONE, XY_LINEAR, XY_TRATE = 0, 1, 2


@njit
def deform_end_of_step(step, dfm, box, hr, vir, dt):
    """FixDeform::end_of_step (LAMMPS 29 Sep 2021, ``src/fix_deform.cpp``) of the 2D sheared box,
    with the fix's parameters ``dfm`` (:data:`Deform`), at ``step`` with the virial ``vir`` (4,) of
    the step and the time step ``dt`` (s).

    y: ``variable`` (the servo: del = (ly - ly0) + kgain (s_yy - target) ly, lo = lo_start - del/2,
    hi = hi_start + del/2, h_rate[1] = gain (s_yy - target) ly, s_yy the virial stress of this step
    over the area of the current box) or fixed. xy (``xy_style``): XY_LINEAR, tilt_start +
    delta (tilt_stop - tilt_start) with delta = (step - begin)/(end - begin) (erate, vel, final,
    delta; h_rate[5] constant, set by ``init``); XY_TRATE, tilt_start exp(rate (step - begin) dt)
    and h_rate[5] = rate * (the tilt before this call); XY_NONE, the current tilt. Then LAMMPS'
    tilt wrap (add/subtract Lx until the tilt is closest to the current one) and its flip test
    (tilt / Lx beyond -/+0.5, with 1/Lx as a factor). x and y ``erate`` (``x_on``, ``y_erate_on``):
    lo/hi = start + delta (stop - start), as the linear tilt styles; the wrap and the flip test
    then use the new Lx. ``remap_x``: ``hr`` is left alone (no velocity jumps: LAMMPS uses h_rate
    only with ``remap v``; the positions follow the box, :func:`remap_positions`). Updates ``box``
    and ``hr``. Returns False
    when the cell collapsed or LAMMPS would flip the box (not supported). Source: LAMMPS
    ``FixDeform::init`` (lo/hi_stop, h_rate) and ``FixDeform::end_of_step``; docs/shear.md."""
    begin, end, xy_style, tilt_start, tilt_stop, rate = (
        dfm.begin, dfm.end, dfm.xy_style, dfm.tilt_start, dfm.tilt_stop, dfm.rate
    )  # fmt: skip
    servo_on, y_lo_start, y_hi_start, ly0, kgain, gain, target = (
        dfm.servo_on, dfm.y_lo_start, dfm.y_hi_start, dfm.ly0, dfm.kgain, dfm.gain, dfm.target
    )  # fmt: skip
    delta = float(step - begin)
    if delta != 0.0:
        delta /= float(end - begin)
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    h5 = box[4]
    lo0 = box[0]
    hi0 = box[2]
    lo1 = box[1]
    hi1 = box[3]
    remap_x = dfm.remap_x
    if dfm.x_on:
        lo0 = dfm.x_lo_start + delta * (dfm.x_lo_stop - dfm.x_lo_start)
        hi0 = dfm.x_hi_start + delta * (dfm.x_hi_stop - dfm.x_hi_start)
    if dfm.y_erate_on:
        lo1 = y_lo_start + delta * (dfm.y_lo_stop - y_lo_start)
        hi1 = y_hi_start + delta * (dfm.y_hi_stop - y_hi_start)
    elif servo_on:
        syy = vir[1] * (1.0 / (h0 * h1))
        dl = (h1 - ly0) + kgain * (syy - target) * h1
        lo1 = y_lo_start - 0.5 * dl
        hi1 = y_hi_start + 0.5 * dl
        if not remap_x:
            hr[1] = gain * (syy - target) * h1
    if xy_style == XY_LINEAR:
        tt = tilt_start + delta * (tilt_stop - tilt_start)
    elif xy_style == XY_TRATE:
        delt = float(step - begin) * dt
        tt = tilt_start * math.exp(rate * delt)
        if not remap_x:
            hr[2] = rate * h5
    else:
        tt = h5
    denom = hi0 - lo0
    current = h5 / h0
    while tt / denom - current > 0.0:
        tt -= denom
    while tt / denom - current < 0.0:
        tt += denom
    if abs(tt / denom - 1.0 - current) < abs(tt / denom - current):
        tt -= denom
    xprd = hi0 - lo0
    yprd = hi1 - lo1
    if not (yprd > 0.0 and xprd > 0.0):
        return False
    xprdinv = 1.0 / xprd
    if tt * xprdinv < -0.5 or tt * xprdinv > 0.5:
        return False
    box[0] = lo0
    box[2] = hi0
    box[1] = lo1
    box[3] = hi1
    box[4] = tt
    return True


@njit
def remap_positions(x, old, box):
    """``fix deform ... remap x``: every position to lamda in the box ``old`` (5,)
    (``Domain::x2lamda``; the z terms add signed zeros only) and back in the new ``box``
    (``Domain::lamda2x``), in place (N, 2)."""
    h0 = old[2] - old[0]
    h1 = old[3] - old[1]
    i0 = 1.0 / h0
    i1 = 1.0 / h1
    i5 = -old[4] / (h0 * h1)
    n0 = box[2] - box[0]
    n1 = box[3] - box[1]
    n5 = box[4]
    for i in range(x.shape[0]):
        d0 = x[i, 0] - old[0]
        d1 = x[i, 1] - old[1]
        l0 = i0 * d0 + i5 * d1
        l1 = i1 * d1
        x[i, 0] = ((n0 * l0 + n5 * l1) + 0.0) + box[0]
        x[i, 1] = (n1 * l1 + 0.0) + box[1]


# --------------------------------------------------------------------------- neighbour list
#: position of the image (b, s) (:func:`gransim.dem.kernels.tilted_image`)
_image_x = K.tilted_image


@njit
def build_list(x, lam, r, box, skin, use_lam):
    """Half list of LAMMPS ``newton off`` (``npair_half_size_bin_newtoff``) in the sheared cell.

    Entries (a, b, s): owned pairs once (s = 0, b > a, ``both``), every pair across the boundary
    once per owner ((a, b, s) and (b, a, -s), each with its own spring). Kept when |x_a - image|^2
    <= (r_a + r_b + skin)^2, the image as :func:`_image_x` computes it. Candidates from a cell list
    in lamda coordinates (bins at least the cutoff wide in every direction of the sheared cell) or,
    when the cell holds fewer than 3 bins a side, all 9 shifts of every pair. Grouped by a.
    Returns (a, b, sx, sy, both, self_image), self_image >= 0 a particle near its own image.
    """
    n = x.shape[0]
    rmax = 0.0
    for i in range(n):
        rmax = max(rmax, r[i])
    cut = (rmax + rmax) + skin
    h0 = box[2] - box[0]
    h1 = box[3] - box[1]
    h5 = box[4]
    nbx = int(h0 / (cut * (1.0 + abs(h5) / h1)))
    nby = int(h1 / cut)
    binned = nbx >= 3 and nby >= 3
    if not binned:
        nbx = 1
        nby = 1
    head = -np.ones(nbx * nby, np.int64)
    nxt = -np.ones(n, np.int64)
    ibx = np.zeros(n, np.int64)
    iby = np.zeros(n, np.int64)
    for i in range(n - 1, -1, -1):
        if binned:
            ix = min(max(int(lam[i, 0] * nbx), 0), nbx - 1)
            iy = min(max(int(lam[i, 1] * nby), 0), nby - 1)
        else:
            ix = 0
            iy = 0
        ibx[i] = ix
        iby[i] = iy
        c = iy * nbx + ix
        nxt[i] = head[c]
        head[c] = i
    self_image = -1
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
            xa = x[a, 0]
            ya = x[a, 1]
            for dyb in range(-1, 2):
                for dxb in range(-1, 2):
                    if binned:
                        jx = ibx[a] + dxb
                        jy = iby[a] + dyb
                        sxb = 0.0
                        syb = 0.0
                        if jx < 0:
                            jx += nbx
                            sxb = -1.0
                        elif jx >= nbx:
                            jx -= nbx
                            sxb = 1.0
                        if jy < 0:
                            jy += nby
                            syb = -1.0
                        elif jy >= nby:
                            jy -= nby
                            syb = 1.0
                        b = head[jy * nbx + jx]
                    else:
                        sxb = float(dxb)
                        syb = float(dyb)
                        b = head[0]
                    owned = sxb == 0.0 and syb == 0.0
                    while b >= 0:
                        if (not owned) or b > a:
                            xb, yb = _image_x(b, sxb, syb, x, lam, use_lam, box)
                            dx = xa - xb
                            dy = ya - yb
                            rc = (r[a] + r[b]) + skin
                            if dx * dx + dy * dy <= rc * rc:
                                if pass_ == 1:
                                    a_out[m] = a
                                    b_out[m] = b
                                    sx_out[m] = sxb
                                    sy_out[m] = syb
                                    both_out[m] = owned
                                elif a == b and self_image < 0:
                                    self_image = a
                                m += 1
                        b = nxt[b]
    return a_out, b_out, sx_out, sy_out, both_out, self_image


@njit
def hand_over(x, r, box, a_new, b_new, sx_new, sy_new, start_old, eb_old, both_old, h_old, touch_old, lmp, h_new, flip):
    """History hand-over at a list build, for a history of any width W (``h_old`` (M_old, W),
    ``h_new`` (M, W) written; ``flip`` (W,) the sign of each column seen from the other particle).
    ``lmp`` (LAMMPS ``fix neigh/history``, ``pre_exchange_no_newton`` / ``post_neighbor``): a new
    entry (a, b) takes the history of a's old entry with partner b, or ``flip`` times the one of
    an owned old entry (b, a), if that entry touched in the last force evaluation; else zero.
    Otherwise (LIGGGHTS): the same look-up, kept only if the pair overlaps now."""
    nw = h_new.shape[1]
    for e in range(a_new.shape[0]):
        a = a_new[e]
        b = b_new[e]
        for c in range(nw):
            h_new[e, c] = 0.0
        if not lmp:
            xb, yb = _image_x(b, sx_new[e], sy_new[e], x, x, False, box)
            dx = x[a, 0] - xb
            dy = x[a, 1] - yb
            rs = r[a] + r[b]
            if not (dx * dx + dy * dy < rs * rs):
                continue
        k = K._find(start_old, eb_old, a, b)
        if k >= 0:
            if lmp and not touch_old[k]:
                continue
            for c in range(nw):
                h_new[e, c] = h_old[k, c]
        else:
            k = K._find(start_old, eb_old, b, a)
            if k >= 0 and both_old[k]:
                if lmp and not touch_old[k]:
                    continue
                for c in range(nw):
                    h_new[e, c] = flip[c] * h_old[k, c]


# --------------------------------------------------------------------------- forces and steps
@njit
def forces(p, nb, law, cell, use_lam, dt, update, vir):
    """Serial force loop of the sheared cell: :func:`gransim.dem.kernels.forces_in` with the image
    :data:`~gransim.dem.kernels.TiltedImage` of ``cell`` (:data:`Cell`; LAMMPS ``newton off``: an
    owned pair acts on both, a boundary entry on its owner a only; virial 0.5 d (x) f per owner as
    ``ev_tally_xyz``). Image positions by :func:`gransim.dem.kernels.tilted_image` (from lamda
    when ``use_lam``), image velocities v_b + s_x hr[0] + s_y (hr[2], hr[1]) (``pack_comm_vel``
    with ``deform_vremap``), spins copied; ``law`` any registered law (its ``apart``: LAMMPS' laws
    zero the history of an entry that does not touch). ``cell.touch`` (M,) receives the contact
    flags, ``nb.slide``, ``nb.ef`` every evaluation. Returns (contacts, sum of overlaps), each
    physical contact once."""
    img = K.TiltedImage(cell.box, cell.hr, cell.lam, use_lam, cell.touch)
    return K.forces_in(p, nb, law, img, dt, update, vir, True)


@njit
def run_block(p, nb, law, cell, dfm, out, vir, dt, skin, lmp, step0, nsteps, resume):
    """Steps step0+1 .. step0+nsteps of LAMMPS' Verlet (nve/sphere first half, neighbour decision,
    forces, second half, ``fix deform`` end_of_step on the steps with ``step % every == 0``, as
    ``Modify::end_of_step`` calls a fix every ``nevery`` steps) until a list build is needed.

    ``p`` :class:`gransim.dem.kernels.Particles`, ``nb`` :class:`~gransim.dem.kernels.Neighbours`
    (the list and the law's history), ``law`` a registered contact law (each law type compiles
    its own copy), ``cell`` :data:`Cell` (box, h_rate, ... updated in place), ``dfm``
    :data:`Deform`, ``out`` :data:`ShearSeries` (rows >= nsteps), ``vir`` (4,) the virial of the
    last step; dt (s), skin (m); ``lmp`` LAMMPS' bookkeeping (triclinic rebuild check; else
    LIGGGHTS' orthogonal one).

    Returns (steps completed, status, bad particle): status 0 done, 1 rebuild needed (the next
    step has done its first half step; call again with ``resume`` after the build: its forces use
    the image positions from lamda), 2 non-finite position, 3 collapsed cell or tilt beyond half
    the box. Per completed step k: stress (xx, yy, xy, yx; virial / area of the box after the
    step, compression positive), virial (xx, yy, xy, yx; sum 0.5 d (x) f of the step, N m), box
    (lx, ly, xy, ylo, yhi), contacts, mean overlap, kinetic energy.
    """
    x, v, w, f, t, m, r = p.x, p.v, p.w, p.f, p.t, p.m, p.r
    box, box_hold, hr = cell.box, cell.box_hold, cell.hr
    old = np.empty(5)  # the box before a ``remap x`` change
    for k in range(nsteps):
        step = step0 + k + 1
        use_lam = False
        if resume and k == 0:
            use_lam = lmp
        else:
            K.initial_integrate(x, v, w, f, t, m, r, dt)
            if lmp:
                rebuild, bad = check_rebuild_corners(x, nb.xhold, box, cell.corners_hold, skin)
            else:
                rebuild, bad = K.check_rebuild(
                    x, nb.xhold, box[0:2], box[2:4], box_hold[0:2], box_hold[2:4], skin, False
                )
            if bad >= 0:
                return k, 2, bad
            if rebuild:
                return k, 1, -1
        nc, so = forces(p, nb, law, cell, use_lam, dt, True, vir)
        ke = K.final_integrate(v, w, f, t, m, r, dt)
        if step % dfm.every == 0:
            if dfm.remap_x:
                old[:] = box
            ok = deform_end_of_step(step, dfm, box, hr, vir, dt)
            if not ok:
                return k, 3, -1
            if dfm.remap_x:
                remap_positions(x, old, box)
        inv = 1.0 / ((box[2] - box[0]) * (box[3] - box[1]))
        for c in range(4):
            out.stress[k, c] = vir[c] * inv
            out.vir[k, c] = vir[c]
        out.box[k, 0] = box[2] - box[0]
        out.box[k, 1] = box[3] - box[1]
        out.box[k, 2] = box[4]
        out.box[k, 3] = box[1]
        out.box[k, 4] = box[3]
        out.nc[k] = nc
        out.ov[k] = so / nc if nc > 0 else 0.0
        out.ke[k] = ke
    return nsteps, 0, -1
