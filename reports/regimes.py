"""Regimes: where a cell ran (its scene, its training views, its preset and its prior providers),
derived from the cell's stored config, and whether a control's regime is a claim's.

Why: a positive control shows that the harness can see a mechanism in the setting the control ran in,
and nowhere else. A control that marks at 3 training views says nothing about a claim decided at 21,
where the same term may not act at all. So a control guards a claim only in the claim's own regime
(methods/gaussiands/study_table.py, `Regime`); the one difference allowed is the exact version of the
claim's depth prior (the gt prior at distortion 0), and the guard says so. The claims page's matrix
has one column per declared regime (`REGIMES` there).
"""
from __future__ import annotations

import functools
import math
from pathlib import Path
from typing import Any

from gsbench import rundir
from gsbench.config import CONFIG_DIR, preset_path, settled_value, shipped_presets
from gsbench.methods.gaussiands.study_table import REGIMES, DeclaredRegime, Regime
from gsbench.reports.data import Results, is_null
from gsbench.reports.studies import PROTOCOL_SHORT
from gsbench.store import read_json
from gsbench.yaml_reader import load_yaml_file

EXACT_DEPTH = "exact depth prior"   # the guard's note when the control used the exact version of the depth prior
UNKNOWN = "?"


def _train_section(path: Path) -> dict:
    data = load_yaml_file(path)
    train = data.get("train") if isinstance(data, dict) else None
    return train if isinstance(train, dict) else {}


@functools.lru_cache(maxsize=1)
def preset_schedules() -> dict[tuple, str]:
    """(train.iterations, train.max_width) -> the shipped preset that gives them (default.yaml under the
    preset); the first preset in name order when two give the same schedule."""
    default = _train_section(CONFIG_DIR / "default.yaml")
    out: dict[tuple, str] = {}
    for name in shipped_presets():
        train = {**default, **_train_section(preset_path(name))}
        out.setdefault((train.get("iterations"), train.get("max_width")), name)
    return out


def preset_of(config: dict) -> str:
    """The preset a resolved config was made from, recognised by its schedule (train.iterations and
    train.max_width); 'custom (N steps, width W)' when no shipped preset gives it, '?' without a train
    section."""
    train = config.get("train")
    if not isinstance(train, dict) or "iterations" not in train:
        return UNKNOWN
    key = (train.get("iterations"), train.get("max_width"))
    return preset_schedules().get(key) or f"custom ({key[0]} steps, width {key[1]})"


def _provider(priors: dict, kind: str) -> str:
    section = priors.get(kind)
    prov = section.get("provider") if isinstance(section, dict) else None
    return str(prov) if prov is not None else UNKNOWN


def regime_of(config: Any, scene: str) -> Regime:
    """A cell's regime from its resolved config (missing parts read '?'): the depth prior's noise, the
    masks' failure settings and the ordering are study settings, not part of the regime."""
    config = config if isinstance(config, dict) else {}
    priors = config.get("priors") if isinstance(config.get("priors"), dict) else {}
    depth = _provider(priors, "depth")
    if depth == "auto":   # what `auto` chose on the cell's scene, when the config records it
        depth = settled_value(config, "priors.depth.provider") or depth
    dist = (priors.get("depth") or {}).get("distortion") if isinstance(priors.get("depth"), dict) else None
    distortion = float(dist) if depth == "gt" and isinstance(dist, (int, float)) and math.isfinite(dist) else None
    train = config.get("train") if isinstance(config.get("train"), dict) else {}
    views = train.get("views")
    return Regime(str(scene), int(views) if isinstance(views, int) and not isinstance(views, bool) else None,
                  preset_of(config), depth, distortion, _provider(priors, "masks"), _provider(priors, "features"))


def run_regimes(res: Results) -> dict[str, Regime]:
    """Run id -> regime, from the config in each run's results.json (read once per Results)."""
    if res.regime_cache is None:
        out: dict[str, Regime] = {}
        for rid in res.runs.index:
            config: Any = None
            run_dir = res.runs.at[rid, "run_dir"] if "run_dir" in res.runs.columns else None
            if not is_null(run_dir):
                try:
                    config = (read_json(Path(str(run_dir)) / rundir.RESULTS) or {}).get("config")
                except FileNotFoundError:
                    config = None
            out[str(rid)] = regime_of(config, str(res.runs.at[rid, "scene"]))
        res.regime_cache = out
    return res.regime_cache


def declared(regime: Regime) -> DeclaredRegime | None:
    """The declared regime (a column of the matrix) this regime is, if any."""
    return next((d for d in REGIMES if d.regime == regime), None)


def depth_text(regime: Regime) -> str:
    """'gt d1', 'gt d0 (exact)', 'sfm': the depth provider and, for gt, its distortion."""
    if regime.depth_distortion is None:
        return regime.depth
    return f"{regime.depth} d{regime.depth_distortion:g}" + (" (exact)" if regime.depth_distortion == 0.0 else "")


def regime_label(regime: Regime, protocol: Any = None, kinds: dict[str, str] | None = None,
                 name: bool = True) -> str:
    """'tabletop-medium-0 (synthetic; 3D-OVS), all views, cpu-medium, depth gt d1, masks simulated, features
    text-aligned', prefixed by the declared regime's name when it is one (and `name`)."""
    kind = (kinds or {}).get(regime.scene)
    proto = PROTOCOL_SHORT.get(protocol, protocol) if protocol is not None else None
    inner = "; ".join(str(x) for x in (kind, proto) if x)
    views = "all views" if regime.views is None else f"{regime.views} views"
    text = (f"{regime.scene}{f' ({inner})' if inner else ''}, {views}, {regime.preset}, depth {depth_text(regime)}, "
            f"masks {regime.masks}, features {regime.features}")
    d = declared(regime) if name else None
    return f"{d.name}: {text}" if d else text


def guard_note(control: Regime, claim: Regime) -> str | None:
    """'' when a control that ran in `control` guards a claim in `claim` (the same regime), EXACT_DEPTH when
    it differs only by using the exact version of the claim's depth prior, None when it does not guard."""
    if control == claim:
        return ""
    return EXACT_DEPTH if claim.exact_depth() == control else None


def differences(a: Regime, b: Regime) -> list[str]:
    """What a control's regime `a` has that a claim's regime `b` does not ('masks gt, not simulated'), field
    by field; the exact version of `b`'s depth prior is not a difference (a guard may use it)."""
    out = []
    exact = b.exact_depth()
    depth_ok = exact is not None and (a.depth, a.depth_distortion) == (exact.depth, exact.depth_distortion)
    for name, x, y in (("scene", a.scene, b.scene), ("views", a.views or "all", b.views or "all"),
                       ("preset", a.preset, b.preset),
                       ("depth", depth_text(b) if depth_ok else depth_text(a), depth_text(b)),
                       ("masks", a.masks, b.masks), ("features", a.features, b.features)):
        if x != y:
            out.append(f"{name} {x}, not {y}")
    return out
