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

Why: the closed-form cylinder field needs elliptic integrals at ~100 surface-charge points per pair; the ring rule is
~3× cheaper for the worm's IPM–IPM pairs and agrees with the closed form to 8e-6 of the largest force and torque
where it is used (``tests/test_magnets_far_pair.py``). A cuboid (the EPM) and a cylinder at least 2.5 circumscribing
radii apart take the same rule for the cylinder alone: the cuboid's face charges in the ring points' field
(:func:`cuboid_faces_in_ring_field`), the cylinder's wrench by reciprocity. Timings: docs/magnets.md.
"""

from __future__ import annotations

import warp as wp

from .common import LANES, SHAPE_CUBOID, SHAPE_CYLINDER, lanes, lanes_dot, lanes_sqrt
from .magnet_charges import box_gap, panel_count
from .magnet_closed_form import F64_0, F64_1
from .magnet_dipoles import CYL_PI, MU0_OVER_4PI, dipole_pair_force_field

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
def ring_setup(nphi: int, rot: wp.mat33, m: wp.vec3):
    """What both ring-rule integrals start from, for ``nphi`` points per ring of a cylinder turned by ``rot`` (its
    frame -> the frame of the computation) with moment ``m`` (its frame): (one step and half a step of the azimuth as
    (cos, sin), 1 / nphi, the moment and the cylinder's x and y axes in the computation's frame)."""
    dphi = 2.0 * CYL_PI / float(nphi)
    step = wp.vec2(wp.cos(dphi), wp.sin(dphi))
    half = wp.vec2(wp.cos(0.5 * dphi), wp.sin(0.5 * dphi))
    ax = wp.vec3(rot[0, 0], rot[1, 0], rot[2, 0])
    ay = wp.vec3(rot[0, 1], rot[1, 1], rot[2, 1])
    return step, half, 1.0 / float(nphi), rot * m, ax, ay


RingPoints = wp.types.matrix(shape=(32, 4), dtype=float)
"""Up to 2 × 16 ring points: (x, y, z, weight) rows."""


@wp.func
def source_ring(s_rule: wp.vec4, s_m: wp.vec3, nphi: int, step: wp.vec2, half: wp.vec2, inv_n: float):
    """The source cylinder's 2 ``nphi`` ring points (rows x, y; z = 0) and its two rings' moments [A·m²], once per
    pair: the same numbers every target point's loop would make again (the recurrence of :func:`ring_point`, the
    weights of :func:`cylinder_ring_rule` ``s_rule``)."""
    src = RingPoints()
    cs = wp.vec2(1.0, 0.0)
    for sp in range(2 * nphi):
        cs = ring_point(sp, nphi, cs, step, half)
        sk = sp // nphi
        src[sp, 0] = s_rule[sk] * cs[0]
        src[sp, 1] = s_rule[sk] * cs[1]
    ms0 = s_m * (s_rule[2] * inv_n)
    ms1 = s_m * (s_rule[3] * inv_n)
    return src, ms0, ms1


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
    step, half, inv_n, mt_dir, ax, ay = ring_setup(nphi, r_rel, t_m)
    src, ms0, ms1 = source_ring(s_rule, s_m, nphi, step, half, inv_n)
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
        for sp in range(nphi):
            ff, bb = dipole_pair_force_field(ms0, mt, pt - wp.vec3(src[sp, 0], src[sp, 1], 0.0))
            f += ff
            b += bb
        for sp in range(nphi, 2 * nphi):
            ff, bb = dipole_pair_force_field(ms1, mt, pt - wp.vec3(src[sp, 0], src[sp, 1], 0.0))
            f += ff
            b += bb
        force += f
        torque += wp.cross(lever, f) + wp.cross(mt, b)
    return force, torque


@wp.func
def ring_dipoles_on_lanes(px: lanes, py: lanes, pz: lanes, mx: lanes, my: lanes, mz: lanes, src: RingPoints,
                          nphi: int, ms0: wp.vec3, ms1: wp.vec3):
    """:func:`~.magnet_dipoles.dipole_pair_force_field` of the source's 2 ``nphi`` ring points (``src``, z = 0; moment
    ``ms0`` on the first ring, ``ms1`` on the second) on the target dipoles of the lanes (positions p, moments m by
    coordinate), summed over the source points in their order: (force x, y, z; field x, y, z) by coordinate, each
    lane the scalar function's operations in its order."""
    mu = lanes(MU0_OVER_4PI)
    mu3 = lanes(3.0 * MU0_OVER_4PI)
    fx = lanes(0.0)
    fy = lanes(0.0)
    fz = lanes(0.0)
    bx = lanes(0.0)
    by = lanes(0.0)
    bz = lanes(0.0)
    for sp in range(2 * nphi):
        ms = wp.where(sp < nphi, ms0, ms1)
        msx = lanes(ms[0])
        msy = lanes(ms[1])
        msz = lanes(ms[2])
        rx = px - lanes(src[sp, 0])
        ry = py - lanes(src[sp, 1])
        rz = pz  # − 0.0: the same bits
        inv_r2 = wp.cw_div(lanes(1.0), lanes_dot(rx, ry, rz, rx, ry, rz))
        inv_r3 = wp.cw_mul(lanes_sqrt(inv_r2), inv_r2)
        inv_r5 = wp.cw_mul(inv_r3, inv_r2)
        a = lanes_dot(rx, ry, rz, msx, msy, msz)
        b = lanes_dot(rx, ry, rz, mx, my, mz)
        a3 = wp.cw_mul(wp.cw_mul(lanes(3.0), a), inv_r5)
        bx += wp.cw_mul(mu, wp.cw_mul(a3, rx) - wp.cw_mul(inv_r3, msx))
        by += wp.cw_mul(mu, wp.cw_mul(a3, ry) - wp.cw_mul(inv_r3, msy))
        bz += wp.cw_mul(mu, wp.cw_mul(a3, rz) - wp.cw_mul(inv_r3, msz))
        coef = wp.cw_mul(mu3, inv_r5)
        msmt = wp.cw_mul(mx, msx) + wp.cw_mul(my, msy) + wp.cw_mul(mz, msz)  # dot(m_s, m_t)
        g = msmt - wp.cw_mul(wp.cw_mul(wp.cw_mul(lanes(5.0), a), b), inv_r2)
        fx += wp.cw_mul(coef, wp.cw_mul(b, msx) + wp.cw_mul(a, mx) + wp.cw_mul(g, rx))
        fy += wp.cw_mul(coef, wp.cw_mul(b, msy) + wp.cw_mul(a, my) + wp.cw_mul(g, ry))
        fz += wp.cw_mul(coef, wp.cw_mul(b, msz) + wp.cw_mul(a, mz) + wp.cw_mul(g, rz))
    return fx, fy, fz, bx, by, bz


