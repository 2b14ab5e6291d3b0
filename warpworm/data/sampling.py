"""Every randomized value of a dataset sample, drawn from the config's distributions (``cfg.randomize``) with the one
counter-based generator of :mod:`warpworm.data.randomize`, and turned into what the simulator and renderer take.

What each draw is keyed by (so that any shard size, worker count, engine or device gives the same samples):

* physics (``worm.*``): (seed, trajectory, attempt) -- :func:`draw_worm`, :func:`worm_params`;
* appearance (``light.*``, ``color.*``, ``texture.*``) and sensor values (``sensor.*``): (seed, trajectory) --
  :func:`appearance_draws`, turned into the renderer's inputs by :func:`appearance_from_draws` and
  :func:`sensor_values`;
* cameras (``camera.*``): (seed, trajectory) or (seed, sample) with ``render.camera_per_frame`` --
  :func:`dataset_cameras`.

A shard draws through two calls, one per side of the simulation: :func:`draw_worlds` (the simulator's parameters of a
batch of trajectories, per solver batch) and, once the worlds have moved, :func:`draw_views` (for each render call:
cameras, looks, sensor values, seeds and the ``params/*`` columns, as a :class:`RenderDraws` the renderer is handed).

:func:`randomized_params` draws ``WormParams`` for W worlds outside a dataset job (``warpworm simulate --randomize``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from warpworm import rng
from warpworm.data import randomize as rnd
from warpworm.data.config import BATCH_SHARED, ConfigError, load_config
from warpworm.physics.gaits import GAIT_PRESETS, gait_theta
from warpworm.physics.params import WormParams
from warpworm.render import default_appearance, hsv_to_rgb, sample_cameras
from warpworm.render.distortion import draw_distortion
from warpworm.render.placement import place, placement_draws
from warpworm.render.scene import BAND_COLORS

_WORM_VECTOR = {"epm_size": ("epm_size_x", "epm_size_y", "epm_size_z"),
                "ipm_moment": ("ipm_moment_tail", "ipm_moment_centre", "ipm_moment_head")}
_WORM_SHARED = {"gait", "backward", "magnet_model"}


# ---------------------------------------------------------------------------------------------------------------------
# Physics
def draw_worm(cfg, traj: np.ndarray, attempt: np.ndarray) -> rnd.Draws:
    """Draw the ``worm.*`` parameters of trajectories ``traj`` (n,) at ``attempt`` (n,)."""
    dists = {f"worm.{k}": v for k, v in cfg.randomize["worm"].items()}
    d = rnd.draw(dists, cfg.seed, traj, attempt)
    _fill_gait_presets(d)
    # kinetic friction can't exceed static: clip per sample (and record the clipped value).
    d.values["worm.mu_kinetic"] = np.minimum(d["worm.mu_kinetic"], d["worm.mu_static"])
    return d


def _fill_gait_presets(d: rnd.Draws) -> None:
    """NaN = "the gait preset's value" (:data:`warpworm.physics.gaits.GAIT_PRESETS`), resolved in place per sample's gait;
    a NaN orientation becomes the preset's EPM moment angle for the sample's gait and direction."""
    gait = np.asarray(d["worm.gait"]).astype(str)
    for g, preset in GAIT_PRESETS.items():
        sel = gait == g
        if not sel.any():
            continue
        for key, value in preset.items():
            arr = d.values.get(f"worm.{key}")
            if arr is not None and arr.dtype.kind == "f":
                arr[sel & np.isnan(arr)] = value
    theta, back = d["worm.orientation"], np.asarray(d["worm.backward"]).astype(bool)
    for g in np.unique(gait):
        for bw in (False, True):
            sel = (gait == g) & (back == bw) & np.isnan(theta)
            theta[sel] = gait_theta(str(g), bw)


def worm_params(cfg, draws: rnd.Draws, sel: np.ndarray | slice = slice(None)) -> WormParams:
    """WormParams for the selected worlds of ``draws``. ``gait``, ``backward`` and ``magnet_model`` are one value
    when equal over ``sel`` (always, for the fields of :data:`warpworm.data.config.BATCH_SHARED`, by which the job splits
    its batches), else (W,) arrays."""
    p = WormParams(n_units=cfg.sim.n_units)
    for name, arr in draws.values.items():
        group, key = name.split(".", 1)
        if group != "worm":
            continue
        a = arr[sel]
        if key in _WORM_SHARED:
            v = np.asarray(a).astype(bool if key == "backward" else str)
            one = bool(v[0]) if key == "backward" else str(v[0])
            setattr(p, key, one if (v == v[0]).all() else v)
        elif not any(key in comps for comps in _WORM_VECTOR.values()):
            setattr(p, key, np.asarray(a, dtype=np.float64))
    for vec, comps in _WORM_VECTOR.items():
        setattr(p, vec, np.stack([np.asarray(draws[f"worm.{c}"][sel], dtype=np.float64) for c in comps], axis=1))
    return p


def randomized_params(cfg_name_or_cfg, num_worlds: int, seed: int) -> WormParams:
    """``WormParams`` of ``num_worlds`` worlds drawn from a config's ``worm.*`` distributions (a
    :class:`~warpworm.data.config.DatasetConfig`, or a config name / path for :func:`warpworm.data.config.load_config`) with the
    counter-based generator: world ``w`` is trajectory ``w`` at attempt 0 of that config with master seed ``seed``
    (the same values a dataset job with that seed draws for its trajectory ``w``).

    ``gait`` and ``backward`` come out per world ((W,) arrays) when they differ between worlds; ``magnet_model`` is
    one value per solver batch, so a config whose draws give it two values is refused, naming the field.
    """
    cfg = load_config(cfg_name_or_cfg) if isinstance(cfg_name_or_cfg, str) else cfg_name_or_cfg
    if int(num_worlds) < 1:
        raise ConfigError([f"num_worlds: got {num_worlds}; expected >= 1"])
    cfg = dataclasses.replace(cfg, seed=int(seed))
    n = int(num_worlds)
    d = draw_worm(cfg, np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64))
    models = sorted({str(v) for v in np.asarray(d["worm.magnet_model"]).tolist()})
    if len(models) > 1:
        raise ConfigError([f"randomize.worm.magnet_model: drew {models} over {n} worlds; expected one value (the "
                           "force model is shared by the solver batch: make it a constant)"])
    return worm_params(cfg, d)


def draw_group(cfg, group: str, index: np.ndarray) -> rnd.Draws:
    """Draw the ``<group>.*`` distributions of the config for ``index`` (n,) (attempt 0)."""
    return rnd.draw({f"{group}.{k}": v for k, v in cfg.randomize[group].items()}, cfg.seed, index)


# ---------------------------------------------------------------------------------------------------------------------
# Appearance and sensor
APPEARANCE_GROUPS = ("light", "color", "texture", "sensor")


def appearance_draws(cfg, traj: np.ndarray) -> dict[str, np.ndarray]:
    """The ``light / color / texture / sensor`` draws of trajectories ``traj`` (B,), each (B,), plus
    ``texture.seed``: the procedural textures' offset, keyed by the trajectory so that the floor grain and paper fibre
    stay put across a trajectory's frames (a per-sample seed would make them crawl between frames of one camera)."""
    app = {}
    for g in APPEARANCE_GROUPS:
        app.update(draw_group(cfg, g, traj).values)
    app["texture.seed"] = rng.derived_seed(rng.sample_keys(cfg.seed, traj), "texture") % (2**31 - 1)
    r = cfg.render  # the plate's pose and material, the lights, distractors (per trajectory)
    if r.plate_pose or r.lights != "fixed" or r.distractors[1] > 0 or r.plate_materials != ["matte"] or r.paper_bsdf:
        app.update(placement_draws(cfg.render, rng.sample_keys(cfg.seed, traj)))
    return app


