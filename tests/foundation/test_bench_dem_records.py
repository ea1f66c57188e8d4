"""bench.dem: the benchmark deck and the records built from measured jobs (no timing asserted)."""

import pytest

from bench import dem


def _job(n, rate, peak_mib, steps=10, ranks=None):
    j = {"n": n, "steps": steps, "loop_s": n * steps / rate, "rate": rate, "rebuilds": 1, "peak_kib": peak_mib * 1024}
    if ranks is not None:
        j.update(
            rank_peaks_kib=[r * 1024 for r in ranks], memory_mb_estimate=1.0, breakdown={"Pair": 0.5, "Other": 0.1}
        )
    else:
        j["contacts"] = 3
    return j


def test_deck_is_the_mirror_deck_without_dump(tmp_path):
    from reference_runs.decks.biaxial import write_biaxial_deck

    p = dem.assembly(100)
    mirror = write_biaxial_deck(tmp_path / "m", p, dem.SETTINGS, dem.LOADING, 40, thermo_every=4).read_text()
    bench = dem.write_bench_deck(tmp_path / "b", p, 40).read_text()
    assert "dump" not in bench
    kept = [ln for ln in mirror.splitlines() if not ln.startswith(("dump ", "dump_modify "))]
    assert bench.splitlines() == kept
    assert (tmp_path / "b" / "data.biaxial").read_bytes() == (tmp_path / "m" / "data.biaxial").read_bytes()


def test_records_medians_ratios_and_series():
    n1, n2 = 100, 1000
    res = {
        (n1, dem.NATIVE_1): [_job(n1, r, 200) for r in (3e6, 1e6, 2e6)],
        (n1, dem.LIG_1): [_job(n1, r, 20, ranks=[20]) for r in (1e6, 2e6, 1.5e6)],
        (n1, dem.LIG_2): [_job(n1, r, 40, ranks=[15, 25]) for r in (2e6, 2e6, 2e6)],
        (n2, dem.NATIVE_1): [_job(n2, r, 300) for r in (4e6, 4e6, 4e6)],
    }
    recs = {r["name"]: r for r in dem._records(res, [n1, n2], [dem.NATIVE_1, dem.LIG_1, dem.LIG_2])}
    assert recs[f"{dem.NATIVE_1}, 100 disks"]["value"] == 2e6
    ratio = recs[f"{dem.NATIVE_1} / {dem.LIG_1}, 100 disks"]
    assert ratio["value"] == pytest.approx(2e6 / 1.5e6) and ratio["target"] == 1.5 and ratio["meets"] is False
    assert "per-repeat ratios 0.5..3" in ratio["note"]  # paired in run order: 3/1, 1/2, 2/1.5
    assert f"{dem.NATIVE_2} / {dem.LIG_2}, 100 disks" not in recs  # no native 2-thread jobs
    series = recs[f"{dem.NATIVE_1}: ns per particle-step"]["series"]
    assert series == [(n1, pytest.approx(500.0)), (n2, pytest.approx(250.0))]
    mem = recs[f"{dem.LIG_2} peak memory, 100 disks"]
    assert mem["value"] == 40 and "largest rank 25 MiB" in mem["note"]
    assert recs[f"{dem.NATIVE_1} peak memory, 1,000 disks"]["value"] == 300
    unjudged = dem._records(res, [n1], [dem.NATIVE_1, dem.LIG_1], judge=False)
    assert all(r.get("meets") is None for r in unjudged)
