"""The report's index.html renders in headless Chromium (Debian package `chromium`): a screenshot
is taken and must be a valid, non-blank PNG. Skips with the reason when Chromium is not installed."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gsbench.reports import build_report
from tests.test_report_synthetic import make_main

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


@pytest.mark.chromium
@pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium not installed (Debian package `chromium`; .ci/run installs it)"
)
def test_index_html_renders_in_headless_chromium(tmp_path: Path):
    make_main(tmp_path / "runs")
    summary = build_report(tmp_path / "runs", tmp_path / "report")
    shot = tmp_path / "shot.png"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
           "--disable-component-update", "--disable-sync", "--no-first-run", "--disable-dev-shm-usage",
           f"--user-data-dir={tmp_path / 'chrome-profile'}", f"--screenshot={shot}", "--window-size=1280,2000",
           summary.index.resolve().as_uri()]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0 and shot.exists(), proc.stderr[-2000:]
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
