"""The Newton iteration of the implicit substep converges to the implicit-Euler solution: the tolerance's early stop
and chord steps against always taking every Newton step, and a step cap that never decides the answer (the kernel
against the NumPy reference's fixed point: tests/test_dynamics_numpy_reference.py)."""

from __future__ import annotations

import numpy as np

from warpworm import gaits, quiet_warp
from warpworm.model import Model
from warpworm.simulator import Simulator

quiet_warp()


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


def test_predictive_stop_saves_steps_within_the_tolerance():
    """The contraction-based stop (``newton_predict``, Hairer & Wanner's θ/(1 − θ)·step < tol) ends substeps one
    step early where the last two steps show the iteration converging, never on a step that changed a contact. On
    0.6 s of the omega preset at the gaits' 2 ms substeps (the gait with the most Newton work) it must take fewer
    steps than the plain test (measured 3.48 against 4.10 per substep) and stay within what the tolerance allows
    against 16 full steps: every substep may leave at most newton_tol·dt_sub = 0.2 µm unconverged, 300 substeps at
    most 60 µm (measured 10.7 µm; the plain test 0.5 µm, the 2 ms substep's own error against 0.5 ms is 20–110 µm
    over 1.5 cycles, tests/test_dynamics_gaits.py)."""
    p = gaits.preset_params("omega", magnet_model="analytic")
    model = Model.from_params(p, 1, "cpu")
    out, steps = {}, {}
    for name, kw in [("full", dict(newton=16, newton_tol=0.0)), ("predict", {}),
                     ("plain", dict(newton_predict=False))]:
        sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, **kw)
        st = sim.initial_state()
        sim.settle(st, 0.2)
        sim.newton_stats(reset=True)
        sim.step(st, 150)
        assert not st.unstable.numpy().any(), name
        stats = sim.newton_stats()
        assert stats["capped"][0] == 0 or name == "full", (name, stats)
        steps[name] = stats["steps"][0]
        out[name] = st.positions.numpy()
    substeps = 150 * gaits.DEFAULT_SUBSTEPS
    bound = substeps * 1e-4 * gaits.DEFAULT_DT / gaits.DEFAULT_SUBSTEPS
    err = {k: float(np.abs(v - out["full"]).max()) for k, v in out.items()}
    assert err["predict"] < bound and err["plain"] < bound, (err, bound)
    assert steps["predict"] < 0.95 * steps["plain"], steps
