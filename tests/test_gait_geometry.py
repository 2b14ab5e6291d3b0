"""The actuation geometry of the paper (§III, §IV-C): the EPM beneath the support plate, and the wrench-sign table.

Independent truths: the EPM cuboid's corners (its top face is exactly h below the origami base at closest approach,
for every θ), the sentences of §III-A–C as signs of the exact (analytic) magnetic wrench at each preset's closest
approach, and mirror symmetry (backward = forward mirrored x → −x: polar F_x and axial T_y flip, tail ↔ head).
"""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator
from warpworm.transforms import quat_wxyz_to_matrix, quat_xyzw_to_wxyz

quiet_warp()

TAIL, CENTRE, HEAD = 1, 2, 3


def closest_approach_wrench(gait: str, backward: bool, **overrides):
    """Analytic force [N] and torque [N·m] on the (EPM, tail, centre, head) magnets, (4, 3) each, and the EPM pose,
    with the rest worm and the EPM at its first closest approach (half a cycle)."""
    p = gaits.preset_params(gait, backward, magnet_model="analytic", **overrides)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=4e-3, substeps=4)
    state = sim.initial_state()
    state.step_count.assign(np.array([round(0.5 * float(p.cycle_period) / sim.dt_sub)], np.int32))
    sim.update_magnets(state)
    q = state.magnet_rot.numpy()[0, 0]
    R = quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q))
    return (state.magnet_force.numpy()[0].astype(np.float64), state.magnet_torque.numpy()[0].astype(np.float64),
            state.magnet_pos.numpy()[0, 0].astype(np.float64), R, model)


@pytest.mark.parametrize("theta", [-0.5 * np.pi, 0.0, 0.3, 0.5 * np.pi, np.pi])
def test_epm_top_face_is_h_below_the_origami_base(theta):
    h = 0.012
    *_, pos, R, model = closest_approach_wrench("peristaltic", False, closest_approach=h, orientation=theta)
    size = model.magnet_size_host[0, 0]
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * 0.5 * size
    top = (pos + corners @ R.T)[:, 2].max()
    assert top == pytest.approx(-h, abs=2e-6)
    # the moment points along (cos θ, 0, sin θ)
    np.testing.assert_allclose(R[:, 2], [np.cos(theta), 0.0, np.sin(theta)], atol=1e-6)


def test_closest_approach_inside_the_plate_is_refused():
    p = gaits.preset_params("omega", closest_approach=0.002, support_thickness=0.003)
    with pytest.raises(ValueError, match=r"worm.closest_approach.*0.002.*support_thickness"):
        Model.from_params(p, 1, "cpu")


def test_peristaltic_wrench_signs():
    """§III-A: the EPM's south pole (up, beneath the anterior half, nearer the centre) attracts the two anterior north
    poles: the anterior pair is squeezed together (the head pulled back relative to the centre), both pressed down,
    harder than the posterior pair is pulled apart or together (the posterior half keeps its shape)."""
    F, T, *_ = closest_approach_wrench("peristaltic", False)
    squeeze_anterior = F[CENTRE, 0] - F[HEAD, 0]
    assert squeeze_anterior > 0, F
    assert F[CENTRE, 2] < 0 and F[HEAD, 2] < 0, F
    assert abs(F[TAIL, 0] - F[CENTRE, 0]) < squeeze_anterior, F


def test_peristaltic_nearer_pulls_the_centre_forward():
    """Closer (h = 10 mm), the attraction takes the literal form of §III-A: centre forward, head back."""
    F, T, *_ = closest_approach_wrench("peristaltic", False, closest_approach=0.010)
    assert F[CENTRE, 0] > 0 > F[HEAD, 0], F


def test_omega_wrench_signs():
    """§III-B: flat, north pole forward, under the centre: the centre IPM is repelled upward with negligible torque;
    the end IPMs are drawn in toward the middle, with torques of opposite sign."""
    F, T, *_ = closest_approach_wrench("omega", False)
    assert F[CENTRE, 2] > 0, F
    assert F[TAIL, 0] > 0 > F[HEAD, 0], F
    assert T[TAIL, 1] * T[HEAD, 1] < 0, T
    assert abs(T[CENTRE, 1]) < 0.05 * min(abs(T[TAIL, 1]), abs(T[HEAD, 1])), T


def test_inchworm_wrench_signs():
    """§III-C: north pole up beneath the anterior half, nearer the centre: the centre IPM and the head IPM feel
    torques of opposite sign (the inverted U of the anterior half), the centre's the larger, and the centre is
    lifted."""
    F, T, *_ = closest_approach_wrench("inchworm", False)
    assert T[CENTRE, 1] * T[HEAD, 1] < 0, T
    assert abs(T[CENTRE, 1]) > abs(T[HEAD, 1]), T
    assert F[CENTRE, 2] > 0, F


