"""What each production realism option costs in the job itself: ``warpworm generate production`` with options switched
off one at a time, its render stage against its simulation stage, runs alternated in one invocation.

Run: ``python benchmarks/bench_job_options.py [--rounds 3] [--json FILE]``, or ``python benchmarks/run.py job_options
[--quick]``. Each variant is the issue-39 job (``generate production --num 128 sim.worlds=16 output.preview=false
--workers 1``) with a few config overrides (:data:`VARIANTS`), run and summarized as :mod:`bench_generate` runs and
summarizes trees (:func:`bench_generate.alternated`: a warm-up of each, then every variant once per round, the order
reversed every other round; :func:`bench_generate.summarize`), so render / sim is the ratio the job's own summary
line prints.

An override can change what the job draws (``render.light_count`` draws fewer lights), so a variant's scenes are
not the shipped job's; its simulation is the same (render options do not touch it).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import bench_generate  # noqa: E402 (the benchmarks folder is not a package)

VARIANTS = {
    "as shipped": [],
    "no lens": ["render.distortion=false"],
    "1 sample per pixel": ["render.supersample=1"],
    "no shadows": ["render.shadows=false"],
    "0-1 point lights": ["render.light_count=[0,1]"],
    "no lens, 1 sample per pixel": ["render.distortion=false", "render.supersample=1"],
}
"""Variant name -> the config overrides added to the job."""

NOTES = ("render_over_sim: the job's render stage over its simulation stage (manifest summary; the issue's goal: "
         "<= 1), median, range and runs <= 1; render_ms_per_sample: the median render stage per sample; the other "
         "columns as bench_generate's")


def measure(job: list[str], rounds: int, log=print) -> list[dict]:
    """One row per (round, variant) of :data:`VARIANTS` (the variant's name in ``tree``)."""
    return bench_generate.alternated({name: sys.executable for name in VARIANTS}, job, rounds, log=log,
                                     extra=VARIANTS)


def summarize(rows: list[dict]) -> list[dict]:
    """:func:`bench_generate.summarize` per variant, with the render stage per sample."""
    samples = rows[0]["samples"]
    return [{"variant": s.pop("tree"), **s, "render_ms_per_sample": 1e3 * s["render_s"] / samples}
            for s in bench_generate.summarize(rows)]


def run(quick: bool = False) -> list[dict]:
    """For ``benchmarks/run.py job_options``: 2 rounds (quick: a 32-sample job, 1 round)."""
    return summarize(measure(bench_generate.QUICK_JOB if quick else bench_generate.JOB, 1 if quick else 2,
                             log=lambda *_: None))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3, help="timed runs of each variant (default 3)")
    parser.add_argument("--quick", action="store_true", help="a 32-sample job at 4 worlds")
    parser.add_argument("--json", metavar="FILE", help="write the rows and the summary here")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds: got {args.rounds}; expected an integer >= 1")
    job = bench_generate.QUICK_JOB if args.quick else bench_generate.JOB
    print(f"warpworm generate {' '.join(job)}: {args.rounds} rounds of {len(VARIANTS)} variants")
    rows = measure(job, args.rounds)
    summary = summarize(rows)
    from run import table  # the runner's table format

    print(table(summary))
    print(NOTES)
    if args.json:
        Path(args.json).write_text(json.dumps({"job": job, "variants": VARIANTS, "rows": rows, "summary": summary,
                                               "notes": NOTES}, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
