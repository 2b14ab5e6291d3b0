"""Shared ``@wp.func`` helpers and constants of the dynamics kernels (:mod:`warpworm.kernels.substep`,
:mod:`warpworm.kernels.magnet_pose`): angle wrapping, hinge fold ranges, freezing a diverging
world, the dihedral angle of a hinge with its gradient, and vectors of :data:`LANES` float32 with the vec3 operations
done lane by lane (:mod:`warpworm.kernels.hinge_lanes`, :mod:`warpworm.kernels.magnet_far_pair`).

Per-world parameters are read as ``p[wrow(world, p.shape[0])]`` (:func:`wrow`: ``world % n`` without the division in
the usual cases) so that an array of one value (shared) or one value per world both work; the renderer reads its
per-world rows the same way. float32, SI units.
"""

from __future__ import annotations

import warp as wp

from warpworm import ids

LABEL_FLAT = wp.constant(ids.FLAT)
LABEL_MOUNTAIN = wp.constant(ids.MOUNTAIN)
LABEL_VALLEY = wp.constant(ids.VALLEY)
WORLD_EXPLODED = wp.constant(ids.WORLD_EXPLODED)
SHAPE_CUBOID = wp.constant(ids.SHAPE_CUBOID)
SHAPE_CYLINDER = wp.constant(ids.SHAPE_CYLINDER)

PI = wp.constant(3.14159265358979)
TWO_PI = wp.constant(6.28318530717959)


@wp.func_native("""
#if defined(__CUDA_ARCH__)
    return true;
#else
    return false;
#endif
""")
def on_gpu() -> bool:
    """True in a kernel's CUDA build, False in its CPU build (a preprocessor test, constant after inlining): lets a
    kernel take its CPU-only path (the SIMD lanes of :mod:`.hinge_lanes`) on the CPU and its scalar code on a GPU, where
    a thread per world has no vector units to fill (docs/dynamics.md, "Notes moved from the code")."""
    ...


@wp.func
def wrow(w: int, n: int) -> int:
    """Row ``w % n`` of a per-world array of ``n`` rows for a world (or pair, or image) index ``w >= 0``, without the
    integer division in the usual cases (n > w: a row each; n == 1: one row shared): a division costs more than the
    rest of a plain pixel's shading, and the general resolve kernel reads ~15 rows per pixel."""
    if w < n:
        return w
    if n == 1:
        return 0
    return w % n


@wp.func
def wrap_angle(a: float) -> float:
    """Wrap an angle difference into (-pi, pi]. |a| < 3 (a hinge's change over a substep, almost always) returns a
    without the division and floor: there (a + π) / 2π lies in (0.02, 0.98), its floor is 0 and a − 2π · 0 is a, so
    the result is the same to the bit either way."""
    if wp.abs(a) < 3.0:
        return a
    return a - TWO_PI * wp.floor((a + PI) / TWO_PI)


@wp.func
def fold_range(label: int):
    """NoFoldThrough range (lo, hi) [rad] of a hinge's signed angle: mountain [−π, 0], valley [0, π], flat [−π, π]."""
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
    """Flag ``world`` unstable (exploded) and put it back, finite, to the start of the substep at rest."""
    unstable[world] = WORLD_EXPLODED
    for i in range(num_vertices):
        x[world, i] = x_prev[world, i]
        v[world, i] = wp.vec3(0.0)
        delta[world, i] = wp.vec3(0.0)
    return 0


LANES = wp.constant(8)
"""Elements (hinges, ring points) per vector of lanes (8 float32: one AVX register)."""

lanes = wp.types.vector(length=LANES, dtype=wp.float32)
"""One float32 per element of a batch: Warp's component-wise operations on it compile to SIMD
instructions on the CPU (:mod:`.hinge_lanes`, :func:`.magnet_far_pair.far_cylinder_pair_wrench_lanes`,
:func:`.magnet_far_pair.cuboid_faces_in_ring_field`)."""


@wp.func
def lanes_cross(ax: lanes, ay: lanes, az: lanes, bx: lanes, by: lanes, bz: lanes):
    """``wp.cross`` lane by lane: (a_y b_z − a_z b_y, a_z b_x − a_x b_z, a_x b_y − a_y b_x)."""
    return (wp.cw_mul(ay, bz) - wp.cw_mul(az, by), wp.cw_mul(az, bx) - wp.cw_mul(ax, bz),
            wp.cw_mul(ax, by) - wp.cw_mul(ay, bx))


@wp.func
def lanes_dot(ax: lanes, ay: lanes, az: lanes, bx: lanes, by: lanes, bz: lanes) -> lanes:
    """``wp.dot`` lane by lane, summed in its order: (a_x b_x + a_y b_y) + a_z b_z."""
    return wp.cw_mul(ax, bx) + wp.cw_mul(ay, by) + wp.cw_mul(az, bz)


@wp.func
def lanes_sqrt(a: lanes) -> lanes:
    """``wp.sqrt`` of every lane."""
    r = lanes()
    for k in range(8):
        r[k] = wp.sqrt(a[k])
    return r


