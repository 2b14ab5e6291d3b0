"""Warp kernels of the batched rasterizer: one raster pass and one resolve/shade pass per batch of images.

Both passes are launched over every (image, element) pair of the batch at once, so the whole batch costs two
launches plus a buffer clear, on CPU and CUDA alike. An *image* is one (world, camera) pair: ``image_world[img]``
names the world whose triangle soup it sees.

Pass 1, :func:`raster_triangles` (``img, tri = wp.tid()``): projects one triangle into one image and, for each pixel
centre it covers, does ``atomic_min`` of a packed 64-bit key ``(fixed-point depth << 24) | triangle``. The minimum
key holds the nearest surface; ties in depth fall to the lower triangle index, so the result is deterministic and
independent of launch order (the min of a set is order-free). Warp has no float->int bit cast, so the depth is packed
as a fixed-point integer ``int64(z * 2**24)`` (resolution 2**-24 m = 6e-8 m, range 2**39 * 2**-24 m = 32 km); that
leaves 24 bits for the triangle index (16.7 M triangles per world).

Pass 2, :func:`resolve_shade` (``img, y, x = wp.tid()``): decodes the key, recomputes the exact camera depth of the
winning triangle at the pixel centre from its plane (the same float ops as pass 1), intersects the pixel ray with
the analytic floor rectangle (the floor is not rasterized: it would cross the near plane and cost an atomic on most
pixels), keeps the nearer surface, shades it and writes RGB, depth, segmentation and (optionally) normals.

Conventions:
- Pixel ``(row y, column x)`` samples the ray through the image point ``(u, v) = (x, y)``: OpenCV's convention in
  which integer coordinates are pixel *centres* (``cx = (width - 1) / 2`` centres the principal point).
- Coverage: a pixel is covered when its centre is inside the projected triangle; centres exactly on an edge belong to
  the triangle only if the edge is a top or left edge (D3D/OpenGL top-left rule, on screen with y down), so a pixel on
  an edge shared by two triangles is drawn exactly once.
- Depth is the camera-frame z [m] of the surface at the pixel centre; background pixels get 0.
- Triangles with a vertex closer than ``near`` to the camera plane (z < near) are skipped, not clipped.
- Every triangle is double-sided: no back-face culling; shading flips the normal to face the camera.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

# forward only: nothing differentiates through rendering, and skipping adjoints halves the compile time
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
def wrow(w: int, n: int) -> int:
    """Row ``w % n`` of a per-world array of ``n`` rows for a world ``w >= 0``, without the integer division in the
    usual cases (n > w: an array per world; n == 1: one row shared): a division costs more than the rest of a plain
    pixel's shading, and the general kernel read ~15 world rows per pixel."""
    if w < n:
        return w
    if n == 1:
        return 0
    return w % n


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


# ---------------------------------------------------------------------------------------------------------------------
# pass 1: raster
# ---------------------------------------------------------------------------------------------------------------------


@wp.kernel
def raster_triangles(
    # Model:
    triangles: wp.array(dtype=wp.vec3i),
    tri_label: wp.array(dtype=wp.int32),
    # Data in:
    vertices: wp.array2d(dtype=wp.vec3),
    image_world: wp.array(dtype=wp.int32),
    cam_rot: wp.array(dtype=wp.mat33),
    cam_trans: wp.array(dtype=wp.vec3),
    cam_intr: wp.array(dtype=wp.vec4),
    width: int,
    height: int,
    near: float,
    # Data out:
    zkey: wp.array2d(dtype=wp.int64),
    worm_mask: wp.array2d(dtype=wp.uint8),
):
    """Z-buffer one triangle into one image.

    Args:
        triangles: vertex indices of every triangle of the (shared) scene topology, shape (T,).
        tri_label: segmentation id of every triangle, shape (T,).
        vertices: world positions [m] of every scene vertex of every world, shape (W, Vs).
        image_world: world index of every image, shape (N,).
        cam_rot: world-to-camera rotation R of every image (x_cam = R x_world + t), shape (N,).
        cam_trans: world-to-camera translation t [m], shape (N,).
        cam_intr: (fx, fy, cx, cy) [px] of every image, shape (N,).
        width, height: image size [px].
        near: triangles with a vertex at camera z < near [m] are skipped.
        zkey: packed (depth, triangle) keys, shape (N, height * width); cleared to EMPTY_KEY before the launch.
        worm_mask: set to 1 where a worm triangle covers the pixel, occluded or not, shape (N, height * width).
    """
    img, tri = wp.tid()
    w = image_world[img]
    f = triangles[tri]
    R = cam_rot[img]
    t = cam_trans[img]
    p0 = R * vertices[w, f[0]] + t
    p1 = R * vertices[w, f[1]] + t
    p2 = R * vertices[w, f[2]] + t
    if wp.min(wp.min(p0[2], p1[2]), p2[2]) < near:
        return
    k = cam_intr[img]
    q0 = project(p0, k)
    q1 = project(p1, k)
    q2 = project(p2, k)
    u0 = q0[0]
    v0 = q0[1]
    u1 = q1[0]
    v1 = q1[1]
    u2 = q2[0]
    v2 = q2[1]
    area = edge_fn(u0, v0, u1, v1, u2, v2)
    if area == 0.0:
        return
    if area < 0.0:
        # double-sided: reorder to positive screen area so one inside test and one top-left rule serve both sides
        u1 = q2[0]
        v1 = q2[1]
        u2 = q1[0]
        v2 = q1[1]
    box = pixel_box(u0, v0, u1, v1, u2, v2, width, height)
    if box[0] > box[1] or box[2] > box[3]:
        return
    plane = depth_plane(p0, p1, p2, k)

    tl0 = is_top_left(u1, v1, u2, v2)
    tl1 = is_top_left(u2, v2, u0, v0)
    tl2 = is_top_left(u0, v0, u1, v1)
    worm = tri_label[tri] >= SEG_WORM_FIRST and tri_label[tri] <= SEG_WORM_LAST
    tkey = wp.int64(tri)

    for y in range(box[2], box[3] + 1):
        py = float(y)
        entered = bool(False)
        for x in range(box[0], box[1] + 1):
            px = float(x)
            e0 = edge_fn(u1, v1, u2, v2, px, py)
            e1 = edge_fn(u2, v2, u0, v0, px, py)
            e2 = edge_fn(u0, v0, u1, v1, px, py)
            if covers(e0, tl0) and covers(e1, tl1) and covers(e2, tl2):
                entered = True
                z = plane[0] / (plane[1] * px + plane[2] * py + plane[3])
                key = wp.int64(z * _DEPTH_SCALE) * _TRI_SCALE + tkey
                pix = y * width + x
                wp.atomic_min(zkey, img, pix, key)
                if worm:
                    worm_mask[img, pix] = wp.uint8(1)
            elif entered:
                break  # a row crosses a convex triangle in one run


