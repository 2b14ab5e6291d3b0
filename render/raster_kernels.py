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

from warpworm.kernels.common import wrow
from warpworm.render.raster_math import (
    _DEPTH_SCALE,
    _TRI_SCALE,
    SEG_BACKGROUND,
    SEG_WORM_FIRST,
    SEG_WORM_LAST,
    covers,
    depth_plane,
    edge_fn,
    is_top_left,
    pixel_box,
    project,
    seg_id,
    to_srgb8,
)
from warpworm.render.shading import (
    Look,
    floor_row,
    mesh_surface,
    nearer_floor,
    plain_world,
    ray_frame,
    shade_hit,
    shade_hit_plain,
)
from warpworm.render.shadow_kernels import _SHADOW_TILE, Lights

# forward only: nothing differentiates through rendering, and skipping adjoints halves the compile time
wp.set_module_options({"enable_backward": False})


# ---------------------------------------------------------------------------------------------------------------------
# pass 1: raster
# ---------------------------------------------------------------------------------------------------------------------


def make_raster(depth_only: bool):
    """The z-buffer kernel: packed (depth, triangle) keys and the worm silhouette, or with ``depth_only`` the depth
    alone and its minimum per block (a float ``zkey`` and ``tile_min``, no silhouette: the shadow maps)."""
    key_dtype = float if depth_only else wp.int64

    @wp.kernel(name="raster_depth" if depth_only else "raster_triangles")
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
        zkey: wp.array2d(dtype=key_dtype),
        worm_mask: wp.array2d(dtype=wp.uint8),
        tile_min: wp.array2d(dtype=float),
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
                With ``depth_only`` (:data:`raster_depth`) the depth [m] itself, cleared to 1e30.
            worm_mask: set to 1 where a worm triangle covers the pixel, occluded or not, shape (N, height * width)
                (depth_only: unused, a 1-element dummy).
            tile_min: depth_only: the nearest depth [m] of each ``SHADOW_TILE``² block, shape (N, tiles²) with
                tiles = ceil(width / SHADOW_TILE), cleared to 1e30 (else unused, a 1-element dummy).
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
                    pix = y * width + x
                    if wp.static(depth_only):
                        wp.atomic_min(zkey, img, pix, key_dtype(z))  # (key_dtype: float here)
                        tiles = (width + _SHADOW_TILE - 1) / _SHADOW_TILE
                        wp.atomic_min(tile_min, img, (y / _SHADOW_TILE) * tiles + x / _SHADOW_TILE, z)
                    else:
                        key = wp.int64(z * _DEPTH_SCALE) * _TRI_SCALE + tkey
                        wp.atomic_min(zkey, img, pix, key)
                        if worm:
                            worm_mask[img, pix] = wp.uint8(1)
                elif entered:
                    break  # a row crosses a convex triangle in one run

    return raster_triangles


raster_triangles = make_raster(False)
"""Z-buffer one triangle into one image: packed (depth, triangle) keys and the worm silhouette."""
raster_depth = make_raster(True)
"""Z-buffer one triangle into one shadow map: the nearest depth [m] per texel and per block of texels."""


def make_resolve_shade(plain: bool):
    """The resolve/shade kernel: ``plain`` compiles the default look's path only (one lit lamp, no shadows, Lambert
    paper, matte opaque floor; world values loaded once per thread, the same bits as the general kernel in a third of
    its CPU time). The general kernel shades every option (shadow maps, any number of lights, paper BSDF, glossy and
    clear plates); see docs/render.md, "The plain path".
    """

    @wp.kernel(name="resolve_shade_plain" if plain else "resolve_shade")
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
        d0, dx = ray_frame(Rt, k, py)
        fr = floor_row(look.floor_normal[wf], look.floor_axis[wrow(w, look.floor_axis.shape[0])],
                       look.floor_origin[wrow(w, look.floor_origin.shape[0])],
                       look.floor_half[wrow(w, look.floor_half.shape[0])], eye, d0, dx)
        for x in range(x_begin, x_end):
            px = float(x)
            d_world = d0 + px * dx  # a point at camera depth z lies at eye + z * d_world
            mz, mlabel, n_world, mmat = mesh_surface(zkey[img, row + x], triangles, tri_label, vertices, texcoords,
                                                     w, R, t, k, px, py, eye, d_world)
            best_z, label, mat = nearer_floor(fr, px, mz, mlabel, mmat)
            if wp.static(plain):
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
            color = wp.cw_mul(color, gain)
            rgb[img, row + x] = wp.vec3ub(to_srgb8(color[0]), to_srgb8(color[1]), to_srgb8(color[2]))
            depth[img, row + x] = best_z
            seg[img, row + x] = wp.uint8(seg_id(label))

    return resolve_shade


resolve_shade = make_resolve_shade(False)
"""Resolve the nearest surface of every pixel and shade it, every option (:func:`make_resolve_shade`)."""
resolve_shade_plain = make_resolve_shade(True)
"""The same for batches without any per-pixel shading option: the default look's path, bit for bit."""
