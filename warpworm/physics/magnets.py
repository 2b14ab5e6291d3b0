"""Permanent magnets: shapes, magnetization, and the batched Warp wrench / field evaluations (host API).

Two models of the interaction (``warpworm.physics.params.MAGNET_MODELS``):

``"dipoles"``
    The paper's aggregation (Swaminathan et al. 2021, §II-B): each magnet is a regular grid of point dipoles at a
    density [dipoles/m³] (default 64 per cm³); the force on a target is the sum over all dipole pairs of the
    point-dipole force, the torque about its centre Σ (r_j − c) × F_j + m_j × B(r_j). Grids (spacing h = density^(-1/3),
    all cells of equal volume, each dipole m_total / N): a cuboid gets n_i = max(1, round(size_i / h)) cell-centred
    points per axis (the paper's EPM, 10×10×40 mm: 4×4×16 = 256); a cylinder gets max(1, round(height / h))
    mid-height layers, each an equal-area polar partition of the disk (round(R / h) rings, round(ring area / h²)
    sectors per ring) with the points on radii that keep the grid's traceless second moment exact — the 10 mm × 1 mm
    IPM gets 3 + 9 = 12 dipoles, where the paper took density × volume ≈ 5 (so 256 + 3·12 = 292 dipoles, not 271).
``"analytic"``
    Exact closed-form source fields (cuboid: Yang / Engel-Herbert; cylinder: Derby axial, Caciagli diametral — both
    closed forms, in float64 inside the kernel) and the exact surface-charge integral over the target
    (F = ∮ σ B dA, T = ∮ (r − c) × σ B dA, σ = M·n), by composite Gauss-Legendre quadrature whose panel count grows
    as faces come close to the source. Default: 4 points per panel side, at most 8 panels per side.

Units: SI. Poses: position (3,) [m] and rotation (3, 3) magnet → world, or batches (N, 3), (N, 3, 3).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from warpworm.ids import MAGNET_MODELS, SHAPE_CUBOID, SHAPE_CYLINDER
from warpworm.kernels.magnet_wrench import (field_kernel, pair_wrench_kernel, sum_pair_wrenches_kernel,
                                            world_pair_wrench_kernel)
from warpworm.transforms import matrix_to_quat_wxyz, quat_wxyz_to_xyzw

MU0 = 1.25663706212e-6
"""Vacuum permeability [T·m/A]."""

MODELS = {name: i for i, name in enumerate(MAGNET_MODELS)}
"""Model name -> id used in the kernels (order of ``warpworm.ids.MAGNET_MODELS``)."""

DEFAULT_DENSITY = 64e6
"""Default dipole density of the 'dipoles' model: 64 per cm³ [1/m³]."""

DEFAULT_QUAD_ORDER = 4
"""Gauss-Legendre points per panel side of the 'analytic' surface integral."""

DEFAULT_MAX_PANELS = 8
"""Largest number of composite panels per face side of the 'analytic' surface integral."""

GRADES_BR = {
    "N35": 1.19,
    "N38": 1.23,
    "N40": 1.26,
    "N42": 1.29,
    "N45": 1.33,
    "N48": 1.37,
    "N50": 1.41,
    "N52": 1.44,
}
"""Nominal remanence Br [T] of sintered NdFeB grades (middle of the usual data-sheet ranges)."""


# ----------------------------------------------------------------------------------------------------------------------
# Magnets
# ----------------------------------------------------------------------------------------------------------------------


def _vec3(name: str, value, expected: str) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if arr.shape == ():
        arr = np.array([0.0, 0.0, float(arr)])
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ValueError(f"{name}={value!r}: expected {expected}")
    return arr


def _magnetization(moment, polarization, volume: float) -> np.ndarray:
    """Moment [A·m²] from exactly one of ``moment`` / ``polarization`` (3-vector, scalar along +z, or grade name)."""
    if (moment is None) == (polarization is None):
        raise ValueError(
            f"moment={moment!r}, polarization={polarization!r}: expected exactly one of moment= [A·m²] or "
            "polarization= [T] (a 3-vector in the magnet frame, a scalar along +z, or a grade name like 'N52')"
        )
    if moment is not None:
        if isinstance(moment, str):
            raise ValueError(f"moment={moment!r}: expected a number or 3-vector [A·m²]; grades go to polarization=")
        return _vec3("moment", moment, "a scalar (along +z) or a 3-vector dipole moment [A·m²] in the magnet frame")
    if isinstance(polarization, str):
        key = polarization.strip().upper()
        if key not in GRADES_BR:
            raise ValueError(f"polarization={polarization!r}: expected a grade in {sorted(GRADES_BR)} or a value [T]")
        polarization = GRADES_BR[key]
    J = _vec3("polarization", polarization, "a scalar (along +z) or a 3-vector polarization J = mu0·M [T]")
    return J / MU0 * volume


@dataclass(frozen=True)
class Magnet:
    """A uniformly magnetized magnet. ``size``: cuboid extents, or (d, d, h) for a cylinder [m], shape (3,);
    ``moment``: dipole moment in the magnet's own frame [A·m²], shape (3,)."""

    shape: int
    size: np.ndarray
    moment: np.ndarray

    @property
    def volume(self) -> float:
        """Volume [m³]."""
        if self.shape == SHAPE_CYLINDER:
            return float(np.pi / 4 * self.size[0] ** 2 * self.size[2])
        return float(np.prod(self.size))

    @property
    def magnetization(self) -> np.ndarray:
        """M = m / V [A/m], magnet frame, shape (3,)."""
        return self.moment / self.volume

    @property
    def polarization(self) -> np.ndarray:
        """J = mu0 M [T], magnet frame, shape (3,)."""
        return MU0 * self.magnetization

    def with_moment(self, moment) -> "Magnet":
        """Same shape, new moment [A·m²] (3-vector or scalar along +z)."""
        return Magnet(self.shape, self.size, _vec3("moment", moment, "a scalar or 3-vector [A·m²]"))


