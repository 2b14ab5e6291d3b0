"""The default solver: implicit Euler with Newton steps on a banded direct solve, one thread per world.

Kernels only; the host orchestration is :class:`warpworm.simulator.Simulator`.
:func:`implicit_step` is launched 1-D over worlds (``world = wp.tid()``); each thread runs its world's substeps. A
substep of length dt finds the positions x that minimise

    ½ |x − x̃|²_M / dt² + E(x),      x̃ = x_n + dt v',   v' = v_n / (1 + c dt) + dt (g + M⁻¹ f_ext)

(implicit Euler: gravity, the step's magnetic force and the linear velocity damping c are in x̃), with E the elastic
energy of the worm:

- every bar a spring ½ (EA / L0)(L − L0)² (stiff bars near-rigid, the valley rings soft; Cauchy strain reported),
  and a soft waist bar strained past its stop |ε| = ε_s a one-sided spring ½ (EA_s / L0)(L − L0(1 ± ε_s))²;
- every crease ½ k_α L (φ − φ0)² plus its damping as the implicit dissipation ½ (c_α L / dt)(φ − φ_n)², and the
  NoFoldThrough limits as a one-sided spring k_lim L beyond the bound (0 for mountain/valley creases), with k_lim
  (``fold_limit_stiffness``) its own material constant: a barrier that scaled with k_α would soften with the crease
  and let a soft worm fold through;
- every anchor ½ k |x − target|² (so the force plate reads k (x − target), the force it applies).

``newton`` Gauss–Newton steps (bar and crease Hessians kept positive semi-definite: the compressive geometric
stiffness and the crease curvature terms dropped) solve it; each assembles the gradient and the 3V × 3V Hessian as
3×3 vertex blocks in a banded per-world scratch and factors it (:mod:`warpworm.kernels.band_cholesky`).

Floor: a vertex on the floor (touching at the end of the last substep, or predicted below it) moves only along it
(its rows of the Newton step are projected, P H P). Before every Newton step after the first, the floor's force at
each contact is read from the gradient, F = ∂Φ/∂x (what holds the vertex against the rest of the implicit step): a
contact the floor would have to pull lets go, a free vertex the last step put below the floor lands. Friction
(eq. 8 of the paper) is a force in the Newton problem with that normal force F_n: static as a stiff viscous force
−(mu_s F_n / ε) v_t reaching mu_s F_n at ε = ``slip_speed`` (a held worm creeps at most ~ε), kinetic as
−mu_k F_n v_t / |v_t|; a stuck vertex breaks loose when the viscous force it needed exceeds mu_s F_n, a sliding one
sticks when the kinetic force reverses its motion or when it starts a substep slower than ε. A last pass catches
vertices that reached the floor in the last step; then v = v' + (x − x̃) / dt.

Why: the bars are near-rigid on 1e-5 kg vertices. An XPBD sweep per substep caps their stiffness near m/dt² (the
Gauss–Seidel and Jacobi XPBD solvers of this package's first version: "rigid" bars strained by percents), a Gauss–Seidel crease sweep
composed with a direct bar projection was linearly unstable, and explicit crease forces projected on rigid bars are
only stable below ~100–200 µs and lose stability as the bellows approaches its snap-through (all measured:
docs/dynamics.md). Implicit Euler with a direct solve is unconditionally stable, has the exact statics of E (no mass
in the equilibrium, unlike a one-pass XPBD compliance) and converges at first order as dt is halved.
"""

from __future__ import annotations

import warp as wp

from .band_cholesky import band_add_block, band_cholesky_factor, band_cholesky_solve
from .common import dihedral_angle_and_gradient, fold_range, freeze_world, pw, wrap_angle

wp.set_module_options({"enable_backward": False})

CONTACT_FREE = wp.constant(0)
CONTACT_SLIDING = wp.constant(1)  # on the floor, kinetic friction
CONTACT_STUCK = wp.constant(2)  # on the floor, static friction (regularised: a stiff viscous force)
CONTACT_FIXED = wp.constant(3)  # a vertex of infinite mass (never moves; reported as free)
WORLD_CRUMPLED = wp.constant(2)  # ``unstable`` flag of a world whose creases folded through (1: exploded)


