"""The substeps of :mod:`warpworm.kernels.xpbd` (Jacobi, :class:`NumpySubstep`), :mod:`warpworm.kernels.xpbd_gs`
(Gauss–Seidel, :class:`NumpyGaussSeidel`) and :mod:`warpworm.kernels.implicit_euler` (:class:`NumpyImplicit`) written
in NumPy, vectorized over worlds: the benchmark's reference and a cross-check of the kernels (same math, float64).

One Jacobi substep = predict (gravity, external force, damping) -> one Jacobi pass over bars and hinges with mass
splitting -> apply corrections, floor contact and friction in velocity space. Anchors and the stability check are
left out (the benchmark uses neither). Usage::

    ref = NumpySubstep(model, dt_sub, split_hinge=sim.split_hinge.numpy())
    x, v, angle = ref.init(state)              # NumPy copies (W, V, 3), (W, V, 3), (W, H)
    x, v, angle = ref.substep(x, v, angle, f_ext)
"""

from __future__ import annotations

import numpy as np


class NumpySubstep:
    def __init__(self, model, dt_sub: float, split_hinge: np.ndarray | None = None):
        p = model.pattern
        self.W, self.V = model.num_worlds, model.num_vertices
        self.dt = float(dt_sub)
        self.edges = p.edges.astype(np.int64)
        self.hinges = p.hinges.astype(np.int64)
        self.label = p.hinge_label.astype(np.int64)
        self.split = model.split.numpy().astype(np.float64)
        sh = model.hinge_split(dt_sub) if split_hinge is None else split_hinge
        self.split_hinge = np.broadcast_to(np.asarray(sh, np.float64), (self.W, self.V))

        def rows(a, inner=()):
            a = np.asarray(a, np.float64)
            return np.broadcast_to(a.reshape((a.shape[0],) + a.shape[1:]), (self.W,) + a.shape[1:])

        self.w = rows(model.inv_mass.numpy())
        self.L0 = rows(model.rest_length.numpy())
        self.rest = rows(model.hinge_rest_angle.numpy())
        self.hlen = rows(model.hinge_length.numpy())

        def col(a):
            return np.broadcast_to(np.asarray(a.numpy(), np.float64), (self.W,))[:, None]

        self.EA = rows(model.bar_stiffness.numpy())
        self.k, self.c_h = col(model.hinge_stiffness), col(model.hinge_damping)
        self.damping, self.g = col(model.damping), col(model.gravity)
        self.mu_s, self.mu_k, self.beta = col(model.mu_static), col(model.mu_kinetic), col(model.floor_incline)
        lo = np.full(len(self.label), -np.pi)
        hi = np.full(len(self.label), np.pi)
        hi[self.label == 1] = 0.0
        lo[self.label == 2] = 0.0
        self.lo, self.hi = lo, hi
        self._flat = (np.arange(self.W)[:, None] * self.V)

    def init(self, state):
        return (state.positions.numpy().astype(np.float64).copy(), state.velocities.numpy().astype(np.float64).copy(),
                state.crease_angle.numpy().astype(np.float64).copy())

    def _scatter(self, idx: np.ndarray, val: np.ndarray) -> np.ndarray:
        """Sum val (W, n, 3) into vertices idx (n,) of each world -> (W, V, 3) (bincount: fast add.at)."""
        flat = (self._flat + idx[None, :]).ravel()
        out = np.empty((self.W * self.V, 3))
        for c in range(3):
            out[:, c] = np.bincount(flat, weights=val[..., c].ravel(), minlength=self.W * self.V)
        return out.reshape(self.W, self.V, 3)

    def substep(self, x, v, angle, f_ext):
        dt, w = self.dt, self.w
        # 1. predict
        acc = f_ext * w[..., None]
        acc[..., 2] -= self.g
        v = np.where(w[..., None] > 0, (v + dt * acc) / (1.0 + self.damping[..., None] * dt), 0.0)
        x_prev = x
        x = x + dt * v
        # 2. bars
        a, b = self.edges[:, 0], self.edges[:, 1]
        d = x[:, a] - x[:, b]
        L = np.linalg.norm(d, axis=-1)
        C = L - self.L0
        denom = self.split[a] * w[:, a] + self.split[b] * w[:, b] + self.L0 / (self.EA * dt * dt)
        dl = -C / denom
        n = d / L[..., None]
        delta = self._scatter(a, n * (w[:, a] * dl)[..., None]) + self._scatter(b, -n * (w[:, b] * dl)[..., None])
        # 2b. hinges
        h = self.hinges
        xi, xj, xk, xl = (x[:, h[:, c]] for c in range(4))
        n1 = np.cross(xj - xi, xk - xi)
        n2 = np.cross(xk - xl, xj - xl)
        e = xj - xk
        e = e / np.linalg.norm(e, axis=-1, keepdims=True)
        raw = np.arctan2(np.einsum("whc,whc->wh", np.cross(n1, n2), e), np.einsum("whc,whc->wh", n1, n2))
        dphi = raw - angle
        phi = angle + (dphi - 2 * np.pi * np.floor((dphi + np.pi) / (2 * np.pi)))
        rkj = xk - xj
        L2 = np.einsum("whc,whc->wh", rkj, rkj)
        Lh = np.sqrt(L2)
        gi = (Lh / np.einsum("whc,whc->wh", n1, n1))[..., None] * n1
        gl = (Lh / np.einsum("whc,whc->wh", n2, n2))[..., None] * n2
        pi_ = (np.einsum("whc,whc->wh", xi - xj, rkj) / L2)[..., None]
        pl_ = (np.einsum("whc,whc->wh", xk - xl, rkj) / L2)[..., None]
        gj = (pi_ - 1.0) * gi - pl_ * gl
        gk = (pl_ - 1.0) * gl - pi_ * gi
        grads = (gi, gj, gk, gl)
        wv = [w[:, h[:, c]] for c in range(4)]
        g2 = [np.sum(g * g, axis=-1) for g in grads]
        sh = [np.take_along_axis(self.split_hinge, np.broadcast_to(h[:, c], (self.W, len(h))), 1) for c in range(4)]
        sb = [self.split[h[:, c]][None, :] for c in range(4)]
        kh = self.k * self.hlen
        alpha = 1.0 / (kh * dt * dt)
        gamma = self.c_h * self.hlen / (kh * dt)
        rate = sum(np.sum(g * (xc - x_prev[:, h[:, c]]), axis=-1) for c, (g, xc) in enumerate(zip(grads, (xi, xj, xk, xl))))
        wsum = sum(sh[c] * wv[c] * g2[c] for c in range(4))
        dl_spring = -((phi - self.rest) + gamma * rate) / ((1.0 + gamma) * wsum + alpha)
        outside = (phi < self.lo) | (phi > self.hi)
        bound = np.where(phi < self.lo, self.lo, self.hi)
        wlim = sum((sb[c] + sh[c]) * wv[c] * g2[c] for c in range(4))
        dl_h = np.where(outside, -(phi - bound) / wlim, dl_spring)
        for c in range(4):
            delta += self._scatter(h[:, c], grads[c] * (wv[c] * dl_h)[..., None])
        # 3. apply, contact, friction (velocity space), velocities
        p_new, v_new = self._floor_contact(x + delta, v + delta / dt, x_prev, dt)
        return p_new, v_new, phi

    def _floor_contact(self, p, vel, x_prev, dt):
        """Floor contact and position-level static / kinetic friction of ``kernels.xpbd.floor_contact``, in
        velocity space: positions p and velocities vel (W, V, 3) after the constraints -> (p, vel)."""
        nrm = np.stack([-np.sin(self.beta[:, 0]), np.zeros(self.W), np.cos(self.beta[:, 0])], -1)[:, None, :]
        depth = -np.sum(p * nrm, axis=-1, keepdims=True)
        touch = depth > 0
        p_c = p + nrm * depth
        vel_c = vel + nrm * (depth / dt)
        vn = np.sum(vel_c * nrm, axis=-1, keepdims=True)
        vt = vel_c - nrm * vn
        vt_len = np.linalg.norm(vt, axis=-1, keepdims=True)
        stick = vt_len * dt <= self.mu_s[..., None] * depth
        p_stick = x_prev + nrm * np.sum((p_c - x_prev) * nrm, axis=-1, keepdims=True)
        vel_slip = vel_c - vt * (self.mu_k[..., None] * depth / (dt * np.maximum(vt_len, 1e-30)))
        p_new = np.where(touch, np.where(stick, p_stick, x_prev + vel_slip * dt), p)
        v_new = np.where(touch, np.where(stick, nrm * vn, vel_slip), vel)
        return p_new, v_new


