"""The floor's contact and friction, as ``@wp.func``s of one vertex: contact statuses, landing at position level
(eq. 8 of the paper), the Newton iteration's starting velocity, stick / slip switches, and the friction force with
its stiffness (isotropic, or a skin whose friction differs by direction). Called by :mod:`.substep`'s per-vertex
phases. float32, SI units.
"""

from __future__ import annotations

import warp as wp

CONTACT_FREE = wp.constant(0)
CONTACT_SLIDING = wp.constant(1)  # on the floor, kinetic friction
CONTACT_STUCK = wp.constant(2)  # on the floor, static friction (regularised: a stiff viscous force)
CONTACT_FIXED = wp.constant(3)  # a vertex of infinite mass (never moves; reported as free)
RELEASED_LET_GO = wp.constant(1)  # bit 0 of ``released``: the vertex let go of the floor in this substep
RELEASED_SWITCH = wp.constant(2)  # the count of its stick/slip switches in this substep, in the bits above
MAX_STICK_SLIP_SWITCHES = wp.constant(6)
"""Stick/slip switches a vertex may make in one substep; past them it is held (stuck) for the rest of it."""


@wp.func
def mass_over_dt2(w_inv: float, inv_dt2: float) -> float:
    """m / dt² [N/m] of a vertex of inverse mass ``w_inv`` (1 for a vertex of infinite mass: it only keeps the
    Newton matrix definite)."""
    if w_inv > 0.0:
        return inv_dt2 / w_inv
    return 1.0


@wp.func
def floor_landing(p0: wp.vec3, vel: wp.vec3, n: wp.vec3, mu_static: float, mu_kinetic: float, dt: float):
    """Position-level contact and friction (eq. 8 of the paper) of a free vertex that reached the floor (normal
    ``n``, through the origin) only in the last Newton step: from ``p0`` at velocity ``vel`` (kept apart so that a
    ~2e-8 m penetration is not lost in a ~0.1 m position's float32 rounding), the depth d removed along n, the
    tangential motion cancelled if at most mu_s d (stuck), else reduced by mu_k d / dt. Returns (p, vel, status,
    d), status CONTACT_FREE when it did not touch."""
    depth = wp.max(-(wp.dot(p0, n) + dt * wp.dot(vel, n)), 0.0)
    out = CONTACT_FREE
    if depth > 0.0:
        vel = vel + n * (depth / dt)
        vn = wp.dot(vel, n)
        vt = vel - n * vn
        vt_len = wp.length(vt)
        if vt_len * dt <= mu_static * depth:
            vel = n * vn  # stick: tangentially back to exactly where the substep started
            out = CONTACT_STUCK
        else:
            vel = vel - vt * (mu_kinetic * depth / (dt * vt_len))
            out = CONTACT_SLIDING
    return p0 + vel * dt, vel, out, depth


@wp.func
def newton_start(status: int, vel: wp.vec3, v_old: wp.vec3, h0: float, n: wp.vec3, inv_dt: float) -> wp.vec3:
    """The velocity the Newton iteration starts from (x = x_n + dt · this): the velocity ``v_old`` a free vertex
    carries over (not x̃'s ``vel``: a warm start, fewer Newton steps), no
    lower than the floor from height ``h0``; a vertex on the floor along it (only an inertial velocity into the floor
    moves it, to the floor at most); a fixed one keeps ``vel`` (zero)."""
    if status == CONTACT_FIXED:
        return vel
    if status == CONTACT_FREE:
        gn = wp.dot(v_old, n)
        return v_old + n * (wp.max(gn, -h0 * inv_dt) - gn)
    start = n * wp.max(wp.min(wp.dot(vel, n), 0.0), -h0 * inv_dt)
    if status == CONTACT_SLIDING:
        start = start + (v_old - n * wp.dot(v_old, n))
    return start


