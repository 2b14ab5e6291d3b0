"""Block-banded Cholesky factorisation and solve of one world's symmetric positive definite 3V × 3V system, in place.

The matrix is kept as 3×3 vertex blocks: a world's lower block-banded part is a row of a (W, V, B + 1) ``mat33`` array,
``mat[world, u, d]`` = A[u, u − d] for 0 ≤ d ≤ B (the diagonal blocks stored whole). The worm's vertices are
numbered section by section along its axis, so a bar or crease couples vertices at most 6 apart (B = 6): a
factorisation is ~V (B + 1)(B + 2) / 2 ≈ 1100 block products. Blocks, not scalars, because a Warp CPU thread pays a
few ns per loop iteration whatever the body, so 3×3 blocks in registers beat the scalar banded matrix's n B² / 2 ≈ 2.3e4
iterations (docs/dynamics.md, "Notes moved from the code"). No atomics, no pivoting.

After :func:`banded_cholesky_factor` the diagonal slot holds the *inverse* of the diagonal factor block, L_uu⁻¹,
which is what the solves and the off-diagonal blocks need.
"""

from __future__ import annotations

import warp as wp


@wp.func
def inverse_lower_cholesky3(s: wp.mat33):
    """L⁻¹ for the lower-triangular L with L Lᵀ = s (a non-positive pivot is clamped so the result stays finite)."""
    l00 = wp.sqrt(wp.max(s[0, 0], 1.0e-30))
    l10 = s[1, 0] / l00
    l20 = s[2, 0] / l00
    l11 = wp.sqrt(wp.max(s[1, 1] - l10 * l10, 1.0e-30))
    l21 = (s[2, 1] - l20 * l10) / l11
    l22 = wp.sqrt(wp.max(s[2, 2] - l20 * l20 - l21 * l21, 1.0e-30))
    i00 = 1.0 / l00
    i11 = 1.0 / l11
    i22 = 1.0 / l22
    i10 = -l10 * i00 * i11
    i21 = -l21 * i11 * i22
    i20 = -(l20 * i00 + l21 * i10) * i22
    return wp.mat33(i00, 0.0, 0.0, i10, i11, 0.0, i20, i21, i22)


@wp.func
def banded_cholesky_factor(world: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33)):
    """A = L Lᵀ in place for one world: off-diagonal blocks become L[u, v], diagonal slots L[u, u]⁻¹."""
    for j in range(nv):
        s = mat[world, j, 0]
        for k in range(wp.max(0, j - bw), j):
            l = mat[world, j, j - k]
            s = s - l * wp.transpose(l)
        inv = inverse_lower_cholesky3(s)
        mat[world, j, 0] = inv
        inv_t = wp.transpose(inv)
        for i in range(j + 1, wp.min(nv, j + bw + 1)):
            t = mat[world, i, i - j]
            for k in range(wp.max(0, i - bw), j):
                t = t - mat[world, i, i - k] * wp.transpose(mat[world, j, j - k])
            mat[world, i, i - j] = t * inv_t
    return 0


UNROLLED_HALF_BANDWIDTH = wp.constant(6)
"""The worm's half-bandwidth (``Model.half_bandwidth``), whose solve runs with its inner loops unrolled."""


@wp.func
def banded_cholesky_solve(world: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33),
                        rhs: wp.array2d(dtype=wp.vec3)):
    """Solve L Lᵀ y = rhs in place (``rhs[world]`` overwritten by y) with the factor of :func:`banded_cholesky_factor`.
    At ``bw`` = :data:`UNROLLED_HALF_BANDWIDTH` the inner loops have constant trip counts (unrolled by Warp; the same
    operations in the same order, so the same bits: ~20 % less time in a micro-benchmark)."""
    if bw == UNROLLED_HALF_BANDWIDTH:
        return banded_cholesky_solve_unrolled(world, nv, mat, rhs)
    return banded_cholesky_solve_loops(world, nv, bw, mat, rhs)


@wp.func
def banded_cholesky_solve_loops(world: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33),
                              rhs: wp.array2d(dtype=wp.vec3)):
    """:func:`banded_cholesky_solve` at any half-bandwidth ``bw``, loops with variable trip counts."""
    for j in range(nv):
        t = rhs[world, j]
        for k in range(wp.max(0, j - bw), j):
            t = t - mat[world, j, j - k] * rhs[world, k]
        rhs[world, j] = mat[world, j, 0] * t
    for jj in range(nv):
        j = nv - 1 - jj
        t = rhs[world, j]
        for i in range(j + 1, wp.min(nv, j + bw + 1)):
            t = t - wp.transpose(mat[world, i, i - j]) * rhs[world, i]
        rhs[world, j] = wp.transpose(mat[world, j, 0]) * t
    return 0


