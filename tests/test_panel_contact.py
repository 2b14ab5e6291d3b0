"""The panels' contact barrier of a hinge wing (kernels.common.wing_contact) against its definition: the energy
½ κ q², q = |(p1 − p0) × (p2 − p0)| − A |p1 − p2|² while q < 0, differentiated numerically in float64."""

from __future__ import annotations

import numpy as np
import warp as wp

from warpworm import quiet_warp
from warpworm.kernels import common

quiet_warp()

A = float(common.PANEL_CONTACT_ALTITUDE)
EA = float(common.PANEL_CONTACT_EA)


@wp.kernel
def _wing_contact_kernel(p: wp.array2d(dtype=wp.vec3), lh: wp.array(dtype=float), f: wp.array(dtype=float),
                         g: wp.array2d(dtype=wp.vec3), kappa: wp.array(dtype=float)):
    i = wp.tid()
    fi, g0, g1, g2, ki = common.wing_contact(p[i, 0], p[i, 1], p[i, 2], lh[i])
    f[i] = fi
    g[i, 0] = g0
    g[i, 1] = g1
    g[i, 2] = g2
    kappa[i] = ki


def _energy(p, lh):
    """½ κ q² (q < 0), float64, from the definition."""
    q = np.linalg.norm(np.cross(p[1] - p[0], p[2] - p[0])) - A * np.sum((p[1] - p[2]) ** 2)
    return 0.5 * EA / lh ** 3 * min(q, 0.0) ** 2


def _wings(rng, n):
    """Hinges of 5–15 mm along random directions, tips at 0.2–4 % of the hinge length from it: both sides of 2 %."""
    out, lhs = [], []
    for _ in range(n):
        length = rng.uniform(0.005, 0.015)
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        side = np.cross(axis, rng.normal(size=3))
        side /= np.linalg.norm(side)
        p1 = rng.normal(scale=0.01, size=3)
        p2 = p1 - axis * length
        p0 = p1 - axis * length * rng.uniform(0.2, 0.8) + side * length * rng.uniform(0.002, 0.04)
        out.append([p0, p1, p2])
        lhs.append(length * rng.uniform(0.9, 1.1))  # the rest length differs from the current one
    return np.array(out), np.array(lhs)


def test_wing_contact_gradient_is_the_energy_derivative():
    rng = np.random.default_rng(7)
    p, lh = _wings(rng, 64)
    n = len(p)
    f = wp.zeros(n, dtype=float)
    g = wp.zeros((n, 3), dtype=wp.vec3)
    kappa = wp.zeros(n, dtype=float)
    wp.launch(_wing_contact_kernel, dim=n, inputs=[wp.array(p.astype(np.float32), dtype=wp.vec3),
                                                   wp.array(lh.astype(np.float32), dtype=float)],
              outputs=[f, g, kappa], device="cpu")
    f, g, kappa = f.numpy(), g.numpy(), kappa.numpy()
    active = 0
    for i in range(n):
        q = np.linalg.norm(np.cross(p[i, 1] - p[i, 0], p[i, 2] - p[i, 0])) - A * np.sum((p[i, 1] - p[i, 2]) ** 2)
        if q >= 0.0:
            assert kappa[i] == 0.0 and f[i] == 0.0 and not g[i].any()  # clear: no force, no stiffness
            continue
        active += 1
        assert abs(kappa[i] - EA / lh[i] ** 3) < 1e-5 * EA / lh[i] ** 3
        h = 1e-9
        for a in range(3):
            for c in range(3):
                dp = np.zeros_like(p[i])
                dp[a, c] = h
                numeric = (_energy(p[i] + dp, lh[i]) - _energy(p[i] - dp, lh[i])) / (2 * h)
                analytic = f[i] * g[i, a, c]  # ∂E/∂p = κ q ∂q/∂p
                scale = np.abs(f[i]) * np.abs(g[i]).max()
                # float32 through q, a difference that cancels near the threshold: 7.4e-5 measured
                assert abs(analytic - numeric) < 3e-4 * scale, (i, a, c, analytic, numeric)
    assert 16 <= active <= n - 16  # both sides of the threshold were drawn
