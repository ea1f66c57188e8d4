"""The ordering of a biaxial run (run_phases(order=...), gransim biaxial --order): a fast run split
at a step and resumed equals the uninterrupted fast run bit for bit; the ordering is part of the
run's identity (a code-order file is not resumed in the fast order); the two orderings agree to
round-off over a short horizon."""

from __future__ import annotations

import numpy as np
import pytest

from gransim.dem import AxisControl, DEMSettings, Loading, OutputSettings, Phase, read_run, read_snapshot, run_phases
from gransim.dem.lattice import lattice_packing
from gransim.errors import InputError, ResultFileError

SETTINGS = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, mu=0.5, dt=2e-6, skin=2e-5)
LOADING = Loading(x=AxisControl("servo", target=100.0, gain=1e-2), y=AxisControl("rate", rate=-1.0))
PHASES = [Phase("a", LOADING, 500), Phase("b", Loading(x=LOADING.x, y=AxisControl("rate", rate=0.5)), 300)]
OUT = OutputSettings(snapshot_every=100, checkpoint_every=300)


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)


def test_fast_run_in_pieces_equals_the_whole_run(tmp_path, packing):
    kw = {"show_progress": False, "order": "fast", "threads": 2}
    full = tmp_path / "full.h5"
    run_phases(packing, SETTINGS, PHASES, full, OUT, **kw)
    part = tmp_path / "part.h5"
    run_phases(packing, SETTINGS, PHASES, part, OUT, stop_at_step=650, **kw)
    assert not read_run(part).complete
    run_phases(packing, SETTINGS, PHASES, part, OUT, resume=True, **kw)
    a, b = read_run(full), read_run(part)
    assert b.complete
    for k in ("step", "stress", "cell", "n_contacts", "kinetic_energy"):
        np.testing.assert_array_equal(a.series[k], b.series[k], err_msg=k)
    np.testing.assert_array_equal(read_snapshot(full).positions, read_snapshot(part).positions)
    # a complete file resumed is returned as it is
    run_phases(packing, SETTINGS, PHASES, part, OUT, resume=True, **kw)


def test_the_ordering_is_part_of_the_run(tmp_path, packing):
    code = tmp_path / "code.h5"
    run_phases(packing, SETTINGS, PHASES, code, OUT, stop_at_step=400, show_progress=False)
    with pytest.raises(ResultFileError, match="another run"):
        run_phases(packing, SETTINGS, PHASES, code, OUT, resume=True, show_progress=False, order="fast")
    with pytest.raises(InputError, match="unknown order"):
        run_phases(packing, SETTINGS, PHASES, tmp_path / "x.h5", OUT, show_progress=False, order="quick")


def test_fast_and_code_order_agree_to_round_off_over_a_short_horizon(tmp_path, packing):
    a, b = tmp_path / "code.h5", tmp_path / "fast.h5"
    run_phases(packing, SETTINGS, PHASES[:1], a, OUT, show_progress=False)
    run_phases(packing, SETTINGS, PHASES[:1], b, OUT, show_progress=False, order="fast", threads=2)
    sa, sb = read_run(a).series, read_run(b).series
    scale = np.abs(sa["stress"]).max()
    assert np.abs(sa["stress"] - sb["stress"]).max() < 1e-9 * scale
    d = read_snapshot(a).positions - read_snapshot(b).positions
    assert np.abs(d).max() < 1e-9 * 2 * np.median(packing.radii)  # of D50, 500 steps
