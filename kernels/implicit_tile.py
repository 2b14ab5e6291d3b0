"""The implicit-Euler substep with one block of threads per world: the GPU path designed for occupancy.

Same physics, same algorithm and, element by element, the same arithmetic as
:func:`warpworm.kernels.implicit_euler.implicit_step` (predictor, floor contacts, friction, fold limits, strain and
speed checks, crumple flag; read that module's docstring), but laid out for a GPU: the kernel is launched with
``wp.launch_tiled(kernel, dim=W, block_dim=T)`` and the T threads of a block share one world.

- Per-vertex phases (prediction, the contact update between Newton steps, the velocity update) and the crease
  angles: thread ``lane`` takes vertices (hinges) ``lane, lane + T, ...``.
- Assembly by rows, without atomics: thread ``lane`` owns the 3×3 block row of its vertex u in the block band
  ``hess[world, u, 0..B]`` (the band path's layout, in the launcher's scratch) and ``grad[world, u]``, and
  gathers the bars and creases incident on u (host-built incidence lists, ascending element index). Each block
  receives the same contributions in the same order as :func:`~warpworm.kernels.implicit_euler.assemble` gives it,
  so the assembled system is bit for bit the band path's; only the factorisation differs.
- Solve, ``dense``: the band is scattered (``wp.tile_scatter_masked``, one entry per thread per call) into a dense
  3V × 3V float32 tile in shared memory, factored by ``wp.tile_cholesky_inplace`` and solved by
  ``wp.tile_cholesky_solve_inplace`` (cuSolverDx in a CUDA cubin when Warp has libmathdx, a cooperative scalar
  factorisation otherwise and on the CPU). The tile is zeroed once per launch: an in-place Cholesky keeps each row's
  envelope (its first non-zero to the diagonal), which for this block band lies inside the band, so the entries
  outside it stay exact zeros and every later Newton step need only rewrite the band. 55 KB of shared memory per
  world (4 worlds per H200 SM). The factor rounds differently from the band path's.
- Solve, band (not ``dense``): the block band is factored in place in ``hess``, column-parallel
  (:func:`block_band_cholesky_factor`: thread 0 the diagonal block, the ≤ B blocks below it one per thread), with
  the band path's arithmetic, so the results are the band path's bit for bit; thread 0 then runs the band path's
  :func:`band_cholesky_solve`. ~No shared memory: one warp per world.
- Block barriers: Warp has no bare ``__syncthreads``; :func:`block_max` (a tile reduction) is one, and also makes a
  flag (a bad strain, a crumpled crease) the whole block's, so every thread takes the same branches and calls the
  same cooperative tile operations (a barrier inside divergent code hangs a GPU block).

Every tile operation must be called by every thread of the block the same number of times: loops around them run
the same count on every thread (e.g. the scatter rounds), never ``range(lane, n, T)``. In Warp 1.19 that includes a
shared tile's element assignment ``t[i, j] = v`` (it ends in a block barrier: per-thread writes of different
entries in divergent code hang or, on CPU fibers, corrupt the tile), hence ``tile_scatter_masked``.

The tile's side N = 3V is a compile-time constant, so the kernel is built per vertex count by
:func:`make_tile_substep_kernel` (one cached module each). float32, SI units.
"""

from __future__ import annotations

import functools

import warp as wp

from .band_cholesky import (band_add_block, band_add_gauss_newton3, band_add_gauss_newton4, band_cholesky_solve,
                            inverse_lower_cholesky3)
from .common import (crease_at_substep_end, dihedral_angle_gradient_and_normals, fold_range, freeze_world, pw,
                     wing_contact_of_normal, wrap_angle)
from .implicit_euler import (
    CONTACT_FIXED,
    CONTACT_FREE,
    CONTACT_SLIDING,
    CONTACT_STUCK,
    CONTACTS_CHANGED,
    CONTACTS_LANDED,
    RELEASED_LET_GO,
    WORLD_CRUMPLED,
    dof_projector,
    floor_landing,
    friction_force,
    mass_over_dt2,
    landing_floor_force,
    newton_start,
    skin_scale,
    starting_contact,
    stick_slip_status,
)

wp.set_module_options({"enable_backward": False})

FLAG_CRUMPLED = wp.constant(1)  # block flag codes, ordered so the block maximum is the worst
FLAG_EXPLODED = wp.constant(2)


