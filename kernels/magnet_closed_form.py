"""Closed-form fields of uniformly magnetized solids as ``@wp.func``s (float64 inside; no kernels, no host code).

Cuboid (Yang 1990 / Engel-Herbert 2005, evaluated in the "bottom quadrant" after Cichon 2019 to avoid indeterminate
logs on edge extensions), axially magnetized cylinder (Derby 2010, Bulirsch's ``cel``) and diametrally magnetized
cylinder (Caciagli 2018 with the small-radius Taylor branch of magpylib). They are sums of O(1) terms whose result
decays like (size/r)^3, so in float32 the far field would lose (r/size)^3 * 1e-7 relative: they run in float64 (the
kernels' inputs and outputs stay float32). Every closed form takes the observer in the *source's own frame* (centre
at the origin, edges / axis along the coordinate axes). Units: SI, polarization J = mu0 M [T], B [T].
"""

from __future__ import annotations

import warp as wp

from .common import SHAPE_CYLINDER

F64_0 = wp.constant(wp.float64(0.0))
F64_HALF = wp.constant(wp.float64(0.5))
F64_1 = wp.constant(wp.float64(1.0))
F64_2 = wp.constant(wp.float64(2.0))
F64_4 = wp.constant(wp.float64(4.0))
F64_PI = wp.constant(wp.float64(3.141592653589793))
F64_INV_4PI = wp.constant(wp.float64(0.07957747154594767))


@wp.func
def cel_start(kc: wp.float64, p: wp.float64, c: wp.float64, s: wp.float64):
    """Bulirsch's initial transformation of cel(kc, p, c, s) (the p <= 0 case moved to p > 0): (p', c', s')."""
    pp = p
    cc = c
    ss = s
    if pp > F64_0:
        pp = wp.sqrt(pp)
        ss = ss / pp
    else:
        f = kc * kc
        q = F64_1 - f
        g = F64_1 - pp
        f = f - pp
        q = q * (ss - cc * pp)
        pp = wp.sqrt(f / g)
        cc = (cc - ss) / g
        ss = -q / (g * g * pp) + cc * pp
    return pp, cc, ss


@wp.func
def cel(kc: wp.float64, p: wp.float64, c: wp.float64, s: wp.float64) -> wp.float64:
    """Bulirsch's complete elliptic integral cel(kc, p, c, s) (Numer. Math. 13, 1969), kc != 0.

    K(m) = cel(sqrt(1-m), 1, 1, 1), E(m) = cel(sqrt(1-m), 1, 1, 1-m), Pi(n, m) = cel(sqrt(1-m), 1-n, 1, 1).
    """
    pp, cc, ss = cel_start(kc, p, c, s)
    em = F64_1
    qc = wp.abs(kc)
    kk = qc
    # quadratic convergence: 1e-12 is reached in <= 6 iterations for kc in [1e-8, 1e8]
    for _it in range(40):
        g = kk / pp
        c_new = cc + ss / pp
        ss = F64_2 * (ss + cc * g)
        cc = c_new
        pp = pp + g
        g = em
        em = em + qc
        if wp.abs(g - qc) <= g * wp.float64(1.0e-12):
            break
        qc = F64_2 * wp.sqrt(kk)
        kk = em * qc
    return F64_HALF * F64_PI * (ss + cc * em) / (em * (em + pp))


