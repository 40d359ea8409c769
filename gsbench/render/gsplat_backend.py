"""The `gsplat` render backend: CUDA rasterization through `gsplat.rasterization` (extra `cuda`).

Mapping of our field and camera to gsplat's arguments (one call renders everything):
- means, scales = field.scales (our bounded exp), quats = our normalised quaternions (zero ->
  identity; gsplat's own renormalisation is then a no-op), opacities = field.opacity;
- colors = [field.rgb(camera centre) | field.features] as post-activation channels with
  sh_degree=None: SH are evaluated by gsbench (3DGS basis, + 0.5, clamped at 0: the same as
  gsplat's own SH path), so every backend composites identical per-Gaussian colours, and the
  features ride along as extra colour channels (any width; gsplat chunks by 32 channels);
- render_mode="RGB+D": gsplat's "D" is the accumulated depth sum_i w_i z_i, which is our depth
  (paper Eq. 4, not divided by alpha). "ED" would divide by alpha and is NOT used;
- viewmats = camera.world_to_camera (OpenCV, world -> camera), Ks = camera.K, pinhole model;
- near_plane=NEAR_PLANE, far_plane=FAR_PLANE, eps2d=EPS2D (0.3), tile_size=16, packed=False,
  rasterize_mode="classic" (no anti-aliasing compensation), radius_clip=0, backgrounds=None:
  the background is added to rgb only, here, as rgb + (1 - alpha) * background.
- Outputs: rgb = channels[:3], features = channels[3:-1], depth = channels[-1], alpha =
  render_alphas. `means2d` is gsplat's projected means (its `.grad` is filled after backward via
  a hook, for densification); `radii` is gsplat's per-axis radii (0 = culled).
info["n_visible"] is a 0-dim device tensor here (int() it when needed): reading it would synchronise
with the GPU, and training renders every step without a host synchronisation.
gsplat computes in float32; a float64 field is cast (gradients flow back through the cast) and the
outputs are cast back. gsplat's screen extent and tile tests are its own; they only differ from
the shared rules where alpha < 1/255, so results match the `torch` backend to float32 rounding
(tests/render/test_render_gsplat.py, run where CUDA exists).
"""
from __future__ import annotations

from typing import Optional

import torch

from gsbench.camera import Camera
from gsbench.errors import InputError
from gsbench.gaussians import GaussianField
from gsbench.render import RenderOutput, rules  # gsbench.render imports this module only when rendering

RENDER_MODE = "RGB+D"


def _import_gsplat():
    try:
        import gsplat  # noqa: PLC0415 (optional, CUDA only)
    except ImportError as e:
        raise InputError("render backend 'gsplat' needs the optional extra `cuda` "
                         f"(pip install 'gsbench[cuda]'): cannot import gsplat ({e}); "
                         "use backend='cpu' or 'auto' on machines without CUDA") from e
    return gsplat


def gsplat_arguments(field: GaussianField, camera: Camera) -> dict:
    """Keyword arguments of gsplat.rasterization for one camera (device of the field, float32)."""
    device = field.means.device
    f32 = torch.float32
    K, w2c, _ = camera.device_tensors(device, f32)
    cam_center = camera.device_tensors(device, field.means.dtype)[2]
    colors = field.rgb(cam_center)
    if field.features is not None:
        colors = torch.cat([colors, field.features], dim=1)
    return dict(
        means=field.means.to(f32),
        quats=field.rotations.to(f32),
        scales=field.scales.to(f32),
        opacities=field.opacity.to(f32),
        colors=colors.to(f32),
        viewmats=w2c[None],
        Ks=K[None],
        width=camera.width,
        height=camera.height,
        near_plane=rules.NEAR_PLANE,
        far_plane=rules.FAR_PLANE,
        radius_clip=0.0,
        eps2d=rules.EPS2D,
        sh_degree=None,
        packed=False,
        tile_size=rules.TILE_SIZE,
        backgrounds=None,
        render_mode=RENDER_MODE,
        rasterize_mode="classic",
    )


def split_outputs(render_colors: torch.Tensor, render_alphas: torch.Tensor, n_features: int,
                  background: Optional[torch.Tensor], dtype: torch.dtype):
    """gsplat's (1,H,W,3+d+1) colours and (1,H,W,1) alphas -> rgb (+ background), depth, features, alpha."""
    out = render_colors[0].to(dtype)
    alpha = render_alphas[0, ..., 0].to(dtype)
    rgb = out[..., :3]
    if background is not None:
        bg = torch.as_tensor(background, device=out.device, dtype=dtype).reshape(1, 1, 3)
        rgb = rgb + (1.0 - alpha)[..., None] * bg
    feats = out[..., 3:3 + n_features] if n_features > 0 else None
    return rgb, out[..., -1], feats, alpha


def _means2d_with_grad(m2d: torch.Tensor) -> torch.Tensor:
    """(N,2) view of gsplat's (1,N,2) projected means whose .grad is set in backward."""
    view = m2d.detach()[0]
    if m2d.requires_grad:
        def _hook(g: torch.Tensor) -> None:
            view.grad = g[0].detach().clone() if view.grad is None else view.grad + g[0].detach()
        m2d.register_hook(_hook)
    return view


def render_gsplat(field: GaussianField, camera: Camera, background: Optional[torch.Tensor] = None):
    """Render with gsplat.rasterization; same outputs as the other backends (see module doc)."""

    gsplat = _import_gsplat()
    if not torch.cuda.is_available():
        raise InputError("render backend 'gsplat' needs a CUDA device and none is available; "
                         "use backend='cpu' or 'auto'")
    if field.means.device.type != "cuda":
        raise InputError(f"render backend 'gsplat' needs the Gaussian field on CUDA, it is on "
                         f"{field.means.device}; move it with field.to('cuda') or use backend='cpu'")
    args = gsplat_arguments(field, camera)
    render_colors, render_alphas, meta = gsplat.rasterization(**args)
    n_feat = 0 if field.features is None else int(field.features.shape[1])
    rgb, depth, feats, alpha = split_outputs(render_colors, render_alphas, n_feat, background, field.means.dtype)
    radii = meta["radii"][0]
    if radii.dim() == 1:                      # older gsplat: one isotropic radius per Gaussian
        radii = radii[:, None].expand(-1, 2)
    radii = radii.to(torch.int64)
    return RenderOutput(rgb=rgb, depth=depth, features=feats, alpha=alpha, backend="gsplat",
                        means2d=_means2d_with_grad(meta["means2d"]), radii=radii,
                        info={"n_gaussians": field.num, "n_visible": (radii > 0).all(-1).sum(),
                              "width": camera.width, "height": camera.height,
                              "dtype": str(field.means.dtype).replace("torch.", ""),
                              "device": str(field.means.device),
                              "gsplat_version": getattr(gsplat, "__version__", "unknown"),
                              "gsplat_render_mode": RENDER_MODE})