def Cuboid(size, moment=None, polarization=None) -> Magnet:
    """A cuboid (bar) magnet. ``size`` (x, y, z) extents [m] in its own frame; give ``moment`` [A·m²] or
    ``polarization`` [T] (3-vector in the magnet frame, scalar = along +z, or a grade such as ``"N52"``)."""
    s = np.asarray(size, dtype=np.float64)
    if s.shape == ():
        s = np.full(3, float(s))
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"size={size!r}: expected three positive extents (x, y, z) [m] or one edge length")
    return Magnet(SHAPE_CUBOID, s, _magnetization(moment, polarization, float(np.prod(s))))


def Cylinder(diameter, height, moment=None, polarization=None) -> Magnet:
    """A cylinder (disk) magnet with its axis along its own +z. ``diameter``, ``height`` [m]; give ``moment``
    [A·m²] or ``polarization`` [T] (3-vector in the magnet frame, scalar = axial, or a grade such as ``"N52"``)."""
    for name, v in (("diameter", diameter), ("height", height)):
        if not np.isscalar(v) or not np.isfinite(v) or v <= 0:
            raise ValueError(f"{name}={v!r}: expected a positive length [m]")
    s = np.array([diameter, diameter, height], dtype=np.float64)
    return Magnet(SHAPE_CYLINDER, s, _magnetization(moment, polarization, float(np.pi / 4 * diameter**2 * height)))


# ----------------------------------------------------------------------------------------------------------------------
# Device API for the solver
# ----------------------------------------------------------------------------------------------------------------------


@functools.lru_cache(maxsize=None)
def _gauss_legendre(order: int, device: str):
    x, w = np.polynomial.legendre.leggauss(int(order))
    return wp.array(x, dtype=wp.float64, device=device), wp.array(w, dtype=wp.float64, device=device)


def _model_array(model, device) -> wp.array:
    if isinstance(model, wp.array):
        return model
    if isinstance(model, str):
        if model not in MODELS:
            raise ValueError(f"model={model!r}: expected one of {sorted(MODELS)}")
        return wp.array([MODELS[model]], dtype=wp.int32, device=device)
    ids = np.atleast_1d(np.asarray(model))
    if ids.dtype.kind in "US":
        bad = [m for m in ids if m not in MODELS]
        if bad:
            raise ValueError(f"model={bad[0]!r}: expected one of {sorted(MODELS)}")
        ids = np.array([MODELS[m] for m in ids])
    if not np.all(np.isin(ids, (0, 1))):
        raise ValueError(f"model={model!r}: expected 'dipoles'/'analytic' or ids 0 (dipoles) / 1 (analytic)")
    return wp.array(ids.astype(np.int32), dtype=wp.int32, device=device)


