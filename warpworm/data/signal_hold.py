"""Sections of HDF5 I/O in which a stop signal is held, not raised.

h5py calls back into Python to write a shard (the writer's fail-safe file object, :mod:`warpworm.data.dataset`). A stop
(:class:`Interrupted`) raised by a signal handler while HDF5 is inside such a call comes back out of
h5py as an ``OSError``: the job would report a write failure (exit 1) for a clean SIGTERM. The job's and the
workers' signal handlers therefore only record a signal that arrives inside :func:`io_section`; the outermost
section raises it when it ends. Process-wide (signals are handled on the main thread), not thread-safe by design.
"""

from __future__ import annotations

import functools
import signal as _signal
from contextlib import contextmanager

_depth = 0
_pending: int | None = None


class Interrupted(BaseException):
    """The job got SIGTERM or SIGINT and stopped cleanly: finished shards committed and in the manifest, the shard in
    flight discarded (its temporary deleted), workers stopped. ``--resume`` continues. Exit code 128 + signal.

    A ``BaseException``, as ``KeyboardInterrupt`` is: the signal handler raises it wherever the main thread is, and
    library code's ``except Exception`` (``inspect.getfullargspec`` turns any exception into ``TypeError('unsupported
    callable')``, a best-effort clean-up swallows it) must not catch or transform a stop."""

    def __init__(self, signum: int):
        self.signum = int(signum)
        super().__init__(f"interrupted by {_signal.Signals(self.signum).name}")


def in_io() -> bool:
    """Whether the main thread is inside an :func:`io_section`."""
    return _depth > 0


def defer(signum: int) -> None:
    """Record ``signum`` for the end of the current I/O section (a signal handler's call)."""
    global _pending
    _pending = int(signum)


@contextmanager
def io_section():
    """Hold stop signals for the duration; if one arrived, raise :class:`Interrupted` at the end of
    the outermost section (only when the section ends normally: an exception leaving it goes on, and the job stops
    on that)."""
    global _depth, _pending
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if _depth == 0 and _pending is not None:
        sig, _pending = _pending, None
        raise Interrupted(sig)


def holds_signals(fn):
    """Decorator: run ``fn`` inside an :func:`io_section`."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with io_section():
            return fn(*args, **kwargs)

    return wrapper