@pytest.mark.parametrize("gait", ["peristaltic", "omega", "inchworm"])
def test_backward_is_the_mirror_image_of_forward(gait):
    Ff, Tf, pf, *_ = closest_approach_wrench(gait, False)
    Fb, Tb, pb, *_ = closest_approach_wrench(gait, True)
    l0 = WormParams().l0
    mirror = [0, HEAD, CENTRE, TAIL]  # slot in the mirrored worm
    scale = np.abs(Ff).max()
    for s in range(1, 4):
        m = mirror[s]
        np.testing.assert_allclose(Fb[m], Ff[s] * [-1, 1, 1], atol=2e-3 * scale)
        np.testing.assert_allclose(Tb[m, 1], -Tf[s, 1], atol=2e-3 * np.abs(Tf).max())
    assert pb[0] == pytest.approx(l0 - pf[0], abs=1e-4) and pb[2] == pytest.approx(pf[2], abs=1e-6)


def epm_positions(path, p, num_worlds: int, cycles):
    """The EPM centre [m] of each world at the given times (in cycles), shape (len(cycles), W, 3), from the kernel."""
    model = Model.from_params(p, num_worlds, "cpu")
    sim = Simulator(model, dt=4e-3, substeps=2)
    sim.set_path(path)
    state = sim.initial_state()
    out = []
    for s in cycles:  # a handful of poses read back one by one (kinematics only, no stepping)
        state.step_count.fill_(round(s * float(p.cycle_period) / sim.dt_sub))
        sim.update_magnets(state)
        out.append(state.magnet_pos.numpy()[:, 0].astype(np.float64))
    return np.stack(out), model


def test_rewound_path_repeats_the_first_pass_in_place():
    """``rewind`` = 1 (a worm tied in place, the force plate): over each cycle's pass (s − ⌊s⌋ in [0.1, 0.9]) and the
    first cycle's start the EPM is where the advancing path puts it in the first cycle, x = x0 + direction · w ·
    (s − ⌊s⌋), with the same gap at every phase; forward and backward worlds in one batch; a rewind of 0 is the
    advancing path itself; within 0.1 cycle of a later far point it returns continuously."""
    from dataclasses import replace

    p = replace(gaits.preset_params("peristaltic"), backward=np.array([False, True]))
    model = Model.from_params(p, 2, "cpu")
    path = model.default_path
    cycles = [0.05, 0.1, 0.5, 0.9, 1.1, 1.5, 2.5, 3.9]  # the first cycle's start too: nothing comes before it
    adv, _ = epm_positions(path, p, 2, cycles)
    rew, _ = epm_positions(replace(path, rewind=np.ones(1)), p, 2, cycles)
    w, d = np.asarray(path.wavelength), np.asarray(path.direction)
    for i, s in enumerate(cycles):
        shift = d * w * np.floor(s)  # (W,): how far the advancing path has gone beyond the first cycle's pass
        np.testing.assert_allclose(rew[i, :, 0], adv[i, :, 0] - shift, atol=2e-6)
        np.testing.assert_allclose(rew[i, :, 1:], adv[i, :, 1:], atol=1e-7)
    for later, first in ((4, 1), (5, 2), (6, 2), (7, 3)):  # the same phase in a later cycle: the same pose
        np.testing.assert_allclose(rew[later], rew[first], atol=2e-6)
    assert np.all(np.abs(adv[6, :, 0] - adv[2, :, 0]) > 0.04)  # (the advancing path has moved on 2 w = 48 mm)
    # the return, within 0.1 cycle of the far point, is continuous: no step larger than the fastest the cubic moves
    # (6.5 w per cycle: 0.8 w back in 0.2 cycle, slope 1 at both ends) over the 4 ms between samples
    fine = np.arange(0.86, 1.14 + 1e-9, 0.004)
    ret, _ = epm_positions(replace(path, rewind=np.ones(1)), p, 2, fine)
    steps = np.abs(np.diff(ret[:, :, 0], axis=0))
    assert steps.max() <= 6.6 * w.max() * 0.004, steps.max() / (w.max() * 0.004)
    np.testing.assert_allclose(ret[:, :, 2], epm_positions(path, p, 2, fine)[0][:, :, 2], atol=1e-7)
    assert d.tolist() == [1.0, -1.0]


def test_a_rewind_other_than_0_or_1_is_refused():
    from dataclasses import replace

    p = gaits.preset_params("omega")
    model = Model.from_params(p, 1, "cpu")
    with pytest.raises(ValueError, match=r"EpmPath.rewind.*0.5.*expected 0"):
        Simulator(model, dt=4e-3, substeps=2).set_path(replace(model.default_path, rewind=np.full(1, 0.5)))
