"""Rendering throughput: images/s of the batched rasterizer (RGB + depth + segmentation) against the reference BVH
ray caster (depth + segmentation only) on the same scenes and cameras, for several image sizes and world counts.

Run through the runner (``python benchmarks/run.py render [--quick]``) or alone (``python benchmarks/bench_render.py``).
Scenes: posed worms (72 facets) with three IPM disks, the EPM bar and the analytic floor; C cameras per world from the
shell sampler. Timings exclude kernel compilation (one warm-up render first) and include the host copies of the
outputs. Every row also reports the fraction of pixels where raster and ray-cast depth agree to 1e-4 m, and
``gauge_ns``: ns per element of a trivial kernel measured in the same run (about 2 ns on this 2-core machine when it
is idle; larger when other processes share the cores), so that rows from busy and idle runs can be compared; and ``raster_img_cpu_s``, images per CPU-second of this
process (CPU time of all its threads): what one dedicated core would deliver, much less sensitive to other load.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np
import warp as wp

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.data.sampling import appearance_draws, sample_appearance
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.placement import distractor_mesh
from warpworm.render.raycast import RayCaster
from warpworm.render.sensor import SensorBatch


def _scene(num_worlds: int, seed: int = 0):
    pattern = default_pattern()
    states = posed_worm_states(seed * 100003 + np.arange(num_worlds), pattern)
    scene = build_scene(states["positions"], pattern.triangles, pattern.triangle_segment,
                        magnet_pos=states["magnet_pos"], magnet_rot=states["magnet_rot"],
                        worm_texcoords=pattern.vertices, appearance=sample_appearance(load_config("default"), np.arange(num_worlds)))
    return states, scene


def _best_time(fn, repeats: int, cpu: bool = False):
    """Best wall time [s] of ``repeats`` calls; with ``cpu``, also the best CPU time of this process [s]."""
    best, best_cpu = float("inf"), float("inf")
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        best = min(best, time.perf_counter() - t0)
        best_cpu = min(best_cpu, time.process_time() - c0)
    return (best, best_cpu) if cpu else best


def _machine_ns_per_element(device) -> float:
    """ns per element of a trivial kernel (DESIGN-NOTES: about 2 ns on this machine when idle): a load gauge."""
    @wp.kernel
    def fill(a: wp.array(dtype=float)):
        i = wp.tid()
        a[i] = float(i) * 0.5

    n = 1 << 22
    a = wp.empty(n, dtype=float, device=device)
    wp.launch(fill, dim=n, inputs=[a], device=device)
    wp.synchronize_device(device)

    def go():
        wp.launch(fill, dim=n, inputs=[a], device=device)
        wp.synchronize_device(device)

    return _best_time(go, 3) / n * 1e9


def run(quick: bool = False, device=None, threads=(1, 2)) -> list[dict]:
    """One row per (size, worlds, threads): rasterizer images/s and the ray caster's on the same batch.

    ``threads`` > 1 renders interleaved chunks from Python threads (CPU only; one process). The ray caster always
    runs single-threaded (one launch).
    """
    quiet_warp()
    wp.init()
    dev = wp.get_device(device)
    thread_counts = tuple(threads) if dev.is_cpu else (1,)
    # (size, worlds, cameras per world); images per batch = worlds * cameras
    if dev.is_cuda:  # batches that fill a GPU (1,024 images at 128² and 256²); the CPU's would time launch latency
        cases = [(128, 128, 8), (256, 128, 8), (512, 32, 4)]
        repeats = 5
    elif quick:
        cases = [(64, 16, 8), (128, 16, 8), (256, 4, 8), (512, 2, 2)]
        repeats = 3
    else:
        cases = [(64, 64, 8), (128, 16, 16), (128, 64, 8), (256, 16, 8), (512, 8, 2)]
        repeats = 5
    rows = []
    for size, W, C in cases:
        states, scene = _scene(W)
        N = W * C
        cams = sample_cameras(np.arange(N), states["positions"], width=size, height=size,
                              world_index=np.arange(N) % W)
        caster = RayCaster(size, size, device=dev)
        ref = caster.render(scene, cams)
        t_build = _best_time(lambda: caster.build(scene), repeats)
        t_c = _best_time(lambda: caster.render(None, cams), max(1, repeats - 2))
        for T in thread_counts:
            renderer = Renderer(size, size, device=dev, threads=T)
            out = renderer.render(scene, cams)  # warm-up: kernel load, buffers
            gauge = _machine_ns_per_element(dev)
            t_r, c_r = _best_time(lambda: renderer.render(scene, cams), repeats, cpu=True)
            agree = float((np.abs(out["depth"] - ref["depth"]) <= 1e-4).mean())
            rows.append({
                "device": dev.alias, "size": size, "worlds": W, "images": N, "threads": T,
                "triangles": int(scene.triangles.shape[0]), "raster_img_s": N / t_r, "raster_ms": t_r * 1e3,
                "raster_img_cpu_s": N / c_r,
                "raycast_img_s": N / (t_c + t_build), "raycast_ms": (t_c + t_build) * 1e3,
                "speedup": (t_c + t_build) / t_r, "depth_agree": agree, "gauge_ns": gauge,
            })
    return rows + feature_rows(quick, dev)


FEATURES = (
    ("off (before)", [], {}),
    ("plate_pose", ["render.plate_pose=true"], {}),
    ("lights: random [1, 4]", ["render.lights=random"], {}),
    ("plate_pose + lights: random", ["render.plate_pose=true", "render.lights=random"], {}),
    ("shadows (sun + lamp, 128 px maps)", [], {"shadows": True}),
    ("shadows, 256 px maps", [], {"shadows": True, "shadow_map": 256}),
    ("shadows + lights: random [1, 4]", ["render.plate_pose=true", "render.lights=random"], {"shadows": True}),
    ("supersample 2 (4 RGB samples per pixel)", [], {"supersample": 2}),
    ("supersample 3 (9 RGB samples per pixel)", [], {"supersample": 3}),
    ("exposure + white balance (gains per image)", [], {"gain": True}),
    ("distractors [3, 6]", ["render.distractors=[3, 6]"], {}),
    ("plate_materials [glossy, acrylic]", ["render.plate_materials=[glossy, acrylic]"], {}),
    ("paper_bsdf", ["render.paper_bsdf=true"], {}),
    ("distortion (k1 -0.25, k2 0.08)", [], {"dist": (-0.25, 0.08, 0.002, -0.002, 0.0)}),
)
"""(name, config overrides, Renderer options) of the issue-24 rows: each realism option on its own and together."""


def _option_case(overrides: list, opts: dict, states: dict, pattern, cams):
    """One benchmark case: the appearance and scene of the default config with ``overrides`` (its looks, lights and
    distractors) over the posed worms ``states``; ``cams`` with the case's ``gain`` (exposure x white balance) and
    ``dist`` (lens) applied; and the rest of ``opts`` (Renderer options). Returns (appearance, scene, cameras,
    options)."""
    W, N = len(states["positions"]), len(cams)
    cfg = load_config("default", overrides)
    app = sample_appearance(cfg, np.arange(W))
    scene = build_scene(states["positions"], pattern.triangles, pattern.triangle_segment,
                        magnet_pos=states["magnet_pos"], magnet_rot=states["magnet_rot"],
                        worm_texcoords=pattern.vertices, appearance=app,
                        extra_mesh=distractor_mesh(appearance_draws(cfg, np.arange(W)), W))
    opts, view = dict(opts), cams
    if opts.pop("gain", False):
        view = dataclasses.replace(view, gain=np.tile([[1.4, 1.0, 0.8]], (N, 1)))
    if "dist" in opts:
        view = dataclasses.replace(view, dist=np.tile([opts.pop("dist")], (N, 1)))
    return app, scene, view, opts


def feature_rows(quick: bool, dev) -> list[dict]:
    """Images/s at the dataset's 128 x 96 with each issue-24 option on and off (posed worms with magnets, the
    config's looks and lights; 16 worlds x 8 cameras, quick 8 x 8, on CUDA 128 x 8; one thread)."""
    W, C, repeats = (128, 8, 5) if dev.is_cuda else (8, 8, 3) if quick else (16, 8, 5)
    pattern = default_pattern()
    states = posed_worm_states(np.arange(W), pattern)
    N = W * C
    cams = sample_cameras(np.arange(N), states["positions"], width=128, height=96, world_index=np.arange(N) % W)
    rows, base = [], None
    for name, overrides, opts in FEATURES:
        app, scene, view, opts = _option_case(overrides, opts, states, pattern, cams)
        renderer = Renderer(128, 96, device=dev, **opts)
        renderer.render(scene, view)  # warm-up
        gauge = _machine_ns_per_element(dev)
        t, c = _best_time(lambda: renderer.render(scene, view), repeats, cpu=True)
        base = t if base is None else base
        rows.append({"device": dev.alias, "feature": name, "size": "128x96", "images": N,
                     "point_lights": int(app.light_pos.shape[1]), "raster_img_s": N / t, "raster_ms": t * 1e3,
                     "raster_img_cpu_s": N / c, "cost_x": t / base, "gauge_ns": gauge})
    return rows


