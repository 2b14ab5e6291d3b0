"""Point dipoles and the dipole grids of the 'dipoles' model as ``@wp.func``s (float32; no kernels, no host code).

The field of a point dipole and the force / torque between two point dipoles: the d -> 0 limit of the paper's pair of
±q charges d = 1 µm apart (the charge-pair form cancels catastrophically in float32; the limit form is accurate to
~2e-7 relative; docs/magnets.md). A magnet of the 'dipoles' model is a grid of equal dipoles generated on the fly from
(shape, size, density). Units: SI, moments m [A·m²], B [T], F [N], T [N·m].
"""

from __future__ import annotations

import warp as wp

from .common import SHAPE_CYLINDER

MU0_OVER_4PI = wp.constant(1.0e-7)
"""mu0 / (4 pi) [T·m/A] (float32)."""


@wp.func
def dipole_field(m: wp.vec3, r: wp.vec3) -> wp.vec3:
    """B [T] of a point dipole ``m`` [A·m²] at offset ``r`` = observer − dipole [m]."""
    inv_r = 1.0 / wp.length(r)
    rh = r * inv_r
    # scale (mu0/4pi)/r^3 before combining: keeps float32 far from under/overflow for r ~ 1e-4..1 m
    s = MU0_OVER_4PI * inv_r * inv_r * inv_r
    return s * (3.0 * wp.dot(m, rh) * rh - m)


@wp.func
def dipole_force(m_s: wp.vec3, m_t: wp.vec3, r: wp.vec3) -> wp.vec3:
    """Force [N] on point dipole ``m_t`` from point dipole ``m_s``, ``r`` = x_t − x_s [m].

    F = 3 mu0 / (4 pi r^4) [ (r̂·m_t) m_s + (r̂·m_s) m_t + (m_s·m_t) r̂ − 5 (r̂·m_s)(r̂·m_t) r̂ ]
    (the gradient of m_t·B_s; antisymmetric under swapping the two dipoles, so Newton's third law holds exactly).
    """
    inv_r = 1.0 / wp.length(r)
    rh = r * inv_r
    s = 3.0 * MU0_OVER_4PI * inv_r * inv_r * inv_r * inv_r
    a = wp.dot(rh, m_s)
    b = wp.dot(rh, m_t)
    return s * (b * m_s + a * m_t + wp.dot(m_s, m_t) * rh - 5.0 * a * b * rh)


# ----------------------------------------------------------------------------------------------------------------------
# Dipole grids of the 'dipoles' model: generated on the fly from (shape, size, density)
# ----------------------------------------------------------------------------------------------------------------------
#
# Nominal spacing h = density^(-1/3) (per_m = 1/h). Every dipole stands for one cell of equal volume and carries
# m_total / N.
#
# - Cuboid: n_i = max(1, round(size_i / h)) cells per axis, a dipole at each cell centre.
# - Cylinder (axis z, radius R, height H): n_z = max(1, round(H / h)) equal layers, dipoles at the layer mid-heights;
#   each layer is an equal-area polar partition of the disk: n_r = max(1, round(R / h)) rings, ring i (nominal
#   radii i R / n_r, (i + 1) R / n_r) split into c_i = max(1, round(nominal ring area / h²)) sectors (c = 2 -> 3),
#   the ring boundaries then moved to r_i = R sqrt(C_i / N_layer) (C_i = cells inside ring i) so that all cells have
#   the same area πR² / N_layer. Sector j of ring i sits at angle (j + 1/2) 2π / c_i and radius
#   ρ_i = sqrt((r_i² + r_{i+1}²) / 2 − Δz² / 6) (0 for a ring of one cell), Δz = H / n_z: the ring's points then
#   have the ring's exact in-plane second moment less the same isotropic deficit Δz²/12 per axis that the
#   mid-height layers leave along z (a cell-centred cuboid lattice of cubic cells has the same isotropic deficit).
#   So the grid's traceless second moment — which is what sets the leading error of the field and the forces away
#   from the magnet — is exact. (Cell centroids, ρ = 2/3 (r2³ − r1³)/(r2² − r1²) sinc(π / c), fall short of it
#   by ~8 % on the 10 mm × 1 mm IPM disk and measured no better than the old square lattice; docs/magnets.md.)
# The 10 mm × 1 mm IPM disk at 64/cm³: one layer, rings of 3 + 9 cells = 12 dipoles.

CYL_PI = wp.constant(3.141592653589793)