TAN_PI_8 = wp.constant(0.41421356237309503)
QUARTER_PI = wp.constant(0.78539816339744831)
HALF_PI = wp.constant(1.57079632679489662)


@wp.func
def atan2_f32(y: float, x: float) -> float:
    """atan2(y, x) [rad] in (−π, π], inline: within 2.8e-7 rad of the float64 value (libm's float32 atan2f: 2.5e-7,
    its rounding near π), without libm's call, which was ~1/4 of the hinge gradient's cost. Octant reduction to
    a = min/max in [0, 1], then a ≤ tan(π/8) directly, else π/4 + atan((a − 1)/(a + 1)), with Cephes' atanf
    minimax polynomial on [0, tan(π/8)]. atan2(±0, x < 0) = π (the sign of a zero y is not kept)."""
    ax = wp.abs(x)
    ay = wp.abs(y)
    mx = wp.max(ax, ay)
    a = wp.min(ax, ay) / wp.max(mx, 1.0e-38)
    base = float(0.0)
    if a > TAN_PI_8:
        a = (a - 1.0) / (a + 1.0)
        base = QUARTER_PI
    z = a * a
    r = base + ((((8.05374449538e-2 * z - 1.38776856032e-1) * z + 1.99777106478e-1) * z - 3.33329491539e-1) * z * a + a)
    if ay > ax:
        r = HALF_PI - r
    if x < 0.0:
        r = PI - r
    if y < 0.0:
        r = -r
    return r


@wp.func
def dihedral_angle_and_normals(xi: wp.vec3, xj: wp.vec3, xk: wp.vec3, xl: wp.vec3):
    """The signed fold angle psi [rad] of the hinge stencil (i, j, k, l) (:func:`dihedral_angle_gradient_and_normals`) with
    what it is made of: (n1, n2, r_kj, |r_kj|², |r_kj|, psi), n1, n2 the wings' normals (their lengths twice the
    wings' areas), r_kj = x_k − x_j the hinge."""
    n1 = wp.cross(xj - xi, xk - xi)
    n2 = wp.cross(xk - xl, xj - xl)
    r_kj = xk - xj
    len2 = wp.dot(r_kj, r_kj)
    length = wp.sqrt(len2)
    # (n1 x n2) . e with e = (x_j - x_k) / |x_j - x_k| = -r_kj / length; atan2 is scale-free, so the length is left out
    psi = atan2_f32(-wp.dot(wp.cross(n1, n2), r_kj), wp.dot(n1, n2) * length)
    return n1, n2, r_kj, len2, length, psi


@wp.func
def dihedral_angle_gradient_and_normals(xi: wp.vec3, xj: wp.vec3, xk: wp.vec3, xl: wp.vec3):
    """Signed fold angle psi [rad] of the hinge stencil (i, j, k, l) (shared edge j-k; 0 flat, > 0 valley) and its
    exact gradient w.r.t. (x_i, x_j, x_k, x_l) [rad/m], sharing their cross products.

    The convention of :func:`warpworm.physics.crease.dihedral_angles`: psi = atan2((n1 x n2) . e, n1 . n2) with the outward
    wing normals n1 = (x_j - x_i) x (x_k - x_i), n2 = (x_k - x_l) x (x_j - x_l) and e = (x_j - x_k) / |x_j - x_k|.
    Gradient (Liu & Paulino 2017, MERLIN, with psi = pi - theta_MERLIN): d psi/d x_i = L n1/|n1|²,
    d psi/d x_l = L n2/|n2|², x_j and x_k by the wings' projections on the hinge axis (free of translation and
    rotation). Returns (psi, g_i, g_j, g_k, g_l, n1, n2, |x_k − x_j|²): the wings' normals and the hinge's
    squared length for their panel contact (:func:`wing_contact_of_normal`).
    """
    n1, n2, r_kj, len2, length, psi = dihedral_angle_and_normals(xi, xj, xk, xl)
    inv_len2 = 1.0 / len2
    # guard degenerate wings (zero area): no gradient rather than inf
    gi = n1 * (length / wp.max(wp.dot(n1, n1), 1.0e-30))
    gl = n2 * (length / wp.max(wp.dot(n2, n2), 1.0e-30))
    pi_ = wp.dot(xi - xj, r_kj) * inv_len2
    pl_ = wp.dot(xk - xl, r_kj) * inv_len2
    gj = gi * (pi_ - 1.0) - gl * pl_
    gk = gl * (pl_ - 1.0) - gi * pi_
    return psi, gi, gj, gk, gl, n1, n2, len2


SLIVER_ALTITUDE = wp.constant(0.005)
"""A hinge wing whose altitude over the hinge is below this fraction of the hinge's length has collapsed: the
sheet crumpled. The worm's wings rest at 0.17 or more and the gait presets keep them above 0.16 of their rest
altitude (≥ 0.028); a collapsing wing makes the hinge gradient (∝ 1 / altitude) and so the Newton matrix
singular, which otherwise shows as an explosion one step later."""


