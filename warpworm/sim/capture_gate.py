"""Graph capture in one thread while other threads of the process run their own worlds (CPU, Warp 1.19).

Warp's CPU graph capture is process-wide on the Python side (``runtime._apic_capture``): while one thread captures,
a Warp operation another thread issues (a launch, an array, a copy) is registered into that graph (its kernels,
arrays and modules, written into the capturing thread's recorder while it records: a race; non-contiguous copies
raise), although the native recorder, per thread, still runs it. Replaying a captured graph (``wp.capture_launch``)
touches none of it: on the CPU it runs the graph's own recorded operations in C++ (thread-local recording state, the
GIL released). So the threads of a split run (:mod:`warpworm.analysis.world_split`) each hold this gate whenever
they are not replaying (:func:`hold`), and :meth:`warpworm.sim.simulator.Simulator.step` lets it go around its replays
(:func:`released`): a capture (made while its thread holds the gate) then overlaps other threads' replays only, and
the replays, where a simulation spends its time, run on every core at once. A thread that never entered
:func:`hold` (one batch, the main thread) is not gated.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

_gate = threading.Lock()
_local = threading.local()


@contextmanager
def hold():
    """Hold the gate in this thread for the block (a share of a split run), except inside :func:`released`."""
    _gate.acquire()
    _local.held = True
    try:
        yield
    finally:
        _local.held = False
        _gate.release()


@contextmanager
def released():
    """Let other gated threads issue Warp work (and capture) for the block: only graph replays belong here."""
    if not getattr(_local, "held", False):
        yield
        return
    _local.held = False
    _gate.release()
    try:
        yield
    finally:
        _gate.acquire()
        _local.held = True


__all__ = ["hold", "released"]
