"""The resolve pass of supersampled and lens images: every output pixel's labels and anti-aliased colour in one
launch over (image, row, column), on CPU and CUDA alike.

It reads two z-buffers that :func:`~warpworm.render.raster_kernels.raster_triangles` filled for the batch: a
*label grid* (the pinhole image at pixel centres; with a lens, widened to hold every pixel's ray) and a *sample
grid* ``s`` times finer. An output pixel

- finds the pinhole point it sees: itself, or through the lens the undistorted direction of its distorted centre
  (:func:`~warpworm.render.lens_kernels.lens_inverse_row32`), with the lens map's Jacobian for the samples;
- takes its labels (depth, segmentation, normal) from the label grid: without a lens its own texel's key (the plain
  pass's labels bit for bit); through a lens, of the four texels around its ray, the nearest triangle that the ray
  hits (:func:`covering_key`), its depth on the exact ray; the worm mask from the nearest texel;
- takes ``s x s`` colour samples on a regular grid over its square (through the lens, each sample's pinhole
  position from the Jacobian), each from the sample grid's nearest key; samples that land on one surface (triangle,
  floor or background) share one lighting evaluation (shadows included) with their mean albedo (the shading is
  linear in albedo), so texture is supersampled while lights and shadows cost about once per surface per pixel; a
  pixel whose samples all see the floor takes, with ``texture_filter``, the floor texture's mean over its footprint
  (:func:`floor_footprint`) and its first sample's lighting instead;
- averages in linear RGB, applies the camera's gain and writes 8-bit display values (gamma 2).
"""

from __future__ import annotations

import threading

import warp as wp

from warpworm.kernels.common import wrow
from warpworm.render.lens_kernels import LensSolution, lens_inverse_row32
from warpworm.render.raster_math import (
    _EMPTY,
    _TRI_SCALE,
    SEG_BACKGROUND,
    SEG_FLOOR,
    depth_plane,
    edge_fn,
    project,
    seg_id,
    to_srgb8,
)
from warpworm.render.shading import (
    Look,
    floor_albedo_box,
    floor_lit_from,
    floor_row,
    floor_shade,
    mesh_surface,
    nearer_floor,
    ray_frame,
    seen_normal,
    shade_surface,
    surface_albedo,
)
from warpworm.render.shadow_kernels import Lights

wp.set_module_options({"enable_backward": False})

SURFACE_FLOOR = wp.constant(-2)
SURFACE_BACKGROUND = wp.constant(-1)
"""Surface ids of a sample that is not on a triangle (triangles are their index >= 0)."""


@wp.func
def grid_key_index(px: float, py: float, gw: int, gh: int) -> int:
    """Index of the grid texel nearest to (px, py) (clamped), as :func:`grid_key` reads it."""
    ix = wp.clamp(int(wp.floor(px + 0.5)), 0, gw - 1)
    iy = wp.clamp(int(wp.floor(py + 0.5)), 0, gh - 1)
    return iy * gw + ix


@wp.func
def grid_key(keys: wp.array2d(dtype=wp.int64), img: int, px: float, py: float, gw: int, gh: int) -> wp.int64:
    """The z-buffer key of the grid texel nearest to point (px, py) [texels] of a ``gw`` x ``gh`` grid (clamped)."""
    return keys[img, grid_key_index(px, py, gw, gh)]


