"""The report as a reader sees it: rendered in headless Chromium at 1400 px (Debian's chromium,
installed by make as root; skipped where absent). The page renders, every image loads, no section is
empty, the summary comes first with the headline figures, each figure links to its data file; and the
check itself fails on a broken image and on an empty section."""

from __future__ import annotations

import pytest

from validation.browser import check_report, chromium, problems
from validation.core import CaseResult, compare
from validation.report import write_html

pytestmark = pytest.mark.skipif(chromium() is None, reason="headless Chromium (Debian package chromium) absent")


def _png(path):
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4, 3))
    ax.plot([0, 1, 2], [0, 1, 4])
    fig.savefig(path, dpi=60)
    plt.close(fig)
    return path


def _results(tmp_path):
    figs = tmp_path / "report" / "figures"
    figs.mkdir(parents=True)
    a = CaseResult("alpha", "first case", "a case with a headline figure")
    a.records.append(compare("alpha/x", "stress", "max_rel_diff", 3e-9, 1e-8, "round-off"))
    data = figs / "curve.csv"
    data.write_text("x,y\n0,0\n1,1\n")
    a.add_figure(_png(figs / "curve.png"), "a curve", data=data, headline=True)
    b = CaseResult("beta", "second case", "a case without headline")
    b.records.append(compare("beta/y", "position", "max_abs_diff", 0.0, 0.0, "bit for bit"))
    b.add_figure(_png(figs / "other.png"), "another curve")
    return [a, b]


def test_the_report_renders_with_every_image_and_section(tmp_path):
    index = write_html(tmp_path / "report", _results(tmp_path), {"liggghts_available": True, "lammps_available": True})
    shot = tmp_path / "first-screen.png"
    seen = check_report(index, width=1400, screenshot=shot)
    assert problems(seen) == [], problems(seen)
    assert seen["window_width"] == 1400
    # the headline figure appears twice (summary and its case), the other once: all three loaded
    assert len(seen["images"]) == 3 and all(i["ok"] and i["width"] > 0 for i in seen["images"])
    titles = [s["title"] for s in seen["sections"]]
    assert titles[0] == "Summary" and titles[1] == "Validation matrix", titles
    text = index.read_text()
    assert "href='figures/curve.csv'" in text  # a declared data file is linked beside its figure
    assert "href='data/beta.json'" in text  # a figure without one links to its case's records
    assert (tmp_path / "report" / "data" / "beta.json").stat().st_size > 0
    assert shot.stat().st_size > 0


def test_the_check_finds_a_broken_image_and_an_empty_section(tmp_path):
    results = _results(tmp_path)
    index = write_html(tmp_path / "report", results, {"liggghts_available": True, "lammps_available": True})
    (tmp_path / "report" / "figures" / "other.png").unlink()  # a figure the report points at is gone
    text = index.read_text().replace("</body>", "<h2>Loose ends</h2></body>")  # a heading with nothing under it
    index.write_text(text)
    found = problems(check_report(index))
    assert any("other.png" in p for p in found), found
    assert any("Loose ends" in p for p in found), found
