"""The report page in a real headless browser: the screenshot is not blank and the images load.

Needs Chromium from the distribution's packages (``apt-get install chromium``; ``.ci/run``
installs it in CI); skips with the reason elsewhere.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from slamkit.app import RunRequest, run_job
from slamkit.app.compare import compare_job

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")

# Written into a copy of the page: after the load event, every image's source, whether it
# finished and its decoded width go into a <pre> that --dump-dom prints.
PROBE = """<script>
window.addEventListener("load", function () {
  var rows = Array.prototype.map.call(document.images, function (im) {
    return [im.getAttribute("src"), im.complete, im.naturalWidth, im.naturalHeight];
  });
  var out = document.createElement("pre");
  out.id = "img-probe";
  out.textContent = JSON.stringify(rows);
  document.body.appendChild(out);
});
</script>"""


# The layout of the page's key elements after the load event: each one's text, its box in
# CSS pixels and whether it is shown (a box of some size, not hidden by its style).
LAYOUT_PROBE = """<script>
window.addEventListener("load", function () {
  function shown(el) {
    var r = el.getBoundingClientRect(), st = window.getComputedStyle(el);
    return r.width > 0 && r.height > 0 && st.visibility !== "hidden" && st.display !== "none";
  }
  function box(el) {
    var r = el.getBoundingClientRect();
    return {text: el.textContent.trim(), x: r.left + window.scrollX, y: r.top + window.scrollY,
            w: r.width, h: r.height, shown: shown(el)};
  }
  function all(sel) { return Array.prototype.map.call(document.querySelectorAll(sel), box); }
  var out = document.createElement("pre");
  out.id = "layout-probe";
  out.textContent = JSON.stringify({
    verdict: all("#verdict"), groups: all("section.metric-group > h3"),
    units: all("section.metric-group > table.metrics td:nth-child(4)"),
    unit_cells: all("section.metric-group > table.metrics td:nth-child(3)"),
    captions: all("figcaption"), figures: all("figure img")
  });
  document.body.appendChild(out);
});
</script>"""


def _browser() -> str:
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    pytest.skip(
        "no headless browser: install Chromium from the distribution "
        "(apt-get install chromium) to render the report page"
    )


def _chromium(browser: str, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
         "--allow-file-access-from-files", "--virtual-time-budget=5000", *args],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip


def _probe(browser: str, page: Path, script: str, name: str) -> object:
    """What ``script`` wrote into ``<pre id=name>`` of a copy of ``page`` after the load
    event, laid out in the screenshot's window size."""
    probe = page.with_name(".probe-" + page.name)
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", script + "</body>"))
    try:
        done = _chromium(browser, "--window-size=1200,1800", "--dump-dom", probe.as_uri())
    finally:
        probe.unlink()
    match = re.search(rf'<pre id="{name}">(.*?)</pre>', done.stdout, re.S)
    assert match, f"the probe did not run: {done.stderr[-500:]}"
    return json.loads(html.unescape(match.group(1)))


def _image_probe(browser: str, page: Path) -> list[list[object]]:
    rows = _probe(browser, page, PROBE, "img-probe")
    assert isinstance(rows, list)
    return rows


def _screenshot(browser: str, page: Path, png: Path) -> np.ndarray:
    done = _chromium(browser, f"--screenshot={png}", "--window-size=1200,1800", page.as_uri())
    assert png.is_file(), f"no screenshot: {done.stderr[-500:]}"
    return np.asarray(Image.open(png).convert("L"), dtype=float)


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "ekf-slam"
    run_job(RunRequest("ekf-slam", "five-features", out))
    return out


def test_report_renders_with_its_images(run_folder: Path, tmp_path: Path) -> None:
    browser = _browser()
    page = run_folder / "report.html"
    rows = _image_probe(browser, page)
    figures = sorted(p.name for p in run_folder.glob("*.png"))
    assert sorted(str(r[0]) for r in rows) == figures  # every PNG is on the page
    for src, complete, width, height in rows:
        with Image.open(run_folder / str(src)) as im:
            assert (width, height) == im.size, src  # decoded by the browser at full size
        assert complete is True

    shot = _screenshot(browser, page, tmp_path / "page.png")
    assert shot.std() > 20.0  # not a blank page
    # The same page with the images' files gone: the figures' pixels are what changes.
    bare = tmp_path / "bare"
    bare.mkdir()
    shutil.copy(page, bare / "report.html")
    missing = _image_probe(browser, bare / "report.html")
    assert all(r[2] == 0 for r in missing)  # the probe does see a broken image
    without = _screenshot(browser, bare / "report.html", tmp_path / "bare.png")
    assert shot.shape == without.shape
    changed = np.mean(np.abs(shot - without) > 30)
    assert changed > 0.05


def test_compare_page_links_every_runs_figures(run_folder: Path, tmp_path: Path) -> None:
    browser = _browser()
    other = run_folder.parent / "ekf-slam-seed1"
    if not other.exists():
        run_job(RunRequest("ekf-slam", "five-features", other, seed=1))
    page = compare_job([run_folder, other], tmp_path / "cmp")
    rows = _image_probe(browser, page)
    assert len(rows) == 2 * len(list(run_folder.glob("*.png")))
    assert all(r[1] is True and int(str(r[2])) > 100 for r in rows)
    shot = _screenshot(browser, page, tmp_path / "cmp.png")
    assert shot.std() > 20.0


def test_the_layouts_key_elements_are_shown(run_folder: Path, tmp_path: Path) -> None:
    """The verdict line near the top, the metric groups with their units and explanations,
    and a caption in words under each figure, all shown; the screenshot has text where
    the browser put the verdict."""
    from slamkit.eval.glossary import GROUPS
    from slamkit.report import FIGURE_CAPTIONS

    browser = _browser()
    page = run_folder / "report.html"
    layout = _probe(browser, page, LAYOUT_PROBE, "layout-probe")
    assert isinstance(layout, dict)
    metrics = json.loads((run_folder / "metrics.json").read_text())
    (verdict,) = layout["verdict"]
    assert verdict["shown"] and verdict["text"] == "Verdict: " + metrics["verdict"]["line"]
    assert verdict["y"] < 1800 and verdict["y"] < min(f["y"] for f in layout["figures"])
    titles = [g["text"] for g in layout["groups"]]
    # ekf-slam on five-features: truth, NEES/NIS, its own counts, the run
    assert titles == list(GROUPS) and all(g["shown"] for g in layout["groups"])
    units = {u["text"] for u in layout["unit_cells"]}
    assert {"m", "deg", "%", "s"} <= units
    assert all(u["shown"] for u in layout["units"]) and any(u["text"] for u in layout["units"])
    captions = layout["captions"]
    assert len(captions) == len(layout["figures"]) == len(list(run_folder.glob("*.png")))
    for cap in captions:
        name = cap["text"].split(" ", 1)[0]
        assert cap["shown"] and FIGURE_CAPTIONS[name] in cap["text"]
    # The screenshot: ink where the verdict is (text on white).
    shot = _screenshot(browser, page, tmp_path / "page.png")
    x, y, w, h = (round(float(verdict[k])) for k in ("x", "y", "w", "h"))
    line = shot[y : y + h, x : x + w]
    assert line.size and line.min() < 128 and line.std() > 20.0