class NumpyGaussSeidel(NumpySubstep):
    """The Gauss–Seidel substep of :mod:`warpworm.kernels.xpbd_gs` in NumPy (float64): vectorized over worlds, a
    Python loop over the elements in the kernel's order (bars, hinges, anchors; ``iterations`` passes with
    accumulated multipliers), then floor contact and friction. The honest reference for the per-world kernel: a
    sequential sweep cannot be vectorized over elements without changing the method.

    ``x, v, angle = ref.substep(x, v, angle, f_ext)`` as :class:`NumpySubstep`.
    """

    def __init__(self, model, dt_sub: float, iterations: int = 1):
        super().__init__(model, dt_sub, split_hinge=np.ones((1, model.num_vertices)))
        self.iterations = int(iterations)
        self.anchor_vertex = model.anchor_vertex.numpy().astype(np.int64)
        A = len(self.anchor_vertex)
        self.anchor_k = np.broadcast_to(model.anchor_stiffness.numpy().astype(np.float64), (self.W, A))
        self.anchor_target = None  # (W, A, 3), set from the state in init()
        self._edges_l = [tuple(e) for e in self.edges.tolist()]
        self._hinges_l = [tuple(h) for h in self.hinges.tolist()]

    def init(self, state):
        self.anchor_target = state.anchor_target.numpy().astype(np.float64)
        return super().init(state)

    def substep(self, x, v, angle, f_ext):
        dt, w = self.dt, self.w
        W = self.W
        acc = f_ext * w[..., None]
        acc[..., 2] -= self.g
        v = np.where(w[..., None] > 0, (v + dt * acc) / (1.0 + self.damping[..., None] * dt), 0.0)
        x_prev = x
        x = x + dt * v
        delta = np.zeros_like(x)
        angle = angle.copy()
        ne, nh = len(self._edges_l), len(self._hinges_l)
        lam = np.zeros((W, ne + nh + len(self.anchor_vertex)))
        multi = self.iterations > 1
        k1, ch = self.k[:, 0], self.c_h[:, 0]
        for _ in range(self.iterations):
            for e, (a, b) in enumerate(self._edges_l):
                d = x[:, a] - x[:, b]
                L = np.sqrt(np.einsum("wc,wc->w", d, d))
                C = L - self.L0[:, e]
                alpha = self.L0[:, e] / self.EA[:, e] / (dt * dt)
                dl = -(C + alpha * lam[:, e]) / (w[:, a] + w[:, b] + alpha)
                if multi:
                    lam[:, e] += dl
                n = d * (dl / L)[:, None]
                ca, cb = n * w[:, a, None], -n * w[:, b, None]
                x[:, a] += ca
                x[:, b] += cb
                delta[:, a] += ca
                delta[:, b] += cb
            for h, (i, j, k, l) in enumerate(self._hinges_l):
                xi, xj, xk, xl = x[:, i], x[:, j], x[:, k], x[:, l]
                n1 = np.cross(xj - xi, xk - xi)
                n2 = np.cross(xk - xl, xj - xl)
                rkj = xk - xj
                L2 = np.einsum("wc,wc->w", rkj, rkj)
                Lh = np.sqrt(L2)
                psi = np.arctan2(-np.einsum("wc,wc->w", np.cross(n1, n2), rkj) / Lh, np.einsum("wc,wc->w", n1, n2))
                dphi = psi - angle[:, h]
                phi = angle[:, h] + (dphi - 2 * np.pi * np.floor((dphi + np.pi) / (2 * np.pi)))
                angle[:, h] = phi
                gi = (Lh / np.einsum("wc,wc->w", n1, n1))[:, None] * n1
                gl = (Lh / np.einsum("wc,wc->w", n2, n2))[:, None] * n2
                pi_ = (np.einsum("wc,wc->w", xi - xj, rkj) / L2)[:, None]
                pl_ = (np.einsum("wc,wc->w", xk - xl, rkj) / L2)[:, None]
                gj = (pi_ - 1.0) * gi - pl_ * gl
                gk = (pl_ - 1.0) * gl - pi_ * gi
                ws = [w[:, i], w[:, j], w[:, k], w[:, l]]
                gs = [gi, gj, gk, gl]
                wsum = sum(wc * np.einsum("wc,wc->w", g, g) for wc, g in zip(ws, gs))
                lo, hi = self.lo[h], self.hi[h]
                outside = (phi < lo) | (phi > hi)
                bound = np.where(phi < lo, lo, hi)
                kh = k1 * self.hlen[:, h]
                alpha = 1.0 / (kh * dt * dt)
                gamma = ch / (k1 * dt)
                rate = sum(np.einsum("wc,wc->w", g, xc - x_prev[:, vi])
                           for g, xc, vi in zip(gs, (xi, xj, xk, xl), (i, j, k, l)))
                dl_s = -((phi - self.rest[:, h]) + alpha * lam[:, ne + h] + gamma * rate) / ((1.0 + gamma) * wsum + alpha)
                dl = np.where(outside, -(phi - bound) / wsum, dl_s)
                if multi:
                    lam[:, ne + h] += np.where(outside, 0.0, dl_s)
                for vi, wc, g in zip((i, j, k, l), ws, gs):
                    c = g * (wc * dl)[:, None]
                    x[:, vi] += c
                    delta[:, vi] += c
            for an, pv in enumerate(self.anchor_vertex.tolist()):
                d = x[:, pv] - self.anchor_target[:, an]
                dist = np.linalg.norm(d, axis=-1)
                alpha = 1.0 / (self.anchor_k[:, an] * dt * dt)
                dl = -(dist + alpha * lam[:, ne + nh + an]) / (w[:, pv] + alpha)
                if multi:
                    lam[:, ne + nh + an] += dl
                c = d * (w[:, pv] * dl / np.maximum(dist, 1e-300))[:, None]
                x[:, pv] += c
                delta[:, pv] += c
        # contact and friction, velocities (in-place positions; velocity from the summed corrections)
        p_new, v_new = self._floor_contact(x, v + delta / dt, x_prev, dt)
        return p_new, v_new, angle


