"""Planning clips before filming (warpworm.analysis.plan, ``warpworm plan-clips``) and the joint fit of several clips
(warpworm.analysis.fit_track): the predicted half-widths against the closed form, the greedy choice against a brute
force over clip pairs, a parameter without effect reported unpinnable by a real batch, and the joint residuals
against each clip evaluated alone."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from warpworm.analysis import fit_track as FT
from warpworm.analysis import plan as P


def test_half_widths_are_the_closed_form():
    # two parameters, F = diag(a, b) + c (off-diagonal): (F^-1)_00 = b / (ab - c^2)
    a, b, c = 400.0, 900.0, 300.0
    F = np.array([[a, c], [c, b]])
    hw = P.half_widths(F[None])[0]
    np.testing.assert_allclose(hw, np.sqrt(3.84 * np.array([b, a]) / (a * b - c * c)), rtol=1e-12)
    assert np.isinf(P.half_widths(np.zeros((1, 2, 2)))).all()  # no information: unpinnable


def test_greedy_plan_matches_brute_force_on_complementary_clips():
    """Clips that each pin one direction well: the pair the greedy plan picks is the best pair by brute force, and
    no single clip pins both parameters (the trade-off the issue saw: k_alpha and the EPM moment along a valley)."""
    rng = np.random.default_rng(0)
    C, D, p = 12, 3, 2
    F = np.zeros((C, D, p, p))
    for c in range(C):
        ang = rng.uniform(0, np.pi)
        u = np.array([np.cos(ang), np.sin(ang)])
        for d in range(D):
            s = rng.uniform(0.8, 1.2)
            F[c, d] = s * (4e5 * np.outer(u, u) + 50 * np.eye(p))  # one well-measured direction per clip
    tol = np.array([0.05, 0.03])
    ok = np.ones((C, D), bool)
    chosen, worst = P.greedy_plan(F, ok, tol, max_clips=2, margin=1e-9)
    single = [np.max(P.half_widths(F[c]) / np.log1p(tol)) for c in range(C)]
    assert min(single) > 1  # no single clip pins both
    pairs = {(i, j): np.max(P.half_widths(F[i] + F[j]) / np.log1p(tol)) for i, j in itertools.combinations(range(C), 2)}
    best = min(pairs.values())
    assert worst[-1] <= 1.05 * best and worst[-1] < 1  # the greedy pair pins both, nearly as well as the best pair
    # an unstable clip is never chosen
    ok[chosen[0], 1] = False
    assert chosen[0] not in P.greedy_plan(F, ok, tol, max_clips=2)[0]


def test_design_worms_span_the_ranges():
    w = P.design_worms({"hinge_stiffness": (0.003, 0.01), "epm_moment": (3.0, 4.0)}, corner_frac=0.8)
    assert w.shape == (5, 2)
    np.testing.assert_allclose(w[0], [np.sqrt(0.003 * 0.01), np.sqrt(12.0)])
    assert np.all(w >= [0.003, 3.0]) and np.all(w <= [0.01, 4.0])
    assert len(np.unique(np.round(w[1:], 9), axis=0)) == 4


def test_a_real_batch_finds_the_moment_and_not_an_ineffective_parameter():
    """One omega clip at one design worm (7 worlds, 1 cycle): under the analytic magnet model the dipole density has
    no effect, so its information is zero and its half-width infinite; the EPM moment's is finite."""
    from warpworm import quiet_warp

    quiet_warp()
    clips = P.candidate_paths(gaits=("omega",), w_scales=(1.0,), a_scales=(1.0,), h_scales=(1.0,), cycles=(1.0,))
    res = P.plan(["epm_moment", "dipole_density"], {"epm_moment": (3.0, 4.0), "dipole_density": (8e6, 64e6)},
                 clips=clips, corner_frac=0.0)
    assert res["ok"].all()
    F = res["fisher"][0, 0]
    assert F[1, 1] < 1e-9 * F[0, 0] and F[0, 0] > 100
    hw = np.sqrt(3.84 / F[0, 0])  # the moment alone
    assert hw < 0.2


