"""``warpworm export-bop DIR OUT``: a dataset folder in the BOP layout (mm, depth_scale, masks, scene_gt*)."""

from __future__ import annotations

import argparse
import sys

HELP = "Export a generated dataset folder to the BOP format (camera.json, scene_gt.json in mm, PNG rgb/depth/masks)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", help="dataset folder written by 'warpworm generate'")
    parser.add_argument("out", help="BOP output folder")
    parser.add_argument("--split", default="train_pbr", help="BOP split folder name (default train_pbr)")
    parser.add_argument("--limit", type=int, default=None, help="export only the first N samples")


def main(args: argparse.Namespace) -> int:
    from warpworm.data.export_bop import export_bop

    try:
        res = export_bop(args.dir, args.out, split=args.split, limit=args.limit)
    except (FileNotFoundError, ValueError, OSError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {res['images']} images in {res['scenes']} scene(s) to {args.out}")
    return 0
