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
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from gransim.errors import InputError, ResultFileError
from gransim.io import atomic_h5, atomic_path
from reference_runs.judge import finite_problem, peak, verdict_problem
from reference_runs.parsers import parse_dump_custom, parse_dump_local, parse_log
from reference_runs.runner import run_job

from .contacts import PGL_EXACT, PGL_POSITION, PL_EXACT, local_columns, local_style, native_rows
from .deck import ReplayDeck, read_deck
from .drive import NativeRun, dump_frames, frame, run_native
from .thermo import thermo_value

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
    """Run the deck unchanged in its code in ``job_dir``, with the deck's command-line variables
    (``run_job(..., variables=...)``: ``-var NAME VALUE``, the runs and dump frames expected with
    them); returns (log path, {dump file: path}, version text). Raises ReferenceRunError (binary
    missing, error, timeout, incomplete)."""
    files = {}
    if not Path(deck.data_name).is_absolute():
        if ".." in Path(deck.data_name).parts or len(Path(deck.data_name).parts) != 1:
            raise InputError(
                f"{deck.path}: read_data {deck.data_name!r}: give the data file as a plain "
                "file name next to the deck (the job runs in its own directory)"
            )
        files[deck.data_name] = deck.data_path.read_bytes()
    res = run_job(
        job_dir,
        "\n".join(deck.lines) + "\n",
        files=files,
        timeout=timeout,
        outputs=tuple(d.file for d in deck.dumps),
        expected_runs=len(deck.runs),
        progress=False,
        force=True,
        engine=deck.engine,
        variables=deck.variables,  # -var NAME VALUE on the code's command line, in the manifest
    )
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
    """Steps of the thermo rows of every ``run``, run after run (a later run repeats its first
    step: the row of its set-up)."""
    return [s for run in deck.runs for s in run.thermo_steps()]


def _max_rel(a, b, scale):
    """max |a - b| / scale (the difference itself for a zero scale); NaN (failing) for empty arrays
    or a NaN anywhere, never 0.0 (``scale > 0`` is False for a NaN scale)."""
    d = peak([np.abs(np.asarray(a, float) - np.asarray(b, float))])
    return float(d / scale) if scale > 0 else (d if scale == 0 else math.nan)


_BOX = ("lx", "ly", "xlo", "xhi", "ylo", "yhi", "xy", "xz", "yz")


def _light_state(part, step):
    """What the thermo needs of a step without a kept state: box, tilt and virial of the step."""
    k = step - part.start
    return SimpleNamespace(step=step, lo=part.lo[k], hi=part.hi[k], xy=float(part.xy[k]), virial=part.virial[k], v=None)


def _native_thermo(deck, nat, k, step, kw):
    part = nat.parts[k]
    st = part.states.get(step)
    if st is None:
        st = _light_state(part, step)
    return thermo_value(kw, deck, st, nat.m)


