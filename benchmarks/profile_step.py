#!/usr/bin/env python
"""Profile of a gait run's dynamics: time per kernel launch of :meth:`warpworm.sim.simulator.Simulator.step`.

The run is what ``warpworm simulate --magnet-model analytic`` does (the peristaltic preset, or ``--gait``'s, ``gaits.DEFAULT_DT`` with
``gaits.DEFAULT_SUBSTEPS``: 4 ms steps of two 2 ms substeps): build, settle (EPM parked), then the gait, without
frame snapshots. Every ``wp.launch`` and every recorded-command launch (the substeps' one ``implicit_step``) is
timed by the wall clock around it with a device synchronize after it (a CPU launch runs synchronously anyway), keyed
by kernel name; whatever the step spends outside the launches (array zeroing, Python) is the ``host`` row. The
timers wrap the launch functions, not the simulator, so the profile follows whatever the simulator launches.

Two extra measurements give the candidate levers a size:
- ``newton``: the implicit substep alone at 2, 3 and 4 Newton steps (the cost of one Newton step);
- ``launch_floor``: a trivial one-thread kernel, the fixed cost of a CPU launch (what graph capture or fused
  launches could save per launch).

Usage::

    python benchmarks/profile_step.py [--worlds 1 64] [--gait peristaltic omega inchworm] [--duration 1.0]
        [--out benchmarks/results/profile_step.json]
    python benchmarks/profile_step.py --parts --worlds 64 --gait omega  # a Newton step's parts, each alone

Prints one table per world count and writes the JSON (rows + metadata).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from collections import defaultdict
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import warp as wp

from warpworm import quiet_warp
from warpworm.kernels import implicit_euler as ie
from warpworm.kernels import substep as sub
from warpworm.kernels.banded_cholesky import ALL_ROWS, banded_cholesky_factor, banded_cholesky_solve
from warpworm.kernels.hinge_lanes import add_hinges, update_hinge_angles_lanes
from warpworm.physics import gaits
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator
from warpworm.sim.solver import state_struct

HERE = Path(__file__).resolve().parent

STAGES = {
    "epm_sine_pose": "EPM pose",
    "epm_keyframe_pose": "EPM pose",
    "ipm_poses": "IPM poses",
    "world_pair_wrench_kernel": "wrench (magnet pairs)",
    "sum_pair_wrenches_kernel": "wrench (sums)",
    "distribute_wrench": "distribute wrench",
    "implicit_step": "implicit substeps",
}
"""Kernel name -> the stage it is reported as (a kernel not listed is reported under its own name)."""


@contextmanager
def launch_timers():
    """Time every ``wp.launch`` and ``wp.Launch.launch`` inside the block.

    Yields ``{kernel key: [wall seconds, CPU seconds of this thread, launches]}``. On the CPU the thread's CPU time is
    the figure to read: a CPU kernel runs on the launching thread, and on a shared machine the wall time also counts
    the time other processes held the core (seen here: wall up to 3x the CPU time under a load of 3.7 on 2 cores).
    """
    acc: dict = defaultdict(lambda: [0.0, 0.0, 0])
    orig_launch, orig_cmd = wp.launch, wp.Launch.launch

    def _timed(key, device, fn):
        t0, c0 = time.perf_counter(), time.thread_time()
        out = fn()
        wp.synchronize_device(device)
        a = acc[key]
        a[0] += time.perf_counter() - t0
        a[1] += time.thread_time() - c0
        a[2] += 1
        return out

    def launch(kernel, *args, **kw):
        if kw.get("record_cmd"):  # recording only: timed when the command is launched
            return orig_launch(kernel, *args, **kw)
        return _timed(kernel.key, kw.get("device"), lambda: orig_launch(kernel, *args, **kw))

    def cmd_launch(self, *args, **kw):
        return _timed(self.kernel.key, self.device, lambda: orig_cmd(self, *args, **kw))

    wp.launch, wp.Launch.launch = launch, cmd_launch
    try:
        yield acc
    finally:
        wp.launch, wp.Launch.launch = orig_launch, orig_cmd


def _build(W: int, magnet_model: str, device: str, newton: int | None = None, newton_tol: float | None = None,
           gait: str = "peristaltic", sim_kw: dict | None = None):
    """The gait preset's model and simulator (default peristaltic); no CUDA graph (each launch must be seen to be timed: the
    profile's whole-run figures on CUDA are therefore without graph replay, see ``benchmarks/run.py`` for those)."""
    model = Model.from_params(gaits.preset_params(gait, magnet_model=magnet_model), W, device)
    kw = {} if newton is None else {"newton": newton}
    kw.update(sim_kw or {})
    if newton_tol is not None:
        kw["newton_tol"] = newton_tol
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, use_graph=False, **kw)
    return model, sim


