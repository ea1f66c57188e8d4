"""``gransim biaxial --flavour liggghts|lammps``: the option reaches the engine (the two arithmetics give
different runs) and the run file's provenance records it; a bad value is one line and exit 2."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import read_run
from gransim.io import save_packing


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("flavour") / "p.h5"
    save_packing(p, lattice_packing(6, 6, seed=4, spread=0.1, compression=0.04))
    return p


def _run(packing_file, out, flavour):
    argv = [
        "biaxial",
        "--packing",
        str(packing_file),
        "--strain",
        "0.0005",
        "--strain-rate",
        "0.5",
        "-o",
        str(out),
        "--consolidation-steps",
        "300",
        "--series-every",
        "5",
        "--allow-unsettled",
    ]
    if flavour is not None:
        argv += ["--flavour", flavour]
    assert main(argv) == 0
    return read_run(out)


def test_flavour_recorded_and_used(tmp_path, packing_file, capsys):
    runs = {
        f: _run(packing_file, tmp_path / f"{f}.h5", None if f == "default" else f)
        for f in ("default", "liggghts", "lammps")
    }
    assert "lammps arithmetic" in capsys.readouterr().out
    for f, run in runs.items():
        want = "liggghts" if f == "default" else f
        assert run.settings["dem"]["flavour"] == want
        with h5py.File(tmp_path / f"{f}.h5") as h:
            assert json.loads(h.attrs["parameters"])["dem"]["flavour"] == want
    s = {f: r.series["stress"] for f, r in runs.items()}
    # the default is the liggghts arithmetic, bit for bit; lammps' law (full radii as lever arms,
    # damping inside the Coulomb cap, spring reset on separation) gives a different run
    assert np.array_equal(s["default"], s["liggghts"])
    assert s["lammps"].shape == s["liggghts"].shape and not np.array_equal(s["lammps"], s["liggghts"])


def test_bad_flavour_is_one_line_exit_2(tmp_path, packing_file, capsys):
    out = tmp_path / "x.h5"
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), "--flavour", "yade"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--flavour" in err[0] and "liggghts, lammps" in err[0] and "'yade'" in err[0]
    assert not out.exists()
