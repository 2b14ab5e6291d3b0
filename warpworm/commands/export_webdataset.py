"""``warpworm export-webdataset DIR OUT``: BOP-webdataset tar shards (warpworm.data.export_webdataset)."""

from __future__ import annotations

import argparse
import importlib.util

from warpworm.commands.common import add_export_arguments, check_export_arguments, refuse
from warpworm.data.export_webdataset import export_webdataset

HELP = ("Export a dataset folder as BOP-webdataset tar shards (per image: rgb, depth, camera, gt, gt_info, masks as "
        "RLE, warpworm labels) with key_to_shard.json and the object models.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    add_export_arguments(parser)
    parser.add_argument("--shard-size", type=int, default=1000, help="images per tar shard (default 1000)")


def main(args: argparse.Namespace) -> int:
    try:
        check_export_arguments(args, shard_size=(args.shard_size, 1))
        if importlib.util.find_spec("webdataset") is None:
            raise ValueError("export-webdataset needs the webdataset package: pip install 'warpworm[export]'")
    except ValueError as exc:
        return refuse(exc)

    try:
        r = export_webdataset(args.dir, args.out, limit=args.limit, shard_size=args.shard_size)
    except (ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {r['images']} images in {r['shards']} tar shard(s) to {args.out}")
    return 0
