"""Bad input on the command line (outside the DEM commands): one line, exit 2, before any long
computation; no traceback ever; resource limits."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import gransim._validate as validate
from gransim import Packing
from gransim.cli import build_parser, main
from gransim.errors import InputError, ResultFileError
from gransim.io import atomic_h5, load_packing, save_packing, write_packing_group

ROOT = Path(__file__).resolve().parents[2]


# ----------------------------------------------------------------------------------------------
# helpers
# ----------------------------------------------------------------------------------------------
def lattice(n_side: int = 4, swell: float = 1.03, coincide: bool = False) -> Packing:
    """Square lattice of n_side^2 disks (spacing 1 mm) whose neighbours overlap by ``swell``."""
    a = 1e-3
    ii, jj = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
    x = np.column_stack([ii.ravel(), jj.ravel()]) * a + 0.5 * a
    if coincide:
        x[1] = x[0]
    r = np.full(x.shape[0], 0.5 * a * swell)
    return Packing(positions=x, radii=r, cell=np.eye(2) * n_side * a)


def random_packing(n: int = 300, seed: int = 4, phi: float = 0.9) -> Packing:
    rng = np.random.default_rng(seed)
    r = rng.uniform(0.5e-3, 1.0e-3, n)
    side = np.sqrt(np.pi * np.sum(r**2) / phi)
    return Packing(positions=rng.random((n, 2)) * side, radii=r, cell=np.eye(2) * side)


def one_line_error(capsys, *fragments) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert "Traceback" not in err
    for f in fragments:
        assert f in err, (f, err)
    return err


@pytest.fixture
def no_compute(monkeypatch):
    """Every long computation of the commands fails the test if it is reached."""
    import gransim.fem.run
    import gransim.generation
    import gransim.rve.study

    def boom(*a, **k):
        raise AssertionError("the computation started before the inputs were checked")

    for mod, name in (
        (gransim.generation, "make_packing"),
        (gransim.generation, "compact_packing"),
        (gransim.generation, "standard_packings"),
        (gransim.rve.study, "run_study"),
        (gransim.fem.run, "run_slope_case"),
    ):
        monkeypatch.setattr(mod, name, boom)


@pytest.fixture
def packing_file(tmp_path):
    return save_packing(tmp_path / "lattice.h5", lattice())


# ----------------------------------------------------------------------------------------------
# 1. broken pipe, 2. no traceback
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("extra", [["--help"], ["rve-stress", "FILE"]])
def test_closed_output_pipe_ends_quietly(extra, packing_file):
    argv = [str(packing_file) if a == "FILE" else a for a in extra]
    proc = subprocess.Popen(
        [sys.executable, "-m", "gransim", *argv],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    proc.stdout.close()  # the reader is gone before the command writes (like `| head -0`)
    with proc.stderr:
        err = proc.stderr.read().decode()
    rc = proc.wait(timeout=120)
    assert "Traceback" not in err and "BrokenPipeError" not in err, err
    assert rc in (0, 141)


def test_shell_pipe_into_head(packing_file):
    gransim = ROOT / ".venv" / "bin" / "gransim"
    if not gransim.exists():
        pytest.skip("no .venv/bin/gransim")
    r = subprocess.run(
        f"{gransim} rve-stress {packing_file} | head -1",
        shell=True,
        check=False,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.stdout.startswith("packing: N = 16") and "Traceback" not in r.stderr


def _failing_handler(monkeypatch, exc):
    import gransim.cli.cmd_packings as mod

    def run(args):
        raise exc

    monkeypatch.setattr(mod, "_run", run)


def test_unexpected_exception_is_one_line(monkeypatch, capsys):
    monkeypatch.delenv("GRANSIM_TRACEBACK", raising=False)
    _failing_handler(monkeypatch, ZeroDivisionError("boom"))
    assert main(["packings"]) == 1
    one_line_error(
        capsys, "gransim packings: internal error: ZeroDivisionError: boom", "GRANSIM_TRACEBACK=1", "please report it"
    )


def test_traceback_on_request(monkeypatch, capsys):
    monkeypatch.setenv("GRANSIM_TRACEBACK", "1")
    _failing_handler(monkeypatch, KeyError("k"))
    assert main(["packings"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "internal error: KeyError" in err


def test_memory_error_and_interrupt(monkeypatch, capsys):
    monkeypatch.delenv("GRANSIM_TRACEBACK", raising=False)
    _failing_handler(monkeypatch, MemoryError())
    assert main(["packings"]) == 1
    err = one_line_error(capsys, "gransim packings: error: out of memory (MemoryError: no details)")
    assert "internal error" not in err
    _failing_handler(monkeypatch, KeyboardInterrupt())
    assert main(["packings"]) == 130
    one_line_error(capsys, "interrupted")


# ----------------------------------------------------------------------------------------------
# 3. output paths checked before the computation
# ----------------------------------------------------------------------------------------------
def test_output_paths_checked_first(tmp_path, capsys, no_compute):
    d = tmp_path / "adir"
    d.mkdir()
    f = tmp_path / "afile"
    f.write_text("x")
    cases = [
        (["pack", "--n", "50", "-o", str(d)], ["-o/--output", "is a directory"]),
        (["pack", "--n", "50", "-o", str(f / "x.h5")], ["-o/--output", "is not a directory"]),
        (
            ["pack", "--n", "50", "-o", str(tmp_path / "p.h5"), "--vtu", str(tmp_path / "p.txt")],
            ["--vtu", "expected one of .vtu"],
        ),
        (["pack", "--n", "50", "-o", ""], ["-o/--output", "empty"]),
        (["packings", "--out", str(f)], ["--out", "is not a directory"]),
        (["rve-study", "--packing-dir", str(d), "-o", str(f)], ["-o/--out", "is not a directory"]),
        (["rve-study", "--packing-dir", str(f)], ["--packing-dir", "is not a directory"]),
        (["rve-check", "--packing-dir", str(f)], ["--packing-dir", "is not a directory"]),
        (["slope", "--out", str(f)], ["--out", "is not a directory"]),
        (["slope", "--out", str(d), "--packing-dir", str(f)], ["--packing-dir"]),
        (["slope", "--out", str(d), "--packing", str(tmp_path / "missing.h5")], ["--packing", "no such file"]),
        (["rve-stress", str(tmp_path / "missing.h5")], ["no such file"]),
        (["rve-stress", str(d)], ["is a directory"]),
    ]
    for argv, fragments in cases:
        assert main(argv) == 2, argv
        one_line_error(capsys, *fragments)
    # an output file name inside -o that is taken by a directory
    (d / "rve_study.h5").mkdir()
    assert main(["rve-study", "--packing-dir", str(tmp_path), "-o", str(d)]) == 2
    one_line_error(capsys, "rve_study.h5", "is a directory")


def test_rve_study_packing_names_must_differ(tmp_path, capsys, no_compute):
    a = save_packing(tmp_path / "a" / "rve.h5", lattice())
    b = save_packing(tmp_path / "b" / "rve.h5", lattice())
    assert main(["rve-study", "--packings", str(a), str(b), "-o", str(tmp_path / "out")]) == 2
    one_line_error(capsys, "--packings", "both give the RVE name 'rve'")


def test_check_paths_library(tmp_path):
    from gransim.cli._paths import check_figure, check_output, check_output_dir

    assert check_figure(tmp_path / "new" / "fig.PNG") == tmp_path / "new" / "fig.PNG"
    with pytest.raises(InputError, match=r"--plot: .*'\.txt'; expected one of \.png"):
        check_figure(tmp_path / "x.txt")
    with pytest.raises(InputError, match="--plot: .* is a directory"):
        check_figure(tmp_path)
    assert check_output(tmp_path / "a" / "b" / "c.h5", "-o") == tmp_path / "a" / "b" / "c.h5"
    assert check_output_dir(tmp_path / "x" / "y", "--out") == tmp_path / "x" / "y"
    (tmp_path / "f").write_text("")
    with pytest.raises(InputError, match="--out: cannot create .*/f' is not a directory"):
        check_output_dir(tmp_path / "f" / "y", "--out")
    assert not (tmp_path / "a").exists() and not (tmp_path / "x").exists()  # checks create nothing


# ----------------------------------------------------------------------------------------------
# 4. broken HDF5 files
# ----------------------------------------------------------------------------------------------
def _write_packing(path, **override):
    """A packing file like save_packing writes, with some datasets/attributes replaced."""
    p = lattice()
    with atomic_h5(path, kind="packing") as f:
        g = f.create_group("packing")
        write_packing_group(g, p)
        for k, v in override.items():
            if k in g.attrs and k in ("metadata", "density"):
                g.attrs[k] = v
            else:
                del g[k]
                if isinstance(v, str) and v == "group":
                    g.create_group(k)
                else:
                    g[k] = v
    return path


@pytest.mark.parametrize(
    "override, fragments",
    [
        ({"metadata": "{not json"}, ["packing", "attribute 'metadata' is not valid JSON"]),
        ({"metadata": "[1, 2]"}, ["attribute 'metadata' must hold a JSON object"]),
        ({"density": "heavy"}, ["attribute 'density' is not a number"]),
        ({"positions": np.zeros((16, 3))}, [":/packing", "positions: expected shape (N, 2), got (16, 3)"]),
        ({"positions": np.zeros(16)}, ["/packing/positions: expected 2 dimension(s)"]),
        ({"radii": -np.ones(16)}, ["not a valid packing", "radii: must be > 0"]),
        ({"radii": np.ones(5)}, ["not a valid packing", "radii: expected shape (16), got (5,)"]),
        ({"cell": np.array([[1.0, 2.0], [2.0, 4.0]])}, ["cell: degenerate"]),
        ({"positions": np.full((16, 2), np.nan)}, ["positions: contains NaN"]),
        ({"positions": "group"}, ["/packing/positions: expected a dataset, found a Group"]),
        ({"radii": np.array([b"a"] * 16)}, ["/packing/radii: expected numbers"]),
    ],
)
def test_malformed_packing_file(tmp_path, capsys, override, fragments):
    path = _write_packing(tmp_path / "bad.h5", **override)
    with pytest.raises(ResultFileError) as exc:
        load_packing(path)
    msg = str(exc.value)
    assert str(path) in msg
    for f in fragments:
        assert f in msg, (f, msg)
    assert main(["rve-stress", str(path)]) == 2
    one_line_error(capsys, str(path), fragments[-1])


def test_foreign_and_non_hdf5_files(tmp_path, capsys):
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["positions"] = np.zeros((3, 2))
    text = tmp_path / "text.h5"
    text.write_text("not hdf5")
    nogroup = tmp_path / "nogroup.h5"
    with atomic_h5(nogroup, kind="packing") as f:
        f["packing"] = 1.0  # a dataset where the group should be
    for path, frag in (
        (foreign, "not a gransim results file"),
        (text, "not a readable HDF5 file"),
        (nogroup, "no group 'packing'"),
    ):
        with pytest.raises(ResultFileError, match=frag):
            load_packing(path)
        assert main(["rve-stress", str(path)]) == 2
        one_line_error(capsys, str(path), frag)


@pytest.fixture
def study_file(tmp_path):
    """A minimal rve-study file: two RVE packings under /rves (what rve-stress reads)."""
    path = tmp_path / "study.h5"
    with atomic_h5(path, kind="rve-study") as f:
        g = f.create_group("rves")
        g.create_dataset("names", data=np.array(["alpha", "beta"], dtype="S"))
        for name in ("alpha", "beta"):
            write_packing_group(g.create_group(name), lattice())
    return path


def test_rve_option(study_file, packing_file, capsys):
    assert main(["rve-stress", str(study_file)]) == 2
    one_line_error(capsys, "--rve NAME", "alpha, beta")
    assert main(["rve-stress", str(study_file), "--rve", "gamma"]) == 2
    one_line_error(capsys, "--rve", "no RVE 'gamma'", "alpha, beta")
    assert main(["rve-stress", str(study_file), "--rve", "beta"]) == 0
    assert "packing: N = 16" in capsys.readouterr().out
    assert main(["rve-stress", str(packing_file), "--rve", "alpha"]) == 2
    one_line_error(capsys, "--rve applies to rve-study files", "'packing'")


# ----------------------------------------------------------------------------------------------
# 5. memory of a packing, --n parsing
# ----------------------------------------------------------------------------------------------
def test_n_parsing():
    parser = build_parser()
    assert parser.parse_args(["pack", "--n", "1e5", "-o", "x.h5"]).n == 100_000
    assert parser.parse_args(["pack", "--n", "700", "-o", "x.h5"]).n == 700
    for bad in ("1.5", "nan", "inf", "ten", "1e400"):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(["pack", "--n", bad, "-o", "x.h5"])
        assert exc.value.code == 2


def test_n_parsing_message(capsys):
    with pytest.raises(SystemExit):
        main(["pack", "--n", "1.5", "-o", "x.h5"])
    assert "argument --n: expected an integer, got '1.5'" in capsys.readouterr().err


def test_huge_packing_refused_before_allocation(tmp_path, capsys, no_compute):
    assert main(["pack", "--n", "1e12", "-o", str(tmp_path / "p.h5")]) == 2
    err = one_line_error(capsys, "--n: a packing of 1e+12 disks needs about 2.5 PB", "available")
    assert "PB" in err or "TB" in err


def test_huge_packing_refused_by_the_library():
    from gransim.generation import make_packing

    with pytest.raises(InputError, match=r"n: a packing of 1e\+12 disks needs about .* of memory"):
        make_packing("quartz-sand", 10**12, 1)


def test_packing_near_the_memory_limit_warns(tmp_path, capsys, monkeypatch):
    import gransim.generation
    from gransim.generation.pack import PACKING_BYTES_PER_DISK

    monkeypatch.setattr(validate, "available_memory", lambda: int(1.5 * PACKING_BYTES_PER_DISK * 10**6))

    def stop(*a, **k):
        raise InputError("stub: stop here")

    monkeypatch.setattr(gransim.generation, "make_packing", stop)
    assert main(["pack", "--n", "1e6", "-o", str(tmp_path / "p.h5")]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "gransim pack: warning: --n 1000000 needs about 67% of the available memory"
    assert "stub" in lines[1]
    assert main(["pack", "--n", "2e6", "-o", str(tmp_path / "p.h5")]) == 2
    one_line_error(capsys, "--n: a packing of 2e+06 disks needs about 5 GB", "3.75 GB available")


def test_available_memory_is_plausible():
    avail = validate.available_memory()
    assert avail is not None and 1e8 < avail <= os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


def test_measured_bytes_per_disk_cover_a_real_packing():
    """The figure of PACKING_BYTES_PER_DISK against the peak RSS of make_packing at N = 1e4."""
    from gransim.generation.pack import PACKING_BYTES_PER_DISK

    code = (
        "from bench._memory import own_peak_kib\n"
        "from gransim.generation import make_packing\n"
        "make_packing('quartz-sand', 200, 1, residual='rms', force_tol=1e-2)\n"
        "base = own_peak_kib()\n"
        "make_packing('quartz-sand', 10000, 1, residual='rms', force_tol=1e-2)\n"
        "print((own_peak_kib() - base) * 1024 / 10000)\n"
    )
    r = subprocess.run(
        [sys.executable, "-c", code],
        check=False,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    per_disk = float(r.stdout.split()[-1])
    assert 100 < per_disk < PACKING_BYTES_PER_DISK, per_disk


# ----------------------------------------------------------------------------------------------
# 6. rve-stress: coincident disks, extreme F, non-finite results
# ----------------------------------------------------------------------------------------------
def test_coincident_disks(tmp_path, capsys):
    from gransim.rve import TaylorMaterial, homogenize

    p = lattice(coincide=True)
    with pytest.raises(InputError, match=r"disks 0 and 1 have coincident centres"):
        homogenize(p, np.eye(2), 1e6)
    with pytest.raises(InputError, match="coincident"):
        TaylorMaterial(p, 1e6).evaluate(np.eye(2))
    path = save_packing(tmp_path / "coincide.h5", p)
    assert main(["rve-stress", str(path)]) == 2
    out, err = capsys.readouterr()
    assert "disks 0 and 1 have coincident centres" in err and err.count("\n") == 1
    assert out == ""  # no P = nan printed


@pytest.mark.parametrize(
    "F, fragments",
    [
        (["1e-9", "0", "0", "1"], ["--F", "collapses the RVE", "shortest lattice vector"]),
        (["0.2", "0", "0", "1"], ["--F", "collapses the RVE"]),  # cell 0.8 mm < disk 1.03 mm
        (["1", "0", "0", "-1"], ["--F", "det F must be > 0 and finite", "-1"]),
        (["1", "1", "1", "1"], ["--F", "det F must be > 0 and finite"]),
        (["nan", "0", "0", "1"], ["--F: expected finite entries"]),
        (["1e200", "0", "0", "1e200"], ["--F"]),
    ],
)
def test_bad_deformation_gradient(packing_file, capsys, F, fragments):
    assert main(["rve-stress", str(packing_file), "--F", *F]) == 2
    one_line_error(capsys, *fragments)


def test_candidate_estimate_matches_the_search():
    from gransim.contacts import find_neighbours
    from gransim.rve.taylor import DEFAULT_SKIN_FRACTION, estimate_candidates

    p = random_packing()
    skin = 2 * DEFAULT_SKIN_FRACTION * p.radii.max()
    for F in ([[1, 0], [0, 1]], [[0.3, 0], [0, 1.2]], [[1, 0.4], [0, 1]], [[0.1, 0.05], [0, 1]]):
        F = np.array(F, float)
        est = estimate_candidates(p, F)["pairs"]
        got = len(find_neighbours(p.positions @ F.T, p.radii, F @ p.cell, skin))
        assert 0.6 < est / got < 1.6, (F, est, got)


def test_candidate_budget_refuses_with_the_estimate(monkeypatch, capsys, tmp_path):
    from gransim.rve import TaylorMaterial
    from gransim.rve.taylor import estimate_candidates

    p = random_packing()
    F = np.diag([0.1, 1.0])  # the cell (24.7 mm) shrinks to 2.5 mm, above the largest disk (2 mm)
    need = estimate_candidates(p, F)["bytes"]
    monkeypatch.setattr(validate, "available_memory", lambda: int(need / 2))
    with pytest.raises(InputError, match=r"F: the contact candidates of [0-9.e+]+ periodic image pairs"):
        TaylorMaterial(p, 1e6).evaluate(F)
    TaylorMaterial(p, 1e6).evaluate(np.eye(2))  # the identity needs 10x less
    path = save_packing(tmp_path / "rand.h5", p)
    assert main(["rve-stress", str(path), "--F", "0.1", "0", "0", "1"]) == 2
    one_line_error(capsys, "--F: the contact candidates of", "available")


def test_non_finite_result_is_an_error(packing_file, capsys, monkeypatch):
    import gransim.rve
    from gransim.rve import TaylorResult

    nan = np.full((2, 2), np.nan)
    monkeypatch.setattr(
        gransim.rve,
        "homogenize",
        lambda *a: TaylorResult(
            energy=np.nan, piola=nan, tangent=np.full((2, 2, 2, 2), np.nan), cauchy=nan, n_contacts=3
        ),
    )
    assert main(["rve-stress", str(packing_file)]) == 2
    one_line_error(capsys, "non-finite result")
    assert capsys.readouterr().out == ""


def test_good_rve_stress_still_works(packing_file, capsys):
    assert main(["rve-stress", str(packing_file), "--F", "0.99", "0", "0", "1", "--kn", "1e6"]) == 0
    out = capsys.readouterr().out
    assert "active contacts: 32" in out and "nan" not in out


# ----------------------------------------------------------------------------------------------
# 7. numeric options
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "argv, fragment",
    [
        (["pack", "--n", "-5"], "--n: expected an integer >= 2, got -5"),
        (["pack", "--n", "50", "--seed", "-1"], "--seed: expected an integer >= 0"),
        (["pack", "--n", "50", "--seed", "1e30"], "--seed"),
        (["pack", "--n", "50", "--density", "nan"], "--density: expected a finite number > 0"),
        (["pack", "--n", "50", "--density", "0"], "--density"),
        (["pack", "--n", "50", "--mean-diameter", "inf"], "--mean-diameter"),
        (["pack", "--n", "50", "--mean-overlap", "0.2"], "--mean-overlap: expected a finite number > 0 and <= 0.05"),
        (["pack", "--n", "50", "--solid-fraction", "nan"], "--solid-fraction"),
        (["pack", "--n", "50", "--force-tol", "0"], "--force-tol"),
        (["pack", "--n", "50", "--friction", "nan"], "--friction"),
        (
            ["pack", "--n", "50", "--friction", "0.1", "--pressure", "2"],
            "--pressure: expected a finite number > 0 and < 1",
        ),
        (["rve-study", "--steps", "0"], "--steps: expected an integer >= 1 and <= 100000"),
        (["rve-study", "--steps", "1e9"], "--steps"),
        (["rve-study", "--kn", "-1"], "--kn: expected a finite number > 0"),
        (["rve-study", "--kn", "inf"], "--kn"),
        (["rve-check", "--tol", "nan"], "--tol: expected a finite number >= 0"),
        (["rve-check", "--kn", "0"], "--kn"),
        (["rve-stress", "FILE", "--kn", "nan"], "--kn"),
        (["slope", "--tol", "nan"], "--tol: expected a finite number > 0 and < 1"),
        (["slope", "--tol", "0"], "--tol"),
        (["slope", "--min-fraction", "0"], "--min-fraction"),
        (["slope", "--min-fraction", "2"], "--min-fraction: expected a finite number > 0 and <= 1"),
    ],
)
def test_bad_numeric_option(argv, fragment, tmp_path, capsys, monkeypatch, no_compute, packing_file):
    monkeypatch.chdir(tmp_path)
    argv = [str(packing_file) if a == "FILE" else a for a in argv]
    if argv[0] == "pack":
        argv += ["-o", "x.h5"]
    assert main(argv) == 2
    one_line_error(capsys, fragment)
    assert not (tmp_path / "x.h5").exists() and not (tmp_path / "results").exists()


def test_metadata_round_trip_is_json(tmp_path):
    """The metadata attribute save_packing writes is the JSON that load_packing accepts."""
    p = lattice().replace(metadata={"seed": 3, "note": "x"})
    path = save_packing(tmp_path / "m.h5", p)
    with h5py.File(path) as f:
        assert json.loads(f["packing"].attrs["metadata"]) == {"seed": 3, "note": "x"}
    assert dict(load_packing(path).metadata) == {"seed": 3, "note": "x"}


def test_bad_sieve_curve_names_the_file(tmp_path, capsys, monkeypatch, no_compute):
    monkeypatch.chdir(tmp_path)
    Path("curve.csv").write_text("size_mm,passing\n0.1,0\n0.2,50\n0.15,100\n")
    Path("text.csv").write_text("size_mm,passing\n0.1,0\nfine,50\n")
    assert main(["pack", "--n", "50", "--distribution", "curve.csv", "-o", "x.h5"]) == 2
    one_line_error(capsys, "curve.csv: diameters: must be strictly increasing (d[1] = 0.0002 >= d[2] = 0.00015)")
    assert main(["pack", "--n", "50", "--distribution", "text.csv", "-o", "x.h5"]) == 2
    one_line_error(capsys, "text.csv: cannot parse line 'fine,50'")
