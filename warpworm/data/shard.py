"""One shard of a dataset: batch of W worlds -> settle -> drive the EPM paths -> frames -> render -> write.

Sample ids and what determines them (so that any shard size, worker count, engine or device gives the same samples):

* sample ``i`` is frame ``i % F`` of view ``(i // F) % K`` of trajectory ``i // (K F)`` (F = ``len(sim.frame_times)``,
  K = ``render.views_per_frame``, 1 by default: then sample ``i`` is frame ``i % F`` of trajectory ``i // F``); the K
  views of a trajectory are K cameras watching the same simulated world, each over all its F frames;
* trajectory ``j``'s physical parameters are drawn from the counter-based generator keyed by (seed, j, attempt);
  attempt starts at 0 and a world that goes unstable is redrawn with attempt + 1 (dropped, replaced, counted);
* its camera (view v) is keyed by (seed, j, v) (or by (seed, i) with ``render.camera_per_frame``), its appearance by
  (seed, j) and its sensor noise by (seed, i) (:mod:`warpworm.data.sampling`);
* shard k holds ids [k·S, min((k+1)·S, N)): its content depends only on (config, k).

:func:`run_shard` is what a worker process runs (:mod:`warpworm.data.workers`); the job around it (plan, manifest, resume,
signals) is :mod:`warpworm.data.job`.
"""

from __future__ import annotations

import functools
import json
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

import warpworm
from warpworm import ids
from warpworm.data import dataset as ds
from warpworm.data.config import PARAM_SPECS, DatasetConfig
from warpworm.data.sampling import RenderDraws, draw_views, draw_worlds
from warpworm.render.placement import MATERIALS


@dataclass
class ShardStats:
    """What one shard cost and produced."""

    index: int
    count: int
    trajectories: int = 0
    replaced: int = 0
    sim_s: float = 0.0
    render_s: float = 0.0
    write_s: float = 0.0
    total_s: float = 0.0
    cameras_below_min: int = 0
    """Cameras whose best view in ``camera.max_tries`` draws kept less than ``camera.min_in_frame`` of the worm."""
    file: str = ""
    bytes: int = 0
    sha256: str = ""


# ---------------------------------------------------------------------------------------------------------------------
# Simulation with replacement of unstable worlds
def simulate_with_replacement(stages, cfg: DatasetConfig, traj: np.ndarray, stats: ShardStats):
    """Simulate trajectories ``traj`` (B,); unstable worlds are redrawn with attempt + 1 until stable.

    Returns (frames: list of dicts (B, ...), the accepted attempt's worm draws {name: (B,)}, attempt (B,)).
    """
    B = len(traj)
    attempt = np.zeros(B, dtype=np.int64)
    frames: list[dict] | None = None
    draws_out: dict[str, np.ndarray] = {}
    todo = np.arange(B)
    while todo.size:
        if attempt[todo[0]] >= cfg.sim.max_attempts:
            bad = traj[todo]
            raise RuntimeError(f"trajectories {bad[:8].tolist()} were unstable in all {cfg.sim.max_attempts} attempts; "
                               "narrow the randomization ranges, lower sim.dt or raise sim.substeps")
        worlds = draw_worlds(cfg, traj[todo], attempt[todo])
        unstable = np.zeros(todo.size, dtype=bool)
        for sel, params in worlds.groups:
            res = _simulate_group(stages, cfg, params, len(sel), stats)
            unstable[sel] = np.asarray(res.unstable, dtype=bool)
            if frames is None:
                frames = [{k: np.zeros((B,) + np.asarray(v).shape[1:], np.asarray(v).dtype) for k, v in f.items()}
                          for f in res.frames]
            ok = sel[~unstable[sel]]
            for fi, f in enumerate(res.frames):
                for k, v in f.items():
                    frames[fi][k][todo[ok]] = np.asarray(v)[~unstable[sel]]
        accepted = todo[~unstable]
        for k, v in worlds.values.items():
            if k not in draws_out:
                draws_out[k] = np.empty(B, dtype=v.dtype)
            draws_out[k][accepted] = v[~unstable]
        stats.replaced += int(unstable.sum())
        todo = todo[unstable]
        attempt[todo] += 1
    return frames, draws_out, attempt


def _simulate_group(stages, cfg, params, num_worlds: int, stats: ShardStats):
    t0 = time.perf_counter()
    res = stages.simulate_batch(params, num_worlds, cfg)
    stats.sim_s += time.perf_counter() - t0
    return res


