"""The protocol forks (issue 53 item 2) on hand-made score maps; every expected value is worked by hand in
the comments. One 1 x 8 view, classes A and B:

    rA = [1.00, 0.93, 0.87, 0.77, 0.22, 0.12, 0.00, 0.00]     GT A = columns 0-2
    rB = [0.00, 0.00, 0.12, 0.62, 0.66, 1.00, 0.00, 0.00]     GT B = columns 3-5 (6, 7 unlabelled)

A one-row map keeps LangSplat's 3 x 3 majority vote from changing anything (its window is empty: the
vote leaves the pixel as it is), and 8 px wide labels scale the blend box to 1 px (round(30 x 8 / 985) = 0,
at least 1), so the threshold fork is min-max normalisation and x > 0.7 alone.
"""
from __future__ import annotations

import numpy as np
import pytest

from gsbench.errors import InputError
from gsbench.evaluation.ovs3d_protocol import fork_masks
from gsbench.evaluation.protocol_registry import fork_of, get_protocol, parse_request
from gsbench.metrics import lerf, ovs3d

RA = [1.00, 0.93, 0.87, 0.77, 0.22, 0.12, 0.00, 0.00]
RB = [0.00, 0.00, 0.12, 0.62, 0.66, 1.00, 0.00, 0.00]
CLASSES = ["A", "B"]
GT = {"A": np.array([[1, 1, 1, 0, 0, 0, 0, 0]], bool), "B": np.array([[0, 0, 0, 1, 1, 1, 0, 0]], bool)}
CONFIG = {"eval": {"lerf_kernels": "auto"}}


def _relevancy() -> np.ndarray:
    return np.array([[RA], [RB]], np.float64)          # (C=2, H=1, W=8)


def test_the_defaults_are_the_reference_forks():
    """Today's protocols are the reference implementations: 3D-OVS's closed-set argmax, LangSplat's LERF."""
    assert get_protocol("3dovs").default_fork == "3dovs-closed-set"
    assert get_protocol("lerf").default_fork == "lerf-langsplat"
    assert parse_request("3dovs") == {"3dovs": "3dovs-closed-set"}
    assert parse_request("3dovs-threshold,lerf-original") == {"3dovs": "3dovs-threshold", "lerf": "lerf-original"}
    assert parse_request("auto") == {}
    with pytest.raises(InputError, match="unknown protocol or fork '3dovs-median'"):
        parse_request("3dovs-median")
    with pytest.raises(InputError, match="two forks of protocol 3dovs"):
        parse_request("3dovs-threshold,3dovs-dynamic-threshold")


def test_results_without_forks_read_as_the_default_fork():
    assert fork_of({"protocols": ["3dovs", "lerf"]}, "3dovs") == "3dovs-closed-set"
    assert fork_of({"forks": {"lerf": "lerf-original"}}, "lerf") == "lerf-original"
    assert fork_of({"forks": {"lerf": "lerf-original"}}, "3dovs") == "3dovs-closed-set"


def test_closed_set_fork():
    """One class per pixel, the argmax over the classes (given here as the class map it gives): A at
    columns 0-2, B at 3-7 (B wins the unlabelled 6 and 7 too: the closed set has no background).
    IoU A = 3/3 = 1; IoU B = |{3,4,5}| / |{3..7}| = 3/5; mIoU = (1 + 0.6) / 2 = 0.8.
    Pixel accuracy (reference rule): columns 0-5 right, 6 and 7 unlabelled but predicted B: 6/8 = 0.75."""
    labels = np.array([[0, 0, 0, 1, 1, 1, 1, 1]], np.int32)
    r = ovs3d.evaluate_ovs3d_scene([ovs3d.Ovs3dView("v", labels, GT)], CLASSES)
    assert r.miou == pytest.approx(0.8)
    assert r.pixel_acc == pytest.approx(0.75)


def test_threshold_fork():
    """x = r / (1 + 1e-9); x > 0.7: A at 0-3 (0.77 passes), B at 5 only (0.66 does not).
    IoU A = 3 / 4 = 0.75; IoU B = 1 / 3; mIoU = (0.75 + 1/3) / 2 = 13/24. No pixel accuracy."""
    masks = fork_masks(_relevancy(), "3dovs-threshold", 8, CONFIG)
    assert masks[0, 0].tolist() == [True, True, True, True, False, False, False, False]
    assert masks[1, 0].tolist() == [False, False, False, False, False, True, False, False]
    r = ovs3d.evaluate_ovs3d_masks([ovs3d.Ovs3dView("v", masks, GT)], CLASSES, impl="t")
    assert r.miou == pytest.approx(13 / 24)
    assert r.pixel_acc is None and r.pixel_acc_labelled is None


