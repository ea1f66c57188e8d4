"""Every option of every gransim command is checked once, at the boundary: a bad value exits 2 with
the option's name on stderr before any computation starts, and no output overwrites an input.

The property tests generate bad values for each numeric and named option (0, negatives, NaN, inf,
huge, non-numbers, as applicable to what the option means) and run :func:`gransim.cli.main` in
process with every long computation replaced by a function that fails the test, so each example
takes milliseconds. :func:`test_every_option_is_covered` reads the commands' parsers: an option
added without an entry in the tables below fails it.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gransim import Packing
from gransim.cli import build_parser, main, plugin_commands
from gransim.io import save_packing

#: the commands of the plug-ins above gransim (entry points of reference_runs: ``reference``,
#: ``replay``; of validation: ``validate``): their options are swept by
#: tests/faults/test_harness_options.py, whose fakes stand in for the reference codes' jobs and the
#: validation cases that these commands start; gransim's own tests never import those packages
#: (tests/test_boundaries.py keeps gransim below them)
HARNESS_COMMANDS = ("reference", "replay", "validate")


def _subcommands(parser: argparse.ArgumentParser) -> dict:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices


#: every command of gransim's parser but the harness plug-ins: a command added tomorrow is swept
#: by the tests below (and fails test_every_option_is_covered until its options have entries)
COMMANDS = tuple(sorted(c for c in _subcommands(build_parser()) if c not in HARNESS_COMMANDS))
INT64_MAX = 2**63 - 1


# ----------------------------------------------------------------------------------------------
# bad values, by what the option means
# ----------------------------------------------------------------------------------------------
def _not_a_float(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return True
    return False


#: words that are not numbers ("nan", "inf", "infinity" are numbers to float(); left out here)
WORDS = st.text(alphabet="abcdefgxyz_+-.", min_size=1, max_size=8).filter(_not_a_float)
NON_FINITE = st.sampled_from(["nan", "-nan", "inf", "-inf", "1e999", "-1e999"])


def _num(x: float) -> str:
    return repr(float(x))


def positive():
    """Finite and > 0."""
    return st.one_of(NON_FINITE, WORDS, st.just("0"), st.floats(max_value=0.0, allow_nan=False).map(_num))


def non_negative():
    """Finite and >= 0."""
    return st.one_of(NON_FINITE, WORDS, st.floats(max_value=0.0, exclude_max=True, allow_nan=False).map(_num))


def between(low, high, low_open=True, high_open=True):
    """Finite in (low, high) (the ends included when not open)."""
    below = st.floats(max_value=low, exclude_max=not low_open, allow_nan=False).map(_num)
    above = st.floats(min_value=high, exclude_min=not high_open, allow_nan=False).map(_num)
    return st.one_of(NON_FINITE, WORDS, below, above)


def count(low, high=INT64_MAX):
    """An integer in [low, high]: smaller, larger (beyond 64 bits at the default), fractions,
    non-numbers (some options also take ``1e5``: no whole float is drawn)."""
    return st.one_of(
        st.integers(max_value=low - 1).map(str),
        st.integers(min_value=high + 1, max_value=high + 2**80).map(str),
        st.sampled_from(["2.5", "-0.5", "nan", "inf", ""]),
        WORDS,
    )


def junk(valid=()):
    """A name that is none of the valid ones (no ':' so it is never a scheduler address)."""
    return st.text(alphabet="abcdefgxyz0123456789_-", min_size=1, max_size=10).filter(
        lambda s: s not in valid and not s.startswith("-")
    )


#: {command: {option: strategy of values that must be refused}}, values given as OPTION=VALUE
BAD = {
    "biaxial": {
        "--strain": st.one_of(positive(), st.floats(min_value=0.5, allow_nan=False).map(_num)),
        "--kn": positive(),
        "--kt-ratio": non_negative(),
        "--mu": non_negative(),
        "--density": positive(),
        "--confining": positive(),
        "--strain-rate": positive(),
        "--inertial-number": positive(),
        "--damping-ratio": non_negative(),
        "--steps-per-contact": positive(),
        "--consolidation-tol": between(0.0, 1.0),
        "--consolidation-steps": count(1),
        "--series-every": count(1),
        "--snapshot-every": count(1),
        "--checkpoint-every": count(0),
        "--threads": count(1),
        "--flavour": junk(("liggghts", "lammps")),
        "--law": junk(),
        "--law-param": st.one_of(WORDS.filter(lambda s: "=" not in s), st.just("k=v=")),
    },
    "dem-export": {"--step": count(0)},
    "info": {"--group": st.sampled_from(["", "/", " ", "//"])},
    "pack": {
        "--n": count(2),
        "--seed": count(0),
        "--solid-fraction": between(0.0, 0.95),
        "--mean-overlap": between(0.0, 0.5, high_open=False),
        "--force-tol": positive(),
        "--friction": non_negative(),
        "--pressure": between(0.0, 1.0),
        "--mean-diameter": positive(),
        "--density": positive(),
        "--distribution": junk(("quartz-sand", "kuhn-1002")),
    },
    "packings": {"--only": junk()},
    "rve-check": {"--kn": positive(), "--tol": non_negative()},
    "rve-study": {
        "--kn": positive(),
        "--steps": count(1, 100_000),
        "--workers": count(1, max(8, 4 * (os.cpu_count() or 1))),
        "--scheduler": junk(),
    },
    "rve-stress": {"--kn": positive(), "--rve": junk()},
    "shear": {
        "--strain": positive(),
        "--rate": positive(),
        "--inertial-number": positive(),
        "--servo": positive(),
        "--kn": positive(),
        "--damping-ratio": non_negative(),
        "--steps-per-contact": positive(),
        "--series-every": count(1),
        "--snapshot-every": count(0),
        "--checkpoint-every": count(0),
        "--threads": count(1),
        "--flavour": junk(("lammps",)),
        "--law": junk(),
        "--law-param": st.one_of(WORDS.filter(lambda s: "=" not in s), st.just("k=v=")),
    },
    "slope": {
        "--load-steps": count(1, 100_000),
        "--dead-load-steps": count(1, 100_000),
        "--stop-after": count(1),
        "--tol": between(0.0, 1.0),
        "--min-fraction": between(0.0, 1.0, high_open=False),
        "--workers": count(1, max(8, 4 * (os.cpu_count() or 1))),
        "--scheduler": junk(),
        "--rve": junk(("taylor", "relaxed")),
        "--mesh": st.one_of(
            junk().filter(lambda s: not re.fullmatch(r"\d+x\d+", s)),
            st.sampled_from(["1x5", "0x0", "5x1", "2000x1000"]),
        ),
    },
    "slope-compare": {"--points": count(0)},
    "voidcells": {"--strain": NON_FINITE},
    "warmup": {
        "--jobs": count(1, 64),
        "--timeout": positive(),
        "--only": junk(),
    },
    "femxdem": {  # base_argv: --rve taylor with a --packing, 10 steps of 1e-4 m on the 0.1 m specimen
        "--rve": junk(("taylor", "j2")),
        "--mesh": st.one_of(
            junk().filter(lambda s: not re.fullmatch(r"\d+x\d+", s)),
            st.sampled_from(["", "0x4", "4x0", "201x1", "2x4x1", "x", "2x", "-2x4"]),
        ),
        "--steps": count(1, 100_000),
        "--gauss": count(2, 5),
        "--pressure": st.one_of(positive(), st.floats(min_value=1e8, exclude_min=True).map(_num)),
        # 1e-12 m to 0.05 m, and 10 steps short of the 0.1 m height: below 0.01 m
        "--top-step": between(1e-12, 0.01, low_open=False),
        "--tol": between(1e-12, 1.0, low_open=False),
        "--max-iter": count(1, 1000),
        "--stop-after": count(1, 10),
        "--workers": count(1, max(8, 4 * (os.cpu_count() or 1))),
        "--scheduler": junk(),
        # steps 1..10 (the base's 10 steps), comma-separated, each once
        "--field-steps": st.one_of(count(1, 10), st.sampled_from(["", ",", "1,,2", "0,5", "5,11", "3,3", "1;2"])),
        # Gauss points of --rve dem only: the base (--rve taylor) refuses any value, and a dem line too
        "--rve-pictures": st.one_of(count(0, 31), st.sampled_from(["0", "0,31", "", "1,1"])),
        # the perturbation h of --tangent perturbation, 2e-5 to 1e-2 (the base's stand-in refuses any value)
        "--tangent-step": between(2e-5, 1e-2, low_open=False, high_open=False),
    },
}

#: options that name files or folders: the explicit tests below (outputs that are inputs, that
#: cannot be written, that are not regular files; missing inputs are refused by check_input)
PATHS = {
    "biaxial": {"--packing", "-o", "--plot"},
    "dem-export": {"run", "--vtu", "--plot"},
    "info": {"file"},
    "pack": {"-o", "--vtu"},
    "packings": {"--out"},
    "rve-check": {"--packings", "--packing-dir"},
    "rve-study": {"--packings", "--packing-dir", "-o"},
    "rve-stress": {"file"},
    "shear": {"--packing", "-o", "--plot"},
    "slope": {"--packing", "--packing-dir", "--out"},
    "slope-compare": {"results", "--packing", "--packing-dir", "--out"},
    "voidcells": {"run", "--out"},
    "warmup": {"--keep", "--packing"},
    "femxdem": {"--packing", "--packing-dir", "--out"},
}
#: options checked by a test of their own here (not by a strategy of single bad values)
OWN_TEST = {"rve-stress": {"--F"}}


# ----------------------------------------------------------------------------------------------
# fixtures: small files, and every long computation replaced by a failure
# ----------------------------------------------------------------------------------------------
def _lattice(n_side: int = 4) -> Packing:
    a = 1e-3
    ii, jj = np.meshgrid(np.arange(n_side), np.arange(n_side), indexing="ij")
    x = np.column_stack([ii.ravel(), jj.ravel()]) * a + 0.5 * a
    return Packing(positions=x, radii=np.full(n_side * n_side, 0.515 * a), cell=np.eye(2) * n_side * a)


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("cli-options")
    p = save_packing(d / "p.h5", _lattice())
    other = save_packing(d / "q.h5", _lattice())
    return {"P": str(p), "Q": str(other), "D": str(d)}


def _boom(*a, **k):
    raise AssertionError("the computation started before the options were checked")


#: (module, attribute) of every long computation (and every reader of a run the checks precede)
COMPUTATIONS = (
    ("gransim.dem.biaxial", "run_biaxial"),
    ("gransim.dem.sheared", "run_shear_file"),
    ("gransim.dem.output", "read_run"),
    ("gransim.dem.output", "snapshot_to_vtu"),
    ("gransim.dem.output", "plot_stress_strain"),
    ("gransim.generation", "make_packing"),
    ("gransim.generation", "compact_packing"),
    ("gransim.generation", "standard_packings"),
    ("gransim.rve.study", "run_study"),
    ("gransim.rve.reference", "crosscheck"),
    ("gransim.rve", "homogenize"),
    ("gransim.fem.run", "run_slope_case"),
    ("gransim.fem.run", "compare_slope"),
    ("gransim.fem.compare", "compare_slopes"),
    ("gransim.voidcell.io", "load_run_snapshots"),
    ("gransim.io", "read_provenance"),
    ("gransim.cli.cmd_warmup", "run_steps"),
    ("gransim.cli.cmd_rve", "make_executor"),  # a LocalCluster of --workers processes
    ("gransim.cli.cmd_slope", "make_executor"),
    ("gransim.fem.femxdem", "run_femxdem"),
    ("gransim.fem.femxdem", "standin_law"),  # the Taylor stand-in's consolidation
    ("gransim.cli.cmd_femxdem", "make_executor"),
)


@pytest.fixture
def no_compute(monkeypatch):
    import importlib

    for mod, name in COMPUTATIONS:
        monkeypatch.setattr(importlib.import_module(mod), name, _boom)


def run(argv) -> tuple[int, str]:
    """``gransim argv`` in process: (exit status, stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main([str(a) for a in argv])
        except SystemExit as exc:  # argparse: usage errors exit 2
            rc = exc.code
    return rc, err.getvalue()


def base_argv(command: str, f: dict) -> list:
    """A command line of ``command`` that is valid but for the option under test."""
    P, Q, D = f["P"], f["Q"], f["D"]
    return {
        "biaxial": ["biaxial", "--packing", P, "-o", f"{D}/b.h5", "--mode", "parallel"],
        "dem-export": ["dem-export", P, "--vtu", f"{D}/s.vtu"],
        "info": ["info", P],
        "pack": ["pack", "--n", "40", "-o", f"{D}/pk.h5"],
        "packings": ["packings", "--out", f"{D}/std"],
        "rve-check": ["rve-check", "--packings", P],
        "rve-study": ["rve-study", "--packings", P, "-o", f"{D}/rs"],
        "rve-stress": ["rve-stress", P],
        "shear": ["shear", "--packing", P, "--strain", "1e-3", "-o", f"{D}/s.h5"],
        "slope": ["slope", "--out", f"{D}/sl", "--packing-dir", f"{D}/std", "--mesh", "3x3"],
        "slope-compare": ["slope-compare", P, Q, "--out", f"{D}/sc"],
        "voidcells": ["voidcells", P, "--out", f"{D}/vc"],
        "warmup": ["warmup"],
        "femxdem": ["femxdem", "--packing", P, "--out", f"{D}/fx"],
    }.get(command) or pytest.fail(f"gransim {command}: no valid command line in base_argv: add one")


def _options(command: str):
    parser = build_parser([command])
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    return sub.choices[command]._actions


def test_biaxial_and_shear_take_the_same_engine_options():
    # the one engine's choices reach both commands under the same names and choices
    shared = ("--order", "--threads", "--checkpoint-every", "--resume", "--flavour", "--law", "--law-param")
    got = {}
    for command in ("biaxial", "shear"):
        acts = {o: a for a in _options(command) for o in a.option_strings}
        missing = [o for o in shared if o not in acts]
        assert not missing, (command, missing)
        got[command] = {o: (acts[o].choices, acts[o].default if o != "--flavour" else None) for o in shared}
    assert got["biaxial"] == got["shear"]


# ----------------------------------------------------------------------------------------------
# every option has a check, and a test
# ----------------------------------------------------------------------------------------------
def test_commands_come_from_the_parser():
    """COMMANDS is gransim's parser less the harness plug-ins, and those are plug-ins indeed (an
    entry point each): a built-in command cannot hide behind the exclusion."""
    assert {"biaxial", "femxdem", "slope", "warmup"} <= set(COMMANDS)
    plugins = {ep.name for ep in plugin_commands()}
    assert set(HARNESS_COMMANDS) <= plugins, plugins
    assert not set(HARNESS_COMMANDS) & set(_subcommands(build_parser(["info"])))  # built-ins only


@pytest.mark.parametrize("command", COMMANDS)
def test_every_option_is_covered(command):
    """Every option that takes a value and has no fixed choices is in BAD, PATHS or OWN_TEST."""
    known = set(BAD.get(command, {})) | PATHS.get(command, set()) | OWN_TEST.get(command, set())
    missing = []
    for a in _options(command):
        if a.nargs == 0 or a.choices is not None or a.dest == "help":  # flags, choices: argparse
            continue
        names = a.option_strings or [a.dest]
        if not known & set(names):
            missing.append("/".join(names))
    assert not missing, f"gransim {command}: options without a check in this test: {missing}"


CASES = [(c, o) for c in COMMANDS for o in BAD.get(c, {})]


@pytest.mark.parametrize("command, option", CASES, ids=[f"{c} {o}" for c, o in CASES])
@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture]
)
@given(data=st.data())
def test_bad_value_exits_2_naming_the_option(command, option, data, files, no_compute):
    value = data.draw(BAD[command][option], label=option)
    law = {"biaxial": "hooke-liggghts", "shear": "hooke-lammps"}.get(command)
    with_law = ["--law", law] if option == "--law-param" else []  # else: refused for lacking --law
    argv = base_argv(command, files) + with_law + [f"{option}={value}"]
    rc, err = run(argv)
    assert rc == 2, f"gransim {' '.join(argv[:1])} ... {option}={value!r}: exit {rc}, stderr {err!r}"
    assert option in err, f"{option}={value!r}: the message does not name the option: {err!r}"
    assert "Traceback" not in err


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    F=st.one_of(
        st.lists(st.sampled_from(["nan", "inf", "-inf"]), min_size=1, max_size=4).map(
            lambda v: v + ["1"] * (4 - len(v))
        ),
        # det F <= 0: F11 F22 - F12 F21 with F11 = a, F22 = b of opposite signs (or one 0), F12 = F21 = 0
        st.tuples(st.floats(0, 10), st.floats(-10, 0)).map(lambda t: [_num(t[0]), "0", "0", _num(t[1])]),
    )
)
def test_rve_stress_deformation_gradient(F, files, no_compute):
    rc, err = run(["rve-stress", files["P"], "--F", *F])
    assert rc == 2 and "--F" in err, (F, rc, err)


