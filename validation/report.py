"""Writers of the validation outputs: JSON summary, HDF5 record table, plain HTML report."""

from __future__ import annotations

import html
import json
import os
from pathlib import Path

import numpy as np

from gransim.io import atomic_h5, atomic_path
from reference_runs.engines import get_engine

from .codes import CODES, DIFFERENCES, code_label, why_they_differ
from .core import PAIRS, CaseResult
from .faults import FAULT_KINDS


def _fmt(v) -> str:
    if isinstance(v, float):
        if v == 0 or not np.isfinite(v):
            return str(v)
        return f"{v:.3e}" if (abs(v) < 1e-3 or abs(v) >= 1e5) else f"{v:.6g}"
    return html.escape(str(v))


def write_json(path: Path, results: list[CaseResult], header: dict) -> None:
    records = [r.to_json() for res in results for r in res.records]
    for res in results:
        if res.error is not None:
            records.append(
                {
                    "case": res.case,
                    "quantity": "case",
                    "metric": "ran",
                    "value": 0.0,
                    "tolerance": 1.0,
                    "pass": False,
                    "reason": f"case did not run: {res.error}",
                }
            )
    doc = {
        "header": header,
        "cases": {res.case: ("pass" if res.passed else "fail") for res in results},
        "records": records,
    }
    with atomic_path(path, suffix=".json.tmp") as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1, default=str))


def write_h5(path: Path, results: list[CaseResult], header: dict) -> None:
    rows = [r for res in results for r in res.records]
    with atomic_h5(path, kind="validation", parameters=header, liggghts=True, lammps=True) as f:
        str_dt = __import__("h5py").string_dtype()
        f.create_dataset("case", data=np.array([r.case for r in rows], dtype=object), dtype=str_dt)
        f.create_dataset("quantity", data=np.array([r.quantity for r in rows], dtype=object), dtype=str_dt)
        f.create_dataset("metric", data=np.array([r.metric for r in rows], dtype=object), dtype=str_dt)
        f.create_dataset("value", data=np.array([r.value for r in rows], float))
        f.create_dataset("tolerance", data=np.array([r.tolerance for r in rows], float))
        f.create_dataset("pass", data=np.array([r.passed and r.kind == "check" for r in rows], bool))
        f.create_dataset("kind", data=np.array([r.kind for r in rows], dtype=object), dtype=str_dt)
        f.create_dataset("pair", data=np.array([r.pair for r in rows], dtype=object), dtype=str_dt)
        f.create_dataset("reason", data=np.array([r.reason for r in rows], dtype=object), dtype=str_dt)


_CSS = """
body{font-family:sans-serif;max-width:1200px;margin:2em auto;color:#222}
pre{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #ccc;padding:3px 7px;font-size:90%}
th{background:#eee}.pass{color:#080;font-weight:bold}.fail{color:#b00;font-weight:bold}
.info{color:#555;font-style:italic}
.matrix td{vertical-align:top;max-width:330px}.na{color:#777}.reason{font-size:85%;color:#444}
.banner{padding:0.7em;border:2px solid #b60;background:#fff4e0;margin:1em 0}
img{max-width:100%;border:1px solid #ddd;margin:0.3em 0}figure{margin:1em 0}
figcaption{font-size:90%;color:#444}code{background:#f4f4f4}
.verdict{font-size:115%}.headline{display:flex;flex-wrap:wrap;gap:1em}
.headline figure{flex:1 1 45%;min-width:300px;margin:0.3em 0}
details{margin:0.6em 0}summary{cursor:pointer;color:#035}section.case{margin-top:2em}
"""


_CELL_CLASS = {"pass": "pass", "FAIL": "fail", "empty": "fail", "n/a": "na", "absent": "na"}


def matrix_html(results: list[CaseResult]) -> list[str]:
    """The validation matrix: a row per case, a column per pair of implementations (native,
    LIGGGHTS, LAMMPS); each cell its verdict, the checks behind it, the tolerances and why."""
    out = [
        "<h2>Validation matrix</h2><table class='matrix'><tr><th>case</th>"
        + "".join(f"<th>{html.escape(v)}</th>" for v in PAIRS.values())
        + "<th>other checks (exact, analytic, bounds)</th></tr>"
    ]
    for res in results:
        row = [
            f"<tr><td><a href='#{res.case}'>{html.escape(res.case)}</a>"
            + (" <span class='fail'>(not run)</span>" if res.error else "")
            + "</td>"
        ]
        for pair in PAIRS:
            c = res.cell(pair)
            st = c["state"]
            word = {"empty": "FAIL: no check", "absent": "&mdash;", "n/a": "n/a"}.get(
                st, st.upper() if st == "pass" else st
            )
            txt = f"<span class='{_CELL_CLASS[st]}'>{word}</span>"
            if st in ("pass", "FAIL", "empty"):
                txt += f" {c['ok']} of {c['n']} checks"
                if c["tolerances"]:
                    txt += "; tolerances " + ", ".join(_fmt(t) for t in c["tolerances"])
            if c["reason"]:
                txt += f"<div class='reason'>{html.escape(c['reason'])}</div>"
            row.append(f"<td>{txt}</td>")
        other = [r for r in res.checks if not r.pair]
        ok = sum(r.passed for r in other)
        row.append(f"<td>{ok} of {len(other)} checks</td>" if other else "<td class='na'>&mdash;</td>")
        out.append("".join(row) + "</tr>")
    out.append(
        "</table><p class='reason'>A cell passes when every check of that pair passes; a declared cell "
        "without a check fails (missing evidence). n/a: the pair does not apply to the case (reason "
        "given).</p>"
    )
    return out


