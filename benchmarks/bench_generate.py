"""End-to-end cost of ``warpworm generate``: whole-process CPU time per sample and the job's own stage times, this
tree against a reference tree, runs alternated in one invocation.

Run: ``python benchmarks/bench_generate.py --reference 16596a5`` (the production job of issue 39: ``generate
production --num 128 sim.worlds=16 output.preview=false --workers 1``, 4 rounds), or through the runner,
``python benchmarks/run.py generate [--quick]`` (this tree alone: its stage times and their ratio).

Each job is its own process; its CPU time is the user + system time the kernel accounts to it and its children
(``os.wait4``), the cost a user pays for the samples whatever the machine's other load does to the wall clock. The
stage times (sim, render, write) are the job's summary in the dataset's ``manifest.json``. Rounds run in the order
A B B A A B ... after one untimed warm-up run of each tree (Warp's kernel cache), so a slow spell of a shared machine
falls on both trees; the ratio is taken round by round and its median quoted.

``--sizes N1 N2`` runs the job at two sample counts (``--num``) in each round and adds the marginal cost: CPU per
sample between the two sizes, (cpu(N2) - cpu(N1)) / (N2 - N1), and its gain against the reference, the samples per
CPU-second a long job approaches once the process start-up (imports, kernel loading: ~1.7 s whatever the size) is
paid.

``--reference COMMIT`` checks the commit out into a worktree with its own virtualenv (system site-packages, the
package installed editable without dependencies) under ``--cache`` the first time; ``--reference-python PATH`` uses
an interpreter that already has the reference installed.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
JOB = ["production", "--num", "128", "sim.worlds=16", "output.preview=false", "--workers", "1"]
QUICK_JOB = ["production", "--num", "32", "sim.worlds=4", "output.preview=false", "--workers", "1"]
NOTES = ("cpu_s: user + system CPU seconds of the whole job process; sim_s/render_s/write_s: the job's stage "
         "times (manifest summary); rest_s: cpu_s less the three stages (start-up, sampling, exit, the writer "
         "thread's work beyond the wait); render_over_sim: the issue's 'render stage <= sim stage'; cpu_ratio: this "
         "tree's CPU over the reference's in the same round (median over rounds), samples_per_cpu_gain = 1 / "
         "cpu_ratio; gain_if_render_free: the reference's CPU over this tree's less its render stage, the ceiling "
         "the rest of the job sets; with --sizes, '(N)' rows are the job at N samples and 'per sample' rows the CPU "
         "seconds per sample between the two sizes (the start-up cancels), their gain the reference's over this "
         "tree's")


def run_job(python: str, job: list[str]) -> dict:
    """One ``generate`` job in its own process with ``python`` (run from an empty folder, so that ``-m warpworm`` is
    the package that interpreter has installed, not a checkout in the working directory): CPU and wall seconds, the
    manifest's stage times."""
    out = Path(tempfile.mkdtemp(prefix="ww-bench-generate-"))
    try:
        cmd = [python, "-m", "warpworm", "generate", job[0], "--out", str(out / "ds"), *job[1:]]
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=out, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env)
        text = proc.stdout.read().decode(errors="replace")
        _pid, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - t0
        if os.waitstatus_to_exitcode(status) != 0:
            raise RuntimeError(f"{' '.join(cmd)} failed:\n{text[-2000:]}")
        summary = json.loads((out / "ds" / "manifest.json").read_text())["summary"]
    finally:
        shutil.rmtree(out, ignore_errors=True)
    samples = summary["new_samples"]
    cpu = usage.ru_utime + usage.ru_stime
    return {"cpu_s": cpu, "wall_s": wall, "sim_s": summary["sim_s"], "render_s": summary["render_s"],
            "write_s": summary["write_s"], "rest_s": cpu - summary["sim_s"] - summary["render_s"] - summary["write_s"],
            "render_over_sim": summary["render_s"] / summary["sim_s"],
            "samples": samples, "samples_per_cpu_s": samples / cpu}


