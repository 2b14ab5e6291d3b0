"""Lens distortion per camera (issue 24, item 4): OpenCV's k1, k2, p1, p2, k3 drawn per camera and stored as
camera/dist; keypoints/pixel equals cv2.projectPoints with it, the warped images agree with a BVH ray caster cast
along the distorted pixels' rays (undistorted by OpenCV), and a dataset carries and verifies it."""

from __future__ import annotations

import dataclasses

import cv2
import h5py
import numpy as np
import pytest

from warpworm import quiet_warp
from warpworm.data.config import ConfigError, load_config
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.distortion import distort, draw_distortion, undistort, undistort_maps
from warpworm.render.labels import schema_labels
from warpworm.render.raycast import RayCaster

quiet_warp()
PATTERN = default_pattern()


def _scenes(n=4, size=(96, 72)):
    st = posed_worm_states(np.arange(n) + 3, PATTERN)
    scene = build_scene(st["positions"], PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=PATTERN.vertices, floor_half=0.12)
    cams = sample_cameras(np.arange(n) + 50, st["positions"], width=size[0], height=size[1])
    cams.dist = draw_distortion(load_config("default", ["render.distortion=true"]).render, np.arange(n) + 9)
    cams.dist[0] = (-0.25, 0.08, 0.002, -0.002, 0.0)  # the strongest barrel of the default ranges
    return st, scene, cams


def test_keypoints_are_opencv_projections():
    st, scene, cams = _scenes()
    img = Renderer(cams.width, cams.height).render(scene, cams)
    lab = schema_labels(st, PATTERN, cams, img, ipm_diameter=0.01)
    for i in range(len(cams)):
        rvec, _ = cv2.Rodrigues(cams.R[i])
        ref, _ = cv2.projectPoints(lab["keypoints/world"][i], rvec, cams.t[i], cams.K[i], cams.dist[i])
        np.testing.assert_allclose(lab["keypoints/pixel"][i], ref[:, 0], atol=1e-9)


def test_inverse_undoes_the_lens():
    d = draw_distortion(load_config("default", ["render.distortion=true"]).render, np.arange(200))
    x, y = np.meshgrid(np.linspace(-0.7, 0.7, 15), np.linspace(-0.55, 0.55, 11))
    xd, yd = distort(x[None], y[None], d[:, None, None])
    xu, yu, res = undistort(xd, yd, d[:, None, None])
    assert np.abs(xu - x).max() < 1e-12 and np.abs(yu - y).max() < 1e-12 and res.max() < 1e-14


def test_warp_maps_equal_the_numpy_inverse():
    # undistort_maps runs Newton's method in a Warp kernel (lens_kernels.undistort_pixels): its twin in NumPy is
    # undistort, so every pixel centre must map to the same pinhole pixel (float64 both, the same iteration)
    _, _, cams = _scenes()
    H, W = cams.height, cams.width
    maps = undistort_maps(cams.K, cams.dist, W, H)
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    fx, fy = cams.K[:, 0, 0, None, None], cams.K[:, 1, 1, None, None]
    cx, cy = cams.K[:, 0, 2, None, None], cams.K[:, 1, 2, None, None]
    x, y, res = undistort((u[None] - cx) / fx, (v[None] - cy) / fy, cams.dist[:, None, None, :])
    assert res.max() < 1e-12
    np.testing.assert_allclose(maps, np.stack([fx * x + cx, fy * y + cy], axis=-1), rtol=0, atol=1e-9)


def test_warped_images_match_rays_through_the_lens():
    st, scene, cams = _scenes()
    out = Renderer(cams.width, cams.height).render(scene, cams)
    H, W = cams.height, cams.width
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    dirs = np.empty((len(cams), H, W, 3))
    for i in range(len(cams)):  # OpenCV's own inverse of the lens, independent of ours
        pts = np.stack([u.ravel(), v.ravel()], 1)[:, None]
        und = cv2.undistortPoints(pts, cams.K[i], cams.dist[i], None, None,
                                  criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12))
        dirs[i] = np.concatenate([und[:, 0], np.ones((H * W, 1))], 1).reshape(H, W, 3)
    ref = RayCaster(W, H).render(scene, cams, directions=dirs)
    agree = out["seg"] == ref["seg"]
    # labels come from the triangle, among the four pinhole texels around each distorted pixel's ray, that the ray
    # hits, its depth on the exact ray: measured 99.957 % of pixels agree (the earlier nearest-texel warp: 99.67 %),
    # and where they agree the depth matches to float32 rounding but for 1 pixel in 26,000 (a triangle no texel kept)
    assert agree.mean() > 0.999
    dz = np.abs(out["depth"] - ref["depth"])
    assert (dz[agree] <= 1e-5).mean() > 0.9998
    assert dz[agree].max() < 1e-3
    # the barrel lens bends the straight floor edge: without distortion the segmentation differs more from the rays
    assert (Renderer(W, H).render(scene, dataclasses.replace(cams, dist=None))["seg"] == ref["seg"]).mean() \
        < agree.mean()