def appearance_from_draws(app: dict, seeds: np.ndarray, band_colors=None):
    """The renderer's :class:`~warpworm.render.Appearance` from the drawn ``light/color/texture`` values (B,) each;
    ``band_colors`` (5, 3): the bands' display colours (``render.band_colors``; None: the paper's)."""
    B = len(seeds)
    a = default_appearance(B)
    worm = hsv_to_rgb(app["color.worm_hue"], app["color.worm_saturation"], app["color.worm_value"])
    floor = hsv_to_rgb(app["color.floor_hue"], app["color.floor_saturation"], app["color.floor_value"])
    a.albedo = a.albedo.copy()
    a.albedo[:, 2:7] = worm[:, None]
    a.albedo[:, 1] = floor
    a.floor_color2 = floor * 0.55
    tex = np.asarray(app["texture.floor"]).astype(str)
    ft = a.floor_tex.copy()
    ft[:, 0] = app["texture.floor_scale"]
    ft[:, 1] = np.where(tex == "checker", 0.6, 0.0)  # checker contrast
    ft[:, 2] = np.where(tex == "noise", 0.5, 0.0)  # grain amplitude
    ft[:, 3] = 1.0 / np.maximum(app["texture.floor_scale"], 1e-4) * 5.0
    a.floor_tex = ft
    fibre = np.asarray(app["texture.worm"]).astype(str) == "fibre"
    a.paper_tex = np.stack([np.where(fibre, 0.25, 0.0), np.where(fibre, 0.10, 0.0)], axis=1)
    bands = np.asarray(app["texture.worm"]).astype(str) == "bands"
    if bands.any():  # the paper's marker bands (§IV-E): one colour per segment, flat paint
        c = BAND_COLORS if band_colors is None else np.asarray(band_colors, np.float64)
        a.albedo[bands, 2:7] = c[None] ** 2
        a.paper_tex[bands] = 0.0
    tex_seed = app.get("texture.seed")  # per trajectory (appearance_draws); a bare per-sample seed otherwise
    a.tex_seed = ((seeds if tex_seed is None else np.asarray(tex_seed)) % (2**31 - 1)).astype(np.int32)
    el, az = app["light.elevation"], app["light.azimuth"]
    a.sun_dir = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    a.sun_color = app["light.intensity"][:, None] * np.ones(3)
    a.ambient = app["light.ambient"][:, None] * np.ones(3)
    bg = app["color.background_value"][:, None] * np.ones(3)
    a.bg_top, a.bg_bottom = bg, 0.6 * bg
    if any(k.startswith(("plate.", "lights.", "distractors.", "paper.")) for k in app):  # drawn when asked
        a = place(a, app)
    return a


