"""Thermo columns of a replayed deck, evaluated natively in each code's arithmetic.

What ``thermo_style custom`` prints, from the native state of the step (:class:`~reference_runs.
replay.drive.State`), with the same double operations in the same order as the codes, so that a
bit-for-bit native run prints the same bits:

* ``compute ID all temp`` (``ComputeTemp::compute_scalar``, both codes): t = sum over the atoms in
  file order of (vx vx + vy vy + vz vz) m (vz = 0), times tfactor = mvv2e / (dof boltz) with
  dof = 2 N - 2 (``dof_compute``: dimension N minus ``extra_dof`` = dimension) and mvv2e = 1 in
  ``units si``; the vector (``compute_vector``) sums m vx vx, m vy vy, 0, m vx vy, 0, 0.
* Boltzmann's constant of ``units si``: 1.3806504e-23 J/K in both codes (LIGGGHTS 3.8.0
  update.cpp, ``"si"``; LAMMPS 29 Sep 2021 prints temperatures that need this value, not the 2019
  SI value 1.380649e-23: with that one the printed ``temp`` was off by 1.0e-6 relative).
* ``ke``: LAMMPS ``Thermo::compute_ke`` = temperature (thermo_temp) times 0.5 dof boltz;
  LIGGGHTS 3.8.0 ``compute ke`` (compute_ke.cpp: sum of m (vx vx + vy vy + vz vz), times 0.5).
* ``compute ID all pressure TEMP [ke] [pair|virial]`` (``ComputePressure``, 2D): scalar
  (dof boltz t + W_xx + W_yy) / 2 / (Lx Ly), components (K_ab + W_ab) / (Lx Ly), with the kinetic
  part K (the temperature compute's vector) only with ``ke`` or no keyword, the virial W only
  with ``pair``, ``virial`` or no keyword; nktv2p = 1. LAMMPS' ``press pxx pyy pxy`` are
  ``compute thermo_press all pressure thermo_temp`` (kinetic and virial); ``pe`` is 0 (granular
  pairs tally no energy) and ``etotal`` = pe + ke.
* ``vol`` = Lx Ly (2D), ``time`` (:func:`elapsed_time`), ``dt``, ``atoms`` = N, the box keywords.

Timings (``cpu``, ``elapsed`` ...) and ``v_NAME`` are printed by the codes and not compared.
"""

from __future__ import annotations

import re

import numpy as np

#: Boltzmann's constant of ``units si`` (J/K) in each code
BOLTZ = {"liggghts": 1.3806504e-23, "lammps": 1.3806504e-23}


def _dof(n: int) -> float:
    """``ComputeTemp::dof_compute`` in 2D: dimension N - extra_dof (= dimension)."""
    return 2.0 * float(n) - (2.0 + 0.0)


def temperature_sums(v: np.ndarray, m: np.ndarray):
    """(t, tensor): t = sum (vx vx + vy vy) m in file order (left to right, as the codes' loop), and
    the (6,) kinetic tensor sums m vx vx, m vy vy, 0, m vx vy, 0, 0 (kg m^2/s^2)."""
    t = 0.0
    k0 = k1 = k3 = 0.0
    for (vx, vy), mi in zip(v.tolist(), m.tolist()):
        t += (vx * vx + vy * vy + 0.0 * 0.0) * mi
        k0 += mi * vx * vx
        k1 += mi * vy * vy
        k3 += mi * vx * vy
    return t, np.array([k0, k1, 0.0, k3, 0.0, 0.0])


