"""Open the validation report in headless Chromium and check what a reader sees.

``check_report(index)`` loads ``index.html`` at a given window width (default 1400 px) in Debian's
Chromium (``/usr/bin/chromium``; ``make`` installs it as root) and returns what the page shows: every
image and whether it loaded (``complete`` and a non-zero natural width), every section heading and how
many non-empty blocks follow it, and the page's scroll width against the window. The check runs a small
script in a copy of the page beside the original (so relative image paths resolve) and reads its answer
from ``--dump-dom``; nothing is sent anywhere (the flags switch Chromium's background networking off).

``problems(result)`` lists what is wrong: images that did not load, empty sections, a missing summary.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import tempfile
from pathlib import Path

from gransim.errors import GransimError
from reference_runs.runner import run_watched

#: the flags of a quiet, offline, throw-away headless Chromium
CHROMIUM_FLAGS = (
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--allow-file-access-from-files",
    "--hide-scrollbars",
)

_PROBE = """
<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.map.call(document.images, function (i) {
    return {src: i.getAttribute('src'), ok: i.complete && i.naturalWidth > 0, width: i.naturalWidth};
  });
  var secs = Array.prototype.map.call(document.querySelectorAll('h2'), function (h) {
    var n = h.nextElementSibling, blocks = 0;
    while (n && n.tagName !== 'H2' && n.tagName !== 'SECTION') {
      var own = n.tagName === 'SCRIPT' || n.id === 'gransim-check';
      if (!own && (n.textContent.trim().length > 0 || n.tagName === 'IMG' || n.querySelector('img'))) { blocks += 1; }
      n = n.nextElementSibling;
    }
    return {title: h.textContent.trim(), blocks: blocks};
  });
  var out = document.createElement('pre');
  out.id = 'gransim-check';
  out.textContent = JSON.stringify({images: imgs, sections: secs,
    scroll_width: document.documentElement.scrollWidth, window_width: window.innerWidth,
    title: document.title});
  document.body.appendChild(out);
});
</script>
"""


def chromium() -> str | None:
    """The Chromium binary (``GRANSIM_CHROMIUM``, else chromium or chromium-browser on PATH), or None."""
    env = os.environ.get("GRANSIM_CHROMIUM")
    if env:
        return env if shutil.which(env) else None
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return None


def check_report(index, width: int = 1400, height: int = 1000, timeout: float = 120.0, screenshot=None) -> dict:
    """Load ``index`` (an HTML file) in headless Chromium at ``width`` x ``height`` px and return
    ``{"images": [{src, ok, width}], "sections": [{title, blocks}], "scroll_width", "window_width",
    "title"}``; ``screenshot``: also write a PNG of the first screen there."""
    index = Path(index)
    if not index.is_file():
        raise GransimError(f"report: {index} does not exist")
    exe = chromium()
    if exe is None:
        raise GransimError("headless Chromium not found (Debian package 'chromium'; make installs it as root)")
    text = index.read_text()
    probe = index.with_name(f".{index.stem}-browser-check.html")
    probe.write_text(text.replace("</body>", _PROBE + "</body>") if "</body>" in text else text + _PROBE)
    try:
        with tempfile.TemporaryDirectory(prefix="gransim-chromium-") as profile:
            base = [
                exe,
                *CHROMIUM_FLAGS,
                f"--user-data-dir={profile}",
                f"--window-size={width},{height}",
                "--virtual-time-budget=15000",
            ]
            # Chromium starts a tree of processes (zygote, renderer...): run_watched kills all of
            # them on a timeout, and none outlives this process, even after a SIGKILL
            run = run_watched(
                [*base, "--dump-dom", probe.resolve().as_uri()], capture_output=True, text=True, timeout=timeout
            )
            if screenshot is not None:
                run_watched(
                    [*base, f"--screenshot={Path(screenshot).resolve()}", index.resolve().as_uri()],
                    capture_output=True,
                    timeout=timeout,
                )
    finally:
        probe.unlink(missing_ok=True)
    m = re.search(r"<pre id=\"gransim-check\">(.*?)</pre>", run.stdout, re.S)
    if run.returncode != 0 or m is None:
        raise GransimError(
            f"Chromium did not render {index} (exit {run.returncode}): "
            f"{run.stderr.strip().splitlines()[-1:] or 'no output'}"
        )

    return json.loads(html.unescape(m.group(1)))


def problems(result: dict) -> list[str]:
    """What is wrong with a rendered report: images that did not load, sections with nothing under
    their heading, no summary section, content wider than the window."""
    out = [f"image did not load: {i['src']}" for i in result["images"] if not i["ok"]]
    out += [f"empty section: {s['title']!r}" for s in result["sections"] if s["blocks"] == 0]
    if not any(s["title"].startswith("Summary") for s in result["sections"]):
        out.append("no Summary section")
    if result["scroll_width"] > result["window_width"] + 1:
        out.append(f"the page is wider ({result['scroll_width']} px) than the window ({result['window_width']} px)")
    return out


__all__ = ["CHROMIUM_FLAGS", "check_report", "chromium", "problems"]
