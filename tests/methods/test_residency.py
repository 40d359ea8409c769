"""train.data_on: per-view training data on the device, or on the host with one view copied per read."""
from __future__ import annotations

import json

import pytest
import torch

from gsbench.cli import main
from gsbench.train.residency import HostViews, place


def test_host_views_keep_host_copies_and_hand_out_device_tensors():
    # 'meta' stands in for a second device on this CPU-only machine: a read must produce a tensor there
    img = torch.arange(12, dtype=torch.float32).reshape(2, 2, 3)
    held = place({7: img, 9: (img[..., 0], img[..., 0] > 3, "disparity")}, "meta", "host")
    assert isinstance(held, HostViews) and sorted(held) == [7, 9] and len(held) == 2
    assert held.host_item(7).device.type == "cpu" and torch.equal(held.host_item(7), img)
    got = held[7]
    assert got.device.type == "meta" and got.shape == (2, 2, 3)
    vals, ok, kind = held[9]
    assert vals.device.type == "meta" and ok.device.type == "meta" and ok.dtype == torch.bool and kind == "disparity"
    assert all(v.device.type == "meta" for v in held.values() if torch.is_tensor(v))


def test_device_placement_moves_everything_once():
    img = torch.ones(2, 2, 3)
    on_dev = place({1: img, 2: (img, "depth")}, "meta", "device")
    assert isinstance(on_dev, dict)
    assert on_dev[1].device.type == "meta" and on_dev[2][0].device.type == "meta" and on_dev[2][1] == "depth"


def test_an_unknown_place_is_refused():
    with pytest.raises(ValueError, match="train.data_on"):
        place({}, "cpu", "disk")


@pytest.mark.parametrize("method", ["gaussiands", "twostage"])
def test_host_data_trains_the_same_run_as_device_data(method, tiny_scene, tmp_path):
    """On the CPU both places hold the same tensors, so the two runs must log the same losses: the host
    path reaches every per-view input the method reads (images, depth prior, edges, semantic targets)."""
    from tiny import TINY_TRAIN_ARGS
    args = [a if a != "vanilla" else method for a in TINY_TRAIN_ARGS]
    logs = {}
    for on in ("device", "host"):
        run = tmp_path / on
        # 10 steps logged every 5 (each logged loss reads every input) and a 10-epoch autoencoder, not 500
        assert main(["train", *args, "--scene", str(tiny_scene), "--out", str(run),
                     "--set", "train.iterations=10", "train.log_every=5", "semantic.autoencoder.epochs=10",
                     f"train.data_on={on}"]) == 0
        rows = [json.loads(x) for x in (run / "train_log.jsonl").read_text().splitlines()]
        logs[on] = [{k: v for k, v in r.items() if k not in ("wall_s", "time", "elapsed_s")} for r in rows
                    if "loss" in r]
    assert logs["device"] and logs["device"] == logs["host"]