class Kinetics:
    """Temperature, kinetic energy and kinetic tensor of one state in ``engine``'s arithmetic."""

    def __init__(self, v: np.ndarray, m: np.ndarray, engine: str):
        self.boltz = BOLTZ[engine]
        self.engine = engine
        self.dof = _dof(m.size)
        tfactor = 1.0 / (self.dof * self.boltz) if self.dof > 0.0 else 0.0
        tsum, self.tensor = temperature_sums(v, m)
        self.tsum = tsum
        self.temp = tsum * tfactor

    @property
    def ke(self) -> float:
        if self.engine == "lammps":
            return self.temp * (0.5 * self.dof * self.boltz)
        # LIGGGHTS compute ke: the same products m (vx vx + vy vy + vz vz), summed, times 0.5 mvv2e
        return self.tsum * 0.5

    def pressure(self, virial, lo, hi, keflag: bool, virflag: bool):
        """(scalar, (6,) components) of ``compute pressure`` (compression positive, N/m)."""
        inv = 1.0 / ((hi[0] - lo[0]) * (hi[1] - lo[1]))
        w = [virial[0], virial[1], 0.0, virial[2], 0.0, 0.0] if virflag else [0.0] * 6
        if keflag:
            scalar = (self.dof * self.boltz * self.temp + w[0] + w[1]) / 2.0 * inv * 1.0
            comp = [(self.tensor[k] + w[k]) * inv * 1.0 for k in range(6)]
        else:
            scalar = (w[0] + w[1]) / 2.0 * inv * 1.0
            comp = [w[k] * inv * 1.0 for k in range(6)]
        comp[2] = comp[4] = comp[5] = 0.0
        return scalar, np.array(comp)


def elapsed_time(deck, step: int) -> float:
    """``time`` of ``step`` (s): ``Update::get_cur_time`` = atime + (step - atimestep) dt, where
    each run's end adds (end - start) dt to atime (``Verlet::cleanup`` -> ``update_time``) and
    its ``init`` sets atimestep to its first step (update.h, update.cpp, integrate.cpp of both
    codes): the sum over the earlier runs, not step dt."""
    dt = deck.settings.dt
    atime = 0.0
    for run in deck.runs:
        if run.start <= step <= run.end:
            return atime + float(step - run.start) * dt
        atime += float(run.end - run.start) * dt
    raise ValueError(f"step {step} lies in no run of the deck")


_C = re.compile(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?")
_PRESS = {"press": None, "pxx": 0, "pyy": 1, "pzz": 2, "pxy": 3, "pxz": 4, "pyz": 5}


def thermo_value(kw: str, deck, state, masses) -> float | None:
    """The native value of thermo keyword ``kw`` at ``state`` (None: printed, not compared).

    ``deck`` gives the engine, the computes and dt; ``masses`` (N,) in file order (kg).
    """
    low = kw.lower()
    lo, hi = state.lo, state.hi
    if low == "step":
        return float(state.step)
    if low == "atoms":
        return float(masses.size)
    if low == "dt":
        return deck.settings.dt
    if low == "time":
        return elapsed_time(deck, state.step)
    if low == "vol":
        return (hi[0] - lo[0]) * (hi[1] - lo[1])
    box = {"lx": hi[0] - lo[0], "ly": hi[1] - lo[1], "xlo": lo[0], "xhi": hi[0], "ylo": lo[1], "yhi": hi[1]}
    if low in box:
        return float(box[low])
    if low in ("xy", "xz", "yz"):
        return float(state.xy) if low == "xy" else 0.0
    if low == "pe":
        return 0.0
    m = _C.fullmatch(kw)
    kin = Kinetics(state.v if state.v is not None else np.zeros((masses.size, 2)), masses, deck.engine)
    if low in ("ke", "etotal"):
        return kin.ke + 0.0 if low == "etotal" else kin.ke
    if low == "temp":
        return kin.temp
    if low in _PRESS:
        scalar, comp = kin.pressure(state.virial, lo, hi, True, True)
        return scalar if _PRESS[low] is None else float(comp[_PRESS[low]])
    if m and m.group(1) in deck.computes:
        c = deck.computes[m.group(1)]
        k = int(m.group(3)) if m.group(3) else None
        if c.style == "temp":
            return kin.temp if k is None else float(kin.tensor[k - 1] * 1.0)
        if c.style == "pressure":
            if c.keflag and state.v is None:
                raise ValueError(f"thermo {kw} at step {state.step}: the native state was not kept")
            scalar, comp = kin.pressure(state.virial, lo, hi, c.keflag, c.virial)
            return scalar if k is None else float(comp[k - 1])
    return None
