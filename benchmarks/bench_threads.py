"""One short job on every core: 1 thread vs 2 threads of one process vs the old spawned process pool per batch.

Run: ``python benchmarks/run.py threads [--quick]``.

Three short interactive jobs at a few hundred worlds, each as the library runs it for its command:

* ``simulate``: :func:`warpworm.analysis.gait_runs.run_gait_split`, 256 randomized peristaltic worlds of the default
  config, a quarter cycle recorded at 30 frames/s (``warpworm simulate --worlds 256 --cycles 0.25``);
* ``experiment``: :func:`warpworm.analysis.experiments.compression` over 192 hinge stiffnesses, 2 increments
  (``warpworm experiment compression``);
* ``search``: :func:`warpworm.analysis.gait_search.search_gait`, a 16 x 4 x 4 = 256-point omega grid, one cycle of
  a 0.2 s EPM period (``warpworm search-gait``).

Modes: ``threads1`` (one batch, this thread), ``threads2`` (:mod:`warpworm.analysis.world_split`: two threads of this
process), ``processes2`` (the split of before: a ``spawn`` pool of two processes made for the batch and closed
after it, reproduced here as it was, so both run in the same session) and ``pool2`` (the same shares in a pool of two
processes started and warmed before the timing, that outlives the batches: no GIL, no start-up, so the machine's own
ceiling for splitting this job in two; what a VM's two cores give two independent processes). The modes alternate
over the rounds (5; 2 with ``--quick``), every result is checked equal to ``threads1``'s, and each row gives the wall
time, the CPU time of this process and its children (pool2: this process only), ``main_cpu_s``: the CPU of the calling
thread alone (for threads2: the serial part, what the split leaves to one thread; for threads1: everything),
``speedup`` = wall of threads1 / wall of the mode in the same round, and ``others_cores``: the CPU the other
processes of this shared machine used meanwhile (a busy machine cannot give two cores to anyone; for pool2 it
counts the pool's own processes). One row per job and mode with ``round = "median"`` gives the median speedup over
the rounds: on a VM whose speed moves by 10-20 % between seconds, single rounds scatter by as much.
"""

from __future__ import annotations

import os
import resource
import time
from dataclasses import replace
from functools import partial

import numpy as np

NOTES = ("speedup: wall of threads1 over the mode's, same round; cpu_s: this process and its children; "
         "main_cpu_s: the calling thread's CPU (threads2: the part left serial); "
         "others_cores: CPU the other processes used during the row")


def _importable():
    """This module as ``import bench_threads`` gives it (benchmarks/run.py loads it from its path without registering
    it): what a spawned process imports to unpickle a share's function."""
    import importlib

    return importlib.import_module("bench_threads")


# ---------------------------------------------------------------------------------------------------------------------
# The split before world_split (a spawn pool per batch), kept here only to compare against
def _old_gait_share(job):
    from warpworm import quiet_warp
    from warpworm.analysis.gait_runs import run_gait

    params, n, cycles, kw = job
    quiet_warp()
    r = run_gait(params, n, cycles, **kw)
    return {k: r[k] for k in ("displacement_m", "unstable", "crumpled", "sim_time_s", "metrics", "frames")}


def old_run_gait_split(params, num_worlds, cycles, *, workers=None, pool=None, **kw):
    """``run_gait_split`` as it was: a spawned pool of ``workers`` processes per call (or the given warm ``pool``)."""
    from warpworm.physics.params import slice_worlds

    bounds = np.linspace(0, num_worlds, workers + 1).astype(int)
    save = kw.pop("save_worlds", 4)
    jobs = [(slice_worlds(params, num_worlds, lo, hi), int(hi - lo), cycles,
             dict(kw, save_worlds=int(max(0, min(save - lo, hi - lo))))) for lo, hi in zip(bounds[:-1], bounds[1:])]
    parts = _map(pool, workers, _importable()._old_gait_share, jobs)
    out = {k: np.concatenate([p[k] for p in parts]) for k in ("displacement_m", "unstable", "crumpled")}
    out["metrics"] = (None if parts[0]["metrics"] is None else
                      {k: np.concatenate([p["metrics"][k] for p in parts]) for k in parts[0]["metrics"]})
    out["sim_time_s"], out["frames"], out["model"], out["sim"] = parts[0]["sim_time_s"], None, None, None
    return out