# ----------------------------------------------------------------------------------------------
# outputs that are inputs
# ----------------------------------------------------------------------------------------------
def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _spell(kind: str, target: Path, workdir: Path) -> str:
    """Another name of the file ``target`` (in ``workdir``, the current folder of the run)."""
    if kind == "same":
        return str(target)
    if kind == "relative":  # ./x.h5 against /abs/x.h5
        return "./" + os.path.relpath(target, workdir)
    if kind == "dotdot":
        (workdir / "sub").mkdir(exist_ok=True)
        return str(workdir / "sub" / ".." / os.path.relpath(target, workdir))
    link = workdir / f"link-{kind}{target.suffix}"
    if link.exists() or link.is_symlink():
        link.unlink()
    if kind == "symlink":
        link.symlink_to(target)
    else:
        os.link(target, link)
    return str(link)


SPELLINGS = ("same", "relative", "dotdot", "symlink", "hardlink")


@pytest.mark.parametrize("spelling", SPELLINGS)
@pytest.mark.parametrize("command", ["biaxial", "shear"])
def test_output_equal_to_the_packing_is_refused(command, spelling, tmp_path, monkeypatch, capsys):
    """-o naming the --packing file (or a link to it) exits 2 before the run; the packing is kept
    byte for byte. The run is the real one: before the check it overwrote the packing."""
    monkeypatch.chdir(tmp_path)
    packing = save_packing(tmp_path / "p.h5", _lattice())
    before = _sha(packing)
    out = _spell(spelling, packing, tmp_path)
    argv = {
        "biaxial": [
            "biaxial",
            *("--packing", "p.h5", "-o", out, "--strain", "1e-5", "--consolidation-steps", "50"),
            "--allow-unsettled",
        ],
        "shear": ["shear", "--packing", "p.h5", "-o", out, "--strain", "1e-5", "--inertial-number", "0.1"],
    }[command]
    rc = main(argv)
    err = capsys.readouterr().err
    assert rc == 2, err
    assert "-o/--output" in err and "--packing" in err and err.count("\n") == 1, err
    assert _sha(packing) == before


