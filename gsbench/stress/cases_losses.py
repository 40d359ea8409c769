"""Training-loss, stiff-lambda and autoencoder cases: float32 against float64, gradients included."""
from __future__ import annotations

import math
from typing import Callable, NamedTuple, Optional

import numpy as np
import torch

from gsbench.gaussians import GaussianField

from gsbench.stress.core import (Case, CaseResult, _camera, _depth_pair, _field, _grads, _images, _leaf,  # isort: skip
                                 _result, all_finite)
from gsbench.render import render
from gsbench.train.autoencoder import FeatureAutoencoder
from gsbench.train.losses import (
    DEPTH_FORMULATIONS,
    depth_edges,
    depth_loss,
    ds_loss,
    reconstruction_loss,
    sem_loss,
    tv_loss,
)


def _loss_case(comp: str, fn: Callable[..., Optional[torch.Tensor]], inputs: list, grad_mask: list[bool],
               out_tol: float = 1e-5, grad_tol: float = 1e-4, expect: Optional[float] = None,
               expect_tol: float = 1e-6, note: str = "") -> CaseResult:
    """fn(*tensors) in float32 and float64; optional hand-computed expected value of the float64 output."""
    res = {}
    for dt in (torch.float32, torch.float64):
        xs = [(_leaf(x, dt) if g else torch.as_tensor(np.asarray(x))) for x, g in zip(inputs, grad_mask)]
        xs = [x.to(dt) if (isinstance(x, torch.Tensor) and x.is_floating_point() and not x.requires_grad) else x
              for x in xs]
        out = fn(*xs)
        if out is None:
            res[dt] = (None, None)
            continue
        leaves = [x for x, g in zip(xs, grad_mask) if g]
        res[dt] = ([out], _grads(out, leaves))
    (o32, g32), (o64, g64) = res[torch.float32], res[torch.float64]
    if o32 is None or o64 is None:
        return CaseResult(comp, "", passed=False,
                          note=f"loss returned None (float32 {o32 is None}, float64 {o64 is None})")
    extra_ok = True
    if expect is not None:
        v = float(o64[0].detach())
        extra_ok = abs(v - expect) <= expect_tol * max(1.0, abs(expect))
        note = (note + "; " if note else "") + f"value {v:.6g} vs hand-computed {expect:.6g}"
    return _result(comp, o32, o64, g32, g64, out_tol, grad_tol, note=note, extra_ok=extra_ok)


def _adder(cases: list[Case]) -> Callable[[str, str, Callable[[], CaseResult]], None]:
    """`add(component, name, fn)` appending one Case to `cases`: keeps each case below to one call."""

    def add(comp, name, fn):
        cases.append(Case(comp, name, fn))

    return add


class _SemInputs(NamedTuple):
    """Rendered and target latents, and the target / edge masks, shared by the L_sem, L_ds and edge cases."""

    s_hat: np.ndarray
    s_tgt: np.ndarray
    has: np.ndarray
    full: np.ndarray
    empty: np.ndarray
    sem_ref: float


def _sem_inputs() -> _SemInputs:
    rng = np.random.default_rng(3)
    s_hat = rng.standard_normal((24, 32, 3))
    s_tgt = rng.standard_normal((24, 32, 3))
    has = np.ones((24, 32), bool)
    has[:, :8] = False
    full = np.ones((24, 32), bool)
    empty = np.zeros((24, 32), bool)
    sem_ref = float(np.abs(s_hat - s_tgt)[has].mean())
    return _SemInputs(s_hat, s_tgt, has, full, empty, sem_ref)


def _rec_loss_cases() -> list[Case]:
    """L_rec = 0.8 L1 + 0.2 (1 - SSIM) on random, constant, 1x1 and out-of-range images."""
    cases: list[Case] = []
    add = _adder(cases)
    pred, gt = _images()
    add("loss:rec", "random images", lambda: _loss_case("loss:rec", reconstruction_loss, [pred, gt], [True, False]))
    c = np.full((24, 32, 3), 0.5)
    add("loss:rec", "identical constant images",
        lambda: _loss_case("loss:rec", reconstruction_loss, [c, c.copy()], [True, False], expect=0.0, expect_tol=1e-9,
                           grad_tol=1e-2, note="L1 = 0 and SSIM = 1 exactly; gradient ~0 (float32 noise < 1e-8)"))
    add("loss:rec", "constant vs constant (0.5 vs 0)",
        lambda: _loss_case("loss:rec", reconstruction_loss, [c, np.zeros_like(c)], [True, False], out_tol=1e-4))
    one = np.full((1, 1, 3), 0.3)
    add("loss:rec", "1x1 images", lambda: _loss_case("loss:rec", reconstruction_loss, [one, one * 0.5], [True, False],
                                                     out_tol=1e-4))
    add("loss:rec", "prediction far outside [0,1] (+-1e3)",
        lambda: _loss_case("loss:rec", reconstruction_loss, [(pred - 0.5) * 2e3, gt], [True, False], out_tol=1e-4))
    return cases


