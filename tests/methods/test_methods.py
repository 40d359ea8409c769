"""Method pieces: autoencoder round trip, removal, densification bookkeeping, LR schedule, persistence."""
import math

import numpy as np
import pytest
import torch

from gsbench.gaussians import GaussianField
from gsbench.methods import Method, get_method
from gsbench.methods.base import removal_mask
from gsbench.train.autoencoder import FeatureAutoencoder, train_autoencoder
from gsbench.train.densify import DensifyStats, ParamSet, densify_and_prune, expon_lr, reset_opacity


def test_autoencoder_round_trips_text_aligned_features():
    from gsbench.priors.features import TextAlignedFeatures
    prov = TextAlignedFeatures(noise=0.05)
    names = ["ball", "box", "can", "floor", "globe", "orange", "poster", "wall"]
    T = prov.encode_text(names)                        # (8, 512) unit rows
    rng = np.random.default_rng(0)
    feats, labels = [], []
    for k in range(len(names)):                        # 12 noisy "mask" features per class
        x = T[k] + rng.normal(0, 0.05 / math.sqrt(512), (12, 512))
        feats.append(x / np.linalg.norm(x, axis=1, keepdims=True))
        labels += [k] * 12
    F = np.concatenate(feats).astype(np.float32)
    ae, stats = train_autoencoder(F, latent_dim=3, epochs=300, lr=1e-3, seed=0)
    with torch.no_grad():
        z = ae.encode(torch.from_numpy(F))
        rec = ae.decode(z).numpy()
    assert z.shape == (len(F), 3)
    np.testing.assert_allclose(np.linalg.norm(z.numpy(), axis=1), 1.0, atol=1e-5)   # L2-normalised latent
    # the decoded vector is closest (in CLIP space) to its own class text, and close to the input
    pred = np.argmax(rec @ T.T, axis=1)
    np.testing.assert_array_equal(pred, np.array(labels))
    assert float(np.mean(np.sum(rec * F, axis=1))) > 0.9
    # encode-mode query: the encoded text is nearest (cosine in d) to its own class's latents
    with torch.no_grad():
        q = ae.encode(torch.from_numpy(T)).numpy()
    centroids = np.stack([z.numpy()[np.array(labels) == k].mean(0) for k in range(len(names))])
    assert (np.argmax(q @ centroids.T, axis=1) == np.arange(len(names))).all()
    assert not any(p.requires_grad for p in ae.parameters())                        # frozen


def test_autoencoder_is_seeded_and_shape():
    F = np.random.default_rng(0).normal(size=(10, 512)).astype(np.float32)
    a, _ = train_autoencoder(F, 4, epochs=5, seed=3)
    b, _ = train_autoencoder(F, 4, epochs=5, seed=3)
    for pa, pb in zip(a.parameters(), b.parameters()):
        assert torch.equal(pa, pb)
    ae = FeatureAutoencoder(512, 6)
    dims = [m.out_features for m in ae.encoder if isinstance(m, torch.nn.Linear)]
    assert dims == [256, 128, 64, 32, 6]
    assert [m.out_features for m in ae.decoder if isinstance(m, torch.nn.Linear)] == [32, 64, 128, 256, 512]


def _field(n, d=3, features=None):
    g = torch.Generator().manual_seed(0)
    return GaussianField(torch.randn(n, 3, generator=g), torch.full((n, 3), -2.0),
                         torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1), torch.zeros(n), torch.rand(n, 1, 3, generator=g),
                         features if features is not None else torch.randn(n, d, generator=g))


def test_removal_mask_exact_threshold():
    q = torch.tensor([1.0, 0.0, 0.0])
    lat = torch.tensor([[2.0, 0.0, 0.0],       # cos 1      -> removed
                        [1.0, 1.0, 0.0],       # cos .7071  -> kept at 0.9, removed at 0.7
                        [-1.0, 0.0, 0.0],      # cos -1
                        [0.0, 0.0, 0.0],       # no direction -> never removed
                        [0.95, 0.3122499, 0.0]])  # cos = 0.95 / sqrt(0.95^2 + 0.31225^2) = 0.95
    np.testing.assert_array_equal(removal_mask(lat, q, 0.9).numpy(), [True, False, False, False, True])
    np.testing.assert_array_equal(removal_mask(lat, q, 0.7).numpy(), [True, True, False, False, True])
    np.testing.assert_array_equal(removal_mask(lat, q, 0.96).numpy(), [True, False, False, False, False])


