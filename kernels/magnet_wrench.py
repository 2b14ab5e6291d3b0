"""Batched magnet kernels: net force and torque on every magnet of every world, pair wrenches, field maps.

The pair physics lives in :mod:`.magnet_dipoles`, :mod:`.magnet_closed_form` and :mod:`.magnet_charges`; this
module only places magnets in the world (rotating into the source's frame, where the closed forms are defined) and
sums over sources.

Conventions: float32 arrays, SI units; sizes are cuboid extents (x, y, z) or (d, d, h) for a cylinder (axis +z of
the magnet); moments [A·m²] are given in the magnet's own frame; rotations are ``wp.quat`` (x, y, z, w) mapping the
magnet frame to the world. Model ids: the index of the model's name in ``warpworm.ids.MAGNET_MODELS``.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

from .common import SHAPE_CYLINDER, wrow
from .magnet_charges import analytic_pair_wrench
from .magnet_closed_form import F64_0, magnet_field_local
from .magnet_dipoles import dipoles_field_local, dipoles_pair_wrench
from .magnet_far_pair import far_pair_wrench


def _cpu_flags_without_slp_cap(flags: str | None) -> str | None:
    """Warp's CPU compiler flags less its cap on the SLP vectorizer's recursion depth (``-slp-recursion-max-depth=4``;
    LLVM's default is 12): only without it do the ring rule's lanes (:func:`.magnet_far_pair.ring_dipoles_on_lanes`)
    compile to whole SIMD expressions (the same operations, so the same bits; the timings: docs/dynamics.md, "Notes
    moved from the code"). ``None`` (LLVM's defaults already) stays None."""
    if flags is None:
        return None
    return " ".join(f for f in flags.split() if not f.startswith("-mllvm=-slp-recursion-max-depth"))


# forward only (nothing differentiates these kernels): the adjoints doubled-to-tripled the cold compile (docs/dynamics.md)
wp.set_module_options({"enable_backward": False,
                       "cpu_compiler_flags": _cpu_flags_without_slp_cap(wp.config.cpu_compiler_flags)})

MODEL_DIPOLES = wp.constant(ids.MODEL_DIPOLES)
MODEL_ANALYTIC = wp.constant(ids.MODEL_ANALYTIC)

MU0 = wp.constant(wp.float64(1.25663706212e-6))


@wp.func
def magnet_volume(shape: int, size: wp.vec3) -> float:
    """Volume [m³] of a cuboid (extents) or cylinder ((d, d, h))."""
    if shape == SHAPE_CYLINDER:
        return 0.7853981633974483 * size[0] * size[0] * size[2]
    return size[0] * size[1] * size[2]


@wp.func
def pair_wrench(
    model: int,
    s_shape: int,
    s_size: wp.vec3,
    s_m: wp.vec3,
    s_pos: wp.vec3,
    s_rot: wp.quat,
    t_shape: int,
    t_size: wp.vec3,
    t_m: wp.vec3,
    t_pos: wp.vec3,
    t_rot: wp.quat,
    density: float,
    gl_x: wp.array(dtype=wp.float64),
    gl_w: wp.array(dtype=wp.float64),
    max_panels: int,
    far_field: int,
):
    """World-frame force [N] and torque about the target centre [N·m] on target t from source s.

    The pair is evaluated in the source's frame (relative pose only), which keeps the closed forms in their
    canonical orientation and removes the large common offset of world positions before any float64 work.
    ``far_field`` = 1 lets the 'analytic' model take two cylinders at least 4 circumscribing radii apart, and a
    cuboid and a cylinder at least 2.5 of the cylinder's, by the multipole-matched ring rule
    (:func:`.magnet_far_pair.far_pair_wrench`, within ~1e-5 of the closed form) instead of the closed form.
    """
    rs = wp.quat_to_matrix(s_rot)
    rt = wp.quat_to_matrix(t_rot)
    r_rel = wp.transpose(rs) * rt
    t_rel = wp.transpose(rs) * (t_pos - s_pos)
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    taken = False
    if model == MODEL_ANALYTIC and far_field != 0:
        taken, force, torque = far_pair_wrench(s_shape, s_size, s_m, t_shape, t_size, t_m, r_rel, t_rel, max_panels)
    if model != MODEL_ANALYTIC:
        force, torque = dipoles_pair_wrench(s_shape, s_size, s_m, t_shape, t_size, t_m, r_rel, t_rel, density)
    elif not taken:
        # J = mu0 m / V (source polarization), M = m / V (target magnetization)
        s_J = wp.vec3d(s_m) * (MU0 / wp.float64(magnet_volume(s_shape, s_size)))
        t_M = wp.vec3d(t_m) / wp.float64(magnet_volume(t_shape, t_size))
        f64, tq64 = analytic_pair_wrench(
            s_shape,
            wp.vec3d(s_size),
            s_J,
            t_shape,
            wp.vec3d(t_size),
            t_M,
            wp.mat33d(r_rel),
            wp.vec3d(t_rel),
            gl_x,
            gl_w,
            max_panels,
        )
        force = wp.vec3(f64)
        torque = wp.vec3(tq64)
    return rs * force, rs * torque


@wp.func
def pair_members(p: int, num_magnets: int) -> wp.vec2i:
    """Magnets (a, b), a < b, of unordered pair ``p`` of a world of ``num_magnets``: (0, 1), (0, 2), …, (1, 2), …"""
    a = int(0)
    rest = p
    while a < num_magnets - 1 and rest >= num_magnets - 1 - a:
        rest -= num_magnets - 1 - a
        a += 1
    return wp.vec2i(a, a + 1 + rest)


@wp.kernel
def world_pair_wrench_kernel(
    # Model:
    model: wp.array(dtype=wp.int32),
    shape: wp.array2d(dtype=wp.int32),
    size: wp.array2d(dtype=wp.vec3),
    moment: wp.array2d(dtype=wp.vec3),
    density: wp.array(dtype=wp.float32),
    gl_x: wp.array(dtype=wp.float64),
    gl_w: wp.array(dtype=wp.float64),
    max_panels: int,
    far_field: int,
    # Data in:
    pos: wp.array2d(dtype=wp.vec3),
    rot: wp.array2d(dtype=wp.quat),
    stopped: wp.array(dtype=wp.int32),
    # Data out:
    pair_force: wp.array3d(dtype=wp.vec3),
    pair_torque: wp.array3d(dtype=wp.vec3),
):
    """The wrench of each unordered magnet pair (a, b), a < b, of each world, on both magnets: ``pair_force[world, p,
    0]`` on a, ``[world, p, 1]`` on b, torques about each magnet's own centre. Launch dim (W, M (M − 1) / 2).

    One evaluation per pair, a the source and b the target (the EPM, magnet 0, is the source of its pairs: the
    integral runs over the IPM, or over the EPM's faces in the IPM's ring field, :func:`pair_wrench`); a's wrench is
    the reaction, F_a = −F_b and τ_a = −τ_b − (c_b − c_a) × F_b (the pair's momentum and angular momentum conserved,
    as the exact wrenches do). Half the pair evaluations of summing each magnet's wrench over its sources; the two
    orders of a pair agree to the quadrature's ~1e-6 (``tests/test_magnets_far_pair.py``). A magnet with zero moment
    is absent: its pairs are zero. Model arrays are read as ``a[wrow(world, a.shape[0])]``. ``stopped`` (W,) or
    empty: a world whose entry is non-zero (a simulator's status: exploded, crumpled, retired) is skipped, its pairs'
    wrenches left as they were."""
    world, p = wp.tid()
    if stopped.shape[0] > 0:
        if stopped[world] != 0:
            return
    ab = pair_members(p, pos.shape[1])
    a = ab[0]
    b = ab[1]
    mrow = wrow(world, moment.shape[0])
    m_a = moment[mrow, a]
    m_b = moment[mrow, b]
    f = wp.vec3(0.0)
    t = wp.vec3(0.0)
    f_a = wp.vec3(0.0)
    t_a = wp.vec3(0.0)
    finite = wp.isfinite(pos[world, a]) and wp.isfinite(pos[world, b]) and wp.isfinite(rot[world, a]) and wp.isfinite(
        rot[world, b])
    if not finite:  # an exploded world's poses: NaN out at once (the quadrature on NaN poses took ~14 ms a world
        # against ~10 us: benchmarks/bench_magnets.py, 'IPM poses NaN')
        f = wp.vec3(wp.nan)
        t = wp.vec3(wp.nan)
        f_a = f
        t_a = t
    elif wp.length_sq(m_a) > 0.0 and wp.length_sq(m_b) > 0.0:
        row = wrow(world, shape.shape[0])
        srow = wrow(world, size.shape[0])
        f, t = pair_wrench(
            model[wrow(world, model.shape[0])],
            shape[row, a],
            size[srow, a],
            m_a,
            pos[world, a],
            rot[world, a],
            shape[row, b],
            size[srow, b],
            m_b,
            pos[world, b],
            rot[world, b],
            density[wrow(world, density.shape[0])],
            gl_x,
            gl_w,
            max_panels,
            far_field,
        )
        f_a = -f
        t_a = -t - wp.cross(pos[world, b] - pos[world, a], f)
    pair_force[world, p, 0] = f_a
    pair_force[world, p, 1] = f
    pair_torque[world, p, 0] = t_a
    pair_torque[world, p, 1] = t


@wp.kernel
def sum_pair_wrenches_kernel(
    epm_wrench: int,
    pair_force: wp.array3d(dtype=wp.vec3),
    pair_torque: wp.array3d(dtype=wp.vec3),
    force_out: wp.array2d(dtype=wp.vec3),
    torque_out: wp.array2d(dtype=wp.vec3),
):
    """Net force and torque on magnet ``i`` of each world: the sum of its pairs' (:func:`world_pair_wrench_kernel`).
    Launch dim (W, M). ``epm_wrench`` = 0 writes magnet 0's (the EPM's) as zero."""
    world, i = wp.tid()
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    if epm_wrench != 0 or i != 0:
        num_magnets = force_out.shape[1]
        for p in range(num_magnets * (num_magnets - 1) / 2):  # the scratch has one unused pair when M = 1
            ab = pair_members(p, num_magnets)
            if ab[0] == i:
                force += pair_force[world, p, 0]
                torque += pair_torque[world, p, 0]
            elif ab[1] == i:
                force += pair_force[world, p, 1]
                torque += pair_torque[world, p, 1]
    force_out[world, i] = force
    torque_out[world, i] = torque


@wp.kernel
def pair_wrench_kernel(
    # Model:
    model: wp.array(dtype=wp.int32),
    s_shape: wp.array(dtype=wp.int32),
    s_size: wp.array(dtype=wp.vec3),
    s_moment: wp.array(dtype=wp.vec3),
    t_shape: wp.array(dtype=wp.int32),
    t_size: wp.array(dtype=wp.vec3),
    t_moment: wp.array(dtype=wp.vec3),
    density: wp.array(dtype=wp.float32),
    gl_x: wp.array(dtype=wp.float64),
    gl_w: wp.array(dtype=wp.float64),
    max_panels: int,
    far_field: int,
    # Data in:
    s_pos: wp.array(dtype=wp.vec3),
    s_rot: wp.array(dtype=wp.quat),
    t_pos: wp.array(dtype=wp.vec3),
    t_rot: wp.array(dtype=wp.quat),
    # Data out:
    force_out: wp.array(dtype=wp.vec3),
    torque_out: wp.array(dtype=wp.vec3),
):
    """Force and torque on target k from source k for a batch of N independent pairs (launch dim N).

    Every input is read as ``a[wrow(k, a.shape[0])]``: one magnet / pose / density shared, or one per pair.
    """
    k = wp.tid()
    f, t = pair_wrench(
        model[wrow(k, model.shape[0])],
        s_shape[wrow(k, s_shape.shape[0])],
        s_size[wrow(k, s_size.shape[0])],
        s_moment[wrow(k, s_moment.shape[0])],
        s_pos[wrow(k, s_pos.shape[0])],
        s_rot[wrow(k, s_rot.shape[0])],
        t_shape[wrow(k, t_shape.shape[0])],
        t_size[wrow(k, t_size.shape[0])],
        t_moment[wrow(k, t_moment.shape[0])],
        t_pos[wrow(k, t_pos.shape[0])],
        t_rot[wrow(k, t_rot.shape[0])],
        density[wrow(k, density.shape[0])],
        gl_x,
        gl_w,
        max_panels,
        far_field,
    )
    force_out[k] = f
    torque_out[k] = t


@wp.kernel
def field_kernel(
    # Model:
    model: int,
    shape: int,
    size: wp.vec3,
    moment: wp.vec3,
    density: float,
    # Data in:
    pos: wp.vec3,
    rot: wp.quat,
    points: wp.array(dtype=wp.vec3),
    # Data out:
    b_out: wp.array(dtype=wp.vec3),
):
    """B [T] of one magnet at world points (launch dim N), evaluated in the magnet's frame."""
    k = wp.tid()
    p = wp.quat_rotate_inv(rot, points[k] - pos)
    b = wp.vec3(0.0)
    if model == MODEL_ANALYTIC:
        J = wp.vec3d(moment) * (MU0 / wp.float64(magnet_volume(shape, size)))
        b = wp.vec3(magnet_field_local(shape, wp.vec3d(size), J, wp.vec3d(p)))
    else:
        b = dipoles_field_local(shape, size, moment, density, p)
    b_out[k] = wp.quat_rotate(rot, b)


__all__ = ["MODEL_ANALYTIC", "MODEL_DIPOLES", "field_kernel", "pair_members", "pair_wrench", "pair_wrench_kernel",
           "sum_pair_wrenches_kernel", "world_pair_wrench_kernel", "F64_0"]
