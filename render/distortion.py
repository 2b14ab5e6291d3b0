"""OpenCV lens distortion (k1, k2, p1, p2, k3) for the renderer's cameras: the forward model, its inverse, and the
per-pixel maps that warp a pinhole render into a distorted image.

With normalized camera coordinates (x, y) = (X / Z, Y / Z) and r² = x² + y² (OpenCV's ``cv2.projectPoints``)::

    x' = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
    y' = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y
    u = fx x' + cx,  v = fy y' + cy

The inverse (which undistorted direction a distorted pixel centre sees) is solved by Newton's method on this map.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import warp as wp

from warpworm.render import lens_kernels as lk
from warpworm.rng import seed_uniforms

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
    Warp kernel :func:`warpworm.render.lens_kernels.undistort_pixels`."""
    N = len(K)
    intr = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]], axis=1).astype(np.float64)
    out = wp.empty((N, height, width), dtype=wp.vec2d, device=device)
    wp.launch(lk.undistort_pixels, dim=(N, height, width), device=device,
              inputs=[wp.array(intr, dtype=wp.vec4d, device=device),
                      wp.array(np.ascontiguousarray(dist, dtype=np.float64), dtype=wp.float64, device=device), 8],
              outputs=[out])
    return out.numpy().reshape(N, height, width, 2)


def lens_margins(cameras, device=None):
    """The widening each camera's lens needs: (left, top, grid width, grid height) [px], four (N,) int arrays, of a
    pinhole image with the camera's K shifted by (left, top) that holds the ray of every distorted pixel centre of
    its image (``dist`` (N, 5)), with a pixel to spare. Each camera's own, not the batch's widest: what a camera's
    image may depend on, so that it does not change with the batch it is rendered in. The lens map is
    one-to-one over the image (:func:`lens_covers_image`), so the extreme rays are those of the image's border: only
    its 2 (W + H) pixel centres are undistorted (float64, the Warp kernel
    :func:`warpworm.render.lens_kernels.border_rays` on ``device``, default the CPU). ValueError when a lens folds
    back inside its image (no ray reaches some pixels)."""
    H, W = int(cameras.height), int(cameras.width)
    dist = np.ascontiguousarray(cameras.dist, dtype=np.float64)
    K = np.asarray(cameras.K, dtype=np.float64)
    N = len(K)
    xs, ys = np.arange(W, dtype=np.float64), np.arange(H, dtype=np.float64)
    bx = np.concatenate([xs, xs, np.zeros(H), np.full(H, W - 1.0)])
    by = np.concatenate([np.zeros(W), np.full(W, H - 1.0), ys, ys])
    d = wp.get_device("cpu" if device is None else device)
    intr = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]], axis=1)
    rays = wp.empty((N, len(bx)), dtype=wp.vec2d, device=d)
    wp.launch(lk.border_rays, dim=(N, len(bx)), device=d,
              inputs=[wp.array(intr, dtype=wp.vec4d, device=d), wp.array(dist, dtype=wp.float64, device=d),
                      wp.array(bx, dtype=wp.float64, device=d), wp.array(by, dtype=wp.float64, device=d), 8],
              outputs=[rays])
    m = rays.numpy()
    off = ~np.isfinite(m).all(axis=(1, 2))
    if off.any():  # the wider image would have to hold rays that do not exist
        i = int(np.flatnonzero(off)[0])
        raise ValueError(f"camera {i} of {len(off)} (and {int(off.sum()) - 1} more): its lens (k1, k2, p1, p2, k3) = "
                         f"{tuple(np.round(dist[i], 5).tolist())} folds back inside its {W}x{H} image (fx "
                         f"{K[i, 0, 0]:.1f} px): some pixels see no ray; expected a lens whose radial map "
                         "rises past the image corners (draw_distortion with K redraws such lenses)")
    lo = np.floor(m.min(axis=1)) - 1  # (N, 2)
    hi = np.ceil(m.max(axis=1)) + 1
    left, top = np.maximum(0, -lo[:, 0]).astype(int), np.maximum(0, -lo[:, 1]).astype(int)
    right = np.maximum(0, hi[:, 0] - (W - 1)).astype(int)
    bottom = np.maximum(0, hi[:, 1] - (H - 1)).astype(int)
    return left, top, W + left + right, H + top + bottom


def widened_pinholes(cameras, device=None) -> list:
    """The pinhole camera each distorted image is warped from (the path tracer's lens path): its K widened by its own
    :func:`lens_margins`, and where each of its distorted pixel centres lies in that wider image. Returns, per camera,
    (a one-camera :class:`Cameras` with the shifted K, ``dist`` None and its wider ``width``/``height``, mx (H, W)
    float32, my (H, W) float32) [px]; the margins and the maps of all the cameras in one launch each."""
    H, W = int(cameras.height), int(cameras.width)
    left, top, Wp, Hp = lens_margins(cameras, device)
    maps = undistort_maps(cameras.K, np.asarray(cameras.dist, dtype=np.float64), W, H, device)  # (N, H, W, 2)
    out = []
    for i in range(len(cameras)):  # a Cameras holds one image size: each widened image its own
        one = cameras.take(np.array([i]))
        K = one.K.copy()
        K[:, 0, 2] += left[i]
        K[:, 1, 2] += top[i]
        wide = dataclasses.replace(one, K=K, dist=None, width=int(Wp[i]), height=int(Hp[i]))
        mx, my = (maps[i, ..., 0] + left[i]).astype(np.float32), (maps[i, ..., 1] + top[i]).astype(np.float32)
        out.append((wide, mx, my))
    return out


