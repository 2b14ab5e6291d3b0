"""The (w, a, h) grid arguments the gait benchmarks share (``gait_robustness.py``, ``gait_cycles.py``,
``gait_dt_error.py``)."""

from __future__ import annotations

import argparse

import numpy as np

from warpworm.physics import gaits

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


def gait_grid_parser(doc: str, *, cycles_default, cycles_type=int, name: str = ""):
    """The parser the grid benchmarks start from: the gait, ``--w/--a/--h``, ``--cycles``, ``--backward``,
    ``--workers`` and ``--out`` (default ``benchmarks/results/<name>_<gait>.json``); each adds its own flags."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("gait", choices=gaits.GAITS)
    add_grid_arguments(ap)
    ap.add_argument("--cycles", type=cycles_type, default=cycles_default)
    ap.add_argument("--backward", action="store_true")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--out", default=None, help=f"JSON path (default benchmarks/results/{name}_<gait>.json)")
    return ap
