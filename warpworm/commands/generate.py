"""``warpworm generate CONFIG --out DIR``: a labeled dataset (sharded HDF5) from a YAML config."""

from __future__ import annotations

import argparse
import importlib.util
import os
import signal
import sys
import threading

from warpworm.data.config import ConfigError, load_config
from warpworm.data.dataset import DatasetError, DatasetLockedError, DatasetWriteError
from warpworm.data.job import generate
from warpworm.data.previews import remove_preview_temporaries, write_previews
from warpworm.data.signal_hold import Interrupted
from warpworm.data.stages import DEFAULT_STAGES
from warpworm.data.workers import WorkerError

HELP = "Generate a labeled synthetic dataset (sharded HDF5) from a YAML config (path or packaged name, e.g. 'default')."

# Exit codes (docs/dataset.md, "Faults and exit codes")
EXIT_OK = 0
EXIT_FAILED = 1  # a worker died, or a stage failed (e.g. worlds unstable in every attempt): --resume continues
EXIT_CONFIG = 2  # bad config / arguments / output folder: refused before any work, nothing written
EXIT_WRITE = 3  # disk full, read-only or unwritable folder mid-job: completed shards intact, --resume continues
EXIT_LOCKED = 4  # another running job holds the output folder's lock (named in the message)
# 128 + signal (130 SIGINT, 143 SIGTERM): stopped cleanly on a signal, --resume continues


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
    phase = ["job"]

    def stop(signum, frame):
        # outside the job's own guard (before it starts, between it and the previews, during the previews): stop
        # here and now, without raising into whatever runs (an exception raised inside an h5py or OpenCV callback
        # becomes a SystemError): nothing of the dataset is in flight, a preview is only ever half-written under its
        # temporary name, which goes

        remove_preview_temporaries(args.out)
        name = signal.Signals(signum).name
        if phase[0] == "job":
            msg = (f"stopped: interrupted by {name}; completed shards are committed and listed in {args.out}/"
                   "manifest.json; rerun the same command with --resume to continue")
        else:
            msg = (f"stopped: interrupted by {name} after the job; the dataset is complete ({args.out}/manifest.json); "
                   "rerun the same command with --resume to write the previews")
        print(msg, file=sys.stderr, flush=True)
        os._exit(128 + signum)

    main_thread = threading.current_thread() is threading.main_thread()
    if main_thread:
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, stop)  # the job's guard takes over while it runs and gives this back after
    try:
        return _generate(args, phase)
    except Interrupted as exc:  # the job's guard: a clean stop of the job
        print(f"stopped: {exc}; completed shards are committed and listed in {args.out}/manifest.json, the shard in "
              "flight was discarded; rerun the same command with --resume to continue", file=sys.stderr)
        return 128 + exc.signum
    finally:
        if main_thread:  # done (or stopped): a signal now would only kill a process that is already ending
            for sig in (signal.SIGTERM, signal.SIGINT):
                signal.signal(sig, signal.SIG_IGN)


def _generate(args, phase: list) -> int:
    """The command under the signal guard; ``phase[0]`` says whether the job ("job") or the previews ("previews")
    is running, for the message of a stop."""

    stages = args.stages or DEFAULT_STAGES
    try:
        cfg = load_config(args.config, args.overrides, num_samples=args.num, seed=args.seed)
        if args.print_config:
            print(cfg.to_yaml(), end="")
            return EXIT_OK
        _check_arguments(args)
        # (generate checks the folder's lock and contents before it writes anything)
        summary = generate(cfg, args.out, workers=args.workers, resume=args.resume, stages=stages,
                           engine=args.engine, address=args.address, progress=not args.no_progress)
    except (ConfigError, DatasetError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_CONFIG
    except DatasetLockedError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_LOCKED
    except DatasetWriteError as exc:
        print(f"error: {exc.strerror if exc.strerror else exc}", file=sys.stderr)
        return EXIT_WRITE
    except (WorkerError, RuntimeError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_FAILED
    phase[0] = "previews"
    if cfg.output.preview and not args.no_preview:
        remove_preview_temporaries(args.out)  # a killed run's
        write_previews_or_warn(cfg, args.out, stages)
    print(summary.text())
    return EXIT_OK


def _check_arguments(args) -> None:
    """The command-line values the config does not check (before anything is written to --out)."""

    if args.workers < 1:
        raise ConfigError([f"--workers: got {args.workers}; expected >= 1"])
    if args.engine == "ray":
        if importlib.util.find_spec("ray") is None:
            raise ConfigError(["--engine: got 'ray'; expected Ray to be installed "
                               "(pip install 'warpworm[ray]') or --engine local"])


def write_previews_or_warn(cfg, out, stages) -> None:
    """``preview.png`` / ``preview.mp4`` of the finished dataset; a failure is a warning (a preview must never fail a
    finished dataset)."""

    try:
        write_previews(cfg, out, stages)
    except Interrupted:
        raise  # a stop, not a failed preview
    except Exception as exc:  # noqa: BLE001
        print(f"warning: preview not written: {exc}", file=sys.stderr)