def _depth_loss_cases(depth: np.ndarray, prior: np.ndarray) -> list[Case]:
    """L_depth per formulation, for depth and disparity priors, and rendered depth with zero rows."""
    cases: list[Case] = []
    add = _adder(cases)
    valid = np.ones(depth.shape, bool)
    for form in DEPTH_FORMULATIONS[1:]:
        for kind, pr in (("depth", prior), ("disparity", 1.0 / prior)):
            add("loss:depth", f"{form}, {kind} prior",
                lambda f=form, k=kind, pr=pr: _loss_case(
                    "loss:depth", lambda d, f=f, k=k, pr=pr: depth_loss(f, d, pr.astype(np.float32), valid, k).loss,
                    [depth], [True], out_tol=1e-3 if f == "pearson" else 1e-4, grad_tol=1e-3))
        zero_d = depth.copy()
        zero_d[:4] = 0.0          # no surface rendered there (1/D guarded, not used)
        add("loss:depth", f"{form}, disparity prior, zero rendered depth rows",
            lambda f=form, zd=zero_d: _loss_case(
                "loss:depth",
                lambda d, f=f: depth_loss(f, d, (1.0 / prior).astype(np.float32), valid, "disparity").loss,
                [zd], [True], out_tol=1e-3 if f == "pearson" else 1e-4, grad_tol=1e-3,
                note="pearson: 1 - corr cancels in float32 when corr ~ 1" if f == "pearson" else ""))
    return cases


def _tv_loss_cases(depth: np.ndarray) -> list[Case]:
    """L_tv on flat depth (eps > 0 and eps = 0: no NaN gradient at sqrt(0)), regular, huge and 1x1 depth."""
    cases: list[Case] = []
    add = _adder(cases)
    const = np.full((24, 32), 2.0)
    eps = 1e-6
    add("loss:tv", "zero gradient (constant depth)",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [const], [True], expect=math.sqrt(eps),
                           expect_tol=1e-9, note="sqrt(eps) exactly, zero gradient"))
    add("loss:tv", "zero gradient, eps = 0",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, 0.0), [const], [True], expect=0.0, expect_tol=1e-12,
                           note="sqrt(0): gradient must not be NaN"))
    add("loss:tv", "regular depth", lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [depth], [True]))
    add("loss:tv", "huge depth steps (1e6)",
        lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [depth * 1e6], [True], out_tol=1e-5))
    add("loss:tv", "1x1 depth", lambda: _loss_case("loss:tv", lambda d: tv_loss(d, eps), [np.full((1, 1), 3.0)], [True],
                                                  expect=0.0, expect_tol=1e-12))
    return cases


def _sem_ds_loss_cases(si: _SemInputs) -> list[Case]:
    """L_sem and L_ds on partial, missing and huge targets, with empty and full edge maps."""
    cases: list[Case] = []
    add = _adder(cases)
    s_hat, s_tgt, has, full, empty, sem_ref = si

    def sem_fn(has_m):
        return lambda a, b: sem_loss(a, b, torch.as_tensor(has_m))

    def ds_fn(edges, has_m=has):
        return lambda a, b: ds_loss(a, b, torch.as_tensor(has_m), torch.as_tensor(edges))

    add("loss:sem", "partial targets", lambda: _loss_case("loss:sem", sem_fn(has), [s_hat, s_tgt], [True, False],
                                                         expect=sem_ref, note="mean |S_hat - S| over target pixels"))
    add("loss:sem", "huge latents (1e6)",
        lambda: _loss_case("loss:sem", sem_fn(has), [s_hat * 1e6, s_tgt], [True, False]))

    def no_target() -> CaseResult:
        out = sem_loss(torch.as_tensor(s_hat), torch.as_tensor(s_tgt), torch.as_tensor(empty))
        ds = ds_loss(torch.as_tensor(s_hat), torch.as_tensor(s_tgt), torch.as_tensor(empty), torch.as_tensor(full))
        ok = float(out) == 0.0 and float(ds) == 0.0
        return CaseResult("loss:sem", "", finite_out=all_finite(out, ds), passed=ok,
                          note=f"no pixel has a target: L_sem = {float(out):.3g}, L_ds = {float(ds):.3g} "
                               "(documented: 0; the method knows such views up front and counts the skip)")
    add("loss:sem", "no pixel has a target", no_target)
    add("loss:ds", "empty edge map", lambda: _loss_case("loss:ds", ds_fn(empty), [s_hat, s_tgt], [True, False],
                                                       expect=0.0, expect_tol=1e-12, note="zero loss, zero gradient"))
    add("loss:ds", "full edge map (equals L_sem)",
        lambda: _loss_case("loss:ds", ds_fn(full), [s_hat, s_tgt], [True, False], expect=sem_ref))
    return cases


