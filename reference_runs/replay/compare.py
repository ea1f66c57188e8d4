"""Replay a user's deck in its own code and natively, compare step by step, write the report.

:func:`replay` runs the deck unchanged in LIGGGHTS or LAMMPS (``reference_runs.runner.run_job``,
or reads a finished job directory given as ``reference``), runs it natively
(:mod:`reference_runs.replay.drive`), and compares

* every thermo row: the step, ``atoms`` (= N), the box (``lx ly xlo xhi ylo yhi``: within the
  position tolerance) and every column of a ``compute pressure ... virial`` (relative to the
  largest magnitude of that column over the run);
* every dump frame, atom by atom (matched by id): positions (``x y z``) against
  :data:`POSITION_TOL` D50, velocities, spins, forces and torques relative to the largest
  magnitude of the column over the run, masses/radii to round-off.

The verdict never rests on incomplete evidence: a thermo step or a dump frame the deck asks for
and the code did not write, an atom missing from a frame, or a step the native run lacks is a
failure named ``incomplete``. Output: ``OUTDIR/report.html``, ``OUTDIR/report.md``,
``OUTDIR/replay.h5`` (provenance, both runs' series; stress tension positive) written atomically.
"""

from __future__ import annotations

import html
import inspect
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gransim.errors import InputError, ResultFileError
from gransim.io import atomic_h5, atomic_path
from reference_runs.judge import finite_problem, peak, verdict_problem
from reference_runs.parsers import parse_dump_custom, parse_log
from reference_runs.runner import run_job

from .deck import ReplayDeck, read_deck
from .drive import NativeRun, run_native

#: positions (and box bounds): |difference| <= POSITION_TOL * D50
POSITION_TOL = 1e-10
#: pressure components: |difference| <= STRESS_TOL * max |code value| of that column over the run
STRESS_TOL = 1e-8
#: velocities, spins, forces, torques: relative to the column's largest magnitude over the run
RATE_TOL = 1e-8
#: masses, radii: relative round-off
EXACT_TOL = 1e-15

_POS = ("x", "y", "z")
_RATE = ("vx", "vy", "vz", "omegax", "omegay", "omegaz", "fx", "fy", "fz", "tqx", "tqy", "tqz")
_EXACT = ("mass", "radius", "diameter")


@dataclass
class Check:
    """One comparison: quantity, metric, measured value, tolerance, pass, and a detail text."""

    quantity: str
    metric: str
    value: float
    tolerance: float
    passed: bool
    detail: str = ""

    def __post_init__(self):
        # whatever rule set ``passed``, a check never passes on a NaN or inf value or tolerance
        problem = verdict_problem(self.value, self.tolerance, self.quantity)
        if problem:
            self.passed = False
            self.detail = f"FAIL: {problem}" + (f"; {self.detail}" if self.detail else "")


def _sides_problem(quantity: str, sides: dict) -> str | None:
    """The first ``{side: values}`` entry holding a NaN or inf, named (None when all are finite)."""
    return next((p for side, v in sides.items() if (p := finite_problem(v, quantity, side))), None)


@dataclass
class ReplayResult:
    """Outcome of :func:`replay`: the deck, the checks, the output files, notes."""

    deck: ReplayDeck
    checks: list
    outdir: Path
    code_version: str
    notes: list = field(default_factory=list)

    @property
    def passed(self) -> bool:
        return bool(self.checks) and all(c.passed for c in self.checks)


# ----------------------------------------------------------------------------- running the code
def run_code(deck: ReplayDeck, job_dir: Path, timeout: float | None):
    """Run the deck unchanged in its code in ``job_dir``; returns (log path, {dump file: path},
    version text). Raises ReferenceRunError (binary missing, error, timeout, incomplete)."""
    files = {}
    if not Path(deck.data_name).is_absolute():
        if ".." in Path(deck.data_name).parts or len(Path(deck.data_name).parts) != 1:
            raise InputError(
                f"{deck.path}: read_data {deck.data_name!r}: give the data file as a plain "
                "file name next to the deck (the job runs in its own directory)"
            )
        files[deck.data_name] = deck.data_path.read_bytes()
    kw = {
        "files": files,
        "timeout": timeout,
        "outputs": tuple(d.file for d in deck.dumps),
        "expected_runs": 1,
        "progress": False,
        "force": True,
    }
    if "engine" in inspect.signature(run_job).parameters:
        kw["engine"] = deck.engine
    elif deck.engine != "liggghts":
        raise InputError(
            "this gransim's reference_runs.runner.run_job runs LIGGGHTS only; a LAMMPS deck "
            "cannot be run (give --reference DIR with a finished LAMMPS job)"
        )
    res = run_job(job_dir, "\n".join(deck.lines) + "\n", **kw)
    m = res.manifest
    version = m.get("engine_version") or m.get("liggghts_version") or res.log.version or "unknown"
    return res.log_path, {d.file: res.path(d.file) for d in deck.dumps}, str(version)


