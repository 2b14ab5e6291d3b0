"""The implicit-Euler substep's physics, once: the Warp structs and ``@wp.func``s both launch layouts call.

A substep of length dt finds the x minimising ½ |x − x̃|²_M / dt² + E(x) (x̃ the inertial prediction; E the bars,
hinges with their fold barrier and panel contact, anchors) by Newton steps with the floor's contacts and friction
(:mod:`.floor_contact`) updated between them. Everything here is per vertex or per element, so the banded
layout (:mod:`.implicit_euler`, one thread per world, element loops) and the tile layout (:mod:`.implicit_tile`, a
block of threads per world, one row per thread) assemble the same numbers in the same order. The element adders
take a ``row``: :data:`~.banded_cholesky.ALL_ROWS` adds the whole element, a vertex index only what lands in that
vertex's row of the gradient and of the lower block-banded part. Per-vertex phases take (``first``, ``stride``): the banded
layout passes (0, 1), the tile layout (lane, block_dim). float32, SI units.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

from .banded_cholesky import ALL_ROWS, banded_add_block, banded_add_gauss_newton3, banded_add_gauss_newton4
from .common import (hinge_angle_at_substep_end, dihedral_angle_gradient_and_normals, fold_range,
                     wing_contact_of_normal, wrap_angle, wrow)
from .floor_contact import (CONTACT_FIXED, CONTACT_FREE, CONTACT_SLIDING, CONTACT_STUCK, RELEASED_LET_GO,
                            dof_projector, floor_landing, friction_force, landing_floor_force, mass_over_dt2,
                            newton_start, skin_scale, starting_contact, stick_slip_status)

CONTACTS_CHANGED = wp.constant(1)  # update_contacts: a vertex changed its contact status
CONTACTS_LANDED = wp.constant(2)  # update_contacts: a free vertex landed (its position moved)
WORLD_CRUMPLED = wp.constant(ids.WORLD_CRUMPLED)  # ``unstable`` flag of a crumpled world (ids: the statuses)


@wp.struct
class BarHingeModel:
    """The model arrays the substep reads, named as :class:`warpworm.sim.model.Model`'s ("(R, ...)": R = 1 shared or
    W rows, read at row ``world % R``)."""

    inv_mass: wp.array2d(dtype=float)  # (R, V) [1/kg]
    gravity: wp.array(dtype=float)  # (R,) [m/s²] along −z
    damping: wp.array(dtype=float)  # (R,) linear velocity damping [1/s]
    edges: wp.array2d(dtype=wp.int32)  # (E, 2)
    rest_length: wp.array2d(dtype=float)  # (R, E) [m]
    bar_stiffness: wp.array2d(dtype=float)  # (R, E) EA [N]
    bar_stop_strain: wp.array2d(dtype=wp.vec2)  # (R, E) (shortened, stretched) stop strains
    bar_stop_stiffness: wp.array2d(dtype=float)  # (R, E) EA of the stop [N]
    hinges: wp.array2d(dtype=wp.int32)  # (H, 4)
    hinge_rest_angle: wp.array2d(dtype=float)  # (R, H) [rad]
    hinge_length: wp.array2d(dtype=float)  # (R, H) [m]
    hinge_label: wp.array(dtype=wp.int32)  # (H,)
    hinge_stiffness: wp.array(dtype=float)  # (R,) k_α per metre of hinge [N·m/rad/m]
    hinge_damping: wp.array(dtype=float)  # (R,) c_α per metre of hinge [N·m·s/rad/m]
    fold_limit_stiffness: wp.array(dtype=float)  # (R,) NoFoldThrough barrier per metre [N·m/rad/m]
    anchor_vertex: wp.array(dtype=wp.int32)  # (A,)
    anchor_stiffness: wp.array2d(dtype=float)  # (R, A) [N/m]
    floor_incline: wp.array(dtype=float)  # (R,) [rad] about +y
    mu_static: wp.array(dtype=float)  # (R,)
    mu_kinetic: wp.array(dtype=float)  # (R,)
    friction_backward_ratio: wp.array(dtype=float)  # (R,) μ tail-ward over μ head-ward (1: isotropic)


@wp.struct
class SubstepOptions:
    """The solver's settings (:class:`warpworm.sim.solver.SubstepSettings`)."""

    dt: float  # substep [s]
    num_substeps: int  # substeps per launch
    newton: int  # Newton steps per substep at most (>= 2)
    newton_tol: float  # [m] a Newton step (the second or later) moving no vertex farther than this ends the substep
    refactor: int  # 1: assemble and factor the Hessian at every Newton step; 0: chord steps (banded layout only)
    slip_speed: float  # static-friction regularisation ε [m/s]
    strain_limit: wp.array(dtype=float)  # (E,) |strain| beyond which a world explodes
    speed_limit: float  # [m/s] beyond which (or non-finite) a world explodes
    fold_tolerance: float  # [rad] beyond a hinge's range: the world crumpled