@wp.func
def far_cylinder_pair_wrench_lanes(
    s_rule: wp.vec4,
    s_m: wp.vec3,
    t_rule: wp.vec4,
    t_m: wp.vec3,
    r_rel: wp.mat33,
    t_rel: wp.vec3,
    nphi: int,
):
    """:func:`far_cylinder_pair_wrench` with :data:`~.common.LANES` target points at a time: the same numbers to the
    bit (each lane sums over the source points in the scalar loops' order; the target points' force and torque are
    summed in theirs), ~2.7x faster on the CPU. Lanes past the last target point repeat it and are not summed."""
    step, half, inv_n, mt_dir, ax, ay = ring_setup(nphi, r_rel, t_m)
    src, ms0, ms1 = source_ring(s_rule, s_m, nphi, step, half, inv_n)
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    ct = wp.vec2(1.0, 0.0)
    lever = wp.vec3(0.0)
    mt = wp.vec3(0.0)
    ntp = 2 * nphi
    for t0 in range(0, ntp, LANES):
        lx = lanes()
        ly = lanes()
        lz = lanes()
        mx = lanes()
        my = lanes()
        mz = lanes()
        for k in range(8):
            if t0 + k < ntp:
                ct = ring_point(t0 + k, nphi, ct, step, half)
                tk = (t0 + k) // nphi
                lever = (ax * ct[0] + ay * ct[1]) * t_rule[tk]
                mt = mt_dir * (t_rule[2 + tk] * inv_n)
            lx[k] = lever[0]
            ly[k] = lever[1]
            lz[k] = lever[2]
            mx[k] = mt[0]
            my[k] = mt[1]
            mz[k] = mt[2]
        # pt = t_rel + lever
        px = lanes(t_rel[0]) + lx
        py = lanes(t_rel[1]) + ly
        pz = lanes(t_rel[2]) + lz
        fx, fy, fz, bx, by, bz = ring_dipoles_on_lanes(px, py, pz, mx, my, mz, src, nphi, ms0, ms1)
        for k in range(wp.min(LANES, ntp - t0)):
            f = wp.vec3(fx[k], fy[k], fz[k])
            b = wp.vec3(bx[k], by[k], bz[k])
            force += f
            torque += wp.cross(wp.vec3(lx[k], ly[k], lz[k]), f) + wp.cross(wp.vec3(mx[k], my[k], mz[k]), b)
    return force, torque


