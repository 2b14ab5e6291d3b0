"""Band-centre accuracy of the tracker on footage warpworm's rasterizer did not draw (issue #41): one cycle of each
gait preset simulated, path-traced by Mitsuba 3 under randomized hard light and a tilted camera with its own K and
lens (:mod:`warpworm.analysis.footage`), the randomization's harshest sensor draws added, tracked
(:func:`warpworm.analysis.track.band_centroids`), and compared with the centroids of each band's visible pixels.

    nice -n 10 python benchmarks/track_pathtraced.py --looks 4                  # ~1 min on the shared 2-core machine
    nice -n 10 python benchmarks/track_pathtraced.py --looks 4 --brightness-cut  # the first tracker's brightness rule
    nice -n 10 python benchmarks/track_pathtraced.py --looks 4 --hard            # hard masks, no boundary unmixing

Numbers: docs/calibration.md ("Track").
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np


def gait_frames(gait: str, frames: int, fps: float = 12.5, cycles: float = 1.0, params=None):
    """(frames dict, model) of one simulated cycle of ``gait``'s preset (or ``params``), ``frames`` frames spread
    over it."""
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

    base = gaits.preset_params(gait, magnet_model="analytic") if params is None else params
    r = run_gait(base, 1, cycles, fps=fps, save_worlds=1)
    t = np.asarray(r["frames"]["time"])
    idx = np.unique(np.round(np.linspace(0, len(t) - 1, frames)).astype(int))
    return {k: np.asarray(v)[idx] for k, v in r["frames"].items()}, r["model"]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gaits", default="peristaltic,omega,inchworm")
    ap.add_argument("--looks", type=int, default=4, help="randomized lights and cameras per gait")
    ap.add_argument("--frames", type=int, default=5, help="frames per look, spread over one cycle")
    ap.add_argument("--size", default="256x192")
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--truth", default="raster", choices=["raster", "pathtracer"])
    ap.add_argument("--brightness-cut", action="store_true", help="the first tracker (value >= half the colour's, hue within 25)")
    ap.add_argument("--hard", action="store_true", help="centroids of the hard masks (soft=0: the tracker before "
                    "the boundary unmixing)")
    ap.add_argument("--threshold", action="append", default=[], metavar="NAME=VALUE",
                    help="a tracker threshold (Thresholds.OVERRIDABLE), as warpworm track's")
    ap.add_argument("--no-distortion", action="store_true")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None)
    args = ap.parse_args()
    from warpworm import quiet_warp
    from warpworm.analysis import footage as FO
    from warpworm.analysis import track as T

    quiet_warp()
    W, H = (int(x) for x in args.size.split("x"))
    thr = T.Thresholds.from_colors(**({"brightness_cut": 1.0, "hue_tol": 25.0} if args.brightness_cut else {}),
                                   **({"soft": 0.0} if args.hard else {}),
                                   **{k: float(v) for k, _, v in (t.partition("=") for t in args.threshold)})
    rows = []
    print(f"{'gait':12s} {'look':>4s} {'mean px':>8s} {'max px':>7s}  per band max (blue pink white green red)")
    for gait in args.gaits.split(","):
        fr, model = gait_frames(gait, args.frames)
        errs = []
        for k in range(args.looks):
            rng = np.random.default_rng([args.seed, k, len(gait)])
            look = FO.random_look(rng)
            cam = FO.random_camera(rng, W, H, distortion=not args.no_distortion and args.truth == "raster")
            F = len(fr["time"])
            t0 = time.perf_counter()
            rgb, truth = FO.pathtraced_band_video(fr, model, cam, W, H, look, spp=args.spp, truth=args.truth,
                                                  sensor_values=T.harshest_sensor(F), seed=100 * k + 7)
            uv = np.stack([T.band_centroids(im, thr)[0] for im in rgb])
            e = np.linalg.norm(uv - truth, axis=-1)  # (F, 5); NaN where a band is lost
            lost = int((~np.isfinite(e) & np.isfinite(truth[..., 0])).sum())
            e = np.where(np.isfinite(e), e, np.inf)
            errs.append(e)
            print(f"{gait:12s} {k:4d} {np.mean(e[np.isfinite(e)]):8.2f} {np.max(e):7.2f}  "
                  f"{np.round(e.max(axis=0), 2).tolist()}  lost {lost}  ({time.perf_counter() - t0:.1f} s)", flush=True)
        e = np.concatenate(errs)
        rows.append({"gait": gait, "mean_px": float(np.mean(e[np.isfinite(e)])), "max_px": float(np.max(e)),
                     "p95_px": float(np.percentile(e, 95)), "band_max_px": e.max(axis=0).tolist(),
                     "frames": int(len(e)), "seed": args.seed, "errors": e.tolist()})
        print(f"{gait:12s}  all  {rows[-1]['mean_px']:8.2f} {rows[-1]['max_px']:7.2f}  (95 %: {rows[-1]['p95_px']:.2f} px, "
              f"{len(e)} frames x 5 bands)")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
