"""Domain randomization: distributions and a counter-based generator keyed by (seed, sample index).

Why counter-based: a sample's values must not depend on which shard, worker, batch or device produced it. Every draw
is a pure function ``u = hash(seed, index, attempt, stream)`` -> uniform [0, 1), where ``stream`` is a fixed 64-bit
hash of the parameter's name. Nothing is stateful, so sample i is the same whether it is drawn alone or among 4096 others,
and adding a new randomized parameter never shifts the values of the existing ones.

The hash is SplitMix64's finalizer applied in a chain (as in Random123-style counter generators), vectorized in NumPy over
indices: no Python loop over samples.

Distributions (YAML forms, parsed by :func:`parse_distribution`):

==================  =============================================================  =========================================
form                meaning                                                        example
==================  =============================================================  =========================================
``0.02``            constant                                                       ``hinge_stiffness: 0.02``
``{constant: v}``   constant (also strings / booleans)                             ``{constant: omega}``
``{uniform: [lo, hi]}``  uniform on [lo, hi)                                       ``{uniform: [0.2, 0.3]}``
``{loguniform: [lo, hi]}``  log-uniform, 0 < lo <= hi                              ``{loguniform: [0.005, 0.05]}``
``{normal: {mean, std, low, high}}``  normal truncated to [low, high] (inverse CDF)  ``{normal: {mean: 0.27, std: 0.02, low: 0.2, high: 0.35}}``
``{choice: [v...], weights: [w...]}``  one of the values (weights optional)          ``{choice: [checker, noise]}``
``{grid: [v...]}``  deterministic sweep: value ``values[index % len]``               ``{grid: [0.01, 0.02, 0.04]}``
==================  =============================================================  =========================================
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Any

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


def _norm_cdf(x: float) -> float:
    return 0.5 * (1.0 + math.erf(x / math.sqrt(2.0)))


# ---------------------------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Distribution:
    """Base class: ``sample(u, index)`` maps uniforms ``u`` (n,) in [0, 1) (and sample indices) to values (n,)."""

    def sample(self, u: np.ndarray, index: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_yaml(self) -> Any:  # pragma: no cover - abstract
        raise NotImplementedError

    @property
    def is_numeric(self) -> bool:
        return True


@dataclass(frozen=True)
class Constant(Distribution):
    value: Any

    def sample(self, u, index):
        if isinstance(self.value, (str, bool)):
            return np.full(len(u), self.value, dtype=object if isinstance(self.value, str) else bool)
        return np.full(len(u), float(self.value))

    def to_yaml(self):
        return self.value

    @property
    def is_numeric(self):
        return isinstance(self.value, (int, float)) and not isinstance(self.value, bool)


@dataclass(frozen=True)
class Uniform(Distribution):
    low: float
    high: float

    def sample(self, u, index):
        return self.low + (self.high - self.low) * u

    def to_yaml(self):
        return {"uniform": [self.low, self.high]}


@dataclass(frozen=True)
class LogUniform(Distribution):
    low: float
    high: float

    def sample(self, u, index):
        return np.exp(math.log(self.low) + (math.log(self.high) - math.log(self.low)) * u)

    def to_yaml(self):
        return {"loguniform": [self.low, self.high]}


@dataclass(frozen=True)
class TruncNormal(Distribution):
    mean: float
    std: float
    low: float = -math.inf
    high: float = math.inf

    def sample(self, u, index):
        # Inverse-CDF sampling restricted to [Φ(a), Φ(b)]: one uniform per value, no rejection loop, so it stays
        # counter-based (a rejection sampler would consume a variable number of draws).
        a = _norm_cdf((self.low - self.mean) / self.std) if self.std > 0 else 0.0
        b = _norm_cdf((self.high - self.mean) / self.std) if self.std > 0 else 1.0
        x = self.mean + self.std * norm_ppf(a + (b - a) * u)
        return np.clip(x, self.low, self.high)

    def to_yaml(self):
        d = {"mean": self.mean, "std": self.std}
        if math.isfinite(self.low):
            d["low"] = self.low
        if math.isfinite(self.high):
            d["high"] = self.high
        return {"normal": d}


@dataclass(frozen=True)
class Choice(Distribution):
    values: tuple
    weights: tuple | None = None

    def sample(self, u, index):
        w = np.ones(len(self.values)) if self.weights is None else np.asarray(self.weights, dtype=np.float64)
        cdf = np.cumsum(w) / w.sum()
        k = np.minimum(np.searchsorted(cdf, u, side="right"), len(self.values) - 1)
        return _take(self.values, k)

    def to_yaml(self):
        d = {"choice": list(self.values)}
        if self.weights is not None:
            d["weights"] = list(self.weights)
        return d

    @property
    def is_numeric(self):
        return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in self.values)


@dataclass(frozen=True)
class Grid(Distribution):
    """Deterministic sweep over ``values`` by sample (trajectory) index: index i gets ``values[i % len(values)]``."""

    values: tuple

    def sample(self, u, index):
        return _take(self.values, np.asarray(index, dtype=np.int64) % len(self.values))

    def to_yaml(self):
        return {"grid": list(self.values)}

    @property
    def is_numeric(self):
        return all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in self.values)


def _take(values: tuple, k: np.ndarray) -> np.ndarray:
    if all(isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=bool)[k]
    if all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        return np.asarray(values, dtype=np.float64)[k]
    return np.asarray(values, dtype=object)[k]


class DistributionError(ValueError):
    """A distribution spec that does not parse; the message says what was expected."""


_EXPECTED = ("a number/string/bool (constant), {uniform: [lo, hi]}, {loguniform: [lo, hi]}, "
             "{normal: {mean, std, low, high}}, {choice: [...], weights: [...]}, {grid: [...]} or {constant: v}")


def _num(x, what):
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(float(x)):
        raise DistributionError(f"{what} must be a finite number, got {x!r}")
    return float(x)


def parse_distribution(spec: Any) -> Distribution:
    """Parse a YAML distribution spec (see module docstring); raises :class:`DistributionError` with what was expected."""
    if isinstance(spec, Distribution):
        return spec
    if isinstance(spec, (bool, str)):
        return Constant(spec)
    if isinstance(spec, (int, float)):
        if isinstance(spec, float) and math.isnan(spec):
            return Constant(spec)  # NaN means "use the preset" for some parameters (worm.orientation)
        return Constant(_num(spec, "constant"))
    if not isinstance(spec, dict) or not spec:
        raise DistributionError(f"got {spec!r}; expected {_EXPECTED}")
    keys = set(spec)
    kinds = keys & {"constant", "uniform", "loguniform", "normal", "choice", "grid"}
    if len(kinds) != 1 or (keys - kinds - {"weights"}) or ("weights" in keys and kinds != {"choice"}):
        raise DistributionError(f"got {spec!r}; expected exactly one of {_EXPECTED}")
    kind = kinds.pop()
    arg = spec[kind]
    if kind == "constant":
        if isinstance(arg, (bool, str)):
            return Constant(arg)
        return Constant(_num(arg, "constant"))
    if kind in ("uniform", "loguniform"):
        if not isinstance(arg, (list, tuple)) or len(arg) != 2:
            raise DistributionError(f"{kind} needs [low, high], got {arg!r}")
        lo, hi = _num(arg[0], f"{kind} low"), _num(arg[1], f"{kind} high")
        if lo > hi:
            raise DistributionError(f"{kind} low > high: [{lo}, {hi}]; expected low <= high")
        if kind == "loguniform" and lo <= 0:
            raise DistributionError(f"loguniform needs 0 < low, got [{lo}, {hi}]")
        return Uniform(lo, hi) if kind == "uniform" else LogUniform(lo, hi)
    if kind == "normal":
        if not isinstance(arg, dict) or not {"mean", "std"} <= set(arg) or set(arg) - {"mean", "std", "low", "high"}:
            raise DistributionError(f"normal needs {{mean, std[, low, high]}}, got {arg!r}")
        mean, std = _num(arg["mean"], "normal mean"), _num(arg["std"], "normal std")
        lo = _num(arg["low"], "normal low") if "low" in arg else -math.inf
        hi = _num(arg["high"], "normal high") if "high" in arg else math.inf
        if std < 0:
            raise DistributionError(f"normal std must be >= 0, got {std}")
        if lo > hi:
            raise DistributionError(f"normal low > high: [{lo}, {hi}]; expected low <= high")
        return TruncNormal(mean, std, lo, hi)
    # choice / grid
    if not isinstance(arg, (list, tuple)) or not arg:
        raise DistributionError(f"{kind} needs a non-empty list of values, got {arg!r}")
    for v in arg:
        if not isinstance(v, (int, float, str, bool)):
            raise DistributionError(f"{kind} values must be numbers, strings or booleans, got {v!r}")
    values = tuple(float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in arg)
    if kind == "grid":
        return Grid(values)
    weights = spec.get("weights")
    if weights is not None:
        if not isinstance(weights, (list, tuple)) or len(weights) != len(values):
            raise DistributionError(f"choice weights must be a list of {len(values)} numbers, got {weights!r}")
        weights = tuple(_num(w, "choice weight") for w in weights)
        if any(w < 0 for w in weights) or sum(weights) <= 0:
            raise DistributionError(f"choice weights must be >= 0 with a positive sum, got {list(weights)}")
    return Choice(values, weights)


def distribution_values(dist: Distribution) -> list:
    """Every value a discrete distribution can take (for validating e.g. gait names); [] for continuous ones."""
    if isinstance(dist, Constant):
        return [dist.value]
    if isinstance(dist, (Choice, Grid)):
        return list(dist.values)
    return []


def distribution_bounds(dist: Distribution) -> tuple[float, float] | None:
    """Closed range a numeric distribution can reach (for range checks), or None for non-numeric ones."""
    if not dist.is_numeric:
        return None
    if isinstance(dist, Constant):
        return (float(dist.value), float(dist.value))
    if isinstance(dist, (Uniform, LogUniform)):
        return (dist.low, dist.high)
    if isinstance(dist, TruncNormal):
        return (dist.low, dist.high)
    vals = [float(v) for v in dist.values]
    return (min(vals), max(vals))


@dataclass
class Draws:
    """Values of every randomized parameter for a set of samples: ``values[name]`` has shape (n,)."""

    values: dict[str, np.ndarray] = field(default_factory=dict)

    def __getitem__(self, name):
        return self.values[name]

    def get(self, name, default=None):
        return self.values.get(name, default)


def draw(dists: dict[str, Distribution], seed: int, index: np.ndarray, attempt: np.ndarray | int = 0,
         prefix: str = "") -> Draws:
    """Draw every distribution in ``dists`` for the given sample indices.

    Args:
        dists: parameter name -> distribution; the name (with ``prefix``) is also the stream id.
        seed: the job's master seed.
        index: (n,) sample (or trajectory) indices.
        attempt: (n,) or scalar replacement attempt (0 first; a world that went unstable is redrawn with attempt + 1).
    Returns: :class:`Draws` with one (n,) array per name.
    """
    index = np.asarray(index, dtype=np.int64)
    keys = sample_keys(seed, index, attempt)
    out = Draws()
    for name, dist in dists.items():
        out.values[name] = dist.sample(uniform01(keys, prefix + name), index)
    return out
