"""Energy balance of the DEM engines with a Hertz law: kinetic energy
plus the law's registered elastic energy (:func:`gransim.contacts.hertz.hertz_energy`, with the
radii of every contact) of a periodic assembly of 36 disks (a jittered square lattice with gaps
of 5 % of a diameter and random velocities: collisions across the periodic boundary, list
rebuilds).

* Undamped and frictionless: velocity Verlet (nve/sphere) conserves the energy to O(dt^2); the
  largest relative deviation over 2 ms (40 samples) falls by 4 when dt is halved (measured on
  dt = 4e-7, 2e-7, 1e-7 s: deviations 2.0e-7, 5.0e-8, 1.2e-8 and rates 2.01, 2.02 orthogonal;
  2.0e-7, 4.8e-8, 1.2e-8 and 2.02, 1.99 sheared; accepted 1.8..2.2). The contacts store up to
  35 % (25 %) of the energy: without the elastic energy (the hook returned 0 for Hertz before)
  the deviation would be that, and would not converge.
* With friction and damping (restitution 0.5, mu 0.5) the total only decreases (between samples,
  up to the integration error of the undamped run at that dt) and loses a large part of itself.

The orthogonal engine runs LIGGGHTS' parametrisation (hertz-liggghts), the sheared cell (a fixed
tilt xy = 0.2 Lx, LAMMPS' bookkeeping) LAMMPS' gran/hertz/history (hertz-lammps): the sheared
engine on a plug-in law.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from gransim.contacts.laws import make_law
from gransim.dem import DEMEngine, DEMSettings, Loading
from gransim.dem.sheared import ShearEngine, ShearLoading
from gransim.geometry import Packing

R = 1e-3  # m
T_RUN = 2e-3  # s
SAMPLES = 40
DTS = (4e-7, 2e-7, 1e-7)  # s; the Hertz contact of two of these disks at 0.2 m/s lasts ~1e-5 s


#: KN of gran/hertz/history = 4/3 Y* for E = 5e8 Pa, nu = 0.3 (Y* = E/(2 (1 - nu^2))); KT = 8 G*
#: = 2 KN/1.15 for nu = 0.3 (G* = E/(4 (2 - nu)(1 + nu)))
KN_LAMMPS = 4 / 3 * 5e8 / (2 * (1 - 0.3**2))


def _assembly(tilt=0.0, n=6, seed=1):
    rng = np.random.default_rng(seed)
    L = n * 2 * R / 0.95
    g = (np.arange(n) + 0.5) * L / n
    pos = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2) + rng.uniform(-0.02, 0.02, (n * n, 2)) * R
    pos[:, 0] += tilt * L * pos[:, 1] / L  # the lattice sheared with the cell
    radii = R * rng.uniform(0.9, 1.1, n * n)
    cell = np.array([[L, tilt * L], [0.0, L]])
    return Packing(positions=pos, radii=radii, cell=cell, density=1000.0), rng.normal(0.0, 0.2, (n * n, 2))


def _settings(dt):
    return DEMSettings(kn=1e5, kt=1e5, dt=dt, skin=2e-4)


def _orthogonal(law, dt):
    p, v = _assembly()
    eng = DEMEngine(p, _settings(dt), velocities=v, law=law, check_dt=False)
    return eng, lambda k: eng.advance(Loading(), k)


def _sheared(law, dt):
    p, v = _assembly(tilt=0.2)
    eng = ShearEngine(p, _settings(dt), velocities=v, law=law, check_dt=False, flavour="lammps")
    eng.start_run(ShearLoading(), round(T_RUN / dt))
    return eng, eng.advance


def _energies(make, law, dt):
    """(E0, E at each of SAMPLES times, largest elastic energy seen) over T_RUN."""
    eng, advance = make(law, dt)
    e0 = eng.kinetic_energy() + eng.elastic_energy()
    chunk = round(T_RUN / dt) // SAMPLES
    es, umax = [], 0.0
    for _ in range(SAMPLES):
        advance(chunk)
        u = eng.elastic_energy()
        umax = max(umax, u)
        es.append(eng.kinetic_energy() + u)
    return e0, np.array(es), umax, eng


CASES = {
    "orthogonal hertz-liggghts": (
        _orthogonal,
        "hertz-liggghts",
        {"youngs_modulus": 5e8, "poisson_ratio": 0.3, "restitution": 1.0, "friction": 0.0},
    ),
    "sheared hertz-lammps": (
        _sheared,
        "hertz-lammps",
        {"kn": KN_LAMMPS, "kt": 2 * KN_LAMMPS / 1.15, "gamma_n": 0.0, "gamma_t": 0.0, "mu": 0.0},
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_undamped_frictionless_hertz_conserves_energy_to_second_order(case):
    make, name, params = CASES[case]
    law = make_law(name, **params)
    errs = []
    for dt in DTS:
        e0, es, umax, eng = _energies(make, law, dt)
        errs.append(np.abs(es - e0).max() / e0)
        # collisions happened and stored energy far above the integration error
        assert eng.n_rebuilds > 3 and umax > 1e3 * errs[-1] * e0
        assert np.all(eng.w == 0.0)  # frictionless: no torque
    rates = [math.log2(errs[k] / errs[k + 1]) for k in range(len(errs) - 1)]
    assert all(1.8 < q < 2.2 for q in rates), (errs, rates)


@pytest.mark.parametrize("case", list(CASES))
def test_friction_and_damping_only_dissipate(case):
    make, name, params = CASES[case]
    if name == "hertz-liggghts":
        lossy = {**params, "restitution": 0.5, "friction": 0.5}
    else:
        lossy = {**params, "gamma_n": 2e4, "gamma_t": 1e4, "mu": 0.5}
    dt = DTS[1]
    e0c, esc, _, _ = _energies(make, make_law(name, **params), dt)
    bound = np.abs(esc - e0c).max()  # the integration error of the conservative run at this dt
    e0, es, _, eng = _energies(make, make_law(name, **lossy), dt)
    assert np.any(eng.w != 0.0)  # friction acted
    e = np.concatenate([[e0], es])
    assert np.diff(e).max() <= 2 * bound, (np.diff(e).max(), bound)
    assert e[-1] < 0.8 * e0
