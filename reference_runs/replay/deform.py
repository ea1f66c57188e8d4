"""Box of an orthogonal periodic cell at every step under ``fix deform``, in each code's arithmetic.

Both LIGGGHTS-PUBLIC 3.8.0 (``src/fix_deform.cpp``, ``FixDeform::init`` and ``end_of_step``) and
LAMMPS 29 Sep 2021 (``src/fix_deform.cpp``, same two functions; the public snapshot read for this
has the same arithmetic for the x/y/z styles) compute the box of step n as follows:

* ``init`` (every ``run``): ``lo_start``/``hi_start`` = the box now; ``delt = (endstep -
  beginstep) * dt`` (a ``bigint`` difference converted to double, times dt); the stop values

  - ``final lo hi``: ``lo_stop = lo``, ``hi_stop = hi``;
  - ``delta dlo dhi``: ``lo_stop = lo_start + dlo``, ``hi_stop = hi_start + dhi``;
  - ``scale s``: ``lo_stop = 0.5*(lo_start+hi_start) - 0.5*s*(hi_start-lo_start)`` (hi: +);
  - ``vel v``: ``lo_stop = lo_start - 0.5*delt*v``, ``hi_stop = hi_start + 0.5*delt*v``;
  - ``erate r``: ``lo_stop = lo_start - 0.5*delt*r*(hi_start-lo_start)`` (hi: +);

* ``end_of_step`` (only on steps with ``ntimestep % N == 0``, N the fix's ``every``):
  ``delta = ntimestep - beginstep`` (double), ``delta /= endstep - beginstep`` when non-zero;

  - ``trate r``: ``delt = (ntimestep - beginstep)*dt``; ``lo = 0.5*(lo_start+hi_start) -
    0.5*((hi_start-lo_start)*exp(r*delt))`` (hi: +), with the C library's ``exp``
    (Python's :func:`math.exp` calls the same libm; numpy's vectorised exp may differ);
  - every other style: ``lo = lo_start + delta*(lo_stop - lo_start)`` (hi alike).

The one difference between the codes for these styles: the default ``units`` of ``fix deform``
is ``box`` in LIGGGHTS and ``lattice`` in LAMMPS, where ``final``, ``delta`` and ``vel`` are
multiplied by the lattice spacing, 1.0 for the default ``lattice none 1.0`` (the subset refuses
the ``lattice`` command), an exact multiplication. Rounding happens at every operation above in
this order; the functions below perform the same double operations in the same order, so the
boxes are bit for bit those of the codes (tests/replay/test_replay_deform.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gransim.errors import InputError

#: styles of one axis and their number of numeric parameters
STYLES = {"final": 2, "delta": 2, "scale": 1, "vel": 1, "erate": 1, "trate": 1}
#: styles of the xy tilt (one number each); trate is read and refused (see deck.py)
TILT_STYLES = ("final", "delta", "vel", "erate", "trate")


@dataclass(frozen=True)
class AxisDeform:
    """``fix deform`` setting of one axis: ``style`` (a key of :data:`STYLES`) and its numbers
    (m for final/delta, m/s for vel, 1/s for erate/trate, dimensionless for scale)."""

    style: str
    params: tuple

    def __post_init__(self):
        if self.style not in STYLES:
            raise InputError(f"fix deform style: expected one of {', '.join(STYLES)}, got {self.style!r}")
        if len(self.params) != STYLES[self.style]:
            raise InputError(
                f"fix deform {self.style}: expected {STYLES[self.style]} number(s), got {len(self.params)}"
            )
        object.__setattr__(self, "params", tuple(float(p) for p in self.params))


@dataclass(frozen=True)
class DeformSpec:
    """One ``fix deform`` of an orthogonal box.

    Attributes
    ----------
    every : N, the fix's period in steps (the box changes on steps that are multiples of N).
    axes : (x, y) AxisDeform or None (axis not controlled).
    remap : "x" (affine remap of the positions) or "v" (a sheared LAMMPS deck: Lees-Edwards).
    units : "box" or "lattice" (lattice spacing 1.0).
    line : 1-based line of the command in the deck.
    tilt : None or (style, value) of ``xy`` (a key of :data:`TILT_STYLES`; m, m/s or 1/s).
    """

    every: int
    axes: tuple
    remap: str = "x"
    units: str = "box"
    line: int = 0
    tilt: tuple | None = None


def tilt_stop(style: str, value: float, tilt_start: float, ly_start: float, delt: float) -> float:
    """``tilt_stop`` of ``xy STYLE value`` in LAMMPS' ``FixDeform::init`` (same double operations in
    the same order; lattice spacing 1.0): final: value; delta: start + value; vel: start +
    delt*value; erate: start + delt*value*(yhi_start - ylo_start). ``trate`` has no linear stop."""
    if style == "final":
        return value * 1.0
    if style == "delta":
        return tilt_start + value * 1.0
    if style == "vel":
        return tilt_start + delt * (value * 1.0)
    if style == "erate":
        return tilt_start + delt * value * ly_start
    raise InputError(f"fix deform xy {style}: no linear tilt_stop (supported: final, delta, vel, erate)")


def _stop(ax: AxisDeform, lo_start: float, hi_start: float, delt: float, scale: float):
    s, p = ax.style, ax.params
    if s == "final":
        return p[0] * scale, p[1] * scale
    if s == "delta":
        return lo_start + p[0] * scale, hi_start + p[1] * scale
    if s == "scale":
        return (
            0.5 * (lo_start + hi_start) - 0.5 * p[0] * (hi_start - lo_start),
            0.5 * (lo_start + hi_start) + 0.5 * p[0] * (hi_start - lo_start),
        )
    if s == "vel":
        v = p[0] * scale
        return lo_start - 0.5 * delt * v, hi_start + 0.5 * delt * v
    if s == "erate":
        r = p[0]
        lo = lo_start - 0.5 * delt * r * (hi_start - lo_start)
        hi = hi_start + 0.5 * delt * r * (hi_start - lo_start)
        if hi <= lo:
            raise InputError(
                "fix deform erate: the final box dimension would be < 0 "
                "(the codes stop with 'Final box dimension due to fix deform is < 0.0')"
            )
        return lo, hi
    return None, None  # trate: computed per step


def box_table(spec: DeformSpec | None, lo0, hi0, dt: float, nsteps: int, engine: str = "liggghts", first_step: int = 0):
    """Box (lo, hi) of x and y after every step of one ``run nsteps``.

    Parameters
    ----------
    spec : the fix deform (None: fixed box).
    lo0, hi0 : (2,) box at the start of the run (m).
    dt : time step (s). nsteps : the run's length. first_step : the time step at the start.
    engine : "liggghts" or "lammps" (units default and lattice scale; see module docstring).

    Returns
    -------
    (lo, hi), each (nsteps + 1, 2) float64: row k is the box after step first_step + k
    (row 0 the start).
    """
    if engine not in ("liggghts", "lammps"):
        raise InputError(f"engine: expected 'liggghts' or 'lammps', got {engine!r}")
    nsteps = int(nsteps)
    lo = np.empty((nsteps + 1, 2))
    hi = np.empty((nsteps + 1, 2))
    lo[0] = [float(lo0[0]), float(lo0[1])]
    hi[0] = [float(hi0[0]), float(hi0[1])]
    if spec is None:
        lo[1:] = lo[0]
        hi[1:] = hi[0]
        return lo, hi
    # units lattice: final/delta/vel times the lattice spacing (1.0 for `lattice none 1.0`)
    scale = 1.0
    begin, end = int(first_step), int(first_step) + nsteps
    delt = float(end - begin) * dt
    starts = [(float(lo[0, d]), float(hi[0, d])) for d in range(2)]
    stops = [(_stop(ax, *starts[d], delt, scale) if ax is not None else (None, None)) for d, ax in enumerate(spec.axes)]
    cur_lo = [float(lo[0, 0]), float(lo[0, 1])]
    cur_hi = [float(hi[0, 0]), float(hi[0, 1])]
    every = int(spec.every)
    for k in range(1, nsteps + 1):
        step = begin + k
        if step % every == 0:
            delta = float(step - begin)
            if delta != 0.0:
                delta /= float(end - begin)
            for d, ax in enumerate(spec.axes):
                if ax is None:
                    continue
                ls, hs = starts[d]
                if ax.style == "trate":
                    t = float(step - begin) * dt
                    e = math.exp(ax.params[0] * t)
                    cur_lo[d] = 0.5 * (ls + hs) - 0.5 * ((hs - ls) * e)
                    cur_hi[d] = 0.5 * (ls + hs) + 0.5 * ((hs - ls) * e)
                else:
                    lstop, hstop = stops[d]
                    cur_lo[d] = ls + delta * (lstop - ls)
                    cur_hi[d] = hs + delta * (hstop - hs)
        lo[k] = cur_lo
        hi[k] = cur_hi
    return lo, hi
