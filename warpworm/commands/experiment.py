"""``warpworm experiment``: the paper's virtual experiments (§IV), each a PNG + JSON (docs/experiments.md)."""

from __future__ import annotations

HELP = "run the paper's virtual experiments (force-distance, compression, flexure, slope, force-plate, strain, " \
       "deformation, all): <name>.png + <name>.json"

NAMES = ("force-distance", "compression", "flexure", "slope", "force-plate", "strain", "deformation")


def add_arguments(parser) -> None:
    parser.add_argument("name", choices=NAMES + ("all",), help="which experiment ('all' runs every one)")
    parser.add_argument("--out", default="out/experiments", help="output folder (default out/experiments)")
    parser.add_argument("--worlds", type=int, default=None,
                        help="sweep size: k_α values (compression, flexure) or slopes (slope); default 4 / 6. "
                             "Gait experiments always run one world per gait (3)")
    parser.add_argument("--quick", action="store_true", help="short horizons and few increments (smoke runs)")
    parser.add_argument("--duration", type=float, default=None, help="gait run length [s] (default 2, quick 0.3)")
    parser.add_argument("--no-plot", action="store_true", help="write the JSON only (no matplotlib needed)")


def _sweep(lo: float, hi: float, n: int):
    import numpy as np

    return np.geomspace(lo, hi, n) if n > 1 else np.array([lo])


def _run(name: str, args, cache: dict):
    import numpy as np

    from warpworm import experiments as ex

    q = args.quick
    dur = args.duration if args.duration is not None else (0.3 if q else 2.0)
    if name == "force-distance":
        return ex.force_distance(gaps=np.geomspace(0.5e-3, 40e-3, 20 if q else 60))
    if name in ("compression", "flexure"):
        ks = _sweep(0.01, 0.08, args.worlds or (2 if q else 4))
        fn = ex.compression if name == "compression" else ex.flexure
        return fn(ks, increments=3 if q else 8, hold=0.05 if q else 0.1, settle=0.1 if q else 0.2)
    if name == "slope":
        n = args.worlds or (2 if q else 6)
        offs = np.array([-2.0, 2.0]) if n == 2 else np.linspace(-4.0, 4.0, n)
        return ex.slope(offs, duration=0.2 if q else 0.5, settle=0.1 if q else 0.2)
    if name == "force-plate":
        return ex.force_plate(duration=dur, settle=0.1 if q else 0.2)
    if "free" not in cache:  # strain and deformation share one free-worm run
        cache["free"] = ex.run_gaits(duration=dur, settle=0.1 if q else 0.2)
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


def main(args) -> int:
    import time
    from pathlib import Path

    from warpworm import experiments as ex

    out = Path(args.out)
    names = NAMES if args.name == "all" else (args.name,)
    cache: dict = {}
    for name in names:
        t0 = time.perf_counter()
        r = _run(name, args, cache)
        jpath = ex.save_json(r, out / f"{name}.json")
        written = [str(jpath)]
        if not args.no_plot:
            from warpworm.plots import PLOTS

            written.append(str(PLOTS[name](r, out / f"{name}.png")))
        print(f"== {name} ({time.perf_counter() - t0:.1f} s): " + ", ".join(written))
        for k, v in r["summary"].items():
            print(f"   {k}: {_fmt(v)}")
    return 0
