"""An image through a lens does not depend on the other cameras of its render call: each camera's label and sample
grids are widened by its own lens's margins (``lens_margins(per_camera=True)``), not by the batch's widest, so a
dataset's samples stay the same bytes whatever its shard size or render batch. Checked by rendering cameras alone
and together (the batch's grid is the widest of their own), every output bit for bit."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.distortion import draw_distortion, lens_margins

quiet_warp()
PATTERN = default_pattern()


def _scene_and_cameras(n=3, size=(80, 64)):
    st = posed_worm_states(np.arange(n) + 3, PATTERN)
    scene = build_scene(st["positions"], PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=PATTERN.vertices, floor_half=0.12)
    cams = sample_cameras(np.arange(n) + 50, st["positions"], width=size[0], height=size[1])
    cams.dist = draw_distortion(load_config("default", ["render.distortion=true"]).render, np.arange(n) + 9)
    cams.dist[2] = (-0.25, 0.08, 0.002, -0.002, 0.0)  # the strongest barrel of the default ranges
    return scene, cams


def test_a_lens_image_is_the_same_alone_and_in_a_batch_with_a_wider_lens():
    scene, cams = _scene_and_cameras()
    own = np.stack(lens_margins(cams, per_camera=True), axis=1)  # (left, top, width, height) of each camera's grid
    batch = np.array(lens_margins(cams))
    assert (own[1] != batch).any() and (own[2] != batch).any()  # cameras 1 and 2 alone get other margins
    renderer = Renderer(cams.width, cams.height, supersample=2)
    together = renderer.render(scene, cams)
    for i in range(3):
        alone = renderer.render(scene, cams.take(np.array([i])))
        for k in ("rgb", "depth", "seg", "worm_mask"):
            np.testing.assert_array_equal(together[k][i], alone[k][0], err_msg=f"camera {i} {k}")


def test_the_batch_margins_are_the_widest_cameras():
    _, cams = _scene_and_cameras()
    each = lens_margins(cams, per_camera=True)
    assert lens_margins(cams) == (int(each[0].max()), int(each[1].max()), int(each[2].max()), int(each[3].max()))
