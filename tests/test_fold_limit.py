"""The NoFoldThrough barrier is its own material constant: a squeeze that crumples the worm leaves no crease more
than 5° outside its range, however soft the crease; without the barrier the same squeeze folds creases through."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.experiments import section_vertices
from warpworm.gait_metrics import fold_violation
from warpworm.model import Model
from warpworm.params import WormParams
from warpworm.simulator import Simulator

quiet_warp()


def squeeze_violation(hinge_stiffness, fold_limit, squeeze=0.035, duration=0.6):
    """Tail section clamped, head section driven 35 mm (44 % of the worm) toward it and pressed 8 mm down into the
    floor, one world per (k_α, k_lim); returns the largest fold violation [deg] over the run, (W,)."""
    k = np.asarray(hinge_stiffness, np.float64)
    p = WormParams(hinge_stiffness=k, fold_limit_stiffness=np.asarray(fold_limit, np.float64),
                   ipm_moment=np.zeros(3), epm_moment=0.0, damping=20.0)
    n = p.n_units
    tail, head = section_vertices(n, 0), section_vertices(n, 2 * n)
    model = Model.from_params(p, len(k), "cpu", anchors=np.concatenate([tail, head]), anchor_stiffness=50.0)
    sim = Simulator(model, dt=4e-3, substeps=4)
    state = sim.initial_state()
    x0 = model.rest_positions_host[:, np.concatenate([tail, head])]
    steps = int(round(duration / sim.dt))
    worst = np.zeros(len(k))
    label = model.pattern.hinge_label
    for i in range(1, steps + 1):
        u = min(1.0, 1.5 * i / steps)
        t = x0.copy()
        t[:, 3:, 0] -= squeeze * u
        t[:, 3:, 2] -= 0.008 * u * (1 - u) * 4
        sim.set_anchor_targets(state, t)
        sim.step(state, 1)
        if i % 5 == 0:
            ang = state.crease_angle.numpy()
            worst = np.maximum(worst, np.degrees(fold_violation(label, ang).max(axis=-1)))
    assert not state.unstable.numpy().any()
    return worst


def test_squeeze_respects_the_fold_range_at_any_crease_stiffness():
    k = [0.0005, 0.005, 0.05]
    worst = squeeze_violation(k + k, [2.0] * 3 + [0.0] * 3)
    with_barrier, without = worst[:3], worst[3:]
    assert np.all(with_barrier <= 5.0), with_barrier
    # the squeeze is hard enough to matter: without the barrier the soft creases fold through
    assert without[:2].max() > 10.0, without
