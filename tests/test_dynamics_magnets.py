"""The magnetic wrench on the mesh against the foundation's magnet API, and batch independence of worlds."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np
import pytest

from warpworm.physics import gaits, magnets
from warpworm import quiet_warp
from warpworm.analysis.gait_runs import randomized_params
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

quiet_warp()


@pytest.mark.parametrize("magnet_model", ["dipoles", "analytic"])
def test_wrench_on_mesh_equals_foundation_api(magnet_model):
    """Sum of the mount-vertex forces and their moment about the IPM centre equal magnets.wrench summed over the
    other three magnets, for the same poses (EPM brought close so every term matters)."""
    p = gaits.preset_params("inchworm", magnet_model=magnet_model)
    model = Model.from_params(p, 1, "cpu")
    ipm = model.ipm_rest_pos_host[0, :, 0]
    tilt = np.array([[0.8, 0.0, 0.6], [0.0, 1.0, 0.0], [-0.6, 0.0, 0.8]])  # EPM tilted: torques on all IPMs
    sim = Simulator(model)
    sim.set_path(gaits.keyframe_path([0.0], [[0.5 * (ipm[1] + ipm[2]), 0.004, 0.05]], [tilt]))
    state = sim.initial_state()
    # deform the worm a little so the IPM frames are not axis-aligned
    rng = np.random.default_rng(0)
    x = state.positions.numpy() + rng.normal(scale=3e-4, size=state.positions.shape + (3,)).astype(np.float32)
    state.positions.assign(x)
    sim.update_magnets(state)
    snap = sim.snapshot(state)
    f_ext = state.external_force.numpy()[0].astype(np.float64)
    pos, rot = snap["magnet_pos"][0].astype(np.float64), snap["magnet_rot"][0].astype(np.float64)
    size, mom = model.magnet_size_host[0], model.magnet_moment_host[0]
    mags = [magnets.Cuboid(size[0], moment=mom[0])] + [
        magnets.Cylinder(size[k, 0], size[k, 2], moment=mom[k]) for k in (1, 2, 3)
    ]
    mv = model.pattern.mount_vertices
    for m in (1, 2, 3):
        F = np.zeros(3)
        T = np.zeros(3)
        for s_ in range(4):
            if s_ != m:
                f, t = magnets.wrench(mags[s_], mags[m], (pos[s_], rot[s_]), (pos[m], rot[m]), magnet_model)
                F += f
                T += t
        fk = f_ext[mv[m - 1]]
        xk = snap["positions"][0][mv[m - 1]].astype(np.float64)
        F_mesh = fk.sum(axis=0)
        T_mesh = np.cross(xk - pos[m], fk).sum(axis=0)
        scale_f = max(np.linalg.norm(F), 1e-6)
        scale_t = max(np.linalg.norm(T), 1e-8)
        assert np.linalg.norm(F_mesh - F) < 1e-3 * scale_f, (m, F_mesh, F)
        assert np.linalg.norm(T_mesh - T) < 1e-3 * scale_t, (m, T_mesh, T)
    assert np.linalg.norm(F) > 1e-3  # the EPM is close: forces of mN or more


def test_world_in_randomized_batch_equals_world_alone():
    W, pick, steps = 16, 11, 25
    batch_params = randomized_params("default", "peristaltic", False, "dipoles", W, seed=5)
    sim_b = Simulator(Model.from_params(batch_params, W, "cpu"), dt=4e-3, substeps=4)
    sb = sim_b.initial_state()
    sim_b.step(sb, steps)
    xb = sim_b.snapshot(sb)["positions"][pick]

    per_world = {f.name: np.asarray(getattr(batch_params, f.name)) for f in fields(batch_params)}
    one = replace(batch_params, **{k: v[pick] for k, v in per_world.items() if v.ndim and len(v) == W})
    sim_1 = Simulator(Model.from_params(one, 1, "cpu"), dt=4e-3, substeps=4)
    s1 = sim_1.initial_state()
    sim_1.step(s1, steps)
    x1 = sim_1.snapshot(s1)["positions"][0]

    moved = np.abs(x1 - sim_1.model.rest_positions_host[0]).max()
    assert moved > 1e-5
    err = np.abs(xb - x1).max() / np.abs(x1).max()
    assert err < 1e-5, f"relative difference {err:.2e}"
    # and the worlds really differ from each other
    assert np.abs(sim_b.snapshot(sb)["positions"][pick] - sim_b.snapshot(sb)["positions"][pick + 1]).max() > 1e-6
