"""Loading a config: a YAML file or a packaged name (``warpworm.dataset_configs``), dotted command-line overrides,
then validation."""

from __future__ import annotations

import copy
import os
from importlib import resources
from pathlib import Path

import yaml

from warpworm.data.config.dataset_config import DatasetConfig
from warpworm.data.config.validate import config_from_dict
from warpworm.errors import ConfigError
from warpworm.physics.param_specs import fmt_value as _fmt


def config_packaged_names() -> list[str]:
    """Names of the YAML configs shipped in ``warpworm.dataset_configs``."""
    root = resources.files("warpworm.dataset_configs")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


def read_yaml(source: str | os.PathLike) -> dict:
    """Load a config mapping from a path or a packaged name (``default``); ConfigError if neither exists/parses."""
    p = Path(source)
    if p.is_file():
        text = p.read_text()
    else:
        name = str(source)[:-5] if str(source).endswith(".yaml") else str(source)
        res = resources.files("warpworm.dataset_configs") / f"{name}.yaml"
        if "/" in str(source) or not res.is_file():
            raise ConfigError([f"config: got {_fmt(str(source))}; expected a YAML file path or a packaged name "
                               f"{config_packaged_names()}"])
        text = res.read_text()
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:  # one line: where, and what the parser expected
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError([f"config: {source} is not valid YAML{where}: {what}"]) from None
    return raw if raw is not None else {}


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``a.b.c=value`` overrides (value parsed as YAML) to a raw mapping; returns a new mapping."""
    raw = copy.deepcopy(raw)
    errors = []
    for item in overrides:
        if "=" not in item:
            errors.append(f"override {_fmt(item)}: expected key.path=value")
            continue
        path, text = item.split("=", 1)
        keys = path.strip().split(".")
        if not all(keys):
            errors.append(f"override {_fmt(item)}: empty key in path {_fmt(path)}")
            continue
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        node = raw
        for i, k in enumerate(keys[:-1]):
            nxt = node.get(k)
            if nxt is None:
                nxt = node[k] = {}
            if not isinstance(nxt, dict):
                errors.append(f"{'.'.join(keys[:i + 1])}: got {_fmt(nxt)}; cannot set {path} under a non-mapping")
                break
            node = nxt
        else:
            node[keys[-1]] = value
    if errors:
        raise ConfigError(errors)
    return raw


def load_config(source, overrides: list[str] = (), **top_level) -> DatasetConfig:
    """Load, override and validate. ``top_level`` (e.g. ``num_samples=100, seed=3``) are applied when not None."""
    raw = read_yaml(source) if not isinstance(source, dict) else copy.deepcopy(source)
    if not isinstance(raw, dict):
        raise ConfigError([f"<root>: got {_fmt(raw)}; expected a mapping"])
    raw = apply_overrides(raw, list(overrides))
    for k, v in top_level.items():
        if v is not None:
            raw[k] = v
    return config_from_dict(raw)
