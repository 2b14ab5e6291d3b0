"""The implicit Warp substep against the independent NumPy implementation in tests/numpy_reference.py (float64),
and the kernel's dihedral angle and gradient against the crease module's NumPy versions and finite differences."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import warp as wp

from warpworm.physics import crease, gaits
from warpworm import quiet_warp
from warpworm.kernels import common
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator

quiet_warp()
sys.path.insert(0, str(Path(__file__).resolve().parent))
from numpy_reference import NumpyImplicit  # noqa: E402


@wp.kernel
def _dihedral_kernel(x: wp.array(dtype=wp.vec3), h: wp.array2d(dtype=wp.int32), ang: wp.array(dtype=float),
                     grad: wp.array2d(dtype=wp.vec3)):
    i = wp.tid()
    a, b, c, d = x[h[i, 0]], x[h[i, 1]], x[h[i, 2]], x[h[i, 3]]
    psi, g0, g1, g2, g3, n1, n2, len2 = common.dihedral_angle_gradient_and_normals(a, b, c, d)
    ang[i] = psi
    grad[i, 0] = g0
    grad[i, 1] = g1
    grad[i, 2] = g2
    grad[i, 3] = g3


@wp.kernel
def _atan2_kernel(y: wp.array(dtype=float), x: wp.array(dtype=float), out: wp.array(dtype=float)):
    i = wp.tid()
    out[i] = common.atan2_f32(y[i], x[i])


def test_inline_atan2_against_numpy_float64():
    """The crease angle's inline atan2 over every octant, magnitudes 1e-12 to 1e3 and the axes: within 2.8e-7 rad of
    NumPy's float64 atan2 of the same float32 inputs (NumPy's own float32 atan2 is off by up to 2.4e-7 here)."""
    rng = np.random.default_rng(0)
    n = 200_000
    ang = rng.uniform(-np.pi, np.pi, n)
    r = 10.0 ** rng.uniform(-12.0, 3.0, n)
    y, x = (r * np.sin(ang)).astype(np.float32), (r * np.cos(ang)).astype(np.float32)
    axes = np.array([[0, 1], [0, -1], [1, 0], [-1, 0], [1, 1], [-1, -1], [1e-30, 1], [2, -2e-30]], dtype=np.float32)
    y[:len(axes)], x[:len(axes)] = axes[:, 0], axes[:, 1]
    out = wp.zeros(n, dtype=float)
    wp.launch(_atan2_kernel, dim=n, inputs=[wp.array(y), wp.array(x)], outputs=[out])
    err = np.abs(out.numpy().astype(np.float64) - np.arctan2(y.astype(np.float64), x.astype(np.float64)))
    assert err.max() < 2.8e-7, (err.max(), y[err.argmax()], x[err.argmax()])


def test_dihedral_angle_and_gradient_against_finite_differences():
    pat = crease.build_worm(0.02, 0.008, 3, l0=0.04)
    rng = np.random.default_rng(1)
    x = pat.vertices + rng.normal(scale=1e-3, size=pat.vertices.shape)
    H = pat.num_hinges
    ang = wp.zeros(H, dtype=float)
    grad = wp.zeros((H, 4), dtype=wp.vec3)
    wp.launch(_dihedral_kernel, dim=H, inputs=[wp.array(x, dtype=wp.vec3), wp.array(pat.hinges, dtype=wp.int32)],
              outputs=[ang, grad])
    np.testing.assert_allclose(ang.numpy(), crease.dihedral_angles(x, pat.hinges), atol=1e-5)
    # central finite differences of the float64 angle
    eps = 1e-7
    fd = np.zeros((H, 4, 3))
    for c in range(4):
        for d in range(3):
            xp, xm = x.copy(), x.copy()
            rows = pat.hinges[:, c]
            # perturb one stencil vertex per hinge at a time (vertices are shared, so do it hinge by hinge in bulk)
            for hh in range(H):
                xp[rows[hh], d] += eps
                xm[rows[hh], d] -= eps
                fd[hh, c, d] = (crease.dihedral_angles(xp, pat.hinges[hh:hh + 1])[0]
                                - crease.dihedral_angles(xm, pat.hinges[hh:hh + 1])[0]) / (2 * eps)
                xp[rows[hh], d] -= eps
                xm[rows[hh], d] += eps
    g = grad.numpy()
    scale = np.abs(fd).max()
    assert np.abs(g - fd).max() < 1e-4 * scale, np.abs(g - fd).max() / scale


@pytest.mark.parametrize("kw, ref_newton", [
    ({"newton_tol": 0.0}, None),  # every step, as many as the reference takes
    ({}, 20),  # the default tolerance against the reference's fixed point
    # chord steps: their own code, the same answer. Their tolerance, 1e-5 m/s (5e-9 m at 0.5 ms): at 2e-6 m/s (1e-9 m,
    # under the float32 resolution of these iterates) no substep met it, all took the 40 steps, and x and x − x̃
    # drifted apart by rounding (v off by 2–3e-4 m/s); at 1e-5 every substep converges in ~2 (asserted below)
    ({"chord": True, "newton": 40, "newton_tol": 1e-5}, 20),
], ids=["same-steps", "tolerance", "chord"])
def test_warp_implicit_substeps_match_numpy_reference(kw, ref_newton):
    """10 implicit substeps of the kernel (one launch) against the NumPy dense-solve reference for worms off the
    floor: falling, magnets, crease damping, an anchor, three worlds with different EPM heights. Taking the
    reference's own steps, stopping at the tolerance, and chord steps (friction added to a gradient-only pass, the
    factor reused) all meet the reference iterated to its fixed point. Off the floor the iteration converges in two
    steps, so this checks the answer, not the speed of convergence (tests/test_newton_convergence.py does)."""
    p = gaits.preset_params("inchworm", hinge_damping=1e-4)
    W = 3
    p.closest_approach = np.array([0.06, 0.07, 0.08])
    model = Model.from_params(p, W, "cpu", anchors=[4], anchor_stiffness=50.0)
    sim = Simulator(model, dt=2e-3, substeps=4, **kw)
    state = sim.initial_state()
    lifted = state.positions.numpy() + np.array([0.0, 0.0, 0.03], np.float32)  # 3 cm up: no contact in the test
    state.positions.assign(lifted)
    sim.set_anchor_targets(lifted[:, [4]])
    sim.step(state, 3)  # get it moving: falling, magnets, creases
    sim.update_magnets(state)
    ref = NumpyImplicit(model, sim.dt_sub, newton=ref_newton or sim.newton)
    x, v, ang = ref.init(state, sim.control)
    x_start = x.copy()
    f = state.external_force.numpy().astype(np.float64)
    sim.newton_stats(reset=True)
    sim.run_substeps(state, 10)
    for _ in range(10):
        x, v, ang = ref.substep(x, v, ang, f)
    assert not state.unstable.numpy().any() and not state.contact.numpy().any()
    if kw.get("newton_tol", 1.0) > 0:
        assert not sim.newton_stats()["capped"].any()  # the tolerance, not the cap, ended every substep
    # float32 against float64 through a stiff solve (bars ~2000 N/m against m/dt² ~50 N/m: condition ~1e4, times
    # float32's 6e-8): agreement to ~1e-3 of the motion of these 10 substeps (measured 5e-4 in x, 6e-4 in v)
    moved = np.abs(x - x_start).max()
    assert np.abs(state.positions.numpy() - x).max() < 2e-3 * moved, (np.abs(state.positions.numpy() - x).max(), moved)
    dv = np.abs(state.velocities.numpy() - v).max()
    assert dv < 2e-3 * np.abs(v).max(), (dv, np.abs(v).max())
    assert np.abs(state.crease_angle.numpy() - ang).max() < 1e-4


def test_implicit_fold_through_limit_matches_numpy_and_pushes_back():
    """The NoFoldThrough limit (a one-sided spring k_lim L beyond the bound, k_lim = fold_limit_stiffness): relabel
    three mountain creases as valleys, so that their angle (≈ −67°, at rest) lies outside the valley range [0, π];
    the kernel and the NumPy reference then agree over 10 substeps, and the limit turns those creases toward 0 while
    without it (k_lim = 0) they stay at rest. (k_lim 0.3 N/rad here: the default makes the relabelled creases snap,
    a violent motion where two float precisions part ways.)"""
    turned = {}
    for ratio in (0.3, 0.0):
        p = gaits.preset_params("peristaltic", gravity=0.0, epm_moment=0.0, ipm_moment=np.zeros(3),
                                hinge_stiffness=0.3, fold_limit_stiffness=ratio)
        model = Model.from_params(p, 1, "cpu")
        labels = model.hinge_label.numpy()
        flip = np.flatnonzero(labels == crease.MOUNTAIN)[:3]
        labels[flip] = crease.VALLEY
        model.hinge_label.assign(labels)
        # the relabelled creases start 67° outside their range: switch the crumple detection off for this test
        sim = Simulator(model, dt=1e-3, substeps=1, fold_tolerance=10.0, newton_tol=0.0)
        state = sim.initial_state()
        lifted = state.positions.numpy() + np.array([0.0, 0.0, 0.03], np.float32)  # no floor contact
        state.positions.assign(lifted)
        ref = NumpyImplicit(model, sim.dt_sub, newton=sim.newton)
        ref.lo[flip], ref.hi[flip] = 0.0, np.pi
        x, v, ang = ref.init(state)
        a0 = ang[0, flip].copy()
        f = np.zeros_like(x)
        sim.run_substeps(state, 10)
        for _ in range(10):
            x, v, ang = ref.substep(x, v, ang, f)
        # small, slow motion (a few µm): measured 6e-9 m and 3e-6 rad apart; the limit's turn is ~1e-3 rad
        assert np.abs(state.positions.numpy() - x).max() < 1e-7, np.abs(state.positions.numpy() - x).max()
        assert np.abs(state.crease_angle.numpy() - ang).max() < 3e-5
        turned[ratio] = float(np.mean(state.crease_angle.numpy()[0, flip] - a0))
    assert turned[0.3] > 1e-3 and abs(turned[0.0]) < 1e-5, turned


@pytest.mark.parametrize("gait", ["inchworm", "peristaltic"])
def test_warp_gait_substeps_on_the_floor_match_numpy_reference(gait):
    """A whole gait substep on the floor, contacts and friction included: two worlds 0.12 s into a preset gait
    (magnets on, vertices sliding and stuck on the floor), 10 substeps of the kernel at its default tolerance and
    chord steps against the NumPy reference (tests/numpy_reference.py: its own floor code) iterated to its fixed
    point. The contact statuses agree vertex by vertex, and positions, velocities, crease angles and the floor's
    force (normal + friction) agree to small multiples of the float32 agreement measured."""
    p = gaits.preset_params(gait)
    model = Model.from_params(p, 2, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=4)
    state = sim.initial_state()
    sim.step(state, 60)
    sim.update_magnets(state)
    ref = NumpyImplicit(model, sim.dt_sub, newton=20, slip_speed=sim.settings.slip_speed)
    x, v, ang = ref.init(state, sim.control)
    start = np.bincount(ref.contact.ravel(), minlength=4)
    assert start[1] > 0 and start[2] > 0, start  # some vertices slide, some stick: both friction laws are compared
    x0 = x.copy()
    f = state.external_force.numpy().astype(np.float64)
    sim.run_substeps(state, 10)
    for _ in range(10):
        x, v, ang = ref.substep(x, v, ang, f)
    assert not state.unstable.numpy().any()
    assert np.array_equal(state.contact.numpy(), ref.contact)
    # measured (inchworm / peristaltic): x 1.0e-3 / 1.8e-3 of the motion (3.2e-5 / 1.2e-5 m), v 1.3e-3 / 7.6e-3 of
    # the fastest vertex, floor force 1.2e-3 / 0.9e-3 of the largest, angles 2.8e-6 / 2.2e-6 rad
    moved = np.abs(x - x0).max()
    assert np.abs(state.positions.numpy() - x).max() < 5e-3 * moved, (np.abs(state.positions.numpy() - x).max(), moved)
    dv = np.abs(state.velocities.numpy() - v).max()
    assert dv < 2e-2 * np.abs(v).max(), (dv, np.abs(v).max())
    dff = np.abs(state.floor_force.numpy() - ref.floor_force).max()
    assert dff < 5e-3 * np.abs(ref.floor_force).max(), (dff, np.abs(ref.floor_force).max())
    assert np.abs(state.crease_angle.numpy() - ang).max() < 1e-5


def test_reference_without_floor_is_the_floor_reference_off_the_floor():
    """The benchmark's ``floor=False`` reference (vectorised, no floor code) and the full one agree in float64 for a
    worm off the floor (5 substeps, measured to rounding), so the benchmark times the tested substep's work."""
    p = gaits.preset_params("inchworm", hinge_damping=1e-4, damping=2.0)
    model = Model.from_params(p, 2, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=4)
    state = sim.initial_state()
    state.positions.assign(state.positions.numpy() + np.array([0.0, 0.0, 0.03], np.float32))
    sim.step(state, 2)
    sim.update_magnets(state)
    f = state.external_force.numpy().astype(np.float64)
    out = []
    for floor in (True, False):
        ref = NumpyImplicit(model, sim.dt_sub, newton=4, floor=floor)
        x, v, a = ref.init(state, sim.control)
        for _ in range(5):
            x, v, a = ref.substep(x, v, a, f)
        out.append((x, v, a))
    for u, w in zip(*out):
        assert np.abs(u - w).max() <= 1e-12 * max(1.0, np.abs(u).max()), np.abs(u - w).max()
