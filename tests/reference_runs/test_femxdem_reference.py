"""Guo & Zhao's FEM x DEM biaxial test run by their own code (Debian's YADE 2023.02a + escript 5.6,
ported by reference_runs/femxdem/port.patch): a tiny run checked against the recipe's physics, and
the fault cases (a cut-short output, a failing or timed-out run, a listening socket) that must be
errors naming what failed, with nothing left running.

The tiny run scales the recipe down (prepareRVE.py's 400 disks in a 0.24 m cell become 100 disks in
a 0.12 m cell: the same cloud density; everything else as in prepareRVE.py and biaxialSmooth.py) on
a 1 x 2 mesh (8 RVEs), 2 load steps, 2 workers. Skipped without yade or python3-escript.
"""

import math
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from reference_runs.errors import ReferenceRunError
from reference_runs.femxdem.output import IncompleteOutputError, read_h5, read_outputs
from reference_runs.femxdem.port import PATCH, PortError, apply_hunks, install_port, read_port
from reference_runs.femxdem.run import DEBIAN_PYTHON, FemxdemParams, check_installed, run_biaxial, run_stage

try:
    check_installed()
    MISSING = None
except PortError as exc:
    MISSING = str(exc)

needs_codes = pytest.mark.skipif(MISSING is not None, reason=f"YADE / escript not usable: {MISSING}")

TINY = FemxdemParams(nx=1, ny=2, steps=2, workers=2, field_steps=(0, 1, 2), n_disks=100, seed=1)
#: prepareRVE.py:28-30: PeriTriaxController(goal=(-1e5, -1e5, 0), stressMask=3, relStressTol=.001)
GOAL, REL_STRESS_TOL = -1.0e5, 1e-3
VEL, LY, LX = -1e-4, 0.1, 0.05  # biaxialSmooth.py:35-38