def read_reference(deck: ReplayDeck, ref_dir: Path):
    """A finished job directory: its log (``log.lammps``, else the only ``log.*``) and dumps."""
    ref_dir = Path(ref_dir)
    if not ref_dir.is_dir():
        raise InputError(f"--reference: {ref_dir} is not a directory")
    log = ref_dir / "log.lammps"
    if not log.exists():
        logs = sorted(ref_dir.glob("log.*"))
        if len(logs) != 1:
            raise InputError(f"--reference: {ref_dir} holds no log.lammps (and not exactly one log.* file)")
        log = logs[0]
    return log, {d.file: ref_dir / d.file for d in deck.dumps}, None


# ----------------------------------------------------------------------------- comparing
def expected_thermo_steps(deck: ReplayDeck) -> list:
    """Steps of the thermo rows of ``run N``: 0, multiples of ``thermo`` N, and the last step."""
    n = deck.nsteps
    steps = set(range(0, n + 1, deck.thermo_every)) if deck.thermo_every else {0}
    steps.add(n)
    return sorted(steps)


def _max_rel(a, b, scale):
    """max |a - b| / scale (the difference itself for a zero scale); NaN (failing) for empty arrays
    or a NaN anywhere, never 0.0 (``scale > 0`` is False for a NaN scale)."""
    d = peak([np.abs(np.asarray(a, float) - np.asarray(b, float))])
    return float(d / scale) if scale > 0 else (d if scale == 0 else math.nan)


def compare_thermo(deck: ReplayDeck, nat: NativeRun, log_path: Path) -> list:
    """Checks of the thermo table (see the module docstring)."""
    checks = []
    log = parse_log(Path(log_path))
    if log.errors:
        checks.append(Check("log", "ERROR lines", len(log.errors), 0, False, str(log.errors[0])))
    if not log.runs:
        return checks + [Check("thermo", "incomplete: no thermo table in the log", 1, 0, False, str(log_path))]
    run = log.runs[-1]
    want = expected_thermo_steps(deck)
    got = [int(s) for s in run.steps]
    missing = sorted(set(want) - set(got))
    extra = sorted(set(got) - set(want))
    ok_steps = not missing and not extra and run.complete
    detail = (
        (f"missing steps {missing[:5]}{'...' if len(missing) > 5 else ''}; " if missing else "")
        + (f"unexpected steps {extra[:5]}; " if extra else "")
        + ("" if run.complete else "run not complete")
    )
    checks.append(
        Check(
            "thermo steps",
            "incomplete: thermo rows missing" if not ok_steps else "rows present",
            len(missing) + len(extra) + (0 if run.complete else 1),
            0,
            ok_steps,
            detail or f"{len(got)} rows",
        )
    )
    rows = [k for k, s in enumerate(got) if 0 <= s <= deck.nsteps]
    st = np.array([got[k] for k in rows], np.int64)
    d50 = deck.d50
    tol_x = POSITION_TOL * d50
    box = {
        "lx": nat.hi[:, 0] - nat.lo[:, 0],
        "ly": nat.hi[:, 1] - nat.lo[:, 1],
        "xlo": nat.lo[:, 0],
        "xhi": nat.hi[:, 0],
        "ylo": nat.lo[:, 1],
        "yhi": nat.hi[:, 1],
        "xy": nat.xy if nat.xy is not None else np.zeros(nat.lo.shape[0]),
        "xz": np.zeros(nat.lo.shape[0]),
        "yz": np.zeros(nat.lo.shape[0]),
    }
    for kw in deck.thermo_columns:
        low = kw.lower()
        try:
            col = run.column(kw)[rows]
        except KeyError:
            checks.append(Check(f"thermo {kw}", "incomplete: column missing in the log", 1, 0, False))
            continue
        if low in box:
            diff = peak([np.abs(col - box[low][st])])  # NaN when no row or any NaN: fails
            problem = _sides_problem(f"thermo {kw}", {deck.engine: col, "native": box[low][st]})
            checks.append(
                Check(
                    f"thermo {kw}",
                    "max |code - native| / D50",
                    diff / d50,
                    POSITION_TOL,
                    diff <= tol_x and not problem,
                    problem or f"bitwise equal: {bool(np.array_equal(col, box[low][st]))}",
                )
            )
        elif low == "atoms":
            bad = int(np.sum(col != deck.packing.n))
            checks.append(Check("thermo atoms", "rows with atoms != N", bad, 0, bad == 0))
        elif low.startswith("c_"):
            m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", kw)
            nat_col = nat.p[st] if m.group(3) is None else nat.pressure[st, int(m.group(3)) - 1]
            scale = peak([np.abs(col)])  # NaN for no row or a NaN: fails
            rel = _max_rel(col, nat_col, scale)
            worst = int(st[np.argmax(np.abs(col - nat_col))]) if col.size else 0
            problem = _sides_problem(f"thermo {kw}", {deck.engine: col, "native": nat_col})
            checks.append(
                Check(
                    f"thermo {kw} (pressure, virial)",
                    "max |code - native| / max |code|",
                    rel,
                    STRESS_TOL,
                    (rel <= STRESS_TOL if scale > 0 else rel == 0.0) and not problem,
                    problem or f"worst at step {worst}; bitwise equal: {bool(np.array_equal(col, nat_col))}",
                )
            )
    return checks


