"""``sim.frame_unit: cycle``: frames at phases of each world's EPM cycle (closest approach at k + 1/2, far point at k),
whatever its period. Checked against the EPM path's own formula (the magnet's height at the frame), against the
seconds-based frames where the two coincide (period 1 s), and the config's refusals."""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.data.config import ConfigError, load_config
from warpworm.data.job import generate
from warpworm.data.warp_stages import frame_steps

COMMON = ["sim.worlds=4", "shard_size=8", "sim.settle_time=0.02", "render.width=32", "render.height=24",
          "output.preview=false"]


def _all(root):
    r = ds.open(root)
    return {k: r.read(k, range(len(r))) for k in r.keys()}


def test_cycles_equal_seconds_when_the_period_is_one_second(tmp_path):
    """The default config's paths all last 1 s: frames at [0.02, 0.04] cycles are those at [0.02, 0.04] s, every
    dataset bit for bit (the per-step snapshots give the same states as one run to each frame)."""
    generate(load_config("default", COMMON + ["sim.frame_times=[0.02, 0.04]"], num_samples=8), tmp_path / "s",
             progress=False)
    generate(load_config("default", COMMON + ["sim.frame_times=[0.02, 0.04]", "sim.frame_unit=cycle"],
                         num_samples=8), tmp_path / "c", progress=False)
    a, b = _all(tmp_path / "s"), _all(tmp_path / "c")
    assert set(a) == set(b)
    for k in a:
        assert np.array_equal(a[k], b[k]), k


def test_frames_fall_on_the_path_phase_whatever_the_period(tmp_path):
    """Periods drawn in [0.8, 1.2] s; frames at 0.5 and 1.0 cycles: each sample's time is round(phase period / dt)
    dt, and there the EPM sits at the path's closest approach h (phase 1/2) or at h + a (far point, phase 1) below the
    origami base: its centre at z = -(gap + e(theta)) (warpworm.physics.gaits), to within the step's rounding."""
    from warpworm.physics.gaits import epm_half_height

    cfg = load_config("default", COMMON + ["sim.frame_times=[0.5, 1.0]", "sim.frame_unit=cycle",
                                           "randomize.worm.cycle_period={uniform: [0.8, 1.2]}"], num_samples=8)
    generate(cfg, tmp_path / "p", progress=False)
    d = _all(tmp_path / "p")
    period = d["params/worm.cycle_period"]
    assert np.ptp(period) > 0.05  # the periods differ, so a fixed time could not hit every phase
    phase = np.array([0.5, 1.0])[d["frame"]]
    dt = cfg.sim.dt
    assert np.allclose(d["time"], np.rint(phase * period / dt) * dt, atol=1e-6)
    h = d["params/worm.closest_approach"] * d["params/worm.closest_approach_scale"]
    a = d["params/worm.amplitude"]
    size = np.stack([d[f"params/worm.epm_size_{c}"] for c in "xyz"], axis=1)
    e = epm_half_height(size, d["params/worm.orientation"])
    s = d["time"] / period  # the phase actually simulated (rounded to a step)
    gap = h + a * (1 + np.cos(2 * np.pi * s)) / 2
    assert np.allclose(d["poses/epm"][:, 2, 3], -(gap + e), atol=1e-6)
    # and the rounding is small: the gap within 0.5 mm of the closest approach / far point
    assert np.all(np.abs(gap - np.where(d["frame"] == 0, h, h + a)) < 5e-4)


def test_refusals():
    with pytest.raises(ValueError, match="sim.frame_times"):
        frame_steps([0.5, 0.501], np.array([1.0, 0.8]), 0.004)
    with pytest.raises(ConfigError, match="multiples of sim.dt"):
        load_config("default", ["sim.frame_times=[0.5, 0.541]"])
    with pytest.raises(ConfigError, match="sim.frame_unit"):
        load_config("default", ["sim.frame_unit=minutes"])
    c = load_config("default", ["sim.frame_unit=cycle", "sim.frame_times=[0.5, 0.541]"])
    assert c.sim.frame_unit == "cycle" and "frame_unit: cycle" in c.to_yaml()
    assert "frame_unit" not in load_config("default").to_yaml()  # off: config_yaml as before the option
