"""Exposure and white balance per sample (issue 24, item 5): a gain on the linear light before the display encoding
(the renderer's gamma 2), drawn per sample from its seed and stored as params/sensor.*; labels untouched."""

from __future__ import annotations

import dataclasses

import h5py
import numpy as np
import pytest

from warpworm import quiet_warp
from warpworm.data.config import ConfigError, load_config
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.sensor import exposure_gains

quiet_warp()
PATTERN = default_pattern()


def test_gain_scales_linear_light_before_encoding():
    st = posed_worm_states(np.arange(3), PATTERN)
    scene = build_scene(st["positions"], PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=PATTERN.vertices)
    cams = sample_cameras(np.arange(3), st["positions"], width=64, height=48)
    gain = np.array([[2.0, 1.0, 0.5], [0.5, 0.5, 0.5], [1.3, 1.0, 0.8]])
    plain = Renderer(64, 48).render(scene, cams)
    lit = Renderer(64, 48).render(scene, dataclasses.replace(cams, gain=gain))
    for k in ("depth", "seg", "worm_mask"):
        assert np.array_equal(plain[k], lit[k]), k
    # a stored level v stands for linear light in [((v - .5) / 255)^2, ((v + .5) / 255)^2]; times g and encoded
    # (sqrt, round), the output must fall in [round(sqrt(g) (v - .5)), round(sqrt(g) (v + .5))], clipped at 255
    v = plain["rgb"].astype(np.float64)
    sg = np.sqrt(gain)[:, None, None, :]
    lo = np.minimum(np.floor(sg * np.maximum(v - 0.5, 0) + 0.5), 255)
    hi = np.minimum(np.floor(sg * (v + 0.5) + 0.5), 255)
    got = lit["rgb"].astype(np.float64)
    assert np.all((got >= lo) & (got <= hi))
    assert got[0, ..., 0].mean() > v[0, ..., 0].mean() * 1.3  # +1 stop on red: brighter (sqrt 2 in display)


def test_draws_per_sample_and_off():
    off = load_config("default").render
    assert exposure_gains(off, np.arange(4)) is None
    r = load_config("default", ["render.exposure=[-1, 0.5]", "render.white_balance=[0.8, 1.25]"]).render
    g, values = exposure_gains(r, np.arange(100))
    g2, _ = exposure_gains(r, np.arange(50, 60))
    assert np.array_equal(g[50:60], g2)  # a sample's seed fixes it, in any batch
    ev = values["sensor.exposure"]
    assert ev.min() >= -1 and ev.max() <= 0.5 and ev.std() > 0.3
    np.testing.assert_allclose(g[:, 1], np.exp2(ev))
    np.testing.assert_allclose(g[:, 0] / g[:, 1], values["sensor.wb_red"])
    assert values["sensor.wb_blue"].min() >= 0.8 and values["sensor.wb_blue"].max() <= 1.25


def test_dataset_stores_the_draws(tmp_path):
    from warpworm.commands.verify import verify_dataset
    from warpworm.data.job import generate

    cfg = load_config("default", ["render.exposure=[-1, 1]", "render.white_balance=[0.8, 1.25]", "num_samples=8",
                                  "shard_size=8", "sim.worlds=2", "output.preview=false", "sim.settle_time=0.02",
                                  "sim.frame_times=[0.02, 0.04, 0.06, 0.08]"])
    generate(cfg, tmp_path / "ds", progress=False)
    with h5py.File(next((tmp_path / "ds").glob("*.h5"))) as f:
        ev, seeds = f["params/sensor.exposure"][...], f["seed"][...]
        red = f["params/sensor.wb_red"][...]
    _, values = exposure_gains(cfg.render, seeds)
    assert np.array_equal(ev, values["sensor.exposure"]) and np.array_equal(red, values["sensor.wb_red"])
    assert len(np.unique(ev)) == 8  # per sample, not per trajectory
    assert verify_dataset(tmp_path / "ds")[0] == []


def test_bad_gain_refused():
    with pytest.raises(ConfigError, match="render.white_balance: got \\[1.2, 0.8\\]"):
        load_config("default", ["render.white_balance=[1.2, 0.8]"])