# ---------------------------------------------------------------------------------------------------------------------
# shadow maps (the raster pass rendered from each light) and lights
# ---------------------------------------------------------------------------------------------------------------------


# Functions taking Lights or Look are inline=True: Warp passes structs by value, and a call the compiler left out
# of line copied both (~1.5 KB) per pixel: 4.5x the plain kernel's resolve time on the same look, 1.5-2x inlined.
@wp.struct
class Lights:
    """Every light of every world (arrays read as ``a[wrow(w, a.shape[0])]``) and, with ``shadows`` = 1, their shadow maps.

    ``pos``, ``power``, ``size``: point lights, shape (Wl, L): position [m], irradiance at 1 m (falls as 1/r²; zero
    pads a world with fewer lights), radius [m]. ``sun_dir`` (unit, toward the light), ``sun_color`` (irradiance),
    ``ambient``: per world. Shadow map ``m`` is a depth image (packed keys of :func:`raster_triangles`, side
    ``map_side``) seen by a pinhole ``map_rot``/``map_trans``/``map_intr`` at the light; world ``w``'s maps are
    ``map_first[w]`` (the sun) and ``map_first[w] + 1 + i`` (point light i); ``map_first[w] < 0``: none (lit).
    ``map_light_size``: the light's radius [m] as placed for the map (it sets the penumbra). ``map_tile_min``
    (M, map_tiles²): the smallest key of each ``SHADOW_TILE`` x ``SHADOW_TILE`` block of texels
    (:func:`shadow_tile_min`), so a point whose blocker search region holds no nearer texel is known lit from a few
    reads (:func:`region_unblocked`).
    """

    ambient: wp.array(dtype=wp.vec3)
    sun_dir: wp.array(dtype=wp.vec3)
    sun_color: wp.array(dtype=wp.vec3)
    pos: wp.array2d(dtype=wp.vec3)
    power: wp.array2d(dtype=wp.vec3)
    size: wp.array2d(dtype=float)
    shadows: int
    map_first: wp.array(dtype=wp.int32)
    map_key: wp.array2d(dtype=wp.int64)
    map_rot: wp.array(dtype=wp.mat33)
    map_trans: wp.array(dtype=wp.vec3)
    map_intr: wp.array(dtype=wp.vec4)
    map_light_size: wp.array(dtype=float)
    map_side: int
    map_tile_min: wp.array2d(dtype=wp.int64)
    map_tiles: int


@wp.func
def map_depth(L: Lights, m: int, x: int, y: int) -> float:
    """Camera z [m] of the nearest occluder in texel (x, y) of shadow map ``m``; 1e30 where nothing (or outside)."""
    s = L.map_side
    z = float(1.0e30)
    if x >= 0 and y >= 0 and x < s and y < s:
        key = L.map_key[m, y * s + x]
        if key != _EMPTY:
            z = float(key / _TRI_SCALE) / _DEPTH_SCALE
    return z


SHADOW_TILE = 8
"""Side [texels] of the blocks whose minimum key :func:`shadow_tile_min` keeps."""
_SHADOW_TILE = wp.constant(SHADOW_TILE)


@wp.kernel
def shadow_tile_min(map_key: wp.array2d(dtype=wp.int64), side: int, tiles: int,
                    tile_min: wp.array2d(dtype=wp.int64)):
    """Smallest key of each ``SHADOW_TILE``² block of every shadow map: ``map_key`` (M, side²) ->
    ``tile_min`` (M, tiles²); launched as (M, tiles²)."""
    m, b = wp.tid()
    x0 = (b % tiles) * _SHADOW_TILE
    y0 = (b / tiles) * _SHADOW_TILE
    best = _EMPTY
    for y in range(y0, wp.min(y0 + _SHADOW_TILE, side)):
        for x in range(x0, wp.min(x0 + _SHADOW_TILE, side)):
            best = wp.min(best, map_key[m, y * side + x])
    tile_min[m, b] = best


@wp.func
def region_unblocked(L: Lights, m: int, u: float, v: float, z: float, radius: float) -> bool:
    """True when no texel :func:`pcf_taps` reads about (u, v) at ``radius`` can hold an occluder nearer than ``z``,
    judged from the tile minima (a texel wider than the taps on each side, so rounding cannot escape): then the
    blocker search would find none, and the point is lit. Exact: the same answer as the 16 taps."""
    s = L.map_side
    x0 = wp.max(int(wp.floor(u - radius + 0.5)) - 1, 0)
    x1 = wp.min(int(wp.floor(u + radius + 0.5)) + 1, s - 1)
    y0 = wp.max(int(wp.floor(v - radius + 0.5)) - 1, 0)
    y1 = wp.min(int(wp.floor(v + radius + 0.5)) + 1, s - 1)
    clear = bool(True)
    if x0 <= x1 and y0 <= y1:
        for ty in range(y0 / _SHADOW_TILE, y1 / _SHADOW_TILE + 1):
            for tx in range(x0 / _SHADOW_TILE, x1 / _SHADOW_TILE + 1):
                key = L.map_tile_min[m, ty * L.map_tiles + tx]
                if key != _EMPTY:
                    if float(key / _TRI_SCALE) / _DEPTH_SCALE < z:
                        clear = False
    return clear


@wp.func
def pcf_taps(L: Lights, m: int, u: float, v: float, z: float, radius: float) -> wp.vec2:
    """4 x 4 taps of shadow map ``m`` on a grid spanning ``radius`` texels about (u, v): (number of taps nearer than
    ``z``, their summed depth) -- the blocker search and the percentage-closer filter of PCSS share it."""
    hits = float(0.0)
    zsum = float(0.0)
    for j in range(4):
        for i in range(4):
            x = int(wp.floor(u + radius * (float(i) - 1.5) / 1.5 + 0.5))
            y = int(wp.floor(v + radius * (float(j) - 1.5) / 1.5 + 0.5))
            d = map_depth(L, m, x, y)
            if d < z:
                hits += 1.0
                zsum += d
    return wp.vec2(hits, zsum)


