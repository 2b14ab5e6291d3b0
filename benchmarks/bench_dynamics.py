"""Dynamics benchmark: worm-substeps per second of the batched solvers on the CPU (and CUDA when present).

Rows (one per device, solver, magnet model and W), in the gait setting (``gaits.DEFAULT_DT``; the implicit solver
at ``gaits.DEFAULT_SUBSTEPS`` = 1 ms substeps, the XPBD solvers at the 50 µs they need):
- ``substep_rate``: worm-substeps/s of the substeps alone (implicit / Gauss–Seidel: the one per-step launch of
  ``implicit_euler.implicit_step`` / ``xpbd_gs.gs_step``; Jacobi: the three substep kernels);
- ``wrench_ms_per_world``: one magnetic-wrench evaluation (poses, ``launch_world_wrenches``, distribution) per world;
- ``step_rate``: worm-substeps/s of whole steps (1 wrench + ``substeps`` substeps, the gait setting dt = 4 ms,
  80 substeps), i.e. what a simulation actually gets;
- ``realtime_factor``: simulated seconds per wall second per world at that rate (>= 1: real time for W = 1);
- ``sim_s_per_wall_s``: simulated seconds per wall second of the whole batch (W × realtime_factor);
- ``numpy_substep_rate`` and ``speedup_vs_numpy``: the same substep in NumPy (``numpy_substep.py``, float64: the
  implicit step with a dense batched ``np.linalg.solve`` (floor contact left out), a Gauss–Seidel sweep vectorized
  over worlds looping over elements, the Jacobi pass vectorized over worlds and elements);
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


def bench_one(W: int, magnet_model: str, device: str, with_numpy: bool, min_time: float,
              solver: str = "implicit") -> dict:
    from numpy_substep import NumpyGaussSeidel, NumpyImplicit, NumpySubstep

    from warpworm import gaits
    from warpworm.model import Model
    from warpworm.simulator import Simulator

    DT = gaits.DEFAULT_DT
    SUBSTEPS = gaits.DEFAULT_SUBSTEPS if solver == "implicit" else 80  # the XPBD solvers need 50 us substeps
    model = Model.from_params(gaits.preset_params("peristaltic", magnet_model=magnet_model), W, device)
    sim = Simulator(model, dt=DT, substeps=SUBSTEPS, solver=solver)
    state = sim.initial_state()
    sim.step(state, 1)
    if solver in ("implicit", "gauss_seidel"):
        cmd = sim._world_cmd(state, SUBSTEPS)

        def substeps():
            cmd.launch()

        t_sub = _timeit(substeps, min_time) / SUBSTEPS
    else:
        cmds = sim._substep_cmds(state)

        def substeps():
            for _ in range(10):
                for c in cmds:
                    c.launch()

        t_sub = _timeit(substeps, min_time) / 10
    t_wrench = _timeit(lambda: sim.update_magnets(state), min_time, max_reps=20)
    t_step = t_wrench + SUBSTEPS * t_sub  # one step = one wrench + SUBSTEPS substeps (measured apart: cheaper)
    row = {
        "device": device,
        "solver": solver,
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
        if solver == "implicit":
            ref = NumpyImplicit(model, sim.dt_sub, newton=sim.newton)
        elif solver == "gauss_seidel":
            ref = NumpyGaussSeidel(model, sim.dt_sub, iterations=sim.iterations)
        else:
            ref = NumpySubstep(model, sim.dt_sub, split_hinge=sim.split_hinge.numpy())
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
        # the XPBD solvers for comparison (analytic magnets; the substep does not depend on the magnet model)
        for solver in ("gauss_seidel", "jacobi"):
            for W in sizes[:3] if quick else [1, 256, 4096]:
                rows.append(bench_one(W, "analytic", device, W <= 256, 0.2 if quick else 0.5, solver=solver))
    return rows


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import table  # noqa: E402

    print(table(run("--quick" in sys.argv)))
