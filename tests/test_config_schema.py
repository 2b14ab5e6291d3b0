"""The exported JSON Schema (``warpworm config-schema``, warpworm.commands.config_schema) against an independent
validator (jsonschema): every packaged config passes it, and it agrees with load_config on what is a mistake, key by
key."""

import json
import math
import subprocess
import sys
from importlib import resources
from pathlib import Path

import jsonschema
import pytest
import yaml

from warpworm.commands.config_schema import json_schema
from warpworm.data.config import PARAM_SPECS, ConfigError, SimConfig, config_packaged_names, load_config

SCHEMA = json_schema()
VALIDATOR = jsonschema.Draft7Validator(SCHEMA)  # what yaml-language-server (VS Code) implements
GOOD = {"num_samples": 8, "shard_size": 4, "sim": {"frame_times": [0.1, 0.2]}}


def _loads(raw) -> bool:
    try:
        load_config(raw)
        return True
    except ConfigError:
        return False


def _schema_ok(raw) -> bool:
    return not list(VALIDATOR.iter_errors(raw))


def test_schema_is_valid_draft7_json():
    jsonschema.Draft7Validator.check_schema(SCHEMA)
    assert SCHEMA["$schema"] == "http://json-schema.org/draft-07/schema#"
    json.dumps(SCHEMA, allow_nan=False)  # strict JSON: no NaN defaults (those are 'the gait preset's value')


def test_schema_lists_every_key_for_completion():
    defs = SCHEMA["$defs"]
    assert list(SCHEMA["properties"]) == ["name", "seed", "num_samples", "shard_size", "sim", "render", "output",
                                          "randomize"]
    assert list(defs["SimConfig"]["properties"]) == [f for f in SimConfig.__dataclass_fields__]
    assert list(defs["Randomize"]["properties"]) == list(PARAM_SPECS)
    for group, specs in PARAM_SPECS.items():
        props = defs[f"Randomize{group.capitalize()}"]["properties"]
        assert list(props) == list(specs)
        for name, spec in specs.items():
            assert spec.doc in props[name]["description"], (group, name)
    assert all(defs[k].get("additionalProperties") is False
               for k in ("SimConfig", "RenderConfig", "OutputConfig", "Randomize", "RandomizeWorm"))


def test_every_yaml_in_dataset_configs_is_packaged():
    folder = Path(__file__).resolve().parents[1] / "dataset_configs"
    assert sorted(p.stem for p in folder.glob("*.yaml")) == config_packaged_names()


@pytest.mark.parametrize("name", config_packaged_names())
def test_packaged_config_passes_the_schema_and_load_config(name):
    raw = yaml.safe_load((resources.files("warpworm.dataset_configs") / f"{name}.yaml").read_text())
    errors = [f"{'.'.join(map(str, e.absolute_path))}: {e.message}" for e in VALIDATOR.iter_errors(raw)]
    assert errors == []
    load_config(raw)


