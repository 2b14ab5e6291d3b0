"""A triangle mesh's bar-and-hinge topology (edges, hinge stencils, boundary), and the worm's five segments and
keypoints along its axis."""

from __future__ import annotations

import numpy as np

NUM_SEGMENTS = 5
"""The paper's five equal segments along the worm (tail -> head)."""


def topology(tri: np.ndarray, num_vertices: int):
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


def worm_segments(x: np.ndarray, tri: np.ndarray, n: int) -> np.ndarray:
    # The five equal segments of the whole length; a facet belongs to the one holding its centroid. Using section
    # indices (not metres) makes the split independent of (a, b, α).
    s = (tri // 3).mean(axis=1)  # centroid "section coordinate" (sections are equally spaced in x)
    return _segment_of(s, 0.0, 2.0 * n)


def worm_keypoints(n: int):
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


def segments_and_keypoints(x: np.ndarray, tri: np.ndarray, axis: int):
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
