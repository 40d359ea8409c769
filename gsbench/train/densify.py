"""3DGS adaptive density control: clone / split / prune and opacity reset, on parameters held in
Adam param groups (one group per tensor, group["name"] = field attribute name).

Gradient statistic: the norm of the screen-space position gradient in NDC units (pixel gradient
times (W/2, H/2), as the reference rasterizer and gsplat do), averaged over the iterations in which
the Gaussian was visible. Every threshold and schedule comes from config `train.densify`.
"""
from __future__ import annotations

import math

import torch
from torch import nn

from gsbench.gaussians import normalize_quats, quat_to_rotmat
from gsbench.train.adam import Adam


def inverse_sigmoid(x: torch.Tensor) -> torch.Tensor:
    x = x.clamp(1e-6, 1 - 1e-6)
    return torch.log(x / (1 - x))


class ParamSet:
    """The trainable tensors of a GaussianField plus their Adam optimiser; rows = Gaussians."""

    def __init__(self, tensors: dict[str, torch.Tensor], lrs: dict[str, float],
                 trainable: set[str] | None = None) -> None:
        self.params: dict[str, nn.Parameter] = {}
        groups = []
        for name, t in tensors.items():
            train = trainable is None or name in trainable
            p = nn.Parameter(t.detach().clone().contiguous(), requires_grad=train)
            self.params[name] = p
            if train:
                groups.append({"params": [p], "lr": float(lrs[name]), "name": name})
        self.optimizer = Adam(groups, lr=0.0, eps=1e-15)

    @property
    def num(self) -> int:
        return int(next(iter(self.params.values())).shape[0])

    def group(self, name: str) -> dict | None:
        for g in self.optimizer.param_groups:
            if g["name"] == name:
                return g
        return None

    def _swap(self, name: str, new: torch.Tensor, state_fn) -> None:
        old = self.params[name]
        p = nn.Parameter(new.detach().contiguous(), requires_grad=old.requires_grad)
        g = self.group(name)
        if g is not None:
            st = self.optimizer.state.pop(old, None)
            if st:
                st = {k: (state_fn(v) if torch.is_tensor(v) and v.dim() > 0 else v) for k, v in st.items()}
                self.optimizer.state[p] = st
            g["params"][0] = p
        self.params[name] = p

    def keep(self, mask: torch.Tensor) -> None:
        """Keep only the rows where mask is True (params and Adam moments)."""
        for name, p in list(self.params.items()):
            self._swap(name, p.data[mask], lambda v: v[mask])

    def append(self, new: dict[str, torch.Tensor]) -> None:
        """Append rows; their Adam moments start at zero."""
        for name, p in list(self.params.items()):
            add = new[name].to(p.data)
            self._swap(name, torch.cat([p.data, add], 0),
                       lambda v, add=add: torch.cat([v, torch.zeros((add.shape[0],) + v.shape[1:], dtype=v.dtype,
                                                                    device=v.device)], 0))

    def set_values(self, name: str, values: torch.Tensor) -> None:
        """Replace a tensor's values and zero its Adam moments (opacity reset)."""
        self._swap(name, values, torch.zeros_like)


class DensifyStats:
    """Accumulated screen-space gradient norms and max screen radii between densification steps."""

    def __init__(self, n: int, device=None) -> None:
        self.grad = torch.zeros(n, device=device)
        self.count = torch.zeros(n, device=device)
        self.max_radii = torch.zeros(n, device=device)
        self._scales: dict = {}      # (W, H, dtype, device) -> the (W/2, H/2) tensor of _ndc_scale

    def update(self, means2d_grad: torch.Tensor | None, radii: torch.Tensor, width: int, height: int) -> None:
        # masked updates (torch.where), not boolean indexing: no host synchronisation on CUDA
        vis = (radii > 0).all(-1) if radii.dim() == 2 else radii > 0
        r = radii.max(-1).values.to(self.max_radii) if radii.dim() == 2 else radii.to(self.max_radii)
        self.max_radii = torch.where(vis, torch.maximum(self.max_radii, r), self.max_radii)
        if means2d_grad is None:
            return
        g = means2d_grad.detach()
        norm = (g * self._ndc_scale(width, height, g)).norm(dim=-1).to(self.grad)
        visf = vis.to(self.grad)
        self.grad = self.grad + torch.where(vis, norm, torch.zeros_like(norm))
        self.count = self.count + visf

    def _ndc_scale(self, width: int, height: int, like: torch.Tensor) -> torch.Tensor:
        """(W/2, H/2) on the gradient's device, made once per image size: building it from Python
        numbers every step would be a blocking host-to-device copy on CUDA."""
        key = (int(width), int(height), like.dtype, like.device)
        if key not in self._scales:
            self._scales[key] = torch.tensor([width / 2.0, height / 2.0], dtype=like.dtype, device=like.device)
        return self._scales[key]

    def keep(self, mask: torch.Tensor) -> None:
        self.grad, self.count, self.max_radii = self.grad[mask], self.count[mask], self.max_radii[mask]

    def append(self, k: int) -> None:
        z = torch.zeros(k, device=self.grad.device)
        self.grad, self.count = torch.cat([self.grad, z]), torch.cat([self.count, z])
        self.max_radii = torch.cat([self.max_radii, z])

    def reset(self, n: int) -> None:
        self.__init__(n, self.grad.device)

    def state_dict(self) -> dict:
        return {"grad": self.grad.cpu(), "count": self.count.cpu(), "max_radii": self.max_radii.cpu()}

    def load_state_dict(self, st: dict) -> None:
        dev = self.grad.device
        self.grad, self.count, self.max_radii = (st["grad"].to(dev).clone(), st["count"].to(dev).clone(),
                                                 st["max_radii"].to(dev).clone())


