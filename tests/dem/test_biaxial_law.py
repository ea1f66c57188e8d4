"""``gransim biaxial --law NAME --law-param KEY=VALUE``: the law reaches the engine, its name and
parameters are in the run file's settings JSON, and bad names/parameters are one line and exit 2."""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest

from gransim.cli import main
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import read_run
from gransim.io import load_packing, save_packing

BASE = [
    "--strain",
    "0.0005",
    "--strain-rate",
    "0.5",
    "--consolidation-steps",
    "300",
    "--series-every",
    "5",
    "--allow-unsettled",
]


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("law") / "p.h5"
    save_packing(p, lattice_packing(6, 6, seed=4, spread=0.1, compression=0.04))
    return p


def _run(packing_file, out, *extra):
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), *BASE, *extra]) == 0
    return read_run(out)


def test_hooke_law_by_name_is_the_default_run_bit_for_bit(tmp_path, packing_file):
    """The factory's hooke-liggghts law with the protocol's defaults is the engine's built-in law:
    the same numbers in every stress row; the law and its parameters are in the provenance."""
    ref = _run(packing_file, tmp_path / "ref.h5")
    got = _run(packing_file, tmp_path / "law.h5", "--law", "hooke-liggghts", "--law-param", "mu=0.5")
    assert np.array_equal(ref.series["stress"], got.series["stress"])
    with h5py.File(tmp_path / "law.h5") as h:
        par = json.loads(h.attrs["parameters"])
    assert par["law_options"]["name"] == "hooke-liggghts"
    assert par["law_options"]["params"]["mu"] == 0.5
    assert par["law_options"]["params"]["kn"] == par["dem"]["kn"]
    assert par["law"]["name"] == "HookeLiggghts" and par["law"]["params"]["kn"] == par["dem"]["kn"]


def test_hertz_law_runs_at_the_designed_indentation(tmp_path, packing_file):
    """hertz-liggghts with the material constants: the flavour is LIGGGHTS', the provenance holds
    the constants, and the equivalent stiffness 2 Y* sqrt(R* delta) at delta = 2e-4 D50 puts the
    mean overlap at the start of compression near 2e-4 D50 (as kn does for the Hooke law)."""
    p = load_packing(packing_file)
    k = 1e5
    ystar = k / (2 * np.sqrt(0.25 * p.d50 * 2e-4 * p.d50))
    E = float(ystar * 2 * (1 - 0.3**2))  # Y* = E/(2 (1 - nu^2)) for one material
    run = _run(
        packing_file,
        tmp_path / "h.h5",
        "--law",
        "hertz-liggghts",
        "--law-param",
        f"youngs_modulus={E!r}",
        "--law-param",
        "poisson_ratio=0.3",
        "--law-param",
        "restitution=0.5",
        "--strain",
        "0.002",
        "--consolidation-steps",
        "20000",
    )
    assert run.settings["dem"]["flavour"] == "liggghts"
    assert run.settings["law_options"] == {
        "name": "hertz-liggghts",
        "params": {"youngs_modulus": E, "poisson_ratio": 0.3, "restitution": 0.5, "friction": 0.5},
    }
    assert run.settings["law"]["name"] == "HertzHistoryLiggghts"
    assert run.settings["law"]["params"]["yeff"] == pytest.approx(ystar, rel=1e-12)
    s = run.series
    comp = s["phase"] == 1
    ov = s["mean_overlap"][comp][0] / p.d50
    assert 0.5e-4 < ov < 5e-4, ov


@pytest.mark.parametrize(
    "extra, words",
    [
        (["--law", "linear-spring"], ["--law", "hooke-liggghts", "'linear-spring'"]),
        (
            ["--law", "hertz-liggghts", "--law-param", "youngs_modulus=7e8"],
            ["--law-param", "poisson_ratio"],
        ),
        (
            ["--law", "hooke-liggghts", "--law-param", "stiffness=3"],
            ["--law-param", "unknown stiffness"],
        ),
        (["--law", "hooke-liggghts", "--law-param", "kn"], ["--law-param", "KEY=VALUE", "'kn'"]),
        (["--law", "hooke-liggghts", "--law-param", "mu=-1"], ["--law-param", "mu"]),
        (["--law-param", "mu=0.3"], ["--law-param", "without --law"]),
        (
            [
                "--law",
                "hertz-liggghts",
                "--law-param",
                "youngs_modulus=soft",
                "--law-param",
                "poisson_ratio=0.3",
                "--law-param",
                "restitution=0.5",
            ],
            ["--law-param", "youngs_modulus", "'soft'"],
        ),
        (["--law", "hooke-lammps", "--flavour", "liggghts"], ["--flavour", "lammps"]),
        (
            [
                "--law",
                "hertz-liggghts",
                "--kn",
                "1e5",
                "--law-param",
                "youngs_modulus=7e8",
                "--law-param",
                "poisson_ratio=0.3",
                "--law-param",
                "restitution=0.5",
            ],
            ["--kn", "Hertz"],
        ),
    ],
)
def test_bad_law_options_are_one_line_exit_2(tmp_path, packing_file, capsys, extra, words):
    out = tmp_path / "x.h5"
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for w in words:
        assert w in err[0], (w, err[0])
    assert not out.exists()
