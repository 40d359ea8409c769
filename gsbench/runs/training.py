"""The training loop: the harness owns it, the methods give it phases to run.

A method's `train_phases(scene, run_dir, config, resume, progress)` (gsbench.methods.base) prepares
its data and yields one optimisation phase at a time (a `gsbench.train.trainer.Trainer`: the 3DGS
recipe with the method's loss; twostage yields two). For each phase this module runs the steps
(`Trainer.train_iteration`), and owns everything around them:
- resume: a checkpoint of that phase restores its state, and train_log.jsonl is cut back to the
  checkpoint's step so the log has no duplicated steps;
- logging: one train_log.jsonl line per `train.log_every` steps (and on a densify step): mean loss
  terms, their shares of the weighted total, skip counts, Gaussian count, position LR;
- periodic evaluation every `train.eval_every` steps: PSNR / SSIM on the eval views and, for a
  semantic field, the segmentation mIoU with gsbench.evaluation's own code;
- checkpoints every `train.checkpoint_every` steps and at the end of each phase;
- SIGTERM: the step under way ends, is checkpointed, and the run stops as after Ctrl-C
  (`sigterm_stops_training`; status "interrupted", the CLI exits 143);
- non-finite checks at those steps only (the loop's only host synchronisation points), so a
  non-finite loss is reported with its exact step and no checkpoint is written after it.
It sends the phase's final field back to the method, which goes on to its next phase or finishes.
"""
from __future__ import annotations

import contextlib
import json
import logging
import signal
import threading
import time
from pathlib import Path
from typing import Callable, Iterator, Optional

import numpy as np
import torch
from tqdm import tqdm

from gsbench import rundir
from gsbench.config import setting
from gsbench.errors import InputError, Terminated
from gsbench.evaluation import segmentation_metrics
from gsbench.gaussians import GaussianField
from gsbench.metrics import psnr, ssim
from gsbench.render import render
from gsbench.store import append_jsonl, read_jsonl, save_torch_atomic, write_text_atomic
from gsbench.train.trainer import Trainer, load_checkpoint_if_any

log = logging.getLogger(__name__)


_SIGTERM = {"in_steps": False, "received": False}


@contextlib.contextmanager
def sigterm_stops_training() -> Iterator[None]:
    """SIGTERM while training ends the run as Ctrl-C does (gsbench.errors.Terminated): during the steps
    of a phase at the end of the current step, after a checkpoint of it (run_phase); anywhere else at
    once (the run resumes from its last checkpoint). Only the main thread can take signals: elsewhere
    SIGTERM keeps its handler."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def on_sigterm(signum, frame) -> None:
        if _SIGTERM["in_steps"]:
            _SIGTERM["received"] = True
        else:
            raise Terminated()
    _SIGTERM.update(in_steps=False, received=False)
    old = signal.signal(signal.SIGTERM, on_sigterm)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)
        _SIGTERM.update(in_steps=False, received=False)


def train_method(method, scene, run_dir: Path, config: dict, progress: bool = True) -> None:
    """Train `method` on `scene` into `run_dir`, resuming from its checkpoint when there is one."""
    with sigterm_stops_training():
        _train_method(method, scene, Path(run_dir), config, progress)


def _train_method(method, scene, run_dir: Path, config: dict, progress: bool) -> None:
    resume = load_checkpoint_if_any(run_dir)
    phases = method.train_phases(scene, run_dir, config, resume=resume, progress=progress)
    try:
        phase = next(phases)
        while True:
            state = resume if (resume is not None and resume.get("phase") == phase.phase) else None
            evaluate = periodic_eval(method, scene, phase, config)
            field = run_phase(phase, run_dir, evaluate, progress=progress, resume_state=state)
            phase = phases.send(field)
    except StopIteration:
        return


def run_phase(tr: Trainer, run_dir: Path, eval_fn: Optional[Callable[[GaussianField], dict]], *,
              progress: bool = True, resume_state: Optional[dict] = None) -> GaussianField:
    """Run one phase's steps to its last iteration; return its final field (a checkpoint is written)."""
    log_path = Path(run_dir) / rundir.TRAIN_LOG
    if resume_state is not None:
        tr.load_state(resume_state)
        log.info("resuming phase %s from its checkpoint at step %d of %d", tr.phase, tr.step, tr.iterations)
        # drop log lines written after the checkpoint (they will be produced again)
        lines = [r for r in read_jsonl(log_path) if r.get("phase") != tr.phase or int(r.get("step", 0)) <= tr.step]
        write_text_atomic(log_path, "".join(json.dumps(r) + "\n" for r in lines))
    bar = tqdm(total=tr.iterations, initial=tr.step, desc=f"train[{tr.phase}]", disable=not progress,
               dynamic_ncols=True, leave=False)
    _SIGTERM["in_steps"] = True
    try:
        _steps(tr, run_dir, eval_fn, log_path, bar)
    finally:
        _SIGTERM["in_steps"] = False
        bar.close()
    _checkpoint_checked(tr, run_dir)
    if _SIGTERM["received"]:        # came after the last step: the phase is whole and checkpointed
        raise Terminated()
    return tr.field


