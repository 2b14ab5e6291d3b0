"""Each gait preset moves the worm forward over 5 cycles; each backward preset moves it backward (paper §III)."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpworm import gaits
from warpworm.commands.simulate import run_gait

wp.config.quiet = True


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
