"""The deck reader of `gransim replay` (reference_runs/replay/deck.py): the supported subset of
both syntaxes, and a clear refusal (file, line, command) of everything else."""

import numpy as np
import pytest
from replay_support import DATA

from gransim.errors import InputError
from reference_runs.replay.deck import read_data_file, read_deck


def _copy(tmp_path, name, edit=None, data="disks_a.data"):
    text = (DATA / name).read_text()
    if edit is not None:
        text = edit(text)
    (tmp_path / data).write_text((DATA / data).read_text())
    p = tmp_path / name
    p.write_text(text)
    return p


def test_liggghts_deck_a_is_read_completely():
    d = read_deck(DATA / "in.deck_a")
    assert d.engine == "liggghts"
    s = d.settings
    assert (s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu, s.dt, s.skin) == (1e5, 7e4, 50.0, 25.0, 0.4, 1e-6, 5e-5)
    assert d.box_lo.tolist() == [-0.0123, 0.0051] and d.box_hi.tolist() == [-0.0043, 0.0120282]
    assert np.allclose(np.diag(d.packing.cell), d.box_hi - d.box_lo, rtol=0, atol=0)
    assert d.packing.n == 16 and d.ids.tolist() == list(range(1, 17))
    assert d.packing.radii[0] == 0.5 * 0.00188467 and d.packing.positions[0].tolist() == [-0.0117557, 0.0059672]
    assert d.packing.density == 2650.0
    assert np.all(d.velocities == 0) and np.all(d.spins == 0)
    ax = d.deform.axes
    assert (d.deform.every, ax[0].style, ax[0].params, ax[1].style, ax[1].params) == (
        1,
        "erate",
        (-5.0,),
        "trate",
        (3.0,),
    )
    assert d.deform.units == "box" and d.nsteps == 500 and d.thermo_every == 1
    assert d.thermo_columns[:3] == ("step", "atoms", "lx") and "press" in d.pressure
    (dump,) = d.dumps
    assert (dump.every, dump.file, dump.sort_id) == (100, "dump.disks", True)
    assert dump.columns == ("id", "x", "y", "vx", "vy", "omegaz", "fx", "fy", "tqz", "radius", "mass")
    assert not d.sorting


def test_lammps_deck_b_null_coefficients_substitution_continuation_velocities():
    d = read_deck(DATA / "in.deck_b")
    assert d.engine == "lammps"
    s = d.settings
    # ${kn} substituted; NULL gammat = gamman/2 (LAMMPS PairGranHookeHistory::settings)
    assert (s.kn, s.kt, s.gamma_n, s.gamma_t, s.mu) == (1e5, 7e4, 50.0, 25.0, 0.4)
    if hasattr(s, "flavour"):
        assert s.flavour == "lammps"
    # the `&` continuation joined the y setting to the fix deform line
    ax = d.deform.axes
    assert (ax[0].style, ax[0].params, ax[1].style, ax[1].params) == ("vel", (-0.02,), "delta", (3e-6, -2e-6))
    assert d.deform.every == 2 and d.deform.units == "lattice"
    assert d.velocities[13].tolist() == [-0.00068, 0.00834] and d.spins[15] == 0.411
    assert d.thermo_columns[-1] == "c_p"


def test_lammps_null_kt_is_two_sevenths_of_kn():
    d = read_deck(DATA / "in.deck_c")
    assert d.settings.kt == 1e5 * 2.0 / 7.0
    assert d.deform.axes[0].params == (0.250004, 0.257992) and d.deform.axes[1].params == (1.002,)


@pytest.mark.parametrize(
    "line,needle",
    [
        ("region box block 0 1 0 1 -1 1", "command `region`"),
        ("fix g all gravity 9.81 vector 0 -1 0", "fix style `gravity`"),
        ("compute ke all ke", "compute style `ke`"),
        ("dump img all image 10 a.jpg type type", "dump style `image`"),
    ],
)
def test_unsupported_command_names_file_line_and_lists_the_subset(tmp_path, line, needle):
    p = _copy(tmp_path, "in.deck_a", lambda t: t.replace("timestep        1e-6", f"timestep 1e-6\n{line}"))
    lineno = p.read_text().splitlines().index(line) + 1
    with pytest.raises(InputError) as e:
        read_deck(p)
    msg = str(e.value)
    assert f"{p}:{lineno}:" in msg and needle in msg
    if "command" in needle or "style" in needle:
        assert "supported commands:" in msg and "fix deform" in msg


