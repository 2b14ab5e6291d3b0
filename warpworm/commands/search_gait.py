"""``warpworm search-gait``: the paper's Table I as one batched grid search over the EPM path (w, a, h)."""

from __future__ import annotations

import os
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_search import grid_points, parse_grid, search_gait, write_csv
from warpworm.commands.common import check_minimum, first_run_notice, refuse
from warpworm.data import export_json as strict_json
from warpworm.physics import gaits
from warpworm.physics.materials import material_params
from warpworm.physics.param_specs import check_worm_params
from warpworm.physics.params import parse_overrides

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
    parser.add_argument("--workers", type=int, default=None, help="threads (default: every core)")
    parser.add_argument("--out", default="search_out", help="output folder for the CSV and the heat map")
    parser.add_argument("--top", type=int, default=10, help="rows of the ranking to print")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a WormParams field for every world, e.g. --set hinge_damping=1e-4")
    parser.add_argument("--max-ratio", type=float, default=None,
                        help="rank only worlds that deform: some segment ratio <= this (e.g. 0.9)")


AXES = (("wavelength", "w"), ("closest_approach", "h"), ("amplitude", "a"))
"""Heat map layout: x = w, y = h, one panel per a (every grid point shown)."""


def full_points(res: dict, params) -> dict:
    """Every grid point's w, a, h [m]: the grid's values, and the gait preset's where the grid does not vary it."""
    n = len(res["per_cycle_m"])
    return {k: np.asarray(res["points"][k], np.float64) if k in res["points"] else
            np.full(n, float(np.asarray(getattr(params, k)).reshape(-1)[0])) for k, _ in AXES}


def _colour(u: np.ndarray) -> np.ndarray:
    return cv2.applyColorMap((255 * np.clip(np.nan_to_num(u), 0, 1)).astype(np.uint8).reshape(-1, 1),
                             cv2.COLORMAP_VIRIDIS).reshape(u.shape + (3,))


