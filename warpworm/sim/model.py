"""Batched worm model (shared topology, per-world parameters), its state and its control inputs, as Warp arrays.

As in Newton (``sim/{builder,model,state,control}.py``) and mujoco_warp (``put_model`` / ``make_data``):

- :class:`ModelBuilder` assembles, on the host, the crease pattern's topology (shared by every world), the per-world
  rest geometry (a, b, l0 may differ per world), masses, material, floor, magnets and the default EPM path, and
  ends in :meth:`ModelBuilder.finalize` (device arrays);
- :class:`Model` holds what does not change during a simulation; it is immutable once built;
- :class:`State` holds what does: positions, velocities, contacts, magnet poses and wrenches, crease angles, the
  outputs of the last substep (physical state only; the solver's scratch belongs to the solver);
- :class:`Control` holds the inputs a run may change: the EPM path and the anchor targets.

Array conventions: every per-world array has the world as its first axis; a per-world parameter is stored either
with one row (shared by all worlds) or ``num_worlds`` rows, and kernels read row ``world % rows``. float32 on the
device, SI units (m, kg, s, N, rad). Build with :meth:`Model.from_params` (= ``ModelBuilder(...).finalize``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpworm.ids import SHAPE_CUBOID, SHAPE_CYLINDER
from warpworm.kernels import magnet_pose
from warpworm.physics import crease, gaits
from warpworm.physics.param_specs import check_worm_params
from warpworm.physics.params import MAGNET_MODELS, WormParams, per_world
from warpworm.transforms import axis_angle_to_matrix, matrix_to_quat_wxyz, quat_wxyz_to_xyzw


def _scalar_param(value, num_worlds: int, name: str) -> np.ndarray:
    """Shared scalar -> (1,), per-world -> (W,), float32."""
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim == 0:
        return arr.reshape(1).astype(np.float32)
    if arr.shape == (num_worlds,):
        return arr.astype(np.float32)
    raise ValueError(f"WormParams.{name}: expected a scalar or shape ({num_worlds},), got {arr.shape}")


def half_bandwidth(edges: np.ndarray, hinges: np.ndarray) -> int:
    """Half-bandwidth, in 3×3 vertex blocks, of the implicit solver's Newton matrix (kernels/banded_cholesky.py): every
    bar and crease couples the vertices it touches, so it is the largest vertex-index span of an element."""
    return max(int(np.ptp(np.asarray(edges), axis=1).max(initial=0)),
               int(np.ptp(np.asarray(hinges), axis=1).max(initial=0)))


def _is_shared(*values) -> bool:
    return all(np.asarray(v).ndim == 0 for v in values)


@dataclass
class State:
    """Per-world physical state (all arrays on the model's device, first axis = world)."""

    positions: wp.array
    """Vertex positions [m], shape (W, V), vec3."""
    velocities: wp.array
    """Vertex velocities [m/s], shape (W, V), vec3."""
    external_force: wp.array
    """Magnetic force on each vertex (the IPMs' wrenches distributed on their mounts) [N], shape (W, V), vec3;
    refreshed once per step."""
    magnet_pos: wp.array
    """Magnet centres [m], shape (W, 4), vec3; slots 0 EPM, 1 tail, 2 centre, 3 head IPM."""
    magnet_rot: wp.array
    """Magnet orientations (magnet -> world), shape (W, 4), ``wp.quat`` (x, y, z, w)."""
    magnet_force: wp.array
    """Net magnetic force on each magnet [N], shape (W, 4), vec3 (from the last wrench evaluation; the dynamics
    skips the EPM's own, slot 0, which stays zero)."""
    magnet_torque: wp.array
    """Net magnetic torque on each magnet about its centre [N·m], shape (W, 4), vec3."""
    crease_angle: wp.array
    """Signed fold angle of every hinge [rad], shape (W, H), float; unwrapped (continuous through ±π)."""
    bar_strain: wp.array
    """Cauchy strain (L − L0) / L0 of every bar at the last substep, shape (W, E), float."""
    contact: wp.array
    """1 where a vertex touched the floor in the last substep, shape (W, V), int32."""
    unstable: wp.array
    """Non-zero for a world the substeps skip (frozen from then on): 1 exploded (strain, speed, non-finite), 2 crumpled
    (a crease folded through its range), 3 retired by the host (``Simulator.retire``; stable), shape (W,), int32."""
    step_count: wp.array
    """Substeps taken by each world since t = 0, shape (W,), int32 (time = step_count · dt_sub, exact)."""
    floor_force: wp.array
    """Force of the floor on each vertex in the last substep (normal + friction) [N], shape (W, V), vec3 (zero off
    the floor); also the next substep's first estimate of the normal force."""


def default_epm_path(model: "Model") -> "gaits.EpmPath":
    """The EPM path a :class:`Control` carries unless given another: the params' sinusoid placed on each world's
    IPMs at rest (:func:`warpworm.physics.gaits.sine_path`)."""
    return gaits.sine_path(model.params, model.ipm_rest_pos_host[:, :, 0], num_worlds=model.num_worlds)


class Control:
    """The inputs of a run: the EPM path of every world (``path``; default :func:`default_epm_path`) and the anchor
    targets. Attributes: ``path`` (host :class:`warpworm.physics.gaits.EpmPath`, sinusoidal or keyframed) and its
    device form, ``sine`` (:class:`warpworm.kernels.magnet_pose.SinePath`, each field (W,) or (1,)) or ``keyframes``
    (``KeyframePath``); ``anchor_target`` [m] (W, A) vec3; ``revision`` (int, bumped by :meth:`set_path`)."""

    def __init__(self, model: "Model", path: "gaits.EpmPath | None" = None):
        self._kpose = magnet_pose
        self.device = model.device
        self.num_worlds, self.num_anchors = model.num_worlds, model.num_anchors
        W, A = self.num_worlds, self.num_anchors
        x0 = model.rest_positions_host.astype(np.float32)
        targets = x0[:, model.anchor_vertex.numpy()] if A else np.zeros((W, 0, 3), np.float32)
        self.anchor_target = wp.array(targets.reshape(W, A, 3), dtype=wp.vec3, device=self.device)
        """Anchor target points [m], shape (W, A), vec3 (A may be 0)."""
        self.revision = -1
        """Bumped by every :meth:`set_path` (new device arrays): a step graph captured at an older revision is stale."""
        self.set_path(default_epm_path(model) if path is None else path)

    def set_path(self, path: "gaits.EpmPath") -> None:
        """Set the EPM path (sinusoidal or keyframed) of every world; takes effect at the next step."""
        dev, k = self.device, self._kpose
        self.path = path
        # new device arrays: a step captured as a graph before this call reads the old ones, so the simulator
        # recaptures when the revision moves
        self.revision += 1
        if path.kind == "sine":
            rewind = np.asarray(path.rewind, np.float64)
            if not np.all((rewind == 0.0) | (rewind == 1.0)):
                raise ValueError(f"EpmPath.rewind: got {rewind.reshape(-1).tolist()}; expected 0 (advance w per "
                                 "cycle) or 1 (repeat the first pass) per world")
            sp = k.SinePath()
            for f in gaits.SINE_FIELDS:
                setattr(sp, f, wp.array(np.asarray(getattr(path, f), np.float32).reshape(-1), dtype=float,
                                        device=dev))
            self.sine = sp
        elif path.kind == "keyframes":
            kt = np.asarray(path.key_time, np.float32).reshape(-1)
            kp = np.asarray(path.key_pos, np.float64)
            kr = np.asarray(path.key_rot, np.float64)
            if kp.ndim == 2:
                kp, kr = kp[None], kr[None]
            q = quat_wxyz_to_xyzw(matrix_to_quat_wxyz(kr))
            kf = k.KeyframePath()
            kf.time = wp.array(kt, dtype=float, device=dev)
            kf.pos = wp.array(kp.astype(np.float32), dtype=wp.vec3, device=dev)
            kf.rot = wp.array(q.astype(np.float32), dtype=wp.quat, device=dev)
            self.keyframes = kf
        else:
            raise ValueError(f"unknown path kind {path.kind!r}")

    def set_anchor_targets(self, targets) -> None:
        """Set anchor targets [m], shape (A, 3) (all worlds) or (W, A, 3)."""
        t = np.broadcast_to(np.asarray(targets, np.float32), (self.num_worlds, self.num_anchors, 3))
        self.anchor_target.assign(wp.array(np.ascontiguousarray(t), dtype=wp.vec3, device=self.device))


class ModelBuilder:
    """Assembles a batch of ``num_worlds`` worms from :class:`~warpworm.physics.params.WormParams` on the host; ends in
    :meth:`finalize` (the device :class:`Model`).

    Args:
        params: per-world parameters (scalars are shared, arrays (W,) per world); default ``WormParams()``.
        num_worlds: W.
        anchors: vertex indices (A,) pinned to a target by a spring (force plate); default none.
        anchor_stiffness: anchor strength [N/m], scalar, (A,) or (W, A).

    The worm's bottom face is laid on its (possibly inclined) floor with the tail at x = 0. Each ``add_*`` step fills
    ``self.host`` (name -> (NumPy array, Warp dtype), device arrays to be) and ``self.info`` (host attributes);
    :meth:`finalize` sets them on the :class:`Model`, which declares every one (a name it does not declare is an
    error).
    """

    def __init__(self, params: WormParams | None = None, num_worlds: int = 1, *, anchors=None,
                 anchor_stiffness=1.0e4):
        p = WormParams() if params is None else params
        W = int(num_worlds)
        if W < 1:
            raise ValueError("num_worlds must be >= 1")
        check_worm_params(p)
        self.params, self.num_worlds = p, W
        self.anchors = np.zeros(0, np.int32) if anchors is None else np.asarray(anchors, np.int32).reshape(-1)
        self.anchor_stiffness = anchor_stiffness
        self.host: dict[str, tuple[np.ndarray, object]] = {}
        self.info: dict[str, object] = {"params": p, "num_worlds": W, "num_anchors": len(self.anchors)}
        self.add_geometry()
        self.add_masses()
        self.add_topology()
        self.add_material()
        self.add_magnets()
        self.add_mount_rest_poses()

    def _put(self, name: str, value, dtype) -> None:
        self.host[name] = (np.asarray(value), dtype)

    def _scalar(self, name: str) -> None:
        """A per-world scalar parameter of ``params`` as a device array (R,)."""
        self._put(name, _scalar_param(getattr(self.params, name), self.num_worlds, name), float)

    # ------------------------------------------------------------------------------------------------------------
    def add_geometry(self) -> None:
        """One topology, per-world rest shapes laid on each world's floor."""
        p, W = self.params, self.num_worlds
        n = int(p.n_units)
        # Arrays that depend only on shared parameters keep one row; otherwise one row per world.
        a = per_world(p.a, W)
        b = per_world(p.b, W)
        l0 = per_world(p.l0, W)
        alpha = np.atleast_1d(crease.rest_alpha(l0, b, n))
        rows = 1 if _is_shared(p.a, p.b, p.l0) else W
        pat = crease.build_worm(float(a[0]), float(b[0]), n, alpha=float(alpha[0]))
        # The built rest state is exactly at rest: its rest angles are its measured dihedrals (the transverse creases
        # +-alpha, the prism's corner creases their built angle, the diagonals 0).
        x_rest, rest_len, rest_angle = crease.worm_rest_state(a[:rows], b[:rows], alpha[:rows], n, pattern=pat)
        hinge_len = crease.edge_lengths(x_rest, pat.edges)[:, pat.hinge_edge]
        incline = per_world(p.floor_incline, W)
        # Lay the worm on its (tilted) floor: rotate about +y by -beta; the floor plane passes through the origin.
        R_floor = axis_angle_to_matrix([0.0, 1.0, 0.0], -incline)  # (W, 3, 3)
        x_w = np.broadcast_to(x_rest, (W,) + x_rest.shape[1:])
        self.geometry_rows, self.x_w, self.R_floor = rows, x_w, R_floor
        self.info.update(pattern=pat, rest_positions_host=np.einsum("wij,wvj->wvi", R_floor, x_w),
                         num_vertices=pat.num_vertices, num_edges=pat.num_edges, num_hinges=pat.num_hinges,
                         hinge_rest_angle_host=rest_angle)
        self._put("rest_length", rest_len.astype(np.float32), float)
        self._put("hinge_rest_angle", rest_angle.astype(np.float32), float)
        self._put("hinge_length", hinge_len.astype(np.float32), float)

    def add_masses(self) -> None:
        """Lumped sheet mass + IPM mass on the mount vertices."""
        p, W, pat = self.params, self.num_worlds, self.info["pattern"]
        V = pat.num_vertices
        mrows = 1 if (self.geometry_rows == 1 and _is_shared(p.sheet_density, p.ipm_diameter, p.ipm_thickness,
                                                             p.magnet_mass_density)) else W
        xm = self.x_w[:mrows]
        tri = pat.triangles
        area = 0.5 * np.linalg.norm(
            np.cross(xm[:, tri[:, 1]] - xm[:, tri[:, 0]], xm[:, tri[:, 2]] - xm[:, tri[:, 0]]), axis=-1
        )  # (mrows, T)
        rho_sheet = per_world(p.sheet_density, W)[:mrows]
        mass = np.zeros((mrows, V))
        for c in range(3):  # lumped: a third of each facet's mass on each of its corners
            np.add.at(mass, (slice(None), tri[:, c]), (rho_sheet[:, None] * area) / 3.0)
        sheet_mass = mass.sum(axis=1)
        ipm_d = per_world(p.ipm_diameter, W)
        ipm_h = per_world(p.ipm_thickness, W)
        ipm_mass = per_world(p.magnet_mass_density, W) * np.pi * (0.5 * ipm_d) ** 2 * ipm_h  # (W,)
        # The IPM mass goes on its mount vertices with least-norm weights that keep the total mass and the centre of
        # mass (so gravity's moment on the mount is exact).
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
        with np.errstate(divide="ignore"):
            inv_mass = np.where(mass > 0, 1.0 / mass, 0.0)
        self.info.update(sheet_mass_host=sheet_mass, ipm_mass_host=ipm_mass, vertex_mass_host=mass)
        self._put("inv_mass", inv_mass.astype(np.float32), float)

    def add_topology(self) -> None:
        """Shared topology: bars, hinges, mounts, anchors."""
        pat, A_idx = self.info["pattern"], self.anchors
        A = len(A_idx)
        self.info["half_bandwidth"] = half_bandwidth(pat.edges, pat.hinges)
        self._put("edges", pat.edges, wp.int32)
        self._put("hinges", pat.hinges, wp.int32)
        self._put("hinge_label", pat.hinge_label.astype(np.int32), wp.int32)
        self._put("mount_vertices", pat.mount_vertices, wp.int32)
        self._put("mount_local_pos", pat.mount_local_pos[None], wp.vec3)
        self._put("mount_local_rot", pat.mount_local_rot[None], wp.mat33)
        self._put("anchor_vertex", A_idx, wp.int32)
        ak = np.asarray(self.anchor_stiffness, dtype=np.float64)
        ak = np.broadcast_to(ak, (A,)).reshape(1, A) if ak.ndim <= 1 else ak.reshape(-1, A)
        self._put("anchor_stiffness", ak.astype(np.float32), float)

    def add_material(self) -> None:
        """Per-bar rigidity and stops, crease stiffness, damping, friction, floor, gravity."""
        p, W, pat = self.params, self.num_worlds, self.info["pattern"]
        # Per-bar rigidity: the valley rings get their own (soft) EA so the isostatic tube can fold.
        ea_rigid = _scalar_param(p.bar_stiffness, W, "bar_stiffness")
        ea_valley = _scalar_param(p.valley_bar_stiffness, W, "valley_bar_stiffness")
        is_valley = pat.edge_label == crease.VALLEY
        ea = np.where(is_valley[None, :], ea_valley[:, None], ea_rigid[:, None])
        self._put("bar_stiffness", ea.astype(np.float32), float)
        stop_c = _scalar_param(p.waist_close_strain, W, "waist_close_strain")
        stop_t = _scalar_param(p.waist_stop_strain, W, "waist_stop_strain")
        rows_s = max(len(stop_c), len(stop_t))
        stop = np.full((rows_s, len(is_valley), 2), 1e3)
        stop[:, is_valley, 0] = np.broadcast_to(stop_c, (rows_s,))[:, None]
        stop[:, is_valley, 1] = np.broadcast_to(stop_t, (rows_s,))[:, None]
        self._put("bar_stop_strain", stop.astype(np.float32), wp.vec2)
        self._put("bar_stop_stiffness", np.where(is_valley[None, :], ea_rigid[:, None], 0.0).astype(np.float32),
                  float)
        for name in ("hinge_stiffness", "hinge_damping", "fold_limit_stiffness", "damping", "mu_static",
                     "mu_kinetic", "friction_backward_ratio", "floor_incline", "gravity", "dipole_density"):
            self._scalar(name)

    def add_magnets(self) -> None:
        """The EPM (slot 0) and the three IPMs: model, shapes, sizes, moments."""
        p, W = self.params, self.num_worlds
        ipm_d = per_world(p.ipm_diameter, W)
        ipm_h = per_world(p.ipm_thickness, W)
        self.info["magnet_model_name"] = p.magnet_model
        self._put("magnet_model", np.array([MAGNET_MODELS.index(p.magnet_model)], np.int32), wp.int32)
        self._put("magnet_shape", np.array([[SHAPE_CUBOID, SHAPE_CYLINDER, SHAPE_CYLINDER, SHAPE_CYLINDER]],
                                           np.int32), wp.int32)
        size = np.zeros((W, 4, 3))
        size[:, 0] = per_world(p.epm_size, W, (3,))
        size[:, 1:, 0] = ipm_d[:, None]
        size[:, 1:, 1] = ipm_d[:, None]
        size[:, 1:, 2] = ipm_h[:, None]
        moment = np.zeros((W, 4, 3))
        moment[:, 0, 2] = per_world(p.epm_moment, W)
        moment[:, 1:, 2] = per_world(p.ipm_moment, W, (3,))
        moment_parked = moment.copy()
        moment_parked[:, 0] = 0.0
        self.info.update(magnet_size_host=size, magnet_moment_host=moment)
        self._put("magnet_size", size.astype(np.float32), wp.vec3)
        self._put("magnet_moment", moment.astype(np.float32), wp.vec3)
        self._put("magnet_moment_parked", moment_parked.astype(np.float32), wp.vec3)

    def add_mount_rest_poses(self) -> None:
        """Each world's IPM centres at rest (where its default EPM path is placed: :func:`default_epm_path`)."""
        mpos_all, _ = crease.mount_poses(self.info["pattern"], self.x_w)
        self.info["ipm_rest_pos_host"] = np.einsum("wij,wmj->wmi", self.R_floor, mpos_all)
        # the params' path must be placeable (e.g. an EPM gap inside the support plate is refused) before any device
        # work: built here to check it, kept by the Control that carries it
        gaits.sine_path(self.params, self.info["ipm_rest_pos_host"][:, :, 0], num_worlds=self.num_worlds)

    # ------------------------------------------------------------------------------------------------------------
    def finalize(self, device=None) -> "Model":
        """The device model (immutable)."""
        dev = wp.get_device(device)
        values = {"device": dev, **self.info}
        values.update({name: wp.array(value, dtype=dtype, device=dev) for name, (value, dtype) in self.host.items()})
        declared = set(Model.__annotations__)
        if set(values) != declared:
            raise RuntimeError(f"ModelBuilder: built but not declared by Model: {sorted(set(values) - declared)}; "
                               f"declared but not built: {sorted(declared - set(values))}")
        m = object.__new__(Model)
        for name, value in values.items():
            object.__setattr__(m, name, value)
        return m


class Model:
    """Shared topology and per-world parameters of a batch of worm worlds; immutable once built
    (:meth:`from_params` or :meth:`ModelBuilder.finalize`). Warp arrays on ``device`` unless noted "host" (NumPy);
    "(R, ...)": R = 1 (shared by every world) or W rows, read at row ``world % R``."""

    device: wp.context.Device
    """The device of every array."""
    params: WormParams
    """The parameters the model was built from (host)."""
    num_worlds: int
    """W."""
    num_vertices: int
    """V, shared topology."""
    num_edges: int
    """E, bars."""
    num_hinges: int
    """H, hinges (the creases and the facets' diagonals)."""
    num_anchors: int
    """A, anchored vertices (0 without a force plate)."""
    pattern: crease.CreasePattern
    """World 0's crease pattern (host; topology shared by every world)."""
    half_bandwidth: int
    """Half-bandwidth of the Newton matrix in vertex blocks (:func:`half_bandwidth`)."""
    # --- geometry and mass
    rest_length: wp.array
    """Bar rest lengths [m], shape (R, E), float."""
    hinge_rest_angle: wp.array
    """Hinge rest fold angles [rad], shape (R, H), float: +alpha valley, -alpha mountain, corners their built angle,
    0 flat."""
    hinge_length: wp.array
    """Hinge lengths [m], shape (R, H), float (a hinge's stiffness is k_alpha times this)."""
    inv_mass: wp.array
    """Inverse vertex masses [1/kg], shape (R, V), float (0: infinite mass)."""
    rest_positions_host: np.ndarray
    """Rest positions laid on each world's floor [m], shape (W, V, 3) (host)."""
    hinge_rest_angle_host: np.ndarray
    """:attr:`hinge_rest_angle` [rad], shape (R, H), float64 (host)."""
    vertex_mass_host: np.ndarray
    """Vertex masses, sheet and IPMs [kg], shape (R, V) (host)."""
    sheet_mass_host: np.ndarray
    """Sheet mass [kg], shape (R,) (host)."""
    ipm_mass_host: np.ndarray
    """Mass of one IPM [kg], shape (W,) (host)."""
    ipm_rest_pos_host: np.ndarray
    """IPM centres at rest [m], shape (W, 3, 3): (tail, centre, head), xyz (host)."""
    # --- topology (shared)
    edges: wp.array
    """Bars, shape (E, 2), int32 vertex indices."""
    hinges: wp.array
    """Hinge stencils (i, j, k, l), shared edge j-k, shape (H, 4), int32."""
    hinge_label: wp.array
    """0 flat, 1 mountain, 2 valley (:mod:`warpworm.ids`), shape (H,), int32."""
    mount_vertices: wp.array
    """Each IPM mount's vertices (tail, centre, head), shape (3, K), int32."""
    mount_local_pos: wp.array
    """IPM centre in its mount's frame [m], shape (1, 3), vec3."""
    mount_local_rot: wp.array
    """IPM orientation in its mount's frame (magnet -> mount), shape (1, 3), mat33."""
    anchor_vertex: wp.array
    """Anchored vertices, shape (A,), int32."""
    anchor_stiffness: wp.array
    """Anchor springs [N/m], shape (R, A), float."""
    # --- material, floor
    bar_stiffness: wp.array
    """Axial rigidity EA [N], shape (R, E), float (the valley rings: ``valley_bar_stiffness``)."""
    bar_stop_strain: wp.array
    """(shortened, stretched) strain magnitudes of the waist bars' stops, shape (R, E), vec2 (1e3: none)."""
    bar_stop_stiffness: wp.array
    """EA of a waist bar past its stop [N], shape (R, E), float (0 for the other bars)."""
    hinge_stiffness: wp.array
    """k_alpha per metre of hinge [N·m/rad/m], shape (R,), float."""
    hinge_damping: wp.array
    """c_alpha per metre of hinge [N·m·s/rad/m], shape (R,), float."""
    fold_limit_stiffness: wp.array
    """NoFoldThrough barrier per metre of hinge [N·m/rad/m], shape (R,), float."""
    damping: wp.array
    """Linear velocity damping [1/s], shape (R,), float."""
    mu_static: wp.array
    """Static friction coefficient, shape (R,), float."""
    mu_kinetic: wp.array
    """Kinetic friction coefficient, shape (R,), float."""
    friction_backward_ratio: wp.array
    """Both friction coefficients tail-ward over head-ward, shape (R,), float (1: isotropic)."""
    floor_incline: wp.array
    """Floor slope about +y [rad], shape (R,), float."""
    gravity: wp.array
    """Gravitational acceleration along −z [m/s²], shape (R,), float."""
    dipole_density: wp.array
    """Dipoles per volume of the 'dipoles' magnet model [1/m³], shape (R,), float."""
    # --- magnets: slot 0 EPM (cuboid), 1 tail, 2 centre, 3 head IPM (cylinders)
    magnet_model: wp.array
    """0 dipoles, 1 analytic (index in :data:`~warpworm.physics.params.MAGNET_MODELS`), shape (1,), int32."""
    magnet_model_name: str
    """'dipoles' or 'analytic' (host)."""
    magnet_shape: wp.array
    """0 cuboid, 1 cylinder, shape (1, 4), int32."""
    magnet_size: wp.array
    """Cuboid extents or cylinder (d, d, h) [m], shape (W, 4), vec3."""
    magnet_moment: wp.array
    """Moments along each magnet's own +z [A·m²], shape (W, 4), vec3."""
    magnet_moment_parked: wp.array
    """:attr:`magnet_moment` with the EPM's zeroed (absent, as while settling) [A·m²], shape (W, 4), vec3."""
    magnet_size_host: np.ndarray
    """:attr:`magnet_size` [m], shape (W, 4, 3), float64 (host)."""
    magnet_moment_host: np.ndarray
    """:attr:`magnet_moment` [A·m²], shape (W, 4, 3), float64 (host)."""

    def __init__(self):
        raise TypeError("use Model.from_params(params, num_worlds, device) or ModelBuilder(...).finalize(device)")

    def __setattr__(self, name, value):
        raise AttributeError(f"Model is immutable once built (setting {name!r}); the EPM path and the anchor targets "
                             "are inputs: see Control")

    @classmethod
    def from_params(cls, params: WormParams | None = None, num_worlds: int = 1, device=None, *, anchors=None,
                    anchor_stiffness=1.0e4) -> "Model":
        """``ModelBuilder(params, num_worlds, anchors=..., anchor_stiffness=...).finalize(device)``."""
        return ModelBuilder(params, num_worlds, anchors=anchors, anchor_stiffness=anchor_stiffness).finalize(device)

    @property
    def default_path(self) -> "gaits.EpmPath":
        """The params' EPM path placed on each world's IPMs at rest (:func:`default_epm_path`), host."""
        return default_epm_path(self)

    # ------------------------------------------------------------------------------------------------------------
    def control(self, path: "gaits.EpmPath | None" = None) -> Control:
        """Control inputs for this model: ``path`` (default: the params' sinusoid) and the anchor targets at the
        anchored vertices' rest positions."""
        return Control(self, path)

    def state(self) -> State:
        """A fresh state: every world at its rest shape on the floor, at rest, t = 0."""
        W, V, E, H = self.num_worlds, self.num_vertices, self.num_edges, self.num_hinges
        dev = self.device
        x0 = self.rest_positions_host.astype(np.float32)
        angles = np.broadcast_to(self.hinge_rest_angle_host, (W, H)).astype(np.float32)

        def z(shape, dtype):
            return wp.zeros(shape, dtype=dtype, device=dev)

        return State(
            positions=wp.array(x0, dtype=wp.vec3, device=dev),
            velocities=z((W, V), wp.vec3),
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
            floor_force=z((W, V), wp.vec3),
        )

    def bytes_per_world(self) -> int:
        """Device bytes of one world's state, control, solver scratch and per-world model arrays (shared topology
        excluded)."""
        s = self.state()
        total = sum(getattr(s, f).capacity for f in State.__dataclass_fields__)
        W, V = self.num_worlds, self.num_vertices
        total += W * self.num_anchors * 12  # anchor targets (Control)
        total += W * V * (12 + 12 + 12) + W * V * (self.half_bandwidth + 1) * 36  # solver scratch
        per = [self.rest_length, self.hinge_rest_angle, self.hinge_length, self.inv_mass, self.magnet_size,
               self.magnet_moment]
        total += sum(a.capacity * self.num_worlds // a.shape[0] for a in per)
        return int(total // self.num_worlds)
