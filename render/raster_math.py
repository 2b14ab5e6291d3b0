"""Shared pieces of the rasterizer's kernels: segmentation ids, the packed z-buffer key, the per-world row read, the
edge functions and top-left rule, projection, the exact depth plane, the baked noise texture and the display
encoding. A leaf: every other kernel module of ``render/`` imports it."""

from __future__ import annotations

import warp as wp

from warpworm import ids

wp.set_module_options({"enable_backward": False})

# segmentation ids (:mod:`warpworm.ids`): 0 background, 1 floor, 2..6 worm segments, 7..9 IPMs, 10 EPM
SEG_BACKGROUND = wp.constant(ids.SEG_BACKGROUND)
SEG_FLOOR = wp.constant(ids.SEG_FLOOR)
SEG_WORM_FIRST = wp.constant(ids.SEG_WORM_FIRST)
SEG_WORM_LAST = wp.constant(ids.SEG_WORM_LAST)
SEG_EPM = wp.constant(ids.SEG_EPM)

TRI_BITS = 24
"""Low bits of the packed key that hold the triangle index."""
DEPTH_SCALE = float(1 << 24)
"""Fixed-point depth units per metre in the packed key."""
EMPTY_KEY = (1 << 63) - 1
"""Key of a pixel no triangle covers (int64 max)."""

_TRI_SCALE = wp.constant(wp.int64(1 << TRI_BITS))
_DEPTH_SCALE = wp.constant(DEPTH_SCALE)
_EMPTY = wp.constant(wp.int64(EMPTY_KEY))


# ---------------------------------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------------------------------


@wp.func
def seg_id(label: int) -> int:
    """The segmentation id a pixel on surface ``label`` gets: its own, but a distractor object's (its own albedo row,
    above SEG_EPM) is the floor's (static scene)."""
    out = label
    if label > SEG_EPM:
        out = int(SEG_FLOOR)
    return out


@wp.func
def edge_fn(ax: float, ay: float, bx: float, by: float, px: float, py: float) -> float:
    """Edge function of directed edge a->b at p, positive on the interior side of a (y down) positive-area triangle."""
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


@wp.func
def is_top_left(ax: float, ay: float, bx: float, by: float) -> bool:
    """Top-left rule for an edge a->b of a positive-area triangle on a y-down screen.

    A top edge is horizontal with the interior below it (it runs toward +x); a left edge runs upward (toward -y).
    """
    return (ay == by and bx > ax) or (by < ay)


@wp.func
def covers(e: float, top_left: bool) -> bool:
    return e > 0.0 or (e == 0.0 and top_left)


NOISE_SIZE = 128
"""Side of the baked, tileable noise texture (a power of two: wrapping is a bit mask)."""


@wp.func
def noise_tex(tex: wp.array2d(dtype=float), u: float, v: float) -> float:
    """Bilinear lookup of the tileable noise texture at texel coordinates (u, v), wrapping (values in [0, 1]).

    Baking the noise once and reading 4 texels costs a fraction of hashing 4 (2-D) or 8 (3-D) lattice points per
    pixel, which dominated the shading cost on CPU.
    """
    fu = wp.floor(u)
    fv = wp.floor(v)
    tu = u - fu
    tv = v - fv
    m = tex.shape[0] - 1
    i0 = int(fu) & m
    j0 = int(fv) & m
    i1 = (i0 + 1) & m
    j1 = (j0 + 1) & m
    a = wp.lerp(tex[j0, i0], tex[j0, i1], tu)
    b = wp.lerp(tex[j1, i0], tex[j1, i1], tu)
    return wp.lerp(a, b, tv)


@wp.func
def to_srgb8(c: float) -> wp.uint8:
    """Linear [0, 1] -> 8-bit with a square-root display gamma (clamped; gamma 2 costs a sqrt, 2.2 a pow)."""
    c = wp.clamp(c, 0.0, 1.0)
    return wp.uint8(int(wp.sqrt(c) * 255.0 + 0.5))


@wp.func
def project(p: wp.vec3, k: wp.vec4) -> wp.vec2:
    """Pixel (u, v) of camera-frame point ``p`` [m] through intrinsics ``k`` = (fx, fy, cx, cy) [px]."""
    return wp.vec2(k[0] * p[0] / p[2] + k[2], k[1] * p[1] / p[2] + k[3])


@wp.func
def depth_plane(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, k: wp.vec4) -> wp.vec4:
    """(nd, a, b, c) of a camera-frame triangle's plane n.p = nd, so that its camera depth at pixel (x, y) is
    z = nd / (a x + b y + c) along the ray ((x - cx) / fx, (y - cy) / fy, 1): exact for any triangle
    (perspective-correct), and the one formula of the raster and resolve passes (their depths agree bit for bit)."""
    n = wp.cross(p1 - p0, p2 - p0)
    pa = n[0] / k[0]
    pb = n[1] / k[1]
    return wp.vec4(wp.dot(n, p0), pa, pb, n[2] - pa * k[2] - pb * k[3])


@wp.func
def pixel_box(u0: float, v0: float, u1: float, v1: float, u2: float, v2: float, width: int,
              height: int) -> wp.vec4i:
    """(xmin, xmax, ymin, ymax): the pixel centres (integers) a screen triangle's bounding box covers, clamped to
    the image (clamped before the conversion to int: no overflow); xmin > xmax or ymin > ymax when none."""
    fw = float(width)
    fh = float(height)
    xmin = int(wp.ceil(wp.clamp(wp.min(wp.min(u0, u1), u2), -1.0, fw)))
    xmax = int(wp.floor(wp.clamp(wp.max(wp.max(u0, u1), u2), -1.0, fw)))
    ymin = int(wp.ceil(wp.clamp(wp.min(wp.min(v0, v1), v2), -1.0, fh)))
    ymax = int(wp.floor(wp.clamp(wp.max(wp.max(v0, v1), v2), -1.0, fh)))
    return wp.vec4i(wp.max(xmin, 0), wp.min(xmax, width - 1), wp.max(ymin, 0), wp.min(ymax, height - 1))


@wp.func
def spec_power(c: float, e: float) -> float:
    """Schlick's rational approximation of ``c**e`` for c in [0, 1]: one division instead of a ``pow``."""
    return c / (e - (e - 1.0) * c)
