"""Nothing world-fixed relative to the worm: the plate's pose and the lights, drawn per trajectory.

Every simulated worm starts at the origin heading +x, so anything drawn fixed in the world (the default lamp at
(-0.15, 0.2, 0.3) m, floor textures along the world axes, the floor square's edges) is also fixed relative to the
worm's head and tail, and a network can tell the two apart by it instead of by the worm. Here the scene
around the worm is drawn relative to it instead; the simulation, cameras and labels are untouched:

* ``render.plate_pose``: the plate (the floor square with its textures, and the room's lights) gets a yaw uniform in
  [0, 2π) and an offset uniform in a disk of radius ``render.plate_offset``. The floor turns about its normal and
  shifts along its axes; the lights (the default lamp, the drawn point lights and the directional light) turn about
  the world's z and shift horizontally by the same offset.
* ``render.lights: random``: ``light_count`` point lights, each at a uniform azimuth and the configured elevation,
  distance, radius, irradiance at the plate's centre and colour (cool daylight to warm tungsten), in the plate's frame.

Draws are keyed by (master seed, trajectory) with :func:`warpworm.rng.uniform01` streams ``plate`` and
``lights.<i>``, so a trajectory's frames share them and any sharding gives the same values. Their names are the
``params/`` datasets they are stored under (docs/render.md).
"""

from __future__ import annotations

import numpy as np

from warpworm import rng as rnd
from warpworm.render.scene import DEFAULT_LAMP_POS, DEFAULT_LAMP_SIZE, Appearance

COOL = np.array([0.90, 0.95, 1.00])
"""Colour of a daylight lamp (~6500 K) before normalization."""
WARM = np.array([1.00, 0.80, 0.58])
"""Colour of a tungsten lamp (~3000 K) before normalization."""
LIGHT_DRAWS = ("azimuth", "elevation", "distance", "size", "irradiance", "warmth")
"""Drawn values of each point light ``i`` (stored as ``params/lights.<i>.<name>``; azimuth and elevation [rad] seen
from the plate's centre in its frame, distance and size [m], irradiance at the plate's centre, warmth in [0, 1])."""


def _between(u: np.ndarray, lo_hi) -> np.ndarray:
    return lo_hi[0] + (lo_hi[1] - lo_hi[0]) * u


