"""`gsbench publish --page PAGE --from results/cpu results/gpu`: another backend's store adds an 'Across
backends' section, its cells classified against the plan on its own backend (as scripts/gpu_claims.py
runs it), one verdict column per store, and whether the verdicts agree."""
from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from gsbench.cli import main
from gsbench.config import run_id as make_run_id
from gsbench.grids.planning import cell_config, settle_on_spec
from gsbench.grids.store import plan_for, plan_on_backend
from gsbench.reports.claims_backends import AGREE, DIFFER, MISSING, agreement, verdict_class

ROOT = Path(__file__).resolve().parents[2]
STORE = ROOT / "results" / "cpu"
GRID = "latent_dim-fewview-cpu"       # 9 published cells: d 3, 16, 32 at 3 seeds, two claims
RISES = "mIoU rises from d = 3 to d = 16"


def test_verdict_words_and_agreement():
    assert verdict_class("opposite (fails Holm; after a second look)") == "opposite"
    assert verdict_class("blind: control ds_mbiou_fewview unmarked") == "blind"
    assert verdict_class("not reproduced (fails Holm): at most +0.69, paper +2.78") == "not reproduced"
    assert agreement(["blind: no control in this regime", "blind: control depth_psnr unmarked"]) == AGREE
    assert agreement(["reproduced", "reproduced (fails Holm)"]) == AGREE
    assert agreement(["reproduced", "opposite"]) == DIFFER
    assert agreement(["reproduced", None]) == MISSING


def _cells(store: Path) -> list[Path]:
    return sorted((store / GRID).glob("*.json"))


def _copy(dst: Path) -> Path:
    (dst / GRID).mkdir(parents=True)
    shutil.copytree(STORE / "_shared", dst / "_shared")
    for p in _cells(STORE):
        shutil.copy(p, dst / GRID / p.name)
    return dst


def _gsplat_store(dst: Path, scale_d16: float = 1.0) -> Path:
    """The grid's cells as if trained with backend gsplat: each under the run id the gsplat plan gives
    its seed and axes, mIoU of the d = 16 cells scaled by `scale_d16`."""
    grid = plan_on_backend(plan_for([GRID]), "gsplat")[0]
    (dst / GRID).mkdir(parents=True)
    shutil.copytree(STORE / "_shared", dst / "_shared")
    for p in _cells(STORE):
        rec = json.loads(p.read_text(encoding="utf-8"))
        planned = [x for x in grid.cells() if x.seed == rec["cell"]["seed"] and x.axes == rec["cell"]["axes"]]
        assert len(planned) == 1
        x = planned[0]
        rid = make_run_id(settle_on_spec(cell_config(x, Path("."), grid.axis_keys), x.scene), rec["scene_fingerprint"])
        assert rid != rec["run_id"]             # the backend is part of the config, so of the run id
        rec["run_id"], rec["config"]["run_id"], rec["config"]["backend"] = rid, rid, "gsplat"
        if rec["cell"]["axes"].get("semantic.latent_dim") == 16:
            for k, v in rec["results"]["metrics"].items():
                if k.startswith("miou") and isinstance(v, float):
                    rec["results"]["metrics"][k] = v * scale_d16
        (dst / GRID / f"{rid}.json").write_text(json.dumps(rec, indent=2), encoding="utf-8")
    return dst


def _across(page: Path) -> dict[str, str]:
    """Claim text -> the 'Across backends' cell of its row in the page's section."""
    text = page.read_text(encoding="utf-8")
    assert "## Across backends" in text
    section = text.split("## Across backends", 1)[1].split("\n## ", 1)[0]
    rows = [ln.split(" | ") for ln in section.splitlines() if ln.startswith("| mIoU")]
    return {r[0].lstrip("| "): r[-1].rstrip(" |") for r in rows}


def test_the_same_verdicts_agree_and_a_flipped_one_differs(tmp_path, capsys):
    cpu = _copy(tmp_path / "cpu")
    page = tmp_path / "page" / "claims.md"
    page.parent.mkdir()
    same = _gsplat_store(tmp_path / "gpu_same")
    assert main(["publish", "--page", str(page), "--from", str(cpu), str(same), "--grids", GRID]) == 0
    got = _across(page)
    assert got == {RISES: AGREE, "mIoU falls from d = 16 to d = 32": AGREE}
    text = page.read_text(encoding="utf-8")
    assert f"--from results/cpu {same}" in text and "results/cpu (cpu)" in text and f"{same} (gsplat)" in text

    capsys.readouterr()
    assert main(["publish", "--status", str(same), "--grids", GRID]) == 0      # against the plan on gsplat
    assert "9 published cells: 9 current, 0 stale" in capsys.readouterr().out

    flipped = _gsplat_store(tmp_path / "gpu_flipped", scale_d16=0.5)      # d 16 far below d 3 on "gsplat"
    assert main(["publish", "--page", str(page), "--from", str(cpu), str(flipped), "--grids", GRID]) == 0
    assert _across(page)[RISES] == DIFFER


def test_one_store_has_no_section_and_a_mixed_store_is_refused(tmp_path, capsys):
    cpu = _copy(tmp_path / "cpu")
    page = tmp_path / "claims.md"
    assert main(["publish", "--page", str(page), "--from", str(cpu), "--grids", GRID]) == 0
    assert "Across backends" not in page.read_text(encoding="utf-8")
    mixed = _gsplat_store(tmp_path / "mixed")
    shutil.copy(_cells(STORE)[0], mixed / GRID / _cells(STORE)[0].name)      # one cpu cell among gsplat ones
    assert main(["publish", "--page", str(page), "--from", str(cpu), str(mixed), "--grids", GRID]) == 1
    err = capsys.readouterr().err
    assert "mixed" in err and "expected the cells of one backend, found cpu, gsplat" in err


@pytest.fixture(autouse=True)
def _store_present():
    if not _cells(STORE):
        pytest.skip(f"{STORE / GRID}: no published cell")
