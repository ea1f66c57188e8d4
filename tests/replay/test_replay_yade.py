"""`gransim replay SCRIPT.py`: YADE scripts of the supported shape (docs/replay.md, "YADE scripts"),
read without running them, run in YADE 2023.02a and natively in YADE's arithmetic, compared
frame by frame, bit for bit.

* the script reference_runs writes (reference_runs.yade.dem_script.DEM_SCRIPT with its
  input.json), against YADE's stored output of the decks' biaxial case (tests/dem/data/yade);
* a user's script of the same form with other parameters, another packing file, no initial
  velocities and other output periods (tests/replay/data/yade, README there), against its
  stored YADE output;
* what is outside the shape is refused naming its line (exit 2);
* a YADE output cut short, a frame, particle or contact row missing: `incomplete`, exit 1;
* with YADE installed, both scripts live (the user's YADE output equal byte for byte to the
  stored one).
"""

from __future__ import annotations

import gzip
import hashlib
import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from gransim.cli import main
from gransim.dem.settings import Loading
from gransim.dem.sheared import ShearLoading
from gransim.errors import InputError
from reference_runs.replay.compare import replay
from reference_runs.replay.yade import read_script
from reference_runs.yade.dem import biaxial_job, read_yade_dem, shear_job, short_biaxial, short_shear
from reference_runs.yade.dem_script import DEM_SCRIPT

DATA = Path(__file__).parent / "data" / "yade"
DEM_DATA = Path(__file__).parents[1] / "dem" / "data" / "yade" / "biaxial"
USER = "user_shear.py"
#: the user's script as stored (not .py: ruff, run on tests/, would read YADE's names as undefined)
STORED_AS = "user_shear.py.txt"
HAVE_YADE = shutil.which("yade") is not None
live = pytest.mark.skipif(not HAVE_YADE, reason="yade binary not installed (apt-get install yade; make engines)")


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _bit_for_bit(res):
    """Every check passed with nothing differing, and the evidence is the whole run."""
    assert res.passed, [c for c in res.checks if not c.passed]
    q = {c.quantity: c for c in res.checks}
    for name in (
        "thermo cell",
        "thermo stress",
        "thermo velGrad",
        "frame positions",
        "frame velocities",
        "frame spins",
        "frame forces",
        "frame torques",
        "frame contact normal force",
        "frame contact shear force",
        "frame contact penetration",
        "frame contact cellDist",
    ):
        assert q[name].value == 0 and q[name].tolerance == 0, q[name]
        assert "largest |yade - native| 0" in q[name].detail, q[name]
    return q


def _user_dir(tmp_path, edit=None) -> Path:
    """A copy of the user's script and its packing file; ``edit(text) -> text`` changes the script."""
    d = tmp_path / "script"
    d.mkdir()
    shutil.copy(DATA / "disks.json", d)
    text = (DATA / STORED_AS).read_text()
    (d / USER).write_text(edit(text) if edit else text)
    return d


def _user_ref(tmp_path, cut=None) -> Path:
    """The stored YADE job of the user's script; ``cut(lines) -> lines`` changes its output."""
    ref = tmp_path / "ref"
    ref.mkdir()
    lines = gzip.decompress((DATA / "shear.out.gz").read_bytes()).decode().splitlines(keepends=True)
    (ref / "shear.out").write_text("".join(cut(lines) if cut else lines))
    shutil.copy(DATA / "manifest.json", ref)
    return ref


# ----------------------------------------------------------------------------- the script reference_runs writes
def _reference_script(tmp_path, job, case, **periods) -> Path:
    d = tmp_path / "script"
    d.mkdir()
    script, files = job(*case, **periods)
    (d / "biaxial.py").write_text(script)
    (d / "input.json").write_bytes(files["input.json"])
    return d / "biaxial.py"


