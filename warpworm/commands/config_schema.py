"""``warpworm config-schema``: print the JSON Schema of dataset configs, so an editor validates and completes them.

The schema is exported from the pydantic model in :mod:`warpworm.config` (``json_schema``); docs/config.md shows how
to point VS Code (yaml-language-server) at it. It checks each key alone (types, ranges, names, distribution forms);
the checks that relate two keys (shard_size and sim.frame_times, frame times and sim.dt, the device) are
``load_config``'s, which ``warpworm generate CONFIG --print-config`` runs without simulating anything.
"""

from __future__ import annotations

import argparse
import json
import sys

HELP = "Print the JSON Schema of dataset configs (for editors: validation and completion of dataset_configs/*.yaml)."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None, help="write the schema to this file instead of printing it")


def main(args: argparse.Namespace) -> int:
    from ..config import json_schema

    text = json.dumps(json_schema(), indent=2, allow_nan=False) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        with open(args.out, "w") as f:
            f.write(text)
    except OSError as exc:
        print(f"error: --out: got '{args.out}'; expected a writable file ({exc.strerror})", file=sys.stderr)
        return 2
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