def _nonfinite_blocks_case(full: np.ndarray) -> CaseResult:
    """NaN / inf blocks count as invalid: edges only at the real depth step, none along the blocks."""
    yy, xx = np.mgrid[0:24, 0:32]
    p = 1.0 + 0.01 * xx + 0.005 * yy + (xx >= 16) * 1.0      # noise-free ramp with one step at x = 16
    p[:8, :8] = np.nan
    p[16:, 4:12] = np.inf
    e = depth_edges(p, full)
    at_step = e & (np.abs(xx - 15.5) <= 3)
    elsewhere = int((e & ~at_step).sum())
    ok = e.dtype == bool and int(at_step.sum()) > 0 and elsewhere == 0
    return CaseResult("loss:ds", "", finite_out=True, passed=ok,
                      note=f"E_d: {int(at_step.sum())} edge pixels at the step, {elsewhere} elsewhere "
                           f"(e.g. along the NaN/inf blocks; expected > 0 and 0)")


def _edge_cases(prior: np.ndarray, si: _SemInputs) -> list[Case]:
    """The depth edge map E_d behind L_ds: none on flat, invalid or non-finite priors, some at real steps."""
    cases: list[Case] = []
    add = _adder(cases)
    s_hat, s_tgt, has, full, empty, _ = si

    def edges_case(values, valid_m, expect_empty: bool, what: str) -> Callable[[], CaseResult]:
        def run() -> CaseResult:
            e = depth_edges(values, valid_m)
            ok = e.dtype == bool and e.shape == values.shape and (not e.any() if expect_empty else bool(e.any()))
            ds = ds_loss(torch.as_tensor(s_hat, dtype=torch.float32), torch.as_tensor(s_tgt, dtype=torch.float32),
                         torch.as_tensor(has), torch.as_tensor(e))
            fin = ds is not None and all_finite(ds)
            return CaseResult("loss:ds", "", finite_out=fin, passed=bool(ok and fin),
                              note=f"E_d on {what}: {int(e.sum())} edge pixels "
                                   f"(expected {'none' if expect_empty else 'some'})")
        return run

    add("loss:ds", "edges of a constant prior", edges_case(np.full((24, 32), 5.0), full, True, "a constant prior"))
    add("loss:ds", "edges of an all-invalid prior", edges_case(prior, empty, True, "an all-invalid prior"))
    add("loss:ds", "edges of an all-NaN prior", edges_case(np.full((24, 32), np.nan), full, True, "an all-NaN prior"))
    add("loss:ds", "edges of a prior with NaN/inf blocks", lambda: _nonfinite_blocks_case(full))
    add("loss:ds", "edges of a prior with a step", edges_case(prior, full, False, "a prior with a depth step"))
    add("loss:ds", "edges of a 1e6 prior with a step", edges_case(prior * 1e6 + 1e6, full, False, "a 1e6 prior"))
    return cases


def loss_cases() -> list[Case]:
    """Each training loss in float32 vs float64 on regular and extreme inputs (gradients included)."""
    depth, prior = _depth_pair()   # one pair shared by the depth, tv and edge cases
    si = _sem_inputs()
    return (_rec_loss_cases() + _depth_loss_cases(depth, prior) + _tv_loss_cases(depth) + _sem_ds_loss_cases(si)
            + _edge_cases(prior, si))


