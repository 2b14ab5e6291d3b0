"""OpenCV lens distortion (k1, k2, p1, p2, k3) for the renderer's cameras: the forward model, its inverse, and the
per-pixel maps that warp a pinhole render into a distorted image.

With normalized camera coordinates (x, y) = (X / Z, Y / Z) and r² = x² + y² (OpenCV's ``cv2.projectPoints``)::

    x' = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
    y' = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
    u = fx x' + cx,  v = fy y' + cy

The inverse (which undistorted direction a distorted pixel centre sees) is solved by Newton's method on this map.
"""

from __future__ import annotations

import numpy as np

DIST_NAMES = ("k1", "k2", "p1", "p2", "k3")
"""Order of the coefficients in ``Cameras.dist`` and ``camera/dist`` (OpenCV's)."""


def distort(x: np.ndarray, y: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distorted normalized coordinates of undistorted ones; ``dist`` (..., 5) broadcast against x, y (...)."""
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    r2 = x * x + y * y
    radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return (x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x),
            y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y)


def undistort(xd: np.ndarray, yd: np.ndarray, dist: np.ndarray, iterations: int = 8
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undistorted normalized coordinates of distorted ones (Newton's method from (xd, yd)); also the residual
    |distort(x, y) - (xd, yd)| (converged to ~1e-15 for the ranges datasets draw)."""
    k1, k2, p1, p2, k3 = (dist[..., i] for i in range(5))
    x, y = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = x * x + y * y
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = 2 * (k1 + r2 * (2 * k2 + 3 * k3 * r2))  # d radial / d (r²) times 2
        fx, fy = distort(x, y, dist)
        fx, fy = fx - xd, fy - yd
        # Jacobian of the forward map
        a = radial + x * x * drad + 2 * p1 * y + 6 * p2 * x
        b = x * y * drad + 2 * p1 * x + 2 * p2 * y
        c = x * y * drad + 2 * p1 * x + 2 * p2 * y
        d = radial + y * y * drad + 6 * p1 * y + 2 * p2 * x
        det = a * d - b * c
        x = x - (d * fx - b * fy) / det
        y = y - (-c * fx + a * fy) / det
    ex, ey = distort(x, y, dist)
    return x, y, np.hypot(ex - xd, ey - yd)


def undistort_maps(K: np.ndarray, dist: np.ndarray, width: int, height: int, device=None) -> np.ndarray:
    """For every pixel centre (u, v) of N distorted images, the pinhole pixel (same K) whose ray it sees:
    (N, H, W, 2) float64 [px]. ``K`` (N, 3, 3), ``dist`` (N, 5). Newton's method as :func:`undistort`, run by the
    Warp kernel :func:`warpworm.render.raster_kernels.undistort_pixels` (NumPy took 70 ms per 256² image)."""
    import warp as wp

    from warpworm.render import raster_kernels as rk

    N = len(K)
    intr = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]], axis=1).astype(np.float64)
    out = wp.empty((N, height, width), dtype=wp.vec2d, device=device)
    wp.launch(rk.undistort_pixels, dim=(N, height, width), device=device,
              inputs=[wp.array(intr, dtype=wp.vec4d, device=device),
                      wp.array(np.ascontiguousarray(dist, dtype=np.float64), dtype=wp.float64, device=device), 8],
              outputs=[out])
    return out.numpy().reshape(N, height, width, 2)


def widened_pinhole(cameras, device=None):
    """The pinhole cameras a distorted image is warped from (the renderers' lens path): the same K widened by
    margins that hold the ray of every distorted pixel centre of ``cameras`` (``dist`` (N, 5)), and where each
    distorted pixel centre lies in that wider image. Returns (cameras with the shifted K, ``dist`` None and the wider
    ``width``/``height``, mx (N, H, W) float32, my (N, H, W) float32) [px]."""
    import dataclasses

    H, W = int(cameras.height), int(cameras.width)
    maps = undistort_maps(cameras.K, np.asarray(cameras.dist, dtype=np.float64), W, H, device)  # (N, H, W, 2)
    lo = np.floor(maps.reshape(-1, 2).min(axis=0)) - 1
    hi = np.ceil(maps.reshape(-1, 2).max(axis=0)) + 1
    ml, mt = int(max(0, -lo[0])), int(max(0, -lo[1]))
    Wp, Hp = W + ml + int(max(0, hi[0] - (W - 1))), H + mt + int(max(0, hi[1] - (H - 1)))
    K = cameras.K.copy()
    K[:, 0, 2] += ml
    K[:, 1, 2] += mt
    wide = dataclasses.replace(cameras, K=K, dist=None, width=Wp, height=Hp)
    return wide, (maps[..., 0] + ml).astype(np.float32), (maps[..., 1] + mt).astype(np.float32)


__all__ = ["DIST_NAMES", "distort", "draw_distortion", "undistort", "undistort_maps", "widened_pinhole"]


def draw_distortion(render_cfg, seeds: np.ndarray) -> np.ndarray:
    """Distortion coefficients (n, 5) of cameras with seeds ``seeds`` (n,): k1, k2, k3 uniform in
    ``render_cfg.distortion_k1/k2/k3`` and p1, p2 each uniform in ``distortion_p`` (stream 0xD157 of the camera's own
    seed, so a camera draws the same in any batch)."""
    from warpworm.data.randomize import seed_uniforms

    u = seed_uniforms(np.asarray(seeds).reshape(-1), 0xD157, 5)
    r = render_cfg
    ranges = (r.distortion_k1, r.distortion_k2, r.distortion_p, r.distortion_p, r.distortion_k3)
    return np.stack([lo + (hi - lo) * u[:, i] for i, (lo, hi) in enumerate(ranges)], axis=1)