@wp.func
def block_max(flag: int) -> int:
    """The largest ``flag`` of the block's threads, returned to every thread. A cooperative tile reduction, so also a
    block barrier: every thread's writes before it (global memory included) are seen by every thread after it.
    Every thread of the block must call it."""
    t = wp.tile(flag)
    m = wp.tile_max(t)
    return m[0]


@wp.func
def bar_terms(
    d: wp.vec3,
    l0: float,
    ea: float,
    stops: wp.vec2,
    bar_stop_stiffness: wp.array2d(dtype=float),
    ks_row: int,
    e: int,
):
    """One bar's strain, force on its first vertex (the second gets −f), unit direction and axial / transverse
    stiffness [N/m] for the bar vector ``d`` = x_a − x_b [m], rest length ``l0`` [m], rigidity ``ea`` [N] and stops
    (shortened, stretched) strain magnitudes. The arithmetic of :func:`implicit_euler.assemble`'s bar loop, as its
    own function (copied: that loop is inline there). Returns (strain, f, n, k_axial, k_trans)."""
    length = wp.length(d)
    strain = (length - l0) / l0
    n = d / length
    ka = ea / l0
    f = n * (ka * (length - l0))
    k_axial = ka
    # a soft waist bar strained past its stops turns rigid (implicit_euler.assemble says why)
    stop = wp.where(strain < 0.0, -stops[0], stops[1])
    l_stop = l0 * (1.0 + stop)
    k_trans = ka * wp.max(0.0, 1.0 - l0 / length)
    if wp.where(strain < 0.0, strain < stop, strain > stop):
        ks = bar_stop_stiffness[ks_row, e] / l0
        f = f + n * (ks * (length - l_stop))
        k_axial = k_axial + ks
        k_trans = k_trans + ks * wp.max(0.0, 1.0 - l_stop / length)
    return strain, f, n, k_axial, k_trans


@wp.func
def hinge_terms(phi: float, prev: float, rest: float, lh: float, label: int, k_hinge: float, c_hinge: float,
                k_limit: float, inv_dt: float):
    """A crease's torque ∂E/∂φ [N·m] and Gauss–Newton stiffness [N·m/rad] at unwrapped angle ``phi`` [rad] (``prev``
    its angle at the start of the substep, ``lh`` its length [m]): spring, implicit damping and the NoFoldThrough
    barrier. The arithmetic of :func:`implicit_euler.assemble`'s crease loop (copied: inline there)."""
    torque = lh * (k_hinge * (phi - rest) + c_hinge * inv_dt * (phi - prev))
    stiff = lh * (k_hinge + c_hinge * inv_dt)
    lo, hi = fold_range(label)
    if phi < lo or phi > hi:
        torque += k_limit * lh * (phi - wp.where(phi < lo, lo, hi))
        stiff += k_limit * lh
    return torque, stiff


@wp.func
def wing_contact_row(world: int, u: int, n: wp.vec3, len2: float, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, a: int,
                     b: int, c: int, lh: float, with_hessian: bool, hess: wp.array3d(dtype=wp.mat33)) -> wp.vec3:
    """Row ``u``'s part of a hinge wing's panel contact barrier (tip ``a``, hinge ``b``–``c``;
    :func:`implicit_euler.wing_contact_terms`): adds the blocks stored in row u and returns
    u's gradient term (zero if u is not in the wing or the wing is clear); ``n`` the wing's normal, ``len2`` the
    hinge's squared length (:func:`~.common.wing_contact_of_normal`)."""
    f, ga, gb, gc, kappa = wing_contact_of_normal(n, len2, p0, p1, p2, lh)
    g = wp.vec3(0.0)
    if kappa > 0.0:
        if a == u:
            g = ga * f
        elif b == u:
            g = gb * f
        elif c == u:
            g = gc * f
        if with_hessian:
            band_add_gauss_newton3(world, hess, u, kappa, a, b, c, ga, gb, gc)
    return g