@wp.func
def light_visibility(L: Lights, m: int, p: wp.vec3, n: wp.vec3) -> float:
    """Fraction [0, 1] of light ``m`` reaching surface point ``p`` (normal ``n`` toward the viewer/light side), by
    percentage-closer soft shadows: a blocker search over the texels the light's disk can be hidden by, then a
    percentage-closer filter as wide as the penumbra a blocker at their mean depth casts (at least one texel)."""
    k = L.map_intr[m]
    R = L.map_rot[m]
    t = L.map_trans[m]
    pc = R * p + t
    if pc[2] <= 0.0:
        return 1.0
    texel = pc[2] / k[0]  # a texel's size [m] at the receiver
    pc = R * (p + n * (1.5 * texel)) + t  # normal offset against self-shadowing of the receiver's own surface
    u = k[0] * pc[0] / pc[2] + k[2]
    v = k[1] * pc[1] / pc[2] + k[3]
    z = pc[2] - texel
    size = L.map_light_size[m]
    search = wp.clamp(size * k[0] / z, 1.0, 8.0)
    side = float(L.map_side)
    if u < -search - 1.0 or v < -search - 1.0 or u > side + search or v > side + search:
        return 1.0  # outside the map, which covers every caster: nothing between the point and the light
    if region_unblocked(L, m, u, v, z, search):
        return 1.0
    blk = pcf_taps(L, m, u, v, z, search)
    if blk[0] == 0.0:
        return 1.0
    zb = blk[1] / blk[0]
    # the 4 x 4 grid's taps at +-r, +-r/3 have the second moment (5/9 r^2) of a disk light's edge profile (its
    # penumbra half-width p: p^2 / 4) for r = 0.67 p
    penumbra = wp.clamp(0.67 * size * (z - zb) / zb * k[0] / z, 1.0, 8.0)
    return 1.0 - pcf_taps(L, m, u, v, z, penumbra)[0] / 16.0


@wp.func(inline=True)
def point_light(L: Lights, wl: int, i: int, p: wp.vec3, n: wp.vec3):
    """Point light ``i`` of world row ``wl`` at ``p``: (unit direction toward it, irradiance on a facing surface,
    n . direction clamped at 0)."""
    to_lamp = L.pos[wl, i] - p
    r2 = wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
    inv_r = 1.0 / wp.sqrt(r2)
    ldir = to_lamp * inv_r
    return ldir, L.power[wl, i] * (inv_r * inv_r), wp.max(wp.dot(n, ldir), 0.0)


@wp.func(inline=True)
def is_dark(L: Lights, wl: int, i: int) -> bool:
    """Point light ``i`` of world row ``wl`` has zero power (a pad): skipping it adds exactly nothing."""
    pw = L.power[wl, i]
    return pw[0] == 0.0 and pw[1] == 0.0 and pw[2] == 0.0


@wp.func(inline=True)
def shadow_factor(L: Lights, first: int, light: int, ndl: float, p: wp.vec3, n: wp.vec3) -> float:
    """``ndl`` times the visibility of light ``light`` (0 = sun, 1 + i = point light i) when shadows are on."""
    out = ndl
    if L.shadows != 0 and first >= 0 and ndl > 0.0:
        out = ndl * light_visibility(L, first + light, p, n)
    return out


# ---------------------------------------------------------------------------------------------------------------------
# pass 2: resolve and shade
# ---------------------------------------------------------------------------------------------------------------------


@wp.func
def spec_power(c: float, e: float) -> float:
    """Schlick's rational approximation of ``c**e`` for c in [0, 1]: one division instead of a ``pow``."""
    return c / (e - (e - 1.0) * c)


@wp.func
def light_surface_plain(albedo: wp.vec3, spec: wp.vec2, p: wp.vec3, n: wp.vec3, to_eye: wp.vec3, ambient: wp.vec3,
                        sun_dir: wp.vec3, sun_color: wp.vec3, lamp_pos: wp.vec3, lamp_power: wp.vec3) -> wp.vec3:
    """:func:`light_surface` for the plain path (:func:`make_resolve_shade`): one lit point lamp, no shadows, the
    world's lights passed in as values (the same float operations, so the same bits)."""
    ndl = wp.max(wp.dot(n, sun_dir), 0.0)
    to_lamp = lamp_pos - p
    r2 = wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
    inv_r = 1.0 / wp.sqrt(r2)
    ldir = to_lamp * inv_r
    lpow = lamp_power * (inv_r * inv_r)
    ndp = wp.max(wp.dot(n, ldir), 0.0)
    color = wp.cw_mul(albedo, ambient + sun_color * ndl + lpow * ndp)
    if spec[0] > 0.0:
        v = wp.normalize(to_eye)
        hs = wp.max(wp.dot(n, wp.normalize(sun_dir + v)), 0.0)
        hl = wp.max(wp.dot(n, wp.normalize(ldir + v)), 0.0)
        if ndl > 0.0:
            color = color + sun_color * (spec[0] * spec_power(hs, spec[1]))
        if ndp > 0.0:
            color = color + lpow * (spec[0] * spec_power(hl, spec[1]))
    return color


@wp.func(inline=True)
def light_surface(albedo: wp.vec3, spec: wp.vec2, p: wp.vec3, n: wp.vec3, to_eye: wp.vec3, L: Lights, w: int,
                  first: int) -> wp.vec3:
    """Ambient + Lambert + Blinn-Phong for the directional sun and every point light of world ``w``, linear RGB.

    ``to_eye`` points from the surface toward the camera (any length); a point light's irradiance falls with the
    inverse square of the distance. Specular terms are evaluated only where ``spec[0] > 0`` (magnets), with
    Schlick's approximation of the power, so matte surfaces pay for Lambert only. ``first``: the world's first
    shadow map (< 0: unshadowed).
    """
    sd = L.sun_dir[wrow(w, L.sun_dir.shape[0])]
    sc = L.sun_color[wrow(w, L.sun_color.shape[0])]
    wl = wrow(w, L.pos.shape[0])
    ndl = wp.max(wp.dot(n, sd), 0.0)
    irr = L.ambient[wrow(w, L.ambient.shape[0])] + sc * shadow_factor(L, first, 0, ndl, p, n)
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        ldir, lpow, ndp = point_light(L, wl, i, p, n)
        irr = irr + lpow * shadow_factor(L, first, 1 + i, ndp, p, n)
    color = wp.cw_mul(albedo, irr)
    if spec[0] > 0.0:
        v = wp.normalize(to_eye)
        hs = wp.max(wp.dot(n, wp.normalize(sd + v)), 0.0)
        if ndl > 0.0:
            color = color + sc * (spec[0] * spec_power(hs, spec[1]) * shadow_factor(L, first, 0, 1.0, p, n))
        for i in range(L.pos.shape[1]):
            if is_dark(L, wl, i):
                continue
            ldir, lpow, ndp = point_light(L, wl, i, p, n)
            hl = wp.max(wp.dot(n, wp.normalize(ldir + v)), 0.0)
            if ndp > 0.0:
                color = color + lpow * (spec[0] * spec_power(hl, spec[1]) * shadow_factor(L, first, 1 + i, 1.0, p, n))
    return color


