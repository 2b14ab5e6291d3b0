"""Warp kernels of the batched XPBD solver (bar-and-hinge origami, floor friction, anchors, magnet mounts).

Kernels only; the host orchestration is :class:`warpworm.simulator.Simulator`. Every kernel is launched over all
worlds at once, 2-D as ``world, elem = wp.tid()``. Per-world parameters are read as ``p[world % p.shape[0]]`` so
that an array of one value (shared) or one value per world both work. float32, SI units.

Solver (one XPBD iteration per substep, "small steps", Macklin et al. 2019), Jacobi form so that every element of
every world is one independent thread (same code path on CPU and CUDA):

1. :func:`integrate_vertices`: symplectic Euler prediction with gravity, the external (magnetic) force, and linear
   velocity damping.
2. :func:`solve_constraints`: bars, hinges and anchors each compute their XPBD correction from the predicted
   positions and atomically add it to a per-vertex ``delta``.
3. :func:`apply_corrections`: ``x += delta``, floor contact with position-level static/kinetic friction, velocity
   from the position change, and the stability check that freezes a diverging world.

Jacobi needs the stiff constraints to be under-relaxed where several meet at a vertex, or the summed corrections
overshoot. We use mass splitting (Tonge et al. 2012): in the denominators of stiff constraints (bars, anchors,
fold-through limits) a vertex's inverse mass is multiplied by ``split[v]``, the number of such constraints at the
vertex. In the soft limit (compliance >> inverse mass) the split cancels out and the force is the exact spring force,
in the rigid limit the summed correction is the average of the individual ones; both limits are dt-consistent.
Hinge springs are split only as much as their stiffness needs at the substep used (``split_hinge = max(1, 2 G_v)``,
G_v = sum over the vertex's hinges of k L w |grad psi|² dt², computed by the Simulator), bars and anchors among the
bars and anchors at the vertex (``split``), fold-through limits among all of them.
"""

from __future__ import annotations

import warp as wp

LABEL_FLAT = wp.constant(0)
LABEL_MOUNTAIN = wp.constant(1)
LABEL_VALLEY = wp.constant(2)

PI = wp.constant(3.14159265358979)
TWO_PI = wp.constant(6.28318530717959)


# ----------------------------------------------------------------------------------------------------------------
# helpers


@wp.func
def pw(p: wp.array(dtype=float), world: int) -> float:
    """Per-world scalar: one shared value or one per world."""
    return p[world % p.shape[0]]


@wp.func
def wrap_angle(a: float) -> float:
    """Wrap an angle difference into (-pi, pi]."""
    return a - TWO_PI * wp.floor((a + PI) / TWO_PI)


@wp.func
def fold_range(label: int):
    """NoFoldThrough range (lo, hi) [rad] of a crease's signed angle: mountain [−π, 0], valley [0, π], flat [−π, π]."""
    lo = -PI
    hi = PI
    if label == LABEL_MOUNTAIN:
        hi = 0.0
    if label == LABEL_VALLEY:
        lo = 0.0
    return lo, hi


@wp.func
def freeze_world(world: int, num_vertices: int, x: wp.array2d(dtype=wp.vec3), v: wp.array2d(dtype=wp.vec3),
                 x_prev: wp.array2d(dtype=wp.vec3), delta: wp.array2d(dtype=wp.vec3),
                 unstable: wp.array(dtype=wp.int32)):
    """Flag ``world`` unstable and put it back, finite, to the start of the substep at rest (per-world solvers)."""
    unstable[world] = 1
    for i in range(num_vertices):
        x[world, i] = x_prev[world, i]
        v[world, i] = wp.vec3(0.0)
        delta[world, i] = wp.vec3(0.0)
    return 0


