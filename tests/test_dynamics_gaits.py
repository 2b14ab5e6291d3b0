"""Each gait preset moves the worm forward over 5 cycles; each backward preset moves it backward (paper §III)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.analysis.gait_runs import run_gait

quiet_warp()


@pytest.mark.parametrize("backward", [False, True], ids=["forward", "backward"])
@pytest.mark.parametrize("gait", ["peristaltic", "omega", "inchworm"])
def test_gait_preset_deforms_and_moves_the_worm_its_way(gait, backward):
    """5 cycles of each preset on the default (mineral-paper) worm: stable and unfolded; it moves the commanded way
    by more than 1 mm, in every cycle after the first by more than 0, and it never gets ahead of the EPM that drags
    it: after k cycles it has gone at most k w + w / 2 (the first cycle pulls the worm in to the EPM's path: inchworm
    28.2 mm at w = 20 mm, measured; peristalsis lags a cycle and catches up, 27.2 mm in its third); its creases swing
    by 15° or more
    (the paper's deformation, not a rigid slide); peristaltic and inchworm rest when the EPM is far (segment ratios
    within 2 % of 1 around the far points; the omega preset, which keeps up with the EPM, does not: 5.7 %,
    docs/dynamics.md)."""
    params = gaits.preset_params(gait, backward)
    result = run_gait(params, 1, 5, fps=25.0, save_worlds=0)
    m = result["metrics"]
    d = float(result["displacement_m"][0])
    assert not result["unstable"][0] and not result["crumpled"][0]
    sign = -1.0 if backward else 1.0
    w = gaits.GAIT_PRESETS[gait]["wavelength"]
    assert sign * d > 1e-3, f"{gait}: net displacement {d * 1e3:+.2f} mm"
    cycles = sign * np.asarray(m["cycle_displacement_m"][0])
    ahead = np.cumsum(cycles) - w * np.arange(1, len(cycles) + 1)
    assert np.all(cycles[1:] > 0.0) and np.all(ahead <= 0.5 * w), (
        f"{gait}: per cycle {np.round(cycles * 1e3, 2)} mm (w = {w * 1e3:.0f} mm)")
    assert m["crease_angle_range_deg"][0] >= 15.0, m["crease_angle_range_deg"]
    assert m["max_fold_violation_deg"][0] <= 5.0
    if gait != "omega":
        assert m["far_point_ratio_deviation"][0] <= 0.02, m["far_point_ratio_deviation"]


@pytest.mark.parametrize("gait", ["peristaltic", "omega", "inchworm"])
def test_gait_default_substep_is_converged_in_dt(gait):
    """The gaits' default substep (``gaits.DEFAULT_SUBSTEPS`` of ``DEFAULT_DT``: 2 ms) against four times finer
    (0.5 ms), the wrench refreshed every 4 ms in both, over 1.5 cycles (through a closest approach and the far point
    after it): the same displacement to 0.2 mm and the same segment ratios to 0.003 (measured: 0.105 / 0.023 / 0.079 mm
    and 0.0004 / 0.0014 / 0.0001 for peristaltic / omega / inchworm). 4 ms against 1 ms gives 0.267 mm for
    peristalsis: a default coarser than the gaits allow fails here."""
    params = gaits.preset_params(gait)
    runs = [run_gait(params, 1, 1.5, substeps=s, fps=25.0, save_worlds=0)
            for s in (gaits.DEFAULT_SUBSTEPS, 4 * gaits.DEFAULT_SUBSTEPS)]
    assert not any(r["unstable"][0] for r in runs)
    d = [float(r["displacement_m"][0]) for r in runs]
    assert abs(d[0] - d[1]) < 2e-4, d
    r0, r1 = (r["metrics"]["deformation_ratio_min"][0] for r in runs)
    np.testing.assert_allclose(r0, r1, atol=3e-3)


def test_direction_dependent_friction_is_mirrored_with_the_gait():
    """Mirror symmetry x → −x with a skin that grips by direction: forward peristalsis whose friction is 2× tail-ward
    (μ head-ward, 2μ tail-ward) is the mirror image of backward peristalsis with 2μ head-ward and μ tail-ward
    (``friction_backward_ratio`` 0.5 on 2μ): opposite displacements to 0.1 mm (measured 0.008 of 17.0 mm over 2
    cycles; the mesh's diagonal bars have one chirality) and the segment ratios reversed to 0.002 (0.0002). The
    mirror holds whichever way a kernel takes the skin; what pins the direction is the forward run's progress
    (> 10 mm: with the skin reversed, ratio 0.5 on μ, it goes back 4.5 mm) and the incline tests
    (tests/test_dynamics_physics.py)."""
    w = 0.008
    fwd = replace(gaits.preset_params("peristaltic", False), wavelength=w, friction_backward_ratio=2.0)
    bwd = replace(gaits.preset_params("peristaltic", True), wavelength=w, friction_backward_ratio=0.5,
                  mu_static=2 * fwd.mu_static, mu_kinetic=2 * fwd.mu_kinetic)
    rf, rb = (run_gait(p, 1, 2, fps=25.0, save_worlds=0) for p in (fwd, bwd))
    df, db = float(rf["displacement_m"][0]), float(rb["displacement_m"][0])
    assert df > 0.01 and abs(df + db) < 1e-4, (df, db)
    np.testing.assert_allclose(rf["metrics"]["deformation_ratio_min"][0],
                               rb["metrics"]["deformation_ratio_min"][0][::-1], atol=2e-3)


def test_every_substep_converges_with_a_one_way_skin():
    """The Newton iteration meets its tolerance in every substep with a skin gripping 2x tail-ward (peristalsis at
    6 / 45 / 5 mm, one cycle): no substep ends at the step cap (before the stick/slip switch limit, half of them
    did, two neighbouring vertices taking turns at sticking), at a cost of a few Newton steps (measured 5.4 per
    substep over two cycles against 3.6 isotropic)."""
    from warpworm.sim.model import Model
    from warpworm.sim.simulator import Simulator

    p = replace(gaits.preset_params("peristaltic"), wavelength=0.006, amplitude=0.045, closest_approach=0.005,
                magnet_model="analytic", friction_backward_ratio=2.0)
    sim = Simulator(Model.from_params(p, 1, "cpu"), dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.2)
    sim.newton_stats(reset=True)
    n = int(round(float(p.cycle_period) / sim.dt))
    sim.step(state, n)
    stats = sim.newton_stats()
    assert stats["capped"][0] == 0, stats
    assert stats["steps"][0] / (n * sim.substeps) < 8.0, stats


def test_omega_preset_lifts_the_middle_and_shortens_the_worm():
    """§III-B: the middle of the worm is pushed up (centre IPM >= 3 mm) while its ends come closer (>= 10 %)."""
    result = run_gait(gaits.preset_params("omega"), 1, 2, fps=25.0, save_worlds=0)
    m = result["metrics"]
    assert m["centre_ipm_max_lift_m"][0] >= 3e-3, m["centre_ipm_max_lift_m"]
    assert m["length_ratio_min"][0] <= 0.9, m["length_ratio_min"]


def test_simulate_set_reaches_the_worlds_and_refuses_bad_values(tmp_path, capsys):
    """``simulate --set``: a bad field or value is refused before any work (exit 2, the item named, no output
    folder); a good one reaches every world: the EPM moved half a metre below the plate exerts nothing, so over one
    cycle the worm stays where it settled (< 0.05 mm), where the preset moves it by millimetres."""
    import json

    from warpworm.cli import main

    out = tmp_path / "bad"
    assert main(["simulate", "--set", "friction_backward_ratio=-1", "--out", str(out)]) == 2
    assert main(["simulate", "--set", "no_such_field=1", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "friction_backward_ratio" in err and "-1" in err and "no_such_field" in err
    assert not out.exists()
    runs = {}
    for tag, extra in (("far", ["--set", "closest_approach=0.5", "--set", "amplitude=0.001"]), ("preset", [])):
        assert main(["simulate", "--gait", "inchworm", "--cycles", "1", "--worlds", "2", "--json", "--no-output",
                     "--magnet-model", "analytic", *extra]) == 0
        runs[tag] = np.asarray(json.loads(capsys.readouterr().out)["displacement_m"])
    assert np.all(np.abs(runs["far"]) < 5e-5), runs["far"]
    assert np.all(np.abs(runs["preset"]) > 1e-3), runs["preset"]


def test_simulate_cli_json_and_files(tmp_path, capsys):
    import json

    from warpworm.cli import main

    out = tmp_path / "run"
    rc = main(["simulate", "--gait", "omega", "--backward", "--cycles", "1", "--worlds", "2", "--json",
               "--out", str(out), "--fps", "10"])
    assert rc == 0
    stdout = capsys.readouterr().out
    summary = json.loads(stdout)  # only JSON on stdout
    assert list(summary)[:7] == ["gait", "worlds", "displacement_m", "unstable", "crumpled", "sim_time_s",
                                 "wall_time_s"]
    for key in ("deformation_ratio_min", "deformation_ratio_max"):
        assert np.shape(summary[key]) == (2, 4)
    for key in ("crease_angle_range_deg", "tail_displacement_m", "head_displacement_m", "centre_ipm_max_lift_m",
                "max_fold_violation_deg"):
        assert np.shape(summary[key]) == (2,)
    assert summary["gait"] == "omega" and summary["worlds"] == 2
    assert len(summary["displacement_m"]) == 2 and len(summary["unstable"]) == 2
    assert summary["sim_time_s"] == pytest.approx(1.0)
    traj = np.load(out / "trajectory.npz")
    F = len(traj["times"])
    assert traj["positions"].shape[:2] == (F, 2) and traj["magnet_rot"].shape[-2:] == (3, 3)
    assert traj["crease_angle"].shape[:2] == (F, 2) and "triangles" in traj.files
    assert (out / "preview.mp4").stat().st_size > 0 and (out / "preview_strip.png").stat().st_size > 0
    assert (out / "filmstrip.png").stat().st_size > 0


def test_simulate_workers_split_equals_one_process(capsys):
    """Three randomized worlds on one and on two processes: every per-world number is identical."""
    import json

    from warpworm.cli import main

    outs = []
    for workers in ("1", "2"):
        assert main(["simulate", "--gait", "inchworm", "--cycles", "1", "--worlds", "3", "--randomize", "--seed", "4",
                     "--json", "--no-output", "--fps", "10", "--workers", workers]) == 0
        outs.append(json.loads(capsys.readouterr().out))
    for key, value in outs[0].items():
        if key != "wall_time_s":
            assert outs[1][key] == value, key
