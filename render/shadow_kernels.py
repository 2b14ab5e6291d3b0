"""Shadow maps and lights: the :class:`Lights` every shading kernel reads, the block minima of the shadow maps'
depths, and percentage-closer soft shadows (PCSS) with exact early-outs for points no texel can shade."""

from __future__ import annotations

import warp as wp

wp.set_module_options({"enable_backward": False})


# Functions taking Lights or Look are inline=True: Warp passes structs by value, and a call the compiler left out
# of line copied both (~1.5 KB) per pixel: 4.5x the plain kernel's resolve time on the same look, 1.5-2x inlined.
@wp.struct
class Lights:
    """Every light of every world (arrays read as ``a[wrow(w, a.shape[0])]``) and, with ``shadows`` = 1, their shadow maps.

    ``pos``, ``power``, ``size``: point lights, shape (Wl, L): position [m], irradiance at 1 m (falls as 1/r²; zero
    pads a world with fewer lights), radius [m]. ``sun_dir`` (unit, toward the light), ``sun_color`` (irradiance),
    ``ambient``: per world. Shadow map ``m`` is a depth image ``map_depth`` (M, side²) [m] of the nearest caster per
    texel (1e30: none; side ``map_side``) seen by a pinhole ``map_rot``/``map_trans``/``map_intr`` at the light;
    world ``w``'s maps are ``map_first[w]`` (the sun) and ``map_first[w] + 1 + i`` (lit point light i: the lights
    come lit first, and a dark one has no map); ``map_first[w] < 0``: none (lit). ``map_light_size``: the light's radius [m] as placed for the map (it sets the
    penumbra). ``map_pair_min`` (M, map_tiles²): the nearest depth [m] of the 2 x 2 ``SHADOW_TILE``² blocks of
    texels from each block on (clamped at the map's edge), ``map_reach`` the nearest within ``SHADOW_REACH`` blocks
    of each (:func:`~warpworm.render.raster_kernels.raster_depth`,
    :func:`shadow_reach_min`): a point whose blocker search can reach no nearer texel is known lit from one read, or
    a few (:func:`footprint_min`). ``map_floor`` (M,): the map's projection of its world's floor plane
    (:func:`floor_projection`), so a floor point needs one matrix product and one division per light.
    """

    ambient: wp.array(dtype=wp.vec3)
    sun_dir: wp.array(dtype=wp.vec3)
    sun_color: wp.array(dtype=wp.vec3)
    pos: wp.array2d(dtype=wp.vec3)
    power: wp.array2d(dtype=wp.vec3)
    size: wp.array2d(dtype=float)
    shadows: int
    map_first: wp.array(dtype=wp.int32)
    map_depth: wp.array2d(dtype=float)
    map_rot: wp.array(dtype=wp.mat33)
    map_trans: wp.array(dtype=wp.vec3)
    map_intr: wp.array(dtype=wp.vec4)
    map_light_size: wp.array(dtype=float)
    map_side: int
    map_pair_min: wp.array2d(dtype=float)
    map_reach: wp.array2d(dtype=float)
    map_tiles: int
    map_floor: wp.array(dtype=wp.mat44)


NO_CASTER = wp.constant(1.0e30)
"""Depth [m] of a shadow-map texel that no caster covers."""


@wp.func
def map_depth(depth: wp.array2d(dtype=float), s: int, m: int, x: int, y: int) -> float:
    """Camera z [m] of the nearest occluder in texel (x, y) of shadow map ``m`` (``depth`` (M, s²)); 1e30 where
    nothing (or outside)."""
    z = float(NO_CASTER)
    if x >= 0 and y >= 0 and x < s and y < s:
        z = depth[m, y * s + x]
    return z


SHADOW_TILE = 8
"""Side [texels] of the blocks whose nearest depth :func:`shadow_reach_min` keeps."""
_SHADOW_TILE = wp.constant(SHADOW_TILE)
SHADOW_REACH = wp.constant(2)
"""Tiles on each side of a point's own tile that :func:`pcf_taps` can read: its taps lie within 8 texels (the widest
search) plus one of rounding and one of margin of the point's texel, at most two 8-texel tiles away."""


@wp.kernel
def shadow_reach_min(tile_min: wp.array2d(dtype=float), tiles: int, reach: wp.array2d(dtype=float),
                     pair_min: wp.array2d(dtype=float)):
    """Nearest depth [m] over the blocks within ``SHADOW_REACH`` of each block -> ``reach``, and over the 2 x 2 blocks
    from each block on -> ``pair_min`` (both clamped to the map); launched as (M, tiles²)."""
    m, b = wp.tid()
    bx = b % tiles
    by = b / tiles
    best = float(NO_CASTER)
    for y in range(wp.max(by - SHADOW_REACH, 0), wp.min(by + SHADOW_REACH + 1, tiles)):
        for x in range(wp.max(bx - SHADOW_REACH, 0), wp.min(bx + SHADOW_REACH + 1, tiles)):
            best = wp.min(best, tile_min[m, y * tiles + x])
    reach[m, b] = best
    x1 = wp.min(bx + 1, tiles - 1)
    y1 = wp.min(by + 1, tiles - 1)
    pair_min[m, b] = wp.min(wp.min(tile_min[m, by * tiles + bx], tile_min[m, by * tiles + x1]),
                            wp.min(tile_min[m, y1 * tiles + bx], tile_min[m, y1 * tiles + x1]))


