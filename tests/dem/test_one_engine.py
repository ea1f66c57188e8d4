"""The one engine class: both orderings and both cells are :class:`gransim.dem.engine.Engine`
with one step loop; an engine built straight from a checkpoint (``Engine.from_checkpoint``: no
run set-up) continues with the bits of the uninterrupted run, in every cell and ordering."""

from __future__ import annotations

import numpy as np
import pytest

from gransim.dem import AxisControl, DEMSettings, Loading
from gransim.dem.engine import Engine, make_engine
from gransim.dem.lattice import lattice_packing
from gransim.dem.sheared import ShearLoading
from gransim.errors import InputError

S = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5, flavour="lammps")
ORTHO = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))
SHEAR = ShearLoading(erate=20.0, y="servo", target=50.0, gain=1e-3)


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(10, 10, seed=3, spread=0.1, compression=0.04)


def _sheared(p):
    from gransim import Packing

    C = np.array(p.cell, np.float64)
    C[0, 1] = 0.1 * C[0, 0]
    return Packing(positions=p.positions, radii=p.radii, cell=C, density=p.density)


def _steps(eng, cell, nsteps, box0):
    """``nsteps`` steps of the test's run: the sheared cell's begun by start_run, the orthogonal
    cell's loading phase measured from step 0 and the box ``box0``."""
    if cell == "sheared":
        return eng.advance(nsteps)
    return eng.advance(ORTHO, nsteps, phase_step0=0, phase_box0=box0)


@pytest.mark.parametrize("order", ["code", "fast"])
@pytest.mark.parametrize("cell", ["orthogonal", "sheared"])
def test_an_engine_from_a_checkpoint_continues_bit_for_bit(packing, cell, order):
    p = _sheared(packing) if cell == "sheared" else packing
    full = make_engine(p, S, cell=cell, order=order)
    assert type(full) is Engine and full.order == order and full.cell_kind == cell
    box0 = (full.lo.copy(), full.hi.copy())
    if cell == "sheared":
        full.start_run(SHEAR, 600)
    _steps(full, cell, 250, box0)
    ck = full.state_arrays()
    if cell == "sheared":
        ck = {**ck, "loading": SHEAR}  # the run's loading is the run file's
    step = full.step
    rest = _steps(full, cell, 350, box0)
    again = Engine.from_checkpoint(p, S, ck, step, cell=cell, order=order)
    assert again.n_rebuilds == 0  # no set-up build: the checkpoint's list
    out = _steps(again, cell, 350, box0)
    for k in ("stress", "n_contacts", "kinetic_energy"):
        np.testing.assert_array_equal(out[k], rest[k], err_msg=k)
    np.testing.assert_array_equal(again.x, full.x)
    np.testing.assert_array_equal(again.v, full.v)
    np.testing.assert_array_equal(again.w, full.w)


def test_a_checkpoint_of_one_ordering_is_refused_by_the_other(packing):
    ck = make_engine(packing, S, order="fast").state_arrays()
    with pytest.raises((InputError, KeyError)):
        Engine.from_checkpoint(packing, S, ck, 0, order="code")
    ck = make_engine(packing, S).state_arrays()
    with pytest.raises(InputError, match="fast-ordering checkpoint"):
        Engine.from_checkpoint(packing, S, ck, 0, order="fast")


def test_a_fast_checkpoint_of_the_other_cell_is_refused(packing):
    """A sheared cell's fast checkpoint has no orthogonal box (and the reverse): an InputError
    naming the dataset, not a KeyError."""
    sheared = make_engine(_sheared(packing), S, cell="sheared", order="fast")
    sheared.start_run(SHEAR, 10)
    with pytest.raises(InputError, match="box_lo"):
        Engine.from_checkpoint(packing, S, sheared.state_arrays(), 0, order="fast")
    cut = make_engine(_sheared(packing), S, cell="sheared", order="fast").state_arrays()
    cut.pop("box_hold")
    with pytest.raises(InputError, match="box_hold"):
        Engine.from_checkpoint(_sheared(packing), S, cut, 0, cell="sheared", order="fast")


def test_the_fast_ordering_has_no_code_order_list_views(packing):
    eng = make_engine(packing, S, order="fast")
    assert eng.ea.shape == eng.eb.shape == (eng.xi.shape[0],)
    with pytest.raises(AttributeError, match="fast ordering keeps no such array"):
        eng.esx  # noqa: B018 - the view is the test


# ---------------------------------------------------------------------------------------------- yade
def _yade_case():
    from reference_runs.decks.shear import wrapped_packing
    from reference_runs.yade.dem import short_biaxial

    p, s, ld, _ = short_biaxial()
    return wrapped_packing(p), s, ld


def test_the_yade_arithmetic_is_a_cell_of_the_engine_and_continues_from_a_checkpoint():
    from gransim.dem.yade_arithmetic import yade_run

    p, s, ld = _yade_case()
    eng = Engine(p, s, flavour="yade")
    assert eng.cell_kind == "orthogonal" and eng.order == "code"
    eng.start_run(ld, 400)
    first = eng.advance(150)
    ck = eng.state_arrays()
    rest = eng.advance(250)
    again = Engine.from_checkpoint(p, s, ck, 150, flavour="yade")
    out = again.advance(250)  # the run's control is in the checkpoint
    for k in ("stress", "n_contacts", "kinetic_energy", "lengths"):
        np.testing.assert_array_equal(out[k], rest[k], err_msg=k)
    np.testing.assert_array_equal(again.x, eng.x)
    # the recording driver (every frame as YADE's script writes it) is the same engine: its stress,
    # compression positive, is -sig^T of YADE's getStress() with the same bits
    run = yade_run(p, s, ld, 400)
    np.testing.assert_array_equal(first["stress"], -np.swapaxes(run.stress[1:151], 1, 2))
    np.testing.assert_array_equal(eng.x, run.positions[400])
    assert eng.elastic_energy() > 0 and eng.contacts()["i"].size == run.n_contacts[400]


def test_the_yade_arithmetic_refuses_what_it_does_not_run():
    p, s, ld = _yade_case()
    with pytest.raises(InputError, match="order"):
        Engine(p, s, flavour="yade", order="fast")
    with pytest.raises(InputError, match="undamped"):
        Engine(p, DEMSettings(**{**s.to_dict(), "gamma_n": 1.0}), flavour="yade")
    with pytest.raises(InputError, match="ShearLoading"):
        Engine(p, s, flavour="yade", cell="sheared").start_run(ld, 10)
    with pytest.raises(InputError, match="law"):
        Engine(p, s, flavour="yade", law=s.hooke_law())


def test_a_yade_run_that_blows_up_names_the_step():
    from gransim.errors import SimulationError

    p, s, ld = _yade_case()
    eng = Engine(p, DEMSettings(**{**s.to_dict(), "dt": 1.2e-3}), flavour="yade", check_dt=False)  # 10x the limit
    eng.start_run(ld, 5000)
    with pytest.raises(SimulationError, match=r"step \d+: .*(kinetic energy|non-finite|bound)"):
        eng.advance(5000)
