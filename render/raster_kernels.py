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

NUM_LABELS = ids.NUM_SEGMENTATION_IDS
"""Segmentation ids 0..10 (:mod:`warpworm.ids`): 0 background, 1 floor, 2..6 worm segments, 7..9 IPMs, 10 EPM."""

LABEL_BACKGROUND = ids.SEG_BACKGROUND
LABEL_FLOOR = ids.SEG_FLOOR
LABEL_WORM_FIRST = ids.SEG_WORM_FIRST
LABEL_WORM_LAST = ids.SEG_WORM_LAST
LABEL_IPM_FIRST = ids.SEG_IPM_FIRST
LABEL_EPM = ids.SEG_EPM

TRI_BITS = 24
"""Low bits of the packed key that hold the triangle index."""
DEPTH_SCALE = float(1 << 24)
"""Fixed-point depth units per metre in the packed key."""
EMPTY_KEY = (1 << 63) - 1
"""Key of a pixel no triangle covers (int64 max)."""

_TRI_SCALE = wp.constant(wp.int64(1 << TRI_BITS))
_DEPTH_SCALE = wp.constant(DEPTH_SCALE)
_EMPTY = wp.constant(wp.int64(EMPTY_KEY))
# hash multipliers as typed constants (a bare literal above 2**31 would be read as int32 first)
_HM1 = wp.constant(wp.uint32(0x7FEB352D))
_HM2 = wp.constant(wp.uint32(0x846CA68B))
_PX = wp.constant(wp.uint32(0x8DA6B343))
_PY = wp.constant(wp.uint32(0xD8163841))
_PZ = wp.constant(wp.uint32(0xCB1AB31F))


# ---------------------------------------------------------------------------------------------------------------------
# helpers
# ---------------------------------------------------------------------------------------------------------------------


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


@wp.func
def hash_u32(x: wp.uint32) -> wp.uint32:
    """lowbias32 integer hash (Wellons): cheap, well mixed, identical on CPU and CUDA."""
    x = x ^ (x >> wp.uint32(16))
    x = x * _HM1
    x = x ^ (x >> wp.uint32(15))
    x = x * _HM2
    x = x ^ (x >> wp.uint32(16))
    return x


@wp.func
def lattice(ix: int, iy: int, iz: int, seed: int) -> float:
    """Hash of an integer lattice point to [0, 1)."""
    h = hash_u32(wp.uint32(ix) * _PX ^ wp.uint32(iy) * _PY ^ wp.uint32(iz) * _PZ ^ wp.uint32(seed))
    return float(h >> wp.uint32(8)) * (1.0 / 16777216.0)


@wp.func
def value_noise2(x: float, y: float, seed: int) -> float:
    """2-D value noise in [0, 1): smoothstep interpolation of hashed lattice values (4 hashes)."""
    fx = wp.floor(x)
    fy = wp.floor(y)
    ix = int(fx)
    iy = int(fy)
    tx = x - fx
    ty = y - fy
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    a = wp.lerp(lattice(ix, iy, 0, seed), lattice(ix + 1, iy, 0, seed), tx)
    b = wp.lerp(lattice(ix, iy + 1, 0, seed), lattice(ix + 1, iy + 1, 0, seed), tx)
    return wp.lerp(a, b, ty)


