"""The implicit-Euler substep of :mod:`warpworm.kernels.implicit_euler` written in NumPy (float64), vectorized over
worlds: the benchmark's reference and a cross-check of the kernel (same math, dense solve). Usage::

    ref = NumpyImplicit(model, dt_sub, newton=sim.newton)
    x, v, angle = ref.init(state)              # NumPy copies (W, V, 3), (W, V, 3), (W, H)
    x, v, angle = ref.substep(x, v, angle, f_ext)
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

    def __init__(self, model, dt_sub: float, newton: int = 3):
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

    def init(self, state, control=None):
        """The reference's start from a Warp ``state`` (and the anchor targets of ``control``, if any)."""
        self.anchor_target = None if control is None else control.anchor_target.numpy().astype(np.float64)
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

    def substep(self, x, v, angle, f_ext):
        from warpworm.physics import crease

        dt, w, W, V = self.dt, self.w, self.W, self.V
        acc = f_ext * w[..., None]
        acc[..., 2] -= self.g
        v_pred = np.where(w[..., None] > 0, (v + dt * acc) / (1.0 + self.damping[..., None] * dt), 0.0)
        xt = x + dt * v_pred
        # the kernel's warm start (implicit_euler.newton_start): a free vertex starts from the velocity it carries
        X = np.where(w[..., None] > 0, x + dt * v, xt)
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
            X = X + np.linalg.solve(H, -g.reshape(W, 3 * V, 1))[..., 0].reshape(W, V, 3)
        psi = crease.dihedral_angles(X, h)
        angle = angle + (psi - angle + np.pi) % (2 * np.pi) - np.pi
        return X, v_pred + (X - xt) / dt, angle
