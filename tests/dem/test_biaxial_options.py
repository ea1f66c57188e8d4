"""Every physical parameter of ``gransim biaxial`` is an option and the derived ones follow the final
values: the inertial number I = rate D50 sqrt(rho / p) of a run stays at the requested
value when the confining stress or the density changes, and the friction coefficient reaches the
engine (a sliding contact obeys |F_t| = mu |F_n| for the mu given, two values)."""

from __future__ import annotations

import numpy as np
import pytest

from gransim import Packing
from gransim.cli import build_parser, main
from gransim.cli.cmd_biaxial import protocol_settings
from gransim.dem import AxisControl, DEMEngine, Loading
from gransim.dem.biaxial import default_settings
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import read_run
from gransim.errors import InputError
from gransim.io import load_packing, save_packing

#: the quick protocol of the other CLI tests (few steps; the consolidation need not settle)
BASE = ["--consolidation-steps", "200", "--series-every", "50", "--snapshot-every", "100000", "--allow-unsettled"]


@pytest.fixture(scope="module")
def packing_file(tmp_path_factory):
    p = tmp_path_factory.mktemp("opts") / "p.h5"
    save_packing(p, lattice_packing(6, 6, seed=4, spread=0.1, compression=0.04))
    return p


def hand_inertial_number(packing, rate, p):
    """I = |rate| D50 sqrt(rho / p), written out here (D50: the packing's area-weighted median
    diameter; rho: mass per area, kg/m^2; p in N/m)."""
    return abs(rate) * packing.d50 * np.sqrt(packing.density / p)


def test_default_settings_derive_the_rate_from_the_final_pressure(packing_file):
    """At p and 4 p the default strain rate keeps I = 5e-5 (so it doubles); a requested I is met
    at any p; strain rate and inertial number together are refused."""
    pk = load_packing(packing_file)
    _, b1 = default_settings(pk, confining=10.0)
    _, b4 = default_settings(pk, confining=40.0)
    assert (b1.confining, b4.confining) == (10.0, 40.0)
    for b in (b1, b4):
        assert hand_inertial_number(pk, b.strain_rate, b.confining) == pytest.approx(5e-5, rel=1e-12)
    assert b4.strain_rate / b1.strain_rate == pytest.approx(2.0, rel=1e-12)
    _, b = default_settings(pk, confining=40.0, inertial_number=2e-4)
    assert hand_inertial_number(pk, b.strain_rate, 40.0) == pytest.approx(2e-4, rel=1e-12)
    with pytest.raises(InputError, match="strain_rate .* inertial_number"):
        default_settings(pk, strain_rate=0.1, inertial_number=1e-4)


@pytest.mark.parametrize(
    "extra, want_i, density_factor",
    [
        ([], 5e-5, 1.0),
        (["--inertial-number", "4e-4"], 4e-4, 1.0),
        (["--inertial-number", "4e-4", "--density", "10600"], 4e-4, 4.0),
    ],
)
def test_cli_run_keeps_the_inertial_number_when_the_pressure_changes(
    tmp_path, packing_file, extra, want_i, density_factor
):
    """The CLI runs at p = 25 N/m and 4 p = 100 N/m: the run files' strain rate, confining stress
    and packing give the requested I for both (the bug: --confining was applied after the rate
    had been derived from the default p, so I was off by sqrt(4) = 2 at 4 p)."""
    base = load_packing(packing_file)
    rates = {}
    for p in (25.0, 100.0):
        out = tmp_path / f"p{p:g}.h5"
        assert (
            main(
                [
                    "biaxial",
                    "--packing",
                    str(packing_file),
                    "-o",
                    str(out),
                    "--strain",
                    "2e-5",
                    "--confining",
                    f"{p!r}",
                    *BASE,
                    *extra,
                ]
            )
            == 0
        )
        run = read_run(out)
        bi = run.settings["biaxial"]
        assert bi["confining"] == p
        assert run.packing.density == pytest.approx(density_factor * base.density, rel=1e-15)
        assert hand_inertial_number(run.packing, bi["strain_rate"], p) == pytest.approx(want_i, rel=1e-12)
        assert np.all(run.series["stress"][run.series["phase"] == 1][:, 0, 0] < 0)  # compressed
        rates[p] = bi["strain_rate"]
    assert rates[100.0] / rates[25.0] == pytest.approx(2.0, rel=1e-12)


def _settings(packing_file, *options):
    args = build_parser().parse_args(["biaxial", "--packing", str(packing_file), *options])
    return protocol_settings(args, load_packing(packing_file))