def test_dynamic_threshold_picks_the_most_stable_threshold():
    """Counts of x > v for rA: 6 for 0 <= v < 0.12, 5 below 0.22, 4 below 0.77, 3 below 0.87, 2 below 0.93,
    1 below 1. Stability s(t) = count(> t + 0.05) / count(> t - 0.05): 1 at t = 0.7 (4 / 4), and below 1
    at every larger t (0.75: 3/4, 0.8: 3/4, 0.85: 2/3, 0.9: 1/3, 0.95: 0/2), so t = 0.7 (the largest of
    the stability-1 thresholds) and A's mask is columns 0-3.
    rB: counts 4 below 0.12, 3 below 0.62, 2 below 0.66, 1 below 1. s = 1 again from t = 0.75 to 0.9
    (1 / 1; area 1/8 inside [0.005, 0.9]) and 0 at 0.95 (0 / 1): t = 0.9, B's mask is column 5.
    IoU A = 3/4, IoU B = 1/3: mIoU 13/24 (the same masks as the fixed threshold, reached another way)."""
    assert ovs3d.dynamic_threshold(np.array([RA])) == pytest.approx(0.7)
    assert ovs3d.dynamic_threshold(np.array([RB])) == pytest.approx(0.9)
    masks = fork_masks(_relevancy(), "3dovs-dynamic-threshold", 8, CONFIG)
    assert np.flatnonzero(masks[0, 0]).tolist() == [0, 1, 2, 3]
    assert np.flatnonzero(masks[1, 0]).tolist() == [5]
    r = ovs3d.evaluate_ovs3d_masks([ovs3d.Ovs3dView("v", masks, GT)], CLASSES, impl="d")
    assert r.miou == pytest.approx(13 / 24)


def test_dynamic_threshold_mask_size_rule():
    """Too small: one pixel at 1.0 and three at 0.5 among 400. x = r / (1 + 1e-9), so 0.5 is just below 0.5.
    count(> v) = 4 for 0 <= v < 0.5 (share 0.01) and 1 above (share 0.0025 < 0.005: refused). s = 1 from
    t = 0.05 to 0.4 (4 / 4); at 0.45, s = count(> 0.5) / count(> 0.4) = 1 / 4 (refused): t = 0.4, four
    pixels. Too large: 19 of 20 pixels at 1.0: every mask covers 0.95 > 0.9 of the image: no threshold,
    an empty mask."""
    small = np.zeros((1, 400))
    small[0, 10] = 1.0
    small[0, [20, 30, 40]] = 0.5
    assert ovs3d.dynamic_threshold(small) == pytest.approx(0.4)
    assert np.flatnonzero(ovs3d.dynamic_threshold_mask(small)).tolist() == [10, 20, 30, 40]
    large = np.ones((1, 20))
    large[0, 0] = 0.0
    assert ovs3d.dynamic_threshold(large) is None
    assert not ovs3d.dynamic_threshold_mask(large).any()


def _spike_and_plateau() -> np.ndarray:
    """5 x 5: a spike of 1.0 at (row 0, column 0) and a 3 x 3 plateau of 0.8 at rows/columns 2-4."""
    r = np.zeros((5, 5))
    r[0, 0] = 1.0
    r[2:, 2:] = 0.8
    return r


def test_lerf_localisation_forks():
    """The raw maximum is the spike (0, 0). The 3 x 3 box mean (reflected border) is 0.8 at (3, 3), (3, 4),
    (4, 3) and (4, 4), whose windows lie in the plateau (reflected), and 1/9 at the spike. So a box over the
    plateau [2, 2, 4, 4] is a LangSplat hit and an original-LERF miss, and a box over the spike [0, 0, 1, 1]
    the other way round: loc. acc. 1/2 under both forks, from different pairs."""
    r = _spike_and_plateau()
    mask = np.zeros((5, 5), bool)
    pairs = [lerf.LerfPair("f", "plateau", r, mask, np.array([[2, 2, 4, 4]])),
             lerf.LerfPair("f", "spike", r, mask, np.array([[0, 0, 1, 1]]))]
    k = lerf.LerfKernels(blend=3, radius=1)
    lang = lerf.evaluate_lerf_scene(pairs, kernels=k, localization="langsplat")
    orig = lerf.evaluate_lerf_scene(pairs, kernels=k, localization="original")
    assert [p["localized"] for p in lang.per_pair] == [True, False]
    assert [p["localized"] for p in orig.per_pair] == [False, True]
    assert lang.loc_acc == orig.loc_acc == pytest.approx(0.5)
    assert lang.miou == orig.miou                  # the fork changes the localisation only
    assert lerf.lerf_localization_original(r, [[0, 0, 0, 0]]) is True
    with pytest.raises(InputError, match="localization must be one of"):
        lerf.evaluate_lerf_scene(pairs, kernels=k, localization="median")


def test_the_registry_refuses_a_taken_name_and_a_protocol_without_metrics():
    """`register` (the hook beside the entry points) checks names before anything is entered in the tables."""
    from gsbench.evaluation.protocol_registry import Protocol, protocol_names, register

    class Clash(Protocol):
        name = "clash"
        metrics = ("miou",)
        forks = ("clash-a", "3dovs-threshold")       # a fork name 3dovs already has

    class Empty(Protocol):
        name = "empty"

    with pytest.raises(InputError, match="'3dovs-threshold' is already taken by protocol '3dovs'"):
        register(Clash())
    with pytest.raises(InputError, match="declares no metric names"):
        register(Empty())
    assert "clash" not in protocol_names() and "empty" not in protocol_names()