def _ratio_text(r) -> str:
    if r.tolerance > 0 and np.isfinite(r.tolerance) and np.isfinite(r.value):
        return f"{_fmt(r.value)} / {_fmt(r.tolerance)}"
    return f"{_fmt(r.value)} (tolerance {_fmt(r.tolerance)})"


def quantity_matrix_html(results: list[CaseResult]) -> list[str]:
    """The matrix by quantity: a row per case and compared quantity (evidence, position, stress,
    ...), a column per pair of implementations; each cell the verdict of that quantity's checks in
    that pair, their count and the worst of them (measured / tolerance)."""
    cols = [*PAIRS, ""]
    out = [
        "<details open><summary>The matrix by quantity (each cell: the worst check, measured / tolerance)"
        "</summary><table class='matrix'><tr><th>case</th><th>quantity</th>"
        + "".join(f"<th>{html.escape(PAIRS.get(p, 'other checks'))}</th>" for p in cols)
        + "</tr>"
    ]
    for res in results:
        quantities = list(dict.fromkeys(r.quantity for r in res.checks))
        for q in quantities:
            row = [f"<tr class='qty'><td>{html.escape(res.case)}</td><td>{html.escape(q)}</td>"]
            for p in cols:
                rs = [r for r in res.checks if r.quantity == q and r.pair == p]
                if not rs:
                    row.append("<td class='na'>&mdash;</td>")
                    continue
                bad = [r for r in rs if not r.passed]
                finite = [r for r in rs if np.isfinite(r.value) and np.isfinite(r.tolerance) and r.tolerance > 0]
                worst = bad[0] if bad else (max(finite, key=lambda r: abs(r.value) / r.tolerance) if finite else rs[0])
                word = "FAIL" if bad else "pass"
                row.append(
                    f"<td><span class='{'fail' if bad else 'pass'}'>{word}</span> {len(rs) - len(bad)} of "
                    f"{len(rs)}; worst {html.escape(_ratio_text(worst))}</td>"
                )
            out.append("".join(row) + "</tr>")
    out.append("</table></details>")
    return out


def differences_html(results: list[CaseResult]) -> list[str]:
    """Why two codes differ beyond round-off, in words (validation.codes.DIFFERENCES), beside the
    largest raw differences the cases show for that pair (info records)."""
    out = []
    for pair in DIFFERENCES:
        if pair not in PAIRS:
            continue
        raw = [r for res in results for r in res.records if r.pair == pair and r.kind == "info"]
        if not raw:
            continue
        a, b = pair.split("-")
        shown = "; ".join(
            f"{html.escape(r.case)} {html.escape(r.quantity)} {_fmt(r.value)}" for r in raw if np.isfinite(r.value)
        )
        out.append(
            f"<h3>Why {html.escape(code_label(a))} and {html.escape(code_label(b))} differ</h3>"
            f"<p>Raw differences (figures, not verdicts): {shown}.</p>"
            f"<p>{html.escape(why_they_differ(pair))}</p>"
        )
    return out


def _verdict(res: CaseResult) -> tuple[str, str]:
    """(word, css class) of a case's verdict."""
    if res.passed:
        return "PASS", "pass"
    return ("NOT RUN", "fail") if res.error else ("FAIL", "fail")


def _case_data(report_dir: Path, res: CaseResult) -> str:
    """Write ``data/<case>.json`` (the case's records and tables) and return its path relative to
    the report: the data file a figure without a declared source links to."""
    d = report_dir / "data"
    d.mkdir(parents=True, exist_ok=True)
    path = d / f"{res.case}.json"
    doc = {
        "case": res.case,
        "title": res.title,
        "verdict": _verdict(res)[0],
        "records": [r.to_json() for r in res.records],
        "tables": [{"caption": c, "header": h, "rows": rows} for c, h, rows in res.tables],
    }
    with atomic_path(path, suffix=".json.tmp") as tmp:
        Path(tmp).write_text(json.dumps(doc, indent=1, default=str))
    return os.path.relpath(path, report_dir)


