"""Anti-aliased RGB by supersampling (issue 24, item 3): each pixel is the linear-RGB mean of s x s samples over its
square (checked against the samples' analytic coverage of a triangle and, as s grows, against its exact area), while
depth, segmentation, the worm mask and normals stay the single pixel-centre sample, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from warpworm import quiet_warp
from warpworm.render import Renderer, SceneBatch, build_scene, default_appearance, make_cameras, sample_cameras
from warpworm.render.camera import intrinsics, look_at
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.scene import box_mesh

quiet_warp()
UV = np.array([[3.3, 2.7], [27.1, 9.4], [8.6, 29.2]])  # a triangle in pixels (non-dyadic: no exact edge hits)
TRI_RGB, BG_RGB = np.array([0.9, 0.5, 0.2]), np.array([0.05, 0.1, 0.3])


def _triangle(sub: int):
    """The triangle (segmentation id 7, unlit albedo TRI_RGB, no specular) on a flat background, 32 x 32 px."""
    a = default_appearance(1)
    a.albedo = a.albedo.copy()
    a.albedo[0, 7] = TRI_RGB
    a.specular = np.zeros_like(a.specular)
    a.ambient = np.ones((1, 3))
    a.sun_color = np.zeros((1, 3))
    a.light_power = np.zeros_like(a.light_power)
    a.bg_top = a.bg_bottom = BG_RGB[None]
    verts = np.concatenate([(UV - 16.0) / 64.0, np.ones((3, 1))], axis=1)
    scene = SceneBatch.from_mesh(verts, np.array([[0, 1, 2]]), [7], floor_half=0.0, appearance=a)
    cams = make_cameras(intrinsics(64.0, 64.0, 16.0, 16.0), np.eye(3), np.zeros(3), 0, 32, 32)
    return Renderer(32, 32, supersample=sub).render(scene, cams)


def _inside(x, y):
    """Whether image points (x, y) lie inside the triangle UV (edge functions, either winding)."""
    e = []
    for i in range(3):
        (ax, ay), (bx, by) = UV[i], UV[(i + 1) % 3]
        e.append((bx - ax) * (y - ay) - (by - ay) * (x - ax))
    e = np.stack(e)
    return np.all(e > 0, axis=0) | np.all(e < 0, axis=0)


def _coverage(n: int) -> np.ndarray:
    """Fraction of each pixel's n x n sample grid ((i + 0.5) / n - 0.5 offsets) inside the triangle, (32, 32)."""
    off = (np.arange(n) + 0.5) / n - 0.5
    y, x = np.mgrid[0:32, 0:32].astype(np.float64)
    xs = x[..., None, None] + off[None, None, None, :]
    ys = y[..., None, None] + off[None, None, :, None]
    return _inside(xs, ys).mean(axis=(2, 3))


def _expected_rgb(cov: np.ndarray) -> np.ndarray:
    """Pixels averaging 8-bit samples of the triangle and background in linear RGB (display gamma 2)."""
    t8 = np.floor(np.sqrt(TRI_RGB) * 255 + 0.5) / 255
    b8 = np.floor(np.sqrt(BG_RGB) * 255 + 0.5) / 255
    lin = cov[..., None] * t8**2 + (1 - cov[..., None]) * b8**2
    return np.floor(np.sqrt(lin) * 255 + 0.5)


@pytest.mark.parametrize("sub", [2, 3, 4])
def test_pixels_average_their_samples(sub):
    out = _triangle(sub)
    assert np.abs(out["rgb"][0].astype(np.float64) - _expected_rgb(_coverage(sub))).max() <= 1.0
    # labels: the single centre sample, as without supersampling
    ref = _triangle(1)
    for k in ("depth", "seg", "worm_mask"):
        assert np.array_equal(out[k], ref[k]), k
    assert np.array_equal(ref["seg"][0] == 7, _inside(*np.mgrid[0:32, 0:32][::-1].astype(np.float64)))


