"""``warpworm config-schema``: print the JSON Schema of dataset configs, so an editor validates and completes them.

pydantic exports the keys, types, ranges, descriptions and defaults from :mod:`warpworm.data.config`; this module adds, for
every ``randomize`` parameter, the distribution forms its ParamSpec allows (a constant, ``{uniform: [lo, hi]}``, ...,
with the parameter's bounds on each number), defined once per kind of parameter under ``$defs``. docs/config.md shows
how to point VS Code (yaml-language-server) at it. The schema checks each key alone; the checks that relate two keys
(shard_size and sim.frame_times, frame times and sim.dt, the device) are load_config's, which
``warpworm generate CONFIG --out X --print-config`` runs without simulating anything.
"""

from __future__ import annotations

import argparse
import json
import sys

from warpworm.data.config import PARAM_SPECS, schema_adapter

HELP = "Print the JSON Schema of dataset configs (for editors: validation and completion of dataset_configs/*.yaml)."

DRAFT = "http://json-schema.org/draft-07/schema#"
"""What yaml-language-server (VS Code's YAML support) implements; the schema uses nothing later (pydantic's ``$defs``
is only where the references point)."""


def json_schema() -> dict:
    """The dataset config's JSON Schema (draft 7)."""

    schema = schema_adapter().json_schema()
    defs = schema["$defs"]
    for group, specs in PARAM_SPECS.items():
        params = defs[f"Randomize{group.capitalize()}"]["properties"]
        for name, spec in specs.items():
            forms_name, forms = _forms(spec)
            assert defs.setdefault(forms_name, forms) == forms, forms_name  # one name, one set of forms
            params[name]["allOf"] = [{"$ref": f"#/$defs/{forms_name}"}]
    return {"$schema": DRAFT, **schema, "title": "warpworm dataset config"}


def _forms(spec) -> tuple[str, dict]:
    """(a name, the JSON Schema) of the YAML forms a parameter of ``spec`` (a warpworm.physics.param_specs.ParamSpec) may take,
    as warpworm.data.randomize.parse_distribution reads them and warpworm.data.config's _check_spec accepts them."""
    def obj(**props):
        return {"type": "object", "properties": props, "required": list(props)[:1], "additionalProperties": False}

    def listof(item, n=None):
        return {"type": "array", "items": item, "minItems": n or 1, **({"maxItems": n} if n else {})}

    if spec.values is not None:
        value = {"enum": list(spec.values)}
        name = "one_of_" + "_".join(str(v).lower() for v in spec.values)
    else:
        value = {"type": "integer" if spec.integer else "number"}
        name = value["type"]
        if spec.positive:
            value["exclusiveMinimum"], name = 0, name + "_gt_0"
        if spec.low is not None:
            value["minimum"], name = spec.low, name + f"_ge_{spec.low:.4g}"
        if spec.high is not None:
            value["maximum"], name = spec.high, name + f"_le_{spec.high:.4g}"
        name += "_constant" if spec.constant_only else "_range" if spec.ranges_only else "_distribution"
    forms = [value, obj(constant=value)]
    if spec.values is None and not spec.constant_only:
        forms.append(obj(uniform=listof(value, 2)))
        if not spec.ranges_only:
            positive = {**value, "exclusiveMinimum": max(0, value.get("exclusiveMinimum", 0))}
            normal = obj(mean={"type": "number"}, std={"type": "number", "minimum": 0}, low=value, high=value)
            # a normal is truncated to [low, high]; a bounded parameter needs the bound (an open side reaches past it)
            normal["required"] = ["mean", "std"] + (["low"] if "minimum" in value or spec.positive else []) + \
                (["high"] if "maximum" in value else [])
            forms += [obj(loguniform=listof(positive, 2)), obj(normal=normal)]
    if not spec.constant_only and not spec.ranges_only:
        forms += [obj(choice=listof(value), weights=listof({"type": "number", "minimum": 0})), obj(grid=listof(value))]
    return name, {"anyOf": forms}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", default=None, help="write the schema to this file instead of printing it")


def main(args: argparse.Namespace) -> int:
    text = json.dumps(json_schema(), indent=2, allow_nan=False) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    try:
        with open(args.out, "w") as f:
            f.write(text)
    except OSError as exc:
        print(f"error: --out: got '{args.out}'; expected a writable file ({exc.strerror})", file=sys.stderr)
        return 2
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
