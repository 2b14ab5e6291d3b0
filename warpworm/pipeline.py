"""Dataset generation: batch of W worlds -> settle -> drive the EPM paths -> frames -> render -> write, shard by shard.

Sample ids and what determines them (so that any shard size, worker count, engine or device gives the same samples):

* sample ``i`` is frame ``i % F`` of trajectory ``i // F`` (F = ``len(sim.frame_times)``);
* trajectory ``j``'s physical parameters are drawn from the counter-based generator keyed by (seed, j, attempt);
  attempt starts at 0 and a world that goes unstable is redrawn with attempt + 1 (dropped, replaced, counted);
* its camera is keyed by (seed, j) (or by (seed, i) with ``render.camera_per_frame``), its appearance by (seed, j) and
  its sensor noise by (seed, i);
* shard k holds ids [k·S, min((k+1)·S, N)): resuming a killed job means redoing the missing shards.

The pipeline is independent of the physics and the renderer: it calls a *stages* object (see :class:`Stages`) given as
``"module:attribute"`` so that worker processes can import it. The default, :class:`WarpStages`, is warpworm's
simulator and renderer.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import json
import math
import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from . import dataset as ds
from . import randomize as rnd
from .config import BATCH_SHARED, ConfigError, DatasetConfig, check_output_dir
from .params import WormParams

DEFAULT_STAGES = "warpworm.pipeline:WarpStages"


# ---------------------------------------------------------------------------------------------------------------------
# Stage interface
@dataclass
class SimResult:
    """What :meth:`Stages.simulate_batch` returns for B worlds.

    frames: one snapshot dict per ``sim.frame_times`` entry, each with at least ``positions (B,V,3)``,
        ``magnet_pos (B,4,3)``, ``magnet_rot (B,4,3,3)``, ``crease_angle (B,H)``, ``bar_strain (B,E)`` [SI].
    unstable: (B,) bool: the world went unstable at some point (it is dropped and redrawn).
    """

    frames: list[dict[str, np.ndarray]]
    unstable: np.ndarray


class Stages(Protocol):
    """The two heavy stages of the pipeline (simulation, rendering), pluggable for tests and other engines."""

    def metadata(self, cfg: DatasetConfig) -> dict:
        """Static per-dataset facts: ``keypoint_names`` (P,), ``triangles (T,3)``, ``triangle_segment (T,)``,
        ``hinges (H,4)``, ``hinge_label (H,)``, ``edges (E,2)``, ``num_vertices``."""

    def simulate_batch(self, params: WormParams, num_worlds: int, cfg: DatasetConfig) -> SimResult:
        """Settle for ``sim.settle_time`` then drive the EPM paths; snapshots at ``sim.frame_times``."""

    def render_batch(self, frame: dict[str, np.ndarray], params: WormParams, cameras,
                     appearance: dict[str, np.ndarray], seeds: np.ndarray, cfg: DatasetConfig) -> dict[str, np.ndarray]:
        """Render B images of one snapshot per world and compute their labels.

        ``cameras`` is a :class:`warpworm.render.Cameras` of B images (``K (B,3,3)``, ``R (B,3,3)``, ``t (B,3)``,
        ``width``, ``height``; image b shows world b of ``frame``).

        Returns name -> (B, ...) arrays for the image and label datasets of :data:`warpworm.dataset.SCHEMA`
        (rgb, depth, segmentation, poses/*, keypoints/*, creases/angle, bars/strain, worm/vertices, labels/*).
        ``appearance`` holds the drawn ``light.*``, ``color.*``, ``texture.*``, ``sensor.*`` values, (B,) each;
        ``seeds`` (B,) int64 seeds all pixel noise must derive from.
        """


def load_stages(spec: str | Any) -> Any:
    """``"package.module:attr"`` -> a stages instance (attr is instantiated if it is a class or factory)."""
    if not isinstance(spec, str):
        return spec
    mod, _, attr = spec.partition(":")
    obj = getattr(importlib.import_module(mod), attr or "Stages")
    return obj() if callable(obj) else obj


class WarpStages:
    """warpworm's own simulator (:mod:`warpworm.simulator`) and rasterizer (:mod:`warpworm.render`).

    Simulation: ``Model.from_params`` -> ``Simulator(dt, substeps)`` -> ``settle(settle_time)`` -> ``step`` to each
    frame time -> ``snapshot``. A world flagged unstable at any frame is reported unstable.
    Rendering: ``render.build_scene`` (worm sheet, IPM disks, EPM bar, floor) with an appearance built from the drawn
    ``light/color/texture`` values, ``Renderer.render``, then sensor effects (:func:`warpworm.render.sensor.apply_sensor`
    with the drawn ``sensor.*`` values, :func:`sensor_values`) and labels (:func:`compute_labels`).
    """

    @staticmethod
    def kernel_modules() -> list[str]:
        """Every module of ``warpworm.kernels`` and ``warpworm.render`` whose name says it holds kernels
        (:meth:`warm` compiles them together). Discovered, not listed, so a new solver module is warmed too."""
        import pkgutil

        from . import kernels, render

        names = []
        for pkg in (kernels, render):
            names += [f"{pkg.__name__}.{m.name}" for m in pkgutil.iter_modules(pkg.__path__)
                      if "kernel" in m.name or pkg is kernels]
        return names

    def __init__(self):
        self._renderers = {}
        self._patterns = {}

    def preload(self):
        """Heavy imports (Warp, the simulator, the renderer), so a worker does them while the parent warms the cache."""
        from . import quiet_warp

        quiet_warp()
        from . import model, simulator  # noqa: F401
        from . import render  # noqa: F401

        for name in self.kernel_modules():
            importlib.import_module(name)

    def warm(self, cfg, max_workers: int | None = None):
        """Load every kernel module of :meth:`kernel_modules` on ``sim.device``, compiling the missing ones into
        Warp's kernel cache in parallel (``max_workers`` threads; default one per available core).

        Run once in the parent before workers start: with a cold cache (a kernel source changed, a fresh install)
        each worker would otherwise compile the same modules itself (measured ~33 s of CPU per process here, ~23 s
        wall when the three modules compile in parallel). With a hot cache it costs the module hashing (~0.3 s).
        """
        import warp as wp

        self.preload()
        if max_workers is None:
            try:
                max_workers = len(os.sched_getaffinity(0))
            except AttributeError:  # pragma: no cover - not Linux
                max_workers = os.cpu_count() or 1
        names = self.kernel_modules()
        wp.force_load(device=cfg.sim.device, modules=[wp.get_module(n) for n in names], max_workers=max_workers)

    def _pattern(self, n_units: int):
        from . import crease

        p = self._patterns.get(n_units)
        if p is None:
            w = WormParams()
            p = self._patterns[n_units] = crease.build_worm(w.a, w.b, n_units, l0=w.l0)
        return p

    def metadata(self, cfg):
        p = self._pattern(cfg.sim.n_units)
        from .render.labels import KEYPOINT_NAMES

        return {"keypoint_names": list(KEYPOINT_NAMES), "triangles": p.triangles,
                "triangle_segment": p.triangle_segment, "hinges": p.hinges, "hinge_label": p.hinge_label,
                "edges": p.edges, "num_vertices": p.num_vertices}

    def simulate_batch(self, params, num_worlds, cfg):
        from .model import Model
        from .simulator import Simulator

        model = Model.from_params(params, num_worlds, device=cfg.sim.device)
        sim = Simulator(model, dt=cfg.sim.dt, substeps=cfg.sim.substeps)
        state = sim.initial_state()
        rest = sim.snapshot(state)["positions"]  # per-world rest geometry (a, b, l0 may differ per world)
        sim.settle(state, cfg.sim.settle_time)
        keep = ("positions", "magnet_pos", "magnet_rot", "crease_angle", "bar_strain")
        frames, unstable, steps_done = [], np.zeros(num_worlds, bool), 0
        for t in cfg.sim.frame_times:
            n = int(round(t / cfg.sim.dt)) - steps_done
            if n > 0:
                sim.step(state, n)
                steps_done += n
            snap = sim.snapshot(state)
            unstable |= snap["unstable"] | ~np.isfinite(snap["positions"]).all(axis=(1, 2))
            frames.append({**{k: snap[k] for k in keep}, "rest_positions": rest})
        return SimResult(frames=frames, unstable=unstable)

    def _renderer(self, cfg):
        from .render import Renderer

        key = (cfg.render.width, cfg.render.height, cfg.sim.device)
        r = self._renderers.get(key)
        if r is None:
            r = self._renderers[key] = Renderer(cfg.render.width, cfg.render.height, device=cfg.sim.device)
        return r

    def render_batch(self, frame, params, cameras, appearance, seeds, cfg):
        from . import render

        B = len(seeds)
        pattern = self._pattern(cfg.sim.n_units)
        scene = render.build_scene(
            frame["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=frame["magnet_pos"],
            magnet_rot=frame["magnet_rot"], worm_texcoords=pattern.vertices, ipm_diameter=params.ipm_diameter,
            ipm_thickness=params.ipm_thickness, epm_size=params.epm_size, floor_incline=params.floor_incline,
            appearance=appearance_from_draws(appearance, seeds))
        from .render.sensor import apply_sensor

        cams = dataclasses.replace(cameras, world=np.arange(B, dtype=np.int32))
        img = self._renderer(cfg).render(scene, cams)
        rgb = apply_sensor(img["rgb"], seeds, values=sensor_values(appearance))
        labels = compute_labels(pattern, frame, params, cams, img)
        return {"rgb": rgb, "depth": img["depth"], "segmentation": img["seg"], **labels}


def appearance_draws(cfg: DatasetConfig, traj: np.ndarray) -> dict[str, np.ndarray]:
    """The ``light / color / texture / sensor`` draws of trajectories ``traj`` (B,), each (B,), plus
    ``texture.seed``: the procedural textures' offset, keyed by the trajectory so that the floor grain and paper fibre
    stay put across a trajectory's frames (a per-sample seed would make them crawl between frames of one camera)."""
    app = {}
    for g in ("light", "color", "texture", "sensor"):
        app.update(draw_group(cfg, g, traj).values)
    app["texture.seed"] = rnd.derived_seed(rnd.sample_keys(cfg.seed, traj), "texture") % (2**31 - 1)
    return app


def appearance_from_draws(app: dict, seeds: np.ndarray):
    """The renderer's :class:`~warpworm.render.Appearance` from the drawn ``light/color/texture`` values (B,) each."""
    from .render import default_appearance, hsv_to_rgb

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
    tex_seed = app.get("texture.seed")  # per trajectory (appearance_draws); a bare per-sample seed otherwise
    a.tex_seed = ((seeds if tex_seed is None else np.asarray(tex_seed)) % (2**31 - 1)).astype(np.int32)
    el, az = app["light.elevation"], app["light.azimuth"]
    a.sun_dir = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=1)
    a.sun_color = app["light.intensity"][:, None] * np.ones(3)
    a.ambient = app["light.ambient"][:, None] * np.ones(3)
    bg = app["color.background_value"][:, None] * np.ones(3)
    a.bg_top, a.bg_bottom = bg, 0.6 * bg
    return a


def sensor_values(app: dict) -> dict:
    """The dataset's drawn ``sensor.*`` values (B,) -> :func:`warpworm.render.sensor.apply_sensor` ``values``.

    Brightness and noise are configured in 8-bit levels (the renderer takes fractions of full scale); JPEG quality 100
    means no round trip (the renderer's 0). White balance, hue, saturation and shot noise are not dataset parameters:
    neutral (the renderer then skips the colour conversions).
    """
    q = np.asarray(app["sensor.jpeg_quality"]).astype(np.int64)
    B = len(q)
    f32 = np.float32  # float32 values keep the per-image arithmetic in float32 (measured ~25 % faster than float64)
    return {"wb_r": np.ones(B), "wb_g": np.ones(B), "wb_b": np.ones(B), "hue_deg": np.zeros(B),
            "saturation": np.ones(B), "contrast": np.asarray(app["sensor.contrast"], f32),
            "brightness": (np.asarray(app["sensor.brightness"], np.float64) / 255.0).astype(f32),
            "blur_sigma": np.asarray(app["sensor.blur_sigma"], np.float64),
            "noise_sigma": np.asarray(app["sensor.noise_std"], np.float64) / 255.0, "shot_noise": np.zeros(B),
            "jpeg_quality": np.where(q >= 100, 0, q)}


def compute_labels(pattern, frame: dict, params: WormParams, cameras, images: dict) -> dict:
    """Schema label arrays of B images from :func:`warpworm.render.labels.compute_labels` (its body frame, keypoints
    and COCO visibility rules; see docs/render.md), reshaped to the dataset's names: poses as 4x4 object -> world,
    boxes as (x, y, w, h) [px]."""
    from . import transforms as tf
    from .render import labels as rl

    lab = rl.compute_labels(frame, pattern, cameras, images, rest_positions=frame.get("rest_positions"),
                            ipm_diameter=params.ipm_diameter, ipm_thickness=params.ipm_thickness)
    body = tf.pose_matrix(lab["body_R_world"], lab["body_t_world"])
    mags = tf.pose_matrix(lab["magnet_R_world"], lab["magnet_t_world"])
    wb = lab["worm_box"]
    vb = lab["worm_box_visible"].astype(np.float32)
    bbv = np.where(vb[:, :1] >= 0, np.concatenate([vb[:, :2], vb[:, 2:] - vb[:, :2] + 1], axis=1), 0)
    return {
        "poses/body": body, "poses/ipm": mags[:, 1:4], "poses/epm": mags[:, 0],
        "poses/body_quat": lab["body_q_world"],
        "keypoints/world": lab["keypoints_world"], "keypoints/camera": lab["keypoints_cam"],
        "keypoints/pixel": lab["keypoints_2d"], "keypoints/visibility": lab["keypoint_visibility"],
        "creases/angle": np.asarray(frame["crease_angle"], np.float32),
        "bars/strain": np.asarray(frame["bar_strain"], np.float32),
        "worm/vertices": np.asarray(frame["positions"], np.float32),
        "labels/bbox_obj": np.concatenate([wb[:, :2], wb[:, 2:] - wb[:, :2]], axis=1).astype(np.float32),
        "labels/bbox_visib": bbv.astype(np.float32),
        "labels/visib_fract": lab["visible_fraction"].astype(np.float32),
        "labels/worm_mask": images["worm_mask"].astype(np.uint8),
        "labels/deformation": lab["deformation_ratio"].astype(np.float32),
    }


# ---------------------------------------------------------------------------------------------------------------------
# Parameters
_WORM_VECTOR = {"epm_size": ("epm_size_x", "epm_size_y", "epm_size_z"),
                "ipm_moment": ("ipm_moment_tail", "ipm_moment_centre", "ipm_moment_head")}
_WORM_SHARED = {"gait", "backward", "magnet_model"}


def draw_worm(cfg: DatasetConfig, traj: np.ndarray, attempt: np.ndarray) -> rnd.Draws:
    """Draw the ``worm.*`` parameters of trajectories ``traj`` (n,) at ``attempt`` (n,)."""
    dists = {f"worm.{k}": v for k, v in cfg.randomize["worm"].items()}
    d = rnd.draw(dists, cfg.seed, traj, attempt)
    # NaN = "the gait preset's value" (warpworm.gaits.GAIT_PRESETS), resolved per sample's gait
    from .gaits import GAIT_PRESETS

    gait = np.asarray(d["worm.gait"]).astype(str)
    for g, preset in GAIT_PRESETS.items():
        sel = gait == g
        if not sel.any():
            continue
        for key, value in preset.items():
            arr = d.values.get(f"worm.{key}")
            if arr is not None and arr.dtype.kind == "f":
                arr[sel & np.isnan(arr)] = value
    from .gaits import gait_theta

    theta, back = d["worm.orientation"], np.asarray(d["worm.backward"]).astype(bool)
    for g in np.unique(gait):
        for bw in (False, True):
            sel = (gait == g) & (back == bw) & np.isnan(theta)
            theta[sel] = gait_theta(str(g), bw)
    # kinetic friction can't exceed static: clip per sample (and record the clipped value).
    d.values["worm.mu_kinetic"] = np.minimum(d["worm.mu_kinetic"], d["worm.mu_static"])
    return d


def worm_params(cfg: DatasetConfig, draws: rnd.Draws, sel: np.ndarray | slice = slice(None)) -> WormParams:
    """WormParams for the selected worlds of ``draws`` (the batch-shared fields must be equal over ``sel``)."""
    p = WormParams(n_units=cfg.sim.n_units)
    for name, arr in draws.values.items():
        group, key = name.split(".", 1)
        if group != "worm":
            continue
        a = arr[sel]
        if key in _WORM_SHARED:
            setattr(p, key, bool(a[0]) if key == "backward" else str(a[0]))
        elif not any(key in comps for comps in _WORM_VECTOR.values()):
            setattr(p, key, np.asarray(a, dtype=np.float64))
    for vec, comps in _WORM_VECTOR.items():
        setattr(p, vec, np.stack([np.asarray(draws[f"worm.{c}"][sel], dtype=np.float64) for c in comps], axis=1))
    return p


def draw_group(cfg: DatasetConfig, group: str, index: np.ndarray) -> rnd.Draws:
    return rnd.draw({f"{group}.{k}": v for k, v in cfg.randomize[group].items()}, cfg.seed, index)


# ---------------------------------------------------------------------------------------------------------------------
# Cameras
def _range(dist: rnd.Distribution) -> tuple[float, float]:
    """(lo, hi) of a camera range (config validation allows only constants and uniforms)."""
    if isinstance(dist, rnd.Uniform):
        return (float(dist.low), float(dist.high))
    return (float(dist.value), float(dist.value))


def dataset_cameras(cfg: DatasetConfig, index: np.ndarray, worm_points: np.ndarray):
    """Cameras of ``index`` (n,) trajectory or sample ids (whatever the camera is keyed by) from the ``camera.*``
    ranges, with :func:`warpworm.render.sample_cameras`: on a shell around the mean of ``worm_points`` (n, P, 3) (the
    worm's vertices over every frame the camera shows), redrawn until at least ``camera.min_in_frame`` of those
    points project inside the image (up to ``camera.max_tries``; then the best view is kept). Square pixels, principal
    point at the image centre, ``fov_y`` vertical.

    Each camera draws from its own seed, derived from (master seed, index), so it is the same in any batch, shard or
    worker. Returns (cameras, ``camera.*`` values (n,) each as stored in ``params/``: the kept view's distance,
    elevation, azimuth, roll, fov_y [rad], look-at offset length [m], its in-frame fraction, max_tries).
    """
    from .render import sample_cameras

    c = cfg.randomize["camera"]
    index = np.asarray(index, dtype=np.int64)
    seeds = rnd.derived_seed(rnd.sample_keys(cfg.seed, index), "camera")
    pts = np.asarray(worm_points, dtype=np.float64)
    target = pts.mean(axis=1)
    deg = lambda name: tuple(np.rad2deg(_range(c[name])))  # noqa: E731
    cams = sample_cameras(
        seeds, pts, width=cfg.render.width, height=cfg.render.height, world_index=np.arange(len(index)),
        target=target, distance=_range(c["distance"]), elevation_deg=deg("elevation"), azimuth_deg=deg("azimuth"),
        roll_deg=deg("roll"), fov_deg=deg("fov_y"), fov_axis="y", lookat_jitter=_range(c["lookat_jitter"])[0],
        aspect_jitter=0.0, principal_jitter=0.0, min_in_frame=_range(c["min_in_frame"])[0],
        max_tries=int(_range(c["max_tries"])[0]))
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
@dataclass
class ShardStats:
    """What one shard cost and produced."""

    index: int
    count: int
    trajectories: int = 0
    replaced: int = 0
    sim_s: float = 0.0
    render_s: float = 0.0
    write_s: float = 0.0
    total_s: float = 0.0
    cameras_below_min: int = 0
    """Cameras whose best view in ``camera.max_tries`` draws kept less than ``camera.min_in_frame`` of the worm."""
    file: str = ""
    bytes: int = 0
    sha256: str = ""


def _take(d: dict, sel) -> dict:
    return {k: v[sel] for k, v in d.items()}


def _simulate_with_replacement(stages, cfg: DatasetConfig, traj: np.ndarray, stats: ShardStats):
    """Simulate trajectories ``traj`` (B,); unstable worlds are redrawn with attempt + 1 until stable.

    Returns (frames: list of dicts (B, ...), draws of the accepted attempt, attempt (B,)).
    """
    B = len(traj)
    attempt = np.zeros(B, dtype=np.int64)
    frames: list[dict] | None = None
    draws_out: dict[str, np.ndarray] = {}
    todo = np.arange(B)
    while todo.size:
        if attempt[todo[0]] >= cfg.sim.max_attempts:
            bad = traj[todo]
            raise RuntimeError(f"trajectories {bad[:8].tolist()} were unstable in all {cfg.sim.max_attempts} attempts; "
                               "narrow the randomization ranges, lower sim.dt or raise sim.substeps")
        d = draw_worm(cfg, traj[todo], attempt[todo])
        # split by the batch-shared fields (gait, direction, magnet model): one solver batch per combination
        keys = np.stack([np.asarray(d[n], dtype=str) for n in BATCH_SHARED], axis=1)
        _, group_of = np.unique(keys, axis=0, return_inverse=True)
        group_of = group_of.reshape(-1)
        unstable = np.zeros(todo.size, dtype=bool)
        for g in np.unique(group_of):
            sel = np.flatnonzero(group_of == g)
            params = worm_params(cfg, d, sel)
            t0 = time.perf_counter()
            res = stages.simulate_batch(params, len(sel), cfg)
            stats.sim_s += time.perf_counter() - t0
            unstable[sel] = np.asarray(res.unstable, dtype=bool)
            if frames is None:
                frames = [{k: np.zeros((B,) + np.asarray(v).shape[1:], np.asarray(v).dtype) for k, v in f.items()}
                          for f in res.frames]
            ok = sel[~unstable[sel]]
            for fi, f in enumerate(res.frames):
                for k, v in f.items():
                    frames[fi][k][todo[ok]] = np.asarray(v)[~unstable[sel]]
        accepted = todo[~unstable]
        for k, v in d.values.items():
            if k not in draws_out:
                draws_out[k] = np.empty(B, dtype=v.dtype)
            draws_out[k][accepted] = v[~unstable]
        stats.replaced += int(unstable.sum())
        todo = todo[unstable]
        attempt[todo] += 1
    return frames, rnd.Draws(draws_out), attempt


def root_attributes(cfg: DatasetConfig, meta: dict) -> dict:
    """Root attributes every shard carries (and the manifest repeats)."""
    import warpworm

    return {
        "format": "warpworm-dataset",
        "schema_version": ds.SCHEMA_VERSION,
        "warpworm_version": warpworm.__version__,
        "warp_version": _warp_version(),
        "config_yaml": cfg.to_yaml(),
        "seed_master": cfg.seed,
        "num_samples": cfg.num_samples,
        "shard_size": cfg.shard_size,
        "frame_times": np.asarray(cfg.sim.frame_times, dtype=np.float64),
        "units": json.dumps(ds.UNITS),
        "quaternion_order": ds.QUATERNION_ORDER,
        "segmentation_ids": json.dumps(ds.SEGMENTATION_IDS),
        "keypoint_names": json.dumps(list(meta["keypoint_names"])),
        "crease_order": "creases/angle[c] is hinge c of the crease pattern: stencil crease_hinges[c] = (i, j, k, l), "
                        "shared edge j-k; crease_labels[c]: 0 flat, 1 mountain, 2 valley",
        "crease_hinges": np.asarray(meta["hinges"], dtype=np.int32),
        "crease_labels": np.asarray(meta["hinge_label"], dtype=np.int8),
        "bar_edges": np.asarray(meta["edges"], dtype=np.int32),
        "mesh_triangles": np.asarray(meta["triangles"], dtype=np.int32),
        "mesh_triangle_segment": np.asarray(meta["triangle_segment"], dtype=np.int32),
        "params_names": json.dumps(sorted(cfg.flat_distributions())),
    }


@functools.lru_cache(maxsize=None)
def _warp_version() -> str:
    try:
        import warp

        return str(warp.__version__)
    except Exception:  # noqa: BLE001 - the fake stages in tests do not need Warp
        return "unavailable"


def run_shard(cfg: DatasetConfig, out_dir, k: int, stages, progress=None) -> ShardStats:
    """Produce and commit shard ``k``; the written content depends only on (cfg, k)."""
    t_start = time.perf_counter()
    stages = load_stages(stages)
    start, stop = cfg.shard_range(k)
    F = cfg.frames_per_trajectory
    stats = ShardStats(index=k, count=stop - start)
    meta = stages.metadata(cfg)
    writer = ds.ShardWriter(out_dir, k, start, stop - start, root_attributes(cfg, meta),
                            cfg.output.compression, cfg.output.compression_level)
    # Compression and HDF5 writes run on one background thread while the next batch simulates and renders (Warp's
    # CPU kernels run without the GIL). At most one write is in flight, so memory stays bounded by one batch.
    io = ThreadPoolExecutor(max_workers=1, thread_name_prefix=f"shard{k}-writer")
    pending = None

    def wait_write():
        nonlocal pending
        if pending is not None:
            t0 = time.perf_counter()
            pending.result()  # re-raises a write error (disk full, ...) here, in the shard's thread
            stats.write_s += time.perf_counter() - t0
            pending = None

    try:
        t_first, t_last = start // F, -(-stop // F)
        W = cfg.sim.worlds
        for c0 in range(t_first, t_last, W):
            traj = np.arange(c0, min(c0 + W, t_last), dtype=np.int64)
            frames, wdraws, attempt = _simulate_with_replacement(stages, cfg, traj, stats)
            stats.trajectories += len(traj)
            B = len(traj)
            appearance = appearance_draws(cfg, traj)
            if not cfg.render.camera_per_frame:
                # one camera per trajectory, keyed by the trajectory: the worm (all its frames) in view
                pts = np.concatenate([f["positions"] for f in frames], axis=1)
                cams_traj, cam_traj = dataset_cameras(cfg, traj, pts)
                stats.cameras_below_min += int((~cams_traj.accepted).sum())
            # Samples in row order (trajectory-major, frame-minor), so that every write is a contiguous row range:
            # strided HDF5 writes into chunked, compressed datasets measured ~25x slower than contiguous ones.
            stacked = _stack_frames(frames)
            sid_all = (traj[:, None] * F + np.arange(F)[None]).reshape(-1)
            tsel_all = np.repeat(np.arange(B), F)  # trajectory (position in this batch) of each sample
            fidx_all = np.tile(np.arange(F), B)
            n_keep = int(np.sum(sid_all < stop))
            step = max(F, (cfg.render.batch // F) * F)  # images per render call: whole trajectories
            for r0 in range(0, n_keep, step):
                sl = slice(r0, min(r0 + step, n_keep))
                sid, tsel, fidx = sid_all[sl], tsel_all[sl], fidx_all[sl]
                # the snapshot of each sample's (trajectory, frame), stacked: (n, ...) "worlds" of the renderer
                fr = _gather_frames(stacked, tsel, fidx)
                skeys = rnd.sample_keys(cfg.seed, sid)
                if cfg.render.camera_per_frame:  # a camera per sample, keyed by the sample id
                    cams, cam_draws = dataset_cameras(cfg, sid, fr["positions"])
                    stats.cameras_below_min += int((~cams.accepted).sum())
                else:
                    cam_draws = _take(cam_traj, tsel)
                    cams = cams_traj.take(tsel)
                cams.world = np.arange(len(sid), dtype=np.int32)
                seeds = rnd.derived_seed(skeys)
                params = worm_params(cfg, wdraws, tsel)
                app = _take(appearance, tsel)
                t0 = time.perf_counter()
                out = stages.render_batch(fr, params, cams, app, seeds, cfg)
                out["keypoints/body"] = keypoints_in_body(out["poses/body"], out["keypoints/world"])
                stats.render_s += time.perf_counter() - t0
                t0 = time.perf_counter()
                rows = {
                    **out,
                    "camera/K": cams.K, "camera/R": cams.R, "camera/t": cams.t,
                    "camera/position": cams.position, "camera/in_frame": cams.in_frame.astype(np.float32),
                    "time": np.asarray(cfg.sim.frame_times, dtype=np.float32)[fidx],
                    "trajectory": traj[tsel], "frame": fidx.astype(np.int32),
                    "attempt": attempt[tsel].astype(np.int32), "sample_id": sid, "seed": seeds,
                }
                for name, v in {**_take(wdraws.values, tsel), **app, **cam_draws}.items():
                    rows[f"params/{name}"] = v
                stats.write_s += time.perf_counter() - t0
                wait_write()
                pending = io.submit(writer.write, int(sid[0] - start), rows)
            if progress is not None:
                progress(int(np.minimum(traj * F + F, stop).sum() - np.minimum(traj * F, stop).sum()))
        wait_write()
        t0 = time.perf_counter()
        final = writer.commit()
        stats.write_s += time.perf_counter() - t0
    except BaseException:
        if pending is not None:
            pending.cancel()
            try:
                pending.result()
            except BaseException:  # the original error is the one to report
                pass
        writer.abort()
        raise
    finally:
        io.shutdown(wait=True)
    stats.file = final.name
    stats.bytes = final.stat().st_size
    stats.sha256 = writer.sha256
    stats.total_s = time.perf_counter() - t_start
    return stats


def keypoints_in_body(body: np.ndarray, kp_world: np.ndarray) -> np.ndarray:
    """``keypoints/body`` (n, P, 3) [m]: world keypoints in the body frame, R_b^T (x - t_b) for body -> world poses
    (n, 4, 4)."""
    body = np.asarray(body, np.float64)
    return np.einsum("nji,npj->npi", body[:, :3, :3], np.asarray(kp_world, np.float64) - body[:, None, :3, 3])


def _stack_frames(frames: list[dict]) -> dict:
    """F snapshots of B worlds -> dict of (B, F, ...) arrays (once per simulated batch)."""
    return {k: np.stack([f[k] for f in frames], axis=1) for k in frames[0]}


def _gather_frames(stacked: dict, tsel: np.ndarray, fidx: np.ndarray) -> dict:
    """Snapshot arrays of samples (trajectory tsel[i], frame fidx[i]) -> dict of (n, ...) arrays."""
    return {k: v[tsel, fidx] for k, v in stacked.items()}


# ---------------------------------------------------------------------------------------------------------------------
@dataclass
class Summary:
    """End-of-job summary (also stored in manifest.json)."""

    out: str
    num_samples: int
    shards_total: int
    shards_done_before: int
    shards_written: int
    replaced_worlds: int
    wall_s: float
    sim_s: float
    render_s: float
    write_s: float
    workers: int
    engine: str
    new_samples: int = 0
    cameras_below_min: int = 0

    @property
    def samples_per_s(self) -> float:
        """Samples written by this run per wall-clock second (whole job, previews excluded)."""
        return self.new_samples / self.wall_s if self.wall_s > 0 else float("nan")

    def text(self) -> str:
        return (f"wrote {self.shards_written} shard(s) ({self.new_samples} samples; {self.shards_done_before} shard(s) "
                f"were already complete) to {self.out} in {self.wall_s:.1f} s = {self.samples_per_s:.1f} samples/s "
                f"with {self.workers} worker(s) [{self.engine}]; unstable worlds dropped and replaced: "
                f"{self.replaced_worlds}; cameras below camera.min_in_frame after max_tries: {self.cameras_below_min}; "
                f"stage time (all workers): sim {self.sim_s:.1f} s, render {self.render_s:.1f} s, "
                f"write {self.write_s:.1f} s")


@functools.lru_cache(maxsize=None)
def _versions() -> dict:
    import h5py

    import warpworm

    return {"warpworm": warpworm.__version__, "warp": _warp_version(), "numpy": np.__version__,
            "h5py": h5py.__version__, "python": sys.version.split()[0]}


def _manifest(cfg: DatasetConfig, done: dict[int, ShardStats | dict], complete: bool, summary=None,
              shard_size_requested: int | None = None) -> dict:
    shards = []
    for k in sorted(done):
        s = done[k]
        s = dataclasses.asdict(s) if isinstance(s, ShardStats) else s
        a, b = cfg.shard_range(k)
        shards.append({"index": k, "file": ds.shard_name(k), "first_sample": a, "count": b - a,
                       "bytes": s.get("bytes", 0), "sha256": s.get("sha256", ""), "replaced": s.get("replaced", 0)})
    return {
        "format": "warpworm-dataset", "schema_version": ds.SCHEMA_VERSION, "complete": complete,
        "num_samples": cfg.num_samples, "shard_size": cfg.shard_size, "num_shards": cfg.num_shards,
        "shard_size_requested": cfg.shard_size if shard_size_requested is None else shard_size_requested,
        "samples_written": int(sum(s["count"] for s in shards)), "shards": shards,
        "config": cfg.to_dict(), "versions": _versions(), "quaternion_order": ds.QUATERNION_ORDER,
        "units": ds.UNITS, "segmentation_ids": ds.SEGMENTATION_IDS,
        "summary": dataclasses.asdict(summary) if summary is not None else None,
    }


def _config_diff(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _config_diff(a.get(k), b.get(k), f"{path}.{k}" if path else str(k))
        return out
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return []
    return [] if a == b else [f"{path}: dataset has {a!r}, this run asks for {b!r}"]


class Interrupted(Exception):
    """The job got SIGTERM or SIGINT and stopped cleanly: finished shards committed and in the manifest, the shard in
    flight discarded (its temporary deleted), workers stopped. ``--resume`` continues. Exit code 128 + signal."""

    def __init__(self, signum: int):
        import signal as _signal

        self.signum = int(signum)
        super().__init__(f"interrupted by {_signal.Signals(self.signum).name}")


class _SignalGuard:
    """While active (main thread only): SIGTERM / SIGINT raise :class:`Interrupted`, except inside :meth:`critical`
    sections (a manifest update), where the signal is held until the section ends."""

    def __init__(self):
        self._old = {}
        self._depth = 0
        self._held: int | None = None

    def _handler(self, signum, frame):
        if self._depth:
            self._held = signum
            return
        raise Interrupted(signum)

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc):
        import signal

        for sig, h in self._old.items():
            signal.signal(sig, h)
        self._old = {}

    def critical(self):
        guard = self

        class _C:
            def __enter__(self):
                guard._depth += 1

            def __exit__(self, *exc):
                guard._depth -= 1
                if not guard._depth and guard._held is not None and exc[0] is None:
                    sig, guard._held = guard._held, None
                    raise Interrupted(sig)

        return _C()


def shard_plan(cfg: DatasetConfig, workers: int) -> tuple[DatasetConfig, str | None]:
    """The shard size a job with ``workers`` processes runs: the config's, unless its samples fit in fewer shards than
    there are workers; then shards of ceil(trajectories / workers) whole trajectories, so every worker has one.
    Samples do not depend on the sharding (module docstring), so this changes files, never data. Returns the config
    to run and a one-line note (None when nothing changed and no worker idles)."""
    if workers <= 1 or cfg.num_shards >= workers:
        return cfg, None
    F = cfg.frames_per_trajectory
    n_traj = -(-cfg.num_samples // F)
    per = -(-n_traj // workers) * F
    note = None
    new = cfg
    if per < cfg.shard_size:
        new = dataclasses.replace(cfg, shard_size=per)
        note = (f"shard_size {cfg.shard_size} -> {per}: {cfg.num_samples} samples fit in {cfg.num_shards} shard(s), "
                f"fewer than --workers {workers}; {new.num_shards} shards of whole trajectories give every worker "
                "work (the samples are the same whatever the sharding)")
    if new.num_shards < workers:
        why = (f"only {n_traj} trajectory(ies) of {F} frames, and a shard holds whole trajectories"
               if per == F or new is not cfg else f"{new.num_shards} shard(s)")
        note = (note + "; " if note else "") + (f"{workers - new.num_shards} of {workers} workers will be idle: "
                                                f"{why}")
    return new, note


def _json_rt(d):
    return json.loads(json.dumps(d, default=str))


def plan(cfg: DatasetConfig, out_dir, resume: bool, requested_shard_size: int | None = None,
         log=None) -> tuple[list[int], dict[int, dict]]:
    """Which shards to write (see :func:`plan_job`, which also returns the config the job must run)."""
    _, todo, done = plan_job(cfg, out_dir, resume, requested_shard_size, log)
    return todo, done


def plan_job(cfg: DatasetConfig, out_dir, resume: bool, requested_shard_size: int | None = None,
             log=None) -> tuple[DatasetConfig, list[int], dict[int, dict]]:
    """(config to run, shards to write, shards already done {k: {bytes, sha256}}).

    On resume: the config must equal the dataset's (its sharding, chosen for the first run's workers, is kept);
    temporaries are deleted; every shard on disk is checked (opens, marked complete, sample ids, and the manifest's
    SHA-256) and a damaged one (truncated, bit-flipped) is deleted and redone with a note. A missing or unreadable
    manifest is rebuilt from the shards, whose ``config_yaml`` must then match this run's config.
    """
    out = Path(out_dir)
    log = log or (lambda m: print(m, file=sys.stderr))
    requested = cfg.shard_size if requested_shard_size is None else requested_shard_size
    done: dict[int, dict] = {}
    if not resume:
        return cfg, list(range(cfg.num_shards)), done
    mpath = out / ds.MANIFEST
    old = None
    if mpath.exists():
        try:
            old = ds.read_manifest(out)
        except ds.DatasetError as exc:
            log(f"note: {str(exc).split(';')[0]}; rebuilding it from the shards")
    elif any(ds.SHARD_RE.match(n) for n in os.listdir(out)):
        log(f"note: {mpath} is missing; rebuilding it from the shards")
    known_sha: dict[int, str] = {}
    if old is not None:
        old_cfg = _json_rt(old.get("config", {}))
        if (old_cfg.get("shard_size") != cfg.shard_size
                and old.get("shard_size_requested", old_cfg.get("shard_size")) == requested):
            cfg = dataclasses.replace(cfg, shard_size=int(old_cfg["shard_size"]))
        diff = _config_diff(old_cfg, _json_rt(cfg.to_dict()))
        if diff:
            raise ConfigError(["--resume: the config differs from the dataset's (same config, --num and --seed "
                               "are needed to resume):"] + diff[:20])
        for sh in old["shards"]:
            if isinstance(sh, dict) and sh.get("sha256"):
                known_sha[int(sh["index"])] = str(sh["sha256"])
    else:
        cfg = _config_from_shards(cfg, out, requested)
    ds.clean_temporaries(out)
    for k in range(cfg.num_shards):
        p = out / ds.shard_name(k)
        if not p.exists():
            continue
        a, b = cfg.shard_range(k)
        problem = ds.shard_problem(p, a, b - a, sha256=known_sha.get(k))
        if problem is None and k not in known_sha:
            problem = _shard_config_problem(p, cfg)
        if problem is None:
            done[k] = {"bytes": p.stat().st_size, "sha256": known_sha.get(k) or ds.file_sha256(p)}
        else:
            log(f"note: {p}: {problem}; deleting it and writing it again")
            p.unlink()
    todo = [k for k in range(cfg.num_shards) if k not in done]
    return cfg, todo, done


def _shard_config_problem(path, cfg: DatasetConfig) -> str | None:
    import h5py

    try:
        with h5py.File(path, "r") as f:
            text = f.attrs.get("config_yaml", "")
    except OSError as exc:
        return f"unreadable ({exc})"
    text = text.decode() if isinstance(text, bytes) else str(text)
    return None if text == cfg.to_yaml() else "written with another config (root attribute config_yaml differs)"


def _config_from_shards(cfg: DatasetConfig, out: Path, requested: int) -> DatasetConfig:
    """Without a manifest: the sharding of the shards on disk (kept if smaller than ``requested``: split for the first
    run's workers), refused with the differing keys if their config is not this run's otherwise."""
    import h5py
    import yaml

    from .config import load_config

    for name in sorted(os.listdir(out)):
        if not ds.SHARD_RE.match(name):
            continue
        try:
            with h5py.File(out / name, "r") as f:
                text = f.attrs["config_yaml"]
        except (OSError, KeyError):
            continue  # damaged: plan_job reports and redoes it
        text = text.decode() if isinstance(text, bytes) else str(text)
        old = load_config(yaml.safe_load(text))
        if old.shard_size < cfg.shard_size and cfg.shard_size == requested:  # split for the first run's workers
            cfg = dataclasses.replace(cfg, shard_size=old.shard_size)
        diff = _config_diff(_json_rt(old.to_dict()), _json_rt(cfg.to_dict()))
        if diff:
            raise ConfigError([f"--resume: the config differs from the one {out / name} was written with:"] + diff[:20])
        return cfg
    return cfg


def device_line(cfg: DatasetConfig) -> str:
    """One line naming the device the job runs on (instead of Warp's CUDA driver warning on CPU-only machines)."""
    import warpworm

    dev = cfg.sim.device
    if dev.startswith("cuda"):
        try:
            import warp as wp

            return f"device: {dev} ({wp.get_device(dev).name})"
        except Exception:  # noqa: BLE001
            return f"device: {dev}"
    if warpworm.cuda_driver_missing:
        return f"device: {dev} (no CUDA driver on this machine: CPU only)"
    return f"device: {dev}"


def generate(cfg: DatasetConfig, out_dir, *, workers: int = 1, resume: bool = False, stages: str = DEFAULT_STAGES,
             engine: str = "local", address: str | None = None, progress: bool = True,
             preview: bool | None = None, log=None) -> Summary:
    """Run a dataset job; returns its :class:`Summary`. See module docstring for what determines each sample.

    Raises :class:`ConfigError` (bad input, before any work), :class:`warpworm.dataset.DatasetLockedError` (another
    job holds the folder), :class:`warpworm.dataset.DatasetWriteError` (disk full, read-only: completed shards intact),
    :class:`Interrupted` (SIGTERM / SIGINT: stopped cleanly), ``WorkerError`` (a worker died).
    """
    t0 = time.perf_counter()
    log = log or (lambda m: print(m, file=sys.stderr))
    holder = ds.lock_holder(out_dir) if Path(out_dir).is_dir() else None
    if holder is not None:
        raise ds.DatasetLockedError(f"{out_dir} is in use by another job: {ds.FolderLock.describe(holder)}; wait for it "
                                    "to finish or stop it (kill -TERM <pid>), then rerun with --resume")
    check_output_dir(out_dir, resume)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lock = ds.FolderLock(out).acquire()
    try:
        if lock.stale:
            log(f"note: {lock.path}: stale lock of a job that is gone ({ds.FolderLock.describe(lock.stale)}); "
                "taking it over")
        with _SignalGuard() as guard:
            return _generate_locked(cfg, out, t0, guard, log, workers=workers, resume=resume, stages=stages,
                                    engine=engine, address=address, progress=progress, preview=preview)
    finally:
        lock.release()


def _generate_locked(cfg, out, t0, guard, log, *, workers, resume, stages, engine, address, progress, preview):
    requested = cfg.shard_size
    run_cfg, note = shard_plan(cfg, workers if engine == "local" else 1)
    cfg, todo, done = plan_job(run_cfg, out, resume, requested_shard_size=requested, log=log)
    if note and (not resume or cfg.shard_size == run_cfg.shard_size):
        log(f"note: {note}")
    log(device_line(cfg))
    done_before = len(done)

    def save(complete, summary=None):
        with guard.critical():
            ds.atomic_write_json(out / ds.MANIFEST, _manifest(cfg, done, complete=complete, summary=summary,
                                                              shard_size_requested=requested))

    save(complete=not todo)

    from tqdm import tqdm

    total_new = sum(cfg.shard_range(k)[1] - cfg.shard_range(k)[0] for k in todo)
    bar = tqdm(total=total_new, unit="sample", disable=not progress, dynamic_ncols=True, smoothing=0.1,
               desc=f"generate {cfg.name}", file=sys.stderr)
    written: dict[int, ShardStats] = {}

    def on_shard(st: ShardStats):
        with guard.critical():
            written[st.index] = st
            done[st.index] = dataclasses.asdict(st)
            ds.atomic_write_json(out / ds.MANIFEST, _manifest(cfg, done, complete=False,
                                                              shard_size_requested=requested))

    from . import workers as wk

    try:
        wk.run_shards(cfg, out, todo, stages, workers=workers, engine=engine, address=address,
                      on_progress=bar.update, on_shard=on_shard)
    except Interrupted:
        # a shard committed to disk between its rename and the manifest update is complete but unrecorded: discard
        # it like the shard in flight (--resume writes the same bytes again), so the manifest lists exactly the
        # shards on disk
        for k in todo:
            if k not in done:
                (out / ds.shard_name(k)).unlink(missing_ok=True)
        # and no temporary stays visible: the workers are stopped and the folder lock is ours, so any left (the shard
        # in flight of a worker stopped mid-write, or a SIGKILLed run's that the signal beat the clean-up to) is dead
        ds.clean_temporaries(out, ".shard-*.tmp-*")
        raise
    finally:
        bar.close()
    wall = time.perf_counter() - t0
    summary = Summary(out=str(out), num_samples=cfg.num_samples, shards_total=cfg.num_shards,
                      shards_done_before=done_before, shards_written=len(written),
                      replaced_worlds=sum(s.replaced for s in written.values()), wall_s=wall,
                      sim_s=sum(s.sim_s for s in written.values()), render_s=sum(s.render_s for s in written.values()),
                      write_s=sum(s.write_s for s in written.values()), workers=workers, engine=engine,
                      new_samples=sum(s.count for s in written.values()),
                      cameras_below_min=sum(s.cameras_below_min for s in written.values()))
    save(complete=True, summary=summary)
    if cfg.output.preview if preview is None else preview:
        try:
            write_previews(cfg, out, stages)
        except Exception as exc:  # noqa: BLE001 - a preview must never fail a finished dataset
            print(f"warning: preview not written: {exc}", file=sys.stderr)
    return summary


# ---------------------------------------------------------------------------------------------------------------------
# Previews
def _sheet_inputs(samples: list[dict]) -> tuple[dict, dict]:
    """Dataset samples -> the (images, labels) that :func:`warpworm.render.contact_sheet.contact_sheet` draws:
    boxes back from (x, y, w, h) to corners, the body pose from ``poses/body``."""
    def st(k):
        return np.stack([s[k] for s in samples])

    box, vb, body = st("labels/bbox_obj"), st("labels/bbox_visib"), st("poses/body")
    visible = vb[:, 2] > 0
    images = {"rgb": st("rgb"), "depth": st("depth"), "seg": st("segmentation")}
    labels = {
        "K": st("camera/K"), "R": st("camera/R"), "t": st("camera/t"),
        "body_R_world": body[:, :3, :3], "body_t_world": body[:, :3, 3],
        "keypoints_2d": st("keypoints/pixel"), "keypoint_visibility": st("keypoints/visibility"),
        "worm_box": np.concatenate([box[:, :2], box[:, :2] + box[:, 2:]], axis=1),
        "worm_box_visible": np.where(visible[:, None], np.concatenate([vb[:, :2], vb[:, :2] + vb[:, 2:] - 1], axis=1),
                                     -1).astype(np.int64),
        "visible_fraction": st("labels/visib_fract"),
    }
    return images, labels


def write_previews(cfg: DatasetConfig, out, stages=DEFAULT_STAGES, max_rows: int = 8) -> list[Path]:
    """``preview.png``: the renderer's contact sheet (:func:`warpworm.render.contact_sheet.contact_sheet`) of the
    first samples; ``preview.mp4``: trajectory 0 resimulated at 20 fps over ``sim.frame_times`` with the same draws,
    seen from sample 0's stored camera (one world, small)."""
    import cv2

    from .render import make_cameras
    from .render.contact_sheet import contact_sheet, save_png

    out = Path(out)
    reader = ds.open(out)
    try:
        n = min(len(reader), max_rows)
        paths = []
        if n == 0:
            return paths
        images, labels = _sheet_inputs([reader[i] for i in range(n)])
        save_png(out / "preview.png", contact_sheet(images, labels, max_rows=n, scale=2))
        paths.append(out / "preview.png")
        cam = {k: reader.read(f"camera/{k}", [0]) for k in ("K", "R", "t")}
    finally:
        reader.close()
    # video: trajectory 0 with a dense frame list (same parameters and camera as in the dataset)
    T = cfg.sim.frame_times[-1]
    nf = max(2, int(T * 20) + 1)
    dense = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, frame_times=list(np.linspace(0, T, nf)),
                                                             worlds=1), shard_size=nf, num_samples=nf)
    stg = load_stages(stages)
    frames, wdraws, _ = _simulate_with_replacement(stg, dense, np.array([0]), ShardStats(0, 0))
    cams = make_cameras(cam["K"], cam["R"], cam["t"], 0, cfg.render.width, cfg.render.height)
    traj = np.array([0])
    app = appearance_draws(cfg, traj)
    vw = cv2.VideoWriter(str(out / "preview.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 20,
                         (cfg.render.width, cfg.render.height))
    for f in frames:
        img = stg.render_batch(f, worm_params(cfg, wdraws), cams, app, np.zeros(1, np.int64), cfg)["rgb"][0]
        vw.write(np.ascontiguousarray(img[..., ::-1]))
    vw.release()
    paths.append(out / "preview.mp4")
    return paths
