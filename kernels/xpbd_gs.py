"""Per-world Gauss–Seidel XPBD: one thread per world runs every substep of a step (the default solver).

Kernels only; the host orchestration is :class:`warpworm.simulator.Simulator` (``solver="gauss_seidel"``).
:func:`gs_step` is launched 1-D over worlds (``world = wp.tid()``); each thread loops over its own world's
substeps, and in each substep

1. predicts every vertex (gravity, the step's magnetic force, implicit linear damping) — as
   :func:`warpworm.kernels.xpbd.integrate_vertices`;
2. projects, ``iterations`` times and in place (Gauss–Seidel: each constraint sees the corrections of the previous
   ones), every bar, every hinge (spring with XPBD damping, or the rigid NoFoldThrough limit) and every anchor, with
   the usual XPBD compliances (bars L0 / (EA dt²), hinges 1 / (k_α L dt²), anchors 1 / (strength dt²)). With more
   than one iteration the Lagrange multipliers are accumulated (``lam``), so the compliant elements converge to
   the implicit-Euler spring force rather than being applied ``iterations`` times;
3. floor contact with position-level static / kinetic friction (:func:`warpworm.kernels.xpbd.floor_contact`),
   velocities v = v_pred + Σ corrections / dt, and the stability check.

No atomics and no mass splitting (a thread owns its world's vertices), no launches per substep. Results are
deterministic and identical on CPU and CUDA up to float32 contraction. A world that becomes unstable (a bar strained
beyond ``strain_limit``, a vertex faster than ``speed_limit``, a non-finite value) is put back to the start of the
offending substep, flagged and skipped from then on.
"""

from __future__ import annotations

import warp as wp

from .xpbd import dihedral_angle_and_gradient, floor_contact, fold_range, freeze_world, pw, wrap_angle

wp.set_module_options({"enable_backward": False})


