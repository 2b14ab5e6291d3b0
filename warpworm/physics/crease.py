"""Crease patterns: the worm's triangular-prism bellows and any other triangulated origami, as NumPy data.

A :class:`CreasePattern` is the bar-and-hinge description of an origami sheet (Liu & Paulino's MERLIN model, the
paper's Kangaroo model): every mesh edge is a bar, every interior edge is a hinge with a label (mountain / valley /
flat) and a rest fold angle. Everything is float64, SI (m, rad), host-side; the solver uploads it.

Geometry of the worm (paper §III, Fig. 3; the triangulation is ours, see ``docs/crease.md``)
-----------------------------------------------------------------------------------------
A tube with an equilateral triangular cross-section of side ``a`` runs along +x, tail at x = 0, one face on the floor
z = 0. There are ``2 n + 1`` cross-sections, one every half unit (``s = 0 .. 2n``): even ``s`` are the unit
boundaries (full triangles of side ``a``), odd ``s`` are the unit middles (inset triangles: every face moved inward
by ``b sin(α/2)``, shrunk about the same axis). Between two sections each of the three faces is a planar trapezoid
of slant width ``b``, tilted by ±α/2 from the axis, so a unit (two panels of width ``b`` meeting at interior angle
π − α) is ``u = 2 b cos(α/2)`` long: eq. (7). Each trapezoid is split into two triangles by a diagonal (a flat
crease); the diagonal alternates between half units so every unit is mirror-symmetric about its middle.

Creases and labels:
- transverse creases at the unit middles: VALLEY, rest +α (the tube is pinched in there);
- transverse creases at interior unit boundaries: MOUNTAIN, rest −α (ridges);
- the prism's corner creases (section s vertex k to section s + 1 vertex k): MOUNTAIN, rest angle = their built
  dihedral (about −2π/3 − a little; exactly −(π − the corner's dihedral), see :func:`dihedral_angles`), since a
  prism corner is a ridge seen from outside and its angle is set by the prism, not by α;
- trapezoid diagonals: FLAT, rest 0; the open ends' edges: BOUNDARY (no hinge).

Signed fold angle (the convention of ``hinge_rest_angle`` and of the dynamics)
-----------------------------------------------------------------------------
Hinge stencil ``(i, j, k, l)``: shared edge j–k; wing ``i`` belongs to the triangle oriented (i, j, k) and wing
``l`` to the triangle oriented (l, k, j) (both in the mesh's consistent, outward orientation). With
``n1 = (x_j − x_i) × (x_k − x_i)``, ``n2 = (x_k − x_l) × (x_j − x_l)`` (outward normals of the two wings) and
``e = (x_j − x_k) / |x_j − x_k|``::

    ψ = atan2((n1 × n2) · e, n1 · n2)      ∈ (−π, π],   0 = flat

ψ > 0 (valley) when the wings fold toward the side their outward normals point to, i.e. ``n1 · (x_l − x_j) > 0``;
ψ < 0 is a mountain. In MERLIN's notation (r_ij = x_i − x_j, r_kj = x_k − x_j, r_kl = x_k − x_l, same node order)
ψ = π − θ_MERLIN, so ∂ψ/∂x_i = |e| n1 / |n1|², ∂ψ/∂x_l = |e| n2 / |n2|² (see :func:`dihedral_gradients`).

Foldability (what the dynamics must know)
-----------------------------------------
Any triangulated tube whose open ends are triangles has E = 3V − 6 bars: generically isostatic, and this one is
(rank of the rigidity matrix = 3V − 6). With every bar stiff, squashing the worm strains bars: at EA = 1e4 N its
axial stiffness is ≈ 4.3e4 N/m (:func:`compression_mode`), far beyond what the IPMs can push. The VALLEY bars (the
rings at the unit middles, 3 per unit) are the minimal set that must give: without them the tube has 3 n internal
mechanisms, axial shortening among them, with every other bar at zero strain to first order (finite check: 20 %
shortening with the other bars under 4e-6 strain, the valley rings at −10 … +6 %). Physically that is the paper's
faces bending near the mid creases. So the solver should give the VALLEY-labelled bars a much lower axial stiffness.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from warpworm.ids import BOUNDARY, CREASE_LABEL_NAMES, FLAT, MOUNTAIN, VALLEY

# FLAT, MOUNTAIN, VALLEY, BOUNDARY (from warpworm.ids): the edge / hinge labels (int8)
LABEL_NAMES = CREASE_LABEL_NAMES
NUM_SEGMENTS = 5
"""The paper's five equal segments along the worm (tail -> head)."""
MOUNT_NAMES = ("tail", "centre", "head")

# Crease colours as in the paper's Fig. 3 (RGBA uint8).
VALLEY_RGBA = np.array([220, 30, 30, 255], dtype=np.uint8)
MOUNTAIN_RGBA = np.array([30, 60, 220, 255], dtype=np.uint8)
SHEET_RGBA = np.array([235, 235, 225, 255], dtype=np.uint8)


