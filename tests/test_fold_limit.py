"""The NoFoldThrough barrier is its own material constant: a moderate squeeze keeps every crease in its range at soft
and stiff creases alike, and a squeeze past what the bellows can fold is flagged, never reported as a live world."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.experiments import section_vertices
from warpworm.analysis.gait_metrics import fold_violation, wing_altitude_ratio
from warpworm.sim.model import Model
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator

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
    """The anchors driven 50 mm (62 % of the worm) together are past what the sheet can fold: its waists close at
    about 17 % shortening (docs/crease.md), the soft waist bars then stretch to their stops and the panels' contact
    barrier (common.wing_contact) holds the wings off their hinges until, at ~40 % shortening (measured: 30 and
    40 mm are held, wings at 0.8–1.2 % of the hinge length), it is overwhelmed and a wing collapses. Every world is
    flagged (the soft one crumpled, 2; the stiffer one may first exceed a strain or speed limit, 1) and frozen
    finite, so no data is made from it. (Before the contact barrier a wing folded flat at 30 mm already.)"""
    worst, flags, x = squeeze([0.005, 0.05], 0.050)
    assert np.all(flags != 0) and flags[0] == 2, flags
    assert np.isfinite(x).all()
    hinges = Model.from_params(WormParams(), 1, "cpu").pattern.hinges
    assert wing_altitude_ratio(hinges, x[0]).min() < 0.01  # the collapse the flag names (rest: 17 % or more)
    assert np.all(worst <= 5.0), worst  # nothing beyond the tolerance was ever reported as a live world


def test_panel_contact_holds_the_wing_that_used_to_collapse():
    """The inchworm preset with its tail section held (the force plate, experiments.force_plate) at 0.5 ms steps
    stands the worm up under the EPM's first approach. Before the panels' contact barrier a waist triangle collapsed
    there (t = 0.44 s; its wing's altitude over the crease went to zero, the Newton matrix singular: flagged
    'exploded' a step later until the collapse check flagged it crumpled). With the barrier (common.wing_contact,
    from 2 % of the hinge length) the same 0.48 s run stays live, and no wing goes below 1 % (measured: 1.76 %)."""
    from warpworm.analysis import experiments

    model, _ = experiments.gait_model(["inchworm"], anchors=section_vertices(6, 0), anchor_stiffness=1e4, base=None,
                                       device="cpu")
    hinges = model.pattern.hinges
    assert wing_altitude_ratio(hinges, model.rest_positions_host[0]).min() > 0.17
    sim = Simulator(model, dt=5e-4, substeps=1)
    state = sim.initial_state()
    sim.settle(state, 0.2)
    lowest = 1.0
    for _ in range(12):  # 0.48 s
        sim.step(state, 80)
        lowest = min(lowest, wing_altitude_ratio(hinges, state.positions.numpy()[0]).min())
    assert state.unstable.numpy()[0] == 0
    assert lowest > 0.01, lowest