PANEL_CONTACT_ALTITUDE = wp.constant(0.02)
"""A hinge wing whose altitude over the hinge falls below this fraction of the hinge's length meets the panel
contact barrier (:func:`wing_contact`). The worm's wings rest at 0.17 or more and the gait presets of the first
model kept them above 0.028; below 0.02 the soft waist bars had let a wing fold flat under a magnet pulling
~150 mN at its mount (docs/dynamics.md, "The sheet's material")."""

PANEL_CONTACT_EA = wp.constant(20.0)
"""[N] the barrier's stiffness, as a panel bar's EA: a wing pressed δ below the contact altitude (as a fraction of
the hinge length L) pushes back with ~EA δ, like a bar of the panel strained by δ."""


@wp.func
def wing_contact(p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, lh: float):
    """The panel contact barrier of one hinge wing: a sheet's panel does not fold flat onto itself (without the
    barrier the bar model lets a wing collapse onto its hinge through the soft waist bars, which stand for the
    panels' bending, not for a panel that can vanish).

    ``p0`` the wing's tip, ``p1``–``p2`` the hinge, ``lh`` the hinge's rest length [m]. With n = (p1 − p0) × (p2 −
    p0) (|n| = altitude × hinge length) and q = |n| − A |p1 − p2|² (A = :data:`PANEL_CONTACT_ALTITUDE`), the energy is
    ½ κ q² while q < 0, κ = :data:`PANEL_CONTACT_EA` / lh³ [N/m³]. Returns (κ q [N/m], ∂q/∂p0, ∂q/∂p1, ∂q/∂p2 [m],
    κ): the force on p_a is −κ q ∂q/∂p_a, the Gauss–Newton stiffness κ ∂q/∂p_a ∂q/∂p_bᵀ; κ = 0 while the wing is
    clear (q ≥ 0). Shared by the banded and tile kernels (through :func:`wing_contact_of_normal`)."""
    e = p1 - p2
    return wing_contact_of_normal(wp.cross(p1 - p0, p2 - p0), wp.dot(e, e), p0, p1, p2, lh)


@wp.func
def wing_contact_of_normal(n: wp.vec3, len2: float, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, lh: float):
    """:func:`wing_contact` given the wing's normal n = (p1 − p0) × (p2 − p0) and the hinge's |p1 − p2|² ``len2``,
    which the hinge's own angle computes anyway (:func:`dihedral_angle_gradient_and_normals`): a clear wing, the
    usual case, then costs one comparison (|n|² against (A L²)², no square root) instead of a cross product and a
    length per wing and Newton step (~15 % of the hinge gradient)."""
    nn = wp.dot(n, n)
    clear = PANEL_CONTACT_ALTITUDE * len2
    if nn >= clear * clear:
        return 0.0, wp.vec3(0.0), wp.vec3(0.0), wp.vec3(0.0), 0.0
    n_len = wp.sqrt(nn)
    q = n_len - clear
    e = p1 - p2
    nh = n / wp.max(n_len, 1.0e-30)
    # ∂|n|/∂p_a = n̂ × (the opposite edge, in the triangle's order): the area gradient
    g0 = wp.cross(nh, p2 - p1)
    g1 = wp.cross(nh, p0 - p2) - e * (2.0 * PANEL_CONTACT_ALTITUDE)
    g2 = wp.cross(nh, p1 - p0) + e * (2.0 * PANEL_CONTACT_ALTITUDE)
    kappa = PANEL_CONTACT_EA / (lh * lh * lh)
    return kappa * q, g0, g1, g2, kappa


@wp.func
def wings_collapsed(n1: wp.vec3, n2: wp.vec3, len2: float) -> bool:
    """Whether either wing of a hinge stencil has an altitude over the hinge below :data:`SLIVER_ALTITUDE` times the
    hinge's length: |n| / L < SLIVER_ALTITUDE · L, with ``n1``, ``n2`` the wings' normals of
    :func:`dihedral_angle_and_normals` (|n| = twice the wing's area = altitude · L) and ``len2`` = L²."""
    return wp.min(wp.length(n1), wp.length(n2)) < SLIVER_ALTITUDE * len2


@wp.func
def hinge_angle_at_substep_end(prev: float, xi: wp.vec3, xj: wp.vec3, xk: wp.vec3, xl: wp.vec3, label: int,
                               fold_tolerance: float):
    """A hinge's angle at the end of a substep, unwrapped from its angle ``prev`` [rad] at the start, and whether
    the sheet crumpled there: the angle more than ``fold_tolerance`` [rad] outside the hinge's NoFoldThrough range,
    or a wing collapsed (:func:`wings_collapsed`). Returns (phi, crumpled); shared by the banded and tile kernels."""
    n1, n2, r_kj, len2, length, psi = dihedral_angle_and_normals(xi, xj, xk, xl)
    phi = prev + wrap_angle(psi - prev)
    lo, hi = fold_range(label)
    crumpled = phi < lo - fold_tolerance or phi > hi + fold_tolerance or wings_collapsed(n1, n2, len2)
    return phi, crumpled