@dataclass
class CreasePattern:
    """Bar-and-hinge crease pattern (NumPy, float64, SI). Construct with :func:`build_worm` or :meth:`from_trimesh`."""

    vertices: np.ndarray
    """Rest positions [m], shape (V, 3), float64."""
    triangles: np.ndarray
    """Facets, shape (T, 3), int32; consistently oriented, normals pointing out of the tube (right-hand rule)."""
    edges: np.ndarray
    """Unique edges (bars), shape (E, 2), int32, each row sorted (v0 < v1), rows sorted lexicographically."""
    edge_label: np.ndarray
    """Label of each edge, shape (E,), int8: FLAT=0, MOUNTAIN=1, VALLEY=2, BOUNDARY=3."""
    edge_rest_length: np.ndarray
    """Rest length of each bar [m], shape (E,), float64."""
    hinges: np.ndarray
    """Hinge stencils (i, j, k, l), shape (H, 4), int32: shared edge j–k, wing i in triangle (i, j, k), wing l in
    triangle (l, k, j) (see the module docstring for the signed angle)."""
    hinge_edge: np.ndarray
    """Index into ``edges`` of each hinge's shared edge, shape (H,), int32."""
    hinge_label: np.ndarray
    """Label of each hinge, shape (H,), int8 (FLAT, MOUNTAIN or VALLEY)."""
    hinge_rest_angle: np.ndarray
    """Rest fold angle ψ₀ [rad], shape (H,), float64: +α valley, −α mountain, 0 flat (worm corner creases: their
    built dihedral)."""
    hinge_length: np.ndarray
    """Rest length of each hinge's crease (edge j–k) [m], shape (H,), float64."""
    triangle_segment: np.ndarray
    """Segment (0..4, tail -> head) of each facet, by its rest centroid x, shape (T,), int32."""
    mount_vertices: np.ndarray
    """Vertices that carry each IPM mount (tail, centre, head), shape (3, K), int32; their frame is
    :func:`frame_from_vertices`."""
    mount_local_pos: np.ndarray
    """IPM centre in its mount frame [m], shape (3, 3) (mount, xyz), float64."""
    mount_local_rot: np.ndarray
    """IPM orientation in its mount frame (magnet -> mount frame), shape (3, 3, 3), float64; the magnet's own +z is
    its moment direction."""
    keypoint_names: list = field(default_factory=list)
    """Keypoint names, length P: ``seg0..seg4`` (segment centres, tail -> head), ``tail``, ``head``."""
    keypoint_vertices: np.ndarray = field(default_factory=lambda: np.zeros((0, 1), np.int32))
    """Vertices averaged for each keypoint, shape (P, K), int32 (padding entries have weight 0)."""
    keypoint_weights: np.ndarray = field(default_factory=lambda: np.zeros((0, 1)))
    """Weights of those vertices, shape (P, K), float64, each row sums to 1."""
    meta: dict = field(default_factory=dict)
    """Design parameters (worm: ``a``, ``b``, ``alpha``, ``l0``, ``n_units``, ``kind``); informational."""

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, dtype=np.float64).reshape(-1, 3)
        self.triangles = np.asarray(self.triangles, dtype=np.int32).reshape(-1, 3)
        self.edges = np.asarray(self.edges, dtype=np.int32).reshape(-1, 2)
        self.edge_label = np.asarray(self.edge_label, dtype=np.int8).reshape(-1)
        self.edge_rest_length = np.asarray(self.edge_rest_length, dtype=np.float64).reshape(-1)
        self.hinges = np.asarray(self.hinges, dtype=np.int32).reshape(-1, 4)
        self.hinge_edge = np.asarray(self.hinge_edge, dtype=np.int32).reshape(-1)
        self.hinge_label = np.asarray(self.hinge_label, dtype=np.int8).reshape(-1)
        self.hinge_rest_angle = np.asarray(self.hinge_rest_angle, dtype=np.float64).reshape(-1)
        self.hinge_length = np.asarray(self.hinge_length, dtype=np.float64).reshape(-1)
        self.triangle_segment = np.asarray(self.triangle_segment, dtype=np.int32).reshape(-1)
        self.mount_vertices = np.asarray(self.mount_vertices, dtype=np.int32)
        self.mount_local_pos = np.asarray(self.mount_local_pos, dtype=np.float64).reshape(-1, 3)
        self.mount_local_rot = np.asarray(self.mount_local_rot, dtype=np.float64).reshape(-1, 3, 3)
        self.keypoint_names = list(self.keypoint_names)
        self.keypoint_vertices = np.asarray(self.keypoint_vertices, dtype=np.int32)
        self.keypoint_weights = np.asarray(self.keypoint_weights, dtype=np.float64)
        E, H, T = len(self.edges), len(self.hinges), len(self.triangles)
        checks = [
            (self.edge_label.shape == (E,), "edge_label"), (self.edge_rest_length.shape == (E,), "edge_rest_length"),
            (self.hinge_edge.shape == (H,), "hinge_edge"), (self.hinge_label.shape == (H,), "hinge_label"),
            (self.hinge_rest_angle.shape == (H,), "hinge_rest_angle"), (self.hinge_length.shape == (H,), "hinge_length"),
            (self.triangle_segment.shape == (T,), "triangle_segment"),
            (self.keypoint_vertices.shape == self.keypoint_weights.shape, "keypoint_weights"),
            (self.keypoint_vertices.shape[0] == len(self.keypoint_names), "keypoint_names"),
            (len(self.mount_local_pos) == len(self.mount_vertices) == len(self.mount_local_rot), "mount_*"),
        ]
        bad = [name for ok, name in checks if not ok]
        if bad:
            raise ValueError(f"CreasePattern: inconsistent shapes for {bad}")

    # --- sizes ---
    @property
    def num_vertices(self) -> int:
        return len(self.vertices)

    @property
    def num_triangles(self) -> int:
        return len(self.triangles)

    @property
    def num_edges(self) -> int:
        return len(self.edges)

    @property
    def num_hinges(self) -> int:
        return len(self.hinges)

    # --- evaluations on (batched) positions ---
    def keypoints(self, positions: np.ndarray | None = None) -> np.ndarray:
        """Keypoint positions [m], shape (..., P, 3), for vertex positions (..., V, 3) (default: rest)."""
        x = self.vertices if positions is None else np.asarray(positions, dtype=np.float64)
        return np.einsum("pk,...pkc->...pc", self.keypoint_weights, x[..., self.keypoint_vertices, :])

    def to_trimesh(self, positions: np.ndarray | None = None):
        """The surface as a ``trimesh.Trimesh`` (no processing, so vertex and face order are kept)."""
        import trimesh

        x = self.vertices if positions is None else np.asarray(positions, dtype=np.float64)
        return trimesh.Trimesh(vertices=x, faces=self.triangles, process=False)

    def label_dict(self) -> dict:
        """``{(v0, v1): label}`` for every edge (v0 < v1): the form :meth:`from_trimesh` takes."""
        return {(int(u), int(v)): int(lab) for (u, v), lab in zip(self.edges, self.edge_label)}

    @classmethod
    def from_trimesh(cls, mesh, crease_labels=None, *, flat_tol: float = 1e-6, mount_vertices=None,
                     mount_local_pos=None, mount_local_rot=None, axis: int = 0) -> "CreasePattern":
        """Crease pattern from any consistently oriented triangle mesh (rest geometry = the mesh's vertices).

        Args:
            mesh: ``trimesh.Trimesh`` (faces are taken as given: load with ``process=False`` to keep the order).
            crease_labels: ``None`` (infer from the rest dihedral: |ψ| <= ``flat_tol`` flat, ψ > 0 valley, ψ < 0
                mountain), a dict ``{(v0, v1): label}`` (either vertex order; missing interior edges are inferred), or an
                array (E,) aligned with the sorted unique edges this function derives (same as ``pattern.edges``).
                Boundary edges are always BOUNDARY.
            flat_tol: angle [rad] below which an inferred crease is flat.
            mount_vertices, mount_local_pos, mount_local_rot: optional IPM mounts (M, K), (M, 3), (M, 3, 3); default
                none.
            axis: body axis (0 = x) along which facets are split into the five segments and the tail / head / segment
                keypoints are placed.

        Rest angles are the measured dihedrals of the given geometry for every hinge, whatever its label, so the mesh
        is at rest as loaded.
        """
        x = np.asarray(mesh.vertices, dtype=np.float64)
        tri = np.asarray(mesh.faces, dtype=np.int64)
        edges, hinges, hinge_edge, boundary = _topology(tri, len(x))
        psi = dihedral_angles(x, hinges)
        labels = np.full(len(edges), FLAT, dtype=np.int8)
        labels[hinge_edge] = np.where(np.abs(psi) <= flat_tol, FLAT, np.where(psi > 0, VALLEY, MOUNTAIN))
        if crease_labels is not None:
            if isinstance(crease_labels, dict):
                index = {(int(u), int(v)): e for e, (u, v) in enumerate(edges)}
                for (u, v), lab in crease_labels.items():
                    key = (min(int(u), int(v)), max(int(u), int(v)))
                    if key not in index:
                        raise ValueError(f"crease_labels: ({u}, {v}) is not an edge of the mesh")
                    labels[index[key]] = lab
            else:
                arr = np.asarray(crease_labels, dtype=np.int8).reshape(-1)
                if arr.shape != (len(edges),):
                    raise ValueError(f"crease_labels: expected {len(edges)} labels (one per unique edge), got {arr.shape}")
                labels = arr.copy()
        labels[boundary] = BOUNDARY
        if np.any(labels[hinge_edge] == BOUNDARY):
            raise ValueError("crease_labels: an interior edge is labelled BOUNDARY")
        seg, kv, kw, names = _segments_and_keypoints(x, tri, axis)
        M = 0 if mount_vertices is None else len(mount_vertices)
        mv = np.zeros((0, 3), np.int32) if mount_vertices is None else mount_vertices
        mp = np.zeros((M, 3)) if mount_local_pos is None else mount_local_pos
        mr = np.broadcast_to(np.eye(3), (M, 3, 3)).copy() if mount_local_rot is None else mount_local_rot
        return cls(
            vertices=x, triangles=tri, edges=edges, edge_label=labels,
            edge_rest_length=np.linalg.norm(x[edges[:, 1]] - x[edges[:, 0]], axis=1),
            hinges=hinges, hinge_edge=hinge_edge, hinge_label=labels[hinge_edge], hinge_rest_angle=psi,
            hinge_length=np.linalg.norm(x[hinges[:, 2]] - x[hinges[:, 1]], axis=1),
            triangle_segment=seg, mount_vertices=mv, mount_local_pos=mp, mount_local_rot=mr,
            keypoint_names=names, keypoint_vertices=kv, keypoint_weights=kw, meta={"kind": "mesh"},
        )