def reference_python(commit: str, cache: Path) -> str:
    """An interpreter with ``commit`` of this repository installed (editable, no dependencies: the ones this
    environment has), made once under ``cache``."""
    found = subprocess.run(["git", "rev-parse", "--verify", f"{commit}^{{commit}}"], cwd=REPO, capture_output=True,
                           text=True)
    if found.returncode != 0:
        raise SystemExit(f"--reference: got {commit!r}; expected a commit of the git checkout at {REPO} "
                         f"(git: {found.stderr.strip() or 'not a repository'}); or give --reference-python")
    sha = found.stdout.strip()
    tree = cache / sha[:12]
    python = tree / ".venv" / "bin" / "python"
    if not python.exists():
        cache.mkdir(parents=True, exist_ok=True)
        if not tree.exists():
            subprocess.run(["git", "worktree", "add", "--detach", str(tree), sha], cwd=REPO, check=True,
                           capture_output=True)
        subprocess.run([sys.executable, "-m", "venv", "--system-site-packages", str(tree / ".venv")], check=True)
        subprocess.run([str(python), "-m", "pip", "install", "-q", "--no-deps", "-e", str(tree)], check=True)
    return str(python)


def with_num(job: list[str], num: int) -> list[str]:
    """``job`` with its sample count (``--num``) set to ``num``."""
    if "--num" in job:
        i = job.index("--num")
        return [*job[:i + 1], str(num), *job[i + 2:]]
    return [*job, "--num", str(num)]


def alternated(trees: dict[str, str], job: list[str], rounds: int, log=print, sizes: list[int] | None = None,
               extra: dict[str, list[str]] | None = None) -> list[dict]:
    """Rows of ``rounds`` rounds of every tree (name -> its Python), A B / B A alternately, after a warm-up each; with
    ``sizes``, each round runs the job at each sample count, the trees alternated within each size (A B, B A, ...:
    no tree runs more than twice in a row, so a slow minute of a shared machine falls on both). ``extra``: arguments
    added to the job for a name (config overrides: variants of one tree, :mod:`bench_job_options`)."""
    names = list(trees)
    jobs = [with_num(job, n) for n in sizes] if sizes else [job]
    extra = extra or {}
    for name in names:
        run_job(trees[name], [*jobs[0], *extra.get(name, [])])  # warm-up: Warp's kernel cache, the page cache
    rows = []
    turn = 0
    for r in range(rounds):
        for j in (jobs if r % 2 == 0 else jobs[::-1]):
            order, turn = (names if turn % 2 == 0 else names[::-1]), turn + 1
            for name in order:
                row = {"tree": name, "round": r, **run_job(trees[name], [*j, *extra.get(name, [])])}
                log(f"  round {r} {name} ({row['samples']} samples): cpu {row['cpu_s']:.2f} s, sim "
                    f"{row['sim_s']:.2f} s, render {row['render_s']:.2f} s, write {row['write_s']:.2f} s")
                rows.append(row)
    return rows


def marginal(rows: list[dict], new: str = "this", ref: str = "reference") -> list[dict]:
    """Per tree, the CPU seconds per sample between the smallest and the largest job of each round (median, range);
    with a reference, the gain of that marginal cost round by round."""
    per = {}
    for r in rows:
        per.setdefault((r["tree"], r["round"]), []).append(r)
    cost = {}
    for (tree, rnd), rs in per.items():
        small, large = min(rs, key=lambda x: x["samples"]), max(rs, key=lambda x: x["samples"])
        if large["samples"] > small["samples"]:
            cost[(tree, rnd)] = (large["cpu_s"] - small["cpu_s"]) / (large["samples"] - small["samples"])
    out = []
    for tree in dict.fromkeys(t for t, _ in cost):
        c = [v for (t, _), v in cost.items() if t == tree]
        out.append({"tree": f"{tree}, per sample", "runs": len(c), "cpu_s_per_sample": statistics.median(c),
                    "cpu_s_per_sample_min": min(c), "cpu_s_per_sample_max": max(c)})
    gains = [cost[(ref, rnd)] / cost[(new, rnd)] for (t, rnd) in cost if t == new and (ref, rnd) in cost]
    if gains:
        out.append({"tree": f"{new} / {ref}, per sample", "runs": len(gains),
                    "samples_per_cpu_gain": statistics.median(gains), "gain_min": min(gains),
                    "gain_max": max(gains)})
    return out


