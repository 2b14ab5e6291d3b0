"""``warpworm export-bop DIR OUT``: a dataset folder in the BOP layout (mm, depth_scale, masks, scene_gt*, models/)."""

from __future__ import annotations

import argparse

from warpworm.commands.common import add_export_arguments, check_export_arguments, refuse
from warpworm.data.export_bop import export_bop

HELP = ("Export a generated dataset folder to the BOP format (camera.json, models/ PLY + models_info.json, "
        "scene_gt.json in mm, PNG rgb/depth/masks).")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_export_arguments(parser, out_help="BOP output folder (new or empty, unless --overwrite)")
    parser.add_argument("--split", default="train_pbr", help="BOP split folder name (default train_pbr)")


def main(args: argparse.Namespace) -> int:
    try:
        check_export_arguments(args)
        if not args.split or "/" in args.split:
            raise ValueError(f"--split: got {args.split!r}; expected a folder name such as train_pbr")
    except ValueError as exc:
        return refuse(exc)
    try:
        res = export_bop(args.dir, args.out, split=args.split, limit=args.limit)
    except (FileNotFoundError, ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {res['images']} images in {res['scenes']} scene(s) and {res.get('models', 5)} object models to "
          f"{args.out}")
    return 0
