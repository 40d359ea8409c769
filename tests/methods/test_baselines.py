"""Baselines as strong as their papers: SH schedule and rest-band LR, twostage's semantic budget,
frustum initialisation of forward-facing scenes, loss shares in the train log."""
import numpy as np
import pytest

from gsbench.camera import Camera
from gsbench.config import load_config
from gsbench.runs import train_run
from gsbench.store import load_torch, read_json, read_jsonl
from gsbench.train.initial_field import frustum_points
from gsbench.train.trainer import sh_active_degree

TINY = ["backend=cpu", "train.iterations=12", "train.max_width=32", "train.eval_every=0", "train.log_every=4",
        "train.checkpoint_every=0", "train.eval_views=1", "train.densify.enabled=false",
        "semantic.autoencoder.epochs=10", "train.init.max_points=300"]


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    from gsbench.datasets.synthetic import make_scene
    return make_scene("tabletop-small", tmp_path_factory.mktemp("s") / "tabletop", seed=0, views=8, resolution=(32, 24))


def test_sh_schedule_is_3dgs():
    assert [sh_active_degree(s, 3, 1000) for s in (0, 999, 1000, 2500, 3000, 29999)] == [0, 0, 1, 2, 3, 3]
    assert sh_active_degree(0, 3, 0) == 3 and sh_active_degree(5000, 0, 1000) == 0


def test_paper_preset_uses_sh3_and_twostage_gets_the_same_semantic_budget():
    c = load_config("vanilla", "paper")
    assert c["train"]["sh_degree"] == 3 and c["train"]["sh_increase_every"] == 1000
    assert c["train"]["lr"]["color_rest_factor"] == pytest.approx(1 / 20)
    from gsbench.methods.twostage_spec import semantic_budget
    t = load_config("twostage", "paper")
    assert semantic_budget(t) == t["train"]["iterations"] == 30000


def test_sh3_run_logs_bands_and_rest_lr(scene, tmp_path):
    cfg = load_config("vanilla", "cpu-small", TINY + ["train.sh_degree=3", "train.sh_increase_every=4"])
    run = train_run(cfg, scene, tmp_path / "v", progress=False)
    log = [r for r in read_jsonl(run / "train_log.jsonl") if "loss" in r]
    assert [r["sh_degree"] for r in log] == [0, 1, 2]         # steps 4, 8, 12 -> degree (step-1)//4
    assert all(r["loss_share"] == {"rec": 1.0} for r in log)
    ck = load_torch(run / "checkpoint.pt")
    lr = {g["name"]: g["lr"] for g in ck["optimizer"]["param_groups"]}
    assert lr["colors_rest"] == pytest.approx(lr["colors"] / 20)
    assert ck["params"]["colors"].shape[1:] == (1, 3) and ck["params"]["colors_rest"].shape[1:] == (15, 3)
    assert float(ck["params"]["colors_rest"].abs().sum()) > 0      # bands 1..2 were trained
    s = read_json(run / "train_summary.json")
    assert s["info"]["budget"] == {"rgb_steps": 12, "semantic_steps": 0, "schedule": "none"}
    from gsbench.evaluation.trained_run import load_run
    m, _, sc = load_run(run)
    assert m.field.sh_degree == 3 and m.device.type in ("cpu", "cuda")


def test_twostage_budget_and_gaussiands_loss_share(scene, tmp_path):
    t = train_run(load_config("twostage", "cpu-small", TINY), scene, tmp_path / "t", progress=False)
    st = read_json(t / "train_summary.json")["info"]["budget"]
    assert st == {"rgb_steps": 12, "semantic_steps": 12, "schedule": "after rgb"}
    assert max(r["step"] for r in read_jsonl(t / "train_log.jsonl") if r["phase"] == "semantic") == 12
    g = train_run(load_config("gaussiands", "cpu-small", TINY), scene, tmp_path / "g", progress=False)
    joint = {"rgb_steps": 12, "semantic_steps": 12, "schedule": "joint"}
    assert read_json(g / "train_summary.json")["info"]["budget"] == joint
    for r in (r for r in read_jsonl(g / "train_log.jsonl") if "loss" in r):
        sh = r["loss_share"]
        assert set(sh) == {"rec", "depth", "tv", "sem", "ds"} and sum(sh.values()) == pytest.approx(1.0)
        assert all(0.0 <= v <= 1.0 for v in sh.values())