@wp.struct
class BarHingeState:
    """The physical state the substep advances (:class:`warpworm.sim.model.State`'s arrays)."""

    x: wp.array2d(dtype=wp.vec3)  # (W, V) [m] positions
    v: wp.array2d(dtype=wp.vec3)  # (W, V) [m/s] velocities
    floor_force: wp.array2d(dtype=wp.vec3)  # (W, V) [N] the floor's force in the last substep
    bar_strain: wp.array2d(dtype=float)  # (W, E)
    crease_angle: wp.array2d(dtype=float)  # (W, H) [rad] every hinge's fold angle, unwrapped
    contact: wp.array2d(dtype=wp.int32)  # (W, V) CONTACT_*
    unstable: wp.array(dtype=wp.int32)  # (W,) 0, 1 exploded, 2 crumpled, 3 retired (all but 0: skipped)
    step_count: wp.array(dtype=wp.int32)  # (W,) substeps since t = 0


@wp.struct
class NewtonScratch:
    """The solver's own scratch (its values mean nothing between launches, except ``delta``, zero there, and the
    counters)."""

    x_prev: wp.array2d(dtype=wp.vec3)  # (W, V) positions at the start of the substep [m]
    delta: wp.array2d(dtype=wp.vec3)  # (W, V) x − x̃ [m]
    hess: wp.array3d(dtype=wp.mat33)  # (W, V, B + 1) lower block-banded part of the Newton matrix
    grad: wp.array2d(dtype=wp.vec3)  # (W, V) right-hand side, then the Newton step
    released: wp.array2d(dtype=wp.int32)  # (W, V) bit 0: let go of the floor this substep; above: stick/slip switches
    newton_steps: wp.array(dtype=wp.int32)  # (W,) Newton steps taken, summed over substeps (banded layout)
    newton_capped: wp.array(dtype=wp.int32)  # (W,) substeps that took every step without meeting the tolerance
    newton_factors: wp.array(dtype=wp.int32)  # (W,) Newton steps that assembled and factored the Hessian


@wp.struct
class WorldCoefficients:
    """One world's parameter rows and scalars, read once per launch (an integer division per bar and Newton step
    cost ~1 µs per step); the scalars named as :class:`BarHingeModel`'s fields."""

    im_row: int
    rl_row: int
    ea_row: int
    hr_row: int
    hl_row: int
    ak_row: int
    ss_row: int  # bar_stop_strain's
    sk_row: int  # bar_stop_stiffness's
    gravity: wp.vec3  # [m/s²]
    damp: float  # 1 / (1 + c dt): the velocity carried over, damped
    hinge_stiffness: float
    hinge_damping: float
    fold_limit_stiffness: float
    floor_n: wp.vec3  # the floor's unit normal
    mu_static: float
    mu_kinetic: float
    friction_backward_ratio: float
    floor_fwd: wp.vec3  # the floor's tangent along the worm's rest axis (+x tilted with the floor): head-ward
    dt: float
    inv_dt: float
    inv_dt2: float


