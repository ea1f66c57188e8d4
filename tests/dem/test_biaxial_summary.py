"""The biaxial summary counts DEM steps of the compression phase, not rows of the series."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from gransim.dem.biaxial import default_settings, run_biaxial
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import OutputSettings, read_run

SERIES_EVERY = 7  # a row every 7 steps: rows and steps differ by that factor


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    packing = lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)
    dem, bi = default_settings(packing, kn=1e5)
    bi = dataclasses.replace(bi, strain=0.001, strain_rate=0.01, consolidation_steps=3000, check_every=500)
    out = tmp_path_factory.mktemp("bi") / "bi.h5"
    summary = run_biaxial(
        packing,
        dem,
        bi,
        out,
        OutputSettings(series_every=SERIES_EVERY, snapshot_every=0, checkpoint_every=0),
        show_progress=False,
        allow_unsettled=True,
    )
    return summary, read_run(out), bi, dem


def test_compression_steps_counts_steps(run):
    summary, rec, bi, dem = run
    assert summary["complete"]
    # the compression phase drives eps22 at a constant rate for strain / (rate dt) steps
    n = math.ceil(bi.strain / (bi.strain_rate * dem.dt))
    assert summary["compression_steps"] == n
    comp = rec.series["phase"] == 1
    rows = int(np.count_nonzero(comp))
    assert rows < n / (SERIES_EVERY - 1)  # the rows are about n / 7: the count is not the rows'
    # the steps between the last consolidation row and the last compression row, to within a row
    span = int(rec.series["step"][comp].max() - rec.series["step"][~comp].max())
    assert n - SERIES_EVERY < span <= n
    # and the strain reached is that of n steps at the rate (the cell height shrinks at the rate)
    assert summary["axial_strain"] == pytest.approx(n * bi.strain_rate * dem.dt, rel=0.02)
