"""Worlds the simulator no longer steps (exploded, crumpled, retired) cost no magnet wrench, an exploded world's NaN
poses give NaN wrenches at once, and a per-phase run stops once every world with frames left is unstable. Checked
against the same calls without each shortcut: the other worlds' wrenches and frames bit for bit."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from test_world_retire import KEYS, _sim

from warpworm import quiet_warp
from warpworm.data.warp_stages import frame_steps, run_at_phases
from warpworm.ids import WORLD_CRUMPLED, WORLD_EXPLODED
from warpworm.physics import gaits
from warpworm.physics.magnets import pair_wrench_scratch
from warpworm.sim.simulator import model_wrenches

quiet_warp()


def _on_path(worlds: int):
    """A settled omega worm (:func:`test_world_retire._sim`) two steps into its gait: every pair's wrench non-zero."""
    sim, state = _sim(worlds)
    sim.step(state, 2)
    return sim, state


def _wrenches(sim, state, scratch, skip: bool):
    m = sim.model
    model_wrenches(m, state, m.magnet_moment, pair_scratch=scratch, skip_stopped=skip)
    return state.magnet_force.numpy().copy(), state.magnet_torque.numpy().copy()


def _move_ipms(state, by: float):
    pos = state.magnet_pos.numpy()
    pos[:, 1:, 2] += by
    state.magnet_pos.assign(pos)


def test_a_stopped_world_keeps_its_wrench_and_the_others_are_recomputed():
    sim, state = _on_path(2)
    scratch = pair_wrench_scratch(2, 4, "cpu")
    f0, t0 = _wrenches(sim, state, scratch, skip=True)  # both running: both evaluated
    _move_ipms(state, 1e-3)
    flags = state.unstable.numpy()
    flags[1] = WORLD_CRUMPLED
    state.unstable.assign(flags)
    f1, t1 = _wrenches(sim, state, scratch, skip=True)
    fresh_f, fresh_t = _wrenches(sim, state, pair_wrench_scratch(2, 4, "cpu"), skip=False)
    np.testing.assert_array_equal(f1[0], fresh_f[0])  # the running world: its wrench at the new poses
    np.testing.assert_array_equal(t1[0], fresh_t[0])
    np.testing.assert_array_equal(f1[1], f0[1])  # the stopped one: the wrench it had
    np.testing.assert_array_equal(t1[1], t0[1])
    assert np.abs(fresh_f[1] - f0[1]).max() > 1e-3 * np.abs(f0[1]).max()  # evaluated, it would have changed


def test_nan_poses_give_nan_wrenches_and_leave_the_other_worlds_alone():
    sim, state = _on_path(2)
    finite_f, finite_t = _wrenches(sim, state, pair_wrench_scratch(2, 4, "cpu"), skip=False)
    pos = state.magnet_pos.numpy()
    pos[1, 2] = np.nan  # world 1's centre IPM, as an exploded world's
    state.magnet_pos.assign(pos)
    f, t = _wrenches(sim, state, pair_wrench_scratch(2, 4, "cpu"), skip=False)
    np.testing.assert_array_equal(f[0], finite_f[0])
    np.testing.assert_array_equal(t[0], finite_t[0])
    assert np.isnan(f[1]).all() and np.isnan(t[1]).all()  # every magnet of the world has a pair with the NaN one


def test_a_phase_run_stops_once_every_world_left_is_unstable():
    """Three periods (the worlds' last frames on three steps); the longest world exploded after settling. The run
    ends at the second world's last frame, not the third's; the other worlds' frames equal a full run's and every
    frame of the exploded world is flagged unstable (the dataset redraws it)."""
    periods = np.array([0.1, 0.13, 0.16])
    phases = [0.5, 1.0]
    p = replace(gaits.preset_params("omega"), cycle_period=periods)
    steps = frame_steps(phases, periods, gaits.DEFAULT_DT)

    def run(keys):
        sim, state = _sim(3, p)
        flags = state.unstable.numpy()
        flags[2] = WORLD_EXPLODED
        state.unstable.assign(flags)
        spent = []
        run_once = sim.run

        def counted(state, times, **kw):
            spent.append(sum(times))
            return run_once(state, times, **kw)

        sim.run = counted
        return run_at_phases(sim, state, p, 3, phases, keys), round(sum(spent) / sim.dt)

    frames, stepped = run(KEYS)
    full, stepped_full = run(KEYS[:-1])  # without the flags the run cannot stop early
    assert stepped == steps[1, -1] < stepped_full == steps[2, -1]
    for f, f_ref in zip(frames, full):
        assert f.pop("clock") == f_ref.pop("clock")
        for k in f_ref:
            np.testing.assert_array_equal(f[k][:2], f_ref[k][:2], err_msg=k)
        assert f["unstable"].tolist() == [False, False, True]