@wp.func
def paper_light(albedo: wp.vec3, n: wp.vec3, v: wp.vec3, ndv: float, l: wp.vec3, irr: wp.vec3, vis: float,
                pb: wp.vec4) -> wp.vec3:
    """One light (unit direction ``l``, irradiance ``irr`` on a facing surface, visibility ``vis``) on paper:
    wrapped diffuse ``max(n.l + w, 0) / (1 + w)`` (light through the thin sheet softens the terminator, w = pb[0])
    plus a soft white sheen, Charlie's distribution ``(2 + 1/r) sin(theta_h)^(1/r) / (2 pi)`` with Ashikhmin's
    visibility ``1 / (4 (n.l + n.v - n.l n.v))`` times n.l, strength pb[1], roughness r = pb[2]."""
    ndl = wp.dot(n, l)
    color = wp.cw_mul(albedo, irr) * (wp.max(ndl + pb[0], 0.0) / (1.0 + pb[0]) * vis)
    if ndl > 0.0 and pb[1] > 0.0:
        nh = wp.dot(n, wp.normalize(l + v))
        sin2 = wp.max(1.0 - nh * nh, 0.0)
        d = (2.0 + 1.0 / pb[2]) * wp.pow(sin2, 0.5 / pb[2]) / (2.0 * wp.pi)
        color = color + irr * (pb[1] * d / (4.0 * (ndl + ndv - ndl * ndv)) * ndl * vis)
    return color


@wp.func(inline=True)
def paper_surface(albedo: wp.vec3, p: wp.vec3, n: wp.vec3, to_eye: wp.vec3, L: Lights, w: int, first: int,
                  pb: wp.vec4) -> wp.vec3:
    """The sheet's paper BSDF (``render.paper_bsdf``) under the sun and every point light: :func:`paper_light` each,
    and a hemispherical ambient, the sky's ``ambient`` from above fading to ``pb[3]`` of it from below (the
    floor's bounce) instead of a constant."""
    v = wp.normalize(to_eye)
    ndv = wp.max(wp.dot(n, v), 1.0e-4)
    sky = 0.5 * (1.0 + n[2])
    color = wp.cw_mul(albedo, L.ambient[wrow(w, L.ambient.shape[0])]) * (pb[3] + (1.0 - pb[3]) * sky)
    sd = L.sun_dir[wrow(w, L.sun_dir.shape[0])]
    vis = float(1.0)
    if wp.dot(n, sd) + pb[0] > 0.0:
        vis = shadow_factor(L, first, 0, 1.0, p, n)
    color = color + paper_light(albedo, n, v, ndv, sd, L.sun_color[wrow(w, L.sun_color.shape[0])], vis, pb)
    wl = wrow(w, L.pos.shape[0])
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        ldir, lpow, ndp = point_light(L, wl, i, p, n)
        vis = 1.0
        if wp.dot(n, ldir) + pb[0] > 0.0:
            vis = shadow_factor(L, first, 1 + i, 1.0, p, n)
        color = color + paper_light(albedo, n, v, ndv, ldir, lpow, vis, pb)
    return color


@wp.func
def mesh_surface(
    key: wp.int64,
    triangles: wp.array(dtype=wp.vec3i),
    tri_label: wp.array(dtype=wp.int32),
    vertices: wp.array2d(dtype=wp.vec3),
    texcoords: wp.array2d(dtype=wp.vec3),
    w: int,
    R: wp.mat33,
    t: wp.vec3,
    k: wp.vec4,
    px: float,
    py: float,
    eye: wp.vec3,
    d_world: wp.vec3,
):
    """The triangle the raster pass kept at pixel (px, py) (its ``zkey``): (camera z, segmentation id, unnormalized
    world normal, material coordinates of the hit), or (1e30, background, 0, 0) where no triangle covers it."""
    best_z = float(1.0e30)
    label = int(SEG_BACKGROUND)
    n_world = wp.vec3(0.0)
    mat = wp.vec3(0.0)
    if key != _EMPTY:
        tri = int(key % _TRI_SCALE)
        f = triangles[tri]
        a = vertices[w, f[0]]
        b = vertices[w, f[1]]
        c = vertices[w, f[2]]
        plane = depth_plane(R * a + t, R * b + t, R * c + t, k)
        best_z = plane[0] / (plane[1] * px + plane[2] * py + plane[3])  # the raster pass's formula, bit for bit
        label = tri_label[tri]
        # perspective-correct barycentrics: areas of the 3-D hit point against the world triangle
        hit = eye + best_z * d_world
        nw = wp.cross(b - a, c - a)
        inv = 1.0 / wp.dot(nw, nw)
        la = wp.dot(nw, wp.cross(c - b, hit - b)) * inv
        lb = wp.dot(nw, wp.cross(a - c, hit - c)) * inv
        mat = la * texcoords[w, f[0]] + lb * texcoords[w, f[1]] + (1.0 - la - lb) * texcoords[w, f[2]]
        n_world = nw * wp.sqrt(inv)
    return best_z, label, n_world, mat


@wp.struct
class FloorRow:
    """One image row's ray against the floor plane: along a row the world ray is affine in x, d(x) = d0 + x dx, and
    so are its dot products with the floor normal and axes (``den``, ``du``, ``dv``: value at x = 0, step per pixel).
    ``height``: the eye's height above the plane; ``eu``, ``ev``: the eye's floor coordinates (from the floor's
    origin); ``half``: half side."""

    den0: float
    dden: float
    du0: float
    ddu: float
    dv0: float
    ddv: float
    eu: float
    ev: float
    height: float
    half: float