@wp.func
def assemble_row(
    world: int,
    u: int,
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
    vert_bar_start: wp.array(dtype=wp.int32),
    vert_bar: wp.array(dtype=wp.int32),
    vert_hinge_start: wp.array(dtype=wp.int32),
    vert_hinge: wp.array(dtype=wp.int32),
    k_hinge: float,
    c_hinge: float,
    anchor_vertex: wp.array(dtype=wp.int32),
    anchor_stiffness: wp.array2d(dtype=float),
    anchor_target: wp.array2d(dtype=wp.vec3),
    k_limit: float,
    strain_limit: wp.array(dtype=float),
    inv_dt: float,
    with_hessian: bool,
    x: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    crease_angle: wp.array2d(dtype=float),
    bar_strain: wp.array2d(dtype=float),
    hess: wp.array3d(dtype=wp.mat33),
    grad: wp.array2d(dtype=wp.vec3),
):
    """Vertex ``u``'s row of :func:`implicit_euler.elastic_terms`: ``grad[world, u]`` and, ``with_hessian``, the
    block row ``hess[world, u, 0..B]`` (blocks (u, u − d)), unprojected and without the friction
    (:func:`finish_row` adds them). Only this row is written, so threads with different rows need no atomics;
    ``bar_strain`` of a bar is written by its first vertex's thread. Reads every vertex's x: call it after a
    barrier. Returns 1 if a bar of the row is strained beyond its limit (or non-finite)."""
    bw = hess.shape[2] - 1
    eye = wp.identity(n=3, dtype=float)
    inv_dt2 = inv_dt * inv_dt
    m_dt2 = mass_over_dt2(inv_mass[im_row, u], inv_dt2)
    g = delta[world, u] * m_dt2
    if with_hessian:
        hess[world, u, 0] = eye * m_dt2
        for k in range(1, bw + 1):
            hess[world, u, k] = wp.mat33(0.0)
    for q in range(vert_bar_start[u], vert_bar_start[u + 1]):
        e = vert_bar[q]
        a = edges[e, 0]
        b = edges[e, 1]
        l0 = rest_length[rl_row, e]
        stops = bar_stop_strain[world % bar_stop_strain.shape[0], e]
        strain, f, n, k_axial, k_trans = bar_terms(x[world, a] - x[world, b], l0, bar_stiffness[ea_row, e], stops,
                                                   bar_stop_stiffness, ea_row % bar_stop_stiffness.shape[0], e)
        if a == u:
            bar_strain[world, e] = strain
            if not (wp.abs(strain) < strain_limit[e]):  # also catches NaN
                return 1
            g = g + f
        else:
            g = g - f
        if with_hessian:
            nn = wp.outer(n, n)
            # the compressive geometric stiffness is dropped (keeps the matrix positive definite)
            kb = k_axial * nn + k_trans * (eye - nn)
            band_add_block(world, hess, u, u, kb)
            if wp.max(a, b) == u:
                band_add_block(world, hess, a, b, -kb)
    for q in range(vert_hinge_start[u], vert_hinge_start[u + 1]):
        h = vert_hinge[q]
        i0 = hinges[h, 0]
        i1 = hinges[h, 1]
        i2 = hinges[h, 2]
        i3 = hinges[h, 3]
        x0 = x[world, i0]
        x1 = x[world, i1]
        x2 = x[world, i2]
        x3 = x[world, i3]
        psi, g0, g1, g2, g3, n1, n2, len2 = dihedral_angle_gradient_and_normals(x0, x1, x2, x3)
        prev = crease_angle[world, h]
        phi = prev + wrap_angle(psi - prev)
        torque, stiff = hinge_terms(phi, prev, hinge_rest[hr_row, h], hinge_length[hl_row, h], hinge_label[h],
                                    k_hinge, c_hinge, k_limit, inv_dt)
        if i0 == u:
            g = g + g0 * torque
        elif i1 == u:
            g = g + g1 * torque
        elif i2 == u:
            g = g + g2 * torque
        else:
            g = g + g3 * torque
        if with_hessian:
            # Gauss–Newton (the angle's curvature term dropped): implicit_euler.crease_terms' blocks, those stored in
            # row u (a block (p, q) lives in row max(p, q))
            band_add_gauss_newton4(world, hess, u, stiff, i0, i1, i2, i3, g0, g1, g2, g3)
        g = g + wing_contact_row(world, u, n1, len2, x0, x1, x2, i0, i1, i2, hinge_length[hl_row, h], with_hessian,
                                 hess)
        g = g + wing_contact_row(world, u, n2, len2, x3, x2, x1, i3, i2, i1, hinge_length[hl_row, h], with_hessian,
                                 hess)
    for an in range(anchor_vertex.shape[0]):
        if anchor_vertex[an] == u:
            ka = anchor_stiffness[ak_row, an]
            if ka > 0.0:
                g = g + (x[world, u] - anchor_target[world, an]) * ka
                if with_hessian:
                    band_add_block(world, hess, u, u, eye * ka)
    grad[world, u] = g
    return 0


