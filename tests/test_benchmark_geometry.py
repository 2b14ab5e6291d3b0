"""Label geometry of the learnability benchmarks (benchmarks/crease_oracle.py ``vertex_pixels``,
benchmarks/pose_baseline.py ``triangle_weights``) against independent truths: OpenCV's projection with lens
distortion, and affine combinations that are exact by construction."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from crease_oracle import vertex_pixels  # noqa: E402
from pose_baseline import triangle_weights  # noqa: E402


def _rotation(rng) -> np.ndarray:
    return cv2.Rodrigues(rng.normal(size=3))[0]


def test_vertex_pixels_match_opencv_projection_with_distortion():
    rng = np.random.default_rng(3)
    N, V = 4, 39
    verts = rng.uniform(-0.04, 0.04, (N, V, 3))
    R = np.stack([_rotation(rng) for _ in range(N)])
    t = np.c_[rng.uniform(-0.01, 0.01, (N, 2)), rng.uniform(0.18, 0.3, N)]
    K = np.array([[[f, 0.0, 63.5], [0.0, f, 60.0], [0.0, 0.0, 1.0]] for f in (150.0, 170.0, 190.0, 210.0)])
    dist = np.c_[rng.uniform(-0.2, 0.2, (N, 2)), rng.uniform(-0.01, 0.01, (N, 2)), rng.uniform(-0.05, 0.05, N)]
    got = vertex_pixels({"worm/vertices": verts, "camera/R": R, "camera/t": t, "camera/K": K, "camera/dist": dist})
    for i in range(N):
        want = cv2.projectPoints(verts[i], cv2.Rodrigues(R[i])[0], t[i], K[i], dist[i])[0][:, 0]
        np.testing.assert_allclose(got[i], want, atol=1e-9)


def test_triangle_weights_place_each_face_centroid_exactly_when_it_is_an_affine_combination():
    """A tetrahedron whose four vertices are the keypoints: each face's centroid is 1/3 of three of them, in any body
    pose; under an affine camera its image is the same combination of the keypoints' images."""
    rng = np.random.default_rng(5)
    kp_body = np.array([[0.0, 0.0, 0.0], [0.03, 0.0, 0.0], [0.0, 0.02, 0.0], [0.0, 0.0, 0.01]])
    tris = np.array([[0, 1, 2], [0, 1, 3], [0, 2, 3], [1, 2, 3]])
    N = 3
    pose = np.tile(np.eye(4), (N, 1, 1))
    pose[:, :3, :3] = np.stack([_rotation(rng) for _ in range(N)])
    pose[:, :3, 3] = rng.normal(0.0, 0.05, (N, 3))
    world = np.einsum("nij,cj->nci", pose[:, :3, :3], kp_body) + pose[:, None, :3, 3]
    d = {"worm/vertices": world.astype(np.float32), "poses/body": pose, "mesh_triangles": tris,
         "keypoints/body": np.tile(kp_body, (N, 1, 1))}
    W = triangle_weights(d, ridge=1e-12)  # the fit itself; the default ridge trades exactness for small weights
    want = np.zeros((4, 4))
    for t, tri in enumerate(tris):
        want[t, tri] = 1.0 / 3.0
    np.testing.assert_allclose(W, want, atol=1e-6)  # 8.5e-8 measured: the float32 vertices
    A = rng.normal(size=(2, 3))  # an affine camera: uv = A x + b
    uv = world[0] @ A.T + np.array([40.0, 50.0])
    np.testing.assert_allclose(W @ uv, world[0][tris].mean(1) @ A.T + np.array([40.0, 50.0]), atol=1e-5)
    np.testing.assert_allclose(triangle_weights(d).sum(1), 1.0, atol=1e-4)  # still affine with the ridge (3.3e-5)


