"""Benchmark: what the remaining routes through the cpu raster kernels would save, each measured as
a variant of gsbench/render/cpu_kernels.py against an unmodified copy of it, in one process.

    .venv/bin/python benchmarks/kernel_routes.py --run RUN [--views 4] [--repeats 5] [--rounds 3]
                                                 [--threads 1] [--routes NAME ...] [--json out.json]

A route is a list of text substitutions on the kernels' source (ROUTES below); a substitution that
no longer matches the source is an error, so a route never measures the unchanged kernels by
accident. The copy ("as is") and every route are written to a scratch folder and compiled there
(numba's cache off), and the `cpu` backend's passes (`_raster_forward`, `_raster_backward`: sort,
packing, binning and the kernels) run with that module in place of the shipped one, on the first
--views training cameras of a trained run (benchmarks/raster_pairs.py's capture).

Each round times every variant in turn (the order rotates by round): per view, the best of
--repeats of each pass, then the mean over views. It prints, per route and pass, the median over
rounds of that mean and of its ratio to the copy's in the same round, and whether the route's
outputs equal the shipped kernels' bit for bit (the forward's channel sums and transmittance, the
backward's gradient rows, on every view). A route marked "differ" is a numerics change or a timing
experiment whose outputs are not a render; its ratio is still what it costs or saves.
"""
from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import tempfile
import warnings
from functools import partial
from pathlib import Path

import gsbench  # noqa: F401  (before torch: gsbench's OpenMP default)

# isort: split
import numpy as np
import torch
from numba.core.errors import NumbaIRAssumptionWarning

from gsbench.render import cpu_backend as CB
from gsbench.render import cpu_kernels as K

sys.path.insert(0, str(Path(__file__).resolve().parent))
from raster_pairs import best, capture  # noqa: E402  (a script beside this one)

_FWD_LANE = "alpha = min(op * _expw(power), amax)\n                            tp = st[p]"
_FWD_CH = """                    for k in range(n_ch if c_hi >= c_lo else 0):
                        cv = ch[g, k]
                        ab = np.uint64(k * MAXPIX)
                        for p in range(p0, p1):
                            w = wb[p]
                            v = w * cv
                            acc[ab + p] += v if w != zero else 0.0
"""
_FWD_CH_PAIRS = """                    for k in range(0, (n_ch if c_hi >= c_lo else 0) - 1, 2):
                        cv0 = ch[g, k]
                        cv1 = ch[g, k + 1]
                        ab0 = np.uint64(k * MAXPIX)
                        ab1 = np.uint64((k + 1) * MAXPIX)
                        for p in range(p0, p1):
                            w = wb[p]
                            v0 = w * cv0
                            v1 = w * cv1
                            acc[ab0 + p] += v0 if w != zero else 0.0
                            acc[ab1 + p] += v1 if w != zero else 0.0
                    for k in range(n_ch - 1 if (c_hi >= c_lo) & (n_ch % 2 == 1) else n_ch, n_ch):
                        cv = ch[g, k]
                        ab = np.uint64(k * MAXPIX)
                        for p in range(p0, p1):
                            w = wb[p]
                            v = w * cv
                            acc[ab + p] += v if w != zero else 0.0
"""
_FWD_BLOCKS = """                    for blk in range(r_lo // 2, r_hi // 2 + 1):
                        # the BLK lanes"""
_FWD_ROWS = """                    for blk in range(r_lo, r_hi + 1):
                        # the BLK lanes"""

