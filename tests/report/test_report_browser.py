"""The report page in a real headless browser: the screenshot is not blank and the images load.

Needs Chromium from the distribution's packages (``apt-get install chromium``; ``.ci/run``
installs it in CI); skips with the reason elsewhere.
"""

from __future__ import annotations

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


def _image_probe(browser: str, page: Path) -> list[list[object]]:
    probe = page.with_name(".probe-" + page.name)
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", PROBE + "</body>"))
    try:
        done = _chromium(browser, "--dump-dom", probe.as_uri())
    finally:
        probe.unlink()
    match = re.search(r'<pre id="img-probe">(.*?)</pre>', done.stdout, re.S)
    assert match, f"the probe did not run: {done.stderr[-500:]}"
    rows: list[list[object]] = json.loads(match.group(1).replace("&quot;", '"'))
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