def summarize(rows: list[dict], new: str = "this", ref: str = "reference") -> list[dict]:
    """Per tree and job size: medians, the render/sim range and how many runs had render <= sim; with a reference,
    the CPU ratio round by round (median, range); with several sizes, the :func:`marginal` rows."""
    sizes = sorted({r["samples"] for r in rows})
    if len(sizes) > 1:
        out = []
        for n in sizes:
            out += [{**x, "tree": f"{x['tree']} ({n})"} for x in summarize([r for r in rows if r["samples"] == n],
                                                                           new, ref)]
        return out + marginal(rows, new, ref)
    out = []
    for name in dict.fromkeys(r["tree"] for r in rows):
        mine = [r for r in rows if r["tree"] == name]
        ros = [r["render_over_sim"] for r in mine]
        out.append({"tree": name, "runs": len(mine),
                    **{k: statistics.median(r[k] for r in mine) for k in ("cpu_s", "sim_s", "render_s", "write_s",
                                                                         "rest_s", "samples_per_cpu_s")},
                    "render_over_sim": statistics.median(ros), "render_over_sim_min": min(ros),
                    "render_over_sim_max": max(ros),
                    "runs_render_le_sim": sum(x <= 1.0 for x in ros)})
    by_round = {}
    for r in rows:
        by_round.setdefault(r["round"], {})[r["tree"]] = r
    pairs = [(v[new], v[ref]) for v in by_round.values() if new in v and ref in v]
    if pairs:
        ratios = [a["cpu_s"] / b["cpu_s"] for a, b in pairs]
        out.append({"tree": f"{new} / {ref}", "runs": len(ratios), "cpu_ratio": statistics.median(ratios),
                    "cpu_ratio_min": min(ratios), "cpu_ratio_max": max(ratios),
                    "samples_per_cpu_gain": 1.0 / statistics.median(ratios),
                    "gain_if_render_free": statistics.median(b["cpu_s"] / (a["cpu_s"] - a["render_s"])
                                                             for a, b in pairs)})
    return out


def run(quick: bool = False) -> list[dict]:
    """For ``benchmarks/run.py generate``: this tree alone, 3 runs (quick: a 32-sample job)."""
    rows = alternated({"this": sys.executable}, QUICK_JOB if quick else JOB, 3, log=lambda *_: None)
    return rows + summarize(rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ref = parser.add_mutually_exclusive_group()
    ref.add_argument("--reference", metavar="COMMIT", help="a commit of this repository to compare against")
    ref.add_argument("--reference-python", metavar="PATH", help="an interpreter with the reference installed")
    parser.add_argument("--cache", default=str(Path.home() / ".cache" / "warpworm-bench"),
                        help="where --reference's worktrees and virtualenvs live (default ~/.cache/warpworm-bench)")
    parser.add_argument("--rounds", type=int, default=4, help="timed runs of each tree (default 4)")
    parser.add_argument("--quick", action="store_true", help="a 32-sample job at 4 worlds")
    parser.add_argument("--sizes", type=int, nargs=2, metavar="N",
                        help="two sample counts: run the job at both in each round and report the per-sample cost")
    parser.add_argument("--json", metavar="FILE", help="write the rows and the summary here")
    parser.add_argument("job", nargs="*", help=f"generate's arguments (default: {' '.join(JOB)})")
    args = parser.parse_args(argv)
    if args.rounds < 1:
        parser.error(f"--rounds: got {args.rounds}; expected an integer >= 1")
    job = args.job or (QUICK_JOB if args.quick else JOB)
    if args.sizes and (min(args.sizes) < 1 or args.sizes[0] == args.sizes[1]):
        parser.error(f"--sizes: got {args.sizes}; expected two different sample counts >= 1")
    trees = {"this": sys.executable}
    if args.reference:
        trees["reference"] = reference_python(args.reference, Path(args.cache))
    elif args.reference_python:
        trees["reference"] = args.reference_python
    sizes = sorted(args.sizes) if args.sizes else None
    print(f"warpworm generate {' '.join(job)}: {args.rounds} rounds of {', '.join(trees)}"
          + (f", --num {sizes[0]} and {sizes[1]}" if sizes else ""))
    rows = alternated(trees, job, args.rounds, sizes=sizes)
    summary = summarize(rows)
    sys.path.insert(0, str(HERE))
    from run import table  # the runner's table format

    print(table(summary))
    print(NOTES)
    if args.json:
        record = {"job": job, "reference": args.reference or args.reference_python, "sizes": sizes, "rows": rows,
                  "summary": summary, "notes": NOTES}
        Path(args.json).write_text(json.dumps(record, indent=1))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
