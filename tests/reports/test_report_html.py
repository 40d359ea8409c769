"""The report's index.html renders in headless Chromium (Debian package `chromium`): a screenshot
is taken and must be a valid, non-blank PNG, and the pictures section's images must load. Skips with
the reason when Chromium is not installed."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from previews_fake import MAGENTA, fake_previews
from report_runs import make_main, write_run

from gsbench.reports import build_report

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium not installed (Debian package `chromium`; .ci/run installs it)")


def _screenshot(page: Path, tmp_path: Path, size: tuple[int, int]) -> Path:
    shot = tmp_path / "shot.png"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage",
           f"--user-data-dir={tmp_path / 'chrome-profile'}", f"--screenshot={shot}",
           f"--window-size={size[0]},{size[1]}", page.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0 and shot.exists(), proc.stderr[-2000:]
    return shot


@pytest.mark.chromium
@needs_chromium
def test_index_html_renders_in_headless_chromium(tmp_path: Path):
    make_main(tmp_path / "runs")
    summary = build_report(tmp_path / "runs", tmp_path / "report")
    shot = _screenshot(summary.index, tmp_path, (1280, 2000))
    assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with Image.open(shot) as im:
        assert im.size == (1280, 2000)
        gray = np.asarray(im.convert("L"), dtype=np.float64)
    # not blank: text, table borders and the embedded plots make the page far from uniform
    assert gray.std() > 20.0
    assert (gray < 128).mean() > 0.01  # dark pixels (text, plot lines) cover more than 1 % of the page
    # the first plot is loaded (an unloaded <img> would leave the figure area white): colourful bars
    rgb = np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16)
    saturated = (rgb.max(axis=2) - rgb.min(axis=2)) > 80
    assert saturated.mean() > 0.005


@pytest.mark.chromium
@needs_chromium
def test_pictures_section_renders_in_headless_chromium(tmp_path: Path):
    """The page with only its pictures section: the render tiles (pure magenta in the saved previews,
    a colour nothing else on the page has) must be loaded and visible."""
    runs = tmp_path / "runs"
    fake_previews(write_run(runs, "gds", method="gaussiands", scene="bench", metrics={"psnr": 20.0}), "gaussiands")
    summary = build_report(runs, tmp_path / "report")
    page = summary.index.read_text()
    section = re.search(r'<section id="pictures">.*?</section>', page, re.S)
    assert section is not None
    only = tmp_path / "report" / "pictures_only.html"
    only.write_text(page[:page.index("<body>") + 6] + section.group(0) + page[page.index("</body>"):])
    shot = _screenshot(only, tmp_path, (1280, 1200))
    rgb = np.asarray(Image.open(shot).convert("RGB"), dtype=np.int16)
    magenta = (np.abs(rgb - np.array(MAGENTA)).max(axis=2) < 8)
    # render tile + removal "before" tile, each at least 88 x 66 CSS px
    assert magenta.sum() > 2 * 88 * 66 * 0.9