def test_joint_residuals_are_each_clip_alone_joined():
    """fit_track's joint evaluation of two clips (omega and inchworm, different paths) equals each clip evaluated on
    its own, joined: the same worlds, the same residuals, in order."""
    from warpworm import quiet_warp
    from warpworm.physics import gaits

    quiet_warp()
    names = ["hinge_stiffness", "epm_moment"]
    bases = [gaits.preset_params("omega", magnet_model="analytic"),
             gaits.preset_params("inchworm", magnet_model="analytic", wavelength=0.015)]
    times = np.arange(4) / 12.5
    tracks = []
    for b in bases:  # a measured track: the preset's own simulation, seen from above
        o = FT.observe(b, 1, times, 0, None)
        tracks.append({"time": times, "ratios": o["ratios"][0] + 0.003, "displacement": o["displacement"][0],
                       "ref": 0})
    theta0 = np.array([float(getattr(bases[0], n)) for n in names])
    X = np.array([[0.0, 0.0], [0.1, -0.05], [-0.2, 0.1]])
    cost, res, obs = FT._evaluate(bases, names, theta0, X, tracks, None, [None, None])
    alone = [FT._evaluate(b, names, theta0, X, t, 0, None)[1] for b, t in zip(bases, tracks)]
    np.testing.assert_allclose(res, np.concatenate(alone, axis=1), rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(cost, np.mean(res ** 2, axis=1))
    assert "ratios@1" in obs and obs["ratios"].shape == (3, 4, 4)
    assert np.abs(alone[0] - alone[1][:, :alone[0].shape[1]]).max() > 0.1  # the clips differ


def test_fit_track_and_plan_clips_refuse_bad_input(tmp_path, capsys):
    from warpworm.cli import main

    t = tmp_path / "t.csv"
    from warpworm.analysis.track import CSV_COLUMNS

    t.write_text(",".join(CSV_COLUMNS) + "\n")
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps({"clips": [{"gait": "omega", "backward": False, "wavelength": 0.016,
                                           "amplitude": 0.03, "closest_approach": 0.025, "cycles": 1.0}] * 2}))
    assert main(["fit-track", str(t), "--plan", str(plan)]) == 2
    assert "2 clips for 1 tracks" in capsys.readouterr().err
    assert main(["fit-track", str(t), str(t), "--gait", "omega,inchworm,omega"]) == 2
    assert "one for all tracks or one per track" in capsys.readouterr().err
    assert main(["plan-clips", "--range", "hinge_stiffness=0.01:0.003"]) == 2
    assert "LO:HI" in capsys.readouterr().err
    assert main(["plan-clips", "--fit", "hinge_stiffness,bar_stiffness"]) == 2
    assert "bar_stiffness" in capsys.readouterr().err


def test_roughness_tells_a_jump_from_a_smooth_response():
    """A smooth track (z = a x + 0.5 c x^2 at x = 0, ±0.05) is nearly linear; one with a stick-slip jump between 0
    and +0.05 is refused by the planner's default cut (0.5)."""
    t = np.linspace(0, 1, 40)
    a, c = np.sin(7 * t), np.cos(3 * t)
    z = lambda x: a * x + 0.5 * c * x * x  # noqa: E731
    smooth = P.roughness(z(0.0), z(0.05)[None], z(-0.05)[None])[0]
    assert smooth < 0.1
    jump = z(0.05) + 0.3 * (t > 0.5)  # a slide that happens only at the perturbed value
    assert P.roughness(z(0.0), jump[None], z(-0.05)[None])[0] > 0.5