@wp.func
def cel2(kc: wp.float64, p1: wp.float64, c1: wp.float64, s1: wp.float64, p2: wp.float64, c2: wp.float64,
         s2: wp.float64):
    """(cel(kc, p1, c1, s1), cel(kc, p2, c2, s2)) in one loop: the iteration's kc part (the AGM sequence, its
    square root and the stopping test) depends on kc alone and is shared; the values equal two :func:`cel` calls
    bit for bit."""
    pa, ca, sa = cel_start(kc, p1, c1, s1)
    pb, cb, sb = cel_start(kc, p2, c2, s2)
    em = F64_1
    qc = wp.abs(kc)
    kk = qc
    for _it in range(40):
        g = kk / pa
        c_new = ca + sa / pa
        sa = F64_2 * (sa + ca * g)
        ca = c_new
        pa = pa + g
        g = kk / pb
        c_new = cb + sb / pb
        sb = F64_2 * (sb + cb * g)
        cb = c_new
        pb = pb + g
        g = em
        em = em + qc
        if wp.abs(g - qc) <= g * wp.float64(1.0e-12):
            break
        qc = F64_2 * wp.sqrt(kk)
        kk = em * qc
    return (
        F64_HALF * F64_PI * (sa + ca * em) / (em * (em + pa)),
        F64_HALF * F64_PI * (sb + cb * em) / (em * (em + pb)),
    )


@wp.func
def atan2_rough(y: wp.float64, x: wp.float64) -> wp.float64:
    """atan2(y, x) to within 0.005 rad (only to pick the 2π branch of an exact argument; see :func:`atan2_sum8`)."""
    ax = wp.abs(x)
    ay = wp.abs(y)
    hi = wp.max(ax, ay)
    if hi == F64_0:
        return F64_0
    t = wp.min(ax, ay) / hi
    # atan t ≈ t (π/4 + 0.273 (1 − t)) on [0, 1], error < 0.0040 rad
    a = t * (wp.float64(0.7853981633974483) + wp.float64(0.273) * (F64_1 - t))
    if ay > ax:
        a = F64_HALF * F64_PI - a
    if x < F64_0:
        a = F64_PI - a
    if y < F64_0:
        a = -a
    return a


@wp.func
def atan2_factor(re: wp.float64, im: wp.float64, n: wp.float64, d: wp.float64, sign: wp.float64):
    """The product re + i im times (d + i n)^sign (sign ±1; the modulus is of no interest, so the conjugate stands for
    the inverse), and sign · :func:`atan2_rough` (n, d)."""
    ni = n * sign
    return re * d - im * ni, re * ni + im * d, sign * atan2_rough(n, d)


@wp.func
def atan2_sum8(n: wp.vec4d, d: wp.vec4d, sign: wp.vec4d, n2: wp.vec4d, d2: wp.vec4d, sign2: wp.vec4d) -> wp.float64:
    """Σ_k sign_k atan2(n_k, d_k) over the 8 terms (two vec4 halves), with one atan2 instead of eight.

    The sum's value modulo 2π is the argument of Π (d_k + i n_k)^sign_k (complex products, each with a relative
    rounding of a few ε, so the argument is as exact as the sum of eight atan2 values); its branch comes from the
    same sum of :func:`atan2_rough` estimates (total error < 0.04 rad, far inside ±π). A term on the negative real
    axis (n = ±0, d <= 0) is where atan2 reads the sign of a zero (±π); there the eight atan2 are summed as they are.
    """
    cut = False
    for k in range(4):
        if (n[k] == F64_0 and d[k] <= F64_0) or (n2[k] == F64_0 and d2[k] <= F64_0):
            cut = True
    if cut:
        exact = F64_0
        for k in range(4):
            exact = exact + sign[k] * wp.atan2(n[k], d[k]) + sign2[k] * wp.atan2(n2[k], d2[k])
        return exact
    re = F64_1
    im = F64_0
    re, im, e0 = atan2_factor(re, im, n[0], d[0], sign[0])
    re, im, e1 = atan2_factor(re, im, n[1], d[1], sign[1])
    re, im, e2 = atan2_factor(re, im, n[2], d[2], sign[2])
    re, im, e3 = atan2_factor(re, im, n[3], d[3], sign[3])
    re, im, e4 = atan2_factor(re, im, n2[0], d2[0], sign2[0])
    re, im, e5 = atan2_factor(re, im, n2[1], d2[1], sign2[1])
    re, im, e6 = atan2_factor(re, im, n2[2], d2[2], sign2[2])
    re, im, e7 = atan2_factor(re, im, n2[3], d2[3], sign2[3])
    arg = wp.atan2(im, re)
    two_pi = F64_2 * F64_PI
    return arg + two_pi * wp.round(((e0 + e1 + e2 + e3) + (e4 + e5 + e6 + e7) - arg) / two_pi)


