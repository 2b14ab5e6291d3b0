"""Virtual experiments (warpworm.analysis.experiments) against independent truths, on few worlds and short horizons.

Truths: the closed-form cube-cube table (DESIGN-NOTES), a linear quasi-static bar-and-hinge solve in NumPy (no
solver), the worm's weight, Coulomb's law on an incline. Gait experiments are smoke runs: they must run and report
whatever they measure (the gait presets are still being tuned).
"""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from warpworm.analysis import experiments as ex
from warpworm.physics import gaits
from warpworm.physics.params import WormParams


def test_force_distance_analytic_equals_table():
    r = ex.force_distance(gaps=np.array([1e-3, 5e-3]))
    rel = r["analytic_at_table"] / r["table_force"] - 1.0
    assert np.abs(rel).max() < 1e-4, rel
    # the paper's 64/cm³ aggregation overestimates by ~5.6 % at 1 mm and < 0.1 % from 5 mm (DESIGN-NOTES)
    d64 = r["dipoles_at_table"][list(r["densities"]).index(64e6)] / r["table_force"] - 1.0
    assert 0.04 < d64[0] < 0.07 and np.all(np.abs(d64[r["table_gap"] >= 5e-3]) < 1e-3)
    # coarser grids are worse near contact
    assert np.all(np.diff(np.abs(r["dipoles_at_table"][:, 0] / r["table_force"][0] - 1.0)) < 0)


def test_compression_matches_linear_quasi_static_and_scales_with_hinge_stiffness():
    """Zero gravity (no friction) and soft bars (EA = 0.02 N): the measured force must follow the independent linear solve of the
    bar-and-hinge stiffness, and so grow with k_α by the solve's ratio, not by k_α's own ratio (bars also resist)."""
    ks = (0.02, 0.08)
    r = ex.compression(ks, max_displacement=1.0e-3, increments=2, hold=0.15, settle=0.05, gravity=0.0,
                       bar_stiffness=0.02, anchor_stiffness=1.0e3)
    f, lin = r["force"], r["linear"]
    assert not r["unstable"].any()
    assert np.all(np.diff(f, axis=0) > 0), f  # force grows with displacement in every world
    assert np.all(np.diff(f[-1]) > 0), f[-1]  # and with k_α
    rel = f[1:] / lin[1:] - 1.0
    assert np.abs(rel).max() < 0.12, rel
    ratio, lin_ratio = f[-1, 1] / f[-1, 0], lin[-1, 1] / lin[-1, 0]
    assert abs(ratio / lin_ratio - 1.0) < 0.05, (ratio, lin_ratio)


def test_flexure_anchor_forces_balance_weight_and_grow_with_deflection():
    r = ex.flexure((0.02,), max_deflection=1.0e-3, increments=2, hold=0.15, settle=0.1)
    # anchor forces (as applied by the solver: Simulator.snapshot) hold the weight at the unloaded start
    # (supports' share minus the load pad's pull; the load pad also carries some)
    import trimesh

    from warpworm.sim.model import Model

    # the weight from the masses' definitions (sheet density × trimesh's area, the IPMs' ρ π r² h), not the model's
    p = replace(WormParams(), **ex.NO_MAGNETS)
    model = Model.from_params(p, 1, "cpu")
    area = trimesh.Trimesh(model.rest_positions_host[0], model.pattern.triangles, process=False).area
    ipm = p.magnet_mass_density * np.pi * (p.ipm_diameter / 2) ** 2 * p.ipm_thickness
    weight = float((p.sheet_density * area + len(model.pattern.mount_vertices) * ipm) * 9.81)
    held = r["force_raw"][0, 0] - r["force_pusher_raw"][0, 0]
    assert abs(held / weight - 1.0) < 0.05, (held, weight)
    assert np.all(np.diff(r["force"][:, 0]) > 0), r["force"]


def test_slope_transition_at_friction_angle():
    r = ex.slope((-2.0, 2.0), duration=0.2, settle=0.1)
    assert list(r["slides"]) == [False, True], r["summary"]
    s = r["summary"]
    assert s["slide_after_settle_mm"][0] < 0.1
    # the sliding world follows Coulomb's ½ g (sin β − μk cos β) t² from rest
    assert abs(r["slide"][-1, 1] / r["predicted"][-1, 1] - 1.0) < 0.05, s