def plain_rows(sizes=(128, 256), worlds: int = 32, cameras: int = 4, repeats: int = 5, device=None) -> list[dict]:
    """Images per CPU-second of the default look (the plain resolve kernel): ``worlds`` posed worms x ``cameras``,
    best of ``repeats`` renders (``python3 benchmarks/bench_render.py --plain``; the A/B measurement of
    docs/render.md's plain-path table)."""
    quiet_warp()
    states, scene = _scene(worlds)
    idx = np.repeat(np.arange(worlds), cameras)
    rows = []
    for size in sizes:
        cams = sample_cameras(np.arange(worlds * cameras), states["positions"][idx], width=size, height=size,
                              world_index=idx)
        renderer = Renderer(size, size, device=device)
        renderer.render(scene, cams)  # warm-up
        _, c = _best_time(lambda: renderer.render(scene, cams), repeats, cpu=True)
        rows.append({"size": size, "images": len(cams), "img_per_cpu_s": len(cams) / c})
    return rows


PRODUCTION_LOOKS = ["render.plate_pose=true", "render.lights=random", "render.distractors=[0, 4]",
                    "render.plate_materials=[matte, glossy, acrylic]", "render.paper_bsdf=true"]
"""The per-trajectory look options of ``dataset_configs/production.yaml`` (shadows, supersampling, the lens and the
gains are renderer/camera options, added by :func:`production_rows`)."""


