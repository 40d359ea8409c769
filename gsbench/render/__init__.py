"""render(): one function, plain tensors out, several backends behind it.

    out = render(field, camera, backend="auto", background=None)
    out.rgb (H,W,3), out.depth (H,W), out.features (H,W,d) or None, out.alpha (H,W)
    out.info: n_gaussians, n_visible (survived culling), width, height, dtype, device

depth is camera-space z composited like colour (paper Eq. 4: sum_k T_k alpha_k z_k), not divided
by alpha. Background is added to rgb only: rgb + (1 - alpha) * background. Denormals are flushed
to zero on CPU once per process, by gsbench.startup() (not per call).

Backends:
  torch  - the reference (plain PyTorch, autograd, any device/dtype); gsbench/render/torch_backend.py
  cpu    - the fast CPU path (fused kernels, hand-written backward); gsbench/render/cpu_backend.py
  gsplat - CUDA through gsplat.rasterization (optional extra `cuda`)
  auto   - the device's backend: gsplat on CUDA tensors (torch, with a warning, where gsplat cannot
           render), cpu otherwise
Which backend renders on a device (`resolve_backend`, the one rule; the methods call it) is
gsbench/render/backend_choice.py. The numerical rules all backends share are in gsbench/render/rules.py.
"""
from __future__ import annotations

from dataclasses import dataclass
from dataclasses import field as dc_field
from typing import Callable, Optional

import torch

from gsbench.camera import Camera
from gsbench.gaussians import GaussianField
from gsbench.render.backend_choice import BACKENDS, resolve_backend
from gsbench.render.projection import Projected, project_gaussians
from gsbench.render.threads import select_numba_threading_layer
from gsbench.render.torch_backend import rasterize_torch

select_numba_threading_layer()    # before any numba kernel of the cpu backend runs (render/threads.py)


@dataclass
class RenderOutput:
    rgb: torch.Tensor                 # (H, W, 3)
    depth: torch.Tensor               # (H, W) camera-space z, alpha-composited
    features: Optional[torch.Tensor]  # (H, W, d) or None
    alpha: torch.Tensor               # (H, W) = 1 - final transmittance
    backend: str = ""
    means2d: Optional[torch.Tensor] = None   # (N, 2) screen positions; .grad after backward (densification)
    radii: Optional[torch.Tensor] = None     # (N, 2) int screen half-extent, 0 where culled
    info: dict = dc_field(default_factory=dict)


def _rasterizer(name: str) -> Callable:
    if name == "torch":
        return rasterize_torch
    if name == "cpu":
        from gsbench.render.cpu_backend import rasterize_cpu  # lazy: optional (numba)
        return rasterize_cpu
    raise ValueError(name)


def _render_projected(field: GaussianField, camera: Camera, name: str):
    """Shared torch projection + the named rasterizer: (out, t_final, means2d, radii, n_visible)."""
    device, dtype = field.means.device, field.means.dtype
    proj: Projected = project_gaussians(field, camera)
    cam_center = camera.device_tensors(device, dtype)[2]
    rgb_g = field.subset(proj.ids).rgb(cam_center)   # colours of visible Gaussians only (NaN-free grads)
    parts = [rgb_g, proj.depths[:, None]]
    if field.features is not None:
        parts.append(field.features[proj.ids])
    channels = torch.cat(parts, dim=1)
    out, t_final = _rasterizer(name)(proj, channels, camera.width, camera.height)
    if torch.is_grad_enabled() and channels.requires_grad and not out.requires_grad:
        # nothing visible: keep the outputs attached to the graph (zero gradients, not an error);
        # empty slices sum to an exact 0 even if some value is inf
        out, t_final = out + channels[:0].sum(), t_final + proj.opacities[:0].sum()
    if torch.is_grad_enabled() and proj.means2d.requires_grad and proj.ids.numel() == 0:
        out = out + proj.means2d[:0].sum()   # so out.means2d.grad is zeros after backward, not None
    return out, t_final, proj.means2d, proj.radii, int(proj.ids.numel())


def render(field: GaussianField, camera: Camera, *, backend: str = "auto",
           background: Optional[torch.Tensor] = None) -> RenderOutput:
    """Render RGB, depth, features and alpha of `field` seen from `camera`."""
    device, dtype = field.means.device, field.means.dtype
    # a concrete name is trusted (the run resolved it once, up front); `auto` takes the device's backend
    name = backend if backend in BACKENDS else resolve_backend(backend, device)
    if name == "gsplat":
        from gsbench.render.gsplat_backend import render_gsplat  # lazy: optional (gsplat)
        return render_gsplat(field, camera, background=background)
    if name == "cpu":
        # fused numba projection + rasterization (gsbench/render/cpu_backend.py); means2d is a leaf
        # whose .grad the backward fills
        from gsbench.render.cpu_backend import render_fused_cpu  # lazy: optional (numba)
        rgb, depth, feats, t_final, means2d, radii, n_visible = render_fused_cpu(field, camera)
    else:
        out, t_final, means2d, radii, n_visible = _render_projected(field, camera, name)
        rgb, depth = out[..., :3], out[..., 3]
        feats = out[..., 4:] if field.features is not None else None
    if background is not None:
        bg = torch.as_tensor(background, device=device, dtype=dtype)
        if bg.numel() != 3:
            raise ValueError(f"render background must be 3 values (RGB), got shape {tuple(bg.shape)}")
        bg = bg.reshape(1, 1, 3)
        rgb = rgb + t_final[..., None] * bg
    return RenderOutput(rgb=rgb, depth=depth, features=feats, alpha=1.0 - t_final, backend=name,
                        means2d=means2d, radii=radii,
                        info={"n_gaussians": field.num, "n_visible": n_visible,
                              "width": camera.width, "height": camera.height,
                              "dtype": str(dtype).replace("torch.", ""), "device": str(device)})
