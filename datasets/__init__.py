"""gsbench.datasets: scene readers (COLMAP, LLFF, transforms.json, 3D-OVS, LERF-OVS, kaolin), the
synthetic scene generator (`gsbench.datasets.synthetic`) and depth-noise injection
(`gsbench.datasets.noise`)."""
from .base import LabelObject, Scene
from .loader import LAYOUTS, detect_layout, load_scene, scene_fingerprint

__all__ = ["LAYOUTS", "LabelObject", "Scene", "detect_layout", "load_scene", "scene_fingerprint"]
