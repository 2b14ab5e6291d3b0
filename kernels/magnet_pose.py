"""Per-step kernels of the magnets' poses and of the magnetic wrench on the mesh: the kinematic EPM on its path
(sine or keyframes), the IPMs carried by their mounts, and the distribution of each IPM's wrench onto its mount
vertices. Launched by :class:`warpworm.sim.simulator.Simulator` once per step, over all worlds.
"""

from __future__ import annotations

import warp as wp

from .common import PI, TWO_PI, wrow

# forward only (nothing differentiates these kernels): the adjoints doubled-to-tripled the cold compile (docs/dynamics.md)
wp.set_module_options({"enable_backward": False})


@wp.func
def mount_frame(
    x: wp.array2d(dtype=wp.vec3), world: int, mount_vertices: wp.array2d(dtype=wp.int32), m: int
):
    """Body frame of mount ``m``'s vertex ring, as :func:`warpworm.physics.crease.frame_from_vertices`: origin = centroid,
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



@wp.struct
class SinePath:
    """The paper's sinusoidal EPM path (§IV-C) of every world, fields as :data:`warpworm.physics.gaits.SINE_FIELDS`, each
    shape (1,) shared or (W,): start x, y [m], wavelength w [m], amplitude a [m], depth of the centre at closest
    approach [m], theta [rad], period [s], direction ±1, phase [cycles], rewind 0 / 1 (1: the first cycle's pass
    repeats in place, a tethered worm's path: :func:`rewound_advance`)."""

    start_x: wp.array(dtype=float)
    start_y: wp.array(dtype=float)
    wavelength: wp.array(dtype=float)
    amplitude: wp.array(dtype=float)
    depth: wp.array(dtype=float)
    theta: wp.array(dtype=float)
    period: wp.array(dtype=float)
    direction: wp.array(dtype=float)
    phase: wp.array(dtype=float)
    rewind: wp.array(dtype=float)


@wp.struct
class KeyframePath:
    """A keyframed EPM path: ``time (K,)`` ascending [s]; ``pos`` [m] / ``rot`` (x, y, z, w) shape (1 or W, K)."""

    time: wp.array(dtype=float)
    pos: wp.array2d(dtype=wp.vec3)
    rot: wp.array2d(dtype=wp.quat)


REWIND_WINDOW = wp.constant(0.1)
"""Half-width [cycles] of the window around each far point in which a rewound path returns (:func:`rewound_advance`)."""


@wp.func
def rewound_advance(s: float) -> float:
    """The advance (in wavelengths) of a rewound path at s cycles: σ = s − ⌊s⌋ itself for σ in [δ, 1 − δ] (the
    advancing path's first pass, δ = REWIND_WINDOW) and over the first cycle's start (s in [0, δ): nothing comes
    before it), and within δ of each later far point a cubic Hermite back from 1 − δ to δ with slope 1 at both
    ends, so that the EPM's position and velocity stay continuous: a jump back would step the force on a tied worm
    (the force plate) at every far point, where its pulses are cut into cycles."""
    sig = s - wp.floor(s)
    half = float(REWIND_WINDOW)
    out = sig
    if (sig < half and s >= 1.0) or sig > 1.0 - half:
        tau = (sig - (1.0 - half)) / (2.0 * half)
        if sig < half:
            tau = (sig + half) / (2.0 * half)
        t2 = tau * tau
        t3 = t2 * tau
        m = 2.0 * half  # slope 1 in σ is 2δ in τ
        out = (2.0 * t3 - 3.0 * t2 + 1.0) * (1.0 - half) + (t3 - 2.0 * t2 + tau) * m + (
            -2.0 * t3 + 3.0 * t2) * half + (t3 - t2) * m
    return out


@wp.kernel
def epm_sine_pose(
    path: SinePath,
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
    z = 0, i.e. its top face h below the origami base) at half a cycle, and advances w per cycle. With
    ``rewind`` 1 every cycle repeats the first cycle's pass, for a worm tied in place (the force plate), which cannot
    follow the EPM: :func:`rewound_advance`.
    Orientation: the EPM's own +z (its magnetization) at angle theta from +x toward +z in the x-z plane.
    """
    world = wp.tid()
    t = float(step_count[world]) * dt_sub
    period = path.period[wrow(world, path.period.shape[0])]
    phase = path.phase[wrow(world, path.phase.shape[0])]
    rewind = path.rewind[wrow(world, path.rewind.shape[0])]
    start_x = path.start_x[wrow(world, path.start_x.shape[0])]
    start_y = path.start_y[wrow(world, path.start_y.shape[0])]
    direction = path.direction[wrow(world, path.direction.shape[0])]
    wavelength = path.wavelength[wrow(world, path.wavelength.shape[0])]
    depth = path.depth[wrow(world, path.depth.shape[0])]
    amplitude = path.amplitude[wrow(world, path.amplitude.shape[0])]
    theta = path.theta[wrow(world, path.theta.shape[0])]
    s = t / period + phase
    s_adv = s
    if rewind != 0.0:
        s_adv = rewound_advance(s)
    px = start_x + direction * wavelength * s_adv
    pz = -(depth + amplitude * 0.5 * (1.0 + wp.cos(TWO_PI * s)))
    magnet_pos[world, 0] = wp.vec3(px, start_y, pz)
    # rotation about +y by (pi/2 - theta) takes +z to (cos theta, 0, sin theta)
    magnet_rot[world, 0] = wp.quat_from_axis_angle(wp.vec3(0.0, 1.0, 0.0), 0.5 * PI - theta)


@wp.kernel
def epm_keyframe_pose(
    path: KeyframePath,
    dt_sub: float,
    # Data in:
    step_count: wp.array(dtype=wp.int32),
    # Data out:
    magnet_pos: wp.array2d(dtype=wp.vec3),
    magnet_rot: wp.array2d(dtype=wp.quat),
):
    """Kinematic EPM on a keyframed path: linear position, slerped rotation, held before the first / after the last
    key. ``path`` as :class:`KeyframePath`. Launch dim (W,)."""
    world = wp.tid()
    t = float(step_count[world]) * dt_sub
    row = wrow(world, path.pos.shape[0])
    nk = path.time.shape[0]
    k = int(0)
    while k < nk - 2 and t >= path.time[k + 1]:
        k += 1
    t0 = path.time[k]
    t1 = path.time[wp.min(k + 1, nk - 1)]
    u = float(0.0)
    if t1 > t0:
        u = wp.clamp((t - t0) / (t1 - t0), 0.0, 1.0)
    k1 = wp.min(k + 1, nk - 1)
    magnet_pos[world, 0] = path.pos[row, k] * (1.0 - u) + path.pos[row, k1] * u
    magnet_rot[world, 0] = wp.quat_slerp(path.rot[row, k], path.rot[row, k1], u)


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
    row = wrow(world, mount_local_pos.shape[0])
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