@wp.func
def cylinder_ring_cells(r_per_m: float, n_r: int, i: int) -> int:
    """Cells of ring ``i`` of ``n_r`` of a disk of radius ``r_per_m`` (in units of h): round(area / h²), >= 1, 2 -> 3
    (three or more points on a ring give an isotropic in-plane second moment, two do not)."""
    w = r_per_m / float(n_r)
    c = wp.max(1, int(wp.round(CYL_PI * w * w * float(2 * i + 1))))
    if c == 2:
        c = 3
    return c


@wp.func
def cylinder_ring_radius(size: wp.vec3, n: wp.vec3i, first: int, cells: int) -> float:
    """Radius [m] of the dipoles of the ring holding cells ``first`` … ``first + cells − 1`` of a layer (see above)."""
    if cells < 3:
        return 0.0
    r2 = 0.25 * size[0] * size[0] / float(n[1])
    dz = size[2] / float(n[2])
    rho2 = 0.5 * r2 * float(2 * first + cells) - dz * dz / 6.0
    return wp.sqrt(wp.max(rho2, 0.0))


@wp.func
def dipole_grid_dims(shape: int, size: wp.vec3, density: float) -> wp.vec3i:
    """Grid dimensions of a magnet of ``size`` [m] at ``density`` [dipoles/m³].

    Cuboid: cells per axis (n_x, n_y, n_z). Cylinder (size = (d, d, h)): (n_r rings, N cells per layer, n_z layers).
    """
    per_m = wp.pow(density, 1.0 / 3.0)
    nz = wp.max(1, int(wp.round(size[2] * per_m)))
    if shape == SHAPE_CYLINDER:
        r_per_m = 0.5 * size[0] * per_m
        nr = wp.max(1, int(wp.round(r_per_m)))
        cells = int(0)
        for i in range(nr):
            cells += cylinder_ring_cells(r_per_m, nr, i)
        return wp.vec3i(nr, cells, nz)
    nx = wp.max(1, int(wp.round(size[0] * per_m)))
    ny = wp.max(1, int(wp.round(size[1] * per_m)))
    return wp.vec3i(nx, ny, nz)


@wp.func
def dipole_grid_count(shape: int, size: wp.vec3, n: wp.vec3i) -> int:
    """Number of grid dipoles of a magnet (>= 1)."""
    if shape == SHAPE_CYLINDER:
        return n[1] * n[2]
    return n[0] * n[1] * n[2]


@wp.func
def dipole_grid_point(shape: int, size: wp.vec3, n: wp.vec3i, per_m: float, idx: int) -> wp.vec3:
    """Dipole ``idx`` (0 … count − 1) of the grid in the magnet's frame [m]; ``per_m`` = density^(1/3)."""
    if shape == SHAPE_CYLINDER:
        k = idx % n[2]
        cell = idx / n[2]
        z = size[2] * ((float(k) + 0.5) / float(n[2]) - 0.5)
        r_per_m = 0.5 * size[0] * per_m
        first = int(0)
        for i in range(n[0]):
            c = cylinder_ring_cells(r_per_m, n[0], i)
            if cell < first + c:
                rho = cylinder_ring_radius(size, n, first, c)
                theta = (float(cell - first) + 0.5) * (2.0 * CYL_PI / float(c))
                return wp.vec3(rho * wp.cos(theta), rho * wp.sin(theta), z)
            first += c
        return wp.vec3(0.0, 0.0, z)
    i = idx / (n[1] * n[2])
    j = (idx / n[2]) % n[1]
    k = idx % n[2]
    return wp.vec3(
        size[0] * ((float(i) + 0.5) / float(n[0]) - 0.5),
        size[1] * ((float(j) + 0.5) / float(n[1]) - 0.5),
        size[2] * ((float(k) + 0.5) / float(n[2]) - 0.5),
    )


@wp.func
def dipoles_field_local(shape: int, size: wp.vec3, m: wp.vec3, density: float, p: wp.vec3) -> wp.vec3:
    """B [T] at ``p`` (source frame) [m] of the dipole-grid model of a magnet with total moment ``m`` [A·m²]."""
    n = dipole_grid_dims(shape, size, density)
    count = dipole_grid_count(shape, size, n)
    per_m = wp.pow(density, 1.0 / 3.0)
    m_each = m / float(count)
    b = wp.vec3(0.0)
    for idx in range(count):
        b += dipole_field(m_each, p - dipole_grid_point(shape, size, n, per_m, idx))
    return b


