"""Validation with one message per problem: a raw mapping -> :class:`DatasetConfig`, a command-line option checked as
its config key, and pydantic's errors said as "path: got X; expected Y"."""

from __future__ import annotations

import functools
import math
import typing
from dataclasses import fields

from pydantic import TypeAdapter, ValidationError

from warpworm.data.config.dataset_config import DatasetConfig, schema_adapter
from warpworm.data.config.sections import OutputConfig, RenderConfig, SimConfig
from warpworm.data.config.specs import PARAM_SPECS
from warpworm.errors import ConfigError
from warpworm.physics.param_specs import fmt_value as _fmt

_KEYS = {"": [f.name for f in fields(DatasetConfig)], "sim": [f.name for f in fields(SimConfig)],
         "render": [f.name for f in fields(RenderConfig)], "output": [f.name for f in fields(OutputConfig)],
         "randomize": list(PARAM_SPECS), **{f"randomize.{g}": list(s) for g, s in PARAM_SPECS.items()}}
_EXPECTED = {"int_type": "an integer", "float_type": "a number", "finite_number": "a finite number",
             "bool_type": "true or false", "string_type": "a string", "list_type": "a list of numbers",
             "too_short": "a non-empty list", "greater_than_equal": ">= {ge}", "greater_than": "> {gt}",
             "less_than_equal": "<= {le}", "literal_error": "{expected}"}
_MAPPING = ("dataclass_type", "dataclass_exact_type", "dict_type", "model_type")


def _path(loc) -> str:
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in loc).lstrip(".")


def _message(e: dict) -> str:
    loc, kind, ctx = e["loc"], e["type"], e.get("ctx") or {}
    path = _path(loc)
    if kind == "config":
        return f"{ctx['path'] or path}: {ctx['detail']}"
    if kind in ("extra_forbidden", "unexpected_keyword_argument", "invalid_key"):  # invalid: not a string (YAML 1:)
        parent = _path(loc[:-1])
        what = {2: "group", 3: "parameter"}.get(len(loc), "key") if loc[0] == "randomize" else "key"
        key = f"{parent}.{loc[-1]}" if parent else str(loc[-1])
        return f"{key}: unknown {what}; expected one of {sorted(_KEYS.get(parent, []))}"
    if kind in _MAPPING:
        expected = "a mapping of parameters" if path.startswith("randomize.") else f"a mapping with keys {_KEYS[path]}"
    else:  # bounds of float fields come as floats: say 0, not 0.0
        ctx = {k: int(v) if isinstance(v, float) and v.is_integer() else v for k, v in ctx.items()}
        expected = _EXPECTED[kind].format(**ctx) if kind in _EXPECTED else e["msg"]
    return f"{path}: got {_fmt(e['input'])}; expected {expected}"


@functools.cache
def _field_adapter(section: str, name: str) -> TypeAdapter:
    cls = {"sim": SimConfig, "render": RenderConfig, "output": OutputConfig}[section]
    return TypeAdapter(typing.get_type_hints(cls, include_extras=True)[name])


def check_option(option: str, value, key: str):
    """A command-line ``option``'s ``value`` validated as the config key ``key`` (e.g. ``--dt`` as ``sim.dt``,
    ``--device`` as ``sim.device``): the validated value, or :class:`ConfigError` "--dt (sim.dt): got X; expected Y"."""
    section, name = key.split(".")
    try:
        out = _field_adapter(section, name).validate_python(value)
    except ValidationError as exc:
        msgs = [_message({**e, "loc": ()}) for e in exc.errors(include_url=False)]
        msgs = [m.replace(f"(override with {key}=cpu)", f"(use {option} cpu)") for m in msgs]
        raise ConfigError([f"{option} ({key}){m}" for m in msgs]) from None
    if isinstance(out, float) and not math.isfinite(out):  # as the config's sections (allow_inf_nan=False)
        raise ConfigError([f"{option} ({key}): got {_fmt(out)}; expected a finite number"])
    return out


def check_options(options: dict) -> dict:
    """:func:`check_option` of every ``{option: (value, key)}`` whose value is not None, all problems at once;
    returns {option: validated value}."""
    out, problems = {}, []
    for option, (value, key) in options.items():
        if value is None:
            out[option] = None
            continue
        try:
            out[option] = check_option(option, value, key)
        except ConfigError as exc:
            problems += exc.errors
    if problems:
        raise ConfigError(problems)
    return out


def config_from_dict(raw: dict) -> DatasetConfig:
    """Validate a raw mapping (as loaded from YAML) into a :class:`DatasetConfig`; raises :class:`ConfigError`."""
    if not isinstance(raw, dict):
        raise ConfigError([f"<root>: got {_fmt(raw)}; expected a mapping"])
    try:
        return schema_adapter().validate_python(raw)
    except ValidationError as exc:
        raise ConfigError([_message(e) for e in exc.errors(include_url=False)]) from None
