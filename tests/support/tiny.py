"""The tiny settings the suite shares: the session scene and run (tests/conftest.py), and short
training overrides for tests that train their own runs."""
from __future__ import annotations

# tabletop-small at 32x24 with 8 views: 7 training views and 1 held-out view (LLFF hold-out of 8).
TINY_SCENE_ARGS = ["--preset", "tabletop-small", "--views", "8", "--resolution", "32x24", "--seed", "0"]
# A vanilla run of 2 iterations: a complete run folder in about a second.
TINY_TRAIN_ARGS = ["--method", "vanilla", "--preset", "cpu-small", "--set", "train.iterations=2",
                   "--set", "train.eval_every=0", "--no-progress"]

# `--set` overrides of a 20-step GaussianDS-capable run on the tiny scene (CPU backend, GT masks).
TINY_SET = ["backend=cpu", "train.iterations=20", "train.max_width=32", "train.eval_every=0", "train.log_every=5",
            "train.checkpoint_every=0", "train.eval_views=0", "train.densify.from_iter=5", "train.densify.interval=10",
            "train.densify.until_iter=15", "train.densify.max_gaussians=800", "semantic.autoencoder.epochs=10",
            "train.init.max_points=300", "priors.masks.provider=gt"]


def device_run_overrides(dev: str) -> list[str]:
    """The end-to-end run below on `dev`: cpu-small pins backend cpu, so the cuda run asks for auto (gsplat)."""
    backend = ["backend=auto"] if dev == "cuda" else []
    return [f"train.device={dev}", *backend, "train.iterations=300", "train.max_width=64"]