@wp.func
def covering_key(keys: wp.array2d(dtype=wp.int64), img: int, px: float, py: float, gw: int, gh: int,
                 triangles: wp.array(dtype=wp.vec3i), vertices: wp.array2d(dtype=wp.vec3), w: int, R: wp.mat33,
                 t: wp.vec3, k: wp.vec4) -> wp.int64:
    """The key of the nearest triangle, among those kept by the four grid texels around point (px, py), whose
    projection contains the point: the surface the exact ray at (px, py) hits when it is one of them (a lens's rays
    fall between texel centres); EMPTY when none contains it (the floor or the background)."""
    best = _EMPTY
    best_z = float(1.0e30)
    x0 = int(wp.floor(px))
    y0 = int(wp.floor(py))
    tested = wp.vec4i(-1, -1, -1, -1)  # triangles already tested (texels on one triangle hold different keys)
    for dy in range(2):
        for dx in range(2):
            ix = wp.clamp(x0 + dx, 0, gw - 1)
            iy = wp.clamp(y0 + dy, 0, gh - 1)
            key = keys[img, iy * gw + ix]
            tri = int(-1)
            if key != _EMPTY:
                tri = int(key % _TRI_SCALE)
            if tri >= 0 and tri != tested[0] and tri != tested[1] and tri != tested[2]:
                tested[dy * 2 + dx] = tri
                f = triangles[tri]
                p0 = R * vertices[w, f[0]] + t
                p1 = R * vertices[w, f[1]] + t
                p2 = R * vertices[w, f[2]] + t
                q0 = project(p0, k)
                q1 = project(p1, k)
                q2 = project(p2, k)
                area = edge_fn(q0[0], q0[1], q1[0], q1[1], q2[0], q2[1])
                e0 = edge_fn(q1[0], q1[1], q2[0], q2[1], px, py) * area
                e1 = edge_fn(q2[0], q2[1], q0[0], q0[1], px, py) * area
                e2 = edge_fn(q0[0], q0[1], q1[0], q1[1], px, py) * area
                if area != 0.0 and e0 >= 0.0 and e1 >= 0.0 and e2 >= 0.0:
                    plane = depth_plane(p0, p1, p2, k)
                    z = plane[0] / (plane[1] * px + plane[2] * py + plane[3])
                    if z < best_z:
                        best_z = z
                        best = key
    return best


@wp.struct
class GridRays:
    """The world ray through any point of a pinhole grid, without a division per ray: ``d(fx, fy) = origin + fx dx
    + fy dy`` (a point at camera depth z lies at eye + z d). The colour samples' rays; the labels keep
    :func:`~warpworm.render.shading.ray_frame`'s per-row form, whose rounding the raster pass's depths match bit for
    bit."""

    origin: wp.vec3
    dx: wp.vec3
    dy: wp.vec3


@wp.func
def grid_rays(Rt: wp.mat33, k: wp.vec4) -> GridRays:
    """:class:`GridRays` of a grid with intrinsics ``k`` = (fx, fy, cx, cy) [px] seen by a camera whose camera-to-world
    rotation is ``Rt``."""
    r = GridRays()
    ix = 1.0 / k[0]
    iy = 1.0 / k[1]
    r.origin = Rt * wp.vec3(-k[2] * ix, -k[3] * iy, 1.0)
    r.dx = Rt * wp.vec3(ix, 0.0, 0.0)
    r.dy = Rt * wp.vec3(0.0, iy, 0.0)
    return r


@wp.func
def grid_ray(r: GridRays, fx: float, fy: float) -> wp.vec3:
    """The world ray of grid point (fx, fy) [texels] (:class:`GridRays`)."""
    return r.origin + fx * r.dx + fy * r.dy


@wp.struct
class Hit:
    """What a colour sample's ray hits: ``z`` camera depth [m], ``label`` segmentation id, ``surface`` (triangle
    index, or SURFACE_FLOOR / SURFACE_BACKGROUND), ``n`` unnormalized mesh normal, ``mat`` material coordinates,
    ``d`` the world ray (a point at depth z is eye + z d); ``mesh_*`` the mesh surface behind a clear floor."""

    z: float
    label: int
    surface: int
    n: wp.vec3
    mat: wp.vec3
    d: wp.vec3
    mesh_z: float
    mesh_label: int
    mesh_mat: wp.vec3


