"""The banded layout's hinges :data:`LANES` at a time: the same numbers as :func:`.substep.add_hinge` and
:func:`.substep.update_hinge_angles`, to the bit, in about half the time on the CPU.

A Newton step of the banded kernel (one thread per world) spent about half its time on the 105 hinges, scalar code
(three cross products, a square root, an atan2, divisions per hinge). Here the geometry of :data:`LANES`
consecutive hinges (positions gathered into vectors of lanes: the wings' normals, the hinge's length, the dihedral
angle and its gradient) is computed with Warp's component-wise vector operations, which the CPU compiler turns into
SIMD instructions. Each lane does the scalar function's operations in the same order (Warp's CPU build contracts
no multiply-add in this code, on either side), so each hinge's numbers are the scalar ones. The rest runs hinge by
hinge in the original order: the torque, the adds into the gradient and the Gauss–Newton blocks, and a wing's
panel contact, which is only evaluated for a hinge whose wing is inside the barrier (rare; the test is the
scalar one, |n|² < (A L²)²). The tile layout keeps the scalar functions (one row per thread), so its bit-for-bit
tests against the banded layout (``tests/test_tile_solver.py``, panel contact included) check this module too.
float32, SI units.
"""

from __future__ import annotations

import warp as wp

from .banded_cholesky import ALL_ROWS
from .common import (LANES, PANEL_CONTACT_ALTITUDE, SLIVER_ALTITUDE, atan2_f32, fold_range, lanes, lanes_cross,
                     lanes_dot, lanes_sqrt, on_gpu, wrap_angle)
from .substep import (BarHingeModel, BarHingeState, NewtonScratch, WorldCoefficients, add_hinge, add_hinge_rows,
                      add_wing, hinge_torque, update_hinge_angles)


@wp.func
def gather_column(world: int, h0: int, col: int, m: BarHingeModel, s: BarHingeState):
    """The positions [m] of stencil vertex ``col`` (``m.hinges``' column: 0 x_i, 1 x_j, 2 x_k, 3 x_l) of hinges
    h0 .. h0 + LANES − 1, by coordinate. (Three vectors of lanes per call: helpers returning many more stopped
    the compiler from keeping the lanes in registers, ~1.7× the time.)"""
    px = lanes()
    py = lanes()
    pz = lanes()
    for k in range(8):
        p = s.x[world, m.hinges[h0 + k, col]]
        px[k] = p[0]
        py[k] = p[1]
        pz[k] = p[2]
    return px, py, pz


@wp.func
def gather_angles(world: int, h0: int, s: BarHingeState) -> lanes:
    """``crease_angle`` [rad] of hinges h0 .. h0 + LANES − 1 (their angles at the start of the substep)."""
    a = lanes()
    for k in range(8):
        a[k] = s.crease_angle[world, h0 + k]
    return a


@wp.func
def lanes_angle(n1x: lanes, n1y: lanes, n1z: lanes, n2x: lanes, n2y: lanes, n2z: lanes, rx: lanes, ry: lanes,
                rz: lanes, length: lanes) -> lanes:
    """The signed fold angle psi [rad] of :func:`~.common.dihedral_angle_and_normals` lane by lane, from the wings'
    normals n1, n2, the hinge r_kj and its length."""
    cx, cy, cz = lanes_cross(n1x, n1y, n1z, n2x, n2y, n2z)
    sin_part = -lanes_dot(cx, cy, cz, rx, ry, rz)
    cos_part = wp.cw_mul(lanes_dot(n1x, n1y, n1z, n2x, n2y, n2z), length)
    psi = lanes()
    for k in range(8):
        psi[k] = atan2_f32(sin_part[k], cos_part[k])
    return psi


@wp.func
def lanes_tip_gradient(nx: lanes, ny: lanes, nz: lanes, length: lanes, nn: lanes):
    """∂psi/∂x of a wing's tip, n · (L / max(|n|², 1e-30)) (:func:`~.common.dihedral_angle_gradient_and_normals`),
    lane by lane; ``nn`` = |n|²."""
    f = wp.cw_div(length, wp.max(nn, lanes(1.0e-30)))
    return wp.cw_mul(nx, f), wp.cw_mul(ny, f), wp.cw_mul(nz, f)


