"""Dynamics benchmark: worm-substeps per second of the batched implicit solver on the CPU (and CUDA when present).

Rows (one per device, magnet model and W), in the gait setting (``gaits.DEFAULT_DT`` at ``gaits.DEFAULT_SUBSTEPS``
= 1 ms substeps):
- ``substep_rate``: worm-substeps/s of the substeps alone (the one per-step launch of
  ``implicit_euler.implicit_step``);
- ``wrench_ms_per_world``: one magnetic-wrench evaluation (poses, ``launch_world_wrenches``, distribution) per world;
- ``step_rate``: worm-substeps/s of whole steps (1 wrench + ``substeps`` substeps, the gait setting dt = 4 ms,
  4 substeps), i.e. what a simulation actually gets;
- ``realtime_factor``: simulated seconds per wall second per world at that rate (>= 1: real time for W = 1);
- ``sim_s_per_wall_s``: simulated seconds per wall second of the whole batch (W × realtime_factor);
- ``numpy_substep_rate`` and ``speedup_vs_numpy``: the same substep in NumPy (``numpy_substep.py``, float64: the
  implicit step with a dense batched ``np.linalg.solve``, floor contact left out);
- ``launches_per_substep``, ``bytes_per_world``;
- ``paper_ratio``: substep_rate(W) / 400, the paper's ~400 Kangaroo iterations per second for one worm.

``python benchmarks/run.py dynamics [--quick]``; or ``python benchmarks/bench_dynamics.py [--quick]``.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np
import warp as wp

from warpworm import quiet_warp

sys.path.insert(0, str(Path(__file__).resolve().parent))

PAPER_ITERATIONS_PER_S = 400.0


def _timeit(fn, min_time=0.5, max_reps=200):
    fn()  # warm
    wp.synchronize()
    reps, t0 = 0, time.perf_counter()
    while True:
        fn()
        reps += 1
        wp.synchronize()
        el = time.perf_counter() - t0
        if el >= min_time or reps >= max_reps:
            return el / reps


def bench_one(W: int, magnet_model: str, device: str, with_numpy: bool, min_time: float) -> dict:
    from numpy_substep import NumpyImplicit

    from warpworm import gaits
    from warpworm.model import Model
    from warpworm.simulator import Simulator

    DT = gaits.DEFAULT_DT
    SUBSTEPS = gaits.DEFAULT_SUBSTEPS
    model = Model.from_params(gaits.preset_params("peristaltic", magnet_model=magnet_model), W, device)
    sim = Simulator(model, dt=DT, substeps=SUBSTEPS)
    state = sim.initial_state()
    sim.step(state, 1)
    cmd = sim._world_cmd(state, sim.control, SUBSTEPS)
    t_sub = _timeit(cmd.launch, min_time) / SUBSTEPS
    t_wrench = _timeit(lambda: sim.update_magnets(state), min_time, max_reps=20)
    t_step = t_wrench + SUBSTEPS * t_sub  # one step = one wrench + SUBSTEPS substeps (measured apart: cheaper)
    row = {
        "device": device,
        "magnets": magnet_model,
        "W": W,
        "substep_us": 1e6 * sim.dt_sub,
        "substep_rate": W / t_sub,
        "wrench_ms_per_world": 1e3 * t_wrench / W,
        "step_rate": W * SUBSTEPS / t_step,
        "realtime_factor": DT / t_step,
        "sim_s_per_wall_s": W * DT / t_step,
        "launches_per_substep": sim.launches_per_substep,
        "bytes_per_world": model.bytes_per_world(),
        "paper_ratio": (W / t_sub) / PAPER_ITERATIONS_PER_S,
    }
    if with_numpy:
        ref = NumpyImplicit(model, sim.dt_sub, newton=sim.newton)
        x, v, a = ref.init(state)
        f = state.external_force.numpy().astype(np.float64)
        t_np = _timeit(lambda: ref.substep(x, v, a, f), min_time, max_reps=50)
        row["numpy_substep_rate"] = W / t_np
        row["speedup_vs_numpy"] = t_np / t_sub
    return row


def run(quick: bool = False) -> list[dict]:
    quiet_warp()
    wp.init()
    sizes = [1, 16, 256] if quick else [1, 16, 256, 1024, 4096, 16384]
    devices = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
    rows = []
    for device in devices:
        for magnet_model in ("analytic", "dipoles"):
            for W in sizes:
                with_numpy = W <= 4096
                rows.append(bench_one(W, magnet_model, device, with_numpy, 0.2 if quick else 0.5))
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import table  # noqa: E402

    print(table(run("--quick" in sys.argv)))