class NumpyImplicit(NumpySubstep):
    """The implicit-Euler substep of :mod:`warpworm.kernels.implicit_euler` in NumPy (float64), vectorized over
    worlds, for a worm off the floor (contact and friction left out: compare with no vertex touching it): predict
    x̃, then ``newton`` Gauss–Newton steps on ½|x − x̃|²_M/dt² + E(x) with a dense batched solve
    (``np.linalg.solve`` on (W, 3V, 3V); the kernel factors a block band), then v = v' + (x − x̃)/dt.
    E: bar springs (compressive geometric stiffness dropped), creases (spring, implicit damping, NoFoldThrough limit
    spring k_lim of ``model.fold_limit_stiffness``; curvature term dropped), anchors. The benchmark's reference and the kernel's
    cross-check.

    ``x, v, angle = ref.substep(x, v, angle, f_ext)`` as :class:`NumpySubstep`.
    """

    def __init__(self, model, dt_sub: float, newton: int = 3):
        super().__init__(model, dt_sub, split_hinge=np.ones((1, model.num_vertices)))
        self.newton = int(newton)
        E = model.num_edges
        self.stop_strain = np.broadcast_to(model.bar_stop_strain.numpy().astype(np.float64), (self.W, E))
        self.stop_k = np.broadcast_to(model.bar_stop_stiffness.numpy().astype(np.float64), (self.W, E))
        self.k_limit = np.broadcast_to(model.fold_limit_stiffness.numpy().astype(np.float64), (self.W,))
        self.anchor_vertex = model.anchor_vertex.numpy().astype(np.int64)
        A = len(self.anchor_vertex)
        self.anchor_k = np.broadcast_to(model.anchor_stiffness.numpy().astype(np.float64), (self.W, A))
        self.anchor_target = None

    def init(self, state):
        self.anchor_target = state.anchor_target.numpy().astype(np.float64)
        return super().init(state)

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

    def substep(self, x, v, angle, f_ext):
        from warpworm import crease

        dt, w, W, V = self.dt, self.w, self.W, self.V
        acc = f_ext * w[..., None]
        acc[..., 2] -= self.g
        v_pred = np.where(w[..., None] > 0, (v + dt * acc) / (1.0 + self.damping[..., None] * dt), 0.0)
        xt = x + dt * v_pred
        X = xt.copy()
        m_dt2 = np.where(w > 0, 1.0 / np.maximum(w, 1e-300), 0.0) / dt**2  # (W, V)
        e = self.edges
        h = self.hinges
        eye = np.eye(3)
        k1, ch = self.k[:, 0], self.c_h[:, 0]
        for _ in range(self.newton):
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
            l_stop = self.L0 * (1.0 + np.where(strain < 0, -self.stop_strain, self.stop_strain))
            ks = np.where(np.abs(strain) > self.stop_strain, self.stop_k / self.L0, 0.0)
            f = f + n * (ks * (L - l_stop))[..., None]
            np.add.at(g, (slice(None), e[:, 0]), f)
            np.add.at(g, (slice(None), e[:, 1]), -f)
            nn = n[..., :, None] * n[..., None, :]
            kb = (ka + ks)[..., None, None] * nn + (ka * np.maximum(0.0, 1.0 - self.L0 / L))[..., None, None] * (eye - nn)
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
            X = X + np.linalg.solve(H, -g.reshape(W, 3 * V, 1))[..., 0].reshape(W, V, 3)
        psi = crease.dihedral_angles(X, h)
        angle = angle + (psi - angle + np.pi) % (2 * np.pi) - np.pi
        return X, v_pred + (X - xt) / dt, angle