@wp.func
def value_noise3(p: wp.vec3, seed: int) -> float:
    """3-D value noise in [0, 1) (8 hashes); used on material coordinates so texture sticks to the sheet."""
    fx = wp.floor(p[0])
    fy = wp.floor(p[1])
    fz = wp.floor(p[2])
    ix = int(fx)
    iy = int(fy)
    iz = int(fz)
    tx = p[0] - fx
    ty = p[1] - fy
    tz = p[2] - fz
    tx = tx * tx * (3.0 - 2.0 * tx)
    ty = ty * ty * (3.0 - 2.0 * ty)
    tz = tz * tz * (3.0 - 2.0 * tz)
    a0 = wp.lerp(lattice(ix, iy, iz, seed), lattice(ix + 1, iy, iz, seed), tx)
    b0 = wp.lerp(lattice(ix, iy + 1, iz, seed), lattice(ix + 1, iy + 1, iz, seed), tx)
    a1 = wp.lerp(lattice(ix, iy, iz + 1, seed), lattice(ix + 1, iy, iz + 1, seed), tx)
    b1 = wp.lerp(lattice(ix, iy + 1, iz + 1, seed), lattice(ix + 1, iy + 1, iz + 1, seed), tx)
    return wp.lerp(wp.lerp(a0, b0, ty), wp.lerp(a1, b1, ty), tz)


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
    fx = k[0]
    fy = k[1]
    cx = k[2]
    cy = k[3]
    u0 = fx * p0[0] / p0[2] + cx
    v0 = fy * p0[1] / p0[2] + cy
    u1 = fx * p1[0] / p1[2] + cx
    v1 = fy * p1[1] / p1[2] + cy
    u2 = fx * p2[0] / p2[2] + cx
    v2 = fy * p2[1] / p2[2] + cy
    area = edge_fn(u0, v0, u1, v1, u2, v2)
    if area == 0.0:
        return
    if area < 0.0:
        # double-sided: reorder to positive screen area so one inside test and one top-left rule serve both sides
        tu = u1
        tv = v1
        u1 = u2
        v1 = v2
        u2 = tu
        v2 = tv

    # pixel centres are integers: cover columns ceil(umin)..floor(umax), clamped (clamp first: no int overflow)
    fw = float(width)
    fh = float(height)
    xmin = int(wp.ceil(wp.clamp(wp.min(wp.min(u0, u1), u2), -1.0, fw)))
    xmax = int(wp.floor(wp.clamp(wp.max(wp.max(u0, u1), u2), -1.0, fw)))
    ymin = int(wp.ceil(wp.clamp(wp.min(wp.min(v0, v1), v2), -1.0, fh)))
    ymax = int(wp.floor(wp.clamp(wp.max(wp.max(v0, v1), v2), -1.0, fh)))
    xmin = wp.max(xmin, 0)
    ymin = wp.max(ymin, 0)
    xmax = wp.min(xmax, width - 1)
    ymax = wp.min(ymax, height - 1)
    if xmin > xmax or ymin > ymax:
        return

    # camera depth at pixel (x, y) from the triangle's plane n.p = nd along the ray ((x-cx)/fx, (y-cy)/fy, 1):
    # z = nd / (a x + b y + c). Exact for any triangle (perspective-correct) and shared with the resolve pass.
    n = wp.cross(p1 - p0, p2 - p0)
    nd = wp.dot(n, p0)
    pa = n[0] / fx
    pb = n[1] / fy
    pc = n[2] - pa * cx - pb * cy

    tl0 = is_top_left(u1, v1, u2, v2)
    tl1 = is_top_left(u2, v2, u0, v0)
    tl2 = is_top_left(u0, v0, u1, v1)
    worm = tri_label[tri] >= LABEL_WORM_FIRST and tri_label[tri] <= LABEL_WORM_LAST
    tkey = wp.int64(tri)

    for y in range(ymin, ymax + 1):
        py = float(y)
        entered = bool(False)
        for x in range(xmin, xmax + 1):
            px = float(x)
            e0 = edge_fn(u1, v1, u2, v2, px, py)
            e1 = edge_fn(u2, v2, u0, v0, px, py)
            e2 = edge_fn(u0, v0, u1, v1, px, py)
            if covers(e0, tl0) and covers(e1, tl1) and covers(e2, tl2):
                entered = True
                z = nd / (pa * px + pb * py + pc)
                key = wp.int64(z * _DEPTH_SCALE) * _TRI_SCALE + tkey
                pix = y * width + x
                wp.atomic_min(zkey, img, pix, key)
                if worm:
                    worm_mask[img, pix] = wp.uint8(1)
            elif entered:
                break  # a row crosses a convex triangle in one run