# ---------------------------------------------------------------------------------------------------------------------
# Attributes
def root_attributes(cfg: DatasetConfig, meta: dict) -> dict:
    """Root attributes every shard carries (and the manifest repeats)."""
    return {
        "format": ds.FORMAT,
        "schema_version": ds.SCHEMA_VERSION,
        "warpworm_version": warpworm.__version__,
        "warp_version": ds.warp_version(),
        "config_yaml": cfg.to_yaml(),
        "seed_master": cfg.seed,
        "num_samples": cfg.num_samples,
        "shard_size": cfg.shard_size,
        "frame_times": np.asarray(cfg.sim.frame_times, dtype=np.float64),
        "units": json.dumps(ds.UNITS),
        "quaternion_order": ds.QUATERNION_ORDER,
        "segmentation_ids": json.dumps(ds.SEGMENTATION_IDS),
        "keypoint_names": json.dumps(list(meta["keypoint_names"])),
        "crease_order": "creases/angle[c] is hinge c of the crease pattern: stencil crease_hinges[c] = (i, j, k, l), "
                        f"shared edge j-k; crease_labels[c]: {ids.HINGE_LABEL_TEXT}",
        "crease_hinges": np.asarray(meta["hinges"], dtype=np.int32),
        "crease_labels": np.asarray(meta["hinge_label"], dtype=np.int8),
        "bar_edges": np.asarray(meta["edges"], dtype=np.int32),
        "mesh_triangles": np.asarray(meta["triangles"], dtype=np.int32),
        "mesh_triangle_segment": np.asarray(meta["triangle_segment"], dtype=np.int32),
        "params_names": json.dumps(sorted(cfg.flat_distributions())),
    }


# ---------------------------------------------------------------------------------------------------------------------
# The shard loop
class _WriteBehind:
    """Compression and HDF5 writes on one background thread while the next batch simulates and renders (Warp's CPU
    kernels run without the GIL). At most one write is in flight, so memory stays bounded by one batch."""

    def __init__(self, writer: ds.ShardWriter, stats: ShardStats, name: str):
        self.writer, self.stats = writer, stats
        self.io = ThreadPoolExecutor(max_workers=1, thread_name_prefix=name)
        self.pending = None

    def submit(self, row: int, rows: dict) -> None:
        self.wait()
        self.pending = self.io.submit(self.writer.write, row, rows)

    def wait(self) -> None:
        if self.pending is not None:
            t0 = time.perf_counter()
            self.pending.result()  # re-raises a write error (disk full, ...) here, in the shard's thread
            self.stats.write_s += time.perf_counter() - t0
            self.pending = None

    def cancel(self) -> None:
        if self.pending is not None:
            self.pending.cancel()
            try:
                self.pending.result()
            except BaseException:  # the original error is the one to report
                pass

    def close(self) -> None:
        self.io.shutdown(wait=True)


def run_shard(cfg: DatasetConfig, out_dir, k: int, stages, progress=None) -> ShardStats:
    """Produce and commit shard ``k`` with ``stages`` (a loaded stages object, :class:`warpworm.data.stages.Stages`);
    the written content depends only on (cfg, k)."""
    t_start = time.perf_counter()
    start, stop = cfg.shard_range(k)
    F = cfg.samples_per_trajectory  # K views x frames
    stats = ShardStats(index=k, count=stop - start)
    writer = ds.ShardWriter(out_dir, k, start, stop - start, root_attributes(cfg, stages.metadata(cfg)),
                            cfg.output.compression, cfg.output.compression_level)
    behind = _WriteBehind(writer, stats, f"shard{k}-writer")
    try:
        t_first, t_last = start // F, -(-stop // F)
        W = cfg.sim.worlds
        for c0 in range(t_first, t_last, W):
            traj = np.arange(c0, min(c0 + W, t_last), dtype=np.int64)
            for first_sample, rows in _trajectory_rows(stages, cfg, traj, stop, stats):
                behind.submit(int(first_sample - start), rows)
            if progress is not None:
                progress(int(np.minimum(traj * F + F, stop).sum() - np.minimum(traj * F, stop).sum()))
        behind.wait()
        t0 = time.perf_counter()
        final = writer.commit()
        stats.write_s += time.perf_counter() - t0
    except BaseException:
        behind.cancel()
        writer.abort()
        raise
    finally:
        behind.close()
    stats.file = final.name
    stats.bytes = final.stat().st_size
    stats.sha256 = writer.sha256
    stats.total_s = time.perf_counter() - t_start
    return stats


