"""``warpworm export-coco DIR OUT``: images and a COCO keypoint annotation file; the format is
:mod:`warpworm.data.export_coco`'s."""

from __future__ import annotations

import argparse

from warpworm.commands.common import add_export_arguments, check_export_arguments, refuse
from warpworm.data.export_coco import export_coco

HELP = "Export a dataset folder to COCO keypoints (images/*.png + annotations/keypoints.json)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_export_arguments(parser)


def main(args: argparse.Namespace) -> int:
    # start-up time: the CLI imports every command module to build its parser; the library loads when one runs

    try:
        check_export_arguments(args)
        r = export_coco(args.dir, args.out, args.limit, overwrite=args.overwrite)
    except (ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {r['images']} images and {r['annotations']} keypoint annotations: {r['file']}")
    return 0
