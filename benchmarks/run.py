#!/usr/bin/env python
"""Benchmark runner: discovers ``benchmarks/bench_*.py`` (each exposing ``run(quick: bool) -> list[dict]``),
prints each one's rows as a table and writes them to ``benchmarks/results/<name>.json``.

Usage: ``python benchmarks/run.py [names...] [--quick]`` (names without the ``bench_`` prefix, e.g. ``magnets``).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import platform
import sys
import time
from pathlib import Path

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
        if v == 0 or 1e-3 <= abs(v) < 1e6:
            return f"{v:.4g}"
        return f"{v:.3e}"
    return str(v)


def table(rows: list[dict]) -> str:
    cols: list[str] = []
    for r in rows:
        cols += [k for k in r if k not in cols]
    cells = [[_fmt(r.get(c, "")) for c in cols] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(cols)]
    line = "  ".join(c.rjust(w) for c, w in zip(cols, widths))
    out = [line, "  ".join("-" * w for w in widths)]
    out += ["  ".join(v.rjust(w) for v, w in zip(row, widths)) for row in cells]
    return "\n".join(out)


def main(argv=None) -> int:
    available = discover()
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*", help=f"benchmarks to run (default all): {', '.join(available)}")
    parser.add_argument("--quick", action="store_true", help="smaller sizes, for CI / a first look")
    args = parser.parse_args(argv)
    from warpworm import quiet_warp

    quiet_warp()  # Warp's banner and module-load lines would interleave with the tables
    names = args.names or list(available)
    unknown = [n for n in names if n not in available]
    if unknown:
        parser.error(f"unknown benchmark(s) {unknown}; available: {list(available)}")
    (HERE / "results").mkdir(exist_ok=True)
    for name in names:
        module = load(name, available[name])
        t0 = time.perf_counter()
        rows = module.run(quick=args.quick)
        elapsed = time.perf_counter() - t0
        print(f"\n== {name} ({'quick' if args.quick else 'full'}, {elapsed:.1f} s) ==")
        print(table(rows))
        notes = getattr(module, "NOTES", "")
        if notes:
            print(notes)
        out = HERE / "results" / f"{name}.json"
        meta = {"benchmark": name, "quick": args.quick, "seconds": elapsed, "python": sys.version.split()[0],
                "machine": platform.machine(), "processor": platform.processor() or platform.machine(),
                "date": time.strftime("%Y-%m-%dT%H:%M:%S")}
        out.write_text(json.dumps({"meta": meta, "notes": notes, "rows": rows}, indent=1, default=float))
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