@wp.func
def starting_contact(w_inv: float, was: int, vel: wp.vec3, v_old: wp.vec3, h0: float, n: wp.vec3, dt: float,
                     slip_speed: float) -> int:
    """A vertex's contact status at the start of a substep: FIXED for infinite mass; on the floor if it was (status
    ``was``) and is not pulled off (``vel`` into the floor, or ``v_old`` not lifting it faster than ``slip_speed``),
    or if free and ``v_old`` takes it below the floor within ``dt``: then sliding or stuck by the speed along the
    floor it carries; else FREE. ``v_old``, not ``vel``, because the iteration starts from it (predicting from ``vel`` made
    vertices land and let go every substep)."""
    if not (w_inv > 0.0):
        return CONTACT_FIXED
    # on the floor, it stays if its inertial velocity presses it in or the velocity it carries does not lift it off
    stays = wp.dot(vel, n) < 0.0 or wp.dot(v_old, n) <= slip_speed
    if (was != CONTACT_FREE and stays) or (was == CONTACT_FREE and h0 + dt * wp.dot(v_old, n) < 0.0):
        vt_old = v_old - n * wp.dot(v_old, n)
        return wp.where(wp.length(vt_old) > slip_speed, CONTACT_SLIDING, CONTACT_STUCK)
    return CONTACT_FREE


@wp.func
def landing_floor_force(h0: float, vel: wp.vec3, n: wp.vec3, dt: float, w_inv: float, inv_dt2: float) -> wp.vec3:
    """The floor's first estimate of its normal force on a vertex that lands this substep: m/dt² times the depth
    its inertial velocity ``vel`` would take it below the floor from height ``h0``."""
    return n * (-(h0 + dt * wp.dot(vel, n)) * mass_over_dt2(w_inv, inv_dt2))


@wp.func
def skin_profile(u: wp.vec3, fwd: wp.vec3, n: wp.vec3, friction_backward_ratio: float):
    """The direction profile g(θ) of a skin whose friction differs by direction, g'(θ), g''(θ) and e_θ = n × u, for
    the unit tangential direction ``u`` at angle θ from the head-ward tangent ``fwd`` (``n`` the floor normal):
    g = 1 + (r − 1) S(w), S(w) = 3w² − 2w³, w = (1 − cos θ) / 2, r = ``friction_backward_ratio``: 1 head-ward,
    (1 + r) / 2 sideways, r tail-ward. A cubic in cos θ, so |v| g and |v|² g are convex for every r > 0 and the
    friction of :func:`friction_force` is monotone with a symmetric PSD stiffness."""
    lat = wp.cross(n, fwd)
    a = wp.dot(u, fwd)  # cos θ
    b = wp.dot(u, lat)  # sin θ
    w = 0.5 * (1.0 - a)
    s1 = 6.0 * w * (1.0 - w)
    d = friction_backward_ratio - 1.0
    g = 1.0 + d * w * w * (3.0 - 2.0 * w)
    return g, d * s1 * 0.5 * b, d * ((6.0 - 12.0 * w) * 0.25 * b * b + s1 * 0.5 * a), lat * a - fwd * b


@wp.func
def skin_scale(v: wp.vec3, fwd: wp.vec3, n: wp.vec3, friction_backward_ratio: float) -> float:
    """g(θ) of :func:`skin_profile` for the tangential part of ``v`` (1 without one, or for isotropic friction): the
    factor on both coefficients where a landing's friction is applied at position level."""
    if friction_backward_ratio == 1.0:
        return 1.0
    vt = v - n * wp.dot(v, n)
    speed = wp.length(vt)
    if not (speed > 0.0):
        return 1.0
    g, g1, g2, e = skin_profile(vt / speed, fwd, n, friction_backward_ratio)
    return g


