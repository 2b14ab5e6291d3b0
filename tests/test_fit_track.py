"""The calibration loop from images alone (warpworm.analysis.fit_track, ``warpworm track`` -> ``warpworm fit-track``):
a gait simulated at a planted EPM moment, rendered with the bands and sensor noise, tracked, fitted back through the
track's camera; a parameter without effect on the track is reported as not identifiable. Kept small (one cycle, 8
worlds a generation); the full-size recovery of four parameters is benchmarks/calibrate_track.py."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from warpworm.analysis import fit_track as FT
from warpworm.analysis import track as T

FPS = 12.5  # 20 solver steps of 4 ms between frames: the video's frame times are the simulation's
PLANT = 1.08  # planted EPM moment over the preset's


@pytest.fixture(scope="module")
def planted_video(tmp_path_factory):
    from warpworm import quiet_warp
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

    quiet_warp()
    base = gaits.preset_params("peristaltic", magnet_model="analytic")
    planted = FT.candidate_params(base, ["epm_moment"], np.array([[PLANT * base.epm_moment]]))
    r = run_gait(planted, 1, 1.0, fps=FPS, save_worlds=1)
    t = np.asarray(r["frames"]["time"])
    on_grid = np.abs(t * FPS - np.round(t * FPS)) < 1e-6  # run_gait also records the last step
    r["frames"] = {k: v[on_grid] for k, v in r["frames"].items()}
    F = int(on_grid.sum())
    np.testing.assert_allclose(r["frames"]["time"], np.arange(F) / FPS, atol=1e-9)
    cam = T.overhead_camera(centre=(0.05, 0.0, 0.0), width=640, height=480, fov_deg=22.0)
    sensor = {"wb_r": np.ones(F), "wb_g": np.ones(F), "wb_b": np.ones(F), "hue_deg": np.zeros(F),
              "saturation": np.ones(F), "contrast": np.full(F, 1.15, np.float32),
              "brightness": np.full(F, 12 / 255, np.float32), "blur_sigma": np.full(F, 0.8),
              "noise_sigma": np.full(F, 4 / 255), "shot_noise": np.zeros(F), "jpeg_quality": np.zeros(F, np.int64)}
    rgb = T.render_band_video(r["frames"], r["model"], cam, 640, 480, sensor_values=sensor, seed=3)
    d = tmp_path_factory.mktemp("planted")
    (d / "frames").mkdir()
    for i, im in enumerate(rgb):
        cv2.imwrite(str(d / "frames" / f"{i:03d}.png"), im[..., ::-1])
    cam.save(d / "camera.json")
    return d, base


def test_fit_track_recovers_the_planted_epm_moment_from_images(planted_video, capsys):
    from warpworm.cli import main

    d, base = planted_video
    assert main(["track", str(d / "frames"), "--camera", str(d / "camera.json"), "--out", str(d / "track.csv"),
                 "--fps", str(FPS), "--json"]) == 0
    capsys.readouterr()
    assert (d / "track.json").is_file()
    # dipole_density has no effect under the analytic magnet model: the fit must say the track cannot pin it
    assert main(["fit-track", str(d / "track.csv"), "--gait", "peristaltic", "--magnet-model", "analytic",
                 "--fit", "epm_moment,dipole_density", "--budget", "16", "--popsize", "8", "--spread", "1.25", "--profile", "1",
                 "--out", str(d / "fit"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    epm = s["value"][0]
    assert abs(epm / (PLANT * base.epm_moment) - 1) < 0.03, (epm, PLANT * base.epm_moment)
    assert s["pinned"] == [True, False] and s["sigma_rel"][0] < 0.03
    assert s["sigma_rel"][1] is None or s["sigma_rel"][1] > 1.0
    # search, stencil and 4 refine steps, one profile step, the scan (and a stencil if the profile moved the fit)
    assert s["worlds"] == 16 + 5 * 5 + 2 * 2 * 3 + 8 + 5 * s["profile_moved"]
    assert s["rms_ratio"] < 0.01 and s["rms_displacement_m"] < 5e-4
    text = (d / "fit" / "fit.yaml").read_text()
    assert "epm_moment:" in text and "--set epm_moment=" in text
    # the fragment is a config fragment that load_config accepts
    import yaml

    from warpworm.data.config import load_config

    frag = yaml.safe_load(text)
    cfg = load_config("default", [f"randomize.worm.{k}={v}" for k, v in frag["randomize"]["worm"].items()
                                  if k not in ("gait", "backward")])
    assert cfg.randomize["worm"]["epm_moment"].to_yaml() == pytest.approx(frag["randomize"]["worm"]["epm_moment"])
    assert (d / "fit" / "fit.png").stat().st_size > 10_000


def test_fit_track_refuses_bad_input_before_any_work(planted_video, tmp_path, capsys):
    from warpworm.cli import main

    d, _ = planted_video
    csv = d / "track.csv"
    if not csv.exists():
        pytest.skip("needs the track of the test above")
    cases = [["--fit", "hinge_stiffness,nonsense"], ["--path", "w=0.02,q=1"], ["--path", "h=-1"],
             ["--set", "mu_static=-1"], ["--budget", "0"], ["--camera", str(d / "camera.json")]]
    for extra in cases:
        out = tmp_path / "o"
        assert main(["fit-track", str(csv), "--gait", "omega", "--out", str(out)] + extra) == 2, extra
        assert not out.exists()
        assert capsys.readouterr().err.startswith("error: ")
    assert main(["fit-track", str(tmp_path / "missing.csv"), "--gait", "omega", "--out", str(tmp_path / "o")]) == 2


def test_parse_helpers():
    assert FT.parse_path("w=0.024,a=0.045,h=0.005") == {"wavelength": 0.024, "amplitude": 0.045,
                                                         "closest_approach": 0.005}
    assert FT.parse_fit("mu_static, epm_moment") == ["mu_static", "epm_moment"]
    with pytest.raises(ValueError, match="--fit"):
        FT.parse_fit("mu_static,mu_static")
    p = FT.candidate_params(__import__("warpworm.physics.gaits", fromlist=["x"]).preset_params("omega"),
                            ["mu_static"], np.array([[0.134], [0.268]]))
    np.testing.assert_allclose(np.asarray(p.mu_kinetic) / np.asarray(p.mu_static), 0.24 / 0.268)
