"""The implicit-Euler substep of :mod:`warpworm.kernels.implicit_euler` written in NumPy (float64), vectorized over
worlds for the elastic terms: the tests' reference (tests/test_dynamics_numpy_reference.py) and the benchmark's
(benchmarks/bench_dynamics.py imports it from here). Same math, its own code: a dense solve instead of the kernel's
block band, per-vertex Python loops for the floor. Usage::

    ref = NumpyImplicit(model, dt_sub, newton=sim.newton, slip_speed=sim.settings.slip_speed)
    x, v, angle = ref.init(state, control)     # NumPy copies (W, V, 3), (W, V, 3), (W, H); contacts kept in ref
    x, v, angle = ref.substep(x, v, angle, f_ext)

The floor (contacts, Coulomb friction with its regularised static part, landings at position level, the projected
Newton step) follows docs/dynamics.md, "The solver", for isotropic friction (``friction_backward_ratio`` 1) and
fresh Newton steps (the simulator's ``chord=False``); the panel-contact barrier of the hinges' wings is left out
(compare where no wing closes).
"""

from __future__ import annotations

import numpy as np


class NumpyImplicit:
    """The implicit-Euler substep of :mod:`warpworm.kernels.implicit_euler` in NumPy (float64), vectorized over
    worlds, for a worm off the floor (contact and friction left out: compare with no vertex touching it): predict
    x̃, start from the velocity carried over (the kernel's warm start), then ``newton`` Gauss–Newton steps on ½|x − x̃|²_M/dt² + E(x) with a dense batched solve
    (``np.linalg.solve`` on (W, 3V, 3V); the kernel factors a block band), then v = v' + (x − x̃)/dt.
    E: bar springs (compressive geometric stiffness dropped), creases (spring, implicit damping, NoFoldThrough limit
    spring k_lim of ``model.fold_limit_stiffness``; curvature term dropped), anchors. The benchmark's reference and the kernel's
    cross-check.
    """

    def __init__(self, model, dt_sub: float, newton: int = 3, slip_speed: float = 1.0e-5, floor: bool = True):
        p = model.pattern
        self.W, self.V = model.num_worlds, model.num_vertices
        self.dt = float(dt_sub)
        self.edges = p.edges.astype(np.int64)
        self.hinges = p.hinges.astype(np.int64)
        self.label = p.hinge_label.astype(np.int64)

        def rows(a):
            a = np.asarray(a, np.float64)
            return np.broadcast_to(a, (self.W,) + a.shape[1:])

        self.w = rows(model.inv_mass.numpy())
        self.L0 = rows(model.rest_length.numpy())
        self.rest = rows(model.hinge_rest_angle.numpy())
        self.hlen = rows(model.hinge_length.numpy())

        def col(a):
            return np.broadcast_to(np.asarray(a.numpy(), np.float64), (self.W,))[:, None]

        self.EA = rows(model.bar_stiffness.numpy())
        self.k, self.c_h = col(model.hinge_stiffness), col(model.hinge_damping)
        self.damping, self.g = col(model.damping), col(model.gravity)
        lo = np.full(len(self.label), -np.pi)
        hi = np.full(len(self.label), np.pi)
        hi[self.label == 1] = 0.0
        lo[self.label == 2] = 0.0
        self.lo, self.hi = lo, hi
        self.newton = int(newton)
        E = model.num_edges
        self.stop_strain = np.broadcast_to(model.bar_stop_strain.numpy().astype(np.float64), (self.W, E, 2))
        self.stop_k = np.broadcast_to(model.bar_stop_stiffness.numpy().astype(np.float64), (self.W, E))
        self.k_limit = np.broadcast_to(model.fold_limit_stiffness.numpy().astype(np.float64), (self.W,))
        self.anchor_vertex = model.anchor_vertex.numpy().astype(np.int64)
        A = len(self.anchor_vertex)
        self.anchor_k = np.broadcast_to(model.anchor_stiffness.numpy().astype(np.float64), (self.W, A))
        self.anchor_target = None
        self.slip = float(slip_speed)
        self.floor = bool(floor)  # False: no floor at all, vectorised (the benchmark's cost, as before the floor)
        beta = np.broadcast_to(np.asarray(model.floor_incline.numpy(), np.float64), (self.W,))
        self.n = np.stack([-np.sin(beta), np.zeros(self.W), np.cos(beta)], -1)  # (W, 3) the floor's unit normal
        self.mu_s = np.broadcast_to(np.asarray(model.mu_static.numpy(), np.float64), (self.W,))
        self.mu_k = np.broadcast_to(np.asarray(model.mu_kinetic.numpy(), np.float64), (self.W,))
        ratio = np.asarray(model.friction_backward_ratio.numpy())
        if not np.all(ratio == 1.0):
            raise NotImplementedError("the reference's friction is isotropic (friction_backward_ratio 1)")
        self.contact = np.zeros((self.W, self.V), np.int64)  # FREE 0, SLIDING 1, STUCK 2, FIXED 3 (as the kernel)
        self.floor_force = np.zeros((self.W, self.V, 3))

    def init(self, state, control=None):
        """The reference's start from a Warp ``state`` (and the anchor targets of ``control``, if any)."""
        self.anchor_target = None if control is None else control.anchor_target.numpy().astype(np.float64)
        self.contact = state.contact.numpy().astype(np.int64).copy()
        self.floor_force = state.floor_force.numpy().astype(np.float64).copy()
        return (state.positions.numpy().astype(np.float64).copy(), state.velocities.numpy().astype(np.float64).copy(),
                state.crease_angle.numpy().astype(np.float64).copy())

    def _add_blocks(self, H, rows, cols, blocks):
        """H (W, 3V, 3V) += blocks (W, n, 3, 3) at vertex rows (n,), cols (n,) and their transposes off the
        diagonal (each unordered pair given once)."""
        W = self.W
        r3 = 3 * rows[:, None, None] + np.arange(3)[None, :, None]
        c3 = 3 * cols[:, None, None] + np.arange(3)[None, None, :]
        r3, c3 = np.broadcast_arrays(r3, c3)
        wi = np.arange(W)[:, None, None, None]
        np.add.at(H, (wi, r3[None], c3[None]), blocks)
        off = rows != cols
        np.add.at(H, (wi, c3[None, off].transpose(0, 1, 3, 2), r3[None, off].transpose(0, 1, 3, 2)),
                  blocks[:, off].transpose(0, 1, 3, 2))

    def _elastic(self, X, xt, angle, m_dt2):
        """Gradient (W, V, 3) and Gauss–Newton Hessian (W, 3V, 3V) of ½|X − x̃|²_M/dt² + E(X), no friction."""
        from warpworm.physics import crease

        W, V, dt = self.W, self.V, self.dt
        e, h, eye = self.edges, self.hinges, np.eye(3)
        k1, ch = self.k[:, 0], self.c_h[:, 0]
        g = m_dt2[..., None] * (X - xt)
        H = np.zeros((W, 3 * V, 3 * V))
        idx = np.arange(3 * V)
        H[:, idx, idx] += np.repeat(m_dt2, 3, axis=1)
        # bars
        d = X[:, e[:, 0]] - X[:, e[:, 1]]
        L = np.linalg.norm(d, axis=-1)
        n = d / L[..., None]
        ka = self.EA / self.L0
        f = n * (ka * (L - self.L0))[..., None]
        strain = (L - self.L0) / self.L0
        stop = np.where(strain < 0, -self.stop_strain[..., 0], self.stop_strain[..., 1])
        l_stop = self.L0 * (1.0 + stop)
        ks = np.where(np.where(strain < 0, strain < stop, strain > stop), self.stop_k / self.L0, 0.0)
        f = f + n * (ks * (L - l_stop))[..., None]
        np.add.at(g, (slice(None), e[:, 0]), f)
        np.add.at(g, (slice(None), e[:, 1]), -f)
        nn = n[..., :, None] * n[..., None, :]
        k_trans = ka * np.maximum(0.0, 1.0 - self.L0 / L) + ks * np.maximum(0.0, 1.0 - l_stop / L)
        kb = (ka + ks)[..., None, None] * nn + k_trans[..., None, None] * (eye - nn)
        self._add_blocks(H, e[:, 0], e[:, 0], kb)
        self._add_blocks(H, e[:, 1], e[:, 1], kb)
        self._add_blocks(H, e[:, 0], e[:, 1], -kb)
        # creases
        psi = crease.dihedral_angles(X, h)
        phi = angle + (psi - angle + np.pi) % (2 * np.pi) - np.pi
        grads = crease.dihedral_gradients(X, h)  # (W, H, 4, 3)
        torque = self.hlen * (k1[:, None] * (phi - self.rest) + ch[:, None] / dt * (phi - angle))
        stiff = self.hlen * (k1[:, None] + ch[:, None] / dt)
        bound = np.clip(phi, self.lo, self.hi)
        out = phi != bound
        torque = torque + np.where(out, self.k_limit[:, None] * self.hlen * (phi - bound), 0.0)
        stiff = stiff + np.where(out, self.k_limit[:, None] * self.hlen, 0.0)
        for a in range(4):
            np.add.at(g, (slice(None), h[:, a]), grads[:, :, a] * torque[..., None])
            for b in range(a + 1):
                blk = stiff[..., None, None] * grads[:, :, a, :, None] * grads[:, :, b, None, :]
                self._add_blocks(H, h[:, a], h[:, b], blk)
        # anchors
        for an, pv in enumerate(self.anchor_vertex.tolist()):
            kk = self.anchor_k[:, an]
            g[:, pv] += kk[:, None] * (X[:, pv] - self.anchor_target[:, an])
            H[:, 3 * pv:3 * pv + 3, 3 * pv:3 * pv + 3] += kk[:, None, None] * eye
        return g, H

    # --- the floor (statuses as the kernel's CONTACT_*)
    FREE, SLIDING, STUCK, FIXED = 0, 1, 2, 3

    def _friction(self, wi, st, vt, fn):
        """Coulomb friction on a vertex at tangential velocity vt under normal force fn: (force, −∂f/∂v on the
        tangent plane less the sliding direction t, t)."""
        zero = np.zeros(3)
        if not fn > 0.0:
            return zero, 0.0, zero
        if st == self.STUCK:  # regularised static friction: viscous, reaching mu_s fn at the slip speed
            c = self.mu_s[wi] * fn / self.slip
            return -c * vt, c, zero
        speed = np.linalg.norm(vt)
        if speed > 0.0:
            c = self.mu_k[wi] * fn / speed
            return -c * vt, c, vt / speed
        return zero, 0.0, zero

    def substep(self, x, v, angle, f_ext):
        """One substep of every world: predict, ``newton`` projected Newton steps with the contacts updated between
        them, then the floor once more and v = (x − x_n) / dt. Contacts and floor forces carry over in ``self``."""
        from warpworm.physics import crease

        if not self.floor:
            return self._substep_no_floor(x, v, angle, f_ext)
        dt, W, V = self.dt, self.W, self.V
        wv = self.w
        m_dt2 = np.where(wv > 0, 1.0 / np.where(wv > 0, wv, 1.0) / dt**2, 1.0)  # (W, V); 1 for infinite mass
        eye = np.eye(3)
        x_prev = x.copy()
        X = x.copy()
        vel = np.zeros_like(v)  # the inertial velocity (x̃ = x_n + dt vel)
        released = np.zeros((W, V), np.int64)
        cont, ff = self.contact, self.floor_force
        for wi in range(W):
            n = self.n[wi]
            damp = 1.0 / (1.0 + self.damping[wi, 0] * dt)
            gvec = np.array([0.0, 0.0, -self.g[wi, 0]])
            for i in range(V):
                w_inv, v_old = wv[wi, i], v[wi, i]
                if w_inv > 0:
                    vel[wi, i] = v_old * damp + dt * (gvec + f_ext[wi, i] * w_inv)
                h0 = x[wi, i] @ n
                # the status at the start of the substep
                if not w_inv > 0:
                    st = self.FIXED
                else:
                    stays = vel[wi, i] @ n < 0.0 or v_old @ n <= self.slip
                    was = cont[wi, i]
                    if (was != self.FREE and stays) or (was == self.FREE and h0 + dt * (v_old @ n) < 0.0):
                        vt_old = v_old - n * (v_old @ n)
                        st = self.SLIDING if np.linalg.norm(vt_old) > self.slip else self.STUCK
                    else:
                        st = self.FREE
                if st in (self.STUCK, self.SLIDING) and cont[wi, i] == self.FREE:  # landing: first normal force
                    ff[wi, i] = n * (-(h0 + dt * (vel[wi, i] @ n)) * m_dt2[wi, i])
                # where the iteration starts: the carried velocity (free), along the floor, or fixed
                if st == self.FIXED:
                    start = vel[wi, i]
                elif st == self.FREE:
                    gn = v_old @ n
                    start = v_old + n * (max(gn, -h0 / dt) - gn)
                else:
                    start = n * max(min(vel[wi, i] @ n, 0.0), -h0 / dt)
                    if st == self.SLIDING:
                        start = start + (v_old - n * (v_old @ n))
                cont[wi, i] = st
                X[wi, i] = x[wi, i] + dt * start
        xt = x_prev + dt * vel
        for it in range(self.newton):
            g, H = self._elastic(X, xt, angle, m_dt2)
            if it >= 1:
                landed = self._update_contacts(X, x_prev, vel, g, m_dt2, released)
                if landed:
                    g, H = self._elastic(X, xt, angle, m_dt2)
            for wi in range(W):
                n = self.n[wi]
                for i in range(V):
                    st = cont[wi, i]
                    if st in (self.SLIDING, self.STUCK):
                        u = (X[wi, i] - x_prev[wi, i]) / dt
                        vt = u - n * (u @ n)
                        f, kf, t = self._friction(wi, st, vt, ff[wi, i] @ n)
                        g[wi, i] -= f
                        H[wi, 3 * i:3 * i + 3, 3 * i:3 * i + 3] += (eye - np.outer(n, n) - np.outer(t, t)) * kf / dt
                # the step restricted to the directions each vertex may move in
                P = np.zeros((V, 3, 3))
                for i in range(V):
                    st = cont[wi, i]
                    P[i] = eye if st == self.FREE else (np.zeros((3, 3)) if st == self.FIXED
                                                         else eye - np.outer(n, n))
                Pb = np.zeros((3 * V, 3 * V))
                for i in range(V):
                    Pb[3 * i:3 * i + 3, 3 * i:3 * i + 3] = P[i]
                Hw = Pb @ H[wi] @ Pb
                for i in range(V):
                    Hw[3 * i:3 * i + 3, 3 * i:3 * i + 3] += (eye - P[i]) * m_dt2[wi, i]
                rhs = Pb @ g[wi].reshape(-1)
                X[wi] += np.linalg.solve(Hw, -rhs).reshape(V, 3)
        # the floor once more, and the velocities
        v_new = np.zeros_like(v)
        for wi in range(W):
            n = self.n[wi]
            for i in range(V):
                u = (X[wi, i] - x_prev[wi, i]) / dt
                p0 = x_prev[wi, i]
                st = cont[wi, i]
                if st == self.FREE:
                    depth = max(-(p0 @ n + dt * (u @ n)), 0.0)
                    if depth > 0.0:
                        u = u + n * (depth / dt)
                        un = u @ n
                        ut = u - n * un
                        ut_len = np.linalg.norm(ut)
                        if ut_len * dt <= self.mu_s[wi] * depth:
                            u, st = n * un, self.STUCK
                        else:
                            u, st = u - ut * (self.mu_k[wi] * depth / (dt * ut_len)), self.SLIDING
                    ff[wi, i] = n * (depth * m_dt2[wi, i])
                elif st in (self.STUCK, self.SLIDING):
                    un = u @ n
                    u = u + n * (max(un, -(p0 @ n) / dt) - un)
                    ut = u - n * (u @ n)
                    fn = ff[wi, i] @ n
                    ff[wi, i] = n * fn + self._friction(wi, st, ut, fn)[0]
                else:
                    u, st = np.zeros(3), self.FREE
                X[wi, i] = p0 + u * dt
                v_new[wi, i] = u
                cont[wi, i] = st
        psi = crease.dihedral_angles(X, self.hinges)
        angle = angle + (psi - angle + np.pi) % (2 * np.pi) - np.pi
        return X, v_new, angle

    def _substep_no_floor(self, x, v, angle, f_ext):
        """The substep without a floor (``floor=False``), vectorised over worlds: what the benchmark times."""
        from warpworm.physics import crease

        dt, w = self.dt, self.w
        acc = f_ext * w[..., None]
        acc[..., 2] -= self.g
        vel = np.where(w[..., None] > 0, v / (1.0 + self.damping[..., None] * dt) + dt * acc, 0.0)
        xt = x + dt * vel
        X = np.where(w[..., None] > 0, x + dt * v, xt)  # the kernel's warm start: the velocity carried over
        m_dt2 = np.where(w > 0, 1.0 / np.where(w > 0, w, 1.0) / dt**2, 1.0)
        for _ in range(self.newton):
            g, H = self._elastic(X, xt, angle, m_dt2)
            X = X + np.linalg.solve(H, -g.reshape(self.W, 3 * self.V, 1))[..., 0].reshape(self.W, self.V, 3)
        psi = crease.dihedral_angles(X, self.hinges)
        angle = angle + (psi - angle + np.pi) % (2 * np.pi) - np.pi
        return X, (X - x) / dt, angle

    def _update_contacts(self, X, x_prev, vel, g, m_dt2, released) -> bool:
        """Between Newton steps (``g``: the gradient without friction): the floor's normal force n·g; a contact the
        floor would have to pull lets go (once per substep); stick / slip; a free vertex the last step put below the
        floor lands. Returns whether one landed (X moved)."""
        dt, cont, ff = self.dt, self.contact, self.floor_force
        landed = False
        for wi in range(self.W):
            n = self.n[wi]
            for i in range(self.V):
                st = cont[wi, i]
                if st == self.FIXED:
                    continue
                u = (X[wi, i] - x_prev[wi, i]) / dt
                un = u @ n
                if st == self.FREE:
                    depth = -(x_prev[wi, i] @ n + dt * un)
                    if depth > 0.0:
                        X[wi, i] = x_prev[wi, i] + (u + n * (depth / dt)) * dt
                        cont[wi, i] = self.STUCK
                        ff[wi, i] = n * (depth * m_dt2[wi, i])
                        landed = True
                    continue
                fn = g[wi, i] @ n  # friction is tangential: not in the normal balance
                if not fn > 0.0:
                    if released[wi, i] & 1 == 0:
                        cont[wi, i] = self.FREE
                        ff[wi, i] = 0.0
                        released[wi, i] |= 1
                        continue
                    fn = 0.0  # let go once already: held without normal force
                vt = u - n * un
                vt_len = np.linalg.norm(vt)
                new = st
                if st == self.STUCK and vt_len * (ff[wi, i] @ n) > self.slip * fn:
                    new = self.SLIDING
                elif st == self.SLIDING and (vt @ ff[wi, i] > 0.0 or vt_len < 0.5 * self.slip):
                    new = self.STUCK
                if new != st:
                    if released[wi, i] // 2 >= 6:  # MAX_STICK_SLIP_SWITCHES: held for the rest of the substep
                        new = self.STUCK
                    else:
                        released[wi, i] += 2
                cont[wi, i] = new
                ff[wi, i] = n * fn + self._friction(wi, new, vt, fn)[0]
        return landed
