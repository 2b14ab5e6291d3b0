"""Surfaces and their light: the per-world :class:`Look`, the mesh and floor hits of a pixel's ray, albedo (paper,
magnets, the floor's checker and grain), Lambert + Blinn-Phong and the paper BSDF under the sun and point lights,
shadowed by :mod:`~warpworm.render.shadow_kernels`. Functions only: the resolve kernels
(:mod:`~warpworm.render.raster_kernels`, :mod:`~warpworm.render.sample_kernels`) call them."""

from __future__ import annotations

import warp as wp

from warpworm.kernels.common import wrow
from warpworm.render.raster_math import (
    _EMPTY,
    _TRI_SCALE,
    SEG_BACKGROUND,
    SEG_EPM,
    SEG_FLOOR,
    SEG_WORM_LAST,
    depth_plane,
    noise_tex,
    spec_power,
)
from warpworm.render.shadow_kernels import Lights, is_dark, point_light, visibility

wp.set_module_options({"enable_backward": False})


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
def sun_light(L: Lights, w: int, first: int, p: wp.vec3, n: wp.vec3, v: wp.vec3, spec: wp.vec2, shiny: bool,
              on_floor: bool):
    """World ``w``'s ambient plus its directional sun, Lambert and shadowed, at ``p`` (normal ``n``; ``on_floor``: on
    the floor plane): (irradiance, the sun's Blinn-Phong highlight seen along unit ``v`` when ``shiny``, strength and
    exponent ``spec``)."""
    irr, highlight = sun_light_from(L.ambient[wrow(w, L.ambient.shape[0])], L.sun_dir[wrow(w, L.sun_dir.shape[0])],
                                    L.sun_color[wrow(w, L.sun_color.shape[0])], L, first, p, n, v, spec, shiny,
                                    on_floor)
    return irr, highlight


@wp.func(inline=True)
def sun_light_from(ambient: wp.vec3, sd: wp.vec3, sc: wp.vec3, L: Lights, first: int, p: wp.vec3, n: wp.vec3,
                   v: wp.vec3, spec: wp.vec2, shiny: bool, on_floor: bool):
    """:func:`sun_light` from the world's ``ambient``, sun direction ``sd`` and colour ``sc``, already loaded."""
    ndl = wp.max(wp.dot(n, sd), 0.0)
    irr = ambient
    highlight = wp.vec3(0.0)
    if ndl > 0.0:
        vis = visibility(L, first, 0, p, n, on_floor)
        irr = irr + sc * (ndl * vis)
        if shiny:
            hs = wp.max(wp.dot(n, wp.normalize(sd + v)), 0.0)
            highlight = sc * (spec[0] * spec_power(hs, spec[1]) * vis)
    return irr, highlight


