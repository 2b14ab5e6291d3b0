"""One short job on every core: 1 thread vs 2 threads of one process.

Run: ``python benchmarks/run.py threads [--quick]``.

Three short interactive jobs at a few hundred worlds, each as the library runs it for its command:

* ``simulate``: :func:`warpworm.analysis.gait_runs.run_gait_split`, 256 randomized peristaltic worlds of the default
  config, a quarter cycle recorded at 30 frames/s (``warpworm simulate --worlds 256 --cycles 0.25``);
* ``experiment``: :func:`warpworm.analysis.experiments.compression` over 192 hinge stiffnesses, 2 increments
  (``warpworm experiment compression``);
* ``search``: :func:`warpworm.analysis.gait_search.search_gait`, a 16 x 4 x 4 = 256-point omega grid, one cycle of
  a 0.2 s EPM period (``warpworm search-gait``).

Modes: ``threads1`` (one batch, this thread) and ``threads2`` (:mod:`warpworm.analysis.world_split`: two threads of
this process). (The process pools the split replaced are retired; docs/dynamics.md, "One job on every core", keeps
their measurements.) The modes alternate over the rounds (5; 2 with ``--quick``), every result is checked equal to
``threads1``'s, and each row gives the wall time, the CPU time of this process and its children, ``main_cpu_s``: the
CPU of the calling thread alone (for threads2: the serial part, what the split leaves to one thread; for threads1:
everything), ``speedup`` = wall of threads1 / wall of the mode in the same round, and ``others_cores``: the CPU the
other processes of this shared machine used meanwhile (a busy machine cannot give two cores to anyone). One row per job and mode with ``round = "median"`` gives the median speedup over
the rounds: on a VM whose speed moves by 10-20 % between seconds, single rounds scatter by as much.
"""

from __future__ import annotations

import json
import os
import resource
import time
from dataclasses import replace

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis import experiments as ex
from warpworm.analysis import gait_runs as gr
from warpworm.analysis import gait_search as gs
from warpworm.analysis.world_split import load_kernels
from warpworm.physics import gaits

NOTES = ("speedup: wall of threads1 over the mode's, same round; cpu_s: this process and its children; "
         "main_cpu_s: the calling thread's CPU (threads2: the part left serial); "
         "others_cores: CPU the other processes used during the row")


# ---------------------------------------------------------------------------------------------------------------------
def _busy_jiffies() -> int:
    with open("/proc/stat") as f:
        v = [int(x) for x in f.readline().split()[1:]]
    return sum(v) - v[3] - v[4]


def _cpu() -> float:
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


def _timed(fn):
    hz = os.sysconf("SC_CLK_TCK")
    j0, c0, m0, t0 = _busy_jiffies(), _cpu(), time.thread_time(), time.perf_counter()
    out = fn()
    j1, c1, m1, t1 = _busy_jiffies(), _cpu(), time.thread_time(), time.perf_counter()
    return out, t1 - t0, c1 - c0, max(0.0, (j1 - j0) / hz - (c1 - c0)) / max(t1 - t0, 1e-9), m1 - m0


def _tasks(quick: bool):
    n = 64 if quick else 256
    p_sim = gr.randomized_params("default", "peristaltic", False, "analytic", n, 0)
    k = np.geomspace(0.0025, 0.04, 48 if quick else 192)
    grid = gs.parse_grid(f"w=0.012:0.024:{n // 16},a=0.02:0.04:4,h=0.02:0.03:4")
    p_search = replace(gaits.preset_params("omega"), cycle_period=0.2)

    def simulate(mode):
        r = gr.run_gait_split(p_sim, n, 0.25, workers=1 if mode == "threads1" else 2, fps=30.0, save_worlds=0)
        return r["displacement_m"]

    def experiment(mode):
        r = ex.compression(k, increments=2, hold=0.05, settle=0.05, workers=1 if mode == "threads1" else 2)
        return np.concatenate([r["force_raw"].ravel(), r["linear"].ravel()])  # the simulation and the prediction

    def search(mode):
        r = gs.search_gait(p_search, grid, 1, workers=1 if mode == "threads1" else 2, fps=25.0)
        return r["per_cycle_m"]

    return {"simulate": (simulate, n), "experiment": (experiment, len(k)), "search": (search, n)}


def _job_rows(name: str, fn, worlds: int, modes: tuple, rounds: int) -> list[dict]:
    """One job's rows: ``rounds`` rounds of every mode (the order reversed every other round), each result checked
    equal to threads1's, the speedups over threads1 of the same round, and a median row per mode."""
    rows = []
    for rnd in range(rounds):
        outs, these = {}, []
        for mode in (modes if rnd % 2 == 0 else modes[::-1]):
            outs[mode], wall, cpu, others, main = _timed(lambda: fn(mode))
            these.append({"bench": "threads", "job": name, "worlds": worlds, "round": rnd, "mode": mode,
                          "wall_s": wall, "cpu_s": cpu, "main_cpu_s": main, "others_cores": others})
        for mode, out in outs.items():  # every split gives the one-batch numbers
            assert np.array_equal(out, outs["threads1"], equal_nan=True), (name, mode)
        base = next(r["wall_s"] for r in these if r["mode"] == "threads1")
        for r in these:
            r["speedup"] = base / r["wall_s"]
        rows += these
    return rows + [{"bench": "threads", "job": name, "worlds": worlds, "round": "median", "mode": mode,
                    "speedup": float(np.median([r["speedup"] for r in rows if r["mode"] == mode]))}
                   for mode in modes[1:]]


def run(quick: bool = False) -> list[dict]:
    quiet_warp()
    load_kernels("cpu")
    rows = []
    modes = ("threads1", "threads2")
    for name, (fn, worlds) in _tasks(quick).items():
        fn("threads2")  # warm: the first Model / Simulator of a size, the caches
        rows += _job_rows(name, fn, worlds, modes, 2 if quick else 5)
    return rows


if __name__ == "__main__":
    print(json.dumps(run(quick=True), indent=1, default=str))