def compare_dumps(deck: ReplayDeck, nat: NativeRun, dump_paths: dict) -> list:
    """Checks of every dump frame (see the module docstring)."""
    checks = []
    d50 = deck.d50
    index = {int(a): i for i, a in enumerate(deck.ids)}
    for d in deck.dumps:
        path = Path(dump_paths[d.file])
        want = list(range(0, deck.nsteps + 1, d.every))
        try:
            frames = {int(f.step): f for f in parse_dump_custom(path)} if path.exists() else {}
        except ResultFileError as exc:
            checks.append(Check(f"dump {d.id}", "incomplete: unreadable dump", 1, 0, False, str(exc)))
            continue
        missing = [s for s in want if s not in frames]
        checks.append(
            Check(
                f"dump {d.id} frames",
                "incomplete: frames missing" if missing else "frames present",
                len(missing),
                0,
                not missing,
                f"{path.name}: expected {len(want)} frames, got {len(frames)}"
                + (f"; missing steps {missing[:5]}" if missing else ""),
            )
        )
        cols = [c for c in d.columns if c in _POS + _RATE + _EXACT]
        worst = {c: 0.0 for c in cols}
        where = {c: None for c in cols}
        scale = {c: 0.0 for c in cols}
        bitwise = {c: True for c in cols}
        problem = {c: None for c in cols}  # the first NaN or inf of a column, named
        inc = []
        pairs = []
        for s in want:
            if s not in frames:
                continue
            fr = frames[s]
            if s not in nat.frames:
                inc.append(f"native frame {s} missing")
                continue
            ids = np.asarray(fr["id"], np.int64)
            if sorted(ids.tolist()) != sorted(index):
                inc.append(f"step {s}: {len(ids)} of {len(index)} atoms")
                continue
            order = np.array([index[int(a)] for a in ids])
            pairs.append((s, fr, order))
            for c in cols:
                if c not in _POS:
                    scale[c] = peak([scale[c], np.abs(fr[c])])  # a NaN sticks (max() would drop it)
        for s, fr, order in pairs:
            nf = nat.frames[s]
            for c in cols:
                a = np.asarray(fr[c], float)
                b = np.asarray(nf[c], float)[order]
                diff = float(np.max(np.abs(a - b)))
                bitwise[c] &= bool(np.array_equal(a, b))
                problem[c] = problem[c] or _sides_problem(f"dump {d.id} {c} at step {s}", {deck.engine: a, "native": b})
                if where[c] is None or diff > worst[c]:
                    worst[c], where[c] = diff, s
        if inc:
            checks.append(
                Check(
                    f"dump {d.id} atoms", "incomplete: atoms or frames missing", len(inc), 0, False, "; ".join(inc[:5])
                )
            )
        for c in cols:
            if c in _POS:
                v, tol, metric = worst[c] / d50, POSITION_TOL, "max |code - native| / D50"
            elif c in _EXACT:
                sc = scale[c] or 1.0
                v, tol, metric = worst[c] / sc, EXACT_TOL, "max |code - native| / max |code|"
            else:
                sc = scale[c]
                v = worst[c] / sc if sc > 0 else worst[c]
                tol, metric = RATE_TOL, "max |code - native| / max |code|"
            if not pairs:  # no frame compared: nothing to judge (the evidence checks say why)
                v = math.nan
            checks.append(
                Check(
                    f"dump {d.id} {c}",
                    metric,
                    v,
                    tol,
                    (v <= tol if (c in _POS or scale[c] > 0) else v == 0.0) and not problem[c],
                    problem[c] or f"worst at step {where[c]}; bitwise equal: {bitwise[c]}",
                )
            )
    return checks