def _old_core_share(job):
    from warpworm import quiet_warp
    from warpworm.sim.model import Model

    core, params, num_worlds, device, model_kw, run_kw = job
    quiet_warp()
    return core(Model.from_params(params, num_worlds, device, **model_kw), params, **run_kw)


def old_split_run(core, params, num_worlds, world_axis, *, workers=1, device="cpu", model_kw=None, pool=None,
                  **run_kw):
    """``experiments.split_run`` as it was: a spawned pool of ``workers`` processes per call (or the warm ``pool``)."""
    from warpworm.analysis.world_split import world_shares
    from warpworm.physics.params import slice_worlds

    jobs = [(core, slice_worlds(params, num_worlds, lo, hi), hi - lo, device, dict(model_kw or {}), run_kw)
            for lo, hi in world_shares(num_worlds, workers)]
    parts = _map(pool, len(jobs), _importable()._old_core_share, jobs)
    return {k: (np.concatenate([q[k] for q in parts], axis=world_axis[k]) if k in world_axis else parts[0][k])
            for k in parts[0]}


def _map(pool, workers, fn, jobs):
    """``pool.map(fn, jobs)`` on the warm ``pool``, or on a spawned pool of ``workers`` made for this call."""
    import multiprocessing as mp

    if pool is not None:
        return pool.map(fn, jobs, chunksize=1)
    with mp.get_context("spawn").Pool(workers) as fresh:
        return fresh.map(fn, jobs)


def _warm_share(_):
    """Imports and the kernel modules in a pool process, before the timing (held 1 s, so that the other task of the
    pair goes to the other process)."""
    from warpworm.analysis.world_split import load_kernels

    load_kernels("cpu")
    time.sleep(1.0)
    return os.getpid()


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


def _tasks(quick: bool, pool=None):
    from warpworm.analysis import experiments as ex
    from warpworm.analysis import gait_runs as gr
    from warpworm.analysis import gait_search as gs
    from warpworm.physics import gaits

    n = 64 if quick else 256
    p_sim = gr.randomized_params("default", "peristaltic", False, "analytic", n, 0)
    k = np.geomspace(0.0025, 0.04, 48 if quick else 192)
    grid = gs.parse_grid(f"w=0.012:0.024:{n // 16},a=0.02:0.04:4,h=0.02:0.03:4")
    p_search = replace(gaits.preset_params("omega"), cycle_period=0.2)

    def old(split, mode):  # the process splits: per batch (processes2) or the warm pool (pool2)
        return partial(split, pool=pool if mode == "pool2" else None)

    def simulate(mode):
        split = old(old_run_gait_split, mode) if mode.startswith("p") else gr.run_gait_split
        r = split(p_sim, n, 0.25, workers=1 if mode == "threads1" else 2, fps=30.0, save_worlds=0)
        return r["displacement_m"]

    def experiment(mode):
        real = ex.split_run
        ex.split_run = old(old_split_run, mode) if mode.startswith("p") else real
        try:
            r = ex.compression(k, increments=2, hold=0.05, settle=0.05, workers=1 if mode == "threads1" else 2)
        finally:
            ex.split_run = real
        return np.concatenate([r["force_raw"].ravel(), r["linear"].ravel()])  # the simulation and the prediction

    def search(mode):
        real = gr.run_gait_split
        gr.run_gait_split = old(old_run_gait_split, mode) if mode.startswith("p") else real
        try:
            r = gs.search_gait(p_search, grid, 1, workers=1 if mode == "threads1" else 2, fps=25.0)
        finally:
            gr.run_gait_split = real
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
    import multiprocessing as mp

    from warpworm import quiet_warp
    from warpworm.analysis.world_split import load_kernels

    quiet_warp()
    load_kernels("cpu")
    rows = []
    modes = ("threads1", "threads2", "processes2", "pool2")
    with mp.get_context("spawn").Pool(2) as pool:
        warm = set()
        for _ in range(10):  # until both processes have loaded (a task held 1 s goes to the idle one)
            warm |= set(pool.map(_importable()._warm_share, range(2), chunksize=1))
            if len(warm) == 2:
                break
        for name, (fn, worlds) in _tasks(quick, pool).items():
            for mode in ("threads2", "pool2", "pool2"):  # warm: the first Model / Simulator of a size, the caches
                fn(mode)
            rows += _job_rows(name, fn, worlds, modes, 2 if quick else 5)
    return rows


if __name__ == "__main__":
    import json

    print(json.dumps(run(quick=True), indent=1, default=str))
