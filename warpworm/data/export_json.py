"""Strict JSON for every file warpworm writes: no bare ``NaN`` / ``Infinity`` (which ``JSON.parse`` and most config
tools reject), ``null`` where there is no value.

:func:`jsonable` turns NumPy arrays and scalars into Python values and every non-finite float into ``None``;
:func:`dumps` / :func:`write` then serialize with ``allow_nan=False``, so a NaN that slipped past would raise instead
of being written.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np


def jsonable(obj):
    """``obj`` with NumPy values as Python ones, tuples as lists and NaN / ±inf as ``None`` (recursively)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return jsonable(obj.item())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def dumps(obj, **kwargs) -> str:
    """``json.dumps`` of :func:`jsonable` (``obj``), strict (``allow_nan=False``)."""
    kwargs.setdefault("allow_nan", False)
    return json.dumps(jsonable(obj), **kwargs)


def write(path, obj, **kwargs) -> Path:
    """Write ``obj`` as strict JSON to ``path`` (via a temporary file and a rename); returns the path."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(dumps(obj, **kwargs))
    tmp.replace(path)
    return path


def loads_strict(text: str):
    """Parse JSON as strict parsers do: ``NaN``, ``Infinity`` and ``-Infinity`` are errors (ValueError)."""

    def refuse(name):
        raise ValueError(f"non-standard JSON constant {name}")

    return json.loads(text, parse_constant=refuse)