def _other_inputs(tmp_path: Path):
    """(argv, output option, the input file) of every other command whose output could be an input."""
    P = save_packing(tmp_path / "p.h5", _lattice())
    curve = tmp_path / "curve.csv"
    curve.write_text("size_mm,passing\n0.1,0\n0.2,50\n0.4,100\n")
    for name in ("a.vtu", "b.png"):  # outputs that exist: a link to them can be made
        (tmp_path / name).write_bytes(b"x")
    run_as_png = save_packing(tmp_path / "run.png", _lattice())  # any file: read after the checks
    run_as_vtu = save_packing(tmp_path / "run.vtu", _lattice())
    rs = tmp_path / "rs"
    rs.mkdir()
    study_in = save_packing(rs / "rve_study.h5", _lattice())
    sl = tmp_path / "sl"
    sl.mkdir()
    slope_in = save_packing(sl / "slope.h5", _lattice())
    keep = tmp_path / "keep"
    keep.mkdir()
    keep_in = save_packing(keep / "p.h5", _lattice())
    sc = tmp_path / "sc"
    sc.mkdir()
    compare_in = save_packing(sc / "compare.md", _lattice())
    fx = tmp_path / "fx"
    fx.mkdir()
    femxdem_in = save_packing(fx / "femxdem.h5", _lattice())
    (fx / "checkpoint").mkdir()
    checkpoint_in = save_packing(fx / "checkpoint" / "step_001.h5", _lattice())
    return [
        (["pack", "--n", "40", "--distribution", str(curve), "-o", "OUT"], "-o/--output", curve),
        (["pack", "--n", "40", "-o", str(tmp_path / "a.vtu"), "--vtu", "OUT"], "--vtu", tmp_path / "a.vtu"),
        (["dem-export", str(run_as_png), "--plot", "OUT"], "--plot", run_as_png),
        (["dem-export", str(run_as_vtu), "--vtu", "OUT"], "--vtu", run_as_vtu),
        (
            ["biaxial", "--packing", str(P), "-o", str(tmp_path / "b.png"), "--plot", "OUT"],
            "--plot",
            tmp_path / "b.png",
        ),
        (["rve-study", "--packings", "OUT", "-o", str(rs)], "-o/--out", study_in),
        (["slope", "--packing", "OUT", "--out", str(sl), "--packing-dir", str(tmp_path / "std")], "--out", slope_in),
        (["slope-compare", str(P), "OUT", "--out", str(sc)], "--out", compare_in),
        (["warmup", "--keep", str(keep), "--packing", "OUT"], "--packing", keep_in),
        (["femxdem", "--packing", "OUT", "--out", str(fx)], "--out", femxdem_in),
        (["femxdem", "--packing", "OUT", "--out", str(fx)], "--packing", checkpoint_in),
    ]


