"""Gait measures against trajectories built by hand, whose answers are known in closed form."""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.physics import crease
from warpworm.analysis.gait_metrics import fold_violation, gait_metrics, segment_ratios, wing_altitude_ratio
from warpworm.analysis.gait_search import grid_points, parse_grid


def _worm():
    return crease.build_worm(0.02, 0.008, 6, l0=0.08)


def test_segment_ratios_of_a_uniform_axial_stretch_equal_the_stretch():
    pat = _worm()
    x = pat.vertices
    s = np.array([1.0, 0.8, 1.2])
    frames = np.stack([x * [k, 1.0, 1.0] for k in s])[:, None]  # (F, 1, V, 3)
    np.testing.assert_allclose(segment_ratios(pat, frames)[:, 0], np.repeat(s[:, None], 4, 1), rtol=1e-12)


def test_fold_violation_is_the_distance_outside_the_range():
    lab = np.array([crease.MOUNTAIN, crease.MOUNTAIN, crease.VALLEY, crease.VALLEY, crease.FLAT])
    ang = np.array([-1.0, 0.2, 0.5, -0.3, 3.0])
    np.testing.assert_allclose(fold_violation(lab, ang), [0.0, 0.2, 0.0, 0.3, 0.0])


def test_wing_altitude_ratio_is_the_lower_wing_over_the_hinge_length():
    """A stencil with its hinge j–k 10 mm along x and wing tips 3 mm and √(2² + 1²) mm from the hinge line: 0.3
    and 0.2236 of the hinge length, the smaller reported; the same scale-free at 1 m, and for two frames at once."""
    x = np.array([[5.0, 3.0, 0.0], [0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [4.0, -2.0, 1.0]]) * 1e-3
    hinges = np.array([[0, 1, 2, 3], [3, 2, 1, 0]])
    np.testing.assert_allclose(wing_altitude_ratio(hinges, x), [np.sqrt(5.0) / 10.0] * 2, rtol=1e-12)
    both = wing_altitude_ratio(hinges, np.stack([x, x * 100.0]))
    np.testing.assert_allclose(both, np.full((2, 2), np.sqrt(5.0) / 10.0), rtol=1e-12)


def test_inchworm_like_trajectory_measures():
    """Two cycles of T = 1 s: in each, the head advances 10 mm while the tail holds (the worm stretches), then the
    tail catches up while the head holds (it contracts); nothing moves within 0.1 cycle of the far points."""
    pat = _worm()
    x0 = pat.vertices
    t = np.linspace(0.0, 2.0, 81)
    V = len(x0)
    frames = np.zeros((len(t), 1, V, 3))
    xa = x0[:, 0]
    for f, tt in enumerate(t):
        c, ph = divmod(tt, 1.0)
        c = min(c, 1.0) if tt < 2.0 else 2.0
        # front half squeezed then released; whole worm advanced by 10 mm per cycle, head first
        # the head moves over s in [0.1, 0.5] of each cycle, the tail over [0.5, 0.9]: still around the far points
        head_adv = 0.010 * (c + (np.clip((ph - 0.1) / 0.4, 0.0, 1.0) if tt < 2.0 else 0.0))
        tail_adv = 0.010 * (c + (np.clip((ph - 0.5) / 0.4, 0.0, 1.0) if tt < 2.0 else 0.0))
        u = xa / xa.max()
        shift = tail_adv + (head_adv - tail_adv) * u
        frames[f, 0] = np.stack([xa + shift, x0[:, 1], x0[:, 2]], -1)
    mag = np.zeros((len(t), 1, 4, 3))
    mag[:, 0, 2, 2] = 0.003 * np.sin(np.pi * t) ** 2
    # the IPMs ride on the worm (centre 40 mm, head 80 mm behind the advance); the EPM 16 mm ahead of the centre IPM
    # at the first closest approach (t = 0.5 s) and 30 mm ahead at the second (t = 1.5 s)
    mag[:, 0, 2, 0] = 0.040 + 0.010 * t
    mag[:, 0, 3, 0] = 0.080 + 0.010 * t
    mag[:, 0, 0, 0] = mag[:, 0, 2, 0] + np.interp(t, [0.5, 1.5], [0.016, 0.030])
    ang = np.zeros((len(t), 1, 2))
    ang[:, 0, 0] = -1.0 + 0.3 * np.sin(np.pi * t)
    ang[:, 0, 1] = 1.0
    m = gait_metrics(pat, np.array([crease.MOUNTAIN, crease.VALLEY]),
                     {"positions": frames, "magnet_pos": mag, "crease_angle": ang, "time": t}, 1.0)
    assert m["tail_displacement_m"][0] == pytest.approx(0.020, abs=1e-9)
    assert m["head_displacement_m"][0] == pytest.approx(0.020, abs=1e-9)
    np.testing.assert_allclose(m["cycle_displacement_m"][0], [0.010, 0.010], atol=1e-9)
    assert m["centre_ipm_max_lift_m"][0] == pytest.approx(0.003, abs=1e-9)
    assert m["crease_angle_range_deg"][0] == pytest.approx(np.degrees(0.6), rel=1e-9)
    assert m["max_fold_violation_deg"][0] == 0.0
    # the worm only stretches, uniformly, by up to 10 mm over its 80 mm
    np.testing.assert_allclose(m["deformation_ratio_min"][0], 1.0, rtol=1e-12)
    np.testing.assert_allclose(m["deformation_ratio_max"][0], 1.0 + 0.010 / xa.max(), rtol=1e-9)
    # the contraction phase of each cycle (longest -> shortest): the head held (0) while the tail moved
    np.testing.assert_allclose(m["end_hold_ratio"][0], [0.0, 0.0], atol=1e-9)
    # 16 and 30 mm ahead of the centre IPM over its 40 mm to the head IPM
    np.testing.assert_allclose(m["approach_placement"][0], [0.4, 0.75], atol=1e-9)
    # nothing moves at the far points (s = 1, 2)
    assert m["far_point_motion_m"][0] == pytest.approx(0.0, abs=1e-12)
    assert m["far_point_ratio_deviation"][0] == pytest.approx(0.0, abs=1e-12)  # relaxed at the far points
    assert m["length_ratio_min"][0] == pytest.approx(1.0, abs=1e-12)  # it never got shorter than at rest


def test_end_hold_of_a_slide_and_of_a_squeeze_from_both_ends():
    """World 0 slides rigidly 10 mm per cycle (never shorter: no contraction, NaN); world 1 is squeezed from both ends
    by 2 mm each at mid-cycle and released (both ends moved as much: 1). World 1 sits on a 0.1 rad incline: its lift
    is measured along the floor normal."""
    pat = _worm()
    x0 = pat.vertices
    t = np.linspace(0.0, 2.0, 41)
    xa = x0[:, 0]
    u = xa / xa.max()
    frames = np.zeros((len(t), 2, len(x0), 3))
    for f, tt in enumerate(t):
        frames[f, 0] = x0 + [0.010 * tt, 0.0, 0.0]
        squeeze = 0.002 * np.sin(np.pi * (tt % 1.0))
        frames[f, 1] = np.stack([xa + squeeze * (1.0 - 2.0 * u), x0[:, 1], x0[:, 2]], -1)
    beta = np.array([0.0, 0.1])
    mag = np.zeros((len(t), 2, 4, 3))
    mag[:, 1, 2] = np.array([-np.sin(0.1), 0.0, np.cos(0.1)]) * 0.004 * np.sin(np.pi * t)[:, None] ** 2
    m = gait_metrics(pat, np.array([crease.FLAT]), {"positions": frames, "magnet_pos": mag,
                                                   "crease_angle": np.zeros((len(t), 2, 1)), "time": t},
                     np.array([1.0, 1.0]), beta)
    assert np.isnan(m["end_hold_ratio"][0]).all()
    np.testing.assert_allclose(m["end_hold_ratio"][1], [1.0, 1.0], atol=1e-9)
    np.testing.assert_allclose(m["cycle_displacement_m"][0], [0.010, 0.010], atol=1e-12)
    assert m["centre_ipm_max_lift_m"][1] == pytest.approx(0.004, rel=1e-9)
    assert m["length_ratio_min"][1] == pytest.approx(1.0 - 0.004 / xa.max(), rel=1e-9)


def test_default_worm_is_mineral_paper():
    from warpworm.physics.materials import material_params
    from warpworm.physics.params import WormParams

    p, d = material_params("mineral_paper"), WormParams()
    for key in ("hinge_stiffness", "valley_bar_stiffness", "sheet_density", "hinge_damping"):
        assert getattr(p, key) == getattr(d, key), key


def test_parse_grid_and_points():
    g = parse_grid("w=0.01:0.03:3,a=0.04,0.05,h=0.01")
    np.testing.assert_allclose(g["wavelength"], [0.01, 0.02, 0.03])
    np.testing.assert_allclose(g["amplitude"], [0.04, 0.05])
    pts = grid_points(g)
    assert len(pts["wavelength"]) == 6 and set(pts["closest_approach"]) == {0.01}
    for bad, msg in [("q=1", "unknown key 'q'"), ("T=1", "unknown key 'T'"), ("w=1:2", "lo:hi:n"), ("0.1", "no key"), ("w=-1", ">= 0"),
                     ("w=1,w=2", "twice")]:
        with pytest.raises(ValueError, match=msg):
            parse_grid(bad)


def test_search_gait_ranks_and_does_not_depend_on_the_worker_split(tmp_path):
    """Two grid points, one cycle: one process and two processes give the same measures bit for bit (worlds never
    interact), the ranking holds only valid worlds, best first, and the CSV has a row per point."""
    import csv

    from warpworm.physics import gaits
    from warpworm.analysis.gait_search import search_gait, write_csv

    params = gaits.preset_params("omega")
    grid = parse_grid("w=0.016,a=0.03,h=0.023,0.035")
    one = search_gait(params, grid, 1, workers=1, fps=10.0)
    two = search_gait(params, grid, 1, workers=2, fps=10.0)
    for k, v in one["metrics"].items():
        np.testing.assert_array_equal(v, two["metrics"][k], err_msg=k)
    per = one["per_cycle_m"]
    order = one["order"]
    assert set(order) == set(np.flatnonzero(one["valid"]))
    assert np.all(np.diff(per[order]) <= 0)
    write_csv(tmp_path / "s.csv", one)
    rows = list(csv.DictReader(open(tmp_path / "s.csv")))
    assert len(rows) == 2 and float(rows[1]["closest_approach"]) == pytest.approx(0.035)
    with pytest.raises(ValueError, match="cycles"):
        search_gait(params, grid, 0)


def test_lateral_drift_is_the_centroid_offset_across_the_axis():
    """A worm translated sideways by a known y(t) on an inclined floor (the lateral axis +y stays in its plane):
    the net and the largest lateral offset are y(end) and max |y|, whatever it does along the axis."""
    pat = _worm()
    x0 = pat.vertices
    t = np.linspace(0.0, 2.0, 41)
    y = 0.004 * np.sin(np.pi * t) - 0.003 * t  # out to +2.1 mm, back, ending at −6 mm
    beta = np.radians(5.0)
    rot = np.array([[np.cos(beta), 0.0, -np.sin(beta)], [0.0, 1.0, 0.0], [np.sin(beta), 0.0, np.cos(beta)]])
    frames = np.stack([(x0 + [0.01 * tt, yy, 0.0]) @ rot.T for tt, yy in zip(t, y)])[:, None]
    m = gait_metrics(pat, pat.hinge_label, {"positions": frames, "magnet_pos": np.zeros((len(t), 1, 4, 3)),
                                            "crease_angle": np.zeros((len(t), 1, pat.num_hinges)), "time": t},
                     1.0, incline=beta)
    assert m["lateral_displacement_m"][0] == pytest.approx(y[-1], abs=1e-12)
    assert m["lateral_drift_max_m"][0] == pytest.approx(np.abs(y).max(), abs=1e-12)
    assert m["tail_displacement_m"][0] == pytest.approx(0.02, abs=1e-12)  # the axis motion is unaffected


@pytest.mark.parametrize("fps", [25.0, 30.0, 50.0, 7.0])
def test_far_point_motion_of_a_steady_slide_is_its_speed_times_the_window(fps):
    """A rigid slide at constant speed v over 3 cycles of T = 1 s moves v · 0.2 T within each ±0.1-cycle window
    around a far point, whatever the frame rate: the window's ends are interpolated, not left to where frames fall
    (at 25 fps the frames nearest s = 1 are 0.92 and 1.08, which alone would give v · 0.16 T). A rigid slide keeps
    every ratio at 1."""
    pat = _worm()
    v = 0.004  # m/s
    t = np.arange(0.0, 3.0 + 1e-9, 1.0 / fps)
    frames = (pat.vertices[None] + v * t[:, None, None] * np.array([1.0, 0.0, 0.0]))[:, None]  # (F, 1, V, 3)
    F = len(t)
    m = gait_metrics(pat, pat.hinge_label, {"positions": frames, "magnet_pos": np.zeros((F, 1, 4, 3)),
                                            "crease_angle": np.zeros((F, 1, len(pat.hinges))), "time": t}, 1.0)
    assert m["far_point_motion_m"][0] == pytest.approx(v * 0.2, rel=1e-9)
    assert m["far_point_ratio_deviation"][0] == pytest.approx(0.0, abs=1e-12)