def sample_appearance(cfg, index: np.ndarray):
    """The renderer's :class:`~warpworm.render.Appearance` of ``index`` (n,) trajectories (or any ids) drawn from the
    config's ``light / color / texture`` distributions: the look a dataset job gives those trajectories."""
    index = np.asarray(index, dtype=np.int64).reshape(-1)
    return appearance_from_draws(appearance_draws(cfg, index), rng.derived_seed(rng.sample_keys(cfg.seed, index)),
                                 cfg.render.band_colors)


def sensor_values(app: dict) -> dict:
    """The dataset's drawn ``sensor.*`` values (B,) -> :func:`warpworm.render.sensor.apply_sensor` ``values``.

    Brightness and noise are configured in 8-bit levels (the renderer takes fractions of full scale); JPEG quality 100
    means no round trip (the renderer's 0). White balance, hue, saturation and shot noise are not dataset parameters:
    neutral (the renderer then skips the colour conversions).
    """
    q = np.asarray(app["sensor.jpeg_quality"]).astype(np.int64)
    B = len(q)
    f32 = np.float32  # float32 values keep the per-image arithmetic in float32 (faster than float64)
    return {"wb_r": np.ones(B), "wb_g": np.ones(B), "wb_b": np.ones(B), "hue_deg": np.zeros(B),
            "saturation": np.ones(B), "contrast": np.asarray(app["sensor.contrast"], f32),
            "brightness": (np.asarray(app["sensor.brightness"], np.float64) / 255.0).astype(f32),
            "blur_sigma": np.asarray(app["sensor.blur_sigma"], np.float64),
            "noise_sigma": np.asarray(app["sensor.noise_std"], np.float64) / 255.0, "shot_noise": np.zeros(B),
            "jpeg_quality": np.where(q >= 100, 0, q)}


# ---------------------------------------------------------------------------------------------------------------------
# Cameras
def _range(dist: rnd.Distribution) -> tuple[float, float]:
    """(lo, hi) of a camera range (config validation allows only constants and uniforms)."""
    if isinstance(dist, rnd.Uniform):
        return (float(dist.low), float(dist.high))
    return (float(dist.value), float(dist.value))