@wp.func
def octant_reflection(p: wp.vec3d):
    """``p`` reflected into the octant x >= 0, y <= 0, z <= 0 and the signs (sx, sy, sz) of the reflection."""
    x = p[0]
    y = p[1]
    z = p[2]
    sx = F64_1
    sy = F64_1
    sz = F64_1
    if x < F64_0:
        x = -x
        sx = -F64_1
    if y > F64_0:
        y = -y
        sy = -F64_1
    if z > F64_0:
        z = -z
        sz = -F64_1
    return wp.vec3d(x, y, z), wp.vec3d(sx, sy, sz)


@wp.func
def cuboid_field(J: wp.vec3d, dim: wp.vec3d, p: wp.vec3d) -> wp.vec3d:
    """B [T] at ``p`` [m] (cuboid frame, centre at origin) of a cuboid with extents ``dim`` [m], polarization ``J`` [T].

    Surface-charge closed form (Yang 1990, Engel-Herbert 2005), valid inside and outside. The observer is first
    reflected into the octant x >= 0, y <= 0, z <= 0, where no log argument can vanish off the magnet's edges
    (Cichon 2019, as magpylib); the reflection S = diag(sx, sy, sz) acts as B(p) = S B'(S p) with J' = S J.
    """
    a = F64_HALF * dim[0]
    b = F64_HALF * dim[1]
    c = F64_HALF * dim[2]
    q, sgn = octant_reflection(p)
    x = q[0]
    y = q[1]
    z = q[2]
    sx = sgn[0]
    sy = sgn[1]
    sz = sgn[2]
    jx = J[0] * sx
    jy = J[1] * sy
    jz = J[2] * sz

    xma = x - a
    xpa = x + a
    ymb = y - b
    ypb = y + b
    zmc = z - c
    zpc = z + c
    xma2 = xma * xma
    xpa2 = xpa * xpa
    ymb2 = ymb * ymb
    ypb2 = ypb * ypb
    zmc2 = zmc * zmc
    zpc2 = zpc * zpc

    mmm = wp.sqrt(xma2 + ymb2 + zmc2)
    pmp = wp.sqrt(xpa2 + ymb2 + zpc2)
    pmm = wp.sqrt(xpa2 + ymb2 + zmc2)
    mmp = wp.sqrt(xma2 + ymb2 + zpc2)
    mpm = wp.sqrt(xma2 + ypb2 + zmc2)
    ppp = wp.sqrt(xpa2 + ypb2 + zpc2)
    ppm = wp.sqrt(xpa2 + ypb2 + zmc2)
    mpp = wp.sqrt(xma2 + ypb2 + zpc2)

    # only the terms a non-zero polarization component multiplies (an axial bar needs 8 of the 24 atan2 and 4 of
    # the 6 logs); the others stay 0
    ff1x = F64_0
    ff1y = F64_0
    ff1z = F64_0
    ff2x = F64_0
    ff2y = F64_0
    ff2z = F64_0
    if jy != F64_0 or jz != F64_0:
        ff2x = wp.log((xma + mmm) * (xpa + ppm) * (xpa + pmp) * (xma + mpp)) - wp.log(
            (xpa + pmm) * (xma + mpm) * (xma + mmp) * (xpa + ppp)
        )
    if jx != F64_0 or jz != F64_0:
        ff2y = wp.log((-ymb + mmm) * (-ypb + ppm) * (-ymb + pmp) * (-ypb + mpp)) - wp.log(
            (-ymb + pmm) * (-ypb + mpm) * (ymb - mmp) * (ypb - ppp)
        )
    if jx != F64_0 or jy != F64_0:
        ff2z = wp.log((-zmc + mmm) * (-zmc + ppm) * (-zpc + pmp) * (-zpc + mpp)) - wp.log(
            (-zmc + pmm) * (zmc - mpm) * (-zpc + mmp) * (zpc - ppp)
        )
    # the three sums of eight atan2 (an axial bar needs only ff1z), each as one atan2 of a complex product
    plus_minus = wp.vec4d(F64_1, -F64_1, -F64_1, F64_1)
    minus_plus = wp.vec4d(-F64_1, F64_1, F64_1, -F64_1)
    if jx != F64_0:
        ff1x = atan2_sum8(
            wp.vec4d(ymb * zmc, ymb * zmc, ypb * zmc, ypb * zmc),
            wp.vec4d(xma * mmm, xpa * pmm, xma * mpm, xpa * ppm),
            plus_minus,
            wp.vec4d(ymb * zpc, ymb * zpc, ypb * zpc, ypb * zpc),
            wp.vec4d(xma * mmp, xpa * pmp, xma * mpp, xpa * ppp),
            minus_plus,
        )
    if jy != F64_0:
        ff1y = atan2_sum8(
            wp.vec4d(xma * zmc, xpa * zmc, xma * zmc, xpa * zmc),
            wp.vec4d(ymb * mmm, ymb * pmm, ypb * mpm, ypb * ppm),
            plus_minus,
            wp.vec4d(xma * zpc, xpa * zpc, xma * zpc, xpa * zpc),
            wp.vec4d(ymb * mmp, ymb * pmp, ypb * mpp, ypb * ppp),
            minus_plus,
        )
    if jz != F64_0:
        ff1z = atan2_sum8(
            wp.vec4d(xma * ymb, xpa * ymb, xma * ypb, xpa * ypb),
            wp.vec4d(zmc * mmm, zmc * pmm, zmc * mpm, zmc * ppm),
            plus_minus,
            wp.vec4d(xma * ymb, xpa * ymb, xma * ypb, xpa * ypb),
            wp.vec4d(zpc * mmp, zpc * pmp, zpc * mpp, zpc * ppp),
            minus_plus,
        )

    bx = jx * ff1x + jy * ff2z + jz * ff2y
    by = jx * ff2z + jy * ff1y - jz * ff2x
    bz = jx * ff2y - jy * ff2x + jz * ff1z
    return wp.vec3d(sx * bx, sy * by, sz * bz) * F64_INV_4PI