def profile_run(W: int, *, duration: float, settle: float, skip: float = 1.0, magnet_model: str = "analytic",
                device: str = "cpu", gait: str = "peristaltic", sim_kw: dict | None = None) -> dict:
    """Settle, ``skip`` [s] of the ``gait`` preset untimed (its first cycle, where the worm is pulled in to the
    EPM's line and the Newton iteration is at its easiest), then ``duration`` [s] with every launch timed.

    Returns ``{"W", "steps", "wall_s", "cpu_s", "us_per_world_step", "worm_substeps_per_s", "sim_s_per_wall_s",
    "stages": [{stage, kernel, calls_per_step, us_per_step, us_per_world_step, share, wall_us_per_step}], ...}``.
    Per-step figures cover the gait steps only (the settle runs first, untimed, so compilation and the settling
    transient stay out); ``us_*`` and ``share`` are CPU time of the launching thread on the CPU (what one dedicated
    core delivers), wall time on CUDA; the rates are per that time (``*_wall`` beside them: per wall second).
    """
    model, sim = _build(W, magnet_model, device, gait=gait, sim_kw=sim_kw)
    state = sim.initial_state()
    sim.step(state, 1, epm=False)  # compile every kernel before anything is timed
    sim.settle(state, settle)
    sim.step(state, int(round(skip / sim.dt)))
    n_steps = max(1, int(round(duration / sim.dt)))
    use_cpu = not model.device.is_cuda
    sim.newton_stats(reset=True)
    with launch_timers() as acc:
        wp.synchronize_device(model.device)
        t0, c0 = time.perf_counter(), time.thread_time()
        sim.step(state, n_steps)
        wp.synchronize_device(model.device)
        wall, cpu = time.perf_counter() - t0, time.thread_time() - c0
    from bench_dynamics import mean_newton_steps  # one definition for the benchmarks (a sibling script)

    mean_newton = mean_newton_steps(sim, n_steps * sim.substeps)
    mean_factors = mean_newton_steps(sim, n_steps * sim.substeps, "factors")
    total = cpu if use_cpu else wall
    unstable = int(state.unstable.numpy().astype(bool).sum())
    stages, timed, timed_wall = [], 0.0, 0.0
    for key, (w_s, c_s, n) in sorted(acc.items(), key=lambda kv: -kv[1][1 if use_cpu else 0]):
        sec = c_s if use_cpu else w_s
        timed, timed_wall = timed + sec, timed_wall + w_s
        stages.append({"stage": STAGES.get(key, key), "kernel": key, "calls_per_step": n / n_steps,
                       "us_per_step": 1e6 * sec / n_steps, "us_per_world_step": 1e6 * sec / n_steps / W,
                       "share": sec / total, "wall_us_per_step": 1e6 * w_s / n_steps})
    host = max(0.0, total - timed)
    stages.append({"stage": "host (zeroing, Python)", "kernel": "-", "calls_per_step": "-",
                   "us_per_step": 1e6 * host / n_steps, "us_per_world_step": 1e6 * host / n_steps / W,
                   "share": host / total, "wall_us_per_step": 1e6 * max(0.0, wall - timed_wall) / n_steps})
    return {"W": W, "gait": gait, "magnets": magnet_model, "device": str(model.device), "steps": n_steps, "dt_s": sim.dt,
            "substeps": sim.substeps, "newton": sim.newton, "newton_steps_per_substep": mean_newton,
            "newton_factors_per_substep": mean_factors,
            "wall_s": wall, "cpu_s": cpu,
            "time_base": "thread CPU time" if use_cpu else "wall",
            "us_per_world_step": 1e6 * total / n_steps / W,
            "worm_substeps_per_s": W * n_steps * sim.substeps / total,
            "sim_s_per_wall_s": W * n_steps * sim.dt / total,
            "worm_substeps_per_s_wall": W * n_steps * sim.substeps / wall,
            "sim_s_per_wall_s_wall": W * n_steps * sim.dt / wall,
            "unstable_worlds": unstable, "stages": stages}


PARTS = ("gradient", "gradient + Hessian", "hinges' gradient", "inertia + bars' gradient", "band copy",
         "band copy + factor", "rhs copy", "rhs copy + solve", "hinges' gradient + Hessian", "contacts update",
         "friction + Hessian", "contact projection", "hinge angles (substep end)")
"""The Newton step's parts :func:`parts_cost` times (the copies restore the factor's and the solve's input)."""