def test_reference_runs_script_replays_bit_for_bit(tmp_path):
    manifest = json.loads((DEM_DATA / "manifest.json").read_text())
    meta = manifest["stored"]
    path = _reference_script(
        tmp_path, biaxial_job, short_biaxial(), thermo_every=meta["thermo_every"], dump_every=meta["dump_every"]
    )
    # the stored YADE output is that of this very script and input
    assert _sha(DEM_SCRIPT.encode()) == manifest["deck_sha256"]
    assert _sha((path.parent / "input.json").read_bytes()) == manifest["inputs"]["input.json"]
    s = read_script(path)
    p, st, ld, n = short_biaxial()
    assert s.loading == ld and s.nsteps == n == 3000 and (s.thermo_every, s.dump_every) == (10, 500)
    assert (s.settings.kn, s.settings.kt, s.settings.mu, s.settings.dt) == (st.kn, st.kt, st.mu, st.dt)
    ref = tmp_path / "ref"
    ref.mkdir()
    (ref / "dem.out").write_bytes(gzip.decompress((DEM_DATA / "dem.out.gz").read_bytes()))
    shutil.copy(DEM_DATA / "manifest.json", ref)
    res = replay(path, outdir=tmp_path / "out", reference=ref)
    q = _bit_for_bit(res)
    assert "301 rows" in q["thermo steps"].detail and "7 frames" in q["frames"].detail
    assert res.code_version.startswith("YADE 2023.02a")
    assert (tmp_path / "out" / "report.html").exists() and (tmp_path / "out" / "replay.h5").exists()


# ----------------------------------------------------------------------------- a user's script
def test_user_script_is_read_as_written(tmp_path):
    s = read_script(_user_dir(tmp_path) / USER)
    # the user's parameters, not the decks' (the stored run tests something the reference script does not)
    assert (s.settings.kn, s.settings.kt, s.settings.mu, s.settings.dt) == (2.0e5, 1.5e5, 0.4, 1.5e-6)
    assert s.loading == ShearLoading(erate=4.0, y="servo", target=1500.0, gain=0.02)
    assert (s.nsteps, s.thermo_every, s.dump_every, s.output, s.z) == (400, 7, 100, "shear.out", 0.015625)
    pk = json.loads((DATA / "disks.json").read_text())
    assert np.array_equal(s.packing.radii, 2.0 * np.array(pk["r"]))
    assert np.array_equal(s.packing.positions, 2.0 * np.array(pk["xy"]))
    assert s.packing.density == 2650.0 and not s.velocities.any() and not s.spins.any()
    assert sorted(s.files) == ["disks.json"]


def test_user_script_replays_bit_for_bit_against_its_stored_yade_run(tmp_path):
    d = _user_dir(tmp_path)
    manifest = json.loads((DATA / "manifest.json").read_text())
    text = gzip.decompress((DATA / "shear.out.gz").read_bytes())
    # provenance: YADE's version, this very script and packing file, this very output
    assert manifest["status"] == "ok" and manifest["engine_version"] == "YADE 2023.02a"
    assert manifest["servers"] == "not started"
    assert _sha((d / USER).read_bytes()) == manifest["deck_sha256"]
    assert _sha((d / "disks.json").read_bytes()) == manifest["inputs"]["disks.json"]
    assert _sha(text) == manifest["outputs"]["shear.out"]
    res = replay(d / USER, outdir=tmp_path / "out", reference=_user_ref(tmp_path))
    q = _bit_for_bit(res)
    assert "59 rows" in q["thermo steps"].detail and "5 frames" in q["frames"].detail
    # the evidence is not trivial: contacts open and close, cross the boundary and slide
    out = read_yade_dem(tmp_path / "ref" / "shear.out")
    pairs = [{tuple(i) for i in f.ids.tolist()} for f in out.frames.values()]
    assert len(pairs[0] ^ pairs[-1]) > 50
    fr = out.frames[400]
    assert np.any(fr.cell_dist != 0)
    ratio = np.linalg.norm(fr.shear_force, axis=1) / (0.4 * np.linalg.norm(fr.normal_force, axis=1))
    assert np.sum(np.abs(ratio - 1.0) < 1e-12) > 10
    assert out.cell[-1][0, 1] > 0  # sheared


def test_cli_replays_a_script_and_refuses_deck_options(tmp_path, capsys):
    d = _user_dir(tmp_path)
    assert main(["replay", str(d / USER), "--reference", str(_user_ref(tmp_path)), "-o", str(tmp_path / "o")]) == 0
    assert "PASS: 20 of 20 checks" in capsys.readouterr().out
    assert main(["replay", str(d / USER), "--var", "kn", "1e5", "-o", str(tmp_path / "o2")]) == 2
    assert "--var" in capsys.readouterr().err