def test_dataset_stores_and_verifies_the_lens(tmp_path):
    from warpworm.commands.verify import verify_dataset
    from warpworm.data.job import generate

    cfg = load_config("default", ["render.distortion=true", "num_samples=8", "shard_size=8", "sim.worlds=2",
                                  "output.preview=false", "sim.settle_time=0.02", "sim.frame_times=[0.02, 0.04, 0.06, 0.08]"])
    generate(cfg, tmp_path / "ds", progress=False)
    with h5py.File(next((tmp_path / "ds").glob("*.h5"))) as f:
        dist, K, R, t = f["camera/dist"][...], f["camera/K"][...], f["camera/R"][...], f["camera/t"][...]
        kw, kp = f["keypoints/world"][...], f["keypoints/pixel"][...]
    assert dist.shape == (8, 5) and np.all(dist[:, 0] < 0.05) and np.any(dist != 0)
    assert np.array_equal(dist[0], dist[1])  # one camera per trajectory, one lens with it
    for i in range(8):
        ref, _ = cv2.projectPoints(kw[i], cv2.Rodrigues(R[i])[0], t[i], K[i], dist[i])
        np.testing.assert_allclose(kp[i], ref[:, 0], atol=1e-9)
    problems, _ = verify_dataset(tmp_path / "ds")
    assert problems == []


def test_bad_range_refused():
    with pytest.raises(ConfigError, match="render.distortion_k1: got \\[0.1, -0.1\\]"):
        load_config("default", ["render.distortion_k1=[0.1, -0.1]"])


def _square_K(corner: float, size: int = 64) -> np.ndarray:
    """Intrinsics of a size x size camera whose farthest pixel centres lie at normalized radius ``corner``."""
    c = (size - 1) / 2.0
    f = c * np.sqrt(2.0) / corner
    return np.array([[[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]]])


def test_lens_cover_is_the_closed_form_fold():
    # k1 only: r (1 + k1 r²) rises until r_f = sqrt(-1 / (3 k1)) and reaches (2/3) r_f there; a lens covers its image
    # when the corners (with COVER_MARGIN) lie below that
    from warpworm.render.distortion import COVER_MARGIN, lens_covers_image

    for k1 in (-0.25, -0.4):
        reach = 2.0 / 3.0 * np.sqrt(-1.0 / (3.0 * k1))
        lens = np.array([[k1, 0.0, 0.0, 0.0, 0.0]])
        edge = reach / (1.0 + COVER_MARGIN)
        assert lens_covers_image(lens, _square_K(edge * 0.995), 64, 64)[0]
        assert not lens_covers_image(lens, _square_K(edge * 1.005), 64, 64)[0]
    assert lens_covers_image(np.array([[0.05, 0.08, 0.0, 0.0, 0.0]]), _square_K(1.2), 64, 64)[0]  # pincushion rises


def test_folded_lens_leaves_its_outer_pixels_without_a_ray():
    # k1 = -0.25 folds at radius (2/3) sqrt(4/3) = 0.7698; a camera whose corners lie at 0.8 has pixels beyond it:
    # the Warp inverse marks exactly those NaN (the rest invert to 1e-9), and the renderers' lens path refuses the
    # camera by name instead of sizing a pinhole image for rays that do not exist (it once asked for 3.35 TiB)
    from warpworm.render.distortion import widened_pinholes

    K, lens = _square_K(0.8), np.array([[-0.25, 0.0, 0.0, 0.0, 0.0]])
    maps = undistort_maps(K, lens, 64, 64)[0]
    v, u = np.mgrid[0:64, 0:64].astype(np.float64)
    rd = np.hypot((u - K[0, 0, 2]) / K[0, 0, 0], (v - K[0, 1, 2]) / K[0, 1, 1])
    reach = 2.0 / 3.0 * np.sqrt(4.0 / 3.0)
    off = np.isnan(maps).any(-1)
    assert off.any() and np.array_equal(off[np.abs(rd - reach) > 2e-3], (rd > reach)[np.abs(rd - reach) > 2e-3])
    xu, yu = (maps[~off, 0] - K[0, 0, 2]) / K[0, 0, 0], (maps[~off, 1] - K[0, 1, 2]) / K[0, 1, 1]
    xd, yd = distort(xu, yu, lens[0])
    assert np.abs(xd - (u[~off] - K[0, 0, 2]) / K[0, 0, 0]).max() < 1e-9
    assert np.all(np.hypot(xu, yu) < np.sqrt(4.0 / 3.0))  # the near branch, before the fold
    cams = dataclasses.replace(sample_cameras(np.arange(1), np.zeros((1, 3, 3)), width=64, height=64), K=K, dist=lens)
    with pytest.raises(ValueError, match="camera 0 of 1 .* folds back inside its 64x64 image"):
        widened_pinholes(cams)


