"""The ``yade`` arithmetic: YADE 2023.02a's periodic DEM iteration, reproduced to the bit.

YADE (an open DEM code written independently of LIGGGHTS and LAMMPS) integrates with a leapfrog of
one kick per step, keeps the mean field of a deforming periodic cell in the velocities, detects
contacts with a periodic insertion-sort collider whose order of creating and erasing interactions
fixes the order in which forces are summed, and stores the shear force of a contact, rotated to
first order. This module runs that iteration natively for 2D disks (spheres with blocked DOFs
``zXY``) with Cundall and Strack's law (:mod:`gransim.contacts.yade_cundall_strack`), on the
loadings of the decks: the biaxial test (each axis fixed, at an engineering rate, or under the
proportional stress servo) and periodic simple shear (``xy erate`` with y fixed or under the servo),
as ``reference_runs/yade/dem_script.py`` drives YADE. The one engine steps it
(``Engine(..., flavour="yade")``, :mod:`gransim.dem.yade_cell`); :func:`yade_run` records every
step of such a run as YADE's script writes them (docs/yade.md, "The native yade arithmetic").

One iteration k (``Scene::moveToNextTimeStep``, core/Scene.cpp:108-127), each step as in YADE's
source (2023.02a, tag of the mirror ``Aoxi-git/Cementor``; file:line):

1. prologue, ``Cell::integrateAndUpdate(dt)`` (core/Cell.cpp:12-42): trsfInc = dt velGrad,
   prevHSize = hSize, vGradTimesPrevH = velGrad prevHSize, hSize += trsfInc hSize, the column norms
   ``size``, the normalised columns, their skew "cosines" and the unshear matrix (Eigen's 3 x 3
   inverse by cofactors, Eigen/src/LU/InverseImpl.h), ``hasShear``;
2. ``ForceResetter``: forces and torques 0;
3. ``InsertionSortCollider`` when ``isActivated`` (pkg/common/InsertionSortCollider.cpp:212-224:
   Newton's ``maxVelocitySq`` >= 1 or == 0): bounds by ``Bo1_Sphere_Aabb`` (pkg/common/Bo1_Aabb.cpp:
   15-40) enlarged by the sweep length of ``BoundDispatcher::processBody`` (core/Dispatching.cpp:
   55-93: verletDist 0.5 r_min, targetInterv 100, minSweepDistFactor 0.1), bound coordinates
   shifted by their period (:435-439), non-real interactions whose boxes no longer overlap erased
   (:484, core/InteractionContainer.hpp:127-137, erase moves the last interaction into the hole,
   core/InteractionContainer.cpp:75-115), then either the initial sort and ``findOverlaps`` along
   x (iteration 0, :541-563, :625-638) or ``insertionSortPeri`` along x, y, z (:660-734), each
   inversion of a lower past an upper bound creating the interaction when the boxes overlap
   (``handleBoundInversionPeri`` :737-756, ``spatialOverlapPeri`` :768-819, which also gives its
   ``cellDist``); new interactions are appended (core/InteractionContainer.cpp:17-44);
4. ``InteractionLoop`` over the container in its order (core/InteractionLoop.cpp:81-190) with
   shift2 = hSize cellDist: :func:`gransim.contacts.yade_cundall_strack.scgeom_cundall_strack`; the
   forces accumulate per body in that order (with -j1 one thread: core/ForceContainerParallel.cpp:
   73-78, sync 161-184 adds them to 0);
5. the script's ``PyRunner``: ``utils.getStress()`` (preprocessing/dem/Shop_02.cpp:395-424: sum in
   container order of (F_n + F_s) (x) ((x_1 - x_2) - hSize cellDist), divided by det(hSize) =
   h00 (h11 z) by Eigen's 3 x 3 determinant) and the loading's velGrad in the script's Python
   arithmetic, given to ``Cell.velGrad`` (kept in ``nextVelGrad``, core/Cell.hpp:138-142);
6. ``NewtonIntegrator(damping=0)`` (pkg/dem/NewtonIntegrator.cpp:137-337): velGrad = nextVelGrad
   (:149-153), dVelGrad = velGrad - prevVelGrad, dSpin = (0, 0, -0.5 (dVelGrad_01 - dVelGrad_10))
   (:155-157); maxVelocitySq from the change of the cell's size (:162-168); per body: a = f/m
   (:58-61; Cundall's damping with damping 0 multiplies by exactly 1, :31-35), a += prevVelGrad v
   (:262), v += dt a (:264), w += dt (t/I) (:267-270), v += dVelGrad x (:320-323), x += dt v
   (:324), w += dSpin (:329); the displacement flag for the collider (:118-135); prevCellSize,
   prevVelGrad (:307-310).

The frame written for step k is the state the ``PyRunner`` sees: positions x_k, velocities v_(k-1/2)
(the mean field included), spins, forces and torques of step k, the cell of step k, the stress and
the velGrad set at step k, and the real interactions in YADE's container order.

Why the plane arithmetic is YADE's to the bit: see :mod:`gransim.contacts.yade_cundall_strack`
(z components exactly 0, so no three-term Eigen sum has three non-zero terms; no FMA in Debian's
build; ``pow(x, 2)`` is ``x * x``). The initial sort of the bounds is
libstdc++'s ``std::sort`` (introsort, not stable: equal bound coordinates of different bodies keep
the order it leaves them in, which later decides the order in which interactions are created);
its heap-sort branch, taken past a recursion depth of 2 log2(2N) (met on the z axis of disks
that all lie in one plane z != 0, where most bounds tie), is ported too. Not reproduced:
``Cell.flipFlippable``, clumps, damping in :func:`yade_run` (:func:`rve_run` has it),
several threads.

Arrays: positions, velocities (N, 2) m, m/s; spins (N,) rad/s along z; cell (2, 2) lattice
vectors as columns (m) plus the z size ``z`` of YADE's 3D cell (m).
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np

from .._numba import njit
from ..contacts.yade_cundall_strack import (
    ERASED,
    FORCE,
    NO_CONTACT,
    scgeom_cundall_strack,
    spheres_touch,
)
from ..errors import InputError, SimulationError
from ..geometry import Packing
from .settings import DEMSettings, Loading
from .sheared import ShearLoading

#: InsertionSortCollider defaults (pkg/common/InsertionSortCollider.hpp:267-274)
VERLET_FACTOR = 0.5  # verletDist = -0.5: 0.5 r_min (InsertionSortCollider.cpp:365-378)
TARGET_INTERV = 100.0
MIN_SWEEP_DIST_FACTOR = 0.1
OVERLAP_TOLERANCE = 1e-7

# error codes of the kernels
_OK, _TOO_BIG, _FULL, _TIE = 0, 1, 2, 3

# loading modes of an axis (reference_runs/yade/dem_script.py, axis_rate)
_FIXED, _RATE, _SERVO = 0, 1, 2


def yade_cell_z(radii) -> float:
    """z size of YADE's 3D cell for a disk assembly (m): the smallest power of two above
    4 r_max + 2 r_min. YADE stops ("Body larger than half of the cell size") when a bound's extent
    in z, 2 (r + verletDist) with the collider's default verletDist = 0.5 r_min, reaches half the
    cell; a power of two keeps z and its divisions exact. ``radii``: (N,) array (m)."""
    r = np.asarray(radii, dtype=float)
    need = 4.0 * float(np.max(r)) + 2.0 * float(np.min(r))
    z = float(2.0 ** math.ceil(math.log2(need)))
    return z if z > need else 2.0 * z


# ----------------------------------------------------------------------------------------------
# the cell


@njit
def _cell_update(H, z, L, dt, prevH, VP, size, U, cos):
    """Cell::integrateAndUpdate(dt) (core/Cell.cpp:12-42) on the 2 x 2 block of hSize (z fixed).

    Returns hasShear. H, prevH, VP (vGradTimesPrevH), U (unshear matrix) are (2, 2); size, cos (3,)."""
    T00 = dt * L[0, 0]  # :12 _trsfInc = dt * velGrad
    T01 = dt * L[0, 1]
    T10 = dt * L[1, 0]
    T11 = dt * L[1, 1]
    for i in range(2):  # :17 prevHSize = hSize
        for j in range(2):
            prevH[i, j] = H[i, j]
    for j in range(2):  # :18 velGrad * prevHSize (the z terms are exact zeros)
        VP[0, j] = L[0, 0] * prevH[0, j] + L[0, 1] * prevH[1, j]
        VP[1, j] = L[1, 0] * prevH[0, j] + L[1, 1] * prevH[1, j]
    for j in range(2):  # :19 hSize += _trsfInc * hSize (the product evaluated first)
        a = T00 * prevH[0, j] + T01 * prevH[1, j]
        b = T10 * prevH[0, j] + T11 * prevH[1, j]
        H[0, j] = prevH[0, j] + a
        H[1, j] = prevH[1, j] + b
    # :23-30 column norms and normalised columns (base /= size)
    size[0] = math.sqrt(H[0, 0] * H[0, 0] + H[1, 0] * H[1, 0])
    size[1] = math.sqrt(H[0, 1] * H[0, 1] + H[1, 1] * H[1, 1])
    size[2] = math.sqrt(z * z)
    a = H[0, 0] / size[0]
    c = H[1, 0] / size[0]
    b = H[0, 1] / size[1]
    d = H[1, 1] / size[1]
    # :32-36 _cos[i] = (Hnorm.col(i1) x Hnorm.col(i2)).squaredNorm(), Hnorm(2, 2) = z / |z| = 1
    cos[0] = d * d + b * b
    cos[1] = c * c + a * a
    e = a * d - c * b
    cos[2] = e * e
    # :40 _unshearTrsf = Hnorm.inverse(): Eigen's cofactors, det = (d e) a + (-(e b)) c with e = 1
    invdet = 1.0 / (d * a + (-b) * c)
    U[0, 0] = d * invdet
    U[0, 1] = (-b) * invdet
    U[1, 0] = (-c) * invdet
    U[1, 1] = a * invdet
    return H[0, 1] != 0.0 or H[1, 0] != 0.0  # :42 _hasShear


# ----------------------------------------------------------------------------------------------
# the interaction container
#
# The container's and the collider's small helpers are inlined (numba IR inlining: the same
# operations): a call to a compiled function that takes arrays increments and decrements each
# array's reference count, and _handle_inversion's 13 arrays made the first collider run of an
# RVE call (findOverlaps, ~8000 candidate pairs of 400 disks) 1.2 ms of a 3.6 ms call
# (bench/femxdem.py).


@njit(inline="always")
def _insert(id1, id2, cd0, cd1, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs):
    """InteractionContainer::insert (core/InteractionContainer.cpp:17-44): appended at the end."""
    n = n_intr[0]
    if n >= i_id.shape[0]:
        return _FULL
    i_id[n, 0] = id1
    i_id[n, 1] = id2
    i_cd[n, 0] = cd0
    i_cd[n, 1] = cd1
    i_real[n] = False
    for q in range(i_geom.shape[1]):
        i_geom[n, q] = 0.0
    i_fs[n, 0] = 0.0
    i_fs[n, 1] = 0.0
    slot[id1, id2] = n
    n_intr[0] = n + 1
    return _OK


@njit(inline="always")
def _erase(pos, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs):
    """InteractionContainer::erase (core/InteractionContainer.cpp:75-115): the last interaction
    moves into the hole."""
    slot[i_id[pos, 0], i_id[pos, 1]] = -1
    last = n_intr[0] - 1
    if pos < last:
        i_id[pos, 0] = i_id[last, 0]
        i_id[pos, 1] = i_id[last, 1]
        i_cd[pos, 0] = i_cd[last, 0]
        i_cd[pos, 1] = i_cd[last, 1]
        i_real[pos] = i_real[last]
        for q in range(i_geom.shape[1]):
            i_geom[pos, q] = i_geom[last, q]
        i_fs[pos, 0] = i_fs[last, 0]
        i_fs[pos, 1] = i_fs[last, 1]
        slot[i_id[pos, 0], i_id[pos, 1]] = pos
    n_intr[0] = last


# ----------------------------------------------------------------------------------------------
# the collider


@njit(inline="always")
def _overlap_peri(id1, id2, minima, maxima, inv_sizes, periods):
    """InsertionSortCollider::spatialOverlapPeri (InsertionSortCollider.cpp:768-819): (overlap,
    error); ``periods`` (3,) receives the cellDist of body 2."""
    for axis in range(3):
        lmin = (minima[id2, axis] - maxima[id1, axis]) * inv_sizes[axis]
        lmax = (maxima[id2, axis] - maxima[id1, axis]) * inv_sizes[axis]
        shifted_min = (minima[id1, axis] - maxima[id1, axis]) * inv_sizes[axis] + 1.0
        if (lmax - lmin) > 0.5 or shifted_min < 0.0:  # :791-801 a body spans half the cell
            return False, _TOO_BIG
        period1 = math.floor(lmax)
        if (lmin - period1) <= OVERLAP_TOLERANCE:  # :806
            periods[axis] = -int(period1)
            continue
        if (lmax - period1 + OVERLAP_TOLERANCE) >= shifted_min:  # :811
            periods[axis] = -int(period1) - 1
            continue
        return False, _OK
    return True, _OK


@njit(inline="always")
def _handle_inversion(id1, id2, minima, maxima, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs, periods):
    """InsertionSortCollider::handleBoundInversionPeri (:737-756), id1 < id2; ``periods`` (3,) int:
    scratch (an allocation per candidate pair cost a third of the first collider run of an RVE call)."""
    if slot[id1, id2] >= 0:  # :740 found
        return _OK
    overlap, err = _overlap_peri(id1, id2, minima, maxima, inv_sizes, periods)
    if err != _OK:
        return err
    if overlap:
        return _insert(id1, id2, periods[0], periods[1], slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs)
    return _OK


@njit(inline="always")
def _norm(i, size):
    """VecBounds::norm (InsertionSortCollider.hpp:137-144). The index is nearly always in
    [0, size) already: returned without the integer division (one per bound visited, a third of
    the first collider run of an RVE call)."""
    if i < 0:
        i += size
    if i < size:
        return i
    return i % size


@njit
def _sort_peri(
    ax, bc, bi, bp, bm, lo_idx, dim, minima, maxima, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs,
    periods,
):  # fmt: skip
    """InsertionSortCollider::insertionSortPeri (:660-734) on axis ``ax`` of the bound arrays
    (coordinate bc, body bi, period bp, isMin bm, each (3, 2N)); returns an error code. ``periods``:
    the scratch of :func:`_handle_inversion`."""
    size = bc.shape[1]
    lo = lo_idx[ax]
    _i = 0
    while _i < size or bc[ax, _norm(_i, size)] < bc[ax, _norm(_i - 1, size)]:
        i = _norm(_i, size)
        i_1 = _norm(i - 1, size)
        if i == lo and bc[ax, i] < 0.0:  # :677-681
            bp[ax, i] -= 1
            bc[ax, i] += dim
            lo = _norm(lo + 1, size)
        icmp = bc[ax, i] + (dim if i == lo else 0.0)  # :685
        if bc[ax, i_1] <= icmp:  # :687
            _i += 1
            continue
        j = i_1
        vc, vid, vp, vmin = bc[ax, i], bi[ax, i], bp[ax, i], bm[ax, i]
        while j < _i and bc[ax, j] > (vc + (dim if _norm(j + 1, size) == lo else 0.0)):  # :696
            j1 = _norm(j + 1, size)
            bc[ax, j1], bi[ax, j1], bp[ax, j1], bm[ax, j1] = bc[ax, j], bi[ax, j], bp[ax, j], bm[ax, j]  # :707
            if j == lo and vc < 0.0:  # :709-717
                vp -= 1
                vc += dim
                lo = _norm(lo + 1, size)
            elif j1 == lo:
                bp[ax, j1] += 1
                bc[ax, j1] -= dim
                lo = _norm(lo - 1, size)
            if vmin and not bm[ax, j] and vid != bi[ax, j1]:  # :718-723
                a, b = (vid, bi[ax, j1]) if vid < bi[ax, j1] else (bi[ax, j1], vid)
                err = _handle_inversion(
                    a, b, minima, maxima, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs, periods
                )
                if err != _OK:
                    lo_idx[ax] = lo
                    return err
            j = _norm(j - 1, size)
        k = _norm(j + 1, size)  # :726
        bc[ax, k], bi[ax, k], bp[ax, k], bm[ax, k] = vc, vid, vp, vmin
        _i += 1
    i = _norm(lo - 1, size)  # :729-733 keep coordinates in [0, cellDim]
    while bc[ax, i] > dim:
        bp[ax, i] += 1
        bc[ax, i] -= dim
        lo = i
        i = _norm(i - 1, size)
    lo_idx[ax] = lo
    return _OK


@njit(inline="always")
def _less(u, v, c, ids, ismin):
    """Bounds::operator< (InsertionSortCollider.hpp:100-105)."""
    if ids[u] == ids[v] and c[u] == c[v]:
        return ismin[u]
    return c[u] < c[v]


@njit(inline="always")
def _linear_insert(order, last, c, ids, ismin):
    """std::__unguarded_linear_insert (libstdc++ bits/stl_algo.h)."""
    val = order[last]
    nxt = last - 1
    while _less(val, order[nxt], c, ids, ismin):
        order[last] = order[nxt]
        last = nxt
        nxt -= 1
    order[last] = val


@njit
def _insertion_sort(order, first, last, c, ids, ismin):
    """std::__insertion_sort."""
    for i in range(first + 1, last):
        if _less(order[i], order[first], c, ids, ismin):
            val = order[i]
            for k in range(i, first, -1):
                order[k] = order[k - 1]
            order[first] = val
        else:
            _linear_insert(order, i, c, ids, ismin)


@njit
def _adjust_heap(order, first, hole, n, value, c, ids, ismin):
    """std::__adjust_heap then std::__push_heap (libstdc++ 12, bits/stl_heap.h) on order[first:first+n]."""
    top = hole
    child = hole
    while child < (n - 1) // 2:
        child = 2 * (child + 1)
        if _less(order[first + child], order[first + child - 1], c, ids, ismin):
            child -= 1
        order[first + hole] = order[first + child]
        hole = child
    if (n & 1) == 0 and child == (n - 2) // 2:
        child = 2 * (child + 1)
        order[first + hole] = order[first + child - 1]
        hole = child - 1
    parent = (hole - 1) // 2
    while hole > top and _less(order[first + parent], value, c, ids, ismin):
        order[first + hole] = order[first + parent]
        hole = parent
        parent = (hole - 1) // 2
    order[first + hole] = value


@njit
def _heap_sort(order, first, last, c, ids, ismin):
    """std::__partial_sort(first, last, last) of libstdc++ 12: __make_heap (__heap_select with
    middle == last), then __sort_heap (each __pop_heap moves the top to the end)."""
    n = last - first
    if n >= 2:
        parent = (n - 2) // 2
        while True:
            _adjust_heap(order, first, parent, n, order[first + parent], c, ids, ismin)
            if parent == 0:
                break
            parent -= 1
    end = last
    while end - first > 1:
        end -= 1
        value = order[end]
        order[end] = order[first]
        _adjust_heap(order, first, 0, end - first, value, c, ids, ismin)


@njit
def _std_sort(order, c, ids, ismin):
    """libstdc++'s std::sort (GCC 12, bits/stl_algo.h: __introsort_loop with the median of three
    moved to the front and the unguarded partition, threshold 16, then __final_insertion_sort) of the
    permutation ``order`` by Bounds::operator<, so that equal bounds of different bodies end in the
    order YADE's sort leaves them; past the depth limit 2 log2(n) a range is heap-sorted
    (std::__partial_sort), as libstdc++ does. Returns True."""
    n = order.shape[0]
    if n == 0:
        return True
    depth = 2 * int(math.floor(math.log2(n)))  # std::__lg(n) * 2
    stack = np.empty((n + 1, 3), np.int64)  # (first, last, depth) of the recursion
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, n, depth
    top = 1
    while top > 0:
        top -= 1
        first, last, dl = stack[top, 0], stack[top, 1], stack[top, 2]
        while last - first > 16:
            if dl == 0:  # std::__partial_sort(first, last, last): heap sort of the range
                _heap_sort(order, first, last, c, ids, ismin)
                break
            dl -= 1
            # __move_median_to_first(first, first + 1, mid, last - 1)
            mid = first + (last - first) // 2
            a, b, cc = first + 1, mid, last - 1
            if _less(order[a], order[b], c, ids, ismin):
                if _less(order[b], order[cc], c, ids, ismin):
                    pick = b
                elif _less(order[a], order[cc], c, ids, ismin):
                    pick = cc
                else:
                    pick = a
            elif _less(order[a], order[cc], c, ids, ismin):
                pick = a
            elif _less(order[b], order[cc], c, ids, ismin):
                pick = cc
            else:
                pick = b
            order[first], order[pick] = order[pick], order[first]
            # __unguarded_partition(first + 1, last, first)
            lo, hi = first + 1, last
            while True:
                while _less(order[lo], order[first], c, ids, ismin):
                    lo += 1
                hi -= 1
                while _less(order[first], order[hi], c, ids, ismin):
                    hi -= 1
                if not lo < hi:
                    break
                order[lo], order[hi] = order[hi], order[lo]
                lo += 1
            # __introsort_loop(cut, last, depth) recurses, then last = cut: the two ranges are disjoint,
            # so the order in which they are sorted does not matter
            stack[top, 0], stack[top, 1], stack[top, 2] = lo, last, dl
            top += 1
            last = lo
    # __final_insertion_sort
    if n > 16:
        _insertion_sort(order, 0, 16, c, ids, ismin)
        for i in range(16, n):
            _linear_insert(order, i, c, ids, ismin)
    else:
        _insertion_sort(order, 0, n, c, ids, ismin)
    return True


@njit
def _collide(
    it, init, pos, radius, has_shear, U, cos, size, verlet, ref_pos, sweep, last_update,
    aabb_min, aabb_max, bc, bi, bp, bm, lo_idx, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs, zc,
):  # fmt: skip
    """InsertionSortCollider::action (InsertionSortCollider.cpp:226-568), periodic, one thread.

    ``init``: the initial sort (first run: the bounds lists are empty). ``zc``: the unsheared z of
    the disks' centres (0 for disks at z = 0; Bo1_Aabb.cpp:38-39). Returns (error, axis)."""
    n = pos.shape[0]
    inv_sizes = np.empty(3)
    for a in range(3):
        inv_sizes[a] = 1.0 / size[a]  # :362
    # BoundDispatcher::action -> processBody (core/Dispatching.cpp:55-93), Bo1_Sphere_Aabb::go
    hs = np.empty(3)
    for b in range(n):
        r = radius[b]
        hs[0] = r  # Bo1_Aabb.cpp:20: (aabbEnlargeFactor > 0 ? f : 1.) * r
        hs[1] = r
        hs[2] = r
        if has_shear:  # :27-36
            for i in range(3):
                i1 = (i + 1) % 3
                i2 = (i + 2) % 3
                hs[i1] += 0.5 * r * (1.0 / cos[i] - 1.0)
                hs[i2] += 0.5 * r * (1.0 / cos[i] - 1.0)
        ux = U[0, 0] * pos[b, 0] + U[0, 1] * pos[b, 1]  # :38-39 unshearPt(position)
        uy = U[1, 0] * pos[b, 0] + U[1, 1] * pos[b, 1]
        aabb_min[b, 0] = ux - hs[0]
        aabb_min[b, 1] = uy - hs[1]
        aabb_min[b, 2] = zc - hs[2]
        aabb_max[b, 0] = ux + hs[0]
        aabb_max[b, 1] = uy + hs[1]
        aabb_max[b, 2] = zc + hs[2]
        # Dispatching.cpp:70-80 (targetInterv > 0)
        if it > last_update[b]:
            dist = max(abs(pos[b, 0] - ref_pos[b, 0]), max(abs(pos[b, 1] - ref_pos[b, 1]), 0.0))
            if dist != 0.0:
                new_len = dist * TARGET_INTERV / float(it - last_update[b])
                new_len = max(0.9 * sweep[b], new_len)
                sweep[b] = max(MIN_SWEEP_DIST_FACTOR * verlet, min(new_len, verlet))
            else:
                sweep[b] = 0.0
        else:
            sweep[b] = verlet
        ref_pos[b, 0] = pos[b, 0]  # :86-87
        ref_pos[b, 1] = pos[b, 1]
        last_update[b] = it
        s = sweep[b]
        if s > 0.0:  # :88-92
            for a in range(3):
                aabb_min[b, a] -= s
                aabb_max[b, a] += s
    # :423-481 bound coordinates, shifted by their period (wrapped into the cell on the initial sort)
    m = bc.shape[1]
    for a in range(3):
        dim = size[a]
        for k in range(m):
            b = bi[a, k]
            x = (aabb_min[b, a] if bm[a, k] else aabb_max[b, a]) - dim * float(bp[a, k])
            if init:  # :439 cellWrap(coord, 0, cellDim, period) (:643-648)
                xn = (x - 0.0) / (dim - 0.0)
                p = math.floor(xn)
                bp[a, k] = int(p)
                x = 0.0 + (xn - p) * (dim - 0.0)
            bc[a, k] = x
    # :484 conditionalyEraseNonReal (core/InteractionContainer.hpp:130-137), one thread
    periods = np.zeros(3, np.int64)
    q = 0
    while q < n_intr[0]:
        if not i_real[q]:
            overlap, err = _overlap_peri(i_id[q, 0], i_id[q, 1], aabb_min, aabb_max, inv_sizes, periods)
            if err != _OK:
                return err, -1
            if not overlap:
                _erase(q, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs)
                continue
        q += 1
    if not init:  # :506-508
        for a in range(3):
            err = _sort_peri(
                a, bc, bi, bp, bm, lo_idx, size[a], aabb_min, aabb_max, inv_sizes, slot, n_intr, i_id, i_cd, i_real,
                i_geom, i_fs, periods,
            )  # fmt: skip
            if err != _OK:
                return err, a
        return _OK, -1
    # :546-549 the initial sort (VecBounds::sort: std::sort with Bounds::operator<), loIdx = 0
    for a in range(3):
        lo_idx[a] = 0
        order = np.arange(m)
        if not _std_sort(order, bc[a], bi[a], bm[a]):
            return _TIE, a
        c2, i2, p2, m2 = bc[a][order], bi[a][order], bp[a][order], bm[a][order]
        for k in range(m):
            bc[a, k], bi[a, k], bp[a, k], bm[a, k] = c2[k], i2[k], p2[k], m2[k]
    # :625-638 findOverlaps along x (sortAxis 0), periodic: handleBoundInversionPeri on each pair met.
    # Most pairs met are neither in the container nor overlapping, and for those it does nothing:
    # they are filtered here (the same tests, without side effects), and the others are handed to
    # it in the order met (:func:`_insert_pairs`), which gives the same container: a pair met twice
    # is found the second time, as in YADE, and an error is raised at the same pair.
    pairs = np.empty((256, 2), np.int64)
    count = 0
    for k in range(m):
        if not bm[0, k]:
            continue
        iid = bi[0, k]
        j = _norm(k + 1, m)
        while bi[0, j] != iid:
            if bm[0, j]:
                jid = bi[0, j]
                a, b = (iid, jid) if iid < jid else (jid, iid)
                if slot[a, b] < 0:
                    overlap, err = _overlap_peri(a, b, aabb_min, aabb_max, inv_sizes, periods)
                    if overlap or err != _OK:
                        pairs[count, 0] = a
                        pairs[count, 1] = b
                        count += 1
                        if count == pairs.shape[0] or err != _OK:
                            err = _insert_pairs(
                                pairs, count, aabb_min, aabb_max, inv_sizes, slot, n_intr, i_id, i_cd, i_real,
                                i_geom, i_fs, periods,
                            )  # fmt: skip
                            count = 0
                            if err != _OK:
                                return err, 0
            j = _norm(j + 1, m)
    err = _insert_pairs(
        pairs, count, aabb_min, aabb_max, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs, periods
    )
    if err != _OK:
        return err, 0
    return _OK, -1


