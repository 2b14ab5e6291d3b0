"""OpenCV's lens model inverted on the device: Newton's method on the distortion map, in float64 (the per-pixel maps
of :func:`warpworm.render.distortion.undistort_maps`, the image border's rays) and in float32 for the renderer's
resolve (:mod:`warpworm.render.sample_kernels`: each pixel cold, or warm from its left neighbour)."""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})


@wp.func
def lens_inverse(xd: wp.float64, yd: wp.float64, k1: wp.float64, k2: wp.float64, p1: wp.float64, p2: wp.float64,
                 k3: wp.float64, iterations: int):
    """The undistorted normalized point (u, v) that OpenCV's lens map (k1, k2, p1, p2, k3) sends to the distorted
    normalized point (xd, yd), by ``iterations`` Newton steps from (xd, yd) in float64; with the forward map's
    symmetric Jacobian (a, b, d) = (dxd/du, dxd/dv = dyd/du, dyd/dv) there, and ``ok``: False where Newton's method
    ends off the lens (residual over 1e-9, or a folded Jacobian: no ray reaches that point)."""
    one = wp.float64(1.0)
    two = wp.float64(2.0)
    u = xd
    v = yd
    ex = wp.float64(0.0)
    ey = wp.float64(0.0)
    a = one
    b = wp.float64(0.0)
    d = one
    for it in range(iterations + 1):
        r2 = u * u + v * v
        radial = one + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = two * (k1 + r2 * (two * k2 + wp.float64(3.0) * k3 * r2))
        ex = u * radial + two * p1 * u * v + p2 * (r2 + two * u * u) - xd
        ey = v * radial + p1 * (r2 + two * v * v) + two * p2 * u * v - yd
        a = radial + u * u * drad + two * p1 * v + wp.float64(6.0) * p2 * u
        b = u * v * drad + two * p1 * u + two * p2 * v
        d = radial + v * v * drad + wp.float64(6.0) * p1 * v + two * p2 * u
        if it < iterations:  # the last round only measures the residual and the Jacobian at the solution
            det = a * d - b * b
            u = u - (d * ex - b * ey) / det
            v = v - (a * ey - b * ex) / det
    # where the polynomial folds back before this point's radius, no ray reaches it: Newton wanders or lands on the
    # far (folded) branch; say so instead of returning a wrong ray
    ok = ex * ex + ey * ey <= wp.float64(1.0e-18) and a > wp.float64(0.0) and a * d - b * b > wp.float64(0.0)
    return u, v, a, b, d, ok


@wp.func
def lens_map32(u: float, v: float, xd: float, yd: float, dist: wp.vec4, k3: float):
    """OpenCV's lens map (``dist`` = (k1, k2, p1, p2), ``k3``) at the undistorted normalized point (u, v) in float32:
    the residual (ex, ey) against the distorted point (xd, yd) and the map's symmetric Jacobian (a, b, d) =
    (dxd/du, dxd/dv = dyd/du, dyd/dv) there."""
    k1 = dist[0]
    k2 = dist[1]
    p1 = dist[2]
    p2 = dist[3]
    r2 = u * u + v * v
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    drad = 2.0 * (k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2))
    ex = u * radial + 2.0 * p1 * u * v + p2 * (r2 + 2.0 * u * u) - xd
    ey = v * radial + p1 * (r2 + 2.0 * v * v) + 2.0 * p2 * u * v - yd
    a = radial + u * u * drad + 2.0 * p1 * v + 6.0 * p2 * u
    b = u * v * drad + 2.0 * p1 * u + 2.0 * p2 * v
    d = radial + v * v * drad + 6.0 * p1 * v + 2.0 * p2 * u
    return ex, ey, a, b, d


@wp.func
def lens_newton32(xd: float, yd: float, dist: wp.vec4, k3: float, u0: float, v0: float, steps: int):
    """Newton's method for the undistorted normalized point (u, v) whose image through OpenCV's lens ``dist`` =
    (k1, k2, p1, p2) and ``k3`` is (xd, yd), from the guess (u0, v0): ``steps`` updates, then a round that measures
    the residual and the forward map's Jacobian (a, b, d) at the solution; ``ok`` False where no ray reaches the
    point (residual above 1e-5 of the radius, or the map folded: a <= 0 or a d - b² <= 0)."""
    r2d = xd * xd + yd * yd
    u = u0
    v = v0
    a = float(1.0)
    b = float(0.0)
    d = float(1.0)
    ex = float(0.0)
    ey = float(0.0)
    for it in range(steps + 1):
        ex, ey, a, b, d = lens_map32(u, v, xd, yd, dist, k3)
        if it < steps:  # the last round only measures the residual and the Jacobian at the solution
            det = a * d - b * b
            u = u - (d * ex - b * ey) / det
            v = v - (a * ey - b * ex) / det
    ok = ex * ex + ey * ey <= 1.0e-10 * (1.0 + r2d) and a > 0.0 and a * d - b * b > 0.0
    return u, v, a, b, d, ok


@wp.func
def lens_inverse32(xd: float, yd: float, dist: wp.vec4, k3: float):
    """:func:`lens_inverse` in float32 for the renderer: :func:`lens_newton32` from
    the radial first guess (xd, yd) / (1 + k1 r² + k2 r⁴ + k3 r⁶). Four steps reach float32 rounding (1e-7 of the
    normalized radius, ~2e-5 px) over every lens that covers its image."""
    r2d = xd * xd + yd * yd
    g = 1.0 + r2d * (dist[0] + r2d * (dist[1] + r2d * k3))
    return lens_newton32(xd, yd, dist, k3, xd / g, yd / g, 4)


