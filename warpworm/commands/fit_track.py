"""``warpworm fit-track track.csv --gait G [--backward] --path w=,a=,h= --fit NAMES [--budget WORLDS]``: fit worm
parameters to a band track (:mod:`warpworm.analysis.fit_track`): CMA-ES, every candidate a world of one batch.

Prints the fit, the residual, each parameter's acceptable range (every evaluated world, the global profile's
included, within a chi-square rise of 3.84 at the track's noise) and which ones the track cannot pin down (a range
beyond the parameter's tolerance); writes ``fit.png`` (Fig. 11-like: measured vs fitted ratios and displacement), ``fit.yaml`` (the fitted
parameters as a config fragment; the ``simulate --set`` form in its header) and ``fit.json`` into ``--out``.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from warpworm.analysis import fit_track as FT
from warpworm.analysis import track as T
from warpworm.commands.common import refuse
from warpworm.data import export_json as strict_json
from warpworm.data.config import ConfigError
from warpworm.physics import gaits
from warpworm.physics.param_specs import check_worm_params
from warpworm.physics.params import WormParams

HELP = "fit worm parameters (k_alpha, friction, EPM moment, ...) to a band track from 'warpworm track' (batched CMA-ES)"


def add_arguments(parser) -> None:
    parser.add_argument("track", metavar="TRACK.csv", nargs="+",
                        help="a track written by 'warpworm track'; several clips of one worm are fitted jointly")
    parser.add_argument("--gait", default=None, metavar="GAIT[,GAIT…]",
                        help="peristaltic, omega or inchworm: one for every track, or one per track (comma-separated)")
    parser.add_argument("--backward", action="store_true", help="the worm was driven toward -x (every track)")
    parser.add_argument("--path", default=None, metavar="w=…,a=…,h=…[;…]",
                        help="the EPM path of the video [m]: wavelength, amplitude, closest approach (default: the "
                             "gait preset's); one for every track or one per track, separated by ';'")
    parser.add_argument("--plan", default=None, metavar="PLAN.json",
                        help="the clips of 'warpworm plan-clips' (gait, path, direction of each, in the order the "
                             "tracks are given), instead of --gait/--path/--backward")
    parser.add_argument("--fit", default="hinge_stiffness,valley_bar_stiffness,mu_static,epm_moment",
                        help="WormParams fields to fit, comma-separated (default: %(default)s)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="a known WormParams value (e.g. a measured a, l0, or the magnet moment from calibrate)")
    parser.add_argument("--budget", type=int, default=96, help="simulated worlds for the search (default 96)")
    parser.add_argument("--popsize", type=int, default=None, help="worlds per CMA-ES generation (default 8+)")
    parser.add_argument("--refine", type=int, default=4,
                        help="Levenberg-Marquardt steps after the search, one batch of 2p+1 worlds each (default 4)")
    parser.add_argument("--profile", type=int, default=6, metavar="STEPS",
                        help="re-fit steps of the global profile (every parameter held over its whole range, the others "
                             "re-fitted; one batch a step; 0: ranges from the search's candidates only; default 6)")
    parser.add_argument("--spread", type=float, default=3.0,
                        help="search within preset / spread .. preset * spread (default 3)")
    parser.add_argument("--magnet-model", choices=["dipoles", "analytic"], default="dipoles")
    parser.add_argument("--camera", default=None, metavar="CAMERA.json",
                        help="the track's camera (default: TRACK.json written by 'warpworm track' next to the CSV; "
                             "'none': band centres seen from above)")
    parser.add_argument("--render-scale", type=float, default=0.5,
                        help="resolution of the simulation's renders relative to the camera's (default 0.5)")
    parser.add_argument("--seed", type=int, default=0, help="CMA-ES seed")
    parser.add_argument("--device", default="cpu", help="Warp device (default cpu)")
    parser.add_argument("--out", default="fit_out", help="output folder (default ./fit_out)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary only")


def _base_params(args, gait, backward, path_fields):
    """The gait preset with the video's path, magnet model and known values (checked by the config's rules)."""

    base = gaits.preset_params(gait, backward, **path_fields)
    base = replace(base, magnet_model=args.magnet_model)
    known = {}
    names = {f for f in WormParams.__dataclass_fields__}
    for item in args.set:
        k, _, v = item.partition("=")
        if k not in names:
            raise ValueError(f"--set {item!r}: unknown field {k!r}; expected a WormParams field")
        try:
            known[k] = float(v)
        except ValueError:
            raise ValueError(f"--set {item!r}: got {v!r}; expected a number") from None
    base = replace(base, **known)

    check_worm_params(base)
    return base, known


def _clips(args, n: int) -> list[tuple[str, bool, dict]]:
    """(gait, backward, path fields) of each of the ``n`` tracks, from --plan or --gait/--path/--backward."""

    if args.plan:
        try:
            plan = json.loads(Path(args.plan).read_text())
            clips = plan["clips"]
        except (OSError, ValueError, KeyError, TypeError):
            raise ValueError(f"--plan {args.plan}: expected the plan.json that 'warpworm plan-clips' wrote") from None
        if len(clips) != n:
            raise ValueError(f"--plan {args.plan}: {len(clips)} clips for {n} tracks; expected one track per clip, "
                             "in the plan's order")
        return [(c["gait"], bool(c["backward"]), {"wavelength": float(c["wavelength"]),
                                                   "amplitude": float(c["amplitude"]),
                                                   "closest_approach": float(c["closest_approach"])}) for c in clips]
    gaits_ = [g.strip() for g in (args.gait or "").split(",") if g.strip()]
    if not gaits_:
        raise ValueError("--gait: missing; expected peristaltic, omega or inchworm (or --plan PLAN.json)")
    bad = [g for g in gaits_ if g not in ("peristaltic", "omega", "inchworm")]
    paths = (args.path or "").split(";")
    if bad or len(gaits_) not in (1, n) or len(paths) not in (1, n):
        raise ValueError(f"--gait/--path: got {len(gaits_)} gait(s) {bad or ''} and {len(paths)} path(s) for {n} "
                         "track(s); expected peristaltic/omega/inchworm, one for all tracks or one per track")
    return [(gaits_[i % len(gaits_)], bool(args.backward), FT.parse_path(paths[i % len(paths)] or None))
            for i in range(n)]


def main(args) -> int:
    try:
        if args.budget < 1 or (args.popsize is not None and args.popsize < 2) or args.refine < 0 or args.profile < 0:
            raise ValueError(f"--budget/--popsize/--refine/--profile: got {args.budget}/{args.popsize}/{args.refine}/"
                             f"{args.profile}; expected >= 1 / >= 2 / >= 0 / >= 0")
        if not args.spread > 1 or not 0 < args.render_scale <= 1:
            raise ValueError(f"--spread/--render-scale: got {args.spread}/{args.render_scale}; expected > 1 / (0, 1]")
        try:
            import cma  # noqa: F401  (checked before any work)
        except ImportError:
            raise ValueError("fit-track: the cma package is missing; expected it installed (pip install "
                             "'warpworm[calibrate]')") from None
        names = FT.parse_fit(args.fit)
        clips = _clips(args, len(args.track))
        tracks, metas, bases = [], [], []
        for path, (gait, backward, path_fields) in zip(args.track, clips):
            if not Path(path).is_file():
                raise ValueError(f"TRACK: got {path!r}; expected a track.csv written by 'warpworm track'")
            track = T.read_csv(path)
            if int(track["seen"].all(axis=1).sum()) < 3:
                raise ValueError(f"TRACK {path}: fewer than 3 frames with all bands; expected a longer track")
            meta = None
            cam_arg = args.camera or (str(T.meta_path(path)) if T.meta_path(path).is_file() else "none")
            if cam_arg != "none":
                meta = T.read_meta(cam_arg) if "height_m" in Path(cam_arg).read_text() else None
                if meta is None:
                    raise ValueError(f"--camera {cam_arg}: expected the TRACK.json that 'warpworm track' wrote "
                                     "(camera, image size, plane height)")
                track["ref"] = meta["ref"]
            else:
                track["ref"] = int(np.nonzero(track["seen"].all(axis=1))[0][0])
            base, known = _base_params(args, gait, backward, path_fields)
            tracks.append(track)
            metas.append(meta)
            bases.append(base)
        gait, backward, path_fields = clips[0]
        track, meta, base = tracks[0], metas[0], bases[0]
    except (ValueError, ConfigError) as exc:
        return refuse(exc)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    log = None if args.json else print
    if log:
        log(f"fitting {names} to {' + '.join(str(len(t['time'])) for t in tracks)} frames of "
            f"{' + '.join(g + (' backward' if b else '') for g, b, _ in clips)} "
            f"({'through the track camera' if meta else 'band centres from above'}), budget {args.budget} worlds")
    res = FT.fit(tracks if len(tracks) > 1 else track, bases if len(bases) > 1 else base, names, budget=args.budget, popsize=args.popsize, spread=args.spread, seed=args.seed,
                 meta=metas if len(metas) > 1 else meta, log=log, refine=args.refine, profile=args.profile, render_scale=args.render_scale, device=args.device)
    frag = FT.write_fragment(out / "fit.yaml", gait, backward, {**path_fields, **known}, res, base)
    plot_note = ""
    try:
        FT.plot_fit(out / "fit.png", track, res, title=f"{gait}: measured (red) vs fitted (blue)"
                    + (f" (clip 1 of {len(tracks)})" if len(tracks) > 1 else ""))
    except ImportError:
        plot_note = " (no fit.png: install the plots extra, pip install 'warpworm[plots]')"
    summary = {"names": names, "value": res["value"].tolist(), "preset": res["base"].tolist(),
               "range_rel": res["range_rel"].tolist(), "at_bound": res["at_bound"].tolist(),
               "tolerance": res["tolerance"].tolist(), "pinned": res["pinned"].tolist(),
               "verdict": [str(v) for v in res["verdict"]], "clips": len(tracks),
               "sigma_rel": [float(s) for s in res["sigma_rel"]],
               "cost": float(res["cost"]), "rms_ratio": float(res["rms_ratio"]),
               "rms_displacement_m": float(res["rms_disp_m"]), "weakest": res["weakest"].tolist(),
               "moved": bool(res["moved"]), "weakest_sigma": float(res["weakest_sigma"]),
               "threshold_dchi2": float(res["threshold"]), "worlds": res["worlds"],
               "wall_s": res["wall_s"], "files": [str(out / f) for f in ("fit.yaml", "fit.png", "fit.json")]}
    strict_json.write(out / "fit.json", summary, indent=1)  # inf (an unidentifiable sigma) as null
    if args.json:
        print(strict_json.dumps(summary))
        return 0
    print("\n".join(FT.report_lines(res)))
    print(f"{res['worlds']} worlds in {res['wall_s']:.1f} s; wrote {out}/fit.yaml, fit.json, fit.png{plot_note}")
    print(frag.splitlines()[1])
    return 0
