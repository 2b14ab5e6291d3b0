"""Batched magnet kernels: net force and torque on every magnet of every world, pair wrenches, field maps.

The pair physics lives in :mod:`warpworm.kernels.magnet_fields`; this module only places magnets in the world
(rotating into the source's frame, where the closed forms are defined) and sums over sources.

Conventions: float32 arrays, SI units; sizes are cuboid extents (x, y, z) or (d, d, h) for a cylinder (axis +z of
the magnet); moments [A·m²] are given in the magnet's own frame; rotations are ``wp.quat`` (x, y, z, w) mapping the
magnet frame to the world. Model ids: the index of the model's name in ``warpworm.ids.MAGNET_MODELS``.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

from .magnet_far_pair import far_cuboid_cylinder_pair_wrench, far_cylinder_pair_wrench, far_pair_rules
from .magnet_fields import (
    F64_0,
    SHAPE_CYLINDER,
    analytic_pair_wrench,
    dipoles_field_local,
    dipoles_pair_wrench,
    magnet_field_local,
)

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
    cuboid and a cylinder at least 2 of the cylinder's, by the multipole-matched ring rule (:mod:`.magnet_far_pair`,
    ~1e-5 of the closed form) instead of the closed form.
    """
    rs = wp.quat_to_matrix(s_rot)
    rt = wp.quat_to_matrix(t_rot)
    r_rel = wp.transpose(rs) * rt
    t_rel = wp.transpose(rs) * (t_pos - s_pos)
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    nphi = int(0)
    s_rule = wp.vec4(0.0)
    t_rule = wp.vec4(0.0)
    taken = False
    if model == MODEL_ANALYTIC and far_field != 0:
        nphi, s_rule, t_rule = far_pair_rules(s_shape, s_size, t_shape, t_size, wp.length(t_rel))
        if nphi == 0:
            taken, force, torque = far_cuboid_cylinder_pair_wrench(s_shape, s_size, s_m, t_shape, t_size, t_m, r_rel,
                                                                   t_rel, max_panels)
    if nphi > 0:
        force, torque = far_cylinder_pair_wrench(s_rule, s_m, t_rule, t_m, r_rel, t_rel, nphi)
    elif model == MODEL_ANALYTIC and not taken:
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
    elif model != MODEL_ANALYTIC:
        force, torque = dipoles_pair_wrench(s_shape, s_size, s_m, t_shape, t_size, t_m, r_rel, t_rel, density)
    return rs * force, rs * torque


@wp.kernel
def world_wrench_kernel(
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
    epm_wrench: int,
    # Data in:
    pos: wp.array2d(dtype=wp.vec3),
    rot: wp.array2d(dtype=wp.quat),
    # Data out:
    force_out: wp.array2d(dtype=wp.vec3),
    torque_out: wp.array2d(dtype=wp.vec3),
):
    """Net magnetic force and torque on magnet ``i`` of world ``world`` from all other magnets of that world.

    Launch dim (W, M). Model arrays are read as ``a[world % a.shape[0]]`` (rows of ``shape``/``size``/``moment``
    too), so one shared row or one per world both work. A magnet with zero moment is absent: it neither acts nor
    is acted on (its outputs are zero). ``epm_wrench`` = 0 skips the wrench on magnet 0 (the EPM, which the
    dynamics moves along its path whatever acts on it): its outputs are written as zero at no cost, and the
    other magnets' wrenches (from magnet 0 as well) are unchanged.
    """
    world, i = wp.tid()
    if epm_wrench == 0 and i == 0:
        force_out[world, i] = wp.vec3(0.0)
        torque_out[world, i] = wp.vec3(0.0)
        return
    num_magnets = pos.shape[1]
    mw = model[world % model.shape[0]]
    dens = density[world % density.shape[0]]
    row = world % shape.shape[0]
    t_shape = shape[row, i]
    t_size = size[world % size.shape[0], i]
    t_m = moment[world % moment.shape[0], i]
    t_pos = pos[world, i]
    t_rot = rot[world, i]
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    if wp.length_sq(t_m) > 0.0:
        for j in range(num_magnets):
            s_m = moment[world % moment.shape[0], j]
            if j != i and wp.length_sq(s_m) > 0.0:
                f, t = pair_wrench(
                    mw,
                    shape[row, j],
                    size[world % size.shape[0], j],
                    s_m,
                    pos[world, j],
                    rot[world, j],
                    t_shape,
                    t_size,
                    t_m,
                    t_pos,
                    t_rot,
                    dens,
                    gl_x,
                    gl_w,
                    max_panels,
                    far_field,
                )
                force += f
                torque += t
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

    Every input is read as ``a[k % a.shape[0]]``: one magnet / pose / density shared, or one per pair.
    """
    k = wp.tid()
    f, t = pair_wrench(
        model[k % model.shape[0]],
        s_shape[k % s_shape.shape[0]],
        s_size[k % s_size.shape[0]],
        s_moment[k % s_moment.shape[0]],
        s_pos[k % s_pos.shape[0]],
        s_rot[k % s_rot.shape[0]],
        t_shape[k % t_shape.shape[0]],
        t_size[k % t_size.shape[0]],
        t_moment[k % t_moment.shape[0]],
        t_pos[k % t_pos.shape[0]],
        t_rot[k % t_rot.shape[0]],
        density[k % density.shape[0]],
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


__all__ = ["MODEL_ANALYTIC", "MODEL_DIPOLES", "field_kernel", "pair_wrench", "pair_wrench_kernel",
           "world_wrench_kernel", "F64_0"]
