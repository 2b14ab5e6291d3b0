"""What each production realism option costs in the job itself: ``warpworm generate production`` with options switched
off one at a time, its render stage against its simulation stage, runs alternated in one invocation.

Run: ``python benchmarks/bench_job_options.py [--rounds 3] [--json FILE]``, or ``python benchmarks/run.py job_options
[--quick]``. Each variant is the issue-39 job (``generate production --num 128 sim.worlds=16 output.preview=false
--workers 1``) with a few config overrides (:data:`VARIANTS`); every round runs every variant once, in an order that
turns each round (a slow minute of a shared machine falls on different variants), after one untimed warm-up run of
each (Warp's kernel cache: a variant's resolve kernel compiles on first use). The stage times come from the dataset's
``manifest.json`` (:func:`bench_generate.run_job`), so render / sim is the ratio the job's own summary line prints.

An override can change what the job draws (``render.light_count`` draws fewer lights), so a variant's scenes are
not the shipped job's; its simulation is the same (render options do not touch it).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_generate import JOB, QUICK_JOB, run_job  # noqa: E402 (the benchmarks folder is not a package)

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
         "<= 1), median, range and runs <= 1; render_ms_per_sample: the render stage per sample; cpu_s: the whole "
         "process's user + system CPU seconds")


def rotated(names: list[str], r: int) -> list[str]:
    """``names`` turned by ``r`` places (round r's order)."""
    k = r % len(names)
    return names[k:] + names[:k]


def measure(job: list[str], variants: dict[str, list[str]], rounds: int, log=print) -> list[dict]:
    """One row per (round, variant): the job with the variant's overrides, timed by :func:`bench_generate.run_job`."""
    names = list(variants)
    for name in names:
        run_job(sys.executable, [*job, *variants[name]])  # warm-up: the variant's kernels compiled and cached
    rows = []
    for r in range(rounds):
        for name in rotated(names, r):
            row = {"variant": name, "round": r, **run_job(sys.executable, [*job, *variants[name]])}
            log(f"  round {r} {name}: sim {row['sim_s']:.2f} s, render {row['render_s']:.2f} s "
                f"(render / sim {row['render_over_sim']:.2f}), cpu {row['cpu_s']:.2f} s")
            rows.append(row)
    return rows


def summarize(rows: list[dict]) -> list[dict]:
    """Per variant: the median stage times, render / sim (median, range, runs <= 1), render per sample."""
    out = []
    for name in dict.fromkeys(r["variant"] for r in rows):
        mine = [r for r in rows if r["variant"] == name]
        ros = [r["render_over_sim"] for r in mine]
        out.append({"variant": name, "runs": len(mine),
                    **{k: statistics.median(r[k] for r in mine) for k in ("cpu_s", "sim_s", "render_s")},
                    "render_ms_per_sample": 1e3 * statistics.median(r["render_s"] / r["samples"] for r in mine),
                    "render_over_sim": statistics.median(ros), "render_over_sim_min": min(ros),
                    "render_over_sim_max": max(ros), "runs_render_le_sim": sum(x <= 1.0 for x in ros)})
    return out


def run(quick: bool = False) -> list[dict]:
    """For ``benchmarks/run.py job_options``: 2 rounds (quick: a 32-sample job, 1 round)."""
    rows = measure(QUICK_JOB if quick else JOB, VARIANTS, 1 if quick else 2, log=lambda *_: None)
    return summarize(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=3, help="timed runs of each variant (default 3)")
    parser.add_argument("--quick", action="store_true", help="a 32-sample job at 4 worlds")
    parser.add_argument("--json", metavar="FILE", help="write the rows and the summary here")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds: got {args.rounds}; expected an integer >= 1")
    job = QUICK_JOB if args.quick else JOB
    print(f"warpworm generate {' '.join(job)}: {args.rounds} rounds of {len(VARIANTS)} variants")
    rows = measure(job, VARIANTS, args.rounds)
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
