"""GaussianField: the parameters of a 3D Gaussian scene, and the one place activations live.

Parameters are raw (unconstrained) tensors so optimisers act on them directly:
  scales  = exp(clamp(log_scales, LOG_SCALE_MIN, LOG_SCALE_MAX))   (bounded exp: no overflow)
  opacity = sigmoid(opacity_logits)
  rotation = normalised quaternion (w, x, y, z); a zero quaternion is the identity rotation.
Colours are RGB (N x 3) composited as given, or SH coefficients (N x K x 3, K in 1, 4, 9, 16)
evaluated for the direction camera centre -> mean, plus 0.5, clamped at 0 (as 3DGS and gsplat).
Features are N x d latents composited as given.
"""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import Optional

import torch

LOG_SCALE_MIN = -30.0
LOG_SCALE_MAX = 30.0
QUAT_EPS = 1e-12

SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
         -0.4570457994644658, 1.445305721320277, -0.5900435899266435)


@dataclass
class GaussianField:
    """N Gaussians: means (N,3), log_scales (N,3), quats (N,4 wxyz), opacity_logits (N,),
    colors (N,3) RGB or (N,K,3) SH, features (N,d) or None."""

    means: torch.Tensor
    log_scales: torch.Tensor
    quats: torch.Tensor
    opacity_logits: torch.Tensor
    colors: torch.Tensor
    features: Optional[torch.Tensor] = None

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        checks = {
            "means": (self.means, (n, 3)),
            "log_scales": (self.log_scales, (n, 3)),
            "quats": (self.quats, (n, 4)),
            "opacity_logits": (self.opacity_logits, (n,)),
        }
        for name, (t, shape) in checks.items():
            if tuple(t.shape) != shape:
                raise ValueError(f"GaussianField.{name} must have shape {shape}, got {tuple(t.shape)}")
        if self.colors.dim() == 2:
            if tuple(self.colors.shape) != (n, 3):
                raise ValueError(f"GaussianField.colors must be (N,3) or (N,K,3), got {tuple(self.colors.shape)}")
        elif self.colors.dim() == 3:
            if self.colors.shape[0] != n or self.colors.shape[2] != 3 or self.colors.shape[1] not in (1, 4, 9, 16):
                raise ValueError(f"GaussianField.colors SH must be (N,K,3) with K in 1,4,9,16, "
                                 f"got {tuple(self.colors.shape)}")
        else:
            raise ValueError(f"GaussianField.colors must be (N,3) or (N,K,3), got {tuple(self.colors.shape)}")
        if self.features is not None and (self.features.dim() != 2 or self.features.shape[0] != n):
            raise ValueError(f"GaussianField.features must be (N,d), got {tuple(self.features.shape)}")

    # ------------------------------------------------------------------ activations
    @property
    def num(self) -> int:
        return int(self.means.shape[0])

    @property
    def scales(self) -> torch.Tensor:
        return torch.exp(self.log_scales.clamp(LOG_SCALE_MIN, LOG_SCALE_MAX))

    @property
    def opacity(self) -> torch.Tensor:
        return torch.sigmoid(self.opacity_logits)

    @property
    def rotations(self) -> torch.Tensor:
        """Unit quaternions; a (near) zero quaternion maps to the identity (1,0,0,0)."""
        return normalize_quats(self.quats)

    @property
    def sh_degree(self) -> Optional[int]:
        if self.colors.dim() == 2:
            return None
        return {1: 0, 4: 1, 9: 2, 16: 3}[self.colors.shape[1]]

    def rgb(self, camera_center: Optional[torch.Tensor] = None) -> torch.Tensor:
        """Per-Gaussian RGB: as given, or SH evaluated towards the Gaussian from the camera."""
        if self.colors.dim() == 2:
            return self.colors
        return sh_rgb(self.colors, self.means, camera_center)

    # ------------------------------------------------------------------ utilities
    def tensors(self) -> dict[str, Optional[torch.Tensor]]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to(self, device=None, dtype=None) -> "GaussianField":
        def conv(t):
            return None if t is None else t.to(device=device, dtype=dtype if t.is_floating_point() else None)
        return GaussianField(**{k: conv(v) for k, v in self.tensors().items()})

    def detach(self) -> "GaussianField":
        return GaussianField(**{k: (None if v is None else v.detach()) for k, v in self.tensors().items()})

    def subset(self, mask: torch.Tensor) -> "GaussianField":
        """The Gaussians selected by a boolean mask or index tensor (used by pruning/removal)."""
        return GaussianField(**{k: (None if v is None else v[mask]) for k, v in self.tensors().items()})

    def with_features(self, features: Optional[torch.Tensor]) -> "GaussianField":
        return replace(self, features=features)

    def state_dict(self) -> dict[str, Optional[torch.Tensor]]:
        return {k: (None if v is None else v.detach().cpu()) for k, v in self.tensors().items()}

    @classmethod
    def from_state_dict(cls, state: dict) -> "GaussianField":
        return cls(**{f.name: state.get(f.name) for f in fields(cls)})


