#!/usr/bin/env python
"""How far the default substep's trajectory is from a fine one, over a (w, a, h) grid, with each point's far-point rest.

Every grid point is one world of one batch, run ``--cycles`` EPM cycles at the default step (``gaits.DEFAULT_DT``)
split into ``--substeps`` implicit substeps (each list entry a run; default 2, 4, 8: 2, 1, 0.5 ms) and once at the
reference ``--reference`` substeps (default 16: 0.25 ms). Per point and run it prints the vertex centroid's distance
to the reference's over the whole trajectory (frames at ``--fps``): the largest and the median, and at the end (a far
point, where the worm should rest, when ``--cycles`` is whole), with the default run's far-point motion (``gait_metrics.far_point_motion_m``: how
far the worm moves within ±0.1 cycle of the EPM's far points) and distance per cycle. Analytic magnets.

A gait whose worm snaps (omega lifting its middle as the EPM comes close) is hard on a fixed step: the snap's time
moves with the step, and mid-snap the worm is then millimetres from where a finer step has it even when it rests in
the same place afterwards. This is the measurement behind docs/dynamics.md, "Omega's far point and the amplitude".

Usage::

    python benchmarks/gait_dt_error.py omega --w 8,16 --a 30,60,80 --h 20,25 [--cycles 5] [--substeps 2,4,8]
        [--reference 16] [--fps 50] [--out benchmarks/results/gait_dt_error_omega.json]
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_runs import run_gait_split
from warpworm.analysis.gait_search import grid_points
from warpworm.physics import gaits


def main(argv=None) -> int:
    from gait_grid import gait_grid_parser, grid_from_arguments

    ap = gait_grid_parser(__doc__, cycles_default=5.0, cycles_type=float, name="gait_dt_error")
    ap.add_argument("--substeps", default="2,4,8", help="substeps per 4 ms step of the runs compared (default 2,4,8)")
    ap.add_argument("--reference", type=int, default=16, help="substeps of the reference run (default 16: 0.25 ms)")
    ap.add_argument("--fps", type=float, default=50.0, help="trajectory frames per second compared (default 50)")
    args = ap.parse_args(argv)
    try:
        runs = [int(v) for v in args.substeps.split(",") if v.strip()]
    except ValueError:
        raise SystemExit(f"--substeps: {args.substeps!r} is not a comma-separated list of integers") from None
    if not runs or min(runs) < 1 or args.reference < 1:
        raise SystemExit(f"--substeps {args.substeps!r} / --reference {args.reference}: expected integers >= 1")
    if not args.cycles > 0 or not args.fps > 0:
        raise SystemExit(f"--cycles {args.cycles} / --fps {args.fps}: expected positive numbers")
    quiet_warp()

    grid = grid_from_arguments(args)
    pts = grid_points(grid)
    N = len(pts["wavelength"])
    params = gaits.preset_params(args.gait, backward=args.backward, magnet_model="analytic")
    params = replace(params, support_thickness=min(float(params.support_thickness), float(grid["closest_approach"].min())),
                     **pts)
    sign = -1.0 if args.backward else 1.0
    out = {}
    for s in sorted(set(runs + [args.reference])):
        r = run_gait_split(params, N, args.cycles, substeps=s, fps=args.fps, save_worlds=N, workers=args.workers)
        out[s] = {"centroid": r["frames"]["positions"].astype(np.float64).mean(axis=2),  # (F, N, 3)
                  "metrics": r["metrics"], "unstable": np.asarray(r["unstable"]).astype(bool)}
    ref = out[args.reference]
    rows = []
    dt_ms = {s: 1e3 * gaits.DEFAULT_DT / s for s in out}
    print(f"{args.gait}{' backward' if args.backward else ''}, {args.cycles:g} cycles; centroid distance to the "
          f"{dt_ms[args.reference]:g} ms run [mm]: max / median / at the end, per substep")
    for i in range(N):
        row = {"w_mm": 1e3 * pts["wavelength"][i], "a_mm": 1e3 * pts["amplitude"][i],
               "h_mm": 1e3 * pts["closest_approach"][i], "unstable": bool(any(out[s]["unstable"][i] for s in out))}
        m = out[runs[0]]["metrics"]
        row["far_point_motion_mm"] = 1e3 * float(m["far_point_motion_m"][i])
        row["per_cycle_mm"] = (1e3 * sign * np.asarray(m["cycle_displacement_m"][i])).round(2).tolist()
        for s in runs:
            d = 1e3 * np.linalg.norm(out[s]["centroid"][:, i] - ref["centroid"][:, i], axis=-1)
            row[f"error_{dt_ms[s]:g}ms_mm"] = [float(d.max()), float(np.median(d)), float(d[-1])]
        rows.append(row)
        errs = "  ".join(f"{dt_ms[s]:g} ms {row[f'error_{dt_ms[s]:g}ms_mm'][0]:5.2f} "
                         f"{row[f'error_{dt_ms[s]:g}ms_mm'][1]:5.2f} {row[f'error_{dt_ms[s]:g}ms_mm'][2]:5.2f}"
                         for s in runs)
        print(f"  w {row['w_mm']:4.1f} a {row['a_mm']:4.1f} h {row['h_mm']:4.1f} | far {row['far_point_motion_mm']:6.3f}"
              f" mm | per cycle {' '.join(f'{v:+.1f}' for v in row['per_cycle_mm'])} | {errs}"
              f"{'  UNSTABLE' if row['unstable'] else ''}")
    path = Path(args.out) if args.out else Path(__file__).resolve().parent / "results" / f"gait_dt_error_{args.gait}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"gait": args.gait, "backward": args.backward, "cycles": args.cycles,
                                "reference_substeps": args.reference, "rows": rows}, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
