"""gsbench.datasets: scene readers (COLMAP, LLFF, transforms.json, 3D-OVS, LERF-OVS, kaolin), the
synthetic scene generator (`gsbench.datasets.synthetic`) and depth-noise injection
(`gsbench.datasets.noise`)."""
from .base import LabelObject, Scene
from .layout_registry import layout_names
from .loader import detect_layout, load_scene, scene_fingerprint

__all__ = ["LabelObject", "Scene", "detect_layout", "layout_names", "load_scene", "scene_fingerprint"]
