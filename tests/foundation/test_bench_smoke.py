"""The benchmark suite's quick mode runs end to end (a smoke test: no timing is asserted)."""

import json
import pkgutil
import subprocess
import sys
from pathlib import Path

import bench


def test_bench_quick_runs_every_area(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "bench", "--quick", "--results", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=Path(bench.__file__).parents[1],
    )
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    doc = json.loads((tmp_path / "bench.json").read_text())
    areas = {m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_")}
    assert doc["failed_areas"] == []
    assert {r["area"] for r in doc["records"]} == areas
    for r in doc["records"]:
        if r["value"] is None:  # a figure quick mode does not measure says so (bench.ab_dem)
            assert "not measured" in r["note"], r
            continue
        assert r["value"] == r["value"] and r["value"] >= 0, r  # finite, non-negative
    for key in ("cores", "cpu", "git_commit", "numba"):
        assert key in doc["machine"]
    assert (tmp_path / "report" / "bench.html").exists()
