"""``warpworm export-usd SOURCE --out FILE.usda``: a time-sampled USD stage of worlds from a dataset or trajectory."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warpworm.commands.common import refuse
from warpworm.data.export_usd import compliance_errors, export_usd

HELP = ("Export worlds of a dataset folder or of `warpworm simulate`'s trajectory.npz to a time-sampled USD stage "
        "(.usda/.usdc).")

SUFFIXES = (".usda", ".usdc", ".usd")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("source", help="dataset folder (warpworm generate) or trajectory file (warpworm simulate's "
                                       "trajectory.npz, or .h5)")
    parser.add_argument("--out", required=True, help="output stage, e.g. worm.usda")
    parser.add_argument("--worlds", default="0",
                        help="comma-separated trajectory ids (dataset) or world indices (trajectory); default 0")
    parser.add_argument("--spacing", type=float, default=None, help="offset between worlds along +y [m]")
    parser.add_argument("--check", action="store_true",
                        help="validate the stage with USD's own checks afterwards (UsdValidation, what usdchecker "
                             "runs; the older ComplianceChecker on usd-core <= 25) and say whether it passed")


def _worlds(text: str) -> list[int]:
    try:
        worlds = [int(w) for w in str(text).split(",") if w.strip()]
    except ValueError:
        raise ValueError(f"--worlds: got {text!r}; expected comma-separated whole numbers, e.g. 0,1,2") from None
    if not worlds or min(worlds) < 0:
        raise ValueError(f"--worlds: got {text!r}; expected comma-separated whole numbers >= 0, e.g. 0,1,2")
    return worlds


def main(args: argparse.Namespace) -> int:
    out = Path(args.out)
    try:
        worlds = _worlds(args.worlds)
        if out.suffix not in SUFFIXES:
            raise ValueError(f"--out: got '{out}'; expected a file name ending in {' or '.join(SUFFIXES)}")
        if out.is_dir():
            raise ValueError(f"--out: got '{out}'; expected a file name (it is a folder)")
        if args.spacing is not None and not args.spacing >= 0:
            raise ValueError(f"--spacing: got {args.spacing}; expected a distance >= 0 [m]")
        out.parent.mkdir(parents=True, exist_ok=True)
        path = export_usd(args.source, out, worlds=worlds, spacing=args.spacing)
    except (FileNotFoundError, ValueError, OSError) as exc:
        return refuse(exc)
    print(f"wrote {path}")
    if args.check:
        errs = compliance_errors(path)
        for e in errs:
            print(f"check: {e}", file=sys.stderr)
        print(f"check: {'FAILED, ' + str(len(errs)) + ' problem(s)' if errs else 'passed (no errors)'}")
        return 1 if errs else 0
    return 0