def test_method_remove_prunes_exactly_above_threshold():
    g = torch.Generator().manual_seed(1)
    feats = torch.randn(200, 3, generator=g)
    m = get_method("gaussiands")()
    m.field = _field(200, features=feats)
    m.autoencoder = FeatureAutoencoder(512, 3)
    q = torch.tensor([0.3, -0.5, 0.8])
    m.embed_text = lambda texts, mode="encode": q[None]   # the query embedding, fixed for the test
    thr = 0.8
    cos = (feats.numpy() @ q.numpy()) / (np.linalg.norm(feats.numpy(), axis=1) * np.linalg.norm(q.numpy()))
    expect_keep = cos <= thr
    out, n = m.remove("anything", thr)
    assert n == int((~expect_keep).sum()) and n > 0
    np.testing.assert_allclose(out.field.means.numpy(), m.field.means.numpy()[expect_keep])
    assert m.field.num == 200                              # the original is untouched


def test_methods_without_semantics_return_none():
    m = get_method("vanilla")()
    m.field = _field(5, features=None).with_features(None)
    from gsbench.camera import Camera
    cam = Camera(np.array([[20.0, 0, 8], [0, 20, 6], [0, 0, 1]]), np.eye(4), 16, 12)
    assert m.semantic_features(cam, "encode") is None and m.embed_text(["x"], "decode") is None
    with pytest.raises(ValueError):
        m.remove("x", 0.5)
    with pytest.raises(ValueError):
        m.semantic_features(cam, "bogus")


def test_decoded_features_are_the_same_in_chunks(monkeypatch):
    """Decode mode decodes in row chunks (memory at full size); chunking must not change any pixel."""
    from gsbench.camera import Camera
    from gsbench.render import RenderOutput
    from gsbench.train import feature_blocks as FB
    m = get_method("gaussiands")()
    m.field = _field(5)
    torch.manual_seed(0)
    m.autoencoder = FeatureAutoencoder(16, 3, (8, 4))
    feats = torch.randn(12, 16, 3)
    monkeypatch.setattr(m, "render", lambda cam: RenderOutput(torch.zeros(12, 16, 3), torch.zeros(12, 16), feats,
                                                              torch.ones(12, 16)))
    cam = Camera(np.array([[20.0, 0, 8], [0, 20, 6], [0, 0, 1]]), np.eye(4), 16, 12)
    whole = m.autoencoder.decode(feats.reshape(-1, 3)).reshape(12, 16, 16)
    monkeypatch.setattr(FB, "BLOCK_ROWS", 7)            # 192 pixels in 28 blocks, the last one partial
    chunked = m.semantic_features(cam, "decode")
    assert chunked.shape == (12, 16, 16)
    torch.testing.assert_close(chunked, whole, rtol=1e-6, atol=1e-6)


def test_decoding_in_chunks_changes_no_bit_at_the_real_sizes():
    """Evaluation decodes a map BLOCK_ROWS pixels at a time for speed; the default autoencoder's
    matrix products must give each row the same bits whatever the rows around it, so the scores do
    not depend on the chunk size (a BLAS that splits the inner sums by row count would fail here)."""
    from gsbench.train.feature_blocks import BLOCK_ROWS, FeatureBlocks
    torch.manual_seed(1)
    ae = FeatureAutoencoder(512, 3)
    z = torch.nn.functional.normalize(torch.randn(3, BLOCK_ROWS + 41, 3), dim=-1)   # 3 blocks, the last partial
    with torch.no_grad():
        whole = ae.decode(z.reshape(-1, 3)).reshape(3, BLOCK_ROWS + 41, 512)
        blocks = FeatureBlocks.of_map(z, ae.decode)
        assert [b.shape[0] for b in blocks.blocks()] == [BLOCK_ROWS, BLOCK_ROWS, BLOCK_ROWS, 123]
        assert torch.equal(blocks.join(), whole)


def test_feature_blocks_cover_the_map_once_in_pixel_order():
    """Without a function a map is one block (no copy); with one, blocks of BLOCK_ROWS pixels in order,
    each computed when read, and join() gives the whole (H, W, D) map."""
    from gsbench.train.feature_blocks import FeatureBlocks
    x = torch.arange(2 * 5 * 3, dtype=torch.float32).reshape(2, 5, 3)
    one = list(FeatureBlocks.of_map(x).blocks())
    assert len(one) == 1 and one[0].data_ptr() == x.data_ptr() and torch.equal(FeatureBlocks.of_map(x).join(), x)
    calls = []
    fb = FeatureBlocks.of_map(x, lambda b: (calls.append(b.shape[0]), torch.cat([b, -b], 1))[1], rows=4)
    assert calls == []                                    # nothing computed before it is read
    assert torch.equal(fb.join(), torch.cat([x, -x], 2)) and calls == [4, 4, 2]
    assert (fb.height, fb.width) == (2, 5)


