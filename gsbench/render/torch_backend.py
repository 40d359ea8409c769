"""The `torch` reference rasterizer: tile-based alpha compositing in plain PyTorch.

Readable and differentiable by autograd, on any device and dtype. For each 16x16 tile it gathers
the Gaussians whose screen box overlaps the tile, sorts them by depth and composites all of the
tile's pixels at once. With gradients enabled each tile is wrapped in activation checkpointing,
so memory stays bounded by one tile's (pixels x Gaussians) matrices.
"""
from __future__ import annotations

import torch
from torch.utils.checkpoint import checkpoint

from gsbench.render import rules
from gsbench.render.projection import Projected


def _composite_tile(px: torch.Tensor, py: torch.Tensor, means2d: torch.Tensor, conics: torch.Tensor,
                    opac: torch.Tensor, channels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite depth-sorted Gaussians over the given pixel centres.

    Returns (P x C) channel sums and (P,) final transmittance.
    """
    dx = px[:, None] - means2d[None, :, 0]
    dy = py[:, None] - means2d[None, :, 1]
    a, b, c = conics[:, 0], conics[:, 1], conics[:, 2]
    power = -0.5 * (a * dx * dx + c * dy * dy) - b * dx * dy
    valid = power <= 0
    power = torch.where(valid, power, torch.zeros_like(power))
    alpha = torch.clamp(opac[None, :] * torch.exp(power), max=rules.ALPHA_MAX)
    alpha = torch.where(valid & (alpha >= rules.ALPHA_MIN), alpha, torch.zeros_like(alpha))
    one_minus = 1.0 - alpha
    # transmittance after each Gaussian (inclusive); a pixel stops before reaching T_MIN
    t_incl = torch.cumprod(one_minus, dim=1)
    keep = (t_incl > rules.T_MIN).detach()
    # once a pixel has stopped, every later Gaussian is excluded too (T is non-increasing)
    alpha = torch.where(keep, alpha, torch.zeros_like(alpha))
    t_incl = torch.cumprod(1.0 - alpha, dim=1)
    t_excl = torch.cat([torch.ones_like(t_incl[:, :1]), t_incl[:, :-1]], dim=1)
    weights = alpha * t_excl
    return weights @ channels, t_incl[:, -1]


def rasterize_torch(proj: Projected, channels: torch.Tensor, width: int, height: int,
                    tile_size: int = rules.TILE_SIZE) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite per-Gaussian `channels` (M x C, rows aligned with `proj.ids`).

    Returns (H x W x C) composited channels (no background) and (H x W) final transmittance.
    """
    device, dtype = channels.device, channels.dtype
    m, C = channels.shape
    out_chunks, t_chunks, pix_chunks = [], [], []
    means2d = proj.means2d[proj.ids]
    radii = proj.radii[proj.ids].to(dtype)
    order = torch.sort(proj.depths.detach(), stable=True).indices
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    with torch.no_grad():
        md = means2d.detach()
        x0 = md[:, 0] - radii[:, 0]
        x1 = md[:, 0] + radii[:, 0]
        y0 = md[:, 1] - radii[:, 1]
        y1 = md[:, 1] + radii[:, 1]
    use_ckpt = torch.is_grad_enabled() and any(t.requires_grad for t in (means2d, proj.conics, proj.opacities, channels))
    for ty in range(tiles_y):
        for tx in range(tiles_x):
            xa, xb = tx * tile_size, min(width, (tx + 1) * tile_size)
            ya, yb = ty * tile_size, min(height, (ty + 1) * tile_size)
            ys, xs = torch.meshgrid(torch.arange(ya, yb, device=device), torch.arange(xa, xb, device=device), indexing="ij")
            pix = (ys * width + xs).reshape(-1)
            pix_chunks.append(pix)
            with torch.no_grad():
                hit = (x1[order] >= xa) & (x0[order] <= xb) & (y1[order] >= ya) & (y0[order] <= yb)
            sel = order[hit]
            if sel.numel() == 0:
                out_chunks.append(torch.zeros(pix.numel(), C, device=device, dtype=dtype))
                t_chunks.append(torch.ones(pix.numel(), device=device, dtype=dtype))
                continue
            px = xs.reshape(-1).to(dtype) + 0.5
            py = ys.reshape(-1).to(dtype) + 0.5
            args = (px, py, means2d[sel], proj.conics[sel], proj.opacities[sel], channels[sel])
            if use_ckpt:
                o, t = checkpoint(_composite_tile, *args, use_reentrant=False)
            else:
                o, t = _composite_tile(*args)
            out_chunks.append(o)
            t_chunks.append(t)
    pix = torch.cat(pix_chunks)
    out = torch.zeros(width * height, C, device=device, dtype=dtype).index_put((pix,), torch.cat(out_chunks))
    t_final = torch.ones(width * height, device=device, dtype=dtype).index_put((pix,), torch.cat(t_chunks))
    return out.reshape(height, width, C), t_final.reshape(height, width)