def placement_draws(render_cfg, keys: np.ndarray) -> dict[str, np.ndarray]:
    """The plate pose and light draws of trajectories with sample keys ``keys`` (B,) (:func:`rnd.sample_keys`),
    for the options ``render_cfg`` (a :class:`warpworm.data.config.RenderConfig`) turns on; {} when both are off."""
    out = {}
    if render_cfg.plate_pose:
        r = render_cfg.plate_offset * np.sqrt(rnd.uniform01(keys, "plate", 1))
        ang = 2 * np.pi * rnd.uniform01(keys, "plate", 2)
        out["plate.yaw"] = 2 * np.pi * rnd.uniform01(keys, "plate", 0)
        out["plate.offset_u"] = r * np.cos(ang)
        out["plate.offset_v"] = r * np.sin(ang)
    if getattr(render_cfg, "paper_bsdf", False):
        for k, (name, lo_hi) in enumerate(PAPER_RANGES.items()):
            out[f"paper.{name}"] = _between(rnd.uniform01(keys, "paper", k), lo_hi)
    materials = list(getattr(render_cfg, "plate_materials", ["matte"]))
    if materials != ["matte"]:
        pick = np.minimum(np.floor(rnd.uniform01(keys, "plate.material", 0) * len(materials)), len(materials) - 1)
        out["plate.material"] = np.asarray(materials, dtype=object)[pick.astype(int)]  # text, as choice draws
        out["plate.gloss"] = rnd.uniform01(keys, "plate.material", 1)
        out["plate.clarity"] = rnd.uniform01(keys, "plate.material", 2)
    lo, hi = getattr(render_cfg, "distractors", (0, 0))
    if hi > 0:
        count = np.minimum(lo + np.floor(rnd.uniform01(keys, "distractors", 0) * (hi - lo + 1)), hi)
        out["distractors.count"] = count.astype(np.float64)
        for i in range(hi):
            for k, name in enumerate(DISTRACTOR_DRAWS):
                u = rnd.uniform01(keys, f"distractors.{i}", k)
                out[f"distractors.{i}.{name}"] = np.floor(u * len(KINDS)) if name == "kind" else u
            g = {k: out[f"distractors.{i}.{k}"] for k in ("kind", "size", "aspect")}
            xy = _off_the_worm(_dims(g["kind"].astype(int), g["size"], g["aspect"])[1],
                               np.stack([rnd.uniform01(keys, f"distractors.{i}.place", k) for k in range(16)], 1))
            out[f"distractors.{i}.x"], out[f"distractors.{i}.y"] = xy[:, 0], xy[:, 1]
    if render_cfg.lights == "random":
        lo, hi = render_cfg.light_count
        count = np.minimum(lo + np.floor(rnd.uniform01(keys, "lights", 0) * (hi - lo + 1)), hi)
        out["lights.count"] = count.astype(np.float64)
        ranges = {"azimuth": (0.0, 2 * np.pi), "elevation": render_cfg.light_elevation,
                  "distance": render_cfg.light_distance, "size": render_cfg.light_size,
                  "irradiance": render_cfg.light_irradiance, "warmth": render_cfg.light_warmth}
        for i in range(hi):
            for k, name in enumerate(LIGHT_DRAWS):
                out[f"lights.{i}.{name}"] = _between(rnd.uniform01(keys, f"lights.{i}", k), ranges[name])
    return out


KINDS = ("paper", "cube", "cylinder", "ruler")
"""Distractor objects: a paper scrap (15-40 x 10-30 x 0.2 mm), a cube (8-20 mm), a cylinder (radius 4-12 mm, height
10-45 mm: a cap, a pen holder), a ruler (150 x 20 x 1.5 mm)."""
DISTRACTOR_DRAWS = ("kind", "size", "aspect", "yaw", "hue", "saturation", "value")
"""Drawn values of each distractor ``i`` (``params/distractors.<i>.<name>``): kind (index into :data:`KINDS`), the
rest uniforms in [0, 1) mapped by :func:`distractor_mesh`; also stored: ``x``, ``y`` [m], its centre on the floor
(:func:`_off_the_worm`)."""
WORM_REGION = (-0.03, 0.11, 0.015)
"""(x from, x to, radius) [m]: the capsule on the floor where a trajectory's worm lies (it starts with its tail at
the origin heading +x, 8 cm long and 2 cm wide, and crawls a few cm either way); no distractor reaches into it."""
PLACE_BOX = (0.04, 0.13, 0.06)
"""(x of the centre, half-length, half-width) [m] of the floor box distractor centres are drawn in (symmetric under
the worm's half turn about its middle, so no object placement tells head from tail); the first half of the
candidates come from a box :data:`NEAR_SCALE` times as large, so that objects stand close to the worm (and in front
of it from some views) more often."""
NEAR_SCALE = (0.7, 0.45)
"""Scale of :data:`PLACE_BOX`'s half-length and half-width for the first half of the candidates."""