__all__ = ["DIST_NAMES", "distort", "draw_distortion", "lens_covers_image", "lens_margins", "undistort",
           "undistort_maps", "widened_pinholes"]

COVER_MARGIN = 0.02
""":func:`lens_covers_image`: how far past the farthest pixel centre (relative) the radial map must still rise."""
LENS_ATTEMPTS = 16
""":func:`draw_distortion`: draws per camera before the ranges are refused."""


def lens_covers_image(dist: np.ndarray, K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Whether each lens's radial map ``r -> r (1 + k1 r² + k2 r⁴ + k3 r⁶)`` still rises past the farthest pixel
    centre of its image (normalized radius, plus ``COVER_MARGIN`` and a bound 3 (|p1| + |p2|) r² on the tangential
    terms), within three times that radius: (n,) bool. Where the polynomial folds back, OpenCV's model describes no
    lens (a fitted lens is monotone over its sensor) and the pixels beyond the fold see no ray. ``dist`` (n, 5),
    ``K`` (n, 3, 3)."""
    dist, K = np.asarray(dist, np.float64).reshape(-1, 5), np.asarray(K, np.float64).reshape(-1, 3, 3)
    corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]])
    x = (corners[None, :, 0] - K[:, 0, 2, None]) / K[:, 0, 0, None]
    y = (corners[None, :, 1] - K[:, 1, 2, None]) / K[:, 1, 1, None]
    corner = np.hypot(x, y).max(axis=1)
    target = corner * (1.0 + COVER_MARGIN) + 3.0 * (np.abs(dist[:, 2]) + np.abs(dist[:, 3])) * corner**2
    r = np.linspace(0.0, 1.0, 1025)[None] * (3.0 * target[:, None])
    s = r * r
    f = r * (1.0 + s * (dist[:, 0, None] + s * (dist[:, 1, None] + s * dist[:, 4, None])))
    rising = np.logical_and.accumulate(np.diff(f, axis=1) > 0.0, axis=1)  # monotone from 0 up to sample j + 1
    return np.where(rising, f[:, 1:], 0.0).max(axis=1) >= target


def _draw(render_cfg, seeds: np.ndarray, stream: int) -> np.ndarray:
    u = seed_uniforms(seeds, stream, 5)
    r = render_cfg
    ranges = (r.distortion_k1, r.distortion_k2, r.distortion_p, r.distortion_p, r.distortion_k3)
    return np.stack([lo + (hi - lo) * u[:, i] for i, (lo, hi) in enumerate(ranges)], axis=1)


def draw_distortion(render_cfg, seeds: np.ndarray, K: np.ndarray | None = None, width: int | None = None,
                    height: int | None = None) -> np.ndarray:
    """Distortion coefficients (n, 5) of cameras with seeds ``seeds`` (n,): k1, k2, k3 uniform in
    ``render_cfg.distortion_k1/k2/k3`` and p1, p2 each uniform in ``distortion_p`` (stream 0xD157 of the camera's own
    seed, so a camera draws the same in any batch). Given the cameras' ``K`` (n, 3, 3) and image size, a lens that
    does not cover its image (:func:`lens_covers_image`: strong barrel at a wide field of view) is drawn again from
    the camera's next stream (0xD1570 + attempt), up to ``LENS_ATTEMPTS`` draws; then a ValueError names the ranges.
    """
    seeds = np.asarray(seeds).reshape(-1)
    dist = _draw(render_cfg, seeds, 0xD157)
    if K is None:
        return dist
    bad = ~lens_covers_image(dist, K, width, height)
    for attempt in range(1, LENS_ATTEMPTS):
        if not bad.any():
            break
        dist[bad] = _draw(render_cfg, seeds[bad], 0xD1570 + attempt)
        bad[bad] = ~lens_covers_image(dist[bad], np.asarray(K)[bad], width, height)
    if bad.any():
        r = render_cfg
        raise ValueError(
            f"render.distortion_k1 {list(r.distortion_k1)}, render.distortion_k2 {list(r.distortion_k2)}, "
            f"render.distortion_k3 {list(r.distortion_k3)}: {int(bad.sum())} of {len(bad)} cameras drew no lens in "
            f"{LENS_ATTEMPTS} tries whose radial map rises past the corners of its {width}x{height} image (fx "
            f"{float(np.asarray(K)[bad][0, 0, 0]):.1f} px); expected milder barrel ranges or a narrower camera.fov_y")
    return dist
