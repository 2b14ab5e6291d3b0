"""The path-traced engine (Mitsuba 3, warpworm.render.pathtrace) against the rasterizer on the same scenes: geometry
pixel by pixel, the picture's objects where the rasterizer puts them, light units, and the per-sample engine draw."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from warpworm import quiet_warp  # noqa: E402
from warpworm.data.config import load_config  # noqa: E402
from warpworm.data.sampling import sample_appearance  # noqa: E402
from warpworm.render import Renderer, build_scene, default_appearance, sample_cameras  # noqa: E402
from warpworm.render import pathtrace as pt  # noqa: E402
from warpworm.render.demo import default_pattern, posed_worm_states  # noqa: E402

quiet_warp()
W_IMG, H_IMG = 64, 48


def _scene(appearance, worlds=3, seed=40):
    pattern = default_pattern()
    st = posed_worm_states(seed + np.arange(worlds), pattern)
    scene = build_scene(st["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=pattern.vertices, appearance=appearance)
    return scene, st


@pytest.fixture(scope="module")
def scenes():
    # the plate's pose drawn (floor square and its checker moved and turned) and 1-4 spherical lights per world
    cfg = load_config("default", ["render.plate_pose=true", "render.lights=random"])
    scene, st = _scene(sample_appearance(cfg, np.arange(3)))
    # principal-point jitter on (the sensor's offset), square pixels (Mitsuba's sensor has one focal length)
    cams = sample_cameras(900 + np.arange(6), st["positions"], width=W_IMG, height=H_IMG,
                          world_index=np.arange(6) % 3, aspect_jitter=0.0, principal_jitter=0.05)
    return scene, cams, Renderer(W_IMG, H_IMG, device="cpu").render(scene, cams)


def _worm(seg):
    return (seg >= 2) & (seg <= 6)


def test_worm_masks_agree(scenes):
    """Mitsuba's first hits through the pixel centres of the very sensors the images use give the rasterizer's worm
    mask (IoU >= 0.99 per image; measured 1.0) and its segmentation on >= 99 % of pixels."""
    scene, cams, img = scenes
    seg = pt.pixel_centre_seg(scene, cams)
    for i in range(len(cams)):
        a, b = _worm(img["seg"][i]), _worm(seg[i])
        assert a.sum() > 20
        assert (a & b).sum() / (a | b).sum() >= 0.99, i
        assert (img["seg"][i] == seg[i]).mean() >= 0.99, i


def test_picture_shows_the_scene_where_the_rasterizer_does():
    """A red worm on a blue floor: the path-traced picture is red inside the rasterizer's (eroded) worm mask and blue
    on the floor away from it (shadows darken the floor but keep its hue)."""
    scene, st = _red_worm_blue_floor()
    cams = sample_cameras(31 + np.arange(2), st["positions"], width=W_IMG, height=H_IMG, world_index=np.arange(2),
                          aspect_jitter=0.0, distance=(0.12, 0.14))
    seg = Renderer(W_IMG, H_IMG, device="cpu").render(scene, cams)["seg"]
    rgb = pt.render_pathtraced(scene, cams, spp=16, linear=True)
    k = np.ones((3, 3), np.uint8)
    for i in range(2):
        worm = _worm(seg[i]).astype(np.uint8)
        inner = cv2.erode(worm, k).astype(bool)
        floor = (seg[i] == 1) & ~cv2.dilate(worm, k, iterations=2).astype(bool)
        assert inner.sum() > 5 and floor.sum() > 100
        red = rgb[i][..., 0] > rgb[i][..., 2]
        assert red[inner].mean() >= 0.95 and (~red[floor]).mean() >= 0.99


def _red_worm_blue_floor(worlds=2, seed=7):
    app = default_appearance(worlds)
    app.albedo[:, 2:7] = (0.8, 0.05, 0.05)
    app.albedo[:, 1] = (0.05, 0.1, 0.6)
    app.floor_tex[:, 1:3] = 0.0  # plain floor
    app.paper_tex[:] = 0.0
    return _scene(app, worlds=worlds, seed=seed)


def test_lens_distortion_and_gain_as_the_rasterizer():
    """A camera with strong lens distortion (OpenCV k1, k2, p1, p2, k3) is path-traced through the same lens: the red
    pixels of the picture overlap the rasterizer's distorted worm mask better than those of the pinhole picture
    (measured IoU 0.88 / 0.90 against 0.83 / 0.84; anti-aliased edges and shading keep it below 1), and are red
    inside its eroded mask; the camera's gain (exposure x white balance) scales the linear light exactly."""
    import dataclasses

    scene, st = _red_worm_blue_floor()
    cams = sample_cameras(51 + np.arange(2), st["positions"], width=W_IMG, height=H_IMG, world_index=np.arange(2),
                          aspect_jitter=0.0, distance=(0.09, 0.1), min_in_frame=0.5)
    lens = dataclasses.replace(cams, dist=np.array([[-0.5, 0.2, 0.004, -0.004, 0.0]] * 2))
    seg = Renderer(W_IMG, H_IMG, device="cpu").render(scene, lens)["seg"]
    rgb = pt.render_pathtraced(scene, lens, spp=8, linear=True)
    pinhole = pt.render_pathtraced(scene, cams, spp=8, linear=True)
    k = np.ones((3, 3), np.uint8)
    for i in range(2):
        worm = _worm(seg[i])
        red, red_pin = rgb[i][..., 0] > rgb[i][..., 2], pinhole[i][..., 0] > pinhole[i][..., 2]
        iou, iou_pin = ((worm & red).sum() / (worm | red).sum(), (worm & red_pin).sum() / (worm | red_pin).sum())
        assert iou >= 0.85 and iou >= iou_pin + 0.03, (iou, iou_pin)
        inner = cv2.erode(worm.astype(np.uint8), k).astype(bool)
        assert inner.sum() > 50 and red[inner].mean() >= 0.98
    gain = np.array([[2.0, 1.0, 0.5], [0.7, 0.7, 0.7]])
    a = pt.render_pathtraced(scene, cams, spp=4, linear=True)
    b = pt.render_pathtraced(scene, dataclasses.replace(cams, gain=gain), spp=4, linear=True)
    assert np.allclose(b, a * gain[:, None, None, :].astype(np.float32), rtol=1e-6, atol=1e-7)


