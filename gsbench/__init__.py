"""gsbench: a benchmark and evaluation harness for semantic 3D Gaussian Splatting.

Importing gsbench before torch sets one OpenMP default: GOMP_SPINCOUNT=30000 (unless the
environment already sets it). PyTorch's OpenMP workers otherwise spin for milliseconds after
every parallel op and compete with the `cpu` render backend's numba threads for the cores; on a
2-core machine this made a training step ~1.5x slower while leaving PyTorch's own op timings
unchanged (measured with benchmarks/render_cpu.py). It has no effect when torch was imported first.
"""
import os as _os

_os.environ.setdefault("GOMP_SPINCOUNT", "30000")

__version__ = "0.1.0"