def compare_thermo(deck: ReplayDeck, nat: NativeRun, log_path: Path) -> list:
    """Checks of the thermo tables of every run (see the module docstring)."""
    checks = []
    log = parse_log(Path(log_path))
    if log.errors:
        checks.append(Check("log", "ERROR lines", len(log.errors), 0, False, str(log.errors[0])))
    if not log.runs:
        return checks + [Check("thermo", "incomplete: no thermo table in the log", 1, 0, False, str(log_path))]
    nruns = len(deck.runs)
    if len(log.runs) != nruns:
        checks.append(
            Check(
                "thermo runs",
                "incomplete: thermo tables missing" if len(log.runs) < nruns else "thermo tables",
                abs(len(log.runs) - nruns),
                0,
                False,
                f"{len(log.runs)} thermo tables in the log, the deck has {nruns} run commands",
            )
        )
    d50 = deck.d50
    values: dict = {}  # column index -> (code values, native values, steps)
    for k, (spec, run) in enumerate(zip(deck.runs, log.runs)):
        want = spec.thermo_steps()
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
                f"thermo steps (run {k + 1}, deck line {spec.line})",
                "incomplete: thermo rows missing" if not ok_steps else "rows present",
                len(missing) + len(extra) + (0 if run.complete else 1),
                0,
                ok_steps,
                detail or f"{len(got)} rows",
            )
        )
        if len(run.columns) != len(spec.thermo_columns):
            checks.append(
                Check(
                    f"thermo columns (run {k + 1})",
                    "incomplete: columns missing in the log",
                    abs(len(run.columns) - len(spec.thermo_columns)),
                    0,
                    False,
                    f"log header {list(run.columns)}",
                )
            )
            continue
        for c, kw in enumerate(spec.thermo_columns):
            for row, s in enumerate(got):
                if not spec.start <= s <= spec.end:
                    continue
                nv = _native_thermo(deck, nat, k, s, kw)
                if nv is None:
                    continue
                rec = values.setdefault(kw, ([], [], []))
                rec[0].append(float(run.data[row, c]))
                rec[1].append(nv)
                rec[2].append(s)
    for kw, (code, native, steps) in values.items():
        code, native = np.array(code), np.array(native)
        low = kw.lower()
        problem = _sides_problem(f"thermo {kw}", {deck.engine: code, "native": native})
        bitwise = bool(np.array_equal(code, native))
        if low in ("step", "atoms"):
            bad = int(np.sum(code != native))
            checks.append(Check(f"thermo {kw}", f"rows with {kw} != native", bad, 0, bad == 0 and not problem))
            continue
        worst = steps[int(np.argmax(np.abs(code - native)))] if code.size else 0
        if low in _BOX:
            diff = peak([np.abs(code - native)])  # NaN when no row or any NaN: fails
            checks.append(
                Check(
                    f"thermo {kw}",
                    "max |code - native| / D50",
                    diff / d50,
                    POSITION_TOL,
                    diff <= POSITION_TOL * d50 and not problem,
                    problem or f"bitwise equal: {bitwise}",
                )
            )
            continue
        scale = peak([np.abs(code)])
        rel = _max_rel(code, native, scale)
        what = _pressure_label(deck, kw)
        checks.append(
            Check(
                f"thermo {kw}{what}",
                "max |code - native| / max |code|",
                rel,
                STRESS_TOL,
                (rel <= STRESS_TOL if scale > 0 else rel == 0.0) and not problem,
                problem or f"worst at step {worst}; bitwise equal: {bitwise}",
            )
        )
    return checks


def _pressure_label(deck, kw) -> str:
    """`` (pressure, virial)``, `` (pressure, kinetic + virial)`` ... for a compute pressure column."""
    m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", kw)
    c = deck.computes.get(m.group(1)) if m else None
    if c is None or c.style != "pressure":
        return ""
    return " (pressure, " + " + ".join(p for p, on in (("kinetic", c.keflag), ("virial", c.virial)) if on) + ")"


def _custom_columns(deck: ReplayDeck, d) -> dict:
    """{dump column: native frame column} of the columns that can be compared (``c_ID[k]`` of a
    compute property/atom maps to the attribute it names)."""
    out = {}
    for c in d.columns:
        if c in _POS + _RATE + _EXACT:
            out[c] = c
            continue
        m = re.fullmatch(r"c_([A-Za-z0-9_]+)(\[(\d+)\])?", c)
        comp = deck.computes.get(m.group(1)) if m else None
        if comp is not None and comp.style == "property/atom":
            attr = comp.args[int(m.group(3)) - 1 if m.group(3) else 0]
            if attr in _POS + _RATE + _EXACT:
                out[c] = attr
    return out


def _frame_state(nat, k, s):
    return nat.parts[k].states.get(s)


def compare_dumps(deck: ReplayDeck, nat: NativeRun, dump_paths: dict) -> list:
    """Checks of every ``dump custom`` frame (see the module docstring)."""
    checks = []
    d50 = deck.d50
    index = {int(a): i for i, a in enumerate(deck.ids)}
    for d in deck.dumps:
        if d.style != "custom":
            continue
        path = Path(dump_paths[d.file])
        sched = dump_frames(deck, d)
        want = [s for s, _, _ in sched]
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
        cols = _custom_columns(deck, d)
        worst = {c: 0.0 for c in cols}
        where = {c: None for c in cols}
        scale = {c: 0.0 for c in cols}
        bitwise = {c: True for c in cols}
        problem = {c: None for c in cols}  # the first NaN or inf of a column, named
        inc = []
        pairs = []
        for s, k, _ in sched:
            if s not in frames:
                continue
            fr = frames[s]
            st = _frame_state(nat, k, s)
            if st is None:
                inc.append(f"native frame {s} missing")
                continue
            ids = np.asarray(fr["id"], np.int64)
            if sorted(ids.tolist()) != sorted(index):
                inc.append(f"step {s}: {len(ids)} of {len(index)} atoms")
                continue
            order = np.array([index[int(a)] for a in ids])
            pairs.append((s, fr, frame(st, nat), order))
            for c, a in cols.items():
                if a not in _POS:
                    scale[c] = peak([scale[c], np.abs(fr[c])])  # a NaN sticks (max() would drop it)
        for s, fr, nf, order in pairs:
            for c, attr in cols.items():
                a = np.asarray(fr[c], float)
                b = np.asarray(nf[attr], float)[order]
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
        for c, attr in cols.items():
            if attr in _POS:
                v, tol, metric = worst[c] / d50, POSITION_TOL, "max |code - native| / D50"
            elif attr in _EXACT:
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
                    (v <= tol if (attr in _POS or scale[c] > 0) else v == 0.0) and not problem[c],
                    problem[c] or f"worst at step {where[c]}; bitwise equal: {bitwise[c]}",
                )
            )
    return checks


