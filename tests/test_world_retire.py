"""``Simulator.retire``: a world whose frames are all taken stops being stepped, and nothing else changes. Checked
against runs without it: the other worlds' trajectories bit for bit, the retired world held where it was, and the
dataset's per-phase frames (``run_at_phases``, which retires each world after its last frame) equal to a run that
steps every world to the end."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from warpworm import quiet_warp
from warpworm.data.warp_stages import frame_steps, run_at_phases
from warpworm.ids import WORLD_EXPLODED, WORLD_RETIRED
from warpworm.physics import gaits
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

quiet_warp()

KEYS = ("positions", "magnet_pos", "magnet_rot", "crease_angle", "bar_strain", "unstable")


def _sim(worlds: int = 3, params=None):
    p = params or replace(gaits.preset_params("omega"), hinge_stiffness=np.linspace(0.004, 0.006, worlds))
    sim = Simulator(Model.from_params(p, worlds, "cpu"), dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.02)
    return sim, state


def test_a_retired_world_stops_and_the_others_run_on_bit_for_bit():
    sim, state = _sim()
    sim.step(state, 10)
    held = state.positions.numpy()[1].copy()
    sim.retire(state, [False, True, False])
    sim.step(state, 15)
    ref_sim, ref = _sim()
    ref_sim.step(ref, 25)
    x, x_ref = state.positions.numpy(), ref.positions.numpy()
    np.testing.assert_array_equal(x[[0, 2]], x_ref[[0, 2]])
    np.testing.assert_array_equal(x[1], held)
    assert np.abs(x_ref[1] - held).max() > 1e-6  # stepped on, world 1 would have moved: the hold is the retirement
    steps = state.step_count.numpy()
    assert steps[1] < steps[0] == steps[2] == ref.step_count.numpy()[0]
    snap = sim.snapshot(state)
    assert not snap["unstable"].any() and not snap["crumpled"].any()  # retired is not unstable


def test_retire_keeps_an_unstable_flag():
    sim, state = _sim(2)
    flags = state.unstable.numpy().copy()
    flags[0] = WORLD_EXPLODED
    state.unstable.assign(flags)
    sim.retire(state, [True, True])
    np.testing.assert_array_equal(state.unstable.numpy(), [WORLD_EXPLODED, WORLD_RETIRED])
    assert sim.snapshot(state)["unstable"].tolist() == [True, False]


def test_frames_at_phases_equal_those_of_a_run_that_steps_every_world_to_the_end(monkeypatch):
    """Three periods, so the worlds' last frames fall on three different steps: every frame of every world equals
    the one taken with retirement switched off, and each world stopped at its own last frame."""
    periods = np.array([0.1, 0.13, 0.16])
    phases = [0.5, 1.0]
    p = replace(gaits.preset_params("omega"), cycle_period=periods)

    sim, state = _sim(3, p)
    frames = run_at_phases(sim, state, p, 3, phases, KEYS)
    stopped = state.step_count.numpy().copy()

    monkeypatch.setattr(Simulator, "retire", lambda self, state, worlds: None)
    sim_ref, ref = _sim(3, p)
    frames_ref = run_at_phases(sim_ref, ref, p, 3, phases, KEYS)

    for f, f_ref in zip(frames, frames_ref):
        assert set(f) == set(f_ref)
        for k in f:
            np.testing.assert_array_equal(f[k], f_ref[k], err_msg=k)
    last = frame_steps(phases, periods, sim.dt)[:, -1]
    assert len(set(last.tolist())) == 3
    np.testing.assert_array_equal(stopped, last * sim.substeps)  # step_count counts substeps
    assert (ref.step_count.numpy() == last.max() * sim.substeps).all()


def test_a_mask_of_the_wrong_length_is_refused():
    sim, state = _sim(2)
    with pytest.raises(ValueError, match=r"retire: worlds has shape \(3,\); expected one bool per world, \(2,\)"):
        sim.retire(state, [True, False, True])
    assert (state.unstable.numpy() == 0).all()