def test_light_units_match_the_rasterizer():
    """A plain floor lit by sky, sun and lamp: the path tracer's linear radiance there equals the rasterizer's
    Lambert shading albedo * (ambient + E_sun cos + lamp cos / r^2) (pi factors in the emitters) within 1 % (measured 0.2-0.3 %), where no
    shadow falls (pixels far from the worm and magnets, whose footprints are dilated)."""
    app = default_appearance(1)
    app.floor_tex[:, 1:3] = 0.0
    scene, st = _scene(app, worlds=1, seed=3)
    cams = sample_cameras(np.array([5]), st["positions"], width=W_IMG, height=H_IMG, world_index=np.zeros(1, np.int64),
                          aspect_jitter=0.0, distance=(0.3, 0.3), elevation_deg=(60, 60))
    img = Renderer(W_IMG, H_IMG, device="cpu").render(scene, cams)
    lin_raster = (img["rgb"][0].astype(np.float64) / 255.0) ** 2
    lin_pt = pt.render_pathtraced(scene, cams, spp=64, linear=True)[0]
    obj = (img["seg"][0] >= 2).astype(np.uint8)
    floor = (img["seg"][0] == 1) & ~cv2.dilate(obj, np.ones((3, 3), np.uint8), iterations=12).astype(bool)
    assert floor.sum() > 200
    ratio = lin_pt[floor].mean(axis=0) / lin_raster[floor].mean(axis=0)
    assert np.all(np.abs(ratio - 1.0) < 0.01), ratio