@wp.func(inline=True)
def light_surface(albedo: wp.vec3, spec: wp.vec2, p: wp.vec3, n: wp.vec3, to_eye: wp.vec3, L: Lights, w: int,
                  first: int) -> wp.vec3:
    """Ambient + Lambert + Blinn-Phong for the directional sun and every point light of world ``w``, linear RGB.

    ``to_eye`` points from the surface toward the camera (any length); a point light's irradiance falls with the
    inverse square of the distance. Specular terms are evaluated only where ``spec[0] > 0`` (magnets), with
    Schlick's approximation of the power, so matte surfaces pay for Lambert only; a light's shadow lookup serves
    both terms. ``first``: the world's first shadow map (< 0: unshadowed).
    """
    wl = wrow(w, L.pos.shape[0])
    shiny = spec[0] > 0.0
    v = wp.vec3(0.0)
    if shiny:
        v = wp.normalize(to_eye)
    irr, highlights = sun_light(L, w, first, p, n, v, spec, shiny, False)
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        ldir, lpow, ndp = point_light(L, wl, i, p, n)
        if ndp > 0.0:
            vis = visibility(L, first, 1 + i, p, n, False)
            irr = irr + lpow * (ndp * vis)
            if shiny:
                hl = wp.max(wp.dot(n, wp.normalize(ldir + v)), 0.0)
                highlights = highlights + lpow * (spec[0] * spec_power(hl, spec[1]) * vis)
    return wp.cw_mul(albedo, irr) + highlights


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
        vis = visibility(L, first, 0, p, n, False)
    color = color + paper_light(albedo, n, v, ndv, sd, L.sun_color[wrow(w, L.sun_color.shape[0])], vis, pb)
    wl = wrow(w, L.pos.shape[0])
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        ldir, lpow, ndp = point_light(L, wl, i, p, n)
        vis = 1.0
        if wp.dot(n, ldir) + pb[0] > 0.0:
            vis = visibility(L, first, 1 + i, p, n, False)
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
def ray_frame(Rt: wp.mat33, k: wp.vec4, py: float):
    """World ray of image row ``py`` through pinhole intrinsics ``k`` (camera-to-world rotation ``Rt``): along a row
    it is affine in x, d(px) = d0 + px dx (a point at camera depth z lies at eye + z d). Returns (d0, dx); both
    resolve passes call it, so their rays agree bit for bit."""
    return Rt * wp.vec3(-k[2] / k[0], (py - k[3]) / k[1], 1.0), Rt * wp.vec3(1.0 / k[0], 0.0, 0.0)


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
def floor_grain(albedo: wp.vec3, mat: wp.vec3, ft: wp.vec4, noise: wp.array2d(dtype=float), off_u: float,
                off_v: float) -> wp.vec3:
    """``albedo`` with the floor's grain at floor coordinates ``mat`` [m]: amplitude ``ft[2]``, frequency ``ft[3]``
    [1/m] of the shared noise texture at the world's offset (``off_u``, ``off_v``) [texels]."""
    g = noise_tex(noise, mat[0] * ft[3] + off_u, mat[1] * ft[3] + off_v)
    return albedo * (1.0 + ft[2] * (g - 0.5))


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
    return floor_grain(albedo, mat, ft, noise, off_u, off_v)


@wp.func
def box_square_wave(p: float, w: float) -> float:
    """Mean over [p - w/2, p + w/2] of the square wave that is +1 on even unit cells and -1 on odd ones: the
    difference of its integral, the triangle wave 1 - |(x mod 2) - 1|, over the width (the wave itself below
    1e-6)."""
    out = float(1.0)
    if w > 1.0e-6:
        a = p - 0.5 * w
        b = p + 0.5 * w
        ta = 1.0 - wp.abs(a - 2.0 * wp.floor(0.5 * a) - 1.0)
        tb = 1.0 - wp.abs(b - 2.0 * wp.floor(0.5 * b) - 1.0)
        out = (tb - ta) / w
    elif (int(wp.floor(p)) & 1) != 0:
        out = -1.0
    return out


@wp.func
def floor_albedo_box(base: wp.vec3, mat: wp.vec3, wu: float, wv: float, inv_tile: float, ft: wp.vec4, fc2: wp.vec3,
                     noise: wp.array2d(dtype=float), off_u: float, off_v: float) -> wp.vec3:
    """:func:`floor_albedo` averaged over a ``wu`` x ``wv`` [m] box about floor coordinates ``mat``: the checker's
    exact mean (its odd cells' share of the box, separable), the grain (smooth at that scale) at the centre."""
    odd = 0.5 * (1.0 - box_square_wave(mat[0] * inv_tile, wu * inv_tile) * box_square_wave(mat[1] * inv_tile,
                                                                                          wv * inv_tile))
    albedo = wp.lerp(base, wp.lerp(base, fc2, ft[1]), odd)
    return floor_grain(albedo, mat, ft, noise, off_u, off_v)


@wp.func(inline=True)
def floor_albedo_at(look: Look, w: int, mat: wp.vec3) -> wp.vec3:
    """World ``w``'s floor albedo (checker + grain, :func:`floor_albedo`) at floor coordinates ``mat`` [m]."""
    ft = look.floor_tex[wrow(w, look.floor_tex.shape[0])]
    off = noise_offset(look, w)
    return floor_albedo(look.albedo[wrow(w, look.albedo.shape[0]), SEG_FLOOR], mat, 1.0 / ft[0], ft,
                        look.floor_color2[wrow(w, look.floor_color2.shape[0])], look.noise, off[0], off[1])