@wp.func
def lanes_hinge_gradient(gax: lanes, gay: lanes, gaz: lanes, gbx: lanes, gby: lanes, gbz: lanes, pa: lanes,
                         pb: lanes):
    """∂psi/∂x of a hinge end, ga (pa − 1) − gb pb, lane by lane (x_j: ga = g_i, gb = g_l, pa = p_i, pb = p_l;
    x_k: the other way round)."""
    pam = pa - lanes(1.0)
    return (wp.cw_mul(gax, pam) - wp.cw_mul(gbx, pb), wp.cw_mul(gay, pam) - wp.cw_mul(gby, pb),
            wp.cw_mul(gaz, pam) - wp.cw_mul(gbz, pb))


@wp.func
def add_hinge_lanes(world: int, h0: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool,
                    s: BarHingeState, w: NewtonScratch):
    """:func:`~.substep.add_hinge` (``ALL_ROWS``) of hinges h0 .. h0 + LANES − 1, one after the other: their
    geometry in lanes, then hinge by hinge the torque, the four gradient rows, the Gauss–Newton blocks and, for a
    wing inside the panel contact barrier, both wings (:func:`~.substep.add_wing`)."""
    xix, xiy, xiz = gather_column(world, h0, 0, m, s)
    xjx, xjy, xjz = gather_column(world, h0, 1, m, s)
    xkx, xky, xkz = gather_column(world, h0, 2, m, s)
    xlx, xly, xlz = gather_column(world, h0, 3, m, s)
    prev = gather_angles(world, h0, s)
    n1x, n1y, n1z = lanes_cross(xjx - xix, xjy - xiy, xjz - xiz, xkx - xix, xky - xiy, xkz - xiz)
    n2x, n2y, n2z = lanes_cross(xkx - xlx, xky - xly, xkz - xlz, xjx - xlx, xjy - xly, xjz - xlz)
    rx = xkx - xjx
    ry = xky - xjy
    rz = xkz - xjz
    len2 = lanes_dot(rx, ry, rz, rx, ry, rz)
    length = lanes_sqrt(len2)
    psi = lanes_angle(n1x, n1y, n1z, n2x, n2y, n2z, rx, ry, rz, length)
    # |n|² once: a second lanes_dot of the same vectors is not merged, and cost ~40 % of the function
    nn1 = lanes_dot(n1x, n1y, n1z, n1x, n1y, n1z)
    nn2 = lanes_dot(n2x, n2y, n2z, n2x, n2y, n2z)
    inv_len2 = wp.cw_div(lanes(1.0), len2)
    gix, giy, giz = lanes_tip_gradient(n1x, n1y, n1z, length, nn1)
    glx, gly, glz = lanes_tip_gradient(n2x, n2y, n2z, length, nn2)
    pi_ = wp.cw_mul(lanes_dot(xix - xjx, xiy - xjy, xiz - xjz, rx, ry, rz), inv_len2)
    pl_ = wp.cw_mul(lanes_dot(xkx - xlx, xky - xly, xkz - xlz, rx, ry, rz), inv_len2)
    gjx, gjy, gjz = lanes_hinge_gradient(gix, giy, giz, glx, gly, glz, pi_, pl_)
    gkx, gky, gkz = lanes_hinge_gradient(glx, gly, glz, gix, giy, giz, pl_, pi_)
    # wing_contact_of_normal's test for a clear wing: |n|² >= (A |r_kj|²)²
    clear = len2 * PANEL_CONTACT_ALTITUDE
    clear2 = wp.cw_mul(clear, clear)
    n = LANES + 0  # a bound that is not a constant: Warp keeps the loop (8 copies of the adds and blocks: bigger code)
    for k in range(n):
        h = h0 + k
        pv = prev[k]
        torque, stiff, lh = hinge_torque(pv + wrap_angle(psi[k] - pv), pv, h, c, m)
        i0 = m.hinges[h, 0]
        i1 = m.hinges[h, 1]
        i2 = m.hinges[h, 2]
        i3 = m.hinges[h, 3]
        g0 = wp.vec3(gix[k], giy[k], giz[k])
        g1 = wp.vec3(gjx[k], gjy[k], gjz[k])
        g2 = wp.vec3(gkx[k], gky[k], gkz[k])
        g3 = wp.vec3(glx[k], gly[k], glz[k])
        add_hinge_rows(world, ALL_ROWS, torque, stiff, i0, i1, i2, i3, g0, g1, g2, g3, with_hessian, w)
        if nn1[k] < clear2[k] or nn2[k] < clear2[k]:
            x0 = wp.vec3(xix[k], xiy[k], xiz[k])
            x1 = wp.vec3(xjx[k], xjy[k], xjz[k])
            x2 = wp.vec3(xkx[k], xky[k], xkz[k])
            x3 = wp.vec3(xlx[k], xly[k], xlz[k])
            add_wing(world, ALL_ROWS, wp.vec3(n1x[k], n1y[k], n1z[k]), len2[k], x0, x1, x2, i0, i1, i2, lh,
                     with_hessian, w)
            add_wing(world, ALL_ROWS, wp.vec3(n2x[k], n2y[k], n2z[k]), len2[k], x3, x2, x1, i3, i2, i1, lh,
                     with_hessian, w)


