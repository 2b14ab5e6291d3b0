"""The worm's pattern (paper §III, eq. 7): the triangular-prism bellows of ``n_units`` units, its rest fold angle and
unit length, its vertices for any (a, b, α) on one topology."""

from __future__ import annotations

import numpy as np

from warpworm.ids import BOUNDARY, FLAT, MOUNTAIN, VALLEY
from warpworm.physics.crease.geometry import dihedral_angles, edge_lengths
from warpworm.physics.crease.pattern import CreasePattern
from warpworm.physics.crease.topology import topology, worm_keypoints, worm_segments


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
    edges, hinges, hinge_edge, boundary = topology(tri, len(x))
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
    seg = worm_segments(x, tri, n)
    kv, kw, names = worm_keypoints(n)
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