# ----------------------------------------------------------------------------- refusals name the line
def _line_of(text: str, needle: str) -> int:
    return next(k for k, line in enumerate(text.splitlines(), 1) if needle in line)


REFUSED = {
    "another law": ("Law2_ScGeom_FrictPhys_CundallStrack()", "Law2_ScGeom_ViscElPhys_Basic()", "another law"),
    "damping": ("damping=0.0", "damping=0.2", "damping 0.2"),
    "default damping": ("NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, 0.0))", "NewtonIntegrator()", "damping 0.2"),
    "clumps": (
        "    O.bodies.append(b)\n",
        "    O.bodies.append(b)\nO.bodies.appendClumped([utils.sphere((0, 0, 0), 1)])\n",
        "clumps",
    ),
    "threads": ("O.dt = dt\n", "O.dt = dt\nO.numThreads = 2\n", "several threads"),
    "engine order": (
        '    PyRunner(command="control()", iterPeriod=1, initRun=True),\n    NewtonIntegrator(damping=0.0, '
        "gravity=(0.0, 0.0, 0.0)),",
        '    NewtonIntegrator(damping=0.0, gravity=(0.0, 0.0, 0.0)),\n    PyRunner(command="control()", '
        "iterPeriod=1, initRun=True),",
        "another order",
    ),
    "collider": (
        "InsertionSortCollider([Bo1_Sphere_Aabb()])",
        "InsertionSortCollider([Bo1_Sphere_Aabb()], verletDist=0)",
        "collider defaults",
    ),
    "recorder": ("    return repr(float(v))", '    return "%.6g" % v', "differs from the recorder"),
    "import": ("import math\n", "import math\nimport os\n", "an import outside"),
    "exec": ("n = len(radii)\n", "n = len(radii)\nexec(open('x.py').read())\n", "outside the supported shape"),
    "mass": ("    m = rho * math.pi * r * r", "    m = math.pi * r * r * rho", "the 2D mass"),
    "shear with x loading": ('"xx": {"mode": "fixed"}', '"xx": {"mode": "rate", "c": -1e-9}', "x fixed"),
    "parameter after the run": (
        'put("END", n_steps)\n',
        'put("END", n_steps)\ndt = 1.0\n',
        "after the run has started",
    ),
    "output over a job file": ('open("shear.out", "w")', 'open("manifest.json", "w")', "job's own files"),
    "tilted start": ("Matrix3(Lx, 0, 0, 0, Ly, 0, 0, 0, z)", "Matrix3(Lx, 1e-4, 0, 0, Ly, 0, 0, 0, z)", "orthogonal"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_outside_the_shape_is_refused_naming_the_line(tmp_path, case, capsys):
    old, new, why = REFUSED[case]
    base = (DATA / STORED_AS).read_text()
    assert base.count(old) == 1, case
    d = _user_dir(tmp_path, lambda t: t.replace(old, new))
    text = (d / USER).read_text()
    # the line of the edit (the added line for an insertion, else its first line)
    first = new.splitlines()[-1] if new.startswith(old) else new.splitlines()[0]
    want = _line_of(text, first.strip())
    with pytest.raises(InputError) as info:
        read_script(d / USER)
    msg = str(info.value)
    assert f"line {want}:" in msg and why in msg, msg
    assert main(["replay", str(d / USER), "-o", str(tmp_path / "out")]) == 2
    assert f"line {want}:" in capsys.readouterr().err
    assert not (tmp_path / "out" / "job").exists()  # refused before anything ran


# ----------------------------------------------------------------------------- incomplete evidence
def _drop(pattern, nth=0):
    """Remove the nth line matching ``pattern`` (a regular expression)."""

    def cut(lines):
        hits = [k for k, line in enumerate(lines) if re.match(pattern, line)]
        k = hits[nth]
        return lines[:k] + lines[k + 1 :]

    return cut


def _drop_frame(step):
    def cut(lines):
        start = next(k for k, line in enumerate(lines) if line.startswith(f"F {step} "))
        end = next(k for k in range(start + 1, len(lines)) if not lines[k].startswith(("P ", "C ")))
        return lines[:start] + lines[end:]

    return cut


INCOMPLETE = {
    "cut short": (lambda lines: lines[: len(lines) // 2], "frame of step 200 has 120 of 120 particles and 21 of"),
    "partial last line": (lambda lines: [*lines[:-1], lines[-1][:3]], "cut short"),
    "END missing": (lambda lines: lines[:-1], "no END line"),
    "thermo step missing": (_drop(r"T 7 "), "thermo step 14 where step 7 is due"),
    "frame missing": (_drop_frame(200), "frame of step 300 where step 200 is due"),
    "particle missing": (_drop(r"P 17 ", 2), "particles"),
    "contact missing": (_drop(r"C ", 40), "contacts"),
}


@pytest.mark.parametrize("case", sorted(INCOMPLETE))
def test_incomplete_yade_output_fails_as_incomplete(tmp_path, case, capsys):
    cut, why = INCOMPLETE[case]
    d = _user_dir(tmp_path)
    ref = _user_ref(tmp_path, cut)
    res = replay(d / USER, outdir=tmp_path / "out", reference=ref)
    assert not res.passed
    bad = [c for c in res.checks if not c.passed]
    assert bad and bad[0].metric.startswith("incomplete") and why in bad[0].detail, bad
    # nothing is judged on what remains
    assert len(res.checks) == 1
    assert "FAIL" in (tmp_path / "out" / "report.md").read_text()
    assert main(["replay", str(d / USER), "--reference", str(ref), "-o", str(tmp_path / "o2")]) == 1
    assert "incomplete" in capsys.readouterr().out


def test_a_differing_value_fails_and_is_named(tmp_path):
    """A YADE output with one force changed in its last digit fails that check only."""

    def nudge(lines):
        k = next(k for k, line in enumerate(lines) if line.startswith("P 5 ") and k > len(lines) // 2)
        f = lines[k].split()
        f[7] = repr(float(np.nextafter(float(f[7]), np.inf)))  # fx
        return [*lines[:k], " ".join(f) + "\n", *lines[k + 1 :]]

    res = replay(_user_dir(tmp_path) / USER, outdir=tmp_path / "out", reference=_user_ref(tmp_path, nudge))
    bad = [c.quantity for c in res.checks if not c.passed]
    assert bad == ["frame forces"]


# ----------------------------------------------------------------------------- live YADE
@live
def test_live_reference_runs_script_replays_bit_for_bit(tmp_path):
    path = _reference_script(
        tmp_path, shear_job, (*short_shear("constant-volume")[:3], 300), thermo_every=1, dump_every=50
    )
    res = replay(path, outdir=tmp_path / "out", timeout=300)
    q = _bit_for_bit(res)
    assert "301 rows" in q["thermo steps"].detail and "7 frames" in q["frames"].detail
    assert isinstance(read_script(path).loading, ShearLoading)
    m = json.loads((tmp_path / "out" / "job" / "manifest.json").read_text())
    assert m["status"] == "ok" and m["servers"] == "not started" and m["engine_version"] == "YADE 2023.02a"


@live
def test_live_user_script_replays_bit_for_bit_and_reproduces_the_stored_output(tmp_path):
    d = _user_dir(tmp_path)
    res = replay(d / USER, outdir=tmp_path / "out", timeout=300)
    _bit_for_bit(res)
    m = json.loads((tmp_path / "out" / "job" / "manifest.json").read_text())
    stored = json.loads((DATA / "manifest.json").read_text())
    assert m["outputs"]["shear.out"] == stored["outputs"]["shear.out"]  # YADE writes the stored bytes again
    assert m["servers"] == "not started"


@live
def test_live_biaxial_variant_with_initial_velocities(tmp_path):
    """The reference script with a fixed x, a y rate and random initial velocities and spins (the
    body loop's full form), other output periods."""
    p, s, _, _ = short_biaxial()
    rng = np.random.default_rng(3)
    case = (p, s, Loading.from_dict({"x": {"mode": "fixed"}, "y": {"mode": "rate", "rate": -2.0}}), 250)
    path = _reference_script(
        tmp_path,
        biaxial_job,
        case,
        thermo_every=3,
        dump_every=40,
        velocities=rng.normal(scale=0.02, size=(p.n, 2)),
        spins=rng.normal(scale=20, size=p.n),
    )
    assert read_script(path).velocities.any()
    _bit_for_bit(replay(path, outdir=tmp_path / "out", timeout=300))
