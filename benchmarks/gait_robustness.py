#!/usr/bin/env python
"""Robustness of gait settings: is a (w, a, h) point stable whatever the numerics and the magnet model?

Every grid point is one world of one batch; the batch runs ``--cycles`` EPM cycles in 8 settings: magnet model
(analytic, dipoles) x direction (forward, backward) x numerics (the wrench every 4 ms with two 2 ms substeps,
the default; every 2 ms with two 1 ms substeps). A point is *robust* when no setting crumples or explodes it. This is how the gait
presets were chosen (warpworm/physics/gaits.py GAIT_PRESETS): a setting that crumples in one of these runs sits on the
crumple edge, where a change of float rounding decides the outcome.

Usage::

    python benchmarks/gait_robustness.py peristaltic --w 20,24,28 --a 30,40,50 --h 16,17,18,20 [--cycles 3]
        [--set FIELD=VALUE ...] [--out benchmarks/results/gait_robustness_peristaltic.json]

Prints one row per point (robust, |displacement| [mm] and the smallest segment ratio in each setting) and writes
the JSON.
"""

from __future__ import annotations

import argparse
import itertools
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_runs import run_gait
from warpworm.physics import gaits
from warpworm.physics.params import parse_overrides

SETTINGS = [(mm, back, dt, sub) for mm in ("analytic", "dipoles") for back in (False, True)
            for dt, sub in ((4e-3, 2), (2e-3, 2))]


def main(argv=None) -> int:
    from gait_grid import add_grid_arguments, grid_from_arguments

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("gait", choices=gaits.GAITS)
    add_grid_arguments(ap)
    ap.add_argument("--cycles", type=int, default=3)
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="override a WormParams field in every setting; a friction_backward_ratio r is mirrored in "
                         "the backward settings (ratio 1/r on r times mu_static and mu_kinetic: the same skin "
                         "facing the other way)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    try:
        overrides = parse_overrides(args.set)
    except ValueError as e:
        raise SystemExit(str(e)) from None
    gridded = sorted(set(overrides) & {"wavelength", "amplitude", "closest_approach"})
    if gridded:
        raise SystemExit(f"--set {gridded[0]}: the grid (--w, --a, --h) sets it; give it there")
    quiet_warp()
    pts_m = np.array(list(itertools.product(*grid_from_arguments(args).values())))  # rows (w, a, h) [m]
    pts = np.round(pts_m * 1e3, 9)  # the same rows in mm, for the table and the JSON
    rows = []
    for mm, back, dt, sub in SETTINGS:
        p = replace(gaits.preset_params(args.gait, back, **overrides), magnet_model=mm, wavelength=pts_m[:, 0],
                    amplitude=pts_m[:, 1], closest_approach=pts_m[:, 2])
        r_skin = float(overrides.get("friction_backward_ratio", 1.0))
        if back and r_skin != 1.0:  # the mirror image of the forward worm's skin
            p = replace(p, friction_backward_ratio=1.0 / r_skin, mu_static=r_skin * float(p.mu_static),
                        mu_kinetic=r_skin * float(p.mu_kinetic))
        r = run_gait(p, len(pts), args.cycles, dt=dt, substeps=sub, fps=50, save_worlds=0)
        rows.append(dict(magnet_model=mm, backward=back, dt=dt, substeps=sub, unstable=r["unstable"].tolist(),
                         displacement_mm=(np.abs(r["displacement_m"]) * 1e3).tolist(),
                         ratio_min=np.min(r["metrics"]["deformation_ratio_min"], axis=1).tolist()))
        print(f"{mm:8s} {'backward' if back else 'forward '} dt {dt * 1e3:.0f} ms: "
              f"{int(r['unstable'].sum())} of {len(pts)} unstable", flush=True)
    robust = ~np.any([r["unstable"] for r in rows], axis=0)
    print(f"\n{'w a h [mm]':>16s}  robust  |displacement| [mm] per setting / smallest segment ratio per setting")
    for i, pt in enumerate(pts):
        d = " ".join(f"{r['displacement_mm'][i]:5.1f}" for r in rows)
        q = " ".join(f"{r['ratio_min'][i]:.3f}" for r in rows)
        print(f"{pt[0]:5g}{pt[1]:5g}{pt[2]:5g}  {'yes' if robust[i] else 'NO ':6s}  {d}  /  {q}")  # 5.5 stays 5.5
    out = Path(args.out or Path(__file__).parent / "results" / f"gait_robustness_{args.gait}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"gait": args.gait, "cycles": args.cycles, "points_mm": pts.tolist(),
                               "robust": robust.tolist(), "settings": rows}, indent=1))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
