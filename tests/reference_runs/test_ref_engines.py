"""Engines (LIGGGHTS, LAMMPS) behind one interface: lookup, install hints, banners, a LAMMPS job
cycle, LAMMPS' dump frame rule, and jobs of one code never reused as the other's."""

import json
import shutil
import subprocess
import sys

import pytest

from gransim.errors import InputError
from gransim.io.provenance import lammps_version, liggghts_version
from reference_runs.engines import ENGINES, engine_of_log, get_engine
from reference_runs.errors import ReferenceRunError
from reference_runs.expect import dump_frame_steps, expected_evidence
from reference_runs.parsers import parse_log
from reference_runs.runner import is_complete, read_manifest, run_job, verify_job
from reference_runs.store import STORED, TAYLOR_CASE

needs_lmp = pytest.mark.skipif(shutil.which("lmp") is None, reason="lmp not installed (apt-get install lammps)")
LAMMPS_BANNER = "LAMMPS (29 Sep 2021 - Update 2)"
LIGGGHTS_BANNER = "LIGGGHTS (Version LIGGGHTS-PUBLIC 3.8.0, compiled 2023-01-05-12:00:00 by root)"


def test_get_engine_names_and_unknown():
    assert get_engine("lammps").binary == "lmp" and get_engine("LAMMPS").deck_name == "in.lammps"
    assert get_engine("liggghts").package == "liggghts" and get_engine(" liggghts ").deck_name == "in.liggghts"
    assert get_engine(ENGINES["lammps"]) is ENGINES["lammps"]
    with pytest.raises(InputError, match=r"engine: unknown DEM code 'lampps'; choose one of: liggghts, lammps"):
        get_engine("lampps")


