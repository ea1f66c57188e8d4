"""One numba cache for every way gransim is run, and the warm-up that fills it (docs/startup.md).

The cache-directory checks run in fresh interpreters: the choice is made when gransim is first
imported, before numba reads its environment, so it cannot be observed in this test process.
"""

from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import pytest

from gransim import _numba_cache_dir
from gransim.cli import cmd_warmup
from gransim.errors import InputError

SITE = sysconfig.get_paths()["purelib"]  # the venv's site-packages (gransim's editable install)


def _env(**kw):
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update({k: v for k, v in kw.items() if v is not None})
    return env


def _py(code: str, env: dict, python: str = sys.executable) -> list[str]:
    code = f"import site; site.addsitedir({SITE!r})\n" + textwrap.dedent(code)
    r = subprocess.run([python, "-c", code], check=False, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    return r.stdout.split()


def test_cache_dir_rule(tmp_path):
    """A writable venv keeps the cache in its prefix (== make's .venv/numba-cache); outside a venv
    it is the user's cache dir, XDG_CACHE_HOME first."""
    venv = tmp_path / "venv"
    venv.mkdir()
    assert _numba_cache_dir(str(venv), "/usr", {}) == str(venv / "numba-cache")
    xdg = {"XDG_CACHE_HOME": str(tmp_path / "xdg")}
    assert _numba_cache_dir("/usr", "/usr", xdg) == str(tmp_path / "xdg" / "gransim" / "numba")
    assert _numba_cache_dir("/usr", "/usr", {}) == os.path.join(os.path.expanduser("~"), ".cache", "gransim", "numba")
    missing = tmp_path / "no-such-venv"  # not writable (absent): fall back to the user cache
    assert _numba_cache_dir(str(missing), "/usr", xdg) == str(tmp_path / "xdg" / "gransim" / "numba")


def test_make_and_plain_runs_share_one_cache():
    """`make` exports NUMBA_CACHE_DIR=$(CURDIR)/.venv/numba-cache; a plain `import gransim` from the
    checkout's venv, without the variable, lands on the same directory (and children inherit it)."""
    make_dir = Path(__file__).resolve().parents[2] / ".venv" / "numba-cache"
    if Path(sys.prefix).resolve() != make_dir.parent.resolve():
        pytest.skip("not running from the checkout's .venv")
    out = _py(
        """
        import os, gransim, numba
        from gransim.geometry import bins  # a module with kernels decorated through gransim._numba
        print(numba.config.CACHE_DIR, os.environ["NUMBA_CACHE_DIR"])
        """,
        _env(),
    )
    assert Path(out[0]).resolve() == make_dir.resolve() and out[0] == out[1]


def test_user_choice_is_kept(tmp_path):
    out = _py("import gransim, numba; print(numba.config.CACHE_DIR)", _env(NUMBA_CACHE_DIR=str(tmp_path)))
    assert out == [str(tmp_path)]


_KERNEL = """
from gransim._numba import njit

@njit
def f(x):
    return 2.0 * x + 1.0
"""

_RUN = """
    import sys, gransim, numba  # the order of the two imports is argv[1]
    sys.path.insert(0, {mod!r})
    import kmod
    assert kmod.f(3.0) == 7.0
    st = kmod.f.stats
    print(numba.config.CACHE_DIR, kmod.f._cache.cache_path, st.cache_hits.total(), st.cache_misses.total(),
          numba.config.THREADING_LAYER_PRIORITY[0])
    """


@pytest.mark.parametrize("numba_first", [False, True])
def test_second_process_loads_what_the_first_compiled(tmp_path, numba_first):
    """End to end, in a scratch venv (sys.prefix != base_prefix) and with NUMBA_CACHE_DIR unset: the
    first process compiles a gransim-decorated kernel into <venv>/numba-cache (one miss), a second
    process loads it from there (one hit, no miss). With numba imported before gransim the
    directory must still be the venv's (numba.config.CACHE_DIR set after numba read its
    environment), and survive numba's reload of its configuration at the first compilation."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    python = str(venv / "bin" / "python")
    mod = tmp_path / "mod"
    mod.mkdir()
    (mod / "kmod.py").write_text(_KERNEL)
    code = _RUN.format(mod=str(mod))
    if numba_first:
        code = code.replace("import sys, gransim, numba", "import sys, numba, gransim")
    env = _env(NUMBA_THREADING_LAYER=None)
    env.pop("NUMBA_THREADING_LAYER", None)
    first = _py(code, env, python)
    second = _py(code, env, python)
    want = str(venv / "numba-cache")
    assert first[0] == want and first[1].startswith(want + os.sep)
    assert (first[2], first[3]) == ("0", "1")  # compiled and saved
    assert (second[2], second[3]) == ("1", "0")  # loaded, nothing compiled
    assert first[4] == "omp"  # gransim._numba's threading-layer choice not reset by a reload


def test_outside_a_venv_the_user_cache_is_used(tmp_path):
    """The base interpreter (no venv) with gransim on its path: the XDG user cache directory."""
    base = Path(sys.base_prefix) / "bin" / f"python{sys.version_info[0]}.{sys.version_info[1]}"
    if sys.prefix == sys.base_prefix or not base.exists():
        pytest.skip("needs a venv over a base interpreter")
    mod = tmp_path / "mod"
    mod.mkdir()
    (mod / "kmod.py").write_text(_KERNEL)
    xdg = tmp_path / "xdg"
    out = _py(_RUN.format(mod=str(mod)), _env(XDG_CACHE_HOME=str(xdg)), str(base))
    assert out[0] == str(xdg / "gransim" / "numba") and out[1].startswith(out[0] + os.sep)


def test_option_a_command_lacks_is_left_out():
    """The warm-up reads each command's parser: an option that does not exist (any more) is dropped,
    a command that does not exist makes the step a skip, the options that exist are kept."""
    opts = cmd_warmup.command_options()
    s = cmd_warmup.Step(
        "x",
        "biaxial",
        ("--packing", "p.h5"),
        (("--strain", "1e-4"), ("--no-such-option", "3"), ("--allow-unsettled",)),
    )
    assert cmd_warmup.argv_of(s, opts) == [
        "biaxial",
        "--packing",
        "p.h5",
        "--strain",
        "1e-4",
        "--allow-unsettled",
    ]
    assert cmd_warmup.argv_of(cmd_warmup.Step("y", "no-such-command"), opts) is None
    # every planned step maps onto a command that exists today
    for step in cmd_warmup.plan("all"):
        assert cmd_warmup.argv_of(step, opts) is not None, step.name
        assert all(a in {t.name for t in cmd_warmup.plan("all")} for a in step.after)


def test_a_failing_command_fails_the_warmup(tmp_path):
    """A command that fails is FAILED (exit status kept), the steps after it are skipped, the
    independent ones still run; the warm-up's own exit status is then 1."""
    steps = [
        cmd_warmup.Step("bad", "info", ("missing.h5",)),
        cmd_warmup.Step("after-bad", "info", ("missing.h5",), after=("bad",)),
        cmd_warmup.Step("fine", "pack", ("--help",)),
    ]
    with open(tmp_path / "log", "w") as log:
        recs = {r["name"]: r for r in cmd_warmup.run_steps(steps, str(tmp_path), 2, 300.0, out=log)}
    assert recs["bad"]["status"] == "FAILED" and recs["bad"]["returncode"] == 2
    assert recs["after-bad"]["status"] == "skipped"
    assert recs["fine"]["status"] == "ok"
    text = (tmp_path / "log").read_text()
    assert "gransim info missing.h5" in text and text.count("warmup: ") >= 3


def test_unknown_step_is_an_input_error(capsys):
    from gransim.cli import main

    assert main(["warmup", "--only", "no-such-step"]) == 2
    assert "--only" in capsys.readouterr().err


@pytest.mark.slow
def test_after_the_warmup_a_larger_run_compiles_nothing(tmp_path):
    """numba specialises on types, not sizes: after `gransim warmup` on a 60-disk packing, `gransim
    info` on a 1,020-disk one loads every kernel from the cache and compiles none (numba's own
    cache log, NUMBA_DEBUG_CACHE: no "saved", some "loaded"); the first, cold, run did save."""
    from bench.dem import assembly
    from gransim.io import save_packing

    save_packing(tmp_path / "tiny.h5", assembly(60))
    save_packing(tmp_path / "big.h5", assembly(1_000))
    env = _env(NUMBA_CACHE_DIR=str(tmp_path / "cache"), NUMBA_DEBUG_CACHE="1")
    cmd = [sys.executable, "-m", "gransim"]
    warm = subprocess.run(
        [
            *cmd,
            "warmup",
            "--laws",
            "default",
            "--packing",
            str(tmp_path / "tiny.h5"),
            "--only",
            "info",
            "--keep",
            str(tmp_path / "w"),
        ],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=1200,
        check=False,
    )
    assert warm.returncode == 0, warm.stdout + warm.stderr
    assert "warmup: info" in warm.stdout and " ok" in warm.stdout
    assert any(p.name.endswith(".nbi") for p in (tmp_path / "cache").rglob("*"))  # the cold run saved
    r = subprocess.run(
        [*cmd, "info", str(tmp_path / "big.h5")],
        env=env,
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    assert r.returncode == 0, r.stderr
    log = r.stdout + r.stderr
    assert "data loaded from" in log
    assert "data saved to" not in log, [ln for ln in log.splitlines() if "saved" in ln]


def _prerequisites(steps, name):
    by = {s.name: s for s in steps}
    seen, todo = set(), list(by[name].after)
    while todo:
        n = todo.pop()
        if n not in seen:
            seen.add(n)
            todo += list(by[n].after)
    return seen


@pytest.mark.parametrize("own_packing", [False, True])
def test_steps_sharing_kernels_run_one_after_the_other(own_packing):
    """Two processes compiling one kernel at once each compile it: every other biaxial step (and the
    frictional pack, which runs the same engine) waits for ``biaxial``, every other shear step for
    ``shear``, so that they load the engine's kernels instead of compiling them a second time."""
    steps = cmd_warmup.plan("all", own_packing=own_packing)
    for s in steps:
        if s.command == "biaxial" and s.name != "biaxial" or s.name == "pack --friction":
            assert "biaxial" in _prerequisites(steps, s.name), s.name
        if s.command == "shear" and s.name != "shear":
            assert "shear" in _prerequisites(steps, s.name), s.name
    assert "pack" in _prerequisites(steps, "pack --friction")


def test_law_sets():
    """--laws biaxial keeps every law's biaxial step and drops every law's shear step (make run's
    suite runs the sheared cell with its default law only) and the fast ordering's steps (its case
    is in the full suite); an unknown set is refused."""
    full = {s.name for s in cmd_warmup.plan("all")}
    run = {s.name for s in cmd_warmup.plan("biaxial")}
    default = {s.name for s in cmd_warmup.plan("default")}
    laws = [name for name, _, _ in cmd_warmup.law_names()]
    assert laws and all(f"biaxial --law {n}" in run for n in laws)
    assert not any(n.startswith("shear --law") for n in run)
    fast = {"biaxial --order fast", "shear --order fast"}
    assert fast <= full and not fast & run
    assert full - run == {n for n in full if n.startswith("shear --law")} | fast != set()
    assert default < run < full
    with pytest.raises(InputError, match="--laws"):
        cmd_warmup.plan("some")