# name -> (pass it changes, what it measures, substitutions (old, new, count) on cpu_kernels.py)
ROUTES: dict[str, tuple[str, str, list[tuple[str, str, int]]]] = {
    "float32 lanes, forward": (
        "forward", "(a float32 working dtype) transmittance, last index and channel sums in float32, not float64",
        [
            ("st = np.empty(2 * MAXPIX, np.float64)", "st = np.empty(2 * MAXPIX, gp.dtype)", 1),
            ("acc = np.zeros(n_ch * MAXPIX, np.float64)", "acc = np.zeros(n_ch * MAXPIX, gp.dtype)", 1),
            ("st[p] = 1.0 if (r < th) & (i < tw) else -1.0", "st[p] = one if (r < th) & (i < tw) else -one", 1),
            ("st[MAXPIX + p] = 0.0\n", "st[MAXPIX + p] = zero\n", 1),
            ("jp1 = np.float64(j + 1)", "jp1 = np.float32(j + 1)", 1),
            ("(alpha >= amin) & (tp > 0.0)\n", "(alpha >= amin) & (tp > zero)\n", 1),
            ("acc[ab + p] += v if w != zero else 0.0", "acc[ab + p] += v if w != zero else zero", 1)]),
    "float32 lanes, backward": (
        "backward", "(a float32 working dtype) per-pixel state and per-Gaussian sums in float32 (rows stay float64)",
        [
            ("px = np.zeros(3 * MAXPIX, np.float64)", "px = np.zeros(3 * MAXPIX, gp.dtype)", 1),
            ("lb = np.zeros(2 * MAXPIX, np.float64)", "lb = np.zeros(2 * MAXPIX, gp.dtype)", 1),
            ("ub = np.zeros(MAXPIX, np.float64)", "ub = np.zeros(MAXPIX, gp.dtype)", 1),
            ("gb = np.zeros(n_ch * MAXPIX, np.float64)", "gb = np.zeros(n_ch * MAXPIX, gp.dtype)", 1),
            ("np.float64(g_t[py, pxx]) * tf", "g_t[py, pxx] * tf", 1),
            ("a64 = np.float64(a)", "a64 = a", 1), ("b64 = np.float64(b)", "b64 = b", 1),
            ("c64 = np.float64(c)", "c64 = c", 1), ("jf = np.float64(j)", "jf = np.float32(j)", 1),
            ("al64 = np.float64(alpha)", "al64 = alpha", 1), ("om = np.float64(one - alpha)", "om = one - alpha", 1),
            ("lb[UL_W + p] = al64 * trn if v else 0.0", "lb[UL_W + p] = al64 * trn if v else zero", 1),
            ("cv = np.float64(ch[g, 0])", "cv = ch[g, 0]", 1),
            ("        sk = 0.0\n", "        sk = np.float32(0.0)\n", 1),
            ("lb[UL_DA + p] = 0.0", "lb[UL_DA + p] = 0", 1),
            ("cv0 = np.float64(ch[g, k])", "cv0 = ch[g, k]", 1),
            ("cv1 = np.float64(ch[g, k + 1])", "cv1 = ch[g, k + 1]", 1),
            ("        s0 = 0.0\n        s1 = 0.0\n", "        s0 = np.float32(0.0)\n        s1 = np.float32(0.0)\n", 1),
            ("al = np.float64(lw[UV_AL + p])", "al = lw[UV_AL + p]", 1),
            ("om = np.float64(lw[UV_OM + p])", "om = lw[UV_OM + p]", 1), ("vv = al != 0.0", "vv = al != 0", 1),
            ("d_pow = d_alpha * np.float64(raw)", "d_pow = d_alpha * raw", 1),
            ("dx64 = np.float64(pxw[UW_X + p] - mx)", "dx64 = pxw[UW_X + p] - mx", 1),
            ("dy64 = np.float64(pxw[UW_Y + p] - my)", "dy64 = pxw[UW_Y + p] - my", 1),
            ("d_alpha * np.float64(G) if cl else 0.0", "d_alpha * G if cl else z", 1),
            ("-0.5 * dx64 * dx64) if cl else 0.0", "mh * dx64 * dx64) if cl else z", 1),
            ("-0.5 * dy64 * dy64) if cl else 0.0", "mh * dy64 * dy64) if cl else z", 1),
            (" if cl else 0.0\n", " if cl else z\n", 3),
            ("    s_op = 0.0\n", "    z = np.float32(0.0)\n    mh = np.float32(-0.5)\n    s_op = z\n", 1),
            ("    s_mx = 0.0\n    s_my = 0.0\n    s_ca = 0.0\n    s_cb = 0.0\n    s_cc = 0.0\n",
             "    s_mx = z\n    s_my = z\n    s_ca = z\n    s_cb = z\n    s_cc = z\n", 1)]),
    "exponential twice, forward": (
        "forward", "a second exponential per lane, added as 0 x exp: the extra time is one exponential's", [
            (_FWD_LANE, _FWD_LANE.replace("amax)\n", "amax) + zero * _expw(power - one)\n"), 1)]),
    "no channel pass, forward": (
        "forward", "the lane pass alone (timing only: no channel is summed)", [
            (_FWD_CH, _FWD_CH.replace("range(n_ch if c_hi >= c_lo else 0)", "range(0)"), 1)]),
    "two channels a loop, forward": (
        "forward", "the channel pass two channels per loop over the pixels (each pixel's sums unchanged)", [
            (_FWD_CH, _FWD_CH_PAIRS, 1)]),
    "one half row a block, forward": (
        "forward", "8 lanes a block instead of 16 (the backward still walks 16: spans in row pairs)", [
            (_FWD_BLOCKS, _FWD_ROWS, 1), ("rb = hb + np.uint64(blk * BLK)\n                        n_stop",
                                           "rb = hb + np.uint64(blk * HALF)\n                        n_stop", 1),
            ("for i in range(np.uint64(0), np.uint64(BLK)):\n                            p = rb + i\n"
             "                            dx = pxw[p] - mx",
             "for i in range(np.uint64(0), np.uint64(HALF)):\n                            p = rb + i\n"
             "                            dx = pxw[p] - mx", 1),
            ("spans[s0 + 2 * h] = 2 * c_lo\n", "spans[s0 + 2 * h] = (c_lo // 2) * 2\n", 1),
            ("spans[s0 + 2 * h + 1] = 2 * c_hi + 1\n", "spans[s0 + 2 * h + 1] = (c_hi // 2) * 2 + 1\n", 1),
            ("p0 = hb + np.uint64(c_lo * BLK)\n                    p1 = hb + np.uint64((c_hi + 1) * BLK)",
             "p0 = hb + np.uint64(c_lo * HALF)\n                    p1 = hb + np.uint64((c_hi + 1) * HALF)", 1)]),
}