def densify_and_prune(ps: ParamSet, stats: DensifyStats, cfg: dict, extent: float, prune_big: bool,
                      generator: torch.Generator) -> dict:
    """One 3DGS densification step: clone small / split large high-gradient Gaussians, then prune.

    Respects `max_gaussians` (highest-gradient candidates first). Returns counts for the log.
    """
    avg = stats.grad / stats.count.clamp_min(1.0)
    avg[~torch.isfinite(avg)] = 0.0
    thr = float(cfg["grad_threshold"])
    scales = torch.exp(ps.params["log_scales"].data.clamp(-30, 30))
    smax = scales.max(-1).values
    big = smax > float(cfg["percent_dense"]) * extent
    cand = avg >= thr
    clone_idx = torch.nonzero(cand & ~big).squeeze(1)
    split_idx = torch.nonzero(cand & big).squeeze(1)
    cap = int(cfg.get("max_gaussians") or 0)
    n0 = ps.num
    if cap > 0:
        room = max(0, cap - n0)               # a clone adds 1, a split adds 1 net (2 new, 1 removed)
        if clone_idx.numel() + split_idx.numel() > room:
            allc = torch.cat([clone_idx, split_idx])
            order = torch.argsort(avg[allc], descending=True, stable=True)[:room]
            chosen = allc[order]
            is_clone = torch.zeros(n0, dtype=torch.bool, device=avg.device)
            is_clone[chosen] = True
            clone_idx = torch.nonzero(is_clone & ~big).squeeze(1)
            split_idx = torch.nonzero(is_clone & big).squeeze(1)
    P = ps.params
    new: dict[str, list[torch.Tensor]] = {k: [] for k in P}
    # clone: exact copies (the optimiser moves them apart)
    for k in P:
        new[k].append(P[k].data[clone_idx])
    # split: 2 samples from the Gaussian, scales / 1.6
    n_split = 2
    if split_idx.numel() > 0:
        s = scales[split_idx].repeat(n_split, 1)
        samples = torch.randn(s.shape, generator=generator, device=s.device, dtype=s.dtype) * s
        rot = quat_to_rotmat(normalize_quats(P["quats"].data[split_idx])).repeat(n_split, 1, 1)
        means = (rot @ samples[..., None]).squeeze(-1) + P["means"].data[split_idx].repeat(n_split, 1)
        for k in P:
            if k == "means":
                new[k].append(means)
            elif k == "log_scales":
                new[k].append(torch.log((s / (0.8 * n_split)).clamp_min(1e-30)))
            else:
                v = P[k].data[split_idx]
                new[k].append(v.repeat((n_split,) + (1,) * (v.dim() - 1)))
    n_clone, n_split_src = int(clone_idx.numel()), int(split_idx.numel())
    added = {k: torch.cat(v, 0) for k, v in new.items()}
    k_add = int(added["means"].shape[0])
    if k_add:
        ps.append(added)
        stats.append(k_add)
    # remove split sources, then prune low opacity / too big
    keep = torch.ones(ps.num, dtype=torch.bool, device=avg.device)
    keep[split_idx] = False
    opac = torch.sigmoid(P_opacity(ps))
    prune = opac < float(cfg["prune_opacity"])
    if prune_big:
        sc = torch.exp(ps.params["log_scales"].data.clamp(-30, 30)).max(-1).values
        prune |= stats.max_radii > float(cfg["max_screen_size"])
        prune |= sc > 0.1 * extent
    n_pruned = int((prune & keep).sum())          # split sources are counted as splits, not prunes
    keep &= ~prune
    if keep.sum() == 0:   # never prune everything: keep the most opaque one
        keep[torch.argmax(opac)] = True
    ps.keep(keep)
    stats.reset(ps.num)
    return {"cloned": n_clone, "split": n_split_src, "pruned": n_pruned, "n_gaussians": ps.num}


def P_opacity(ps: ParamSet) -> torch.Tensor:
    return ps.params["opacity_logits"].data


def reset_opacity(ps: ParamSet, max_opacity: float = 0.01) -> None:
    """Clamp every opacity to at most `max_opacity` (3DGS opacity reset) and zero its Adam moments."""
    cur = torch.sigmoid(ps.params["opacity_logits"].data)
    ps.set_values("opacity_logits", inverse_sigmoid(torch.minimum(cur, torch.full_like(cur, max_opacity))))


def expon_lr(step: int, lr_init: float, lr_final: float, max_steps: int, delay_steps: int = 0,
             delay_mult: float = 1.0) -> float:
    """3DGS exponential learning-rate decay (log-linear from lr_init to lr_final over max_steps)."""
    if lr_init <= 0 or lr_final <= 0:
        return 0.0
    if step < 0:
        return 0.0
    if delay_steps > 0:
        delay = delay_mult + (1 - delay_mult) * math.sin(0.5 * math.pi * min(max(step / delay_steps, 0.0), 1.0))
    else:
        delay = 1.0
    t = min(max(step / max(1, max_steps), 0.0), 1.0)
    return delay * math.exp(math.log(lr_init) * (1 - t) + math.log(lr_final) * t)