# ----------------------------------------------------------------------------------------------------------------------
# A cuboid and a far cylinder (the EPM and an IPM): the cuboid's face charges in the cylinder's ring field
# ----------------------------------------------------------------------------------------------------------------------

CUBOID_RING_NEAR = wp.constant(2.5)
"""Below this many circumscribing radii of the cylinder between its centre and the cuboid, the closed form is used."""


@wp.func
def gauss_legendre_node(order: int, i: int) -> wp.vec2:
    """(node, weight) ``i`` of the 4- or 6-point Gauss–Legendre rule on [−1, 1] (the rules :func:`cuboid_ring_rule`
    picks; any other order gives the 6-point rule)."""
    j = wp.where(i < order / 2, order / 2 - 1 - i, i - order / 2)  # distance rank from the centre
    sign = wp.where(i < order / 2, -1.0, 1.0)
    if order == 4:
        if j == 0:
            return wp.vec2(-sign * 0.33998104358485626, 0.6521451548625461)
        return wp.vec2(-sign * 0.8611363115940526, 0.34785484513745385)
    if j == 0:
        return wp.vec2(-sign * 0.2386191860831969, 0.46791393457269104)
    if j == 1:
        return wp.vec2(-sign * 0.6612093864662645, 0.3607615730481386)
    return wp.vec2(-sign * 0.932469514203152, 0.17132449237917036)


@wp.func
def cuboid_ring_rule(c_size: wp.vec3, y_size: wp.vec3, y_in_c: wp.vec3):
    """Whether the pair of a cuboid (extents ``c_size`` [m]) and a cylinder ((d, d, h) ``y_size``, centre
    ``y_in_c`` in the cuboid's frame) takes the ring rule: (points per ring, Gauss–Legendre order on the cuboid's
    faces, the cylinder's :func:`cylinder_ring_rule`); 0 points = the closed form.

    By the gap g from the cylinder's centre to the cuboid over the cylinder's circumscribing radius a: g ≥ 4a, the
    points of :func:`ring_points_for_distance` and order 4; 2.5a ≤ g < 4a, 16 points and order 6; closer, the closed
    form. Measured for the paper's EPM (10 × 10 × 40 mm) and a 10 × 1 mm IPM against the closed form, largest error
    over the largest force / torque of 400 random poses per gap, both directions of the pair: ≤ 2.3e-6 / 5.1e-6
    from 2.5a to 12a (``tests/test_magnets_far_pair.py``). At 2a the same rule loses 2.5e-5 / 4.8e-5 (hence 2.5a),
    and 8 points or order 4 below 4a lose ~1e-4 there (a NumPy prototype)."""
    radius = 0.5 * y_size[0]
    reach = wp.sqrt(radius * radius + 0.25 * y_size[2] * y_size[2])
    q = float(box_gap(wp.vec3d(0.5 * c_size), wp.vec3d(y_in_c))) / reach
    rule = cylinder_ring_rule(radius, y_size[2])
    if q < CUBOID_RING_NEAR or rule[2] <= 0.0:
        return 0, 0, rule
    if q < NEAR_LIMIT:
        return 16, 6, rule
    return ring_points_for_distance(q, 1.0), 4, rule