def test_save_load_round_trip(tmp_path):
    m = get_method("gaussiands")()
    m.field = _field(7)
    m.autoencoder = FeatureAutoencoder(512, 3)
    m.config = {"train": {"background": [0, 0, 0]}, "priors": {"features": {"provider": "text-aligned", "noise": 0.05}}}
    m.providers = {"depth": "gt", "masks": "sim", "features": "f", "ordering": "pose"}
    m.save(tmp_path / "model.pt")
    m2 = Method.load(tmp_path / "model.pt")
    assert type(m2).__name__ == "GaussianDS" and m2.provider_ids() == m.providers
    # load() puts a model saved with the torch backend on CUDA where there is one (docstring)
    dev = torch.device("cuda:0" if torch.cuda.is_available() else "cpu")
    assert m2.field.features.device == dev
    assert torch.equal(m2.field.features.cpu(), m.field.features)
    x = torch.randn(4, 512)
    assert torch.allclose(m2.autoencoder.encode(x.to(dev)).cpu(), m.autoencoder.encode(x), atol=1e-5)
    # embed_text goes through the provider and the AE encoder: unit (Q, d) in encode mode, (Q, 512) in decode mode
    e = m2.embed_text(["ball", "box"], "encode").cpu()
    assert e.shape == (2, 3) and torch.allclose(e.norm(dim=-1), torch.ones(2), atol=1e-5)
    assert m2.embed_text(["ball"], "decode").shape == (1, 512)
    (tmp_path / "bad.pt").write_bytes(b"garbage")
    with pytest.raises(ValueError, match="bad.pt"):
        Method.load(tmp_path / "bad.pt")


def test_get_method_unknown():
    with pytest.raises(ValueError, match="unknown method"):
        get_method("nerf")


# ---------------------------------------------------------------------------- densification
def _paramset(n):
    f = _field(n)
    return ParamSet({k: v for k, v in f.tensors().items()}, {k: 1e-3 for k in f.tensors()})


def test_clone_split_prune_counts_and_adam_state():
    n = 6
    ps = _paramset(n)
    # take one optimiser step so Adam state exists
    loss = sum((p ** 2).sum() for p in ps.params.values())
    loss.backward()
    ps.optimizer.step()
    ls = ps.params["log_scales"].data
    ls[:3] = math.log(0.001)        # small: clone candidates
    ls[3:] = math.log(1.0)          # big (> percent_dense * extent = 0.01): split candidates
    op = ps.params["opacity_logits"].data
    op[:] = 5.0
    op[2] = -10.0                   # opacity 4.5e-5 < 0.005: pruned (and as a clone source its clone is pruned too)
    stats = DensifyStats(n)
    stats.grad[:] = torch.tensor([1.0, 1.0, 1.0, 1.0, 0.0, 1.0])
    stats.count[:] = 1.0
    cfg = {"grad_threshold": 0.5, "percent_dense": 0.01, "prune_opacity": 0.005, "max_screen_size": 20,
           "max_gaussians": 0}
    info = densify_and_prune(ps, stats, cfg, extent=1.0, prune_big=False, generator=torch.Generator().manual_seed(0))
    # clones: 0,1,2 (+3); splits: 3,5 -> +4, -2 sources; prune: 2 and its clone
    assert info["cloned"] == 3 and info["split"] == 2
    assert ps.num == 6 + 3 + 4 - 2 - 2
    for name, p in ps.params.items():
        st = ps.optimizer.state[p]
        assert st["exp_avg"].shape == p.shape and st["exp_avg_sq"].shape == p.shape
        assert ps.group(name)["params"][0] is p
    # split children have scale / 1.6
    child_scales = torch.exp(ps.params["log_scales"].data).max(-1).values
    assert torch.isclose(child_scales, torch.tensor(1.0 / 1.6)).sum() == 4
    assert stats.grad.shape == (ps.num,)


def test_max_gaussians_cap_and_opacity_reset():
    ps = _paramset(10)
    ps.params["log_scales"].data[:] = math.log(0.001)
    stats = DensifyStats(10)
    stats.grad[:] = torch.arange(10.0)
    stats.count[:] = 1
    cfg = {"grad_threshold": 0.5, "percent_dense": 0.01, "prune_opacity": 0.0, "max_screen_size": 20,
           "max_gaussians": 13}
    info = densify_and_prune(ps, stats, cfg, 1.0, False, torch.Generator().manual_seed(0))
    assert ps.num == 13 and info["cloned"] == 3
    ps.params["opacity_logits"].data[:] = 4.0
    reset_opacity(ps, 0.01)
    assert torch.allclose(torch.sigmoid(ps.params["opacity_logits"].data), torch.full((13,), 0.01), atol=1e-6)


def test_expon_lr_endpoints_and_midpoint():
    assert expon_lr(0, 1e-2, 1e-4, 100) == pytest.approx(1e-2)
    assert expon_lr(100, 1e-2, 1e-4, 100) == pytest.approx(1e-4)
    assert expon_lr(50, 1e-2, 1e-4, 100) == pytest.approx(1e-3)          # log-linear
    assert expon_lr(500, 1e-2, 1e-4, 100) == pytest.approx(1e-4)
    assert expon_lr(0, 1e-2, 1e-4, 100, delay_steps=10, delay_mult=0.01) == pytest.approx(1e-4)


