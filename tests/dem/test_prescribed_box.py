"""DEMEngine's prescribed-box loading (a table of the box of every step, applied inside run_block) and
its explicit box origin (``box=(lo, hi)``)."""

from __future__ import annotations

import numpy as np
import pytest

from gransim.dem import AxisControl, DEMEngine, DEMSettings, Loading
from gransim.dem.lattice import lattice_packing
from gransim.dem.settings import PrescribedBox
from gransim.errors import InputError

S = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(6, 6, seed=5, spread=0.1, compression=0.04)


def _rate_table(eng, rate_x, rate_y, n):
    """The box of AxisControl('rate') on both axes, in box_target's arithmetic."""
    lo0, hi0 = eng.lo.copy(), eng.hi.copy()
    lo, hi = np.empty((n + 1, 2)), np.empty((n + 1, 2))
    lo[0], hi[0] = lo0, hi0
    for d, rate in enumerate((rate_x, rate_y)):
        c = rate * (hi0[d] - lo0[d]) * S.dt
        for k in range(1, n + 1):
            dl = c * float(k)
            lo[k, d] = lo0[d] - 0.5 * dl
            hi[k, d] = hi0[d] + 0.5 * dl
    return lo, hi


def test_table_of_a_rate_loading_reproduces_it_bit_for_bit(packing):
    n = 400
    a = DEMEngine(packing, S)
    b = DEMEngine(packing, S)
    ra = a.advance(Loading(x=AxisControl("rate", rate=-3.0), y=AxisControl("rate", rate=2.0)), n)
    lo, hi = _rate_table(b, -3.0, 2.0, n)
    table = PrescribedBox(lo, hi)
    rb = {}
    for chunk in (1, 150, 249):  # several calls: the table is indexed by the engine's step
        part = b.advance(table, chunk)
        for k, v in part.items():
            rb.setdefault(k, []).append(v)
    rb = {k: np.concatenate(v) for k, v in rb.items()}
    assert a.n_rebuilds == b.n_rebuilds > 2
    for k in ("stress", "lengths", "n_contacts", "kinetic_energy", "virial"):
        assert np.array_equal(ra[k], rb[k]), k
    assert np.array_equal(a.x, b.x) and np.array_equal(a.v, b.v) and np.array_equal(a.lo, lo[-1])
    # the virial output is the stress times the area of the box after the step
    area = rb["lengths"][:, 0] * rb["lengths"][:, 1]
    assert np.allclose(rb["virial"][:, 0] / area, rb["stress"][:, 0, 0], rtol=1e-14, atol=0)


def test_remap_rows_are_honoured(packing):
    n = 60
    a = DEMEngine(packing, S)
    lo = np.tile(a.lo, (n + 1, 1))
    hi = np.tile(a.hi, (n + 1, 1))
    # no remap row: the fixed-box run itself
    ref = DEMEngine(packing, S)
    ref.advance(Loading(), n)
    a.advance(PrescribedBox(lo, hi, np.zeros(n + 1, bool)), n)
    assert np.array_equal(a.x, ref.x)
    # remap on every 3rd step with an unchanged box: x = L ((x - lo)/L) + lo rounds, as the codes'
    # fix deform does, so the run differs from the fixed box in the last bits
    b = DEMEngine(packing, S)
    remap = np.zeros(n + 1, bool)
    remap[3::3] = True
    b.advance(PrescribedBox(lo, hi, remap), n)
    assert not np.array_equal(b.x, ref.x) and np.allclose(b.x, ref.x, rtol=0, atol=1e-12)
    # a box change on a row without the remap flag is ignored
    c = DEMEngine(packing, S)
    hi2 = hi * 1.01
    c.advance(PrescribedBox(lo, hi2, np.zeros(n + 1, bool)), n)
    assert np.array_equal(c.hi, ref.hi)


def test_bad_tables_and_boxes_are_refused(packing):
    eng = DEMEngine(packing, S)
    lo = np.tile(eng.lo, (11, 1))
    hi = np.tile(eng.hi, (11, 1))
    with pytest.raises(InputError, match=r"covers steps 1\.\.10, the run needs 1\.\.11"):
        eng.advance(PrescribedBox(lo, hi), 11)
    with pytest.raises(InputError, match=r"\(T, 2\)"):
        PrescribedBox(lo[:, :1], hi[:, :1])
    bad = hi.copy()
    bad[4, 1] = lo[4, 1]
    with pytest.raises(InputError, match="row 4 has hi <= lo"):
        PrescribedBox(lo, bad)
    with pytest.raises(InputError, match="remap must have 11 rows"):
        PrescribedBox(lo, hi, np.ones(3, bool))
    with pytest.raises(InputError, match="finite"):
        PrescribedBox(lo * np.nan, hi)
    with pytest.raises(InputError, match="Loading or a PrescribedBox"):
        eng.advance("rate", 1)
    L = np.diag(packing.cell)
    with pytest.raises(InputError, match="differs from the cell's side lengths"):
        DEMEngine(packing, S, box=([0.1, 0.2], [0.1 + L[0] * 1.001, 0.2 + L[1]]))
    with pytest.raises(InputError, match="box: expected"):
        DEMEngine(packing, S, box=([0.1], [0.2]))


def test_box_origin_is_used_as_given(packing):
    lo = np.array([0.25, -0.0417])
    x = np.asarray(packing.positions) + lo
    hi = lo + np.diag(packing.cell)
    p = packing.replace(positions=x, cell=np.diag(hi - lo))
    eng = DEMEngine(p, S, box=(lo, hi))
    assert np.array_equal(eng.lo, lo) and np.array_equal(eng.hi, hi)
    ref = DEMEngine(packing, S)
    eng.advance(Loading(y=AxisControl("rate", rate=-2.0)), 300)
    ref.advance(Loading(y=AxisControl("rate", rate=-2.0)), 300)
    # the same run in a translated frame: agreement to round-off of the translation, and the box
    # stays at its origin (centre-symmetric rate control)
    assert np.allclose(eng.x - eng.lo, ref.x - ref.lo, rtol=0, atol=1e-12)
    assert np.allclose(eng.stress, ref.stress, rtol=1e-9, atol=0) and eng.lo[0] == lo[0]