@pytest.mark.parametrize("spelling", ("relative", "symlink", "hardlink"))
def test_no_command_writes_over_an_input(spelling, tmp_path, monkeypatch, no_compute):
    """Every other command whose output can name an input file (or a second output): exit 2,
    naming the option, the file kept. ``OUT`` is the file under another spelling."""
    monkeypatch.chdir(tmp_path)
    for argv, option, target in _other_inputs(tmp_path):
        before = _sha(target)
        name = _spell(spelling, Path(target), tmp_path)
        full = [name if a == "OUT" else a for a in argv]
        rc, err = run(full)
        assert rc == 2 and option in err, (full, rc, err)
        assert _sha(target) == before, full


# ----------------------------------------------------------------------------------------------
# --threads without threads, outputs that cannot be written
# ----------------------------------------------------------------------------------------------
@pytest.mark.parametrize("mode", [None, "serial"])
@pytest.mark.parametrize("threads", ["1", "2"])
def test_threads_need_the_parallel_mode(mode, threads, files, no_compute):
    argv = ["biaxial", "--packing", files["P"], "-o", f"{files['D']}/t.h5", "--threads", threads]
    rc, err = run(argv + (["--mode", mode] if mode else []))
    assert rc == 2 and "--threads" in err and "--mode parallel" in err and "--order fast" in err, err


