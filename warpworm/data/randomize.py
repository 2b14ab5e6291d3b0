"""Domain randomization: the distributions a config names (YAML forms), drawn per sample with warpworm.rng.

Distributions draw with the counter-based generator of :mod:`warpworm.rng`, keyed by (seed, sample index,
attempt, stream): sample i's values do not depend on the shard, worker, batch or device that produced it.

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

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from warpworm.rng import norm_ppf, sample_keys, uniform01


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
