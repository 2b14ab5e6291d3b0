"""The Newton iteration of the implicit substep converges to the implicit-Euler solution: the kernel's converged
substeps (default tolerance, and chord steps that reuse the factorization) against the NumPy dense-solve reference
iterated to its fixed point, and the tolerance's early stop against always taking every Newton step."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from warpworm import gaits, quiet_warp
from warpworm.model import Model
from warpworm.simulator import Simulator

quiet_warp()
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from numpy_substep import NumpyImplicit  # noqa: E402


@pytest.mark.parametrize("kw", [{}, {"chord": True, "newton": 40, "newton_tol": 2e-6}], ids=["default", "chord"])
def test_converged_substeps_match_the_numpy_fixed_point(kw):
    """Off the floor (falling, magnets, an anchor, crease damping), 10 substeps of the kernel against the float64
    reference iterated 20 Gauss–Newton steps per substep (its fixed point): the chord path (its own code: friction
    added to a gradient-only pass, the factor reused) reaches the same answer as the full one. Off the floor the
    iteration converges in two steps, so this checks the answer, not the speed of convergence (the floor test
    below does: measured 4.0e-4 of the motion for 2, 3 and converged steps alike, float32's floor)."""
    p = gaits.preset_params("inchworm", hinge_damping=1e-4)
    p.closest_approach = np.array([0.015, 0.02])
    model = Model.from_params(p, 2, "cpu", anchors=[4], anchor_stiffness=50.0)
    sim = Simulator(model, dt=2e-3, substeps=4, **kw)
    state = sim.initial_state()
    lifted = state.positions.numpy() + np.array([0.0, 0.0, 0.03], np.float32)  # 3 cm up: no floor contact
    state.positions.assign(lifted)
    sim.set_anchor_targets(lifted[:, [4]])
    sim.step(state, 3)
    sim.update_magnets(state)
    ref = NumpyImplicit(model, sim.dt_sub, newton=20)
    x, v, ang = ref.init(state, sim.control)
    x_start = x.copy()
    f = state.external_force.numpy().astype(np.float64)
    sim.run_substeps(state, 10)
    for _ in range(10):
        x, v, ang = ref.substep(x, v, ang, f)
    assert not state.unstable.numpy().any() and not state.contact.numpy().any()
    moved = np.abs(x - x_start).max()
    # float32 through a stiff solve (condition ~1e4 x 6e-8): the bound of the 3-step comparison in
    # test_dynamics_numpy_reference, which a fixed point must meet as well
    err = np.abs(state.positions.numpy() - x).max()
    assert err < 2e-3 * moved, (err, moved)
    assert np.abs(state.crease_angle.numpy() - ang).max() < 1e-4


def test_tolerance_stop_and_chord_steps_reach_the_full_newton_answer():
    """On the floor with friction and the EPM crawling it (peristaltic preset, 0.2 s): the default early stop (a
    Newton step changing no vertex's velocity by more than 1e-4 m/s, 1e-7 m here, ends the substep) and chord steps
    (one factorization per substep unless a contact changes or a step fails to halve) land where 12 full Newton
    steps per substep do, within the float32 floor of this 0.2 s run: 12 full steps and a 1e-6 m/s tolerance end
    1.0 µm apart (measured; the default 1.1 µm, chord 1.7 µm, a 1e-3 m/s tolerance 5.0 µm, two steps 3.6 µm)."""
    p = gaits.preset_params("peristaltic", magnet_model="analytic")
    model = Model.from_params(p, 1, "cpu")
    out = {}
    for name, kw in [("full", dict(newton=12, newton_tol=0.0)), ("default", {}),
                     ("chord", dict(chord=True, newton=30, newton_tol=1e-5))]:
        sim = Simulator(model, dt=4e-3, substeps=4, **kw)
        st = sim.initial_state()
        sim.settle(st, 0.1)
        sim.step(st, 50)
        assert not st.unstable.numpy().any(), name
        out[name] = st.positions.numpy()
    err = {k: float(np.abs(v - out["full"]).max()) for k, v in out.items()}
    assert err["default"] < 3e-6 and err["chord"] < 5e-6, err


def test_converged_substeps_do_not_depend_on_the_step_cap():
    """Converged means the cap on Newton steps never decides the answer: 0.6 s of the inchworm preset (the gait whose
    contacts land and let go the most) with at most 12 and at most 16 steps per substep are bit for bit the same,
    and no substep used them all. (Before a vertex could let go of the floor only once per substep, 94 of its first
    1000 substeps cycled land / let go until the cap, and the caps 12 and 13 ended 6.7 mm apart.)"""
    p = gaits.preset_params("inchworm", magnet_model="analytic")
    model = Model.from_params(p, 1, "cpu")
    out = {}
    for cap in (12, 16):
        sim = Simulator(model, dt=4e-3, substeps=4, newton=cap)
        st = sim.initial_state()
        sim.settle(st, 0.05)
        sim.newton_stats(reset=True)
        sim.step(st, 150)
        stats = sim.newton_stats()
        assert stats["capped"][0] == 0, (cap, stats)
        assert 2 * 600 <= stats["steps"][0] < cap * 600, stats  # 600 substeps, at least 2 steps each
        out[cap] = st.positions.numpy()
    assert np.array_equal(out[12], out[16])
