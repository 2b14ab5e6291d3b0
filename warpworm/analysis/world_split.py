"""One batch of worlds on every core: contiguous shares of the worlds, one thread each, in this process.

Worlds never interact, so a batch of W worlds can run as a few batches of contiguous shares, each with its own
:class:`~warpworm.sim.model.Model` and :class:`~warpworm.sim.simulator.Simulator`, and every per-world result is the
one-batch result bit for bit (tests/test_threads_split.py). Threads, not processes: Warp's CPU kernels run on the
launching thread and release the GIL while they run (a ctypes call), so two threads keep two cores busy, and nothing
is paid per share to start (a process per share pays Python, ``import warp`` and kernel loading per batch;
docs/dynamics.md, "One job on every core", has the measurements and ``benchmarks/bench_threads.py`` the timing).

Two rules make the threads safe with Warp 1.19: the kernel modules are loaded once before the threads start (Warp
loads a module on its first launch, without a lock: two threads could load it twice), and the shares hold the
capture gate (:mod:`warpworm.sim.capture_gate`) shared for their Warp work while a capture takes it alone: a graph
capture is process-wide state in Warp (another thread's launches during it would be registered into it), a replay
touches none of it. So the shares step with CPU graphs like one batch (graphs replay the same trajectory bit for
bit, tests/test_step_graph.py) and run at once but for their captures.

NumPy's OpenBLAS runs one thread inside a split, whatever the worker count (:func:`one_blas_thread`): its rounding
depends on its thread count, so a per-world result computed with BLAS would otherwise depend on the split, and a
two-thread OpenBLAS spin-waits on small solves (docs/dynamics.md, "One job on every core"). Host work per world (e.g. compression's NumPy prediction) belongs in the
share's own function, after its simulation: no third thread competes with the shares for two cores, and a share's
host work overlaps the other share's replays (docs/dynamics.md, "One job on every core").

Used by :func:`warpworm.analysis.gait_runs.run_gait_split` (``simulate``, ``search-gait``) and
:func:`warpworm.analysis.experiments.split_run` (``experiment``).
"""

from __future__ import annotations

import ctypes
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from typing import Callable

import numpy as np

from warpworm import quiet_warp
from warpworm.physics.params import WormParams
from warpworm.sim import capture_gate
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

_local = threading.local()
_blas = {"lock": threading.Lock(), "users": 0, "saved": None, "lib": False}
_loaded = {"lock": threading.Lock(), "devices": set()}


def default_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def world_shares(num_worlds: int, workers: int | None) -> list[tuple[int, int]]:
    """Contiguous world ranges [lo, hi) for ``workers`` threads (None: every core; never more than the worlds)."""
    if int(num_worlds) < 1:
        raise ValueError(f"num_worlds: got {num_worlds}; expected >= 1")
    if workers is not None and int(workers) < 1:
        raise ValueError(f"workers: got {workers}; expected >= 1 (or None: every core)")
    n = max(1, min(int(workers or default_workers()), int(num_worlds)))
    bounds = np.linspace(0, num_worlds, n + 1).astype(int)
    return [(int(lo), int(hi)) for lo, hi in zip(bounds[:-1], bounds[1:])]


def in_split() -> bool:
    """Whether the calling thread runs a share of a split batch (then a split inside it runs in this thread)."""
    return getattr(_local, "split", False)


def load_kernels(device="cpu") -> None:
    """Load the kernel modules a simulation uses on ``device`` (from Warp's cache; compiled when cold), by one step and
    one snapshot of a one-world batch in this thread: exactly the modules the shares will launch, none they will not
    (the tile solver's, on a cold cache, would cost a compile for nothing). Once per device and process: a loaded
    module stays loaded, so the one-world run need not be repeated."""
    with _loaded["lock"]:
        if str(device) in _loaded["devices"]:
            return
        _load_kernels(device)
        _loaded["devices"].add(str(device))