def _parts_kernel():
    """A kernel running part ``part`` of a Newton step ``reps`` times per world (:data:`PARTS`), with the substep's
    own functions, on the scratch of a simulator (``hess0`` / ``grad0``: an assembled band and right-hand side)."""
    @wp.kernel
    def parts(part: int, reps: int, m: sub.BarHingeModel, opt: sub.SubstepOptions,
              anchor_target: wp.array2d(dtype=wp.vec3), s: sub.BarHingeState, w: sub.NewtonScratch,
              hess0: wp.array3d(dtype=wp.mat33), grad0: wp.array2d(dtype=wp.vec3)):
        world = wp.tid()
        c = sub.world_coefficients(m, world, opt.dt)
        nv = s.x.shape[1]
        bw = w.hess.shape[2] - 1
        for r in range(reps):
            if part == 0 or part == 1:
                ie.elastic_terms(world, c, m, opt, anchor_target, part == 1, s, w)
            elif part == 2:
                add_hinges(world, c, m, False, s, w)
            elif part == 3:
                for i in range(nv):
                    sub.inertia_row(world, i, c, m, False, w)
                for e in range(m.edges.shape[0]):
                    sub.add_bar(world, e, ALL_ROWS, c, m, opt, False, s, w)
            elif part == 4 or part == 5:
                for i in range(nv):
                    for k in range(bw + 1):
                        w.hess[world, i, k] = hess0[world, i, k]
                if part == 5:
                    banded_cholesky_factor(world, nv, bw, w.hess)
            elif part == 6 or part == 7:
                for i in range(nv):
                    w.grad[world, i] = grad0[world, i]
                if part == 7:
                    banded_cholesky_solve(world, nv, bw, w.hess, w.grad)
            elif part == 8:
                add_hinges(world, c, m, True, s, w)
            elif part == 9:
                sub.update_contacts(world, 0, 1, c, m, opt.slip_speed, s, w)
            elif part == 10:
                ie.friction_terms(world, c, opt.slip_speed, True, s, w)
            elif part == 11:
                ie.project_on_contacts(world, c, m, s, w)
            else:
                update_hinge_angles_lanes(world, m, opt.fold_tolerance, s)

    return parts


def parts_cost(W: int, gait: str = "omega", at: float = 1.5, reps: int = 20, tries: int = 7) -> list[dict]:
    """µs of thread CPU per world and call of each of :data:`PARTS` on the ``gait`` preset's state ``at`` [s] into
    the gait (CPU; the least of ``tries`` launches of ``reps`` calls each, the parts interleaved)."""
    kernel = _parts_kernel()
    model, sim = _build(W, "analytic", "cpu", gait=gait)
    state = sim.initial_state()
    sim.settle(state, 0.2)
    sim.step(state, int(round(at / sim.dt)))
    sol = sim.solver
    w = sol.scratch
    hess0, grad0 = wp.zeros_like(w.hess), wp.zeros_like(w.grad)

    def launch(part, reps_):
        wp.launch(kernel, dim=W, inputs=[part, reps_, sol.model_arrays, sol.options(1), sim.control.anchor_target,
                                         state_struct(state), w, hess0, grad0], device="cpu")

    launch(1, 1)  # an assembled band and gradient (inertia, bars, hinges) to factor and solve
    wp.copy(hess0, w.hess)
    wp.copy(grad0, w.grad)
    best = [float("inf")] * len(PARTS)
    for _ in range(tries):
        for part in range(len(PARTS)):
            c0 = time.thread_time()
            launch(part, reps)
            best[part] = min(best[part], 1e6 * (time.thread_time() - c0) / (W * reps))
    return [{"gait": gait, "W": W, "part": name, "us_per_world_call": t} for name, t in zip(PARTS, best)]


def newton_cost(W: int, newtons=(2, 3, 4), device: str = "cpu", steps: int = 15) -> list[dict]:
    """The implicit substeps alone (their launch's time inside a gait step; thread CPU time on the CPU) at each
    Newton count, after a short settle: the median over ``steps`` steps, the counts interleaved step by step so that
    other work on a shared machine falls on all of them alike."""
    sims = []
    for k in newtons:
        model, sim = _build(W, "analytic", device, newton=k, newton_tol=0.0)  # every step: the cost of one
        state = sim.initial_state()
        sim.settle(state, 0.05)
        sims.append((sim, state, []))
    for _ in range(steps):
        for sim, state, times in sims:
            with launch_timers() as acc:
                sim.step(state, 1)
            times.append(acc["implicit_step"][0 if sim.model.device.is_cuda else 1])
    rows = [{"W": W, "newton": k, "us_per_world_substep": 1e6 * float(np.median(t)) / (sim.substeps * W)}
            for k, (sim, _, t) in zip(newtons, sims)]
    for a, b in zip(rows, rows[1:]):
        b["us_per_extra_newton"] = b["us_per_world_substep"] - a["us_per_world_substep"]
    return rows