def write_heatmap(path, res: dict, pts: dict, title: str) -> Path:
    """Distance per cycle [mm] over w (x) and h (y), one panel per a, one colour scale with its colour bar; grey:
    unstable, crumpled or dragged (not valid). Every grid point is in one cell of one panel."""

    per, valid = np.asarray(res["per_cycle_m"]) * 1e3, np.asarray(res["valid"], bool)
    xs, ys, zs = (np.unique(pts[k]) for k, _ in AXES)
    lo, hi = (float(per[valid].min()), float(per[valid].max())) if valid.any() else (0.0, 1.0)
    hi = hi if hi > lo else lo + 1e-6
    cw, ch = int(np.clip(360 // len(xs), 14, 60)), int(np.clip(300 // len(ys), 10, 60))
    font, pad_l, pad_t, pad_b, gap = cv2.FONT_HERSHEY_SIMPLEX, 64, 68, 46, 24
    pw, ph = cw * len(xs), ch * len(ys)
    width = max(pad_l + len(zs) * (pw + gap) + 110, 640)
    canvas = np.full((pad_t + ph + pad_b, width, 3), 255, np.uint8)
    cv2.putText(canvas, title, (8, 20), font, 0.5, 0, 1, cv2.LINE_AA)
    cv2.putText(canvas, "distance per cycle [mm]; grey: unstable, crumpled or dragged", (8, 40), font, 0.42, 0, 1,
                cv2.LINE_AA)
    for p, z in enumerate(zs):
        x0 = pad_l + p * (pw + gap)
        for i in np.flatnonzero(np.isclose(pts["amplitude"], z)):
            c, r = np.searchsorted(xs, pts["wavelength"][i]), len(ys) - 1 - np.searchsorted(ys, pts["closest_approach"][i])
            colour = _colour(np.array([(per[i] - lo) / (hi - lo)]))[0] if valid[i] else np.array([160, 160, 160])
            canvas[pad_t + r * ch:pad_t + (r + 1) * ch, x0 + c * cw:x0 + (c + 1) * cw] = colour
        cv2.putText(canvas, f"a = {1e3 * z:.1f} mm", (x0, pad_t - 6), font, 0.42, 0, 1, cv2.LINE_AA)
        for c in range(0, len(xs), max(1, int(np.ceil(34 / cw)))):
            cv2.putText(canvas, f"{1e3 * xs[c]:.0f}", (x0 + c * cw, pad_t + ph + 14), font, 0.35, 0, 1, cv2.LINE_AA)
        cv2.putText(canvas, "w [mm]", (x0, pad_t + ph + 34), font, 0.4, 0, 1, cv2.LINE_AA)
    for r in range(0, len(ys), max(1, int(np.ceil(14 / ch)))):
        y = ys[len(ys) - 1 - r]
        cv2.putText(canvas, f"{1e3 * y:.1f}", (pad_l - 40, pad_t + r * ch + ch // 2 + 4), font, 0.35, 0, 1,
                    cv2.LINE_AA)
    cv2.putText(canvas, "h [mm]", (4, pad_t + ph + 34), font, 0.4, 0, 1, cv2.LINE_AA)
    bx = width - 90  # colour bar: lo at the bottom, hi at the top
    bar = _colour(np.linspace(1, 0, ph)[:, None].repeat(16, axis=1))
    canvas[pad_t:pad_t + ph, bx:bx + 16] = bar
    for v, y in ((hi, pad_t + 8), (0.5 * (lo + hi), pad_t + ph // 2 + 4), (lo, pad_t + ph)):
        cv2.putText(canvas, f"{v:.2f}", (bx + 20, y), font, 0.38, 0, 1, cv2.LINE_AA)
    path = Path(path)
    cv2.imwrite(str(path), canvas)
    return path


def _check(args):
    """Every option, by the rules generate applies (warpworm.data.config), before any work; returns (grid, params)."""

    grid = parse_grid(args.grid)
    base = material_params(args.material) if args.material else None
    check_minimum(cycles=(args.cycles, 1), workers=(args.workers, 1), top=(args.top, 0))
    if args.max_ratio is not None and not 0 < args.max_ratio <= 1:
        raise ValueError(f"--max-ratio: got {args.max_ratio}; expected a segment ratio in (0, 1]")
    if Path(args.out).exists() and not Path(args.out).is_dir():
        raise ValueError(f"--out: got '{args.out}'; expected a folder (it is a file)")
    params = gaits.preset_params(args.gait, args.backward, base=base, magnet_model=args.magnet_model,
                                 **parse_overrides(args.set))
    n = int(np.prod([len(v) for v in grid.values()]))

    check_worm_params(replace(params, **{k: v for k, v in grid_points(grid).items()}))
    return grid, params, n


def main(args) -> int:
    quiet_warp()
    try:
        grid, params, n = _check(args)
    except ValueError as e:
        return refuse(e)

    first_run_notice()
    workers = args.workers or os.cpu_count() or 1
    print(f"search-gait {args.gait}{' backward' if args.backward else ''}: {n} grid points x {args.cycles} cycles "
          f"on {min(workers, n)} thread(s)")
    t0 = time.perf_counter()
    res = search_gait(params, grid, args.cycles, workers=workers, max_ratio=args.max_ratio)
    wall = time.perf_counter() - t0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pts = full_points(res, params)
    write_csv(out / "search.csv", res)
    write_heatmap(out / "heatmap.png", res, pts, f"search-gait {args.gait}{' backward' if args.backward else ''}: "
                  f"{n} points x {args.cycles} cycles")
    m = res["metrics"]
    print(f"  {wall:.1f} s wall; {int(res['valid'].sum())} of {n} worlds stable and unfolded "
          f"({int(m['unstable'].sum())} unstable, {int(m['crumpled'].sum())} of them crumpled)")
    print("  rank      w [mm]   a [mm]   h [mm]   mm/cycle  ratio min (tail->head)     swing [deg]  end hold")
    for r, i in enumerate(res["order"][:args.top]):
        hold = m["end_hold_ratio"][i]
        hold = float(np.nanmax(hold)) if np.isfinite(hold).any() else float("nan")
        print(f"  {r + 1:4d}  {1e3 * pts['wavelength'][i]:8.1f} {1e3 * pts['amplitude'][i]:8.1f} "
              f"{1e3 * pts['closest_approach'][i]:8.1f}  {1e3 * res['per_cycle_m'][i]:9.2f}  "
              f"{np.round(m['deformation_ratio_min'][i], 2).tolist()}  {m['crease_angle_range_deg'][i]:9.1f}  "
              f"{'-' if np.isnan(hold) else f'{hold:.2f}':>8}")
    best = None if not len(res["order"]) else {k: float(pts[k][res["order"][0]]) for k, _ in AXES}
    summary = {"gait": args.gait, "backward": bool(args.backward), "grid": args.grid, "cycles": args.cycles,
               "max_ratio": args.max_ratio, "points": n, "crumpled": int(m["crumpled"].sum()),
               "unstable": int(m["unstable"].sum()), "valid": int(res["valid"].sum()), "wall_time_s": wall,
               "best": best, "best_per_cycle_m": float(res["per_cycle_m"][res["order"][0]]) if best else None}
    strict_json.write(out / "search.json", summary, indent=1)
    print(f"  best: {best}")
    print(f"  wrote {out / 'search.csv'}, {out / 'heatmap.png'}, {out / 'search.json'}")
    return 0