@wp.func
def sample_hit(keys: wp.array2d(dtype=wp.int64), img: int, fx: float, fy: float, gw: int, gh: int,
               triangles: wp.array(dtype=wp.vec3i), tri_label: wp.array(dtype=wp.int32),
               vertices: wp.array2d(dtype=wp.vec3), texcoords: wp.array2d(dtype=wp.vec3), w: int, R: wp.mat33,
               t: wp.vec3, rays: GridRays, k: wp.vec4, eye: wp.vec3, fn: wp.vec3, fa: wp.vec3, fb: wp.vec3,
               floor_eye: wp.vec3, half: float) -> Hit:
    """The :class:`Hit` of the sample at (fx, fy) of a grid with intrinsics ``k`` (its world rays ``rays``): the mesh
    surface its nearest grid key holds, or the floor square (normal ``fn``, axes ``fa``, ``fb``, half side
    ``half``) where nearer; ``floor_eye`` = the eye's floor coordinates and height (a ray-plane test, not the label
    pass's per-row form)."""
    d = grid_ray(rays, fx, fy)
    key = grid_key(keys, img, fx, fy, gw, gh)
    mz, mlabel, n, mmat = mesh_surface(key, triangles, tri_label, vertices, texcoords, w, R, t, k, fx, fy, eye, d)
    h = Hit()
    h.d = d
    h.n = n
    h.mesh_z = mz
    h.mesh_label = mlabel
    h.mesh_mat = mmat
    h.z = mz
    h.label = mlabel
    h.mat = mmat
    h.surface = int(SURFACE_BACKGROUND)
    if mlabel != SEG_BACKGROUND:
        h.surface = int(key % _TRI_SCALE)
    den = wp.dot(fn, d)
    if den < 0.0 and floor_eye[2] > 0.0:
        zf = -floor_eye[2] / den
        if zf < mz:
            fu = floor_eye[0] + zf * wp.dot(d, fa)
            fv = floor_eye[1] + zf * wp.dot(d, fb)
            if wp.abs(fu) <= half and wp.abs(fv) <= half:
                h.z = zf
                h.label = int(SEG_FLOOR)
                h.mat = wp.vec3(fu, fv, 0.0)
                h.surface = int(SURFACE_FLOOR)
    return h


MAX_GROUPS = wp.constant(8)
"""Surfaces a pixel's samples are grouped by (one lighting evaluation each); a sample on a further surface (only
possible with more than 8 samples per pixel) is counted with the last group."""


@wp.func
def sample_point(x: int, y: int, i: int, j: int, sub: int, inv_sub: float, lens: bool, u0: float, v0: float,
                 jac: wp.vec4):
    """Sample (i, j) of the ``sub`` x ``sub`` samples of output pixel (x, y) in the sample grid's coordinates [texels]:
    a regular grid over the pixel's square, through the lens map's Jacobian ``jac`` about pinhole point (u0, v0);
    ``inv_sub`` = 1 / ``sub``."""
    fx = float(0.0)
    fy = float(0.0)
    if lens:
        half_sub = 0.5 * float(sub - 1)
        ox = (float(i) + 0.5) * inv_sub - 0.5
        oy = (float(j) + 0.5) * inv_sub - 0.5
        fx = float(sub) * (u0 + jac[0] * ox + jac[1] * oy) + half_sub
        fy = float(sub) * (v0 + jac[2] * ox + jac[3] * oy) + half_sub
    else:
        fx = float(sub * x + i)
        fy = float(sub * y + j)
    return fx, fy


