"""``warpworm export-webdataset DIR OUT``: BOP-webdataset tar shards (warpworm.data.export_webdataset)."""

from __future__ import annotations

import argparse

HELP = ("Export a dataset folder as BOP-webdataset tar shards (per image: rgb, depth, camera, gt, gt_info, masks as "
        "RLE, warpworm labels) with key_to_shard.json and the object models.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", help="dataset folder written by 'warpworm generate'")
    parser.add_argument("out", help="output folder (new or empty, unless --overwrite)")
    parser.add_argument("--limit", type=int, default=None, help="export only the first N samples")
    parser.add_argument("--shard-size", type=int, default=1000, help="images per tar shard (default 1000)")
    parser.add_argument("--overwrite", action="store_true", help="write into a non-empty OUT")


def main(args: argparse.Namespace) -> int:
    from warpworm.commands.common import check_minimum, dataset_folder, output_folder, refuse

    try:
        dataset_folder(args.dir)
        output_folder(args.out, overwrite=args.overwrite)
        check_minimum(limit=(args.limit, 1), shard_size=(args.shard_size, 1))
        import importlib.util

        if importlib.util.find_spec("webdataset") is None:
            raise ValueError("export-webdataset needs the webdataset package: pip install 'warpworm[export]'")
    except ValueError as exc:
        return refuse(exc)
    from warpworm.data.export_webdataset import export_webdataset

    try:
        r = export_webdataset(args.dir, args.out, limit=args.limit, shard_size=args.shard_size)
    except (ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {r['images']} images in {r['shards']} tar shard(s) to {args.out}")
    return 0
