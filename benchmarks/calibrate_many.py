"""Calibration from images over many worms (issue #41): worms drawn across production's ranges of k_alpha, mu_s and
the EPM moment (dataset_configs/production.yaml: k_alpha loguniform 0.003-0.01 N m/rad, mu_s uniform 0.2-0.4, EPM
moment uniform 3-4 A m^2; every other parameter at the preset, analytic magnets), each filmed in the clips of a plan
(``warpworm plan-clips``'s plan.json), every clip path-traced by Mitsuba 3 under its own randomized hard light and
tilted camera with lens distortion (:mod:`warpworm.analysis.footage`), the harshest sensor noise added, tracked
(:mod:`warpworm.analysis.track`) and all clips of a worm fitted jointly (:func:`warpworm.analysis.fit_track.fit`,
through each clip's camera). Prints per worm and the table: recovery error and verdicts per parameter.

    warpworm plan-clips --max-clips 2 --out plan.json
    nice -n 10 python benchmarks/calibrate_many.py --plan plan.json --worms 20 --size 384x288 --json many.jsonl
    python benchmarks/calibrate_many.py --table many.jsonl
    nice -n 10 python benchmarks/calibrate_many.py --plan plan.json --worms 3 --noise-seed 1 ... --json noise.jsonl
    python benchmarks/calibrate_many.py --stability many.jsonl noise.jsonl    # do verdicts flip on re-rendering?
    python benchmarks/calibrate_many.py --stability many.jsonl noise1.jsonl noise2.jsonl  # and two-take verdicts?

Numbers: docs/calibration.md ("Many worms").
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time

import numpy as np

NAMES = ["hinge_stiffness", "mu_static", "epm_moment"]
TOL = (0.05, 0.05, 0.03)
RANGES = {"hinge_stiffness": (0.003, 0.01), "mu_static": (0.2, 0.4), "epm_moment": (3.0, 4.0)}
"""Production's ranges of NAMES (dataset_configs/production.yaml), as :func:`draw_worm` draws them."""


def draw_worm(rng: np.random.Generator) -> np.ndarray:
    """One worm across production's ranges: k_alpha loguniform 0.003-0.01, mu_s uniform 0.2-0.4, EPM 3-4 A m^2."""
    return np.array([np.exp(rng.uniform(np.log(0.003), np.log(0.01))), rng.uniform(0.2, 0.4), rng.uniform(3.0, 4.0)])


def film_clip(clip: dict, truth: np.ndarray, rng: np.random.Generator, *, size=(256, 192), spp=8, seed=0):
    """(track, meta, base) of one clip of the worm ``truth`` (NAMES' values): simulated, path-traced, tracked."""
    from warpworm.analysis import fit_track as FT
    from warpworm.analysis import footage as FO
    from warpworm.analysis import plan as P
    from warpworm.analysis import track as T
    from warpworm.physics import gaits

    W, H = size
    base = gaits.preset_params(clip["gait"], bool(clip["backward"]), magnet_model="analytic",
                               wavelength=float(clip["wavelength"]), amplitude=float(clip["amplitude"]),
                               closest_approach=float(clip["closest_approach"]))
    times = np.arange(int(round(clip["cycles"] * P.FPS)) + 1) / P.FPS
    fr = FT.simulate_frames(FT.candidate_params(base, NAMES, truth[None]), 1, times)
    if fr["unstable"][0]:
        raise RuntimeError("the planted worm's simulation went unstable")
    look = FO.random_look(rng)
    x = np.asarray(fr["positions"])[:, 0, :, 0]  # the worm's path, framed as a camera operator would
    cam = FO.random_camera(rng, W, H, centre=(0.5 * (x.min() + x.max()), 0.0, 0.0), span=float(x.max() - x.min()))
    F = len(times)
    rgb, truth_px = FO.pathtraced_band_video(fr, fr["model"], cam, W, H, look, spp=spp,
                                             sensor_values=T.harshest_sensor(F), seed=seed)
    h = T.default_band_height(base)
    tr = T.track(rgb, cam, height=h, fps=P.FPS)
    err_px = np.linalg.norm(tr["pixel"] - truth_px, axis=-1)
    meta = {"camera": cam, "width": W, "height": H, "height_m": h}
    return tr, meta, base, err_px