def route_source(source: str, subs: list[tuple[str, str, int]], name: str = "") -> str:
    """`source` with each (old, new, count) substitution made; an error when `old` does not occur
    exactly `count` times (the kernels changed under the route)."""
    for old, new, count in subs:
        found = source.count(old)
        if found != count:
            raise ValueError(f"route {name!r}: {old[:60]!r}... occurs {found} times in cpu_kernels.py, "
                             f"expected {count}")
        source = source.replace(old, new)
    return source


def compile_module(source: str, folder: Path, name: str):
    """Import `source` as module `name` from `folder`, with numba's on-disk cache off."""
    path = folder / f"{name}.py"
    path.write_text(source.replace("cache=True", "cache=False"))
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


# numba's pedantic SSA check warns about the second inlined exponential of one route; harmless
warnings.filterwarnings("ignore", category=NumbaIRAssumptionWarning)


class _Kernels:
    """The `cpu` backend's passes with module `mod` in place of gsbench.render.cpu_kernels."""

    def __init__(self, mod):
        self.mod = mod

    def __enter__(self):
        CB.K = self.mod

    def __exit__(self, *exc):
        CB.K = K


def run_passes(mod, args, kw, g_outs, g_t):
    """(forward outputs, backward gradient rows) of one view with kernels `mod`."""
    with _Kernels(mod):
        outs, t_out, state = CB._raster_forward(*args, **kw)
        full = CB._raster_backward(state, g_outs, g_t)
    return (*outs, t_out), full


def time_passes(mod, captured: list, grads: list, repeats: int) -> dict:
    """Mean over views of the best-of-`repeats` ms of each pass with kernels `mod`."""
    fwd, bwd = [], []
    with _Kernels(mod):
        for (args, kw), (g_outs, g_t) in zip(captured, grads):
            _, _, state = CB._raster_forward(*args, **kw)
            fwd.append(best(partial(CB._raster_forward, *args, **kw), repeats) * 1e3)
            bwd.append(best(partial(CB._raster_backward, state, g_outs, g_t), repeats) * 1e3)
    return {"forward": statistics.fmean(fwd), "backward": statistics.fmean(bwd)}