@wp.func
def finish_row(
    world: int,
    u: int,
    im_row: int,
    inv_mass: wp.array2d(dtype=float),
    inv_dt: float,
    floor_n: wp.vec3,
    mu_s: float,
    mu_k: float,
    mu_back: float,
    floor_fwd: wp.vec3,
    slip_speed: float,
    v: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    contact: wp.array2d(dtype=wp.int32),
    floor_force: wp.array2d(dtype=wp.vec3),
    hess: wp.array3d(dtype=wp.mat33),
    grad: wp.array2d(dtype=wp.vec3),
):
    """Row ``u`` after :func:`assemble_row` and the contact update: the floor friction (implicit_euler's
    ``friction_terms``), the row restricted to the allowed directions (``project_on_contacts``) and the projected
    right-hand side (``newton_solve``). Touches only row u; reads every vertex's contact."""
    bw = hess.shape[2] - 1
    eye = wp.identity(n=3, dtype=float)
    m_dt2 = mass_over_dt2(inv_mass[im_row, u], inv_dt * inv_dt)
    g = grad[world, u]
    su = contact[world, u]
    if su == CONTACT_SLIDING or su == CONTACT_STUCK:
        vel = v[world, u] + delta[world, u] * inv_dt
        vt = vel - floor_n * wp.dot(vel, floor_n)
        f, c, t, k_skin = friction_force(su, vt, wp.dot(floor_force[world, u], floor_n), mu_s, mu_k, mu_back,
                                         floor_fwd, floor_n, slip_speed)
        g = g - f
        hess[world, u, 0] = hess[world, u, 0] + (eye - wp.outer(floor_n, floor_n) - wp.outer(t, t)) * (
            c * inv_dt) + k_skin * inv_dt
    for band in range(bw + 1):
        vv = u - band
        if vv >= 0:
            sv = contact[world, vv]
            if su != CONTACT_FREE or sv != CONTACT_FREE:
                pu = dof_projector(su, floor_n)
                blk = pu * hess[world, u, band] * dof_projector(sv, floor_n)
                if band == 0:
                    blk = blk + (eye - pu) * m_dt2
                hess[world, u, band] = blk
    # the right-hand side of the restricted step
    if su != CONTACT_FREE:
        g = dof_projector(su, floor_n) * g
    grad[world, u] = g
    return 0


@wp.func
def predict_vertex(
    world: int,
    i: int,
    im_row: int,
    inv_mass: wp.array2d(dtype=float),
    gvec: wp.vec3,
    damp: float,
    dt: float,
    inv_dt: float,
    inv_dt2: float,
    floor_n: wp.vec3,
    slip_speed: float,
    f_ext: wp.array2d(dtype=wp.vec3),
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    floor_force: wp.array2d(dtype=wp.vec3),
    contact: wp.array2d(dtype=wp.int32),
    released: wp.array2d(dtype=wp.int32),
):
    """Step 1 of implicit_step for vertex ``i`` (copied from its loop, which is inline there): the prediction x̃ and
    the start of the Newton iteration, a vertex on the floor stuck or sliding on it. Touches only vertex i."""
    w_inv = inv_mass[im_row, i]
    vel = wp.vec3(0.0)
    v_old = v[world, i]
    if w_inv > 0.0:
        vel = v_old * damp + dt * (gvec + f_ext[world, i] * w_inv)
    p = x[world, i]
    x_prev[world, i] = p
    released[world, i] = 0
    v[world, i] = vel
    h0 = wp.dot(p, floor_n)
    st = starting_contact(w_inv, contact[world, i], vel, v_old, h0, floor_n, dt, slip_speed)
    if (st == CONTACT_STUCK or st == CONTACT_SLIDING) and contact[world, i] == CONTACT_FREE:
        floor_force[world, i] = landing_floor_force(h0, vel, floor_n, dt, w_inv, inv_dt2)
    start = newton_start(st, vel, v_old, h0, floor_n, inv_dt)
    contact[world, i] = st
    x[world, i] = p + dt * start
    delta[world, i] = (start - vel) * dt
    return 0