@wp.func
def footprint_min(pair_min: wp.array2d(dtype=float), tiles: int, s: int, m: int, u: float, v: float,
                  radius: float) -> float:
    """A lower bound [m] on the depth of every texel that :func:`pcf_taps` reads about (u, v) at ``radius``: the
    nearest of the blocks its footprint, widened by one texel on each side against rounding, overlaps (a few more
    where it spans one block), from four 2 x 2-block minima (``pair_min`` (M, tiles²): :class:`Lights`'
    ``map_pair_min``; ``s`` the maps' side [texels]). ``radius`` <= 8 texels (the callers clamp it): the footprint
    spans at most four blocks each way, which two overlapping pairs cover."""
    x0 = wp.max(int(wp.floor(u - radius + 0.5)) - 1, 0)
    x1 = wp.min(int(wp.floor(u + radius + 0.5)) + 1, s - 1)
    y0 = wp.max(int(wp.floor(v - radius + 0.5)) - 1, 0)
    y1 = wp.min(int(wp.floor(v + radius + 0.5)) + 1, s - 1)
    near = float(NO_CASTER)
    if x0 <= x1 and y0 <= y1:
        xa = x0 / _SHADOW_TILE
        ya = y0 / _SHADOW_TILE
        xb = wp.max(x1 / _SHADOW_TILE - 1, xa)
        yb = wp.max(y1 / _SHADOW_TILE - 1, ya)
        near = wp.min(wp.min(pair_min[m, ya * tiles + xa], pair_min[m, ya * tiles + xb]),
                      wp.min(pair_min[m, yb * tiles + xa], pair_min[m, yb * tiles + xb]))
    return near


@wp.func
def blocks_clear(pair_min: wp.array2d(dtype=float), tiles: int, s: int, m: int, u: float, v: float, z: float,
                 radius: float) -> bool:
    """True when no block that the 16 taps of :func:`pcf_taps` about (u, v) at ``radius`` can read holds a depth
    nearer than ``z`` (:func:`footprint_min`): then none of the taps is nearer. Exact where True."""
    return not (footprint_min(pair_min, tiles, s, m, u, v, radius) < z)


@wp.func
def map_tile(u: float, v: float, s: int, tiles: int) -> int:
    """Index of the ``SHADOW_TILE``² block of the texel nearest to (u, v) (clamped to the map of side ``s``)."""
    tx = wp.clamp(int(wp.floor(u + 0.5)), 0, s - 1) / _SHADOW_TILE
    ty = wp.clamp(int(wp.floor(v + 0.5)), 0, s - 1) / _SHADOW_TILE
    return ty * tiles + tx


@wp.func
def tap_grid(u: float, v: float, radius: float):
    """The 4 columns and 4 rows [texels] of the tap grid spanning ``radius`` about (u, v): taps at ±r, ±r/3, rounded
    to the nearest texel (the texels :func:`pcf_taps` reads)."""
    third = radius * (1.0 / 3.0)  # no division per tap: the offsets are -r, -r/3, r/3, r
    xs = wp.vec4i(int(wp.floor(u - radius + 0.5)), int(wp.floor(u - third + 0.5)), int(wp.floor(u + third + 0.5)),
                  int(wp.floor(u + radius + 0.5)))
    ys = wp.vec4i(int(wp.floor(v - radius + 0.5)), int(wp.floor(v - third + 0.5)), int(wp.floor(v + third + 0.5)),
                  int(wp.floor(v + radius + 0.5)))
    return xs, ys


@wp.func
def pcf_taps(depth: wp.array2d(dtype=float), s: int, m: int, u: float, v: float, z: float, radius: float) -> wp.vec2:
    """4 x 4 taps of shadow map ``m`` (``depth`` (M, s²)) on a grid spanning ``radius`` texels about (u, v): (number of taps nearer than
    ``z``, their summed depth) -- the blocker search and the percentage-closer filter of PCSS share it. The grid's
    four columns and rows are found once; a grid inside the map reads its texels without per-tap bounds checks."""
    xs, ys = tap_grid(u, v, radius)
    inside = xs[0] >= 0 and ys[0] >= 0 and xs[3] < s and ys[3] < s
    hits = float(0.0)
    zsum = float(0.0)
    for j in range(4):
        for i in range(4):
            d = float(NO_CASTER)
            if inside:
                d = depth[m, ys[j] * s + xs[i]]
            else:
                d = map_depth(depth, s, m, xs[i], ys[j])
            if d < z:
                hits += 1.0
                zsum += d
    return wp.vec2(hits, zsum)


