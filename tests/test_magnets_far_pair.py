"""The far-field ring rule for cylinder pairs (kernels/magnet_far_pair.py) against independent truths:

- the rule's points reproduce the cylinder's geometric multipole moments <r^l P_l> (l = 2, 4, 6), integrated here
  numerically over the solid cylinder, and every odd and |m| < nphi moment vanishes;
- in the thin-disk limit the rule is two-point Gauss-Legendre in s = rho^2;
- the 'analytic' wrench with the rule agrees with the closed form (``far_field=False``, itself checked against
  magpylib in test_magnets_wrench.py) over random orientations at 4-20 circumscribing radii;
- Newton's third law holds for the rule (pairwise antisymmetric dipole sums);
- a cylinder with no valid rule (taller than wide) falls back to the closed form exactly.
"""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpworm.physics import magnets as mg
from warpworm.kernels import magnet_wrench
from warpworm.kernels.magnet_far_pair import (cylinder_ring_rule, far_cylinder_pair_wrench,
                                              far_cylinder_pair_wrench_lanes)

# compiled as the wrench kernel that runs the rules is (its SLP vectorizer flags), so the lanes are checked as run
wp.set_module_options({"cpu_compiler_flags": wp.get_module_options(magnet_wrench)["cpu_compiler_flags"]})


@wp.kernel
def _rule_kernel(radius: wp.array(dtype=float), height: wp.array(dtype=float), out: wp.array(dtype=wp.vec4)):
    i = wp.tid()
    out[i] = cylinder_ring_rule(radius[i], height[i])


def _rules(radius, height):
    r = wp.array(np.asarray(radius, np.float32), dtype=float, device="cpu")
    h = wp.array(np.asarray(height, np.float32), dtype=float, device="cpu")
    out = wp.zeros(len(r), dtype=wp.vec4, device="cpu")
    wp.launch(_rule_kernel, dim=len(r), inputs=[r, h], outputs=[out], device="cpu")
    return out.numpy().astype(np.float64)


def _legendre_moments(points, weights, lmax=7):
    """sum_i w_i r_i^l P_l^m-free check: returns <r^l P_l(cos theta)> for l = 0..lmax (axial, m = 0)."""
    x, y, z = points.T
    r = np.sqrt(x * x + y * y + z * z)
    cos = np.divide(z, r, out=np.zeros_like(z), where=r > 0)
    out = []
    for l in range(lmax + 1):
        coeff = np.zeros(l + 1)
        coeff[l] = 1.0
        out.append(np.sum(weights * r**l * np.polynomial.legendre.legval(cos, coeff)))
    return np.array(out)


def _cylinder_moments(radius, height, lmax=7, n=48):
    """<r^l P_l> of the solid cylinder by tensor Gauss quadrature in (s = rho^2, z, phi-free)."""
    xg, wg = np.polynomial.legendre.leggauss(n)
    s = 0.5 * (xg + 1.0) * radius**2
    z = 0.5 * height * xg
    S, Z = np.meshgrid(s, z)
    W = np.outer(0.5 * wg, 0.5 * wg)
    pts = np.stack([np.sqrt(S).ravel(), np.zeros(S.size), Z.ravel()], axis=1)
    return _legendre_moments(pts, W.ravel(), lmax)


def _ring_points(rule, nphi):
    rho1, rho2, w1, w2 = rule
    pts, wts = [], []
    for k, (rho, w) in enumerate(((rho1, w1), (rho2, w2))):
        phi = 2 * np.pi * (np.arange(nphi) + 0.5 * k) / nphi
        pts.append(np.stack([rho * np.cos(phi), rho * np.sin(phi), np.zeros(nphi)], axis=1))
        wts.append(np.full(nphi, w / nphi))
    return np.concatenate(pts), np.concatenate(wts)


