"""Nothing world-fixed relative to the worm: the plate's pose and the lights, drawn per trajectory.

Every simulated worm starts at the origin heading +x, so anything drawn fixed in the world (the default lamp at
(-0.15, 0.2, 0.3) m, floor textures along the world axes, the floor square's edges) is also fixed relative to the
worm's head and tail, and a network can tell the two apart by it instead of by the worm (issue 24). Here the scene
around the worm is drawn relative to it instead; the simulation, cameras and labels are untouched:

* ``render.plate_pose``: the plate (the floor square with its textures, and the room's lights) gets a yaw uniform in
  [0, 2π) and an offset uniform in a disk of radius ``render.plate_offset``. The floor turns about its normal and
  shifts along its axes; the lights (the default lamp, the drawn point lights and the directional light) turn about
  the world's z and shift horizontally by the same offset.
* ``render.lights: random``: ``light_count`` point lights, each at a uniform azimuth and the configured elevation,
  distance, radius, irradiance at the plate's centre and colour (cool daylight to warm tungsten), in the plate's frame.

Draws are keyed by (master seed, trajectory) with :func:`warpworm.data.randomize.uniform01` streams ``plate`` and
``lights.<i>``, so a trajectory's frames share them and any sharding gives the same values. Their names are the
``params/`` datasets they are stored under (docs/render.md).
"""

from __future__ import annotations

import numpy as np

from warpworm.data import randomize as rnd
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
    if "lights.count" in draws:
        n = max(1, max((int(k.split(".")[1]) + 1 for k in draws if k.startswith("lights.") and k != "lights.count"),
                       default=0))
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


__all__ = ["COOL", "LIGHT_DRAWS", "WARM", "placement_draws", "place", "DEFAULT_LAMP_POS"]