def test_gait_experiments_run_and_report():
    rec = ex.run_gaits(duration=0.04, settle=0.02, sample_every=2)
    W, V = 3, rec["model"].num_vertices
    assert rec["positions"].shape[1:] == (W, V, 3)
    d = ex.deformation(record=rec)
    assert d["ratio"].shape == (len(rec["time"]), W, 4)
    np.testing.assert_allclose(d["ratio"][0], 1.0)
    st = ex.strain(record=rec)
    assert st["max_abs"].shape == (W, rec["model"].num_edges) and np.all(np.isfinite(st["max_abs"]))
    # recomputed from the recorded positions (not the solver's recorded strain): |L / L0 − 1|, its max and mean over
    # time; measured 3.3e-6 apart (float32 positions and strains) against strains up to 0.024
    m, pos = rec["model"], rec["positions"].astype(np.float64)
    e = m.pattern.edges
    eps = np.linalg.norm(pos[..., e[:, 0], :] - pos[..., e[:, 1], :], axis=-1) / m.rest_length.numpy() - 1.0
    assert np.abs(np.abs(eps).max(axis=0) - st["max_abs"]).max() < 1e-5
    assert np.abs(np.abs(eps).mean(axis=0) - st["mean_abs"]).max() < 1e-5
    assert np.abs(eps).max() > 1e-3  # the gaits do strain the bars
    # the deformation ratios and displacement from the pattern's segment centres of the recorded positions (exact)
    idx = [m.pattern.keypoint_names.index(f"seg{i}") for i in range(5)]
    kp = m.pattern.keypoints(pos)[..., idx, :]
    dist = np.linalg.norm(np.diff(kp, axis=-2), axis=-1)
    assert np.abs(dist / dist[0] - d["ratio"]).max() < 1e-12
    assert np.abs(kp[..., 0].mean(-1) - kp[0, ..., 0].mean(-1) - d["displacement"]).max() < 1e-12
    fp = ex.force_plate(duration=0.04, settle=0.02)
    assert fp["force"].shape[1:] == (W, 3) and np.all(np.isfinite(fp["force"]))
    assert len(fp["summary"]["rise_time_10_90_ms"]) == W and len(fp["summary"]["fall_time_90_10_trough_ms"]) == W
    json.dumps(ex.to_jsonable(d)), json.dumps(ex.to_jsonable(fp))


def test_force_plate_pulses_repeat_when_the_pass_repeats():
    """A tied worm driven by a periodic force settles to a periodic response: with the EPM's pass repeated in place
    (``rewind``, the default) the inchworm's cycle-to-cycle difference in pull shrinks (a contraction toward one
    periodic pulse: the third cycle differs from the second by under half of what the second differs from the
    first, and by under 3 % RMS of the pulse), and its rise and fall times agree between those cycles to 2 %. With
    the EPM advancing (``rewind=False``) the same cycles differ by more than half the pulse: the magnet has moved
    on by w and leaves the tied worm behind."""
    def cycles(r):
        t, pull = r["time"], r["pull"][:, 0]
        c = [pull[(t >= k) & (t < k + 1)] for k in range(3)]
        n = min(len(x) for x in c)
        return [x[:n] for x in c]

    def rms(x):
        return float(np.sqrt(np.mean(np.square(x))))

    r = ex.force_plate(["inchworm"], duration=3.0, settle=0.1)
    assert not r["unstable"].any() and r["summary"]["rewind"]
    c = cycles(r)
    assert c[2].max() > 0.02, c[2].max()  # a real pulse (tens of mN), not noise
    d21, d32 = np.abs(c[1] - c[0]).max(), np.abs(c[2] - c[1]).max()
    assert d32 < 0.5 * d21, (d21, d32)
    assert rms(c[2] - c[1]) < 0.03 * rms(c[2])
    for k in ("rise_time", "fall_time"):
        assert abs(r[k][2, 0] / r[k][1, 0] - 1.0) < 0.02, (k, r[k][:, 0])
    a = cycles(ex.force_plate(["inchworm"], duration=3.0, settle=0.1, rewind=False))
    assert rms(a[2] - a[1]) > 0.5 * rms(a[2])


def test_worlds_split_over_threads_equal_one_batch():
    """Worlds never interact: each experiment's arrays from two threads (contiguous world shares, their parameters
    sliced, each its own Model and Simulator, graphs behind the capture gate) equal the one-batch run exactly.
    Covers a per-world incline (slope), per-world hinge stiffness with anchors (compression) and per-world gait
    presets with the force-plate anchors (3 worlds: shares of 2 and 1)."""
    kw = dict(duration=0.02, settle=0.02)
    one, two = (ex.slope((-2.0, 2.0, 3.0), workers=w, **kw) for w in (1, 2))
    for k in ("time", "slide", "predicted", "slides", "unstable"):
        np.testing.assert_array_equal(one[k], two[k], err_msg=k)
    assert one["summary"] == two["summary"]
    one, two = (ex.compression((0.01, 0.02, 0.04), increments=1, hold=0.02, settle=0.02, workers=w) for w in (1, 2))
    for k in ("force_raw", "force_pusher_raw", "displacement", "unstable", "final_positions", "linear"):
        np.testing.assert_array_equal(one[k], two[k], err_msg=k)
    one, two = (ex.run_gaits(duration=0.02, settle=0.01, anchors=ex.section_vertices(6, 0), workers=w)
                for w in (1, 2))
    for k in ("time", "positions", "bar_strain", "anchor_force", "magnet_pos", "unstable", "rest_positions"):
        np.testing.assert_array_equal(one[k], two[k], err_msg=k)
    assert ex.world_shares(3, 2) == [(0, 1), (1, 3)] and ex.world_shares(2, 8) == [(0, 1), (1, 2)]