@wp.func
def floor_row(fn: wp.vec3, fa: wp.vec3, fo: wp.vec3, half: float, eye: wp.vec3, d0: wp.vec3, dx: wp.vec3) -> FloorRow:
    """The :class:`FloorRow` of the row whose ray is ``d0 + x dx`` from ``eye``, for the floor square with normal
    ``fn``, in-plane axis ``fa`` and centre ``fo`` (a point of the plane through the world origin)."""
    fb = wp.cross(fn, fa)
    fr = FloorRow()
    fr.den0 = wp.dot(fn, d0)
    fr.dden = wp.dot(fn, dx)
    fr.eu = wp.dot(eye - fo, fa)
    fr.ev = wp.dot(eye - fo, fb)
    fr.du0 = wp.dot(d0, fa)
    fr.ddu = wp.dot(dx, fa)
    fr.dv0 = wp.dot(d0, fb)
    fr.ddv = wp.dot(dx, fb)
    fr.height = wp.dot(fn, eye)
    fr.half = half
    return fr


@wp.func
def nearer_floor(fr: FloorRow, px: float, best_z: float, label: int, mat: wp.vec3):
    """The analytic floor (the square |u|, |v| <= half of its plane, seen from above only) where it is nearer
    than the mesh's surface at pixel x = px: (z, label, material coordinates (u, v, 0))."""
    z_out = best_z
    label_out = label
    mat_out = mat
    denom = fr.den0 + px * fr.dden
    if denom < 0.0 and fr.height > 0.0:
        zf = -fr.height / denom
        if zf < best_z:
            fu = fr.eu + zf * (fr.du0 + px * fr.ddu)
            fv = fr.ev + zf * (fr.dv0 + px * fr.ddv)
            if wp.abs(fu) <= fr.half and wp.abs(fv) <= fr.half:
                z_out = zf
                label_out = int(SEG_FLOOR)
                mat_out = wp.vec3(fu, fv, 0.0)
    return z_out, label_out, mat_out


@wp.struct
class Look:
    """Per-world surfaces (arrays read as ``a[wrow(w, a.shape[0])]``): ``albedo`` (linear RGB) and ``specular``
    (strength, Blinn exponent) per segmentation id, (Wa, 11); the floor square: unit ``floor_normal``, in-plane
    ``floor_axis`` (+u), centre ``floor_origin`` [m], ``floor_half`` [m]; ``floor_tex`` (tile [m], checker contrast,
    grain amplitude, grain frequency [1/m]); ``floor_color2``; ``paper_tex`` (fibre, mottle amplitudes);
    ``tex_seed`` (offsets the shared ``noise`` texture per world); background gradient ``bg_top``, ``bg_bottom``;
    ``floor_transmit``: the fraction of the light from meshes under the floor that shows through it (a clear plate);
    ``paper_bsdf``: (wrap, sheen, sheen roughness, ground ambient) of the sheet (:func:`paper_surface`; 0: Lambert)."""

    albedo: wp.array2d(dtype=wp.vec3)
    specular: wp.array2d(dtype=wp.vec2)
    floor_normal: wp.array(dtype=wp.vec3)
    floor_axis: wp.array(dtype=wp.vec3)
    floor_origin: wp.array(dtype=wp.vec3)
    floor_half: wp.array(dtype=float)
    floor_tex: wp.array(dtype=wp.vec4)
    floor_color2: wp.array(dtype=wp.vec3)
    paper_tex: wp.array(dtype=wp.vec2)
    tex_seed: wp.array(dtype=wp.int32)
    bg_top: wp.array(dtype=wp.vec3)
    bg_bottom: wp.array(dtype=wp.vec3)
    noise: wp.array2d(dtype=float)
    floor_transmit: wp.array(dtype=float)
    paper_bsdf: wp.array(dtype=wp.vec4)


@wp.func(inline=True)
def noise_offset(look: Look, w: int) -> wp.vec2:
    """World ``w``'s offset [texels] into the shared noise texture, from its texture seed."""
    seed0 = look.tex_seed[wrow(w, look.tex_seed.shape[0])]
    return wp.vec2(float(seed0 & 4095) * 0.03125, float((seed0 >> 12) & 4095) * 0.03125)


@wp.func
def floor_albedo(base: wp.vec3, mat: wp.vec3, inv_tile: float, ft: wp.vec4, fc2: wp.vec3,
                 noise: wp.array2d(dtype=float), off_u: float, off_v: float) -> wp.vec3:
    """The floor's checker (tiles ``1 / inv_tile`` [m], colours ``base`` and its mix with ``fc2``) and grain at floor
    coordinates ``mat`` [m] (``ft``: the world's ``Look.floor_tex``; ``off_u``, ``off_v``: its noise offset)."""
    cu = int(wp.floor(mat[0] * inv_tile))
    cv = int(wp.floor(mat[1] * inv_tile))
    albedo = base
    if ((cu + cv) & 1) != 0:
        albedo = wp.lerp(base, fc2, ft[1])
    g = noise_tex(noise, mat[0] * ft[3] + off_u, mat[1] * ft[3] + off_v)
    return albedo * (1.0 + ft[2] * (g - 0.5))


@wp.func(inline=True)
def floor_albedo_at(look: Look, w: int, mat: wp.vec3) -> wp.vec3:
    """World ``w``'s floor albedo (checker + grain, :func:`floor_albedo`) at floor coordinates ``mat`` [m]."""
    ft = look.floor_tex[wrow(w, look.floor_tex.shape[0])]
    off = noise_offset(look, w)
    return floor_albedo(look.albedo[wrow(w, look.albedo.shape[0]), SEG_FLOOR], mat, 1.0 / ft[0], ft,
                        look.floor_color2[wrow(w, look.floor_color2.shape[0])], look.noise, off[0], off[1])


