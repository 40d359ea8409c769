"""The priors tests' ray-cast sphere scene (tests/support/sphere_scene.py) against hand-computed values."""
from __future__ import annotations

import numpy as np
from sphere_scene import look_at, make_sphere_scene, raycast

from gsbench.camera import Camera


def test_raycast_depth_matches_hand_computed():
    # A camera on the +x axis at height 0.35 looking at the centre sphere's centre: the central
    # pixel ray hits the sphere (centre (0,0,0.35), radius 0.35) at distance 3 - 0.35 = 2.65.
    K = np.array([[50.0, 0, 50.5], [0, 50.0, 50.5], [0, 0, 1]])  # pixel (50, 50)'s centre is on axis
    cam = Camera(K, look_at((3.0, 0.0, 0.35), target=(0.0, 0.0, 0.35)), 100, 100)
    rgb, z, inst = raycast(cam)
    assert inst[50, 50] == 0
    assert abs(z[50, 50] - 2.65) < 1e-9
    assert inst[0, 0] == -1 or inst[0, 0] == 4
    assert rgb.shape == (100, 100, 3) and 0 <= rgb.min() and rgb.max() <= 1


def test_scene_parts():
    s = make_sphere_scene(3, 32, 24)
    assert len(s.cameras) == 6 and s.has_depth and s.has_instances and s.has_semantics
    inst, cls = s.gt_instances(0), s.gt_classes(0)
    assert inst.shape == (24, 32) and set(np.unique(cls)) <= {-1, 0, 1, 2, 3}
    # class map agrees with instances + instance_classes
    for i in np.unique(inst[inst >= 0]):
        assert np.all(cls[inst == i] == s.instance_classes[int(i)])