def _processes_under(root: Path) -> list:
    """Live processes whose working directory lies under ``root``."""
    root = str(root.resolve())
    out = []
    for d in os.listdir("/proc"):
        if not d.isdigit():
            continue
        try:
            cwd = os.readlink(f"/proc/{d}/cwd")
            state = Path(f"/proc/{d}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state not in ("Z", "X") and (cwd == root or cwd.startswith(root + "/")):
            out.append(int(d))
    return out


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("femxdem")
    t0 = time.monotonic()
    h5 = run_biaxial(out / "run", TINY, timeout=240)
    wall = time.monotonic() - t0
    return {"out": out, "h5": h5, "data": read_h5(h5), "wall": wall}


# ----------------------------------------------------------------------------- the port
def test_every_added_line_of_the_port_says_why():
    """The port is documented line by line: each added line carries a `# gransim:` comment,
    and each removed line is replaced (a `+` line in the same hunk)."""
    port = read_port()
    assert port.hunks, "no hunks parsed"
    for name, hunks in port.hunks.items():
        for _start, old, new in hunks:
            added = [ln for ln in new if ln not in old]
            assert added, f"{name}: a hunk that adds nothing"
            for ln in added:
                assert "# gransim:" in ln, f"{name}: undocumented added line {ln!r}"


def test_a_hunk_that_does_not_match_is_refused_naming_file_and_line():
    port = read_port()
    hunks = port.hunks["biaxialSmooth.py"]
    start, old, _new = hunks[0]
    lines = ["x"] * (start + len(old) + 5)
    lines[start - 1 : start - 1 + len(old)] = list(old)
    text = "\n".join(lines) + "\n"
    apply_hunks(text, hunks[:1], "biaxialSmooth.py")  # applies where it matches
    lines[start] = lines[start] + " # changed"
    with pytest.raises(PortError, match=rf"biaxialSmooth.py: hunk 1 does not apply at line {start + 1}"):
        apply_hunks("\n".join(lines) + "\n", hunks[:1], "biaxialSmooth.py")


def test_an_original_of_another_version_is_refused(tmp_path):
    """A Debian file whose SHA-256 differs from the recorded one (another package version) is
    refused, naming the file: the patch was made against exactly those files."""
    text = PATCH.read_text()
    orig = read_port().originals[0]
    fake = tmp_path / "biaxialSmooth.py"
    fake.write_text("print('another version')\n")
    patch = tmp_path / "port.patch"
    patch.write_text(
        text.replace(f"# file: {orig.path} |", f"# file: {fake} |").replace(f"--- {orig.path}", f"--- {fake}")
    )
    from reference_runs.femxdem.port import check_originals

    with pytest.raises(PortError, match=rf"{fake}: SHA-256 .* is not {orig.sha256}"):
        check_originals(read_port(patch))


@needs_codes
def test_the_port_changes_only_what_it_documents(tmp_path):
    """Removing the documented lines from the ported biaxialSmooth.py and putting the replaced
    originals back gives Debian's file byte for byte (a patch that changed more would not)."""
    port = install_port(tmp_path)
    ported = (tmp_path / "biaxialSmooth.py").read_text().splitlines()
    orig = next(o for o in port.originals if o.name == "biaxialSmooth.py")
    original = Path(orig.path).read_text().splitlines()
    kept = [ln for ln in ported if "# gransim:" not in ln]
    removed = [ln for _s, old, new in port.hunks["biaxialSmooth.py"] for ln in old if ln not in new]
    assert len(kept) + len(removed) == len(original)
    assert set(kept) <= set(original)
    assert sorted(kept + removed) == sorted(original)


# ----------------------------------------------------------------------------- physics of the tiny run
@needs_codes
def test_the_rve_follows_the_recipe(tiny):
    """prepareRVE.py: the disks, their 2D masses at 2650 kg/m^3 x 0.1 m (line 15), the friction
    angle set after consolidation (0.5 rad: tan 0.5 on every contact and in the material, line 44),
    the consolidation controller removed and damping 0.1 kept (lines 36, 41)."""
    a = tiny["data"]["attrs"]
    import h5py

    with h5py.File(tiny["h5"], "r") as f:
        g = f["rve"]
        radii, masses = g["radii"][()], g["masses"][()]
        tans, angles = g.attrs["tan_friction"], g.attrs["material_friction_angle"]
        engines, damping = g.attrs["engines"], g.attrs["damping"]
        n = int(g.attrs["n_bodies"])
    assert n == TINY.n_disks == radii.size
    np.testing.assert_allclose(masses, 2650 * 0.1 * math.pi * radii**2, rtol=1e-15)
    r_mean = 0.005
    assert radii.min() >= r_mean * 0.6 - 1e-15 and radii.max() <= r_mean * 1.4 + 1e-15
    assert list(tans) == [math.tan(0.5)] and list(angles) == [0.5]
    assert "PeriTriaxController" not in str(engines) and "NewtonIntegrator" in str(engines)
    assert list(damping) == [0.1]
    assert a["packages"]["yade"].startswith("2023.02a") and a["yade_version"] == "YADE 2023.02a"


@needs_codes
def test_contact_stiffness_is_youngs_modulus_times_the_harmonic_radius(tiny):
    """FrictMat(young=6e8, poisson=.8) (prepareRVE.py:5) through Ip2_FrictMat_FrictMat_FrictPhys:
    kn = 2 (E r1)(E r2) / (E r1 + E r2), ks = the same with E nu, i.e. 0.8 kn (FrictPhys.cpp:30-38
    at e627a44de36e), checked on every contact of the installed 2023.02a. kn: the same operations
    in the same order, 1e-15; ks: 0.8 enters before the harmonic mean in YADE, after it here, a
    few roundings apart: 4e-15."""
    import h5py

    with h5py.File(tiny["h5"], "r") as f:
        c = f["rve/contacts"][()]
    assert c.shape[0] > TINY.n_disks  # a jammed packing: about two contacts per disk
    E = 6e8  # noqa: N806 - Young's modulus
    kn = 2 * (E * c[:, 0]) * (E * c[:, 1]) / (E * c[:, 0] + E * c[:, 1])
    np.testing.assert_allclose(c[:, 2], kn, rtol=1e-15)
    np.testing.assert_allclose(c[:, 3], 0.8 * c[:, 2], rtol=4e-15)


@needs_codes
def test_step0_every_gauss_point_holds_the_consolidation_stress(tiny):
    """Before loading every Gauss point holds the same RVE (msFEM2D loads 0.yade.gz for each,
    simDEM.py:24): its stress is the same at every point and isotropic at the confining 100 kPa
    within PeriTriaxController's tolerance, |sigma_ii - goal| <= relStressTol |goal| for xx and yy
    (PeriIsoCompressor.cpp:263 at e627a44de36e); the unloaded particle rotations are exactly 0
    (prepareRVE.py:51 sets refOri)."""
    f0 = tiny["data"]["fields"][0]
    s = f0["stress"]
    assert s.shape == (TINY.n_gauss, 2, 2)
    assert np.all(s == s[0]), "the Gauss points of step 0 differ"
    for i in (0, 1):
        assert abs(s[0, i, i] - GOAL) <= REL_STRESS_TOL * abs(GOAL), (i, s[0, i, i])
    assert s[0, 0, 1] == s[0, 1, 0]  # getStressAndTangent2D symmetrises (simDEM.py:141)
    assert np.all(f0["rotation"] == 0.0)
    assert np.all(f0["strain"] == 0.0)


@needs_codes
def test_step0_void_ratio_is_the_cells_free_area_over_the_disks(tiny):
    """voidratio2D(zlen) = (det hSize / zlen - sum pi r^2) / sum pi r^2 (Shop_02.cpp:1081-1092 at
    e627a44de36e), recomputed here from the consolidated cell and radii of rve.txt."""
    import h5py

    with h5py.File(tiny["h5"], "r") as f:
        h, radii = f["rve"].attrs["hsize"], f["rve/radii"][()]
    solid = float(np.sum(math.pi * radii**2))
    e = (h[0, 0] * h[1, 1] - solid) / solid
    np.testing.assert_allclose(tiny["data"]["fields"][0]["void_ratio"], e, rtol=1e-12)


@needs_codes
def test_top_reaction_equals_mean_sigma_yy_times_width(tiny):
    """The top platen's resultant (biaxialSmooth.py:91-94: Gauss stresses projected to the nodes,
    traction integrated over the top) equals the volume-averaged sigma_yy times the top's current
    length. Step 0: a uniform field, which the projection reproduces: to 1e-9. Loaded steps: the
    FE solution is in equilibrium only to Newton's tolerance (rtol 1e-2 on the displacement
    correction, msFEM2D.py:230-232) and the field is not quite uniform: 1e-3 (measured on the 2 x 4
    mesh with 400-disk RVEs: at most 5.4e-5 over 10 steps, 5.9e-4 over 20 steps, near the peak)."""
    s = tiny["data"]["steps"]
    fy, mean = s["force_top_y"], s["stress_yy"] * s["length_top"]
    assert abs(fy[0] - mean[0]) <= 1e-9 * abs(fy[0])
    np.testing.assert_allclose(fy[1:], mean[1:], rtol=1e-3)
    assert np.all(fy[1:] < fy[0])  # compression grows as the top moves down


@needs_codes
def test_the_sides_carry_the_confining_pressure(tiny):
    """The sides are loaded by 100 kPa (Neumann, biaxialSmooth.py:75), so the volume-averaged
    sigma_xx equals -100 kPa at equilibrium. Tolerance 2 %: Newton stops on the displacement
    correction (1e-2), not on the residual (measured: at most 0.78 % over the 20 steps of the
    2 x 4 mesh with 400-disk RVEs)."""
    s = tiny["data"]["steps"]
    np.testing.assert_allclose(s["stress_xx"], GOAL, rtol=2e-2)


@needs_codes
def test_the_mean_axial_strain_is_the_imposed_displacement(tiny):
    """The top moves VEL per step and the bottom is fixed in y (biaxialSmooth.py:71-73), so the
    volume average of d(u_y)/dy over each step's configuration is VEL / (current height); msFEM2D
    sums these increments (msFEM2D.py:247). Tolerance 1e-7 relative: the average is taken with the
    updated geometry's weights over a nearly uniform field (measured: 2e-10)."""
    s = tiny["data"]["steps"]
    expect = np.concatenate([[0.0], np.cumsum([VEL / (LY + (t - 1) * VEL) for t in range(1, TINY.steps + 1)])])
    np.testing.assert_allclose(s["strain_yy"], expect, rtol=1e-7, atol=0)
    np.testing.assert_array_equal(s["axial_strain"], np.arange(TINY.steps + 1) * VEL / LY)


@needs_codes
def test_the_run_records_newton_and_time_and_leaves_nothing(tiny):
    s = tiny["data"]["steps"]
    assert s["iterations"][0] == 0 and np.all(s["iterations"][1:] >= 1)
    assert np.all(s["relative_error"][1:] < 1e-2)  # converged within biaxialSmooth.py:51's rtol
    t = tiny["data"]["attrs"]["timing"]
    assert t["rve_calls"] == TINY.n_gauss * int(s["n_dem_maps"][1:].sum()) // 2
    assert t["wall_dem"] > 0 and t["wall_total"] > 0
    assert _processes_under(tiny["out"]) == []
    print(f"tiny run: {tiny['wall']:.1f} s, Newton iterations {list(s['iterations'][1:])}")


# ----------------------------------------------------------------------------- faults
def _copy_job(tiny, tmp_path) -> Path:
    job = tmp_path / "job"
    shutil.copytree(tiny["out"] / "run" / "job", job, symlinks=True)
    return job


@needs_codes
def test_a_cut_short_steps_file_is_an_error_naming_it(tiny, tmp_path):
    job = _copy_job(tiny, tmp_path)
    args = (TINY.steps, TINY.n_gauss, TINY.field_steps)
    read_outputs(job, *args)  # the copy is complete
    steps = job / "result" / "steps.txt"
    lines = steps.read_text().splitlines()
    steps.write_text("\n".join(lines[:-2]) + "\n")  # the last step and the END line lost
    with pytest.raises(IncompleteOutputError, match=rf"{steps}.*no END line.*after step 1 of 2"):
        read_outputs(job, *args)
    steps.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:5])  # END line cut mid-way
    with pytest.raises(IncompleteOutputError, match=str(steps)):
        read_outputs(job, *args)