def test_lens_draws_cover_their_images():
    # production's ranges at its widest field of view (fov_y 1 rad, corners at 0.77): about 1 lens in 75 folds inside
    # the image (1 in 1,300 over its fov range) and is drawn again; every other camera keeps the lens it drew before
    from warpworm.render.distortion import lens_covers_image

    rcfg = load_config("production").render
    n = 4000
    K = np.repeat(_square_K(np.tan(0.5) * np.sqrt(2.0) * 255.0 / 256.0, 256), n, axis=0)
    first = draw_distortion(rcfg, np.arange(n))
    drawn = draw_distortion(rcfg, np.arange(n), K, 256, 256)
    covers = lens_covers_image(first, K, 256, 256)
    assert 0 < (~covers).sum() < 0.03 * n and lens_covers_image(drawn, K, 256, 256).all()
    assert np.array_equal(drawn[covers], first[covers]) and np.all(drawn[~covers, :4] != first[~covers, :4])
    lo, hi = np.array([-0.25, -0.02, -0.002, -0.002, 0.0]), np.array([0.05, 0.08, 0.002, 0.002, 0.0])
    assert np.all((drawn >= lo) & (drawn <= hi))
    folding = load_config("production", ["render.distortion_k1=[-0.3, -0.28]", "render.distortion_k2=[-0.02, 0]"])
    with pytest.raises(ValueError, match=r"render.distortion_k1 \[-0.3, -0.28\], .*: 4000 of 4000 cameras drew no lens"):
        draw_distortion(folding.render, np.arange(n), K, 256, 256)


@pytest.mark.parametrize("dist", [(-0.25, 0.08, 0.002, -0.002, 0.0), (0.15, -0.05, -0.003, 0.001, 0.01)])
def test_warm_lens_inverse_matches_opencv(dist):
    # the resolve solves each pixel's lens inverse from its left neighbour's solution with one Newton step, the first
    # of a row and any failed warm start cold (render.lens_kernels.lens_inverse_row32, the resolve's own call):
    # against OpenCV's iterated float64 inverse over a 256² image, float32 rounding (~4e-5 px), as the cold solve alone
    import warp as wp

    from warpworm.render.lens_kernels import LensSolution, lens_inverse_row32

    f, c, n = 200.0, 127.5, 256

    @wp.kernel
    def rows(dist: wp.vec4, k3: float, f: float, c: float, warm: int, out: wp.array2d(dtype=wp.vec2)):
        y = wp.tid()
        sol = LensSolution()
        for x in range(256):
            xd = (float(x) - c) / f
            yd = (float(y) - c) / f
            if warm == 0:  # every point cold
                sol.ok = False
            sol = lens_inverse_row32(xd, yd, dist, k3, 1.0 / f, sol)
            out[y, x] = wp.vec2(sol.u, sol.v)

    K = np.array([[f, 0.0, c], [0.0, f, c], [0.0, 0.0, 1.0]])
    pts = np.stack(np.meshgrid(np.arange(n), np.arange(n)), -1).reshape(-1, 1, 2).astype(np.float64)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-15)
    ref = cv2.undistortPoints(pts, K, np.array(dist), None, None, None, crit).reshape(n, n, 2)
    err = {}
    for warm in (0, 1):
        out = wp.zeros((n, n), dtype=wp.vec2, device="cpu")
        wp.launch(rows, dim=n, inputs=[wp.vec4(*dist[:4]), dist[4], f, c, warm], outputs=[out], device="cpu")
        err[warm] = np.abs(out.numpy() - ref).max() * f
    assert err[1] < 1e-4 and err[0] < 1e-4, err
