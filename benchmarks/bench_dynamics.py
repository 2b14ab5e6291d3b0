"""Dynamics benchmark: worm-substeps per second of the batched implicit solver, beside the NumPy reference and, when
the ``newton`` package is importable, Newton on the same mesh.

Rows of :func:`run` (one per device, magnet model and W), in the gait setting (peristaltic preset,
``gaits.DEFAULT_DT`` = 4 ms steps of ``gaits.DEFAULT_SUBSTEPS`` = 2 substeps of 2 ms):
- ``step_rate``: worm-substeps/s of whole steps (1 magnetic wrench + the step's substeps), timed at the gait's start (the EPM
  far: the analytic wrench is cheaper there than over a cycle; :func:`compare` times a whole cycle);
- ``substep_rate``: worm-substeps/s of the substeps alone (``Simulator.run_substeps``: the one launch of
  ``implicit_euler.implicit_step``);
- ``wrench_ms_per_world``: one magnetic-wrench evaluation (poses, wrench, distribution) per world;
- ``realtime_factor``: simulated seconds per second per world at the step rate (>= 1: real time for W = 1);
- ``sim_s_per_wall_s``: simulated worm-seconds per second of the whole batch (W × realtime_factor);
- ``numpy_substep_rate`` and ``speedup_vs_numpy``: the same substep in NumPy (``tests/numpy_reference.py``, float64: the
  implicit step with a dense batched ``np.linalg.solve``, floor contact left out);
- ``launches_per_substep``, ``bytes_per_world``; ``time_base``.

Time base: on the CPU the CPU time of this process (``time.process_time``), i.e. what one dedicated core delivers
(Warp runs a CPU kernel on the launching thread; on this shared 2-core machine the wall clock also counts other
processes' turns, up to several times the CPU time); on CUDA the wall clock after a device synchronize.

:func:`compare` is the one table of ``python benchmarks/run.py``: warpworm (whole gait steps and substeps alone),
the NumPy reference and Newton (or a "not installed" row), all measured in the same run.

``python benchmarks/run.py dynamics [--quick] [--device cuda]``; or ``python benchmarks/bench_dynamics.py [--quick]``.
"""

from __future__ import annotations

import sys
from pathlib import Path
import time

import numpy as np
import warp as wp

from warpworm import quiet_warp

# the tests' NumPy reference substep (tests/numpy_reference.py) is this benchmark's reference: tests/ is no package
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from warpworm.physics import gaits  # noqa: E402
from warpworm.sim import simulator
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

NEWTON_MESH = "39 vertices, 111 bars, 105 hinges"


def clock_for(device) -> tuple:
    """(clock, name): process CPU time on the CPU, wall time on CUDA (see the module docstring)."""
    if wp.get_device(device).is_cuda:
        return time.perf_counter, "wall"
    return time.process_time, "process CPU time"


def timeit(fn, device, min_time: float = 0.5, max_reps: int = 200) -> float:
    """Mean time [s] per call of ``fn`` (after one warm-up call) on ``device``'s clock, over at least ``min_time``."""
    clock, _ = clock_for(device)
    fn()
    wp.synchronize_device(device)
    reps, t0 = 0, clock()
    while True:
        fn()
        reps += 1
        wp.synchronize_device(device)
        el = clock() - t0
        if el >= min_time or reps >= max_reps:
            return el / reps


def mean_newton_steps(sim, substeps_run: int, key: str = "steps") -> float:
    """Newton steps (``key="factors"``: of them, those that factored the Hessian) per substep the worlds took on
    average since ``sim.newton_stats(reset=True)``, over ``substeps_run`` substeps each; NaN for a solver that does
    not count (the tile solvers)."""
    counted = sim.newton_stats()
    return float(counted[key].mean()) / substeps_run if counted is not None else float("nan")


def reference_newton_steps(sim, mean_steps: float) -> int:
    """The NumPy reference's Newton count for "the same step": the kernel's mean, rounded up (at least 2); the
    simulator's cap when the mean is unknown."""
    return max(2, int(np.ceil(mean_steps - 1e-9))) if mean_steps == mean_steps else sim.newton


def gait_sim(W: int, magnet_model: str = "analytic", device: str = "cpu", solver: str = "band"):
    """The peristaltic preset on ``W`` worlds at the gait setting, settled briefly: (model, sim, state)."""
    model = Model.from_params(gaits.preset_params("peristaltic", magnet_model=magnet_model), W, device)
    kw = {} if solver == "band" else {"solver": solver}  # the one-thread-per-world band solve is the default
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, **kw)
    state = sim.initial_state()
    sim.settle(state, 2 * sim.dt)  # compiles (and on CUDA captures) the step
    return model, sim, state