def test_cli_writes_png_and_json(tmp_path, capsys):
    pytest.importorskip("matplotlib")
    from warpworm.cli import main

    assert main(["experiment", "force-distance", "--quick", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "force-distance.png").stat().st_size > 10_000
    data = json.loads((tmp_path / "force-distance.json").read_text())
    assert data["summary"]["analytic_max_rel_err_vs_table"] < 1e-4
    assert "force-distance" in capsys.readouterr().out


def _raised_cosine_pulses(t, period, rise, fall, start, peaks, base=0.0):
    """A pulse per cycle: raised-cosine rise over ``rise`` [s] from ``start`` into the cycle, raised-cosine fall over
    ``fall``; 10 %→90 % of a raised-cosine edge of length D takes D (acos(−0.8) − acos(0.8)) / π (analytic)."""
    y = np.full_like(t, base)
    for c, p in enumerate(peaks):
        s = t - c * period - start
        up, dn = (s >= 0) & (s < rise), (s >= rise) & (s < rise + fall)
        y[up] = base + (p - base) * (1 - np.cos(np.pi * s[up] / rise)) / 2
        y[dn] = base + (p - base) * (1 + np.cos(np.pi * (s[dn] - rise) / fall)) / 2
    return y


def test_rise_fall_times_of_an_analytic_pulse_train():
    T, dt = 1.0, 1.0e-3
    t = np.arange(0.0, 4 * T + 0.5 * dt, dt)
    edge = lambda D: D * (np.arccos(-0.8) - np.arccos(0.8)) / np.pi  # noqa: E731
    # a steep rise and a smooth fall (the paper's inchworm), peaks varying per cycle; the first cycle is a different
    # shape (a start-up transient) and must not enter the means
    y = _raised_cosine_pulses(t, T, 0.1, 0.4, 0.3, [1.0, 1.2, 1.4, 1.6])
    y[t < T] = _raised_cosine_pulses(t[t < T], T, 0.3, 0.3, 0.1, [2.0])
    r = ex.rise_fall_times(t, y, T)
    assert len(r["rise"]) == 4
    np.testing.assert_allclose(r["rise"][1:], edge(0.1), rtol=5e-3)
    np.testing.assert_allclose(r["fall"][1:], edge(0.4), rtol=5e-3)
    np.testing.assert_allclose(r["rise"][0], edge(0.3), rtol=5e-3)
    assert abs(r["rise_mean"] / edge(0.1) - 1) < 5e-3 and abs(r["fall_mean"] / edge(0.4) - 1) < 5e-3
    # the reverse (omega in the paper) on a negative offset: levels from the fixed baseline, or from each edge's
    # trough, give the same times; a zero baseline under a pulse that never rises above 0 gives NaN
    y2 = _raised_cosine_pulses(t, T, 0.35, 0.05, 0.2, [0.5, 0.5, 0.5, 0.5], base=-0.3)
    for bl in (-0.3, "trough"):
        r2 = ex.rise_fall_times(t, y2, T, baseline=bl)
        assert abs(r2["rise_mean"] / edge(0.35) - 1) < 5e-3 and abs(r2["fall_mean"] / edge(0.05) - 1) < 1e-2, bl
    assert np.isnan(ex.rise_fall_times(t, y2 - 1.0, T)["rise_mean"])
    # fewer than two whole cycles: no mean
    assert np.isnan(ex.rise_fall_times(t[t <= 1.5], y[t <= 1.5], T)["rise_mean"])


def test_set_overrides_name_the_item_and_reach_the_worlds(tmp_path, capsys):
    """``--set FIELD=VALUE`` (experiment, search-gait): parsed to WormParams overrides; a bad field or value is refused
    before any work, naming the item; a good one reaches every world (the force plate's EPM path scales with it)."""
    from warpworm.cli import main
    from warpworm.physics.params import parse_overrides

    assert parse_overrides(["closest_approach_scale=1.1", "hinge_damping=2e-4"]) == {
        "closest_approach_scale": 1.1, "hinge_damping": 2e-4}
    for bad, msg in (("bogus=1", "one of WormParams' fields"), ("hinge_damping", "FIELD=VALUE"),
                     ("hinge_damping=abc", "expected a number")):
        with pytest.raises(ValueError, match=msg):
            parse_overrides([bad])
        assert main(["experiment", "force-plate", "--set", bad, "--out", str(tmp_path / "x")]) == 2
        assert bad in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    model, _ = ex.gait_model(["peristaltic"], base=replace(WormParams(), closest_approach_scale=1.1))
    model0, _ = ex.gait_model(["peristaltic"])
    depth = model.default_path.depth - model0.default_path.depth
    np.testing.assert_allclose(depth, 0.1 * gaits.GAIT_PRESETS["peristaltic"]["closest_approach"], rtol=1e-9)
