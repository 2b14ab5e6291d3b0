"""Dark point lights (zero power: the pads of worlds with fewer lights) cost nothing and change nothing: the renderer
orders each world's lights lit first (:func:`~warpworm.render.rasterizer.lit_first`) and makes shadow maps for the
lit ones only. Checked against each world rendered alone with its lit lights only (the same images, bit for bit, shadows
and a glossy plate on) and against the order and count the layout must keep."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.ids import SEG_FLOOR
from warpworm.render import Renderer, SceneBatch, default_appearance, make_cameras
from warpworm.render.camera import intrinsics, look_at
from warpworm.render.rasterizer import lit_first, shadow_cameras
from warpworm.render.scene import box_mesh

quiet_warp()
SIZE = 64
LAMPS = np.array([[0.05, 0.02, 0.25], [-0.04, 0.06, 0.2], [0.0, -0.07, 0.3]])  # three lit lamps, in this order
POWER = np.array([[0.02, 0.018, 0.015], [0.01, 0.012, 0.014], [0.016, 0.016, 0.016]])


def _scene(pos, power, size):
    """len(pos) worlds (the same cube over a glossy floor) with the given point lights (W, L, ...)."""
    v, t = box_mesh()
    W = len(pos)
    a = default_appearance(W)
    a.light_pos, a.light_power, a.light_size = pos, power, size
    a.specular = np.array(a.specular, dtype=np.float64)
    a.specular[:, SEG_FLOOR] = (0.3, 40.0)  # a glossy plate: the lights' highlights are summed too
    lo, hi = np.array([-0.01, -0.01, 0.005]), np.array([0.01, 0.01, 0.025])
    one = v * (hi - lo) + (hi + lo) / 2
    return SceneBatch.from_mesh(np.stack([one] * W), t, np.full(len(t), 10), appearance=a, floor_half=0.2)


def _render(scene):
    W = scene.num_worlds
    R, t = look_at([[0.03, -0.02, 0.3]] * W, [[0.0, 0.0, 0.0]] * W, up=(0.0, 1.0, 0.0))
    cams = make_cameras(intrinsics(160.0, 160.0, (SIZE - 1) / 2, (SIZE - 1) / 2), R, t, np.arange(W), SIZE, SIZE)
    return Renderer(SIZE, SIZE, shadows=True, shadow_map=128, supersample=2).render(scene, cams)


def test_each_world_renders_as_it_does_alone_with_its_lit_lights():
    """World 0: lamp 2 among dark pads; world 1: lamps 0 and 1 with pads between them. Each image equals that world
    rendered in a scene of its own holding only its lit lamps (no pads, no other world's maps)."""
    pos = np.full((2, 5, 3), [0.3, 0.3, 0.05])  # a pad's position: never looked at
    power = np.zeros((2, 5, 3))
    size = np.full((2, 5), 0.01)
    for w, slots, lamps in ((0, [3], [2]), (1, [0, 2], [0, 1])):
        pos[w, slots], power[w, slots] = LAMPS[lamps], POWER[lamps]
    both = _render(_scene(pos, power, size))
    for w, lamps in ((0, [2]), (1, [0, 1])):
        alone = _render(_scene(LAMPS[lamps][None], POWER[lamps][None], np.full((1, len(lamps)), 0.01)))
        for k in ("rgb", "depth", "seg", "worm_mask"):
            np.testing.assert_array_equal(both[k][w], alone[k][0], err_msg=f"world {w} {k}")
    one_lamp = _render(_scene(LAMPS[[0]][None], POWER[[0]][None], np.full((1, 1), 0.01)))
    assert np.abs(one_lamp["rgb"][0].astype(int) - both["rgb"][1]).max() > 2  # world 1's second lamp shows


def test_lit_first_keeps_the_order_and_the_maps_follow_it():
    power = np.array([[[3, 3, 3], [0, 0, 0], [0, 0, 0], [0, 0, 0]], [[0, 0, 0], [1, 1, 1], [0, 0, 0], [2, 2, 2]]],
                     dtype=np.float64)
    pos = np.arange(24, dtype=np.float64).reshape(2, 4, 3)
    size = np.arange(8, dtype=np.float64).reshape(2, 4)
    p, w, s = lit_first(pos, power, size)
    assert w.shape == (2, 2, 3)  # the slots dark in both rows dropped
    np.testing.assert_array_equal(w[1], power[1, [1, 3]])
    np.testing.assert_array_equal(p[1], pos[1, [1, 3]])
    np.testing.assert_array_equal(s[0], size[0, [0, 1]])
    np.testing.assert_array_equal(w[0, 1], 0.0)
    scene = _scene(pos * 0.01 + [0.0, 0.0, 0.2], power * 0.01, size * 0.001 + 0.005)
    cams = shadow_cameras(scene, np.array([0, 1]), 64)
    assert cams["world"].tolist() == [0, 0, 1, 1, 1]  # the sun and the lit lights: 2 maps, then 3
    assert cams["first"].tolist() == [0, 2]
    np.testing.assert_allclose(cams["size"][[1, 3, 4]], s[[0, 1, 1], [0, 0, 1]] * 0.001 + 0.005)  # lamp radii
