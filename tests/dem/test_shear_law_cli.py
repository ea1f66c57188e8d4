"""``gransim shear --law``: the sheared cell on a plug-in law from the command line. A
Hertz run (hertz-granular-lammps from material constants) records the law in its run file and
its shear stress builds up; a law in LIGGGHTS' arithmetic and --law-param without --law are
refused (exit 2, the message naming the option)."""

import json

import h5py
import pytest

from gransim.cli import main
from gransim.io import save_packing
from reference_runs.decks.shear import short_case


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p, _, _, _ = short_case("constant-volume")
    path = tmp_path_factory.mktemp("shear-law") / "p.h5"
    save_packing(path, p)
    return path


def test_hertz_law_runs_and_is_recorded(packing_file, tmp_path):
    out = tmp_path / "hertz.h5"
    assert (
        main(
            [
                "shear",
                "--packing",
                str(packing_file),
                "--strain",
                "0.002",
                "--rate",
                "5",
                "--law",
                "hertz-granular-lammps",
                "--law-param",
                "youngs_modulus=5e8",
                "--law-param",
                "poisson_ratio=0.3",
                "--law-param",
                "damp=0.5",
                "--law-param",
                "friction=0.5",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    with h5py.File(out, "r") as f:
        settings = json.loads(f.attrs["settings"])
        sxy = f["series/stress"][()][:, 0, 1]
        assert f.attrs["complete"]
    assert settings["law"]["name"] == "hertz-granular-lammps"
    assert settings["law"]["params"]["youngs_modulus"] == 5e8
    assert abs(sxy[-1]) > 0.0


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--law", "hertz-liggghts"], "--law hertz-liggghts: a law in LIGGGHTS' arithmetic"),
        (["--law-param", "kn=1"], "--law-param: given without --law"),
        (["--law", "hertz-lammps", "--kn", "1e5"], "--kn: not used with the Hertz law"),
        (["--law", "hooke-lammps", "--law-param", "kn"], "--law-param: expected KEY=VALUE"),
    ],
)
def test_bad_law_options_are_refused(packing_file, tmp_path, capsys, argv, match):
    code = main(
        [
            "shear",
            "--packing",
            str(packing_file),
            "--strain",
            "0.002",
            "--rate",
            "5",
            "-o",
            str(tmp_path / "x.h5"),
            *argv,
        ]
    )
    assert code == 2
    assert match in capsys.readouterr().err
