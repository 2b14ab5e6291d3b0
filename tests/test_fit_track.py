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


def _planted_video(d, magnet_model):
    """Simulate one peristaltic cycle at the planted EPM moment under magnet_model, render it with the bands and the
    harshest sensor draws, and write frames/*.png and camera.json under d; returns the preset's params."""
    from warpworm import quiet_warp
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

    quiet_warp()
    base = gaits.preset_params("peristaltic", magnet_model=magnet_model)
    planted = FT.candidate_params(base, ["epm_moment"], np.array([[PLANT * base.epm_moment]]))
    r = run_gait(planted, 1, 1.0, fps=FPS, save_worlds=1)
    t = np.asarray(r["frames"]["time"])
    on_grid = np.abs(t * FPS - np.round(t * FPS)) < 1e-6  # run_gait also records the last step
    r["frames"] = {k: v[on_grid] for k, v in r["frames"].items()}
    F = int(on_grid.sum())
    np.testing.assert_allclose(r["frames"]["time"], np.arange(F) / FPS, atol=1e-9)
    cam = T.overhead_camera(centre=(0.05, 0.0, 0.0), width=640, height=480, fov_deg=22.0)
    sensor = T.harshest_sensor(F)  # the randomization's harshest sensor draws, no JPEG
    rgb = T.render_band_video(r["frames"], r["model"], cam, 640, 480, sensor_values=sensor, seed=3)
    (d / "frames").mkdir()
    for i, im in enumerate(rgb):
        cv2.imwrite(str(d / "frames" / f"{i:03d}.png"), im[..., ::-1])
    cam.save(d / "camera.json")
    return base


@pytest.fixture(scope="module")
def planted_video(tmp_path_factory):
    d = tmp_path_factory.mktemp("planted")
    return d, _planted_video(d, "analytic")


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
    # the planted moment lies inside the acceptable range, which stays within the verdict band's outer edge (3 % x
    # 1.25; measured -2.7 .. +3.1 % with the brightness-independent tracker, -0.75 .. +1.35 % with the first one)
    lo, hi = s["range_rel"][0]
    assert lo <= PLANT * base.epm_moment / epm - 1 <= hi and max(-lo, hi) < 0.03 * (1 + FT.VERDICT_MARGIN), \
        s["range_rel"]
    # (its range, ~2.5 % wide, lies inside the verdict's margin band of 3 % / 1.25 .. 3 % x 1.25: borderline or
    # pinned, never not pinned; FT.VERDICT_MARGIN)
    assert s["verdict"][0] in ("pinned", "borderline") and s["verdict"][1] == "not pinned"
    assert s["pinned"] == [s["verdict"][0] == "pinned", False] and s["tolerance"] == [0.03, 0.05]
    # dipole_density: acceptable over the whole search range (to a bound)
    assert s["at_bound"] == [False, True] and s["range_rel"][1][1] - s["range_rel"][1][0] > 0.3
    print(s["worlds"], s["wall_s"], s["range_rel"], s["moved"])
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


class _Residuals(FT._Batches):
    """FT._Batches over an analytic residual function r(x) (n,) instead of simulated worlds: the search, the
    global profile and the acceptable ranges checked against costs known in closed form, in milliseconds."""

    def __init__(self, fun, lim):
        self.fun, self.lim, self.seen = fun, lim, []

    def __call__(self, X):
        X = np.clip(np.asarray(X, np.float64), -self.lim, self.lim)
        r = np.array([self.fun(x) for x in X])
        cost = np.mean(r ** 2, axis=1)
        self.seen.append((X, cost))
        return cost, r, {"x": X}


def _vectors(n=60, seed=0):
    rng = np.random.default_rng(seed)
    u, v, w, noise = rng.standard_normal((4, n))
    return u, v, w, 0.3 * noise


