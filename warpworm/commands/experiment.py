"""``warpworm experiment``: the paper's virtual experiments (§IV), each a PNG + JSON (docs/experiments.md)."""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from warpworm.analysis import experiments as ex
from warpworm.analysis import material_fit as mf
from warpworm.commands.common import check_minimum, check_positive, first_run_notice, refuse
from warpworm.physics.materials import material_params
from warpworm.physics.param_specs import check_worm_params
from warpworm.physics.params import parse_overrides

HELP = "run the paper's virtual experiments (force-distance, compression, flexure, slope, force-plate, strain, " \
       "deformation, all): <name>.png + <name>.json"

NAMES = ("force-distance", "compression", "flexure", "slope", "force-plate", "strain", "deformation")


def add_arguments(parser) -> None:
    parser.add_argument("name", choices=NAMES + ("all",), help="which experiment ('all' runs every one)")
    parser.add_argument("--out", default="out/experiments", help="output folder (default out/experiments)")
    parser.add_argument("--worlds", type=int, default=None,
                        help="sweep size: k_α values (compression, flexure; geometric 0.0025-0.04 N/rad) or slopes "
                             "(slope); default 5 / 6; with --fit the coarse batch (default 24). "
                             "Gait experiments always run one world per gait (3)")
    parser.add_argument("--quick", action="store_true", help="short horizons and few increments (smoke runs)")
    parser.add_argument("--duration", type=float, default=None, help="gait run length [s] (default 2, quick 0.3)")
    parser.add_argument("--no-plot", action="store_true", help="write the JSON only (no matplotlib needed)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a WormParams field of every world, e.g. --set closest_approach_scale=1.1 (the "
                             "gait experiments keep each preset's w, a, h and scale them)")
    parser.add_argument("--material", default="mineral_paper",
                        help="sheet material of the worm (warpworm.physics.materials.MATERIALS: bopet, mineral_paper, "
                             "tracing_paper; default mineral_paper)")
    parser.add_argument("--fit", metavar="TABLE.csv", default=None,
                        help="compression / flexure only: fit k_α to a measured curve, a CSV with columns "
                             "displacement_m,force_n (header line optional); writes <name>-fit.json / .png")
    parser.add_argument("--workers", type=int, default=None,
                        help="threads to split the worlds over (default: every core; results equal one "
                             "thread's)")
    parser.add_argument("--advance", action="store_true",
                        help="force-plate only: let the EPM advance w per cycle as in locomotion (it then leaves the "
                             "tied worm behind) instead of repeating its first pass in place every cycle")
    parser.add_argument("--k-range", nargs=2, type=float, metavar=("LO", "HI"), default=(5.0e-4, 0.1),
                        help="--fit search range for k_α [N/rad] (default 5e-4 0.1)")


def _sweep(lo: float, hi: float, n: int):
    return np.geomspace(lo, hi, n) if n > 1 else np.array([lo])


def _run(name: str, args, cache: dict, base=None):
    q = args.quick
    dur = args.duration if args.duration is not None else (0.3 if q else 2.0)
    workers = args.workers  # None: every core (split_run caps it at the world count)
    if name == "force-distance":
        return ex.force_distance(gaps=np.geomspace(0.5e-3, 40e-3, 20 if q else 60))
    if name in ("compression", "flexure"):
        ks = _sweep(0.0025, 0.04, args.worlds or (2 if q else 5))
        fn = ex.compression if name == "compression" else ex.flexure
        return fn(ks, increments=3 if q else 8, hold=0.05 if q else 0.1, settle=0.1 if q else 0.2, base=base,
                  workers=workers)
    if name == "slope":
        n = args.worlds or (2 if q else 6)
        offs = np.array([-2.0, 2.0]) if n == 2 else np.linspace(-4.0, 4.0, n)
        return ex.slope(offs, duration=0.2 if q else 0.5, settle=0.1 if q else 0.2, base=base, workers=workers)
    if name == "force-plate":
        return ex.force_plate(duration=dur, settle=0.1 if q else 0.2, base=base, workers=workers,
                              rewind=not args.advance)
    if "free" not in cache:  # strain and deformation share one free-worm run
        cache["free"] = ex.run_gaits(duration=dur, settle=0.1 if q else 0.2, base=base, workers=workers)
    fn = ex.strain if name == "strain" else ex.deformation
    return fn(record=cache["free"])


