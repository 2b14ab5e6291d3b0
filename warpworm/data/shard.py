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
from warpworm import ids, rng
from warpworm.data import dataset as ds
from warpworm.data import randomize as rnd
from warpworm.data.config import BATCH_SHARED, PARAM_SPECS, DatasetConfig
from warpworm.data.sampling import appearance_draws, dataset_cameras, draw_worm, worm_params
from warpworm.data.stages import load_stages
from warpworm.render.placement import MATERIALS
from warpworm.data.signal_hold import Interrupted  # noqa: F401  (re-exported: the workers and job raise it)


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


def _take(d: dict, sel) -> dict:
    return {k: v[sel] for k, v in d.items()}


# ---------------------------------------------------------------------------------------------------------------------
# Simulation with replacement of unstable worlds
def simulate_with_replacement(stages, cfg: DatasetConfig, traj: np.ndarray, stats: ShardStats):
    """Simulate trajectories ``traj`` (B,); unstable worlds are redrawn with attempt + 1 until stable.

    Returns (frames: list of dicts (B, ...), draws of the accepted attempt, attempt (B,)).
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
        d = draw_worm(cfg, traj[todo], attempt[todo])
        unstable = np.zeros(todo.size, dtype=bool)
        for sel in _solver_groups(d):
            res = _simulate_group(stages, cfg, worm_params(cfg, d, sel), len(sel), stats)
            unstable[sel] = np.asarray(res.unstable, dtype=bool)
            if frames is None:
                frames = [{k: np.zeros((B,) + np.asarray(v).shape[1:], np.asarray(v).dtype) for k, v in f.items()}
                          for f in res.frames]
            ok = sel[~unstable[sel]]
            for fi, f in enumerate(res.frames):
                for k, v in f.items():
                    frames[fi][k][todo[ok]] = np.asarray(v)[~unstable[sel]]
        accepted = todo[~unstable]
        for k, v in d.values.items():
            if k not in draws_out:
                draws_out[k] = np.empty(B, dtype=v.dtype)
            draws_out[k][accepted] = v[~unstable]
        stats.replaced += int(unstable.sum())
        todo = todo[unstable]
        attempt[todo] += 1
    return frames, rnd.Draws(draws_out), attempt


def _solver_groups(d: rnd.Draws) -> list[np.ndarray]:
    """Positions in ``d`` split by the batch-shared fields (gait, direction, magnet model): one solver batch each."""
    keys = np.stack([np.asarray(d[n], dtype=str) for n in BATCH_SHARED], axis=1)
    _, group_of = np.unique(keys, axis=0, return_inverse=True)
    group_of = group_of.reshape(-1)
    return [np.flatnonzero(group_of == g) for g in np.unique(group_of)]


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
        "warp_version": warp_version(),
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


@functools.lru_cache(maxsize=None)
def warp_version() -> str:
    try:
        import warp  # start-up time: Warp loads on first use

        return str(warp.__version__)
    except Exception:  # noqa: BLE001 - the fake stages in tests do not need Warp
        return "unavailable"


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
    """Produce and commit shard ``k``; the written content depends only on (cfg, k)."""
    t_start = time.perf_counter()
    stages = load_stages(stages)
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


@dataclass
class _Trajectories:
    """A simulated batch of B trajectories and everything drawn for them (camera fields None when per frame)."""

    traj: np.ndarray
    stacked: dict
    """Snapshot arrays (B, F, ...)."""
    draws: rnd.Draws
    attempt: np.ndarray
    appearance: dict
    cams: object = None
    """Cameras of every (trajectory, view), trajectory-major: camera ``b * K + v`` is view v of trajectory b."""
    cam_draws: dict | None = None


def _views(cfg: DatasetConfig) -> int:
    return int(getattr(cfg.render, "views_per_frame", 1))


def _trajectory_rows(stages, cfg: DatasetConfig, traj: np.ndarray, stop: int, stats: ShardStats):
    """Simulate trajectories ``traj`` and render their samples below ``stop``; yields (first sample id, rows) per
    render call, rows in sample order (trajectory-major, then view, then frame) so every write is a contiguous row
    range: strided HDF5 writes into chunked, compressed datasets measured ~25x slower than contiguous ones."""
    F, K = cfg.frames_per_trajectory, _views(cfg)
    frames, wdraws, attempt = simulate_with_replacement(stages, cfg, traj, stats)
    stats.trajectories += len(traj)
    batch = _Trajectories(traj=traj, stacked=_stack_frames(frames), draws=wdraws, attempt=attempt,
                          appearance=appearance_draws(cfg, traj))
    B = len(traj)
    if not cfg.render.camera_per_frame:
        # K cameras per trajectory, keyed by (trajectory, view): the worm (all its frames) in view of each
        pts = np.concatenate([f["positions"] for f in frames], axis=1)
        if K == 1:
            batch.cams, batch.cam_draws = dataset_cameras(cfg, traj, pts)
        else:
            batch.cams, batch.cam_draws = dataset_cameras(cfg, np.repeat(traj, K), np.repeat(pts, K, axis=0),
                                                          view=np.tile(np.arange(K), B))
        stats.cameras_below_min += int((~batch.cams.accepted).sum())
    S = F * K
    sid_all = (traj[:, None] * S + np.arange(S)[None]).reshape(-1)
    tsel_all = np.repeat(np.arange(B), S)  # trajectory (position in this batch) of each sample
    vidx_all = np.tile(np.repeat(np.arange(K), F), B)
    fidx_all = np.tile(np.arange(F), B * K)
    n_keep = int(np.sum(sid_all < stop))
    step = max(S, (cfg.render.batch // S) * S)  # images per render call: whole trajectories
    for r0 in range(0, n_keep, step):
        sl = slice(r0, min(r0 + step, n_keep))
        yield sid_all[sl][0], _render_rows(stages, cfg, batch, sid_all[sl], tsel_all[sl], fidx_all[sl], stats,
                                           vidx_all[sl])


def _render_rows(stages, cfg: DatasetConfig, batch: _Trajectories, sid: np.ndarray, tsel: np.ndarray,
                 fidx: np.ndarray, stats: ShardStats, vidx: np.ndarray) -> dict:
    """The dataset rows of samples ``sid`` (n,): trajectory ``batch.traj[tsel]``, frame ``fidx``, view ``vidx``."""
    K = _views(cfg)
    # the snapshot of each sample's (trajectory, frame), stacked: (n, ...) "worlds" of the renderer
    fr = _gather_frames(batch.stacked, tsel, fidx)
    if cfg.render.camera_per_frame:  # a camera per sample, keyed by the sample id
        cams, cam_draws = dataset_cameras(cfg, sid, fr["positions"])
        stats.cameras_below_min += int((~cams.accepted).sum())
    else:
        csel = tsel * K + vidx
        cam_draws = _take(batch.cam_draws, csel)
        cams = batch.cams.take(csel)
    cams.world = np.arange(len(sid), dtype=np.int32)
    seeds = rng.derived_seed(rng.sample_keys(cfg.seed, sid))
    app = _take(batch.appearance, tsel)
    t0 = time.perf_counter()
    out = stages.render_batch(fr, worm_params(cfg, batch.draws, tsel), cams, app, seeds, cfg)
    stats.render_s += time.perf_counter() - t0
    t0 = time.perf_counter()
    rows = {
        **out,
        "camera/K": cams.K, "camera/R": cams.R, "camera/t": cams.t,
        "camera/position": cams.position, "camera/in_frame": cams.in_frame.astype(np.float32),
        "time": (fr["frame_time"].astype(np.float32) if "frame_time" in fr  # sim.frame_unit: cycle (per world)
                 else np.asarray(cfg.sim.frame_times, dtype=np.float32)[fidx]),
        "trajectory": batch.traj[tsel], "frame": fidx.astype(np.int32),
        "attempt": batch.attempt[tsel].astype(np.int32), "sample_id": sid, "seed": seeds,
    }
    if K > 1:  # only then: a dataset of views_per_frame = 1 keeps exactly the datasets of before the option
        rows["view"] = vidx.astype(np.int32)
    for name, v in {**_take(batch.draws.values, tsel), **app, **cam_draws}.items():
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


__all__ = ["Interrupted", "ShardStats", "root_attributes", "run_shard",
           "simulate_with_replacement", "text_column", "text_widths"]