@wp.func
def cylinder_axial_field_rz(z0: wp.float64, r: wp.float64, z: wp.float64):
    """(B_r, B_z) for unit axial polarization (Derby 2010); lengths in units of the radius, z0 = half height."""
    zph = z + z0
    zmh = z - z0
    dpr = F64_1 + r
    dmr = F64_1 - r
    sq0 = wp.sqrt(zmh * zmh + dpr * dpr)
    sq1 = wp.sqrt(zph * zph + dpr * dpr)
    k1 = wp.sqrt((zph * zph + dmr * dmr) / (zph * zph + dpr * dpr))
    k0 = wp.sqrt((zmh * zmh + dmr * dmr) / (zmh * zmh + dpr * dpr))
    gamma = dmr / dpr
    cr1, cz1 = cel2(k1, F64_1, F64_1, -F64_1, gamma * gamma, F64_1, gamma)
    cr0, cz0 = cel2(k0, F64_1, F64_1, -F64_1, gamma * gamma, F64_1, gamma)
    br = (cr1 / sq1 - cr0 / sq0) / F64_PI
    bz = (zph * cz1 / sq1 - zmh * cz0 / sq0) / (dpr * F64_PI)
    return br, bz


@wp.func
def diametral_field_near_axis(zp: wp.float64, zm: wp.float64, zp2: wp.float64, zm2: wp.float64, r: wp.float64,
                              r2: wp.float64, phi: wp.float64) -> wp.vec3d:
    """:func:`cylinder_diametral_field_cyl` for r < 0.05, where the general form loses digits: its 5th-order Taylor
    series in r."""
    zpp = zp2 + F64_1
    zmm = zm2 + F64_1
    sqrt_p = wp.sqrt(zpp)
    sqrt_m = wp.sqrt(zmm)
    frac1 = zp / sqrt_p
    frac2 = zm / sqrt_m
    r3 = r2 * r
    r4 = r3 * r
    r5 = r4 * r
    term1 = frac1 - frac2
    term2 = (frac1 / (zpp * zpp) - frac2 / (zmm * zmm)) * r2 / wp.float64(8.0)
    zpp4 = zpp * zpp * zpp * zpp
    zmm4 = zmm * zmm * zmm * zmm
    term3 = (
        ((wp.float64(3.0) - F64_4 * zp2) * frac1 / zpp4 - (wp.float64(3.0) - F64_4 * zm2) * frac2 / zmm4)
        / wp.float64(64.0)
        * r4
    )
    hr = -wp.cos(phi) / F64_4 * (term1 + wp.float64(9.0) * term2 + wp.float64(25.0) * term3)
    hphi = wp.sin(phi) / F64_4 * (term1 + wp.float64(3.0) * term2 + wp.float64(5.0) * term3)
    zpp3 = zpp * zpp * zpp
    zmm3 = zmm * zmm * zmm
    zpp5 = zpp3 * zpp * zpp
    zmm5 = zmm3 * zmm * zmm
    hz = (
        -wp.cos(phi)
        / F64_4
        * (
            r * (F64_1 / zpp / sqrt_p - F64_1 / zmm / sqrt_m)
            + wp.float64(0.375)
            * r3
            * ((F64_1 - F64_4 * zp2) / zpp3 / sqrt_p - (F64_1 - F64_4 * zm2) / zmm3 / sqrt_m)
            + wp.float64(0.234375)
            * r5
            * (
                (F64_1 - wp.float64(12.0) * zp2 + wp.float64(8.0) * zp2 * zp2) / zpp5 / sqrt_p
                - (F64_1 - wp.float64(12.0) * zm2 + wp.float64(8.0) * zm2 * zm2) / zmm5 / sqrt_m
            )
        )
    )
    return wp.vec3d(hr, hphi, hz)