@wp.func
def dipole_pair_force_field(m_s: wp.vec3, m_t: wp.vec3, r: wp.vec3):
    """Force [N] on ``m_t`` from ``m_s`` and the field [T] of ``m_s`` at ``m_t`` (``r`` = x_t − x_s [m]).

    :func:`dipole_force` and :func:`dipole_field` sharing one square root and no normalization (the 'dipoles'
    model sums the same terms in :func:`dipole_column_sums`). float32 is safe: 1/r^5 <= 1e20 for r >= 1e-4 m.
    """
    inv_r2 = 1.0 / wp.dot(r, r)
    inv_r = wp.sqrt(inv_r2)
    inv_r3 = inv_r * inv_r2
    inv_r5 = inv_r3 * inv_r2
    a = wp.dot(r, m_s)
    b = wp.dot(r, m_t)
    field = MU0_OVER_4PI * (3.0 * a * inv_r5 * r - inv_r3 * m_s)
    force = (3.0 * MU0_OVER_4PI * inv_r5) * (b * m_s + a * m_t + (wp.dot(m_s, m_t) - 5.0 * a * b * inv_r2) * r)
    return force, field


@wp.func
def dipole_column_sums(rx: float, ry: float, rz0: float, dz: float, nz: int, ms: wp.vec3, mt: wp.vec3, msmt: float):
    """Partial sums of the pair terms of a point dipole ``mt`` against a column of ``nz`` source dipoles ``ms``.

    The column's dipoles are at offsets r_k = (rx, ry, rz0 − k dz) [m] from the target (r = x_t − x_s), ``msmt`` =
    ms·mt. With a = r·ms, b = r·mt and i_n = |r|^−n the pair force is 3 (mu0/4pi) (b i5 ms + a i5 mt + g r),
    g = ms·mt i5 − 5 a b i7, and the source field is (mu0/4pi) (3 a i5 r − i3 ms); since ms and mt are the same for
    every pair only the scalar weights need summing, and rx, ry, a and b are linear along the column. Returns
    (Σ a i5, Σ b i5, Σ i3, Σ g, Σ a i5 rz, Σ g rz). The inner loop has one division, one square root and no vector
    temporaries: it is the 'dipoles' model's hot loop.
    """
    rxy2 = rx * rx + ry * ry
    a_xy = rx * ms[0] + ry * ms[1]
    b_xy = rx * mt[0] + ry * mt[1]
    sa = float(0.0)
    sb = float(0.0)
    s3 = float(0.0)
    sg = float(0.0)
    saz = float(0.0)
    sgz = float(0.0)
    for k in range(nz):
        rz = rz0 - float(k) * dz
        inv_r2 = 1.0 / (rxy2 + rz * rz)
        inv_r = wp.sqrt(inv_r2)
        inv_r3 = inv_r * inv_r2
        inv_r5 = inv_r3 * inv_r2
        a5 = (a_xy + rz * ms[2]) * inv_r5
        b = b_xy + rz * mt[2]
        g = msmt * inv_r5 - 5.0 * a5 * b * inv_r2
        sa += a5
        sb += b * inv_r5
        s3 += inv_r3
        sg += g
        saz += a5 * rz
        sgz += g * rz
    return sa, sb, s3, sg, saz, sgz


@wp.func
def dipole_sums_to_force_field(sa: float, sb: float, s3: float, u: wp.vec3, v: wp.vec3, ms: wp.vec3, mt: wp.vec3):
    """Force [N] and field [T] at the target from the summed weights of :func:`dipole_column_sums` (Σ a i5, Σ b i5,
    Σ i3, Σ a i5 r, Σ g r)."""
    f = (3.0 * MU0_OVER_4PI) * (sb * ms + sa * mt + v)
    b = MU0_OVER_4PI * (3.0 * u - s3 * ms)
    return f, b


@wp.func
def cuboid_source_sum(s_size: wp.vec3, ns: wp.vec3i, ms: wp.vec3, mt: wp.vec3, pt: wp.vec3):
    """Force [N] on a point dipole ``mt`` at ``pt`` (source frame) from every dipole (moment ``ms`` each) of a cuboid
    source's n_x × n_y × n_z lattice, and the lattice's field [T] there: one :func:`dipole_column_sums` per column."""
    sa = float(0.0)
    sb = float(0.0)
    s3 = float(0.0)
    u = wp.vec3(0.0)
    v = wp.vec3(0.0)
    msmt = wp.dot(ms, mt)
    dx = s_size[0] / float(ns[0])
    dy = s_size[1] / float(ns[1])
    dz = s_size[2] / float(ns[2])
    rx0 = pt[0] - (0.5 * dx - 0.5 * s_size[0])
    ry0 = pt[1] - (0.5 * dy - 0.5 * s_size[1])
    rz0 = pt[2] - (0.5 * dz - 0.5 * s_size[2])
    for i in range(ns[0]):
        rx = rx0 - float(i) * dx
        for j in range(ns[1]):
            ry = ry0 - float(j) * dy
            ka, kb, k3, kg, kaz, kgz = dipole_column_sums(rx, ry, rz0, dz, ns[2], ms, mt, msmt)
            sa += ka
            sb += kb
            s3 += k3
            u += wp.vec3(ka * rx, ka * ry, kaz)
            v += wp.vec3(kg * rx, kg * ry, kgz)
    return dipole_sums_to_force_field(sa, sb, s3, u, v, ms, mt)