@pytest.mark.parametrize("threads", ["1", "2"])
def test_shear_threads_need_the_fast_order(threads, files, no_compute):
    argv = ["shear", "--packing", files["P"], "--strain", "1e-3", "-o", f"{files['D']}/t.h5", "--threads", threads]
    rc, err = run(argv)
    assert rc == 2 and "--threads" in err and "--order fast" in err, err


def test_fast_order_takes_no_mode(files, no_compute):
    argv = ["biaxial", "--packing", files["P"], "-o", f"{files['D']}/t.h5", "--order", "fast", "--mode", "parallel"]
    rc, err = run(argv)
    assert rc == 2 and "--mode" in err and "--order fast" in err, err


@pytest.fixture(scope="module")
def unwritable(tmp_path_factory):
    """A folder in which no file can be created: a read-only one for a user; for root (who may write
    anywhere os.access allows), the sysfs root /sys."""
    d = tmp_path_factory.mktemp("ro")
    d.chmod(0o555)
    for cand in (d, Path("/sys")):
        try:
            probe = cand / ".probe"
            probe.touch()
            probe.unlink()
        except OSError:
            yield cand
            d.chmod(0o755)
            return
    d.chmod(0o755)
    pytest.skip("no folder here refuses a new file")


def _unwritable_cases(R: Path, f: dict):
    P, Q, D = f["P"], f["Q"], f["D"]
    return [
        (["pack", "--n", "40", "-o", R / "o.h5"], "-o/--output"),
        (["pack", "--n", "40", "-o", f"{D}/o.h5", "--vtu", R / "o.vtu"], "--vtu"),
        (["biaxial", "--packing", P, "-o", R / "o.h5"], "-o/--output"),
        (["biaxial", "--packing", P, "-o", f"{D}/o.h5", "--plot", R / "o.png"], "--plot"),
        (["shear", "--packing", P, "--strain", "1e-3", "-o", R / "o.h5"], "-o/--output"),
        (["shear", "--packing", P, "--strain", "1e-3", "-o", f"{D}/o.h5", "--plot", R / "o.png"], "--plot"),
        (["dem-export", P, "--vtu", R / "o.vtu"], "--vtu"),
        (["dem-export", P, "--plot", R / "o.png"], "--plot"),
        (["rve-study", "--packings", P, "-o", R / "rs"], "-o/--out"),
        (["rve-study", "--packing-dir", R / "std", "-o", f"{D}/rs"], "--packing-dir"),
        (["rve-check", "--packing-dir", R / "std"], "--packing-dir"),
        (["packings", "--out", R / "std"], "--out"),
        (["slope", "--out", R / "sl", "--packing-dir", f"{D}/std"], "--out"),
        (["slope", "--out", f"{D}/sl", "--packing-dir", R / "std"], "--packing-dir"),
        (["slope-compare", P, Q, "--out", R / "sc"], "--out"),
        (["slope-compare", P, Q, "--out", f"{D}/sc", "--packing-dir", R / "std"], "--packing-dir"),
        (["voidcells", P, "--out", R / "vc"], "--out"),
        (["warmup", "--keep", R / "k"], "--keep"),
        (["femxdem", "--out", R / "fx", "--packing-dir", f"{D}/std"], "--out"),
        (["femxdem", "--out", f"{D}/fx", "--packing-dir", R / "std"], "--packing-dir"),
    ]