def same_bits(a: tuple, b: tuple) -> bool:
    """Whether two tuples of arrays are equal element for element (NaN equal to NaN), shapes included."""
    return len(a) == len(b) and all(x.shape == y.shape and np.array_equal(x, y, equal_nan=True) for x, y in zip(a, b))


def measure(captured: list, names: list[str], repeats: int, rounds: int, threads: int) -> dict:
    """Per variant ("as is" first, then `names`): per-round ms of each pass, ratios to "as is"
    in the same round, and whether its outputs equal the shipped kernels' on every view."""
    torch.set_num_threads(threads)
    source = Path(K.__file__).read_text()
    rng = np.random.default_rng(0)
    grads, refs = [], []          # per view: d loss / d outputs, and the shipped kernels' outputs
    for args, kw in captured:
        outs, t_out, state = CB._raster_forward(*args, **kw)
        g_outs = tuple(rng.standard_normal(o.shape).astype(o.dtype) for o in outs)
        g_t = rng.standard_normal(outs[0].shape[:2]).astype(outs[0].dtype)
        grads.append((g_outs, g_t))
        refs.append(((*outs, t_out), CB._raster_backward(state, g_outs, g_t)))
    with tempfile.TemporaryDirectory() as tmp:
        mods = {"as is": compile_module(source, Path(tmp), "kernels_as_is")}
        for i, name in enumerate(names):
            mods[name] = compile_module(route_source(source, ROUTES[name][2], name), Path(tmp), f"kernels_route_{i}")
        result = {}
        for name, mod in mods.items():
            same_f = same_b = True
            for (args, kw), (g_outs, g_t), ref in zip(captured, grads, refs):
                got = run_passes(mod, args, kw, g_outs, g_t)      # also compiles the variant
                same_f &= same_bits(ref[0], got[0])
                same_b &= same_bits((ref[1],), (got[1],))
            result[name] = {"same_forward": bool(same_f), "same_backward": bool(same_b),
                            "forward": [], "backward": [], "ratio_forward": [], "ratio_backward": []}
        order = list(mods)
        for r in range(rounds):
            k = r % len(order)
            times = {name: time_passes(mods[name], captured, grads, repeats) for name in order[k:] + order[:k]}
            for name, t in times.items():
                for p in ("forward", "backward"):
                    result[name][p].append(t[p])
                    base = times["as is"][p]
                    result[name][f"ratio_{p}"].append(t[p] / base if base > 0 else float("nan"))
    return result


def table(result: dict) -> str:
    lines = ["| route | changes | forward ms | forward ratio | backward ms | backward ratio | outputs |",
             "|---|---|---:|---:|---:|---:|---|"]
    for name, r in result.items():
        what = "-" if name == "as is" else ROUTES[name][0]
        same = "same bits" if r["same_forward"] and r["same_backward"] else "differ"
        med = {k: statistics.median(r[k]) for k in ("forward", "backward", "ratio_forward", "ratio_backward")}
        lines.append(f"| {name} | {what} | {med['forward']:.2f} | {med['ratio_forward']:.2f} | "
                     f"{med['backward']:.2f} | {med['ratio_backward']:.2f} | {same} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--run", type=Path, required=True, help="a trained run folder (cpu backend)")
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--routes", nargs="+", default=list(ROUTES), choices=list(ROUTES), metavar="NAME")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)
    if not (args.run / "model.pt").exists():
        print(f"{args.run}: not a trained run folder (no model.pt)", file=sys.stderr)
        return 2
    captured = capture(args.run, args.views)
    result = measure(captured, args.routes, args.repeats, args.rounds, args.threads)
    for name in args.routes:
        print(f"- {name}: {ROUTES[name][1]}")
    print(table(result))
    if args.json:
        args.json.write_text(json.dumps({"run": str(args.run), "threads": args.threads, "result": result}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