def test_crop_to_worm_maps_pixels_keypoints_and_intrinsics_consistently():
    """A ramp image (red = u, green = v at pixel centres) cropped around a box: each crop pixel holds the native
    coordinates its centre maps to; the cropped keypoints are the pinhole projections with the cropped K."""
    pytest.importorskip("torch")  # the benchmark's resampling (grid_sample) is torch's, like the whole benchmark
    from pose_baseline import crop_to_worm

    H = W = 200
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rgb = np.stack([u, v, np.zeros_like(u)], -1).clip(0, 255).astype(np.uint8)[None]
    K = np.array([[[180.0, 0.0, 99.5], [0.0, 180.0, 99.5], [0.0, 0.0, 1.0]]])
    cam = np.array([[[0.01, -0.02, 0.25], [-0.015, 0.01, 0.3], [0.02, 0.015, 0.22]]])  # camera-frame points [m]
    kp = np.einsum("nij,npj->npi", K, cam)
    kp = kp[..., :2] / kp[..., 2:]
    box = np.array([[60.0, 70.0, 40.0, 30.0]])  # x, y, w, h
    d = {"rgb": rgb, "keypoints/pixel": kp, "keypoints/visibility": np.full((1, 3), 2, np.uint8),
         "camera/K": K, "labels/bbox_obj": box.astype(np.float32), "depth": np.zeros((1, H, W), np.float32)}
    side = 46
    e = crop_to_worm(d, side)
    s = 1.15 * 40.0
    x0, y0 = 80.0 - s / 2, 85.0 - s / 2
    j = np.arange(side)
    np.testing.assert_allclose(e["rgb"][0, 0, :, 0], np.round(x0 + (j + 0.5) * s / side - 0.5), atol=1)
    np.testing.assert_allclose(e["rgb"][0, :, 0, 1], np.round(y0 + (j + 0.5) * s / side - 0.5), atol=1)
    proj = np.einsum("nij,npj->npi", e["camera/K"], cam)
    np.testing.assert_allclose(e["keypoints/pixel"], proj[..., :2] / proj[..., 2:], atol=1e-9)
    assert "depth" not in e and e["rgb"].shape == (1, side, side, 3)
    assert e["keypoints/visibility"].tolist() == [[2 if 0 <= p[0] < side and 0 <= p[1] < side else 0
                                                   for p in e["keypoints/pixel"][0]]]


def test_turned_crops_keep_every_keypoint_on_the_pixel_it_labels():
    """Training crops turned in the image plane (``rotate``): sampling the cropped ramp image at each cropped
    keypoint returns the keypoint's native coordinates (the label stays on its pixel), the map is a similarity
    (distances scale by side / crop span), and the crops are turned (not the unturned map)."""
    pytest.importorskip("torch")
    from pose_baseline import CROP_MARGIN, crop_to_worm

    n, H, W, side = 8, 200, 200, 64
    u, v = np.meshgrid(np.arange(W, dtype=float), np.arange(H, dtype=float))
    rgb = np.stack([u, v, np.zeros_like(u)], -1).clip(0, 255).astype(np.uint8)[None].repeat(n, 0)
    rng = np.random.default_rng(3)
    kp = np.array([70.0, 80.0]) + rng.uniform(0, 30, (n, 5, 2))
    box = np.array([[60.0, 70.0, 50.0, 45.0]] * n)
    d = {"rgb": rgb, "keypoints/pixel": kp, "keypoints/visibility": np.full((n, 5), 2, np.uint8),
         "camera/K": np.eye(3)[None].repeat(n, 0), "labels/bbox_obj": box.astype(np.float32)}
    e = crop_to_worm(d, side, np.random.default_rng(0), 0.0, np.pi)
    assert "camera/K" not in e
    q = e["keypoints/pixel"]
    assert (e["keypoints/visibility"] == 2).all()  # all within the crop (box margin, no jitter)
    img = e["rgb"].astype(float)
    i0, j0 = np.floor(q[..., 0]).astype(int), np.floor(q[..., 1]).astype(int)
    fx, fy = (q[..., 0] - i0)[..., None], (q[..., 1] - j0)[..., None]
    b = np.arange(n)[:, None]
    val = (img[b, j0, i0] * (1 - fx) * (1 - fy) + img[b, j0, i0 + 1] * fx * (1 - fy)
           + img[b, j0 + 1, i0] * (1 - fx) * fy + img[b, j0 + 1, i0 + 1] * fx * fy)
    np.testing.assert_allclose(val[..., :2], kp, atol=0.75)  # uint8 rounding of the ramp: <= 0.5, interpolated
    scale = side / (CROP_MARGIN * 50.0)
    dn = np.linalg.norm(kp[:, :, None] - kp[:, None], axis=-1)
    np.testing.assert_allclose(np.linalg.norm(q[:, :, None] - q[:, None], axis=-1), dn * scale, atol=1e-9)
    unturned = crop_to_worm(d, side)["keypoints/pixel"]
    assert np.abs(q - unturned).max() > 5.0