@wp.func
def update_contact(
    world: int,
    i: int,
    im_row: int,
    inv_mass: wp.array2d(dtype=float),
    dt: float,
    inv_dt: float,
    inv_dt2: float,
    floor_n: wp.vec3,
    mu_s: float,
    mu_k: float,
    mu_back: float,
    floor_fwd: wp.vec3,
    slip_speed: float,
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    floor_force: wp.array2d(dtype=wp.vec3),
    grad: wp.array2d(dtype=wp.vec3),
    contact: wp.array2d(dtype=wp.int32),
    released: wp.array2d(dtype=wp.int32),
):
    """implicit_step's contact update before a Newton step after the first, for vertex ``i`` (copied from its loop):
    normal force from the gradient, let go / land / stick / slip. Touches only vertex i. Returns
    implicit_euler.update_contacts' code for this vertex (CONTACTS_LANDED, CONTACTS_CHANGED or 0)."""
    st = contact[world, i]
    if st == CONTACT_FIXED:
        return 0
    vel0 = v[world, i]
    vel = vel0 + delta[world, i] * inv_dt
    vn = wp.dot(vel, floor_n)
    if st == CONTACT_FREE:
        depth = -(wp.dot(x_prev[world, i], floor_n) + dt * vn)
        if depth > 0.0:
            vel = vel + floor_n * (depth * inv_dt)
            x[world, i] = x_prev[world, i] + vel * dt
            delta[world, i] = (vel - vel0) * dt
            contact[world, i] = CONTACT_STUCK
            floor_force[world, i] = floor_n * (depth * mass_over_dt2(inv_mass[im_row, i], inv_dt2))
            return CONTACTS_LANDED
        return 0
    fn = wp.dot(grad[world, i], floor_n)
    if not (fn > 0.0):
        if (released[world, i] & RELEASED_LET_GO) == 0:
            contact[world, i] = CONTACT_FREE
            floor_force[world, i] = wp.vec3(0.0)
            released[world, i] = released[world, i] | RELEASED_LET_GO
            return CONTACTS_CHANGED
        fn = 0.0  # it let go once already: held on the floor, without normal force (nor friction)
    vt = vel - floor_n * vn
    new_st, rel = stick_slip_status(st, vt, floor_force[world, i], fn, floor_n, slip_speed, released[world, i])
    contact[world, i] = new_st
    released[world, i] = rel
    f, c, t, k_skin = friction_force(contact[world, i], vt, fn, mu_s, mu_k, mu_back, floor_fwd, floor_n, slip_speed)
    floor_force[world, i] = floor_n * fn + f
    if contact[world, i] != st:
        return CONTACTS_CHANGED
    return 0


@wp.func
def finish_vertex(
    world: int,
    i: int,
    im_row: int,
    inv_mass: wp.array2d(dtype=float),
    dt: float,
    inv_dt: float,
    inv_dt2: float,
    floor_n: wp.vec3,
    mu_s: float,
    mu_k: float,
    mu_back: float,
    floor_fwd: wp.vec3,
    slip_speed: float,
    speed_limit: float,
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    floor_force: wp.array2d(dtype=wp.vec3),
    contact: wp.array2d(dtype=wp.int32),
) -> int:
    """Step 3 of implicit_step for vertex ``i`` (copied from its loop): the floor once more, the velocity, the
    speed check. Touches only vertex i. Returns 1 if the vertex is too fast or non-finite."""
    bad = int(0)
    vel = v[world, i] + delta[world, i] * inv_dt
    delta[world, i] = wp.vec3(0.0)
    p0 = x_prev[world, i]
    st = contact[world, i]
    if st == CONTACT_FREE:
        k_dir = skin_scale(vel, floor_fwd, floor_n, mu_back)
        p, vel2, st2, depth = floor_landing(p0, vel, floor_n, mu_s * k_dir, mu_k * k_dir, dt)
        vel = vel2
        st = st2
        floor_force[world, i] = floor_n * (depth * mass_over_dt2(inv_mass[im_row, i], inv_dt2))
    elif st == CONTACT_STUCK or st == CONTACT_SLIDING:
        vn = wp.dot(vel, floor_n)
        vel = vel + floor_n * (wp.max(vn, -wp.dot(p0, floor_n) * inv_dt) - vn)
        vt = vel - floor_n * wp.dot(vel, floor_n)
        fn = wp.dot(floor_force[world, i], floor_n)
        f, c, t, k_skin = friction_force(st, vt, fn, mu_s, mu_k, mu_back, floor_fwd, floor_n, slip_speed)
        floor_force[world, i] = floor_n * fn + f
    else:
        vel = wp.vec3(0.0)  # infinite mass
        st = CONTACT_FREE
    if not (wp.length(vel) < speed_limit):  # NaN fails every comparison
        bad = 1
    x[world, i] = p0 + vel * dt
    v[world, i] = vel
    contact[world, i] = st
    return bad