@pytest.mark.parametrize("raw", [
    {"bogus": 1}, {"sim": {"substepz": 3}}, {"sim": {"substeps": "many"}}, {"sim": {"substeps": 2.5}},
    {"sim": {"dt": "0.1"}}, {"sim": {"dt": 0}}, {"sim": {"worlds": True}}, {"sim": {"frame_times": []}},
    {"sim": {"frame_times": [0.1, "x"]}}, {"sim": [1, 2]}, {"render": {"camera_per_frame": "yes"}},
    {"render": {"width": 4}}, {"num_samples": 0}, {"seed": -1}, {"name": 3},
    {"output": {"compression": "zstd"}}, {"output": {"compression_level": 10}},
    {"randomize": {"weather": {}}}, {"randomize": {"worm": {"kalpha": 1.0}}}, {"randomize": {"worm": [1]}},
    {"randomize": {"worm": {"gait": "crawl"}}}, {"randomize": {"worm": {"gait": {"choice": ["omega", "slither"]}}}},
    {"randomize": {"worm": {"gait": {"uniform": [0, 1]}}}}, {"randomize": {"worm": {"backward": "yes"}}},
    {"randomize": {"worm": {"a": -0.01}}}, {"randomize": {"worm": {"a": "big"}}},
    {"randomize": {"worm": {"a": {"gauss": [1, 2]}}}}, {"randomize": {"worm": {"a": {"uniform": [0.01]}}}},
    {"randomize": {"worm": {"a": {"normal": {"mean": 0.02, "std": 0.001}}}}},  # reaches a <= 0
    {"randomize": {"worm": {"a": {"normal": {"mean": 0.02, "std": 0.001, "low": 0.01, "sigma": 1}}}}},
    {"randomize": {"worm": {"mu_static": {"choice": [0.2, 0.3], "weights": [1, -1]}}}},
    {"randomize": {"camera": {"distance": {"loguniform": [0.1, 0.5]}}}},
    {"randomize": {"camera": {"min_in_frame": 1.5}}}, {"randomize": {"camera": {"max_tries": 2.5}}},
    {"randomize": {"camera": {"lookat_jitter": {"uniform": [0, 0.01]}}}},
    {"randomize": {"sensor": {"jpeg_quality": {"choice": [100, 0]}}}}, {"randomize": {"texture": {"floor": "wood"}}},
])
def test_a_wrong_value_is_refused_by_the_schema_and_by_load_config(raw):
    raw = {**GOOD, **raw}
    assert not _schema_ok(raw)
    assert not _loads(raw)


@pytest.mark.parametrize("raw", [
    {"sim": {"dt": 1, "frame_times": [1, 2]}}, {"render": {"width": 8}}, {"output": {"compression": "none"}},
    {"randomize": {"worm": {"gait": {"grid": ["omega", "inchworm"]}, "backward": True}}},
    {"randomize": {"worm": {"a": {"normal": {"mean": 0.02, "std": 0.001, "low": 0.01}}}}},
    {"randomize": {"worm": {"mu_static": {"choice": [0.2, 0.3], "weights": [1, 3]}, "damping": {"constant": 1}}}},
    {"randomize": {"camera": {"max_tries": 3.0, "distance": 0.2}}},
    {"randomize": {"texture": {"floor": {"choice": ["plain", "noise"]}}}},
])
def test_a_right_value_passes_both(raw):
    raw = {**GOOD, **raw}
    assert _schema_ok(raw)
    assert _loads(raw)


def _probes(spec):
    """Values a parameter of ``spec`` may not take: past each bound, a wrong type, an unknown name."""
    if spec.values is not None:
        return ["no-such-value", {"uniform": [0, 1]}] + ([] if isinstance(spec.values[0], bool) else [True])
    out = ["0.1", True]
    if spec.low is not None:
        out += [spec.low - 1, {"uniform": [spec.low - 1, spec.low]}]
    if spec.high is not None:
        out += [spec.high + 1, {"choice": [spec.high, spec.high + 1]}]
    if spec.positive:
        out += [0, {"grid": [0.0, 1.0]} if not (spec.ranges_only or spec.constant_only) else -1.0]
    return out


@pytest.mark.parametrize("group", list(PARAM_SPECS))
def test_every_parameter_agrees_with_load_config(group):
    """Per parameter: its default passes both; every probe past its spec is refused by both."""
    for name, spec in PARAM_SPECS[group].items():
        default = spec.default
        if not (isinstance(default, float) and math.isnan(default)):  # NaN (the preset) has no JSON spelling
            raw = {**GOOD, "randomize": {group: {name: default}}}
            assert _schema_ok(raw) and _loads(raw), (group, name, default)
        for probe in _probes(spec):
            raw = {**GOOD, "randomize": {group: {name: probe}}}
            assert (_schema_ok(raw), _loads(raw)) == (False, False), (group, name, probe)


def test_cli_prints_the_schema(tmp_path):
    r = subprocess.run([sys.executable, "-m", "warpworm", "config-schema"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and json.loads(r.stdout) == SCHEMA
    out = tmp_path / "warpworm-config.schema.json"
    r = subprocess.run([sys.executable, "-m", "warpworm", "config-schema", "--out", str(out)], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0 and json.loads(out.read_text()) == SCHEMA