@pytest.mark.parametrize("diameter,height", [(0.010, 0.001), (0.008, 0.0016), (0.012, 0.0005)])
def test_rule_matches_cylinder_moments(diameter, height):
    rule = _rules([diameter / 2], [height])[0]
    assert rule[2] > 0 and rule[3] > 0
    pts, wts = _ring_points(rule, 12)
    got = _legendre_moments(pts, wts)
    want = _cylinder_moments(diameter / 2, height)
    scale = (np.hypot(diameter / 2, height / 2)) ** np.arange(8)
    # l = 0..7: weights sum to one, odd moments vanish, l = 2, 4, 6 matched (float32 rule: ~1e-6 relative)
    np.testing.assert_allclose(got / scale, want / scale, atol=2e-6)
    # |m| = 1..nphi-1 moments of the point set vanish (azimuthal symmetry of the rings)
    phi = np.arctan2(pts[:, 1], pts[:, 0])
    rho = np.hypot(pts[:, 0], pts[:, 1])
    for m in range(1, 12):
        assert abs(np.sum(wts * rho**m * np.exp(1j * m * phi))) < 1e-9 * (diameter / 2) ** m


def test_thin_disk_limit_is_gauss_legendre_in_rho_squared():
    radius = 0.005
    rule = _rules([radius], [1e-7])[0]
    s_expected = radius**2 * (1 + np.array([-1, 1]) / np.sqrt(3)) / 2
    np.testing.assert_allclose(rule[:2] ** 2, s_expected, rtol=1e-5)
    np.testing.assert_allclose(rule[2:], [0.5, 0.5], atol=1e-6)


def test_tall_cylinder_has_no_rule_and_falls_back_to_closed_form():
    # mid-plane rings represent a positive moment measure only for disks up to height / diameter ~ 0.23
    rules = _rules([0.005, 0.005, 0.005, 0.001], [0.0022, 0.0025, 0.004, 0.010])
    assert rules[0, 2] > 0 and rules[0, 3] > 0
    assert np.all(rules[1:, 2] < 0)
    tall = mg.Cylinder(0.002, 0.010, moment=0.02)
    rng = np.random.default_rng(3)
    rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    rot *= np.sign(np.linalg.det(rot))
    pose_t = ((0.04, 0.01, -0.02), rot)
    a = mg.wrench(tall, tall, ((0, 0, 0), np.eye(3)), pose_t, far_field=True)
    b = mg.wrench(tall, tall, ((0, 0, 0), np.eye(3)), pose_t, far_field=False)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def _random_rotations(rng, n):
    """n random proper rotations (QR of Gaussian matrices, the determinant's sign folded in)."""
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    return q * np.sign(np.linalg.det(q))[:, None, None]


def _random_pairs(n, distance, seed):
    rng = np.random.default_rng(seed)
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1)[:, None]
    q = _random_rotations(rng, 2 * n)
    return dirs * distance, q[:n], q[n:]


@pytest.mark.parametrize("diameter,height", [(0.010, 0.001), (0.006, 0.0012)])
@pytest.mark.parametrize("radii", [4.0, 5.0, 7.5, 11.0, 20.0])
def test_far_rule_agrees_with_closed_form(diameter, height, radii):
    reach = np.hypot(diameter / 2, height / 2)
    src = mg.Cylinder(diameter, height, moment=0.07)
    tgt = mg.Cylinder(diameter, height, moment=0.05)
    pos, rs, rt = _random_pairs(200, radii * reach * 1.0001, seed=int(radii * 10))
    zero = np.zeros_like(pos)
    f_far, t_far = mg.wrench(src, tgt, (zero, rs), (pos, rt), far_field=True)
    f_cf, t_cf = mg.wrench(src, tgt, (zero, rs), (pos, rt), far_field=False)
    assert not np.array_equal(f_far, f_cf)  # the rule is in use at these distances
    f_scale = np.linalg.norm(f_cf, axis=1).max()
    t_scale = np.linalg.norm(t_cf, axis=1).max()
    # measured (500 orientations): 7.8e-6 / 7.0e-6 of the largest force / torque at 4 radii, 3.5e-6 at 11, <= 1.3e-6
    # elsewhere; the bound leaves 2.5x
    assert np.abs(f_far - f_cf).max() <= 2e-5 * f_scale
    assert np.abs(t_far - t_cf).max() <= 2e-5 * t_scale


