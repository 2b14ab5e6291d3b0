"""Scale-out: shards run in worker processes (one per core, ``spawn``), or as Ray tasks on a cluster.

Why processes: Warp runs CPU kernels on one thread, so P cores need P processes. Why ``spawn``: Warp and h5py hold
native state that must not be forked. Each shard is an independent task whose output depends only on (config, k), so
the engine and worker count never change the data.

Start-up: the job has loaded the stages' Warp kernel modules once before it starts the shards
(:func:`warpworm.data.job.warm_kernels`: with a cold kernel cache the modules compile in parallel threads, into the
cache every worker reads), so no two processes compile the same module; each worker does its heavy imports
(``preload``) when it starts.

A worker that dies (SIGKILL, out of memory) breaks the local pool: the job stops with a clear error, finished shards stay
committed, the half-written shard is a temporary file, and ``--resume`` redoes exactly the missing shards. A worker whose
parent dies exits by itself (a watchdog thread), so a killed job leaves no orphan writing files.

On Ray, a shard task whose worker or node dies is re-run by Ray (``RAY_MAX_RETRIES``) and the job goes on; the
temporaries such attempts left are deleted when every shard is committed (tested: tests/test_dataset_ray.py kills a
node of a two-node cluster mid-shard).
"""

from __future__ import annotations

import gc
import multiprocessing as mp
import os
import queue as queue_mod
import signal
import threading
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Callable, Iterator

from warpworm.data import signal_hold
from warpworm.data.dataset import DatasetWriteError, clean_temporaries, shard_name
from warpworm.data.shard import ShardStats, run_shard
from warpworm.data.signal_hold import Interrupted
from warpworm.data.stages import load_stages

_progress_queue = None
_in_shard = False
_stages = None
"""This worker process's stages object, loaded once from the job's spec (:func:`_init_worker`)."""


def _worker_signal(signum, frame):
    """SIGTERM / SIGINT in a worker: discard the shard in flight (run_shard deletes its temporary), then exit."""
    if _in_shard:
        if signal_hold.in_io():  # inside an h5py call: raised when it returns (warpworm.data.signal_hold)
            signal_hold.defer(signum)
            return
        raise Interrupted(signum)
    os._exit(128 + signum)


def _init_worker(q, parent_pid: int, stages):
    global _progress_queue, _stages

    _progress_queue = q
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, _worker_signal)

    def watchdog():
        while True:
            if os.getppid() != parent_pid:
                os._exit(1)  # parent gone (killed): stop writing at once
            time.sleep(0.5)

    threading.Thread(target=watchdog, daemon=True, name="warpworm-parent-watchdog").start()
    _stages = load_stages(stages)
    preload = getattr(_stages, "preload", None)
    if preload is not None:  # heavy imports (Warp, the simulator, the renderer) before the first shard
        preload()
    gc.freeze()  # what the imports made lives until exit: collections, the worker's last one included, skip it


def _report(n: int):
    if _progress_queue is not None:
        _progress_queue.put(n)


def _run_shard_task(cfg, out, k):
    global _in_shard
    _in_shard = True
    try:
        return run_shard(cfg, out, k, _stages, progress=_report)
    except Interrupted as exc:  # the temporary is gone (run_shard aborted the writer): stop this process now
        os._exit(128 + exc.signum)
    finally:
        _in_shard = False


class WorkerError(RuntimeError):
    """A worker failed; completed shards are intact and ``--resume`` continues the job."""


def run_shards(cfg, out, todo: list[int], stages, *, loaded=None, workers: int = 1, engine: str = "local",
               address: str | None = None,
               on_progress: Callable[[int], None] = lambda n: None) -> Iterator[ShardStats]:
    """Run shards ``todo``, yielding each one's :class:`~warpworm.data.shard.ShardStats` as it is committed (in the
    order they finish); calls ``on_progress(samples)`` as batches finish. Closing the generator early (the caller
    stopped: a signal, an error) stops the workers; use it in ``contextlib.closing``.

    ``stages``: the ``"module:attr"`` spec worker processes and Ray tasks load (or a stages object, in this process
    only); ``loaded``: the stages object already loaded here, for shards run in this process (None: load ``stages``).
    """
    if not todo:
        return
    if engine == "ray":
        yield from _run_ray(cfg, out, todo, stages, address, on_progress)
        return
    if engine != "local":
        raise ValueError(f"--engine: got {engine!r}; expected 'local' or 'ray'")
    if workers <= 1:
        here = load_stages(stages) if loaded is None else loaded
        for k in todo:
            yield run_shard(cfg, out, k, here, progress=on_progress)
        return
    yield from _run_local_pool(cfg, out, todo, stages, workers, on_progress)