def _load_kernels(device) -> None:
    quiet_warp()
    sim = Simulator(Model.from_params(WormParams(), 1, device), dt=0.004, substeps=2, use_graph=False)
    state = sim.initial_state()
    sim.step(state, 1)
    sim.snapshot(state)


def _openblas():
    """(get, set) of the thread count of the OpenBLAS NumPy loaded (ctypes), or None where there is none (MKL,
    Accelerate, not Linux): then :func:`one_blas_thread` does nothing."""
    if _blas["lib"] is not False:
        return _blas["lib"]
    _blas["lib"] = None
    try:
        with open("/proc/self/maps") as f:
            paths = sorted({ln.split()[-1] for ln in f if "openblas" in ln.lower() and ".so" in ln})
    except OSError:  # pragma: no cover - not Linux
        paths = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:  # pragma: no cover
            continue
        for get, put in (("scipy_openblas_get_num_threads64_", "scipy_openblas_set_num_threads64_"),
                         ("openblas_get_num_threads64_", "openblas_set_num_threads64_"),
                         ("openblas_get_num_threads", "openblas_set_num_threads")):
            if hasattr(lib, get) and hasattr(lib, put):
                g, p = getattr(lib, get), getattr(lib, put)
                g.restype, g.argtypes, p.restype, p.argtypes = ctypes.c_int, [], None, [ctypes.c_int]
                _blas["lib"] = (g, p)
                return _blas["lib"]
    return None


def blas_threads() -> int | None:
    """NumPy's OpenBLAS thread count now (None: not an OpenBLAS this module can set)."""
    lib = _openblas()
    return None if lib is None else int(lib[0]())


@contextmanager
def one_blas_thread():
    """NumPy's OpenBLAS at one thread while any caller is inside (the setting is process-wide in a pthreads OpenBLAS;
    the count before the first caller entered is put back when the last one leaves). Module docstring: why."""
    lib = _openblas()
    if lib is None:
        yield
        return
    with _blas["lock"]:
        if _blas["users"] == 0:
            _blas["saved"] = int(lib[0]())
            lib[1](1)
        _blas["users"] += 1
    try:
        yield
    finally:
        with _blas["lock"]:
            _blas["users"] -= 1
            if _blas["users"] == 0:
                lib[1](_blas["saved"])


def run_shares(fn: Callable[[int, int], dict], num_worlds: int, workers: int | None = None,
               device="cpu") -> list[dict]:
    """``fn(lo, hi)`` for the contiguous shares of ``num_worlds`` worlds (:func:`world_shares`), one thread each
    (one share: in this thread, no gate); returns their results in world order. ``fn`` builds its own Model
    and Simulator for worlds [lo, hi). An exception in a share is re-raised here after
    every share has stopped. NumPy's OpenBLAS runs one thread meanwhile, whatever the shares
    (:func:`one_blas_thread`)."""
    shares = world_shares(num_worlds, workers)
    # one device queue: a GPU runs the batch as one; a split inside a share runs in that share's thread (its own
    # threads' first capture would wait for the share's hold on the gate, and the share for them)
    if len(shares) == 1 or str(device).startswith("cuda") or in_split():
        with one_blas_thread():
            return [fn(0, int(num_worlds))]
    load_kernels(device)

    def share(lo_hi):
        _local.split = True
        try:
            with one_blas_thread(), capture_gate.hold():
                return fn(*lo_hi)
        finally:
            _local.split = False

    with ThreadPoolExecutor(max_workers=len(shares), thread_name_prefix="warpworm-share") as pool:
        return list(pool.map(share, shares))


def concat(parts: list[dict], world_axis: dict) -> dict:
    """The shares' result dicts as one: key ``k`` concatenated along ``world_axis[k]``; a key not in ``world_axis``
    (a value that does not depend on the worlds) is the first share's."""
    return {k: (np.concatenate([q[k] for q in parts], axis=world_axis[k]) if k in world_axis else parts[0][k])
            for k in parts[0]}


__all__ = ["blas_threads", "concat", "default_workers", "in_split", "load_kernels", "one_blas_thread",
           "run_shares", "world_shares"]