def dataset_cameras(cfg, index: np.ndarray, worm_points: np.ndarray, view: np.ndarray | None = None):
    """Cameras of ``index`` (n,) trajectory or sample ids (whatever the camera is keyed by) from the ``camera.*``
    ranges, with :func:`warpworm.render.sample_cameras`: on a shell around the mean of ``worm_points`` (n, P, 3) (the
    worm's vertices over every frame the camera shows), redrawn until at least ``camera.min_in_frame`` of those
    points project inside the image (up to ``camera.max_tries``; then the best view is kept). Square pixels, principal
    point at the image centre, ``fov_y`` vertical.

    Each camera draws from its own seed, derived from (master seed, index), so it is the same in any batch, shard or
    worker. ``view`` (n,): which of a trajectory's ``render.views_per_frame`` cameras (None: all view 0); view 0 is
    the camera of before that option, view v > 0 draws from its own stream ``camera.view<v>`` of the same key.
    Returns (cameras, ``camera.*`` values (n,) each as stored in ``params/``: the kept view's distance,
    elevation, azimuth, roll, fov_y [rad], look-at offset length [m], its in-frame fraction, max_tries).
    """
    c = cfg.randomize["camera"]
    index = np.asarray(index, dtype=np.int64)
    keys = rng.sample_keys(cfg.seed, index)
    seeds = rng.derived_seed(keys, "camera")
    if view is not None:
        view = np.asarray(view, dtype=np.int64)
        for v in np.unique(view[view > 0]):
            seeds[view == v] = rng.derived_seed(keys[view == v], f"camera.view{int(v)}")
    pts = np.asarray(worm_points, dtype=np.float64)
    target = pts.mean(axis=1)
    deg = lambda name: tuple(np.rad2deg(_range(c[name])))  # noqa: E731
    cams = sample_cameras(
        seeds, pts, width=cfg.render.width, height=cfg.render.height, world_index=np.arange(len(index)),
        target=target, distance=_range(c["distance"]), elevation_deg=deg("elevation"), azimuth_deg=deg("azimuth"),
        roll_deg=deg("roll"), fov_deg=deg("fov_y"), fov_axis="y", lookat_jitter=_range(c["lookat_jitter"])[0],
        aspect_jitter=0.0, principal_jitter=0.0, min_in_frame=_range(c["min_in_frame"])[0],
        max_tries=int(_range(c["max_tries"])[0]))
    if cfg.render.distortion:  # lens distortion per camera, from the camera's seed (stored as camera/dist)
        cams.dist = draw_distortion(cfg.render, seeds, cams.K, cfg.render.width, cfg.render.height)
    d = cams.draws
    n = len(index)
    values = {
        "camera.distance": d["distance"], "camera.elevation": np.deg2rad(d["elevation_deg"]),
        "camera.azimuth": np.deg2rad(d["azimuth_deg"]), "camera.roll": np.deg2rad(d["roll_deg"]),
        "camera.fov_y": np.deg2rad(d["fov_deg"]),
        "camera.lookat_jitter": np.linalg.norm(d["lookat"] - target, axis=1),
        "camera.min_in_frame": cams.in_frame.astype(np.float64),
        "camera.max_tries": np.full(n, float(_range(c["max_tries"])[0])),
    }
    return cams, values


# ---------------------------------------------------------------------------------------------------------------------
# What a shard draws: one call before the simulation, one after
@dataclass
class WorldDraws:
    """The ``worm.*`` draws of n trajectories at their attempts, and the simulator's parameters per solver batch."""

    values: dict[str, np.ndarray]
    """Parameter name -> (n,) values (gait presets resolved, kinetic friction clipped to static)."""
    groups: list[tuple[np.ndarray, WormParams]]
    """(positions among the n (m,), ``WormParams`` of those m worlds): one solver batch per value of the batch-shared
    fields (:data:`warpworm.data.config.BATCH_SHARED`: gait, direction, magnet model)."""


def draw_worlds(cfg, traj: np.ndarray, attempt: np.ndarray) -> WorldDraws:
    """The worm draws of trajectories ``traj`` (n,) at ``attempt`` (n,), split into solver batches."""
    d = draw_worm(cfg, traj, attempt)
    return WorldDraws(values=d.values, groups=[(sel, worm_params(cfg, d, sel)) for sel in _solver_groups(d)])


def _solver_groups(d: rnd.Draws) -> list[np.ndarray]:
    """Positions in ``d`` split by the batch-shared fields (gait, direction, magnet model): one solver batch each."""
    keys = np.stack([np.asarray(d[n], dtype=str) for n in BATCH_SHARED], axis=1)
    _, group_of = np.unique(keys, axis=0, return_inverse=True)
    group_of = group_of.reshape(-1)
    return [np.flatnonzero(group_of == g) for g in np.unique(group_of)]