@wp.func(inline=True)
def floor_lit(look: Look, L: Lights, w: int, first: int, albedo: wp.vec3, p: wp.vec3, to_eye: wp.vec3) -> wp.vec3:
    """The floor of albedo ``albedo`` at ``p``: ambient + sun + every point light, and, for a glossy plate (floor
    specular strength > 0), their highlights seen along ``to_eye``. Linear in ``albedo`` plus the highlights."""
    fn = look.floor_normal[wrow(w, look.floor_normal.shape[0])]
    sc = L.sun_color[wrow(w, L.sun_color.shape[0])]
    ndl = wp.max(wp.dot(fn, L.sun_dir[wrow(w, L.sun_dir.shape[0])]), 0.0)
    irr = L.ambient[wrow(w, L.ambient.shape[0])] + sc * shadow_factor(L, first, 0, ndl, p, fn)
    wl = wrow(w, L.pos.shape[0])
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        to_lamp = L.pos[wl, i] - p
        inv_r2 = 1.0 / wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
        ndp = wp.max(wp.dot(fn, to_lamp), 0.0) * wp.sqrt(inv_r2)
        irr = irr + L.power[wl, i] * (shadow_factor(L, first, 1 + i, ndp, p, fn) * inv_r2)
    color = wp.cw_mul(albedo, irr)
    spec = look.specular[wrow(w, look.specular.shape[0]), SEG_FLOOR]
    if spec[0] > 0.0:  # a glossy plate (render.plate_materials): Blinn-Phong highlights of every light
        color = color + floor_highlights(L, w, first, spec, p, fn, to_eye)
    return color


@wp.func(inline=True)
def floor_highlights(L: Lights, w: int, first: int, spec: wp.vec2, p: wp.vec3, fn: wp.vec3, to_eye: wp.vec3
                     ) -> wp.vec3:
    """Blinn-Phong highlights (strength, exponent ``spec``) of the sun and every point light on the floor at ``p``
    seen along ``to_eye``, shadowed like the diffuse term."""
    v = wp.normalize(to_eye)
    sd = L.sun_dir[wrow(w, L.sun_dir.shape[0])]
    out = wp.vec3(0.0)
    if wp.dot(fn, sd) > 0.0:
        hs = wp.max(wp.dot(fn, wp.normalize(sd + v)), 0.0)
        out = L.sun_color[wrow(w, L.sun_color.shape[0])] * (spec[0] * spec_power(hs, spec[1]) *
                                                       shadow_factor(L, first, 0, 1.0, p, fn))
    wl = wrow(w, L.pos.shape[0])
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        ldir, lpow, ndp = point_light(L, wl, i, p, fn)
        if ndp > 0.0:
            hl = wp.max(wp.dot(fn, wp.normalize(ldir + v)), 0.0)
            out = out + lpow * (spec[0] * spec_power(hl, spec[1]) * shadow_factor(L, first, 1 + i, 1.0, p, fn))
    return out


@wp.func(inline=True)
def object_albedo(look: Look, w: int, label: int, mat: wp.vec3) -> wp.vec3:
    """A worm or magnet surface's albedo at material coordinates ``mat``: paper texture on the sheet, the EPM's
    painted half."""
    off = noise_offset(look, w)
    return textured_albedo(look.albedo[wrow(w, look.albedo.shape[0]), label], label, mat,
                           look.paper_tex[wrow(w, look.paper_tex.shape[0])], look.noise, off[0], off[1])


@wp.func
def textured_albedo(base: wp.vec3, label: int, mat: wp.vec3, pt: wp.vec2, noise: wp.array2d(dtype=float),
                    off_u: float, off_v: float) -> wp.vec3:
    """:func:`object_albedo` from the world's values: ``base`` albedo of ``label``, paper texture amplitudes ``pt``,
    noise offset (``off_u``, ``off_v``) [texels]."""
    albedo = base
    if label <= SEG_WORM_LAST:
        # paper: short fibres (noise stretched along the sheet's x) over a soft mottle; material coordinates
        # are the rest positions [m], so the texture sticks to the sheet as it folds
        sw = mat[1] + mat[2]
        fib = noise_tex(noise, mat[0] * 2500.0 + off_v, sw * 600.0 + off_u)
        mot = noise_tex(noise, mat[0] * 180.0 - off_u, (mat[1] - mat[2]) * 180.0 + off_v)
        albedo = base * (1.0 + pt[0] * (fib - 0.5) + pt[1] * (mot - 0.5))
    elif label == SEG_EPM:
        if mat[2] > 0.0:
            albedo = base * 0.55  # a painted north half breaks the bar's 180 degree symmetry
    return albedo


@wp.func(inline=True)
def surface_albedo(look: Look, w: int, label: int, mat: wp.vec3) -> wp.vec3:
    """Albedo (linear RGB) of surface ``label`` at material coordinates ``mat``: the floor's checker and grain, the
    paper and magnets' textures; 0 for the background."""
    albedo = wp.vec3(0.0)
    if label == SEG_FLOOR:
        albedo = floor_albedo_at(look, w, mat)
    elif label != SEG_BACKGROUND:
        albedo = object_albedo(look, w, label, mat)
    return albedo


@wp.func(inline=True)
def shade_surface(look: Look, L: Lights, w: int, first: int, label: int, albedo: wp.vec3, z: float,
                  n_world: wp.vec3, eye: wp.vec3, d_world: wp.vec3, bg: wp.vec3):
    """Colour (linear RGB) and unit world normal (0 for background) of surface ``label`` of albedo ``albedo`` hit at
    camera depth ``z`` along ``d_world`` (mesh normal ``n_world``, unnormalized). Linear in ``albedo`` (plus
    highlights and sheen), so a pixel's samples on one surface may share it with their mean albedo."""
    color = bg
    nrm = wp.vec3(0.0)
    if label == SEG_FLOOR:
        nrm = look.floor_normal[wrow(w, look.floor_normal.shape[0])]
        color = floor_lit(look, L, w, first, albedo, eye + z * d_world, -d_world)
    elif label != SEG_BACKGROUND:
        nrm = n_world
        if wp.dot(n_world, -d_world) < 0.0:
            nrm = -n_world  # double-sided sheet: light the side the camera sees
        pb = look.paper_bsdf[wrow(w, look.paper_bsdf.shape[0])]
        if label <= SEG_WORM_LAST and (pb[0] > 0.0 or pb[1] > 0.0 or pb[3] > 0.0):
            color = paper_surface(albedo, eye + z * d_world, nrm, -d_world, L, w, first, pb)
        else:
            color = light_surface(albedo, look.specular[wrow(w, look.specular.shape[0]), label], eye + z * d_world,
                                  nrm, -d_world, L, w, first)
    return color, nrm


