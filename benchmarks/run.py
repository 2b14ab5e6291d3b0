#!/usr/bin/env python
"""Benchmark runner.

``python benchmarks/run.py [--quick] [--device DEV] [--out DIR]`` (no names): the summary, ONE table measured in one
run: warpworm's gait step and substep rates beside the NumPy reference of the substep (``tests/numpy_reference.py``) and
Newton on the same mesh (a "not installed" row unless the optional ``newton`` package is importable), then the
renderer's images/s and the dataset pipeline's samples/s (one and four camera views per frame). On ``--device cuda`` the dynamics rows are at 1k, 16k and
64k worlds. Written to ``DIR/summary.json``.

``python benchmarks/run.py NAME [NAME ...] | all [--quick] [--device DEV] [--out DIR]``: the named
``benchmarks/bench_<NAME>.py`` (each exposing ``run(quick: bool) -> list[dict]``, optionally taking ``device=``),
each printed as a table and written to ``DIR/<NAME>.json``; ``all`` runs every one.

``DIR`` defaults to ``benchmarks/results``.
"""

from __future__ import annotations

import argparse
import importlib.util
import inspect
import json
import os
import platform
import sys
import textwrap
import time
from pathlib import Path

# one BLAS thread (set before NumPy loads): the NumPy reference is compared per core, like Warp's CPU kernels (one
# thread each); spinning BLAS threads would also bill idle CPU time to it on a shared machine
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent


def discover() -> dict[str, Path]:
    return {p.stem[len("bench_"):]: p for p in sorted(HERE.glob("bench_*.py"))}


def load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(f"bench_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fmt(v) -> str:
    if isinstance(v, float):
        if v != v:
            return "nan"
        if v == 0 or 1e-3 <= abs(v) < 1e6:
            return f"{v:.4g}"
        return f"{v:.3e}"
    return str(v)


def table(rows: list[dict], first=()) -> str:
    """Rows as a right-aligned text table; columns in first-appearance order, those in ``first`` leading."""
    cols: list[str] = [c for c in first if any(c in r for r in rows)]
    for r in rows:
        cols += [k for k in r if k not in cols]
    cells = [[_fmt(r.get(c, "")) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(cols)]
    line = "  ".join(c.rjust(w) for c, w in zip(cols, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(v.rjust(w) for v, w in zip(row, widths)) for row in cells]
    return "\n".join(out)


def _meta(name: str, quick: bool, device: str, seconds: float) -> dict:
    import warp as wp

    meta = {"benchmark": name, "quick": quick, "device": device, "seconds": seconds,
            "python": sys.version.split()[0], "warp": wp.config.version, "machine": platform.machine(),
            "processor": platform.processor() or platform.machine(), "cpu_count": os.cpu_count(),
            "load_avg_1min": os.getloadavg()[0], "date": time.strftime("%Y-%m-%dT%H:%M:%S")}
    if device.startswith("cuda"):
        meta["gpu"] = wp.get_device(device).name
    return meta


def _write(out_dir: Path, name: str, meta: dict, rows: list[dict], notes: str = "") -> Path:
    out = out_dir / f"{name}.json"
    out.write_text(json.dumps({"meta": meta, "notes": notes, "rows": rows}, indent=1, default=float))
    return out


SUMMARY_COLUMNS = ("system", "device", "W", "substep_us", "step_rate", "sim_s_per_wall_s", "vs_numpy", "rate",
                   "unit", "time_base", "note")


def summary(quick: bool, device: str):
    """The rows of the summary table (see the module docstring), yielded as they grow (after the dynamics, the
    renderer, the pipeline) so that a run stopped by a time limit still leaves what it measured; each stage guarded
    so one failure is one row."""
    modules = discover()
    rows = []
    dyn = load("dynamics", modules["dynamics"])
    rows += [{**r, "unit": "worm-substeps/s"} for r in dyn.compare(device, quick=quick)]
    yield rows
    for name, label in (("render", "warpworm rasterizer"), ("dataset", "warpworm generate"),
                        ("views", "warpworm generate, views")):
        try:
            rows.append(load(name, modules[name]).headline(device, quick=quick))
        except Exception as exc:  # report, keep the table
            rows.append({"system": label, "device": device, "note": f"failed: {type(exc).__name__}: {exc}"[:160]})
        yield rows


SUMMARY_NOTES = ("step_rate: worm-substeps/s (of substep_us each; Newton's: its own steps); sim_s_per_wall_s: simulated "
                 "worm-seconds per second of the time base (process CPU time on the CPU = one dedicated core; wall "
                 "on CUDA); vs_numpy: warpworm's substep over the NumPy reference's at the same W")


def main(argv=None) -> int:
    available = discover()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*",
                        help=f"benchmarks to run: {', '.join(available)} or 'all' (default: the summary table)")
    parser.add_argument("--quick", action="store_true", help="smaller sizes, for CI / a first look")
    parser.add_argument("--device", default="cpu", help="Warp device: cpu | cuda | cuda:N (default cpu)")
    parser.add_argument("--out", default=str(HERE / "results"), help="folder for the JSON (default benchmarks/results)")
    args = parser.parse_args(argv)
    from warpworm import quiet_warp

    quiet_warp()  # Warp's banner and module-load lines would interleave with the tables
    import warp as wp

    wp.init()
    device = "cuda:0" if args.device == "cuda" else args.device
    try:
        wp.get_device(device)
    except Exception:
        parser.error(f"--device {args.device!r}: not a Warp device here (have: "
                     f"{[d.alias for d in wp.get_devices()]})")
    names = list(available) if args.names == ["all"] else args.names
    unknown = [n for n in names if n not in available]
    if unknown:
        parser.error(f"unknown benchmark(s) {unknown}; available: {list(available)} or 'all'")
    out_dir = Path(args.out)
    out_dir.mkdir(parents=True, exist_ok=True)
    if not names:
        t0 = time.perf_counter()
        for rows in summary(args.quick, device):  # written as it grows
            elapsed = time.perf_counter() - t0
            path = _write(out_dir, "summary", _meta("summary", args.quick, device, elapsed), rows, SUMMARY_NOTES)
        print(f"\n== summary on {device} ({'quick' if args.quick else 'full'}, {elapsed:.1f} s) ==")
        print(table(rows, SUMMARY_COLUMNS))
        print(textwrap.fill(SUMMARY_NOTES, 118))  # one line was 291 characters (issue 25)
        print(f"wrote {path}")
        return 0
    for name in names:
        module = load(name, available[name])
        kw = {"device": device} if "device" in inspect.signature(module.run).parameters else {}
        if device != "cpu" and not kw:
            print(f"note: bench_{name}.run takes no device: it runs on its own choice of device")
        t0 = time.perf_counter()
        rows = module.run(quick=args.quick, **kw)
        elapsed = time.perf_counter() - t0
        print(f"\n== {name} ({'quick' if args.quick else 'full'}, {elapsed:.1f} s) ==")
        print(table(rows))
        notes = getattr(module, "NOTES", "")
        if notes:
            print(notes)
        print(f"wrote {_write(out_dir, name, _meta(name, args.quick, device, elapsed), rows, notes)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