@wp.func
def world_coefficients(m: BarHingeModel, world: int, dt: float) -> WorldCoefficients:
    c = WorldCoefficients()
    c.im_row = wrow(world, m.inv_mass.shape[0])
    c.rl_row = wrow(world, m.rest_length.shape[0])
    c.ea_row = wrow(world, m.bar_stiffness.shape[0])
    c.hr_row = wrow(world, m.hinge_rest_angle.shape[0])
    c.hl_row = wrow(world, m.hinge_length.shape[0])
    c.ak_row = wrow(world, m.anchor_stiffness.shape[0])
    c.ss_row = wrow(world, m.bar_stop_strain.shape[0])
    c.sk_row = wrow(world, m.bar_stop_stiffness.shape[0])
    c.gravity = wp.vec3(0.0, 0.0, -m.gravity[wrow(world, m.gravity.shape[0])])
    c.damp = 1.0 / (1.0 + m.damping[wrow(world, m.damping.shape[0])] * dt)
    c.hinge_stiffness = m.hinge_stiffness[wrow(world, m.hinge_stiffness.shape[0])]
    c.hinge_damping = m.hinge_damping[wrow(world, m.hinge_damping.shape[0])]
    c.fold_limit_stiffness = m.fold_limit_stiffness[wrow(world, m.fold_limit_stiffness.shape[0])]
    beta = m.floor_incline[wrow(world, m.floor_incline.shape[0])]
    c.floor_n = wp.vec3(-wp.sin(beta), 0.0, wp.cos(beta))
    c.mu_static = m.mu_static[wrow(world, m.mu_static.shape[0])]
    c.mu_kinetic = m.mu_kinetic[wrow(world, m.mu_kinetic.shape[0])]
    c.friction_backward_ratio = m.friction_backward_ratio[wrow(world, m.friction_backward_ratio.shape[0])]
    c.floor_fwd = wp.vec3(wp.cos(beta), 0.0, wp.sin(beta))
    c.dt = dt
    c.inv_dt = 1.0 / dt
    c.inv_dt2 = c.inv_dt * c.inv_dt
    return c


@wp.func
def in_row(row: int, u: int) -> bool:
    """Whether an element adder with ``row`` writes vertex ``u``'s gradient (every vertex with ALL_ROWS)."""
    return row == ALL_ROWS or row == u


@wp.func
def add_to_row(world: int, row: int, u: int, g: wp.vec3, w: NewtonScratch):
    """``grad[world, u] += g`` if ``row`` selects u."""
    if in_row(row, u):
        w.grad[world, u] = w.grad[world, u] + g


# ------------------------------------------------------------------------------------------------------------------
# the floor in a world's coefficients


@wp.func
def world_friction(c: WorldCoefficients, status: int, vt: wp.vec3, normal_force: float, slip_speed: float):
    """:func:`friction_force` with world ``c``'s coefficients and floor."""
    return friction_force(status, vt, normal_force, c.mu_static, c.mu_kinetic, c.friction_backward_ratio,
                          c.floor_fwd, c.floor_n, slip_speed)


# ------------------------------------------------------------------------------------------------------------------
# per-vertex phases of a substep: vertices first, first + stride, ...