@pytest.mark.parametrize(
    "engine,hint", [("liggghts", "sudo apt-get install liggghts"), ("lammps", "sudo apt-get install lammps")]
)
def test_missing_binary_gives_install_hint(engine, hint, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    e = get_engine(engine)
    assert not e.available() and e.version() is None and e.package_version() is None
    with pytest.raises(ReferenceRunError, match=hint):
        e.find()
    with pytest.raises(ReferenceRunError, match=hint):
        run_job(tmp_path / "job", "run 0\n", progress=False, engine=engine)
    assert read_manifest(tmp_path / "job") is None


def test_run_job_unknown_engine_is_input_error(tmp_path):
    with pytest.raises(InputError, match="engine: unknown DEM code 'gromacs'"):
        run_job(tmp_path / "job", "run 0\n", progress=False, engine="gromacs")
    assert not (tmp_path / "job").exists()


def test_store_cli_without_binary_exits_2_with_hint(tmp_path):
    # the command-line entry of the stored outputs: one line, exit 2, nothing written
    env = {"PATH": str(tmp_path), "HOME": str(tmp_path)}
    before = sorted(p.name for p in STORED.iterdir())
    out = subprocess.run(
        [sys.executable, "-m", "reference_runs.store", "--engine", "lammps"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=str(STORED.parents[1]),
    )
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert "`lmp` binary (LAMMPS) was not found on PATH" in out.stderr and "apt-get install lammps" in out.stderr
    assert sorted(p.name for p in STORED.iterdir()) == before
    bad = subprocess.run(
        [sys.executable, "-m", "reference_runs.store", "--engine", "nope"],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        cwd=str(STORED.parents[1]),
    )
    assert bad.returncode == 2 and "unknown DEM code 'nope'" in bad.stderr and "Traceback" not in bad.stderr


def test_banners_of_both_codes():
    e, v = engine_of_log(LAMMPS_BANNER)
    assert e.name == "lammps" and v == "LAMMPS 29 Sep 2021 - Update 2"
    e, v = engine_of_log(LIGGGHTS_BANNER)
    assert e.name == "liggghts" and v == "LIGGGHTS-PUBLIC 3.8.0"
    assert engine_of_log("LAMMPS data file written by gransim") == (None, None)
    log = parse_log(
        f"{LAMMPS_BANNER}\nStep Atoms \n       0       36 \nLoop time of 1e-06 on 1 procs for 0 steps "
        "with 36 atoms\nERROR: Lost atoms: original 36 current 35 (src/thermo.cpp:487)\n"
    )
    assert log.engine == "lammps" and log.version == "LAMMPS 29 Sep 2021 - Update 2"
    assert len(log.runs) == 1 and log.runs[0].complete and log.lost_atoms and len(log.errors) == 1
    log = parse_log(f"{LIGGGHTS_BANNER}\nStep Atoms\n 0 36\n")
    assert log.engine == "liggghts" and log.version == "LIGGGHTS-PUBLIC 3.8.0" and not log.runs[0].complete


def _script(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(f"#!{sys.executable}\nprint({text!r})\n")
    p.chmod(0o755)
    return p


def test_version_from_the_binary_banner(tmp_path):
    (tmp_path / "a").mkdir()
    lmp = _script(tmp_path / "a", "lmp", LAMMPS_BANNER + "\nTotal wall time: 0:00:00")
    assert lammps_version(lmp) == f"LAMMPS 29 Sep 2021 - Update 2 ({lmp})"
    assert get_engine("lammps").version(lmp) == lammps_version(lmp)
    (tmp_path / "b").mkdir()
    other = _script(tmp_path / "b", "lmp", LIGGGHTS_BANNER)  # answers, but not as LAMMPS
    assert lammps_version(other).startswith("unknown: no LAMMPS banner") and liggghts_version(other).startswith(
        "LIGGGHTS-PUBLIC 3.8.0 ("
    )


@needs_lmp
def test_real_lammps_version_matches_its_help():
    # two independent sources: the banner of a run and the first line of `lmp -h`
    v = get_engine("lammps").version()
    h = subprocess.run(["lmp", "-h"], capture_output=True, text=True, timeout=30).stdout
    date = next(ln for ln in h.splitlines() if ln.strip()).split(" - ", 1)[1].strip()
    assert v.startswith(f"LAMMPS {date} (") and v.endswith("/lmp)"), (v, date)
    assert (get_engine("lammps").package_version() or "").startswith("LAMMPS ")


SETUP = """\
units si
atom_style sphere
dimension 2
boundary p p p
newton off
comm_modify mode single vel yes
atom_modify map array sort 0 0.0
read_data p.data
set group all density/disc 2650
neighbor 1e-5 bin
neigh_modify delay 0
pair_style gran/hooke 1e6 0 0 0 0 0
pair_coeff * *
fix 2d all enforce2d
fix i all nve/sphere disc
timestep 1e-7
thermo_style custom step atoms
thermo 4
"""

#: the deck of reference_runs.expect's frame rules, in LAMMPS syntax
FRAMES_TAIL = """\
dump d1 all custom 7 dump.a id x y
dump d2 all custom 3 dump.b id x y
run 10
run 0
run 5
reset_timestep 23
run 4
run 30 upto
undump d2
run 3
dump d3 all custom 5 dump.c id x y
dump_modify d3 first yes
reset_timestep 41
run 4
run 5
"""


@pytest.fixture
def data():
    import tempfile
    from pathlib import Path

    import numpy as np

    from reference_runs.datafile import write_data_file
    from reference_runs.demo_packings import perturbed_lattice

    p = perturbed_lattice(6, 6, seed=1)
    with tempfile.TemporaryDirectory() as tmp:
        write_data_file(Path(tmp) / "p.data", p, velocities=np.zeros((p.n, 2)))
        return (Path(tmp) / "p.data").read_bytes()


@needs_lmp
def test_lammps_frame_rule_is_the_deck_readers(tmp_path, data):
    # LAMMPS writes exactly the frames expect.py derives (measured rule, same as LIGGGHTS')
    deck = SETUP + FRAMES_TAIL
    outputs = ["dump.a", "dump.b", "dump.c"]
    res = run_job(tmp_path / "job", deck, {"p.data": data}, outputs=outputs, progress=False, engine="lammps")
    exp = expected_evidence(deck)
    got = {f: dump_frame_steps(tmp_path / "job" / f)[0] for f in outputs}
    assert got["dump.a"] == (0, 7, 14, 28, 42, 49) and got["dump.b"] == (0, 3, 6, 9, 12, 15, 24, 27, 30)
    assert got["dump.c"] == (41, 45, 50)  # first yes: the first step 41 too
    assert {f: exp.dumps[f].steps for f in outputs} == got
    assert [r.end for r in exp.runs] == [int(r.steps[-1]) for r in res.log.runs]
    assert res.manifest["warnings"] == []  # LAMMPS prints no WARNING on this deck


@needs_lmp
def test_lammps_job_run_reuse_verify_cycle(tmp_path, data):
    job = tmp_path / "job"
    deck = SETUP + "dump d1 all custom 5 dump.atoms id x y\nrun 20\n"
    r1 = run_job(job, deck, {"p.data": data}, outputs=["dump.atoms"], progress=False, engine="lammps")
    m = r1.manifest
    assert not r1.skipped and m["status"] == "ok" and m["engine"] == "lammps" and m["deck"] == "in.lammps"
    assert m["engine_version"].startswith("LAMMPS ") and m["engine_binary"].endswith("/lmp")
    assert m["command"][0].endswith("/lmp") and "liggghts_version" not in m
    assert m["evidence"]["dumps"]["dump.atoms"]["frames_got"] == 5 and is_complete(job, engine="lammps")
    assert verify_job(job, engine="lammps") == [] and not (job / "in.liggghts").exists()
    assert verify_job(job, engine="liggghts") == ["the job was run by lammps, not liggghts"]
    r2 = run_job(job, deck, {"p.data": data}, outputs=["dump.atoms"], progress=False, engine="lammps")
    assert r2.skipped and r2.manifest == m
    # a changed output is found and the job is rerun automatically
    with open(job / "dump.atoms", "a") as fh:
        fh.write("garbage\n")
    assert any("dump.atoms changed" in p for p in verify_job(job, require_hashes=True))
    r3 = run_job(job, deck, {"p.data": data}, outputs=["dump.atoms"], progress=False, engine="lammps")
    assert not r3.skipped and any("dump.atoms changed" in p for p in r3.manifest["rerun_reason"])
    assert verify_job(job, require_hashes=True, engine="lammps") == []


def test_stored_liggghts_job_is_not_reused_as_lammps(tmp_path, monkeypatch):
    # the stored LIGGGHTS Taylor job, asked for as a LAMMPS job with the very same deck and inputs
    job = tmp_path / "taylor"
    shutil.copytree(STORED / TAYLOR_CASE, job)
    m = json.loads((job / "manifest.json").read_text())
    deck = (job / "in.liggghts").read_text()
    files = {name: (job / name).read_bytes() for name in m["inputs"]}
    assert verify_job(job, engine="liggghts") == [] and verify_job(job) == []
    assert verify_job(job, engine="lammps") == ["the job was run by liggghts, not lammps"]
    assert not is_complete(job, engine="lammps")
    monkeypatch.setenv("PATH", str(tmp_path / "empty"))
    outputs = list(m["outputs"])
    with pytest.raises(
        ReferenceRunError,
        match=r"fails verification: the job was run by liggghts, not lammps[;.].*"
        r"It cannot be rerun here: the `lmp` binary",
    ):
        run_job(job, deck, files, outputs=outputs, progress=False, engine="lammps")
    assert read_manifest(job) == m and not (job / "in.lammps").exists()  # left untouched


LAMMPS_TIMING = """\
Per MPI rank memory allocation (min/avg/max) = 9.853 | 9.855 | 9.857 Mbytes
Step Atoms
       0     1020
     300     1020
Loop time of 0.0797981 on 2 procs for 300 steps with 1020 atoms

MPI task timing breakdown:
Section |  min time  |  avg time  |  max time  |%varavg| %total
---------------------------------------------------------------
Pair    | 0.024      | 0.025219   | 0.0264     |   2.1 | 31.60
Neigh   | 0.0066     | 0.0067697  | 0.0069     |   1.0 |  8.48
Comm    | 0.0201     | 0.020895   | 0.0217     |   1.7 | 26.18
Output  | 0.0022     | 0.002278   | 0.0023     |   0.1 |  2.85
Modify  | 0.0026     | 0.0026487  | 0.0027     |   0.2 |  3.32
Other   |            | 0.02199    |            |       | 27.56
"""


def test_bench_reads_the_lammps_timing_table():
    from bench._dem_job import lammps_breakdown

    parts, mem = lammps_breakdown(LAMMPS_TIMING)
    assert mem == 9.857  # the largest rank
    assert parts == {
        "Pair": 0.025219,
        "Neigh": 0.0067697,
        "Comm": 0.020895,
        "Output": 0.002278,
        "Modify": 0.0026487,
        "Other": 0.02199,
    }
    assert lammps_breakdown("Loop time of 1 on 1 procs for 1 steps with 1 atoms\n") == ({}, None)


def test_a_serial_job_runs_as_a_lone_mpi_singleton_and_an_mpi_job_keeps_open_mpis_defaults(monkeypatch):
    from reference_runs.engines import SERIAL_MPI_ENV

    for key in SERIAL_MPI_ENV:
        monkeypatch.delenv(key, raising=False)
    for name in ("liggghts", "lammps"):
        serial, mpi = get_engine(name).env(1), get_engine(name).env(2)
        assert {k: serial.get(k) for k in SERIAL_MPI_ENV} == SERIAL_MPI_ENV
        assert not set(SERIAL_MPI_ENV) & set(mpi)  # btl self alone would stop two ranks from talking
    monkeypatch.setenv("OMPI_MCA_btl", "tcp,self")  # the user's own choice is kept
    assert get_engine("lammps").env(1)["OMPI_MCA_btl"] == "tcp,self"


def _timing_free(text: str) -> list:
    """A log without the lines that hold wall times (they differ between any two runs)."""
    words = ("time", "Time", "Performance", "CPU", "Pair ", "Neigh ", "Comm ", "Output ", "Modify ", "Other ")
    return [ln for ln in text.splitlines() if not any(w in ln for w in words) and "|" not in ln]


@needs_lmp
def test_a_serial_jobs_outputs_are_the_same_without_the_serial_mpi_settings(tmp_path, monkeypatch):
    """The stored biaxial-short LAMMPS deck (120 disks, 3000 steps, 7 dump frames) run with the serial
    settings and with Open MPI's defaults: the dump byte for byte, the log but for its timings."""
    import reference_runs.engines as engines

    d = STORED / "biaxial-short-lammps"
    deck, files = (d / "in.lammps").read_text(), {"data.biaxial": d / "data.biaxial"}
    runs = {}
    for label, settings in (("serial", engines.SERIAL_MPI_ENV), ("defaults", {})):
        monkeypatch.setattr(engines, "SERIAL_MPI_ENV", settings)
        for key in engines.SERIAL_MPI_ENV if settings else ():
            monkeypatch.delenv(key, raising=False)
        run_job(tmp_path / label, deck, files, outputs=["dump.atoms"], progress=False, engine="lammps")
        runs[label] = tmp_path / label
    a, b = runs["serial"], runs["defaults"]
    assert (a / "dump.atoms").read_bytes() == (b / "dump.atoms").read_bytes()
    assert (a / "dump.atoms").read_bytes().count(b"ITEM: TIMESTEP") == 7
    assert _timing_free((a / "log.lammps").read_text()) == _timing_free((b / "log.lammps").read_text())
