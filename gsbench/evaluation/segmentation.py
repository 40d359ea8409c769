"""Segmentation scoring of a trained method: every registered protocol (gsbench.evaluation.protocol_registry)
per query mode and frame set, each under its fork.

Query modes: "encode" (the paper: text encoded into the latent space) and "decode" (LangSplat:
latents decoded to CLIP space); each mode's metric ids end in "+query-<mode>". The un-suffixed
names carry the configured `query.mode`. Frame sets: see gsbench.evaluation.frames.

Each scored frame is rendered once for every protocol and query mode (`frame_outputs`): the
rendered latents serve the encode mode, their decoding (only when the decode mode is scored, a
block of pixels at a time, each block scored against every protocol's texts while it is in the
cache) serves the decode mode, and each protocol keeps only its small per-frame result (its
`frame_output`: a 3D-OVS class map, LERF relevancy maps) before the next frame is rendered.
"""
from __future__ import annotations

import logging
from typing import Optional

import numpy as np
from threadpoolctl import threadpool_limits

from gsbench.config import setting
from gsbench.config_keys import PROTOCOLS, QUERY_MODES
from gsbench.errors import InputError
from gsbench.metrics import pixel_norms, pixel_text_cosines
from gsbench.train.feature_blocks import FeatureBlocks

from .block import Block, to_numpy
from .protocol_registry import AUTO, ProtocolContext, get_protocol, parse_request, protocols

log = logging.getLogger(__name__)


def resolve_protocols(scene, protocol: str) -> tuple[list[str], dict]:
    """Which protocols to run ({protocol: reason} for the others): `auto` = every registered protocol the
    scene supports that is part of `auto` (`Protocol.in_auto`); else the protocols a comma-separated list
    of protocol and fork names names, each of which the scene must support."""
    request = parse_request(protocol)
    wanted = [p.name for p in protocols() if (p.name in request if request else p.in_auto)]
    skipped, out = {}, []
    for name in wanted:
        reason = get_protocol(name).supports(scene)
        if reason is None:
            out.append(name)
        elif request:
            raise InputError(f"scene {scene.path}: protocol {name} requested but {reason}")
        else:
            skipped[name] = reason
    return out, skipped


def requested_forks(protocol: Optional[str], names: list[str]) -> dict[str, str]:
    """{protocol: fork} of the protocols `names` under a request: the fork it names, else the default."""
    request = parse_request(protocol)
    return {n: request.get(n) or get_protocol(n).default_fork for n in names}


def _text(method, texts: list[str], mode: str):
    t = method.embed_text(list(texts), mode)
    return None if t is None else to_numpy(t)


def _feature_blocks(method, cam, modes: tuple) -> dict:
    """{mode: FeatureBlocks or None} of one camera, from one render (`semantic_feature_blocks`); a
    method without it gives whole maps, one `semantic_features` call per mode."""
    many = getattr(method, "semantic_feature_blocks", None)
    if many is not None:
        return many(cam, modes)
    out = {}
    for m in modes:
        f = method.semantic_features(cam, m)
        out[m] = None if f is None else FeatureBlocks.of_map(f)
    return out


def _cosines(blocks: FeatureBlocks, groups: dict) -> dict:
    """{group: (H*W, K) cosines of every pixel with the group's (K, D) texts}, from one pass over the
    blocks: each block's pixel norms serve every group, and a decoded block is scored while it is in
    the cache (the values are those of the whole map: every pixel is on its own)."""
    parts: dict = {g: [] for g in groups}
    for b in blocks.blocks():
        b = to_numpy(b)[None]                    # (1, n, D)
        norms = pixel_norms(b, "pixel_features")
        for g, t in groups.items():
            parts[g].append(pixel_text_cosines(b, t, "pixel_features", norms)[0])
    return {g: np.concatenate(p) for g, p in parts.items()}


def _camera_key(cam) -> tuple:
    return (cam.width, cam.height, np.asarray(cam.K, np.float64).tobytes(),
            np.asarray(cam.world_to_camera, np.float64).tobytes())


def frame_outputs(method, scene, ids_by_protocol: dict, config: dict, modes: tuple,
                  forks: Optional[dict] = None) -> dict:
    """Per-frame predictions {(protocol, mode, view id): value} for the frames each protocol scores,
    each protocol's `frame_output` under its fork (`forks`: {protocol: fork}, default forks otherwise).

    3dovs (closed set): the predicted class map (None without features); lerf: (relevancy (Q, H, W) or
    None, GT masks, GT boxes). Frames are visited one at a time; each distinct camera is rendered once
    for all protocols and modes, and its features are scored a block of pixels at a time.
    """
    text_memo: dict = {}

    def text(texts: list[str], mode: str):
        key = (tuple(texts), mode)
        if key not in text_memo:
            text_memo[key] = _text(method, texts, mode)
        return text_memo[key]

    need: dict[int, list[str]] = {}
    for p, ids in ids_by_protocol.items():
        for i in ids:
            if p not in need.setdefault(i, []):
                need[i].append(p)
    forks = {p: (forks or {}).get(p) or get_protocol(p).default_fork for p in ids_by_protocol}
    # numpy's BLAS on one thread: its block products are small, and its spinning threads took the
    # cores from torch's decoder running between them (2.5x slower layers; the same bits either way)
    with threadpool_limits(limits=1, user_api="blas"):
        return _frame_outputs(method, scene, need, config, modes, text, forks)