@wp.func
def banded_cholesky_solve_unrolled(world: int, nv: int, mat: wp.array3d(dtype=wp.mat33), rhs: wp.array2d(dtype=wp.vec3)):
    """:func:`banded_cholesky_solve` at half-bandwidth :data:`UNROLLED_HALF_BANDWIDTH`: k = j − d for d from the half-bandwidth down
    to 1 (k ascending, as there), i = j + d for d from 1 up."""
    for j in range(nv):
        t = rhs[world, j]
        for dd in range(UNROLLED_HALF_BANDWIDTH):
            d = UNROLLED_HALF_BANDWIDTH - dd
            if d <= j:
                t = t - mat[world, j, d] * rhs[world, j - d]
        rhs[world, j] = mat[world, j, 0] * t
    for jj in range(nv):
        j = nv - 1 - jj
        t = rhs[world, j]
        for d in range(1, UNROLLED_HALF_BANDWIDTH + 1):
            if j + d < nv:
                t = t - wp.transpose(mat[world, j + d, d]) * rhs[world, j + d]
        rhs[world, j] = wp.transpose(mat[world, j, 0]) * t
    return 0


@wp.func
def banded_add_block(world: int, mat: wp.array3d(dtype=wp.mat33), u: int, v: int, k: wp.mat33):
    """Add the block ``k`` at (u, v) of the symmetric matrix (so kᵀ at (v, u)); for u == v, ``k`` must be symmetric."""
    if u >= v:
        mat[world, u, u - v] = mat[world, u, u - v] + k
    else:
        mat[world, v, v - u] = mat[world, v, v - u] + wp.transpose(k)
    return 0


ALL_ROWS = wp.constant(-1)
"""``row`` of the Gauss–Newton adders: every block (the banded kernel, one thread per world, adds an element whole);
a row index instead adds only the blocks stored in that row (the tile kernel, one thread per row)."""


@wp.func
def banded_add_outer(world: int, mat: wp.array3d(dtype=wp.mat33), row: int, u: int, v: int, scale: float,
                   gu: wp.vec3, gv: wp.vec3):
    """:func:`banded_add_block` of ``scale`` · gu gvᵀ at (u, v): the Gauss–Newton block of a scalar energy term
    whose gradients at vertices u and v are ``gu`` and ``gv`` (``scale`` its second derivative). Only if the block
    is stored in ``row`` (row max(u, v)), or always with :data:`ALL_ROWS`: the same arithmetic either way."""
    if row == ALL_ROWS or wp.max(u, v) == row:
        banded_add_block(world, mat, u, v, scale * wp.outer(gu, gv))
    return 0


@wp.func
def banded_add_gauss_newton3(world: int, mat: wp.array3d(dtype=wp.mat33), row: int, scale: float, a: int, b: int,
                           c: int, ga: wp.vec3, gb: wp.vec3, gc: wp.vec3):
    """The Gauss–Newton blocks ``scale`` · ∇q ∇qᵀ of a scalar term q of three distinct vertices (a panel's contact),
    with ∂q/∂x_a = ``ga`` etc. (:func:`banded_add_outer`: in ``row`` only, or :data:`ALL_ROWS`). Each block has its
    own slot, so their order does not change the sum."""
    banded_add_outer(world, mat, row, a, a, scale, ga, ga)
    banded_add_outer(world, mat, row, b, b, scale, gb, gb)
    banded_add_outer(world, mat, row, c, c, scale, gc, gc)
    banded_add_outer(world, mat, row, b, a, scale, gb, ga)
    banded_add_outer(world, mat, row, c, a, scale, gc, ga)
    banded_add_outer(world, mat, row, c, b, scale, gc, gb)
    return 0


@wp.func
def banded_add_gauss_newton4(world: int, mat: wp.array3d(dtype=wp.mat33), row: int, scale: float, a: int, b: int,
                           c: int, d: int, ga: wp.vec3, gb: wp.vec3, gc: wp.vec3, gd: wp.vec3):
    """:func:`banded_add_gauss_newton3` for a term of four distinct vertices (a crease's angle): the three's blocks and
    those of d."""
    banded_add_gauss_newton3(world, mat, row, scale, a, b, c, ga, gb, gc)
    banded_add_outer(world, mat, row, d, d, scale, gd, gd)
    banded_add_outer(world, mat, row, d, a, scale, gd, ga)
    banded_add_outer(world, mat, row, d, b, scale, gd, gb)
    banded_add_outer(world, mat, row, d, c, scale, gd, gc)
    return 0