@wp.func
def mass_over_dt2(w_inv: float, inv_dt2: float) -> float:
    """m / dt² [N/m] of a vertex of inverse mass ``w_inv`` (1 for a vertex of infinite mass, which never moves: it
    only keeps the Newton matrix definite)."""
    if w_inv > 0.0:
        return inv_dt2 / w_inv
    return 1.0


@wp.func
def floor_landing(p0: wp.vec3, vel: wp.vec3, n: wp.vec3, mu_s: float, mu_k: float, dt: float):
    """Position-level floor contact and friction (eq. 8 of the paper) of a free vertex that reached the floor only in
    the last Newton step of a substep.

    ``p0`` its position at the start of the substep, ``vel`` = (x − p0) / dt its velocity over the substep (kept
    apart from p0 so that a penetration of ~g dt² ≈ 2e-8 m at 50 µs is not lost in the float32 rounding of a ~0.1 m
    position), ``n`` the floor normal (floor through the origin). A penetration d is removed along n; the tangential
    motion is cancelled if it is at most mu_s d (stuck), otherwise reduced by mu_k d / dt (sliding: f = mu_k F_n
    over the substep with F_n = m d / dt²). Returns (p, vel, status, d), status CONTACT_FREE when it did not touch.
    """
    depth = wp.max(-(wp.dot(p0, n) + dt * wp.dot(vel, n)), 0.0)
    out = CONTACT_FREE
    if depth > 0.0:
        vel = vel + n * (depth / dt)
        vn = wp.dot(vel, n)
        vt = vel - n * vn
        vt_len = wp.length(vt)
        if vt_len * dt <= mu_s * depth:
            vel = n * vn  # stick: tangentially back to exactly where the substep started
            out = CONTACT_STUCK
        else:
            vel = vel - vt * (mu_k * depth / (dt * vt_len))
            out = CONTACT_SLIDING
    return p0 + vel * dt, vel, out, depth


@wp.func
def friction_force(status: int, vt: wp.vec3, normal_force: float, mu_s: float, mu_k: float, slip_speed: float):
    """The floor's friction on a vertex on it moving at tangential velocity ``vt`` [m/s] under ``normal_force``
    [N]: (force [N], stiffness ∂f/∂v projected PSD [N·s/m] as a scalar on the tangent plane, and the unit direction
    the stiffness excludes (the sliding direction; zero when stuck)).

    Stuck (static, ``status`` CONTACT_STUCK): f = −(mu_s F_n / ε) v_t, a stiff viscous force that reaches mu_s F_n
    at ε = ``slip_speed``, so a vertex held by friction creeps at most ~ε; one moving faster than ε has broken loose.
    Sliding (kinetic): f = −mu_k F_n v_t / |v_t|, whose derivative is (mu_k F_n / |v_t|)(I − t tᵀ) on the plane.
    """
    if not (normal_force > 0.0):
        return wp.vec3(0.0), 0.0, wp.vec3(0.0)
    if status == CONTACT_STUCK:
        c = mu_s * normal_force / slip_speed
        return vt * (-c), c, wp.vec3(0.0)
    speed = wp.length(vt)
    if speed > 0.0:
        c = mu_k * normal_force / speed
        return vt * (-c), c, vt / speed
    return wp.vec3(0.0), 0.0, wp.vec3(0.0)


@wp.func
def dof_projector(status: int, n: wp.vec3) -> wp.mat33:
    """The directions a vertex may move in a constrained Newton step: all (free), along the floor (on it), none (a
    vertex of infinite mass)."""
    if status == CONTACT_FIXED:
        return wp.mat33(0.0)
    if status == CONTACT_SLIDING or status == CONTACT_STUCK:
        return wp.identity(n=3, dtype=float) - wp.outer(n, n)
    return wp.identity(n=3, dtype=float)