@wp.func
def dihedral_angle_and_gradient(xi: wp.vec3, xj: wp.vec3, xk: wp.vec3, xl: wp.vec3):
    """Signed fold angle psi [rad] of the hinge stencil (i, j, k, l) (shared edge j-k; 0 flat, > 0 valley) and its
    exact gradient w.r.t. (x_i, x_j, x_k, x_l) [rad/m], sharing their cross products.

    The convention of :func:`warpworm.crease.dihedral_angles`: psi = atan2((n1 x n2) . e, n1 . n2) with the outward
    wing normals n1 = (x_j - x_i) x (x_k - x_i), n2 = (x_k - x_l) x (x_j - x_l) and e = (x_j - x_k) / |x_j - x_k|.
    Gradient (Liu & Paulino 2017, MERLIN, with psi = pi - theta_MERLIN): d psi/d x_i = L n1/|n1|²,
    d psi/d x_l = L n2/|n2|², x_j and x_k by the wings' projections on the hinge axis (free of translation and
    rotation). Returns (psi, g_i, g_j, g_k, g_l).
    """
    n1 = wp.cross(xj - xi, xk - xi)
    n2 = wp.cross(xk - xl, xj - xl)
    r_kj = xk - xj
    len2 = wp.dot(r_kj, r_kj)
    length = wp.sqrt(len2)
    # (n1 x n2) . e with e = (x_j - x_k) / |x_j - x_k| = -r_kj / length
    psi = wp.atan2(-wp.dot(wp.cross(n1, n2), r_kj) / length, wp.dot(n1, n2))
    # guard degenerate wings (zero area): no gradient rather than inf
    gi = n1 * (length / wp.max(wp.dot(n1, n1), 1.0e-30))
    gl = n2 * (length / wp.max(wp.dot(n2, n2), 1.0e-30))
    pi_ = wp.dot(xi - xj, r_kj) / len2
    pl_ = wp.dot(xk - xl, r_kj) / len2
    gj = gi * (pi_ - 1.0) - gl * pl_
    gk = gl * (pl_ - 1.0) - gi * pi_
    return psi, gi, gj, gk, gl


@wp.func
def mount_frame(
    x: wp.array2d(dtype=wp.vec3), world: int, mount_vertices: wp.array2d(dtype=wp.int32), m: int
):
    """Body frame of mount ``m``'s vertex ring, as :func:`warpworm.crease.frame_from_vertices`: origin = centroid,
    x = ring normal by Newell's rule, y = centroid -> first vertex made orthogonal to x, z = x cross y.

    Returns (origin, R) with R's columns the frame axes in world coordinates (frame -> world).
    """
    nk = mount_vertices.shape[1]
    o = wp.vec3(0.0)
    for k in range(nk):
        o += x[world, mount_vertices[m, k]]
    o = o / float(nk)
    nrm = wp.vec3(0.0)
    for k in range(nk):
        q0 = x[world, mount_vertices[m, k]] - o
        q1 = x[world, mount_vertices[m, (k + 1) % nk]] - o
        nrm += wp.cross(q0, q1)
    ex = wp.normalize(nrm)
    y = x[world, mount_vertices[m, 0]] - o
    ey = wp.normalize(y - ex * wp.dot(y, ex))
    ez = wp.cross(ex, ey)
    return o, wp.matrix_from_cols(ex, ey, ez)


@wp.func
def floor_contact(p: wp.vec3, vel: wp.vec3, p0: wp.vec3, beta: float, mu_s: float, mu_k: float, dt: float):
    """Floor contact and position-level static / kinetic friction of one vertex (eq. 8 of the paper).

    ``p`` the corrected position, ``vel`` its velocity (predicted + correction / dt), ``p0`` the position at the start
    of the substep. The floor is the plane through the origin with normal n = (-sin b, 0, cos b). A penetration d is
    removed along n; the tangential displacement of the substep is cancelled if it is at most mu_s d (stick: back to
    exactly where the substep started, tangentially) and otherwise reduced by mu_k d (kinetic). With d = (F_n/m) dt²
    this is f = min(F_h, mu F_n). Done in velocity space: at small substeps mu d is about one float32 ulp of a
    position. Returns (p, vel, touching).
    """
    n = wp.vec3(-wp.sin(beta), 0.0, wp.cos(beta))
    depth = -wp.dot(p, n)
    touching = int(0)
    if depth > 0.0:
        touching = 1
        p = p + n * depth
        vel = vel + n * (depth / dt)
        vn = wp.dot(vel, n)
        vt = vel - n * vn
        vt_len = wp.length(vt)
        if vt_len * dt <= mu_s * depth:
            # stick: tangentially back to exactly where the substep started (p0 + n dn, not p - s, whose
            # round-off would random-walk downhill)
            p = p0 + n * wp.dot(p - p0, n)
            vel = n * vn
        else:
            vel = vel - vt * (mu_k * depth / (dt * vt_len))
            p = p0 + vel * dt
    return p, vel, touching


# ----------------------------------------------------------------------------------------------------------------
# substep kernels