def bench_hinge_stiffness(test: str, k_true: float, base, rng: np.random.Generator, noise: float) -> dict:
    """k_alpha as a bench test of the worm measures it: its ``test`` curve at ``k_true`` with ``noise`` on every force
    (:func:`warpworm.analysis.material_fit.simulated_table`, 8 load steps), fitted as ``warpworm experiment --fit``
    fits a table (24 + 16 candidates) with every other parameter at ``base``. Returns the fit's dict
    (``hinge_stiffness``, ``interval_rel``, ...)."""
    from warpworm.analysis import material_fit as mf

    d, f = mf.simulated_table(test, k_true, base=base, noise=noise, rng=rng)
    return mf.fit_hinge_stiffness(test, d, f, base=base)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--plan", required=True, help="plan.json of warpworm plan-clips (its clips are filmed)")
    ap.add_argument("--worms", type=int, default=20)
    ap.add_argument("--first", type=int, default=0, help="index of the first worm (draws are per index)")
    ap.add_argument("--size", default="256x192")
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--budget", type=int, default=48, help="CMA-ES worlds after the plan's design worms")
    ap.add_argument("--refine", type=int, default=4)
    ap.add_argument("--profile", type=int, default=3)
    ap.add_argument("--render-scale", type=float, default=1.0)
    ap.add_argument("--noise-seed", type=int, default=0,
                    help="added to every image's noise seeds (sensor noise and the path tracer's sampler): the same "
                         "worms, lights and cameras re-rendered, to measure whether the verdicts flip on noise")
    ap.add_argument("--known", action="append", default=[], choices=NAMES,
                    help="a parameter held at its planted value in the fit (measured elsewhere, e.g. k_alpha from a "
                         "compression curve); repeatable")
    ap.add_argument("--known-error", type=float, default=0.0,
                    help="relative error of the --known values handed to the fit (e.g. 0.05: k_alpha 5 %% high, as "
                         "an imperfect compression calibration would give)")
    ap.add_argument("--known-from", choices=["compression", "flexure"], default=None,
                    help="hold k_alpha at what a bench test of the planted worm gives: its compression (or 3-point "
                         "flexure) curve simulated, 8 load steps to 2 mm, --curve-noise on every force, fitted as "
                         "`warpworm experiment compression --fit` fits a measured table (implies --known "
                         "hinge_stiffness; its 95 %% interval is k_alpha's verdict)")
    ap.add_argument("--curve-noise", type=float, default=0.02,
                    help="relative Gaussian noise of the simulated bench curve's forces (default 0.02)")
    ap.add_argument("--json", default=None, help="append one JSON line per worm here")
    args = ap.parse_args()
    from warpworm import quiet_warp
    from warpworm.analysis import fit_track as FT

    quiet_warp()
    if args.known_from and "hinge_stiffness" not in args.known:
        args.known.append("hinge_stiffness")
    plan = json.loads(open(args.plan).read())
    clips = plan["clips"]
    fit_names = [n for n in NAMES if n not in args.known]
    idx = [NAMES.index(n) for n in fit_names]
    starts = np.asarray(plan["design_worms"]) if "design_worms" in plan and plan.get("names") == NAMES else None
    if args.known:  # the design worms of the parameters left to fit (plan.design_worms over production's ranges)
        from warpworm.analysis.plan import design_worms

        starts = design_worms({n: RANGES[n] for n in fit_names})
    size = tuple(int(x) for x in args.size.split("x"))
    print(f"{len(clips)} clip(s): " + "; ".join(f"{c['gait']} w={c['wavelength']:.4g} a={c['amplitude']:.4g} "
                                                 f"h={c['closest_approach']:.4g} x{c['cycles']:g}" for c in clips))
    for j in range(args.first, args.first + args.worms):
        t0 = time.perf_counter()
        rng = np.random.default_rng([41, j])
        truth = draw_worm(rng)
        try:
            filmed = [film_clip(c, truth, rng, size=size, spp=args.spp, seed=1000 * j + 10 * k + 100003 * args.noise_seed)
                      for k, c in enumerate(clips)]
        except (RuntimeError, ValueError) as exc:
            print(f"worm {j}: {exc}; skipped", flush=True)
            continue
        t_film = time.perf_counter() - t0
        tracks, metas, bases = [f[0] for f in filmed], [f[1] for f in filmed], [f[2] for f in filmed]
        held = {n: float(truth[NAMES.index(n)]) * (1.0 + args.known_error) for n in args.known}
        bench = None
        if args.known_from:  # k_alpha as the bench test measures it, with its own 95 % interval
            bench = bench_hinge_stiffness(args.known_from, truth[0], bases[0], np.random.default_rng([41, j, 2]),
                                          args.curve_noise)
            held["hinge_stiffness"] = bench["hinge_stiffness"]
        bases = [dataclasses.replace(b, **held) for b in bases]
        px = np.concatenate([f[3].ravel() for f in filmed])
        res = FT.fit(tracks, bases, fit_names, meta=metas, budget=args.budget, refine=args.refine,
                     profile=args.profile, render_scale=args.render_scale, seed=j, starts=starts)
        err = res["value"] / truth[idx] - 1
        inside = [bool(lo <= -e / (1 + e) <= hi) for (lo, hi), e in zip(res["range_rel"], err)]
        row = {"worm": j, "names": fit_names, "known": args.known, "known_error": args.known_error,
               "planted": truth[idx].tolist(),
               "fitted": res["value"].tolist(), "error": err.tolist(),
               "range_rel": res["range_rel"].tolist(), "verdict": [str(v) for v in res["verdict"]],
               "planted_inside": inside, "rms_ratio": res["rms_ratio"], "rms_disp_m": res["rms_disp_m"],
               "track_px_mean": float(np.nanmean(px)), "track_px_max": float(np.nanmax(px)),
               "worlds": res["worlds"], "film_s": t_film, "noise_seed": args.noise_seed, "wall_s": time.perf_counter() - t0, "clips": clips}
        if bench is not None:
            row["bench"] = {"test": args.known_from, "curve_noise": args.curve_noise, "planted": float(truth[0]),
                            "fitted": bench["hinge_stiffness"], "error": bench["hinge_stiffness"] / truth[0] - 1,
                            "interval_rel": bench["interval_rel"]}
            lo, hi = bench["interval_rel"]
            print(f"worm {j}: {args.known_from} curve: k_alpha {100 * row['bench']['error']:+.2f} % "
                  f"[{100 * lo:+.1f},{100 * hi:+.1f}]", flush=True)
        print(f"worm {j}: planted k={truth[0]:.4g} mu={truth[1]:.3f} m={truth[2]:.3f}  error ({', '.join(fit_names)}) "
              + "  ".join(f"{100 * e:+.2f}%" for e in err) + "  ranges "
              + "  ".join(f"[{100 * lo:+.1f},{100 * hi:+.1f}]" for lo, hi in res["range_rel"]) + "  "
              + "/".join(row["verdict"]) + f"  tracker {row['track_px_mean']:.2f}/{row['track_px_max']:.2f} px  "
              f"{res['worlds']} worlds {row['wall_s']:.0f} s", flush=True)
        if args.json:
            with open(args.json, "a") as f:
                f.write(json.dumps(row) + "\n")