@wp.func
def diametral_field_general(zp: wp.float64, zm: wp.float64, zp2: wp.float64, zm2: wp.float64, r: wp.float64,
                            r2: wp.float64, phi: wp.float64) -> wp.vec3d:
    """:func:`cylinder_diametral_field_cyl` off the axis (Caciagli 2018), with complete elliptic integrals."""
    rp = r + F64_1
    rm = r - F64_1
    rp2 = rp * rp
    rm2 = rm * rm
    ap2 = zp2 + rm2
    am2 = zm2 + rm2
    ap = wp.sqrt(ap2)
    am = wp.sqrt(am2)
    argp = -F64_4 * r / ap2
    argm = -F64_4 * r / am2
    argc = wp.float64(1.0e16)
    one_over_rm = F64_0
    if rm != F64_0:
        argc = -F64_4 * r / rm2
        one_over_rm = F64_1 / rm
    kcp = wp.sqrt(F64_1 - argp)
    kcm = wp.sqrt(F64_1 - argm)
    elle_p, ellk_p = cel2(kcp, F64_1, F64_1, F64_1 - argp, F64_1, F64_1, F64_1)
    elle_m, ellk_m = cel2(kcm, F64_1, F64_1, F64_1 - argm, F64_1, F64_1, F64_1)
    ellpi_p = cel(kcp, F64_1 - argc, F64_1, F64_1)
    ellpi_m = cel(kcm, F64_1 - argc, F64_1, F64_1)
    hr = (
        -wp.cos(phi)
        / (F64_4 * F64_PI * r2)
        * (
            -zm * am * elle_m
            + zp * ap * elle_p
            + zm / am * (F64_2 + zm2) * ellk_m
            - zp / ap * (F64_2 + zp2) * ellk_p
            + (zm / am * ellpi_m - zp / ap * ellpi_p) * rp * (r2 + F64_1) * one_over_rm
        )
    )
    hphi = (
        wp.sin(phi)
        / (F64_4 * F64_PI * r2)
        * (
            zm * am * elle_m
            - zp * ap * elle_p
            - zm / am * (F64_2 + zm2 + F64_2 * r2) * ellk_m
            + zp / ap * (F64_2 + zp2 + F64_2 * r2) * ellk_p
            + zm / am * rp2 * ellpi_m
            - zp / ap * rp2 * ellpi_p
        )
    )
    hz = (
        -wp.cos(phi)
        / (F64_2 * F64_PI * r)
        * (am * elle_m - ap * elle_p - (F64_1 + zm2 + r2) / am * ellk_m + (F64_1 + zp2 + r2) / ap * ellk_p)
    )
    return wp.vec3d(hr, hphi, hz)


