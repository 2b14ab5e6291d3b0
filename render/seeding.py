"""Counter-based random numbers: sample ``i`` depends only on its own seed, never on the batch it is drawn in.

NumPy's generators are sequential, so drawing a batch from one generator ties every sample to its position in the
batch. Here each value is a pure function ``hash(seed, stream, index)`` (SplitMix64 finalizer applied twice), fully
vectorised over seeds: rendering sample ``i`` alone or inside any batch gives the same cameras and appearance.
"""

from __future__ import annotations

import numpy as np

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_STREAM = np.uint64(0xD1B54A32D192ED03)


def _mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finalizer on uint64 arrays (wrapping arithmetic)."""
    x = x ^ (x >> np.uint64(30))
    x = x * _M1
    x = x ^ (x >> np.uint64(27))
    x = x * _M2
    return x ^ (x >> np.uint64(31))


def uniforms(seeds, stream: int, count: int) -> np.ndarray:
    """Uniform numbers in [0, 1), shape ``(len(seeds), count)``, float64.

    Args:
        seeds: one non-negative integer per sample, shape (N,).
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


def uniform_range(u: np.ndarray, lo_hi) -> np.ndarray:
    """Map uniforms in [0, 1) to [lo, hi)."""
    lo, hi = lo_hi
    return lo + (hi - lo) * u


def derive_seeds(master_seed: int, count: int, stream: int = 0) -> np.ndarray:
    """``count`` per-sample seeds (uint32 range, int64) derived from one master seed and a stream id."""
    return (uniforms([master_seed], stream, count)[0] * 2**32).astype(np.int64)