def normalize_quats(q: torch.Tensor) -> torch.Tensor:
    """Normalise (w,x,y,z) quaternions; zero quaternions become the identity (finite gradients)."""
    n2 = (q * q).sum(-1, keepdim=True)
    small = n2 < QUAT_EPS
    ident = torch.zeros_like(q)
    ident[..., 0] = 1.0
    safe_q = torch.where(small, ident, q)
    safe_n = torch.sqrt(torch.where(small, torch.ones_like(n2), n2))
    return safe_q / safe_n


def quat_to_rotmat(q: torch.Tensor) -> torch.Tensor:
    """Unit quaternions (N,4 wxyz) -> rotation matrices (N,3,3)."""
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ], dim=-1).reshape(q.shape[:-1] + (3, 3))


def sh_rgb(sh: torch.Tensor, means: Optional[torch.Tensor],
           camera_center: Optional[torch.Tensor] = None) -> torch.Tensor:
    """RGB of SH colours sh (N,K,3) seen from `camera_center` (None: along +z) by Gaussians at `means`
    (N,3): SH value + 0.5, clamped at 0 (3DGS / gsplat: no negative light). Degree 0 (K = 1) does not
    depend on the direction: its directions are not computed, and `means` may be None."""
    if sh.shape[1] == 1:
        return torch.clamp_min(SH_C0 * sh[:, 0] + 0.5, 0.0)
    if means is None:
        raise ValueError(f"sh_rgb: SH with {sh.shape[1]} coefficients depends on the direction; means is needed")
    if camera_center is None:
        dirs = torch.zeros_like(means)
        dirs[:, 2] = 1.0
    else:
        d = means - camera_center.to(means)
        dirs = d / torch.sqrt((d * d).sum(-1, keepdim=True) + 1e-20)
    return torch.clamp_min(eval_sh(sh, dirs) + 0.5, 0.0)


def eval_sh(sh: torch.Tensor, dirs: torch.Tensor) -> torch.Tensor:
    """Real spherical harmonics up to degree 3 (the 3DGS basis). sh: (N,K,3), dirs: (N,3) unit."""
    k = sh.shape[1]
    out = SH_C0 * sh[:, 0]
    if k == 1:
        return out
    x, y, z = dirs[:, 0:1], dirs[:, 1:2], dirs[:, 2:3]
    out = out - SH_C1 * y * sh[:, 1] + SH_C1 * z * sh[:, 2] - SH_C1 * x * sh[:, 3]
    if k == 4:
        return out
    xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
    out = (out + SH_C2[0] * xy * sh[:, 4] + SH_C2[1] * yz * sh[:, 5]
           + SH_C2[2] * (2 * zz - xx - yy) * sh[:, 6] + SH_C2[3] * xz * sh[:, 7]
           + SH_C2[4] * (xx - yy) * sh[:, 8])
    if k == 9:
        return out
    out = (out + SH_C3[0] * y * (3 * xx - yy) * sh[:, 9] + SH_C3[1] * xy * z * sh[:, 10]
           + SH_C3[2] * y * (4 * zz - xx - yy) * sh[:, 11]
           + SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy) * sh[:, 12]
           + SH_C3[4] * x * (4 * zz - xx - yy) * sh[:, 13]
           + SH_C3[5] * z * (xx - yy) * sh[:, 14] + SH_C3[6] * x * (xx - 3 * yy) * sh[:, 15])
    return out
