"""benchmarks/raster_pairs.py: its scalar pair walk takes the forward kernel's decisions (it checks
itself against the kernel's last contributor and final transmittance of every pixel); nothing here
times anything."""
import sys

from bench_scripts import load_benchmark
from paths import REPO_ROOT


def test_pair_walk_agrees_with_the_forward_kernel():
    sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
    mod = load_benchmark("raster_pairs")
    import render_cpu
    field, cam = render_cpu.make_scene(48, 32, 400, 3, seed=1)
    captured = mod.capture_renders(field, [cam])
    assert len(captured) == 1
    rows = mod.measure(captured, threads=1, repeats=1)      # exits when the walk and the kernel disagree
    state = mod.CB._raster_forward(*captured[0][0], **captured[0][1])[2]
    tile_off, tile_size, tiles_x = state[2], state[7], state[6]
    # at most every Gaussian of a pixel's tile list contributes to it
    listed = sum(int(tile_off[(y // tile_size) * tiles_x + x // tile_size + 1]
                     - tile_off[(y // tile_size) * tiles_x + x // tile_size]) for y in range(32) for x in range(48))
    assert 0 < rows["pairs"][0] <= listed
    assert rows["forward"][0] > 0 and rows["backward"][0] > 0
    assert "| 1 | forward |" in mod.table({1: rows})