@wp.func
def floor_footprint(fx: float, fy: float, jac: wp.vec4, sub: int, rays: GridRays, fn: wp.vec3, fa: wp.vec3,
                    fb: wp.vec3, floor_eye: wp.vec3, half: float) -> wp.vec4:
    """Where the floor plane is seen at sample-grid point (fx, fy) (world rays ``rays``), the centre of an output
    pixel, and how big the pixel is there: (u, v) floor coordinates [m] and the widths [m] of the box with the
    second moments of the pixel's footprint, the parallelogram spanned by d(floor) / d(output px) (= d(floor) /
    d(sample grid) x ``sub`` x the lens Jacobian ``jac``). Widths -1 where the footprint is not wholly on the
    square of half side ``half`` (to first order) or the ray misses the plane."""
    d = grid_ray(rays, fx, fy)
    den = wp.dot(fn, d)
    out = wp.vec4(0.0, 0.0, -1.0, -1.0)
    if den < 0.0 and floor_eye[2] > 0.0:
        inv_den = 1.0 / den
        zf = -floor_eye[2] * inv_den
        a = wp.dot(d, fa)
        b = wp.dot(d, fb)
        c0 = rays.dx  # d(ray) / d(fx), d(ray) / d(fy)
        c1 = rays.dy
        dx = wp.dot(fn, c0) * inv_den
        dy = wp.dot(fn, c1) * inv_den
        # u = eye_u + zf a with zf = -h / den: du/dfx = zf (da/dfx - a dden/dfx / den), and so on
        ux = zf * (wp.dot(fa, c0) - a * dx)
        uy = zf * (wp.dot(fa, c1) - a * dy)
        vx = zf * (wp.dot(fb, c0) - b * dx)
        vy = zf * (wp.dot(fb, c1) - b * dy)
        s = float(sub)
        # the footprint's edge vectors (per output pixel step in x and in y)
        pu = s * (ux * jac[0] + uy * jac[2])
        qu = s * (ux * jac[1] + uy * jac[3])
        pv = s * (vx * jac[0] + vy * jac[2])
        qv = s * (vx * jac[1] + vy * jac[3])
        u = floor_eye[0] + zf * a
        v = floor_eye[1] + zf * b
        if wp.abs(u) + 0.5 * (wp.abs(pu) + wp.abs(qu)) <= half and wp.abs(v) + 0.5 * (wp.abs(pv) + wp.abs(qv)) <= half:
            # a box of width w has variance w² / 12, the parallelogram (p² + q²) / 12 along each axis
            out = wp.vec4(u, v, wp.sqrt(pu * pu + qu * qu), wp.sqrt(pv * pv + qv * qv))
    return out


@wp.func(inline=True)
def shade_sample(look: Look, lights: Lights, w: int, first: int, hit: Hit, albedo: wp.vec3, eye: wp.vec3,
                 bg: wp.vec3, transmit: float, gain: wp.vec3) -> wp.vec3:
    """Display-linear colour in [0, 1] of a sample ``hit`` of albedo ``albedo`` (a group's mean): lit and shadowed,
    the mesh under a clear floor mixed in by ``transmit``, times the camera's ``gain``."""
    # a clear plate (render.plate_materials: acrylic) lets the mesh under it (the EPM) show through: a second
    # layer, shaded at the same call site (one inlined copy of the lighting code, not two)
    layers = 1
    if hit.label != hit.mesh_label and hit.mesh_label != SEG_BACKGROUND and transmit > 0.0:
        layers = 2
    color = wp.vec3(0.0)
    for layer in range(layers):
        label = hit.label
        z = hit.z
        alb = albedo
        if layer == 1:
            label = hit.mesh_label
            z = hit.mesh_z
            alb = surface_albedo(look, w, label, hit.mesh_mat)
        c, _nrm = shade_surface(look, lights, w, first, label, alb, z, hit.n, eye, hit.d, bg)
        if layer == 0:
            color = c
        else:
            color = wp.lerp(color, c, transmit)
    return exposed(color, gain)


@wp.func
def exposed(color: wp.vec3, gain: wp.vec3) -> wp.vec3:
    """Linear ``color`` times the camera's ``gain``, clipped to the display's [0, 1]."""
    c = wp.cw_mul(color, gain)
    return wp.vec3(wp.clamp(c[0], 0.0, 1.0), wp.clamp(c[1], 0.0, 1.0), wp.clamp(c[2], 0.0, 1.0))