@wp.func
def cuboid_faces_in_ring_field(
    c_size: wp.vec3,
    c_m: wp.vec3,
    y_rule: wp.vec4,
    y_m: wp.vec3,
    y_rot: wp.mat33,
    y_pos: wp.vec3,
    nphi: int,
    order: int,
    max_panels: int,
):
    """Force [N] on a uniformly magnetized cuboid and torque [N·m] about its centre, in its own frame, in the field
    of a cylinder's ring rule: F = ∮ σ B dA over the cuboid's faces (σ = M·n, M = ``c_m`` / volume), Gauss–Legendre
    of ``order`` on panels no larger than their distance to the cylinder's centre (the closed form's
    :func:`~.magnet_charges.panel_count`).

    Args:
        c_size, c_m: the cuboid's extents [m] and moment [A·m²] (its frame).
        y_rule: :func:`cylinder_ring_rule` of the cylinder (valid); y_m its moment [A·m²] in its own frame.
        y_rot, y_pos: the cylinder's frame -> the cuboid's frame, and its centre there [m].
        nphi, order: points per ring and quadrature order (:func:`cuboid_ring_rule`).

    The ring dipoles all point along one moment, so their field at a point is (μ0/4π)(3 Σ w a r / r⁵ − m Σ w / r³)
    with a = r·m̂: two scalar sums and a vector one per ring point, no per-point vectors.
    """
    step, half, inv_n, m_dir, ax, ay = ring_setup(nphi, y_rot, y_m)
    mag = c_m / (c_size[0] * c_size[1] * c_size[2])
    pts = RingPoints()  # (position, weight) of every ring point
    cs = wp.vec2(1.0, 0.0)
    for rp in range(2 * nphi):
        cs = ring_point(rp, nphi, cs, step, half)
        rk = rp // nphi
        q = y_pos + (ax * cs[0] + ay * cs[1]) * y_rule[rk]
        pts[rp, 0] = q[0]
        pts[rp, 1] = q[1]
        pts[rp, 2] = q[2]
        pts[rp, 3] = y_rule[2 + rk]
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    for k in range(3):
        mk = mag[k]
        if mk != 0.0:
            u = (k + 1) % 3
            v = (k + 2) % 3
            lu = c_size[u]
            lv = c_size[v]
            for side in range(2):
                sign = wp.where(side == 0, 1.0, -1.0)
                sigma = sign * mk
                centre = wp.vec3(0.0)
                centre[k] = sign * 0.5 * c_size[k]
                # distance from the cylinder's centre to this face: a box of zero thickness along k
                face_half = 0.5 * c_size
                face_half[k] = 0.0
                gap = box_gap(wp.vec3d(face_half), wp.vec3d(y_pos - centre))
                nu = panel_count(wp.float64(lu), gap, max_panels)
                nv = panel_count(wp.float64(lv), gap, max_panels)
                du = lu / float(nu)
                dv = lv / float(nv)
                # the face's (nu order) x (nv order) points, v fastest, LANES at a time (lanes past the last point
                # repeat it and are not summed)
                npts = nu * order * nv * order
                for q0 in range(0, npts, LANES):
                    px, py, pz, wq = face_points_lanes(q0, npts, nv * order, order, centre, u, v, lu, lv, du, dv,
                                                       sigma)
                    sx, sy, sz, si3 = ring_field_sums_lanes(px, py, pz, pts, nphi, m_dir)
                    for j in range(wp.min(LANES, npts - q0)):  # not k: the face's axis
                        p = wp.vec3(px[j], py[j], pz[j])
                        b = (MU0_OVER_4PI * inv_n) * (3.0 * wp.vec3(sx[j], sy[j], sz[j]) - si3[j] * m_dir)
                        f = b * wq[j]
                        force += f
                        torque += wp.cross(p, f)
    return force, torque


@wp.func
def face_points_lanes(q0: int, npts: int, nvo: int, order: int, centre: wp.vec3, u: int, v: int, lu: float,
                      lv: float, du: float, dv: float, sigma: float):
    """Points q0 .. q0 + LANES − 1 (q = iu · nvo + iv, the scalar loops' order; past ``npts`` the last) of a face's
    Gauss–Legendre grid (:func:`cuboid_faces_in_ring_field`): positions by coordinate [m] and each point's weight
    σ w_u w_v du dv / 4, the scalar expressions in their order."""
    px = lanes()
    py = lanes()
    pz = lanes()
    wq = lanes()
    for k in range(8):
        q = wp.min(q0 + k, npts - 1)
        iu = q / nvo
        iv = q - iu * nvo
        gu = gauss_legendre_node(order, iu % order)
        cu = -0.5 * lu + (float(iu / order) + 0.5 + 0.5 * gu[0]) * du
        gv = gauss_legendre_node(order, iv % order)
        cv = -0.5 * lv + (float(iv / order) + 0.5 + 0.5 * gv[0]) * dv
        p = centre
        p[u] = cu
        p[v] = cv
        px[k] = p[0]
        py[k] = p[1]
        pz[k] = p[2]
        wq[k] = sigma * gu[1] * gv[1] * 0.25 * du * dv
    return px, py, pz, wq


