"""Faults of the DEM: the stability limit with damping, unsettled consolidations,
divergence detection, readers that refuse unfinished or truncated run files, and clear messages
(exit 2) for bad options, all on small packings (<= 100 disks, a few thousand steps)."""

from __future__ import annotations

import dataclasses
import shutil

import h5py
import numpy as np
import pytest

from gransim import Packing
from gransim.cli import main
from gransim.dem import DEMEngine, DEMSettings, Loading, contact_time, stability_limit
from gransim.dem.biaxial import default_settings
from gransim.dem.lattice import lattice_packing
from gransim.dem.output import (
    OutputSettings,
    plot_stress_strain,
    read_record,
    read_run,
    require_complete,
    snapshot_to_vtu,
)
from gransim.dem.run import Phase, run_phases
from gransim.errors import ConvergenceError, InputError, ResultFileError, SimulationError
from gransim.io import save_packing
from gransim.voidcell.io import load_run_snapshots

NO_FILES = OutputSettings(series_every=5, snapshot_every=0, checkpoint_every=0)


@pytest.fixture(scope="module")
def packing():
    return lattice_packing(8, 8, seed=2, spread=0.1, compression=0.04)


@pytest.fixture(scope="module")
def packing_file(packing, tmp_path_factory):
    return save_packing(tmp_path_factory.mktemp("pk") / "p.h5", packing)


def _biaxial(packing, out, stop_at_step=None, allow_unsettled=True, consolidation_steps=2000):
    """A short biaxial run: 2000 consolidation steps (not settled), ~860 compression steps."""
    dem, bi = default_settings(packing, kn=1e5, strain=0.001, strain_rate=0.1)
    bi = dataclasses.replace(bi, consolidation_steps=consolidation_steps, check_every=500)
    from gransim.dem.biaxial import biaxial_phases

    run_phases(
        packing,
        dem,
        biaxial_phases(dem, bi),
        out,
        OutputSettings(series_every=5, snapshot_every=100, checkpoint_every=0),
        show_progress=False,
        metadata={"biaxial": dataclasses.asdict(bi)},
        stop_at_step=stop_at_step,
        allow_unsettled=allow_unsettled,
    )
    return out


@pytest.fixture(scope="module")
def good_run(packing, tmp_path_factory):
    return _biaxial(packing, tmp_path_factory.mktemp("good") / "run.h5")


@pytest.fixture(scope="module")
def killed_run(packing, tmp_path_factory):
    """The same run stopped in its compression phase: complete = False."""
    return _biaxial(packing, tmp_path_factory.mktemp("killed") / "run.h5", stop_at_step=2400)


# ---------------------------------------------------------------- 1. stability limit with damping
def _lightest_pair_omega(p, k):
    m = np.sort(np.pi * p.radii**2 * p.density)
    meff = m[0] * m[1] / (m[0] + m[1])
    return np.sqrt(k / meff)


def test_stability_limit_decreases_with_damping_as_the_formula(packing):
    k = 1e5
    w = _lightest_pair_omega(packing, k)
    tc = np.pi / w  # contact time of the lightest pair
    lims = []
    for zeta in (0.0, 0.1, 0.3, 1.0, 5.0):
        s = DEMSettings(kn=k, kt=k, gamma_n=2 * zeta * w, gamma_t=2 * zeta * w)  # gamma = 2 zeta omega
        lim = stability_limit(packing, s)
        assert lim == pytest.approx(tc / 5 * (np.sqrt(1 + zeta**2) - zeta), rel=1e-10)
        lims.append(lim)
    assert lims[0] == pytest.approx(contact_time(packing, k) / 5, rel=1e-12)  # the undamped margin kept
    assert all(a > b for a, b in zip(lims, lims[1:]))
    assert lims[-1] < lims[0] / 10  # zeta = 5: sqrt(26) - 5 = 0.099


def _chain(a, r=1e-3, overlap=2e-5):
    """4 equal disks in a periodic row along x, each pre-compressed by ``overlap`` against its two
    neighbours, with the alternating mode excited by a displacement +-a."""
    s = 2 * r - overlap
    x = np.array([[(i + 0.5) * s + a * (-1) ** i, 4 * r] for i in range(4)])
    return Packing(positions=x, radii=[r] * 4, cell=np.diag([4 * s, 8 * r]), density=2650.0)