@wp.func
def predict(world: int, first: int, stride: int, c: WorldCoefficients, m: BarHingeModel, slip_speed: float,
            f_ext: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch) -> int:
    """Predict x̃ (gravity, the step's force ``f_ext``, damping of the velocity carried over) and start the Newton
    iteration at :func:`newton_start`, a vertex on the floor (:func:`starting_contact`) stuck or sliding on it.
    Returns 1 if a vertex changed its contact status."""
    dt = c.dt
    changed = int(0)
    for i in range(first, s.x.shape[1], stride):
        w_inv = m.inv_mass[c.im_row, i]
        vel = wp.vec3(0.0)
        v_old = s.v[world, i]
        if w_inv > 0.0:
            # damping on the velocity carried over, not on this substep's forces (that would lower a hanging worm's
            # weight on its anchors by 1 / (1 + c dt))
            vel = v_old * c.damp + dt * (c.gravity + f_ext[world, i] * w_inv)
        p = s.x[world, i]
        w.x_prev[world, i] = p
        w.released[world, i] = 0
        s.v[world, i] = vel
        h0 = wp.dot(p, c.floor_n)
        st = starting_contact(w_inv, s.contact[world, i], vel, v_old, h0, c.floor_n, dt, slip_speed)
        if (st == CONTACT_STUCK or st == CONTACT_SLIDING) and s.contact[world, i] == CONTACT_FREE:
            s.floor_force[world, i] = landing_floor_force(h0, vel, c.floor_n, dt, w_inv, c.inv_dt2)
        start = newton_start(st, vel, v_old, h0, c.floor_n, c.inv_dt)
        if st != s.contact[world, i]:
            changed = 1
        s.contact[world, i] = st
        s.x[world, i] = p + dt * start
        w.delta[world, i] = (start - vel) * dt
    return changed


@wp.func
def update_contact(world: int, i: int, c: WorldCoefficients, m: BarHingeModel, slip_speed: float,
                   s: BarHingeState, w: NewtonScratch) -> int:
    """Vertex ``i`` between Newton steps (``w.grad`` holds ∂Φ/∂x): the floor's normal force is n · ∂Φ/∂x; a contact
    the floor would have to pull lets go (once per substep: after that it is held without normal force, so it cannot
    cycle); stick / slip (:func:`stick_slip_status`); a free vertex the last step put below the floor lands.
    Returns CONTACTS_LANDED (x moved), CONTACTS_CHANGED or 0."""
    dt = c.dt
    st = s.contact[world, i]
    if st == CONTACT_FIXED:
        return 0
    vel0 = s.v[world, i]
    vel = vel0 + w.delta[world, i] * c.inv_dt
    vn = wp.dot(vel, c.floor_n)
    if st == CONTACT_FREE:
        depth = -(wp.dot(w.x_prev[world, i], c.floor_n) + dt * vn)
        if depth > 0.0:
            vel = vel + c.floor_n * (depth * c.inv_dt)
            s.x[world, i] = w.x_prev[world, i] + vel * dt
            w.delta[world, i] = (vel - vel0) * dt
            # stuck: it lets go at the next update if static friction cannot hold it
            s.contact[world, i] = CONTACT_STUCK
            s.floor_force[world, i] = c.floor_n * (depth * mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2))
            return CONTACTS_LANDED
        return 0
    fn = wp.dot(w.grad[world, i], c.floor_n)  # friction is tangential: not in the normal balance
    if not (fn > 0.0):
        if (w.released[world, i] & RELEASED_LET_GO) == 0:
            s.contact[world, i] = CONTACT_FREE
            s.floor_force[world, i] = wp.vec3(0.0)
            w.released[world, i] = w.released[world, i] | RELEASED_LET_GO
            return CONTACTS_CHANGED
        fn = 0.0  # it let go once already: held on the floor, without normal force (nor friction)
    vt = vel - c.floor_n * vn
    new_st, rel = stick_slip_status(st, vt, s.floor_force[world, i], fn, c.floor_n, slip_speed, w.released[world, i])
    s.contact[world, i] = new_st
    w.released[world, i] = rel
    f, kf, t, k_skin = world_friction(c, new_st, vt, fn, slip_speed)
    s.floor_force[world, i] = c.floor_n * fn + f
    if new_st != st:
        return CONTACTS_CHANGED
    return 0