def test_unwritable_outputs_exit_2_naming_the_option(unwritable, files, no_compute):
    for argv, option in _unwritable_cases(unwritable, files):
        rc, err = run(argv)
        assert rc == 2 and option in err and err.count("\n") == 1, (argv, rc, err)


def test_an_output_that_is_not_a_regular_file_is_refused(files, no_compute, tmp_path):
    """A pipe (or a device: -o /dev/full) as output: the atomic write would replace the node."""
    fifo = tmp_path / "fifo.h5"
    os.mkfifo(fifo)
    for argv, option in (
        (["pack", "--n", "40", "-o", fifo], "-o/--output"),
        (["biaxial", "--packing", files["P"], "-o", fifo], "-o/--output"),
        (["shear", "--packing", files["P"], "--strain", "1e-3", "-o", fifo], "-o/--output"),
    ):
        rc, err = run(argv)
        assert rc == 2 and option in err and "not a regular file" in err, (argv, rc, err)
    assert fifo.is_fifo()


def test_options_a_command_would_ignore_are_refused(files, no_compute, tmp_path):
    """An option that would have no effect is refused, like --threads in serial mode."""
    cases = [
        (
            ["rve-study", "--packings", files["P"], "--packing-dir", tmp_path / "std", "-o", tmp_path / "rs"],
            "--packing-dir",
        ),
        (["rve-check", "--packings", files["P"], "--packing-dir", tmp_path / "std"], "--packing-dir"),
        (["slope", "--out", tmp_path / "sl", "--load-steps", "2", "--stop-after", "4"], "--stop-after"),
        (["slope", "--out", tmp_path / "sl", "--relaxed-start", "trial"], "--relaxed-start"),
        (["rve-study", "--packings", files["P"], "--workers", "2", "--scheduler", "tcp://h:1"], "--workers"),
    ]
    fx = ["femxdem", "--out", tmp_path / "fx"]
    (tmp_path / "text.h5").write_text("not HDF5\n")
    cases += [
        (fx + ["--packing", tmp_path / "text.h5"], "--packing"),
        (fx + ["--workers", "2", "--scheduler", "tcp://h:1"], "--workers"),
        (fx + ["--rve", "j2", "--packing", files["P"]], "--packing"),
        (fx + ["--rve", "j2", "--packing-dir", tmp_path / "std"], "--packing-dir"),
        (fx + ["--packing", files["P"], "--packing-dir", tmp_path / "std"], "--packing-dir"),
        (fx + ["--full", "--mesh", "2x4", "--steps", "5"], "--full"),
        (fx + ["--element", "Q9", "--gauss", "2"], "--gauss"),
        (fx + ["--steps", "4", "--stop-after", "5"], "--stop-after"),
        (fx + ["--full", "--stop-after", "101"], "--stop-after"),
        (fx + ["--rve", "taylor", "--pressure", "0"], "--pressure"),
        (fx + ["--steps", "1000", "--top-step", "1e-4"], "--top-step"),
        (fx + ["--resume"], "--resume"),
    ]
    for argv, option in cases:
        rc, err = run(argv)
        assert rc == 2 and option in err, (argv, rc, err)