def launch_world_wrenches(
    model,
    shape: wp.array,
    size: wp.array,
    moment: wp.array,
    pos: wp.array,
    rot: wp.array,
    force_out: wp.array,
    torque_out: wp.array,
    density: wp.array,
    device=None,
    *,
    quad_order: int = DEFAULT_QUAD_ORDER,
    max_panels: int = DEFAULT_MAX_PANELS,
    epm_wrench: bool = True,
    far_field: bool = True,
    pair_scratch: tuple[wp.array, wp.array] | None = None,
    stopped: wp.array | None = None,
) -> None:
    """Net magnetic force and torque on every magnet of every world from all the other magnets of its world.

    Two kernel launches: each unordered pair once (:func:`warpworm.kernels.magnet_wrench.world_pair_wrench_kernel`,
    dim (W, M (M − 1) / 2): the wrench on one magnet of the pair, the other's by reaction), then each magnet's sum
    over its pairs (``sum_pair_wrenches_kernel``, dim (W, M)); no host round trip, any M. Capturable in a graph once
    the model array, the quadrature arrays and the pair scratch exist: pass a ``wp.array`` for ``model`` (a string
    makes a small array) and a ``pair_scratch``, and launch once outside the capture (the first call creates the
    Gauss–Legendre arrays from host data, whose copy a capture would record instead of doing).

    Args:
        model: ``"dipoles"`` | ``"analytic"`` for the whole batch, or per-world ids (0 dipoles, 1 analytic) as a
            sequence / int32 ``wp.array`` of shape (W,) (read as ``model[w % len]``).
        shape: int32, shape (W, M) or (1, M): 0 cuboid, 1 cylinder.
        size: vec3, shape (W, M) or (1, M): cuboid extents or cylinder (d, d, h) [m], magnet frame.
        moment: vec3, shape (W, M) or (1, M): dipole moment [A·m²] in the magnet frame; zero = magnet absent.
        pos: vec3, shape (W, M): magnet centres in the world [m].
        rot: quat (x, y, z, w), shape (W, M): magnet frame -> world.
        force_out: vec3, shape (W, M): net force on each magnet [N] (overwritten).
        torque_out: vec3, shape (W, M): net torque on each magnet about its own centre [N·m] (overwritten).
        density: float32, shape (W,) or (1,): dipoles per m³ ('dipoles' model; ignored by 'analytic').
        device: Warp device (default: that of ``pos``).
        quad_order: Gauss-Legendre points per panel side ('analytic').
        max_panels: most composite panels per face side ('analytic'; used only for faces close to a source).
        epm_wrench: ``False`` writes magnet 0's (the EPM's, whose motion is prescribed) force and torque as zero;
            every other magnet's wrench is the same as with ``True``. The EPM's costs nothing either way: each
            pair is evaluated once and its reaction is the other magnet's share.
        far_field: ``True`` ('analytic' only) takes two cylinders at least 4 circumscribing radii apart (the IPM
            pairs of a worm) by a multipole-matched ring rule of point dipoles (:mod:`warpworm.kernels.magnet_far_pair`,
            within 8e-6 of the closed form's largest force and torque, ~3x cheaper per pair), and a cuboid and a
            cylinder at least 2.5 of the cylinder's circumscribing radii apart (the EPM and an IPM) by the same rule
            for the cylinder, the cuboid's face charges in its field (the cylinder's wrench by reciprocity; within
            5.1e-6, ~2.4x cheaper); ``False`` always uses the closed form.
        pair_scratch: the pairs' wrenches between the two launches, from :func:`pair_wrench_scratch` for these W
            and M (a caller that steps repeatedly, e.g. the simulator, owns one); ``None`` allocates one for this
            call.
        stopped: int32, shape (W,), or ``None``: worlds whose entry is non-zero are skipped and keep the wrenches
            they had (a caller's own ``pair_scratch`` keeps their pairs'): the simulator passes its world status, so
            a world it no longer steps (exploded, crumpled, retired) costs no pair evaluation.

    Magnets must not overlap. Cost per world ('dipoles') ~ Σ over unordered pairs of N_a · N_b point-dipole pairs
    (paper's worm at 64/cm³: 256·12·3 + 12·12·3 = 9,648 pair interactions, with or without the EPM's wrench).
    """
    device = device or pos.device
    gl_x, gl_w = _gauss_legendre(quad_order, str(device))
    W, M = pos.shape
    pair_force, pair_torque = pair_scratch if pair_scratch is not None else pair_wrench_scratch(W, M, device)
    if M > 1:
        wp.launch(
            world_pair_wrench_kernel,
            dim=(W, M * (M - 1) // 2),
            inputs=[_model_array(model, device), shape, size, moment, density, gl_x, gl_w, int(max_panels),
                    int(bool(far_field)), pos, rot, stopped],
            outputs=[pair_force, pair_torque],
            device=device,
        )
    wp.launch(sum_pair_wrenches_kernel, dim=(W, M), inputs=[int(bool(epm_wrench)), pair_force, pair_torque],
              outputs=[force_out, torque_out], device=device)


def pair_wrench_scratch(num_worlds: int, num_magnets: int, device=None) -> tuple[wp.array, wp.array]:
    """The (W, max(1, M (M − 1) / 2), 2) force and torque scratch of :func:`launch_world_wrenches` (each unordered
    pair's wrench on its two magnets; its values live only between that call's two launches)."""
    P = max(1, num_magnets * (num_magnets - 1) // 2)
    dev = _device(device)
    return (wp.zeros((num_worlds, P, 2), dtype=wp.vec3, device=dev),
            wp.zeros((num_worlds, P, 2), dtype=wp.vec3, device=dev))


# ----------------------------------------------------------------------------------------------------------------------
# Host API (NumPy in, NumPy out)
# ----------------------------------------------------------------------------------------------------------------------


def _poses(pose, name: str):
    """(position, rotation) -> positions (N, 3), quats xyzw (N, 4), batched flag."""
    try:
        p, R = pose
    except (TypeError, ValueError):
        raise ValueError(f"{name}={pose!r}: expected (position[3], rotation 3x3) or batches ((N,3), (N,3,3))") from None
    p = np.asarray(p, dtype=np.float64)
    R = np.asarray(R, dtype=np.float64)
    if p.shape[-1:] != (3,) or R.shape[-2:] != (3, 3) or p.ndim > 2 or R.ndim > 3:
        raise ValueError(f"{name}: expected position (3,) or (N,3) and rotation (3,3) or (N,3,3), got {p.shape}, {R.shape}")
    if not np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-6):
        raise ValueError(f"{name}: rotation is not orthonormal")
    batched = p.ndim == 2 or R.ndim == 3
    q = quat_wxyz_to_xyzw(matrix_to_quat_wxyz(R.reshape(-1, 3, 3)))
    return p.reshape(-1, 3), q, batched


def _device(device):
    return wp.get_device(device) if device is not None else wp.get_device("cpu")


def wrench(
    source: Magnet,
    target: Magnet,
    source_pose,
    target_pose,
    model: str = "analytic",
    density: float = DEFAULT_DENSITY,
    *,
    quad_order: int = DEFAULT_QUAD_ORDER,
    max_panels: int = DEFAULT_MAX_PANELS,
    far_field: bool = True,
    device=None,
):
    """Force and torque on ``target`` from ``source``.

    Args:
        source, target: :class:`Magnet` (from :func:`Cuboid` / :func:`Cylinder`).
        source_pose, target_pose: ``(position (3,) [m], rotation (3, 3) magnet -> world)`` or batches
            ``((N, 3), (N, 3, 3))``; a single pose broadcasts against a batch.
        model: ``"analytic"`` (exact fields, surface-charge quadrature) or ``"dipoles"`` (dipole grids).
        density: dipoles per m³ for ``"dipoles"`` (scalar or (N,)).
        quad_order, max_panels: 'analytic' quadrature (see :func:`launch_world_wrenches`).
        far_field: ring rule for far cylinder pairs and far cuboid–cylinder pairs ('analytic'; see
            :func:`launch_world_wrenches`); ``False``
            gives the closed form at every distance.
        device: Warp device (default CPU). One kernel launch for the whole batch.

    Returns:
        ``(F, T)``: force on the target [N] and torque on the target about its centre [N·m], shape (3,) each, or
        (N, 3) for batched poses, float64 arrays (computed in float32 on the device).
    """
    dev = _device(device)
    if model not in MODELS:
        raise ValueError(f"model={model!r}: expected one of {sorted(MODELS)}")
    ps, qs, bs = _poses(source_pose, "source_pose")
    pt, qt, bt = _poses(target_pose, "target_pose")
    dens = np.atleast_1d(np.asarray(density, dtype=np.float64))
    sizes = {len(ps), len(qs), len(pt), len(qt), len(dens)} - {1}
    if len(sizes) > 1:
        raise ValueError(f"batch sizes differ: poses and density give {sorted(sizes)}")
    if np.any(dens <= 0):
        raise ValueError(f"density={density!r}: expected positive dipoles per m³")
    n = max(sizes) if sizes else 1

    def arr(x, dtype):
        return wp.array(np.asarray(x, dtype=np.float32 if dtype != wp.int32 else np.int32), dtype=dtype, device=dev)

    gl_x, gl_w = _gauss_legendre(quad_order, str(dev))
    F = wp.zeros(n, dtype=wp.vec3, device=dev)
    T = wp.zeros(n, dtype=wp.vec3, device=dev)
    wp.launch(
        pair_wrench_kernel,
        dim=n,
        inputs=[
            arr([MODELS[model]], wp.int32),
            arr([source.shape], wp.int32),
            arr(source.size[None], wp.vec3),
            arr(source.moment[None], wp.vec3),
            arr([target.shape], wp.int32),
            arr(target.size[None], wp.vec3),
            arr(target.moment[None], wp.vec3),
            arr(dens, wp.float32),
            gl_x,
            gl_w,
            int(max_panels),
            int(bool(far_field)),
            arr(ps, wp.vec3),
            arr(qs, wp.quat),
            arr(pt, wp.vec3),
            arr(qt, wp.quat),
        ],
        outputs=[F, T],
        device=dev,
    )
    Fn = F.numpy().astype(np.float64)
    Tn = T.numpy().astype(np.float64)
    if not (bs or bt or dens.size > 1):
        return Fn[0], Tn[0]
    return Fn, Tn


def field(magnet: Magnet, pose, points, model: str = "analytic", density: float = DEFAULT_DENSITY, *, device=None):
    """Magnetic flux density B [T] of ``magnet`` at ``pose`` (position (3,), rotation (3, 3)) at world ``points``
    [m], shape (..., 3) -> (..., 3). ``model="dipoles"`` sums the dipole grid at ``density`` [1/m³] instead of the
    exact field. Inside a magnet the exact model returns B (including J)."""
    if model not in MODELS:
        raise ValueError(f"model={model!r}: expected one of {sorted(MODELS)}")
    dev = _device(device)
    p, q, batched = _poses(pose, "pose")
    if batched and len(p) > 1:
        raise ValueError("pose: field() takes a single pose")
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-1:] != (3,):
        raise ValueError(f"points: expected shape (..., 3), got {pts.shape}")
    flat = wp.array(pts.reshape(-1, 3).astype(np.float32), dtype=wp.vec3, device=dev)
    out = wp.zeros(flat.shape[0], dtype=wp.vec3, device=dev)
    if flat.shape[0]:
        wp.launch(
            field_kernel,
            dim=flat.shape[0],
            inputs=[
                MODELS[model],
                int(magnet.shape),
                wp.vec3(*magnet.size.astype(np.float32)),
                wp.vec3(*magnet.moment.astype(np.float32)),
                float(density),
                wp.vec3(*p[0].astype(np.float32)),
                wp.quat(*q[0].astype(np.float32)),
                flat,
            ],
            outputs=[out],
            device=dev,
        )
    return out.numpy().astype(np.float64).reshape(pts.shape)