def test_engine_choice_is_per_sample_and_seeded():
    """The choice of engine is a function of each sample's own seed: the same in any batch, about the configured share,
    all or nothing at 1 and 0."""
    seeds = np.arange(4000, dtype=np.int64) * 7919 + 13
    c = pt.choose_pathtraced(seeds, 0.25)
    assert np.array_equal(c[1000:1010], pt.choose_pathtraced(seeds[1000:1010], 0.25))
    assert abs(c.mean() - 0.25) < 4 * np.sqrt(0.25 * 0.75 / len(seeds))
    assert pt.choose_pathtraced(seeds, 1.0).all() and not pt.choose_pathtraced(seeds, 0.0).any()


def test_non_square_pixels_refused():
    """Mitsuba's perspective sensor has one focal length: a K with fx != fy is refused, naming it."""
    K = np.array([[100.0, 0, 31.5], [0, 90.0, 23.5], [0, 0, 1]])
    with pytest.raises(ValueError, match="camera/K"):
        pt.sensor_dict(K, np.eye(3), np.zeros(3), W_IMG, H_IMG)


def test_dataset_mixes_the_engines_per_sample(tmp_path):
    """``render.pathtraced_fraction: 0.5``: each sample's engine is drawn from its seed and stored (``engine``); its
    labels, depth and segmentation are those of the raster-only dataset of the same seed, bit for bit, and so is the
    rgb of its raster samples; the path-traced samples' rgb differs; ``warpworm verify`` passes."""
    from warpworm.commands.verify import verify_dataset
    from warpworm.data import dataset as ds
    from warpworm.data.job import generate

    common = ["sim.worlds=2", "shard_size=4", "sim.settle_time=0.02", "sim.frame_times=[0.02, 0.04]",
              "render.width=32", "render.height=24", "output.preview=false", "render.pathtraced_spp=4"]
    generate(load_config("default", common, num_samples=8), tmp_path / "r", progress=False)
    cfg = load_config("default", common + ["render.pathtraced_fraction=0.5"], num_samples=8)
    generate(cfg, tmp_path / "m", progress=False)
    a, b = ds.open(tmp_path / "r"), ds.open(tmp_path / "m")
    assert "engine" not in a.keys() and "engine" in b.keys()
    idx = range(8)
    eng = b.read("engine", idx)
    assert np.array_equal(eng, pt.choose_pathtraced(b.read("seed", idx), 0.5)) and 0 < eng.sum() < 8
    for k in a.keys():
        if k != "rgb":
            assert np.array_equal(a.read(k, idx), b.read(k, idx)), k
    ra, rb = a.read("rgb", idx), b.read("rgb", idx)
    for i in idx:
        assert np.array_equal(ra[i], rb[i]) == (eng[i] == 0), i
    assert verify_dataset(tmp_path / "m")[0] == []


def test_a_lens_image_does_not_depend_on_the_other_cameras_of_its_call():
    """Two cameras with different lenses (so different widenings): each path-traced alone and both together, the
    same pixels (each is traced in a pinhole image widened by its own lens's margins, with its own seed). Up to
    Mitsuba's own repeatability: the same camera rendered twice differs by at most 1.2e-7 in a few values (its
    threads' sums); the code that widened every image for the call's widest lens differed by up to 0.91 (mean 0.09)."""
    import dataclasses

    scene, st = _red_worm_blue_floor()
    cams = sample_cameras(51 + np.arange(2), st["positions"], width=W_IMG, height=H_IMG, world_index=np.arange(2),
                          aspect_jitter=0.0, distance=(0.09, 0.1), min_in_frame=0.5)
    lens = dataclasses.replace(cams, dist=np.array([[-0.5, 0.2, 0.004, -0.004, 0.0], [-0.1, 0.02, 0.0, 0.0, 0.0]]))
    together = pt.render_pathtraced(scene, lens, spp=2, seeds=np.array([7, 8]), linear=True)
    for i in range(2):
        alone = pt.render_pathtraced(scene, lens.take(np.array([i])), spp=2, seeds=np.array([7 + i]), linear=True)
        np.testing.assert_allclose(together[i], alone[0], rtol=0.0, atol=1e-5)
