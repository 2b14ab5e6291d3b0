"""Each gait preset moves the worm forward over 5 cycles; each backward preset moves it backward (paper §III)."""

from __future__ import annotations

import numpy as np
import pytest

from warpworm import gaits, quiet_warp
from warpworm.commands.simulate import run_gait

quiet_warp()


@pytest.mark.parametrize("backward", [False, True], ids=["forward", "backward"])
@pytest.mark.parametrize("gait", ["peristaltic", "omega", "inchworm"])
def test_gait_preset_moves_the_worm_its_way(gait, backward):
    params = gaits.preset_params(gait, backward)
    result = run_gait(params, 1, 5, fps=None)
    d = float(result["displacement_m"][0])
    assert not result["unstable"][0]
    sign = -1.0 if backward else 1.0
    # at least 1 mm in the commanded direction over 5 cycles (the worm is 80 mm long)
    assert sign * d > 1e-3, f"{gait} {'backward' if backward else 'forward'}: net displacement {d * 1e3:+.2f} mm"


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
