#!/usr/bin/env python
"""Cycle by cycle: does a gait deform the worm in *every* cycle, or only while the EPM starts where it was placed?

Every (w, a, h) grid point is one world of one batch (``warpworm.analysis.gait_search.search_gait``, split over the cores);
each runs ``--cycles`` EPM cycles and is measured per cycle (``warpworm.analysis.gait_metrics``):

- ``ratio``: the smallest anterior segment ratio of the cycle (the two segment pairs ahead of the centre, tail →
  head, behind it backward; every pair for omega), and in the summary the smallest of any pair;
- ``hold``: the end-hold ratio of its contraction (0 one end held, 1 both ends slid together);
- ``disp``: the distance it moved [mm];
- ``place``: where the EPM passed at its closest approach, from the centre IPM over the centre-to-head spacing
  (the presets start at ``gaits.GAIT_PLACEMENT``; with ``--backward`` its sign is flipped, so that +0.4 is 0.4 of
  the way toward the tail, the backward gaits' side).

It prints one row per stable point (best later-cycle ratio first), then the ranges over the grid: the first cycle
(placed by the path's origin) against the later ones (placed by where the worm's own motion left it). This is the
measurement behind docs/dynamics.md, "Every cycle, or the first".

Usage::

    python benchmarks/gait_cycles.py peristaltic --w 2,4,8,16,24,32 --a 30,45,60 --h 4.5,5,6,8 [--cycles 5]
        [--set hinge_stiffness=0.0025 ...] [--backward] [--out benchmarks/results/gait_cycles_peristaltic.json]
"""

from __future__ import annotations

import json
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_search import search_gait
from warpworm.physics import gaits
from warpworm.physics.params import parse_overrides


def main(argv=None) -> int:
    from gait_grid import gait_grid_parser, grid_from_arguments

    ap = gait_grid_parser(__doc__, cycles_default=5, name="gait_cycles")
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override a WormParams field, e.g. --set hinge_stiffness=0.0025")
    ap.add_argument("--top", type=int, default=12)
    args = ap.parse_args(argv)
    if args.cycles < 2:
        raise SystemExit(f"--cycles: {args.cycles}; expected at least 2 (the first cycle against the later ones)")
    quiet_warp()

    grid = grid_from_arguments(args)
    params = gaits.preset_params(args.gait, backward=args.backward, magnet_model="analytic")
    params = replace(params, **parse_overrides(args.set))
    # the plate must not be thicker than the closest approach the grid asks for (h is measured from the worm's base)
    params = replace(params, support_thickness=min(float(params.support_thickness), float(grid["closest_approach"].min())))
    res = search_gait(params, grid, args.cycles, workers=args.workers)
    pts, m = res["points"], res["metrics"]
    sign = -1.0 if args.backward else 1.0
    cyc = np.asarray(m["cycle_ratio_min"])  # (N, C, 4)
    anterior = cyc.min(axis=2) if args.gait == "omega" else (cyc[:, :, :2] if args.backward else cyc[:, :, 2:]).min(axis=2)
    stable = ~np.asarray(m["unstable"]).astype(bool)
    rows = []
    for i in np.flatnonzero(stable):
        rows.append({
            "w_mm": 1e3 * pts["wavelength"][i], "a_mm": 1e3 * pts["amplitude"][i], "h_mm": 1e3 * pts["closest_approach"][i],
            "ratio": anterior[i].round(4).tolist(),
            "any_segment_ratio": cyc[i].min(axis=1).round(4).tolist(),
            "hold": np.asarray(m["end_hold_ratio"][i]).round(3).tolist(),
            "disp_mm": (1e3 * sign * np.asarray(m["cycle_displacement_m"][i])).round(2).tolist(),
            "place": (sign * np.asarray(m["approach_placement"][i])).round(3).tolist(),
        })
    rows.sort(key=lambda r: max(r["ratio"][1:]))
    print(f"{args.gait}{' backward' if args.backward else ''}: {len(rows)} of {len(stable)} points stable, "
          f"{args.cycles} cycles; per cycle: anterior ratio | end hold | distance [mm] | EPM placement")
    for r in rows[: args.top]:
        print(f"  w {r['w_mm']:4.1f} a {r['a_mm']:4.1f} h {r['h_mm']:4.1f} | "
              f"{' '.join(f'{v:.3f}' for v in r['ratio'])} | {' '.join(f'{v:.2f}' for v in r['hold'])} | "
              f"{' '.join(f'{v:+.1f}' for v in r['disp_mm'])} | {' '.join(f'{v:+.2f}' for v in r['place'])}")
    summary = {}
    if rows:
        first = np.array([r["ratio"][0] for r in rows])
        later = np.array([max(r["ratio"][1:]) for r in rows])
        any_later = np.array([max(r["any_segment_ratio"][1:]) for r in rows])
        place_first = np.array([r["place"][0] for r in rows])
        place_last = np.array([r["place"][-1] for r in rows])
        summary = {"first_cycle_ratio": [float(first.min()), float(first.max())],
                   "later_cycles_worst_ratio": [float(later.min()), float(later.max())],
                   "points_every_cycle_le_0_85": int(np.sum(np.maximum(first, later) <= 0.85)),
                   "later_cycles_worst_any_segment_ratio": [float(any_later.min()), float(any_later.max())],
                   "first_placement": [float(place_first.min()), float(place_first.max())],
                   "last_placement": [float(place_last.min()), float(place_last.max())]}
        print(f"first cycle: anterior ratio {first.min():.3f}–{first.max():.3f}, EPM placement "
              f"{place_first.min():+.2f}…{place_first.max():+.2f}")
        print(f"cycles 2–{args.cycles}: worst anterior ratio {later.min():.3f}–{later.max():.3f}, last placement "
              f"{place_last.min():+.2f}…{place_last.max():+.2f}; points at <= 0.85 in every cycle: "
              f"{summary['points_every_cycle_le_0_85']} of {len(rows)} (any segment, cycles 2–{args.cycles}: "
              f"{any_later.min():.3f}–{any_later.max():.3f})")
    out = Path(args.out) if args.out else Path(__file__).resolve().parent / "results" / f"gait_cycles_{args.gait}.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"gait": args.gait, "backward": args.backward, "cycles": args.cycles,
                               "set": args.set, "summary": summary, "rows": rows}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
