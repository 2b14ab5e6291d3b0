"""``warpworm report DIR [DIR2 ...] [--out OUT]``: histograms and numbers of what one or more datasets contain."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from warpworm.data.report import ReportError, build, text_summary

HELP = ("Summarize datasets: histograms of every randomized parameter and of the labels (crease angles, their range "
        "within a trajectory, deformation, visibility, box size, camera distance) as PNG + JSON, side by side.")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dirs", nargs="+", metavar="DIR", help="dataset folder(s) (with manifest.json)")
    parser.add_argument("--out", default=None,
                        help="writes OUT.png and OUT.json (default: DIR/report with one folder, ./report with several)")


def main(args: argparse.Namespace) -> int:
    out = args.out or (str(Path(args.dirs[0]) / "report") if len(args.dirs) == 1 else "report")
    try:
        report, jpath, png, note = build(args.dirs, out)
    except ReportError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:
        print(f"error: writing {out}.json / .png failed: {exc}", file=sys.stderr)
        return 2
    print(text_summary(report))
    print(f"wrote {jpath}" + (f" and {png}" if png else ""))
    if note:
        print(note, file=sys.stderr)
    return 0
