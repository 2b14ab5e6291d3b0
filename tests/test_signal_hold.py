"""A stop signal that arrives while HDF5 is calling back into Python (the shard writer's file object) stops the job
cleanly (Interrupted, exit 128 + signal) instead of surfacing as an HDF5 write error (exit 1)."""

from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.data import signal_hold
from warpworm.data.job import SignalGuard
from warpworm.data.signal_hold import Interrupted


def test_signal_inside_an_io_section_is_raised_when_it_ends():
    reached_end_of_section = False
    with SignalGuard():
        with pytest.raises(Interrupted) as info:
            with signal_hold.io_section():
                with signal_hold.io_section():  # nested: only the outermost delivers
                    os.kill(os.getpid(), signal.SIGTERM)
                reached_end_of_section = True
    assert reached_end_of_section and info.value.signum == signal.SIGTERM
    assert not signal_hold.in_io()


def test_sigterm_during_an_h5py_write_callback_is_a_clean_stop(tmp_path, monkeypatch):
    """SIGTERM sent from inside the file object's write (so the handler runs while HDF5 is in the callback, as a
    kill landing in a shard's flush does): the writer raises Interrupted after the write, where before the stop came
    back out of h5py as an error (measured without the hold: SystemError from the file object's flush)."""
    calls = {"n": 0}
    real = ds.FailSafeFile._raw_write

    def write_and_get_killed(self, b):
        calls["n"] += 1
        if calls["n"] == 3:
            os.kill(os.getpid(), signal.SIGTERM)
        return real(self, b)

    monkeypatch.setattr(ds.FailSafeFile, "_raw_write", write_and_get_killed)
    with SignalGuard():
        with pytest.raises(Interrupted):
            writer = ds.ShardWriter(tmp_path, 0, 0, 4, {"note": "test"})
            writer.write(0, {"rgb": np.zeros((4, 8, 8, 3), np.uint8)})
            writer.commit()
    assert calls["n"] >= 3
