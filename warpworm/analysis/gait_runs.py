"""Run a gait on a batch of worlds: settle, run N EPM cycles, measure. Shared by the ``simulate`` and ``search-gait``
commands, the gait search and the gait benchmarks; ``run_gait_split`` spreads the worlds over the cores (threads of
this process, :mod:`warpworm.analysis.world_split`)."""

from __future__ import annotations

import time

import numpy as np

from warpworm.analysis.gait_metrics import gait_metrics
from warpworm.analysis.world_split import concat, run_shares
from warpworm.data import sampling
from warpworm.data.config import load_config
from warpworm.physics import gaits
from warpworm.physics.params import slice_worlds
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator


def randomized_params(config: str, gait: str, backward: bool, magnet_model: str, num_worlds: int, seed: int):
    """World w's parameters as trajectory w of a dataset job of ``config`` with master seed ``seed`` draws them
    (:func:`warpworm.data.sampling.randomized_params`: the config's distributions, the counter-based generator), with the
    gait, direction and magnet model fixed to the command's."""
    cfg = load_config(config, [f"randomize.worm.gait={gait}", f"randomize.worm.backward={str(bool(backward)).lower()}",
                               f"randomize.worm.magnet_model={magnet_model}"])
    return sampling.randomized_params(cfg, num_worlds, seed)


def axis_displacement(x0: np.ndarray, x1: np.ndarray, incline) -> np.ndarray:
    """Net displacement [m] of each world's vertex centroid along the worm axis (+x laid on the floor), (W,)."""
    beta = np.broadcast_to(np.asarray(incline, np.float64), (x0.shape[0],))
    axis = np.stack([np.cos(beta), np.zeros_like(beta), np.sin(beta)], -1)
    return np.einsum("wc,wc->w", x1.mean(axis=1) - x0.mean(axis=1), axis)


def run_gait(params, num_worlds: int, cycles: float, *, device="cpu", dt=None, substeps=None, settle=0.2,
             fps: float | None = 30.0, save_worlds: int = 4):
    """Settle, then run ``cycles`` EPM cycles, recording every world at ``fps`` frames per second.

    Returns a dict: displacement_m (W,), unstable (W,), sim_time_s, wall_time_s, metrics (per-world gait measures,
    :func:`warpworm.analysis.gait_metrics.gait_metrics`; None without ``fps``), frames (stacked snapshots of the first
    ``save_worlds`` worlds, or None), model, sim."""
    dt = gaits.DEFAULT_DT if dt is None else dt
    substeps = gaits.DEFAULT_SUBSTEPS if substeps is None else substeps
    t_wall = time.perf_counter()
    model = Model.from_params(params, num_worlds, device)
    sim = Simulator(model, dt=dt, substeps=substeps)
    state = sim.initial_state()
    if settle > 0:
        sim.settle(state, settle)
    x0 = state.positions.numpy().copy()
    period = float(np.max(np.asarray(params.cycle_period)))
    sim_time = cycles * period
    n_steps = int(round(sim_time / dt))
    frames = metrics = None
    every_world = ("positions", "magnet_pos", "crease_angle")  # what the metrics need, for all worlds
    saved_only = ("magnet_rot", "bar_strain")  # the trajectory file's extras, first save_worlds worlds
    if fps:
        every = max(1, int(round(1.0 / (fps * dt))))
        S = min(save_worlds, num_worlds)
        steps = np.unique(np.minimum(np.arange(0, n_steps + every, every), n_steps))
        rec = sim.run(state, steps * dt, keys=every_world + saved_only, stack=True)
        rec["time"] = rec.pop("clock")  # host clock: an unstable world's own step count stops
        metrics = gait_metrics(model.pattern, model.pattern.hinge_label, rec, params.cycle_period,
                               params.floor_incline)
        frames = {k: (v[:, :S] if v.ndim > 1 else v) for k, v in rec.items()}
    else:
        sim.step(state, n_steps)
    snap = sim.snapshot(state)
    disp = axis_displacement(x0, snap["positions"], params.floor_incline)
    return {
        "displacement_m": disp,
        "unstable": snap["unstable"],
        "crumpled": snap["crumpled"],
        "sim_time_s": n_steps * dt,
        "wall_time_s": time.perf_counter() - t_wall,
        "metrics": metrics,
        "frames": frames,
        "model": model,
        "sim": sim,
    }


RESULT_WORLD_AXIS = {"displacement_m": 0, "unstable": 0, "crumpled": 0}
"""Per-world outputs of :func:`run_gait` (world axis); ``metrics`` arrays are per world along axis 0, ``frames``
along axis 1 (time first)."""


def run_gait_split(params, num_worlds: int, cycles: float, *, workers: int | None = None, **kw):
    """:func:`run_gait` with the worlds split over ``workers`` threads (default: every core), each a batch of a
    contiguous share with its own Model and Simulator (:func:`warpworm.analysis.world_split.run_shares`); worlds never
    interact, so every per-world result equals one batch's bit for bit. The trajectory frames are those of the first
    ``save_worlds`` worlds, gathered from the shares that hold them; ``model`` and ``sim`` are the first share's."""
    t0 = time.perf_counter()
    save = kw.pop("save_worlds", 4)

    def share(lo, hi):
        p = params if (lo, hi) == (0, num_worlds) else slice_worlds(params, num_worlds, lo, hi)
        return run_gait(p, hi - lo, cycles, save_worlds=int(max(0, min(save - lo, hi - lo))), **kw)

    parts = run_shares(share, num_worlds, workers, device=kw.get("device", "cpu"))
    if len(parts) == 1:
        return parts[0]
    out = concat([{k: p[k] for k in RESULT_WORLD_AXIS} for p in parts], RESULT_WORLD_AXIS)
    out["metrics"] = (None if parts[0]["metrics"] is None else
                      concat([p["metrics"] for p in parts], dict.fromkeys(parts[0]["metrics"], 0)))
    fr = [p["frames"] for p in parts if p["frames"] is not None]
    out["frames"] = None if not fr else {
        k: (fr[0][k] if fr[0][k].ndim == 1 else np.concatenate([f[k] for f in fr], axis=1)) for k in fr[0]}
    out["sim_time_s"] = parts[0]["sim_time_s"]
    out["wall_time_s"] = time.perf_counter() - t0
    out["model"], out["sim"] = parts[0]["model"], parts[0]["sim"]
    return out