@pytest.mark.parametrize(
    "old,new,needle",
    [
        (
            "kt peratomtypepair 1 7e4",
            "kt peratomtypepair 1 7e4x",
            "fix property/global kt coefficient: expected a number, got '7e4x'",
        ),
        ("gamman peratomtypepair 1 50", "gamman peratomtypepair 2 50", "peratomtypepair 1 VALUE"),
        ("coefficientFriction peratomtypepair 1 0.4", "coefficientFriction peratomtypepair 1 -0.4", "expected >= 0"),
        ("timestep        1e-6", "timestep abc", "timestep DT: expected a number"),
        ("remap x units box", "remap v", "remap v"),
        ("x erate -5.0 y trate 3.0", "x erate -5.0 y wiggle 1 2", "y wiggle: not in the subset"),
        ("x erate -5.0 y trate 3.0", "x erate -5.0 xy erate 0.1", "triclinic"),
        (
            "neigh_modify    delay 0 every 1 check yes",
            "neigh_modify delay 10 every 1 check yes",
            "neigh_modify delay: expected 0",
        ),
        ("newton          off", "newton on", "newton off"),
        ("communicate     single vel yes", "comm_modify mode single vel yes", "mixes LIGGGHTS syntax"),
        ("run             500", "run 500 upto", "run N"),
        ("model hooke/stiffness tangential history", "model hertz tangential history", "hooke/stiffness"),
        ("thermo_style    custom step atoms", "thermo_style    custom step pxx atoms", "thermo keyword 'pxx'"),
    ],
)
def test_malformed_or_refused_value_names_its_line(tmp_path, old, new, needle):
    p = _copy(tmp_path, "in.deck_a", lambda t: t.replace(old, new))
    assert new in p.read_text()
    lineno = next(k for k, ln in enumerate(p.read_text().splitlines(), 1) if new in ln)
    with pytest.raises(InputError) as e:
        read_deck(p)
    assert needle in str(e.value)
    if "mixes" not in needle:
        assert f":{lineno}:" in str(e.value)


@pytest.mark.parametrize(
    "drop,needle",
    [
        ("set group all density/disc 2650", "density/disc RHO` is missing"),
        ("newton off", "`newton off` is missing"),
        ("neigh_modify delay 0 every 1 check yes", "neigh_modify delay 0 every 1 check yes` is missing"),
    ],
)
def test_lammps_deck_without_required_command_is_refused(tmp_path, drop, needle):
    p = _copy(tmp_path, "in.deck_b", lambda t: t.replace(drop + "\n", ""), data="disks_b.data")
    with pytest.raises(InputError, match=needle.replace("[", r"\[").replace("`", "`")):
        read_deck(p)


def test_lammps_nve_sphere_without_disc_and_engine_mismatch(tmp_path):
    p = _copy(tmp_path, "in.deck_b", lambda t: t.replace("nve/sphere disc", "nve/sphere"), data="disks_b.data")
    with pytest.raises(InputError, match="without `disc`"):
        read_deck(p)
    with pytest.raises(InputError, match="--engine liggghts: the deck is written for lammps"):
        read_deck(DATA / "in.deck_b", engine="liggghts")


def test_data_file_errors_name_file_and_line(tmp_path):
    text = (DATA / "disks_a.data").read_text()
    bad = tmp_path / "bad.data"
    bad.write_text(text.replace("1 1 0.00188467 2650", "1 1 0.00188467 abc"))
    with pytest.raises(InputError, match=r"bad.data:12: density: expected a number"):
        read_data_file(bad)
    bad.write_text(text.replace("1 atom types", "2 atom types"))
    with pytest.raises(InputError, match=r"bad.data:4: 2 atom types"):
        read_data_file(bad)
    bad.write_text(text.replace("-0.0117557 0.0059672 0", "-0.0117557 0.0059672 0.001"))
    with pytest.raises(InputError, match="z = 0"):
        read_data_file(bad)


def test_data_override_and_positions_wrapped_once(tmp_path):
    text = (DATA / "disks_a.data").read_text().replace("-0.0117557 0.0059672 0", "-0.0037557 0.0059672 0")
    (tmp_path / "other.data").write_text(text)
    d = read_deck(DATA / "in.deck_a", data=tmp_path / "other.data")
    assert d.data_path == tmp_path / "other.data"
    # x = -0.0037557 >= xhi = -0.0043: wrapped by - L as Domain::remap does
    assert d.packing.positions[0, 0] == -0.0037557 - (-0.0043 - -0.0123)
