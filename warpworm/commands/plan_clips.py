"""``warpworm plan-clips --fit NAMES [--range NAME=LO:HI ...]``: before filming, choose the EPM paths (gait, w, a, h,
cycles, direction; several clips if needed) whose tracks pin the parameters to calibrate for any worm in the expected
ranges (:mod:`warpworm.analysis.plan`: every candidate path x design worm x parameter perturbation one world of one
batch, Fisher information per clip, greedy over the worst design worm). Writes ``plan.json``; film its clips, track
each (``warpworm track``) and fit them jointly: ``warpworm fit-track T1.csv T2.csv ... --plan plan.json``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from warpworm.analysis import fit_track as FT
from warpworm.analysis import plan as P
from warpworm.commands.common import refuse

HELP = "choose the EPM paths to film so that a track pins the parameters to calibrate (batched Fisher information)"


def add_arguments(parser) -> None:
    parser.add_argument("--fit", default="hinge_stiffness,mu_static,epm_moment",
                        help="parameters to calibrate (default: %(default)s)")
    parser.add_argument("--range", action="append", default=[], metavar="NAME=LO:HI",
                        help="the worm's expected range of a parameter (default: production's, "
                             "dataset_configs/production.yaml: hinge_stiffness 0.003:0.01, mu_static 0.2:0.4, "
                             "epm_moment 3:4)")
    parser.add_argument("--gaits", default="peristaltic,omega,inchworm")
    parser.add_argument("--w-scales", default="0.75,1,1.25", help="wavelength x the preset's (default %(default)s)")
    parser.add_argument("--a-scales", default="0.75,1,1.3", help="amplitude x the preset's (default %(default)s)")
    parser.add_argument("--h-scales", default="0.95,1.3", help="closest approach x the preset's (default %(default)s)")
    parser.add_argument("--cycles", default="1,2", help="clip lengths in EPM cycles (default %(default)s)")
    parser.add_argument("--backward", action="store_true", help="also candidate clips driven toward -x")
    parser.add_argument("--max-clips", type=int, default=3)
    parser.add_argument("--margin", type=float, default=0.5,
                        help="stop adding clips once every design worm's predicted half-width is within this "
                             "fraction of the tolerance (default 0.5: room for the tracker's bias and the global "
                             "profile's wider ranges)")
    parser.add_argument("--max-nonlinearity", type=float, default=0.5,
                        help="refuse a clip whose forward and backward differences disagree by more than this "
                             "fraction of their sum at any design worm (a track that jumps; default 0.5)")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default="plan.json")
    parser.add_argument("--fisher-out", default=None, metavar="NPZ",
                        help="also save every candidate's Fisher matrices (C, D, p, p), ok, nonlinearity and the "
                             "design worms (for analyses of clip combinations: docs/calibration.md 3a.)")


def _floats(text, key):
    try:
        v = [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        v = []
    if not v or any(x <= 0 for x in v):
        raise ValueError(f"{key}: got {text!r}; expected positive numbers separated by ','")
    return v


def main(args) -> int:
    try:
        names = FT.parse_fit(args.fit)
        ranges = dict(P.PRODUCTION_RANGES)
        for item in args.range:
            k, _, v = item.partition("=")
            lo, _, hi = v.partition(":")
            try:
                lo, hi = float(lo), float(hi)
            except ValueError:
                lo = hi = float("nan")
            if k not in FT.fittable_fields() or not (0 < lo < hi):
                raise ValueError(f"--range {item!r}: expected NAME=LO:HI with 0 < LO < HI and NAME a fittable field")
            ranges[k] = (lo, hi)
        missing = [n for n in names if n not in ranges]
        if missing:
            raise ValueError(f"--range: none for {missing}; expected --range NAME=LO:HI for every --fit parameter")
        gaits = [g for g in args.gaits.split(",") if g]
        if not gaits or any(g not in ("peristaltic", "omega", "inchworm") for g in gaits):
            raise ValueError(f"--gaits: got {args.gaits!r}; expected peristaltic, omega, inchworm (comma-separated)")
        clips = P.candidate_paths(gaits, _floats(args.w_scales, "--w-scales"), _floats(args.a_scales, "--a-scales"),
                                  _floats(args.h_scales, "--h-scales"), _floats(args.cycles, "--cycles"),
                                  (False, True) if args.backward else (False,))
        if args.max_clips < 1 or not args.margin > 0:
            raise ValueError(f"--max-clips/--margin: got {args.max_clips}/{args.margin}; expected >= 1 / > 0")
    except ValueError as exc:
        return refuse(exc)
    print(f"planning {names} over {len(clips)} candidate clips for worms in "
          + ", ".join(f"{n} {ranges[n][0]:g}..{ranges[n][1]:g}" for n in names))
    res = P.plan(names, {n: ranges[n] for n in names}, clips=clips, max_clips=args.max_clips, margin=args.margin,
                 device=args.device, log=print, max_nonlinearity=args.max_nonlinearity)
    print("\n".join(P.report_lines(res)))
    out = {"names": names, "ranges": {n: list(ranges[n]) for n in names},
           "clips": [res["clips"][i] for i in res["chosen"]],
           "predicted_half_width_rel": np.expm1(res["plan_half"]).max(axis=0).tolist(),
           "tolerance": res["tolerance"].tolist(), "worst_after_each_clip": res["worst"].tolist(),
           "design_worms": res["worms"].tolist(),
           "candidates": [{**c, "usable": bool(ok), "nonlinearity": float(np.max(nl)),
                           "half_width_rel": np.expm1(h).max(axis=0).tolist()}
                          for c, ok, nl, h in zip(res["clips"], res["ok"].all(axis=1), res["nonlin"], res["half"])]}
    Path(args.out).write_text(json.dumps(out, indent=1))
    if args.fisher_out:
        np.savez(args.fisher_out, fisher=res["fisher"], ok=res["ok"], nonlin=res["nonlin"], worms=res["worms"],
                 names=np.array(names), tolerance=res["tolerance"], clips=json.dumps(res["clips"]))
    print(f"wrote {args.out}: film its {len(out['clips'])} clip(s), track each, then "
          f"warpworm fit-track T1.csv ... --plan {args.out} --fit {','.join(names)}")
    return 0