@wp.kernel
def _pair_rule_kernel(lanes: int, t_rel: wp.array(dtype=wp.vec3), r_rel: wp.array(dtype=wp.mat33), nphi: int,
                      s_rule: wp.vec4, s_m: wp.vec3, t_rule: wp.vec4, t_m: wp.vec3, force: wp.array(dtype=wp.vec3),
                      torque: wp.array(dtype=wp.vec3)):
    i = wp.tid()
    if lanes != 0:
        f, t = far_cylinder_pair_wrench_lanes(s_rule, s_m, t_rule, t_m, r_rel[i], t_rel[i], nphi)
    else:
        f, t = far_cylinder_pair_wrench(s_rule, s_m, t_rule, t_m, r_rel[i], t_rel[i], nphi)
    force[i] = f
    torque[i] = t


@pytest.mark.parametrize("nphi", [6, 8, 12, 16])
def test_far_rule_in_lanes_is_the_scalar_rule_bit_for_bit(nphi):
    """far_cylinder_pair_wrench_lanes (8 target points at a time, what the wrench kernel runs) gives the scalar
    ring rule's numbers to the last bit: 2 nphi = 12, 16, 24, 32 target points (12 and 24 leave lanes unused);
    two different cylinders, so a source and target rule mixed up shows."""
    pos, rs, rt = _random_pairs(64, 0.03, seed=nphi)
    t_rel = np.einsum("nji,nj->ni", rs, pos)  # the target's centre in the source's frame
    r_rel = np.einsum("nji,njk->nik", rs, rt)
    s_rule, t_rule = (wp.vec4(*r.astype(np.float32)) for r in _rules([0.005, 0.003], [0.001, 0.0012]))
    out = []
    for lanes in (0, 1):
        force = wp.zeros(len(pos), dtype=wp.vec3, device="cpu")
        torque = wp.zeros(len(pos), dtype=wp.vec3, device="cpu")
        wp.launch(_pair_rule_kernel, dim=len(pos), device="cpu",
                  inputs=[lanes, wp.array(t_rel.astype(np.float32), dtype=wp.vec3, device="cpu"),
                          wp.array(r_rel.astype(np.float32), dtype=wp.mat33, device="cpu"), nphi, s_rule,
                          wp.vec3(0.0, 0.0, 0.07), t_rule, wp.vec3(0.01, -0.02, 0.05), force, torque])
        out.append((force.numpy(), torque.numpy()))
    assert np.abs(out[0][0]).max() > 0.0
    np.testing.assert_array_equal(out[1][0], out[0][0])
    np.testing.assert_array_equal(out[1][1], out[0][1])


def test_far_rule_inside_limit_is_closed_form():
    src = mg.Cylinder(0.010, 0.001, moment=0.07)
    pos, rs, rt = _random_pairs(20, 0.019, seed=1)  # 3.78 circumscribing radii
    zero = np.zeros_like(pos)
    a = mg.wrench(src, src, (zero, rs), (pos, rt), far_field=True)
    b = mg.wrench(src, src, (zero, rs), (pos, rt), far_field=False)
    np.testing.assert_array_equal(a[0], b[0])


def _assert_pair_balances(on_second, on_first, pos, rtol):
    """Newton's third law and the pair's angular momentum, to ``rtol`` of the largest force / torque: (F, T) on the
    second magnet of a pair (at ``pos``, the first at the origin) and on the first, torques about each centre."""
    f_on_t, t_on_t = on_second
    f_on_s, t_on_s = on_first
    np.testing.assert_allclose(f_on_t, -f_on_s, atol=rtol * np.linalg.norm(f_on_t, axis=1).max())
    # angular momentum: torques about the two centres plus the lever of the force balance out
    total = t_on_t + t_on_s + np.cross(pos, f_on_t)
    np.testing.assert_allclose(total, 0.0, atol=rtol * np.linalg.norm(t_on_t, axis=1).max())