@wp.func
def cylinder_ring_start(rho: float, cells: int) -> wp.vec4:
    """(x, y) [m] of the first of ``cells`` columns at radius ``rho`` (angle π / cells) and (cos, sin) of the step
    2π / cells: what :func:`cylinder_ring_source_sum` walks the ring with."""
    step = 2.0 * CYL_PI / float(cells)
    return wp.vec4(rho * wp.cos(0.5 * step), rho * wp.sin(0.5 * step), wp.cos(step), wp.sin(step))


@wp.func
def cylinder_ring_source_sum(ring: wp.vec4, cells: int, s_size: wp.vec3, nz: int, ms: wp.vec3, mt: wp.vec3,
                             pt: wp.vec3):
    """Force [N] on a point dipole ``mt`` at ``pt`` (source frame) from the dipoles of one ring of a cylinder
    source's grid (``cells`` columns of ``nz`` layers), and their field [T] there. ``ring`` = (x, y of the first
    column [m], cos, sin of the angular step), the columns by rotation recurrence (:func:`cylinder_ring_start`)."""
    sa = float(0.0)
    sb = float(0.0)
    s3 = float(0.0)
    u = wp.vec3(0.0)
    v = wp.vec3(0.0)
    msmt = wp.dot(ms, mt)
    dz = s_size[2] / float(nz)
    rz0 = pt[2] - (0.5 * dz - 0.5 * s_size[2])
    ca = ring[0]
    sa_ = ring[1]
    cs = ring[2]
    sn = ring[3]
    for j in range(cells):
        rx = pt[0] - ca
        ry = pt[1] - sa_
        ka, kb, k3, kg, kaz, kgz = dipole_column_sums(rx, ry, rz0, dz, nz, ms, mt, msmt)
        sa += ka
        sb += kb
        s3 += k3
        u += wp.vec3(ka * rx, ka * ry, kaz)
        v += wp.vec3(kg * rx, kg * ry, kgz)
        tmp = ca * cs - sa_ * sn
        sa_ = sa_ * cs + ca * sn
        ca = tmp
    return dipole_sums_to_force_field(sa, sb, s3, u, v, ms, mt)


