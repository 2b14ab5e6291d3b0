"""Samples per simulated second: ``render.views_per_frame`` K = 1, 2, 4, 8 on the default and production configs.

Run: ``python benchmarks/run.py views [--quick]``.

Each row is one in-process ``warpworm.data.job.generate`` of the same trajectories (the config's own physics, one
worker, one shard, no previews) rendered by K cameras per frame, so it writes K times the samples of K = 1 from the
same simulation. ``samples_s`` is samples per wall second of the job; ``speedup`` is over K = 1 of the same config in
the same run; ``sim_s`` / ``render_s`` / ``write_s`` are the job's stage times (the write runs on a background thread,
overlapping the next batch, so the stages may sum to more than the wall); ``cpu_s`` is the process's CPU time (``samples_per_cpu_s``, ``speedup_cpu``: what one
dedicated core gives, steadier than the wall clock on this shared machine);
``others_cores`` is the CPU the *other* processes of this shared machine used meanwhile (``/proc/stat`` minus this
process), in cores. The production config runs on the CPU here with fewer worlds per batch (``sim.worlds``) than its
4096 and 256x256 images as configured.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path

from warpworm.data.config import load_config
from warpworm.data.job import generate

NOTES = ("samples_s: samples per wall second of the job (one process); speedup: over K = 1 of the same config in "
         "this run; samples_per_cpu_s / speedup_cpu: the same per CPU second of the process; others_cores: CPU the other processes used during the row (shared machine)")

KS = (1, 2, 4, 8)


def _busy_jiffies() -> int:
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return sum(v) - v[3] - v[4]  # all but idle and iowait


def measure(fn):
    """(fn(), wall s, this process's CPU s, the other processes' mean cores busy during the call)."""
    hz = os.sysconf("SC_CLK_TCK")
    j0, c0, t0 = _busy_jiffies(), time.process_time(), time.perf_counter()
    out = fn()
    j1, c1, t1 = _busy_jiffies(), time.process_time(), time.perf_counter()
    others = max(0.0, (j1 - j0) / hz - (c1 - c0)) / max(t1 - t0, 1e-9)
    return out, t1 - t0, c1 - c0, others


CONFIGS = {
    # name: (packaged config, overrides, trajectories)
    "default": ("default", ["sim.worlds=16"], 16),
    "production": ("production", ["sim.device=cpu", "sim.worlds=8"], 8),
}


def _cfg(name: str, k: int, trajectories: int, quick: bool):
    src, over, _ = CONFIGS[name]
    if quick:
        over = over + ["sim.settle_time=0.1", "render.width=64", "render.height=48"]
    probe = load_config(src, over + ["output.preview=false"])
    n = trajectories * len(probe.sim.frame_times) * k
    return load_config(src, over + ["output.preview=false", f"render.views_per_frame={k}", f"shard_size={n}"],
                       num_samples=n)


def bench_config(name: str, quick: bool = False) -> list[dict]:
    trajectories = 4 if quick else CONFIGS[name][2]
    rows, base = [], None
    for k in KS:
        cfg = _cfg(name, k, trajectories, quick)
        tmp = Path(tempfile.mkdtemp(prefix="ww-views-"))
        try:
            s, wall, cpu, others = measure(lambda: generate(cfg, tmp / "d", progress=False, log=lambda m: None))
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
        rate = cfg.num_samples / wall
        base = (rate, cfg.num_samples / cpu) if base is None else base
        rows.append({"bench": "views", "config": name, "K": k, "trajectories": trajectories,
                     "samples": cfg.num_samples, "image": f"{cfg.render.width}x{cfg.render.height}",
                     "wall_s": wall, "samples_s": rate, "speedup": rate / base[0],
                     "samples_per_cpu_s": cfg.num_samples / cpu, "speedup_cpu": cfg.num_samples / cpu / base[1],
                     "sim_s": s.sim_s,
                     "render_s": s.render_s, "write_s": s.write_s, "cpu_s": cpu, "others_cores": others})
    return rows


def run(quick: bool = False) -> list[dict]:
    # load (compile on a cold cache) every kernel once, outside the timed rows
    tmp = Path(tempfile.mkdtemp(prefix="ww-views-warm-"))
    try:
        generate(_cfg("default", 2, 1, True), tmp / "d", progress=False, log=lambda m: None)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    rows = []
    for name in CONFIGS:
        rows += bench_config(name, quick)
    return rows


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=1, default=str))


def headline(device: str = "cpu", quick: bool = False) -> dict:
    """One row for the summary table of ``benchmarks/run.py``: the ``dataset`` row's job (default config, its short
    physics, 128x96, W = 16 on the CPU, 4 on ``quick``) rendered by 4 cameras per frame; on CUDA 256 worlds, so that
    the row writes the 4096 samples of the dataset row's 1024 worlds (the host's gzip bounds both there)."""
    def cfg_of(overrides, **top):  # the dataset row's config (benchmarks/bench_dataset.py): default, short physics
        short = ["output.preview=false", "sim.settle_time=0.008", "sim.frame_times=[0.008, 0.016, 0.024, 0.032]"]
        return load_config("default", [*short, *overrides], **top)

    K, F = 4, 4
    W = 1024 // K if str(device).startswith("cuda") else (4 if quick else 16)
    tmp = Path(tempfile.mkdtemp(prefix="ww-views-headline-"))
    try:
        generate(cfg_of([f"sim.device={device}", "sim.worlds=2", "shard_size=8", "render.width=32",
                         "render.height=24"], num_samples=8), tmp / "warm", progress=False, log=lambda m: None)
        cfg = cfg_of([f"sim.device={device}", f"sim.worlds={W}", f"shard_size={W * F * K}",
                      f"render.views_per_frame={K}"], num_samples=W * F * K)
        t0 = time.perf_counter()
        generate(cfg, tmp / "d", progress=False, log=lambda m: None)
        total = time.perf_counter() - t0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return {"system": f"warpworm generate, render.views_per_frame {K}", "device": str(device), "W": W,
            "rate": W * F * K / total, "unit": "samples/s", "time_base": "wall",
            "note": f"the row above's job, {K} cameras per simulated frame" + (f" ({W} worlds)" if W >= 256 else "")}
