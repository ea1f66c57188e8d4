"""Benchmark suite: ``python -m bench [--quick] [--only AREA]`` (``make bench``).

Each module ``bench/<area>.py`` defines ``run(quick: bool) -> list[dict]`` returning records
``{"name", "value", "unit", "target", "note"}`` (optionally ``"n"`` and ``"series"`` for scaling
plots, and ``"meets"`` True/False/None). Timings repeat and report medians with spread (see
:func:`timeit`). Results land in results/bench.json and results/report/bench.html.

A record whose value (or a point of its series) is NaN or inf is a failed measurement, never a
figure: :func:`judge_record` marks it (``meets`` False, ``"failed"`` naming the quantity) and
``python -m bench`` exits 1 listing it; :func:`show` prints it as ``NaN (FAIL)``.
"""

import math
import numbers
import statistics
import time


def timeit(func, repeat: int = 5, number: int = 1, warmup: int = 1) -> dict:
    """Median and spread of ``func()`` wall time (s) over ``repeat`` runs of ``number`` calls."""
    for _ in range(warmup):
        func()
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            func()
        times.append((time.perf_counter() - t0) / number)
    return {"median": statistics.median(times), "min": min(times), "max": max(times), "repeat": repeat}


def median(values) -> float:
    """``statistics.median``, but NaN when there is no value or any is NaN or inf: a NaN sorts
    anywhere, so ``statistics.median`` may return a finite middle value over a NaN."""
    vals = [float(v) for v in values]
    if not vals or not all(math.isfinite(v) for v in vals):
        return math.nan
    return statistics.median(vals)


def _nonfinite(v) -> str | None:
    """The word for a non-finite number ("NaN", "+inf", "-inf"), else None (also for None and text)."""
    if isinstance(v, bool) or not isinstance(v, numbers.Real):  # numpy's scalars are numbers.Real too
        return None
    x = float(v)
    if math.isfinite(x):
        return None
    return "NaN" if math.isnan(x) else ("+inf" if x > 0 else "-inf")


def judge_record(r: dict) -> str | None:
    """None when the record's value and series are finite (or not measured: None), else a
    one-line message naming the record and what is wrong; the record is then marked failed:
    ``meets`` False, ``failed`` the message, ``value`` the text ``"NaN"``/``"+inf"``/``"-inf"``
    (bench.json stays valid JSON) and the note prefixed with the failure."""
    name = r.get("name", "?")
    problem = None
    w = _nonfinite(r.get("value"))
    if w:
        problem = f"{name} is {w}"
    else:
        for key, v in r.items():  # another figure of the record (a ratio, a time)
            if _nonfinite(v):
                problem = f"{name}: its {key} is {_nonfinite(v)}"
                break
    if not problem:
        for pt in r.get("series") or ():
            bad = next((_nonfinite(c) for c in (pt if isinstance(pt, list | tuple) else (pt,)) if _nonfinite(c)), None)
            if bad:
                problem = f"{name}: a point of its series is {bad} ({pt!r})"
                break
    if problem:
        if w:
            r["value"] = w
        r["meets"] = False
        r["failed"] = problem
        r["note"] = f"FAIL: {problem}" + (f"; {r['note']}" if r.get("note") else "")
    return problem


def show(v) -> str:
    """A record's value for a table: 4 significant digits, "not measured" (None), or
    "NaN (FAIL)" / "+inf (FAIL)" for a value that is not a finite number."""
    if v is None:
        return "not measured"
    if isinstance(v, str):
        return f"{v} (FAIL)"
    w = _nonfinite(v)
    return f"{w} (FAIL)" if w else f"{v:.4g}"


def print_records(records) -> int:
    """Print records one a line (name, value, unit, target, note) for a bench module run on its
    own; 1 when a record's figure is NaN or inf (:func:`judge_record`, printed as ``NaN (FAIL)``
    and listed at the end), else 0."""
    failed = []
    for r in records:
        problem = judge_record(r)
        if problem:
            failed.append(problem)
        tgt = "" if r.get("target") in (None, "") else f"  (target {r['target']})"
        print(f"{r.get('name', '?'):56s} {show(r.get('value')):>12s} {r.get('unit', '')}{tgt}  [{r.get('note', '')}]")
    for msg in failed:
        print(f"FAIL: {msg}")
    return 1 if failed else 0
