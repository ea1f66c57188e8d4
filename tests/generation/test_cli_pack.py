"""gransim pack / info / packings on the command line: output files, printed statistics, one-line errors."""

import h5py
import pytest

from gransim.cli import main
from gransim.io import load_packing


def test_pack_then_info(tmp_path, capsys):
    out = tmp_path / "rve.h5"
    assert (
        main(
            [
                "pack",
                "--distribution",
                "quartz-sand",
                "--n",
                "60",
                "--seed",
                "3",
                "-o",
                str(out),
                "--vtu",
                str(tmp_path / "rve.vtu"),
            ]
        )
        == 0
    )
    p = load_packing(out)
    assert p.n == 60 and p.metadata["seed"] == 3 and (tmp_path / "rve.vtu").exists()
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    for key in (
        "N                      60",
        "packing fraction",
        "void ratio",
        "coordination",
        "without rattlers",
        "mean overlap",
        "max overlap",
    ):
        assert key in text
    assert f"{p.solid_fraction:.5f}" in text


def test_pack_solid_fraction_option(tmp_path, capsys):
    out = tmp_path / "phi.h5"
    assert main(["pack", "--n", "40", "--seed", "1", "--solid-fraction", "0.88", "-o", str(out)]) == 0
    assert load_packing(out).solid_fraction == pytest.approx(0.88, rel=1e-12)


def test_pack_residual_options(tmp_path, capsys):
    out = tmp_path / "rms.h5"
    assert main(["pack", "--n", "200", "--seed", "2", "--residual", "rms", "--force-tol", "5e-4", "-o", str(out)]) == 0
    m = load_packing(out).metadata
    assert m["residual_norm"] == "rms" and m["force_tol"] == 5e-4 and m["residual"] <= 5e-4


def test_pack_method_option(tmp_path, capsys):
    out = tmp_path / "front.h5"
    assert main(["pack", "--n", "80", "--seed", "2", "--method", "front", "-o", str(out)]) == 0
    m = load_packing(out).metadata
    assert m["method"] == "front" and m["residual"] <= 1e-3


def test_pack_cell_option(tmp_path, capsys):
    out = tmp_path / "shape.h5"
    assert main(["pack", "--n", "80", "--seed", "2", "--cell", "shape", "-o", str(out)]) == 0
    p = load_packing(out)
    m = p.metadata
    assert m["cell"] == "shape" and m["force_tol"] == 1e-5 and m["residual"] <= 1e-5
    assert p.cell[0, 1] != 0.0 and p.cell[1, 0] == 0.0  # the sheared cell is written as it is


def test_pack_by_frictional_compaction(tmp_path, capsys):
    out = tmp_path / "dem.h5"
    assert (
        main(
            [
                "pack",
                "--distribution",
                "kuhn-1002",
                "--n",
                "80",
                "--seed",
                "2",
                "--friction",
                "0.3",
                "--pressure",
                "2e-4",
                "-o",
                str(out),
            ]
        )
        == 0
    )
    p = load_packing(out)
    assert p.n == 80 and p.metadata["friction"] == 0.3 and p.metadata["pressure_over_kn"] == 2e-4
    assert "DEM steps" in capsys.readouterr().out


@pytest.mark.parametrize(
    "argv, message",
    [
        (["pack", "--n", "50", "--friction", "0.1", "--solid-fraction", "0.85", "-o", "x.h5"], "takes no --solid"),
        (["pack", "--n", "50", "--pressure", "1e-4", "-o", "x.h5"], "--pressure needs --friction"),
        (["pack", "--n", "50", "--friction", "0.1", "--residual", "rms", "-o", "x.h5"], "belong to the FIRE"),
        (["pack", "--n", "50", "--friction", "0.1", "--method", "front", "-o", "x.h5"], "belong to the FIRE"),
        (["pack", "--n", "50", "--force-tol=-1", "-o", "x.h5"], "--force-tol: expected"),
        (["pack", "--n", "50", "--friction=-1", "-o", "x.h5"], "--friction: expected"),
        (["pack", "--n", "1", "-o", "x.h5"], "--n: expected an integer >= 2"),
        (["pack", "--n", "50", "--distribution", "granite", "-o", "x.h5"], "unknown distribution 'granite'"),
        (
            ["pack", "--n", "50", "--solid-fraction", "0.97", "-o", "x.h5"],
            "--solid-fraction: expected a finite number > 0 and < 0.95",
        ),
        (["pack", "--n", "50", "--mean-overlap=-1e-4", "-o", "x.h5"], "--mean-overlap: expected"),
        (["packings", "--only", "rve-9-9"], "unknown standard packing"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(argv, message, tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x.h5").exists()


def test_info_on_foreign_and_missing_files(tmp_path, capsys):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    assert main(["info", str(foreign)]) == 2
    assert "not a gransim results file" in capsys.readouterr().err
    assert main(["info", str(tmp_path / "missing.h5")]) == 2
    assert "no such file" in capsys.readouterr().err
    text = tmp_path / "text.h5"
    text.write_text("hello")
    assert main(["info", str(text)]) == 2
    assert "not a readable HDF5 file" in capsys.readouterr().err