@needs_codes
def test_a_cut_short_field_file_is_an_error_naming_it(tiny, tmp_path):
    job = _copy_job(tiny, tmp_path)
    fields = job / "result" / "fields_2.txt"
    text = fields.read_text()
    fields.write_text(text[: len(text) // 2])
    with pytest.raises(IncompleteOutputError, match=rf"incomplete: {fields}"):
        read_outputs(job, TINY.steps, TINY.n_gauss, TINY.field_steps)
    fields.unlink()
    with pytest.raises(IncompleteOutputError, match=rf"{fields} is missing"):
        read_outputs(job, TINY.steps, TINY.n_gauss, TINY.field_steps)


@needs_codes
def test_a_failing_script_is_an_error_naming_it_with_its_stderr(tiny, tmp_path):
    """biaxialSmooth.py itself fails (its parameters file is gone): exit status 1, named, with the
    traceback's last lines; nothing is left running."""
    job = _copy_job(tiny, tmp_path)
    (job / "femxdem_params.json").unlink()
    with pytest.raises(ReferenceRunError, match=r"biaxialSmooth.py failed: exit status 1") as err:
        run_stage([DEBIAN_PYTHON, "biaxialSmooth.py"], job, 60, "biaxialSmooth.py")
    assert any("femxdem_params.json" in ln for ln in err.value.log_lines)
    assert _processes_under(tmp_path) == []


@needs_codes
def test_a_timed_out_run_is_killed_whole_and_writes_no_result(tiny, tmp_path):
    """A run cut by its timeout: every process of it (the pool's workers too) is killed, the error
    says so, and no femxdem.h5 is written (a stale one from before is removed)."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "femxdem.h5").write_bytes(b"stale")
    params = FemxdemParams(nx=1, ny=2, steps=50, workers=2, field_steps=(0,), n_disks=100, seed=1)
    with pytest.raises(
        ReferenceRunError, match=r"biaxialSmooth.py: timed out after .* every process of the job killed"
    ):
        run_biaxial(out, params, rve_dir=tiny["out"] / "run" / "rve", timeout=6)
    assert not (out / "femxdem.h5").exists()
    assert _processes_under(tmp_path) == []


def test_a_listening_socket_fails_the_stage_and_is_closed(tmp_path):
    """The stage watches its processes' sockets: a job that listens on TCP (as `yade` run as a
    program does, /usr/bin/yade:388-393) is killed and named."""
    code = (
        "import socket, time\n"
        "s = socket.socket(); s.bind(('127.0.0.1', 0)); s.listen(1)\n"
        "open('port', 'w').write(str(s.getsockname()[1]))\n"
        "time.sleep(60)\n"
    )
    with pytest.raises(ReferenceRunError, match=r"listens on TCP port"):
        run_stage([sys.executable, "-c", code], tmp_path, 30, "listener")
    port = int((tmp_path / "port").read_text())
    rows = Path("/proc/net/tcp").read_text().splitlines()[1:]
    assert not any(r.split()[3] == "0A" and int(r.split()[1].rsplit(":", 1)[1], 16) == port for r in rows)
    assert _processes_under(tmp_path) == []


def test_bad_usage_exits_2_naming_the_option(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    for args, option in (
        (["--workers", "1"], "--workers"),
        (["--field-steps", "0,7", "--steps", "3"], "--field-steps"),
    ):
        r = subprocess.run(
            [sys.executable, "-m", "reference_runs.femxdem", "run", "--out", str(tmp_path / "x"), *args],
            capture_output=True,
            text=True,
            env=env,
            timeout=120,
        )
        assert r.returncode == 2, r.stderr
        assert option in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "x").exists()