@njit
def _insert_pairs(pairs, count, minima, maxima, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs, periods):
    """:func:`_handle_inversion` on the first ``count`` pairs (id1 < id2) of ``pairs`` (K, 2), in
    order, up to the first error (returned)."""
    for p in range(count):
        err = _handle_inversion(
            pairs[p, 0], pairs[p, 1], minima, maxima, inv_sizes, slot, n_intr, i_id, i_cd, i_real, i_geom, i_fs,
            periods,
        )  # fmt: skip
        if err != _OK:
            return err
    return _OK


# ----------------------------------------------------------------------------------------------
# interaction loop, stress, integrator


@njit
def _interactions(
    pos, vel, spin, radius, H, VP, kn_c, ks_c, tan_c, young, poisson, dt, agr, n_intr, i_id, i_cd, i_real, i_geom,
    i_fs, force, torque,
):  # fmt: skip
    """ForceResetter, then InteractionLoop::action (core/InteractionLoop.cpp:81-190) in container
    order, with :func:`gransim.contacts.yade_cundall_strack.scgeom_cundall_strack` (``agr``: its
    ``avoidGranularRatcheting``). i_geom rows: (n_x, n_y, penetrationDepth, F_n,x, F_n,y, kn, ks,
    tan phi).

    Stiffnesses: with ``young`` = 0 the constants ``kn_c``, ``ks_c``, ``tan_c`` of
    ``MatchMaker(algo='val')`` (the decks of :func:`yade_run`); with ``young`` > 0 Guo & Zhao's
    radius-dependent ones, made by ``Ip2_FrictMat_FrictMat_FrictPhys`` when an interaction becomes
    real (pkg/dem/FrictPhys.cpp:13-44: kn = 2 (E r_1)(E r_2)/(E r_1 + E r_2), ks the same with
    (E r_i) nu, ``tan_c`` the tan of the material's friction angle; one material, so
    min(phi_1, phi_2) = phi; Ra = refR1 = r_1, Rb = r_2: ScGeom.hpp:108) and kept in i_geom.

    A non-real interaction whose spheres do not touch is skipped before its stiffnesses are made
    (:func:`~gransim.contacts.yade_cundall_strack.spheres_touch`, the test the law starts with):
    YADE makes them only for a new geometry (InteractionLoop.cpp:160-168), and the skipped ones
    are most of the non-real entries of a step."""
    force[:] = 0.0
    torque[:] = 0.0
    # the cell's matrices as scalars: read once, not once per interaction (a store into the
    # container or the forces might alias them for the compiler)
    h00, h01, h10, h11 = H[0, 0], H[0, 1], H[1, 0], H[1, 1]
    v00, v01, v10, v11 = VP[0, 0], VP[0, 1], VP[1, 0], VP[1, 1]
    for q in range(n_intr[0]):
        b1 = i_id[q, 0]
        b2 = i_id[q, 1]
        c0 = float(i_cd[q, 0])
        c1 = float(i_cd[q, 1])
        sx = h00 * c0 + h01 * c1  # :145 shift2 = cellHsize * cellDist
        sy = h10 * c0 + h11 * c1
        real = i_real[q]
        if real:
            if young > 0.0:
                kn = i_geom[q, 5]
                ks = i_geom[q, 6]
                tp = i_geom[q, 7]
            else:
                kn = kn_c
                ks = ks_c
                tp = tan_c
        else:
            if not spheres_touch(pos[b1, 0], pos[b1, 1], pos[b2, 0], pos[b2, 1], sx, sy, radius[b1], radius[b2]):
                continue
            if young > 0.0:
                kna = young * radius[b1]
                knb = young * radius[b2]
                ksa = kna * poisson
                ksb = knb * poisson
                kn = 2 * kna * knb / (kna + knb)
                ks = 2 * ksa * ksb / (ksa + ksb)
            else:
                kn = kn_c
                ks = ks_c
            tp = tan_c
        svx = v00 * c0 + v01 * c1  # Cell::intrShiftVel (core/Cell.hpp:119)
        svy = v10 * c0 + v11 * c1
        st, nx, ny, pen, fnx, fny, fsx, fsy, fx, fy, t1, t2 = scgeom_cundall_strack(
            real, pos[b1, 0], pos[b1, 1], pos[b2, 0], pos[b2, 1], sx, sy, radius[b1], radius[b2],
            vel[b1, 0], vel[b1, 1], spin[b1], vel[b2, 0], vel[b2, 1], spin[b2], svx, svy,
            i_geom[q, 0], i_geom[q, 1], i_fs[q, 0], i_fs[q, 1], kn, ks, tp, dt, agr,
        )  # fmt: skip
        if st == NO_CONTACT:
            continue
        if st == ERASED:  # requestErase: Interaction::reset (core/Interaction.cpp:34-42)
            i_real[q] = False
            i_fs[q, 0] = 0.0
            i_fs[q, 1] = 0.0
            continue
        i_real[q] = True
        i_geom[q, 0] = nx
        i_geom[q, 1] = ny
        i_geom[q, 2] = pen
        i_geom[q, 3] = fnx
        i_geom[q, 4] = fny
        i_geom[q, 5] = kn
        i_geom[q, 6] = ks
        i_geom[q, 7] = tp
        i_fs[q, 0] = fsx
        i_fs[q, 1] = fsy
        force[b1, 0] += fx  # ElasticContactLaw.cpp:109-112
        force[b1, 1] += fy
        force[b2, 0] += -fx
        force[b2, 1] += -fy
        torque[b1] += t1
        torque[b2] += t2
    return FORCE