def _checkpoint_checked(tr: Trainer, run_dir: Path) -> None:
    """The phase's checkpoint after its steps stopped: written only when no step was non-finite."""
    tr.synchronize()
    tr.raise_if_bad()
    tr.check_finite("parameters")
    save_torch_atomic(Path(run_dir) / rundir.CHECKPOINT, tr.state())


def _stop_if_terminated(tr: Trainer, run_dir: Path) -> None:
    """After a step: when SIGTERM came during it, checkpoint this step (a finite one) and stop."""
    if not _SIGTERM["received"]:
        return
    _checkpoint_checked(tr, run_dir)
    log.warning("SIGTERM: stopped phase %s at step %d of %d; its checkpoint is saved", tr.phase, tr.step,
                tr.iterations)
    raise Terminated()


def _steps(tr: Trainer, run_dir: Path, eval_fn: Optional[Callable[[GaussianField], dict]], log_path: Path,
           bar) -> None:
    """The phase's steps from tr.step to its last iteration (logs, evaluations and checkpoints between)."""
    log_every = max(1, int(setting(tr.cfg, "train.log_every")))
    eval_every = int(setting(tr.cfg, "train.eval_every"))
    ckpt_every = int(setting(tr.cfg, "train.checkpoint_every"))
    acc: dict = {}          # device tensors (or floats) summed per step, read at log steps only
    acc_w: dict = {}
    acc_n = 0
    skipped: dict = {}
    while tr.step < tr.iterations:
        t0 = time.perf_counter()
        out = tr.train_iteration()
        res, info = out.loss, out.densify
        for k, v in res.terms.items():
            acc[k] = acc.get(k, 0.0) + v
        for k, v in res.weighted.items():
            acc_w[k] = acc_w.get(k, 0.0) + v
        acc_n += 1
        for k, v in res.skipped.items():
            skipped[k] = skipped.get(k, 0) + v
        bar.update(1)
        step = tr.step
        is_log = step % log_every == 0 or step == tr.iterations or bool(info)
        is_eval = eval_fn is not None and eval_every > 0 and (step % eval_every == 0 or step == tr.iterations)
        is_ckpt = ckpt_every > 0 and (step % ckpt_every == 0) and step < tr.iterations
        if is_log or is_eval or is_ckpt:
            # the only host synchronisation of the loop: finiteness, timings and logged values
            tr.synchronize()
            tr.raise_if_bad()
            tr.check_finite("parameters")
        tr.elapsed += time.perf_counter() - t0
        if is_log:
            loss = {k: float(v) / max(1, acc_n) for k, v in acc.items()}
            rec = {"phase": tr.phase, "step": step, "wall_s": round(tr.elapsed, 4), "loss": loss,
                   "n_gaussians": tr.ps.num, "lr_position": out.lr_position,
                   "skipped": {k: int(v) for k, v in skipped.items()}}
            if acc_w:
                w = {k: float(v) for k, v in acc_w.items()}
                tot_w = sum(w.values())
                rec["loss_share"] = {k: (v / tot_w if tot_w > 0 else 0.0) for k, v in w.items()}
            if tr.sh_max > 0:
                rec["sh_degree"] = tr.sh_degree()
            if info:
                rec["densify"] = info
            append_jsonl(log_path, rec)
            if "total" in loss:
                bar.set_postfix(loss=f"{loss['total']:.4f}", n=tr.ps.num)
            acc, acc_w, acc_n, skipped = {}, {}, 0, {}
        if is_eval:
            ev = eval_fn(tr.field)
            append_jsonl(log_path, {"phase": tr.phase, "step": step, "wall_s": round(tr.elapsed, 4), "eval": ev})
        if is_ckpt:
            save_torch_atomic(Path(run_dir) / rundir.CHECKPOINT, tr.state())
        _stop_if_terminated(tr, run_dir)