def world_wrenches(magnets, positions, rotations, model: str = "analytic", density=DEFAULT_DENSITY, *,
                   quad_order: int = DEFAULT_QUAD_ORDER, max_panels: int = DEFAULT_MAX_PANELS, epm_wrench: bool = True,
                   far_field: bool = True, device=None):
    """NumPy convenience around :func:`launch_world_wrenches`.

    Args:
        magnets: list of M :class:`Magnet` (shared by all worlds).
        positions: (W, M, 3) [m]; rotations: (W, M, 3, 3) magnet -> world.
        model: model name, or per-world names / ids (W,). density: scalar or (W,) [1/m³].
        epm_wrench: ``False``: magnet 0's wrench is returned as zero (the others' are the same).
        far_field: the ring rule for far cylinder and cuboid–cylinder pairs (see :func:`launch_world_wrenches`).

    Returns:
        (F, T), each (W, M, 3): net force [N] and torque about each magnet's centre [N·m].
    """
    dev = _device(device)
    positions = np.asarray(positions, dtype=np.float64)
    rotations = np.asarray(rotations, dtype=np.float64)
    W, M = positions.shape[:2]
    if len(magnets) != M or rotations.shape != (W, M, 3, 3):
        raise ValueError(f"expected {M} magnets and rotations of shape {(W, M, 3, 3)}, got {len(magnets)}, {rotations.shape}")
    q = quat_wxyz_to_xyzw(matrix_to_quat_wxyz(rotations.reshape(-1, 3, 3))).reshape(W, M, 4)
    F = wp.zeros((W, M), dtype=wp.vec3, device=dev)
    T = wp.zeros((W, M), dtype=wp.vec3, device=dev)
    launch_world_wrenches(
        model,
        wp.array(np.array([[m.shape for m in magnets]], dtype=np.int32), dtype=wp.int32, device=dev),
        wp.array(np.array([[m.size for m in magnets]], dtype=np.float32), dtype=wp.vec3, device=dev),
        wp.array(np.array([[m.moment for m in magnets]], dtype=np.float32), dtype=wp.vec3, device=dev),
        wp.array(positions.astype(np.float32), dtype=wp.vec3, device=dev),
        wp.array(q.astype(np.float32), dtype=wp.quat, device=dev),
        F,
        T,
        wp.array(np.atleast_1d(np.asarray(density, dtype=np.float32)), dtype=wp.float32, device=dev),
        dev,
        quad_order=quad_order,
        max_panels=max_panels,
        epm_wrench=epm_wrench,
        far_field=far_field,
    )
    return F.numpy().astype(np.float64), T.numpy().astype(np.float64)