@njit
def _stress(pos, H, z, n_intr, i_id, i_cd, i_real, i_geom, i_fs, out):
    """z utils.getStress() (preprocessing/dem/Shop_02.cpp:395-424) as the script forms it, (2, 2) N/m."""
    s00 = 0.0
    s01 = 0.0
    s10 = 0.0
    s11 = 0.0
    for q in range(n_intr[0]):
        if not i_real[q]:
            continue
        b1 = i_id[q, 0]
        b2 = i_id[q, 1]
        c0 = float(i_cd[q, 0])
        c1 = float(i_cd[q, 1])
        bx = pos[b1, 0] - pos[b2, 0]  # :419-420
        by = pos[b1, 1] - pos[b2, 1]
        bx -= H[0, 0] * c0 + H[0, 1] * c1
        by -= H[1, 0] * c0 + H[1, 1] * c1
        fx = i_geom[q, 3] + i_fs[q, 0]  # :421
        fy = i_geom[q, 4] + i_fs[q, 1]
        s00 += fx * bx
        s01 += fx * by
        s10 += fy * bx
        s11 += fy * by
    vol = H[0, 0] * (H[1, 1] * z) - H[1, 0] * (H[0, 1] * z)  # Eigen's bruteforce 3 x 3 determinant
    out[0, 0] = z * (s00 / vol)
    out[0, 1] = z * (s01 / vol)
    out[1, 0] = z * (s10 / vol)
    out[1, 1] = z * (s11 / vol)


