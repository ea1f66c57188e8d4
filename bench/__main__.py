"""Run the benchmark suite and write results/bench.json plus an HTML table with scaling plots."""

from __future__ import annotations

import argparse
import html
import importlib
import json
import os
import pkgutil
import platform
import sys
import time
import traceback
from pathlib import Path

import numba
import numpy

import bench
from gransim import __version__
from gransim.io import git_commit, liggghts_version


def _num(v) -> str:
    """A record's value for the tables: 4 significant digits, "not measured" (None), or "NaN (FAIL)"
    (:func:`bench.show`)."""
    return bench.show(v)


def machine() -> dict:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    return {
        "cores": os.cpu_count(),
        "cpu": cpu,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "numba": numba.__version__,
        "gransim": __version__,
        "git_commit": git_commit(),
        "liggghts": liggghts_version() or "absent",
        "host": platform.node(),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench", description=__doc__)
    ap.add_argument("--quick", action="store_true", help="small sizes, smoke test (no targets judged)")
    ap.add_argument("--only", action="append", help="run only this area (module name), repeatable")
    ap.add_argument("--results", default="results")
    args = ap.parse_args(argv)

    areas = sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_"))
    if args.only:
        unknown = set(args.only) - set(areas)
        if unknown:
            print(f"bench: unknown area(s) {sorted(unknown)}; known: {areas}", file=sys.stderr)
            return 2
        areas = [a for a in areas if a in args.only]
    records, failures, bad_records = [], [], []
    for area in areas:
        t0 = time.perf_counter()

        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)  # an area may have left fewer threads set
        print(f"[bench] {area} ...", flush=True)
        try:
            mod = importlib.import_module(f"bench.{area}")
            if not hasattr(mod, "run"):  # a tool run on its own (python -m bench.ab_dem), not an area
                print(f"[bench] {area}: no run(), skipped", flush=True)
                continue
            for r in mod.run(quick=args.quick):
                r.setdefault("area", area)
                problem = bench.judge_record(r)  # a NaN or inf figure is a failure, not a number
                if problem:
                    bad_records.append(f"{area}: {problem}")
                records.append(r)
                print(
                    f"[bench]   {r['name']}: {_num(r['value'])} {r.get('unit', '')} (target {r.get('target')})",
                    flush=True,
                )
        except Exception:
            failures.append(area)
            traceback.print_exc()
        print(f"[bench] {area} done in {time.perf_counter() - t0:.1f} s", flush=True)
    out = Path(args.results)
    out.mkdir(parents=True, exist_ok=True)
    doc = {
        "machine": machine(),
        "quick": args.quick,
        "records": records,
        "failed_areas": failures,
        "failed_records": bad_records,
    }
    tmp = out / ".bench.json.tmp"
    tmp.write_text(json.dumps(doc, indent=1, default=str))
    os.replace(tmp, out / "bench.json")
    _html(out / "report", doc)
    print(f"[bench] wrote {out / 'bench.json'}")
    for msg in bad_records:
        print(f"[bench] FAIL: {msg}", file=sys.stderr)
    return 1 if failures or bad_records else 0


def _html(report: Path, doc: dict) -> None:
    report.mkdir(parents=True, exist_ok=True)
    rows = [
        "<tr><th>area</th><th>benchmark</th><th>value</th><th>unit</th><th>target</th><th>meets</th><th>note</th></tr>"
    ]
    for r in doc["records"]:
        meets = r.get("meets")
        rows.append(
            "<tr>"
            + "".join(
                f"<td>{html.escape(str(c))}</td>"
                for c in (
                    r.get("area"),
                    r["name"],
                    _num(r["value"]),
                    r.get("unit", ""),
                    r.get("target", ""),
                    "" if meets is None else ("yes" if meets else "NO"),
                    r.get("note", ""),
                )
            )
            + "</tr>"
        )
    figs = []
    series = [r for r in doc["records"] if r.get("series")]
    if series:
        # lazy: pyplot costs ~1.5 s of import (measured, load 9); only the figures need it
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, ax = plt.subplots(figsize=(7, 5))
        for r in series:
            xs, ys = zip(*r["series"])
            ax.loglog(xs, ys, "o-", label=f"{r['area']}: {r['name']} [{r.get('unit', '')}]")
        ax.set_xlabel("N (particles)")
        ax.legend(fontsize=7)
        ax.grid(True, which="both", alpha=0.3)
        (report / "figures").mkdir(exist_ok=True)
        fig.savefig(report / "figures" / "bench_scaling.png", dpi=110, bbox_inches="tight")
        plt.close(fig)
        figs.append("<img src='figures/bench_scaling.png'>")
    machine_rows = "".join(
        f"<tr><th>{html.escape(k)}</th><td>{html.escape(str(v))}</td></tr>" for k, v in doc["machine"].items()
    )
    text = (
        "<!doctype html><html><head><meta charset='utf-8'><title>gransim benchmarks</title></head><body>"
        f"<h1>gransim benchmarks{' (quick)' if doc['quick'] else ''}</h1><table>{machine_rows}</table>"
        f"<table border=1>{''.join(rows)}</table>{''.join(figs)}</body></html>"
    )
    tmp = report / ".bench.html.tmp"
    tmp.write_text(text)
    os.replace(tmp, report / "bench.html")


if __name__ == "__main__":
    sys.exit(main())