@wp.kernel
def gs_step(
    # Model:
    inv_mass: wp.array2d(dtype=float),
    gravity: wp.array(dtype=float),
    damping: wp.array(dtype=float),
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
    floor_incline: wp.array(dtype=float),
    mu_static: wp.array(dtype=float),
    mu_kinetic: wp.array(dtype=float),
    dt: float,
    num_substeps: int,
    iterations: int,
    strain_limit: float,
    speed_limit: float,
    # Data in:
    f_ext: wp.array2d(dtype=wp.vec3),
    anchor_target: wp.array2d(dtype=wp.vec3),
    # Data out:
    x: wp.array2d(dtype=wp.vec3),
    v: wp.array2d(dtype=wp.vec3),
    x_prev: wp.array2d(dtype=wp.vec3),
    delta: wp.array2d(dtype=wp.vec3),
    lam: wp.array2d(dtype=float),
    bar_strain: wp.array2d(dtype=float),
    crease_angle: wp.array2d(dtype=float),
    contact: wp.array2d(dtype=wp.int32),
    unstable: wp.array(dtype=wp.int32),
    step_count: wp.array(dtype=wp.int32),
):
    """``num_substeps`` Gauss–Seidel XPBD substeps of length ``dt`` of one world. Launch dim (W,).

    ``lam (W, E + H + A)`` is scratch for the accumulated multipliers (read only when ``iterations > 1``);
    ``delta (W, V)`` scratch for the summed corrections of a substep (zero between substeps). Other arrays as in :mod:`warpworm.kernels.xpbd`.
    """
    world = wp.tid()
    if unstable[world] != 0:
        return
    nv = x.shape[1]
    ne = edges.shape[0]
    nh = hinges.shape[0]
    na = anchor_vertex.shape[0]
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
    beta = pw(floor_incline, world)
    mu_s = pw(mu_static, world)
    mu_k = pw(mu_kinetic, world)
    inv_dt2 = 1.0 / (dt * dt)
    multi = iterations > 1

    for s in range(num_substeps):
        # 1. predict
        for i in range(nv):
            w_inv = inv_mass[im_row, i]
            vel = wp.vec3(0.0)
            if w_inv > 0.0:
                vel = (v[world, i] + dt * (gvec + f_ext[world, i] * w_inv)) * damp
            p = x[world, i]
            x_prev[world, i] = p
            q = p + dt * vel
            x[world, i] = q
            v[world, i] = vel
        if multi:
            for cix in range(ne + nh + na):
                lam[world, cix] = 0.0

        # 2. constraints, in place
        bad = int(0)
        for it in range(iterations):
            for e in range(ne):
                a = edges[e, 0]
                b = edges[e, 1]
                xa = x[world, a]
                xb = x[world, b]
                d = xa - xb
                length = wp.length(d)
                l0 = rest_length[rl_row, e]
                c = length - l0
                strain = c / l0
                bar_strain[world, e] = strain
                if not (wp.abs(strain) < strain_limit):  # also catches NaN
                    bad = 1
                wa = inv_mass[im_row, a]
                wb = inv_mass[im_row, b]
                alpha = l0 / bar_stiffness[ea_row, e] * inv_dt2
                denom = wa + wb + alpha
                if denom > 0.0 and length > 0.0 and bad == 0:
                    lam0 = float(0.0)
                    if multi:
                        lam0 = lam[world, e]
                    dlam = -(c + alpha * lam0) / denom
                    if multi:
                        lam[world, e] = lam0 + dlam
                    n = d * (dlam / length)
                    x[world, a] = xa + n * wa
                    x[world, b] = xb - n * wb
                    delta[world, a] = delta[world, a] + n * wa
                    delta[world, b] = delta[world, b] - n * wb
            if bad != 0:
                break
            for h in range(nh):
                i = hinges[h, 0]
                j = hinges[h, 1]
                k = hinges[h, 2]
                l = hinges[h, 3]
                xi = x[world, i]
                xj = x[world, j]
                xk = x[world, k]
                xl = x[world, l]
                psi, gi, gj, gk, gl = dihedral_angle_and_gradient(xi, xj, xk, xl)
                prev = crease_angle[world, h]
                phi = prev + wrap_angle(psi - prev)
                crease_angle[world, h] = phi
                wi = inv_mass[im_row, i]
                wj = inv_mass[im_row, j]
                wk = inv_mass[im_row, k]
                wl = inv_mass[im_row, l]
                wsum = wi * wp.length_sq(gi) + wj * wp.length_sq(gj) + wk * wp.length_sq(gk) + wl * wp.length_sq(gl)
                lo, hi = fold_range(hinge_label[h])
                dlam = float(0.0)
                if phi < lo or phi > hi:
                    # rigid NoFoldThrough limit
                    bound = wp.where(phi < lo, lo, hi)
                    if wsum > 0.0:
                        dlam = -(phi - bound) / wsum
                else:
                    kh = k_hinge * hinge_length[hl_row, h]
                    if kh > 0.0:
                        alpha = inv_dt2 / kh
                        # XPBD damping (Macklin 2016): gamma = beta / (k L dt), beta = c_alpha L
                        gamma = c_hinge / (k_hinge * dt)
                        rate = float(0.0)
                        if gamma > 0.0:
                            rate = (
                                wp.dot(gi, xi - x_prev[world, i])
                                + wp.dot(gj, xj - x_prev[world, j])
                                + wp.dot(gk, xk - x_prev[world, k])
                                + wp.dot(gl, xl - x_prev[world, l])
                            )
                        lam0 = float(0.0)
                        if multi:
                            lam0 = lam[world, ne + h]
                        cc = phi - hinge_rest[hr_row, h]
                        dlam = -(cc + alpha * lam0 + gamma * rate) / ((1.0 + gamma) * wsum + alpha)
                        if multi:
                            lam[world, ne + h] = lam0 + dlam
                if dlam != 0.0:
                    ci = gi * (wi * dlam)
                    cj = gj * (wj * dlam)
                    ck = gk * (wk * dlam)
                    cl = gl * (wl * dlam)
                    x[world, i] = xi + ci
                    x[world, j] = xj + cj
                    x[world, k] = xk + ck
                    x[world, l] = xl + cl
                    delta[world, i] = delta[world, i] + ci
                    delta[world, j] = delta[world, j] + cj
                    delta[world, k] = delta[world, k] + ck
                    delta[world, l] = delta[world, l] + cl
            for an in range(na):
                pv = anchor_vertex[an]
                strength = anchor_stiffness[ak_row, an]
                wpv = inv_mass[im_row, pv]
                if strength > 0.0 and wpv > 0.0:
                    xp = x[world, pv]
                    d = xp - anchor_target[world, an]
                    dist = wp.length(d)
                    if dist > 0.0:
                        alpha = inv_dt2 / strength
                        lam0 = float(0.0)
                        if multi:
                            lam0 = lam[world, ne + nh + an]
                        dlam = -(dist + alpha * lam0) / (wpv + alpha)
                        if multi:
                            lam[world, ne + nh + an] = lam0 + dlam
                        cp = d * (wpv * dlam / dist)
                        x[world, pv] = xp + cp
                        delta[world, pv] = delta[world, pv] + cp
        if bad != 0:
            freeze_world(world, nv, x, v, x_prev, delta, unstable)
            return

        # 3. floor contact and friction, velocities, stability
        for i in range(nv):
            p = x[world, i]
            # Velocity = predicted + summed correction / dt. The corrections are summed in ``delta`` at their own
            # precision: (x - x_pred) / dt or (x - x_prev) / dt would carry the float32 rounding of every in-place
            # correction of a ~0.1 m position (~1e-8 m against friction steps of ~1e-8 m at 50 us substeps; kinetic
            # friction came out 8 % weak that way).
            vel = v[world, i] + delta[world, i] / dt
            delta[world, i] = wp.vec3(0.0)
            p, vel, touching = floor_contact(p, vel, x_prev[world, i], beta, mu_s, mu_k, dt)
            if not (wp.length(vel) < speed_limit):  # NaN fails every comparison
                bad = 1
            x[world, i] = p
            v[world, i] = vel
            contact[world, i] = touching
        if bad != 0:
            freeze_world(world, nv, x, v, x_prev, delta, unstable)
            return
        step_count[world] = step_count[world] + 1