@wp.func
def update_contacts(world: int, first: int, stride: int, c: WorldCoefficients, m: BarHingeModel,
                    slip_speed: float, s: BarHingeState, w: NewtonScratch) -> int:
    """:func:`update_contact` of vertices first, first + stride, ...: the largest code."""
    changed = int(0)
    for i in range(first, s.x.shape[1], stride):
        changed = wp.max(changed, update_contact(world, i, c, m, slip_speed, s, w))
    return changed


@wp.func
def finish_vertices(world: int, first: int, stride: int, c: WorldCoefficients, m: BarHingeModel,
                    opt: SubstepOptions, s: BarHingeState, w: NewtonScratch):
    """The floor once more (a vertex that reached it in the last step: :func:`floor_landing`) and v = v' + (x − x̃)
    / dt. Returns (1 if a vertex is faster than ``speed_limit`` or non-finite; 1 if one changed its contact status)."""
    dt = c.dt
    bad = int(0)
    changed = int(0)
    for i in range(first, s.x.shape[1], stride):
        # v = v' + (x − x̃) / dt with x − x̃ summed at its own precision (see floor_landing)
        vel = s.v[world, i] + w.delta[world, i] * c.inv_dt
        w.delta[world, i] = wp.vec3(0.0)
        p0 = w.x_prev[world, i]
        st = s.contact[world, i]
        if st == CONTACT_FREE:
            k_dir = skin_scale(vel, c.floor_fwd, c.floor_n, c.friction_backward_ratio)
            p, vel, st, depth = floor_landing(p0, vel, c.floor_n, c.mu_static * k_dir, c.mu_kinetic * k_dir, dt)
            s.floor_force[world, i] = c.floor_n * (depth * mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2))
        elif st == CONTACT_STUCK or st == CONTACT_SLIDING:
            vn = wp.dot(vel, c.floor_n)
            vel = vel + c.floor_n * (wp.max(vn, -wp.dot(p0, c.floor_n) * c.inv_dt) - vn)
            vt = vel - c.floor_n * wp.dot(vel, c.floor_n)
            fn = wp.dot(s.floor_force[world, i], c.floor_n)
            f, kf, t, k_skin = world_friction(c, st, vt, fn, opt.slip_speed)
            s.floor_force[world, i] = c.floor_n * fn + f
        else:
            vel = wp.vec3(0.0)  # infinite mass
            st = CONTACT_FREE
        if not (wp.length(vel) < opt.speed_limit):  # NaN fails every comparison
            bad = 1
        s.x[world, i] = p0 + vel * dt
        s.v[world, i] = vel
        if st != s.contact[world, i]:
            changed = 1
        s.contact[world, i] = st
    return bad, changed


@wp.func
def update_hinge_angles(world: int, first: int, stride: int, m: BarHingeModel, fold_tolerance: float,
                        s: BarHingeState) -> int:
    """Unwrap hinges first, first + stride, ...'s angles to the end of the substep. Returns 1 if one left its
    NoFoldThrough range by more than ``fold_tolerance`` or a wing collapsed (:func:`~.common.hinge_angle_at_substep_end`):
    the sheet crumpled."""
    crumpled = int(0)
    for h in range(first, m.hinges.shape[0], stride):
        phi, flagged = hinge_angle_at_substep_end(s.crease_angle[world, h], s.x[world, m.hinges[h, 0]],
                                             s.x[world, m.hinges[h, 1]], s.x[world, m.hinges[h, 2]],
                                             s.x[world, m.hinges[h, 3]], m.hinge_label[h], fold_tolerance)
        s.crease_angle[world, h] = phi
        if flagged:
            crumpled = 1
    return crumpled


@wp.func
def apply_step(world: int, i: int, dx: wp.vec3, s: BarHingeState, w: NewtonScratch):
    """x += dx and (x − x̃) += dx for vertex ``i``."""
    s.x[world, i] = s.x[world, i] + dx
    w.delta[world, i] = w.delta[world, i] + dx


