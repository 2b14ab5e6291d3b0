"""Far-field wrench between two uniformly magnetized cylinders by a multipole-matched ring rule.

Outside its circumscribing sphere, a uniformly magnetized body's field is that of the gradient of its shape's
Newtonian potential, so it is fixed by the shape's geometric multipole moments ⟨r^l P_l(cos ϑ)⟩ (all l, m). A set
of point dipoles whose positions reproduce those moments up to degree L gives the exterior field, and by
reciprocity the force and torque on a second such body, with a relative error of order (a / r)^(L+2) (a the
circumscribing radius, r the centre distance). The cylinder's rule here: two rings in its mid-plane (z = 0, which
kills every odd moment), radii² s₁, s₂ and weights w₁, w₂ the two-point Gauss rule of the measure whose first
moments are the cylinder's ⟨s⟩, ⟨s²⟩, ⟨s³⟩ *as seen by* l = 2, 4, 6 (s = ρ²; the axial extent folded in:
for points at z = 0, ⟨r²P₂⟩ = −⟨s⟩/2, ⟨r⁴P₄⟩ = 3⟨s²⟩/8, ⟨r⁶P₆⟩ = −5⟨s³⟩/16). So every m = 0 moment up to
l = 7 is exact; ``nphi`` equally spaced points per ring (the second ring turned by half a step) leave the first
azimuthal moment at |m| = nphi, which sets the accuracy at a given distance (:func:`ring_points_for_distance`).
Such a rule exists (a positive measure on s ≥ 0) for disks up to height / diameter ≈ 0.23; a thicker cylinder keeps
the closed form at every distance.

Why: the closed-form cylinder field needs complete elliptic integrals at each of ~100 surface-charge points; the
IPM–IPM pairs of a worm (disks 10 × 1 mm, 20–80 mm apart) were ~60 % of the analytic wrench. The ring rule costs
(2·nphi)² float32 dipole pairs (~4.5 µs per IPM pair against 14.5 µs for the closed form) and agrees with
the closed form to 8e-6 of the largest force and torque where it is used
(``tests/test_magnets_far_pair.py``; docs/magnets.md has the table).
"""

from __future__ import annotations

import warp as wp

from .magnet_fields import CYL_PI, F64_0, F64_1, SHAPE_CYLINDER, dipole_pair_force_field

NEAR_LIMIT = wp.constant(4.0)
"""Below this many circumscribing radii (of the larger magnet) the closed form is used."""


@wp.func
def cylinder_ring_rule(radius: float, height: float) -> wp.vec4:
    """(ρ₁, ρ₂, w₁, w₂) of the two-ring rule of a cylinder of ``radius`` and ``height`` [m]; w₁ < 0 when no such
    rule exists (a cylinder much taller than wide): the caller must then use the closed form.

    Moments of the uniform cylinder (R radius, c half height), in closed form:
    ⟨s⟩ = R²/2 − 2c²/3, ⟨s²⟩ = R⁴/3 − 4R²c²/3 + 8c⁴/15, ⟨s³⟩ = R⁶/4 − 2R⁴c² + 12R²c⁴/5 − 16c⁶/35.
    """
    r2 = wp.float64(radius) * wp.float64(radius)
    c = wp.float64(0.5) * wp.float64(height)
    c2 = c * c
    a = r2 / wp.float64(2.0) - wp.float64(2.0) * c2 / wp.float64(3.0)
    b = r2 * r2 / wp.float64(3.0) - wp.float64(4.0) * r2 * c2 / wp.float64(3.0) + wp.float64(8.0) * c2 * c2 / wp.float64(15.0)
    g = (
        r2 * r2 * r2 / wp.float64(4.0)
        - wp.float64(2.0) * r2 * r2 * c2
        + wp.float64(12.0) * r2 * c2 * c2 / wp.float64(5.0)
        - wp.float64(16.0) * c2 * c2 * c2 / wp.float64(35.0)
    )
    var = b - a * a
    invalid = wp.vec4(0.0, 0.0, -1.0, -1.0)
    if var <= F64_0:
        return invalid
    # monic p(s) = s² + k1 s + k0 orthogonal to 1 and s under the moments (1, a, b, g)
    k1 = (a * b - g) / var
    k0 = -b - k1 * a
    disc = k1 * k1 - wp.float64(4.0) * k0
    if disc <= F64_0:
        return invalid
    root = wp.sqrt(disc)
    s1 = wp.float64(0.5) * (-k1 - root)
    s2 = wp.float64(0.5) * (-k1 + root)
    if s1 < F64_0:
        return invalid
    w2 = (a - s1) / (s2 - s1)
    w1 = F64_1 - w2
    if w1 <= F64_0 or w2 <= F64_0:
        return invalid
    return wp.vec4(float(wp.sqrt(s1)), float(wp.sqrt(s2)), float(w1), float(w2))