def _run_local_pool(cfg, out, todo, stages, workers, on_progress):
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    # one thread per process: BLAS/OpenMP pools would oversubscribe the cores the other workers use
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    stop = threading.Event()

    def drain():
        while not stop.is_set() or not q.empty():
            try:
                on_progress(q.get(timeout=0.1))
            except queue_mod.Empty:
                continue
            except (EOFError, OSError):
                return

    t = threading.Thread(target=drain, daemon=True)
    t.start()
    pool = ProcessPoolExecutor(max_workers=min(workers, len(todo)), mp_context=ctx, initializer=_init_worker,
                               initargs=(q, os.getpid(), stages))
    try:
        pending = {pool.submit(_run_shard_task, cfg, str(out), k): k for k in todo}  # starts the workers
        while pending:
            finished, _ = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                k = pending.pop(fut)
                try:
                    st = fut.result()
                except Exception as exc:  # noqa: BLE001 - re-raised with the recovery advice
                    for f in pending:
                        f.cancel()

                    if isinstance(exc, DatasetWriteError):  # disk full in a worker: its own one-line message
                        _stop_workers(pool)
                        raise exc from None
                    raise WorkerError(f"shard {k} failed in a worker: {type(exc).__name__}: {exc}. Completed shards "
                                      "are intact; rerun the same command with --resume to finish the job") from exc
                yield st
    except BaseException:  # GeneratorExit too: the caller stopped
        _stop_workers(pool)  # SIGTERM / SIGINT in the parent, or a failure: no worker keeps writing
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        stop.set()
        t.join(timeout=2)


def _stop_workers(pool, timeout: float = 10.0) -> None:
    """SIGTERM every live worker (each discards its shard in flight and exits), SIGKILL any left after ``timeout``."""
    procs = list(getattr(pool, "_processes", {}).values())
    for p in procs:
        if p.is_alive():
            try:
                os.kill(p.pid, signal.SIGTERM)
            except (ProcessLookupError, TypeError):
                pass
    t_end = time.monotonic() + timeout
    for p in procs:
        p.join(max(0.0, t_end - time.monotonic()))
        if p.is_alive():
            p.kill()
            p.join(1.0)


RAY_MAX_RETRIES = 3
"""Ray re-runs a shard task up to this many times when its worker or node dies (system failures only; an exception in
the task, e.g. disk full, is not retried). A re-run is safe: shard k's content depends only on (config, k), and the
shard is written under a temporary name and renamed when complete."""


def _run_ray(cfg, out, todo, stages, address, on_progress):
    try:
        import ray  # optional dependency: ray (the ray extra)
    except ImportError:
        raise WorkerError("--engine ray needs Ray: pip install 'warpworm[ray]'") from None
    ray.init(address=address, ignore_reinit_error=True, log_to_driver=False,
             runtime_env={"env_vars": {"OMP_NUM_THREADS": "1"}})
    task = ray.remote(num_cpus=1, max_retries=RAY_MAX_RETRIES, retry_exceptions=False)(_ray_shard)
    refs = {task.remote(cfg, str(out), k, stages): k for k in todo}
    while refs:
        ready, _ = ray.wait(list(refs), num_returns=1)
        k = refs.pop(ready[0])
        try:
            st = ray.get(ready[0])
        except Exception as exc:  # noqa: BLE001
            for r in refs:
                ray.cancel(r)
            raise WorkerError(f"shard {k} failed in a Ray task: {exc}. Completed shards are intact; rerun with "
                              "--resume") from exc
        on_progress(st.count)
        yield st
    _remove_dead_attempts(out, todo)


def _remove_dead_attempts(out, shards) -> list[str]:
    """Delete the temporaries (``.shard-k.h5.tmp-<pid>``) that attempts killed with their node left behind, once every
    shard in ``shards`` is committed: Ray re-ran those attempts elsewhere, and a task whose node died is gone (its
    worker exits when its raylet does), so nothing is still writing them. (The pid in a name is another host's, so it
    cannot tell here whether its writer lives.)"""
    return [name for k in shards for name in clean_temporaries(out, f".{shard_name(k)}.tmp-*")]


def _ray_shard(cfg, out, k, stages):
    # Ray workers may not see the driver's sys.path (tests' fake stages): it travels with the task
    return run_shard(cfg, out, k, load_stages(stages))


def default_workers() -> int:
    """One worker per core available to this process."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


__all__ = ["run_shards", "default_workers", "WorkerError"]