@wp.func
def block_band_cholesky_factor(world: int, lane: int, bd: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33)):
    """:func:`warpworm.kernels.band_cholesky.band_cholesky_factor`, column-parallel over the block's ``bd`` threads
    (every thread must call it; ``lane`` its index) with the same arithmetic, entry by entry, so the factor is bit for
    bit the band path's. Column j: thread 0 factors the diagonal block (it also updated row j + 1 in column j − 1, so
    it needs no barrier for it); a barrier; the ≤ B blocks below it, one row per thread. One barrier per column."""
    for j in range(nv):
        if lane == 0:
            s = mat[world, j, 0]
            for k in range(wp.max(0, j - bw), j):
                l = mat[world, j, j - k]
                s = s - l * wp.transpose(l)
            mat[world, j, 0] = inverse_lower_cholesky3(s)
        block_max(0)  # the diagonal's inverse before the rows below read it
        for i in range(j + 1 + lane, wp.min(nv, j + bw + 1), bd):
            inv_t = wp.transpose(mat[world, j, 0])
            t = mat[world, i, i - j]
            for k in range(wp.max(0, i - bw), j):
                t = t - mat[world, i, i - k] * wp.transpose(mat[world, j, j - k])
            mat[world, i, i - j] = t * inv_t
    block_max(0)  # the last column before anyone reads the factor
    return 0


MAX_REGISTERS = 128
"""Registers per thread the kernel is compiled for on CUDA (``__maxnreg__``). Unbounded, ptxas (CUDA 13.0, sm_90)
gives it 192 (band) and 241 (dense), which caps an H200 SM at 10 one-warp worlds (band) and 2 four-warp worlds
(dense, although its shared memory holds 4); at 128 it spills 168 / 296 bytes per thread (stores; L1-resident local
memory) and 16 band or 4 dense worlds fit an SM. To be confirmed on a GPU (``None`` lifts the bound)."""