@wp.func
def cylinder_diametral_field_cyl(z0: wp.float64, r: wp.float64, z: wp.float64, phi: wp.float64) -> wp.vec3d:
    """(H_r, H_phi, H_z) for unit diametral magnetization along phi = 0 (Caciagli 2018; small-r Taylor branch from
    magpylib); lengths in units of the radius, z0 = half height. Multiply by |J_perp| for B outside the magnet."""
    zp = z + z0
    zm = z - z0
    zp2 = zp * zp
    zm2 = zm * zm
    r2 = r * r
    if r < wp.float64(0.05):
        return diametral_field_near_axis(zp, zm, zp2, zm2, r, r2, phi)
    return diametral_field_general(zp, zm, zp2, zm2, r, r2, phi)


@wp.func
def cylinder_field(J: wp.vec3d, diameter: wp.float64, height: wp.float64, p: wp.vec3d) -> wp.vec3d:
    """B [T] at ``p`` [m] (cylinder frame: centre at origin, axis +z) of a cylinder with polarization ``J`` [T]."""
    r0 = F64_HALF * diameter
    rho = wp.sqrt(p[0] * p[0] + p[1] * p[1])
    r = rho / r0
    z = p[2] / r0
    z0 = F64_HALF * height / r0
    # the observer's azimuth as (cos, sin) without trigonometry; phi = 0 on the axis (as atan2(0, 0))
    cphi = F64_1
    sphi = F64_0
    if rho > F64_0:
        cphi = p[0] / rho
        sphi = p[1] / rho
    b = wp.vec3d(F64_0, F64_0, F64_0)
    if J[2] != F64_0:
        br, bz = cylinder_axial_field_rz(z0, r, z)
        b = b + wp.vec3d(br * cphi * J[2], br * sphi * J[2], bz * J[2])
    jt = wp.sqrt(J[0] * J[0] + J[1] * J[1])
    if jt > F64_0:
        phi = wp.atan2(p[1], p[0])
        theta = wp.atan2(J[1], J[0])
        h = cylinder_diametral_field_cyl(z0, r, z, phi - theta) * jt
        b = b + wp.vec3d(h[0] * cphi - h[1] * sphi, h[0] * sphi + h[1] * cphi, h[2])
        if r <= F64_1 and wp.abs(z) <= z0:
            # the diametral closed form is mu0 H; B = mu0 H + J inside the magnet
            b = b + wp.vec3d(J[0], J[1], F64_0)
    return b


@wp.func
def magnet_field_local(shape: int, size: wp.vec3d, J: wp.vec3d, p: wp.vec3d) -> wp.vec3d:
    """B [T] at ``p`` [m] in the magnet's frame; ``size`` = cuboid extents or (d, d, h) for a cylinder."""
    if shape == SHAPE_CYLINDER:
        return cylinder_field(J, size[0], size[2], p)
    return cuboid_field(J, size, p)
