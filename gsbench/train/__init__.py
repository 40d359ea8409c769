"""gsbench.train: the training engine every method shares.

    trainer.py          Trainer: one optimisation phase and its step; LossResult, StepContext, make_trainer
    strategy.py         Strategy: how the Gaussians are densified and pruned (DefaultStrategy: 3DGS's ADC)
    densify.py          ParamSet (the trainable tensors and their Adam) and the 3DGS clone / split / prune ops
    adam.py             Adam (fused, bit-identical to torch.optim.Adam on the CPU)
    losses.py           the loss terms (L_rec, depth, TV, semantic, L_ds); losses_cpu.py, ssim_cpu.py: their CPU kernels
    views.py            TrainViews and load_views: the training and periodic-evaluation views
    initial_field.py    the initial Gaussians of a run (points, random cube, frusta)
    residency.py        where per-view training data lives (device or host)
    render_backend.py   the run's render backend, resolved and prepared before any work
    autoencoder.py      the frozen feature autoencoder; semantic_targets.py: the per-pixel latent targets
    feature_blocks.py   a rendered feature map handed out in blocks of pixels

The loop around the steps (logging, periodic evaluation, checkpoints, resume) is the harness's,
gsbench/runs/training.py. The engine imports no method: methods (gsbench.methods) build on it.
Importing this package imports nothing; import the module you need.
"""