def test_global_profile_reports_a_traded_pair_not_identifiable_and_keeps_a_pinned_one():
    """r = 30 u (d0 + d1) + 0.5 v d1 + 40 w d2 + noise (d = x - truth): x0 and x1 trade against each other along a
    valley where the chi-square rises only as 60 * 0.25 * d1^2 (acceptable to |d1| ~ 0.5 >> 5 %), x2 is pinned to
    well under its 3 % tolerance."""
    u, v, w, noise = _vectors()
    truth = np.array([0.1, -0.1, 0.05])
    lim = np.log(3.0)

    def fun(x):
        d = x - truth
        return 30 * u * (d[0] + d[1]) + 0.5 * v * d[1] + 40 * w * d[2] + noise

    ev = _Residuals(fun, lim)
    out = FT.fit_batches(ev, ["hinge_stiffness", "valley_bar_stiffness", "epm_moment"], lim=lim, budget=48, pop=8,
                         refine=4, profile=2)
    assert out["pinned"].tolist() == [False, False, True]
    half = np.maximum(-out["lo"], out["hi"])
    assert half[0] > 0.3 and half[1] > 0.3 and half[2] < np.log1p(0.03)
    # x1's range in closed form: its profile re-fits x0 and x2, so the chi-square rises as |P a1|^2 d1^2 with a1 =
    # dr/dx1 and P the projection off dr/dx0 and dr/dx2; acceptable to sqrt(3.84 / |P a1|^2) on both sides. The
    # profile's points are exact conditional minima here (a linear model), so the interpolated crossing is exact.
    others = np.stack([30 * u, 40 * w], 1)
    a1 = 30 * u + 0.5 * v
    pa1 = a1 - others @ np.linalg.lstsq(others, a1, rcond=None)[0]
    cross = np.sqrt(FT.ACCEPT_DCHI2 / np.sum(pa1 ** 2))
    # (the fit may sit off the flat valley's exact minimum: the interval's width and where it lies are checked)
    xmin = truth + np.linalg.lstsq(np.stack([30 * u, a1, 40 * w], 1), -noise, rcond=None)[0]
    x = out["st"]["x"]
    np.testing.assert_allclose(out["hi"][1] - out["lo"][1], 2 * cross, rtol=0.02)
    np.testing.assert_allclose(x[1] + (out["hi"][1] + out["lo"][1]) / 2, xmin[1], atol=0.02 * cross)
    c2 = np.sqrt(FT.ACCEPT_DCHI2 / np.sum((40 * w - np.stack([30 * u, a1], 1) @ np.linalg.lstsq(
        np.stack([30 * u, a1], 1), 40 * w, rcond=None)[0]) ** 2))
    np.testing.assert_allclose(out["hi"][2] - out["lo"][2], 2 * c2, rtol=0.02)  # x2: the same from its grid
    assert abs(x[2] - truth[2]) < 0.01 and x[2] + out["lo"][2] <= truth[2] <= x[2] + out["hi"][2]


def test_global_profile_moves_a_fit_out_of_a_side_valley():
    """r = 10 u (x0 - 0.3)(x0 + 0.4) + 0.5 v (x0 - 0.3) + 40 w x1 + noise: a side valley at x0 = -0.4 (a
    chi-square above the true one by 60 * 0.25 * 0.7^2 ~ 7 > 3.84); a fit started there is moved by the profile to
    x0 = 0.3, and the side valley is not in the acceptable range."""
    u, v, w, noise = _vectors(seed=1)
    lim = np.log(3.0)

    def fun(x):
        return 10 * u * (x[0] - 0.3) * (x[0] + 0.4) + 0.5 * v * (x[0] - 0.3) + 40 * w * x[1] + noise

    ev = _Residuals(fun, lim)
    out = FT.fit_batches(ev, ["mu_static", "epm_moment"], lim=lim, budget=0, pop=8, refine=4, profile=2,
                         start=np.array([-0.4, 0.0]))
    assert out["moved"]
    x = out["st"]["x"]
    assert abs(x[0] - 0.3) < 0.02 and abs(x[1]) < 0.005
    # x0's range is 0.91 of its tolerance: inside it, but within the verdict's margin (FT.VERDICT_MARGIN)
    assert out["verdict"].tolist() == ["borderline", "pinned"]
    assert 0.8 < max(-out["lo"][0], out["hi"][0]) / np.log1p(0.05) < 1.0
    assert x[0] + out["lo"][0] > -0.3


