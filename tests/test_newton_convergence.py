"""The Newton iteration of the implicit substep converges to the implicit-Euler solution: the tolerance's early stop
and chord steps against always taking every Newton step, and a step cap that never decides the answer (the kernel
against the NumPy reference's fixed point: tests/test_dynamics_numpy_reference.py)."""

from __future__ import annotations

import numpy as np

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

quiet_warp()


def test_tolerance_stop_and_chord_steps_reach_the_full_newton_answer():
    """On the floor with friction and the EPM crawling it (peristaltic preset, 0.2 s): the default early stop (a
    Newton step changing no vertex's velocity by more than 1e-4 m/s, 1e-7 m here, ends the substep) and chord steps
    (a factorization every other substep of a launch unless a contact changes or a step fails to halve) land where
    12 full Newton steps per substep do, within the float32 floor of this 0.2 s run (measured: the default 0.67 µm apart,
    chord steps at 1e-5 m/s 0.10 µm; fresh factors at every step: at 1e-6 m/s 0.11 µm, at the default 1e-4 m/s
    0.83 µm, at 1e-3 m/s 0.67 µm, two steps 2.2 µm)."""
    p = gaits.preset_params("peristaltic", magnet_model="analytic")
    model = Model.from_params(p, 1, "cpu")
    out = {}
    for name, kw in [("full", dict(newton=12, newton_tol=0.0, chord=False)), ("default", {}),
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