PRODUCTION_SENSOR = {"wb_r": 1.0, "wb_g": 1.0, "wb_b": 1.0, "hue_deg": 0.0, "saturation": 1.0, "contrast": 1.05,
                     "brightness": 0.01, "blur_sigma": 0.4, "noise_sigma": 2.0 / 255, "shot_noise": 0.0}
"""Sensor values near the middle of the dataset's ``sensor.*`` ranges (JPEG set per row)."""


def production_rows(size: int = 256, worlds: int = 8, cameras: int = 2, repeats: int = 7, device=None) -> list[dict]:
    """CPU ms per image of the default look, production's looks, + shadows, + supersample 2 and a lens of k1 -0.25,
    k2 0.08 (gains on), + the sensor (blur, noise, colour; on the device), + a JPEG round trip of half the images
    (quality 80, on the host): ``size``² px, posed worms, and each row's cost against the default look in the same
    run (``python3 benchmarks/bench_render.py --production [--json OUT]``). The cases take turns, ``repeats``
    rounds, and each keeps its best CPU time of this process, so a drift in the machine's speed or other load on it
    touches every row alike."""
    quiet_warp()
    dist = (-0.25, 0.08, 0.002, -0.002, 0.0)
    full = {"shadows": True, "supersample": 2, "gain": True, "dist": dist}
    cases = [("default look", [], {}, None), ("production looks", PRODUCTION_LOOKS, {"gain": True}, None),
             ("production looks + shadows", PRODUCTION_LOOKS, {"shadows": True, "gain": True}, None),
             ("+ supersample 2, lens", PRODUCTION_LOOKS, full, None),
             ("+ sensor (device)", PRODUCTION_LOOKS, full, 0),
             ("+ JPEG q80 on half (host): production as shipped", PRODUCTION_LOOKS, full, 80)]
    pattern = default_pattern()
    states = posed_worm_states(np.arange(worlds), pattern)
    N = worlds * cameras
    cams = sample_cameras(np.arange(N), states["positions"], width=size, height=size,
                          world_index=np.arange(N) % worlds)
    calls = []
    for name, overrides, opts, jpeg in cases:
        _, scene, view, opts = _option_case(overrides, opts, states, pattern, cams)
        sensor = None
        if jpeg is not None:
            values = dict(PRODUCTION_SENSOR, jpeg_quality=np.where(np.arange(N) % 2 == 0, jpeg, 0))
            sensor = SensorBatch.from_values(values, np.arange(N))
        renderer = Renderer(size, size, device=device, **opts)
        call = functools.partial(renderer.render, scene, view, sensor=sensor)
        call()  # warm-up: kernel load, buffers
        calls.append(call)
    best = [float("inf")] * len(cases)
    for _ in range(repeats):
        for i, call in enumerate(calls):
            best[i] = min(best[i], _best_time(call, 1, cpu=True)[1])
    rows = [{"case": name, "size": size, "images": N, "cpu_ms_per_image": c / N * 1e3}
            for (name, *_), c in zip(cases, best)]
    for r in rows:
        r["x_default"] = r["cpu_ms_per_image"] / rows[0]["cpu_ms_per_image"]
    return rows


