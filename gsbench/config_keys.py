"""What each key of default.yaml accepts, beyond the type its default has.

A key's type comes from gsbench/configs/default.yaml (a bool default takes only true/false, a
number default only numbers, ...). This table adds ranges and choices, and the type of keys whose
default is null. A key of default.yaml without a rule here is type-checked only. A method's own
section is not here: its spec declares its defaults and rules (gsbench.method_table.MethodSpec). The choice lists
are declared here, once, and the modules that consume them import them from here (priors, render,
evaluation, datasets): reading a config must import no method, renderer or model library (this
module is on the ground floor, docs/architecture.md), and those packages load cv2 and the model
code on import (about a second), so the declaration cannot live in them. The method names are read
live from gsbench.method_table.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Optional

from gsbench.method_table import METHODS  # live: the registered method names (ground floor, imports no method)


@dataclass(frozen=True)
class Rule:
    """Range [low, high] (low excluded when low_open), choices, and the type of a null default."""

    low: Optional[float] = None
    high: Optional[float] = None
    low_open: bool = False
    choices: Optional[tuple] = None
    kind: Optional[str] = None        # int | float | str | list: for keys whose default is null
    nullable: bool = False            # null is a valid value (keys with a null default always are)
    integer: bool = False             # a number that must be whole (an int default implies it)
    length: Optional[tuple[int, int]] = None   # a list: its fewest and most elements
    item: Optional["Rule"] = None     # a list: the rule of every element (its `kind` and range or choices)

    def describe(self) -> str:
        """The allowed values in words, for error messages and the docs."""
        if self.length is not None:
            low, high = self.length
            count = str(low) if low == high else f"{low} to {high}"
            item = self.item or Rule()
            each = "" if item.describe() == "any value" else f", each {item.describe()}"
            return f"a list of {count} {_PLURALS.get(item.kind or '', 'values')}{each}"
        if self.choices is not None:
            return "one of " + ", ".join("null" if c is None else str(c) for c in self.choices)
        lo = "" if self.low is None else (f"> {self.low:g}" if self.low_open else f">= {self.low:g}")
        if self.low is not None and self.high is not None and not self.low_open:
            return f"in [{self.low:g}, {self.high:g}]"
        hi = "" if self.high is None else f"<= {self.high:g}"
        return " and ".join(x for x in (lo, hi) if x) or "any value"

    def admits(self, value: Any) -> bool:
        """True when `value` (already of the right type) is inside the rule."""
        if value is None:
            return True
        if self.length is not None and isinstance(value, list):
            return self.length[0] <= len(value) <= self.length[1]   # the elements: by `item`, one by one
        if self.choices is not None:
            return value in self.choices
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            v = float(value)
            if not math.isfinite(v):
                return False
            if self.low is not None and (v <= self.low if self.low_open else v < self.low):
                return False
            if self.high is not None and v > self.high:
                return False
        return True


def positive(**kw: Any) -> Rule:
    return Rule(low=0.0, low_open=True, **kw)


def at_least(x: float, **kw: Any) -> Rule:
    return Rule(low=x, **kw)


def unit(**kw: Any) -> Rule:
    """A probability or a mixing weight: [0, 1]."""
    return Rule(low=0.0, high=1.0, **kw)


def one_of(*choices: Any, **kw: Any) -> Rule:
    return Rule(choices=tuple(choices), **kw)


def list_of(item: Rule, shortest: int, longest: int) -> Rule:
    """A list of `shortest` to `longest` elements, each of `item.kind` and inside `item`."""
    return Rule(kind="list", length=(shortest, longest), item=item)


_PLURALS = {"float": "numbers", "int": "whole numbers", "str": "strings"}   # a list's elements, in words
BACKENDS = ("auto", "torch", "cpu", "gsplat")
DEPTH_PROVIDERS = ("gt", "sparse", "sfm", "depth-anything", "auto", "none")
MASK_PROVIDERS = ("simulated", "sam2", "gt")
FEATURE_PROVIDERS = ("text-aligned", "openclip")
PROPAGATORS = ("flow", "reproject")
NEW_OBJECT_RULES = ("uncarried", "unmatched")
ORDERINGS = ("pose", "random", "filename")
NOISE_TYPES = (None, "gaussian", "poisson", "motion_blur", "salt_pepper")
NOISE_SEVERITIES = (0, 1, 2, 3, 4, 5)
INIT_MODES = ("auto", "points", "random", "frustum")
QUERY_MODES = ("encode", "decode")
PROTOCOLS = ("auto", "lerf", "3dovs")
LPIPS_NETS = ("vgg", "alex")
HOLDOUTS = ("every-8", "none")
DATA_PLACES = ("device", "host")   # train.data_on: where per-view training data lives (gsbench/train/residency.py)
EVAL_RESOLUTIONS = ("reference", "train")
LERF_KERNEL_MODES = ("auto", "reference")

RULES: dict[str, Rule] = {
    "method": Rule(choices=METHODS),  # type: ignore[arg-type]
    "seed": at_least(0, integer=True),
    "backend": one_of(*BACKENDS),
    # training schedule
    "train.iterations": at_least(1),
    "train.holdout": one_of(*HOLDOUTS),
    "train.views": at_least(1, kind="int", integer=True),   # null = every view the hold-out leaves
    "train.max_width": at_least(1, kind="int", integer=True),
    "train.data_on": one_of(*DATA_PLACES),
    "train.sh_degree": Rule(low=0, high=3),
    "train.sh_increase_every": at_least(0),
    "train.lr.color_rest_factor": positive(),
    "train.lambda_dssim": unit(),
    "train.background": list_of(unit(kind="float"), 3, 3),   # RGB in [0, 1]
    "train.init.mode": one_of(*INIT_MODES),
    "train.init.num_random": at_least(1),
    "train.init.max_points": at_least(1, kind="int", integer=True),
    "train.init.random_scale": positive(),
    "train.lr.position_init": positive(),
    "train.lr.position_final": positive(),
    "train.lr.position_delay_mult": positive(),
    "train.lr.position_delay_steps": at_least(0),
    "train.lr.position_max_steps": at_least(1),
    "train.lr.color": positive(),
    "train.lr.opacity": positive(),
    "train.lr.scaling": positive(),
    "train.lr.rotation": positive(),
    "train.lr.semantic": positive(),
    "train.densify.from_iter": at_least(0),
    "train.densify.until_iter": at_least(0),
    "train.densify.interval": at_least(1),
    "train.densify.grad_threshold": positive(),
    "train.densify.percent_dense": positive(),
    "train.densify.opacity_reset_interval": at_least(1),
    "train.densify.prune_opacity": unit(),
    "train.densify.max_screen_size": at_least(0),
    "train.densify.max_gaussians": at_least(1),
    "train.eval_every": at_least(0),
    "train.eval_views": at_least(0),  # 0 = no periodic evaluation views,
    "train.checkpoint_every": at_least(0),  # 0 = no intermediate checkpoints
    "train.log_every": at_least(1),
    # priors
    "priors.cache_dir": Rule(kind="str"),
    "priors.ordering": one_of(*ORDERINGS),
    "priors.depth.provider": one_of(*DEPTH_PROVIDERS),
    "priors.depth.model_path": Rule(kind="str"),
    "priors.depth.noise.type": one_of(*NOISE_TYPES, kind="str"),
    "priors.depth.noise.severity": one_of(*NOISE_SEVERITIES),
    "priors.masks.provider": one_of(*MASK_PROVIDERS),
    "priors.masks.severity": at_least(0),
    **{f"priors.masks.failures.{k}": at_least(0, kind="float") for k in ("merge", "split", "miss", "leak", "texture")},
    "priors.depth.distortion": at_least(0),
    "priors.depth.working_size": Rule(low=16, high=4096, integer=True),  # px; the cap keeps the working image in memory
    "priors.masks.propagator": one_of(*PROPAGATORS),
    "priors.masks.checkpoint": Rule(kind="str"),
    "priors.masks.model_config": Rule(kind="str"),
    "priors.masks.min_iou": unit(),
    "priors.masks.new_objects": one_of(*NEW_OBJECT_RULES),
    "priors.masks.model_overrides": list_of(Rule(kind="str"), 0, 64),   # hydra overrides of the SAM2 config
    "priors.features.provider": one_of(*FEATURE_PROVIDERS),
    "priors.features.checkpoint": Rule(kind="str"),
    "priors.features.noise": at_least(0),
    "priors.features.context": unit(),
    # the shared semantic section (methods that learn latents; a method's own section: its spec's rules)
    "semantic.latent_dim": at_least(1),
    "semantic.autoencoder.hidden": list_of(Rule(low=1, high=8192, kind="int", integer=True), 0, 16),
    "semantic.autoencoder.epochs": at_least(0),
    "semantic.autoencoder.lr": positive(),
    # queries and evaluation
    "query.mode": one_of(*QUERY_MODES),
    "removal.threshold": Rule(low=-1.0, high=1.0),
    "eval.protocol": one_of(*PROTOCOLS),
    "eval.lpips_net": one_of(*LPIPS_NETS),
    "eval.resolution": one_of(*EVAL_RESOLUTIONS),
    "eval.ovs3d_downsample": at_least(1, kind="int", integer=True),   # null = the reference's rule
    "eval.lerf_kernels": one_of(*LERF_KERNEL_MODES),
    "eval.fps_warmup": at_least(0),
    "eval.fps_repeats": at_least(1),
    "eval.boundary_dilation_ratio": unit(),
    "eval.previews": at_least(0, integer=True),   # labelled frames per protocol saved as pictures (0 = none)
    "eval.preview_width": at_least(16, integer=True),
}

# Leaves whose value is a free-form mapping handed to a library as is (not split into keys).
FREE_MAPPINGS = ("priors.masks.generator",)
