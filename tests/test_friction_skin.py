"""Friction that differs by direction (kernels.floor_contact.friction_force with ``mu_back`` ≠ 1) against its
definition: the force is −∇D and the stiffness is D's Hessian, for the dissipation D = mu_k F_n |v| g(θ) sliding and
(mu_s F_n / 2ε) |v|² g(θ) stuck, g(θ) = 1 + (r − 1) S((1 − cos θ) / 2), S(w) = 3w² − 2w³, θ the angle of v from the
head-ward tangent; D is differentiated numerically in float64 here. And g's own limits: 1 head-ward, r tail-ward,
(1 + r) / 2 sideways, and the isotropic law unchanged at r = 1."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpworm import quiet_warp
from warpworm.kernels import floor_contact as fc

quiet_warp()

MU_S, MU_K, FN, EPS = 0.268, 0.24, 0.02, 1.0e-5
BETA = 0.2  # a tilted floor: its head-ward tangent and normal are not the world axes
N = np.array([-np.sin(BETA), 0.0, np.cos(BETA)])
FWD = np.array([np.cos(BETA), 0.0, np.sin(BETA)])
LAT = np.cross(N, FWD)


@wp.kernel
def _friction_kernel(status: int, vt: wp.array(dtype=wp.vec3), mu_back: float, fwd: wp.vec3, n: wp.vec3,
                     f: wp.array(dtype=wp.vec3), k: wp.array(dtype=wp.mat33)):
    i = wp.tid()
    fi, kf, t, ks = fc.friction_force(status, vt[i], FN, MU_S, MU_K, mu_back, fwd, n, EPS)
    f[i] = fi
    k[i] = (wp.identity(n=3, dtype=float) - wp.outer(n, n) - wp.outer(t, t)) * kf + ks


def _friction(status: int, v: np.ndarray, r: float):
    m = len(v)
    f = wp.zeros(m, dtype=wp.vec3)
    k = wp.zeros(m, dtype=wp.mat33)
    wp.launch(_friction_kernel, dim=m, inputs=[status, wp.array(v.astype(np.float32), dtype=wp.vec3), r,
                                                wp.vec3(*FWD), wp.vec3(*N), f, k])
    return f.numpy().astype(np.float64), k.numpy().astype(np.float64)


def _g(v, r):
    c = (v @ FWD) / np.linalg.norm(v)
    w = 0.5 * (1.0 - c)
    return 1.0 + (r - 1.0) * w * w * (3.0 - 2.0 * w)


def _dissipation(status, v, r):
    speed = np.linalg.norm(v)
    if status == int(fc.CONTACT_STUCK):
        return MU_S * FN / (2.0 * EPS) * speed ** 2 * _g(v, r)
    return MU_K * FN * speed * _g(v, r)


def _velocities(rng, m, scale):
    """Tangential velocities at angles all round the floor, of speed ``scale`` × (0.3–3)."""
    th = rng.uniform(0.0, 2.0 * np.pi, m)
    sp = scale * rng.uniform(0.3, 3.0, m)
    return (np.cos(th)[:, None] * FWD + np.sin(th)[:, None] * LAT) * sp[:, None]


@pytest.mark.parametrize("r", [0.5, 2.0, 3.0])
@pytest.mark.parametrize("status, scale", [(int(fc.CONTACT_SLIDING), 1e-3), (int(fc.CONTACT_STUCK), 1e-5)],
                         ids=["sliding", "stuck"])
def test_skin_friction_is_minus_the_gradient_of_its_dissipation_with_its_hessian(status, scale, r):
    rng = np.random.default_rng(3)
    v = _velocities(rng, 48, scale)
    f, k = _friction(status, v, r)
    h = 1e-4 * scale
    basis = np.stack([FWD, LAT])

    def grad_at(x):  # D's in-plane gradient (components along FWD, LAT), float64 central differences
        return np.array([(_dissipation(status, x + h * e, r) - _dissipation(status, x - h * e, r)) / (2 * h)
                         for e in basis])

    for i in range(len(v)):
        grad = basis.T @ grad_at(v[i])
        hess = sum(np.outer(basis.T @ ((grad_at(v[i] + h * e) - grad_at(v[i] - h * e)) / (2 * h)), e) for e in basis)
        fmag = np.linalg.norm(grad)
        np.testing.assert_allclose(f[i], -grad, atol=2e-4 * fmag, err_msg=f"v {v[i]}")
        kp = basis @ k[i] @ basis.T  # the stiffness on the floor's plane
        hp = basis @ hess @ basis.T
        np.testing.assert_allclose(kp, hp, atol=2e-3 * np.abs(hp).max(), err_msg=f"v {v[i]}")
        assert np.allclose(k[i], k[i].T, atol=1e-6 * np.abs(k[i]).max())
        assert np.linalg.eigvalsh(0.5 * (kp + kp.T)).min() >= -1e-6 * np.abs(kp).max()  # PSD
        np.testing.assert_allclose(k[i] @ N, 0.0, atol=1e-6 * np.abs(k[i]).max())  # nothing off the plane


@pytest.mark.parametrize("r", [0.5, 2.0, 3.0])
def test_skin_scales_the_friction_head_ward_by_1_tail_ward_by_r_sideways_by_the_mean(r):
    """Sliding straight head-ward, tail-ward and sideways: |f| = mu_k F_n × (1, r, (1 + r) / 2), along −v except
    sideways, where maximal dissipation also pushes the slide toward the easier direction."""
    v = np.stack([FWD, -FWD, LAT]) * 1e-3
    f, _ = _friction(int(fc.CONTACT_SLIDING), v, r)
    np.testing.assert_allclose(f[0], -MU_K * FN * FWD, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(f[1], MU_K * FN * r * FWD, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(f[2] @ LAT, -MU_K * FN * 0.5 * (1.0 + r), rtol=1e-5)
    # g'(π/2) = (r − 1) S'(½) / 2 = 0.75 (r − 1): the sideways slide is pushed head-ward for r > 1 (tail-ward r < 1)
    np.testing.assert_allclose(f[2] @ FWD, MU_K * FN * 0.75 * (r - 1.0), rtol=1e-4, atol=1e-9)


def test_isotropic_friction_is_the_coulomb_law():
    """r = 1: the kinetic force is −mu_k F_n v / |v| and the static one −(mu_s F_n / ε) v, whatever the direction,
    and no extra stiffness: the paper's friction, as before the skin existed."""
    rng = np.random.default_rng(5)
    v = _velocities(rng, 16, 1e-3)
    f, _ = _friction(int(fc.CONTACT_SLIDING), v, 1.0)
    np.testing.assert_allclose(f, -MU_K * FN * v / np.linalg.norm(v, axis=1, keepdims=True), rtol=1e-5, atol=1e-10)
    vs = _velocities(rng, 16, 1e-5)
    f, _ = _friction(int(fc.CONTACT_STUCK), vs, 1.0)
    np.testing.assert_allclose(f, -MU_S * FN / EPS * vs, rtol=1e-5, atol=1e-10)