@wp.func
def ring_field_sums_lanes(px: lanes, py: lanes, pz: lanes, pts: RingPoints, nphi: int, m_dir: wp.vec3):
    """The ring rule's field sums at the lanes' points p (:func:`cuboid_faces_in_ring_field`): Σ r (w_k a / r⁵) by
    coordinate and Σ w_k / r³ over the 2 ``nphi`` ring points in their order (r = p − the ring point, a = r·m̂)."""
    mx = lanes(m_dir[0])
    my = lanes(m_dir[1])
    mz = lanes(m_dir[2])
    sx = lanes(0.0)
    sy = lanes(0.0)
    sz = lanes(0.0)
    si3 = lanes(0.0)
    for rp in range(2 * nphi):
        rx = px - lanes(pts[rp, 0])
        ry = py - lanes(pts[rp, 1])
        rz = pz - lanes(pts[rp, 2])
        inv_r2 = wp.cw_div(lanes(1.0), lanes_dot(rx, ry, rz, rx, ry, rz))
        inv_r3 = wp.cw_mul(lanes_sqrt(inv_r2), inv_r2)
        wk = wp.cw_mul(lanes(pts[rp, 3]), inv_r3)
        t = wp.cw_mul(wp.cw_mul(wk, lanes_dot(rx, ry, rz, mx, my, mz)), inv_r2)
        sx += wp.cw_mul(rx, t)
        sy += wp.cw_mul(ry, t)
        sz += wp.cw_mul(rz, t)
        si3 += wk
    return sx, sy, sz, si3


@wp.func
def far_pair_wrench(
    s_shape: int,
    s_size: wp.vec3,
    s_m: wp.vec3,
    t_shape: int,
    t_size: wp.vec3,
    t_m: wp.vec3,
    r_rel: wp.mat33,
    t_rel: wp.vec3,
    max_panels: int,
):
    """The one place that decides whether a pair takes a ring rule: (taken, force [N] on the target, torque [N·m]
    about its centre) in the source's frame (``r_rel`` target -> source frame, ``t_rel`` the target's centre there
    [m]); taken = False (zeros): the caller's closed form.

    Two far cylinders by :func:`far_cylinder_pair_wrench_lanes` (:func:`far_cylinder_pair_wrench`'s numbers). A
    cuboid and a far cylinder (either the source) by :func:`cuboid_faces_in_ring_field`, where
    :func:`cuboid_ring_rule` allows: a cylinder target (the EPM's wrench on an IPM) by reciprocity, the cuboid's
    force and torque F_c, τ_c in the cylinder's ring field, then F = −F_c and τ = −τ_c + t_rel × F_c (momentum
    and angular momentum of the pair conserved). The cuboid's ~32 face points against ~24 ring dipoles replace ~96
    closed-form cuboid fields over the cylinder's caps: docs/magnets.md."""
    zero = wp.vec3(0.0)
    nphi, s_rule, t_rule = far_pair_rules(s_shape, s_size, t_shape, t_size, wp.length(t_rel))
    if nphi > 0:
        force, torque = far_cylinder_pair_wrench_lanes(s_rule, s_m, t_rule, t_m, r_rel, t_rel, nphi)
        return True, force, torque
    if s_shape == SHAPE_CUBOID and t_shape == SHAPE_CYLINDER:
        nphi, order, rule = cuboid_ring_rule(s_size, t_size, t_rel)
        if nphi == 0:
            return False, zero, zero
        fc, tc = cuboid_faces_in_ring_field(s_size, s_m, rule, t_m, r_rel, t_rel, nphi, order, max_panels)
        return True, -fc, wp.cross(t_rel, fc) - tc
    if s_shape == SHAPE_CYLINDER and t_shape == SHAPE_CUBOID:
        # in the cuboid's (target's) frame: the cylinder at −r_relᵀ t_rel, turned by r_relᵀ
        inv = wp.transpose(r_rel)
        y_pos = -(inv * t_rel)
        nphi, order, rule = cuboid_ring_rule(t_size, s_size, y_pos)
        if nphi == 0:
            return False, zero, zero
        fc, tc = cuboid_faces_in_ring_field(t_size, t_m, rule, s_m, inv, y_pos, nphi, order, max_panels)
        return True, r_rel * fc, r_rel * tc
    return False, zero, zero


__all__ = ["CUBOID_RING_NEAR", "NEAR_LIMIT", "cuboid_faces_in_ring_field", "cuboid_ring_rule", "cylinder_ring_rule",
           "far_cylinder_pair_wrench", "far_cylinder_pair_wrench_lanes", "far_pair_rules", "far_pair_wrench",
           "gauss_legendre_node", "ring_points_for_distance"]