@wp.func(inline=True)
def shade_hit(look: Look, L: Lights, w: int, first: int, label: int, z: float, mat: wp.vec3, n_world: wp.vec3,
              eye: wp.vec3, d_world: wp.vec3, bg: wp.vec3):
    """:func:`shade_surface` with the surface's own albedo at material coordinates ``mat``."""
    color, nrm = shade_surface(look, L, w, first, label, surface_albedo(look, w, label, mat), z, n_world, eye,
                               d_world, bg)
    return color, nrm


@wp.struct
class PlainWorld:
    """One world's values the plain path (:func:`make_resolve_shade`) loads once per thread: its lights (ambient,
    sun, the one lamp), floor (checker ``ft``, ``inv_tile`` = 1 / tile [m], second colour ``fc2``, ``floor_irr``:
    the ambient + sun irradiance of its constant normal ``fn``), paper texture ``pt`` and noise offset [texels]."""

    amb: wp.vec3
    sd: wp.vec3
    sc: wp.vec3
    lp: wp.vec3
    lpw: wp.vec3
    fn: wp.vec3
    ft: wp.vec4
    inv_tile: float
    fc2: wp.vec3
    floor_irr: wp.vec3
    pt: wp.vec2
    off_u: float
    off_v: float


@wp.func
def plain_world(look: Look, L: Lights, w: int) -> PlainWorld:
    """World ``w``'s :class:`PlainWorld` (one lamp: light 0)."""
    pw = PlainWorld()
    pw.amb = L.ambient[wrow(w, L.ambient.shape[0])]
    pw.sd = L.sun_dir[wrow(w, L.sun_dir.shape[0])]
    pw.sc = L.sun_color[wrow(w, L.sun_color.shape[0])]
    pw.lp = L.pos[wrow(w, L.pos.shape[0]), 0]
    pw.lpw = L.power[wrow(w, L.power.shape[0]), 0]
    pw.fn = look.floor_normal[wrow(w, look.floor_normal.shape[0])]
    pw.ft = look.floor_tex[wrow(w, look.floor_tex.shape[0])]
    pw.inv_tile = 1.0 / pw.ft[0]
    pw.fc2 = look.floor_color2[wrow(w, look.floor_color2.shape[0])]
    pw.floor_irr = pw.amb + pw.sc * wp.max(wp.dot(pw.fn, pw.sd), 0.0)
    pw.pt = look.paper_tex[wrow(w, look.paper_tex.shape[0])]
    off = noise_offset(look, w)
    pw.off_u = off[0]
    pw.off_v = off[1]
    return pw


@wp.func(inline=True)
def shade_hit_plain(look: Look, pw: PlainWorld, wa: int, ws: int, label: int, z: float, mat: wp.vec3,
                    n_world: wp.vec3, eye: wp.vec3, d_world: wp.vec3, bg: wp.vec3):
    """:func:`shade_hit` for the plain path: world ``pw`` (its albedo row ``wa``, specular row ``ws``) under one lamp,
    no shadows, Lambert paper, a matte opaque floor."""
    color = bg
    nrm = wp.vec3(0.0)
    if label == SEG_FLOOR:
        nrm = pw.fn
        p = eye + z * d_world
        to_lamp = pw.lp - p
        inv_r2 = 1.0 / wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
        ndp = wp.max(wp.dot(pw.fn, to_lamp), 0.0) * wp.sqrt(inv_r2)
        albedo = floor_albedo(look.albedo[wa, SEG_FLOOR], mat, pw.inv_tile, pw.ft, pw.fc2, look.noise, pw.off_u,
                              pw.off_v)
        color = wp.cw_mul(albedo, pw.floor_irr + pw.lpw * (ndp * inv_r2))
    elif label != SEG_BACKGROUND:
        nrm = n_world
        if wp.dot(n_world, -d_world) < 0.0:
            nrm = -n_world  # double-sided sheet: light the side the camera sees
        base = textured_albedo(look.albedo[wa, label], label, mat, pw.pt, look.noise, pw.off_u, pw.off_v)
        color = light_surface_plain(base, look.specular[ws, label], eye + z * d_world, nrm, -d_world, pw.amb, pw.sd,
                                    pw.sc, pw.lp, pw.lpw)
    return color, nrm


