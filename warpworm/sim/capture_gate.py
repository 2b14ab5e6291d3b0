"""Graph capture in one thread while other threads of the process run their own worlds (CPU, Warp 1.19).

Warp's CPU graph capture is process-wide on the Python side (``runtime._apic_capture``): while one thread captures,
a Warp operation another thread issues (a launch, an array, a copy) is registered into that graph (its kernels,
arrays and modules, written into the capturing thread's recorder while it records: a race; non-contiguous copies
raise), although the native recorder, per thread, still runs it. Replaying a captured graph (``wp.capture_launch``)
touches none of it: on the CPU it runs the graph's own recorded operations in C++ (thread-local recording state, the
GIL released).

So the gate is a readers-writer lock. The threads of a split run (:mod:`warpworm.analysis.world_split`) hold it
shared for their Warp work (:func:`hold`: building Models, plain launches, snapshots; all of them at once), a capture
takes it alone (:func:`capturing`, in :meth:`warpworm.sim.simulator.Simulator.step`: it waits until no other thread
is inside, and new entrants wait for it), and replays hold nothing (:func:`released`). A capture then overlaps other
threads' replays only, and everything else runs on every core at once. A thread that never entered :func:`hold`
(one batch, the main thread) is not gated.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager

_cond = threading.Condition()
_state = {"inside": 0, "capturing": False, "waiting": 0}  # threads holding it shared; a capture in progress; queued
_local = threading.local()


def _enter() -> None:
    with _cond:
        while _state["capturing"] or _state["waiting"]:  # a queued capture goes first (it cannot be starved)
            _cond.wait()
        _state["inside"] += 1
    _local.held = True


def _leave() -> None:
    _local.held = False
    with _cond:
        _state["inside"] -= 1
        _cond.notify_all()


@contextmanager
def hold():
    """Hold the gate shared in this thread for the block (a share of a split run), except inside :func:`released`
    and while this thread captures (:func:`capturing`). Not re-entrant: a thread already holding it would wait for
    a queued capture that waits for it (``world_split.run_shares`` runs a split inside a share in its thread)."""
    if getattr(_local, "held", False):
        raise RuntimeError("capture_gate.hold: this thread holds the gate already (a split inside a share?)")
    _enter()
    try:
        yield
    finally:
        if _local.held:  # not where a capture's wait was interrupted (it left the gate, and did not come back)
            _leave()


@contextmanager
def released():
    """Hold nothing for the block: only graph replays belong here (they touch no capture state)."""
    if not getattr(_local, "held", False):
        yield
        return
    _leave()
    try:
        yield
    finally:
        _enter()


@contextmanager
def capturing():
    """Hold the gate alone for the block (a graph capture): no other gated thread does Warp work meanwhile, replays
    aside. Outside :func:`hold` (one batch) it does nothing."""
    if not getattr(_local, "held", False):
        yield
        return
    _leave()
    with _cond:
        _state["waiting"] += 1
        try:
            while _state["capturing"] or _state["inside"]:
                _cond.wait()
        finally:
            _state["waiting"] -= 1
            _cond.notify_all()  # entrants held off by this queued capture (if the wait was interrupted)
        _state["capturing"] = True
    try:
        yield
    finally:
        with _cond:
            _state["capturing"] = False
            _cond.notify_all()
        _enter()


__all__ = ["capturing", "hold", "released"]
