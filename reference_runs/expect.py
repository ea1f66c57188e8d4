"""What a reference deck (LIGGGHTS or LAMMPS) must leave behind: its runs (first and last step) and its
dump frames.

:func:`expected_evidence` reads a deck the way LIGGGHTS 3.8.0 executes it, command by command,
tracking the time step (``run``, ``reset_timestep``, ``clear``) and the dumps defined
(``dump``, ``undump``, ``dump_modify ID every N|first yes``, ``clear``). :func:`check_evidence`
compares a job's log and dump files with that expectation.

Rules, measured on LIGGGHTS-PUBLIC 3.8.0 (Debian 3.8.0+repack1) runs of a deck with ``run 10``,
``run 0``, ``run 5``, ``reset_timestep 23``, ``run 4``, ``run 30 upto``, ``undump``, ``run 3`` and
dumps every 7 and every 3 steps (tests/faults/test_runner_faults.py repeats the check):

* ``run N`` from step s prints a thermo table whose first row is step s and last row step s + N,
  ended by a ``Loop time of`` line (``run 0`` too: one row); ``run N upto`` ends at step N.
* a ``dump ID GROUP custom|local EVERY FILE ...`` writes one frame at every step t that is a
  multiple of EVERY and lies within a run (s <= t <= s + N), once per step: the last step of a run
  and the first of the next are the same step and give one frame. A run that starts off a multiple
  of EVERY (after ``reset_timestep 23`` with EVERY 7) writes no frame at its first step; with
  ``dump_modify ID first yes`` the first step of the first run after the definition is written too.
  ``run 10; run 0; run 5`` with EVERY 7 gives frames 0, 7, 14; the full deck above gives 0, 7, 14, 28
  (EVERY 7) and 0, 3, 6, 9, 12, 15, 24, 27, 30 (EVERY 3, undumped before the last run).
* ``clear`` deletes every dump and resets the step to 0 (the Taylor decks: ``clear``, a new
  ``dump``, ``reset_timestep k``, ``run 0``: one frame at step k per state).

Variables are substituted as the codes do (``${name}`` and ``$x``): an index variable by its
text (``variable NAME index V``: its first value), an equal-style one only when it is a plain
number (``variable NAME equal NUMBER``). The job's command-line variables (``-var NAME VALUE``,
``expected_evidence(deck, variables)``) are index variables defined before the deck's first line,
so a deck's ``variable NAME index DEFAULT`` of the same name is skipped: an index variable keeps
its first definition (``if (find(arg[0]) >= 0) return;`` in ``Variable::set``, LAMMPS
src/variable.cpp:152-154 at commit b8208f58, LIGGGHTS-PUBLIC 3.8.0 src/variable.cpp:187-189; the
command line's ``-var``: LAMMPS src/input.cpp:107-110 at commit 256531a2, LIGGGHTS
src/input.cpp:141-144). Redefining an index variable as ``equal``, ``string``, ``atom`` or
``getenv`` stops the codes ("Cannot redefine variable as a different style", LIGGGHTS
src/variable.cpp:385); the reader stops there too.
Anything that cannot be followed without running LIGGGHTS (``jump``, ``label``, ``next``,
``include``, ``if``, ``minimize``, ``rerun``, ``run ... every``, ``$(...)``, a variable that is an
expression or is not defined, a dump EVERY that is ``v_name``, a multi-file dump name with ``*``
or ``%``) is reported in :attr:`DeckExpectation.unresolved` instead of guessed; the counts it
affects are None.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

_NUMBER = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_UNFOLLOWABLE = {
    "jump": "a jump",
    "label": "a label (loop)",
    "next": "a next (loop variable)",
    "include": "an include file",
    "if": "an if command",
    "minimize": "a minimize",
    "rerun": "a rerun",
    "python": "a python command",
    "partition": "a partition command",
}


@dataclass(frozen=True)
class RunSpec:
    """One ``run`` command: deck line, first and last step."""

    lineno: int
    start: int
    end: int

    @property
    def steps(self) -> int:
        return self.end - self.start


@dataclass(frozen=True)
class DumpSpec:
    """One dump file: its ``dump`` line, style, EVERY and the steps at which frames are written
    (None when they cannot be determined)."""

    lineno: int
    dump_id: str
    style: str
    every: int | None
    file: str
    steps: tuple | None

    @property
    def frames(self) -> int | None:
        return None if self.steps is None else len(self.steps)


@dataclass(frozen=True)
class DeckExpectation:
    """The evidence a deck must produce (:func:`expected_evidence`).

    Attributes
    ----------
    runs : the ``run`` commands in order, or None when the deck cannot be followed.
    dumps : {file: DumpSpec} of the ``dump custom|local`` files of the deck.
    unresolved : why runs or dump counts could not be determined (empty when all could).
    """

    runs: tuple | None
    dumps: dict
    unresolved: tuple = field(default=())

    @property
    def n_runs(self) -> int | None:
        return None if self.runs is None else len(self.runs)


def _logical_lines(text: str):
    """(first line number, text) of each command: comments stripped, ``&`` continuations joined."""
    buf, start = "", None
    for n, raw in enumerate(text.splitlines(), start=1):
        line = _strip_comment(raw)
        if start is None:
            start = n
        if line.rstrip().endswith("&"):
            buf += line.rstrip()[:-1] + " "
            continue
        buf += line
        if buf.strip():
            yield start, buf.strip()
        buf, start = "", None
    if buf.strip():
        yield start, buf.strip()


def _strip_comment(line: str) -> str:
    quote = None
    for k, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return line[:k]
    return line


def _int(word: str) -> int | None:
    if not _NUMBER.match(word):
        return None
    v = float(word)
    return int(v) if v == int(v) else None


#: styles whose ``variable`` line is skipped when the name exists (``Variable::set``: ``return``)
_KEEP_FIRST = {"index", "loop", "world", "universe", "uloop", "file", "atomfile"}
#: styles that replace a variable of the same style and stop the codes on another style
_SAME_STYLE = {"equal", "string", "atom", "getenv"}


def expected_evidence(deck_text: str, variables=None) -> DeckExpectation:
    """Runs and dump frames a deck asks LIGGGHTS (or LAMMPS) for (rules in the module docstring).

    Parameters
    ----------
    deck_text : the deck as run (``in.liggghts``, ``in.lammps``).
    variables : the job's command-line variables {NAME: VALUE} (``-var NAME VALUE``, as checked
        by :func:`reference_runs.engines.check_variables`): index variables defined before the
        first line, which the deck's ``variable NAME index ...`` lines do not change.

    Returns
    -------
    :class:`DeckExpectation`; ``unresolved`` says what could not be followed, in which line.
    """
    # name -> text substituted for ${name}, or None (defined, but not a text we can substitute)
    values: dict = {str(k): str(v) for k, v in dict(variables or {}).items()}
    styles: dict = dict.fromkeys(values, "index")  # name -> style of its definition
    unresolved: list = []
    runs: list = []
    step = 0
    active: dict = {}  # dump id -> state dict
    done: list = []  # finished dump states

    def note(lineno, why):
        unresolved.append(f"deck line {lineno}: {why}")

    def subst(line):
        """(substituted line, None) or (None, why)."""
        if "$(" in line:
            return None, f"immediate variable $(...) in {line!r}"
        bad = []

        def rep(m):
            name = m.group(1) or m.group(2)
            if values.get(name) is None:
                bad.append(name)
                return m.group(0)
            return values[name]

        out = re.sub(r"\$\{(\w+)\}|\$(\w)", rep, line)
        if bad:
            name = bad[0]
            if name not in values:
                return None, (
                    f"{line!r} uses ${{{name}}}, which is not defined (neither by the deck before this line "
                    f"nor as a command-line variable -var {name} VALUE)"
                )
            return None, (
                f"{line!r} uses ${{{name}}}, which is not a plain number or text known before the run "
                "(variable NAME index VALUE, variable NAME equal NUMBER and -var NAME VALUE are)"
            )
        return out, None

    broken = False
    for lineno, line in _logical_lines(deck_text):
        words = line.split()
        cmd = words[0]
        if cmd in _UNFOLLOWABLE:
            note(lineno, f"{_UNFOLLOWABLE[cmd]} ({line[:60]!r}) cannot be followed without running LIGGGHTS")
            broken = True
            break
        unknown = False  # a variable line whose value holds a variable we cannot substitute
        if "$" in line:  # the codes substitute every line before running it (Input::parse)
            sub, why = subst(line)
            if sub is None:
                if cmd in ("run", "reset_timestep", "clear", "dump", "undump", "dump_modify"):
                    note(lineno, why)
                    broken = True
                    break
                if cmd != "variable":
                    continue
                unknown = True
            else:
                line, words = sub, sub.split()
        if cmd == "variable" and len(words) >= 3:
            name, style = words[1], words[2]
            vals = words[3:]
            if style == "delete":
                values.pop(name, None)
                styles.pop(name, None)
                continue
            if name in styles and style in _KEEP_FIRST:
                continue  # the first definition (the command line's -var included) is kept
            if name in styles and style in _SAME_STYLE and styles[name] != style:
                note(
                    lineno,
                    f"variable {name} {style}: {name} is already defined with style {styles[name]}"
                    + (" (given on the command line)" if name in dict(variables or {}) else "")
                    + "; the codes stop here (Cannot redefine variable as a different style)",
                )
                broken = True
                break
            styles[name] = style
            if unknown:
                values[name] = None
            elif style == "index" and vals and vals[0][0] not in "\"'":
                values[name] = vals[0]  # the text of the first value, as retrieve() gives it
            elif style == "equal" and len(vals) == 1 and _NUMBER.match(vals[0]):
                values[name] = vals[0]
            else:
                values[name] = None
            continue
        if cmd == "clear":
            done.extend(active.values())
            active.clear()
            step = 0
        elif cmd == "reset_timestep":
            v = _int(words[1]) if len(words) > 1 else None
            if v is None:
                note(lineno, f"reset_timestep value {line!r} is not an integer")
                broken = True
                break
            step = v
        elif cmd == "run":
            n = _int(words[1]) if len(words) > 1 else None
            if n is None:
                note(lineno, f"run length in {line!r} is not an integer")
                broken = True
                break
            kw = words[2:]
            if "every" in kw:
                note(lineno, f"'run ... every' ({line[:60]!r}) runs commands between chunks")
                broken = True
                break
            end = n if "upto" in kw else step + n
            if end < step:
                note(lineno, f"run upto {n} lies before the current step {step}")
                broken = True
                break
            runs.append(RunSpec(lineno, step, end))
            for d in active.values():
                if d["steps"] is None:
                    continue
                e = d["every"]
                first = (step + e - 1) // e * e
                new = list(range(first, end + 1, e))
                if d["first"] and not d["ran"] and (not new or new[0] != step):
                    new.insert(0, step)
                d["ran"] = True
                for t in new:
                    if not d["steps"] or t > d["steps"][-1]:
                        d["steps"].append(t)
            step = end
        elif cmd == "dump" and len(words) >= 6:
            did, style, every, fname = words[1], words[3], words[4], words[5]
            if style not in ("custom", "local", "atom", "xyz"):
                continue
            e = _int(every)
            d = {
                "lineno": lineno,
                "id": did,
                "style": style,
                "every": e,
                "file": fname,
                "first": False,
                "ran": False,
                "steps": [],
            }
            if e is None or e <= 0:
                note(lineno, f"dump {did} every {every!r} is not a positive integer: frames not counted")
                d["steps"] = None
            elif "*" in fname or "%" in fname:
                note(lineno, f"dump {did} writes one file per step or process ({fname}): not counted")
                d["steps"] = None
            if did in active:
                done.append(active.pop(did))
            active[did] = d
        elif cmd == "undump" and len(words) >= 2:
            if words[1] in active:
                done.append(active.pop(words[1]))
        elif cmd == "dump_modify" and len(words) >= 3 and words[1] in active:
            d = active[words[1]]
            kw = words[2:]
            for k, w in enumerate(kw[:-1]):
                if w == "every":
                    e = _int(kw[k + 1])
                    if e is None or e <= 0:
                        note(lineno, f"dump_modify {d['id']} every {kw[k + 1]!r}: frames not counted")
                        d["steps"] = None
                    elif d["steps"] is not None:
                        d["every"] = e
                elif w == "first" and kw[k + 1] == "yes":
                    d["first"] = True
                elif w == "append" and kw[k + 1] == "yes":
                    note(lineno, f"dump {d['id']} appends to an existing file: frames not counted")
                    d["steps"] = None
    done.extend(active.values())
    dumps = {}
    for d in done:
        if d["file"] in dumps:  # the same file written by two dump commands (e.g. after clear)
            old = dumps[d["file"]]
            note(d["lineno"], f"file {d['file']} is written by more than one dump command: not counted")
            dumps[d["file"]] = DumpSpec(old.lineno, old.dump_id, old.style, old.every, old.file, None)
            continue
        steps = None if (broken or d["steps"] is None) else tuple(d["steps"])
        dumps[d["file"]] = DumpSpec(d["lineno"], d["id"], d["style"], d["every"], d["file"], steps)
    return DeckExpectation(None if broken else tuple(runs), dumps, tuple(unresolved))


# ----------------------------------------------------------------------------- dump frames
def dump_frame_steps(path) -> tuple[tuple, str | None]:
    """Steps of the complete frames of a ``dump custom|local|atom`` file, and the problem of its
    last frame if it is cut short (None when the file ends cleanly).

    Reads only the frame headers and counts rows (fast on large dumps); a frame is complete when
    its ``ITEM: NUMBER OF ...`` rows are all present.
    """
    steps: list = []
    try:
        fh = open(path, errors="replace")
    except OSError as exc:
        return (), f"cannot read ({exc.strerror or exc})"
    with fh:
        lineno = 0

        def nxt():
            nonlocal lineno
            lineno += 1
            return fh.readline()

        while True:
            line = nxt()
            if not line:
                return tuple(steps), None
            if not line.strip():
                continue
            if line.strip() != "ITEM: TIMESTEP":
                return tuple(steps), f"line {lineno}: expected 'ITEM: TIMESTEP', got {line.strip()[:40]!r}"
            try:
                step = int(nxt())
                if not nxt().startswith("ITEM: NUMBER OF"):
                    raise ValueError
                n = int(nxt())
                for _ in range(4):  # BOX BOUNDS and its three rows
                    if not nxt():
                        raise ValueError
                if not nxt().startswith("ITEM:"):
                    raise ValueError
            except ValueError:
                return tuple(steps), f"line {lineno}: truncated or malformed frame header"
            for k in range(n):
                if not nxt().strip():
                    return tuple(steps), f"frame at step {step} cut short: {k} of {n} rows"
            steps.append(step)


# ----------------------------------------------------------------------------- the check
def check_evidence(expect: DeckExpectation, log, log_name: str, job_dir, outputs=()) -> tuple[dict, list]:
    """Compare a parsed log and the dump files among ``outputs`` with what the deck asked for.

    Parameters
    ----------
    expect : from :func:`expected_evidence`.
    log : the parsed log (:class:`~reference_runs.parsers.LogFile`), or None when it is missing.
    log_name : the log's file name, for messages.
    job_dir : directory of the outputs.
    outputs : job-relative names of the outputs; dumps of the deck among them are counted.

    Returns
    -------
    ``(evidence, problems)``: ``evidence`` (JSON-able) records expected and found counts
    (``runs_expected``, ``runs_complete``, ``last_steps_expected``, ``last_steps_got``, and per
    dump ``frames_expected``, ``frames_got``); ``problems`` lists messages such as
    ``incomplete: log.lammps holds 2 of 3 runs`` or ``dump.atoms: expected 7 frames, got 1``.
    """
    problems: list = []
    ev: dict = {"log": log_name, "unresolved": list(expect.unresolved)}
    runs = log.runs if log is not None else ()
    complete = [r for r in runs if r.complete]
    ev["runs_found"] = len(runs)
    ev["runs_complete"] = len(complete)
    ev["last_steps_got"] = [int(r.steps[-1]) if len(r) else None for r in runs]
    if log is None:
        problems.append(f"incomplete: {log_name} was not written")
    if expect.runs is not None:
        want = len(expect.runs)
        ev["runs_expected"] = want
        ev["last_steps_expected"] = [r.end for r in expect.runs]
        if log is not None:
            if len(complete) < want or len(runs) < want:
                msg = f"incomplete: {log_name} holds {len(complete)} of {want} runs"
                if len(runs) > len(complete):
                    bad = next(k for k, r in enumerate(runs) if not r.complete)
                    last = ev["last_steps_got"][bad]
                    if bad < want:
                        spec = expect.runs[bad]
                        msg += (
                            f"; run {bad + 1} (deck line {spec.lineno}, steps {spec.start}..{spec.end}) "
                            f"stops at step {last} with no 'Loop time' line"
                        )
                problems.append(msg)
            elif len(runs) > want:
                problems.append(f"{log_name} holds {len(runs)} runs, the deck has {want} run commands")
            for k, (spec, run) in enumerate(zip(expect.runs, runs)):
                if not run.complete or not len(run):
                    continue
                first, last = int(run.steps[0]), int(run.steps[-1])
                if (first, last) != (spec.start, spec.end):
                    problems.append(
                        f"{log_name}: run {k + 1} (deck line {spec.lineno}) covers steps "
                        f"{first}..{last}, the deck asks for {spec.start}..{spec.end}"
                    )
                    break
    else:
        ev["runs_expected"] = None
        incomplete = [k for k, r in enumerate(runs) if not r.complete]
        if incomplete:
            problems.append(f"incomplete: {log_name}: run {incomplete[0] + 1} of {len(runs)} has no 'Loop time' line")
    dumps = {}
    for name in outputs:
        spec = expect.dumps.get(str(name))
        if spec is None:
            continue
        steps, cut = dump_frame_steps(Path(job_dir) / name) if (Path(job_dir) / name).exists() else ((), None)
        rec = {"style": spec.style, "every": spec.every, "frames_expected": spec.frames, "frames_got": len(steps)}
        if not (Path(job_dir) / name).exists():
            rec["frames_got"] = None
        elif spec.steps is not None and tuple(steps) != spec.steps:
            if len(steps) != len(spec.steps):
                problems.append(
                    f"{name}: expected {spec.frames} frames, got {len(steps)}" + (f" ({cut})" if cut else "")
                )
            else:
                diff = next(k for k, (a, b) in enumerate(zip(steps, spec.steps)) if a != b)
                problems.append(f"{name}: frame {diff + 1} is at step {steps[diff]}, expected {spec.steps[diff]}")
        elif cut:
            problems.append(f"{name}: {cut}")
        dumps[str(name)] = rec
    ev["dumps"] = dumps
    ev["problems"] = list(problems)
    return ev, problems


__all__ = ["DeckExpectation", "DumpSpec", "RunSpec", "check_evidence", "dump_frame_steps", "expected_evidence"]