@wp.func
def ring_points_for_distance(distance: float, reach: float) -> int:
    """Points per ring for a pair whose centres are ``distance`` apart, ``reach`` [m] the larger circumscribing
    radius; 0 = too close for the rule (use the closed form).

    Measured against the closed form over 500 random orientations of two 10 × 1 mm disks (largest force error over
    the largest |F| of the set): 12 points 7.8e-6 at 4 radii and 5.6e-7 at 5; 8 points 1.3e-6 at 7; 6 points
    3.5e-6 at 11. The largest error over a sample's own |F| is ~2.5× these (1.9e-5 at 4 and at 11 radii). Fewer
    points closer in lose accuracy fast (8 points at 6 radii: 2.6e-5 of a sample's own force).
    """
    q = distance / reach
    if q >= 11.0:
        return 6
    if q >= 7.0:
        return 8
    if q >= NEAR_LIMIT:
        return 12
    return 0


@wp.func
def far_pair_rules(s_shape: int, s_size: wp.vec3, t_shape: int, t_size: wp.vec3, distance: float):
    """Whether a pair takes the ring rule: (nphi, source rule, target rule), nphi = 0 when it does not (not two
    cylinders, closer than :data:`NEAR_LIMIT` circumscribing radii of the larger, or a cylinder with no rule).
    Sizes are (d, d, h) [m]; ``distance`` between the centres [m]."""
    none = wp.vec4(0.0)
    if s_shape != SHAPE_CYLINDER or t_shape != SHAPE_CYLINDER:
        return 0, none, none
    s_radius = 0.5 * s_size[0]
    t_radius = 0.5 * t_size[0]
    reach = wp.sqrt(wp.max(s_radius * s_radius + 0.25 * s_size[2] * s_size[2],
                           t_radius * t_radius + 0.25 * t_size[2] * t_size[2]))
    nphi = ring_points_for_distance(distance, reach)
    if nphi == 0:
        return 0, none, none
    s_rule = cylinder_ring_rule(s_radius, s_size[2])
    t_rule = cylinder_ring_rule(t_radius, t_size[2])
    if s_rule[2] <= 0.0 or t_rule[2] <= 0.0:
        return 0, none, none
    return nphi, s_rule, t_rule


@wp.func
def ring_point(p: int, nphi: int, cs: wp.vec2, step: wp.vec2, half: wp.vec2) -> wp.vec2:
    """(cos, sin) of point ``p`` (0 … 2·nphi − 1; ring p // nphi) of the two rings, from ``cs``, that of point p − 1:
    ring 0 starts at angle 0, ring 1 half a step (``half``) on, so that its |m| = nphi azimuthal moment partly cancels
    ring 0's; along a ring each point is the last turned by ``step`` (a complex product: no trig per point)."""
    if p == 0:
        return wp.vec2(1.0, 0.0)
    if p == nphi:
        return half
    return wp.vec2(cs[0] * step[0] - cs[1] * step[1], cs[1] * step[0] + cs[0] * step[1])


@wp.func
def far_cylinder_pair_wrench(
    s_rule: wp.vec4,
    s_m: wp.vec3,
    t_rule: wp.vec4,
    t_m: wp.vec3,
    r_rel: wp.mat33,
    t_rel: wp.vec3,
    nphi: int,
):
    """Force [N] on the target and torque [N·m] about its centre, in the source's frame, by the ring rules.

    Args:
        s_rule, t_rule: :func:`cylinder_ring_rule` of source and target (valid).
        s_m: source moment [A·m²], source frame; t_m: target moment [A·m²], target frame.
        r_rel: target frame -> source frame; t_rel: target centre in the source frame [m].
        nphi: points per ring (:func:`ring_points_for_distance`).
    """
    dphi = 2.0 * CYL_PI / float(nphi)
    step = wp.vec2(wp.cos(dphi), wp.sin(dphi))
    half = wp.vec2(wp.cos(0.5 * dphi), wp.sin(0.5 * dphi))
    inv_n = 1.0 / float(nphi)
    mt_dir = r_rel * t_m
    ax = wp.vec3(r_rel[0, 0], r_rel[1, 0], r_rel[2, 0])
    ay = wp.vec3(r_rel[0, 1], r_rel[1, 1], r_rel[2, 1])
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    ct = wp.vec2(1.0, 0.0)
    for tp in range(2 * nphi):
        ct = ring_point(tp, nphi, ct, step, half)
        tk = tp // nphi
        lever = (ax * ct[0] + ay * ct[1]) * t_rule[tk]
        mt = mt_dir * (t_rule[2 + tk] * inv_n)
        pt = t_rel + lever
        f = wp.vec3(0.0)
        b = wp.vec3(0.0)
        cs = wp.vec2(1.0, 0.0)
        for sp in range(2 * nphi):
            cs = ring_point(sp, nphi, cs, step, half)
            sk = sp // nphi
            ff, bb = dipole_pair_force_field(s_m * (s_rule[2 + sk] * inv_n), mt,
                                             pt - wp.vec3(s_rule[sk] * cs[0], s_rule[sk] * cs[1], 0.0))
            f += ff
            b += bb
        force += f
        torque += wp.cross(lever, f) + wp.cross(mt, b)
    return force, torque


__all__ = ["NEAR_LIMIT", "cylinder_ring_rule", "far_cylinder_pair_wrench", "far_pair_rules", "ring_points_for_distance"]
