"""Per-world scenes for the rasterizer: one shared triangle topology, per-world vertex positions and appearance.

A :class:`SceneBatch` holds W worlds that share one triangle list (the worm's crease-pattern triangles, three IPM
disks, the EPM bar), so one kernel launch rasterizes every world. Per world it holds vertex positions [m], material
coordinates (where procedural textures are evaluated, so textures move with the surface), the floor plane and an
:class:`Appearance` (colours, lights, textures).

Segmentation ids (docs/architecture.md; also in docs/render.md):

====  ================================
id    surface
====  ================================
0     background (no surface)
1     floor / incline
2..6  worm segment 0..4 (tail -> head)
7     tail IPM
8     centre IPM
9     head IPM
10    EPM
====  ================================

The worm is one sheet rendered double-sided (no culling; the normal is flipped toward the camera). The floor is an
analytic square in the plane through the world origin with normal ``(-sin i, 0, cos i)`` for incline ``i`` (positive
raises the floor toward +x, :class:`warpworm.physics.params.WormParams`), half side ``floor_half``; it is intersected per pixel
rather than rasterized. Nothing is drawn where no surface is hit: the background gradient.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from warpworm import ids
from warpworm.ids import NUM_SEGMENTATION_IDS, SEG_EPM, SEG_FLOOR, SEG_IPM_FIRST, SEG_WORM_FIRST

LABEL_NAMES = ids.SEGMENTATION_NAMES
"""Name of every segmentation id, indexed by id."""


# ---------------------------------------------------------------------------------------------------------------------
# appearance
# ---------------------------------------------------------------------------------------------------------------------


@dataclass
class Appearance:
    """Per-world look of a scene. Colours are linear RGB in [0, 1]; every array has a leading world axis (W or 1)."""

    albedo: np.ndarray
    """Albedo per segmentation id, shape (W, 11, 3)."""
    specular: np.ndarray
    """(strength, Blinn-Phong exponent) per segmentation id, shape (W, 11, 2)."""
    floor_tex: np.ndarray
    """(checker tile [m], checker contrast in [0, 1], grain amplitude, grain frequency [1/m]), shape (W, 4)."""
    floor_color2: np.ndarray
    """Second checker colour, shape (W, 3)."""
    paper_tex: np.ndarray
    """(fibre amplitude, mottle amplitude) of the paper texture, shape (W, 2)."""
    tex_seed: np.ndarray
    """Seed of the procedural textures, shape (W,), int32."""
    ambient: np.ndarray
    """Ambient irradiance, shape (W, 3)."""
    sun_dir: np.ndarray
    """Unit direction toward the directional light (world), shape (W, 3)."""
    sun_color: np.ndarray
    """Directional light irradiance, shape (W, 3)."""
    sun_size: np.ndarray
    """Angular radius [rad] of the directional light (the softness of its shadows), shape (W,)."""
    light_pos: np.ndarray
    """Point light positions [m] (world), shape (W, L, 3); any number L >= 1 of lights per world."""
    light_power: np.ndarray
    """Point light irradiance at 1 m (falls as 1/r²), shape (W, L, 3); zero pads a world with fewer lights."""
    light_size: np.ndarray
    """Point light radius [m] (spherical lights: the softness of their shadows), shape (W, L)."""
    paper_bsdf: np.ndarray
    """The sheet's paper BSDF (wrap, sheen strength, sheen roughness, ground ambient fraction), shape (W, 4); zeros:
    Lambert with a constant ambient (before ``render.paper_bsdf``; :func:`shading.paper_surface`)."""
    floor_transmit: np.ndarray
    """Fraction of the light of meshes under the floor (the EPM) that shows through it: 0 opaque, a clear acrylic
    plate 0.3-0.6 (its glossiness is the floor's ``specular`` row), shape (W,)."""
    plate: np.ndarray
    """Pose of the floor square (the plate) in its plane, shape (W, 3): yaw [rad] of its axes (and textures) about
    the floor normal, offset [m] of its centre along the unrotated floor axes u, v (:func:`floor_frame`)."""
    bg_top: np.ndarray
    """Background colour at the top image row, shape (W, 3)."""
    bg_bottom: np.ndarray
    """Background colour at the bottom image row, shape (W, 3)."""

    @property
    def num_worlds(self) -> int:
        return self.albedo.shape[0]

    @property
    def lamp_pos(self) -> np.ndarray:
        """The first point light's position [m], (W, 3) (of ``light_pos``: every light is there)."""
        return self.light_pos[:, 0]

    @property
    def lamp_power(self) -> np.ndarray:
        """The first point light's irradiance at 1 m, (W, 3) (of ``light_power``: every light is there)."""
        return self.light_power[:, 0]

    def take(self, index) -> "Appearance":
        """Appearance of the worlds ``index`` (broadcasting a single shared world)."""
        index = np.asarray(index)
        out = {}
        for f in fields(self):
            a = getattr(self, f.name)
            out[f.name] = a[index % a.shape[0]]
        return Appearance(**out)


DEFAULT_LAMP_POS = (-0.15, 0.2, 0.3)
"""The default point light's position [m] (in the plate's frame: in the world unless the plate is posed)."""
DEFAULT_LAMP_SIZE = 0.01
"""The default point light's radius [m]."""
SUN_SIZE = 0.02
"""The directional light's angular radius [rad] (a window or softbox rather than the 0.005 rad sun)."""


def default_appearance(num_worlds: int = 1) -> Appearance:
    """A plain, fixed look: white paper, grey checker floor, nickel magnets, sun + lamp, grey background."""
    albedo = np.zeros((NUM_SEGMENTATION_IDS, 3))
    albedo[SEG_FLOOR] = (0.45, 0.42, 0.38)
    albedo[SEG_WORM_FIRST:SEG_WORM_FIRST + 5] = (0.80, 0.78, 0.72)
    albedo[SEG_IPM_FIRST:SEG_IPM_FIRST + 3] = (0.55, 0.55, 0.58)
    albedo[SEG_EPM] = (0.60, 0.60, 0.62)
    spec = np.zeros((NUM_SEGMENTATION_IDS, 2))
    spec[:, 1] = 16.0
    # floor and paper are matte (no specular term: it is evaluated only where strength > 0)
    spec[SEG_IPM_FIRST:] = (0.8, 60.0)
    sun = np.array([0.4, -0.3, 0.87])
    a = Appearance(
        albedo=albedo[None],
        specular=spec[None],
        floor_tex=np.array([[0.02, 0.5, 0.25, 300.0]]),
        floor_color2=np.array([[0.25, 0.24, 0.22]]),
        paper_tex=np.array([[0.25, 0.10]]),
        tex_seed=np.array([12345], dtype=np.int32),
        ambient=np.array([[0.25, 0.25, 0.27]]),
        sun_dir=(sun / np.linalg.norm(sun))[None],
        sun_color=np.array([[0.75, 0.72, 0.68]]),
        sun_size=np.array([SUN_SIZE]),
        light_pos=np.array([[DEFAULT_LAMP_POS]]),
        light_power=np.array([[[0.04, 0.04, 0.045]]]),
        light_size=np.array([[DEFAULT_LAMP_SIZE]]),
        floor_transmit=np.zeros(1),
        paper_bsdf=np.zeros((1, 4)),
        plate=np.zeros((1, 3)),
        bg_top=np.array([[0.55, 0.6, 0.68]]),
        bg_bottom=np.array([[0.25, 0.27, 0.3]]),
    )
    return a.take(np.zeros(num_worlds, dtype=np.int64))


def hsv_to_rgb(h, s, v):
    """Vectorised HSV (all in [0, 1]) -> linear-ish RGB, shape (..., 3)."""
    h = np.asarray(h) * 6.0
    i = np.floor(h).astype(int) % 6
    f = h - np.floor(h)
    p = v * (1 - s)
    q = v * (1 - s * f)
    t = v * (1 - s * (1 - f))
    table = np.stack([np.stack([v, t, p], -1), np.stack([q, v, p], -1), np.stack([p, v, t], -1),
                      np.stack([p, q, v], -1), np.stack([t, p, v], -1), np.stack([v, p, q], -1)], 0)
    return np.take_along_axis(table, i[None, ..., None].repeat(3, -1), 0)[0]


BAND_NAMES = ("blue", "pink", "white", "green", "red")
"""The paper's marker bands (§IV-E, Fig. 11), one per segment 0..4 (``CreasePattern.triangle_segment``), tail -> head."""
BAND_COLORS = np.array([[0.15, 0.35, 0.95], [1.00, 0.45, 0.80], [0.95, 0.95, 0.95], [0.20, 0.80, 0.30],
                        [0.90, 0.12, 0.10]])
"""Default band colours as displayed (gamma-2 RGB in [0, 1], what a camera sees under white light), (5, 3)."""


def band_appearance(appearance: Appearance, colors=None) -> Appearance:
    """``appearance`` with the worm painted in five bands: segment i (segmentation id 2 + i) gets display colour
    ``colors[i]`` ((5, 3) in [0, 1], default :data:`BAND_COLORS`; albedo = colour², the renderer shows sqrt) and no
    paper texture (flat paint, so the bands' hues stay clean for a tracker)."""
    c = BAND_COLORS if colors is None else np.asarray(colors, dtype=np.float64)
    if c.shape != (5, 3) or not np.all((c >= 0) & (c <= 1)):
        raise ValueError(f"band colors: got shape {c.shape} / range [{c.min():.3g}, {c.max():.3g}]; expected (5, 3) "
                         "RGB values in [0, 1], tail -> head")
    out = appearance.take(np.arange(appearance.num_worlds))
    out.albedo = out.albedo.copy()
    out.albedo[:, SEG_WORM_FIRST:SEG_WORM_FIRST + 5] = c[None] ** 2
    out.paper_tex = np.zeros_like(out.paper_tex)
    return out


# ---------------------------------------------------------------------------------------------------------------------
# meshes
# ---------------------------------------------------------------------------------------------------------------------


def disk_mesh(segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Closed cylinder of radius 1 and height 1 centred at the origin, axis +z: (vertices (2+2s, 3), triangles (4s, 3))."""
    ang = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    top = np.concatenate([ring, np.full((segments, 1), 0.5)], axis=1)
    bot = np.concatenate([ring, np.full((segments, 1), -0.5)], axis=1)
    verts = np.concatenate([[[0, 0, 0.5], [0, 0, -0.5]], top, bot])
    i = np.arange(segments)
    j = (i + 1) % segments
    T, B = 2 + i, 2 + segments + i
    Tn, Bn = 2 + j, 2 + segments + j
    tris = np.concatenate([
        np.stack([np.zeros_like(i), T, Tn], 1),
        np.stack([np.ones_like(i), Bn, B], 1),
        np.stack([T, B, Bn], 1),
        np.stack([T, Bn, Tn], 1),
    ])
    return verts, tris.astype(np.int32)


def box_mesh() -> tuple[np.ndarray, np.ndarray]:
    """Unit cube [-0.5, 0.5]^3, outward-oriented: (vertices (8, 3), triangles (12, 3))."""
    v = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
    # vertex index = 4*ix + 2*iy + iz
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    tris = []
    for a, b, c, d in quads:
        tris += [(a, b, c), (a, c, d)]
    return v, np.array(tris, dtype=np.int32)


# ---------------------------------------------------------------------------------------------------------------------
# scene batch
# ---------------------------------------------------------------------------------------------------------------------


def floor_frame(incline, num_worlds: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit normal and in-plane +u axis of the floor for every world, each (W, 3).

    The floor rises toward +x for a positive incline: u = (cos i, 0, sin i), n = (-sin i, 0, cos i).
    """
    inc = np.broadcast_to(np.asarray(incline, dtype=np.float64), (num_worlds,))
    c, s = np.cos(inc), np.sin(inc)
    z = np.zeros_like(c)
    return np.stack([-s, z, c], 1), np.stack([c, z, s], 1)


def plate_frame(normal: np.ndarray, axis: np.ndarray, plate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The posed plate's in-plane axis and centre, each (W, 3): ``axis`` (W, 3) turned by yaw ``plate[:, 0]`` [rad]
    about ``normal`` (W, 3), and the centre ``plate[:, 1] u + plate[:, 2] v`` [m] along the unturned axes
    (v = normal x u). A zero pose returns ``axis`` itself and the origin."""
    plate = np.asarray(plate, dtype=np.float64)
    c, s = np.cos(plate[:, :1]), np.sin(plate[:, :1])
    b = np.cross(normal, axis)
    turned = np.where(plate[:, :1] == 0.0, axis, c * axis + s * b)
    return turned, plate[:, 1:2] * axis + plate[:, 2:3] * b


@dataclass
class SceneBatch:
    """W worlds sharing one triangle topology. Arrays are NumPy; the renderer uploads them."""

    vertices: np.ndarray
    """World positions [m] of every scene vertex, shape (W, Vs, 3), float32."""
    triangles: np.ndarray
    """Vertex indices of every triangle, shape (T, 3), int32 (shared by every world)."""
    tri_label: np.ndarray
    """Segmentation id of every triangle, shape (T,), int32."""
    texcoords: np.ndarray
    """Material coordinates [m] of every vertex (textures live there), shape (W or 1, Vs, 3), float32."""
    floor_normal: np.ndarray
    """Unit floor normal (world), shape (W, 3)."""
    floor_axis: np.ndarray
    """Unit in-plane +u axis of the floor (checker orientation), shape (W, 3)."""
    floor_origin: np.ndarray
    """Centre [m] of the floor square (and origin of its textures), a point of the plane, shape (W, 3)."""
    floor_half: np.ndarray
    """Half side of the square floor [m], shape (W,); 0 removes the floor."""
    appearance: Appearance
    """Per-world colours, lights and textures."""

    @property
    def num_worlds(self) -> int:
        return self.vertices.shape[0]

    @classmethod
    def from_mesh(cls, vertices, triangles, tri_label, *, texcoords=None, floor_incline=0.0, floor_half=1.0,
                  appearance: Appearance | None = None) -> "SceneBatch":
        """A scene from any triangle mesh: ``vertices`` (W, V, 3) or (V, 3), ``triangles`` (T, 3), labels (T,)."""
        v = np.asarray(vertices, dtype=np.float32)
        if v.ndim == 2:
            v = v[None]
        W = v.shape[0]
        tc = v if texcoords is None else np.asarray(texcoords, dtype=np.float32)
        if tc.ndim == 2:
            tc = tc[None]
        n, a = floor_frame(floor_incline, W)
        app = appearance if appearance is not None else default_appearance(W)
        a, origin = plate_frame(n, a, app.plate[np.arange(W) % app.plate.shape[0]])
        return cls(vertices=np.ascontiguousarray(v), triangles=np.ascontiguousarray(triangles, dtype=np.int32),
                   tri_label=np.broadcast_to(np.asarray(tri_label, dtype=np.int32), (len(triangles),)).copy(),
                   texcoords=np.ascontiguousarray(tc), floor_normal=n, floor_axis=a, floor_origin=origin,
                   floor_half=np.broadcast_to(np.asarray(floor_half, dtype=np.float64), (W,)).copy(),
                   appearance=app)

    def reference_mesh(self, world: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World ``world`` as one plain mesh including the floor square as two triangles (for reference ray casting).

        Returns (vertices (Vs+4, 3) float64, triangles (T+2, 3) int32, labels (T+2,) int32).
        """
        v = self.vertices[world].astype(np.float64)
        n, a = self.floor_normal[world], self.floor_axis[world]
        b = np.cross(n, a)
        h = float(self.floor_half[world])
        corners = np.array([self.floor_origin[world] + h * (su * a + sv * b)
                            for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
        V = v.shape[0]
        tris = np.concatenate([self.triangles, np.array([[V, V + 1, V + 2], [V, V + 2, V + 3]], dtype=np.int32)])
        labels = np.concatenate([self.tri_label, [SEG_FLOOR, SEG_FLOOR]]).astype(np.int32)
        if h <= 0:
            tris, labels = tris[:-2], labels[:-2]
        return np.concatenate([v, corners]), tris, labels


def build_scene(
    worm_positions,
    worm_triangles,
    triangle_segment,
    *,
    magnet_pos=None,
    magnet_rot=None,
    worm_texcoords=None,
    ipm_diameter=0.010,
    ipm_thickness=0.001,
    epm_size=(0.010, 0.010, 0.040),
    floor_incline=0.0,
    floor_half: float = 1.0,
    appearance: Appearance | None = None,
    disk_segments: int = 16,
    show_epm: bool = True,
    extra_mesh: tuple | None = None,
) -> SceneBatch:
    """Assemble the W worlds: worm sheet (ids 2..6 by segment), three IPM disks (7, 8, 9), EPM bar (10).

    Args:
        worm_positions: deformed sheet vertices [m], shape (W, V, 3) (``Simulator.snapshot()['positions']``).
        worm_triangles: crease-pattern triangles, (T, 3) int. triangle_segment: segment 0..4 of each, (T,).
        magnet_pos, magnet_rot: magnet poses in slot order (EPM, tail, centre, head IPM), (W, 4, 3) and (W, 4, 3, 3);
            None renders the worm only. The disk axis is the magnet's local z; the EPM extents are along its local axes.
        worm_texcoords: material coordinates of the sheet (its rest vertices), (V, 3) or (W, V, 3); default: the
            first world's positions (the texture then sticks to that pose).
        ipm_diameter, ipm_thickness: [m], () or (W,). epm_size: [m], (3,) or (W, 3).
        floor_incline: [rad], () or (W,). floor_half: half side of the floor square [m].
        appearance: per-world look (default :func:`default_appearance`).
        disk_segments: facets around each disk. show_epm: False leaves the EPM out of the picture.
        extra_mesh: more objects, (vertices (W, Ve, 3) [m], triangles (Te, 3) indexing them, labels (Te,),
            texcoords (W, Ve, 3)) (e.g. :func:`warpworm.render.placement.distractor_mesh`); a label above
            ``SEG_EPM`` shades with its own albedo row and is written to the segmentation as the floor's id.
    """
    P = np.asarray(worm_positions, dtype=np.float64)
    W, V, _ = P.shape
    tris = [np.asarray(worm_triangles, dtype=np.int32)]
    labels = [SEG_WORM_FIRST + np.asarray(triangle_segment, dtype=np.int32)]
    tc = P[:1] if worm_texcoords is None else np.asarray(worm_texcoords, dtype=np.float64)
    if tc.ndim == 2:
        tc = tc[None]
    verts = [P]
    texs = [np.broadcast_to(tc, (W, V, 3))]
    offset = V
    if magnet_pos is not None:
        mp = np.asarray(magnet_pos, dtype=np.float64)
        mr = np.asarray(magnet_rot, dtype=np.float64)
        dv, dt = disk_mesh(disk_segments)
        d = np.broadcast_to(np.asarray(ipm_diameter, dtype=np.float64), (W,))
        h = np.broadcast_to(np.asarray(ipm_thickness, dtype=np.float64), (W,))
        scale = np.stack([d / 2, d / 2, h], axis=1)  # (W, 3)
        local = dv[None] * scale[:, None]  # (W, Kd, 3)
        for slot in (1, 2, 3):
            world = np.einsum("wij,wkj->wki", mr[:, slot], local) + mp[:, slot, None]
            verts.append(world)
            texs.append(local)
            tris.append(dt + offset)
            labels.append(np.full(len(dt), SEG_IPM_FIRST + slot - 1, dtype=np.int32))
            offset += dv.shape[0]
        if show_epm:
            bv, bt = box_mesh()
            size = np.broadcast_to(np.asarray(epm_size, dtype=np.float64), (W, 3))
            local = bv[None] * size[:, None]
            verts.append(np.einsum("wij,wkj->wki", mr[:, 0], local) + mp[:, 0, None])
            texs.append(local)
            tris.append(bt + offset)
            labels.append(np.full(len(bt), SEG_EPM, dtype=np.int32))
            offset += bv.shape[0]
    if extra_mesh is not None:
        ev, et, el, etc = extra_mesh
        verts.append(np.broadcast_to(np.asarray(ev, dtype=np.float64), (W,) + np.shape(ev)[1:]))
        texs.append(np.broadcast_to(np.asarray(etc, dtype=np.float64), (W,) + np.shape(etc)[1:]))
        tris.append(np.asarray(et, dtype=np.int32) + offset)
        labels.append(np.asarray(el, dtype=np.int32))
        offset += verts[-1].shape[1]
    scene = SceneBatch.from_mesh(np.concatenate(verts, axis=1), np.concatenate(tris), np.concatenate(labels),
                                 texcoords=np.concatenate(texs, axis=1), floor_incline=floor_incline,
                                 floor_half=floor_half, appearance=appearance)
    return scene


def scene_from_snapshot(snapshot: dict, pattern, params=None, *, rest_vertices=None, appearance=None,
                        **kwargs) -> SceneBatch:
    """:func:`build_scene` from ``Simulator.snapshot()`` and the crease pattern; magnet sizes from ``WormParams``."""
    kw = {}
    if params is not None:
        kw = dict(ipm_diameter=params.ipm_diameter, ipm_thickness=params.ipm_thickness, epm_size=params.epm_size,
                  floor_incline=params.floor_incline)
    kw.update(kwargs)
    return build_scene(snapshot["positions"], pattern.triangles, pattern.triangle_segment,
                       magnet_pos=snapshot.get("magnet_pos"), magnet_rot=snapshot.get("magnet_rot"),
                       worm_texcoords=pattern.vertices if rest_vertices is None else rest_vertices,
                       appearance=appearance, **kw)


__all__ = ["LABEL_NAMES", "Appearance", "SceneBatch", "box_mesh", "build_scene", "default_appearance", "disk_mesh",
           "floor_frame", "plate_frame", "scene_from_snapshot"]
