"""Batched NumPy geometry of a crease pattern's shapes: signed dihedral angles and their gradients, bar lengths, the
rigidity matrix, the frames the IPM mounts are placed in."""

from __future__ import annotations

import numpy as np


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