# ----------------------------------------------------------------------------- the whole replay
def replay(
    deck_path,
    data=None,
    engine: str | None = None,
    outdir=None,
    timeout: float | None = None,
    reference=None,
    echo=None,
) -> ReplayResult:
    """Read, run in its code (or read ``reference``), run natively, compare, write the report.

    Parameters
    ----------
    deck_path : the deck. data : data file replacing the one of ``read_data``. engine : insist
        on "liggghts" or "lammps" syntax. outdir : output directory (default
        ``results/replay/<deck name>``). timeout : seconds for the code's run (None: no limit).
    reference : a finished job directory (log + dumps of this deck) used instead of running
        the code. echo : callable for progress lines (default: silent).

    Returns
    -------
    ReplayResult (``passed``: every check within tolerance and the evidence complete).

    Raises
    ------
    InputError for a deck outside the subset or bad options (before anything runs);
    ReferenceRunError when the code fails; SimulationError when the native run diverges.
    """
    say = echo or (lambda msg: None)
    deck = read_deck(deck_path, data=data, engine=engine)
    out = Path(outdir) if outdir is not None else Path("results/replay") / Path(deck_path).name
    if out.exists() and not out.is_dir():
        raise InputError(f"-o: {out} exists and is not a directory")
    if timeout is not None and not timeout > 0:
        raise InputError(f"--timeout: expected seconds > 0, got {timeout!r}")
    out.mkdir(parents=True, exist_ok=True)
    if reference is not None:
        log, dumps, version = read_reference(deck, Path(reference))

        version = parse_log(log).version or "unknown (stored job)"
        say(f"reading the {deck.engine} job in {reference}")
    else:
        say(f"running the deck in {deck.engine} (job directory {out / 'job'})")
        log, dumps, version = run_code(deck, out / "job", timeout)
    say(f"running the deck natively ({deck.packing.n} disks, {deck.nsteps} steps)")
    nat = run_native(deck)
    checks = compare_thermo(deck, nat, log) + compare_dumps(deck, nat, dumps)
    res = ReplayResult(deck, checks, out, version, list(deck.notes))
    write_report(res, nat)
    return res