# ----------------------------------------------------------------------------------------------
# the driver


@dataclass(frozen=True, eq=False)
class YadeRun:
    """Steps 0..n of a native run in YADE's arithmetic, as YADE's script writes them.

    Attributes
    ----------
    step : (T,) steps. cell : (T, 2, 2) hSize (lattice vectors as columns, m). stress : (T, 2, 2)
    z getStress() (N/m, tension positive, not symmetrised). vel_grad : (T, 2, 2) velGrad set at
    the step (1/s). n_contacts : (T,). positions, velocities, forces : (T, N, 2) (velocity
    v_(k-1/2), mean field included); spins, torques : (T, N). contacts : list of T tuples (ids
    (M, 2), cell_dist (M, 2), normal_force (M, 2), shear_force (M, 2), penetration (M,)), the real
    interactions in YADE's container order. mass, inertia : (N,). z : YADE's cell z size (m).
    """

    step: np.ndarray
    cell: np.ndarray
    stress: np.ndarray
    vel_grad: np.ndarray
    n_contacts: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    forces: np.ndarray
    torques: np.ndarray
    contacts: list
    mass: np.ndarray
    inertia: np.ndarray
    z: float


def yade_run(
    packing: Packing, settings: DEMSettings, loading, nsteps: int, velocities=None, spins=None, z=None
) -> YadeRun:
    """Run ``nsteps`` steps in YADE's arithmetic and return every step 0..nsteps (:class:`YadeRun`):
    the one engine with ``flavour="yade"`` (:mod:`gransim.dem.yade_cell`), one step at a time.

    Parameters
    ----------
    packing : the disks (positions as YADE gets them: the YADE job wraps them into the cell, so give
        the same wrapped packing), radii, orthogonal cell, density (kg/m^2; m = density pi r^2,
        I = m r^2 / 2 in the script's Python arithmetic).
    settings : kn, kt (N/m), mu, dt (s); gamma_n = gamma_t = 0 (YADE's runs are undamped).
    loading : :class:`gransim.dem.Loading` (fixed / rate / servo per axis) or
        :class:`gransim.dem.sheared.ShearLoading` (``xy erate``, every 1, y fixed or servo).
    velocities, spins : initial (N, 2), (N,) (default 0). z : YADE's cell z size (default
        :func:`yade_cell_z`).
    """
    from .engine import Engine  # noqa: PLC0415 - cycle: engine -> yade_cell -> yade_arithmetic

    nsteps = int(nsteps)
    if nsteps < 0:
        raise InputError(f"nsteps: expected an integer >= 0, got {nsteps}")
    if not isinstance(loading, (Loading, ShearLoading)):
        raise InputError(f"loading: expected a gransim.dem.Loading or ShearLoading, got {type(loading).__name__}")
    cell = "sheared" if isinstance(loading, ShearLoading) else "orthogonal"
    eng = Engine(
        packing, settings, velocities, spins, check_dt=False, cell=cell, flavour="yade",
        cell_options=None if z is None else {"z": float(z)},
    )  # fmt: skip
    control = eng.cell_ops.control(eng, loading)  # the script's control(): the velGrad of each frame below
    if nsteps:
        eng.start_run(loading, nsteps)
    yb, yc, yq = eng.yb, eng.yc, eng.yq
    n = packing.n
    T = nsteps + 1
    out_cell = np.zeros((T, 2, 2))
    out_stress = np.zeros((T, 2, 2))
    out_grad = np.zeros((T, 2, 2))
    out_nc = np.zeros(T, np.int64)
    out_pos = np.zeros((T, n, 2))
    out_vel = np.zeros((T, n, 2))
    out_spin = np.zeros((T, n))
    out_force = np.zeros((T, n, 2))
    out_torque = np.zeros((T, n))
    contacts = []
    for k in range(T):
        if k:
            eng.advance(1)
        real = np.flatnonzero(yq.i_real[: yq.n_intr[0]])
        out_cell[k] = yc.H
        out_stress[k] = yc.sig
        out_grad[k] = eng.cell_ops.vel_grad(eng, control)  # the script's control() of the frame
        out_nc[k] = len(real)
        out_pos[k] = yb.pos
        out_vel[k] = yb.vel
        out_spin[k] = yb.spin
        out_force[k] = yb.force
        out_torque[k] = yb.torque
        contacts.append(
            (yq.i_id[real].copy(), yq.i_cd[real].copy(), yq.i_geom[real, 3:5].copy(), yq.i_fs[real].copy(),
             yq.i_geom[real, 2].copy())
        )  # fmt: skip
    return YadeRun(
        np.arange(T), out_cell, out_stress, out_grad, out_nc, out_pos, out_vel, out_spin, out_force, out_torque,
        contacts, yb.mass.copy(), yb.inertia.copy(), eng.cell_ops.z,
    )  # fmt: skip