def _dims(kind: np.ndarray, size: np.ndarray, aspect: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Extents (n, 3) [m] of distractors (box sides, or a cylinder's (radius, radius, height)) and their footprint
    radius (n,) [m] (circumradius on the floor)."""
    n = len(kind)
    dims = np.select([(kind == 0)[:, None], (kind == 1)[:, None], (kind == 2)[:, None]], [
        np.stack([0.015 + 0.025 * size, 0.010 + 0.020 * aspect, np.full(n, 0.0002)], 1),
        np.stack([0.008 + 0.012 * size] * 3, 1),
        np.stack([0.004 + 0.008 * size, 0.004 + 0.008 * size, 0.010 + 0.035 * aspect], 1)],
        np.tile([0.150, 0.020, 0.0015], (n, 1)))
    return dims, np.where(kind == 2, dims[:, 0], 0.5 * np.hypot(dims[:, 0], dims[:, 1]))


def _off_the_worm(foot: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Floor centres (n, 2) [m]: the first of the candidates (uniforms u (n, 2k)) in :data:`PLACE_BOX` whose
    footprint (radius ``foot``) stays out of :data:`WORM_REGION`'s capsule; if none, the first pushed out along its
    normal to the capsule until it does."""
    cx, hx, hy = PLACE_BOX
    x0, x1, r = WORM_REGION
    k = u.shape[1] // 2
    sx = np.where(np.arange(k) < k // 2, NEAR_SCALE[0], 1.0) * hx
    sy = np.where(np.arange(k) < k // 2, NEAR_SCALE[1], 1.0) * hy
    cand = np.stack([cx + sx * (2 * u[:, 0::2] - 1), sy * (2 * u[:, 1::2] - 1)], axis=-1)  # (n, k, 2)
    near = np.stack([np.clip(cand[..., 0], x0, x1), np.zeros(cand.shape[:2])], axis=-1)
    dist = np.linalg.norm(cand - near, axis=-1)
    ok = dist > r + foot[:, None]
    pick = np.argmax(ok, axis=1)
    rows = np.arange(len(foot))
    out, d, q = cand[rows, pick], dist[rows, pick], near[rows, pick]
    bad = ~ok[rows, pick]
    away = np.where(d[:, None] > 1e-9, (out - q) / np.maximum(d, 1e-9)[:, None], [0.0, 1.0])
    out[bad] = q[bad] + away[bad] * (r + foot[bad] + 1e-4)[:, None]
    return out


def distractor_mesh(draws: dict, num_worlds: int, floor_incline=0.0, segments: int = 12):
    """The distractor objects of :func:`placement_draws` as an extra mesh for
    :func:`warpworm.render.scene.build_scene` (``extra_mesh``), or None when the draws hold none.

    Every slot carries a box and a cylinder (one topology for all worlds); the kind drawn keeps its shape and the
    other (and every slot beyond the count) collapses to a point, which the rasterizer skips. Object ``i`` is
    labelled ``SEG_EPM + 1 + i`` (its own albedo row, :func:`place`; the floor's id in the segmentation). It lies on
    the floor plane (incline about y) centred at its drawn floor point (x, y) (outside the worm's capsule,
    :func:`_off_the_worm`), turned by ``2π yaw`` about the floor normal.
    Returns (vertices (W, Vd, 3), triangles (Td, 3), labels (Td,), texcoords (W, Vd, 3)) [m]."""
    from warpworm.ids import SEG_EPM
    from warpworm.render.scene import box_mesh, disk_mesh, floor_frame

    if "distractors.count" not in draws:
        return None
    n = _slot_count(draws, "distractors")
    W = num_worlds
    g = lambda i, name: np.broadcast_to(np.asarray(draws[f"distractors.{i}.{name}"], np.float64), (W,))  # noqa
    count = np.broadcast_to(np.asarray(draws["distractors.count"]), (W,))
    normal, axis = floor_frame(floor_incline, W)
    side = np.cross(normal, axis)
    bv, bt = box_mesh()
    cv, ct = disk_mesh(segments)
    verts, tris, labels, texs, off = [], [], [], [], 0
    for i in range(n):
        kind = g(i, "kind").astype(int)
        dims, _ = _dims(kind, g(i, "size"), g(i, "aspect"))  # (W, 3): box extents, or cylinder (r, r, height)
        cu, cvv = g(i, "x"), g(i, "y")
        yaw = 2 * np.pi * g(i, "yaw")
        ex = np.cos(yaw)[:, None] * axis + np.sin(yaw)[:, None] * side  # object x on the floor
        ey = np.cross(normal, ex)
        centre = cu[:, None] * axis + cvv[:, None] * side + (0.5 * dims[:, 2:3] + 1e-5) * normal
        on = i < count
        for shape_v, shape_t, is_shape in ((bv, bt, kind != 2), (cv, ct, kind == 2)):
            local = shape_v[None] * dims[:, None]  # unit cube / unit cylinder -> extents (radius, radius, height)
            world = (centre[:, None] + local[..., :1] * ex[:, None] + local[..., 1:2] * ey[:, None]
                     + local[..., 2:3] * normal[:, None])
            keep = (on & is_shape)[:, None, None]
            verts.append(np.where(keep, world, centre[:, None]))
            texs.append(np.where(keep, local, 0.0))
            tris.append(shape_t + off)
            labels.append(np.full(len(shape_t), SEG_EPM + 1 + i, np.int32))
            off += len(shape_v)
    return (np.concatenate(verts, 1), np.concatenate(tris), np.concatenate(labels), np.concatenate(texs, 1))


PAPER_RANGES = {"wrap": (0.15, 0.45), "sheen": (0.1, 0.4), "roughness": (0.3, 0.7), "ground": (0.25, 0.6)}
"""Ranges of the sheet's paper BSDF (``render.paper_bsdf``; :func:`warpworm.render.shading.paper_surface`),
drawn per trajectory and stored as ``params/paper.<name>``: wrap of the diffuse term, sheen strength and roughness,
the ambient from below as a fraction of the sky's."""
MATERIALS = ("matte", "glossy", "acrylic")
"""Plate materials: matte (as before), glossy (Blinn-Phong strength 0.2-0.6, exponent 30-150 from ``plate.gloss``)
and clear acrylic (as glossy, and ``floor_transmit`` 0.3-0.6 from ``plate.clarity``: the EPM under it shows)."""


def _slot_count(draws: dict, prefix: str) -> int:
    """Number of slots ``i`` drawn as ``<prefix>.<i>.<name>`` in ``draws`` (0 when none)."""
    return max((int(k.split(".")[1]) + 1 for k in draws if k.startswith(prefix + ".") and k != prefix + ".count"),
               default=0)


def _plate_material(a: Appearance, draws: dict) -> None:
    """The floor's specular row and transmittance from the drawn ``plate.material``, ``plate.gloss``,
    ``plate.clarity`` (B,)."""
    B = a.num_worlds
    kind = np.asarray(draws["plate.material"]).astype(str)
    gloss = np.asarray(draws["plate.gloss"], dtype=np.float64)
    shiny = kind != "matte"
    a.specular = np.broadcast_to(a.specular, (B,) + a.specular.shape[1:]).copy()
    a.specular[:, 1] = np.where(shiny[:, None], np.stack([0.2 + 0.4 * gloss, 30.0 + 120.0 * gloss], 1),
                                a.specular[:, 1])
    clear = 0.3 + 0.3 * np.asarray(draws["plate.clarity"], dtype=np.float64)
    a.floor_transmit = np.where(kind == "acrylic", clear, 0.0)


def _distractor_looks(a: Appearance, draws: dict) -> None:
    """Albedo and specular rows of the distractors (label SEG_EPM + 1 + i): paper and rulers light and matte, cubes
    and cylinders any hue, a little gloss."""
    from warpworm.render.scene import hsv_to_rgb

    n = _slot_count(draws, "distractors")
    B = a.num_worlds
    alb = np.broadcast_to(a.albedo, (B,) + a.albedo.shape[1:])
    spec = np.broadcast_to(a.specular, (B,) + a.specular.shape[1:])
    rows_a, rows_s = [], []
    for i in range(n):
        g = {k: np.broadcast_to(np.asarray(draws[f"distractors.{i}.{k}"], np.float64), (B,))
             for k in ("kind", "hue", "saturation", "value")}
        flat = (g["kind"] == 0) | (g["kind"] == 3)
        sat = np.where(flat, 0.15 * g["saturation"], 0.2 + 0.6 * g["saturation"])
        val = np.where(flat, 0.7 + 0.25 * g["value"], 0.3 + 0.6 * g["value"])
        rows_a.append(hsv_to_rgb(g["hue"], sat, val) ** 2)  # display colour -> linear albedo
        rows_s.append(np.stack([np.where(flat, 0.0, 0.3), np.full(B, 30.0)], 1))
    a.albedo = np.concatenate([alb, np.stack(rows_a, 1)], axis=1)
    a.specular = np.concatenate([spec, np.stack(rows_s, 1)], axis=1)


def _yaw(v: np.ndarray, yaw: np.ndarray) -> np.ndarray:
    """Vectors v (B, ..., 3) turned by yaw (B,) [rad] about the world's z."""
    c, s = np.cos(yaw), np.sin(yaw)
    c = c.reshape((-1,) + (1,) * (v.ndim - 2))
    s = s.reshape(c.shape)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1], v[..., 2]], axis=-1)


def place(a: Appearance, draws: dict) -> Appearance:
    """``a`` (B worlds) with the drawn point lights and plate pose of :func:`placement_draws` applied (in place and
    returned); draws of an option that is off are absent, and ``a`` keeps what it had for it."""
    B = a.num_worlds
    if "paper.wrap" in draws:
        a.paper_bsdf = np.stack([np.asarray(draws[f"paper.{k}"], dtype=np.float64) for k in PAPER_RANGES], axis=1)
    if "plate.material" in draws:
        _plate_material(a, draws)
    if "distractors.count" in draws:
        _distractor_looks(a, draws)
    if "lights.count" in draws:
        n = max(1, _slot_count(draws, "lights"))
        pos, power, size = np.zeros((B, n, 3)), np.zeros((B, n, 3)), np.full((B, n), DEFAULT_LAMP_SIZE)
        count = np.asarray(draws["lights.count"])
        for i in range(n):
            if f"lights.{i}.azimuth" not in draws:
                continue
            g = {k: np.asarray(draws[f"lights.{i}.{k}"], dtype=np.float64) for k in LIGHT_DRAWS}
            el, az, d = g["elevation"], g["azimuth"], g["distance"]
            pos[:, i] = d[:, None] * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
            colour = (1 - g["warmth"][:, None]) * COOL + g["warmth"][:, None] * WARM
            colour /= colour.mean(axis=1, keepdims=True)
            on = (i < count)[:, None]
            power[:, i] = np.where(on, colour * (g["irradiance"] * d * d)[:, None], 0.0)
            size[:, i] = g["size"]
        a.light_pos, a.light_power, a.light_size = pos, power, size
    if "plate.yaw" in draws:
        yaw = np.asarray(draws["plate.yaw"], dtype=np.float64)
        off = np.stack([draws["plate.offset_u"], draws["plate.offset_v"], np.zeros(B)], axis=1)
        a.plate = np.stack([yaw, off[:, 0], off[:, 1]], axis=1)
        lp = np.broadcast_to(a.light_pos, (B,) + a.light_pos.shape[1:])
        a.light_pos = _yaw(lp, yaw) + off[:, None]
        a.light_power = np.broadcast_to(a.light_power, lp.shape).copy()
        a.light_size = np.broadcast_to(a.light_size, lp.shape[:2]).copy()
        a.sun_dir = _yaw(np.broadcast_to(a.sun_dir, (B, 3)), yaw)
    return a


__all__ = ["COOL", "DISTRACTOR_DRAWS", "KINDS", "LIGHT_DRAWS", "MATERIALS", "PAPER_RANGES", "WARM", "WORM_REGION", "distractor_mesh",
           "placement_draws", "place"]