def launch_floor(device: str = "cpu", reps: int = 200) -> float:
    """Median wall time [µs] of launching a one-thread kernel that writes one float: the fixed cost of a launch."""
    @wp.kernel
    def _noop(a: wp.array(dtype=float)):
        a[wp.tid()] = 1.0

    a = wp.zeros(1, dtype=float, device=device)
    wp.launch(_noop, dim=1, inputs=[a], device=device)
    wp.synchronize_device(device)
    clock = time.perf_counter if wp.get_device(device).is_cuda else time.thread_time
    times = []
    for _ in range(reps):
        t0 = clock()
        wp.launch(_noop, dim=1, inputs=[a], device=device)
        wp.synchronize_device(device)
        times.append(clock() - t0)
    return 1e6 * float(np.median(times))


def _table(rows: list[dict], cols: list[str]) -> str:
    from run import table  # a sibling script

    return table([{c: r.get(c, "") for c in cols} for r in rows])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worlds", type=int, nargs="+", default=[1, 64], help="world counts (default 1 64)")
    ap.add_argument("--duration", type=float, default=1.0, help="gait time profiled [s] (default 1.0: one cycle)")
    ap.add_argument("--settle", type=float, default=0.2, help="settling before the gait [s] (default 0.2)")
    ap.add_argument("--skip", type=float, default=1.0, help="gait time run untimed first [s] (default 1.0: the first "
                    "cycle)")
    ap.add_argument("--magnet-model", choices=["analytic", "dipoles"], default="analytic")
    ap.add_argument("--gait", nargs="+", choices=["peristaltic", "omega", "inchworm"], default=["peristaltic"],
                    help="gait presets profiled, each at every --worlds (default peristaltic)")
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--no-levers", action="store_true", help="skip the Newton-count and launch-floor measurements")
    ap.add_argument("--parts", action="store_true", help="only the Newton step's parts (gradient, Hessian, factor, "
                    "solve, contacts, friction, projection, substep-end angles) timed alone on each --gait's state "
                    "1.5 s into the gait (first --worlds; CPU)")
    ap.add_argument("--out", default=str(HERE / "results" / "profile_step.json"), help="JSON path")
    args = ap.parse_args(argv)
    for w in args.worlds:
        if w < 1:
            ap.error(f"--worlds: expected counts >= 1, got {w}")
    if not args.skip >= 0:
        ap.error(f"--skip: expected >= 0 [s], got {args.skip}")
    if not args.duration > 0:
        ap.error(f"--duration: expected > 0 [s], got {args.duration}")

    quiet_warp()

    wp.init()
    if args.parts:
        rows = [r for g in args.gait for r in parts_cost(args.worlds[0], g)]
        print(_table(rows, ["gait", "W", "part", "us_per_world_call"]))
        return 0
    device = "cuda:0" if args.device == "cuda" else args.device
    runs = []
    for gait, W in [(g, w) for g in args.gait for w in args.worlds]:
        r = profile_run(W, duration=args.duration, settle=args.settle, skip=args.skip, magnet_model=args.magnet_model,
                        device=device, gait=gait)
        runs.append(r)
        print(f"\n== {args.magnet_model} magnets, {gait}, W = {W}, {r['steps']} steps of {1e3 * r['dt_s']:g} ms "
              f"({r['substeps']} substeps, <= {r['newton']} Newton, {r['newton_steps_per_substep']:.2f} on average, "
              f"{r['newton_factors_per_substep']:.2f} of them factored) "
              f"on {device}: {r['wall_s']:.2f} s wall, "
              f"{r['cpu_s']:.2f} s CPU; per {r['time_base']}: {r['us_per_world_step']:.0f} µs per world-step, "
              f"{r['worm_substeps_per_s']:.3g} worm-substeps/s, {r['sim_s_per_wall_s']:.3g} worm-s per s; "
              f"{r['unstable_worlds']} unstable ==")
        print(_table(r["stages"], ["stage", "kernel", "calls_per_step", "us_per_step", "us_per_world_step", "share",
                                   "wall_us_per_step"]))
    levers = {}
    if not args.no_levers:
        levers["newton"] = [row for W in args.worlds for row in newton_cost(W, device=device)]
        levers["launch_floor_us"] = launch_floor(device)
        print("\n== levers: implicit substep alone vs Newton steps; fixed cost of one launch ==")
        print(_table(levers["newton"], ["W", "newton", "us_per_world_substep", "us_per_extra_newton"]))
        print(f"launch floor: {levers['launch_floor_us']:.1f} µs per launch on {device}")
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    meta = {"command": "python benchmarks/profile_step.py " + " ".join(argv if argv is not None else sys.argv[1:]),
            "python": sys.version.split()[0], "warp": wp.config.version, "machine": platform.machine(),
            "date": time.strftime("%Y-%m-%dT%H:%M:%S")}
    out.write_text(json.dumps({"meta": meta, "runs": runs, "levers": levers}, indent=1,
                              default=lambda o: None if isinstance(o, float) and not np.isfinite(o) else float(o)))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