@wp.func
def assemble(
    world: int,
    im_row: int,
    rl_row: int,
    ea_row: int,
    hr_row: int,
    hl_row: int,
    ak_row: int,
    inv_mass: wp.array2d(dtype=float),
    edges: wp.array2d(dtype=wp.int32),
    rest_length: wp.array2d(dtype=float),
    bar_stiffness: wp.array2d(dtype=float),
    bar_stop_strain: wp.array2d(dtype=wp.vec2),
    bar_stop_stiffness: wp.array2d(dtype=float),
    hinges: wp.array2d(dtype=wp.int32),
    hinge_rest: wp.array2d(dtype=float),
    hinge_length: wp.array2d(dtype=float),
    hinge_label: wp.array(dtype=wp.int32),
    k_hinge: float,
    c_hinge: float,
    anchor_vertex: wp.array(dtype=wp.int32),
    anchor_stiffness: wp.array2d(dtype=float),
    anchor_target: wp.array2d(dtype=wp.vec3),
    k_limit: float,
    strain_limit: wp.array(dtype=float),
    inv_dt: float,
    floor_n: wp.vec3,
    mu_s: float,
    mu_k: float,
    slip_speed: float,
    with_hessian: bool,
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    crease_angle: wp.array2d(dtype=float),
    contact: wp.array2d(dtype=wp.int32),
    floor_force: wp.array2d(dtype=wp.vec3),
    bar_strain: wp.array2d(dtype=float),
    hess: wp.array3d(dtype=wp.mat33),
    grad: wp.array2d(dtype=wp.vec3),
):
    """Gradient ∂Φ/∂x of the substep's objective (inertia, bars, creases, anchors; with the Hessian also the floor
    friction, :func:`friction_force`) into ``grad[world]`` and, ``with_hessian``, its Gauss–Newton Hessian projected
    on each vertex's allowed directions into ``hess[world]``. ``crease_angle`` holds the angles at the start of the
    substep (damping, unwrapping).
    Returns 1 if a bar is strained beyond its ``strain_limit`` (per bar; or non-finite), else 0."""
    nv = x.shape[1]
    bw = hess.shape[2] - 1
    eye = wp.identity(n=3, dtype=float)
    inv_dt2 = inv_dt * inv_dt
    for i in range(nv):
        m_dt2 = mass_over_dt2(inv_mass[im_row, i], inv_dt2)
        g = delta[world, i] * m_dt2  # delta is 0 for a vertex of infinite mass
        if with_hessian:
            # m/dt² on the diagonal in every direction, also the fixed ones (keeps the matrix definite; their rows
            # are decoupled by the projection and their update is zero)
            diag = eye * m_dt2
            st = contact[world, i]
            if st == CONTACT_SLIDING or st == CONTACT_STUCK:
                vel = v[world, i] + delta[world, i] * inv_dt
                vt = vel - floor_n * wp.dot(vel, floor_n)
                f, c, t = friction_force(st, vt, wp.dot(floor_force[world, i], floor_n), mu_s, mu_k, slip_speed)
                g = g - f
                diag = diag + (eye - wp.outer(floor_n, floor_n) - wp.outer(t, t)) * (c * inv_dt)
            hess[world, i, 0] = diag
            for k in range(1, bw + 1):
                hess[world, i, k] = wp.mat33(0.0)
        grad[world, i] = g
    for e in range(edges.shape[0]):
        a = edges[e, 0]
        b = edges[e, 1]
        d = x[world, a] - x[world, b]
        length = wp.length(d)
        l0 = rest_length[rl_row, e]
        strain = (length - l0) / l0
        bar_strain[world, e] = strain
        if not (wp.abs(strain) < strain_limit[e]):  # also catches NaN
            return 1
        n = d / length
        ka = bar_stiffness[ea_row, e] / l0
        f = n * (ka * (length - l0))
        k_axial = ka
        # a soft waist bar strained past its stops (−ε_c shortened, +ε_t stretched) turns rigid: the sheet's panels,
        # which the soft bar stands for, bend only so far (without them a hard squeeze flattens the waist triangles
        # into slivers, whose crease gradients blow up, or pinches the waist through the axis)
        stops = bar_stop_strain[world % bar_stop_strain.shape[0], e]
        stop = wp.where(strain < 0.0, -stops[0], stops[1])
        l_stop = l0 * (1.0 + stop)
        k_trans = ka * wp.max(0.0, 1.0 - l0 / length)
        if wp.where(strain < 0.0, strain < stop, strain > stop):
            ks = bar_stop_stiffness[ea_row % bar_stop_stiffness.shape[0], e] / l0
            f = f + n * (ks * (length - l_stop))
            k_axial = k_axial + ks
            k_trans = k_trans + ks * wp.max(0.0, 1.0 - l_stop / length)  # the stop's tension, as the bar's
        grad[world, a] = grad[world, a] + f
        grad[world, b] = grad[world, b] - f
        if with_hessian:
            nn = wp.outer(n, n)
            # the compressive geometric stiffness is dropped (keeps the matrix positive definite)
            kb = k_axial * nn + k_trans * (eye - nn)
            band_add_block(world, hess, a, a, kb)
            band_add_block(world, hess, b, b, kb)
            band_add_block(world, hess, a, b, -kb)
    for h in range(hinges.shape[0]):
        i0 = hinges[h, 0]
        i1 = hinges[h, 1]
        i2 = hinges[h, 2]
        i3 = hinges[h, 3]
        psi, g0, g1, g2, g3 = dihedral_angle_and_gradient(x[world, i0], x[world, i1], x[world, i2], x[world, i3])
        prev = crease_angle[world, h]
        phi = prev + wrap_angle(psi - prev)
        lh = hinge_length[hl_row, h]
        torque = lh * (k_hinge * (phi - hinge_rest[hr_row, h]) + c_hinge * inv_dt * (phi - prev))
        stiff = lh * (k_hinge + c_hinge * inv_dt)
        lo, hi = fold_range(hinge_label[h])
        if phi < lo or phi > hi:
            torque += k_limit * lh * (phi - wp.where(phi < lo, lo, hi))
            stiff += k_limit * lh
        grad[world, i0] = grad[world, i0] + g0 * torque
        grad[world, i1] = grad[world, i1] + g1 * torque
        grad[world, i2] = grad[world, i2] + g2 * torque
        grad[world, i3] = grad[world, i3] + g3 * torque
        if with_hessian:
            # Gauss–Newton: the angle's curvature term (torque ∇²φ) is dropped
            band_add_block(world, hess, i0, i0, stiff * wp.outer(g0, g0))
            band_add_block(world, hess, i1, i1, stiff * wp.outer(g1, g1))
            band_add_block(world, hess, i2, i2, stiff * wp.outer(g2, g2))
            band_add_block(world, hess, i3, i3, stiff * wp.outer(g3, g3))
            band_add_block(world, hess, i1, i0, stiff * wp.outer(g1, g0))
            band_add_block(world, hess, i2, i0, stiff * wp.outer(g2, g0))
            band_add_block(world, hess, i3, i0, stiff * wp.outer(g3, g0))
            band_add_block(world, hess, i2, i1, stiff * wp.outer(g2, g1))
            band_add_block(world, hess, i3, i1, stiff * wp.outer(g3, g1))
            band_add_block(world, hess, i3, i2, stiff * wp.outer(g3, g2))
    for an in range(anchor_vertex.shape[0]):
        pv = anchor_vertex[an]
        ka = anchor_stiffness[ak_row, an]
        if ka > 0.0:
            grad[world, pv] = grad[world, pv] + (x[world, pv] - anchor_target[world, an]) * ka
            if with_hessian:
                band_add_block(world, hess, pv, pv, eye * ka)
    if with_hessian:
        # the Newton step restricted to each vertex's allowed directions: block (u, v) -> P_u B P_v; the removed
        # directions of a diagonal block get m/dt² back (keeps the matrix definite; their update is zero)
        for u in range(nv):
            su = contact[world, u]
            for band in range(bw + 1):
                vv = u - band
                if vv >= 0:
                    sv = contact[world, vv]
                    if su != CONTACT_FREE or sv != CONTACT_FREE:
                        pu = dof_projector(su, floor_n)
                        blk = pu * hess[world, u, band] * dof_projector(sv, floor_n)
                        if band == 0:
                            blk = blk + (eye - pu) * mass_over_dt2(inv_mass[im_row, u], inv_dt2)
                        hess[world, u, band] = blk
    return 0