def _trajectory_rows(stages, cfg: DatasetConfig, traj: np.ndarray, stop: int, stats: ShardStats):
    """Simulate trajectories ``traj`` and render their samples below ``stop``; yields (first sample id, rows) per
    render call, rows in sample order (trajectory-major, then view, then frame) so every write is a contiguous row
    range (strided writes into chunked, compressed HDF5 datasets are far slower)."""
    F, K = cfg.frames_per_trajectory, int(getattr(cfg.render, "views_per_frame", 1))
    frames, world_values, attempt = simulate_with_replacement(stages, cfg, traj, stats)
    stats.trajectories += len(traj)
    stacked = _stack_frames(frames)  # (B, F, ...)
    B, S = len(traj), F * K
    sid_all = (traj[:, None] * S + np.arange(S)[None]).reshape(-1)
    tsel_all = np.repeat(np.arange(B), S)  # trajectory (position in this batch) of each sample
    vidx_all = np.tile(np.repeat(np.arange(K), F), B)
    fidx_all = np.tile(np.arange(F), B * K)
    n_keep = int(np.sum(sid_all < stop))
    step = max(S, (cfg.render.batch // S) * S)  # images per render call: whole trajectories
    calls = [(sid_all[sl], tsel_all[sl], fidx_all[sl], vidx_all[sl])
             for sl in (slice(r0, min(r0 + step, n_keep)) for r0 in range(0, n_keep, step))]
    views, below = draw_views(cfg, traj, world_values, stacked["positions"], calls)
    stats.cameras_below_min += below
    for (sid, tsel, fidx, vidx), draws in zip(calls, views):
        yield sid[0], _render_rows(stages, cfg, stacked, traj, attempt, draws, sid, tsel, fidx, vidx, stats)


def _render_rows(stages, cfg: DatasetConfig, stacked: dict, traj: np.ndarray, attempt: np.ndarray, draws: RenderDraws,
                 sid: np.ndarray, tsel: np.ndarray, fidx: np.ndarray, vidx: np.ndarray, stats: ShardStats) -> dict:
    """The dataset rows of samples ``sid`` (n,): trajectory ``traj[tsel]``, frame ``fidx``, view ``vidx``."""
    # the snapshot of each sample's (trajectory, frame), stacked: (n, ...) "worlds" of the renderer
    fr = _gather_frames(stacked, tsel, fidx)
    t0 = time.perf_counter()
    out = stages.render_batch(fr, draws, cfg)
    stats.render_s += time.perf_counter() - t0
    t0 = time.perf_counter()
    cams = draws.cameras
    rows = {
        **out,
        "camera/K": cams.K, "camera/R": cams.R, "camera/t": cams.t,
        "camera/position": cams.position, "camera/in_frame": cams.in_frame.astype(np.float32),
        "time": (fr["frame_time"].astype(np.float32) if "frame_time" in fr  # sim.frame_unit: cycle (per world)
                 else np.asarray(cfg.sim.frame_times, dtype=np.float32)[fidx]),
        "trajectory": traj[tsel], "frame": fidx.astype(np.int32),
        "attempt": attempt[tsel].astype(np.int32), "sample_id": sid, "seed": draws.seeds,
    }
    if int(getattr(cfg.render, "views_per_frame", 1)) > 1:  # only then: views_per_frame = 1 keeps the old datasets
        rows["view"] = vidx.astype(np.int32)
    for name, v in draws.columns.items():
        rows[f"params/{name}"] = text_column(name, v) if np.asarray(v).dtype.kind in "OSU" else v
    stats.write_s += time.perf_counter() - t0
    return rows


@functools.lru_cache(maxsize=None)
def text_widths() -> dict[str, int]:
    """Bytes of the longest value each text parameter may take, from the schema (not from the values drawn): the
    ``values`` of every text parameter of :data:`~warpworm.data.config.PARAM_SPECS` and the renderer's plate
    materials (``render.plate_materials``, :data:`warpworm.render.placement.MATERIALS`)."""
    out = {f"{g}.{n}": max(len(str(v).encode()) for v in spec.values)
           for g, specs in PARAM_SPECS.items() for n, spec in specs.items()
           if spec.values is not None and all(isinstance(v, str) for v in spec.values)}
    out["plate.material"] = max(len(m.encode()) for m in MATERIALS)
    return out


def text_column(name: str, values) -> np.ndarray:
    """Text parameter ``name``'s values (n,) as fixed-width bytes ``S<w>``, w from :func:`text_widths`, so a shard's
    dtype depends on the schema alone, not on which values its samples drew (nor on the shard size)."""
    width = text_widths().get(name)
    if width is None:
        raise RuntimeError(f"params/{name}: a text parameter without a declared set of values; give it `values` in "
                           "warpworm.data.config.PARAM_SPECS (its width in the files comes from them)")
    raw = np.asarray(values, dtype=object).astype("S")
    if raw.dtype.itemsize > width:
        raise ValueError(f"params/{name}: got {max(raw.tolist(), key=len)!r}; expected one of the schema's values "
                         f"(at most {width} bytes)")
    return raw.astype(f"S{width}")


def _stack_frames(frames: list[dict]) -> dict:
    """F snapshots of B worlds -> dict of (B, F, ...) arrays (once per simulated batch)."""
    return {k: np.stack([f[k] for f in frames], axis=1) for k in frames[0]}


def _gather_frames(stacked: dict, tsel: np.ndarray, fidx: np.ndarray) -> dict:
    """Snapshot arrays of samples (trajectory tsel[i], frame fidx[i]) -> dict of (n, ...) arrays."""
    return {k: v[tsel, fidx] for k, v in stacked.items()}


__all__ = ["ShardStats", "root_attributes", "run_shard",
           "simulate_with_replacement", "text_column", "text_widths"]
