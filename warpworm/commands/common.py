"""What the commands share for their input checks: one rule set (:mod:`warpworm.data.config`), one error format.

Every command refuses bad input before any work with ``error: <what>: got X; expected Y`` on one line of stderr and
exit code 2 (:data:`EXIT_USAGE`), and writes nothing.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

import warp as wp

from warpworm import quiet_warp
from warpworm.data.config import ConfigError, check_option

EXIT_USAGE = 2
"""Bad arguments, a missing or wrong file, an unavailable device: refused before any work, nothing written."""


def refuse(message) -> int:
    """Print ``error: message`` (one line per problem) on stderr; returns :data:`EXIT_USAGE`."""
    print(f"error: {message}", file=sys.stderr)
    return EXIT_USAGE


def check_minimum(**values) -> None:
    """``option_name=(value, minimum)``: ConfigError for each value below its minimum (None values are skipped);
    option names use ``_`` for ``-`` (``save_worlds`` is ``--save-worlds``)."""

    problems = [f"--{name.replace('_', '-')}: got {v}; expected >= {lo}"
                for name, (v, lo) in values.items() if v is not None and not v >= lo]
    if problems:
        raise ConfigError(problems)


def check_positive(**values) -> None:
    """``option_name=value``: ConfigError for each value that is not a finite number > 0 (None skipped)."""

    problems = [f"--{name.replace('_', '-')}: got {v}; expected a number > 0"
                for name, v in values.items() if v is not None and not (math.isfinite(v) and v > 0)]
    if problems:
        raise ConfigError(problems)


def device_option(value: str | None) -> str | None:
    """``--device`` checked as ``sim.device`` (so ``cuda`` on a machine without a GPU is refused as ``generate``
    refuses ``sim.device=cuda``); ``cuda`` becomes ``cuda:0``; None stays None (Warp's default)."""

    if value is None:
        return None
    dev = check_option("--device", value, "sim.device")
    return "cuda:0" if dev == "cuda" else dev


def dataset_folder(path, option: str = "DIR"):
    """``path`` as a Path if it is a dataset folder written by ``warpworm generate`` (has manifest.json), else
    ValueError saying which it is not (no such folder / a file / a folder without a manifest)."""

    p = Path(path)
    if not p.exists():
        raise ValueError(f"{option}: got '{path}'; expected a dataset folder written by warpworm generate (no such "
                         "folder)")
    if not p.is_dir():
        raise ValueError(f"{option}: got '{path}'; expected a dataset folder written by warpworm generate (it is a "
                         "file)")
    if not (p / "manifest.json").is_file():
        raise ValueError(f"{option}: got '{path}'; expected a dataset folder written by warpworm generate (it has no "
                         "manifest.json; if a job was killed there, rerun it with --resume)")
    return p


def output_folder(path, option: str = "OUT", *, overwrite: bool = False):
    """``path`` as a Path for an export: new, empty, or (with ``overwrite``) any folder; ValueError otherwise
    (a file, or a non-empty folder without ``overwrite``). Creates nothing."""

    p = Path(path)
    if p.exists() and not p.is_dir():
        raise ValueError(f"{option}: got '{path}'; expected a folder (it is a file)")
    if p.is_dir() and any(p.iterdir()) and not overwrite:
        raise ValueError(f"{option}: got '{path}'; expected a new or empty folder (it is not empty: add --overwrite "
                         "to write over it)")
    return p


def add_export_arguments(parser, out_help: str = "output folder (new or empty, unless --overwrite)") -> None:
    """The arguments every ``export-*`` command of a dataset folder takes: DIR, OUT, ``--limit``, ``--overwrite``."""
    parser.add_argument("dir", help="dataset folder written by 'warpworm generate'")
    parser.add_argument("out", help=out_help)
    parser.add_argument("--limit", type=int, default=None, help="export only the first N samples")
    parser.add_argument("--overwrite", action="store_true", help="write into a non-empty OUT")


def check_export_arguments(args, **minimums) -> None:
    """ValueError (ConfigError) unless ``args.dir`` is a dataset folder, ``args.out`` a usable output folder and
    ``args.limit`` (and each ``option=(value, minimum)`` of ``minimums``, as :func:`check_minimum`) in range."""
    dataset_folder(args.dir)
    output_folder(args.out, overwrite=args.overwrite)
    check_minimum(limit=(args.limit, 1), **minimums)


def first_run_notice(modules=("warpworm.kernels.implicit_euler", "warpworm.kernels.magnet_wrench")) -> bool:
    """Say on stderr, before a command's first kernel launch, that the Warp kernels compile now when none of
    ``modules`` has ever been built into Warp's kernel cache (a fresh machine or cache: ~20-60 s of silence
    otherwise). Returns whether it said so. A changed kernel source on an existing cache is not detected (rare)."""

    quiet_warp()
    root = wp.config.kernel_cache_dir
    if not root or not Path(root).is_dir():
        cold = True
    else:
        names = [p.name for p in Path(root).iterdir()]
        cold = not all(any(n.startswith(f"wp_{m}_") for n in names) for m in modules)
    if cold:
        print("note: first run here: compiling Warp kernels (about 20-60 s on a CPU; cached for later runs)",
              file=sys.stderr, flush=True)
    return cold