def _figure_html(report_dir: Path, res: CaseResult, path, caption: str, case_data: str) -> str:
    rel = os.path.relpath(path, report_dir)
    data = res.figure_data.get(str(path))
    if data is not None:
        drel = os.path.relpath(data, report_dir)
        link = f"<a href='{html.escape(drel)}'>data: {html.escape(Path(data).name)}</a>"
    else:
        link = f"<a href='{html.escape(case_data)}'>data: the records of {html.escape(res.case)} (JSON)</a>"
    return (
        f"<figure><a href='{html.escape(rel)}'><img src='{html.escape(rel)}' alt='{html.escape(caption)}'></a>"
        f"<figcaption>{html.escape(caption)} &middot; {link}</figcaption></figure>"
    )


def summary_html(results: list[CaseResult]) -> list[str]:
    """The one-screen answer: the overall verdict, then a row per case with its verdict, its checks
    and the check closest to (or furthest past) its tolerance."""
    n_fail = sum(not r.passed for r in results)
    if not results:
        head = "<p class='fail verdict'>No case ran: nothing is validated.</p>"
    elif n_fail == 0:
        head = (
            f"<p class='pass verdict'>All {len(results)} cases pass: every check of native gransim against "
            "LIGGGHTS, LAMMPS and the analytic answers is within its tolerance, on complete evidence.</p>"
        )
    else:
        names = ", ".join(r.case for r in results if not r.passed)
        head = f"<p class='fail verdict'>{n_fail} of {len(results)} cases FAIL: {html.escape(names)}.</p>"
    out = [
        "<h2>Summary</h2>",
        head,
        "<table class='summary'><tr><th>case</th><th>verdict</th><th>checks passed</th>"
        "<th>closest to its tolerance (measured / tolerance)</th><th>time</th></tr>",
    ]
    for res in results:
        word, cls = _verdict(res)
        checks = res.checks
        worst = res.worst_check()
        if res.error:
            w = f"<span class='fail'>did not run: {html.escape(res.error[:200])}</span>"
        elif worst is None:
            w = "<span class='fail'>no check</span>" if not checks else "&mdash;"
        else:
            ratio = (
                f" = {abs(worst.value) / worst.tolerance:.2g} of the tolerance"
                if worst.tolerance > 0 and np.isfinite(worst.tolerance) and np.isfinite(worst.value)
                else ""
            )
            w = (
                f"<span class='{'pass' if worst.passed else 'fail'}'>{html.escape(worst.case)}</span>: "
                f"{html.escape(worst.quantity)} ({html.escape(worst.metric)}) {_fmt(worst.value)} / "
                f"{_fmt(worst.tolerance)}{ratio}"
            )
        t = f"{res.seconds:.0f} s" if res.seconds is not None else ""
        out.append(
            f"<tr><td><a href='#{res.case}'>{html.escape(res.case)}</a></td><td class='{cls}'>{word}</td>"
            f"<td>{sum(r.passed for r in checks)} of {len(checks)}</td><td>{w}</td><td>{t}</td></tr>"
        )
    out.append("</table>")
    return out


def headline_html(report_dir: Path, results: list[CaseResult], case_data: dict) -> list[str]:
    """The headline figures the cases marked (stress-strain of both codes with the envelope,
    void-cell maps side by side, the slope), side by side under the summary."""
    figs = [(res, Path(p), cap) for res in results for p, cap in res.figures if str(p) in res.headline]
    if not figs:
        return []
    out = ["<div class='headline'>"]
    for res, p, cap in figs[:4]:
        out.append(_figure_html(report_dir, res, p, cap, case_data[res.case]))
    out.append("</div>")
    return out


def _package(code: str) -> str:
    """The Debian package of ``code``'s binary."""
    return get_engine(code).package