@wp.func
def dipoles_pair_wrench_direct(
    s_shape: int,
    s_size: wp.vec3,
    s_m: wp.vec3,
    t_shape: int,
    t_size: wp.vec3,
    t_m: wp.vec3,
    r_rel: wp.mat33,
    t_rel: wp.vec3,
    per_m: float,
    ns: wp.vec3i,
    nt: wp.vec3i,
):
    """Force [N] and torque about the target centre [N·m] on a target from a source, 'dipoles' model, as the
    literal double sum over target dipoles and source dipoles (the source's columns innermost); frames as in
    :func:`dipoles_pair_wrench`, ``per_m`` = density^(1/3), ``ns`` / ``nt`` the grids' :func:`dipole_grid_dims`.
    Grid points as :func:`dipole_grid_point` gives them, in the same order per chunk."""
    ms = s_m / float(dipole_grid_count(s_shape, s_size, ns))
    nt_count = dipole_grid_count(t_shape, t_size, nt)
    mt = (r_rel * t_m) / float(nt_count)
    force = wp.vec3(0.0)
    torque = wp.vec3(0.0)
    b_sum = wp.vec3(0.0)
    # outer: the source in chunks (a cuboid's whole lattice; a cylinder's rings, so that a ring's set-up is paid once
    # per pair); inner: the target's grid walked by its own loops (a cylinder's rings by rotation recurrence), no
    # per-dipole index arithmetic or trigonometry
    s_cyl = s_shape == SHAPE_CYLINDER
    t_cyl = t_shape == SHAPE_CYLINDER
    s_chunks = 1
    if s_cyl:
        s_chunks = ns[0]
    s_r_per_m = 0.5 * s_size[0] * per_m
    t_r_per_m = 0.5 * t_size[0] * per_m
    t_step = wp.cw_div(t_size, wp.vec3(float(nt[0]), float(nt[1]), float(nt[2])))
    t_first = 0.5 * t_step - 0.5 * t_size
    s_first_cell = int(0)
    for chunk in range(s_chunks):
        s_cells = int(0)
        s_ring = wp.vec4(0.0)
        if s_cyl:
            s_cells = cylinder_ring_cells(s_r_per_m, ns[0], chunk)
            s_ring = cylinder_ring_start(cylinder_ring_radius(s_size, ns, s_first_cell, s_cells), s_cells)
            s_first_cell += s_cells
        t_first_cell = int(0)
        for it in range(nt[0]):
            n_cols = nt[1]
            x = t_first[0] + float(it) * t_step[0]
            y = float(0.0)
            t_ring = wp.vec4(0.0)
            if t_cyl:
                n_cols = cylinder_ring_cells(t_r_per_m, nt[0], it)
                t_ring = cylinder_ring_start(cylinder_ring_radius(t_size, nt, t_first_cell, n_cols), n_cols)
                t_first_cell += n_cols
                x = t_ring[0]
                y = t_ring[1]
            for jt in range(n_cols):
                if not t_cyl:
                    y = t_first[1] + float(jt) * t_step[1]
                for kt in range(nt[2]):
                    lever = r_rel * wp.vec3(x, y, t_first[2] + float(kt) * t_step[2])
                    f = wp.vec3(0.0)
                    b = wp.vec3(0.0)
                    if s_cyl:
                        f, b = cylinder_ring_source_sum(s_ring, s_cells, s_size, ns[2], ms, mt, t_rel + lever)
                    else:
                        f, b = cuboid_source_sum(s_size, ns, ms, mt, t_rel + lever)
                    force += f
                    torque += wp.cross(lever, f)
                    b_sum += b
                if t_cyl:
                    tmp = x * t_ring[2] - y * t_ring[3]
                    y = y * t_ring[2] + x * t_ring[3]
                    x = tmp
    # every target dipole has the same moment: Σ mt × B_k = mt × Σ B_k
    return force, torque + wp.cross(mt, b_sum)


@wp.func
def dipoles_pair_wrench(
    s_shape: int,
    s_size: wp.vec3,
    s_m: wp.vec3,
    t_shape: int,
    t_size: wp.vec3,
    t_m: wp.vec3,
    r_rel: wp.mat33,
    t_rel: wp.vec3,
    density: float,
):
    """Force [N] and torque about the target centre [N·m] on a target magnet from a source, 'dipoles' model.

    Everything is in the *source's* frame: ``s_m`` and ``t_m`` are the total moments [A·m²] in their own frames,
    ``r_rel`` rotates target-frame vectors into the source frame, ``t_rel`` is the target centre in the source frame.
    Sum over all source-dipole / target-dipole pairs of the point-dipole force; the torque on each target dipole is
    lever × F + m × B (eq. (4)–(5) of the paper in the d -> 0 limit).

    The double sum runs with the larger grid in the inner loop (long inner loops, little per-target set-up): when
    the target has more dipoles than the source (the EPM bar from an IPM disk), the wrench on the *source* is
    summed and the target's follows from the pair's conservation laws, which every point-dipole pair obeys exactly:
    F_t = −F_s, T_t = −T_s + (c_t − c_s) × F_s (equal to the direct sum to float rounding).
    """
    per_m = wp.pow(density, 1.0 / 3.0)
    ns = dipole_grid_dims(s_shape, s_size, density)
    nt = dipole_grid_dims(t_shape, t_size, density)
    if dipole_grid_count(t_shape, t_size, nt) <= dipole_grid_count(s_shape, s_size, ns):
        return dipoles_pair_wrench_direct(s_shape, s_size, s_m, t_shape, t_size, t_m, r_rel, t_rel, per_m, ns, nt)
    # the roles swapped: the source seen from the target's frame
    r_inv = wp.transpose(r_rel)
    f_s, tq_s = dipoles_pair_wrench_direct(t_shape, t_size, t_m, s_shape, s_size, s_m, r_inv, -(r_inv * t_rel),
                                           per_m, nt, ns)
    f_s = r_rel * f_s
    tq_s = r_rel * tq_s
    return -f_s, wp.cross(t_rel, f_s) - tq_s