@functools.cache
def make_tile_substep_kernel(num_vertices: int, bandwidth: int, dense: bool = True,
                             max_registers: int | None = MAX_REGISTERS):
    """The block-per-world substep kernel for worms of ``num_vertices`` vertices and Newton-matrix half-bandwidth
    ``bandwidth`` (vertex blocks); one module per (shape, solve).

    ``dense``: the Newton systems are factored as a dense 3V × 3V float32 tile in shared memory (``wp.tile_cholesky``;
    the tile's side is a compile-time constant, hence the factory). Otherwise the block band is factored in place
    in ``hess`` by :func:`block_band_cholesky_factor` (column-parallel, bit for bit the band path's factor; ~0 shared
    memory) and solved by thread 0 with :func:`band_cholesky_solve`."""
    if num_vertices < 1 or bandwidth < 0:
        raise ValueError(f"num_vertices must be >= 1 and bandwidth >= 0, got {num_vertices}, {bandwidth}")
    N = 3 * num_vertices
    DENSE = bool(dense)
    SLOTS = num_vertices * (bandwidth + 1) * 9  # 3x3 entries of the lower block band, with the out-of-range ones

    @wp.kernel(enable_backward=False, module="unique", cuda_max_registers=max_registers)
    def implicit_step_tile(
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
        friction_backward_ratio: wp.array(dtype=float),
        vert_bar_start: wp.array(dtype=wp.int32),
        vert_bar: wp.array(dtype=wp.int32),
        vert_hinge_start: wp.array(dtype=wp.int32),
        vert_hinge: wp.array(dtype=wp.int32),
        dt: float,
        num_substeps: int,
        newton: int,
        newton_tol: float,
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
        released: wp.array2d(dtype=wp.int32),
        bar_strain: wp.array2d(dtype=float),
        crease_angle: wp.array2d(dtype=float),
        contact: wp.array2d(dtype=wp.int32),
        unstable: wp.array(dtype=wp.int32),
        step_count: wp.array(dtype=wp.int32),
    ):
        """``num_substeps`` implicit substeps of one world per block: launch_tiled dim (W,), any block_dim. The
        arguments of implicit_euler.implicit_step (same shapes and units) plus the vertex -> incident bar / hinge
        lists (CSR, ascending element index: ``vert_bar[vert_bar_start[u]:vert_bar_start[u + 1]]``). ``hess`` must
        have ``bandwidth + 1`` blocks per row."""
        world, lane = wp.tid()
        bd = wp.block_dim()
        if unstable[world] != 0:  # the same for every thread of the block: the whole block leaves
            return
        nv = x.shape[1]
        nh = hinges.shape[0]
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
        mu_back = pw(friction_backward_ratio, world)
        floor_fwd = wp.vec3(wp.cos(beta), 0.0, wp.sin(beta))
        inv_dt = 1.0 / dt
        inv_dt2 = inv_dt * inv_dt
        slot_rounds = (SLOTS + bd - 1) // bd
        rhs_rounds = (N + bd - 1) // bd

        if wp.static(DENSE):
            # the world's Newton matrix (lower triangle; factored in place) and right-hand side, in shared memory
            mat = wp.tile_zeros(shape=(N, N), dtype=float, storage="shared")
            rhs = wp.tile_zeros(shape=(N,), dtype=float, storage="shared")

        for s in range(num_substeps):
            # 1. prediction (implicit_step's step 1)
            for i in range(lane, nv, bd):
                predict_vertex(world, i, im_row, inv_mass, gvec, damp, dt, inv_dt, inv_dt2, floor_n, slip_speed,
                               f_ext, x, v, x_prev, delta, floor_force, contact, released)
            bad = block_max(0)  # barrier: every x predicted before any row reads it

            # 2. Newton steps, the contacts updated before each after the first (implicit_step's order: one
            # assembly without friction, the contact update, then friction and the projection row by row)
            for it in range(newton):
                flag = int(0)
                for u in range(lane, nv, bd):
                    if assemble_row(world, u, im_row, rl_row, ea_row, hr_row, hl_row, ak_row, inv_mass, edges,
                                    rest_length, bar_stiffness, bar_stop_strain, bar_stop_stiffness, hinges,
                                    hinge_rest, hinge_length, hinge_label, vert_bar_start, vert_bar,
                                    vert_hinge_start, vert_hinge, k_hinge, c_hinge, anchor_vertex, anchor_stiffness,
                                    anchor_target, k_limit, strain_limit, inv_dt, True, x, delta, crease_angle,
                                    bar_strain, hess, grad) != 0:
                        flag = 1
                bad = block_max(flag)  # also the barrier: every row's gradient before the contacts read it
                if bad != 0:
                    break
                if it >= 1:
                    change = int(0)
                    for i in range(lane, nv, bd):
                        change = wp.max(change, update_contact(world, i, im_row, inv_mass, dt, inv_dt, inv_dt2,
                                                               floor_n, mu_s, mu_k, mu_back, floor_fwd, slip_speed,
                                                               x, v, x_prev, delta, floor_force, grad, contact,
                                                               released))
                    change = block_max(change)  # barrier: contacts and landed positions before the rows read them
                    if change == CONTACTS_LANDED:
                        # x moved: assemble anew at it
                        for u in range(lane, nv, bd):
                            if assemble_row(world, u, im_row, rl_row, ea_row, hr_row, hl_row, ak_row, inv_mass,
                                            edges, rest_length, bar_stiffness, bar_stop_strain, bar_stop_stiffness,
                                            hinges, hinge_rest, hinge_length, hinge_label, vert_bar_start, vert_bar,
                                            vert_hinge_start, vert_hinge, k_hinge, c_hinge, anchor_vertex,
                                            anchor_stiffness, anchor_target, k_limit, strain_limit, inv_dt, True, x,
                                            delta, crease_angle, bar_strain, hess, grad) != 0:
                                flag = 1
                        bad = block_max(flag)
                        if bad != 0:
                            break
                for u in range(lane, nv, bd):
                    finish_row(world, u, im_row, inv_mass, inv_dt, floor_n, mu_s, mu_k, mu_back, floor_fwd, slip_speed,
                               v, delta, contact, floor_force, hess, grad)
                bad = block_max(0)  # barrier: every row finished before the solve reads it
                moving = int(0)
                if wp.static(DENSE):
                    # the band into the tile: one entry per thread per round, block (u, u - d) entry (a, b); the
                    # diagonal blocks' upper entries are skipped (the factorisation reads the lower triangle only)
                    for r in range(slot_rounds):
                        q = r * bd + lane
                        u = q // (9 * (bandwidth + 1))
                        rem = q - u * 9 * (bandwidth + 1)
                        d = rem // 9
                        a = (rem - d * 9) // 3
                        b = rem - d * 9 - a * 3
                        vv = u - d
                        ok = q < SLOTS and vv >= 0 and (d > 0 or b <= a)
                        row = int(0)
                        col = int(0)
                        val = float(0.0)
                        if ok:
                            row = 3 * u + a
                            col = 3 * vv + b
                            val = hess[world, u, d][a, b]
                        wp.tile_scatter_masked(mat, row, col, val, ok)
                    for r in range(rhs_rounds):
                        q = r * bd + lane
                        ok = q < N
                        val = float(0.0)
                        idx = int(0)
                        if ok:
                            idx = q
                            val = grad[world, q // 3][q - (q // 3) * 3]
                        wp.tile_scatter_masked(rhs, idx, val, ok)
                    wp.tile_cholesky_inplace(mat)
                    wp.tile_cholesky_solve_inplace(mat, rhs)
                    for i in range(lane, nv, bd):
                        dx = -wp.vec3(rhs[3 * i], rhs[3 * i + 1], rhs[3 * i + 2])
                        x[world, i] = x[world, i] + dx
                        delta[world, i] = delta[world, i] + dx
                        if not (wp.length(dx) < newton_tol):
                            moving = 1
                else:
                    block_band_cholesky_factor(world, lane, bd, nv, bandwidth, hess)
                    if lane == 0:
                        band_cholesky_solve(world, nv, bandwidth, hess, grad)
                    bad = block_max(0)  # barrier: the step solved before every thread reads its rows
                    for i in range(lane, nv, bd):
                        dx = -grad[world, i]
                        x[world, i] = x[world, i] + dx
                        delta[world, i] = delta[world, i] + dx
                        if not (wp.length(dx) < newton_tol):
                            moving = 1
                moving = block_max(moving)  # also the barrier: the step taken before the next rows read x
                if it >= 1 and moving == 0:
                    break  # converged (implicit_step's test: no vertex moved by newton_tol or more)
            if bad != 0:
                if lane == 0:
                    freeze_world(world, nv, x, v, x_prev, delta, unstable)
                return

            # 3. floor once more, velocities, crease angles, stability
            flag = int(0)
            for i in range(lane, nv, bd):
                if finish_vertex(world, i, im_row, inv_mass, dt, inv_dt, inv_dt2, floor_n, mu_s, mu_k, mu_back,
                                 floor_fwd, slip_speed,
                                 speed_limit, x, v, x_prev, delta, floor_force, contact) != 0:
                    flag = FLAG_EXPLODED
            bad = block_max(flag)  # barrier: every final x before the crease angles read them
            for h in range(lane, nh, bd):
                phi, crumpled = crease_at_substep_end(crease_angle[world, h], x[world, hinges[h, 0]],
                                                      x[world, hinges[h, 1]], x[world, hinges[h, 2]],
                                                      x[world, hinges[h, 3]], hinge_label[h], fold_tolerance)
                crease_angle[world, h] = phi
                if crumpled:
                    flag = wp.max(flag, FLAG_CRUMPLED)
            worst = block_max(flag)  # barrier: angles and flags before the next substep moves any vertex
            if worst != 0:
                if lane == 0:
                    freeze_world(world, nv, x, v, x_prev, delta, unstable)
                    if worst == FLAG_CRUMPLED:
                        unstable[world] = WORLD_CRUMPLED
                return
            if lane == 0:
                step_count[world] = step_count[world] + 1

    return implicit_step_tile