def _sliding_contact(dem, vt_over_vn=20.0):
    """Two disks (radius R = 1 mm, density 2650 kg/m^2) colliding head-on along x with a large
    sliding velocity along y, undamped; the engine's per-step contact forces, decomposed along the line of centres:
    (|F_n|, |F_t|, sliding flags) of the steps in contact."""
    R = 1e-3
    pk = Packing(
        positions=np.array([[0.01, 0.01], [0.01 + 2 * R * 1.0001, 0.01]]),
        radii=np.array([R, R]),
        cell=np.eye(2) * 0.02,
        density=2650.0,
    )
    m_eff = 0.5 * pk.masses[0]
    vn = 1e-3 * R * np.sqrt(dem.kn / m_eff)  # undamped: the largest overlap is vn / omega = 1e-3 R
    v = np.array([[0.0, 0.0], [-vn, vt_over_vn * vn]])
    eng = DEMEngine(pk, dem, velocities=v)
    fixed = Loading(x=AxisControl("fixed"), y=AxisControl("fixed"))
    fn, ft, slide = [], [], []
    for _ in range(4000):
        eng.advance(fixed, 1)
        c = eng.contacts()
        if c["i"].size:
            l_ij = eng.x[c["j"][0]] + c["shift"][0] @ eng.cell.T - eng.x[c["i"][0]]
            n = l_ij / np.linalg.norm(l_ij)
            f = c["force"][0]
            fn.append(abs(f @ n))
            ft.append(abs(f[0] * n[1] - f[1] * n[0]))
            slide.append(bool(c["sliding"][0]))
        elif fn:
            break
    return np.array(fn), np.array(ft), np.array(slide)


@pytest.mark.parametrize("flavour", ["liggghts", "lammps"])
def test_mu_reaches_the_engine(packing_file, flavour):
    """--mu 0.2 and 0.6: the settings carry it, and in a contact that slides throughout (sliding
    speed 20x the approach speed) the engine's tangential force is mu times the normal force at
    every step (Coulomb cap; undamped, so both codes' caps agree), for each mu."""
    ratios = {}
    for mu in (0.2, 0.6):
        _, _, dem, _, _ = _settings(packing_file, "--mu", f"{mu!r}", "--damping-ratio", "0", "--flavour", flavour)
        assert dem.mu == mu and dem.kt == dem.kn
        fn, ft, slide = _sliding_contact(dem)
        assert len(fn) > 20 and slide.all()
        np.testing.assert_allclose(ft, mu * fn, rtol=1e-9)
        ratios[mu] = float(np.sum(ft) / np.sum(fn))
    assert ratios[0.6] / ratios[0.2] == pytest.approx(3.0, rel=1e-9)


def test_kt_ratio_and_mu_with_a_law(packing_file):
    """--kt-ratio sets kt = ratio kn; --mu is the law's mu too, and a different --law-param mu is
    refused (one friction coefficient per run)."""
    _, _, dem, _, _ = _settings(packing_file, "--kn", "2e5", "--kt-ratio", "0.25")
    assert (dem.kn, dem.kt) == (2e5, 5e4)
    _, _, dem, _, opts = _settings(packing_file, "--law", "hooke-liggghts", "--mu", "0.3")
    assert dem.mu == 0.3 and opts["params"]["mu"] == 0.3
    _, _, dem, _, opts = _settings(packing_file, "--law", "hooke-liggghts", "--law-param", "mu=0.35")
    assert dem.mu == 0.35 and opts["params"]["mu"] == 0.35
    with pytest.raises(InputError, match="mu"):
        _settings(packing_file, "--law", "hooke-liggghts", "--law-param", "mu=0.35", "--mu", "0.3")


@pytest.mark.parametrize(
    "options, needle",
    [
        (["--mu", "-0.1"], "--mu"),
        (["--kt-ratio", "nan"], "--kt-ratio"),
        (["--density", "0"], "--density"),
        (["--inertial-number=-1e-4"], "--inertial-number"),
        (["--confining", "0"], "--confining"),
        (["--consolidation-tol", "0"], "--consolidation-tol"),
    ],
)
def test_bad_options_are_one_line_exit_2(tmp_path, packing_file, capsys, options, needle):
    out = tmp_path / "x.h5"
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0] and not out.exists()


def test_strain_rate_and_inertial_number_exclude_each_other(tmp_path, packing_file, capsys):
    with pytest.raises(SystemExit) as e:
        main(
            [
                "biaxial",
                "--packing",
                str(packing_file),
                "-o",
                str(tmp_path / "x.h5"),
                "--strain-rate",
                "0.1",
                "--inertial-number",
                "1e-4",
            ]
        )
    assert e.value.code == 2 and "not allowed with" in capsys.readouterr().err
