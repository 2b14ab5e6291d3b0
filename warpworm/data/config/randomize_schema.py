"""The ``randomize`` section: one TypedDict per group generated from :data:`PARAM_SPECS`; a parameter is parsed by
:func:`warpworm.data.randomize.parse_distribution`, then checked against its :class:`ParamSpec`."""

from __future__ import annotations

import math
from typing import Annotated, Any

from pydantic import BeforeValidator, ConfigDict, PlainValidator, WithJsonSchema
from typing_extensions import TypedDict

from warpworm.data import randomize as rnd
from warpworm.data.config.sections import none_is_empty, problem
from warpworm.data.config.specs import PARAM_SPECS
from warpworm.physics.param_specs import ParamSpec
from warpworm.physics.param_specs import fmt_value as _fmt


def _check_spec(dist: rnd.Distribution, spec: ParamSpec) -> list[str]:
    """What is wrong with ``dist`` for a parameter of ``spec`` ("got X; expected Y" each); [] if nothing."""
    got = f"got {_fmt(dist.to_yaml())}"
    if spec.values is not None and not (spec.low is not None and dist.is_numeric):
        vals = rnd.distribution_values(dist)
        if not vals:
            return [f"{got}; expected a constant or choice/grid of {list(spec.values)}"]
        bad = [v for v in vals if v not in spec.values or type(v) is not type(spec.values[0])]
        return [f"got {_fmt(bad[0])}; expected one of {list(spec.values)}"] if bad else []
    if spec.constant_only and not isinstance(dist, rnd.Constant):
        return [f"{got}; expected a constant [{spec.unit}] ({spec.doc})"]
    if spec.ranges_only and not isinstance(dist, (rnd.Constant, rnd.Uniform)):
        return [f"{got}; expected a constant or {{uniform: [lo, hi]}} [{spec.unit}] (the camera sampler draws "
                "uniformly in the range, per attempt)"]
    b = rnd.distribution_bounds(dist)
    if b is None:
        return [f"{got}; expected numeric values [{spec.unit}]"]
    lo, hi = b
    if math.isnan(lo) or math.isnan(hi):  # NaN = "the gait preset's value", only where a preset gives one
        return [] if spec.preset and isinstance(dist, rnd.Constant) else [f"{got}; expected a number [{spec.unit}]"]
    problems = []
    if spec.integer and not (float(lo).is_integer() and float(hi).is_integer()):
        problems.append(f"{got}; expected a whole number")
    if spec.positive and lo <= 0:
        problems.append(f"{got}; expected values > 0 [{spec.unit}]")
    if spec.low is not None and lo < spec.low:
        problems.append(f"{got}; expected values >= {spec.low} [{spec.unit}]")
    if spec.high is not None and hi > spec.high:
        problems.append(f"{got}; expected values <= {spec.high} [{spec.unit}]")
    return problems


def _dist_validator(spec: ParamSpec):
    def parse(raw) -> rnd.Distribution:
        try:
            dist = rnd.parse_distribution(raw)
        except rnd.DistributionError as exc:
            raise problem(str(exc)) from None
        problems = _check_spec(dist, spec)
        if problems:
            raise problem("; ".join(problems))
        return dist
    return parse


def _param_schema(spec: ParamSpec) -> dict:
    """A parameter's JSON Schema as pydantic exports it: what it is and its default. The YAML forms it may take are
    added from the same ParamSpec by warpworm.commands.config_schema."""
    out = {"description": f"{spec.doc} [{spec.unit}]" if spec.unit else spec.doc}
    default = rnd.parse_distribution(spec.default).to_yaml()
    if not (isinstance(default, float) and math.isnan(default)):  # NaN (the gait preset's value) has no JSON spelling
        out["default"] = default
    return out


def _group(name: str, specs: dict[str, ParamSpec]):
    params = {n: Annotated[Any, PlainValidator(_dist_validator(s)), WithJsonSchema(_param_schema(s))]
              for n, s in specs.items()}
    td = TypedDict(f"Randomize{name.capitalize()}", params, total=False)
    td.__doc__ = f"randomize.{name}: parameter -> distribution; parameters not named keep their defaults."
    td.__pydantic_config__ = ConfigDict(extra="forbid")
    return Annotated[td, BeforeValidator(none_is_empty)]


_DEFAULTS = {g: {n: rnd.parse_distribution(s.default) for n, s in specs.items()} for g, specs in PARAM_SPECS.items()}
Randomize = TypedDict("Randomize", {g: _group(g, specs) for g, specs in PARAM_SPECS.items()}, total=False)
Randomize.__pydantic_config__ = ConfigDict(extra="forbid")
Randomize.__doc__ = "group -> parameter -> distribution (warpworm.data.randomize)."


def with_defaults(given: dict) -> dict:
    """Every parameter of PARAM_SPECS, in its order: the given distribution, else the default."""
    return {g: {n: given.get(g, {}).get(n, d) for n, d in dists.items()} for g, dists in _DEFAULTS.items()}
