""":class:`CreasePattern`: the bar-and-hinge description of an origami sheet as NumPy data (vertices, triangles, labelled
bars, hinge stencils with rest angles, segments, IPM mounts, keypoints), from the worm's builder or any triangle mesh;
the IPM mounts' poses and the compression mode of a pattern."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from warpworm.ids import BOUNDARY, CREASE_LABEL_NAMES, FLAT, MOUNTAIN, VALLEY
from warpworm.physics.crease.geometry import dihedral_angles, frame_from_vertices, rigidity_matrix
from warpworm.physics.crease.topology import segments_and_keypoints, topology

LABEL_NAMES = CREASE_LABEL_NAMES
"""FLAT, MOUNTAIN, VALLEY, BOUNDARY (from warpworm.ids): the edge / hinge labels (int8), by name."""
MOUNT_NAMES = ("tail", "centre", "head")


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
        import trimesh  # start-up time: trimesh loads on first use

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
        edges, hinges, hinge_edge, boundary = topology(tri, len(x))
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
        seg, kv, kw, names = segments_and_keypoints(x, tri, axis)
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


def mount_poses(pattern: CreasePattern, positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World poses of the IPMs for positions (..., V, 3) (default: rest): pos (..., M, 3) [m], rot (..., M, 3, 3)
    (magnet -> world; the magnet's own +z is its moment direction)."""
    x = pattern.vertices if positions is None else np.asarray(positions, dtype=np.float64)
    origin, R = frame_from_vertices(x[..., pattern.mount_vertices, :])
    pos = origin + np.einsum("...mij,mj->...mi", R, pattern.mount_local_pos)
    rot = np.einsum("...mij,mjk->...mik", R, pattern.mount_local_rot)
    return pos, rot
