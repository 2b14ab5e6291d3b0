"""Batched worm model (shared topology, per-world parameters) and simulation state, as Warp arrays.

:class:`Model` holds what does not change during a simulation: the crease pattern's topology (shared by every
world), the per-world rest geometry (a, b, l0 may differ per world), masses, material, floor, magnet and EPM-path
parameters. :class:`State` holds what does: positions, velocities, magnet poses and the outputs of the last substep.

Array conventions: every per-world array has the world as its first axis; a per-world parameter is stored either
with one row (shared by all worlds) or ``num_worlds`` rows, and kernels read row ``world % rows``. float32 on the
device, SI units (m, kg, s, N, rad). Build with :meth:`Model.from_params`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from . import crease, gaits
from .params import MAGNET_MODELS, WormParams, per_world
from .ids import SHAPE_CUBOID, SHAPE_CYLINDER
from .transforms import axis_angle_to_matrix, matrix_to_quat_wxyz, quat_wxyz_to_xyzw


def _scalar_param(value, num_worlds: int, name: str) -> np.ndarray:
    """Shared scalar -> (1,), per-world -> (W,), float32."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return arr.reshape(1).astype(np.float32)
    if arr.shape == (num_worlds,):
        return arr.astype(np.float32)
    raise ValueError(f"WormParams.{name}: expected a scalar or shape ({num_worlds},), got {arr.shape}")


def vertex_bandwidth(edges: np.ndarray, hinges: np.ndarray) -> int:
    """Half-bandwidth, in 3×3 vertex blocks, of the implicit solver's Newton matrix (kernels/band_cholesky.py): every
    bar and crease couples the vertices it touches, so it is the largest vertex-index span of an element."""
    return max(int(np.ptp(np.asarray(edges), axis=1).max(initial=0)),
               int(np.ptp(np.asarray(hinges), axis=1).max(initial=0)))


def _is_shared(*values) -> bool:
    return all(np.asarray(v).ndim == 0 for v in values)


@dataclass
class State:
    """Per-world simulation state (all arrays on the model's device, first axis = world)."""

    positions: wp.array
    """Vertex positions [m], shape (W, V), vec3."""
    velocities: wp.array
    """Vertex velocities [m/s], shape (W, V), vec3."""
    prev_positions: wp.array
    """Positions at the start of the current substep [m], shape (W, V), vec3 (solver scratch)."""
    delta: wp.array
    """x − x̃ of the current substep (position minus its prediction) [m], shape (W, V), vec3 (solver scratch, zero
    between substeps)."""
    external_force: wp.array
    """External (magnetic) force on each vertex [N], shape (W, V), vec3; refreshed once per step."""
    magnet_pos: wp.array
    """Magnet centres [m], shape (W, 4), vec3; slots 0 EPM, 1 tail, 2 centre, 3 head IPM."""
    magnet_rot: wp.array
    """Magnet orientations (magnet -> world), shape (W, 4), ``wp.quat`` (x, y, z, w)."""
    magnet_force: wp.array
    """Net magnetic force on each magnet [N], shape (W, 4), vec3 (from the last wrench evaluation)."""
    magnet_torque: wp.array
    """Net magnetic torque on each magnet about its centre [N·m], shape (W, 4), vec3."""
    crease_angle: wp.array
    """Signed fold angle of every hinge [rad], shape (W, H), float; unwrapped (continuous through ±π)."""
    bar_strain: wp.array
    """Cauchy strain (L − L0) / L0 of every bar at the last substep, shape (W, E), float."""
    contact: wp.array
    """1 where a vertex touched the floor in the last substep, shape (W, V), int32."""
    unstable: wp.array
    """Non-zero for a world flagged unstable (frozen from then on): 1 exploded (strain, speed, non-finite), 2 crumpled
    (a crease folded through its range), shape (W,), int32."""
    step_count: wp.array
    """Substeps taken by each world since t = 0, shape (W,), int32 (time = step_count · dt_sub, exact)."""
    anchor_target: wp.array
    """Anchor target points [m], shape (W, A), vec3 (A may be 0)."""
    floor_force: wp.array
    """Force of the floor on each vertex in the last substep (normal + friction) [N], shape (W, V), vec3 (implicit
    solver; zero off the floor)."""
    newton_matrix: wp.array
    """Lower block band of the Newton matrix, shape (W, V, B + 1), mat33 (implicit solver scratch)."""
    newton_rhs: wp.array
    """Newton right-hand side, then step, shape (W, V), vec3 (implicit solver scratch)."""