def test_verdicts_have_a_margin_band():
    """pinned below tol / 1.25, not pinned above tol x 1.25 or at a bound, borderline between; a range that moves by
    a few per cent (re-rendering noise) can move a verdict only into or out of the band."""
    tol = np.array([0.05, 0.05, 0.05, 0.05, 0.03])
    t = np.log1p(tol)
    lo = -np.array([0.5, 0.9, 1.1, 1.4, 0.1]) * t
    hi = np.array([0.7, 0.3, 0.2, 0.1, 0.1]) * t
    got = FT.verdicts(lo, hi, np.array([False, False, False, False, True]), tol)
    assert got.tolist() == ["pinned", "borderline", "borderline", "not pinned", "not pinned"]
    # a 3 % change of every range never turns pinned into not pinned or back
    rng = np.random.default_rng(0)
    w = np.exp(rng.uniform(np.log(0.3), np.log(3.0), 2000)) * t[0]
    a = FT.verdicts(-w, w, np.zeros(2000, bool), np.full(2000, 0.05))
    b = FT.verdicts(-1.03 * w, 1.03 * w, np.zeros(2000, bool), np.full(2000, 0.05))
    assert not np.any((a == "pinned") & (b == "not pinned")) and not np.any((a == "not pinned") & (b == "pinned"))
    assert np.any(a != b)  # (some moved into or out of the band)


def test_fit_track_absorbs_the_dipole_model_error_into_the_analytic_moment(tmp_path, capsys):
    """Issue 26 item 4, second test: a track of the paper's dipole-aggregate magnets (64 per cm^3) fitted with the
    exact analytic model. At peristalsis's gaps (>= 5 mm) the two models' fields agree to < 0.1 % (docs/magnets.md,
    magpylib), so the moment the fit absorbs must stay within the EPM's 3 % tolerance and the analytic model must
    explain the dipole track to the tracker's accuracy; the absorbed offset is printed."""
    from warpworm.cli import main

    base = _planted_video(tmp_path, "dipoles")
    assert main(["track", str(tmp_path / "frames"), "--camera", str(tmp_path / "camera.json"), "--out",
                 str(tmp_path / "track.csv"), "--fps", str(FPS), "--json"]) == 0
    capsys.readouterr()
    assert main(["fit-track", str(tmp_path / "track.csv"), "--gait", "peristaltic", "--magnet-model", "analytic",
                 "--fit", "epm_moment", "--budget", "16", "--popsize", "8", "--spread", "1.25", "--profile", "1",
                 "--out", str(tmp_path / "fit"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    absorbed = s["value"][0] / (PLANT * base.epm_moment) - 1
    print(f"dipole track, analytic fit: EPM moment absorbs {absorbed:+.2%}, range {s['range_rel'][0]}")
    assert abs(absorbed) < 0.03, absorbed
    assert s["rms_ratio"] < 0.01 and s["rms_displacement_m"] < 5e-4, (s["rms_ratio"], s["rms_displacement_m"])


def test_two_take_verdict_rejects_takes_that_disagree():
    """benchmarks/calibrate_many.combined_verdict: two takes both "pinned" whose acceptable ranges share no value
    (one fit in a side valley: measured, worm 10 fitted -18.5 % and +1.8 % from two renders) are not pinned; takes
    that agree keep the single-take rule (pinned only if both say so)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from calibrate_many import combined_verdict

    assert combined_verdict(["pinned", "pinned"], [(0.80, 0.82), (1.01, 1.03)]) == "not pinned"
    assert combined_verdict(["pinned", "pinned"], [(0.98, 1.02), (1.01, 1.03)]) == "pinned"
    assert combined_verdict(["pinned", "borderline"], [(0.98, 1.02), (1.01, 1.03)]) == "borderline"
    assert combined_verdict(["not pinned", "not pinned"]) == "not pinned"