def test_damped_spring_grows_above_the_critical_step_and_decays_below():
    # independent check of dt_c = (2/omega)(sqrt(1 + zeta^2) - zeta) with the engine's integrator:
    # alternating mode of the chain, m u'' + 4 c u' + 4 k u = 0 with c = m_eff gamma, m_eff = m/2,
    # so omega = 2 sqrt(k/m) and zeta = gamma / omega
    r, k, zeta = 1e-3, 1e5, 0.5
    m = np.pi * r * r * 2650.0
    w = 2 * np.sqrt(k / m)
    dtc = 2 / w * (np.sqrt(1 + zeta**2) - zeta)
    assert 1.05 * dtc < 2 / w  # the undamped limit would accept the unstable step
    x_eq = _chain(0.0).positions[:, 0]
    sign = np.array([1, -1, 1, -1])
    growth = {}
    for f in (0.95, 1.05):
        a0 = 2e-8
        s = DEMSettings(kn=k, kt=0.0, gamma_n=zeta * w, gamma_t=0.0, mu=0.0, dt=f * dtc, skin=1e-5)
        eng = DEMEngine(_chain(a0), s, check_dt=False)
        eng.advance(Loading(), 40)
        growth[f] = abs(np.mean((eng.x[:, 0] - x_eq) * sign)) / a0
        if f > 1:
            with pytest.raises(SimulationError, match=r"step \d+: particle \d+ lost|kinetic energy"):
                eng.advance(Loading(), 200)  # and the run blows up
    assert growth[0.95] < 1e-3
    assert growth[1.05] > 10


def test_engine_refuses_the_undamped_step_when_damped(packing):
    k = 1e5
    w = _lightest_pair_omega(packing, k)
    s = DEMSettings(kn=k, kt=k, gamma_n=2 * w, gamma_t=2 * w, dt=contact_time(packing, k) / 6, skin=2e-5)
    with pytest.raises(InputError, match=r"stability limit.*damping ratio zeta = 1"):
        DEMEngine(packing, s)  # tc/6 was accepted by the undamped limit tc/5