class Model:
    """Shared topology and per-world parameters of a batch of worm worlds.

    Attributes are Warp arrays on ``device`` unless noted; "(R, ...)" means R = 1 (shared) or W rows.
    """

    def __init__(self):
        raise TypeError("use Model.from_params(params, num_worlds, device)")

    # ------------------------------------------------------------------------------------------------------------
    @classmethod
    def from_params(
        cls,
        params: WormParams | None = None,
        num_worlds: int = 1,
        device=None,
        *,
        anchors=None,
        anchor_stiffness=1.0e4,
        place: str = "floor",
    ) -> "Model":
        """Build the model of ``num_worlds`` worms from :class:`~warpworm.params.WormParams`.

        Args:
            params: per-world parameters (scalars are shared, arrays (W,) per world); default ``WormParams()``.
            num_worlds: W.
            device: Warp device ("cpu", "cuda:0", ...; default Warp's default device).
            anchors: vertex indices (A,) pinned to a target by a spring (force plate); default none.
            anchor_stiffness: anchor strength [N/m], scalar, (A,) or (W, A).
            place: "floor" puts the worm's bottom face on the (possibly inclined) floor at x = 0 for the tail.
        """
        self = object.__new__(cls)
        p = WormParams() if params is None else params
        W = int(num_worlds)
        if W < 1:
            raise ValueError("num_worlds must be >= 1")
        if p.magnet_model not in MAGNET_MODELS:
            raise ValueError(f"magnet_model must be one of {MAGNET_MODELS}, got {p.magnet_model!r}")
        self.params = p
        self.num_worlds = W
        self.device = wp.get_device(device)
        dev = self.device
        n = int(p.n_units)

        # --- geometry: one topology, per-world rest shapes -----------------------------------------------------
        # Arrays that depend only on shared parameters keep one row; otherwise one row per world.
        a = per_world(p.a, W)
        b = per_world(p.b, W)
        l0 = per_world(p.l0, W)
        alpha = np.atleast_1d(crease.rest_alpha(l0, b, n))
        rows = 1 if _is_shared(p.a, p.b, p.l0) else W
        self.pattern = crease.build_worm(float(a[0]), float(b[0]), n, alpha=float(alpha[0]))
        """The crease pattern of world 0 (host, float64): topology, labels, mounts, keypoints."""
        pat = self.pattern
        # The built rest state is exactly at rest: its rest angles are its measured dihedrals (the transverse creases
        # +-alpha, the prism's corner creases their built angle, the diagonals 0).
        x_rest, rest_len, rest_angle = crease.worm_rest_state(a[:rows], b[:rows], alpha[:rows], n, pattern=pat)
        hinge_len = crease.edge_lengths(x_rest, pat.edges)[:, pat.hinge_edge]
        incline = per_world(p.floor_incline, W)
        # Lay the worm on its (tilted) floor: rotate about +y by -beta; the floor plane passes through the origin.
        R_floor = axis_angle_to_matrix([0.0, 1.0, 0.0], -incline)  # (W, 3, 3)
        x_w = np.broadcast_to(x_rest, (W,) + x_rest.shape[1:])
        self.rest_positions_host = np.einsum("wij,wvj->wvi", R_floor, x_w)
        """Initial vertex positions [m], host float64, shape (W, V, 3) (rest shape laid on each world's floor)."""

        V, E, H = pat.num_vertices, pat.num_edges, pat.num_hinges
        self.num_vertices, self.num_edges, self.num_hinges = V, E, H

        # --- masses: lumped sheet mass + IPM mass on the mount vertices -----------------------------------------
        mrows = 1 if (rows == 1 and _is_shared(p.sheet_density, p.ipm_diameter, p.ipm_thickness,
                                                 p.magnet_mass_density)) else W
        xm = x_w[:mrows]
        tri = pat.triangles
        area = 0.5 * np.linalg.norm(
            np.cross(xm[:, tri[:, 1]] - xm[:, tri[:, 0]], xm[:, tri[:, 2]] - xm[:, tri[:, 0]]), axis=-1
        )  # (mrows, T)
        rho_sheet = per_world(p.sheet_density, W)[:mrows]
        mass = np.zeros((mrows, V))
        for c in range(3):  # lumped: a third of each facet's mass on each of its corners
            np.add.at(mass, (slice(None), tri[:, c]), (rho_sheet[:, None] * area) / 3.0)
        self.sheet_mass_host = mass.sum(axis=1)
        """Sheet mass of each mass row [kg], host, shape (R,)."""
        ipm_d = per_world(p.ipm_diameter, W)
        ipm_h = per_world(p.ipm_thickness, W)
        ipm_mass = per_world(p.magnet_mass_density, W) * np.pi * (0.5 * ipm_d) ** 2 * ipm_h  # (W,)
        self.ipm_mass_host = ipm_mass
        """Mass of one IPM [kg], host, shape (W,)."""
        # The IPM mass goes on its mount vertices with least-norm weights that keep the total mass and the centre of
        # mass (so gravity's moment on the mount is exact); docs/dynamics.md discusses the inertia this implies.
        mv = pat.mount_vertices
        mpos_rest, _ = crease.mount_poses(pat, xm)  # (mrows, 3, 3)
        # least-norm weights w (K,) with sum(w) = 1 and sum(w x_k) = mount centre: a batched 4 x K pseudo-inverse over
        # (row, mount), no loop over worlds
        pts = xm[:, mv]  # (mrows, M, K, 3)
        Amat = np.concatenate([np.ones(pts.shape[:-1])[..., None, :], np.swapaxes(pts, -1, -2)], axis=-2)
        rhs = np.concatenate([np.ones(mpos_rest.shape[:-1] + (1,)), mpos_rest], axis=-1)  # (mrows, M, 4)
        wgt = np.einsum("...kj,...j->...k", np.linalg.pinv(Amat), rhs)  # (mrows, M, K)
        negative = np.any(wgt < -1e-9, axis=-1, keepdims=True)
        wgt = np.where(negative, 1.0 / mv.shape[1], wgt)
        np.add.at(mass, (np.arange(mrows)[:, None, None], mv[None]), ipm_mass[:mrows, None, None] * wgt)
        self.vertex_mass_host = mass
        """Lumped vertex masses [kg], host float64, shape (R, V)."""

        # --- topology arrays (shared) ---------------------------------------------------------------------------
        A_idx = np.zeros(0, np.int32) if anchors is None else np.asarray(anchors, np.int32).reshape(-1)
        A = len(A_idx)
        self.num_anchors = A
        self.edges = wp.array(pat.edges, dtype=wp.int32, device=dev)
        """Bar vertex pairs, shape (E, 2), int32."""
        self.vertex_bandwidth = vertex_bandwidth(pat.edges, pat.hinges)
        """Half-bandwidth in vertex blocks of the implicit solver's Newton matrix (6 for the default worm)."""
        self.hinges = wp.array(pat.hinges, dtype=wp.int32, device=dev)
        """Hinge stencils (i, j, k, l), shared edge j-k, shape (H, 4), int32."""
        self.hinge_label = wp.array(pat.hinge_label.astype(np.int32), dtype=wp.int32, device=dev)
        """Hinge labels (0 flat, 1 mountain, 2 valley), shape (H,), int32; sets the NoFoldThrough range."""

        self.mount_vertices = wp.array(mv, dtype=wp.int32, device=dev)
        """IPM mount vertices (tail, centre, head), shape (3, K), int32."""
        self.mount_local_pos = wp.array(pat.mount_local_pos[None], dtype=wp.vec3, device=dev)
        """IPM centre in its mount frame [m], shape (1, 3), vec3."""
        self.mount_local_rot = wp.array(pat.mount_local_rot[None], dtype=wp.mat33, device=dev)
        """IPM orientation in its mount frame, shape (1, 3), mat33 (magnet -> frame)."""
        self.anchor_vertex = wp.array(A_idx, dtype=wp.int32, device=dev)
        """Anchored vertices, shape (A,), int32."""
        ak = np.asarray(anchor_stiffness, dtype=np.float64)
        ak = np.broadcast_to(ak, (A,)).reshape(1, A) if ak.ndim <= 1 else ak.reshape(-1, A)
        self.anchor_stiffness = wp.array(ak.astype(np.float32), dtype=float, device=dev)
        """Anchor strength [N/m], shape (R, A), float."""

        # --- per-world geometry arrays ---------------------------------------------------------------------------
        self.rest_length = wp.array(rest_len.astype(np.float32), dtype=float, device=dev)
        """Bar rest lengths [m], shape (R, E), float."""
        self.hinge_rest_angle = wp.array(rest_angle.astype(np.float32), dtype=float, device=dev)
        """Hinge rest fold angles [rad], shape (R, H), float (+alpha valley, -alpha mountain, corners their built
        angle, 0 flat)."""
        self.hinge_rest_angle_host = rest_angle
        self.hinge_length = wp.array(hinge_len.astype(np.float32), dtype=float, device=dev)
        """Crease lengths [m], shape (R, H), float: a hinge's stiffness is k_alpha times this."""
        with np.errstate(divide="ignore"):
            inv_mass = np.where(mass > 0, 1.0 / mass, 0.0)
        self.inv_mass = wp.array(inv_mass.astype(np.float32), dtype=float, device=dev)
        """Inverse lumped vertex masses [1/kg], shape (R, V), float."""

        # --- per-world material / floor parameters (R, ) --------------------------------------------------------
        def sp(name):
            return wp.array(_scalar_param(getattr(p, name), W, name), dtype=float, device=dev)

        # Per-bar rigidity: the valley rings get their own (soft) EA so the isostatic tube can fold (docs/crease.md).
        ea_rigid = _scalar_param(p.bar_stiffness, W, "bar_stiffness")
        ea_valley = _scalar_param(p.valley_bar_stiffness, W, "valley_bar_stiffness")
        is_valley = pat.edge_label == crease.VALLEY
        ea = np.where(is_valley[None, :], ea_valley[:, None], ea_rigid[:, None])
        self.bar_stiffness = wp.array(ea.astype(np.float32), dtype=float, device=dev)
        """Axial rigidity EA of each bar [N], shape (R, E), float (valley-ring bars: ``valley_bar_stiffness``)."""
        stop_c = _scalar_param(p.waist_close_strain, W, "waist_close_strain")
        stop_t = _scalar_param(p.waist_stop_strain, W, "waist_stop_strain")
        rows_s = max(len(stop_c), len(stop_t))
        stop = np.full((rows_s, len(is_valley), 2), 1e3)
        stop[:, is_valley, 0] = np.broadcast_to(stop_c, (rows_s,))[:, None]
        stop[:, is_valley, 1] = np.broadcast_to(stop_t, (rows_s,))[:, None]
        self.bar_stop_strain = wp.array(stop.astype(np.float32), dtype=wp.vec2, device=dev)
        """Strain magnitudes (shortened, stretched) beyond which a bar meets its stops, shape (R, E), vec2:
        (``waist_close_strain``, ``waist_stop_strain``) for the waist (VALLEY) bars, none (1e3) for the others."""
        self.bar_stop_stiffness = wp.array(np.where(is_valley[None, :], ea_rigid[:, None], 0.0).astype(np.float32),
                                           dtype=float, device=dev)
        """Axial rigidity of the stop [N], shape (R, E), float: the rigid bars' EA on the waist bars, 0 elsewhere."""
        self.hinge_stiffness = sp("hinge_stiffness")
        """Crease stiffness k_alpha per metre of crease [N·m/rad/m], shape (R,)."""
        self.hinge_damping = sp("hinge_damping")
        """Crease damping per metre of crease [N·m·s/rad/m], shape (R,)."""
        self.fold_limit_stiffness = sp("fold_limit_stiffness")
        """NoFoldThrough barrier stiffness per metre of crease [N·m/rad/m], shape (R,): independent of k_alpha."""
        self.damping = sp("damping")
        """Linear velocity damping rate [1/s], shape (R,)."""
        self.mu_static = sp("mu_static")
        """Static friction coefficient, shape (R,)."""
        self.mu_kinetic = sp("mu_kinetic")
        """Kinetic friction coefficient, shape (R,)."""
        self.floor_incline = sp("floor_incline")
        """Floor slope about +y [rad], shape (R,)."""
        self.gravity = sp("gravity")
        """Gravitational acceleration along -z [m/s²], shape (R,)."""

        # --- magnets -------------------------------------------------------------------------------------------
        self.magnet_model_name = p.magnet_model
        self.magnet_model = wp.array(np.array([MAGNET_MODELS.index(p.magnet_model)], np.int32), dtype=wp.int32,
                                     device=dev)
        """Magnet model id (0 dipoles, 1 analytic), shape (1,), int32."""
        self.magnet_shape = wp.array(np.array([[SHAPE_CUBOID, SHAPE_CYLINDER, SHAPE_CYLINDER, SHAPE_CYLINDER]],
                                              np.int32), dtype=wp.int32, device=dev)
        """Magnet shapes (0 cuboid, 1 cylinder), shape (1, 4), int32."""
        size = np.zeros((W, 4, 3))
        size[:, 0] = per_world(p.epm_size, W, (3,))
        size[:, 1:, 0] = ipm_d[:, None]
        size[:, 1:, 1] = ipm_d[:, None]
        size[:, 1:, 2] = ipm_h[:, None]
        moment = np.zeros((W, 4, 3))
        moment[:, 0, 2] = per_world(p.epm_moment, W)
        moment[:, 1:, 2] = per_world(p.ipm_moment, W, (3,))
        self.magnet_size_host = size
        self.magnet_moment_host = moment
        self.magnet_size = wp.array(size.astype(np.float32), dtype=wp.vec3, device=dev)
        """Magnet sizes [m], shape (W, 4), vec3: cuboid extents or cylinder (d, d, h), magnet frame."""
        self.magnet_moment = wp.array(moment.astype(np.float32), dtype=wp.vec3, device=dev)
        """Magnet dipole moments in the magnet frame (along its own +z) [A·m²], shape (W, 4), vec3."""
        moment_parked = moment.copy()
        moment_parked[:, 0] = 0.0
        self.magnet_moment_parked = wp.array(moment_parked.astype(np.float32), dtype=wp.vec3, device=dev)
        """As ``magnet_moment`` with the EPM absent (used while settling), shape (W, 4), vec3."""
        self.dipole_density = sp("dipole_density")
        """Dipoles per m³ of the 'dipoles' model, shape (R,)."""

        # --- EPM path -------------------------------------------------------------------------------------------
        mpos_all, _ = crease.mount_poses(pat, x_w)
        mpos_world = np.einsum("wij,wmj->wmi", R_floor, mpos_all)
        self.ipm_rest_pos_host = mpos_world
        """IPM centres at rest [m], host, shape (W, 3, 3) (tail, centre, head)."""
        self.set_path(gaits.sine_path(p, mpos_world[:, :, 0], num_worlds=W))
        return self

    # ------------------------------------------------------------------------------------------------------------
    def set_path(self, path: "gaits.EpmPath") -> None:
        """Set the EPM path (sinusoidal or keyframed) of every world; takes effect at the next step."""
        dev = self.device
        self.path = path
        if path.kind == "sine":
            def arr(v):
                return wp.array(np.asarray(v, np.float32).reshape(-1), dtype=float, device=dev)

            self.path_arrays = [arr(getattr(path, f)) for f in gaits.SINE_FIELDS]
        elif path.kind == "keyframes":
            kt = np.asarray(path.key_time, np.float32).reshape(-1)
            kp = np.asarray(path.key_pos, np.float64)
            kr = np.asarray(path.key_rot, np.float64)
            if kp.ndim == 2:
                kp, kr = kp[None], kr[None]
            q = quat_wxyz_to_xyzw(matrix_to_quat_wxyz(kr))
            self.path_arrays = [
                wp.array(kt, dtype=float, device=dev),
                wp.array(kp.astype(np.float32), dtype=wp.vec3, device=dev),
                wp.array(q.astype(np.float32), dtype=wp.quat, device=dev),
            ]
        else:
            raise ValueError(f"unknown path kind {path.kind!r}")

    # ------------------------------------------------------------------------------------------------------------
    def state(self) -> State:
        """A fresh state: every world at its rest shape on the floor, at rest, t = 0."""
        W, V, E, H, A = self.num_worlds, self.num_vertices, self.num_edges, self.num_hinges, self.num_anchors
        dev = self.device
        x0 = self.rest_positions_host.astype(np.float32)
        angles = np.broadcast_to(self.hinge_rest_angle_host, (W, H)).astype(np.float32)
        targets = x0[:, self.anchor_vertex.numpy()] if A else np.zeros((W, 0, 3), np.float32)

        def z(shape, dtype):
            return wp.zeros(shape, dtype=dtype, device=dev)

        return State(
            positions=wp.array(x0, dtype=wp.vec3, device=dev),
            velocities=z((W, V), wp.vec3),
            prev_positions=wp.array(x0, dtype=wp.vec3, device=dev),
            delta=z((W, V), wp.vec3),
            external_force=z((W, V), wp.vec3),
            magnet_pos=z((W, 4), wp.vec3),
            magnet_rot=wp.array(np.tile(np.array([0, 0, 0, 1], np.float32), (W, 4, 1)), dtype=wp.quat, device=dev),
            magnet_force=z((W, 4), wp.vec3),
            magnet_torque=z((W, 4), wp.vec3),
            crease_angle=wp.array(angles, dtype=float, device=dev),
            bar_strain=z((W, E), float),
            contact=z((W, V), wp.int32),
            unstable=z((W,), wp.int32),
            step_count=z((W,), wp.int32),
            anchor_target=wp.array(targets.reshape(W, A, 3), dtype=wp.vec3, device=dev),
            floor_force=z((W, V), wp.vec3),
            newton_matrix=z((W, V, self.vertex_bandwidth + 1), wp.mat33),
            newton_rhs=z((W, V), wp.vec3),
        )

    def bytes_per_world(self) -> int:
        """Device bytes of one world's state and per-world model arrays (shared topology excluded)."""
        s = self.state()
        total = sum(getattr(s, f).capacity for f in State.__dataclass_fields__)
        per = [self.rest_length, self.hinge_rest_angle, self.hinge_length, self.inv_mass, self.magnet_size,
               self.magnet_moment]
        total += sum(a.capacity * self.num_worlds // a.shape[0] for a in per)
        return int(total // self.num_worlds)
