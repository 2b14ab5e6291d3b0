"""The render stage of a real ``generate`` job, captured once and replayed: per-kernel CPU time on the job's own
scenes (not a benchmark's posed ones), and a fixed workload for comparing two trees or counting instructions.

``python benchmarks/job_render_replay.py capture calls.pkl production sim.worlds=16 --num 64`` runs the job (to a
temporary folder, deleted after) and pickles every ``Renderer.render`` call it makes (the renderer's settings, the
scene, the cameras, the sensor values: host arrays only).

``python benchmarks/job_render_replay.py replay calls.pkl [--images 8] [--repeats 3] [--npz out.npz]`` renders them
again after one untimed render (kernel load): the best process-CPU time per image of the whole ``render`` and of each
kernel's launches, and optionally the outputs (to check that two trees give the same bytes). Instruction counts, which
a busy machine does not change: ``valgrind --tool=cachegrind --cache-sim=no <python> benchmarks/job_render_replay.py
replay calls.pkl --images 8 --repeats 2``, whose Warp kernels are the code valgrind lists without a symbol (``???``);
check that it printed its timing line: valgrind stops at AVX instructions it does not decode (``vex amd64->IR:
unhandled instruction bytes``) in kernels from Warp's cache, and a run that ended there still prints totals. Timer
samples mapped onto a kernel's code work where valgrind does not: ``benchmarks/kernel_samples.py calls.pkl``.
"""

from __future__ import annotations

import argparse
import os
import pickle
import shutil
import sys
import tempfile
import time

import numpy as np
from profile_step import launch_timers  # benchmarks/: per-kernel CPU time of every launch in a block

from warpworm import quiet_warp
from warpworm.render import rasterizer


def capture(path: str, config: str, num: int, overrides: list[str]) -> int:
    """Run ``generate config`` for ``num`` samples and pickle its render calls to ``path``; returns their count."""
    from warpworm.data.config import load_config
    from warpworm.data.job import generate

    calls = []
    original = rasterizer.Renderer.render

    def recording(self, scene, cameras, **kw):
        settings = {"width": self.width, "height": self.height, "shadows": self.shadows,
                    "shadow_map": self.shadow_map, "supersample": self.supersample,
                    "texture_filter": self.texture_filter}
        calls.append((settings, scene, cameras, kw))
        return original(self, scene, cameras, **kw)

    cfg = load_config(config, ["output.preview=false", *overrides], num_samples=num)
    out = tempfile.mkdtemp(prefix="ww-replay-")
    rasterizer.Renderer.render = recording
    try:
        generate(cfg, os.path.join(out, "ds"), workers=1, progress=False)
    finally:
        rasterizer.Renderer.render = original
        shutil.rmtree(out, ignore_errors=True)
    with open(path, "wb") as f:
        pickle.dump(calls, f)
    return len(calls)


def _first(call, n: int):
    """``call`` cut to its first ``n`` images (cameras and sensor values alike)."""
    settings, scene, cameras, kw = call
    if kw.get("sensor") is not None:
        kw = {**kw, "sensor": kw["sensor"].take(slice(0, n))}
    return settings, scene, cameras.take(np.arange(n)), kw


def replay(path: str, images: int = 0, repeats: int = 3) -> tuple[dict, dict]:
    """Render the captured calls ``repeats`` times (``images`` > 0: the first call's first ``images`` only): the best
    CPU ms per image of the whole render and of each kernel (by name), and the last outputs."""
    with open(path, "rb") as f:
        calls = pickle.load(f)
    if images:
        calls = [_first(calls[0], images)]
    renderers = [rasterizer.Renderer(**settings) for settings, *_ in calls]

    def render_all():
        return [r.render(scene, cameras, **kw) for r, (_, scene, cameras, kw) in zip(renderers, calls)]

    outputs = render_all()  # kernel load
    n = sum(o["rgb"].shape[0] for o in outputs)
    best = {}
    for _ in range(repeats):
        with launch_timers() as spent:  # {kernel: [wall s, CPU s, launches]}
            t = time.process_time()
            outputs = render_all()
            total = time.process_time() - t
        for k, v in [("render", total), *((k, a[1]) for k, a in spent.items())]:
            best[k] = min(best.get(k, float("inf")), v * 1e3 / n)
    arrays = {k: np.concatenate([o[k] for o in outputs]) for k in outputs[0] if isinstance(outputs[0][k], np.ndarray)}
    return best, arrays


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="cmd", required=True)
    cap = sub.add_parser("capture", help="run a generate job and pickle its render calls")
    cap.add_argument("path")
    cap.add_argument("config")
    cap.add_argument("--num", type=int, default=64)
    cap.add_argument("overrides", nargs="*", help="config overrides, KEY=VALUE")
    rep = sub.add_parser("replay", help="render the captured calls again, timed per kernel")
    rep.add_argument("path")
    rep.add_argument("--images", type=int, default=0, help="only the first call's first N images (0: all)")
    rep.add_argument("--repeats", type=int, default=3)
    rep.add_argument("--npz", help="write the last outputs here")
    args = parser.parse_args(argv)
    quiet_warp()
    if args.cmd == "capture":
        if args.num < 1:
            parser.error(f"--num: got {args.num}; expected an integer >= 1")
        print(f"{capture(args.path, args.config, args.num, args.overrides)} render call(s) -> {args.path}")
        return 0
    if args.repeats < 1:
        parser.error(f"--repeats: got {args.repeats}; expected an integer >= 1")
    best, arrays = replay(args.path, args.images, args.repeats)
    n = len(arrays["rgb"])
    kernels = sorted(((k, v) for k, v in best.items() if k != "render"), key=lambda kv: -kv[1])
    print(f"{n} images: render {best['render']:.2f} ms/image (best of {args.repeats}); kernels "
          f"{sum(v for _, v in kernels):.2f}: " + ", ".join(f"{k} {v:.2f}" for k, v in kernels[:6]))
    if args.npz:
        np.savez(args.npz, **arrays)
    return 0


if __name__ == "__main__":
    sys.exit(main())