def test_far_rule_newtons_third_law():
    src = mg.Cylinder(0.010, 0.001, moment=0.07)
    tgt = mg.Cylinder(0.008, 0.0015, moment=0.03)
    pos, rs, rt = _random_pairs(50, 0.045, seed=7)
    zero = np.zeros_like(pos)
    _assert_pair_balances(mg.wrench(src, tgt, (zero, rs), (pos, rt)), mg.wrench(tgt, src, (pos, rt), (zero, rs)),
                          pos, 1e-5)


def test_world_wrench_of_a_worm_with_the_rule_matches_the_closed_form():
    """The three IPMs of a worm (10 x 1 mm disks on the axis, moments tail -x, centre +x, head -x) in 16 random
    deformed poses (spacings 20-48 mm, tilts up to 30 degrees): the world wrench kernel's net IPM forces and torques
    with the ring rule (4-12 radii: all three point counts) agree with the closed form's (measured 4.7e-7 / 1.4e-6 of the
    largest force / torque)."""
    rng = np.random.default_rng(11)
    ipm = mg.Cylinder(0.010, 0.001, moment=0.0707)
    W = 16
    spacing = rng.uniform(0.020, 0.048, size=(W, 2))
    x = np.concatenate([np.zeros((W, 1)), np.cumsum(spacing, axis=1)], axis=1)
    pos = np.stack([x, rng.uniform(-3e-3, 3e-3, (W, 3)), rng.uniform(0.0, 0.01, (W, 3))], axis=-1)
    base = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], dtype=np.float64)  # own +z (the moment) along world +x
    rot = np.empty((W, 3, 3, 3))
    for w in range(W):
        for i, sign in enumerate((-1, 1, -1)):
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            ang = np.radians(rng.uniform(0, 30))
            k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
            tilt = np.eye(3) + np.sin(ang) * k + (1 - np.cos(ang)) * k @ k
            flip = np.diag([1.0, 1.0, 1.0]) if sign > 0 else np.diag([-1.0, 1.0, -1.0])  # turn the moment to -x
            rot[w, i] = tilt @ base @ flip
    f_far, t_far = mg.world_wrenches([ipm] * 3, pos, rot, far_field=True)
    f_cf, t_cf = mg.world_wrenches([ipm] * 3, pos, rot, far_field=False)
    assert not np.array_equal(f_far, f_cf)
    # a few times what this set measures (4.7e-7 / 1.4e-6); the single-pair bound above (2e-5) covers every orientation
    assert np.abs(f_far - f_cf).max() <= 5e-6 * np.linalg.norm(f_cf, axis=-1).max()
    assert np.abs(t_far - t_cf).max() <= 5e-6 * np.linalg.norm(t_cf, axis=-1).max()


# ----------------------------------------------------------------------------------------------------------------------
# A cuboid (the EPM) and a far cylinder (an IPM): the cuboid's face charges in the cylinder's ring field
# ----------------------------------------------------------------------------------------------------------------------

def _ipm_near_cuboid(n, size, gap, seed):
    """n random poses of a cylinder whose centre is ``gap`` [m] off a random point of a random face of a cuboid of
    ``size`` at the origin (turned at random): (cuboid rotations, cylinder positions, cylinder rotations)."""
    rng = np.random.default_rng(seed)
    half = np.asarray(size) / 2
    local = rng.uniform(-1.0, 1.0, (n, 3)) * half
    axis, sign = rng.integers(0, 3, n), rng.choice([-1.0, 1.0], n)
    local[np.arange(n), axis] = sign * (half[axis] + gap)
    q = _random_rotations(rng, 2 * n)
    return q[:n], np.einsum("nij,nj->ni", q[:n], local), q[n:]