GroupIds = wp.types.vector(length=8, dtype=wp.int32)
GroupSums = wp.types.vector(length=8, dtype=float)
"""Per-group sample counts and ids, and albedo sums per channel (length MAX_GROUPS)."""


def make_resolve_samples(sub: int, lens: bool, normals: bool = False, texture_filter: bool = True):
    """The sample resolve kernel for ``sub`` x ``sub`` colour samples per pixel (>= 1), through each camera's lens
    (``lens``) or a pinhole, writing camera-frame ``normals`` or not, with the floor's ``texture_filter`` or not: all
    compile-time constants, so the sample loops unroll (up to ``UNROLL_SIDE`` a side) and a kernel carries no code
    for what it does not do. Each variant is its own Warp module, compiled on first use
    (:func:`resolve_samples_kernel`)."""
    sub = int(sub)
    lens = bool(lens)
    write_normals = bool(normals)  # (``normals`` is also the output array's name inside the kernel)
    filtered = bool(texture_filter) and sub > 1
    name = (f"resolve_samples_{sub}x{sub}{'_lens' if lens else ''}{'_normals' if write_normals else ''}"
            f"{'_unfiltered' if sub > 1 and not filtered else ''}")

    @wp.kernel(name=name, module="unique",
               module_options={"enable_backward": False,
                               "max_unroll": wp.config.max_unroll if sub <= UNROLL_SIDE else UNROLL_SIDE})
    def resolve_samples(
        # Model:
        triangles: wp.array(dtype=wp.vec3i), tri_label: wp.array(dtype=wp.int32),
        look: Look, lights: Lights,
        # Data in:
        vertices: wp.array2d(dtype=wp.vec3), texcoords: wp.array2d(dtype=wp.vec3),
        image_world: wp.array(dtype=wp.int32),
        cam_rot: wp.array(dtype=wp.mat33), cam_trans: wp.array(dtype=wp.vec3), cam_intr: wp.array(dtype=wp.vec4),
        cam_dist: wp.array(dtype=wp.vec4), cam_k3: wp.array(dtype=float), cam_gain: wp.array(dtype=wp.vec3),
        sample_intr: wp.array(dtype=wp.vec4),
        label_key: wp.array2d(dtype=wp.int64), label_mask: wp.array2d(dtype=wp.uint8),
        sample_key: wp.array2d(dtype=wp.int64),
        width: int, height: int, span: int, grid_w: int, grid_h: int, cam_margin: wp.array(dtype=wp.vec3i),
        # Data out:
        rgb: wp.array2d(dtype=wp.vec3ub), depth: wp.array2d(dtype=float), seg: wp.array2d(dtype=wp.uint8),
        worm_mask: wp.array2d(dtype=wp.uint8), normals: wp.array2d(dtype=wp.vec3),
    ):
        """``span`` output pixels of row y of image ``img``; launched as (N, height, ceil(width / span)) (span 1 on
        CUDA; on the CPU the whole row, so a thread's set-up, its copy of ``look`` and ``lights`` included, is paid once
        per row).

        ``cam_intr`` (N,): the label grid's pinhole (fx, fy, cx, cy) [px] (stored ``grid_w`` x ``grid_h``, the
        batch's widest; with a lens, the output's K shifted by the image's own widening ``cam_margin`` (N,) = (left,
        top, its grid's height) [px], so that an image does not depend on its batch); ``cam_dist`` (N,) OpenCV's
        (k1, k2, p1, p2) and ``cam_k3`` (N,) its k3 (read only when ``lens``); ``sample_intr`` (N,) the sample grid's
        pinhole (the one its raster pass used: ``cam_intr`` times ``sub``, centres shifted by (sub - 1) / 2);
        ``label_key``/``label_mask`` (N, grid_h * grid_w) and ``sample_key`` (N, sub² grid_h * grid_w) the raster
        pass's keys and worm silhouette; ``sub`` colour samples per pixel side (>= 1); with ``texture_filter``, a pixel
        whose samples all see the floor (no mesh key, its footprint inside the square) takes the floor's box-filtered
        albedo over its footprint (:func:`~warpworm.render.shading.floor_albedo_box`) and its first sample's hit for
        its lighting, not ``sub``² of each. Outputs (N, height * width): 8-bit ``rgb``, camera ``depth`` [m] (0:
        background), ``seg`` ids, ``worm_mask``, camera-frame ``normals`` when the variant writes them (else a
        placeholder, not written).
        """
        img, y, xb = wp.tid()
        w = image_world[img]
        R = cam_rot[img]
        t = cam_trans[img]
        k = cam_intr[img]
        Rt = wp.transpose(R)
        eye = -(Rt * t)
        fa = look.floor_axis[wrow(w, look.floor_axis.shape[0])]
        fo = look.floor_origin[wrow(w, look.floor_origin.shape[0])]
        fh = look.floor_half[wrow(w, look.floor_half.shape[0])]
        bg_top = look.bg_top[wrow(w, look.bg_top.shape[0])]
        bg_bottom = look.bg_bottom[wrow(w, look.bg_bottom.shape[0])]
        first = int(-1)
        if lights.shadows != 0:
            first = lights.map_first[w]
        fshade = floor_shade(look, lights, w)  # the floor's lighting values, in registers for the row
        fn = fshade.fn

        fb = wp.cross(fn, fa)
        floor_eye = wp.vec3(wp.dot(eye - fo, fa), wp.dot(eye - fo, fb), wp.dot(fn, eye))
        kf = sample_intr[img]
        rays = grid_rays(Rt, kf)  # the sample grid's world rays
        fxy = k[0] / k[1]  # the lens Jacobian's aspect terms
        fyx = k[1] / k[0]
        fw = grid_w * sub
        fhgt = grid_h * sub
        inv_ss = 1.0 / float(sub * sub)
        inv_sub = 1.0 / float(sub)  # exact for sub = 2, 4
        transmit = look.floor_transmit[wrow(w, look.floor_transmit.shape[0])]
        gain = cam_gain[img]
        margin = cam_margin[img]
        sol = LensSolution()  # the lens solution of the pixel last solved on this thread's run: the next one's start
        inv_fx = 1.0 / k[0]
        inv_fy = 1.0 / k[1]
        dist = wp.vec4(0.0)
        k3 = float(0.0)
        if wp.static(lens):
            dist = cam_dist[img]
            k3 = cam_k3[img]
        for x in range(xb * span, wp.min(xb * span + span, width)):
            pix = y * width + x
            # the pinhole point the pixel centre sees, and d(pinhole px) / d(output px) for its samples
            u0 = float(x)
            v0 = float(y)
            jac = wp.vec4(1.0, 0.0, 0.0, 1.0)
            ok = bool(True)
            if wp.static(lens):
                # the output's principal point is the label grid's less the widening margins
                xd = (float(x + margin[0]) - k[2]) * inv_fx
                yd = (float(y + margin[1]) - k[3]) * inv_fy
                # warm from the pixel to the left along a CPU thread's row; the run's first pixel solved cold
                sol = lens_inverse_row32(xd, yd, dist, k3, inv_fx, sol)
                ok = sol.ok
                u0 = k[0] * sol.u + k[2]
                v0 = k[1] * sol.v + k[3]
                jac = wp.vec4(sol.d * sol.inv_det, -sol.b * sol.inv_det * fxy, -sol.b * sol.inv_det * fyx,
                              sol.a * sol.inv_det)
            if not ok:  # no ray reaches this pixel (the host refuses such lenses; a guard, never data)
                rgb[img, pix] = wp.vec3ub(wp.uint8(0), wp.uint8(0), wp.uint8(0))
                depth[img, pix] = 0.0
                seg[img, pix] = wp.uint8(SEG_BACKGROUND)
                worm_mask[img, pix] = wp.uint8(0)
                if wp.static(write_normals):
                    normals[img, pix] = wp.vec3(0.0)
                continue

            # the background's vertical gradient follows the ray: its row in the (widened) pinhole grid
            bg = wp.lerp(bg_top, bg_bottom, v0 / float(margin[2]))

            # labels: the label grid's nearest key, the surface on the exact ray (the plain pass's ops without a lens)
            d0, dx = ray_frame(Rt, k, v0)
            d_world = d0 + u0 * dx
            fr = floor_row(fn, fa, fo, fh, eye, d0, dx)
            lkey = wp.int64(0)
            if wp.static(lens):  # between texel centres: the texels' triangle that the exact ray hits
                lkey = covering_key(label_key, img, u0, v0, grid_w, grid_h, triangles, vertices, w, R, t, k)
            else:
                lkey = label_key[img, grid_key_index(u0, v0, grid_w, grid_h)]
            mz, mlabel, n_world, mmat = mesh_surface(lkey, triangles, tri_label, vertices, texcoords, w, R, t, k, u0,
                                                     v0, eye, d_world)
            best_z, label, mat = nearer_floor(fr, u0, mz, mlabel, mmat)
            if wp.static(write_normals):
                normals[img, pix] = R * seen_normal(label, fn, n_world, d_world)
            if label == SEG_BACKGROUND:
                best_z = 0.0
            depth[img, pix] = best_z
            seg[img, pix] = wp.uint8(seg_id(label))
            worm_mask[img, pix] = label_mask[img, grid_key_index(u0, v0, grid_w, grid_h)]

            # colour: a filtered floor pixel lit once; any other, sub x sub samples grouped by the surface they land
            # on: the first sample's surface in registers (most pixels see one surface), the next MAX_GROUPS - 1
            # surfaces in small vectors, made only on that path (their zeroing is not paid per floor pixel)
            hit0 = Hit()
            count0 = int(0)
            alb0 = wp.vec3(0.0)
            acc = wp.vec3(0.0)
            nsub = sub
            if wp.static(filtered):
                # a pixel wholly on the floor: the texture filtered over its footprint, the first sample lit
                on_floor = bool(True)
                for j in range(sub):
                    for i in range(sub):
                        fx, fy = sample_point(x, y, i, j, sub, inv_sub, lens, u0, v0, jac)
                        if sample_key[img, grid_key_index(fx, fy, fw, fhgt)] != _EMPTY:
                            on_floor = False
                if on_floor:
                    half_sub = 0.5 * float(sub - 1)
                    fp = floor_footprint(float(sub) * u0 + half_sub, float(sub) * v0 + half_sub, jac, sub, rays, fn,
                                         fa, fb, floor_eye, fh)
                    if fp[2] >= 0.0:  # the whole pixel on the square (its samples lie inside the pixel's edges)
                        fx, fy = sample_point(x, y, 0, 0, sub, inv_sub, lens, u0, v0, jac)
                        nsub = 0
                        hit0 = sample_hit(sample_key, img, fx, fy, fw, fhgt, triangles, tri_label, vertices,
                                          texcoords, w, R, t, rays, kf, eye, fn, fa, fb, floor_eye, fh)
                        count0 = sub * sub
                        alb0 = floor_albedo_box(fshade.base, wp.vec3(fp[0], fp[1], 0.0), fp[2], fp[3], fshade.inv_tile,
                                                fshade.ft, fshade.fc2, look.noise, fshade.off_u,
                                                fshade.off_v) * float(count0)
            if nsub == 0:  # a filtered floor pixel: one surface, nothing under it (no key), lit from the row's values
                lit = floor_lit_from(fshade, lights, first, alb0 * (1.0 / float(count0)), eye + hit0.z * hit0.d,
                                     -hit0.d)
                acc = acc + exposed(lit, gain) * float(count0)
            else:  # not a floor pixel filtered above: its samples grouped by surface
                gid = GroupIds()
                gfirst = GroupIds()
                gcount = GroupIds()
                gr = GroupSums()
                gg = GroupSums()
                gb = GroupSums()
                ng = int(0)
                for j in range(sub):
                    for i in range(sub):
                        fx, fy = sample_point(x, y, i, j, sub, inv_sub, lens, u0, v0, jac)
                        hit = sample_hit(sample_key, img, fx, fy, fw, fhgt, triangles, tri_label, vertices,
                                         texcoords, w, R, t, rays, kf, eye, fn, fa, fb, floor_eye, fh)
                        alb = surface_albedo(look, w, hit.label, hit.mat)
                        if count0 == 0:
                            hit0 = hit
                            count0 = 1
                            alb0 = alb
                        elif hit.surface == hit0.surface:
                            count0 = count0 + 1
                            alb0 = alb0 + alb
                        else:
                            g = int(-1)
                            for q in range(ng):
                                if gid[q] == hit.surface:
                                    g = q
                            if g < 0 and ng < MAX_GROUPS - 1:
                                g = ng
                                gid[g] = hit.surface
                                gfirst[g] = j * sub + i
                                gcount[g] = 0
                                gr[g] = 0.0
                                gg[g] = 0.0
                                gb[g] = 0.0
                                ng = ng + 1
                            if g < 0:  # every group taken (more than MAX_GROUPS surfaces): counted with the last
                                g = ng - 1
                            gcount[g] = gcount[g] + 1
                            gr[g] = gr[g] + alb[0]
                            gg[g] = gg[g] + alb[1]
                            gb[g] = gb[g] + alb[2]
                # each surface lit once with its samples' mean albedo, at one call site (the lighting code inlined once)
                for g in range(ng + 1):
                    hit = hit0
                    count = count0
                    alb = alb0 * (1.0 / float(count0))
                    if g > 0:  # the first sample of each further surface, again
                        first_sample = gfirst[g - 1]
                        fx, fy = sample_point(x, y, first_sample % sub, first_sample / sub, sub, inv_sub, lens, u0,
                                              v0, jac)
                        hit = sample_hit(sample_key, img, fx, fy, fw, fhgt, triangles, tri_label, vertices, texcoords,
                                         w, R, t, rays, kf, eye, fn, fa, fb, floor_eye, fh)
                        count = gcount[g - 1]
                        inv_n = 1.0 / float(count)
                        alb = wp.vec3(gr[g - 1] * inv_n, gg[g - 1] * inv_n, gb[g - 1] * inv_n)
                    color = shade_sample(look, lights, w, first, hit, alb, eye, bg, transmit, gain)
                    acc = acc + color * float(count)
            acc = acc * inv_ss
            rgb[img, pix] = wp.vec3ub(to_srgb8(acc[0]), to_srgb8(acc[1]), to_srgb8(acc[2]))

    return resolve_samples


UNROLL_SIDE = 4
"""Sample loops of at most this many samples a side unroll (4 x 4 = 16 inlined samples); longer ones stay loops (code
size and compile time), as do the kernel's other loops longer than this."""

_RESOLVE_SAMPLES: dict = {}
_RESOLVE_SAMPLES_LOCK = threading.Lock()


def resolve_samples_kernel(sub: int, lens: bool, normals: bool = False, texture_filter: bool = True):
    """The :func:`make_resolve_samples` kernel for these values, made once per process (renderers in several threads
    share it)."""
    key = (int(sub), bool(lens), bool(normals), bool(texture_filter) and int(sub) > 1)  # one sample: no filter
    with _RESOLVE_SAMPLES_LOCK:
        kernel = _RESOLVE_SAMPLES.get(key)
        if kernel is None:
            kernel = _RESOLVE_SAMPLES[key] = make_resolve_samples(*key)
    return kernel