@wp.kernel
def integrate_vertices(
    # Model:
    inv_mass: wp.array2d(dtype=float),
    gravity: wp.array(dtype=float),
    damping: wp.array(dtype=float),
    dt: float,
    # Data in:
    f_ext: wp.array2d(dtype=wp.vec3),
    unstable: wp.array(dtype=wp.int32),
    # Data out:
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
):
    """Predict positions: v += dt (g + f/m), v /= 1 + c dt, x_prev = x, x += dt v. Launch dim (W, V)."""
    world, i = wp.tid()
    if unstable[world] != 0:
        return
    w_inv = inv_mass[world % inv_mass.shape[0], i]
    vel = v[world, i]
    if w_inv > 0.0:
        vel = vel + dt * (wp.vec3(0.0, 0.0, -pw(gravity, world)) + f_ext[world, i] * w_inv)
        # implicit linear damping: unconditionally stable for any rate * dt
        vel = vel / (1.0 + pw(damping, world) * dt)
    else:
        vel = wp.vec3(0.0)
    p = x[world, i]
    x_prev[world, i] = p
    x[world, i] = p + dt * vel
    v[world, i] = vel


@wp.kernel
def solve_constraints(
    # Model:
    inv_mass: wp.array2d(dtype=float),
    split: wp.array(dtype=float),
    split_hinge: wp.array2d(dtype=float),
    edges: wp.array2d(dtype=wp.int32),
    rest_length: wp.array2d(dtype=float),
    bar_stiffness: wp.array2d(dtype=float),
    hinges: wp.array2d(dtype=wp.int32),
    hinge_rest: wp.array2d(dtype=float),
    hinge_length: wp.array2d(dtype=float),
    hinge_label: wp.array(dtype=wp.int32),
    hinge_stiffness: wp.array(dtype=float),
    hinge_damping: wp.array(dtype=float),
    anchor_vertex: wp.array(dtype=wp.int32),
    anchor_stiffness: wp.array2d(dtype=float),
    dt: float,
    strain_limit: float,
    # Data in:
    x: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    anchor_target: wp.array2d(dtype=wp.vec3),
    # Data out:
    delta: wp.array2d(dtype=wp.vec3),
    bar_strain: wp.array2d(dtype=float),
    crease_angle: wp.array2d(dtype=float),
    unstable: wp.array(dtype=wp.int32),
):
    """One Jacobi XPBD pass over bars [0, E), hinges [E, E+H) and anchors [E+H, E+H+A). Launch dim (W, E+H+A).

    Bars: C = |x_a - x_b| - L0, compliance L0 / EA [m/N]; writes the Cauchy strain C / L0.
    Hinges: C = phi - phi_rest, compliance 1 / (k_alpha L) [rad/(N m)], Rayleigh-type damping c_alpha L
    (XPBD damping, Macklin 2016); NoFoldThrough: a mountain fold stays in [-pi, 0], a valley fold in [0, pi]
    (a rigid limit replaces the spring outside). The angle is unwrapped against the previous substep's value so
    that passing through +-pi is seen, not aliased; it is written to ``crease_angle``.
    Anchors: C = |x - target|, compliance 1 / strength [m/N].
    """
    world, e = wp.tid()
    if unstable[world] != 0:
        return
    num_edges = edges.shape[0]
    num_hinges = hinges.shape[0]
    im_row = world % inv_mass.shape[0]
    dt2 = dt * dt
    if e < num_edges:
        a = edges[e, 0]
        b = edges[e, 1]
        d = x[world, a] - x[world, b]
        length = wp.length(d)
        l0 = rest_length[world % rest_length.shape[0], e]
        c = length - l0
        strain = c / l0
        bar_strain[world, e] = strain
        if not (wp.abs(strain) < strain_limit):  # also catches NaN
            unstable[world] = 1
            return
        wa = inv_mass[im_row, a]
        wb = inv_mass[im_row, b]
        alpha = l0 / (bar_stiffness[world % bar_stiffness.shape[0], e] * dt2)
        denom = split[a] * wa + split[b] * wb + alpha
        if denom > 0.0 and length > 0.0:
            n = d / length
            dlam = -c / denom
            wp.atomic_add(delta, world, a, n * (wa * dlam))
            wp.atomic_add(delta, world, b, n * (-wb * dlam))
        return
    h = e - num_edges
    if h < num_hinges:
        sh_row = world % split_hinge.shape[0]
        i = hinges[h, 0]
        j = hinges[h, 1]
        k = hinges[h, 2]
        l = hinges[h, 3]
        xi = x[world, i]
        xj = x[world, j]
        xk = x[world, k]
        xl = x[world, l]
        prev = crease_angle[world, h]
        psi, gi, gj, gk, gl = dihedral_angle_and_gradient(xi, xj, xk, xl)
        phi = prev + wrap_angle(psi - prev)
        crease_angle[world, h] = phi
        wi = inv_mass[im_row, i]
        wj = inv_mass[im_row, j]
        wk = inv_mass[im_row, k]
        wl = inv_mass[im_row, l]
        lo, hi = fold_range(hinge_label[h])
        dlam = float(0.0)
        if phi < lo or phi > hi:
            # rigid NoFoldThrough limit: split over every constraint at the vertex
            bound = wp.where(phi < lo, lo, hi)
            denom = (
                (split[i] + split_hinge[sh_row, i]) * wi * wp.length_sq(gi)
                + (split[j] + split_hinge[sh_row, j]) * wj * wp.length_sq(gj)
                + (split[k] + split_hinge[sh_row, k]) * wk * wp.length_sq(gk)
                + (split[l] + split_hinge[sh_row, l]) * wl * wp.length_sq(gl)
            )
            if denom > 0.0:
                dlam = -(phi - bound) / denom
        else:
            length = hinge_length[world % hinge_length.shape[0], h]
            kh = pw(hinge_stiffness, world) * length
            if kh > 0.0:
                alpha = 1.0 / (kh * dt2)
                # XPBD damping (Macklin 2016): gamma = compliance * beta / dt with beta = c L [N m s/rad] and the
                # compliance 1 / (k L) (not alpha-tilde): in the soft limit the force is then k C + c dC/dt
                gamma = pw(hinge_damping, world) * length / (kh * dt)
                rate = float(0.0)
                # Up to 12 hinges share a vertex and their summed Jacobi corrections overshoot once
                # G_v = sum_h k L w |grad|² dt² is not small (k_alpha = 0.02 N/rad diverged at dt = 250 us unsplit).
                # split_hinge = max(1, 2 G_v) (set by the Simulator for its dt) splits only where needed: a full
                # split by the hinge count halved the effective crease stiffness at dt = 125 us.
                wsum = (
                    split_hinge[sh_row, i] * wi * wp.length_sq(gi)
                    + split_hinge[sh_row, j] * wj * wp.length_sq(gj)
                    + split_hinge[sh_row, k] * wk * wp.length_sq(gk)
                    + split_hinge[sh_row, l] * wl * wp.length_sq(gl)
                )
                if gamma > 0.0:  # the fold rate costs four more vertex loads: only when damped
                    rate = (
                        wp.dot(gi, xi - x_prev[world, i])
                        + wp.dot(gj, xj - x_prev[world, j])
                        + wp.dot(gk, xk - x_prev[world, k])
                        + wp.dot(gl, xl - x_prev[world, l])
                    )
                c = phi - hinge_rest[world % hinge_rest.shape[0], h]
                dlam = -(c + gamma * rate) / ((1.0 + gamma) * wsum + alpha)
        if dlam != 0.0:
            wp.atomic_add(delta, world, i, gi * (wi * dlam))
            wp.atomic_add(delta, world, j, gj * (wj * dlam))
            wp.atomic_add(delta, world, k, gk * (wk * dlam))
            wp.atomic_add(delta, world, l, gl * (wl * dlam))
        return
    an = h - num_hinges
    p = anchor_vertex[an]
    strength = anchor_stiffness[world % anchor_stiffness.shape[0], an]
    wpv = inv_mass[im_row, p]
    if strength > 0.0 and wpv > 0.0:
        d = x[world, p] - anchor_target[world, an]
        dist = wp.length(d)
        if dist > 0.0:
            alpha = 1.0 / (strength * dt2)
            dlam = -dist / (split[p] * wpv + alpha)
            wp.atomic_add(delta, world, p, (d / dist) * (wpv * dlam))