# ------------------------------------------------------------------------------------------------------------------
# the Newton system, row by row or element by element (``row``: ALL_ROWS or a vertex)


@wp.func
def inertia_row(world: int, i: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool, w: NewtonScratch):
    """Start vertex ``i``'s row of ``grad`` (and of the banded matrix) with the inertia term M (x − x̃) / dt²; m/dt² on the
    diagonal in every direction, the fixed ones too (keeps the matrix definite; the projection decouples them)."""
    m_dt2 = mass_over_dt2(m.inv_mass[c.im_row, i], c.inv_dt2)
    w.grad[world, i] = w.delta[world, i] * m_dt2  # delta is 0 for a vertex of infinite mass
    if with_hessian:
        w.hess[world, i, 0] = wp.identity(n=3, dtype=float) * m_dt2
        for k in range(1, w.hess.shape[2]):
            w.hess[world, i, k] = wp.mat33(0.0)


@wp.func
def bar_terms(e: int, d: wp.vec3, c: WorldCoefficients, m: BarHingeModel):
    """Bar ``e``'s spring ½ (EA / L0)(L − L0)² at bar vector ``d`` = x_a − x_b [m], and a waist bar's stop past
    |ε| = ε_s (a soft bar standing for panel bending turns rigid: the panels bend only so far). Returns (strain, f
    on a [N], unit direction, axial and transverse stiffness [N/m]); the compressive geometric stiffness is dropped
    (keeps the matrix positive definite)."""
    length = wp.length(d)
    l0 = m.rest_length[c.rl_row, e]
    strain = (length - l0) / l0
    n = d / length
    ka = m.bar_stiffness[c.ea_row, e] / l0
    f = n * (ka * (length - l0))
    k_axial = ka
    stops = m.bar_stop_strain[c.ss_row, e]
    stop = wp.where(strain < 0.0, -stops[0], stops[1])
    l_stop = l0 * (1.0 + stop)
    k_trans = ka * wp.max(0.0, 1.0 - l0 / length)
    if wp.where(strain < 0.0, strain < stop, strain > stop):
        ks = m.bar_stop_stiffness[c.sk_row, e] / l0
        f = f + n * (ks * (length - l_stop))
        k_axial = k_axial + ks
        k_trans = k_trans + ks * wp.max(0.0, 1.0 - l_stop / length)  # the stop's tension, as the bar's
    return strain, f, n, k_axial, k_trans


@wp.func
def add_bar(world: int, e: int, row: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
            with_hessian: bool, s: BarHingeState, w: NewtonScratch) -> int:
    """Add bar ``e`` (:func:`bar_terms`) to the rows ``row`` selects and record its strain (its first vertex's row).
    Returns 1 if it is strained beyond its ``strain_limit`` (or non-finite), else 0."""
    a = m.edges[e, 0]
    b = m.edges[e, 1]
    strain, f, n, k_axial, k_trans = bar_terms(e, s.x[world, a] - s.x[world, b], c, m)
    if in_row(row, a):
        s.bar_strain[world, e] = strain
        if not (wp.abs(strain) < opt.strain_limit[e]):  # also catches NaN
            return 1
        w.grad[world, a] = w.grad[world, a] + f
    add_to_row(world, row, b, -f, w)
    if with_hessian:
        nn = wp.outer(n, n)
        kb = k_axial * nn + k_trans * (wp.identity(n=3, dtype=float) - nn)
        if in_row(row, a):
            banded_add_block(world, w.hess, a, a, kb)
        if in_row(row, b):
            banded_add_block(world, w.hess, b, b, kb)
        if in_row(row, wp.max(a, b)):
            banded_add_block(world, w.hess, a, b, -kb)
    return 0


