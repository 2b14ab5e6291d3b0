"""The learnability benchmark's crease visibility (benchmarks/pose_baseline.py ``creases_seen``) on scenes whose
depth image is known in closed form: a tilted two-triangle hinge in front of an OpenCV camera (depth of the plane
along each pixel centre's ray), with and without a card in front of either face."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from pose_baseline import creases_seen  # noqa: E402

H = W = 64
K = np.array([[80.0, 0.0, 31.5], [0.0, 80.0, 31.5], [0.0, 0.0, 1.0]])


def _scene(tilt: float, occlude: int = 0):
    """One sample: a hinge (i, j, k, l) = (0, 1, 2, 3) flat on the plane z = 0.2 + tilt * x (camera frame = world),
    its depth image in closed form (0 where a ray misses), optionally a card at z = 0.1 over the face (j, l, k)
    (``occlude`` 1, at x > 0) or (i, j, k) (-1, at x < 0)."""
    x = np.array([[-0.03, 0.0], [0.0, -0.03], [0.0, 0.03], [0.03, 0.0]])  # i, j, k, l: j-k the shared edge
    verts = np.c_[x, 0.2 + tilt * x[:, 0]]
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rx, ry = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    depth = 0.2 / (1.0 - tilt * rx)  # z on the plane along the ray (rx z, ry z, z)
    inside = np.abs(rx * depth) + np.abs(ry * depth) <= 0.03  # the hinge is the square |x| + |y| <= 0.03
    depth = np.where(inside, depth, 0.0)
    if occlude:
        card = (occlude * rx * 0.1 > 0.002) & inside  # in front of one face: x > 0 (j, l, k) or x < 0 (i, j, k)
        depth = np.where(card, 0.1, depth)
    return {"crease_hinges": np.array([[0, 1, 2, 3]]), "worm/vertices": verts[None].astype(np.float32),
            "depth": depth[None].astype(np.float32), "camera/K": K[None], "camera/R": np.eye(3)[None],
            "camera/t": np.zeros((1, 3))}


def test_a_crease_in_view_is_seen_at_any_tilt_and_hidden_by_a_card_over_either_face():
    for tilt in (0.0, 0.5, -1.0):
        assert creases_seen(_scene(tilt)).tolist() == [[True]], tilt
        for side in (1, -1):  # either face hidden: the crease's angle is not in view
            assert creases_seen(_scene(tilt, occlude=side)).tolist() == [[False]], (tilt, side)