def compare_local(deck: ReplayDeck, nat: NativeRun, dump_paths: dict) -> list:
    """Checks of every ``dump local`` of contact rows (:mod:`reference_runs.replay.contacts`).

    Per dump: every frame the deck asks for is present (else ``incomplete``); in each frame the
    rows of the native touching pairs are all present, matched by (id1, id2) (LIGGGHTS) or
    (patom1, patom2) (LAMMPS) (a missing row: ``incomplete``), a row the native run has no
    contact for holds no force (LAMMPS lists non-touching neighbours with zeros); each compared
    column's largest difference relative to its largest magnitude (positions: over D50).
    """
    checks = []
    for d in deck.dumps:
        if d.style != "local":
            continue
        style = local_style(deck, d)
        names = local_columns(deck, d)
        keys = ("id1", "id2") if style == "pair/gran/local" else ("patom1", "patom2")
        path = Path(dump_paths[d.file])
        sched = dump_frames(deck, d)
        want = [s for s, _, _ in sched]
        if not all(k in names for k in keys):
            checks.append(
                Check(
                    f"dump {d.id} rows",
                    "incomplete: rows cannot be matched",
                    1,
                    0,
                    False,
                    f"the dump needs the columns {' and '.join(keys)} (compute "
                    + ("pair/gran/local id" if style == "pair/gran/local" else "property/local patom1 patom2")
                    + ") to match its rows with the native contacts",
                )
            )
            continue
        try:
            frames = {int(f.step): f for f in parse_dump_local(path, names=names, sort=False)} if path.exists() else {}
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
        exact = [c for c in names if c in (PGL_EXACT if style == "pair/gran/local" else PL_EXACT)]
        posc = [c for c in names if style == "pair/gran/local" and c in PGL_POSITION]
        code_v = {c: [] for c in exact + posc}
        nat_v = {c: [] for c in exact + posc}
        inc, stray, compared, skipped = [], [], 0, 0
        for s, k, setup in sched:
            if s not in frames:
                continue
            st = _frame_state(nat, k, s)
            if st is None or st.contacts is None:
                inc.append(f"native state of step {s} missing")
                continue
            rows = native_rows(st, deck, style, nat.ids, nat.m, nat.r)
            fr = frames[s]
            got = {}
            for r in range(len(fr[keys[0]])):
                got[(int(fr[keys[0]][r]), int(fr[keys[1]][r]))] = r
            lost = [key for key in rows if key not in got]
            if lost:
                inc.append(f"step {s}: {len(lost)} of {len(rows)} native contacts have no row, e.g. {lost[0]}")
            for key, r in got.items():
                if key not in rows:
                    force = [abs(float(fr[c][r])) for c in ("fx", "fy", "force") if c in names]
                    if any(f != 0.0 for f in force):
                        stray.append(f"step {s}: row {key} holds a force, the native pair does not touch")
                    continue
                nr = rows[key]
                if nr["_periodic"] and not setup:
                    skipped += 1
                    continue
                compared += 1
                for c in exact + posc:
                    code_v[c].append(float(fr[c][r]))
                    nat_v[c].append(nr[c])
        if inc:
            checks.append(
                Check(f"dump {d.id} rows", "incomplete: rows or frames missing", len(inc), 0, False, "; ".join(inc[:3]))
            )
        checks.append(
            Check(
                f"dump {d.id} rows without a native contact",
                "rows holding a force",
                len(stray),
                0,
                not stray,
                "; ".join(stray[:3])
                or f"{compared} rows compared"
                + (
                    f"; {skipped} periodic rows of frames written after a step checked for presence only "
                    "(the codes evaluate them against ghost atoms not updated since the step's communication)"
                    if skipped
                    else ""
                ),
            )
        )
        d50 = deck.d50
        for c in exact + posc:
            a, b = np.array(code_v[c]), np.array(nat_v[c])
            problem = _sides_problem(f"dump {d.id} {c}", {deck.engine: a, "native": b})
            bitwise = bool(np.array_equal(a, b))
            if c in posc:
                diff = peak([np.abs(a - b)]) if a.size else math.nan
                v, tol, metric = diff / d50, POSITION_TOL, "max |code - native| / D50"
                ok = v <= tol
            else:
                scale = peak([np.abs(a)]) if a.size else math.nan
                v = _max_rel(a, b, scale) if a.size else math.nan
                tol, metric = RATE_TOL, "max |code - native| / max |code|"
                ok = v <= tol if scale > 0 else v == 0.0
            checks.append(
                Check(
                    f"dump {d.id} {c}",
                    metric,
                    v,
                    tol,
                    bool(ok) and not problem,
                    problem or f"{a.size} rows; bitwise equal: {bitwise}",
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
    variables=None,
) -> ReplayResult:
    """Read, run in its code (or read ``reference``), run natively, compare, write the report.

    Parameters
    ----------
    deck_path : the deck, or a YADE script (``.py`` or ``engine="yade"``: handed to
        :func:`reference_runs.replay.yade.replay_yade`). data : data file replacing the one of
        ``read_data``. engine : insist on "liggghts" or "lammps" syntax. outdir : output directory (default
        ``results/replay/<deck name>``). timeout : seconds for the code's run (None: no limit).
    reference : a finished job directory (log + dumps of this deck) used instead of running
        the code. echo : callable for progress lines (default: silent).
    variables : {NAME: VALUE} given on the command line (``--var``): substituted natively and
        passed to the code as ``-var NAME VALUE``.

    Returns
    -------
    ReplayResult (``passed``: every check within tolerance and the evidence complete).

    Raises
    ------
    InputError for a deck outside the subset or bad options (before anything runs);
    ReferenceRunError when the code fails; SimulationError when the native run diverges.
    """
    if Path(deck_path).suffix == ".py" or engine == "yade":  # a YADE script (reference_runs.replay.yade)
        from .yade import replay_yade  # noqa: PLC0415 - imports this module

        for option, given in (("--data", data), ("--var", variables)):
            if given:
                raise InputError(f"{option}: a YADE script reads its own files and has no variables")
        return replay_yade(deck_path, outdir=outdir, timeout=timeout, reference=reference, echo=echo)
    say = echo or (lambda msg: None)
    deck = read_deck(deck_path, data=data, engine=engine, variables=variables)
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
    checks = compare_thermo(deck, nat, log) + compare_dumps(deck, nat, dumps) + compare_local(deck, nat, dumps)
    res = ReplayResult(deck, checks, out, version, list(deck.notes))
    write_report(res, nat)
    return res


def _fmt(v) -> str:
    return f"{v:.3g}" if isinstance(v, float) else str(v)


def write_text_reports(res: ReplayResult, name: str, head: list, verdict: str) -> None:
    """``report.md`` and ``report.html`` of a replay (a deck's or a YADE script's ``name``) in
    ``res.outdir``, each atomically: the ``head`` lines (markdown; its "- " items are listed in the
    page), the table of every check, the notes."""
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
        f"<!doctype html><html><head><meta charset=utf-8><title>gransim replay {esc(name)}</title>"
        "<style>body{font-family:sans-serif}td,th{border:1px solid #ccc;padding:2px 6px}"
        ".bad{background:#fdd}.ok{background:#efe}</style></head><body>"
        f"<h1>gransim replay: {esc(name)} &mdash; {verdict}</h1><ul>"
        + "".join(f"<li>{esc(h[2:])}</li>" for h in head[2:] if h)
        + "</ul><table><tr><th>quantity</th><th>metric</th><th>value</th><th>tolerance</th><th>pass</th>"
        f"<th>detail</th></tr>{trs}</table><h2>Notes</h2><ul>"
        + "".join(f"<li>{esc(n)}</li>" for n in res.notes or ["none"])
        + "</ul></body></html>\n"
    )
    with atomic_path(res.outdir / "report.html") as tmp:
        Path(tmp).write_text(page)


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
    write_text_reports(res, d.path.name, head, verdict)
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