def _fmt(v):
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, list):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k}: {_fmt(x)}" for k, x in v.items()) + "}"
    return str(v)


def _fit(args, base) -> int:
    """``--fit TABLE.csv``: check the table (before any simulation), fit k_α, print and write JSON / PNG."""

    if args.name not in mf.TESTS:
        print(f"error: --fit works with compression or flexure, not {args.name!r}", file=sys.stderr)
        return 2
    try:
        d, f = mf.read_curve(args.fit)
    except mf.CurveError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    kw = dict(k_range=tuple(args.k_range), workers=args.workers)
    if args.worlds:
        kw["coarse"] = args.worlds
    if args.quick:
        kw.update(coarse=args.worlds or 12, fine=6)
    try:
        r = mf.fit_hinge_stiffness(args.name, d, f, base=base, **kw)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    r["summary"].update(material=args.material, table=str(args.fit))
    out = Path(args.out)
    stem = f"{args.name}-fit"
    written = [str(ex.save_json(r, out / f"{stem}.json"))]
    note = None
    if not args.no_plot:
        try:
            import matplotlib  # noqa: F401
        except ImportError:
            note = "note: matplotlib is not installed (the 'plots' extra): PNG skipped"
        else:
            from warpworm.analysis.plots import plot_fit  # (matplotlib: checked just above)

            written.append(str(plot_fit(r, out / f"{stem}.png")))
    print(f"== {stem} ({time.perf_counter() - t0:.1f} s): " + ", ".join(written))
    if note:
        print(note)
    s = r["summary"]
    lo, hi = s["hinge_stiffness_95_rel"]
    print(f"   fitted k_α = {s['hinge_stiffness_N_per_rad']:.5g} N/rad ({args.material}, every other parameter "
          f"held); 95 % interval {100 * lo:+.1f} … {100 * hi:+.1f} % (from the residual and the curve's slope)")
    print(f"   RMS residual = {s['rms_residual_N']:.4g} N ({100 * s['relative_residual']:.2f} % of the RMS "
          "measured force)")
    if s["at_search_bound"]:
        print("   warning: the best coarse candidate is at an end of --k-range: widen it")
    for k, v in s.items():
        print(f"   {k}: {_fmt(v)}")
    return 0


def main(args) -> int:
    try:
        base = material_params(args.material)
    except ValueError as exc:
        print(f"error: --{exc}", file=sys.stderr)
        return 2

    try:  # the rules generate applies (warpworm.data.config), before any work
        base = check_worm_params(replace(base, **parse_overrides(args.set)))
        check_minimum(worlds=(args.worlds, 1), workers=(args.workers, 1))
        check_positive(duration=args.duration)
        lo, hi = args.k_range
        if not (0 < lo < hi and np.isfinite(hi)):
            raise ValueError(f"--k-range: got {lo} {hi}; expected 0 < LO < HI [N/rad]")
        if Path(args.out).exists() and not Path(args.out).is_dir():
            raise ValueError(f"--out: got '{args.out}'; expected a folder (it is a file)")
    except ValueError as exc:
        return refuse(exc)

    first_run_notice()
    if args.fit is not None:
        return _fit(args, base)
    out = Path(args.out)
    names = NAMES if args.name == "all" else (args.name,)
    cache: dict = {}
    for name in names:
        t0 = time.perf_counter()
        r = _run(name, args, cache, base)
        jpath = ex.save_json(r, out / f"{name}.json")
        written = [str(jpath)]
        if not args.no_plot:
            from warpworm.analysis.plots import PLOTS  # here: the plots need matplotlib, an optional extra

            written.append(str(PLOTS[name](r, out / f"{name}.png")))
        print(f"== {name} ({time.perf_counter() - t0:.1f} s): " + ", ".join(written))
        for k, v in r["summary"].items():
            print(f"   {k}: {_fmt(v)}")
    return 0
