"""The NoFoldThrough barrier is its own material constant: a moderate squeeze keeps every crease in its range at soft
and stiff creases alike, and a squeeze past what the bellows can fold is flagged, never reported as a live world."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.experiments import section_vertices
from warpworm.gait_metrics import fold_violation
from warpworm.model import Model
from warpworm.params import WormParams
from warpworm.simulator import Simulator

quiet_warp()


def squeeze(hinge_stiffness, distance, duration=0.6):
    """Tail section clamped, head section driven ``distance`` [m] toward it (over 2/3 of ``duration``, then held),
    one world per k_α; returns (largest fold violation [deg] while not flagged, (W,); final ``unstable`` flags (W,);
    final positions (W, V, 3))."""
    k = np.asarray(hinge_stiffness, np.float64)
    p = WormParams(hinge_stiffness=k, ipm_moment=np.zeros(3), epm_moment=0.0, damping=20.0)
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
        t = x0.copy()
        t[:, 3:, 0] -= distance * min(1.0, 1.5 * i / steps)
        sim.set_anchor_targets(t)
        sim.step(state, 1)
        flagged = state.unstable.numpy() != 0
        viol = np.degrees(fold_violation(label, state.crease_angle.numpy()).max(axis=-1))
        worst = np.where(flagged, worst, np.maximum(worst, viol))
    return worst, state.unstable.numpy(), state.positions.numpy()


def test_moderate_squeeze_keeps_every_crease_in_range():
    """8 mm (10 % of the worm): soft and stiff creases fold without leaving their range (measured 0.0°; the simulator
    would flag a world past 5°)."""
    worst, flags, _ = squeeze([0.005, 0.05], 0.008)
    assert np.all(flags == 0), flags
    assert np.all(worst < 0.5), worst


def test_hard_squeeze_crumples_and_is_flagged_not_written():
    """30 mm (37 %) is past what the bellows can fold (its waists close at about 17 % shortening, docs/crease.md):
    the sheet crumples; every world is flagged (the soft one crumpled, 2; the stiffer one may first exceed a strain
    or speed limit, 1) and frozen finite, so no data is made from it."""
    worst, flags, x = squeeze([0.005, 0.05], 0.030)
    assert np.all(flags != 0) and flags[0] == 2, flags
    assert np.isfinite(x).all()
    assert np.all(worst <= 5.0), worst  # nothing beyond the tolerance was ever reported as a live world