def test_isotropic_friction_adds_no_skin_stiffness_and_a_held_vertex_at_rest_gets_the_mean():
    """r = 1: the stiffness is the isotropic one alone (mu_k F_n / |v| across a slide, mu_s F_n / ε held). r ≠ 1 and a
    held vertex exactly at rest (every one at a substep's start): no force, and D's Hessian, which has no value at
    v = 0, taken as the mean of head-ward and tail-ward, c0 (1 + r) / 2 on the plane."""
    v = np.stack([FWD, LAT]) * 1e-3
    _, k = _friction(int(fc.CONTACT_SLIDING), v, 1.0)
    for i in range(2):
        u = v[i] / np.linalg.norm(v[i])
        np.testing.assert_allclose(k[i], MU_K * FN / 1e-3 * (np.eye(3) - np.outer(N, N) - np.outer(u, u)),
                                   rtol=1e-5, atol=1e-6)
    _, k = _friction(int(fc.CONTACT_STUCK), v * 1e-2, 1.0)
    np.testing.assert_allclose(k, np.broadcast_to(MU_S * FN / EPS * (np.eye(3) - np.outer(N, N)), k.shape),
                               rtol=1e-5, atol=1e-3)
    f, k = _friction(int(fc.CONTACT_STUCK), np.zeros((1, 3)), 3.0)
    np.testing.assert_array_equal(f, 0.0)
    np.testing.assert_allclose(k[0], MU_S * FN / EPS * 2.0 * (np.eye(3) - np.outer(N, N)), rtol=1e-5, atol=1e-3)