def test_cli_refuses_a_step_above_the_damped_limit(packing_file, tmp_path, capsys):
    out = tmp_path / "b.h5"
    rc = main(
        ["biaxial", "--packing", str(packing_file), "-o", str(out), "--steps-per-contact", "5", "--damping-ratio", "1"]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "--steps-per-contact 5 with --damping-ratio 1" in err and "use --steps-per-contact >=" in err
    assert not out.exists()


# ---------------------------------------------------------------- 2. unsettled consolidation
def test_unsettled_consolidation_stops_the_run(packing, tmp_path):
    out = tmp_path / "u.h5"
    with pytest.raises(ConvergenceError, match=r"consolidation did not settle within 2000 steps: sigma_11/p = "):
        _biaxial(packing, out, allow_unsettled=False)
    run = read_run(out)
    assert not run.complete and run.stop_reason.startswith("consolidation did not settle within 2000 steps")
    assert run.series["step"][-1] == 2000 and not np.any(run.series["phase"] == 1)  # no compression
    # continuing it with allow_unsettled finishes the run and records the unsettled phase
    _biaxial(packing, out, allow_unsettled=True)  # a fresh run (no resume): the same trajectory
    run = read_run(out)
    assert run.complete and run.stop_reason == ""
    assert [u["name"] for u in run.unsettled_phases] == ["consolidation"]
    assert "did not settle within 2000 steps" in run.unsettled_phases[0]["reason"]


def test_resume_an_unsettled_run_with_allow_unsettled(packing, tmp_path, good_run):
    out = tmp_path / "u.h5"
    with pytest.raises(ConvergenceError):
        _biaxial(packing, out, allow_unsettled=False)
    dem, bi = default_settings(packing, kn=1e5, strain=0.001, strain_rate=0.1)
    bi = dataclasses.replace(bi, consolidation_steps=2000, check_every=500)
    from gransim.dem.biaxial import biaxial_phases

    run_phases(
        packing,
        dem,
        biaxial_phases(dem, bi),
        out,
        OutputSettings(series_every=5, snapshot_every=100, checkpoint_every=0),
        show_progress=False,
        metadata={"biaxial": dataclasses.asdict(bi)},
        resume=True,
        allow_unsettled=True,
    )
    a, b = read_run(out), read_run(good_run)
    assert a.complete and [u["name"] for u in a.unsettled_phases] == ["consolidation"]
    np.testing.assert_array_equal(a.series["stress"], b.series["stress"])  # bit for bit


def test_cli_unsettled_exit_2_and_info(packing_file, tmp_path, capsys):
    out = tmp_path / "b.h5"
    args = [
        "biaxial",
        "--packing",
        str(packing_file),
        "-o",
        str(out),
        "--strain",
        "0.001",
        "--strain-rate",
        "0.1",
        "--consolidation-steps",
        "1000",
        "--snapshot-every",
        "500",
    ]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "consolidation did not settle within 1000 steps: sigma_11/p = " in err and "--allow-unsettled" in err
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "complete               False  INCOMPLETE RUN: consolidation did not settle" in text
    assert main(args + ["--allow-unsettled", "--resume"]) == 0
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "complete               True" in text and "UNSETTLED phase        consolidation" in text


# ---------------------------------------------------------------- 3. divergence
def test_kinetic_energy_blow_up_is_detected():
    p = lattice_packing(10, 10, seed=1, spread=0.1, compression=0.002)
    s = DEMSettings(kn=1e5, kt=1e5, mu=0.5, dt=0.6 * contact_time(p, 1e5), skin=3e-4)  # 3 times the limit
    eng = DEMEngine(p, s, check_dt=False)
    with pytest.raises(SimulationError, match=r"step \d+: kinetic energy blow-up: .* exceeds 10 times"):
        eng.advance(Loading(), 3000)
    # the same packing at a stable (undamped, above the accepted) step runs 3000 steps untouched
    eng = DEMEngine(p, dataclasses.replace(s, dt=0.4 * contact_time(p, 1e5)), check_dt=False)
    eng.advance(Loading(), 3000)


def test_particle_moving_more_than_a_skin_in_one_step_is_lost(tmp_path):
    p = lattice_packing(6, 6, seed=0)
    s = DEMSettings(kn=1e5, kt=1e5, dt=2e-6, skin=2e-5)
    v = np.zeros((p.n, 2))
    v[4, 1] = 2.0 * s.skin / s.dt  # two skins in one step, well inside the cell
    out = tmp_path / "lost.h5"
    with pytest.raises(SimulationError, match=r"step 1: particle 4 lost: it moved .* 2 skins"):
        run_phases(p, s, [Phase("load", Loading(), 100)], out, NO_FILES, velocities=v, show_progress=False)
    run = read_run(out)
    assert not run.complete and "particle 4 lost" in run.stop_reason


def test_nan_velocity_is_reported_with_step_and_particle(tmp_path):
    p = lattice_packing(6, 6, seed=0)
    s = DEMSettings(kn=1e5, kt=1e5, dt=2e-6, skin=2e-5)
    v = np.zeros((p.n, 2))
    v[3, 0] = np.nan
    with pytest.raises(InputError, match="velocities: expected finite numbers"):
        DEMEngine(p, s, velocities=v)  # a NaN given is refused at the boundary
    eng = DEMEngine(p, s)
    eng.v[3, 0] = np.nan  # a NaN that appears in the state stops the run naming step and particle
    with pytest.raises(SimulationError, match=r"step 1: particle 3"):
        eng.advance(Loading(), 5)


# ---------------------------------------------------------------- 4. readers of unfinished runs
def test_library_readers_of_an_unfinished_run(killed_run, tmp_path):
    run = read_run(killed_run)
    assert not run.complete and "stopped at step 2400 by stop_at_step" in run.stop_reason
    rec = read_record(killed_run)
    assert not rec.complete and rec.stop_reason == run.stop_reason
    with pytest.raises(ResultFileError, match=r"run.h5: incomplete run \(complete = False\): stopped at step 2400"):
        require_complete(run)
    with pytest.raises(ResultFileError, match="incomplete run"):
        snapshot_to_vtu(killed_run, None, tmp_path / "s.vtu")
    with pytest.raises(ResultFileError, match="incomplete run"):
        plot_stress_strain(killed_run, tmp_path / "f.png")
    with pytest.raises(ResultFileError, match="incomplete run.*allow-incomplete"):
        load_run_snapshots(killed_run, [1e-4])
    assert load_run_snapshots(killed_run, [1e-4], allow_incomplete=True)[0].step > 2000
    assert plot_stress_strain(killed_run, tmp_path / "f.png", allow_incomplete=True).exists()


def test_cli_readers_of_an_unfinished_run(killed_run, tmp_path, capsys):
    for argv in (
        ["dem-export", str(killed_run), "--vtu", str(tmp_path / "s.vtu")],
        ["voidcells", str(killed_run), "--strain", "0.0001", "--out", str(tmp_path / "vc")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert str(killed_run) in err and "stopped at step 2400" in err and "--allow-incomplete" in err
        assert err.count("\n") == 1  # one line, no traceback
    assert not (tmp_path / "s.vtu").exists() and not (tmp_path / "vc").exists()
    assert main(["dem-export", str(killed_run), "--vtu", str(tmp_path / "s.vtu"), "--allow-incomplete"]) == 0
    assert "WARNING" in capsys.readouterr().out and (tmp_path / "s.vtu").exists()
    assert (
        main(
            [
                "voidcells",
                str(killed_run),
                "--strain",
                "0.0001",
                "--out",
                str(tmp_path / "vc"),
                "--no-vtk",
                "--allow-incomplete",
            ]
        )
        == 0
    )
    assert "incomplete run" in capsys.readouterr().out
    assert main(["info", str(killed_run)]) == 0
    assert "False  INCOMPLETE RUN: stopped at step 2400" in capsys.readouterr().out


def test_readers_accept_the_finished_run(good_run, tmp_path, capsys):
    assert main(["dem-export", str(good_run), "--vtu", str(tmp_path / "s.vtu"), "--plot", str(tmp_path / "f.png")]) == 0
    assert main(["voidcells", str(good_run), "--strain", "0.0005", "--out", str(tmp_path / "vc"), "--no-vtk"]) == 0
    capsys.readouterr()
    assert main(["info", str(good_run)]) == 0
    text = capsys.readouterr().out
    assert "complete               True" in text and "series_every" in text


# ---------------------------------------------------------------- 5. truncated / corrupt files
def _copy(src, dst, edit):
    shutil.copy(src, dst)
    with h5py.File(dst, "r+") as f:
        edit(f)
    return dst


def _cut_series(f):
    f["series/stress"].resize(f["series/stress"].shape[0] - 7, axis=0)


def _cut_snapshot(f):
    name = sorted(f["snapshots"])[-2]
    x = f[f"snapshots/{name}/positions"][()]
    del f[f"snapshots/{name}/positions"]
    f[f"snapshots/{name}/positions"] = x[:-3]


def _bad_settings(f):
    f.attrs["settings"] = '{"dem": {"kn": 1e5'


@pytest.mark.parametrize(
    "edit, what",
    [
        (_cut_series, r"/series/stress has \d+ rows, /series/step has"),
        (_cut_snapshot, r"/positions has shape \(61, 2\), expected \(64, 2\)"),
        (_bad_settings, r"attribute 'settings' of / is not valid JSON"),
    ],
)
def test_truncated_or_corrupt_run_files(good_run, tmp_path, capsys, edit, what):
    bad = _copy(good_run, tmp_path / "bad.h5", edit)
    for reader in (read_run, read_record):
        with pytest.raises(ResultFileError, match=what):
            reader(bad)
    assert main(["dem-export", str(bad), "--vtu", str(tmp_path / "s.vtu"), "--plot", str(tmp_path / "f.png")]) == 2
    err = capsys.readouterr().err
    assert "bad.h5" in err and "Traceback" not in err
    if edit is not _bad_settings:  # the void-cell reader does not use the settings
        assert main(["voidcells", str(bad), "--strain", "0.0005", "--out", str(tmp_path / "vc")]) == 2
        err = capsys.readouterr().err
        assert "bad.h5" in err and ("/series/stress" if edit is _cut_series else "/positions") in err
    assert main(["info", str(bad)]) == 2


def test_voidcells_series_truncated(good_run, tmp_path, capsys):
    bad = _copy(good_run, tmp_path / "bad.h5", lambda f: f["series/cell"].resize(10, axis=0))
    assert main(["voidcells", str(bad), "--strain", "0.0005", "--out", str(tmp_path / "vc")]) == 2
    assert "/series/cell has 10 rows" in capsys.readouterr().err


# ---------------------------------------------------------------- 5. messages for bad options
@pytest.mark.parametrize(
    "option, value",
    [
        ("--kn", "0"),
        ("--kn", "-1e5"),
        ("--strain", "0"),
        ("--strain", "-0.01"),
        ("--strain", "0.7"),
        ("--confining", "0"),
        ("--confining", "-5"),
        ("--strain-rate", "0"),
        ("--strain-rate", "-1"),
        ("--steps-per-contact", "0"),
        ("--steps-per-contact", "-50"),
        ("--damping-ratio", "-0.3"),
        ("--consolidation-steps", "0"),
        ("--consolidation-steps", "-10"),
        ("--series-every", "0"),
        ("--series-every", "-1"),
        ("--snapshot-every", "0"),
        ("--snapshot-every", "-5"),
        ("--checkpoint-every", "-1"),
        ("--threads", "0"),
        ("--threads", "-2"),
        ("--kn", "nan"),
    ],
)
def test_cli_biaxial_bad_numbers_name_the_option(packing_file, tmp_path, capsys, option, value):
    out = tmp_path / "b.h5"
    assert main(["biaxial", "--packing", str(packing_file), "-o", str(out), f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert f"error: {option}" in err and "gamma_n" not in err
    assert not out.exists()


@pytest.mark.parametrize(
    "argv, message",
    [
        (["-o", "{tmp}"], "-o/--output: .* is a directory"),
        (["--plot", "{tmp}/x.txt"], "--plot: .*x.txt' has suffix '.txt'"),
        (["-o", "{tmp}/nodir/sub/x.h5", "--plot", "{tmp}"], "--plot: .* is a directory"),
    ],
)
def test_cli_biaxial_bad_outputs_before_computing(packing_file, tmp_path, capsys, argv, message):
    argv = [a.format(tmp=tmp_path) for a in argv]
    assert main(["biaxial", "--packing", str(packing_file), *argv]) == 2
    import re

    assert re.search(message, capsys.readouterr().err)


def test_library_damping_message_names_the_damping_ratio(packing):
    with pytest.raises(InputError, match="damping_ratio"):
        default_settings(packing, damping_ratio=-1.0)
    with pytest.raises(InputError, match="steps_per_contact"):
        default_settings(packing, steps_per_contact=0.0)


def test_dem_export_bad_outputs(good_run, tmp_path, capsys):
    assert main(["dem-export", str(good_run), "--plot", str(tmp_path / "x.txt")]) == 2
    assert "--plot" in capsys.readouterr().err
    assert main(["dem-export", str(good_run), "--vtu", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "--vtu" in err and "is a directory" in err
    assert main(["dem-export", str(good_run), "--vtu", str(tmp_path / "x.png")]) == 2
    assert "expected one of .vtu" in capsys.readouterr().err


@pytest.mark.parametrize(
    "strain, message",
    [
        ("nan", "--strain: nan is not a finite number"),
        ("inf", "--strain: inf is not a finite number"),
        ("0.05", r"strain 0.05 is outside the range of the run: .* cover "),
        ("-0.01", r"strain -0.01 is outside the range"),
    ],
)
def test_voidcells_rejects_strains_outside_the_run(good_run, tmp_path, capsys, strain, message):
    import re

    assert main(["voidcells", str(good_run), "--strain", strain, "--out", str(tmp_path / "vc")]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not (tmp_path / "vc").exists()


def test_resume_with_another_sampling_is_refused(packing, tmp_path, packing_file, capsys):
    s = DEMSettings(kn=1e5, kt=1e5, gamma_n=50.0, gamma_t=50.0, dt=2e-6, skin=2e-5)
    ph = [Phase("load", Loading(), 400)]
    out = tmp_path / "r.h5"
    run_phases(
        packing, s, ph, out, OutputSettings(series_every=2, snapshot_every=100), stop_at_step=200, show_progress=False
    )
    with pytest.raises(InputError, match=r"series_every \(--series-every\) = 5 differs from series_every = 2"):
        run_phases(
            packing, s, ph, out, OutputSettings(series_every=5, snapshot_every=100), resume=True, show_progress=False
        )
    # through the CLI: a biaxial run cut by a failure, resumed with another --series-every
    b = tmp_path / "b.h5"
    args = [
        "biaxial",
        "--packing",
        str(packing_file),
        "-o",
        str(b),
        "--strain",
        "0.001",
        "--strain-rate",
        "0.1",
        "--consolidation-steps",
        "1000",
        "--snapshot-every",
        "500",
    ]
    assert main(args) == 2  # unsettled: a checkpoint at step 1000
    capsys.readouterr()
    assert main(args + ["--resume", "--allow-unsettled", "--series-every", "5"]) == 2
    err = capsys.readouterr().err
    assert "--series-every" in err and "= 5" in err and "= 10" in err