def _frame_outputs(method, scene, need: dict, config: dict, modes: tuple, text, forks: dict) -> dict:
    """`frame_outputs` of the frames in need ({view id: protocols}); text(texts, mode) embeds, memoised."""
    out = {}
    for i in sorted(need):
        by_cam: dict = {}                        # camera key -> (camera, protocols scoring at it)
        for p in need[i]:
            cam = get_protocol(p).camera(scene, i, config)
            by_cam.setdefault(_camera_key(cam), (cam, []))[1].append(p)
        for cam, names in by_cam.values():
            blocks = _feature_blocks(method, cam, modes)
            context = {p: get_protocol(p).frame_query(scene, i, cam, forks[p]) for p in names}
            for m in modes:
                groups = {}
                for p in names:
                    t = get_protocol(p).frame_texts(context[p], lambda texts, m=m: text(texts, m), forks[p])
                    if t is not None:
                        groups[p] = t
                cos = _cosines(blocks[m], groups) if blocks[m] is not None and groups else {}
                for p in names:
                    out[(p, m, i)] = get_protocol(p).frame_output(cos.get(p), context[p], cam, forks[p])
    return out


def _context(method, scene, name: str, sets: dict, config: dict, modes: tuple, fork: Optional[str],
             frames: Optional[dict]) -> ProtocolContext:
    """The ProtocolContext of one protocol (its frames' outputs computed here when not given)."""
    protocol = get_protocol(name)
    fork = fork or protocol.default_fork
    if frames is None:
        frames = frame_outputs(method, scene, {name: [i for ids in sets.values() for i in ids]}, config,
                               tuple(modes), {name: fork})
    return ProtocolContext(protocol=protocol, method=method, scene=scene, config=config, sets=sets,
                           modes=tuple(modes), configured=query_mode(config), fork=fork, frames=frames)


def score_3dovs(method, scene, ids: list[int], config: dict, mode: str, configured: str,
                frame_set: str, frames: Optional[dict] = None, fork: Optional[str] = None) -> Block:
    """3D-OVS metrics of frames `ids` in one query mode (`frames`: `frame_outputs` covering them,
    computed here when not given); the 3dovs protocol's `score_set`."""
    ctx = _context(method, scene, "3dovs", {frame_set: ids}, config, (mode,), fork, frames)
    ctx.configured = configured
    return ctx.protocol.score_set(ctx, ids, mode, frame_set)


def score_lerf(method, scene, ids: list[int], config: dict, mode: str, configured: str, frame_set: str,
               frames: Optional[dict] = None, fork: Optional[str] = None) -> Block:
    """LERF-OVS metrics of frames `ids` in one query mode; the lerf protocol's `score_set`."""
    ctx = _context(method, scene, "lerf", {frame_set: ids}, config, (mode,), fork, frames)
    ctx.configured = configured
    return ctx.protocol.score_set(ctx, ids, mode, frame_set)


def segmentation(method, scene, protocols: list[str], sets: dict, config: dict,
                 modes: tuple = QUERY_MODES, frames: Optional[dict] = None,
                 forks: Optional[dict] = None) -> Block:
    """Every protocol x frame set x query mode, each protocol under its fork ({protocol: fork}; default
    forks otherwise). sets: protocol -> {frame set: ids}. frames: `segmentation_frames` of the same
    arguments when the caller keeps them (the previews show them), computed here otherwise."""
    if frames is None:
        frames = segmentation_frames(method, scene, protocols, sets, config, modes, forks)
    out = Block()
    for p in protocols:
        ctx = _context(method, scene, p, sets[p], config, modes, (forks or {}).get(p), frames)
        out.merge(ctx.protocol.score(ctx))
    return out


def segmentation_frames(method, scene, protocols: list[str], sets: dict, config: dict,
                        modes: tuple = QUERY_MODES, forks: Optional[dict] = None) -> dict:
    """`frame_outputs` of every frame that `segmentation` scores (each rendered and decoded once)."""
    return frame_outputs(method, scene, {p: [i for ids in sets[p].values() for i in ids] for p in protocols},
                         config, tuple(modes), forks)


def query_mode(config: dict) -> str:
    mode = setting(config, "query.mode")
    if mode not in QUERY_MODES:
        raise InputError(f"query.mode must be one of {', '.join(QUERY_MODES)}, got {mode!r}")
    return mode


__all__ = ["PROTOCOLS", "AUTO", "resolve_protocols", "requested_forks", "frame_outputs", "segmentation",
           "segmentation_frames", "score_3dovs", "score_lerf", "query_mode"]