@wp.func(inline=True)
def light_visibility(L: Lights, m: int, p: wp.vec3, n: wp.vec3) -> float:
    """Fraction [0, 1] of light ``m`` reaching surface point ``p`` (normal ``n`` toward the viewer/light side): the
    point, offset along ``n`` by 1.5 texels against self-shadowing of its own surface, in map ``m``'s texels and
    depth, then :func:`map_visibility`."""
    k = L.map_intr[m]
    R = L.map_rot[m]
    t = L.map_trans[m]
    pc = R * p + t
    out = float(1.0)
    if pc[2] > 0.0:  # else behind the light's map camera: lit
        texel = pc[2] / k[0]  # a texel's size [m] at the receiver
        pc = R * (p + n * (1.5 * texel)) + t
        out = map_visibility(L, m, k[0] * pc[0] / pc[2] + k[2], k[1] * pc[1] / pc[2] + k[3], pc[2] - texel)
    return out


@wp.func(inline=True)
def floor_visibility(L: Lights, m: int, p: wp.vec3) -> float:
    """:func:`light_visibility` of a point ``p`` on its world's floor plane, through the map's floor projection
    (:func:`floor_projection`: the same offset and texels, one division instead of four)."""
    q = L.map_floor[m] * wp.vec4(p[0], p[1], p[2], 1.0)
    out = float(1.0)
    if q[2] > 0.0:  # else behind the light's map camera: lit
        inv = 1.0 / q[2]
        out = map_visibility(L, m, q[0] * inv, q[1] * inv, q[3])
    return out


@wp.func(inline=True)
def map_visibility(L: Lights, m: int, u: float, v: float, z: float) -> float:
    """Fraction [0, 1] of light ``m`` reaching a receiver at texel position (u, v) of its map and depth ``z`` [m]
    (less a texel of bias), by percentage-closer soft shadows: a blocker search over the texels the light's disk can
    be hidden by, then a percentage-closer filter as wide as the penumbra a blocker at their mean depth casts (at
    least one texel)."""
    out = float(1.0)
    side = float(L.map_side)
    # outside the map, which covers every caster, nothing is between the point and the light: first against the
    # widest search (8 texels) and the blocks within reach, then against this receiver's own search width
    if u >= -9.0 and v >= -9.0 and u <= side + 8.0 and v <= side + 8.0:
        if L.map_reach[m, map_tile(u, v, L.map_side, L.map_tiles)] < z:
            k0 = L.map_intr[m][0]
            size = L.map_light_size[m]
            search = wp.clamp(size * k0 / z, 1.0, 8.0)
            near = float(NO_CASTER)
            if u >= -search - 1.0 and v >= -search - 1.0 and u <= side + search and v <= side + search:
                near = footprint_min(L.map_pair_min, L.map_tiles, L.map_side, m, u, v, search)
            if near < z:  # a texel the blocker search may read is nearer (the rest of the map is known lit)
                # the 4 x 4 grid's taps at +-r, +-r/3 have the second moment (5/9 r^2) of a disk light's edge
                # profile (its penumbra half-width p: p^2 / 4) for r = 0.67 p; blockers no nearer than ``near``
                # give a penumbra under 0.999 texel, clamped to 1: then no search is needed, the one-texel filter
                # below is the answer (it finds no blocker where there is none)
                penumbra = float(1.0)
                blocked = bool(True)
                if 0.67 * size * (z - near) * k0 > 0.999 * near * z:  # the bound's penumbra over 0.999 texel
                    blk = pcf_taps(L.map_depth, L.map_side, m, u, v, z, search)
                    if blk[0] != 0.0:
                        zb = blk[1] / blk[0]
                        penumbra = wp.clamp(0.67 * size * (z - zb) / zb * k0 / z, 1.0, 8.0)
                    else:
                        blocked = False
                # the filter's own footprint may hold no blocker (the search's is wider): lit, from the blocks
                if blocked and not blocks_clear(L.map_pair_min, L.map_tiles, L.map_side, m, u, v, z, penumbra):
                    out = 1.0 - pcf_taps(L.map_depth, L.map_side, m, u, v, z, penumbra)[0] / 16.0
    return out


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
def visibility(L: Lights, first: int, light: int, p: wp.vec3, n: wp.vec3, on_floor: bool) -> float:
    """Fraction [0, 1] of light ``light`` (0 = sun, 1 + i = point light i) reaching ``p`` when shadows are on (1
    otherwise): the world's map ``first + light``; ``on_floor``: ``p`` lies on the floor plane (normal ``n``)."""
    out = float(1.0)
    if L.shadows != 0 and first >= 0:
        if on_floor:
            out = floor_visibility(L, first + light, p)
        else:
            out = light_visibility(L, first + light, p, n)
    return out
