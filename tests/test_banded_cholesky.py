"""The block-banded Cholesky factor and solve (kernels/banded_cholesky.py) against NumPy's dense solve, and the
unrolled solve at the worm's half-bandwidth against the loops it replaces, bit for bit (it claims the same operations in
the same order). Random symmetric positive definite block-band matrices, float64 truth, float32 kernels."""

from __future__ import annotations

import numpy as np
import pytest
import warp as wp

from warpworm.kernels.banded_cholesky import (UNROLLED_HALF_BANDWIDTH, banded_cholesky_factor, banded_cholesky_solve,
                                            banded_cholesky_solve_loops)


@wp.kernel
def _factor_solve(mode: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33), rhs: wp.array2d(dtype=wp.vec3)):
    world = wp.tid()
    banded_cholesky_factor(world, nv, bw, mat)
    if mode == 0:
        banded_cholesky_solve(world, nv, bw, mat, rhs)
    else:
        banded_cholesky_solve_loops(world, nv, bw, mat, rhs)


def _system(nv: int, bw: int, worlds: int, seed: int):
    """(A (W, 3nv, 3nv) float64 SPD with 3x3-block half-bandwidth bw, b (W, 3nv)) and A's lower block-banded part as stored."""
    rng = np.random.default_rng(seed)
    n = 3 * nv
    blk = np.abs(np.arange(n)[:, None] // 3 - np.arange(n)[None, :] // 3) <= bw
    A = np.empty((worlds, n, n))
    for w in range(worlds):
        m = rng.normal(size=(n, n)) * blk
        A[w] = (m @ m.T) * blk + n * np.eye(n)  # symmetric, band-limited, SPD (least eigenvalue 35-112 here)
    band = np.zeros((worlds, nv, bw + 1, 3, 3))
    for u in range(nv):
        for d in range(min(bw, u) + 1):
            band[:, u, d] = A[:, 3 * u:3 * u + 3, 3 * (u - d):3 * (u - d) + 3]
    return A, rng.normal(size=(worlds, n)), band


def _run(mode: int, nv: int, bw: int, band: np.ndarray, b: np.ndarray) -> np.ndarray:
    mat = wp.array(band.astype(np.float32), dtype=wp.mat33, device="cpu")
    rhs = wp.array(b.reshape(len(b), nv, 3).astype(np.float32), dtype=wp.vec3, device="cpu")
    wp.launch(_factor_solve, dim=len(b), inputs=[mode, nv, bw, mat, rhs], device="cpu")
    return rhs.numpy().reshape(len(b), -1).astype(np.float64)


@pytest.mark.parametrize("bw", [1, 3, UNROLLED_HALF_BANDWIDTH])
def test_factor_and_solve_match_numpy(bw):
    nv, W = 13, 4
    A, b, band = _system(nv, bw, W, seed=bw)
    truth = np.linalg.solve(A, b[..., None])[..., 0]
    for mode in (0, 1):
        x = _run(mode, nv, bw, band, b)
        # float32 factor of a well-conditioned matrix: measured 2.0-2.3e-7 of the largest entry at bw 1, 3, 6
        assert np.abs(x - truth).max() <= 2e-6 * np.abs(truth).max(), (bw, mode)


def test_unrolled_solve_is_the_loops_bit_for_bit():
    nv = 39  # the worm's 13 sections x 3 corners
    A, b, band = _system(nv, int(UNROLLED_HALF_BANDWIDTH), 6, seed=7)
    np.testing.assert_array_equal(_run(0, nv, int(UNROLLED_HALF_BANDWIDTH), band, b),
                                  _run(1, nv, int(UNROLLED_HALF_BANDWIDTH), band, b))
