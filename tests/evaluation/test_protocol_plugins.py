"""A new evaluation protocol and a new scene layout are one file each (issue 53 item 1).

The test writes a plugin outside gsbench: `zz_protocol.py` (a protocol with two forks) and `zz_layout.py`
(a reader plus its detection), registered by the entry points of a `zzplugin` distribution (its metadata
only: no code). In a fresh interpreter with the plugin on the path, the layout is detected, read and
checked by `gsbench data check`'s code, and the protocol is resolved for the scene, scored under the fork
asked for, and its numbers are accepted by the results schema. It counts the files that name the new
protocol or layout: one each in the plugin, none in gsbench.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

from paths import REPO_ROOT

PROTOCOL_FILE = '''
from gsbench.evaluation.block import Block
from gsbench.evaluation.protocol_registry import Protocol


class TrainedShare(Protocol):
    """The share of the scene's views a run trains on (all views under the fork zz-count-all)."""

    name = "zz-count"
    metric_key = "zzcount"
    metrics = ("share",)
    forks = ("zz-count-trained", "zz-count-all")

    def supports(self, scene):
        return None if scene.layout == "zzlayout" else "not a zzlayout scene"

    def score(self, ctx):
        out = Block()
        n = len(ctx.scene.cameras)
        share = 1.0 if ctx.fork == "zz-count-all" else len(ctx.scene.train_ids) / n
        for mode in ctx.modes:
            for name in ctx.names("share", mode):
                out.put(name, share, "zz-count/v1" + ctx.fork_tag())
        return out


PROTOCOL = TrainedShare()
'''

LAYOUT_FILE = '''
import json

import numpy as np

from gsbench.camera import Camera
from gsbench.datasets.base import Scene
from gsbench.datasets.layout_registry import Layout


def detect(root):
    return (root / "zz_scene.json").is_file()


def read(root):
    views = json.loads((root / "zz_scene.json").read_text())["views"]
    K = np.array([[10.0, 0.0, 4.0], [0.0, 10.0, 3.0], [0.0, 0.0, 1.0]])
    cams = [Camera(K=K, world_to_camera=np.eye(4), width=8, height=6, name=f"v{i}") for i in range(views)]
    return Scene(name=root.name, path=str(root), layout="zzlayout", cameras=cams, train_ids=list(range(1, views)),
                 test_ids=[0], image_paths=[])


LAYOUT = Layout("zzlayout", detect=detect, read=read, priority=5)
'''

ENTRY_POINTS = """
[gsbench.protocols]
zz = zz_protocol:PROTOCOL

[gsbench.layouts]
zz = zz_layout:LAYOUT
"""

RUN = '''
import json, sys
from pathlib import Path
from gsbench.datasets import layout_names, load_scene
from gsbench.datasets.check import check_folder
from gsbench.evaluation.protocol_registry import fork_names, protocol_names
from gsbench.evaluation.segmentation import requested_forks, resolve_protocols, segmentation
from gsbench.results import run_results

root = Path(sys.argv[1])
scene = load_scene(root)                                   # layout detected
report = check_folder(root)
protocols, skipped = resolve_protocols(scene, "auto")
forks = requested_forks("zz-count-all", protocols)
sets = {p: {"reference": [], "held-out": []} for p in protocols}
config = {"query": {"mode": "encode"}}
default = segmentation(None, scene, protocols, sets, config, modes=("encode",))
forked = segmentation(None, scene, protocols, sets, config, modes=("encode",), forks=forks)
res = run_results(identity={"protocols": protocols}, metrics=forked.metrics, metric_impl=forked.metric_impl,
                  skipped={}, per_view={}, view_names=[], frames={}, frames_skipped={}, resolution={}, notes={},
                  timings={}, memory={}, machine={}, forks=forks)
print(json.dumps({"layouts": list(layout_names()), "protocols": protocol_names(), "forks": fork_names(),
                  "scene_layout": scene.layout, "check_layout": report.layout, "check_ok": report.ok,
                  "resolved": protocols, "default": default.metrics, "forked": forked.metrics,
                  "impl": forked.metric_impl, "recorded": res["forks"]}))
'''


def _write_plugin(site: Path) -> list[Path]:
    """The plugin: two code files and the distribution's metadata; returns the files written."""
    dist = site / "zzplugin-0.1.dist-info"
    dist.mkdir(parents=True)
    files = {site / "zz_protocol.py": PROTOCOL_FILE, site / "zz_layout.py": LAYOUT_FILE,
             dist / "METADATA": "Metadata-Version: 2.1\nName: zzplugin\nVersion: 0.1\n",
             dist / "entry_points.txt": ENTRY_POINTS}
    for f, text in files.items():
        f.write_text(textwrap.dedent(text).lstrip())
    return list(files)


def _naming(files, word: str) -> list[Path]:
    return [f for f in files if word in f.read_text(errors="replace")]


def test_a_protocol_and_a_layout_are_one_file_each(tmp_path):
    site = tmp_path / "site"
    written = _write_plugin(site)
    scene = tmp_path / "scene"
    scene.mkdir()
    (scene / "zz_scene.json").write_text(json.dumps({"views": 3}))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", RUN, str(scene)], cwd=tmp_path, env=env, capture_output=True,
                         text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    # picked up: the layout is detected, read and checked; the protocol is a registered choice with its forks
    assert "zzlayout" in got["layouts"] and "zz-count" in got["protocols"]
    assert got["forks"]["zz-count-all"] == got["forks"]["zz-count-trained"] == "zz-count"
    assert got["scene_layout"] == got["check_layout"] == "zzlayout" and got["check_ok"]
    assert got["resolved"] == ["zz-count"]                    # the built-in protocols do not support it
    # 3 views, view 0 held out: 2/3 under the default fork, 1 under zz-count-all; the plain name carries
    # the configured mode, and the schema accepts both names
    assert got["default"] == {"share_zzcount_encode": 2 / 3, "share_zzcount": 2 / 3}
    assert got["forked"] == {"share_zzcount_encode": 1.0, "share_zzcount": 1.0}
    assert got["impl"]["share_zzcount"] == "zz-count/v1+fork-zz-count-all"
    assert got["recorded"] == {"zz-count": "zz-count-all"}
    # the files touched: one code file names the protocol, one the layout; the rest is packaging metadata
    code = [f for f in written if f.suffix == ".py"]
    assert _naming(code, "class TrainedShare(Protocol)") == [site / "zz_protocol.py"]
    assert _naming(code, "Layout(") == [site / "zz_layout.py"]
    assert len(code) == 2
    sources = [f for d in ("gsbench", "methods", "datasets", "metrics", "reports")
               for f in (REPO_ROOT / d).rglob("*.py")]
    assert not _naming(sources, "zz-count") and not _naming(sources, "zzlayout")   # nothing in gsbench changed