# ---------------------------------------------------------------------------------------------------------------------
# pass 2: resolve and shade
# ---------------------------------------------------------------------------------------------------------------------


@wp.func
def spec_power(c: float, e: float) -> float:
    """Schlick's rational approximation of ``c**e`` for c in [0, 1]: one division instead of a ``pow``."""
    return c / (e - (e - 1.0) * c)


@wp.func
def light_surface(
    albedo: wp.vec3,
    spec: wp.vec2,
    p: wp.vec3,
    n: wp.vec3,
    to_eye: wp.vec3,
    ambient: wp.vec3,
    sun_dir: wp.vec3,
    sun_color: wp.vec3,
    lamp_pos: wp.vec3,
    lamp_power: wp.vec3,
) -> wp.vec3:
    """Ambient + Lambert + Blinn-Phong for one directional (sun) and one point (lamp) light, linear RGB.

    ``to_eye`` points from the surface toward the camera (any length); ``lamp_power`` is the lamp's irradiance at
    1 m, falling with the inverse square of the distance. Specular terms are evaluated only where ``spec[0] > 0``
    (magnets), with Schlick's approximation of the power, so matte surfaces pay for Lambert only.
    """
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


@wp.kernel
def resolve_shade(
    # Model:
    triangles: wp.array(dtype=wp.vec3i),
    tri_label: wp.array(dtype=wp.int32),
    # Data in:
    vertices: wp.array2d(dtype=wp.vec3),
    texcoords: wp.array2d(dtype=wp.vec3),
    image_world: wp.array(dtype=wp.int32),
    cam_rot: wp.array(dtype=wp.mat33),
    cam_trans: wp.array(dtype=wp.vec3),
    cam_intr: wp.array(dtype=wp.vec4),
    zkey: wp.array2d(dtype=wp.int64),
    width: int,
    height: int,
    span: int,
    # Model (per-world appearance, read as a[w % a.shape[0]]):
    albedo: wp.array2d(dtype=wp.vec3),
    specular: wp.array2d(dtype=wp.vec2),
    floor_normal: wp.array(dtype=wp.vec3),
    floor_axis: wp.array(dtype=wp.vec3),
    floor_half: wp.array(dtype=float),
    floor_tex: wp.array(dtype=wp.vec4),
    floor_color2: wp.array(dtype=wp.vec3),
    paper_tex: wp.array(dtype=wp.vec2),
    tex_seed: wp.array(dtype=wp.int32),
    ambient: wp.array(dtype=wp.vec3),
    sun_dir: wp.array(dtype=wp.vec3),
    sun_color: wp.array(dtype=wp.vec3),
    lamp_pos: wp.array(dtype=wp.vec3),
    lamp_power: wp.array(dtype=wp.vec3),
    bg_top: wp.array(dtype=wp.vec3),
    bg_bottom: wp.array(dtype=wp.vec3),
    noise: wp.array2d(dtype=float),
    write_normals: int,
    # Data out:
    rgb: wp.array2d(dtype=wp.vec3ub),
    depth: wp.array2d(dtype=float),
    seg: wp.array2d(dtype=wp.uint8),
    normals: wp.array2d(dtype=wp.vec3),
):
    """Resolve the nearest surface and shade ``span`` consecutive pixels of one row of one image.

    Launched as ``(N, height, ceil(width / span))``: span = 1 on CUDA (a thread per pixel), span = width on CPU (a
    thread per row, so per-row setup is paid once and the per-thread launch overhead vanishes). Same code either way.

    Args (beyond :func:`raster_triangles`'s):
        texcoords: material coordinates [m] of every scene vertex (rest position for the sheet, magnet-local for
            magnets), shape (W, Vs); procedural textures are functions of them, so they move with the surface.
        zkey: keys written by the raster pass, shape (N, H * W).
        span: pixels per thread along a row.
        albedo: linear RGB albedo per segmentation id, shape (Wa, 11). specular: (strength, Blinn exponent), (Wa, 11).
        floor_normal, floor_axis: unit normal and in-plane +u axis of the floor plane through the world origin, (Wf,).
        floor_half: half side [m] of the square floor, (Wf,).
        floor_tex: (tile size [m], checker contrast [0, 1], grain amplitude, grain frequency [1/m]), (Wf,).
        floor_color2: second checker colour (linear RGB), (Wf,). paper_tex: (fibre amplitude, mottle amplitude).
        tex_seed: per-world texture seed (offsets the shared noise texture per world and surface). ambient, sun_dir (unit, toward the sun), sun_color, lamp_pos [m],
            lamp_power (irradiance at 1 m), bg_top, bg_bottom (background gradient): per world.
        noise: baked tileable noise texture in [0, 1], (NOISE_SIZE, NOISE_SIZE) (see :func:`bake_noise`).
        write_normals: 1 to write camera-frame unit normals (facing the camera; 0 for background), 0 to skip.
        rgb: (N, H * W) vec3ub. depth: camera z [m], 0 for background, (N, H * W). seg: ids, (N, H * W).
        normals: (N, H * W) vec3, or a 1-element dummy when write_normals is 0.
    """
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

    # per-world constants, loaded once per thread
    wa = w % albedo.shape[0]
    wf = w % floor_normal.shape[0]
    fn = floor_normal[wf]
    fa = floor_axis[wf]
    fb = wp.cross(fn, fa)
    half = floor_half[wf]
    ft = floor_tex[wf]
    fc2 = floor_color2[wf]
    pt = paper_tex[w % paper_tex.shape[0]]
    seed0 = tex_seed[w % tex_seed.shape[0]]
    # per-world offsets into the shared noise texture (texels)
    off_u = float(seed0 & 4095) * 0.03125
    off_v = float((seed0 >> 12) & 4095) * 0.03125
    amb = ambient[w % ambient.shape[0]]
    sd = sun_dir[w % sun_dir.shape[0]]
    sc = sun_color[w % sun_color.shape[0]]
    lp = lamp_pos[w % lamp_pos.shape[0]]
    lpw = lamp_power[w % lamp_power.shape[0]]
    hgt = wp.dot(fn, eye)
    bg = wp.lerp(bg_top[w % bg_top.shape[0]], bg_bottom[w % bg_bottom.shape[0]], py / float(height))
    row = y * width
    inv_tile = 1.0 / ft[0]
    # the floor is matte with a constant normal: its ambient + sun irradiance is one constant per thread
    floor_irr = amb + sc * wp.max(wp.dot(fn, sd), 0.0)

    # along a row the world ray is affine in x: d(x) = d0 + x * dx, and so are its dot products with the floor axes
    d0 = Rt * wp.vec3(-k[2] / k[0], (py - k[3]) / k[1], 1.0)
    dx = Rt * wp.vec3(1.0 / k[0], 0.0, 0.0)
    den0 = wp.dot(fn, d0)
    dden = wp.dot(fn, dx)
    eu = wp.dot(eye, fa)
    ev = wp.dot(eye, fb)
    du0 = wp.dot(d0, fa)
    ddu = wp.dot(dx, fa)
    dv0 = wp.dot(d0, fb)
    ddv = wp.dot(dx, fb)

    for x in range(x_begin, x_end):
        px = float(x)
        d_world = d0 + px * dx  # a point at camera depth z lies at eye + z * d_world

        best_z = float(1.0e30)
        label = int(LABEL_BACKGROUND)
        n_world = wp.vec3(0.0)
        mat = wp.vec3(0.0)

        key = zkey[img, row + x]
        if key != _EMPTY:
            tri = int(key % _TRI_SCALE)
            f = triangles[tri]
            a = vertices[w, f[0]]
            b = vertices[w, f[1]]
            c = vertices[w, f[2]]
            p0 = R * a + t
            p1 = R * b + t
            p2 = R * c + t
            n = wp.cross(p1 - p0, p2 - p0)
            nd = wp.dot(n, p0)
            pa = n[0] / k[0]
            pb = n[1] / k[1]
            pc = n[2] - pa * k[2] - pb * k[3]
            best_z = nd / (pa * px + pb * py + pc)  # the raster pass's formula, bit for bit
            label = tri_label[tri]
            # perspective-correct barycentrics: areas of the 3-D hit point against the world triangle
            hit = eye + best_z * d_world
            nw = wp.cross(b - a, c - a)
            inv = 1.0 / wp.dot(nw, nw)
            la = wp.dot(nw, wp.cross(c - b, hit - b)) * inv
            lb = wp.dot(nw, wp.cross(a - c, hit - c)) * inv
            mat = la * texcoords[w, f[0]] + lb * texcoords[w, f[1]] + (1.0 - la - lb) * texcoords[w, f[2]]
            n_world = nw * wp.sqrt(inv)

        # analytic floor: the square |u|, |v| <= half of the plane fn . p = 0, seen from above only
        denom = den0 + px * dden
        if denom < 0.0 and hgt > 0.0:
            zf = -hgt / denom
            if zf < best_z:
                fu = eu + zf * (du0 + px * ddu)
                fv = ev + zf * (dv0 + px * ddv)
                if wp.abs(fu) <= half and wp.abs(fv) <= half:
                    best_z = zf
                    label = LABEL_FLOOR
                    mat = wp.vec3(fu, fv, 0.0)

        color = bg
        nrm = wp.vec3(0.0)
        if label == LABEL_BACKGROUND:
            best_z = 0.0
        elif label == LABEL_FLOOR:
            # checker + grain in floor coordinates [m]; matte: ambient + sun (constant) + lamp (per pixel)
            base = albedo[wa, LABEL_FLOOR]
            cu = int(wp.floor(mat[0] * inv_tile))
            cv = int(wp.floor(mat[1] * inv_tile))
            if ((cu + cv) & 1) != 0:
                base = wp.lerp(base, fc2, ft[1])
            g = noise_tex(noise, mat[0] * ft[3] + off_u, mat[1] * ft[3] + off_v)
            base = base * (1.0 + ft[2] * (g - 0.5))
            p = eye + best_z * d_world
            to_lamp = lp - p
            inv_r2 = 1.0 / wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
            ndp = wp.max(wp.dot(fn, to_lamp), 0.0) * wp.sqrt(inv_r2)
            color = wp.cw_mul(base, floor_irr + lpw * (ndp * inv_r2))
            if write_normals != 0:
                nrm = R * fn
        else:
            p = eye + best_z * d_world
            view = -d_world  # toward the camera (unnormalized)
            if wp.dot(n_world, view) < 0.0:
                n_world = -n_world  # double-sided sheet: light the side the camera sees
            base = albedo[wa, label]
            if label <= LABEL_WORM_LAST:
                # paper: short fibres (noise stretched along the sheet's x) over a soft mottle; material coordinates
                # are the rest positions [m], so the texture sticks to the sheet as it folds
                sw = mat[1] + mat[2]
                fib = noise_tex(noise, mat[0] * 2500.0 + off_v, sw * 600.0 + off_u)
                mot = noise_tex(noise, mat[0] * 180.0 - off_u, (mat[1] - mat[2]) * 180.0 + off_v)
                base = base * (1.0 + pt[0] * (fib - 0.5) + pt[1] * (mot - 0.5))
            elif label == LABEL_EPM:
                if mat[2] > 0.0:
                    base = base * 0.55  # a painted north half breaks the bar's 180 degree symmetry
            color = light_surface(base, specular[wa, label], p, n_world, view, amb, sd, sc, lp, lpw)
            if write_normals != 0:
                nrm = R * n_world
        if write_normals != 0:
            normals[img, row + x] = nrm
        rgb[img, row + x] = wp.vec3ub(to_srgb8(color[0]), to_srgb8(color[1]), to_srgb8(color[2]))
        depth[img, row + x] = best_z
        seg[img, row + x] = wp.uint8(label)