@wp.kernel
def apply_corrections(
    # Model:
    floor_incline: wp.array(dtype=float),
    mu_static: wp.array(dtype=float),
    mu_kinetic: wp.array(dtype=float),
    dt: float,
    speed_limit: float,
    # Data in:
    x_prev: wp.array2d(dtype=wp.vec3),
    # Data out:
    delta: wp.array2d(dtype=wp.vec3),
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    contact: wp.array2d(dtype=wp.int32),
    unstable: wp.array(dtype=wp.int32),
    step_count: wp.array(dtype=wp.int32),
):
    """Apply the summed corrections, then floor contact and friction, then velocities. Launch dim (W, V).

    Floor: the plane through the origin with normal n = (-sin b, 0, cos b) (raised toward +x for b > 0).
    A penetration p is removed along n; the tangential displacement of this substep, s, is then cancelled
    entirely if |s| <= mu_s p (static friction: the vertex sticks, so a worm below atan(mu_s) never creeps) or
    reduced by mu_k p (kinetic friction). With p = (F_n / m) dt², this is eq. (8) of the paper at the position level:
    the friction force is min(F_h, mu F_n).
    A world whose vertex becomes non-finite or faster than ``speed_limit`` [m/s] is flagged unstable and frozen; the
    offending vertex is put back to its previous position so that frozen worlds stay finite.
    """
    world, i = wp.tid()
    if unstable[world] != 0:
        delta[world, i] = wp.vec3(0.0)
        return
    corr = delta[world, i]
    delta[world, i] = wp.vec3(0.0)
    p = x[world, i] + corr
    # Velocity = predicted velocity + correction / dt, not (x - x_prev) / dt: positions are float32 of ~0.1 m, and
    # the difference of two of them loses ~1 % of a substep's displacement to a rounding that repeats with the same
    # sign every substep (free fall came out 0.35 % slow that way).
    vel = v[world, i] + corr / dt
    p0 = x_prev[world, i]
    p, vel, touching = floor_contact(p, vel, p0, pw(floor_incline, world), pw(mu_static, world),
                                     pw(mu_kinetic, world), dt)
    speed = wp.length(vel)
    if not (speed < speed_limit):  # NaN fails every comparison
        unstable[world] = 1
        p = p0
        vel = wp.vec3(0.0)
    x[world, i] = p
    v[world, i] = vel
    contact[world, i] = touching
    if i == 0:
        step_count[world] = step_count[world] + 1