# ----------------------------------------------------------------------------------------------
# Guo & Zhao's RVE: radius-dependent stiffness, Cundall's non-viscous damping, a saved scene


@njit
def _sign(x):
    """math::sign (lib/high-precision/MathFunctions.hpp:284): (0 < x) - (x < 0)."""
    return float((0.0 < x) - (x < 0.0))


@njit
def _newton_damped(
    pos, vel, spin, mass, inertia, force, torque, L, nextL, changed, Lprev, size, prev_size, dt, dt2, ref_pos, sweep,
    damping,
):  # fmt: skip
    """NewtonIntegrator::action (pkg/dem/NewtonIntegrator.cpp:137-312), no gravity, blocked DOFs
    zXY, spherical bodies, with Cundall's non-viscous damping ``damping`` (0 in the decks: the
    multiplier is then exactly 1, :31-35) (cundallDamp2nd, :30-34: a_i *= 1 - damping sign(a_i (v_i + dt/2 a_i)), on
    the fluctuation velocity v - prevVelGrad x (Cell.hpp:121, NewtonIntegrator.cpp:208) for the
    translation (:226) and on the spin for the rotation (:240)); ``changed`` (1,) is the cell's
    velGradChanged. Returns maxVelocitySq."""
    if changed[0] or nextL[0, 0] != 0.0 or nextL[0, 1] != 0.0 or nextL[1, 0] != 0.0 or nextL[1, 1] != 0.0:
        for i in range(2):  # :149-153 velGrad = nextVelGrad, nextVelGrad = 0
            for j in range(2):
                L[i, j] = nextL[i, j]
                nextL[i, j] = 0.0
        changed[0] = False
    d00 = L[0, 0] - Lprev[0, 0]
    d01 = L[0, 1] - Lprev[0, 1]
    d10 = L[1, 0] - Lprev[1, 0]
    d11 = L[1, 1] - Lprev[1, 1]
    dspin = -(0.5 * (d01 - d10))
    if (prev_size[0] != size[0] or prev_size[1] != size[1] or prev_size[2] != size[2]) and not math.isnan(prev_size[0]):
        e0 = prev_size[0] - size[0]
        e1 = prev_size[1] - size[1]
        e2 = prev_size[2] - size[2]
        max_v2 = (e0 * e0 + e1 * e1 + e2 * e2) / dt2
    else:
        max_v2 = 0.0
    h = 0.5 * dt
    p00, p01, p10, p11 = Lprev[0, 0], Lprev[0, 1], Lprev[1, 0], Lprev[1, 1]  # read once (as in _interactions)
    for b in range(pos.shape[0]):
        ax = force[b, 0] / mass[b]
        ay = force[b, 1] / mass[b]
        if damping != 0.0:
            fvx = vel[b, 0] - (p00 * pos[b, 0] + p01 * pos[b, 1])  # bodyFluctuationVel
            fvy = vel[b, 1] - (p10 * pos[b, 0] + p11 * pos[b, 1])
            ax *= 1.0 - damping * _sign(ax * (fvx + h * ax))
            ay *= 1.0 - damping * _sign(ay * (fvy + h * ay))
        ax += p00 * vel[b, 0] + p01 * vel[b, 1]
        ay += p10 * vel[b, 0] + p11 * vel[b, 1]
        vel[b, 0] += dt * ax
        vel[b, 1] += dt * ay
        aw = torque[b] / inertia[b]
        if damping != 0.0:
            aw *= 1.0 - damping * _sign(aw * (spin[b] + h * aw))
        spin[b] += dt * aw
        vel[b, 0] += d00 * pos[b, 0] + d01 * pos[b, 1]
        vel[b, 1] += d10 * pos[b, 0] + d11 * pos[b, 1]
        pos[b, 0] += vel[b, 0] * dt
        pos[b, 1] += vel[b, 1] * dt
        spin[b] += dspin
        md = max(abs(pos[b, 0] - ref_pos[b, 0]), max(abs(pos[b, 1] - ref_pos[b, 1]), 0.0))
        flag = 0.5 if (md == 0.0 or md < sweep[b]) else 2.0
        max_v2 = max(max_v2, flag)
    for i in range(3):
        prev_size[i] = size[i]
    for i in range(2):
        for j in range(2):
            Lprev[i, j] = L[i, j]
    return max_v2


