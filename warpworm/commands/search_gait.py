"""``warpworm search-gait``: the paper's Table I as one batched grid search over the EPM path (w, a, h)."""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

import numpy as np

from warpworm.data import export_json as strict_json

HELP = "grid-search the EPM path (w, a, h) of a gait, every grid point one world; rank by distance per cycle"


def add_arguments(parser) -> None:
    parser.add_argument("--gait", choices=["peristaltic", "omega", "inchworm"], default="peristaltic")
    parser.add_argument("--backward", action="store_true", help="drive the worm toward -x")
    parser.add_argument("--grid", default="w=0.008:0.032:10,a=0.03:0.06:4,h=0.006:0.03:25",
                        help="KEY=lo:hi:n or KEY=v1,v2 for w, a, h [m] (the period is one per run: --set "
                             "cycle_period=T); default 10 x 4 x 25 = 1000 points")
    parser.add_argument("--cycles", type=int, default=3, help="EPM cycles per world (default 3)")
    parser.add_argument("--material", default=None, help="sheet material (warpworm.physics.materials; default the worm's)")
    parser.add_argument("--magnet-model", choices=["dipoles", "analytic"], default="dipoles")
    parser.add_argument("--workers", type=int, default=None, help="processes (default: every core)")
    parser.add_argument("--out", default="search_out", help="output folder for the CSV and the heat map")
    parser.add_argument("--top", type=int, default=10, help="rows of the ranking to print")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a WormParams field for every world, e.g. --set hinge_damping=1e-4")
    parser.add_argument("--max-ratio", type=float, default=None,
                        help="rank only worlds that deform: some segment ratio <= this (e.g. 0.9)")


def main(args) -> int:
    from warpworm.physics import gaits
    from warpworm import quiet_warp
    from warpworm.analysis.gait_search import parse_grid, search_gait, write_csv, write_heatmap
    from warpworm.physics.materials import material_params

    quiet_warp()
    try:
        grid = parse_grid(args.grid)
        base = material_params(args.material) if args.material else None
    except ValueError as e:
        print(f"warpworm search-gait: {e}", file=sys.stderr)
        return 2
    if args.cycles < 1:
        print(f"warpworm search-gait: --cycles {args.cycles}: expected >= 1", file=sys.stderr)
        return 2
    from warpworm.physics.params import parse_overrides

    try:
        overrides = parse_overrides(args.set)
    except ValueError as e:
        print(f"warpworm search-gait: {e}", file=sys.stderr)
        return 2
    params = gaits.preset_params(args.gait, args.backward, base=base, magnet_model=args.magnet_model, **overrides)
    n = int(np.prod([len(v) for v in grid.values()]))
    workers = args.workers or os.cpu_count() or 1
    print(f"search-gait {args.gait}{' backward' if args.backward else ''}: {n} grid points x {args.cycles} cycles "
          f"on {min(workers, n)} process(es)")
    t0 = time.perf_counter()
    res = search_gait(params, grid, args.cycles, workers=workers, max_ratio=args.max_ratio)
    wall = time.perf_counter() - t0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "search.csv", res)
    write_heatmap(out / "heatmap.png", res)
    m = res["metrics"]
    print(f"  {wall:.1f} s wall; {int(res['valid'].sum())} of {n} worlds stable and unfolded "
          f"({int(m['unstable'].sum())} unstable, {int(m['crumpled'].sum())} of them crumpled)")
    print("  rank      w [mm]   a [mm]   h [mm]   mm/cycle  ratio min (tail->head)     swing [deg]  end hold")
    for r, i in enumerate(res["order"][:args.top]):
        pts = res["points"]
        print(f"  {r + 1:4d}  {1e3 * pts.get('wavelength', [np.nan] * n)[i]:8.1f} "
              f"{1e3 * pts.get('amplitude', [np.nan] * n)[i]:8.1f} {1e3 * pts.get('closest_approach', [np.nan] * n)[i]:8.1f}"
              f"  {1e3 * res['per_cycle_m'][i]:9.2f}  {np.round(m['deformation_ratio_min'][i], 2).tolist()}"
              f"  {m['crease_angle_range_deg'][i]:9.1f}  {np.nanmax(np.append(m['end_hold_ratio'][i], -1.0)):8.2f}")
    summary = {"gait": args.gait, "backward": bool(args.backward), "grid": args.grid, "cycles": args.cycles,
               "max_ratio": args.max_ratio, "points": n, "crumpled": int(m["crumpled"].sum()),
               "unstable": int(m["unstable"].sum()), "valid": int(res["valid"].sum()), "wall_time_s": wall, "best": res["best"],
               "best_per_cycle_m": float(res["per_cycle_m"][res["order"][0]]) if len(res["order"]) else None}
    strict_json.write(out / "search.json", summary, indent=1)
    print(f"  best: {res['best']}")
    print(f"  wrote {out / 'search.csv'}, {out / 'heatmap.png'}, {out / 'search.json'}")
    return 0