# ----------------------------------------------------------------------------------------------------------------
# per-step kernels: magnet poses and the magnetic wrench on the mesh


@wp.kernel
def epm_sine_pose(
    # Model:
    start_x: wp.array(dtype=float),
    start_y: wp.array(dtype=float),
    wavelength: wp.array(dtype=float),
    amplitude: wp.array(dtype=float),
    depth: wp.array(dtype=float),
    theta: wp.array(dtype=float),
    period: wp.array(dtype=float),
    direction: wp.array(dtype=float),
    phase: wp.array(dtype=float),
    dt_sub: float,
    # Data in:
    step_count: wp.array(dtype=wp.int32),
    # Data out:
    magnet_pos: wp.array2d(dtype=wp.vec3),
    magnet_rot: wp.array2d(dtype=wp.quat),
):
    """Kinematic EPM on the paper's sinusoidal path (§IV-C). Launch dim (W,).

    s = t / period + phase (cycles); x = x0 + direction * w * s; z = -(depth + a (1 + cos 2 pi s) / 2): the EPM
    moves beneath the floor, starts far (a below its closest approach), comes closest (its centre ``depth`` below
    z = 0, i.e. its top face h below the origami base) at half a cycle, and advances w per cycle.
    Orientation: the EPM's own +z (its magnetization) at angle theta from +x toward +z in the x-z plane.
    """
    world = wp.tid()
    t = float(step_count[world]) * dt_sub
    s = t / pw(period, world) + pw(phase, world)
    px = pw(start_x, world) + pw(direction, world) * pw(wavelength, world) * s
    pz = -(pw(depth, world) + pw(amplitude, world) * 0.5 * (1.0 + wp.cos(TWO_PI * s)))
    magnet_pos[world, 0] = wp.vec3(px, pw(start_y, world), pz)
    # rotation about +y by (pi/2 - theta) takes +z to (cos theta, 0, sin theta)
    magnet_rot[world, 0] = wp.quat_from_axis_angle(wp.vec3(0.0, 1.0, 0.0), 0.5 * PI - pw(theta, world))