def bench_one(W: int, magnet_model: str, device: str, with_numpy: bool, min_time: float) -> dict:
    model, sim, state = gait_sim(W, magnet_model, device)
    S = sim.substeps
    t_step = timeit(lambda: sim.step(state, 1), device, min_time)
    t_sub = timeit(lambda: sim.run_substeps(state, S), device, min_time) / S
    t_wrench = timeit(lambda: sim.update_magnets(state), device, min_time, max_reps=20)
    sim.newton_stats(reset=True)
    sim.run_substeps(state, 10 * S)
    mean_steps = mean_newton_steps(sim, 10 * S)
    row = {
        "device": str(model.device),
        "magnets": magnet_model,
        "W": W,
        "substep_us": 1e6 * sim.dt_sub,
        "step_rate": W * S / t_step,
        "substep_rate": W / t_sub,
        "wrench_ms_per_world": 1e3 * t_wrench / W,
        "realtime_factor": sim.dt / t_step,
        "sim_s_per_wall_s": W * sim.dt / t_step,
        "newton_steps_per_substep": mean_steps,
        "launches_per_substep": sim.launches_per_substep,
        "bytes_per_world": model.bytes_per_world(),
        "time_base": clock_for(device)[1],
    }
    if with_numpy:
        t_np = numpy_substep_time(model, sim, state, min_time, newton=reference_newton_steps(sim, mean_steps))
        row["numpy_substep_rate"] = W / t_np
        row["speedup_vs_numpy"] = t_np / t_sub
    return row


def numpy_substep_time(model, sim, state, min_time: float, newton: int | None = None) -> float:
    """Process CPU time [s] of one NumPy reference substep of all ``model``'s worlds with ``newton`` Newton steps
    (default the simulator's most; NumPy's BLAS may use threads: they count too)."""
    from numpy_reference import NumpyImplicit

    # floor=False: the reference's vectorised substep without the floor (its floor code loops over vertices in
    # Python: a test's truth, not a speed reference), the same work it timed before the floor was added
    ref = NumpyImplicit(model, sim.dt_sub, newton=sim.newton if newton is None else newton, floor=False)
    x, v, a = ref.init(state, sim.control)
    f = state.external_force.numpy().astype(np.float64)
    return timeit(lambda: ref.substep(x, v, a, f), "cpu", min_time, max_reps=50)


# ---------------------------------------------------------------------------------------------------------------------
# Newton (optional; not a dependency)