@wp.func
def lens_inverse_next32(xd: float, yd: float, dist: wp.vec4, k3: float, step: float, u: float, v: float, a: float,
                        b: float, d: float, inv_det: float):
    """:func:`lens_inverse32` of the point ``step`` to the right of one already solved, (u, v) with the forward
    Jacobian (a, b, d) near it and ``inv_det`` = 1 / (a d - b²) (a pixel's neighbour along its row): the guess
    (u, v) + J⁻¹ (step, 0) is within ~(step)² of the root, and one Newton step from it reaches float32 rounding, as
    four from the radial guess do (tests/test_render_distortion.py::test_warm_lens_inverse_matches_opencv). One
    evaluation of the map: returns (u, v, a, b, d, inv_det, ok) with the guess's Jacobian (~(step)² from the root's,
    which the samples' offsets and the next guess do not feel); ``ok``: the guess was close (residual under 1e-4 of
    the radius) on an unfolded map, else the caller solves cold."""
    gu = u + d * step * inv_det
    gv = v - b * step * inv_det
    ex, ey, ga, gb, gd = lens_map32(gu, gv, xd, yd, dist, k3)
    det = ga * gd - gb * gb
    ok = ex * ex + ey * ey <= 1.0e-8 * (1.0 + xd * xd + yd * yd) and ga > 0.0 and det > 0.0
    inv = 1.0 / det
    return gu - (gd * ex - gb * ey) * inv, gv - (ga * ey - gb * ex) * inv, ga, gb, gd, inv, ok


@wp.struct
class LensSolution:
    """A pixel's lens solution, the next pixel's warm start: the undistorted normalized point (``u``, ``v``), the lens
    map's Jacobian (``a``, ``b``, ``d``) there and ``inv_det`` = 1 / (a d - b²); ``ok`` False where no ray reaches
    the pixel (and in a new struct: nothing solved yet, the next pixel solves cold)."""

    u: float
    v: float
    a: float
    b: float
    d: float
    inv_det: float
    ok: bool


@wp.func
def lens_inverse_row32(xd: float, yd: float, dist: wp.vec4, k3: float, step: float, last: LensSolution) -> LensSolution:
    """The next point along a row, ``step`` to the right of ``last``: warm from it (:func:`lens_inverse_next32`)
    where it solved, cold (:func:`lens_inverse32`) where it did not or the warm guess failed."""
    sol = LensSolution()
    if last.ok:
        u, v, a, b, d, inv, ok = lens_inverse_next32(xd, yd, dist, k3, step, last.u, last.v, last.a, last.b, last.d,
                                                     last.inv_det)
        sol = LensSolution(u, v, a, b, d, inv, ok)
    if not sol.ok:
        u, v, a, b, d, ok = lens_inverse32(xd, yd, dist, k3)
        sol = LensSolution(u, v, a, b, d, 1.0 / (a * d - b * b), ok)
    return sol


@wp.func
def pinhole_pixel(k: wp.vec4d, dist: wp.array2d(dtype=wp.float64), img: int, x: wp.float64, y: wp.float64,
                  iterations: int) -> wp.vec2d:
    """The pinhole pixel (intrinsics ``k`` = (fx, fy, cx, cy)) whose ray distorted pixel point (x, y) of image ``img``
    sees through its lens ``dist[img]`` (k1, k2, p1, p2, k3), by :func:`lens_inverse`; NaN where no ray reaches it."""
    u, v, _a, _b, _d, ok = lens_inverse((x - k[2]) / k[0], (y - k[3]) / k[1], dist[img, 0], dist[img, 1],
                                       dist[img, 2], dist[img, 3], dist[img, 4], iterations)
    out = wp.vec2d(k[0] * u + k[2], k[1] * v + k[3])
    if not ok:
        out = wp.vec2d(wp.float64(wp.nan), wp.float64(wp.nan))
    return out


@wp.kernel
def undistort_pixels(
    intr: wp.array(dtype=wp.vec4d),
    dist: wp.array2d(dtype=wp.float64),
    iterations: int,
    # Data out:
    pinhole: wp.array3d(dtype=wp.vec2d),
):
    """For pixel centre (x, y) of distorted image ``img``: the pinhole pixel (same intrinsics ``intr`` = (fx, fy, cx,
    cy)) whose ray it sees, by :func:`lens_inverse` with ``dist`` (k1, k2, p1, p2, k3) (float64; the NumPy twin is
    :func:`warpworm.render.distortion.undistort`). ``pinhole``: (N, H, W); NaN where no ray reaches that pixel."""
    img, y, x = wp.tid()
    pinhole[img, y, x] = pinhole_pixel(intr[img], dist, img, wp.float64(x), wp.float64(y), iterations)


@wp.kernel
def border_rays(
    intr: wp.array(dtype=wp.vec4d),
    dist: wp.array2d(dtype=wp.float64),
    px: wp.array(dtype=wp.float64),
    py: wp.array(dtype=wp.float64),
    iterations: int,
    # Data out:
    pinhole: wp.array2d(dtype=wp.vec2d),
):
    """:func:`undistort_pixels` at ``P`` given pixel centres (``px``, ``py``) (P,) of each image (an image's border,
    for :func:`warpworm.render.distortion.lens_margins`): ``pinhole`` (N, P), NaN where no ray reaches the point."""
    img, i = wp.tid()
    pinhole[img, i] = pinhole_pixel(intr[img], dist, img, px[i], py[i], iterations)