@pytest.mark.parametrize("ipm_moment", [(0.0, 0.0, 0.0707), (0.04, -0.02, 0.05)], ids=["axial", "oblique"])
@pytest.mark.parametrize("gap_mm", [12.6, 15.0, 20.1, 30.0, 40.0, 60.0])
def test_cuboid_cylinder_rule_agrees_with_closed_form(gap_mm, ipm_moment):
    """The paper's EPM (10 x 10 x 40 mm, 3.6 A m^2) and an IPM (10 x 1 mm; axial, and oblique: the rule's points stand
    for the shape, whatever the magnetization) from 2.5 to 12 of the IPM's circumscribing radii: both directions of
    the pair (the EPM's wrench on the IPM by reciprocity, and the IPM's on the EPM) agree with the closed form
    (measured over 400 poses at each gap, both moments: <= 2.3e-6 of the largest force and <= 5.1e-6 of the largest
    torque, the latter the IPM's on the EPM at 4 radii). The bound leaves 2x."""
    epm = mg.Cuboid((0.01, 0.01, 0.04), (0.0, 0.0, 3.6))
    ipm = mg.Cylinder(0.010, 0.001, moment=ipm_moment)
    re, pos, ri = _ipm_near_cuboid(150, (0.01, 0.01, 0.04), gap_mm * 1e-3, seed=int(gap_mm * 10))
    zero = np.zeros_like(pos)
    for src, tgt, sp, tp in ((epm, ipm, (zero, re), (pos, ri)), (ipm, epm, (pos, ri), (zero, re))):
        f_far, t_far = mg.wrench(src, tgt, sp, tp, far_field=True)
        f_cf, t_cf = mg.wrench(src, tgt, sp, tp, far_field=False)
        assert not np.array_equal(f_far, f_cf)  # the rule is in use at this gap
        assert np.abs(f_far - f_cf).max() <= 1e-5 * np.linalg.norm(f_cf, axis=1).max()
        assert np.abs(t_far - t_cf).max() <= 1e-5 * np.linalg.norm(t_cf, axis=1).max()


def test_cuboid_cylinder_rule_inside_its_limit_is_closed_form():
    """Closer than 2.5 circumscribing radii of the cylinder (12.56 mm for the IPM), the closed form, bit for bit."""
    epm = mg.Cuboid((0.01, 0.01, 0.04), (0.0, 0.0, 3.6))
    ipm = mg.Cylinder(0.010, 0.001, moment=0.0707)
    re, pos, ri = _ipm_near_cuboid(40, (0.01, 0.01, 0.04), 0.0124, seed=3)
    zero = np.zeros_like(pos)
    a = mg.wrench(epm, ipm, (zero, re), (pos, ri), far_field=True)
    b = mg.wrench(epm, ipm, (zero, re), (pos, ri), far_field=False)
    np.testing.assert_array_equal(a[0], b[0])
    np.testing.assert_array_equal(a[1], b[1])


def test_cuboid_cylinder_rule_newtons_third_law():
    """The EPM's wrench on the IPM (by reciprocity) and the IPM's on the EPM (directly) are two evaluations of the same
    face integral: their forces cancel and the pair's angular momentum balances, to float32 rounding."""
    epm = mg.Cuboid((0.012, 0.01, 0.03), (0.5, 0.0, 2.0))
    ipm = mg.Cylinder(0.008, 0.0015, moment=(0.01, 0.0, 0.05))
    re, pos, ri = _ipm_near_cuboid(60, (0.012, 0.01, 0.03), 0.025, seed=5)
    zero = np.zeros_like(pos)
    _assert_pair_balances(mg.wrench(epm, ipm, (zero, re), (pos, ri)), mg.wrench(ipm, epm, (pos, ri), (zero, re)),
                          pos, 1e-6)