@wp.func
def whole_lanes(nh: int) -> int:
    """How many of ``nh`` hinges go in whole batches of lanes: all but the last nh mod LANES on the CPU, none in a
    CUDA build (a thread per world has no vector units to fill; with the count a constant 0 there, the compiler drops
    the lanes' code: docs/dynamics.md, "Notes moved from the code")."""
    if on_gpu():
        return 0
    return (nh / LANES) * LANES


@wp.func
def add_hinges(world: int, c: WorldCoefficients, m: BarHingeModel, with_hessian: bool, s: BarHingeState,
               w: NewtonScratch):
    """Every hinge's :func:`~.substep.add_hinge` (``ALL_ROWS``) in order: whole batches in lanes
    (:func:`add_hinge_lanes`), the last H mod LANES hinges one by one (in a CUDA build all of them:
    :func:`whole_lanes`)."""
    nh = m.hinges.shape[0]
    whole = whole_lanes(nh)
    for h0 in range(0, whole, LANES):
        add_hinge_lanes(world, h0, c, m, with_hessian, s, w)
    for h in range(whole, nh):
        add_hinge(world, h, ALL_ROWS, c, m, with_hessian, s, w)


@wp.func
def update_hinge_angles_lanes(world: int, m: BarHingeModel, fold_tolerance: float, s: BarHingeState) -> int:
    """:func:`~.substep.update_hinge_angles` of every hinge (stride 1), whole batches in lanes, the last H mod LANES
    hinges by that function (in a CUDA build all of them: :func:`whole_lanes`): the angles unwrapped to the end of
    the substep into ``crease_angle``; 1 if the sheet crumpled (:func:`~.common.hinge_angle_at_substep_end`), else 0."""
    nh = m.hinges.shape[0]
    whole = whole_lanes(nh)
    crumpled = int(0)
    for h0 in range(0, whole, LANES):
        xix, xiy, xiz = gather_column(world, h0, 0, m, s)
        xjx, xjy, xjz = gather_column(world, h0, 1, m, s)
        xkx, xky, xkz = gather_column(world, h0, 2, m, s)
        xlx, xly, xlz = gather_column(world, h0, 3, m, s)
        prev = gather_angles(world, h0, s)
        n1x, n1y, n1z = lanes_cross(xjx - xix, xjy - xiy, xjz - xiz, xkx - xix, xky - xiy, xkz - xiz)
        n2x, n2y, n2z = lanes_cross(xkx - xlx, xky - xly, xkz - xlz, xjx - xlx, xjy - xly, xjz - xlz)
        rx = xkx - xjx
        ry = xky - xjy
        rz = xkz - xjz
        len2 = lanes_dot(rx, ry, rz, rx, ry, rz)
        psi = lanes_angle(n1x, n1y, n1z, n2x, n2y, n2z, rx, ry, rz, lanes_sqrt(len2))
        # wings_collapsed: min(|n1|, |n2|) < SLIVER_ALTITUDE |r_kj|²
        wing = wp.min(lanes_sqrt(lanes_dot(n1x, n1y, n1z, n1x, n1y, n1z)),
                      lanes_sqrt(lanes_dot(n2x, n2y, n2z, n2x, n2y, n2z)))
        sliver = SLIVER_ALTITUDE * len2
        n = LANES + 0
        for k in range(n):
            h = h0 + k
            phi = prev[k] + wrap_angle(psi[k] - prev[k])
            lo, hi = fold_range(m.hinge_label[h])
            s.crease_angle[world, h] = phi
            if phi < lo - fold_tolerance or phi > hi + fold_tolerance or wing[k] < sliver[k]:
                crumpled = 1
    if update_hinge_angles(world, whole, 1, m, fold_tolerance, s) != 0:  # the last H mod LANES hinges
        crumpled = 1
    return crumpled