__all__ = [
    "Cuboid",
    "Cylinder",
    "GRADES_BR",
    "MODELS",
    "Magnet",
    "field",
    "launch_world_wrenches",
    "pair_wrench_scratch",
    "world_wrenches",
    "wrench",
]


def dipole_grid(magnet: Magnet, density: float = DEFAULT_DENSITY) -> np.ndarray:
    """The 'dipoles' model's grid of ``magnet`` at ``density`` [1/m³]: points (N, 3) [m] in the magnet frame.

    Mirrors the kernels' on-the-fly generation (``kernels/magnet_dipoles.py``: ``dipole_grid_*``, same order); every
    point stands for a cell of equal volume and carries ``magnet.moment / N``. Cuboid: cell centres of an
    n_x × n_y × n_z lattice, n_i = max(1, round(size_i · density^(1/3))). Cylinder: n_z mid-height layers, each an
    equal-area polar partition (rings of width ≈ h, sectors of area ≈ h²) with the dipoles on radii that keep the
    grid's traceless second moment exact (see the kernel module).
    """
    per_m = float(np.float32(density)) ** (1.0 / 3.0)
    if magnet.shape != SHAPE_CYLINDER:
        n = np.maximum(1, np.round(magnet.size * per_m).astype(int))
        axes = [magnet.size[k] * ((np.arange(n[k]) + 0.5) / n[k] - 0.5) for k in range(3)]
        return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    diameter, height = magnet.size[0], magnet.size[2]
    n_z = max(1, int(np.round(height * per_m)))
    r_per_m = 0.5 * diameter * per_m
    n_r = max(1, int(np.round(r_per_m)))
    cells = [max(1, int(np.round(np.pi * (r_per_m / n_r) ** 2 * (2 * i + 1)))) for i in range(n_r)]
    cells = [3 if c == 2 else c for c in cells]
    n_layer = sum(cells)
    dz = height / n_z
    z = height * ((np.arange(n_z) + 0.5) / n_z - 0.5)
    pts = []
    first = 0
    for c in cells:
        rho2 = 0.25 * diameter**2 / n_layer * 0.5 * (2 * first + c) - dz * dz / 6.0
        rho = np.sqrt(max(rho2, 0.0)) if c >= 3 else 0.0
        theta = (np.arange(c) + 0.5) * (2.0 * np.pi / c)
        for t in theta:
            for zk in z:
                pts.append((rho * np.cos(t), rho * np.sin(t), zk))
        first += c
    return np.array(pts, dtype=np.float64)


__all__.append("dipole_grid")