def periodic_eval(method, scene, tr: Trainer, config: dict) -> Callable[[GaussianField], dict]:
    """PSNR / SSIM (gsbench.metrics) of a field on the phase's eval views, plus the segmentation mIoU
    (gsbench.evaluation's code, the configured query mode) once the method has a semantic field."""
    views = tr.views
    seg = _segmentation(method, scene, views, config)

    def _eval(fld: GaussianField) -> dict:
        if not views.eval_cameras:
            return {"skipped": "no test views"}
        ps, ss = [], []
        with torch.no_grad():
            for i, cam in views.eval_cameras.items():
                out = render(fld, cam, backend=tr.backend, background=tr.background)
                pred = out.rgb.clamp(0, 1).cpu().numpy()
                gt = views.eval_images[i].cpu().numpy()
                ps.append(psnr(pred, gt))
                ss.append(ssim(pred, gt))
        res = {"psnr": float(np.mean(ps)), "ssim": float(np.mean(ss)), "n_views": len(ps)}
        if seg is not None:
            res.update(seg(fld))
        return res

    return _eval


def _segmentation(method, scene, views, config: dict) -> Optional[Callable[[GaussianField], dict]]:
    """The periodic segmentation mIoU of a semantic method on the eval views (training resolution):
    {"miou_3dovs": .., "miou_lerf": ..} for the protocols the scene supports; {} while the field has
    no latents or the method no autoencoder yet (e.g. twostage's rgb phase); None when the scene has
    no segmentation GT or there are no eval views."""
    if not views.eval_cameras or not (scene.has_semantics or scene.has_labels):
        return None
    ids = sorted(views.eval_cameras)
    cams = [views.eval_cameras[i] for i in ids]

    def _sem(fld: GaussianField) -> dict:
        probe = method.with_field(fld)      # the method's own view of this field (Method.with_field)
        if not probe.has_semantics:   # e.g. no latents yet, or no autoencoder yet (twostage's rgb phase)
            return {}
        try:   # build (and cache) the text encoder once, on the real method
            method.feature_provider()
        except (InputError, ImportError, OSError) as e:
            # e.g. CLIP weights missing while the priors came from the cache: training goes on, and
            # the log says why this entry has no mIoU (gsbench eval will raise the same error)
            return {"miou_skipped": f"text encoder unavailable: {type(e).__name__}: {e}"}
        metrics, skipped = segmentation_metrics(probe, scene, ids, cams, config)
        out = {k: float(metrics[k]) for k in ("miou_3dovs", "miou_lerf") if metrics.get(k) is not None}
        if out:
            out["query_mode"] = setting(config, "query.mode")
        elif skipped:   # e.g. the eval views carry no segmentation GT
            out["miou_skipped"] = "; ".join(f"{k}: {v}" for k, v in sorted(skipped.items()))
        return out

    return _sem


__all__ = ["train_method", "run_phase", "periodic_eval"]