@wp.kernel
def epm_keyframe_pose(
    # Model:
    key_time: wp.array(dtype=float),
    key_pos: wp.array2d(dtype=wp.vec3),
    key_rot: wp.array2d(dtype=wp.quat),
    dt_sub: float,
    # Data in:
    step_count: wp.array(dtype=wp.int32),
    # Data out:
    magnet_pos: wp.array2d(dtype=wp.vec3),
    magnet_rot: wp.array2d(dtype=wp.quat),
):
    """Kinematic EPM on a keyframed path: linear position, slerped rotation, held before the first / after the last
    key. ``key_time (K,)`` ascending [s]; ``key_pos``/``key_rot`` (1 or W, K). Launch dim (W,)."""
    world = wp.tid()
    t = float(step_count[world]) * dt_sub
    row = world % key_pos.shape[0]
    nk = key_time.shape[0]
    k = int(0)
    while k < nk - 2 and t >= key_time[k + 1]:
        k += 1
    t0 = key_time[k]
    t1 = key_time[wp.min(k + 1, nk - 1)]
    u = float(0.0)
    if t1 > t0:
        u = wp.clamp((t - t0) / (t1 - t0), 0.0, 1.0)
    k1 = wp.min(k + 1, nk - 1)
    magnet_pos[world, 0] = key_pos[row, k] * (1.0 - u) + key_pos[row, k1] * u
    magnet_rot[world, 0] = wp.quat_slerp(key_rot[row, k], key_rot[row, k1], u)


@wp.kernel
def ipm_poses(
    # Model:
    mount_vertices: wp.array2d(dtype=wp.int32),
    mount_local_pos: wp.array2d(dtype=wp.vec3),
    mount_local_rot: wp.array2d(dtype=wp.mat33),
    # Data in:
    x: wp.array2d(dtype=wp.vec3),
    # Data out:
    magnet_pos: wp.array2d(dtype=wp.vec3),
    magnet_rot: wp.array2d(dtype=wp.quat),
):
    """Pose of IPM ``m`` (slot m + 1) from its mount: the mount ring's frame composed with the mount's local pose.
    Launch dim (W, 3)."""
    world, m = wp.tid()
    o, R = mount_frame(x, world, mount_vertices, m)
    row = world % mount_local_pos.shape[0]
    magnet_pos[world, m + 1] = o + R * mount_local_pos[row, m]
    magnet_rot[world, m + 1] = wp.quat_from_matrix(R * mount_local_rot[row, m])


@wp.kernel
def distribute_wrench(
    # Model:
    mount_vertices: wp.array2d(dtype=wp.int32),
    # Data in:
    x: wp.array2d(dtype=wp.vec3),
    magnet_pos: wp.array2d(dtype=wp.vec3),
    force: wp.array2d(dtype=wp.vec3),
    torque: wp.array2d(dtype=wp.vec3),
    # Data out:
    f_ext: wp.array2d(dtype=wp.vec3),
):
    """Least-norm vertex forces carrying the wrench of IPM ``m`` onto its K mount vertices. Launch dim (W, 3).

    With r_k = x_k - c (c the vertices' centroid), f_k = F / K + w x r_k with J w = T_c, J = sum(|r|^2 I - r r^T),
    T_c = T + (p - c) x F the torque about c (T is about the magnet centre p). Then sum f_k = F and
    sum (x_k - p) x f_k = T exactly, with the smallest sum |f_k|^2. ``f_ext`` must be zeroed before.
    """
    world, m = wp.tid()
    nk = mount_vertices.shape[1]
    c = wp.vec3(0.0)
    for k in range(nk):
        c += x[world, mount_vertices[m, k]]
    c = c / float(nk)
    J = wp.mat33(0.0)
    for k in range(nk):
        r = x[world, mount_vertices[m, k]] - c
        J += wp.diag(wp.vec3(wp.dot(r, r))) - wp.outer(r, r)
    f = force[world, m + 1]
    tc = torque[world, m + 1] + wp.cross(magnet_pos[world, m + 1] - c, f)
    # J is SPD for non-collinear mount vertices; the tiny ridge keeps a collinear mount finite (no twist about it)
    tr = J[0, 0] + J[1, 1] + J[2, 2]
    omega = wp.inverse(J + wp.diag(wp.vec3(1.0e-9 * tr))) * tc
    for k in range(nk):
        vk = mount_vertices[m, k]
        r = x[world, vk] - c
        wp.atomic_add(f_ext, world, vk, f / float(nk) + wp.cross(omega, r))