@wp.func
def hinge_torque(phi: float, prev: float, h: int, c: WorldCoefficients, m: BarHingeModel):
    """Hinge ``h``'s ∂E/∂φ [N·m] and Gauss–Newton stiffness [N·m/rad] at unwrapped angle ``phi`` (``prev`` at the
    start of the substep): spring ½ k_α L (φ − φ0)², damping as the implicit dissipation ½ (c_α L / dt)(φ − φ_n)²,
    and the NoFoldThrough barrier k_lim L beyond the range (a material constant of its own: a barrier scaling with
    k_α would soften with the hinge). Returns (torque, stiffness, L)."""
    lh = m.hinge_length[c.hl_row, h]
    torque = lh * (c.hinge_stiffness * (phi - m.hinge_rest_angle[c.hr_row, h]) + c.hinge_damping * c.inv_dt * (
        phi - prev))
    stiff = lh * (c.hinge_stiffness + c.hinge_damping * c.inv_dt)
    lo, hi = fold_range(m.hinge_label[h])
    if phi < lo or phi > hi:
        torque += c.fold_limit_stiffness * lh * (phi - wp.where(phi < lo, lo, hi))
        stiff += c.fold_limit_stiffness * lh
    return torque, stiff, lh


@wp.func
def add_wing(world: int, row: int, n: wp.vec3, len2: float, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, a: int, b: int,
             cc: int, lh: float, with_hessian: bool, w: NewtonScratch):
    """Add a hinge wing's panel contact barrier (:func:`~.common.wing_contact_of_normal`: tip ``a`` at ``p0``, hinge
    ``b``–``cc``, ``n`` the wing's normal, ``len2`` the hinge's squared length) to the rows ``row`` selects."""
    f, ga, gb, gc, kappa = wing_contact_of_normal(n, len2, p0, p1, p2, lh)
    if kappa > 0.0:
        add_to_row(world, row, a, ga * f, w)
        add_to_row(world, row, b, gb * f, w)
        add_to_row(world, row, cc, gc * f, w)
        if with_hessian:
            banded_add_gauss_newton3(world, w.hess, row, kappa, a, b, cc, ga, gb, gc)


@wp.func
def add_hinge_rows(world: int, row: int, torque: float, stiff: float, i0: int, i1: int, i2: int, i3: int, g0: wp.vec3,
                   g1: wp.vec3, g2: wp.vec3, g3: wp.vec3, with_hessian: bool, w: NewtonScratch):
    """A hinge's torque along its dihedral's gradient ``g0`` … ``g3`` (vertices ``i0`` … ``i3``) into the rows ``row``
    selects, and its Gauss–Newton blocks (``stiff`` g gᵀ) when ``with_hessian``."""
    add_to_row(world, row, i0, g0 * torque, w)
    add_to_row(world, row, i1, g1 * torque, w)
    add_to_row(world, row, i2, g2 * torque, w)
    add_to_row(world, row, i3, g3 * torque, w)
    if with_hessian:
        banded_add_gauss_newton4(world, w.hess, row, stiff, i0, i1, i2, i3, g0, g1, g2, g3)


@wp.func
def add_hinge(world: int, h: int, row: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool,
              s: BarHingeState, w: NewtonScratch):
    """Add hinge ``h`` (:func:`hinge_torque` along the dihedral's gradient, Gauss–Newton: the angle's curvature
    dropped) and its two wings' panel contact (:func:`add_wing`) to the rows ``row`` selects (``crease_angle`` holds
    the angles at the start of the substep: damping, unwrapping)."""
    i0 = m.hinges[h, 0]
    i1 = m.hinges[h, 1]
    i2 = m.hinges[h, 2]
    i3 = m.hinges[h, 3]
    x0 = s.x[world, i0]
    x1 = s.x[world, i1]
    x2 = s.x[world, i2]
    x3 = s.x[world, i3]
    psi, g0, g1, g2, g3, n1, n2, len2 = dihedral_angle_gradient_and_normals(x0, x1, x2, x3)
    prev = s.crease_angle[world, h]
    torque, stiff, lh = hinge_torque(prev + wrap_angle(psi - prev), prev, h, c, m)
    add_hinge_rows(world, row, torque, stiff, i0, i1, i2, i3, g0, g1, g2, g3, with_hessian, w)
    # the wings' normals are the dihedral's own: n1 = (x1 − x0) × (x2 − x0), n2 = (x2 − x3) × (x1 − x3)
    add_wing(world, row, n1, len2, x0, x1, x2, i0, i1, i2, lh, with_hessian, w)
    add_wing(world, row, n2, len2, x3, x2, x1, i3, i2, i1, lh, with_hessian, w)