def test_fit_track_cli_fits_two_clips_jointly(tmp_path, capsys):
    """Two clips of one worm (omega and inchworm, the moment at 1.05 x the preset), rendered, tracked and fitted by
    the CLI from a plan.json: the joint fit runs, reports both clips and finds the moment within 3 %."""
    from warpworm import quiet_warp
    from warpworm.analysis import track as T
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.cli import main
    from warpworm.physics import gaits

    quiet_warp()
    clips = [{"gait": "omega", "backward": False, "wavelength": 0.016, "amplitude": 0.03, "closest_approach": 0.025,
              "cycles": 0.5},
             {"gait": "inchworm", "backward": False, "wavelength": 0.02, "amplitude": 0.06,
              "closest_approach": 0.0055, "cycles": 0.5}]
    (tmp_path / "plan.json").write_text(json.dumps({"clips": clips}))
    tracks = []
    for k, c in enumerate(clips):
        base = gaits.preset_params(c["gait"], magnet_model="analytic")
        r = run_gait(FT.candidate_params(base, ["epm_moment"], np.array([[1.05 * base.epm_moment]])), 1, 0.5,
                     fps=12.5, save_worlds=1)
        cam = T.overhead_camera(centre=(0.045, 0.0, 0.0), width=320, height=240, fov_deg=26.0)
        rgb = T.render_band_video(r["frames"], r["model"], cam, 320, 240)
        h = T.default_band_height(base)
        tr = T.track(rgb, cam, height=h, fps=12.5)
        T.write_csv(tmp_path / f"t{k}.csv", tr)
        T.write_meta(tmp_path / f"t{k}.json", cam, 320, 240, h, 12.5, tr["ref"])
        tracks.append(str(tmp_path / f"t{k}.csv"))
    assert main(["fit-track", *tracks, "--plan", str(tmp_path / "plan.json"), "--fit", "epm_moment,mu_static",
                 "--magnet-model", "analytic", "--budget", "8", "--popsize", "4", "--spread", "1.2", "--refine", "2",
                 "--profile", "0", "--out", str(tmp_path / "fit"), "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["clips"] == 2
    assert abs(s["value"][0] / (1.05 * 3.6) - 1) < 0.03, s["value"]


def test_least_pinned_direction_is_the_valley():
    """A Fisher matrix built from a known valley (a k_alpha / moment trade-off direction with little information,
    two well-measured directions across it): least_pinned returns that direction and sqrt(3.84 / its
    information) as the half-width along it."""
    u = np.array([0.8, 0.0, 0.5])
    u /= np.linalg.norm(u)
    a = np.array([0.0, 1.0, 0.0])
    b = np.cross(u, a)
    F = 25.0 * np.outer(u, u) + 4e4 * np.outer(a, a) + 9e3 * np.outer(b, b)
    v, hw = P.least_pinned(F)
    np.testing.assert_allclose(v, u, atol=1e-9)
    assert abs(hw - np.sqrt(3.84 / 25.0)) < 1e-9


def test_plan_clips_saves_the_fisher_matrices(tmp_path, capsys):
    """``plan-clips --fisher-out``: one omega clip, the moment alone (3 design worms x 3 worlds): the saved Fisher
    matrices give the plan's predicted half-width, and the report names the plan's least pinned direction."""
    from warpworm import quiet_warp
    from warpworm.cli import main

    quiet_warp()
    out, npz = tmp_path / "plan.json", tmp_path / "fisher.npz"
    assert main(["plan-clips", "--fit", "epm_moment", "--range", "epm_moment=3:4", "--gaits", "omega",
                 "--w-scales", "1", "--a-scales", "1", "--h-scales", "1", "--cycles", "1", "--max-clips", "1",
                 "--out", str(out), "--fisher-out", str(npz)]) == 0
    assert "least pinned direction of the plan" in capsys.readouterr().out
    z = np.load(npz)
    assert z["fisher"].shape == (1, 3, 1, 1) and list(z["names"]) == ["epm_moment"]
    plan = json.loads(out.read_text())
    hw = np.expm1(np.sqrt(3.84 / z["fisher"][0, :, 0, 0])).max()
    assert abs(plan["predicted_half_width_rel"][0] - hw) < 1e-9 * max(1.0, hw)
