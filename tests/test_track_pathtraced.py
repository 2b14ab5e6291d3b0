"""The tracker on footage warpworm's rasterizer did not draw (issue #41): a simulated omega cycle path-traced by Mitsuba
3 under a hard lamp and a dim room light (faces turned from the lamp at 25-45 % of their lit value), seen by a
camera tilted ~10 degrees with its own K and lens distortion, with the dataset's harshest sensor noise. The band
centres are checked against the independent truth: the centroids of each band's visible pixels (the rasterizer's
pixel-centre segmentation of the same scene through the same camera). The first tracker's brightness rule
(``brightness_cut=1``: value >= half the paint's) loses the shaded faces; the test shows it would fail."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from warpworm.analysis import footage as FO  # noqa: E402
from warpworm.analysis import track as T  # noqa: E402

W_IMG, H_IMG = 256, 192


@pytest.fixture(scope="module")
def shaded_footage():
    """4 frames of one omega cycle, path-traced at 256x192, 8 spp (~3 s), and the true band centres."""
    from warpworm import quiet_warp
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

    quiet_warp()
    r = run_gait(gaits.preset_params("omega", magnet_model="analytic"), 1, 1.0, fps=12.5, save_worlds=1)
    idx = np.array([0, 4, 8, 12])
    fr = {k: np.asarray(v)[idx] for k, v in r["frames"].items()}
    rng = np.random.default_rng(11)
    look = FO.random_look(rng)
    look.update(ambient=np.full(3, 0.07), lamp_pos=np.array([0.2, 0.15, 0.2]))  # a low lamp: hard shading
    cam = FO.random_camera(rng, W_IMG, H_IMG)
    rgb, truth = FO.pathtraced_band_video(fr, r["model"], cam, W_IMG, H_IMG, look, spp=8,
                                          sensor_values=T.harshest_sensor(len(idx)), seed=3)
    return rgb, truth, cam


def _errors(rgb, truth, thr):
    uv = np.stack([T.band_centroids(im, thr)[0] for im in rgb])
    return np.nan_to_num(np.linalg.norm(uv - truth, axis=-1), nan=np.inf)


def test_tracker_finds_the_shaded_bands_on_path_traced_footage(shaded_footage):
    rgb, truth, cam = shaded_footage
    assert np.isfinite(truth).all()
    assert abs(np.degrees(np.arccos(-cam.R[2, 2]))) > 5  # tilted (the optical axis is not straight down)
    err = _errors(rgb, truth, T.Thresholds.from_colors())
    # measured 0.94 px worst, 0.45 px mean (this look is harsher than the benchmark's average: docs/calibration.md)
    assert err.max() <= 1.0, err.max(axis=0)
    assert err.mean() <= 0.6, err.mean()
    # the hard masks (no boundary unmixing, saturation cut at half the paint's: the tracker before) miss the goal
    # here: 1.40 px worst, 0.63 px mean
    hard = _errors(rgb, truth, T.Thresholds.from_colors(soft=0.0, sat_frac=0.5))
    assert hard.max() > 1.0, hard.max()
    # the brightness rule of the first tracker loses the faces turned from the lamp: 6.5 px worst, 2.4 px mean
    old = _errors(rgb, truth, T.Thresholds.from_colors(brightness_cut=1.0, hue_tol=25.0))
    assert old.max() > 4.0 and old.mean() > 2.0, (old.max(), old.mean())


def test_floor_level_ignores_the_bright_tail():
    rng = np.random.default_rng(0)
    v = np.clip(rng.normal(40, 3, (100, 100)), 0, 255)
    v[40:60, 20:80] = 200  # a white band
    s = np.full_like(v, 10)
    fl, sig = T.floor_level(np.round(v).astype(np.int16), s.astype(np.int16))
    assert abs(fl - 40) < 1.0 and 2.0 < sig < 4.0