def make_resolve_shade(plain: bool, shade: bool = True):
    """The resolve/shade kernel: ``plain`` compiles the default look's path only (one lit lamp, no shadows, Lambert
    paper, matte opaque floor; world values loaded once per thread, the same bits as the general kernel in a third of
    its CPU time); ``shade=False`` (:data:`resolve_labels`) writes depth, segmentation and normals only. The general
    kernel shades every option (shadow maps, any number of lights, paper BSDF, glossy and clear plates); see
    docs/render.md, "The plain path".
    """

    @wp.kernel(name="resolve_labels" if not shade else ("resolve_shade_plain" if plain else "resolve_shade"))
    def resolve_shade(
        # Model:
        triangles: wp.array(dtype=wp.vec3i), tri_label: wp.array(dtype=wp.int32),
        look: Look, lights: Lights,
        # Data in:
        vertices: wp.array2d(dtype=wp.vec3), texcoords: wp.array2d(dtype=wp.vec3),
        image_world: wp.array(dtype=wp.int32),
        cam_rot: wp.array(dtype=wp.mat33), cam_trans: wp.array(dtype=wp.vec3), cam_intr: wp.array(dtype=wp.vec4),
        zkey: wp.array2d(dtype=wp.int64),
        width: int, height: int, span: int, write_normals: int,
        cam_gain: wp.array(dtype=wp.vec3),
        # Data out:
        rgb: wp.array2d(dtype=wp.vec3ub), depth: wp.array2d(dtype=float), seg: wp.array2d(dtype=wp.uint8),
        normals: wp.array2d(dtype=wp.vec3),
    ):
        """Resolve the nearest surface and shade ``span`` pixels of one row of one image; launched as
        ``(N, height, ceil(width / span))`` (span 1 on CUDA, the whole row on the CPU). Beyond
        :func:`raster_triangles`'s arguments: ``texcoords`` (W, Vs) material coordinates [m] (procedural textures move
        with the surface); ``zkey`` (N, H*W) the raster pass's keys; ``cam_gain`` (N,) linear RGB gain (exposure x
        white balance); outputs (N, H*W): ``rgb`` vec3ub, ``depth`` camera z [m] (0 background), ``seg`` ids,
        ``normals`` camera-frame unit normals when ``write_normals`` is 1 (else a 1-element dummy)."""
        img, y, xb = wp.tid()
        x_begin = xb * span
        x_end = wp.min(x_begin + span, width)
        w = image_world[img]
        R = cam_rot[img]
        t = cam_trans[img]
        k = cam_intr[img]
        Rt = wp.transpose(R)
        eye = -(Rt * t)
        py = float(y)
        wf = wrow(w, look.floor_normal.shape[0])
        bg = wp.lerp(look.bg_top[wrow(w, look.bg_top.shape[0])], look.bg_bottom[wrow(w, look.bg_bottom.shape[0])],
                     py / float(height))
        first = int(-1)
        if lights.shadows != 0:
            first = lights.map_first[w]
        row = y * width
        gain = cam_gain[img]
        transmit = look.floor_transmit[wrow(w, look.floor_transmit.shape[0])]
        pw = plain_world(look, lights, w)
        wa = wrow(w, look.albedo.shape[0])
        ws = wrow(w, look.specular.shape[0])
        # along a row the world ray is affine in x: d(x) = d0 + x * dx, and so are its dot products with the floor
        d0 = Rt * wp.vec3(-k[2] / k[0], (py - k[3]) / k[1], 1.0)
        dx = Rt * wp.vec3(1.0 / k[0], 0.0, 0.0)
        fr = floor_row(look.floor_normal[wf], look.floor_axis[wrow(w, look.floor_axis.shape[0])],
                       look.floor_origin[wrow(w, look.floor_origin.shape[0])],
                       look.floor_half[wrow(w, look.floor_half.shape[0])], eye, d0, dx)
        for x in range(x_begin, x_end):
            px = float(x)
            d_world = d0 + px * dx  # a point at camera depth z lies at eye + z * d_world
            mz, mlabel, n_world, mmat = mesh_surface(zkey[img, row + x], triangles, tri_label, vertices, texcoords,
                                                     w, R, t, k, px, py, eye, d_world)
            best_z, label, mat = nearer_floor(fr, px, mz, mlabel, mmat)
            color = bg
            nrm = wp.vec3(0.0)
            if wp.static(not shade):
                if label == SEG_FLOOR:
                    nrm = pw.fn
                elif label != SEG_BACKGROUND:
                    nrm = n_world
                    if wp.dot(n_world, -d_world) < 0.0:
                        nrm = -n_world
            elif wp.static(plain):
                color, nrm = shade_hit_plain(look, pw, wa, ws, label, best_z, mat, n_world, eye, d_world, bg)
            else:
                color, nrm = shade_hit(look, lights, w, first, label, best_z, mat, n_world, eye, d_world, bg)
                if label != mlabel and mlabel != SEG_BACKGROUND and transmit > 0.0:
                    # a clear plate (render.plate_materials: acrylic): the mesh under it (the EPM) shows through
                    under, _n = shade_hit(look, lights, w, first, mlabel, mz, mmat, n_world, eye, d_world, bg)
                    color = wp.lerp(color, under, transmit)
            if label == SEG_BACKGROUND:
                best_z = 0.0
            if write_normals != 0:
                if label == SEG_BACKGROUND:
                    normals[img, row + x] = wp.vec3(0.0)
                else:
                    normals[img, row + x] = R * nrm
            if wp.static(shade):
                color = wp.cw_mul(color, gain)
                rgb[img, row + x] = wp.vec3ub(to_srgb8(color[0]), to_srgb8(color[1]), to_srgb8(color[2]))
            depth[img, row + x] = best_z
            if label > SEG_EPM:
                label = SEG_FLOOR  # a distractor object (its own albedo row): static scene, the floor's id
            seg[img, row + x] = wp.uint8(label)

    return resolve_shade


resolve_shade = make_resolve_shade(False)
"""Resolve the nearest surface of every pixel and shade it, every option (:func:`make_resolve_shade`)."""
resolve_shade_plain = make_resolve_shade(True)
"""The same for batches without any per-pixel shading option: the default look's path, bit for bit."""
resolve_labels = make_resolve_shade(True, shade=False)
"""Depth, segmentation and normals only (the same labels as :data:`resolve_shade`, without shading or shadow maps)."""


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
    for _it in range(iterations):
        r2 = u * u + v * v
        radial = one + r2 * (k1 + r2 * (k2 + r2 * k3))
        drad = two * (k1 + r2 * (two * k2 + wp.float64(3.0) * k3 * r2))
        fx = u * radial + two * p1 * u * v + p2 * (r2 + two * u * u) - xd
        fy = v * radial + p1 * (r2 + two * v * v) + two * p2 * u * v - yd
        a = radial + u * u * drad + two * p1 * v + wp.float64(6.0) * p2 * u
        b = u * v * drad + two * p1 * u + two * p2 * v
        d = radial + v * v * drad + wp.float64(6.0) * p1 * v + two * p2 * u
        det = a * d - b * b
        u = u - (d * fx - b * fy) / det
        v = v - (a * fy - b * fx) / det
    # where the polynomial folds back before this point's radius, no ray reaches it: Newton wanders or lands on the
    # far (folded) branch; say so instead of returning a wrong ray
    r2 = u * u + v * v
    radial = one + r2 * (k1 + r2 * (k2 + r2 * k3))
    drad = two * (k1 + r2 * (two * k2 + wp.float64(3.0) * k3 * r2))
    ex = u * radial + two * p1 * u * v + p2 * (r2 + two * u * u) - xd
    ey = v * radial + p1 * (r2 + two * v * v) + two * p2 * u * v - yd
    a = radial + u * u * drad + two * p1 * v + wp.float64(6.0) * p2 * u
    b = u * v * drad + two * p1 * u + two * p2 * v
    d = radial + v * v * drad + wp.float64(6.0) * p1 * v + two * p2 * u
    ok = ex * ex + ey * ey <= wp.float64(1.0e-18) and a > wp.float64(0.0) and a * d - b * b > wp.float64(0.0)
    return u, v, a, b, d, ok


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
    k = intr[img]
    u, v, _a, _b, _d, ok = lens_inverse((wp.float64(x) - k[2]) / k[0], (wp.float64(y) - k[3]) / k[1], dist[img, 0],
                                       dist[img, 1], dist[img, 2], dist[img, 3], dist[img, 4], iterations)
    if not ok:
        nan = wp.float64(wp.nan)
        pinhole[img, y, x] = wp.vec2d(nan, nan)
        return
    pinhole[img, y, x] = wp.vec2d(k[0] * u + k[2], k[1] * v + k[3])