# ----------------------------------------------------------------------------------------------------------------
# Geometry helpers (batched NumPy)
# ----------------------------------------------------------------------------------------------------------------

def dihedral_angles(positions: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """Signed fold angle ψ [rad] of every hinge, shape (..., H), for positions (..., V, 3) and stencils (H, 4).

    ψ = atan2((n1 × n2)·e, n1·n2), n1 = (x_j − x_i) × (x_k − x_i), n2 = (x_k − x_l) × (x_j − x_l),
    e = (x_j − x_k)/|x_j − x_k|: 0 flat, > 0 valley, < 0 mountain (module docstring). atan2 keeps full precision near
    0 and ±π, unlike arccos.
    """
    x = np.asarray(positions, dtype=np.float64)
    h = np.asarray(hinges)
    xi, xj, xk, xl = (x[..., h[:, c], :] for c in range(4))
    n1 = np.cross(xj - xi, xk - xi)
    n2 = np.cross(xk - xl, xj - xl)
    e = xj - xk
    e = e / np.linalg.norm(e, axis=-1, keepdims=True)
    s = np.einsum("...c,...c->...", np.cross(n1, n2), e)
    c = np.einsum("...c,...c->...", n1, n2)
    return np.arctan2(s, c)


def dihedral_gradients(positions: np.ndarray, hinges: np.ndarray) -> np.ndarray:
    """∂ψ/∂x of every hinge's four stencil vertices, shape (..., H, 4, 3) [rad/m] (MERLIN's exact gradient, with
    ψ = π − θ_MERLIN): a reference for the dynamics kernels."""
    x = np.asarray(positions, dtype=np.float64)
    h = np.asarray(hinges)
    xi, xj, xk, xl = (x[..., h[:, c], :] for c in range(4))
    n1 = np.cross(xj - xi, xk - xi)
    n2 = np.cross(xk - xl, xj - xl)
    rkj = xk - xj
    L2 = np.einsum("...c,...c->...", rkj, rkj)
    L = np.sqrt(L2)
    gi = (L / np.einsum("...c,...c->...", n1, n1))[..., None] * n1
    gl = (L / np.einsum("...c,...c->...", n2, n2))[..., None] * n2
    # Projections of the wings onto the hinge axis distribute the (translation- and rotation-free) remainder.
    pi = (np.einsum("...c,...c->...", xi - xj, rkj) / L2)[..., None]
    pl = (np.einsum("...c,...c->...", xk - xl, rkj) / L2)[..., None]
    gj = (pi - 1.0) * gi - pl * gl
    gk = (pl - 1.0) * gl - pi * gi
    return np.stack([gi, gj, gk, gl], axis=-2)


def edge_lengths(positions: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Length of every edge [m], shape (..., E), for positions (..., V, 3)."""
    x = np.asarray(positions, dtype=np.float64)
    return np.linalg.norm(x[..., edges[:, 1], :] - x[..., edges[:, 0], :], axis=-1)


def rigidity_matrix(positions: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Compatibility (rigidity) matrix C, shape (E, 3V): row e maps vertex velocities (3V,) to the rate of change of
    bar e's length [m/s per m/s], C[e, 3 v1 : 3 v1 + 3] = unit(x_v1 − x_v0) = −C[e, 3 v0 : 3 v0 + 3]."""
    x = np.asarray(positions, dtype=np.float64)
    E, V = len(edges), len(x)
    d = x[edges[:, 1]] - x[edges[:, 0]]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    C = np.zeros((E, V, 3))
    C[np.arange(E), edges[:, 1]] = d
    C[np.arange(E), edges[:, 0]] = -d
    return C.reshape(E, 3 * V)


def compression_mode(pattern: CreasePattern, released: np.ndarray | None = None):
    """Cheapest small axial shortening of a pattern in its rest pose (linear bar-and-hinge analysis, bars only).

    Finds the vertex displacement u (V, 3) that shortens the distance tail -> head keypoint (along x) by 1 m per
    metre of displacement, with no rigid motion, minimising the bar energy Σ_e (Δl_e)² / l_e (equal axial rigidity
    EA) over the bars not ``released`` (mask (E,)). Returns (u (V, 3), strain per bar (E,) [1/m of shortening],
    energy Σ l ε² over the kept bars [1/m]; the axial stiffness is EA times it).

    For the worm with every bar kept the tube is isostatic (rank 3V − 6) and the energy is finite (≈ 4.3 m⁻¹ for
    the defaults: 4.3e4 N/m at EA = 1e4 N); with ``released = edge_label == VALLEY`` it is ≈ 0: a mechanism.
    """
    x = pattern.vertices
    V = len(x)
    keep = np.ones(pattern.num_edges, bool) if released is None else ~np.asarray(released, bool)
    C = rigidity_matrix(x, pattern.edges)
    L = pattern.edge_rest_length
    K = C[keep].T @ (C[keep] / L[keep, None])
    names = pattern.keypoint_names
    g = np.zeros((V, 3))
    for name, sgn in (("head", 1.0), ("tail", -1.0)):  # x(head) − x(tail), a weighted mean of vertices
        p = names.index(name)
        np.add.at(g[:, 0], pattern.keypoint_vertices[p], sgn * pattern.keypoint_weights[p])
    rigid = [np.tile(np.eye(3)[c], V) for c in range(3)]
    rigid += [np.cross(np.eye(3)[c], x - x.mean(0)).ravel() for c in range(3)]
    G = np.vstack([g.ravel()] + rigid)
    rhs = np.zeros(len(G))
    rhs[0] = -1.0
    kkt = np.block([[K, G.T], [G, np.zeros((len(G), len(G)))]])
    sol = np.linalg.lstsq(kkt, np.r_[np.zeros(3 * V), rhs], rcond=None)[0]
    u = sol[: 3 * V]
    strain = (C @ u) / L
    energy = float(np.sum(L[keep] * strain[keep] ** 2))
    return u.reshape(V, 3), strain, energy


def frame_from_vertices(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body frame of a ring of mount vertices: points (..., K, 3) -> origin (..., 3) [m], R (..., 3, 3) (frame -> world).

    origin = centroid; x axis = the ring's normal by Newell's rule (right-handed about the ring order; for the worm's
    sections it points forward, +x); y axis = direction from the centroid to the first point, made orthogonal to x;
    z = x × y. Works for any K >= 3 and any deformation that keeps the ring non-degenerate.
    """
    p = np.asarray(points, dtype=np.float64)
    origin = p.mean(axis=-2)
    q = p - origin[..., None, :]
    # Newell: sum of cross products of consecutive points; robust for non-planar rings.
    nx = np.cross(q, np.roll(q, -1, axis=-2)).sum(axis=-2)
    ex = nx / np.linalg.norm(nx, axis=-1, keepdims=True)
    y = q[..., 0, :]
    y = y - np.einsum("...c,...c->...", y, ex)[..., None] * ex
    ey = y / np.linalg.norm(y, axis=-1, keepdims=True)
    ez = np.cross(ex, ey)
    return origin, np.stack([ex, ey, ez], axis=-1)


def mount_poses(pattern: CreasePattern, positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World poses of the IPMs for positions (..., V, 3) (default: rest): pos (..., M, 3) [m], rot (..., M, 3, 3)
    (magnet -> world; the magnet's own +z is its moment direction)."""
    x = pattern.vertices if positions is None else np.asarray(positions, dtype=np.float64)
    origin, R = frame_from_vertices(x[..., pattern.mount_vertices, :])
    pos = origin + np.einsum("...mij,mj->...mi", R, pattern.mount_local_pos)
    rot = np.einsum("...mij,mjk->...mik", R, pattern.mount_local_rot)
    return pos, rot


# ----------------------------------------------------------------------------------------------------------------
# The worm
# ----------------------------------------------------------------------------------------------------------------

def rest_alpha(l0, b, n) -> np.ndarray | float:
    """Rest fold angle α [rad] from eq. (7): α = π − arccos(1 − (l0/n)² / (2 b²)), i.e. l0/n = 2 b cos(α/2).

    Args:
        l0: worm rest length [m], scalar or array.
        b: panel length [m], scalar or array (broadcasts with l0).
        n: number of units.
    Raises ValueError when l0/n is not in (0, 2b] (a unit cannot be longer than its two unfolded panels).
    """
    l0 = np.asarray(l0, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    u = l0 / n
    if np.any(u <= 0) or np.any(b <= 0):
        raise ValueError(f"rest_alpha: need l0 > 0 and b > 0 (got l0={l0}, b={b}, n={n})")
    ratio = u / (2.0 * b)
    if np.any(ratio > 1.0 + 1e-12):
        raise ValueError(f"rest_alpha: unit length l0/n = {u} exceeds 2b = {2 * b}: the panels cannot span it")
    cos_pi_minus = np.clip(1.0 - u**2 / (2.0 * b**2), -1.0, 1.0)
    alpha = np.pi - np.arccos(cos_pi_minus)
    return float(alpha) if alpha.ndim == 0 else alpha


def unit_length(b, alpha) -> np.ndarray | float:
    """Length of one unit [m] at fold angle α: u = 2 b cos(α/2) (inverse of :func:`rest_alpha`)."""
    u = 2.0 * np.asarray(b, dtype=np.float64) * np.cos(0.5 * np.asarray(alpha, dtype=np.float64))
    return float(u) if u.ndim == 0 else u


# Cross-section vertex k sits at polar angle _SECTION_ANGLES[k] about the axis, counter-clockwise about +x
# (from +y toward +z): k = 0 bottom-left, 1 bottom-right (the floor face 0–1), 2 top. CCW about +x is what makes
# the quads below outward-oriented and the mount frames' x axis point forward.
_SECTION_ANGLES = np.deg2rad([-150.0, -30.0, 90.0])


def worm_vertices(a, b, alpha, n_units: int) -> np.ndarray:
    """Rest vertices of the worm for one or many (a, b, α): shape (V, 3) for scalars, (W, V, 3) for arrays (W,).

    Vertex ``3 s + k`` is corner k of section s (s = 0 .. 2n tail -> head; even s unit boundaries, odd s unit
    middles). All sections share the axis y = 0, z = a/(2√3) (the full triangles' inradius) so the full sections
    touch the floor z = 0 with their face 0–1.

    Args:
        a: cross-section side [m]; b: panel length [m]; alpha: rest fold angle [rad]; each scalar or (W,).
        n_units: number of units (shared topology).
    Raises ValueError when an inset section would vanish (b sin(α/2) >= a/(2√3)) or α is outside [0, π).
    """
    a_, b_, al_ = (np.asarray(v, dtype=np.float64) for v in (a, b, alpha))
    scalar = a_.ndim == b_.ndim == al_.ndim == 0
    a_, b_, al_ = np.broadcast_arrays(np.atleast_1d(a_), np.atleast_1d(b_), np.atleast_1d(al_))
    if n_units < 1:
        raise ValueError(f"worm_vertices: n_units must be >= 1, got {n_units}")
    if np.any(a_ <= 0) or np.any(b_ <= 0) or np.any(al_ < 0) or np.any(al_ >= np.pi):
        raise ValueError("worm_vertices: need a > 0, b > 0 and 0 <= alpha < pi")
    r = a_ / (2.0 * np.sqrt(3.0))  # inradius of the full section [m]
    d = b_ * np.sin(0.5 * al_)  # how far each face moves in at a unit middle [m]
    if np.any(d >= r):
        raise ValueError(
            f"worm_vertices: b sin(alpha/2) = {d.max():.6g} m must be below the section's inradius a/(2*sqrt(3)) = "
            f"{r.min():.6g} m, or the unit middles pinch to nothing")
    half = b_ * np.cos(0.5 * al_)  # half a unit along x [m]
    S = 2 * n_units + 1
    s = np.arange(S)
    inset = (s % 2 == 1).astype(np.float64)
    xs = s[None, :] * half[:, None]  # (W, S)
    circ = 2.0 * (r[:, None] - inset[None, :] * d[:, None])  # circumradius of each section, (W, S)
    cy, cz = np.cos(_SECTION_ANGLES), np.sin(_SECTION_ANGLES)
    W = len(a_)
    v = np.empty((W, S, 3, 3))
    v[..., 0] = xs[:, :, None]
    v[..., 1] = circ[:, :, None] * cy
    v[..., 2] = r[:, None, None] + circ[:, :, None] * cz
    v = v.reshape(W, 3 * S, 3)
    return v[0] if scalar else v


def worm_triangles(n_units: int) -> np.ndarray:
    """Outward-oriented facets of the worm tube, shape (12 n, 3), int32 (same for every (a, b, α))."""
    S = 2 * n_units + 1
    s = np.arange(S - 1)[:, None]
    k = np.arange(3)[None, :]
    A = 3 * s + k  # section s, corner k
    B = 3 * s + (k + 1) % 3  # section s, corner k + 1
    C = B + 3  # section s + 1, corner k + 1
    D = A + 3  # section s + 1, corner k
    even = np.broadcast_to((s % 2 == 0), A.shape)
    # Quad (A, B, C, D) is CCW seen from outside. Diagonal A–C in even half units, B–D in odd ones: mirror symmetry
    # of each unit about its middle section.
    t1 = np.where(even[..., None], np.stack([A, B, C], -1), np.stack([A, B, D], -1))
    t2 = np.where(even[..., None], np.stack([A, C, D], -1), np.stack([B, C, D], -1))
    return np.stack([t1, t2], axis=2).reshape(-1, 3).astype(np.int32)


def build_worm(a: float, b: float, n_units: int, l0: float | None = None, alpha: float | None = None) -> CreasePattern:
    """The paper's triangular-prism worm (Fig. 3) as a :class:`CreasePattern` at rest.

    Args:
        a: side of the triangular cross-section [m].
        b: length of each of a unit's two panels along the worm (unfolded) [m].
        n_units: number of units (>= 1); an even n puts the centre IPM on a unit boundary.
        l0: rest length of the worm [m] (sets α by eq. (7)); or
        alpha: rest fold angle [rad]. Give exactly one of l0 / alpha.

    Mounts: tail (section 0), centre (section n, the middle, for even n; for odd n the middle is a unit middle whose
    inset section is too small for a disk, so the unit boundary just tail-side of it, section n − 1, u/2 off-centre)
    and head (section 2n). Each IPM is centred on its section, its moment (own +z) along −x, +x, −x at rest.
    """
    if (l0 is None) == (alpha is None):
        raise ValueError("build_worm: give exactly one of l0 or alpha")
    n = int(n_units)
    if n < 1:
        raise ValueError(f"build_worm: n_units must be >= 1, got {n_units}")
    if alpha is None:
        alpha = rest_alpha(l0, b, n)
    alpha = float(alpha)
    x = worm_vertices(float(a), float(b), alpha, n)
    tri = worm_triangles(n)
    edges, hinges, hinge_edge, boundary = _topology(tri, len(x))
    S = 2 * n + 1
    sec = edges // 3  # section of each edge end
    ring = sec[:, 0] == sec[:, 1]
    corner = (~ring) & (edges[:, 0] % 3 == edges[:, 1] % 3)
    labels = np.full(len(edges), FLAT, dtype=np.int8)
    labels[ring & (sec[:, 0] % 2 == 1)] = VALLEY
    labels[ring & (sec[:, 0] % 2 == 0)] = MOUNTAIN
    labels[corner] = MOUNTAIN
    labels[boundary] = BOUNDARY
    assert np.all(boundary == (ring & ((sec[:, 0] == 0) | (sec[:, 0] == S - 1))))
    hl = labels[hinge_edge]
    h_ring = ring[hinge_edge]
    rest = np.zeros(len(hinges))
    rest[h_ring & (hl == VALLEY)] = alpha
    rest[h_ring & (hl == MOUNTAIN)] = -alpha
    # Corner creases: their angle is set by the prism, not by α; use the built dihedral so the worm is at rest.
    hc = corner[hinge_edge]
    rest[hc] = dihedral_angles(x, hinges[hc])
    seg = _worm_segments(x, tri, n)
    kv, kw, names = _worm_keypoints(n)
    mid = n if n % 2 == 0 else n - 1
    mount_sections = np.array([0, mid, 2 * n])
    mv = 3 * mount_sections[:, None] + np.arange(3)[None, :]
    # In the mount frame x is forward (+x at rest): tail and head moments along −x, centre along +x.
    rot_fwd = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])  # own z -> frame +x
    rot_back = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # own z -> frame −x
    mr = np.stack([rot_back, rot_fwd, rot_back])
    return CreasePattern(
        vertices=x, triangles=tri, edges=edges, edge_label=labels, edge_rest_length=edge_lengths(x, edges),
        hinges=hinges, hinge_edge=hinge_edge, hinge_label=hl, hinge_rest_angle=rest,
        hinge_length=np.linalg.norm(x[hinges[:, 2]] - x[hinges[:, 1]], axis=1), triangle_segment=seg,
        mount_vertices=mv, mount_local_pos=np.zeros((3, 3)), mount_local_rot=mr,
        keypoint_names=names, keypoint_vertices=kv, keypoint_weights=kw,
        meta={"kind": "worm", "a": float(a), "b": float(b), "alpha": alpha, "n_units": n,
              "l0": float(n * unit_length(b, alpha))},
    )


def worm_rest_state(a, b, alpha, n_units: int, pattern: CreasePattern | None = None):
    """Per-world rest geometry on one topology: (vertices (W, V, 3), edge rest lengths (W, E), hinge rest angles
    (W, H)) for arrays (W,) of a, b, α. Every hinge's rest angle is its built dihedral, which equals ±α for the
    transverse creases and 0 for the diagonals exactly (pass ``pattern`` to reuse its topology)."""
    p = build_worm(float(np.ravel(a)[0]), float(np.ravel(b)[0]), n_units, alpha=float(np.ravel(alpha)[0])) \
        if pattern is None else pattern
    x = worm_vertices(np.atleast_1d(a), np.atleast_1d(b), np.atleast_1d(alpha), n_units)
    return x, edge_lengths(x, p.edges), dihedral_angles(x, p.hinges)


# ----------------------------------------------------------------------------------------------------------------
# Topology, segments, keypoints
# ----------------------------------------------------------------------------------------------------------------

def _topology(tri: np.ndarray, num_vertices: int):
    """Edges (E, 2) sorted, hinge stencils (H, 4), hinge -> edge (H,), boundary mask (E,) from oriented triangles.

    Raises ValueError for a non-manifold edge (> 2 facets) or two facets traversing an edge the same way
    (inconsistent orientation).
    """
    tri = np.asarray(tri, dtype=np.int64)
    T = len(tri)
    if T == 0:
        raise ValueError("crease pattern: no triangles")
    if tri.min() < 0 or tri.max() >= num_vertices:
        raise ValueError("crease pattern: triangle index out of range")
    # Directed half-edges (j -> k) of each facet and the facet's third vertex i: facet is (i, j, k) cyclically.
    j = tri.reshape(-1)
    k = np.roll(tri, -1, axis=1).reshape(-1)
    i = np.roll(tri, 1, axis=1).reshape(-1)
    lo, hi = np.minimum(j, k), np.maximum(j, k)
    key = lo * num_vertices + hi
    uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
    if np.any(counts > 2):
        raise ValueError(f"crease pattern: {np.sum(counts > 2)} non-manifold edges (shared by more than 2 facets)")
    edges = np.stack([uniq // num_vertices, uniq % num_vertices], axis=1)
    boundary = counts == 1
    # Pair the two half-edges of each interior edge: the one going lo -> hi and the one going hi -> lo.
    fwd = j < k
    E = len(uniq)
    first = np.full(E, -1)
    second = np.full(E, -1)
    first[inv[fwd]] = np.nonzero(fwd)[0]
    second[inv[~fwd]] = np.nonzero(~fwd)[0]
    interior = ~boundary
    if np.any(interior & ((first < 0) | (second < 0))):
        raise ValueError("crease pattern: triangles are not consistently oriented (an edge is traversed the same "
                         "way by both facets)")
    he = np.nonzero(interior)[0]
    a_, b_ = first[he], second[he]  # a_: facet (i, j=lo, k=hi); b_: facet traverses hi -> lo, its third vertex is l
    hinges = np.stack([i[a_], j[a_], k[a_], i[b_]], axis=1)
    return edges.astype(np.int32), hinges.astype(np.int32), he.astype(np.int32), boundary


def _segment_of(xc: np.ndarray, x0: float, x1: float) -> np.ndarray:
    return np.clip(np.floor((xc - x0) / (x1 - x0) * NUM_SEGMENTS), 0, NUM_SEGMENTS - 1).astype(np.int32)


def _worm_segments(x: np.ndarray, tri: np.ndarray, n: int) -> np.ndarray:
    # The five equal segments of the whole length; a facet belongs to the one holding its centroid. Using section
    # indices (not metres) makes the split independent of (a, b, α).
    s = (tri // 3).mean(axis=1)  # centroid "section coordinate" (sections are equally spaced in x)
    return _segment_of(s, 0.0, 2.0 * n)


def _worm_keypoints(n: int):
    """Keypoints of the worm as weighted means of section corners: (P, 6) vertices and weights, names.

    Every section's corner mean lies on the axis, so a point at section coordinate σ (x = σ u/2) is a linear blend of
    the two sections around it. The blend weights do not depend on (a, b, α).
    """
    S = 2 * n + 1
    sigma = (np.arange(NUM_SEGMENTS) + 0.5) * (S - 1) / NUM_SEGMENTS
    sigma = np.concatenate([sigma, [0.0, S - 1.0]])
    s0 = np.minimum(np.floor(sigma).astype(int), S - 2)
    t = sigma - s0
    kv = np.concatenate([3 * s0[:, None] + np.arange(3), 3 * (s0 + 1)[:, None] + np.arange(3)], axis=1)
    kw = np.concatenate([np.repeat(((1 - t) / 3)[:, None], 3, 1), np.repeat((t / 3)[:, None], 3, 1)], axis=1)
    names = [f"seg{i}" for i in range(NUM_SEGMENTS)] + ["tail", "head"]
    return kv.astype(np.int32), kw, names


def _segments_and_keypoints(x: np.ndarray, tri: np.ndarray, axis: int):
    """Generic mesh: facets split into five equal bins along ``axis``; keypoints = mean of the vertices in each bin
    (seg0..4) and of the vertices at the two extremes (tail, head)."""
    c = x[:, axis]
    x0, x1 = c.min(), c.max()
    if x1 <= x0:
        x1 = x0 + 1.0
    seg = _segment_of(x[tri, axis].mean(axis=1), x0, x1)
    tol = 1e-9 * max(1.0, np.abs(x).max())
    vseg = _segment_of(c, x0, x1)
    groups = [np.nonzero(vseg == i)[0] for i in range(NUM_SEGMENTS)]
    groups += [np.nonzero(c <= x0 + tol)[0], np.nonzero(c >= x1 - tol)[0]]
    groups = [g if len(g) else np.array([np.argmin(np.abs(c - 0.5 * (x0 + x1)))]) for g in groups]
    K = max(len(g) for g in groups)
    kv = np.zeros((len(groups), K), np.int32)
    kw = np.zeros((len(groups), K))
    for p, g in enumerate(groups):  # seven keypoints: a loop over them is fine
        kv[p, : len(g)] = g
        kv[p, len(g):] = g[0]
        kw[p, : len(g)] = 1.0 / len(g)
    names = [f"seg{i}" for i in range(NUM_SEGMENTS)] + ["tail", "head"]
    return seg, kv, kw, names


# ----------------------------------------------------------------------------------------------------------------
# Files
# ----------------------------------------------------------------------------------------------------------------

def load_pattern(path, labels=None, **kwargs) -> CreasePattern:
    """Load a triangle mesh (PLY, OBJ, GLB, STL, ...) with trimesh, unprocessed, and make a crease pattern of it.

    ``labels`` as in :meth:`CreasePattern.from_trimesh` (None infers mountain / valley / flat from the geometry);
    ``kwargs`` go to it too. A GLB written by :func:`export_mesh` is read back from its ``surface`` node.
    """
    import trimesh

    loaded = trimesh.load(str(path), process=False)
    if isinstance(loaded, trimesh.Scene):
        geoms = loaded.geometry
        meshes = [name for name, g in geoms.items() if isinstance(g, trimesh.Trimesh)]
        if "surface" in geoms:
            name = "surface"
        elif len(meshes) == 1:
            name = meshes[0]
        else:
            raise ValueError(f"load_pattern: {path} holds {len(meshes)} meshes and none is named 'surface'")
        mesh = geoms[name].copy()
        # A glTF node may carry a transform: take the mesh in scene coordinates.
        nodes = loaded.graph.geometry_nodes.get(name, [])
        if nodes:
            mesh.apply_transform(loaded.graph[nodes[0]][0])
    else:
        mesh = loaded
    return CreasePattern.from_trimesh(mesh, labels, **kwargs)


def _crease_ribbons(x: np.ndarray, pattern: CreasePattern, mask: np.ndarray, width: float):
    """Thin triangular prisms along the masked hinges' creases, lifted slightly off the surface so a viewer shows
    them above the facets: (vertices (6C, 3), faces (8C, 3))."""
    h = pattern.hinges[mask]
    xi, xj, xk, xl = (x[h[:, c]] for c in range(4))
    e = xk - xj
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    n1 = np.cross(xj - xi, xk - xi)
    n2 = np.cross(xk - xl, xj - xl)
    nrm = n1 / np.linalg.norm(n1, axis=1, keepdims=True) + n2 / np.linalg.norm(n2, axis=1, keepdims=True)
    nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-12)
    side = np.cross(e, nrm)
    off = [0.5 * width * nrm + 0.5 * width * side, 0.5 * width * nrm - 0.5 * width * side, 1.5 * width * nrm]
    v = np.concatenate([np.stack([xj + o for o in off], 1), np.stack([xk + o for o in off], 1)], axis=1)  # (C, 6, 3)
    base = 6 * np.arange(len(h))[:, None, None]
    f = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5], [0, 2, 1], [3, 4, 5]])
    return v.reshape(-1, 3), (base + f[None]).reshape(-1, 3)


def export_mesh(pattern: CreasePattern, path, positions: np.ndarray | None = None, *, creases: bool = True,
                crease_width: float | None = None) -> Path:
    """Write the pattern (at rest or at ``positions`` (V, 3)) with trimesh; the format follows the suffix.

    GLB / glTF: a scene with the node ``surface`` (the facets, paper-white; :func:`load_pattern` reads it back) and,
    with ``creases``, nodes ``valley`` (red) and ``mountain`` (blue): thin prisms along those creases, as in the
    paper's Fig. 3. Other formats (PLY, OBJ, ...) get one mesh: the surface first (its V vertices and T faces keep
    their order), then the crease prisms, with face colours; pass ``creases=False`` for a bare surface.
    ``crease_width`` [m] defaults to 0.4 % of the surface's bounding-box diagonal.
    """
    import trimesh

    path = Path(path)
    x = pattern.vertices if positions is None else np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    surface = trimesh.Trimesh(vertices=x, faces=pattern.triangles, process=False)
    surface.visual.face_colors = np.broadcast_to(SHEET_RGBA, (len(pattern.triangles), 4))
    if crease_width is None:
        crease_width = 0.004 * float(np.linalg.norm(np.ptp(x, axis=0)))
    parts = []
    if creases:
        for name, lab, rgba in (("valley", VALLEY, VALLEY_RGBA), ("mountain", MOUNTAIN, MOUNTAIN_RGBA)):
            mask = pattern.hinge_label == lab
            if not np.any(mask):
                continue
            v, f = _crease_ribbons(x, pattern, mask, crease_width)
            m = trimesh.Trimesh(vertices=v, faces=f, process=False)
            m.visual.face_colors = np.broadcast_to(rgba, (len(f), 4))
            parts.append((name, m))
    suffix = path.suffix.lower()
    path.parent.mkdir(parents=True, exist_ok=True)
    if suffix in (".glb", ".gltf"):
        scene = trimesh.Scene()
        scene.add_geometry(surface, geom_name="surface", node_name="surface")
        for name, m in parts:
            scene.add_geometry(m, geom_name=name, node_name=name)
        scene.export(str(path))
    else:
        mesh = trimesh.util.concatenate([surface] + [m for _, m in parts]) if parts else surface
        mesh.export(str(path))
    return path