def test_more_samples_approach_the_area():
    area = _coverage(64)  # the pixels' exact covered area, to 1/64^2
    edge = (area > 0) & (area < 1)
    lin = lambda rgb: (rgb[..., 0].astype(np.float64) / 255) ** 2  # noqa: E731
    t, b = lin(_expected_rgb(np.ones((1, 1)))), lin(_expected_rgb(np.zeros((1, 1))))
    err = [np.abs((lin(_triangle(s)["rgb"][0]) - b) / (t - b) - area)[edge].mean() for s in (1, 2, 4)]
    # mean coverage error on edge pixels; it falls as the grid refines (measured 0.188, 0.064, 0.021 for s = 1, 2, 4)
    assert err[0] > 0.15 and err[2] < 0.03 and err[0] > 2 * err[1] > 4 * err[2], err


def test_worm_scene_labels_exact_with_supersampling():
    pattern = default_pattern()
    st = posed_worm_states(np.arange(3), pattern)
    scene = build_scene(st["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=pattern.vertices)
    cams = sample_cameras(np.arange(6), st["positions"], width=64, height=48, world_index=np.arange(6) % 3)
    one = Renderer(64, 48).render(scene, cams, normals=True)
    three = Renderer(64, 48, supersample=3, max_chunk_pixels=64 * 48 * 9 * 2).render(scene, cams, normals=True)
    for k in ("depth", "seg", "worm_mask", "normals"):
        assert one[k].tobytes() == three[k].tobytes(), k
    # RGB changes where the surface changes within a pixel (edges), little inside uniform regions
    diff = np.abs(one["rgb"].astype(int) - three["rgb"].astype(int)).max(axis=-1)
    seg = one["seg"]
    edge = np.zeros_like(seg, dtype=bool)
    edge[:, 1:] |= seg[:, 1:] != seg[:, :-1]
    edge[:, :-1] |= seg[:, 1:] != seg[:, :-1]
    edge[:, 1:, :] |= seg[:, 1:] != seg[:, :-1]
    edge[:, :-1, :] |= seg[:, 1:] != seg[:, :-1]
    assert diff[edge].mean() > 3 * diff[~edge].mean()


def test_bad_supersample_refused():
    with pytest.raises(ValueError, match="supersample: got 0"):
        Renderer(8, 8, supersample=0)


def _checker_floor(sub: int, texture_filter: bool, tilt: float = 0.0):
    """A 64 x 64 view of a light-and-dark checker floor (2.5 mm tiles, no grain) lit by a uniform ambient only, from
    0.3 m above (``tilt`` [rad] off vertical about the x axis); the mesh (a tiny box) is out of view. Returns the
    render, the scene and the cameras."""
    v, t = box_mesh()
    a = default_appearance(1)
    a.albedo = a.albedo.copy()
    a.albedo[0, 1] = (0.8, 0.8, 0.8)
    a.floor_color2 = np.full((1, 3), 0.05)
    a.floor_tex = np.array([[0.0025, 1.0, 0.0, 300.0]])
    a.ambient = np.ones((1, 3))
    a.sun_color = np.zeros((1, 3))
    a.light_power = np.zeros_like(a.light_power)
    a.specular = np.zeros_like(a.specular)
    scene = SceneBatch.from_mesh(v * 0.001 + 5.0, t, np.full(len(t), 10), appearance=a, floor_half=1.0)
    target = np.array([[0.0013, 0.0007, 0.0]])  # off the tiles' corners
    R, tr = look_at(target + [[0.0, -0.3 * np.sin(tilt), 0.3 * np.cos(tilt)]], target, up=(0.0, 1.0, 0.0))
    cams = make_cameras(intrinsics(300.0, 300.0, 31.5, 31.5), R, tr, 0, 64, 64)
    return Renderer(64, 64, supersample=sub, texture_filter=texture_filter).render(scene, cams), scene, cams


def _linear(rgb):
    return (rgb[0].astype(np.float64) / 255) ** 2


def _light_share(lo, hi, tile):
    """Share of each interval [lo, hi] [m] (arrays) lying in even tiles (floor(x / tile) even), by walking the tiles
    it overlaps."""
    out = np.zeros(lo.shape)
    for idx in np.ndindex(lo.shape):
        a, b = lo[idx] / tile, hi[idx] / tile
        cells = np.arange(np.floor(a), np.floor(b) + 1)
        overlap = np.minimum(cells + 1, b) - np.maximum(cells, a)
        out[idx] = overlap[cells % 2 == 0].sum() / (b - a)
    return out


def test_floor_texture_filter_is_the_area_mean():
    # pixels wholly on the floor take the checker's mean over their footprint (render.texture_filter): seen from
    # straight above, the footprint is the pixel's own square on the floor, and the filtered image must match the
    # exact share of light tiles in each square (walked tile by tile in NumPy) to the 8-bit rounding, where 2 x 2
    # samples are off by up to a quarter of the contrast
    out, scene, cams = _checker_floor(2, True)
    K, R, t = cams.K[0], cams.R[0], cams.t[0]
    eye, fa, fn = -R.T @ t, scene.floor_axis[0], scene.floor_normal[0]
    fb = np.cross(fn, fa)

    def floor_uv(x, y):  # pixel point -> floor coordinates [m]
        d = np.stack([(x - K[0, 2]) / K[0, 0], (y - K[1, 2]) / K[1, 1], np.ones_like(x)], -1) @ R
        p = eye + (-(eye - scene.floor_origin[0]) @ fn / (d @ fn))[..., None] * d
        return (p - scene.floor_origin[0]) @ fa, (p - scene.floor_origin[0]) @ fb

    y, x = np.mgrid[0:64, 0:64].astype(np.float64)
    u0, v0 = floor_uv(x - 0.5, y - 0.5)
    u1, v1 = floor_uv(x + 0.5, y + 0.5)
    su = 2 * _light_share(np.minimum(u0, u1), np.maximum(u0, u1), 0.0025) - 1  # the square wave's means
    sv = 2 * _light_share(np.minimum(v0, v1), np.maximum(v0, v1), 0.0025) - 1
    light = 0.5 * (1 + su * sv)  # share of light tiles: (1 + S(u) S(v)) / 2, separable over an axis-aligned square
    expected = np.floor(np.sqrt(0.05 + 0.75 * light) * 255 + 0.5)
    assert np.abs(out["rgb"][0, ..., 0] - expected).max() <= 1
    sampled = _checker_floor(2, False)[0]
    assert np.abs(sampled["rgb"][0, ..., 0] - expected).max() > 40
    # labels never depend on it
    for k in ("depth", "seg", "worm_mask"):
        assert np.array_equal(out[k], sampled[k]), k


def test_floor_texture_filter_beats_its_samples_when_tilted():
    # a tilted view (footprints stretched, the box an approximation): closer to the 8 x 8 image than 2 x 2 samples
    truth = _linear(_checker_floor(8, False, tilt=1.0)[0]["rgb"])
    err_filtered = np.abs(_linear(_checker_floor(2, True, tilt=1.0)[0]["rgb"]) - truth).mean()
    err_sampled = np.abs(_linear(_checker_floor(2, False, tilt=1.0)[0]["rgb"]) - truth).mean()
    assert err_filtered < 0.7 * err_sampled, (err_filtered, err_sampled)


def test_texture_filter_config_reaches_the_renderer():
    # render.texture_filter: absent from a config's YAML at its default (the files' config_yaml as before the key),
    # recorded when off, and the dataset stages build their renderer with it
    from warpworm.data.config import load_config
    from warpworm.data.warp_stages import WarpStages

    assert "texture_filter" not in load_config("production").to_dict()["render"]
    off = load_config("production", ["render.texture_filter=false"])
    assert off.to_dict()["render"]["texture_filter"] is False
    assert WarpStages()._renderer(off).texture_filter is False
    assert WarpStages()._renderer(load_config("production")).texture_filter is True
