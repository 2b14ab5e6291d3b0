"""An image through a lens does not depend on the other cameras of its render call: each camera's label and sample
grids are widened by its own lens's margins (``lens_margins``), not by the batch's widest, so a
dataset's samples stay the same bytes whatever its shard size or render batch. Checked by rendering cameras alone
and together (the batch's grid holds every camera's own), every output bit for bit."""

from __future__ import annotations

import cv2
import numpy as np
from test_render_distortion import _scenes

from warpworm import quiet_warp
from warpworm.render import Renderer
from warpworm.render.distortion import lens_margins

quiet_warp()


def test_a_lens_image_is_the_same_alone_and_in_a_batch_with_a_wider_lens():
    _, scene, cams = _scenes()
    left, top, gw, gh = lens_margins(cams)
    own = np.stack([left, top, gw - cams.width - left, gh - cams.height - top], axis=1)  # each side's margin [px]
    assert ((own != own.max(axis=0)).any(axis=1)).sum() >= 2  # cameras whose margins are not the batch's widest
    renderer = Renderer(cams.width, cams.height, supersample=2)
    together = renderer.render(scene, cams)
    for i in range(len(cams)):
        alone = renderer.render(scene, cams.take(np.array([i])))
        for k in ("rgb", "depth", "seg", "worm_mask"):
            np.testing.assert_array_equal(together[k][i], alone[k][0], err_msg=f"camera {i} {k}")


def test_the_margins_hold_opencvs_rays_of_the_border():
    _, _, cams = _scenes()
    left, top, gw, gh = lens_margins(cams)
    W, H = cams.width, cams.height
    # each camera's grid holds its border pixels' rays (OpenCV's iterated inverse, P = K) shifted by its margins with
    # at least a pixel to spare, a widened side at most two (whole pixels: floor / ceil of the extreme ray, +1)
    xs, ys = np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64)
    border = np.concatenate([np.stack([xs, np.zeros(W)], 1), np.stack([xs, np.full(W, H - 1.0)], 1),
                             np.stack([np.zeros(H), ys], 1), np.stack([np.full(H, W - 1.0), ys], 1)])
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    for i in range(len(cams)):
        ray = cv2.undistortPoints(border[:, None], cams.K[i], cams.dist[i], None, cams.K[i], criteria=crit)[:, 0]
        x, y = ray[:, 0] + left[i], ray[:, 1] + top[i]
        spare = np.array([x.min(), y.min(), gw[i] - 1 - x.max(), gh[i] - 1 - y.max()])
        widened = np.array([left[i], top[i], gw[i] - W - left[i], gh[i] - H - top[i]]) > 0
        assert widened.any() and np.all(spare >= 1.0 - 1e-6) and np.all(spare[widened] < 2.0 + 1e-6), (i, spare)
