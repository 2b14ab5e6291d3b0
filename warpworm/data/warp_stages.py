"""warpworm's own stages (:class:`warpworm.data.stages.Stages`): the simulator (:mod:`warpworm.sim`) and the
rasterizer (:mod:`warpworm.render`) behind the pipeline's interface, with the frame timing of ``sim.frame_unit:
cycle`` and the path-traced sample choice."""

from __future__ import annotations

import dataclasses
import importlib
import os
import pkgutil

import numpy as np
import warp as wp

from warpworm import kernels, quiet_warp, render
from warpworm.data.stages import SimResult
from warpworm.physics import crease
from warpworm.physics.params import WormParams, per_world
from warpworm.render import Renderer
from warpworm.render.labels import KEYPOINT_NAMES, schema_labels
from warpworm.render.motion import motion_blurred_rgb
from warpworm.render.pathtrace import choose_pathtraced, render_pathtraced
from warpworm.render.placement import distractor_mesh
from warpworm.render.sample_kernels import resolve_samples_kernel
from warpworm.render.sensor import SensorBatch, apply_sensor_batch, exposure_gains
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator


class WarpStages:
    """warpworm's own simulator (:mod:`warpworm.sim.simulator`) and rasterizer (:mod:`warpworm.render`).

    Simulation: ``Model.from_params`` -> ``Simulator(dt, substeps)`` -> ``settle(settle_time)`` -> ``step`` to each
    frame time -> ``snapshot``. A world flagged unstable at any frame is reported unstable.
    Rendering: ``render.build_scene`` (worm sheet, IPM disks, EPM bar, floor) with an appearance built from the drawn
    ``light/color/texture`` values (the ``look`` of the draws), ``Renderer.render`` with the drawn ``sensor.*``
    values applied in its pass (:class:`warpworm.render.sensor.SensorBatch`) and labels in the dataset's form
    (:func:`warpworm.render.labels.schema_labels`).
    """

    @staticmethod
    def kernel_modules() -> list[str]:
        """Every module of ``warpworm.kernels`` and ``warpworm.render`` whose name says it holds kernels
        (:meth:`warm` compiles them together). Discovered, not listed, so a new solver module is warmed too."""
        names = []
        for pkg in (kernels, render):
            names += [f"{pkg.__name__}.{m.name}" for m in pkgutil.iter_modules(pkg.__path__)
                      if "kernel" in m.name or pkg is kernels]
        return names

    def __init__(self):
        self._renderers = {}
        self._patterns = {}

    def preload(self):
        """Quiet Warp and import every kernel module (a worker does this when it starts)."""
        quiet_warp()
        for name in self.kernel_modules():
            importlib.import_module(name)

    def warm(self, cfg, max_workers: int | None = None):
        """Load every kernel module of :meth:`kernel_modules` on ``sim.device``, compiling the missing ones into
        Warp's kernel cache in parallel (``max_workers`` threads; default one per available core).

        Run once in the parent before workers start: with a cold cache (a kernel source changed, a fresh install)
        each worker would otherwise compile the same modules itself; with a hot cache it only hashes the modules.
        """
        self.preload()
        if max_workers is None:
            try:
                max_workers = len(os.sched_getaffinity(0))
            except AttributeError:  # pragma: no cover - not Linux
                max_workers = os.cpu_count() or 1
        modules = [m for m in map(wp.get_module, self.kernel_modules()) if m.kernels]  # (functions only: nothing)
        if cfg.render.supersample > 1 or cfg.render.distortion:  # the factory-made sample resolve the images take
            modules.append(resolve_samples_kernel(max(cfg.render.supersample, 1), cfg.render.distortion,
                                                  texture_filter=cfg.render.texture_filter).module)
        wp.force_load(device=cfg.sim.device, modules=modules, max_workers=max_workers)

    def _pattern(self, n_units: int):
        p = self._patterns.get(n_units)
        if p is None:
            w = WormParams()
            p = self._patterns[n_units] = crease.build_worm(w.a, w.b, n_units, l0=w.l0)
        return p

    def metadata(self, cfg):
        p = self._pattern(cfg.sim.n_units)

        return {"keypoint_names": list(KEYPOINT_NAMES), "triangles": p.triangles,
                "triangle_segment": p.triangle_segment, "hinges": p.hinges, "hinge_label": p.hinge_label,
                "edges": p.edges, "num_vertices": p.num_vertices}

    def simulate_batch(self, params, num_worlds, cfg):
        model = Model.from_params(params, num_worlds, device=cfg.sim.device)
        sim = Simulator(model, dt=cfg.sim.dt, substeps=cfg.sim.substeps)
        state = sim.initial_state()
        rest = model.rest_positions_host.astype(np.float32)  # per-world rest geometry (a, b, l0 may differ)
        sim.settle(state, cfg.sim.settle_time)
        keep = ("positions", "magnet_pos", "magnet_rot", "crease_angle", "bar_strain", "unstable")
        if cfg.render.motion_blur > 0:  # the shutter's motion needs the vertices' velocities
            keep += ("velocities",)
        if getattr(cfg.sim, "frame_unit", "s") == "cycle":
            frames = run_at_phases(sim, state, params, num_worlds, cfg.sim.frame_times, keep)
        else:
            frames = sim.run(state, cfg.sim.frame_times, keys=keep)
        unstable = np.zeros(num_worlds, bool)
        for f in frames:
            unstable |= f.pop("unstable") | ~np.isfinite(f["positions"]).all(axis=(1, 2))
            f.pop("clock")
            f["rest_positions"] = rest
        return SimResult(frames=frames, unstable=unstable)

    def _renderer(self, cfg):
        key = (cfg.render.width, cfg.render.height, cfg.sim.device, cfg.render.shadows, cfg.render.shadow_map,
               cfg.render.supersample, cfg.render.texture_filter)
        r = self._renderers.get(key)
        if r is None:
            r = self._renderers[key] = Renderer(cfg.render.width, cfg.render.height, device=cfg.sim.device,
                                                shadows=cfg.render.shadows, shadow_map=cfg.render.shadow_map,
                                                supersample=cfg.render.supersample,
                                                texture_filter=cfg.render.texture_filter)
        return r

    def render_batch(self, frame, draws, cfg):
        params, cameras, appearance, seeds = draws.params, draws.cameras, draws.appearance, draws.seeds
        B = len(seeds)
        pattern = self._pattern(cfg.sim.n_units)
        scene = render.build_scene(
            frame["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=frame["magnet_pos"],
            magnet_rot=frame["magnet_rot"], worm_texcoords=pattern.vertices, ipm_diameter=params.ipm_diameter,
            ipm_thickness=params.ipm_thickness, epm_size=params.epm_size, floor_incline=params.floor_incline,
            appearance=draws.look,
            extra_mesh=distractor_mesh(appearance, B, params.floor_incline))  # render.distractors (None: off)

        cams = dataclasses.replace(cameras, world=np.arange(B, dtype=np.int32))
        gains = exposure_gains(cfg.render, seeds)  # render.exposure / white_balance: None when off
        if gains is not None:
            cams.gain = gains[0]
        engine = pathtraced_samples(cfg, seeds)  # None: the option is off (nothing more is written)
        # the sensor runs inside the renderer's pass, unless the RGB is replaced first (motion blur, path tracing)
        replaced = cfg.render.motion_blur > 0 or (engine is not None and engine.any())
        sensor = SensorBatch.from_values(draws.sensor, seeds)
        img = self._renderer(cfg).render(scene, cams, sensor=None if replaced else sensor)
        rgb = img["rgb"]
        if cfg.render.motion_blur > 0:  # RGB over the shutter from the simulated velocities; labels at the frame

            rgb = motion_blurred_rgb(self._renderer(cfg), scene, cams, frame, cfg.render.motion_blur,
                                     cfg.render.motion_blur_samples)
        if engine is not None and engine.any():  # RGB only: labels stay the rasterizer's exact passes

            sel = np.flatnonzero(engine)
            rgb = rgb.copy()
            rgb[sel] = render_pathtraced(scene, cams.take(sel), spp=cfg.render.pathtraced_spp, seeds=seeds[sel])
        if replaced:
            rgb = apply_sensor_batch(rgb, sensor, device=cfg.sim.device)  # the values drawn above, once
        labels = schema_labels(frame, pattern, cams, img, rest_positions=frame.get("rest_positions"),
                               ipm_diameter=params.ipm_diameter, ipm_thickness=params.ipm_thickness)
        out = {"rgb": rgb, "depth": img["depth"], "segmentation": img["seg"], **labels}
        if engine is not None:
            out["engine"] = engine.astype(np.uint8)
        if cams.dist is not None:  # render.distortion: the lens the image and keypoints/pixel went through
            out["camera/dist"] = np.asarray(cams.dist, dtype=np.float64)
        if gains is not None:
            out.update({f"params/{k}": v for k, v in gains[1].items()})
        return out


def frame_steps(phases, period, dt: float) -> np.ndarray:
    """Steps after settling (W, F) at which each world's frames fall: ``round(phases[f] · period[w] / dt)``, phases in
    cycles of the EPM path (k + 0.5: its k-th closest approach, k: a far point), ``period`` (W,) [s]. ValueError when
    two frames of a world round to one step."""
    steps = np.rint(np.outer(np.asarray(period, np.float64), np.asarray(phases, np.float64)) / dt).astype(np.int64)
    if steps.shape[1] > 1 and np.any(np.diff(steps, axis=1) <= 0):
        w = int(np.flatnonzero(np.any(np.diff(steps, axis=1) <= 0, axis=1))[0])
        raise ValueError(f"sim.frame_times: got {list(phases)} cycles; with worm.cycle_period {period[w]} s and "
                         f"sim.dt {dt} s two frames fall on one step; expected phases further apart")
    return steps


def run_at_phases(sim, state, params, num_worlds: int, phases, keys) -> list[dict]:
    """``sim.run`` for frames given in cycles of each world's EPM period (``sim.frame_unit: cycle``): one snapshot
    per distinct step over the worlds, each world keeping its own steps and retired after its last
    (:meth:`~warpworm.sim.simulator.Simulator.retire`). Returns F dicts of (W, ...) arrays like
    ``sim.run`` plus ``frame_time`` (W,) [s] and ``clock``.

    With ``unstable`` among ``keys``, the run stops once every world with frames left has gone unstable (exploded
    or crumpled: the substeps no longer move it, and its trajectory is redrawn): its frames left are its state at
    that step, flagged unstable, and the steps up to the last frame are not spent."""
    W = num_worlds
    steps = frame_steps(phases, per_world(params.cycle_period, W), sim.dt)  # (W, F)
    frames = [None] * steps.shape[1]
    done = 0
    for n in np.unique(steps):
        snap = sim.run(state, [(int(n) - done) * sim.dt], keys=keys)[0]
        done = int(n)
        sim.retire(state, steps[:, -1] == n)  # its last frame taken: a world is not stepped further
        left = steps[:, -1] > n
        stop = "unstable" in snap and not (left & ~np.asarray(snap["unstable"], bool)).any()
        for f in range(steps.shape[1]):
            hit = (steps[:, f] >= n) if stop else (steps[:, f] == n)
            if not hit.any():
                continue
            if frames[f] is None:
                frames[f] = {k: np.zeros_like(np.asarray(v)) for k, v in snap.items() if k != "clock"}
            for k, fr in frames[f].items():
                fr[hit] = np.asarray(snap[k])[hit]
        if stop:
            break
    for f, fr in enumerate(frames):
        fr["frame_time"] = (steps[:, f] * sim.dt).astype(np.float32)
        fr["clock"] = float(steps[:, f].max() * sim.dt)
    return frames


def pathtraced_samples(cfg, seeds: np.ndarray) -> np.ndarray | None:
    """Which of the samples with per-sample ``seeds`` (B,) are path-traced ((B,) bool; ``render.engine`` /
    ``render.pathtraced_fraction``, drawn from each sample's seed), or None when neither option is on."""
    r = cfg.render
    engine, frac = getattr(r, "engine", "raster"), float(getattr(r, "pathtraced_fraction", 0.0))
    if engine == "raster" and frac <= 0:
        return None

    return choose_pathtraced(seeds, 1.0 if engine == "pathtraced" else frac)
