"""``warpworm generate CONFIG --out DIR``: a labeled dataset (sharded HDF5) from a YAML config."""

from __future__ import annotations

import argparse
import sys

HELP = "Generate a labeled synthetic dataset (sharded HDF5) from a YAML config (path or packaged name, e.g. 'default')."


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="YAML config: a file path or a packaged name (default, production, ...)")
    parser.add_argument("--out", required=True, help="output folder (must be empty or new unless --resume)")
    parser.add_argument("--num", type=int, default=None, help="number of samples N (overrides num_samples)")
    parser.add_argument("--seed", type=int, default=None, help="master seed (overrides seed)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes, one per core (default 1)")
    parser.add_argument("--resume", action="store_true",
                        help="continue a killed job in --out: redo missing shards, keep complete ones")
    parser.add_argument("--engine", choices=("local", "ray"), default="local",
                        help="local processes (default) or Ray tasks (pip install 'warpworm[ray]')")
    parser.add_argument("--address", default=None, help="Ray cluster address (with --engine ray; default: local)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--no-preview", action="store_true", help="skip preview.png / preview.mp4")
    parser.add_argument("--stages", default=None, help=argparse.SUPPRESS)  # advanced/tests: module:attr
    parser.add_argument("--print-config", action="store_true", help="print the resolved config and exit")
    parser.add_argument("overrides", nargs="*", metavar="key=value",
                        help="dotted overrides, e.g. sim.substeps=20 'randomize.worm.mu_static={uniform: [0.2, 0.3]}'")
    allow_intermixed(parser)


def allow_intermixed(parser: argparse.ArgumentParser) -> None:
    """Let positionals follow options (``CONFIG --out DIR key=value``): Python < 3.13's argparse consumes an
    ``nargs='*'`` positional as empty at the first positional and then rejects later ones. The subcommand's parser is
    called through ``parse_known_args``, so route that one instance through ``parse_known_intermixed_args``."""

    def parse_known(args=None, namespace=None):
        del parser.parse_known_args  # the intermixed parser calls the class method internally
        try:
            return parser.parse_known_intermixed_args(args, namespace)
        finally:
            parser.parse_known_args = parse_known

    parser.parse_known_args = parse_known


def main(args: argparse.Namespace) -> int:
    from ..config import ConfigError, check_output_dir, load_config

    try:
        cfg = load_config(args.config, args.overrides, num_samples=args.num, seed=args.seed)
        if args.print_config:
            print(cfg.to_yaml(), end="")
            return 0
        if args.workers < 1:
            raise ConfigError([f"--workers: got {args.workers}; expected >= 1"])
        if args.engine == "ray":
            import importlib.util

            if importlib.util.find_spec("ray") is None:  # before anything is written to --out
                raise ConfigError(["--engine: got 'ray'; expected Ray to be installed "
                                   "(pip install 'warpworm[ray]') or --engine local"])
        check_output_dir(args.out, args.resume)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2

    from ..dataset import DatasetWriteError
    from ..pipeline import DEFAULT_STAGES, generate
    from ..workers import WorkerError

    try:
        summary = generate(cfg, args.out, workers=args.workers, resume=args.resume,
                           stages=args.stages or DEFAULT_STAGES, engine=args.engine, address=args.address,
                           progress=not args.no_progress, preview=False if args.no_preview else None)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (DatasetWriteError, WorkerError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(summary.text())
    return 0
