"""The band tracker (warpworm.analysis.track, ``warpworm track``) on warpworm's own renders of each gait: band centres
against the renderer's exact visible-pixel labels (render.labels.band_labels), ratios and displacement against the
labels' centres taken on the same plane and, for a worm that stays on the floor, against their 3-D centres; the
back-projection against cv2.projectPoints; unseen bands marked; the command's CSV and refusals."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from warpworm.analysis import track as T

W_IMG, H_IMG = 640, 480


@pytest.fixture(scope="module")
def gait_videos():
    """One cycle of each preset (1 world, 15 fps), rendered with the bands from above at 640x480 with sensor noise."""
    from warpworm import quiet_warp
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits
    from warpworm.render import make_cameras
    from warpworm.render.labels import band_labels

    quiet_warp()
    out = {}
    cam = T.overhead_camera(centre=(0.05, 0.0, 0.0), width=W_IMG, height=H_IMG, fov_deg=22.0)
    for gait in ("peristaltic", "omega", "inchworm"):
        r = run_gait(gaits.preset_params(gait), 1, 1.0, fps=15, save_worlds=1)
        F = r["frames"]["positions"].shape[0]
        rgb, images = T.render_band_video(r["frames"], r["model"], cam, W_IMG, H_IMG,
                                          sensor_values=T.harshest_sensor(F), seed=7, return_images=True)
        cams = make_cameras(cam.K, np.broadcast_to(cam.R, (F, 3, 3)), np.broadcast_to(cam.t, (F, 3)), np.arange(F),
                            W_IMG, H_IMG)
        out[gait] = (rgb, band_labels(images, cams), cam, r["model"].params)
    return out


@pytest.mark.parametrize("gait", ["peristaltic", "omega", "inchworm"])
def test_track_matches_the_render_labels(gait_videos, gait):
    rgb, lab, cam, params = gait_videos[gait]
    h = T.default_band_height(params)
    tr = T.track(rgb, cam, height=h, fps=15)
    assert tr["seen"].all() and tr["ref"] == 0
    err = np.linalg.norm(tr["pixel"] - lab["bands/pixel"], axis=-1)
    assert err.max() <= 1.0, err.max(axis=0)
    # the same plane through the labels' exact pixel centroids
    r_lab, d_lab = T.ratios_and_displacement(T.back_project(lab["bands/pixel"], cam, h))
    assert np.abs(tr["ratios"] - r_lab).max() <= 0.01
    assert np.abs(tr["displacement"] - d_lab).max() <= 5e-4
    # the worm moved and deformed (the check is not of a still picture)
    assert np.abs(r_lab - 1).max() > 0.05 and np.abs(d_lab).max() > 5e-3
    if gait == "inchworm":  # its sheet stays on the floor: the plane is the truth in 3-D too
        r3, d3 = T.ratios_and_displacement(lab["bands/world"])
        assert np.abs(tr["ratios"] - r3).max() <= 0.01
        assert np.abs(tr["displacement"] - d3).max() <= 5e-4


def test_back_projection_inverts_opencv_projection_with_distortion():
    cam = T.overhead_camera(width=640, height=480, fov_deg=30.0, tilt_deg=25.0)
    cam.dist = np.array([-0.12, 0.03, 0.001, -0.0015, 0.0])
    cam.floor_incline = 0.1
    rng = np.random.default_rng(0)
    h = 0.006
    n = np.array([-np.sin(0.1), 0.0, np.cos(0.1)])
    u_ax = np.array([np.cos(0.1), 0.0, np.sin(0.1)])
    pts = (0.045 + rng.uniform(-0.04, 0.04, (50, 1))) * u_ax + rng.uniform(-0.02, 0.02, (50, 1)) * [0, 1, 0] + h * n
    uv, _ = cv2.projectPoints(pts, cv2.Rodrigues(cam.R)[0], cam.t, cam.K, cam.dist)
    back = T.back_project(uv.reshape(-1, 2), cam, h)
    assert np.abs(back - pts).max() < 1e-6


def test_unseen_band_is_marked_and_csv_round_trips(gait_videos, tmp_path):
    rgb, lab, cam, params = gait_videos["inchworm"]
    rgb = rgb[:6].copy()
    m = T.band_masks(rgb[3], T.Thresholds.from_colors())[2]
    rgb[3][m] = 0  # the white band hidden in frame 3
    tr = T.track(rgb, cam, height=T.default_band_height(params), fps=15)
    assert tr["seen"][3].tolist() == [True, True, False, True, True] and tr["seen"][[0, 1, 2, 4, 5]].all()
    assert np.isnan(tr["ratios"][3, 1:3]).all() and np.isfinite(tr["ratios"][3, [0, 3]]).all()
    assert np.isnan(tr["displacement"][3]) and np.isfinite(tr["displacement"][[2, 4]]).all()
    T.write_csv(tmp_path / "t.csv", tr)
    back = T.read_csv(tmp_path / "t.csv")
    np.testing.assert_array_equal(back["seen"], tr["seen"])
    np.testing.assert_allclose(back["ratios"], tr["ratios"], equal_nan=True, rtol=0, atol=0)
    np.testing.assert_allclose(back["displacement"], tr["displacement"], equal_nan=True, rtol=0, atol=0)


def test_track_command_writes_csv_and_refuses_bad_input(gait_videos, tmp_path, capsys):
    from warpworm.cli import main

    rgb, _, cam, _ = gait_videos["peristaltic"]
    folder = tmp_path / "frames"
    folder.mkdir()
    for i, im in enumerate(rgb[:5]):
        cv2.imwrite(str(folder / f"f{i:03d}.png"), im[..., ::-1])
    cam.save(tmp_path / "camera.json")
    out = tmp_path / "track.csv"
    assert main(["track", str(folder), "--camera", str(tmp_path / "camera.json"), "--out", str(out), "--fps", "15",
                 "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == 5 and summary["frames_all_bands"] == 5
    expect = T.track(list(rgb[:5]), cam, height=T.default_band_height(), fps=15)
    np.testing.assert_allclose(T.read_csv(out)["ratios"], expect["ratios"], rtol=0, atol=0)
    # refused before any work, nothing written
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"K": np.eye(3).tolist(), "R": np.eye(3).tolist()}))
    for argv in (["--camera", str(bad)], ["--camera", str(tmp_path / "camera.json"), "--threshold", "hue=3"],
                 ["--camera", str(tmp_path / "camera.json"), "--band-colors", "1,0,0"],
                 ["--camera", str(tmp_path / "camera.json"), "--band-colors-from", str(tmp_path / "no_dataset")],
                 ["--camera", str(tmp_path / "camera.json"), "--band-colors-from", str(tmp_path),
                  "--band-colors", "0,0,1;1,0,1;1,1,1;0,1,0;1,0,0"],
                 ["--camera", str(tmp_path / "camera.json"), "--fps", "0"]):
        o = tmp_path / "no.csv"
        assert main(["track", str(folder), "--out", str(o)] + argv) == 2
        assert not o.exists()
        assert capsys.readouterr().err.startswith("error: ")


def test_bands_texture_in_dataset_configs():
    from warpworm.data import sampling
    from warpworm.data.config import ConfigError, load_config
    from warpworm.render.scene import BAND_COLORS

    cfg = load_config("default", ["randomize.texture.worm=bands"])
    a = sampling.sample_appearance(cfg, np.arange(3))
    np.testing.assert_allclose(a.albedo[:, 2:7], np.broadcast_to(BAND_COLORS ** 2, (3, 5, 3)))
    assert (a.paper_tex == 0).all()
    with pytest.raises(ConfigError, match="texture.worm"):
        load_config("default", ["randomize.texture.worm=stripes"])


def test_harshest_sensor_is_the_randomization_ranges_upper_end():
    from warpworm.data.config import load_config

    v = T.harshest_sensor(2)  # PARAM_SPECS' ranges: noise [0, 4], blur [0, 0.8], brightness ±12, contrast 1.15
    np.testing.assert_allclose(v["noise_sigma"], 4 / 255)
    np.testing.assert_allclose(v["blur_sigma"], 0.8)
    np.testing.assert_allclose(v["brightness"], 12 / 255, rtol=1e-6)
    np.testing.assert_allclose(v["contrast"], 1.15, rtol=1e-6)
    assert (v["jpeg_quality"] == 0).all()  # JPEG off
    d = T.harshest_sensor(1, load_config("default").randomize["sensor"])  # default.yaml: noise [0, 3]
    np.testing.assert_allclose(d["noise_sigma"], 3 / 255)


def _two_band_scene(seed, S=8, H=96, W=128):
    """A green band (a triangle, two faces: one at 55 % of the light) and a red one (a rectangle, its lower face at
    40 %) on a dark floor, drawn at S x S sub-pixels per pixel, each pixel the mean of its sub-pixels' display
    values (the area it covers), then the harshest sensor's blur (0.8 px) and noise (3 levels). The independent
    truth: the centroid of each band's covered area, from the sub-pixels."""
    from warpworm.render.scene import BAND_COLORS

    yy, xx = (np.mgrid[:H * S, :W * S] + 0.5) / S - 0.5

    def side(p, q):
        return (xx - q[0]) * (p[1] - q[1]) - (p[0] - q[0]) * (yy - q[1])

    a, b, c = (30.3, 20.7), (62.6, 48.2), (28.1, 70.4)
    d1, d2, d3 = side(a, b), side(b, c), side(c, a)
    green = ~(((d1 < 0) | (d2 < 0) | (d3 < 0)) & ((d1 > 0) | (d2 > 0) | (d3 > 0)))
    red = (xx >= 62.2) & (xx <= 95.7) & (yy >= 25.4) & (yy <= 70.9) & ~green
    light = np.ones(yy.shape)
    light[red & (yy > 0.35 * (xx - 62.0) + 40.3)] = 0.4
    light[green & (xx > 40)] = 0.55
    col = np.full(yy.shape + (3,), 0.09)
    col[green], col[red] = BAND_COLORS[3], BAND_COLORS[4]
    disp = ((col ** 2.2) * light[..., None]) ** (1 / 2.2)
    img = cv2.GaussianBlur((disp.reshape(H, S, W, S, 3).mean(axis=(1, 3)) * 255).astype(np.float32), (0, 0), 0.8)
    img = np.clip(np.round(img + np.random.default_rng(seed).normal(0, 3, img.shape)), 0, 255).astype(np.uint8)
    return img, np.array([[xx[m].mean(), yy[m].mean()] for m in (green, red)])


def test_soft_weights_find_the_covered_area_centroid():
    """Boundary unmixing (T.band_weights, the default): each band's centre within 0.25 px of the centroid of the
    area it covers (measured 0.04-0.18 px over 4 noise draws), where the hard masks, gaining or losing whole pixels
    at every blurred edge and more at a shaded face's, are off by 0.09-0.54 px (mean 0.31)."""
    soft, hard = [], []
    for seed in range(4):
        img, truth = _two_band_scene(seed)
        soft.append(np.linalg.norm(T.band_centroids(img, T.Thresholds.from_colors())[0][3:] - truth, axis=-1))
        hard.append(np.linalg.norm(T.band_centroids(img, T.Thresholds.from_colors(soft=0))[0][3:] - truth, axis=-1))
    soft, hard = np.array(soft), np.array(hard)
    assert soft.max() <= 0.25 and soft.mean() <= 0.15, soft
    assert hard.mean() > 0.25, hard  # the test can tell the two apart
    # the weights are fractions, and a pixel's weights never sum above 1
    img, _ = _two_band_scene(0)
    w = T.band_weights(img, T.band_masks(img, T.Thresholds.from_colors()))
    assert w.min() >= 0 and w.sum(axis=0).max() <= 1 + 1e-6