@njit(inline="always")
def _unsheared_z(H, size, z_pos):
    """unshearPt(position).z = _unshearTrsf(2, 2) z (Eigen's 3 x 3 inverse: cofactor(2, 2) invdet)."""
    a = H[0, 0] / size[0]
    c = H[1, 0] / size[0]
    b = H[0, 1] / size[1]
    d = H[1, 1] / size[1]
    return ((a * d - b * c) * (1.0 / (d * a + (-b) * c))) * z_pos


@dataclass(frozen=True, eq=False)
class YadeRVEState:
    """A periodic 2D disk RVE as YADE serialises its scene (``Omega.sceneToString``), reduced to what
    the next run reads; Guo & Zhao's ``simDEM`` carries exactly this between calls.

    What a saved scene keeps and the native run needs (core/*.hpp attributes, 2023.02a): the
    iteration and dt (Scene.hpp:98-99); per disk position, velocity (v_(k-1/2), mean field
    included), spin, mass, inertia, radius, and its bound's refPos, sweepLength, lastUpdateIter
    (Bound.hpp:28-31); the cell's hSize, velGrad, nextVelGrad, velGradChanged (Cell.hpp:232-239);
    NewtonIntegrator's prevVelGrad and prevCellSize (NewtonIntegrator.hpp:77, 81) and damping; the
    collider's verletDist (InsertionSortCollider.hpp:273); the material (young, poisson,
    frictionAngle); the real interactions in container order (only those are saved,
    InteractionContainer.cpp:174-181) with cellDist, normal, penetrationDepth, kn, ks,
    tangensOfFrictionAngle, normalForce, shearForce. Not saved, hence rebuilt by every run: the
    collider's bound lists (its first run sorts them), the forces, and the penetration depth (NaN in
    a deserialised scene; recomputed before it is read).

    Arrays: radii, mass, inertia, spins, sweep (N,); positions, velocities, bound_ref (N, 2) m,
    m/s; last_update (N,) int; hsize, vel_grad, next_vel_grad, newton_prev_vel_grad (2, 2) (cell
    vectors as columns, m; 1/s); prev_cell_size (3,) m; interactions: ids, cell_dist (M, 2) int,
    normal, normal_force, shear_force (M, 2) (forces on body 2, N), kn, ks, tan_phi (M,).
    ``z``: the cell's z size (m); ``z_pos``: the disks' z (m).
    """

    iteration: int
    dt: float
    z: float
    z_pos: float
    radii: np.ndarray
    mass: np.ndarray
    inertia: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    spins: np.ndarray
    bound_ref: np.ndarray
    sweep: np.ndarray
    last_update: np.ndarray
    hsize: np.ndarray
    vel_grad: np.ndarray
    next_vel_grad: np.ndarray
    vel_grad_changed: bool
    newton_prev_vel_grad: np.ndarray
    prev_cell_size: np.ndarray
    verlet: float
    damping: float
    young: float
    poisson: float
    friction_angle: float
    ids: np.ndarray
    cell_dist: np.ndarray
    normal: np.ndarray
    kn: np.ndarray
    ks: np.ndarray
    tan_phi: np.ndarray
    normal_force: np.ndarray
    shear_force: np.ndarray

    @property
    def n(self) -> int:
        """Number of disks."""
        return len(self.radii)


