"""A hostile user's sweep over every ``gransim`` command: bad options, bad files, signals, a full disk.

Run it from the repository root (it takes a few minutes on two cores; the real ``liggghts`` and
``lmp`` are used where installed, a full disk needs root or ``unshare``)::

    .venv/bin/python tests/faults/sweep.py [--only SUBSTRING] [--jobs 2] [--json FILE]

Every case runs one ``gransim`` process in a fresh directory with a private ``TMPDIR`` and is
judged by the same rules, whatever the command:

- the process ends by itself, with an exit status the README allows (0, 1, 2, 129, 130, 143), never a
  signal's death (a segfault is -11 here, 139 through a shell), except by the signal the sweep
  sent: SIGKILL, or SIGINT / SIGTERM landing in the interpreter's last moments after a run that
  had ended (its output complete, nothing on stderr);
- no traceback, no "Exception ignored", at most a few lines on stderr for an error;
- a bad option or file gives exit 2 with the option's (or file's) name on stderr;
- no input file changed (SHA-256 before and after);
- no hidden ``.*.tmp`` file left anywhere under the case directory (after a SIGKILL: once the
  same command has run again, which removes a killed writer's temporaries), nothing left in its
  TMPDIR (after a SIGKILL: within 10 s, the watchdogs' time);
- no process of a reference code (``liggghts``, ``lmp``, ``mpirun``, ``orted``) left running;
- a comparison of non-finite numbers never says PASS.

Prints one line per finding and a summary; exits 1 when anything was found. Not collected by
pytest (its name does not start with ``test_``); ``tests/faults`` holds the unit tests of each rule.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
GRANSIM = [sys.executable, "-m", "gransim"]
CODES = ("liggghts", "lmp", "mpirun", "mpiexec", "orted", "prterun", "prted", "yade")
ALLOWED_RC = {0, 1, 2, 129, 130, 143}


@dataclass
class Case:
    name: str
    argv: list
    rc: set | None = None  # required exit statuses (None: any allowed one)
    names: tuple = ()  # strings stderr must contain when rc is 2
    inputs: tuple = ()  # files that must not change
    signal_at: float | None = None  # send ``sig`` this many seconds after the start
    sig: int = signal.SIGINT
    after: object = None  # callable(case_dir, proc) -> list of findings
    timeout: float = 120.0
    env: dict = field(default_factory=dict)
    wrap: list | None = None  # a command prefix (unshare, sh -c)


def _sha(path: Path):
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else None


def _code_pids(marker: str) -> set:
    """Live processes of a reference code that carry ``marker`` in their environment (every
    process a case starts inherits it, reference codes included)."""
    out = set()
    want = marker.encode()
    for d in Path("/proc").iterdir():
        if d.name.isdigit():
            try:
                comm = (d / "comm").read_text().strip()
                state = (d / "stat").read_text().rsplit(")", 1)[1].split()[0]
                env = (d / "environ").read_bytes().split(b"\0")
            except OSError:
                continue
            if comm in CODES and state not in ("Z", "X") and want in env:
                out.add(int(d.name))
    return out


def _fixtures(root: Path) -> dict:
    """The shared inputs: a packing, a short biaxial run, a shear run, a packing with two
    coincident disks, a text file posing as HDF5, a read-only directory."""
    env = dict(os.environ, GRANSIM_QUIET="1")
    root.mkdir(parents=True, exist_ok=True)
    p = root / "p.h5"

    def run(*a):
        subprocess.run([*GRANSIM, *a], cwd=root, env=env, check=True, capture_output=True, timeout=600)

    run("pack", "--n", "60", "-o", str(p))
    run("biaxial", "--packing", str(p), "-o", str(root / "b.h5"), "--strain", "0.0005")
    run("shear", "--packing", str(p), "-o", str(root / "s.h5"), "--strain", "0.001")
    code = (
        "import sys; import numpy as np\n"
        "from gransim.io.hdf5 import load_packing, save_packing\n"
        "p = load_packing(sys.argv[1]); x = np.array(p.positions); x[1] = x[0]\n"
        "save_packing(sys.argv[2], p.replace(positions=x))\n"
    )
    subprocess.run([sys.executable, "-c", code, str(p), str(root / "nan.h5")], check=True, env=env, timeout=120)
    (root / "text.h5").write_text("not an HDF5 file\n")
    (root / "empty.h5").write_bytes(b"")
    # a folder nobody may write into, root included (sysfs)
    ro = Path("/sys")
    return {
        "P": p,
        "B": root / "b.h5",
        "S": root / "s.h5",
        "NAN": root / "nan.h5",
        "TXT": root / "text.h5",
        "EMPTY": root / "empty.h5",
        "RO": ro,
        "ROOT": root,
    }


def _fmt(argv, fx, case_dir):
    out = []
    for a in argv:
        a = str(a)
        for k, v in fx.items():
            a = a.replace("{" + k + "}", str(v))
        out.append(a.replace("{D}", str(case_dir)))
    return out


def run_case(case: Case, fx: dict, work: Path) -> list:
    case_dir = work / re.sub(r"[^A-Za-z0-9_.-]+", "_", case.name)[:120]
    case_dir.mkdir(parents=True)
    tmp = case_dir / "_tmp"
    tmp.mkdir()
    argv = _fmt(case.argv, fx, case_dir)
    inputs = [Path(_fmt([i], fx, case_dir)[0]) for i in case.inputs]
    before = {i: _sha(i) for i in inputs}
    marker = f"GRANSIM_SWEEP_CASE={os.getpid()}-{case_dir.name}"
    env = dict(os.environ, TMPDIR=str(tmp), GRANSIM_QUIET="1", **case.env)
    env["GRANSIM_SWEEP_CASE"] = marker.split("=", 1)[1]
    env.pop("GRANSIM_TRACEBACK", None)
    cmd = [*(case.wrap or []), *GRANSIM, *argv]
    t0 = time.monotonic()
    proc = subprocess.Popen(
        cmd, cwd=case_dir, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True
    )
    if case.signal_at is not None:
        try:
            proc.wait(timeout=case.signal_at)
        except subprocess.TimeoutExpired:
            os.kill(proc.pid, case.sig)
    try:
        out, err = proc.communicate(timeout=case.timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, err = proc.communicate()
        return [f"{case.name}: did not end within {case.timeout:.0f} s"]
    out, err = out.decode(errors="replace"), err.decode(errors="replace")
    rc = proc.returncode
    found = []
    # a process that dies of the signal the sweep sent: SIGKILL always; SIGINT / SIGTERM only in
    # the last moments of the interpreter's teardown, when its handlers are gone (the shell then
    # shows 130 / 143 as for a handled signal), so only after a run that had ended: no output
    # beyond the command's own and an output file, if any, complete
    died_of_ours = rc < 0 and case.signal_at is not None and -rc == case.sig
    if died_of_ours and case.sig != signal.SIGKILL:
        out_file = case_dir / "o.h5"
        info = (
            subprocess.run([*GRANSIM, "info", str(out_file)], capture_output=True, text=True, timeout=120, env=env)
            if out_file.is_file()
            else None
        )
        ended = info is None or re.search(r"complete\W+(yes|true|1)\b", info.stdout, re.I)
        died_of_ours = bool(ended) and not err.strip()
    if rc < 0 and not died_of_ours:
        found.append(f"{case.name}: died of signal {-rc} ({signal.Signals(-rc).name})")
    elif rc not in ALLOWED_RC and not (rc < 0 and case.signal_at is not None and -rc == case.sig):
        found.append(f"{case.name}: exit status {rc} not one the README allows")
    if case.rc is not None and rc not in case.rc:
        found.append(f"{case.name}: exit status {rc}, expected {sorted(case.rc)}; stderr: {err.strip()[-300:]!r}")
    if "Traceback" in err or "Traceback" in out:
        found.append(f"{case.name}: traceback: {err.strip().splitlines()[-1][:200] if err.strip() else ''}")
    if "Exception ignored" in err:
        found.append(f"{case.name}: 'Exception ignored' on stderr")
    if rc == 2:
        for n in case.names:
            if n not in err:
                found.append(f"{case.name}: exit 2 without naming {n!r}: {err.strip()[-200:]!r}")
    # argparse's own refusals print the usage block before their one error line
    if rc in (1, 2) and "usage: " not in err and len(err.strip().splitlines()) > 8:
        found.append(f"{case.name}: {len(err.strip().splitlines())} lines on stderr for an error")
    for i in inputs:
        if before[i] is not None and _sha(i) != before[i]:
            found.append(f"{case.name}: input {i.name} changed")
    stale = [p for p in case_dir.rglob(".*.tmp")] + [p for p in case_dir.rglob("*.tmp")]
    if stale and rc == -signal.SIGKILL:
        # a killed writer cannot remove its temporary: the next write of the same file does
        # (gransim.io.atomic_path); so the command is run again, uninterrupted, and must leave none
        subprocess.run(cmd, cwd=case_dir, env=env, capture_output=True, timeout=case.timeout)
        stale = [p for p in case_dir.rglob(".*.tmp")] + [p for p in case_dir.rglob("*.tmp")]
    if stale:
        found.append(f"{case.name}: temporary files left: {sorted({p.name for p in stale})[:3]}")
    # after a SIGKILL of gransim its watchdogs (reference_runs.runner) kill the codes and remove the
    # private directories: they need a moment (a scan of /proc every 0.05 s until 0.25 s without a
    # marked process), so a directory is a finding only if it outlives 10 s
    deadline = time.monotonic() + (10.0 if rc < 0 else 0.0)
    left = list(tmp.iterdir())
    while left and time.monotonic() < deadline:
        time.sleep(0.1)
        left = list(tmp.iterdir())
    if left:
        found.append(f"{case.name}: left in TMPDIR: {[p.name for p in left][:3]}")
    deadline = time.monotonic() + 3.0
    new = _code_pids(marker)
    while new and time.monotonic() < deadline:
        time.sleep(0.1)
        new = _code_pids(marker)
    if new:
        found.append(f"{case.name}: reference code still running after exit: pids {sorted(new)}")
        for pid in new:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass
    if re.search(r"\bPASS\b", out + err) and re.search(r"\b(nan|inf)\b", out + err, re.I):
        found.append(f"{case.name}: PASS printed beside a NaN or inf")
    if case.after is not None:
        found += [f"{case.name}: {m}" for m in case.after(case_dir, rc, out, err, argv)]
    elapsed = time.monotonic() - t0
    return found if found else [f"ok {case.name} (rc {rc}, {elapsed:.1f} s)"]


# ----------------------------------------------------------------------------- the cases
BAD_NUMBERS = ("nan", "inf", "-inf", "abc", "-3")

#: command -> (base argv that is otherwise valid, {option: values that must be refused})
NUMERIC = {
    "pack": (
        ["pack", "--n", "40", "-o", "{D}/o.h5"],
        {
            "--n": ("0", "1", "-5", "nan", "abc", "2.5"),
            "--seed": ("-1", "nan", "abc"),
            "--solid-fraction": ("0", "1.5", "nan", "-0.2"),
            "--force-tol": ("0", "-1", "nan", "inf"),
            "--mean-diameter": ("0", "-1", "nan", "inf"),
            "--density": ("0", "-1", "nan", "inf"),
            "--pressure": ("-1", "nan", "inf"),
            "--friction": ("-1", "nan", "inf"),
        },
    ),
    "biaxial": (
        ["biaxial", "--packing", "{P}", "-o", "{D}/o.h5", "--strain", "0.0002"],
        {
            "--strain": ("0", "-0.1", "nan", "inf"),
            "--kn": ("0", "-1", "nan", "inf"),
            "--kt-ratio": ("-1", "nan", "inf"),
            "--mu": ("-1", "nan", "inf"),
            "--density": ("0", "-1", "nan"),
            "--confining": ("-1", "nan", "inf"),
            "--strain-rate": ("0", "-1", "nan", "inf"),
            "--inertial-number": ("0", "-1", "nan", "inf"),
            "--damping-ratio": ("-1", "nan", "inf"),
            "--steps-per-contact": ("0", "-1", "nan", "inf"),
            "--consolidation-tol": ("0", "-1", "nan"),
            "--consolidation-steps": ("0", "-1", "nan"),
            "--series-every": ("0", "-1", "nan"),
            "--snapshot-every": ("-1", "nan"),
            "--checkpoint-every": ("-1", "nan"),
            "--threads": ("0", "-1", "nan"),
        },
    ),
    "shear": (
        ["shear", "--packing", "{P}", "-o", "{D}/o.h5", "--strain", "0.0005"],
        {
            "--strain": ("0", "-0.1", "nan", "inf"),
            "--rate": ("0", "nan", "inf"),
            "--kn": ("0", "-1", "nan"),
            "--inertial-number": ("0", "-1", "nan"),
            "--servo": ("nan", "inf", "-1"),
            "--damping-ratio": ("-1", "nan"),
            "--steps-per-contact": ("0", "-1", "nan"),
            "--series-every": ("0", "-1", "nan"),
            "--snapshot-every": ("-1", "nan"),
        },
    ),
    "rve-stress": (["rve-stress", "{P}"], {"--kn": ("0", "-1", "nan", "inf")}),
    "rve-check": (["rve-check", "--packings", "{P}"], {"--kn": ("0", "-1", "nan"), "--tol": ("-1", "nan")}),
    "rve-study": (
        ["rve-study", "--packings", "{P}", "-o", "{D}/out"],
        {"--kn": ("0", "-1", "nan"), "--steps": ("0", "-1", "nan", "1e9"), "--workers": ("0", "-1", "nan")},
    ),
    "slope": (
        ["slope", "--out", "{D}/out"],
        {
            "--load-steps": ("0", "-1", "nan"),
            "--dead-load-steps": ("0", "-1", "nan"),
            "--tol": ("0", "-1", "nan"),
            "--min-fraction": ("0", "-1", "nan", "2"),
            "--workers": ("0", "-1"),
            "--stop-after": ("0", "-1", "nan"),
            "--mesh": ("0x0", "axb", "-2x3", "20"),
        },
    ),
    "voidcells": (["voidcells", "{B}", "--out", "{D}/out"], {"--strain": ("nan", "inf", "-1")}),
    "dem-export": (["dem-export", "{B}", "--vtu", "{D}/o.vtu"], {"--step": ("-1", "nan", "123456789")}),
    "warmup": (["warmup", "--list"], {"--jobs": ("0", "-1", "nan"), "--timeout": ("0", "-1", "nan")}),
    "validate": (
        ["validate", "--case", "taylor-rve", "--results", "{D}/out"],
        {"--jobs": ("0", "-3", "nan"), "--timeout": ("0", "-5", "nan")},
    ),
    "reference run": (
        ["reference", "run", "taylor-demo", "--out", "{D}/out"],
        {"--np": ("0", "-1", "nan"), "--timeout": ("0", "-5", "nan")},
    ),
    "replay": (
        ["replay", str(REPO / "tests/replay/data/in.deck_a"), "-o", "{D}/out"],
        {"--timeout": ("0", "-5", "nan")},  # inf: no limit
    ),
}


def _incomplete_then_resume(extra):
    """After an interrupted run: the file says incomplete, and --resume finishes it."""

    def check(case_dir, rc, out, err, argv):
        f = case_dir / "o.h5"
        msgs = []
        if rc == 0:
            return msgs  # the run ended before the signal: nothing to check
        if not f.is_file():
            return msgs if rc in (129, 130, 143) and "checkpoint" not in extra else [f"rc {rc} and no run file"]
        info = subprocess.run([*GRANSIM, "info", str(f)], capture_output=True, text=True, timeout=120)
        said_whole = "written complete before the signal" in err
        if re.search(r"complete\W+(yes|true|1)\b", info.stdout, re.I) and not said_whole:
            msgs.append(f"interrupted (rc {rc}) but the file says complete, and stderr did not say so")
        res = subprocess.run(
            [*GRANSIM, *argv, "--resume"],
            cwd=case_dir,
            capture_output=True,
            text=True,
            timeout=600,
            env=dict(os.environ, GRANSIM_QUIET="1"),
        )
        if res.returncode != 0:
            msgs.append(f"--resume after rc {rc} gave rc {res.returncode}: {res.stderr.strip()[-200:]!r}")
        stale = list(case_dir.rglob(".*.tmp"))
        if stale:
            msgs.append(f"temporaries left after --resume: {[p.name for p in stale][:3]}")
        return msgs

    return check


def cases(fx: dict) -> list:
    out = []
    for cmd, (base, opts) in NUMERIC.items():
        name = cmd.split()[-1]
        for opt, values in opts.items():
            for v in values:
                out.append(
                    Case(f"{name} {opt} {v}", [*base, opt, v], rc={2}, names=(opt,), inputs=("{P}",), timeout=60)
                )
    P, B, S = "{P}", "{B}", "{S}"
    # files that are not what they should be
    for f in ("{TXT}", "{EMPTY}", "{ROOT}", "{D}/missing.h5", B):
        # a run file holds its packing: reading it as one is allowed
        ok = {0, 2} if f == B else {2}
        out.append(Case(f"biaxial --packing {Path(f).name}", ["biaxial", "--packing", f, "-o", "{D}/o.h5"], rc=ok))
        out.append(
            Case(
                f"shear --packing {Path(f).name}",
                ["shear", "--packing", f, "-o", "{D}/o.h5", "--strain", "0.001"],
                rc=ok,
            )
        )
        out.append(Case(f"info {Path(f).name}", ["info", f], rc=ok))
        out.append(Case(f"rve-stress {Path(f).name}", ["rve-stress", f], rc=ok))
    for f in ("{TXT}", "{EMPTY}", P, "{D}/missing.h5"):
        out.append(Case(f"voidcells {Path(f).name}", ["voidcells", f, "--out", "{D}/out"], rc={2}))
        out.append(Case(f"dem-export {Path(f).name}", ["dem-export", f, "--vtu", "{D}/o.vtu"], rc={2}))
    # outputs that cannot be written, or that are an input
    for opt_cmd in (
        ["biaxial", "--packing", P, "--strain", "0.0002", "-o"],
        ["shear", "--packing", P, "--strain", "0.0005", "-o"],
        ["pack", "--n", "40", "-o"],
    ):
        for target, label in (
            ("{RO}/o.h5", "read-only dir"),
            ("{TXT}/o.h5", "parent is a file"),
            ("{ROOT}", "a directory"),
            ("{D}/no/such/dir/o.h5", "missing parent"),
        ):
            # a missing parent folder is created (mkdir -p)
            ok = {0} if label == "missing parent" else {2}
            out.append(Case(f"{opt_cmd[0]} -o into {label}", [*opt_cmd, target], rc=ok, timeout=60))
    for c in (
        ["biaxial", "--packing", P, "--strain", "0.0002", "-o", P],
        ["shear", "--packing", P, "--strain", "0.0005", "-o", P],
        ["biaxial", "--packing", P, "--strain", "0.0002", "-o", "{ROOT}/./p.h5"],
    ):
        out.append(Case(f"{c[0]} -o equal to --packing ({c[-1][-8:]})", c, rc={2}, names=("-o",), inputs=(P,)))
    out.append(Case("voidcells --out the run file", ["voidcells", B, "--out", B], rc={2}, inputs=(B,)))
    out.append(Case("dem-export --vtu the run file", ["dem-export", B, "--vtu", B], rc={2}, inputs=(B,)))
    out.append(Case("dem-export --plot the run file", ["dem-export", B, "--plot", B], rc={2}, inputs=(B,)))
    out.append(
        Case(
            "biaxial --plot the packing",
            ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--strain", "0.0002", "--plot", P],
            rc={2},
            inputs=(P,),
        )
    )
    out.append(
        Case(
            "biaxial serial --threads 2",
            ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--strain", "0.0002", "--mode", "serial", "--threads", "2"],
            rc={2},
            names=("--threads",),
        )
    )
    out.append(Case("biaxial --resume with no run", ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--resume"], rc={2}))
    out.append(
        Case(
            "biaxial --law nonsense",
            ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--law", "nonsense"],
            rc={2},
            names=("--law",),
        )
    )
    out.append(
        Case(
            "biaxial --law-param nonsense",
            ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--law-param", "nonsense"],
            rc={2},
            names=("--law-param",),
        )
    )
    out.append(
        Case(
            "biaxial --law-param k=nan",
            ["biaxial", "--packing", P, "-o", "{D}/o.h5", "--law", "hertz", "--law-param", "youngs_modulus=nan"],
            rc={2},
        )
    )
    out.append(Case("voidcells on a shear run", ["voidcells", S, "--out", "{D}/out"], rc={0}))
    out.append(Case("info on a shear run", ["info", S], rc={0}))
    out.append(Case("dem-export on a shear run", ["dem-export", S, "--vtu", "{D}/o.vtu"], rc={0}))
    # NaN evidence never passes
    out.append(
        Case(
            "reference taylor on coincident disks",
            ["reference", "taylor", "{NAN}", "--out", "{D}/out"],
            rc={1, 2},
            timeout=300,
        )
    )
    out.append(Case("rve-stress on coincident disks", ["rve-stress", "{NAN}"], rc={1, 2}))
    out.append(
        Case(
            "biaxial on coincident disks",
            ["biaxial", "--packing", "{NAN}", "-o", "{D}/o.h5", "--strain", "0.0002"],
            rc={1, 2},
        )
    )
    # signals during a run: SIGINT and SIGTERM at several times; the file is incomplete and resumes
    for t in (0.9, 1.5, 2.2, 3.0, 4.0):
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
            extra = ["biaxial", "--packing", P, "-o", "o.h5", "--strain", "0.003", "--checkpoint-every", "2000"]
            out.append(
                Case(
                    f"biaxial {sig.name} at {t} s",
                    extra,
                    rc={0, 128 + int(sig)},
                    signal_at=t,
                    sig=sig,
                    after=_incomplete_then_resume(extra),
                    inputs=(P,),
                )
            )
        extra = ["shear", "--packing", P, "-o", "o.h5", "--strain", "0.01"]
        out.append(Case(f"shear SIGINT at {t} s", extra, rc={0, 130}, signal_at=t, sig=signal.SIGINT))
        out.append(
            Case(f"pack SIGINT at {t / 2} s", ["pack", "--n", "3000", "-o", "o.h5"], rc={0, 130}, signal_at=t / 2)
        )
    # the reference codes under signals
    deck = str(REPO / "tests/replay/data/in.deck_a")
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGKILL):
        for t in (0.8, 1.6):
            out.append(
                Case(
                    f"replay {sig.name} at {t} s",
                    ["replay", deck, "-o", "{D}/out"],
                    signal_at=t,
                    sig=sig,
                    rc={0, 1, 130, 143} if sig != signal.SIGKILL else None,
                )
            )
            out.append(
                Case(
                    f"validate {sig.name} at {t} s",
                    ["validate", "--case", "taylor-rve", "--results", "{D}/out"],
                    signal_at=t + 1,
                    sig=sig,
                    rc={0, 1, 130, 143} if sig != signal.SIGKILL else None,
                )
            )
    for c in ("replay", "reference", "validate"):
        argv = {
            "replay": ["replay", deck, "-o"],
            "reference": ["reference", "run", "taylor-demo", "--out"],
            "validate": ["validate", "--case", "taylor-rve", "--results"],
        }[c]
        out.append(Case(f"{c} output in a read-only dir", [*argv, "{RO}/out"], rc={2}))
        out.append(Case(f"{c} output under a file", [*argv, "{TXT}/out"], rc={2}))
    # a full disk
    if _can_mount():
        for label, argv in (
            ("pack", ["pack", "--n", "2000", "-o", "{D}/full/o.h5"]),
            ("biaxial", ["biaxial", "--packing", P, "-o", "{D}/full/o.h5", "--strain", "0.001"]),
        ):
            out.append(
                Case(
                    f"{label} on a full disk", argv, rc={1, 2}, wrap=_mount_wrap(), after=_nothing_in_full, inputs=(P,)
                )
            )
    return out


def _can_mount() -> bool:
    return (
        shutil.which("unshare") is not None
        and subprocess.run(["unshare", "-rm", "true"], capture_output=True).returncode == 0
    )


def _mount_wrap():
    # a mount namespace of its own with a 48 kB tmpfs at ./full (the case directory's)
    # a mount namespace of its own with a 48 kB tmpfs at ./full (the case directory's); what is
    # left in it after gransim's exit is listed on stderr ("LEFT: name")
    script = (
        'mkdir -p full && mount -t tmpfs -o size=48k tmpfs full || exit 99; "$@"; rc=$?; '
        'ls -A full | sed "s/^/LEFT: /" >&2; exit $rc'
    )
    return ["unshare", "-rm", "sh", "-c", script, "sh"]


def _nothing_in_full(case_dir, rc, out, err, argv):
    msgs = [f"left on the full disk: {m}" for m in re.findall(r"^LEFT: (.*)$", err, re.M)]
    err = re.sub(r"^LEFT: .*\n?", "", err, flags=re.M)
    if not re.search(r"space|full|ENOSPC|quota", err, re.I):
        msgs.append(f"the error does not name the cause: {err.strip()[-200:]!r}")
    return msgs


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default=None, help="only cases whose name contains this")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the findings here")
    ap.add_argument("--keep", action="store_true", help="keep the work folder")
    args = ap.parse_args(argv)
    work = Path(tempfile.mkdtemp(prefix="gransim-sweep-"))
    try:
        fx = _fixtures(work / "_fixtures")
        todo = [c for c in cases(fx) if args.only is None or args.only in c.name]
        print(f"{len(todo)} cases, work folder {work}", flush=True)
        findings, oks = [], 0
        with concurrent.futures.ThreadPoolExecutor(max(1, args.jobs)) as ex:
            for res in ex.map(lambda c: run_case(c, fx, work), todo):
                for line in res:
                    if line.startswith("ok "):
                        oks += 1
                    else:
                        findings.append(line)
                        print("FINDING", line, flush=True)
        print(f"{len(todo)} cases: {oks} clean, {len(findings)} findings")
        if args.json:
            Path(args.json).write_text(json.dumps({"cases": len(todo), "clean": oks, "findings": findings}, indent=1))
        return 1 if findings else 0
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