def table(path: str) -> None:
    """The docs' table from a --json file: per parameter, |error| median / 90th percentile / max, the rate within
    the tolerance, the pinned rate and the planted value inside the acceptable range."""
    rows = [json.loads(line) for line in open(path)]
    names = rows[0].get("names", NAMES)  # the fitted parameters (the rest held at their planted values)
    err = np.abs(np.array([r["error"] for r in rows]))
    ver = np.array([r["verdict"] for r in rows])
    inside = np.array([r["planted_inside"] for r in rows])
    tol = np.array([TOL[NAMES.index(n)] for n in names])
    print(f"N = {len(rows)} worms")
    print("| parameter | |error| median | 90 % | max | within tolerance | pinned | pinned and within tolerance | "
          "borderline | not pinned | planted inside range |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for i, n in enumerate(names):
        print(f"| {n} | {100 * np.median(err[:, i]):.2f} % | {100 * np.percentile(err[:, i], 90):.2f} % | "
              f"{100 * err[:, i].max():.2f} % | {np.mean(err[:, i] <= tol[i]):.0%} | {np.mean(ver[:, i] == 'pinned'):.0%} "
              f"| {np.mean((ver[:, i] == 'pinned') & (err[:, i] <= tol[i])):.0%} "
              f"| {np.mean(ver[:, i] == 'borderline'):.0%} | {np.mean(ver[:, i] == 'not pinned'):.0%} | "
              f"{np.mean(inside[:, i]):.0%} |")
    allp = (ver == "pinned").all(axis=1)
    allw = (err <= tol).all(axis=1)
    if all("bench" in r for r in rows):  # k_alpha from the bench curve: its error and 95 % interval
        b_signed = np.array([r["bench"]["error"] for r in rows])
        b_err = np.abs(b_signed)
        b_iv = np.array([r["bench"]["interval_rel"] for r in rows])
        b_pin = np.maximum(-b_iv[:, 0], b_iv[:, 1]) <= TOL[0]
        b_in = (1 + b_iv[:, 0] <= 1 / (1 + b_signed)) & (1 / (1 + b_signed) <= 1 + b_iv[:, 1])  # planted inside
        print(f"| hinge_stiffness ({rows[0]['bench']['test']} curve, {100 * rows[0]['bench']['curve_noise']:g} % "
              f"noise) | {100 * np.median(b_err):.2f} % | {100 * np.percentile(b_err, 90):.2f} % | "
              f"{100 * b_err.max():.2f} % | {np.mean(b_err <= TOL[0]):.0%} | {b_pin.mean():.0%} | "
              f"{np.mean(b_pin & (b_err <= TOL[0])):.0%} | | | {b_in.mean():.0%} |")
        allp &= b_pin
        allw &= b_err <= TOL[0]
    print(f"all pinned: {allp.mean():.0%}; all within tolerance: {allw.mean():.0%}; all pinned "
          f"and within tolerance: {(allp & allw).mean():.0%}; tracker "
          f"{np.mean([r['track_px_mean'] for r in rows]):.2f} px mean, {np.max([r['track_px_max'] for r in rows]):.2f} "
          "px worst")


def combined_verdict(verdicts, ranges=None) -> str:
    """The verdict of several takes of one worm (the same clips re-filmed or re-rendered): not pinned if the takes'
    acceptable ranges ``ranges`` (absolute (lo, hi) per take) have no value in common (the takes disagree: at least
    one fit sits in a side valley), else pinned only if every take says pinned, not pinned only if every take says
    not pinned, else borderline."""
    if ranges is not None and max(lo for lo, _ in ranges) > min(hi for _, hi in ranges):
        return "not pinned"
    v = set(verdicts)
    return next(iter(v)) if len(v) == 1 and v <= {"pinned", "not pinned"} else "borderline"


def _abs_range(row: dict, i: int) -> tuple[float, float]:
    lo, hi = row["range_rel"][i]
    return row["fitted"][i] * (1 + lo), row["fitted"][i] * (1 + hi)


def stability(*paths: str) -> None:
    """Verdicts of the same worms rendered with different noise seeds (--noise-seed), one --json file per take: per
    parameter and pair of takes, how many verdicts changed, how many flipped between pinned and not pinned, and the
    range half-widths' relative change; with three takes or more also the two-take verdict
    (:func:`combined_verdict`) of every pair of takes against every other pair: does it change when one take is
    replaced by another?"""
    import itertools

    takes = [{json.loads(line)["worm"]: json.loads(line) for line in open(p)} for p in paths]
    both = sorted(set.intersection(*(set(t) for t in takes)))
    print(f"{len(both)} worms rendered {len(takes)} times")
    names = next(iter(takes[0].values())).get("names", NAMES)  # the fitted parameters
    tol = [TOL[NAMES.index(n)] for n in names]
    for i, n in enumerate(names):
        changed = flipped = pairs = 0
        rel = []
        for ta, tb in itertools.combinations(takes, 2):
            for w in both:
                va, vb = ta[w]["verdict"][i], tb[w]["verdict"][i]
                pairs += 1
                changed += va != vb
                flipped += {va, vb} == {"pinned", "not pinned"}
                ha = max(-ta[w]["range_rel"][i][0], ta[w]["range_rel"][i][1])
                hb = max(-tb[w]["range_rel"][i][0], tb[w]["range_rel"][i][1])
                rel.append(hb / ha - 1)
        line = (f"| {n} | one take: {changed} of {pairs} changed, {flipped} pinned <-> not pinned | half-width change "
                f"median {100 * np.median(np.abs(rel)):.0f} %, max {100 * np.max(np.abs(rel)):.0f} %")
        if len(takes) >= 3:
            c_changed = c_flipped = c_pairs = 0
            duos = list(itertools.combinations(range(len(takes)), 2))
            for w in both:
                comb = {d: combined_verdict([takes[k][w]["verdict"][i] for k in d],
                                            [_abs_range(takes[k][w], i) for k in d]) for d in duos}
                for d1, d2 in itertools.combinations(duos, 2):
                    c_pairs += 1
                    c_changed += comb[d1] != comb[d2]
                    c_flipped += {comb[d1], comb[d2]} == {"pinned", "not pinned"}
            line += f" | two takes: {c_changed} of {c_pairs} changed, {c_flipped} pinned <-> not pinned"
        if len(takes) >= 2:
            right = wrong = 0
            for w in both:
                for d in itertools.combinations(range(len(takes)), 2):
                    v = combined_verdict([takes[k][w]["verdict"][i] for k in d], [_abs_range(takes[k][w], i) for k in d])
                    if v == "pinned":
                        ok = all(abs(takes[k][w]["error"][i]) <= tol[i] for k in d)
                        right += ok
                        wrong += not ok
            line += f" | two-take pinned: {right} within tolerance in both takes, {wrong} not"
        print(line + " |")
    for w in both:
        two = [combined_verdict([t[w]["verdict"][i] for t in takes], [_abs_range(t[w], i) for t in takes])
               for i in range(len(names))]
        print(f"  worm {w}: " + "  ".join("->".join(t[w]["verdict"][i] for t in takes) for i in range(len(names)))
              + "  (all takes: " + "/".join(two) + ")"
              + "  errors " + " ".join("/".join(f"{100 * t[w]['error'][i]:+.1f}" for t in takes) + "%"
                                       for i in range(len(names))))


if __name__ == "__main__":
    import sys

    if len(sys.argv) == 3 and sys.argv[1] == "--table":
        table(sys.argv[2])
    elif len(sys.argv) >= 4 and sys.argv[1] == "--stability":
        stability(*sys.argv[2:])
    else:
        main()