#: arrays of :class:`YadeRVEState`, in field order (checkpoints: :func:`pack_rve_states`)
RVE_STATE_FIELDS = tuple(f for f in YadeRVEState.__dataclass_fields__)


def n_steps_of(D) -> int:
    """simDEM.shear2D's number of steps for the strain increment D (2, 2):
    int(max(1e5 max|D|, 2)) in numpy's and Python's arithmetic (simDEM.py:57)."""
    d = np.asarray(D, dtype=float).reshape(4)
    return int(max(1e5 * np.max(np.abs(d.tolist())), 2))


def rve_run(state: YadeRVEState, D) -> YadeRVEState:
    """One call of Guo & Zhao's ``simDEM.shear2D`` (simDEM.py:53-62) in YADE's arithmetic, from the
    deserialised ``state`` (never modified): velGrad = D / (ns dt) set through ``Cell.velGrad``
    (kept in nextVelGrad, Cell.hpp:138-142), ns = :func:`n_steps_of` iterations, then velGrad = 0
    set the same way; returns the state the serialised scene then holds.

    As in YADE, the first iteration's cell update uses the velGrad the scene was saved with (the
    previous call's rate, or the consolidation's last one): a call moves the cell by one step of
    the old rate and ns - 1 steps of D / (ns dt). ``D``: (2, 2) strain increment (Guo & Zhao's
    grad u; f - 1 of a load step). The disks' rotations: :func:`rve_run_rotation`."""
    return rve_run_rotation(state, D)[0]


def rve_run_rotation(state: YadeRVEState, D, rotation=None):
    """:func:`rve_run` that also turns the disks: ``(new state, rotation (N,) rad)``, where each
    disk's ``rotation`` (counter-clockwise; default 0, never modified) receives spin dt at every
    step, with the spin that step ends with (after NewtonIntegrator's dSpin), in step order: the
    angle by which YADE's ``State::ori`` turns (leapfrogSphericalRotate, NewtonIntegrator.cpp:
    327-337), summed in double precision instead of composed as quaternions (docs/femxdem.md, "The
    disk rotation"). Every other output is :func:`rve_run`'s, to the bit: the sum is read by
    nothing else.

    The call runs on the one engine (:mod:`gransim.dem.yade_cell`, the sheared yade cell): the
    calling thread's engine loaded with ``state`` (its set-up: step 0's cell update, the
    collider's first run and the interaction loop, none of which reads D), then
    ``start_run(VelGradRun(D / (ns dt)), ns)`` and ``advance(ns)``, and the scene it saves. For a
    ``state`` whose arrays are all read-only (the committed states of
    :mod:`gransim.fem.material_points`) the set-up is kept as long as the state lives
    (``_FIRST_RUNS``) and restored by the next calls from it, the Newton iterates of a load step.
    Raises InputError for a D that is not finite or a rotation of another shape, SimulationError
    naming the call and its step when the RVE diverges (a position not finite, a kinetic-energy
    blow-up), a bound spans over half of the cell (YADE throws there too) or the interaction
    container is full."""
    from .yade_cell import VelGradRun, rve_engine  # noqa: PLC0415 - cycle: yade_cell -> yade_arithmetic

    D = np.asarray(D, dtype=float).reshape(2, 2)
    if not np.all(np.isfinite(D)):
        raise InputError(f"D: the strain increment must be finite, got {D.tolist()}")
    ns = n_steps_of(D)
    n = state.n
    theta = None if rotation is None else np.asarray(rotation, float)
    if theta is not None and theta.shape != (n,):
        raise InputError(f"rotation: one angle per disk ({n},) expected, got shape {theta.shape}")
    it0 = int(state.iteration)
    try:
        with rve_engine(state, theta) as eng:
            eng.start_run(VelGradRun(D / (ns * state.dt)), ns)  # Matrix3 / float in minieigen: each entry
            eng.advance(ns)
            return eng.cell_ops.scene(eng), eng.yb.theta.copy()
    except SimulationError as exc:
        raise SimulationError(f"the RVE call from iteration {it0} ({ns} steps): {exc}") from None