def headline(device=None, quick: bool = False) -> dict:
    """One row for the summary table of ``benchmarks/run.py``: images/s of the rasterizer (RGB + depth +
    segmentation, host copies included) on ``device``: 128² px, 16 worlds × 8 cameras on the CPU (quick: 4 × 8);
    256² px, 512 worlds × 8 cameras on CUDA (4096 images per batch, enough to fill the GPU)."""
    quiet_warp()
    wp.init()
    dev = wp.get_device(device)
    size, W, C = (256, 512, 8) if dev.is_cuda else ((128, 4, 8) if quick else (128, 16, 8))
    states, scene = _scene(W)
    N = W * C
    cams = sample_cameras(np.arange(N), states["positions"], width=size, height=size, world_index=np.arange(N) % W)
    renderer = Renderer(size, size, device=dev)
    renderer.render(scene, cams)  # warm-up: kernel load, buffers

    def go():
        renderer.render(scene, cams)
        wp.synchronize_device(dev)

    t = _best_time(go, 3)
    return {"system": "warpworm rasterizer (RGB + depth + segmentation)", "device": dev.alias, "W": W,
            "rate": N / t, "unit": "images/s", "time_base": "wall",
            "note": f"{size}x{size} px, {C} cameras per world, host copies included"}

def main(argv=None) -> int:
    import argparse
    import json
    import sys
    from pathlib import Path

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--production", action="store_true", help="CPU ms per 256² image of production's option sets")
    which.add_argument("--plain", action="store_true", help="the plain path against the general kernel")
    parser.add_argument("--quick", action="store_true", help="fewer sizes and worlds")
    parser.add_argument("--json", metavar="FILE", help="write the rows here")
    args = parser.parse_args(argv)
    rows = production_rows() if args.production else plain_rows() if args.plain else run(quick=args.quick)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import table  # the runner's table: the raster rows and the option rows have different columns

    print(table(rows))
    if args.json:
        out = Path(args.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
