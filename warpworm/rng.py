"""The counter-based random number generator every layer draws with: a leaf module (imports nothing of the package).

Why counter-based: a sample's values must not depend on which shard, worker, batch or device produced it. Every draw
is a pure function ``u = hash(seed, index, attempt, stream)`` -> uniform [0, 1), where ``stream`` is a fixed 64-bit
hash of the parameter's name. Nothing is stateful, so sample i is the same whether it is drawn alone or among 4096
others, and adding a new randomized parameter never shifts the values of the existing ones.

The hash is SplitMix64's finalizer applied in a chain (as in Random123-style counter generators), vectorized in NumPy
over indices: no Python loop over samples. The distributions built on it (YAML forms) are in
:mod:`warpworm.data.randomize`.
"""

from __future__ import annotations

import hashlib

import numpy as np

_M64 = np.uint64(0xFFFFFFFFFFFFFFFF)
_GOLDEN = np.uint64(0x9E3779B97F4A7C15)


def _mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finalizer (bijective 64-bit mixer), vectorized; uint64 arithmetic wraps modulo 2**64."""
    x = np.asarray(x, dtype=np.uint64)
    with np.errstate(over="ignore"):
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        x = x ^ (x >> np.uint64(31))
    return x


def _combine(h: np.ndarray, v) -> np.ndarray:
    with np.errstate(over="ignore"):
        return _mix64(np.asarray(h, dtype=np.uint64) ^ (np.asarray(v, dtype=np.uint64) + _GOLDEN))


def stream_id(name: str) -> int:
    """Stable 64-bit id of a parameter name (independent of Python's hash randomization)."""
    return int.from_bytes(hashlib.blake2b(name.encode(), digest_size=8).digest(), "little")


def sample_keys(seed: int, index: np.ndarray, attempt: np.ndarray | int = 0) -> np.ndarray:
    """Per-sample 64-bit keys for (seed, index, attempt), shape of ``index``, uint64.

    The seed is mixed before the index joins it: unmixed, seed ^ (index + golden) made (seed s, index i) and
    (s + 1, i − 1) collide for even s, so seeds 0, 1, 2 drew the same samples shifted by one (seed 0 is unchanged:
    the mixer maps 0 to 0)."""
    index = np.asarray(index, dtype=np.uint64)
    h = _combine(np.full(index.shape, _mix64(np.uint64(seed & 0xFFFFFFFFFFFFFFFF))), index)
    return _combine(h, np.broadcast_to(np.asarray(attempt, dtype=np.uint64), index.shape))


def uniform01(keys: np.ndarray, stream: str, k: int = 0) -> np.ndarray:
    """Uniform [0, 1) float64 for each key, for the named stream (and sub-draw ``k``), shape of ``keys``."""
    h = _combine(_combine(keys, np.uint64(stream_id(stream))), np.uint64(k))
    return (h >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def derived_seed(keys: np.ndarray, stream: str = "seed") -> np.ndarray:
    """A non-negative int64 seed per key, for consumers that want an integer seed (renderer noise, OpenCV)."""
    h = _combine(keys, np.uint64(stream_id(stream)))
    return (h >> np.uint64(1)).astype(np.int64)


_STREAM = np.uint64(0xD1B54A32D192ED03)


def seed_uniforms(seeds, stream: int, count: int) -> np.ndarray:
    """Uniform [0, 1) float64, shape ``(len(seeds), count)``: ``count`` numbers per integer seed and numeric stream.

    The same generator as :func:`uniform01` (this module's SplitMix64 finalizer), keyed the way the renderer's
    consumers are (one integer seed per image, a numeric stream per use and rejection attempt: the cameras of
    :func:`warpworm.render.sample_cameras`, :func:`warpworm.render.demo.posed_worm_states`): value ``j`` of seed ``s``
    is ``mix(mix(s·φ + stream·c) ^ (j + 1)·φ)``, so image ``i`` gives the same numbers alone or in any batch.

    Args:
        seeds: one non-negative integer per sample, shape (N,) (e.g. :func:`derived_seed`).
        stream: names an independent stream (e.g. one per use and per rejection attempt).
        count: numbers per sample.
    """
    s = np.asarray(seeds).astype(np.uint64).reshape(-1, 1)
    idx = np.arange(count, dtype=np.uint64).reshape(1, -1)
    st = np.asarray([stream], dtype=np.uint64)
    with np.errstate(over="ignore"):
        x = _mix64(s * _GOLDEN + st * _STREAM)
        x = _mix64(x ^ (idx + np.uint64(1)) * _GOLDEN)
    return (x >> np.uint64(11)).astype(np.float64) * (1.0 / 9007199254740992.0)


def derive_seeds(master_seed: int, count: int, stream: int = 0) -> np.ndarray:
    """``count`` integer seeds (uint32 range, int64) from one master seed and a numeric stream (:func:`seed_uniforms`)."""
    return (seed_uniforms([master_seed], stream, count)[0] * 2**32).astype(np.int64)


# ---------------------------------------------------------------------------------------------------------------------
# Inverse normal CDF (Acklam's rational approximation, relative error < 1.2e-9), vectorized; avoids a SciPy dependency.
_A = (-3.969683028665376e01, 2.209460984245205e02, -2.759285104469687e02, 1.383577518672690e02,
      -3.066479806614716e01, 2.506628277459239e00)
_B = (-5.447609879822406e01, 1.615858368580409e02, -1.556989798598866e02, 6.680131188771972e01,
      -1.328068155288572e01)
_C = (-7.784894002430293e-03, -3.223964580411365e-01, -2.400758277161838e00, -2.549732539343734e00,
      4.374664141464968e00, 2.938163982698783e00)
_D = (7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e00, 3.754408661907416e00)


def norm_ppf(p: np.ndarray) -> np.ndarray:
    """Standard normal quantile for p in (0, 1), float64."""
    p = np.clip(np.asarray(p, dtype=np.float64), 1e-300, 1 - 1e-16)
    out = np.empty_like(p)
    lo, hi = p < 0.02425, p > 1 - 0.02425
    mid = ~(lo | hi)
    q = p[mid] - 0.5
    r = q * q
    out[mid] = (((((_A[0] * r + _A[1]) * r + _A[2]) * r + _A[3]) * r + _A[4]) * r + _A[5]) * q / (
        ((((_B[0] * r + _B[1]) * r + _B[2]) * r + _B[3]) * r + _B[4]) * r + 1)
    for sel, sign in ((lo, 1.0), (hi, -1.0)):
        pp = p[sel] if sign > 0 else 1 - p[sel]
        q = np.sqrt(-2 * np.log(pp))
        out[sel] = sign * (((((_C[0] * q + _C[1]) * q + _C[2]) * q + _C[3]) * q + _C[4]) * q + _C[5]) / (
            (((_D[0] * q + _D[1]) * q + _D[2]) * q + _D[3]) * q + 1)
    return out