#: the set-up of a read-only saved scene (gransim.dem.yade_cell): {YadeRVEState: kept}, dropped
#: with the state
_FIRST_RUNS = weakref.WeakKeyDictionary()


@njit
def _stress_tangent(pos, H, z, ids, cd, normal, fn, fs, kn, ks, stress, tangent):
    """Shop::getStressAndTangent (preprocessing/dem/Shop_02.cpp:1000-1098) in the plane: the sum
    over the real interactions in container order of (F_n + F_s) (x) branch and of the contact
    stiffness terms, each divided by det(hSize) (the 3D volume, z included). ``tangent`` (3, 3):
    YADE's Voigt entries (0, 0), (0, 1), (0, 5), (1, 1), (1, 5), (5, 5) at [0, 0], [0, 1],
    [0, 2], [1, 1], [1, 2], [2, 2] (upper triangle; tensor shear components)."""
    s00 = 0.0
    s01 = 0.0
    s10 = 0.0
    s11 = 0.0
    t00 = 0.0
    t01 = 0.0
    t05 = 0.0
    t11 = 0.0
    t15 = 0.0
    t55 = 0.0
    for q in range(ids.shape[0]):
        b1 = ids[q, 0]
        b2 = ids[q, 1]
        c0 = float(cd[q, 0])
        c1 = float(cd[q, 1])
        bx = pos[b1, 0] - pos[b2, 0]  # :1021-1022
        by = pos[b1, 1] - pos[b2, 1]
        bx -= H[0, 0] * c0 + H[0, 1] * c1
        by -= H[1, 0] * c0 + H[1, 1] * c1
        kN = kn[q]
        kT = ks[q]
        nx = normal[q, 0]
        ny = normal[q, 1]
        T = math.sqrt(fs[q, 0] * fs[q, 0] + fs[q, 1] * fs[q, 1])  # :1030-1034
        tx = 0.0
        ty = 0.0
        if T > 0:
            tx = fs[q, 0] / T
            ty = fs[q, 1] / T
        fx = fn[q, 0] + fs[q, 0]
        fy = fn[q, 1] + fs[q, 1]
        s00 += fx * bx  # :1035
        s01 += fx * by
        s10 += fy * bx
        s11 += fy * by
        t00 += kN * nx * bx * nx * bx + kT * tx * bx * tx * bx  # :1036
        t01 += kN * nx * bx * ny * by + kT * tx * bx * ty * by  # :1037
        t05 += kN * nx * bx * (nx * by + ny * bx) * 0.5 + kT * tx * bx * (tx * by + ty * bx) * 0.5  # :1044-1045
        t11 += kN * ny * by * ny * by + kT * ty * by * ty * by  # :1046
        t15 += kN * ny * by * (nx * by + ny * bx) * 0.5 + kT * ty * by * (tx * by + ty * bx) * 0.5  # :1053-1054
        t55 += (
            kN * (nx * by * nx * by + nx * by * ny * bx * 2 + ny * bx * ny * bx) * 0.25
            + kT * (tx * by * tx * by + tx * by * ty * bx * 2 + ty * bx * ty * bx) * 0.25
        )  # :1086-1088
    vol = H[0, 0] * (H[1, 1] * z) - H[1, 0] * (H[0, 1] * z)
    stress[0, 0] = s00 / vol
    stress[0, 1] = s01 / vol
    stress[1, 0] = s10 / vol
    stress[1, 1] = s11 / vol
    tangent[0, 0] = t00 / vol
    tangent[0, 1] = t01 / vol
    tangent[0, 2] = t05 / vol
    tangent[1, 1] = t11 / vol
    tangent[1, 2] = t15 / vol
    tangent[2, 2] = t55 / vol


def rve_stress_tangent(state: YadeRVEState):
    """(stress (2, 2), tangent (3, 3)) of ``utils.getStressAndTangent()`` on the scene ``state``
    (:func:`_stress_tangent`): Pa, per unit volume of YADE's 3D cell (det hSize, z included: the
    2D stress in N/m divided by z), tension positive, not symmetrised; the forces are those of the
    last interaction loop and the branch vectors from the positions after the last move, as YADE
    holds them in a saved scene."""
    s = state
    stress = np.zeros((2, 2))
    tangent = np.zeros((3, 3))
    _stress_tangent(
        np.asarray(s.positions, float), np.asarray(s.hsize, float), float(s.z), s.ids, s.cell_dist,
        np.asarray(s.normal, float), np.asarray(s.normal_force, float), np.asarray(s.shear_force, float),
        np.asarray(s.kn, float), np.asarray(s.ks, float), stress, tangent,
    )  # fmt: skip
    return stress, tangent


def guo_zhao_stress_tangent(state: YadeRVEState):
    """simDEM.getStressAndTangent2D (simDEM.py:137-149): the stress symmetrised, 0.5 (s + s^T), and
    the 2D fourth-order tangent t[i, j, k, l] from YADE's Voigt entries (0, 0), (0, 1), (0, 5),
    (1, 1), (1, 5), (5, 5), with every minor symmetry; Pa. ``(sigma (2, 2), t (2, 2, 2, 2))``."""
    s, v = rve_stress_tangent(state)
    sym = 0.5 * (s + s.T)
    t = np.zeros((2, 2, 2, 2))
    t[0, 0, 0, 0] = v[0, 0]
    t[1, 1, 0, 0] = t[0, 0, 1, 1] = v[0, 1]
    t[0, 1, 0, 0] = t[0, 0, 0, 1] = t[1, 0, 0, 0] = t[0, 0, 1, 0] = v[0, 2]
    t[1, 1, 1, 1] = v[1, 1]
    t[1, 1, 0, 1] = t[0, 1, 1, 1] = t[1, 1, 1, 0] = t[1, 0, 1, 1] = v[1, 2]
    t[0, 1, 0, 1] = t[0, 1, 1, 0] = t[1, 0, 0, 1] = t[1, 0, 1, 0] = v[2, 2]
    return sym, t


__all__ = [
    "RVE_STATE_FIELDS",
    "YadeRVEState",
    "YadeRun",
    "guo_zhao_stress_tangent",
    "n_steps_of",
    "rve_run",
    "rve_run_rotation",
    "rve_stress_tangent",
    "yade_cell_z",
    "yade_run",
]
