"""`gaussiands.sem_geometry`: where L_sem's gradient goes. `joint` (null, the default): one render, into
the latents, the geometry and the densification statistic; `no_densify`: a second render for the latents,
so the statistic (the first render's screen positions) no longer sees L_sem; `detached`: the latents only."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
import torch
from render_fields import look_at

from gsbench.config import canonical, load_config, run_id
from gsbench.errors import InputError
from gsbench.methods.gaussiands.method import gaussiands_loss
from gsbench.render import render
from gsbench.train.initial_field import init_field
from gsbench.train.trainer import StepContext, Trainer, field_from_params
from gsbench.train.views import TrainViews

H, W, D = 12, 16, 3
GEOMETRY = ("means", "log_scales", "quats", "opacity_logits")


def _config(*sets: str, backend: str = "cpu") -> dict:
    return load_config("gaussiands", "cpu-small", [f"backend={backend}", "gaussiands.losses.depth=false",
                                                     "gaussiands.losses.tv=false", "gaussiands.losses.ds=false",
                                                     *sets])


def _grads(tmp_path, *sets: str, backend: str = "cpu") -> tuple[dict, torch.Tensor]:
    """The parameters' gradients and the first render's screen-position gradient after one loss."""
    cfg = _config(*sets, backend=backend)
    cam = look_at(W, H, (0.0, 0.0, -3.0))
    views = TrainViews({0: cam}, {0: torch.full((H, W, 3), 0.5)})
    fld, _ = init_field(None, None, "random", 48, np.zeros(3), 0.5, 0, D, seed=0)
    tr = Trainer(cfg, views, 1.0, fld, tmp_path, lambda ctx: None, backend=backend)
    with torch.no_grad():   # latents start at zero, where L_sem has no gradient into the blending weights
        tr.ps.params["features"].copy_(torch.randn(48, D, generator=torch.Generator().manual_seed(2)))
    target = torch.nn.functional.normalize(torch.randn(H, W, D, generator=torch.Generator().manual_seed(1)), dim=-1)
    targets = SimpleNamespace(latents={0: target}, has_target={0: torch.ones(H, W, dtype=torch.bool)})
    loss_fn = gaussiands_loss(cfg, {}, targets, {0: True}, {})
    out = render(field_from_params(tr.ps, 0), cam, backend=backend)
    res = loss_fn(StepContext(1, 0, out, views.images[0], tr))
    res.total.backward()
    grads = {k: (p.grad.clone() if p.grad is not None else torch.zeros_like(p)) for k, p in tr.ps.params.items()}
    return grads, out.means2d.grad.clone()


@pytest.mark.parametrize("backend", ["cpu", "torch"])
def test_detached_leaves_the_geometry_to_the_colour_loss_and_still_trains_the_latents(tmp_path, backend):
    off, off_2d = _grads(tmp_path, "semantic.loss=false", backend=backend)
    joint, joint_2d = _grads(tmp_path, backend=backend)
    det, det_2d = _grads(tmp_path, "gaussiands.sem_geometry=detached", backend=backend)
    for k in GEOMETRY:
        assert torch.allclose(det[k], off[k], atol=1e-7), k            # L_sem adds nothing to the geometry
    assert any(not torch.allclose(joint[k], off[k], atol=1e-6) for k in GEOMETRY)   # ...where joint does
    assert torch.allclose(det_2d, off_2d, atol=1e-7) and not torch.allclose(joint_2d, off_2d, atol=1e-6)
    assert det["features"].abs().sum() > 0 and torch.allclose(det["features"], joint["features"], atol=1e-6)


def test_no_densify_moves_the_geometry_but_not_the_densification_statistic(tmp_path):
    off, off_2d = _grads(tmp_path, "semantic.loss=false")
    nod, nod_2d = _grads(tmp_path, "gaussiands.sem_geometry=no_densify")
    joint, _ = _grads(tmp_path)
    assert torch.allclose(nod_2d, off_2d, atol=1e-7)
    for k in GEOMETRY:
        assert torch.allclose(nod[k], joint[k], atol=1e-6), k


def test_the_key_is_out_of_the_run_id_while_null_and_checked_when_set():
    base = _config()
    assert "sem_geometry" not in canonical(base)["gaussiands"]
    assert run_id(base, "s") != run_id(_config("gaussiands.sem_geometry=detached"), "s")
    with pytest.raises(InputError, match="sem_geometry"):
        _config("gaussiands.sem_geometry=frozen")