def write_html(report_dir: Path, results: list[CaseResult], header: dict) -> Path:
    """The report: the one-screen summary (verdicts, the closest check of each case, the headline
    figures), the validation matrix, then a section per case with its long tables collapsed."""
    report_dir.mkdir(parents=True, exist_ok=True)
    case_data = {res.case: _case_data(report_dir, res) for res in results}
    out = [
        f"<!doctype html><html><head><meta charset='utf-8'><title>gransim validation</title>"
        f"<style>{_CSS}</style></head><body>",
        "<h1>gransim validation report</h1>",
        f"<p class='reason'>suite {html.escape(str(header.get('suite', '')))}, gransim "
        f"{html.escape(str(header.get('gransim_version', '')))} ({html.escape(str(header.get('git_commit', '')))}), "
        + "".join(
            f"{html.escape(code_label(c))}: {html.escape(str(header.get(f'{c}_version', 'absent')))}, " for c in CODES
        )
        + f"{html.escape(str(header.get('created', '')))}</p>",
    ]
    for code in CODES:
        if not header.get(f"{code}_available"):
            out.append(
                f"<div class='banner'><b>{code_label(code)} is not installed on this machine.</b> Its comparisons "
                "use the stored reference outputs in <code>reference_runs/stored/</code> only "
                f"(install with <code>apt-get install {_package(code)}</code>).</div>"
            )
    out += summary_html(results)
    out += headline_html(report_dir, results, case_data)
    out += matrix_html(results)
    out += quantity_matrix_html(results)
    out += differences_html(results)
    out.append(
        "<p>A case passes only when it ran, has at least one check, and every check passes. A check whose "
        "evidence is incomplete (a missing step, frame, state, contact or run on either side) is a "
        "failure named <i>incomplete</i>, never a pass on what remains; <i>info</i> rows are figures for "
        "the reader, not verdicts.</p>"
    )
    out.append("<details><summary>Run details (provenance)</summary><table>")
    for k, v in header.items():
        out.append(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>")
    if (report_dir / "bench.html").exists():
        out.append(
            "<tr><th>benchmarks</th><td><a href='bench.html'>bench.html</a> (make bench: speed figures "
            "against their targets, scaling plots)</td></tr>"
        )
    out.append("</table></details>")

    out.append(
        "<details><summary>Faults the test suite injects to show that these verdicts can fail "
        f"({len(FAULT_KINDS)} kinds, <code>tests/faults</code>; each ends in a failing verdict or a clear "
        "error)</summary><table><tr><th>fault</th><th>expected outcome</th><th>test</th></tr>"
        + "".join(
            f"<tr><td>{html.escape(k.fault)}</td><td>{html.escape(k.outcome)}</td>"
            f"<td><code>{html.escape(k.test)}</code></td></tr>"
            for k in FAULT_KINDS
        )
        + "</table></details>"
    )
    for res in results:
        word, cls = _verdict(res)
        out.append(
            f"<section class='case'><h2 id='{res.case}'>{html.escape(res.case)}: {html.escape(res.title)} "
            f"<span class='{cls}'>{word}</span></h2>"
        )
        out.append(f"<p>{res.description or html.escape(res.title)}</p>")
        if res.error:
            out.append(f"<p class='fail'>The case did not run: {html.escape(res.error)}</p>")
        for note in res.notes:
            out.append(f"<p>{note}</p>")
        for path, caption in res.figures:
            out.append(_figure_html(report_dir, res, path, caption, case_data[res.case]))
        if res.records:
            n_fail = sum(1 for r in res.checks if not r.passed)
            opened = " open" if n_fail else ""
            out.append(
                f"<details{opened}><summary>{len(res.records)} records ({len(res.checks)} checks, "
                f"{n_fail} failing) &middot; <a href='{html.escape(case_data[res.case])}'>JSON</a></summary>"
                "<table><tr><th>compared</th><th>quantity</th><th>metric</th><th>measured</th>"
                "<th>tolerance</th><th>result</th><th>why this tolerance</th></tr>"
            )
            for r in sorted(res.records, key=lambda r: (r.kind != "check" or r.passed,)):
                rcls = {"pass": "pass", "FAIL": "fail", "info": "info"}[r.verdict]
                tol = "" if r.kind == "info" else _fmt(r.tolerance)
                out.append(
                    f"<tr><td>{html.escape(r.case)}</td><td>{html.escape(r.quantity)}</td>"
                    f"<td>{html.escape(r.metric)}</td><td>{_fmt(r.value)}</td>"
                    f"<td>{tol}</td><td class='{rcls}'>{r.verdict}"
                    f"</td><td>{html.escape(r.reason)}</td></tr>"
                )
            out.append("</table></details>")
        if res.runs:
            out.append(
                f"<details><summary>Runs declared by this case ({len(res.runs)}; the matrix columns follow from "
                "their codes)</summary><table><tr><th>run</th><th>code</th><th>arithmetic</th><th>source</th>"
                "<th>status</th></tr>"
                + "".join(
                    "<tr>" + "".join(f"<td>{html.escape(str(c))}</td>" for c in row) + "</tr>" for row in res.runs
                )
                + "</table></details>"
            )
        for caption, head, rows in res.tables:
            out.append(
                f"<details><summary>{html.escape(caption)} ({len(rows)} rows)</summary>"
                f"<table><caption>{html.escape(caption)}</caption><tr>"
                + "".join(f"<th>{html.escape(str(h))}</th>" for h in head)
                + "</tr>"
            )
            for row in rows:
                out.append("<tr>" + "".join(f"<td>{_fmt(c)}</td>" for c in row) + "</tr>")
            out.append("</table></details>")
        out.append("</section>")
    out.append("</body></html>")
    index = report_dir / "index.html"
    with atomic_path(index, suffix=".html.tmp") as tmp:
        Path(tmp).write_text("\n".join(out))
    return index
