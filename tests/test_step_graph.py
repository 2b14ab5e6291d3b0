"""A step captured as a graph (``Simulator(use_graph=True)``, the default: Warp's CPU graph here, a CUDA graph on a
GPU) replays exactly what the plain launches do, and a graph captured before ``control.set_path`` does not keep
replaying the old path."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

quiet_warp()


def _run(use_graph: bool) -> list[np.ndarray]:
    """Settle (EPM parked), 20 steps of the omega preset, a new path (another wavelength and height), 20 more steps;
    two worlds of different stiffness. Returns the positions after each phase."""
    p = replace(gaits.preset_params("omega"), hinge_stiffness=np.array([0.004, 0.006]))
    model = Model.from_params(p, 2, "cpu")
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, use_graph=use_graph)
    state = sim.initial_state()
    sim.settle(state, 0.04)
    out = [state.positions.numpy().copy()]
    sim.step(state, 20)
    out.append(state.positions.numpy().copy())
    path = sim.control.path
    sim.set_path(replace(path, wavelength=np.asarray(path.wavelength) * 1.5, depth=np.asarray(path.depth) - 0.004))
    sim.step(state, 20)
    out.append(state.positions.numpy().copy())
    return out


def test_graph_replay_equals_plain_launches_across_a_new_path():
    plain, graph = _run(False), _run(True)
    for a, b in zip(plain, graph):
        np.testing.assert_array_equal(a, b)
    # the new path changed the motion (else the set_path check would be empty): the last 20 steps differ from the
    # same 20 steps on the old path by far more than rounding
    p = replace(gaits.preset_params("omega"), hinge_stiffness=np.array([0.004, 0.006]))
    model = Model.from_params(p, 2, "cpu")
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS)
    state = sim.initial_state()
    sim.settle(state, 0.04)
    sim.step(state, 40)
    assert np.abs(state.positions.numpy() - graph[-1]).max() > 1e-5


def test_a_graph_captured_first_thing_in_a_process_is_sound():
    """In a fresh process the first magnetic wrench of all is evaluated by a graph-stepped simulator (so the wrench's
    quadrature arrays are created by that first step): the Gauss–Legendre arrays hold their values afterwards and
    the run equals plain launches. (Created inside the capture, their host copy was recorded instead of done: the
    arrays held garbage for the rest of the process and its datasets' worlds exploded, 5 of 6 runs.)"""
    import subprocess
    import sys

    code = """
import numpy as np
from dataclasses import replace
from warpworm.physics import gaits, magnets
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator
quiet_warp()
def run(graph):
    model = Model.from_params(replace(gaits.preset_params("peristaltic"), magnet_model="analytic"), 2, "cpu")
    sim = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, use_graph=graph)
    state = sim.initial_state()
    sim.settle(state, 0.02)
    sim.step(state, 30)
    return state.positions.numpy().copy(), state.unstable.numpy().copy()
x_graph, u_graph = run(True)
x_plain, u_plain = run(False)
gx, gw = (a.numpy() for a in magnets._gauss_legendre(magnets.DEFAULT_QUAD_ORDER, "cpu"))
ref = np.polynomial.legendre.leggauss(magnets.DEFAULT_QUAD_ORDER)
assert np.allclose(gx, ref[0]) and np.allclose(gw, ref[1]), (gx, gw)
assert not u_graph.any() and not u_plain.any()
assert np.array_equal(x_graph, x_plain), np.abs(x_graph - x_plain).max()
print("ok")
"""
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stdout.strip().endswith("ok"), r.stdout[-2000:] + r.stderr[-2000:]


def test_graph_cache_is_bounded_and_a_failing_capture_falls_back(monkeypatch):
    """Six states stepped in turn by one simulator keep at most ``MAX_GRAPHS`` graphs, and each state ends where
    plain launches take it; a CPU capture that raises (a Warp before 1.19) turns the graphs off and the step still
    runs, to the same positions."""
    import warp as wp

    from warpworm.sim import simulator as sim_mod

    model = Model.from_params(gaits.preset_params("inchworm"), 1, "cpu")
    graph, plain = (Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, use_graph=g)
                    for g in (True, False))
    states = [[s.initial_state() for _ in range(6)] for s in (graph, plain)]
    for _ in range(2):
        for sim, sts in zip((graph, plain), states):
            for st in sts:
                sim.step(st, 3)
    assert len(graph._graphs) <= sim_mod.MAX_GRAPHS
    for a, b in zip(*states):
        np.testing.assert_array_equal(a.positions.numpy(), b.positions.numpy())

    def no_capture(*args, **kwargs):
        raise RuntimeError("Must be a CUDA device")

    monkeypatch.setattr(wp, "ScopedCapture", no_capture)
    fallback = Simulator(model, dt=gaits.DEFAULT_DT, substeps=gaits.DEFAULT_SUBSTEPS, use_graph=True)
    st = fallback.initial_state()
    fallback.step(st, 4)
    assert not fallback.use_graph
    ref = plain.initial_state()
    plain.step(ref, 4)
    np.testing.assert_array_equal(st.positions.numpy(), ref.positions.numpy())