@wp.struct
class FloorShade:
    """World values the floor's albedo and lighting read at every floor point (:func:`floor_lit_from`), gathered
    once (:func:`floor_shade`): a resolve thread loads them before its pixel loop, where each store to an 8-bit
    output would make the compiler load them again for the next pixel. ``fn``: unit floor normal; ``spec``: the
    floor's (strength, exponent); ``ambient``, ``sun_dir``, ``sun_color``: the world's; ``wl``: its row of the
    point-light arrays; the checker and grain of :func:`floor_albedo`: ``base`` albedo, ``ft``
    (``Look.floor_tex``), ``inv_tile`` [1/m], ``fc2``, noise offset (``off_u``, ``off_v``) [texels]."""

    fn: wp.vec3
    spec: wp.vec2
    ambient: wp.vec3
    sun_dir: wp.vec3
    sun_color: wp.vec3
    wl: int
    base: wp.vec3
    ft: wp.vec4
    inv_tile: float
    fc2: wp.vec3
    off_u: float
    off_v: float


@wp.func(inline=True)
def floor_shade(look: Look, L: Lights, w: int) -> FloorShade:
    """World ``w``'s :class:`FloorShade`."""
    fs = FloorShade()
    fs.fn = look.floor_normal[wrow(w, look.floor_normal.shape[0])]
    fs.spec = look.specular[wrow(w, look.specular.shape[0]), SEG_FLOOR]
    fs.ambient = L.ambient[wrow(w, L.ambient.shape[0])]
    fs.sun_dir = L.sun_dir[wrow(w, L.sun_dir.shape[0])]
    fs.sun_color = L.sun_color[wrow(w, L.sun_color.shape[0])]
    fs.wl = wrow(w, L.pos.shape[0])
    fs.base = look.albedo[wrow(w, look.albedo.shape[0]), SEG_FLOOR]
    fs.ft = look.floor_tex[wrow(w, look.floor_tex.shape[0])]
    fs.inv_tile = 1.0 / fs.ft[0]
    fs.fc2 = look.floor_color2[wrow(w, look.floor_color2.shape[0])]
    off = noise_offset(look, w)
    fs.off_u = off[0]
    fs.off_v = off[1]
    return fs


@wp.func(inline=True)
def floor_lit_from(fs: FloorShade, L: Lights, first: int, albedo: wp.vec3, p: wp.vec3, to_eye: wp.vec3) -> wp.vec3:
    """:func:`floor_lit` from the world's gathered values ``fs`` (:func:`floor_shade`)."""
    fn = fs.fn
    spec = fs.spec
    glossy = spec[0] > 0.0  # a glossy plate (render.plate_materials)
    v = wp.vec3(0.0)
    if glossy:
        v = wp.normalize(to_eye)
    irr, highlights = sun_light_from(fs.ambient, fs.sun_dir, fs.sun_color, L, first, p, fn, v, spec, glossy, True)
    wl = fs.wl
    for i in range(L.pos.shape[1]):
        if is_dark(L, wl, i):
            continue
        to_lamp = L.pos[wl, i] - p
        inv_r2 = 1.0 / wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
        ndp = wp.max(wp.dot(fn, to_lamp), 0.0) * wp.sqrt(inv_r2)
        if ndp > 0.0:
            vis = visibility(L, first, 1 + i, p, fn, True)
            irr = irr + L.power[wl, i] * (ndp * vis * inv_r2)
            if glossy:
                ldir = to_lamp * wp.sqrt(inv_r2)
                hl = wp.max(wp.dot(fn, wp.normalize(ldir + v)), 0.0)
                highlights = highlights + L.power[wl, i] * inv_r2 * (spec[0] * spec_power(hl, spec[1]) * vis)
    return wp.cw_mul(albedo, irr) + highlights


@wp.func(inline=True)
def floor_lit(look: Look, L: Lights, w: int, first: int, albedo: wp.vec3, p: wp.vec3, to_eye: wp.vec3) -> wp.vec3:
    """The floor of albedo ``albedo`` at ``p``: ambient + sun + every point light, and, for a glossy plate (floor
    specular strength > 0), their Blinn-Phong highlights seen along ``to_eye``, shadowed like the diffuse term (one
    lookup per light serves both). Linear in ``albedo`` plus the highlights."""
    return floor_lit_from(floor_shade(look, L, w), L, first, albedo, p, to_eye)


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


