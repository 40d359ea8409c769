"""The `torch` reference rasterizer: tile-based alpha compositing in plain PyTorch.

Readable and differentiable by autograd, on any device and dtype. Gaussians are sorted by depth
once; for each 16x16 tile the ones whose screen box overlaps the tile are composited over all of
the tile's pixels at once, in depth-ordered chunks of CHUNK Gaussians that carry the pixels'
transmittance from one chunk to the next. A tile stops as soon as all of its pixels have stopped
(transmittance rule), which is where most of the work of a dense scene is saved. With gradients
enabled each chunk is an activation checkpoint (`_CheckpointedChunk`: forward without a graph,
recomputed under autograd in backward), so memory stays bounded by one (pixels x CHUNK) block
plus the per-chunk inputs, and gradients are still exactly autograd's.
"""
from __future__ import annotations

import torch

from gsbench.render import rules
from gsbench.render.projection import Projected

CHUNK = 256   # Gaussians composited per block (memory ~ tile pixels x CHUNK per intermediate)


def _composite_chunk(px: torch.Tensor, py: torch.Tensor, t_in: torch.Tensor, done_in: torch.Tensor,
                     means2d: torch.Tensor, conics: torch.Tensor, opac: torch.Tensor,
                     channels: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Composite one depth-sorted chunk of Gaussians over pixel centres (px, py).

    t_in: (P,) transmittance before the chunk; done_in: (P,) bool, pixels that already stopped.
    Returns (P x C) weighted channel sums of this chunk, (P,) transmittance after it, (P,) done.
    """
    dx = px[:, None] - means2d[None, :, 0]
    dy = py[:, None] - means2d[None, :, 1]
    power = -0.5 * (conics[None, :, 0] * dx * dx + conics[None, :, 2] * dy * dy) - conics[None, :, 1] * dx * dy
    valid = (power <= 0).detach()
    power = torch.where(valid, power, torch.zeros_like(power))        # exp never overflows (NaN-free grads)
    alpha = torch.clamp(opac[None, :] * torch.exp(power), max=rules.ALPHA_MAX)   # no grad when clamped
    used = valid & (alpha.detach() >= rules.ALPHA_MIN) & ~done_in[:, None]
    alpha = torch.where(used, alpha, torch.zeros_like(alpha))
    t_incl = t_in[:, None] * torch.cumprod(1.0 - alpha, dim=1)       # transmittance after each Gaussian
    stop = (t_incl.detach() <= rules.T_MIN)
    if bool(stop.any()):
        # a pixel stops before the Gaussian that would bring T to T_MIN or below; T is
        # non-increasing, so that Gaussian and every later one are excluded
        alpha = torch.where(stop, torch.zeros_like(alpha), alpha)
        t_incl = t_in[:, None] * torch.cumprod(1.0 - alpha, dim=1)
    done_out = done_in | stop[:, -1]
    t_excl = torch.cat([t_in[:, None], t_incl[:, :-1]], dim=1)
    weights = alpha * t_excl
    return weights @ channels, t_incl[:, -1], done_out


class _CheckpointedChunk(torch.autograd.Function):
    """`_composite_chunk` as an activation checkpoint.

    Hand-rolled rather than torch.utils.checkpoint: same gradients (autograd on the recomputed
    chunk), less per-call overhead, and no first-call import of torch's compiler stack.
    """

    @staticmethod
    def forward(ctx, *args):
        ctx.save_for_backward(*args)
        o, t, done = _composite_chunk(*args)      # grad mode is off inside Function.forward
        ctx.mark_non_differentiable(done)
        return o, t, done

    @staticmethod
    def backward(ctx, grad_o, grad_t, _grad_done):
        saved = ctx.saved_tensors
        inputs = [x.detach().requires_grad_(need) for x, need in zip(saved, ctx.needs_input_grad)]
        wrt = [x for x, need in zip(inputs, ctx.needs_input_grad) if need]
        if not wrt:
            return (None,) * len(saved)
        with torch.enable_grad():
            o, t, _ = _composite_chunk(*inputs)
            # only the outputs on the graph: with the geometry held constant the transmittance is not
            outs = [(x, g) for x, g in ((o, grad_o), (t, grad_t)) if x.requires_grad]
            grads = iter(torch.autograd.grad([x for x, _ in outs], wrt, [g for _, g in outs], allow_unused=True))
        return tuple(next(grads) if need else None for need in ctx.needs_input_grad)


def rasterize_torch(proj: Projected, channels: torch.Tensor, width: int, height: int,
                    tile_size: int = rules.TILE_SIZE) -> tuple[torch.Tensor, torch.Tensor]:
    """Composite per-Gaussian `channels` (M x C, rows aligned with `proj.ids`).

    Returns (H x W x C) composited channels (no background) and (H x W) final transmittance.
    """
    device, dtype = channels.device, channels.dtype
    C = channels.shape[1]
    means2d = proj.means2d[proj.ids]
    use_ckpt = torch.is_grad_enabled() and any(
        t.requires_grad for t in (means2d, proj.conics, proj.opacities, channels))
    with torch.no_grad():
        order = torch.sort(proj.depths.detach(), stable=True).indices   # front to back, ties by index
        md = means2d.detach()[order]
        radii = proj.radii[proj.ids][order].to(dtype)
        x0, x1 = md[:, 0] - radii[:, 0], md[:, 0] + radii[:, 0]
        y0, y1 = md[:, 1] - radii[:, 1], md[:, 1] + radii[:, 1]
    tiles_x = (width + tile_size - 1) // tile_size
    tiles_y = (height + tile_size - 1) // tile_size
    pix_chunks, out_chunks, t_chunks = [], [], []
    for ty in range(tiles_y):
        ya, yb = ty * tile_size, min(height, (ty + 1) * tile_size)
        with torch.no_grad():   # Gaussians overlapping this row of tiles, in depth order
            row = torch.nonzero((y1 >= ya) & (y0 <= yb)).squeeze(1)
            rx0, rx1 = x0[row], x1[row]
        if row.numel() == 0:
            continue
        for tx in range(tiles_x):
            xa, xb = tx * tile_size, min(width, (tx + 1) * tile_size)
            with torch.no_grad():
                sel = order[row[(rx1 >= xa) & (rx0 <= xb)]]   # indices into proj.ids, depth order
            if sel.numel() == 0:
                continue
            ys, xs = torch.meshgrid(torch.arange(ya, yb, device=device), torch.arange(xa, xb, device=device),
                                    indexing="ij")
            ys, xs = ys.reshape(-1), xs.reshape(-1)
            px, py = xs.to(dtype) + 0.5, ys.to(dtype) + 0.5
            acc = torch.zeros(px.numel(), C, device=device, dtype=dtype)
            t = torch.ones(px.numel(), device=device, dtype=dtype)
            done = torch.zeros(px.numel(), device=device, dtype=torch.bool)
            for k in range(0, sel.numel(), CHUNK):
                idx = sel[k:k + CHUNK]
                args = (px, py, t, done, means2d[idx], proj.conics[idx], proj.opacities[idx], channels[idx])
                if use_ckpt:
                    o, t, done = _CheckpointedChunk.apply(*args)
                else:
                    o, t, done = _composite_chunk(*args)
                acc = acc + o
                if bool(done.all()):
                    break
            pix_chunks.append(ys * width + xs)
            out_chunks.append(acc)
            t_chunks.append(t)
    out = torch.zeros(height * width, C, device=device, dtype=dtype)
    t_final = torch.ones(height * width, device=device, dtype=dtype)
    if pix_chunks:
        pix = torch.cat(pix_chunks)
        out = out.index_put((pix,), torch.cat(out_chunks))
        t_final = t_final.index_put((pix,), torch.cat(t_chunks))
    if use_ckpt and not out.requires_grad:
        # nothing reached a pixel: keep the outputs attached to the graph (exact zero gradients
        # for channels and opacities; the `cpu` backend does the same)
        out = out + channels[:0].sum()
        t_final = t_final + proj.opacities[:0].sum()
    return out.reshape(height, width, C), t_final.reshape(height, width)