@wp.kernel
def implicit_step(
    # Model:
    inv_mass: wp.array2d(dtype=float),
    gravity: wp.array(dtype=float),
    damping: wp.array(dtype=float),
    edges: wp.array2d(dtype=wp.int32),
    rest_length: wp.array2d(dtype=float),
    bar_stiffness: wp.array2d(dtype=float),
    bar_stop_strain: wp.array2d(dtype=wp.vec2),
    bar_stop_stiffness: wp.array2d(dtype=float),
    hinges: wp.array2d(dtype=wp.int32),
    hinge_rest: wp.array2d(dtype=float),
    hinge_length: wp.array2d(dtype=float),
    hinge_label: wp.array(dtype=wp.int32),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    fold_limit_stiffness: wp.array(dtype=float),
    anchor_vertex: wp.array(dtype=wp.int32),
    anchor_stiffness: wp.array2d(dtype=float),
    floor_incline: wp.array(dtype=float),
    mu_static: wp.array(dtype=float),
    mu_kinetic: wp.array(dtype=float),
    dt: float,
    num_substeps: int,
    newton: int,
    slip_speed: float,
    strain_limit: wp.array(dtype=float),
    speed_limit: float,
    fold_tolerance: float,
    # Data in:
    f_ext: wp.array2d(dtype=wp.vec3),
    anchor_target: wp.array2d(dtype=wp.vec3),
    # Data out:
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    floor_force: wp.array2d(dtype=wp.vec3),
    hess: wp.array3d(dtype=wp.mat33),
    grad: wp.array2d(dtype=wp.vec3),
    bar_strain: wp.array2d(dtype=float),
    crease_angle: wp.array2d(dtype=float),
    contact: wp.array2d(dtype=wp.int32),
    unstable: wp.array(dtype=wp.int32),
    step_count: wp.array(dtype=wp.int32),
):
    """``num_substeps`` implicit-Euler substeps of length ``dt`` [s] of one world (module docstring). Launch dim (W,).

    Shapes as :class:`warpworm.model.Model` / :class:`warpworm.model.State`: ``x``, ``v`` (W, V) [m, m/s];
    ``delta (W, V)`` x − x̃ of the current substep [m] (zero between substeps); ``floor_force (W, V)`` the floor's
    force on each vertex in the last substep (normal + friction) [N], also the next substep's first normal-force
    estimate; ``hess (W, V, B + 1)`` (mat33) and
    ``grad (W, V)`` (vec3) the Newton system's scratch; ``crease_angle (W, H)`` [rad] unwrapped, at the end of the step;
    ``contact (W, V)`` 0 free, 1 sliding, 2 stuck (last substep).
    """
    world = wp.tid()
    if unstable[world] != 0:
        return
    nv = x.shape[1]
    nh = hinges.shape[0]
    bw = hess.shape[2] - 1
    im_row = world % inv_mass.shape[0]
    rl_row = world % rest_length.shape[0]
    ea_row = world % bar_stiffness.shape[0]
    hr_row = world % hinge_rest.shape[0]
    hl_row = world % hinge_length.shape[0]
    ak_row = world % anchor_stiffness.shape[0]
    gvec = wp.vec3(0.0, 0.0, -pw(gravity, world))
    damp = 1.0 / (1.0 + pw(damping, world) * dt)
    k_hinge = pw(hinge_stiffness, world)
    c_hinge = pw(hinge_damping, world)
    k_limit = pw(fold_limit_stiffness, world)
    beta = pw(floor_incline, world)
    floor_n = wp.vec3(-wp.sin(beta), 0.0, wp.cos(beta))
    mu_s = pw(mu_static, world)
    mu_k = pw(mu_kinetic, world)
    inv_dt = 1.0 / dt
    inv_dt2 = inv_dt * inv_dt

    for s in range(num_substeps):
        # 1. predict x̃; x starts there, except that a vertex on the floor (touching at the end of the last
        #    substep, or predicted below it) starts stuck on it, unless it is moving off it: every substep first
        #    tries static friction, the Coulomb test below lets go where it cannot hold
        for i in range(nv):
            w_inv = inv_mass[im_row, i]
            vel = wp.vec3(0.0)
            v_old = v[world, i]
            if w_inv > 0.0:
                # linear damping on the velocity carried over, not on this substep's forces (damping them too
                # would lower a hanging worm's weight on its anchors by the factor 1 / (1 + c dt))
                vel = v_old * damp + dt * (gvec + f_ext[world, i] * w_inv)
            p = x[world, i]
            x_prev[world, i] = p
            v[world, i] = vel
            h0 = wp.dot(p, floor_n)
            vn = wp.dot(vel, floor_n)
            start = vel
            st = CONTACT_FREE
            if not (w_inv > 0.0):
                st = CONTACT_FIXED
            elif vn < 0.0 and (contact[world, i] != CONTACT_FREE or h0 + dt * vn < 0.0):
                # on the floor (still, or landing): stuck or sliding by the speed along the floor it has (a contact
                # moving along the floor is sliding whatever it did in the last substep, e.g. a worm kicked at rest);
                # a stuck vertex starts where it is tangentially, a sliding one moves on; neither goes below it
                vt_old = v_old - floor_n * wp.dot(v_old, floor_n)
                st = wp.where(wp.length(vt_old) > slip_speed, CONTACT_SLIDING, CONTACT_STUCK)
                start = floor_n * wp.max(vn, -h0 * inv_dt)
                if st == CONTACT_SLIDING:
                    start = start + (vel - floor_n * vn)
                if contact[world, i] == CONTACT_FREE:
                    floor_force[world, i] = floor_n * (-(h0 + dt * vn) * mass_over_dt2(w_inv, inv_dt2))
            contact[world, i] = st
            x[world, i] = p + dt * start
            delta[world, i] = (start - vel) * dt

        # 2. Newton steps, the contacts updated before each after the first (module docstring)
        bad = int(0)
        for it in range(newton):
            if it >= 1:
                # the floor's normal force at each contact is n · ∂Φ/∂x there (what holds the vertex against the
                # rest of the implicit step); a contact the floor would have to pull lets go; a stuck vertex faster
                # than the slip speed broke loose, a sliding one whose motion reversed (kinetic friction stopped it)
                # or fell below half the slip speed sticks; a free vertex the last step put below the floor lands
                bad = assemble(world, im_row, rl_row, ea_row, hr_row, hl_row, ak_row, inv_mass, edges, rest_length,
                               bar_stiffness, bar_stop_strain, bar_stop_stiffness, hinges, hinge_rest, hinge_length, hinge_label, k_hinge, c_hinge,
                               anchor_vertex, anchor_stiffness, anchor_target, k_limit, strain_limit, inv_dt,
                               floor_n, mu_s, mu_k, slip_speed, False, x, v, delta, crease_angle, contact,
                               floor_force, bar_strain, hess, grad)
                if bad != 0:
                    break
                for i in range(nv):
                    st = contact[world, i]
                    if st == CONTACT_FIXED:
                        continue
                    vel0 = v[world, i]
                    vel = vel0 + delta[world, i] * inv_dt
                    vn = wp.dot(vel, floor_n)
                    if st == CONTACT_FREE:
                        depth = -(wp.dot(x_prev[world, i], floor_n) + dt * vn)
                        if depth > 0.0:
                            vel = vel + floor_n * (depth * inv_dt)
                            x[world, i] = x_prev[world, i] + vel * dt
                            delta[world, i] = (vel - vel0) * dt
                            # stuck: it lets go at the next update if static friction cannot hold it
                            contact[world, i] = CONTACT_STUCK
                            floor_force[world, i] = floor_n * (depth * mass_over_dt2(inv_mass[im_row, i], inv_dt2))
                        continue
                    fn = wp.dot(grad[world, i], floor_n)  # friction is tangential: not in the normal balance
                    if not (fn > 0.0):
                        contact[world, i] = CONTACT_FREE
                        floor_force[world, i] = wp.vec3(0.0)
                        continue
                    vt = vel - floor_n * vn
                    vt_len = wp.length(vt)
                    ff = floor_force[world, i]
                    fn_old = wp.dot(ff, floor_n)
                    # the viscous static friction supplied (mu_s F_n,old / ε)|v_t|: more than mu_s F_n (the normal
                    # force now known) means static friction cannot hold it
                    if st == CONTACT_STUCK and vt_len * fn_old > slip_speed * fn:
                        contact[world, i] = CONTACT_SLIDING
                    elif st == CONTACT_SLIDING and (wp.dot(vt, ff) > 0.0 or vt_len < 0.5 * slip_speed):
                        contact[world, i] = CONTACT_STUCK
                    f, c, t = friction_force(contact[world, i], vt, fn, mu_s, mu_k, slip_speed)
                    floor_force[world, i] = floor_n * fn + f
            bad = assemble(world, im_row, rl_row, ea_row, hr_row, hl_row, ak_row, inv_mass, edges, rest_length,
                           bar_stiffness, bar_stop_strain, bar_stop_stiffness, hinges, hinge_rest, hinge_length, hinge_label, k_hinge, c_hinge,
                           anchor_vertex, anchor_stiffness, anchor_target, k_limit, strain_limit, inv_dt, floor_n,
                           mu_s, mu_k, slip_speed, True, x, v, delta, crease_angle, contact, floor_force, bar_strain,
                           hess, grad)
            if bad != 0:
                break
            # the step restricted to the allowed directions: solve H dx = -grad
            for i in range(nv):
                g = grad[world, i]
                st = contact[world, i]
                if st != CONTACT_FREE:
                    g = dof_projector(st, floor_n) * g
                grad[world, i] = g
            band_cholesky_factor(world, nv, bw, hess)
            band_cholesky_solve(world, nv, bw, hess, grad)
            for i in range(nv):
                dx = -grad[world, i]
                x[world, i] = x[world, i] + dx
                delta[world, i] = delta[world, i] + dx
        if bad != 0:
            freeze_world(world, nv, x, v, x_prev, delta, unstable)
            return

        # 3. floor once more (vertices that reached it in the last step), velocities, crease angles, stability
        for i in range(nv):
            # v = v' + (x − x̃) / dt with x − x̃ summed at its own precision (see floor_landing)
            vel = v[world, i] + delta[world, i] * inv_dt
            delta[world, i] = wp.vec3(0.0)
            p0 = x_prev[world, i]
            st = contact[world, i]
            if st == CONTACT_FREE:
                # a vertex that reaches the floor only in the last step: position-level contact and friction
                p, vel, st, depth = floor_landing(p0, vel, floor_n, mu_s, mu_k, dt)
                floor_force[world, i] = floor_n * (depth * mass_over_dt2(inv_mass[im_row, i], inv_dt2))
            elif st == CONTACT_STUCK or st == CONTACT_SLIDING:
                vn = wp.dot(vel, floor_n)
                vel = vel + floor_n * (wp.max(vn, -wp.dot(p0, floor_n) * inv_dt) - vn)
                vt = vel - floor_n * wp.dot(vel, floor_n)
                fn = wp.dot(floor_force[world, i], floor_n)
                f, c, t = friction_force(st, vt, fn, mu_s, mu_k, slip_speed)
                floor_force[world, i] = floor_n * fn + f
            else:
                vel = wp.vec3(0.0)  # infinite mass
                st = CONTACT_FREE
            if not (wp.length(vel) < speed_limit):  # NaN fails every comparison
                bad = 1
            x[world, i] = p0 + vel * dt
            v[world, i] = vel
            contact[world, i] = st
        crumpled = int(0)
        for h in range(nh):
            psi, g0, g1, g2, g3 = dihedral_angle_and_gradient(x[world, hinges[h, 0]], x[world, hinges[h, 1]],
                                                              x[world, hinges[h, 2]], x[world, hinges[h, 3]])
            prev = crease_angle[world, h]
            phi = prev + wrap_angle(psi - prev)
            crease_angle[world, h] = phi
            lo, hi = fold_range(hinge_label[h])
            if phi < lo - fold_tolerance or phi > hi + fold_tolerance:
                crumpled = 1
        if bad != 0:
            freeze_world(world, nv, x, v, x_prev, delta, unstable)
            return
        if crumpled != 0:
            # a crease folded through its range by more than the tolerance: the sheet crumpled (flag 2)
            freeze_world(world, nv, x, v, x_prev, delta, unstable)
            unstable[world] = WORLD_CRUMPLED
            return
        step_count[world] = step_count[world] + 1
