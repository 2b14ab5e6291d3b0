"""A dataset job: plan the shards (resume, sharding for the workers), hold the folder lock and the signals, run the
shards (:mod:`warpworm.data.workers`, each one :func:`warpworm.data.shard.run_shard`), keep ``manifest.json`` current.

What determines each sample is in :mod:`warpworm.data.shard`; resuming a killed job means redoing the missing shards
(shard k's content depends only on (config, k)). Previews are not part of the job: the ``generate`` command writes
them afterwards (:func:`warpworm.data.previews.write_previews`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import math
import os
import signal
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import h5py
import yaml
from tqdm import tqdm

import warpworm
from warpworm.data import dataset as ds
from warpworm.data import signal_hold
from warpworm.data import workers as wk
from warpworm.data.config import ConfigError, DatasetConfig, load_config
from warpworm.data.export_json import jsonable
from warpworm.data.shard import ShardStats
from warpworm.data.signal_hold import Interrupted
from warpworm.data.stages import DEFAULT_STAGES, load_stages


@dataclass
class Summary:
    """End-of-job summary (also stored in manifest.json)."""

    out: str
    num_samples: int
    shards_total: int
    shards_done_before: int
    shards_written: int
    replaced_worlds: int
    wall_s: float
    sim_s: float
    render_s: float
    write_s: float
    workers: int
    engine: str
    new_samples: int = 0
    cameras_below_min: int = 0
    kernels_s: float = 0.0
    """Wall time [s] loading the Warp kernels before the first shard (compiling them on a cold cache)."""

    @property
    def samples_per_s(self) -> float:
        """Samples written by this run per wall-clock second (whole job, previews excluded)."""
        return self.new_samples / self.wall_s if self.wall_s > 0 else float("nan")

    def text(self) -> str:
        compiled = " (compiled: first run)" if self.kernels_s > KERNEL_NOTICE_S else ""
        return (f"wrote {self.shards_written} shard(s) ({self.new_samples} samples; {self.shards_done_before} shard(s) "
                f"were already complete) to {self.out}\n"
                f"  {self.wall_s:.1f} s = {self.samples_per_s:.1f} samples/s with {self.workers} worker(s) "
                f"[{self.engine}]; kernels {self.kernels_s:.1f} s{compiled}\n"
                f"  stage time (all workers): sim {self.sim_s:.1f} s, render {self.render_s:.1f} s, "
                f"write {self.write_s:.1f} s\n"
                f"  unstable worlds dropped and replaced: {self.replaced_worlds}; cameras below "
                f"camera.min_in_frame after max_tries: {self.cameras_below_min}")


def _config_diff(a, b, path="") -> list[str]:
    if isinstance(a, dict) and isinstance(b, dict):
        out = []
        for k in sorted(set(a) | set(b)):
            out += _config_diff(a.get(k), b.get(k), f"{path}.{k}" if path else str(k))
        return out
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return []
    return [] if a == b else [f"{path}: dataset has {a!r}, this run asks for {b!r}"]


class SignalGuard:
    """While active (main thread only): SIGTERM / SIGINT raise :class:`Interrupted`, except inside :meth:`critical`
    sections (a manifest update), where the signal is held until the section ends."""

    def __init__(self):
        self._old = {}
        self._depth = 0
        self._held: int | None = None

    def _handler(self, signum, frame):
        if self._depth:
            self._held = signum
            return
        if signal_hold.in_io():  # inside an h5py call: raised when it returns (warpworm.data.signal_hold)
            signal_hold.defer(signum)
            return
        raise Interrupted(signum)

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._old[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc):
        for sig, h in self._old.items():
            signal.signal(sig, h)
        self._old = {}

    def critical(self):
        guard = self

        class _C:
            def __enter__(self):
                guard._depth += 1

            def __exit__(self, *exc):
                guard._depth -= 1
                if not guard._depth and guard._held is not None and exc[0] is None:
                    sig, guard._held = guard._held, None
                    raise Interrupted(sig)

        return _C()


def shard_plan(cfg: DatasetConfig, workers: int) -> tuple[DatasetConfig, str | None]:
    """The shard size a job with ``workers`` processes runs: the config's, unless its samples fit in fewer shards than
    there are workers; then shards of ceil(trajectories / workers) whole trajectories, so every worker has one.
    Samples do not depend on the sharding (module docstring), so this changes files, never data. Returns the config
    to run and a one-line note (None when nothing changed and no worker idles)."""
    if workers <= 1 or cfg.num_shards >= workers:
        return cfg, None
    F = cfg.samples_per_trajectory  # every view of every frame of a trajectory
    n_traj = -(-cfg.num_samples // F)
    per = -(-n_traj // workers) * F
    note = None
    new = cfg
    if per < cfg.shard_size:
        new = dataclasses.replace(cfg, shard_size=per)
        note = (f"shard_size {cfg.shard_size} -> {per}: {cfg.num_samples} samples fit in {cfg.num_shards} shard(s), "
                f"fewer than --workers {workers}; {new.num_shards} shards of whole trajectories give every worker "
                "work (the samples are the same whatever the sharding)")
    if new.num_shards < workers:
        why = (f"only {n_traj} trajectory(ies) of {F} frames, and a shard holds whole trajectories"
               if per == F or new is not cfg else f"{new.num_shards} shard(s)")
        note = (note + "; " if note else "") + (f"{workers - new.num_shards} of {workers} workers will be idle: "
                                                f"{why}")
    return new, note


KERNEL_NOTICE_S = 3.0
"""Loading the kernels longer than this [s] means they are compiling: say so (a cold cache sits ~24 s at 0 %)."""


def warm_kernels(cfg: DatasetConfig, stages, log) -> float:
    """Load (on a cold cache: compile) the Warp kernels of ``stages`` (a loaded stages object) before the progress
    bar starts; returns the wall time [s]. If it takes longer than :data:`KERNEL_NOTICE_S`, one line says that
    kernels are compiling, roughly how long it takes and that it happens once, and another how long it took."""
    warm = getattr(stages, "warm", None)
    if warm is None:
        return 0.0
    t0 = time.perf_counter()
    done = threading.Event()
    said = []

    def notice():
        if not done.wait(KERNEL_NOTICE_S):
            said.append(True)
            log("compiling Warp kernels (first run on this machine or after an upgrade: about 20-60 s on a CPU; "
                "cached for later runs)...")

    t = threading.Thread(target=notice, daemon=True)
    t.start()
    try:
        warm(cfg)
    except Exception as exc:  # noqa: BLE001 - a failed warm-up only costs time; the shards report real errors
        log(f"warning: kernel warm-up failed ({type(exc).__name__}: {exc}); modules load on first use")
    finally:
        done.set()
        t.join()
    wall = time.perf_counter() - t0
    if said:
        log(f"kernels ready in {wall:.0f} s")
    return wall


def _json_rt(d):
    return json.loads(json.dumps(jsonable(d), default=str))


def plan_job(cfg: DatasetConfig, out_dir, resume: bool, requested_shard_size: int | None = None,
             log=None) -> tuple[DatasetConfig, list[int], dict[int, dict]]:
    """(config to run, shards to write, shards already done {k: {bytes, sha256}}).

    On resume: the config must equal the dataset's (its sharding, chosen for the first run's workers, is kept);
    temporaries are deleted; every shard on disk is checked (opens, marked complete, sample ids, and the manifest's
    SHA-256) and a damaged one (truncated, bit-flipped) is deleted and redone with a note. A missing or unreadable
    manifest is rebuilt from the shards, whose ``config_yaml`` must then match this run's config.
    """
    out = Path(out_dir)
    log = log or (lambda m: print(m, file=sys.stderr))
    requested = cfg.shard_size if requested_shard_size is None else requested_shard_size
    done: dict[int, dict] = {}
    if not resume:
        return cfg, list(range(cfg.num_shards)), done
    mpath = out / ds.MANIFEST
    old = None
    if mpath.exists():
        try:
            old = ds.read_manifest(out)
        except ds.DatasetError as exc:
            log(f"note: {str(exc).split(';')[0]}; rebuilding it from the shards")
    elif any(ds.SHARD_RE.match(n) for n in os.listdir(out)):
        log(f"note: {mpath} is missing; rebuilding it from the shards")
    known_sha: dict[int, str] = {}
    if old is not None:
        old_cfg = _json_rt(old.get("config", {}))
        if (old_cfg.get("shard_size") != cfg.shard_size
                and old.get("shard_size_requested", old_cfg.get("shard_size")) == requested):
            cfg = dataclasses.replace(cfg, shard_size=int(old_cfg["shard_size"]))
        diff = _config_diff(old_cfg, _json_rt(cfg.to_dict()))
        if diff:
            raise ConfigError(["--resume: the config differs from the dataset's (same config, --num and --seed "
                               "are needed to resume):"] + diff[:20])
        for sh in old["shards"]:
            if isinstance(sh, dict) and sh.get("sha256"):
                known_sha[int(sh["index"])] = str(sh["sha256"])
    else:
        cfg = _config_from_shards(cfg, out, requested)
    ds.clean_temporaries(out)
    for k in range(cfg.num_shards):
        p = out / ds.shard_name(k)
        if not p.exists():
            continue
        a, b = cfg.shard_range(k)
        problem = ds.shard_problem(p, a, b - a, sha256=known_sha.get(k))
        if problem is None and k not in known_sha:
            problem = _shard_config_problem(p, cfg)
        if problem is None:
            done[k] = {"bytes": p.stat().st_size, "sha256": known_sha.get(k) or ds.file_sha256(p)}
        else:
            log(f"note: {p}: {problem}; deleting it and writing it again")
            p.unlink()
    todo = [k for k in range(cfg.num_shards) if k not in done]
    return cfg, todo, done


def _shard_config_problem(path, cfg: DatasetConfig) -> str | None:
    try:
        with h5py.File(path, "r") as f:
            text = f.attrs.get("config_yaml", "")
    except OSError as exc:
        return f"unreadable ({exc})"
    text = text.decode() if isinstance(text, bytes) else str(text)
    return None if text == cfg.to_yaml() else "written with another config (root attribute config_yaml differs)"


def _config_from_shards(cfg: DatasetConfig, out: Path, requested: int) -> DatasetConfig:
    """Without a manifest: the sharding of the shards on disk (kept if smaller than ``requested``: split for the first
    run's workers), refused with the differing keys if their config is not this run's otherwise."""
    for name in sorted(os.listdir(out)):
        if not ds.SHARD_RE.match(name):
            continue
        try:
            with h5py.File(out / name, "r") as f:
                text = f.attrs["config_yaml"]
        except (OSError, KeyError):
            continue  # damaged: plan_job reports and redoes it
        text = text.decode() if isinstance(text, bytes) else str(text)
        old = load_config(yaml.safe_load(text))
        if old.shard_size < cfg.shard_size and cfg.shard_size == requested:  # split for the first run's workers
            cfg = dataclasses.replace(cfg, shard_size=old.shard_size)
        diff = _config_diff(_json_rt(old.to_dict()), _json_rt(cfg.to_dict()))
        if diff:
            raise ConfigError([f"--resume: the config differs from the one {out / name} was written with:"] + diff[:20])
        return cfg
    return cfg


def device_line(cfg: DatasetConfig) -> str:
    """One line naming the device the job runs on (instead of Warp's CUDA driver warning on CPU-only machines)."""
    dev = cfg.sim.device
    if dev.startswith("cuda"):
        try:
            import warp as wp  # start-up time: Warp loads on first use

            return f"device: {dev} ({wp.get_device(dev).name})"
        except Exception:  # noqa: BLE001
            return f"device: {dev}"
    if warpworm.cuda_driver_missing:
        return f"device: {dev} (no CUDA driver on this machine: CPU only)"
    return f"device: {dev}"


def generate(cfg: DatasetConfig, out_dir, *, workers: int = 1, resume: bool = False, stages: str = DEFAULT_STAGES,
             engine: str = "local", address: str | None = None, progress: bool = True, log=None) -> Summary:
    """Run a dataset job; returns its :class:`Summary`. See :mod:`warpworm.data.shard` for what determines each sample.

    Raises :class:`ConfigError` (bad input, before any work), :class:`warpworm.data.dataset.DatasetLockedError` (another
    job holds the folder), :class:`warpworm.data.dataset.DatasetWriteError` (disk full, read-only: completed shards intact),
    :class:`Interrupted` (SIGTERM / SIGINT: stopped cleanly), ``WorkerError`` (a worker died).
    """
    t0 = time.perf_counter()
    log = log or (lambda m: print(m, file=sys.stderr))
    holder = ds.lock_holder(out_dir) if Path(out_dir).is_dir() else None
    if holder is not None:
        raise ds.DatasetLockedError(f"{out_dir} is in use by another job: {ds.FolderLock.describe(holder)}; wait for it "
                                    "to finish or stop it (kill -TERM <pid>), then rerun with --resume")
    ds.check_output_dir(out_dir, resume)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    lock = ds.FolderLock(out).acquire()
    try:
        if lock.stale:
            log(f"note: {lock.path}: stale lock of a job that is gone ({ds.FolderLock.describe(lock.stale)}); "
                "taking it over")
        with SignalGuard() as guard:
            return _generate_locked(cfg, out, t0, guard, log, workers=workers, resume=resume, stages=stages,
                                    engine=engine, address=address, progress=progress)
    finally:
        lock.release()


def _generate_locked(cfg, out, t0, guard, log, *, workers, resume, stages, engine, address, progress):
    requested = cfg.shard_size
    run_cfg, note = shard_plan(cfg, workers if engine == "local" else 1)
    cfg, todo, done = plan_job(run_cfg, out, resume, requested_shard_size=requested, log=log)
    if note and (not resume or cfg.shard_size == run_cfg.shard_size):
        log(f"note: {note}")
    log(device_line(cfg))
    done_before = len(done)

    def save(complete, summary=None):
        with guard.critical():
            ds.atomic_write_json(out / ds.MANIFEST, ds.manifest(
                cfg, done, complete=complete, summary=dataclasses.asdict(summary) if summary is not None else None,
                shard_size_requested=requested))

    save(complete=not todo)
    loaded = load_stages(stages)  # once: the shards that run in this process use it; worker processes load the spec
    kernels_s = warm_kernels(cfg, loaded, log) if todo and engine == "local" else 0.0

    total_new = sum(cfg.shard_range(k)[1] - cfg.shard_range(k)[0] for k in todo)
    bar = tqdm(total=total_new, unit="sample", disable=not progress, dynamic_ncols=True, smoothing=0.1,
               desc=f"generate {cfg.name}", file=sys.stderr)
    written: dict[int, ShardStats] = {}
    try:
        with contextlib.closing(wk.run_shards(cfg, out, todo, stages, loaded=loaded, workers=workers, engine=engine,
                                              address=address, on_progress=bar.update)) as shards:
            for st in shards:
                with guard.critical():
                    written[st.index] = st
                    done[st.index] = dataclasses.asdict(st)
                    save(complete=False)
    except Interrupted:
        _discard_unrecorded(out, todo, done)
        raise
    finally:
        bar.close()
    summary = _summary(cfg, out, written, wall_s=time.perf_counter() - t0, done_before=done_before, workers=workers,
                       engine=engine)
    summary.kernels_s = kernels_s
    save(complete=True, summary=summary)
    return summary


def _discard_unrecorded(out: Path, todo: list[int], done: dict) -> None:
    """After a clean stop: a shard committed to disk between its rename and the manifest update is complete but
    unrecorded: discard it like the shard in flight (--resume writes the same bytes again), so the manifest lists
    exactly the shards on disk. And no temporary stays visible: the workers are stopped and the folder lock is ours,
    so any left (the shard in flight of a worker stopped mid-write, or a SIGKILLed run's that the signal beat the
    clean-up to) is dead."""
    for k in todo:
        if k not in done:
            (out / ds.shard_name(k)).unlink(missing_ok=True)
    ds.clean_temporaries(out, ".shard-*.tmp-*")


def _summary(cfg, out, written: dict[int, ShardStats], *, wall_s, done_before, workers, engine) -> Summary:
    w = written.values()
    return Summary(out=str(out), num_samples=cfg.num_samples, shards_total=cfg.num_shards,
                   shards_done_before=done_before, shards_written=len(written),
                   replaced_worlds=sum(s.replaced for s in w), wall_s=wall_s, sim_s=sum(s.sim_s for s in w),
                   render_s=sum(s.render_s for s in w), write_s=sum(s.write_s for s in w), workers=workers,
                   engine=engine, new_samples=sum(s.count for s in w),
                   cameras_below_min=sum(s.cameras_below_min for s in w))


__all__ = ["Summary", "device_line", "generate", "plan_job", "shard_plan"]
