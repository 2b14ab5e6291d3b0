"""``warpworm export-yolo DIR OUT``: an Ultralytics YOLO pose dataset (warpworm.data.export_yolo)."""

from __future__ import annotations

import argparse

from warpworm.commands.common import add_export_arguments, check_export_arguments, refuse
from warpworm.data.export_yolo import export_yolo

HELP = ("Export a dataset folder for Ultralytics YOLO pose: images/ and labels/ (train/val by trajectory) and "
        "dataset.yaml with kpt_shape, flip_idx and OKS sigmas.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_export_arguments(parser)
    parser.add_argument("--val-fraction", type=float, default=0.1,
                        help="share of the trajectories held out for validation (default 0.1)")


def main(args: argparse.Namespace) -> int:
    try:
        check_export_arguments(args)
        if not 0 <= args.val_fraction < 1:
            raise ValueError(f"--val-fraction: got {args.val_fraction}; expected a fraction in [0, 1)")
    except ValueError as exc:
        return refuse(exc)

    try:
        r = export_yolo(args.dir, args.out, limit=args.limit, val_fraction=args.val_fraction)
    except (ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {r['train']} train and {r['val']} val images ({r['labels']} with a worm) and {r['yaml']}; train "
          f"with: yolo pose train data={r['yaml']} model=yolo11n-pose.yaml")
    return 0