@wp.func
def seen_normal(label: int, floor_n: wp.vec3, n_world: wp.vec3, d_world: wp.vec3) -> wp.vec3:
    """World normal of surface ``label`` on the side a ray along ``d_world`` sees: the floor's ``floor_n``, a mesh's
    ``n_world`` (unnormalized) turned toward the camera (the sheet is double-sided: the side the camera sees is lit),
    0 for the background."""
    nrm = wp.vec3(0.0)
    if label == SEG_FLOOR:
        nrm = floor_n
    elif label != SEG_BACKGROUND:
        nrm = n_world
        if wp.dot(n_world, -d_world) < 0.0:
            nrm = -n_world
    return nrm


@wp.func(inline=True)
def shade_surface(look: Look, L: Lights, w: int, first: int, label: int, albedo: wp.vec3, z: float,
                  n_world: wp.vec3, eye: wp.vec3, d_world: wp.vec3, bg: wp.vec3):
    """Colour (linear RGB) and unit world normal (0 for background) of surface ``label`` of albedo ``albedo`` hit at
    camera depth ``z`` along ``d_world`` (mesh normal ``n_world``, unnormalized). Linear in ``albedo`` (plus
    highlights and sheen), so a pixel's samples on one surface may share it with their mean albedo."""
    color = bg
    nrm = seen_normal(label, look.floor_normal[wrow(w, look.floor_normal.shape[0])], n_world, d_world)
    if label == SEG_FLOOR:
        color = floor_lit(look, L, w, first, albedo, eye + z * d_world, -d_world)
    elif label != SEG_BACKGROUND:
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
    """One world's values the plain path (:func:`make_resolve_shade`) loads once per thread: the floor's and the
    sun's (``fs``, :class:`FloorShade`), the one lamp (position ``lp``, power ``lpw``), ``floor_irr``: the ambient +
    sun irradiance of the floor's constant normal, and the paper texture ``pt``."""

    fs: FloorShade
    lp: wp.vec3
    lpw: wp.vec3
    floor_irr: wp.vec3
    pt: wp.vec2


@wp.func
def plain_world(look: Look, L: Lights, w: int) -> PlainWorld:
    """World ``w``'s :class:`PlainWorld` (one lamp: light 0)."""
    pw = PlainWorld()
    fs = floor_shade(look, L, w)
    pw.fs = fs
    pw.lp = L.pos[fs.wl, 0]
    pw.lpw = L.power[fs.wl, 0]
    pw.floor_irr = fs.ambient + fs.sun_color * wp.max(wp.dot(fs.fn, fs.sun_dir), 0.0)
    pw.pt = look.paper_tex[wrow(w, look.paper_tex.shape[0])]
    return pw


@wp.func(inline=True)
def shade_hit_plain(look: Look, pw: PlainWorld, wa: int, ws: int, label: int, z: float, mat: wp.vec3,
                    n_world: wp.vec3, eye: wp.vec3, d_world: wp.vec3, bg: wp.vec3):
    """:func:`shade_hit` for the plain path: world ``pw`` (its albedo row ``wa``, specular row ``ws``) under one lamp,
    no shadows, Lambert paper, a matte opaque floor."""
    fs = pw.fs
    color = bg
    nrm = seen_normal(label, fs.fn, n_world, d_world)
    if label == SEG_FLOOR:
        p = eye + z * d_world
        to_lamp = pw.lp - p
        inv_r2 = 1.0 / wp.max(wp.dot(to_lamp, to_lamp), 1.0e-6)
        ndp = wp.max(wp.dot(fs.fn, to_lamp), 0.0) * wp.sqrt(inv_r2)
        albedo = floor_albedo(fs.base, mat, fs.inv_tile, fs.ft, fs.fc2, look.noise, fs.off_u, fs.off_v)
        color = wp.cw_mul(albedo, pw.floor_irr + pw.lpw * (ndp * inv_r2))
    elif label != SEG_BACKGROUND:
        base = textured_albedo(look.albedo[wa, label], label, mat, pw.pt, look.noise, fs.off_u, fs.off_v)
        color = light_surface_plain(base, look.specular[ws, label], eye + z * d_world, nrm, -d_world, fs.ambient,
                                    fs.sun_dir, fs.sun_color, pw.lp, pw.lpw)
    return color, nrm