def newton_row(device: str = "cpu", *, dt: float = 5.0e-5, hinge_scale: float = 0.3, duration: float = 0.02) -> dict:
    """Newton's semi-implicit particle solver on the same mesh (the worm's rest shape, vertex masses, bars as springs
    EA/L0, creases as Newton's dihedral bending elements with ``hinge_scale`` × k_α, a ground plane with the worm's
    friction): one world, ``dt`` [s] steps (semi-implicit needs ~50 µs; it was stable only with the hinges softened
    to 0.3×), timed over ``duration`` simulated seconds. A "not installed" row when ``newton`` is not importable."""
    base = {"system": "Newton (semi-implicit)", "device": str(device), "W": 1, "mesh": NEWTON_MESH}
    try:
        import newton
    except ImportError:
        return {**base, "substep_us": "", "note": "not installed (pip install newton: optional, not a dependency)"}

    model = Model.from_params(gaits.preset_params("peristaltic"), 1, "cpu")
    pat = model.pattern
    x0 = model.rest_positions_host[0].astype(np.float64)
    mass = np.asarray(model.vertex_mass_host)[0]
    EA = np.broadcast_to(model.bar_stiffness.numpy().reshape(-1), (model.num_edges,))
    L0 = model.rest_length.numpy().reshape(-1)[: model.num_edges]
    k_hinge = float(np.asarray(model.hinge_stiffness.numpy()).reshape(-1)[0]) * hinge_scale
    mu = float(np.asarray(model.mu_kinetic.numpy()).reshape(-1)[0])
    b = newton.ModelBuilder(gravity=(0.0, 0.0, -float(np.asarray(model.gravity.numpy()).reshape(-1)[0])))
    for v in range(model.num_vertices):
        b.add_particle(wp.vec3(*(float(c) for c in x0[v])), wp.vec3(0.0, 0.0, 0.0), float(mass[v]), radius=1.0e-4)
    for e, (i, j) in enumerate(pat.edges):
        b.add_spring(int(i), int(j), float(EA[e] / L0[e]), 0.0, 0.0)
    for i, j, k, l in pat.hinges:  # warpworm (i, j, k, l): edge j-k, wings i, l -> Newton (wing, wing, edge, edge)
        b.add_edge(int(i), int(l), int(j), int(k), edge_ke=k_hinge, edge_kd=0.0)
    # contact: Newton's defaults (shape kd = 100, kf = 1000 N s/m; particle kd = 10) on vertices of ~1e-5 kg are explicit
    # damping / friction rates of 1e6-1e8 /s, unstable at any dt above a few µs (the worm is thrown off the floor);
    # 1e-2 N s/m keeps k dt / m < 1 at 50 µs
    cfg = b.default_shape_cfg
    cfg.ke, cfg.kd, cfg.kf, cfg.mu = 1.0e3, 1.0e-2, 1.0e-2, mu
    b.add_ground_plane()
    nm = b.finalize(device=device)
    nm.soft_contact_ke, nm.soft_contact_kd, nm.soft_contact_mu = 1.0e3, 1.0e-2, mu
    nm.particle_grid = None  # no particle-particle contact (neighbouring vertices of one sheet)
    pipeline = newton.CollisionPipeline(nm, reduce_contacts=False, broad_phase="nxn")
    contacts = pipeline.contacts()
    solver = newton.solvers.SolverSemiImplicit(nm)
    s0, s1 = nm.state(), nm.state()
    n = max(2, 2 * int(round(duration / dt / 2)))

    def two_steps():  # an even number of steps leaves s0 / s1 where they were: one capturable unit
        for a, b_ in ((s0, s1), (s1, s0)):
            a.clear_forces()
            pipeline.collide(a, contacts)
            solver.step(a, b_, None, contacts, dt)

    two_steps()  # compile
    graph = None
    try:  # graph capture (CPU graphs too in Warp >= 1.19): the launches recorded once, replayed
        with wp.ScopedCapture(device=device) as cap:
            two_steps()
        graph = cap.graph
    except Exception:
        graph = None

    def run():
        for _ in range(n // 2):
            if graph is not None:
                wp.capture_launch(graph)
            else:
                two_steps()

    t = timeit(run, device, min_time=0.5, max_reps=20)
    rate = n / t
    z = s0.particle_q.numpy()[:, 2]
    stable = bool(np.all(np.isfinite(z)) and np.abs(z).max() < 0.1)  # on the floor, not thrown off it
    return {**base, "substep_us": 1e6 * dt, "step_rate": rate, "sim_s_per_wall_s": rate * dt,
            "time_base": clock_for(device)[1],
            "note": f"newton {getattr(newton, '__version__', '?')}, hinges x{hinge_scale}, "
                    f"{'graph' if graph is not None else 'no graph'}, {'stable' if stable else 'UNSTABLE'} "
                    f"(vertex z {1e3 * float(np.min(z)):.2f} to {1e3 * float(np.max(z)):.2f} mm after the run)"}


# ---------------------------------------------------------------------------------------------------------------------


def solvers_for(device) -> tuple:
    """The solvers to compare: every ``simulator.SOLVERS`` entry on CUDA (the tile paths are the GPU's), the default
    band solve on the CPU."""
    if wp.get_device(device).is_cuda:
        return tuple(getattr(simulator, "SOLVERS", ("band",)))
    return ("band",)


def compare(device: str = "cpu", sizes=None, quick: bool = False, solvers=None,
            numpy_reference: bool = True) -> list[dict]:
    """The one table of ``python benchmarks/run.py``: per W (and solver, :func:`solvers_for`), warpworm's whole gait
    steps (analytic magnets) and its substeps alone, then the NumPy reference of the substep and Newton on the same
    mesh, measured in this run.

    ``sizes`` default: (1, 64) on the CPU (quick: (1, 16)), (1024, 16384, 65536) on CUDA. The gait step is timed over
    one EPM cycle (a quarter with ``quick`` or on CUDA). The NumPy reference runs at the smallest W only on CUDA (a
    dense 117-unknown solve per world on the host: 64k worlds would take minutes); ``numpy_reference=False`` leaves it
    out (a caller timing one large size at a time).
    """
    quiet_warp()
    wp.init()
    cuda = wp.get_device(device).is_cuda
    if sizes is None:
        sizes = (1024, 16384, 65536) if cuda else ((1, 16) if quick else (1, 64))
    solvers = tuple(solvers or solvers_for(device))
    min_time = 0.2 if quick else 0.5
    rows = []
    for W in sizes:
        for solver in solvers:
            try:
                model, sim, state = gait_sim(W, "analytic", device, solver)
            except Exception as exc:  # e.g. a solver that does not fit this device: one row says so
                rows.append({"system": f"warpworm ({solver})", "device": str(device), "W": W,
                             "note": f"failed: {type(exc).__name__}: {exc}"[:160]})
                continue
            S, (clock, base) = sim.substeps, clock_for(device)
            # whole steps over an EPM cycle (a quarter with quick / on CUDA): the analytic wrench costs more when the
            # EPM is near (composite panels), so the gait's start alone (EPM far) would flatter it
            period = float(np.max(np.asarray(model.params.cycle_period)))
            n = max(1, int(round(period / sim.dt / (4 if (quick or cuda) else 1))))
            # the first cycle, untimed: there the worm is pulled in to the EPM's line and the Newton iteration is
            # at its easiest (2.9 steps per 2 ms substep against 4.1-4.7 in the cycles after it)
            sim.step(state, n)
            wp.synchronize_device(device)
            sim.newton_stats(reset=True)
            t0 = clock()
            sim.step(state, n)
            wp.synchronize_device(device)
            t_step = (clock() - t0) / n
            mean_steps = mean_newton_steps(sim, n * S)
            t_sub = timeit(lambda: sim.run_substeps(state, S), device, min_time) / S
            tag = "" if solver == "band" and len(solvers) == 1 else f", {solver}"
            common = {"device": str(model.device), "W": W, "substep_us": 1e6 * sim.dt_sub, "time_base": base}
            if cuda:  # what this size holds on the GPU (model, state, solver scratch, graphs), mempool bytes in use
                common["gpu_mem_MiB"] = wp.get_mempool_used_mem_current(device) / 2**20
            rows.append({"system": f"warpworm gait step (analytic magnets{tag})", **common,
                         "step_rate": W * S / t_step, "sim_s_per_wall_s": W * sim.dt / t_step,
                         "newton_steps": mean_steps,
                         "note": f"1 wrench + {S} substeps per {sim.dt * 1e3:g} ms, {n} steps of the peristaltic gait after as many untimed"})
            rows.append({"system": f"warpworm substeps alone{tag.replace(', ', ' (') + ')' if tag else ''}",
                         **common, "step_rate": W / t_sub, "sim_s_per_wall_s": W * sim.dt_sub / t_sub,
                         "note": "implicit substeps to the Newton tolerance"})
            if numpy_reference and solver == solvers[0] and (not cuda or W == min(sizes)):
                k = reference_newton_steps(sim, mean_steps)
                t_np = numpy_substep_time(model, sim, state, min_time, newton=k)
                rows.append({"system": "NumPy reference substep", "device": "cpu", "W": W,
                             "substep_us": 1e6 * sim.dt_sub, "time_base": "process CPU time", "step_rate": W / t_np,
                             "sim_s_per_wall_s": W * sim.dt_sub / t_np, "newton_steps": float(k),
                             "note": "float64 dense solve, no floor"})
            del model, sim, state
    try:
        rows.append(newton_row("cpu"))
    except Exception as exc:  # an API change in an optional package must not sink the table
        rows.append({"system": "Newton (semi-implicit)", "device": "cpu", "W": 1, "mesh": NEWTON_MESH,
                     "note": f"failed: {type(exc).__name__}: {exc}"[:160]})
    ref = {r["W"]: r["step_rate"] for r in rows if r["system"] == "NumPy reference substep"}
    for r in rows:
        if r["system"].startswith("warpworm substeps alone") and r["W"] in ref:
            r["vs_numpy"] = r["step_rate"] / ref[r["W"]]
    return rows


def run(quick: bool = False, device: str | None = None) -> list[dict]:
    quiet_warp()
    wp.init()
    if device is None:
        devices = ["cpu"] + (["cuda:0"] if wp.is_cuda_available() else [])
    else:
        devices = [device]
    rows = []
    for dev in devices:
        cuda = wp.get_device(dev).is_cuda
        if cuda:
            sizes = [1024, 16384] if quick else [1024, 16384, 65536]
        else:
            sizes = [1, 16, 256] if quick else [1, 16, 256, 1024, 4096]
        for magnet_model in ("analytic", "dipoles"):
            for W in sizes:
                with_numpy = W <= (1024 if cuda else 4096)
                rows.append(bench_one(W, magnet_model, dev, with_numpy, 0.2 if quick else 0.5))
    return rows


if __name__ == "__main__":
    from run import table  # noqa: E402

    print(table(run("--quick" in sys.argv)))
