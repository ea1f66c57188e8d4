"""The orthogonal and the sheared cell run in one engine class (gransim.dem.engine.Engine): the
divergence check of the sheared cell (now the energy balance of the orthogonal one, on the kinetic
energy relative to the cell's flow) lets an honest shear run through and stops a kinetic energy
that no work paid for; the lost-particle check and the energies are the same functions."""

from __future__ import annotations

import numpy as np
import pytest

from gransim.dem import DEMEngine, DEMSettings
from gransim.dem.engine import Engine
from gransim.dem.lattice import lattice_packing
from gransim.dem.sheared import ShearEngine, ShearLoading
from gransim.errors import SimulationError

S = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)


def _sheared(erate=20.0):
    p = lattice_packing(8, 8)
    eng = ShearEngine(p, S)
    eng.start_run(ShearLoading(erate=erate), 400)
    return eng


def test_both_cells_run_in_one_engine():
    p = lattice_packing(8, 8)
    kinds = []
    for eng in (DEMEngine(p, S), ShearEngine(p, S)):
        assert type(eng) is Engine
        kinds.append(eng.cell_kind)
    assert kinds == ["orthogonal", "sheared"]


def test_sheared_budget_is_the_kinetic_energy_relative_to_the_flow():
    # disks at rest in a cell sheared at erate: relative to the flow u_x = hr5 (y - ylo)/Ly they
    # move at -u, so the budget starts with sum m u^2/2 (an independent sum here)
    eng = _sheared(erate=20.0)
    b = eng.box
    u = eng.h_rate[2] * (eng.x[:, 1] - b[1]) / (b[3] - b[1])
    want = 0.5 * np.sum(eng.m * u * u)
    assert want > 0.0 and eng._budget_kinetic_energy() == pytest.approx(want, rel=1e-12)
    assert eng._energy0 == pytest.approx(want + eng.elastic_energy(), rel=1e-12)


def test_an_honest_shear_run_passes_the_check():
    eng = _sheared()
    out = eng.advance(400)
    assert np.all(np.isfinite(out["kinetic_energy"])) and eng.n_rebuilds >= 1


def test_kinetic_energy_without_work_is_a_divergence():
    # every fourth disk kicked (y) so that they carry 30 times the energy the run has had:
    # kinetic energy no work of the cell paid for, beyond 10 times the balance; slow enough to
    # stay within half a skin per step (the lost-particle check would speak first), so the
    # divergence check names the step
    eng = _sheared()
    eng.advance(10)
    k = np.arange(0, eng.m.size, 4)
    v = np.sqrt(2.0 * 30.0 * eng._energy0 / eng.m[k].sum())
    assert v * S.dt < 0.4 * S.skin, "the kick must not lose a particle"
    eng.v[k, 1] += v * np.where(k % 8 == 0, 1.0, -1.0)
    with pytest.raises(SimulationError, match=r"step 1[1-9]\d*: kinetic energy blow-up"):
        eng.advance(200)


def test_a_non_finite_velocity_is_named():
    eng = _sheared()
    eng.advance(5)
    eng.v[3, 0] = np.inf
    with pytest.raises(SimulationError, match=r"step 6: (the kinetic energy is not finite|particle 3)"):
        eng.advance(5)