def _fmt(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def write_report(res: ReplayResult, nat: NativeRun) -> None:
    """``report.md``, ``report.html`` and ``replay.h5`` in ``res.outdir`` (each atomically)."""
    d = res.deck
    verdict = "PASS" if res.passed else "FAIL"
    head = [
        f"# gransim replay: {d.path.name} ({verdict})",
        "",
        f"- deck: `{d.path}` ({d.engine} syntax), data `{d.data_path}`",
        f"- code: {res.code_version}",
        (
            f"- {d.packing.n} disks, box x [{float(d.box_lo[0])!r}, {float(d.box_hi[0])!r}] y "
            f"[{float(d.box_lo[1])!r}, {float(d.box_hi[1])!r}] m, {d.nsteps} steps of {d.settings.dt!r} s"
        ),
        f"- native settings: {json.dumps(d.settings.to_dict(), sort_keys=True)}",
        f"- fix deform: {d.deform if d.deform is not None else 'none (fixed box)'}",
        (
            f"- sheared (triclinic) deck, tilt xy {d.tilt!r} m at the start: native run through "
            f"ShearEngine (flavour lammps), {d.shear}"
            if d.sheared
            else "- orthogonal box: native run through DEMEngine with the box table of every step (PrescribedBox)"
        ),
        f"- native neighbour-list builds: {nat.n_rebuilds}",
        (
            f"- tolerances: positions {POSITION_TOL:g} D50 (D50 = {d.d50:.6g} m), pressure {STRESS_TOL:g} "
            f"relative, velocities/forces {RATE_TOL:g} relative; missing evidence fails"
        ),
        "",
    ]
    rows = ["| quantity | metric | value | tolerance | pass | detail |", "|---|---|---|---|---|---|"]
    for c in res.checks:
        metric = c.metric.replace("|", "\\|")
        rows.append(
            f"| {c.quantity} | {metric} | {_fmt(float(c.value))} | {_fmt(float(c.tolerance))} | "
            f"{'yes' if c.passed else 'NO'} | {c.detail} |"
        )
    notes = ["", "## Notes", ""] + [f"- {n}" for n in res.notes or ["none"]]
    md = "\n".join(head + rows + notes) + "\n"
    with atomic_path(res.outdir / "report.md") as tmp:
        Path(tmp).write_text(md)
    esc = html.escape
    trs = "".join(
        f"<tr class={'ok' if c.passed else 'bad'}><td>{esc(c.quantity)}</td><td>{esc(c.metric)}</td>"
        f"<td>{_fmt(float(c.value))}</td><td>{_fmt(float(c.tolerance))}</td>"
        f"<td>{'yes' if c.passed else 'NO'}</td><td>{esc(c.detail)}</td></tr>"
        for c in res.checks
    )
    page = (
        f"<!doctype html><html><head><meta charset=utf-8><title>gransim replay {esc(d.path.name)}</title>"
        "<style>body{font-family:sans-serif}td,th{border:1px solid #ccc;padding:2px 6px}"
        ".bad{background:#fdd}.ok{background:#efe}</style></head><body>"
        f"<h1>gransim replay: {esc(d.path.name)} &mdash; {verdict}</h1><ul>"
        + "".join(f"<li>{esc(h[2:])}</li>" for h in head[2:] if h)
        + "</ul><table><tr><th>quantity</th><th>metric</th><th>value</th><th>tolerance</th><th>pass</th>"
        f"<th>detail</th></tr>{trs}</table><h2>Notes</h2><ul>"
        + "".join(f"<li>{esc(n)}</li>" for n in res.notes or ["none"])
        + "</ul></body></html>\n"
    )
    with atomic_path(res.outdir / "report.html") as tmp:
        Path(tmp).write_text(page)
    params = {
        "deck": str(d.path),
        "data": str(d.data_path),
        "engine": d.engine,
        "settings": d.settings.to_dict(),
        "nsteps": d.nsteps,
        "code_version": res.code_version,
    }
    with atomic_h5(res.outdir / "replay.h5", kind="replay", parameters=params, liggghts=d.engine == "liggghts") as f:
        f.attrs["passed"] = res.passed
        f.attrs["deck_text"] = "\n".join(d.lines)
        f.attrs["notes"] = json.dumps(res.notes)
        g = f.create_group("native")
        g.create_dataset("step", data=nat.steps)
        g.create_dataset("box_lo", data=nat.lo)
        g.create_dataset("box_hi", data=nat.hi)
        g.create_dataset("xy", data=nat.xy if nat.xy is not None else np.zeros(nat.lo.shape[0]))
        g["xy"].attrs["units"] = "m (the box's xy tilt after each step)"
        # files hold stress tension positive: sigma = -pressure (xx, yy, xy)
        g.create_dataset("stress", data=-nat.pressure[:, [0, 1, 3]])
        g["stress"].attrs["convention"] = "tension positive; columns xx, yy, xy (N/m in 2D)"
        fr = g.create_group("frames")
        for s, cols in sorted(nat.frames.items()):
            h = fr.create_group(str(s))
            h.create_dataset("positions", data=np.stack([cols["x"], cols["y"]], axis=1))
            h.create_dataset("velocities", data=np.stack([cols["vx"], cols["vy"]], axis=1))
            h.create_dataset("spins", data=cols["omegaz"])
        c = f.create_group("checks")
        c.create_dataset("quantity", data=np.array([k.quantity for k in res.checks], dtype="S"))
        c.create_dataset("metric", data=np.array([k.metric for k in res.checks], dtype="S"))
        c.create_dataset("value", data=np.array([float(k.value) for k in res.checks]))
        c.create_dataset("tolerance", data=np.array([float(k.tolerance) for k in res.checks]))
        c.create_dataset("passed", data=np.array([k.passed for k in res.checks], bool))