def test_frustum_points_lie_inside_the_bounds():
    K = np.array([[30.0, 0, 16], [0, 30.0, 12], [0, 0, 1]])
    cams = []
    for x in (-0.2, 0.0, 0.2):
        w2c = np.eye(4)
        w2c[:3, 3] = [-x, 0.0, 0.0]
        cams.append(Camera(K, w2c, 32, 24))
    p = frustum_points(cams, 2.0, 8.0, 2000, seed=0)
    z = p[:, 2]
    assert z.min() >= 2.0 - 1e-9 and z.max() <= 8.0 + 1e-9
    seen = np.zeros(len(p), bool)
    for c in cams:
        uv, zz = c.project(p)
        seen |= (zz > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= 32) & (uv[:, 1] >= 0) & (uv[:, 1] <= 24)
    assert seen.all()
    # uniform in inverse depth: half the points nearer than the harmonic midpoint 1 / ((1/2 + 1/8) / 2) = 3.2
    assert abs(np.mean(z < 3.2) - 0.5) < 0.05
    with pytest.raises(ValueError, match="near"):
        frustum_points(cams, 5.0, 1.0, 10, seed=0)


def test_auto_init_mode_per_layout():
    from types import SimpleNamespace

    from gsbench.train.initial_field import init_mode
    cfg = {"train": {"init": {"mode": "auto"}}}
    bounds = {"near": 1.0, "far": 5.0}
    assert init_mode(SimpleNamespace(has_points=True, layout="llff", meta=bounds), cfg) == "points"
    assert init_mode(SimpleNamespace(has_points=False, layout="llff", meta=bounds), cfg) == "frustum"
    assert init_mode(SimpleNamespace(has_points=False, layout="3dovs", meta=bounds), cfg) == "frustum"
    assert init_mode(SimpleNamespace(has_points=False, layout="llff", meta={}), cfg) == "random"
    assert init_mode(SimpleNamespace(has_points=False, layout="nerf", meta=bounds), cfg) == "random"
    assert init_mode(SimpleNamespace(has_points=False, layout="llff", meta=bounds),
                     {"train": {"init": {"mode": "random"}}}) == "random"


def test_frustum_init_on_a_forward_facing_scene_without_points(tmp_path):
    """A generated scene read as LLFF (poses_bounds.npy, no sparse/): the initial Gaussians lie between
    its near and far bounds in front of the training cameras."""
    from gsbench.datasets import load_scene
    from gsbench.datasets.synthetic import make_scene
    from gsbench.train.initial_field import scene_init
    root = make_scene("tabletop-small", tmp_path / "s", seed=0, views=6, resolution=(32, 24))
    if not (root / "poses_bounds.npy").is_file():
        pytest.skip("the generator wrote no poses_bounds.npy for this preset")
    sc = load_scene(root, layout="llff")
    assert not sc.has_points and "near" in sc.meta
    cfg = load_config("vanilla", "cpu-small", ["train.init.num_random=500"])
    fld, how = scene_init(sc, cfg, 0)
    assert how.startswith("frustum") and fld.num == 500
    xyz = fld.means.numpy()
    zs = np.stack([sc.cameras[i].project(xyz)[1] for i in sc.train_ids])
    near, far = sc.meta["near"], sc.meta["far"]
    assert (zs > 0).all()                                          # in front of every training camera
    assert ((zs >= near * (1 - 1e-6)) & (zs <= far * (1 + 1e-6))).any(0).all()   # within bounds of its camera


def test_gaussiands_says_when_the_depth_edge_map_is_empty(scene, tmp_path, caplog):
    """Canny thresholds above any 8-bit gradient (the Sobel sum peaks at 2040) leave E_d empty: training
    says so (a warning, the count of empty views in the summary) instead of running L_ds on nothing in
    silence."""
    cfg = load_config("gaussiands", "cpu-small", TINY + ["train.iterations=2", "gaussiands.edges.canny_low=5000",
                                                    "gaussiands.edges.canny_high=6000"])
    with caplog.at_level("WARNING", logger="gsbench.methods.gaussiands.method"):
        g = train_run(cfg, scene, tmp_path / "g", progress=False)
    info = read_json(g / "train_summary.json")["info"]
    n_train = 7                                      # 8 views, every 8th held out
    assert info["edge_fraction"] == 0.0 and info["edge_views_empty"] == n_train
    said = [r.getMessage() for r in caplog.records if "E_d" in r.getMessage()]
    assert len(said) == 1 and "covers 0.000 %" in said[0] and f"{n_train} of {n_train} views" in said[0]
