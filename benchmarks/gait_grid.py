"""The (w, a, h) grid arguments the gait benchmarks share (``gait_robustness.py``, ``gait_cycles.py``)."""

from __future__ import annotations

import numpy as np

GRID_FLAGS = {"w": "wavelength", "a": "amplitude", "h": "closest_approach"}
"""Flag -> the WormParams field it grids (values given in millimetres)."""


def add_grid_arguments(parser) -> None:
    """``--w``, ``--a``, ``--h``: comma-separated millimetres, each required."""
    for flag, name in (("w", "wavelengths"), ("a", "amplitudes"), ("h", "closest approaches")):
        parser.add_argument(f"--{flag}", required=True, help=f"{name} [mm], comma-separated")


def grid_from_arguments(args) -> dict[str, np.ndarray]:
    """{WormParams field: values [m]} from the parsed flags; a bad list stops with a message naming its flag, its
    text and what was expected."""
    out = {}
    for flag, field in GRID_FLAGS.items():
        text = getattr(args, flag)
        try:
            vals = np.array([float(v) for v in text.split(",") if v.strip()]) * 1e-3
        except ValueError:
            raise SystemExit(f"--{flag}: {text!r} is not a comma-separated list of millimetres") from None
        if len(vals) == 0 or not np.all(np.isfinite(vals)) or not np.all(vals >= 0):
            raise SystemExit(f"--{flag}: {text!r}: expected one or more finite values >= 0 [mm]")
        out[field] = vals
    return out