# ---------------------------------------------------------------------------- stiff loss weights
def stiff_lambda_cases() -> list[Case]:
    """The GaussianDS total loss on a real render with lambdas spanning 1e-4..1e4: finite and float32 ~ float64."""

    cam = _camera(24, 24)
    rng = np.random.default_rng(5)
    gt = rng.random((24, 24, 3))
    tgt = rng.standard_normal((24, 24, 3))
    has = np.ones((24, 24), bool)
    has[:5] = False

    params = _field(60, log_scale=-1.8)
    with torch.no_grad():   # the prior is an input of training: one fixed array for both precisions
        d_ref = render(GaussianField(**params), cam, backend="torch").depth.numpy()
    yy, xx = np.mgrid[0:24, 0:24]
    prior = 0.5 * d_ref + 0.2 + 0.05 * np.sin(xx / 3.0) * np.cos(yy / 4.0)
    pv = d_ref > 1e-3
    edges = torch.as_tensor(depth_edges(prior, pv))

    def total(lams: dict, dtype) -> tuple[torch.Tensor, list[torch.Tensor]]:
        leaves = {k: (None if v is None else v.to(dtype).clone().requires_grad_(True)) for k, v in params.items()}
        out = render(GaussianField(**leaves), cam, backend="torch")
        t = torch.as_tensor(tgt, dtype=dtype)
        h = torch.as_tensor(has)
        L = reconstruction_loss(out.rgb, torch.as_tensor(gt, dtype=dtype))
        dt = depth_loss("scale_shift", out.depth, prior, pv, "depth")
        if dt.loss is not None:
            L = L + lams["depth"] * dt.loss
        L = L + lams["tv"] * tv_loss(out.depth, 1e-6)
        L = L + lams["sem"] * sem_loss(out.features, t, h) + lams["ds"] * ds_loss(out.features, t, h, edges)
        names = ["means", "log_scales", "quats", "opacity_logits", "colors", "features"]
        return L, _grads(L, [leaves[k] for k in names])

    def case(lams: dict) -> CaseResult:
        l32, g32 = total(lams, torch.float32)
        l64, g64 = total(lams, torch.float64)
        r = _result("stiff-lambdas", [l32], [l64], g32, g64, out_tol=1e-4, grad_tol=2e-3,
                    note="lambdas " + ",".join(f"{k}={v:g}" for k, v in lams.items()))
        return r

    cases = []
    for v in (1e-4, 1e-2, 1.0, 1e2, 1e4):
        lams = {"depth": v, "tv": v, "sem": v, "ds": v}
        cases.append(Case("stiff-lambdas", f"all lambdas {v:g}", lambda lams=lams: case(lams)))
    cases.append(Case("stiff-lambdas", "depth,sem 1e4 / tv,ds 1e-4",
                      lambda: case({"depth": 1e4, "tv": 1e-4, "sem": 1e4, "ds": 1e-4})))
    cases.append(Case("stiff-lambdas", "depth,sem 1e-4 / tv,ds 1e4",
                      lambda: case({"depth": 1e-4, "tv": 1e4, "sem": 1e-4, "ds": 1e4})))
    cases.append(Case("stiff-lambdas", "paper weights (0.01, 1.5, 5, 1)",
                      lambda: case({"depth": 0.01, "tv": 1.5, "sem": 5.0, "ds": 1.0})))
    return cases


# ---------------------------------------------------------------------------- autoencoder
def autoencoder_cases() -> list[Case]:
    """The frozen feature autoencoder: finite, unit-norm latents and reconstructions, float32 ~ float64."""

    def case(make_x: Callable[[], torch.Tensor], latent_dim: int = 3, tol: float = 1e-4) -> CaseResult:
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(0)
            ae = FeatureAutoencoder(512, latent_dim)
        ae64 = FeatureAutoencoder(512, latent_dim).double()
        ae64.load_state_dict({k: v.double() for k, v in ae.state_dict().items()})
        x = make_x()
        outs = {}
        for dt, model in ((torch.float32, ae), (torch.float64, ae64)):
            xx = x.to(dt).clone().requires_grad_(True)
            z = model.encode(xx)
            y = model.decode(z)
            g = torch.autograd.grad((z.sum() + (y * torch.linspace(-1, 1, y.shape[-1], dtype=dt)).sum()), xx)[0]
            outs[dt] = ([z, y], [g])
        (o32, g32), (o64, g64) = outs[torch.float32], outs[torch.float64]
        norms = torch.cat([o.detach().norm(dim=-1) for o in o32])
        unit = bool(torch.isfinite(norms).all()) and float((norms - 1).abs().max()) <= 1e-5
        r = _result("autoencoder", o32, o64, g32, g64, out_tol=tol, grad_tol=1e-2,
                    note=f"output norms in [{float(norms.min()):.6f}, {float(norms.max()):.6f}] (must be 1)",
                    extra_ok=unit)
        return r

    g = torch.Generator().manual_seed(4)

    def unit_rows(n=16):
        x = torch.randn(n, 512, generator=g, dtype=torch.float64)
        return x / x.norm(dim=-1, keepdim=True)

    cases = [Case("autoencoder", "unit-norm inputs (d=3)", lambda: case(unit_rows)),
             Case("autoencoder", "unit-norm inputs (d=32)", lambda: case(unit_rows, latent_dim=32)),
             Case("autoencoder", "zero inputs", lambda: case(lambda: torch.zeros(4, 512, dtype=torch.float64))),
             Case("autoencoder", "tiny inputs (1e-30)", lambda: case(lambda: unit_rows(4) * 1e-30))]
    for mag in (1e6, 1e20, 1e30):
        cases.append(Case("autoencoder", f"huge inputs ({mag:g})", lambda mag=mag: case(lambda: unit_rows(4) * mag)))
    return cases