@wp.func
def add_anchors(world: int, row: int, c: WorldCoefficients, m: BarHingeModel,
                anchor_target: wp.array2d(dtype=wp.vec3), with_hessian: bool, s: BarHingeState, w: NewtonScratch):
    """Add every anchor's spring ½ k |x − target|² to the rows ``row`` selects."""
    for an in range(m.anchor_vertex.shape[0]):
        pv = m.anchor_vertex[an]
        if in_row(row, pv):
            ka = m.anchor_stiffness[c.ak_row, an]
            if ka > 0.0:
                w.grad[world, pv] = w.grad[world, pv] + (s.x[world, pv] - anchor_target[world, an]) * ka
                if with_hessian:
                    banded_add_block(world, w.hess, pv, pv, wp.identity(n=3, dtype=float) * ka)


@wp.func
def friction_row(world: int, i: int, c: WorldCoefficients, slip_speed: float, with_hessian: bool,
                 s: BarHingeState, w: NewtonScratch):
    """Add vertex ``i``'s floor friction (:func:`friction_force` at its Newton iterate's velocity v' + (x − x̃)/dt and
    the normal force of ``floor_force``) to ``grad`` and its stiffness / dt to the diagonal block. Friction depends
    on the contacts, so it is added after they are updated."""
    st = s.contact[world, i]
    if st == CONTACT_SLIDING or st == CONTACT_STUCK:
        vel = s.v[world, i] + w.delta[world, i] * c.inv_dt
        vt = vel - c.floor_n * wp.dot(vel, c.floor_n)
        f, kf, t, k_skin = world_friction(c, st, vt, wp.dot(s.floor_force[world, i], c.floor_n), slip_speed)
        w.grad[world, i] = w.grad[world, i] - f
        if with_hessian:
            w.hess[world, i, 0] = w.hess[world, i, 0] + (
                wp.identity(n=3, dtype=float) - wp.outer(c.floor_n, c.floor_n) - wp.outer(t, t)) * (
                kf * c.inv_dt) + k_skin * c.inv_dt


@wp.func
def project_row(world: int, u: int, c: WorldCoefficients, m: BarHingeModel, s: BarHingeState, w: NewtonScratch):
    """Row ``u`` of the Newton matrix restricted to the vertices' allowed directions: block (u, v) -> P_u B P_v; the
    removed directions of the diagonal block get m/dt² back (keeps the matrix definite; their update is zero)."""
    su = s.contact[world, u]
    for off in range(w.hess.shape[2]):
        vv = u - off
        if vv >= 0:
            sv = s.contact[world, vv]
            if su != CONTACT_FREE or sv != CONTACT_FREE:
                pu = dof_projector(su, c.floor_n)
                blk = pu * w.hess[world, u, off] * dof_projector(sv, c.floor_n)
                if off == 0:
                    blk = blk + (wp.identity(n=3, dtype=float) - pu) * mass_over_dt2(m.inv_mass[c.im_row, u],
                                                                                    c.inv_dt2)
                w.hess[world, u, off] = blk


@wp.func
def project_rhs(world: int, i: int, c: WorldCoefficients, s: BarHingeState, w: NewtonScratch):
    """Vertex ``i``'s right-hand side restricted to its allowed directions."""
    st = s.contact[world, i]
    if st != CONTACT_FREE:
        w.grad[world, i] = dof_projector(st, c.floor_n) * w.grad[world, i]
