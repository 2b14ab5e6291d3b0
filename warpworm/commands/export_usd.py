"""``warpworm export-usd SOURCE --out FILE.usda``: a time-sampled USD stage of worlds from a dataset or trajectory."""

from __future__ import annotations

import argparse
import sys

HELP = "Export worlds of a dataset folder or a saved trajectory to a time-sampled USD stage (.usda/.usdc)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", help="dataset folder (warpworm generate) or trajectory file (.npz/.h5)")
    parser.add_argument("--out", required=True, help="output stage, e.g. worm.usda")
    parser.add_argument("--worlds", default="0",
                        help="comma-separated trajectory ids (dataset) or world indices (trajectory); default 0")
    parser.add_argument("--spacing", type=float, default=None, help="offset between worlds along +y [m]")
    parser.add_argument("--check", action="store_true", help="run pxr's UsdUtils.ComplianceChecker afterwards")


def main(args: argparse.Namespace) -> int:
    from warpworm.data.usd_export import compliance_errors, export_usd

    try:
        worlds = [int(w) for w in str(args.worlds).split(",") if w.strip()]
        path = export_usd(args.source, args.out, worlds=worlds, spacing=args.spacing)
    except (FileNotFoundError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {path}")
    if args.check:
        errs = compliance_errors(path)
        for e in errs:
            print(f"compliance: {e}", file=sys.stderr)
        return 1 if errs else 0
    return 0