def test_large_counts_are_refused_before_they_overflow(files, no_compute):
    """Counts beyond 64 bits (numpy and numba counters) and beyond the float range."""
    for value in (str(2**63), str(10**400)):
        for argv, option in (
            (base_argv("biaxial", files), "--series-every"),
            (base_argv("shear", files), "--snapshot-every"),
            (base_argv("slope-compare", files), "--points"),
            (base_argv("dem-export", files), "--step"),
        ):
            rc, err = run(argv + [f"{option}={value}"])
            assert rc == 2 and option in err, (option, value, err)


def _value_options(command: str) -> list[str]:
    """The options of ``command`` that take one value (or one per use: append)."""
    out = []
    for a in _options(command):
        if a.option_strings and a.dest != "help" and a.nargs is None and a.choices is None:
            out.append(max(a.option_strings, key=len))
    return out


DASH_CASES = [(c, o) for c in COMMANDS for o in _value_options(c)]


@pytest.mark.parametrize("command, option", DASH_CASES, ids=[f"{c} {o}" for c, o in DASH_CASES])
def test_a_dash_dash_value_is_refused(command, option, files, no_compute):
    """``--option=--``: argparse (Python 3.11) stores an empty list, which ``if args.plot:`` read
    as "not given" and float() failed on with an internal error."""
    rc, err = run(base_argv(command, files) + [f"{option}=--"])
    assert rc == 2 and option in err and "Traceback" not in err, (command, option, rc, err)


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    """A short biaxial run of 30 disks (under a second)."""
    d = tmp_path_factory.mktemp("run")
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(["pack", "--n", "30", "--seed", "1", "-o", str(d / "p.h5")]) == 0
        argv = ["biaxial", "--packing", str(d / "p.h5"), "-o", str(d / "b.h5"), "--strain", "1e-4"]
        argv += ["--inertial-number", "1e-2", "--consolidation-steps", "200", "--allow-unsettled"]
        argv += ["--snapshot-every", "10", "--checkpoint-every", "0"]
        assert main(argv) == 0
    return d / "b.h5"


def test_values_checked_against_the_run_file_name_the_option(run_file, tmp_path):
    """A --step the run has no snapshot at, --step without --vtu (the plot ignored it), a
    voidcells --strain outside the run: exit 2 naming the option, nothing written."""
    cases = [
        (["dem-export", run_file, "--vtu", tmp_path / "s.vtu", "--step", "123456789"], "--step"),
        (["dem-export", run_file, "--plot", tmp_path / "f.png", "--step", "0"], "--step"),
        (["voidcells", run_file, "--strain", "0.5", "--out", tmp_path / "vc"], "--strain"),
    ]
    for argv, option in cases:
        rc, err = run(argv)
        assert rc == 2 and option in err and err.count("\n") == 1, (argv, rc, err)
    assert not any(tmp_path.iterdir())


def test_resume_without_a_run_file_is_refused(files, no_compute, tmp_path):
    """biaxial --resume with no -o file to continue: it started a new run (exit 0) instead."""
    rc, err = run(["biaxial", "--packing", files["P"], "-o", tmp_path / "none.h5", "--resume"])
    assert rc == 2 and "--resume" in err and "none.h5" in err, err
