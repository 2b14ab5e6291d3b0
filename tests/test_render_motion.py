"""Motion blur from the simulated velocities (issue 24, item 7): a square sheet moving at a known velocity blurs
into the mean of its sub-frames' analytic coverage; a dataset with a shutter differs from one without only in rgb."""

from __future__ import annotations

import h5py
import numpy as np

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.render import Renderer, build_scene, default_appearance, make_cameras
from warpworm.render.camera import intrinsics, look_at
from warpworm.render.motion import motion_blurred_rgb, shutter_offsets

quiet_warp()
SQUARE = np.array([[-0.01, -0.01, 0.0], [0.01, -0.01, 0.0], [0.01, 0.01, 0.0], [-0.01, 0.01, 0.0]])
VEL = np.array([0.413, 0.1537, 0.0])  # [m/s] (no sub-frame puts an edge exactly on a pixel centre)
COL, BG = np.array([0.8, 0.7, 0.3]), np.array([0.1, 0.1, 0.2])


def _scene():
    a = default_appearance(1)
    a.albedo = a.albedo.copy()
    a.albedo[0, 2] = COL
    a.paper_tex = np.zeros((1, 2))
    a.ambient, a.sun_color = np.ones((1, 3)), np.zeros((1, 3))
    a.light_power = np.zeros_like(a.light_power)
    a.bg_top = a.bg_bottom = BG[None]
    scene = build_scene(SQUARE[None] + [0.0, 0.0, 0.01], np.array([[0, 1, 2], [0, 2, 3]]), [0, 0], appearance=a,
                        floor_half=0.0)
    R, t = look_at([[0.0, 0.0, 0.3]], [[0.0, 0.0, 0.0]], up=(0.0, 1.0, 0.0))
    return scene, make_cameras(intrinsics(400.0, 400.0, 31.5, 31.5), R, t, 0, 64, 64)


def test_blur_is_the_mean_of_the_shutter():
    scene, cams = _scene()
    frame = {"positions": SQUARE[None] + [0.0, 0.0, 0.01], "velocities": np.broadcast_to(VEL, (1, 4, 3))}
    shutter, K = 0.0213, 8
    rgb = motion_blurred_rgb(Renderer(64, 64), scene, cams, frame, shutter, K)[0].astype(np.float64)
    # truth: at each sub-frame the square is [-1, 1] cm + VEL tau; a pixel centre's floor point is under it or not
    y, x = np.mgrid[0:64, 0:64].astype(np.float64)
    ray = np.stack([(x - 31.5) / 400, (y - 31.5) / 400, np.ones_like(x)], -1) @ cams.R[0]
    p = cams.position[0] + ray * ((cams.position[0][2] - 0.01) / -ray[..., 2:3])
    cover = np.zeros((64, 64))
    for tau in shutter_offsets(shutter, K):
        c = VEL[:2] * tau
        cover += (np.abs(p[..., 0] - c[0]) < 0.01) & (np.abs(p[..., 1] - c[1]) < 0.01)
        assert np.abs(np.abs(p[..., :2] - c) - 0.01).min() > 1e-7  # (coverage on an edge would follow its rule)
    cover /= K
    t8, b8 = np.floor(np.sqrt(COL) * 255 + 0.5) / 255, np.floor(np.sqrt(BG) * 255 + 0.5) / 255
    want = np.floor(np.sqrt(cover[..., None] * t8**2 + (1 - cover[..., None]) * b8**2) * 255 + 0.5)
    assert np.abs(rgb - want).max() <= 1.0
    assert ((cover > 0) & (cover < 1)).sum() > 100  # a real smear (the square moves 8 mm ~ 11 px)


def test_dataset_blur_changes_rgb_only(tmp_path):
    from warpworm.data.job import generate

    common = ["num_samples=8", "shard_size=8", "sim.worlds=2", "output.preview=false", "sim.settle_time=0.02",
              "sim.frame_times=[0.2, 0.24, 0.28, 0.32]"]
    generate(load_config("default", common), tmp_path / "a", progress=False)
    generate(load_config("default", common + ["render.motion_blur=0.05"]), tmp_path / "b", progress=False)
    fa, fb = (h5py.File(next((tmp_path / d).glob("*.h5"))) for d in "ab")
    names = []
    fa.visit(lambda n: names.append(n) if isinstance(fa[n], h5py.Dataset) else None)
    for n in names:
        if n != "rgb":
            assert np.array_equal(fa[n][()], fb[n][()]), n
    assert not np.array_equal(fa["rgb"][()], fb["rgb"][()])