@wp.func
def friction_force(status: int, vt: wp.vec3, normal_force: float, mu_static: float, mu_kinetic: float,
                   friction_backward_ratio: float, fwd: wp.vec3, n: wp.vec3, slip_speed: float):
    """The floor's friction on a vertex moving at tangential velocity ``vt`` [m/s] under ``normal_force`` [N].
    Returns (force [N]; a scalar stiffness −∂f/∂v [N·s/m] on the tangent plane less the unit direction t it returns
    next (sliding; zero when stuck); the rest of the stiffness as a symmetric PSD matrix, zero when isotropic).

    Isotropic (ratio 1): stuck, f = −(mu_s F_n / ε) v_t, a stiff viscous force reaching mu_s F_n at ε =
    ``slip_speed``; sliding, f = −mu_k F_n v_t / |v_t|. Otherwise f = −∇D of the convex dissipation D = mu_k F_n |v|
    g(θ) sliding, (mu_s F_n / 2ε) |v|² g(θ) stuck (:func:`skin_profile`), with D's Hessian as its stiffness, so the
    Newton matrix stays symmetric and exact."""
    if not (normal_force > 0.0):
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    speed = wp.length(vt)
    if friction_backward_ratio == 1.0:
        if status == CONTACT_STUCK:
            c = mu_static * normal_force / slip_speed
            return vt * (-c), c, wp.vec3(0.0), wp.mat33(0.0)
        if speed > 0.0:
            c = mu_kinetic * normal_force / speed
            return vt * (-c), c, vt / speed, wp.mat33(0.0)
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    if not (speed > 0.0):
        if status == CONTACT_STUCK:
            # D's Hessian has no value at v = 0 (it depends on the direction): the mean of head-ward and tail-ward
            return wp.vec3(0.0), 0.0, wp.vec3(0.0), (wp.identity(n=3, dtype=float) - wp.outer(n, n)) * (
                mu_static * normal_force / slip_speed * 0.5 * (1.0 + friction_backward_ratio))
        return wp.vec3(0.0), 0.0, wp.vec3(0.0), wp.mat33(0.0)
    u = vt / speed
    g, g1, g2, e = skin_profile(u, fwd, n, friction_backward_ratio)
    if status == CONTACT_STUCK:
        c0 = mu_static * normal_force / slip_speed
        f = (vt * g + e * (0.5 * g1 * speed)) * (-c0)
        k = (wp.outer(u, u) * g + (wp.outer(u, e) + wp.outer(e, u)) * (0.5 * g1) + wp.outer(e, e) * (g + 0.5 * g2))
        return f, 0.0, wp.vec3(0.0), k * c0
    cn = mu_kinetic * normal_force
    return (u * g + e * g1) * (-cn), 0.0, wp.vec3(0.0), wp.outer(e, e) * (cn / speed * wp.max(g + g2, 0.0))


@wp.func
def dof_projector(status: int, n: wp.vec3) -> wp.mat33:
    """The directions a vertex may move in a constrained Newton step: all (free), along the floor (on it), none
    (infinite mass)."""
    if status == CONTACT_FIXED:
        return wp.mat33(0.0)
    if status == CONTACT_SLIDING or status == CONTACT_STUCK:
        return wp.identity(n=3, dtype=float) - wp.outer(n, n)
    return wp.identity(n=3, dtype=float)


@wp.func
def stick_slip_status(st: int, vt: wp.vec3, ff: wp.vec3, fn: float, n: wp.vec3, slip_speed: float, released: int):
    """Between Newton steps: a stuck vertex whose viscous static friction exceeds what mu_s F_n (``fn``, now known)
    can hold broke loose; a sliding one whose motion reversed against its last floor force ``ff`` or fell below half
    the slip speed sticks. After MAX_STICK_SLIP_SWITCHES switches in a substep it is held (stuck): neighbours taking
    turns would keep the iteration from converging. Returns (status, released)."""
    vt_len = wp.length(vt)
    new_st = st
    if st == CONTACT_STUCK and vt_len * wp.dot(ff, n) > slip_speed * fn:
        new_st = CONTACT_SLIDING
    elif st == CONTACT_SLIDING and (wp.dot(vt, ff) > 0.0 or vt_len < 0.5 * slip_speed):
        new_st = CONTACT_STUCK
    if new_st != st:
        if released / RELEASED_SWITCH >= MAX_STICK_SLIP_SWITCHES:
            new_st = CONTACT_STUCK
        else:
            released = released + RELEASED_SWITCH
    return new_st, released