@dataclass
class RenderDraws:
    """Everything drawn for the n images of one render call: what the renderer is told, and what the rows store.

    Image i shows world i (the snapshot of its sample's trajectory and frame) through ``cameras`` image i.
    """

    params: WormParams
    """The trajectories' accepted worm parameters, (n,) worlds."""
    cameras: object
    """:class:`warpworm.render.Cameras` of the n images (``world`` = 0..n-1)."""
    appearance: dict[str, np.ndarray]
    """The drawn ``light / color / texture / sensor`` (and placement) values, (n,) each."""
    look: object
    """The renderer's :class:`~warpworm.render.Appearance` of ``appearance`` (:func:`appearance_from_draws`)."""
    sensor: dict[str, np.ndarray]
    """Sensor values (n,) each for :class:`warpworm.render.sensor.SensorBatch` (:func:`sensor_values`)."""
    seeds: np.ndarray
    """(n,) int64 per-sample seeds every pixel noise derives from."""
    columns: dict[str, np.ndarray]
    """``params/<name>`` values (n,) each: worm, appearance and camera draws, in that order."""


def render_draws(cfg, world_values: dict, appearance: dict, tsel: np.ndarray, cameras, seeds: np.ndarray,
                 camera_values: dict | None = None) -> RenderDraws:
    """The :class:`RenderDraws` of n images: trajectory ``tsel`` (n,) of ``world_values`` / ``appearance`` (B,)
    each, seen through ``cameras`` (n images) with per-image ``seeds`` (n,)."""
    app = _take(appearance, tsel)
    cameras.world = np.arange(len(seeds), dtype=np.int32)
    return RenderDraws(params=worm_params(cfg, rnd.Draws(world_values), tsel), cameras=cameras, appearance=app,
                       look=appearance_from_draws(app, seeds, cfg.render.band_colors), sensor=sensor_values(app),
                       seeds=seeds, columns={**_take(world_values, tsel), **app, **(camera_values or {})})


def draw_views(cfg, traj: np.ndarray, world_values: dict, positions: np.ndarray,
               calls: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]) -> tuple[list[RenderDraws], int]:
    """Everything the render calls of a simulated batch need, drawn at once.

    ``traj`` (B,) trajectories with accepted worm draws ``world_values`` (B,) each and vertex positions
    ``positions`` (B, F, V, 3) [m] at their F frames; ``calls``: per render call (sample ids, trajectory position in
    the batch, frame, view), (n,) each. A camera is keyed by (trajectory, view) and shows the worm over all its
    frames, or with ``render.camera_per_frame`` by the sample id and shows that frame. Returns one
    :class:`RenderDraws` per call and the number of cameras below ``camera.min_in_frame`` after ``camera.max_tries``.
    """
    B, K = len(traj), int(getattr(cfg.render, "views_per_frame", 1))
    appearance = appearance_draws(cfg, traj)
    below = 0
    if not cfg.render.camera_per_frame:  # K cameras per trajectory: the worm (all its frames) in view of each
        pts = positions.reshape(B, -1, 3)
        if K == 1:
            cams, cam_values = dataset_cameras(cfg, traj, pts)
        else:
            cams, cam_values = dataset_cameras(cfg, np.repeat(traj, K), np.repeat(pts, K, axis=0),
                                               view=np.tile(np.arange(K), B))
        below += int((~cams.accepted).sum())
    out = []
    for sid, tsel, fidx, vidx in calls:
        if cfg.render.camera_per_frame:  # a camera per sample, keyed by the sample id
            c, cv = dataset_cameras(cfg, sid, positions[tsel, fidx])
            below += int((~c.accepted).sum())
        else:
            csel = tsel * K + vidx
            c, cv = cams.take(csel), _take(cam_values, csel)
        seeds = rng.derived_seed(rng.sample_keys(cfg.seed, sid))
        out.append(render_draws(cfg, world_values, appearance, tsel, c, seeds, cv))
    return out, below


def _take(d: dict, sel) -> dict:
    return {k: v[sel] for k, v in d.items()}


__all__ = ["RenderDraws", "WorldDraws", "appearance_draws", "appearance_from_draws", "dataset_cameras", "draw_group",
           "draw_views", "draw_worlds", "draw_worm", "randomized_params", "render_draws", "sample_appearance",
           "sensor_values", "worm_params"]
