"""`scripts/prior_figures.py --stats` runs on a small scene and prints every row it promises."""
import subprocess
import sys

from paths import REPO_ROOT

ROOT = REPO_ROOT


def test_stats_prints_every_ordering_and_rule(tiny_scene):
    out = subprocess.run([sys.executable, str(ROOT / "scripts" / "prior_figures.py"), "--stats", "--scene",
                          str(tiny_scene), "--seeds", "0"], capture_output=True, text=True, timeout=600)
    assert out.returncode == 0, out.stderr
    rows = [line.split() for line in out.stdout.splitlines() if line.startswith("0 ")]
    assert len(rows) == 7                                  # per-frame + 2 rules x 3 orderings
    assert sum("unmatched" in r for r in rows) == 3 and sum("per-frame" in r for r in rows) == 1
    assert "differ between pose and random" in out.stdout
    for r in rows:                                         # after the IoU column: target pixel acc, target mIoU
        k = next(i for i, t in enumerate(r) if "/" in t)
        assert 0.0 <= float(r[k + 1]) <= 1.0 and 0.0 <= float(r[k + 2]) <= 1.0
