"""Planted-parameter recovery from images alone (issue #26): simulate a gait at planted parameters, render it with the
marker bands and the dataset's harshest sensor draws (noise 4 levels, blur 0.8 px, brightness +12, contrast 1.15; no
JPEG), track it (warpworm.analysis.track), fit it (warpworm.analysis.fit_track) and print planted vs fitted values,
their 1-sigma and whether the track pins them.

    python benchmarks/calibrate_track.py --gaits peristaltic,inchworm,omega          # ~1.5-3 min per gait (2 cores)
    python benchmarks/calibrate_track.py --gaits peristaltic --true-model dipoles --fit-model analytic
                                                            # the model error the analytic magnets absorb

Numbers: docs/calibration.md.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

PLANT = {"hinge_stiffness": 1.3, "valley_bar_stiffness": 0.8, "mu_static": 0.85, "epm_moment": 1.1}
FPS = 12.5  # 20 solver steps of 4 ms between frames


def planted_track(gait: str, names, mult, model: str, cycles: float, width=640, height=480, backward=False,
                  path=None):
    """(track dict, camera meta, base params, planted values) of one simulated, rendered and tracked run."""
    from warpworm.analysis import fit_track as FT
    from warpworm.analysis import track as T
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

    base = gaits.preset_params(gait, backward, magnet_model=model, **(path or {}))
    truth = np.array([float(getattr(base, n)) * mult[n] for n in names])
    r = run_gait(FT.candidate_params(base, names, truth[None]), 1, cycles, fps=FPS, save_worlds=1)
    t = np.asarray(r["frames"]["time"])
    keep = np.abs(t * FPS - np.round(t * FPS)) < 1e-6
    frames = {k: v[keep] for k, v in r["frames"].items()}
    F = int(keep.sum())
    sensor = T.harshest_sensor(F)  # the randomization's harshest sensor draws, no JPEG
    centre = (0.03 if backward else 0.05, 0.0, 0.0)
    cam = T.overhead_camera(centre=centre, width=width, height=height, fov_deg=22.0 if cycles <= 1 else 30.0)
    rgb = T.render_band_video(frames, r["model"], cam, width, height, sensor_values=sensor, seed=11)
    h = T.default_band_height(base)
    tr = T.track(rgb, cam, height=h, fps=FPS)
    meta = {"camera": cam, "width": width, "height": height, "height_m": h}
    return tr, meta, base, truth


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gaits", default="peristaltic,inchworm,omega")
    ap.add_argument("--fit", default=",".join(PLANT))
    ap.add_argument("--budget", type=int, default=64)
    ap.add_argument("--refine", type=int, default=5)
    ap.add_argument("--profile", type=int, default=6, help="re-fit steps of the global profile (0: none)")
    ap.add_argument("--popsize", type=int, default=None)
    ap.add_argument("--cycles", type=float, default=1.0)
    ap.add_argument("--path", default=None, metavar="w=…,a=…,h=…", help="the EPM path [m] (default: the preset's)")
    ap.add_argument("--true-model", default="analytic", choices=["analytic", "dipoles"])
    ap.add_argument("--fit-model", default="analytic", choices=["analytic", "dipoles"])
    ap.add_argument("--known", default="", help="planted parameters given to the fit as known (calibration steps "
                    "1-2: e.g. epm_moment from a force-gap table), not fitted")
    ap.add_argument("--json", default=None, help="write the results here")
    args = ap.parse_args()
    from warpworm import quiet_warp
    from warpworm.analysis import fit_track as FT

    quiet_warp()
    known = [n for n in args.known.split(",") if n]
    names = [n for n in args.fit.split(",") if n not in known]
    rows = []
    for gait in args.gaits.split(","):
        t0 = time.perf_counter()
        tr, meta, base, truth_all = planted_track(gait, names + known, PLANT, args.true_model, args.cycles,
                                                  path=FT.parse_path(args.path))
        truth = truth_all[:len(names)]
        from dataclasses import replace

        base = replace(base, magnet_model=args.fit_model, **dict(zip(known, truth_all[len(names):])))
        res = FT.fit(tr, base, names, budget=args.budget, meta=meta, refine=args.refine, popsize=args.popsize,
                     profile=args.profile)
        err = res["value"] / truth - 1
        print(f"\n{gait}{' path ' + args.path if args.path else ''} ({args.true_model} -> {args.fit_model}, "
              f"{args.cycles:g} cycle, {len(tr['time'])} frames, "
              f"{res['worlds']} worlds, {time.perf_counter() - t0:.0f} s; known: {known or 'none'})")
        print("\n".join(FT.report_lines(res)))
        for n, tv, e in zip(names, truth, err):
            print(f"  {n:24s} planted {tv:.5g}  error {100 * e:+.2f} %  (planted at {-100 * e / (1 + e):+.2f} % of the "
                  "fitted value)")
        rows.append({"gait": gait, "true_model": args.true_model, "fit_model": args.fit_model, "names": names,
                     "planted": truth.tolist(), "fitted": res["value"].tolist(), "error": err.tolist(),
                     "range_rel": res["range_rel"].tolist(), "at_bound": res["at_bound"].tolist(),
                     "planted_inside": [bool(lo <= -e / (1 + e) <= hi) for (lo, hi), e in zip(res["range_rel"], err)],
                     "sigma_rel": [float(s) for s in res["sigma_rel"]], "pinned": res["pinned"].tolist(),
                     "moved": res["moved"],
                     "rms_ratio": res["rms_ratio"], "rms_disp_m": res["rms_disp_m"], "worlds": res["worlds"],
                     "wall_s": time.perf_counter() - t0})
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    main()
