"""What every virtual experiment shares: the worlds split over threads, the rigs' vertex sections, magnets off, the
default step, and the results as JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.world_split import concat, run_shares
from warpworm.physics import gaits
from warpworm.physics.params import WormParams, slice_worlds
from warpworm.sim.model import Model

EXPERIMENTS = ("force-distance", "compression", "flexure", "slope", "force-plate", "strain", "deformation")

NO_MAGNETS = dict(ipm_moment=np.zeros(3), epm_moment=0.0)
"""Overrides that switch every magnet off (mechanical tests: compression, flexure, slope)."""


def dt_substeps(dt, substeps) -> tuple[float, int]:
    """(dt [s], substeps): the given values, else the gait runs' (:data:`warpworm.physics.gaits.DEFAULT_DT`,
    ``DEFAULT_SUBSTEPS``)."""
    return (gaits.DEFAULT_DT if dt is None else float(dt),
            gaits.DEFAULT_SUBSTEPS if substeps is None else int(substeps))


def split_run(core, params: WormParams, num_worlds: int, world_axis: dict, *, workers: int | None = 1,
              device="cpu", model_kw: dict | None = None, **run_kw) -> dict:
    """``core(model, params, **run_kw) -> dict of arrays`` on ``num_worlds`` worlds, the worlds split over
    ``workers`` threads of this process (None: every core), each a batch of a contiguous share with its own Model
    (its parameters sliced by :func:`warpworm.physics.params.slice_worlds`) and Simulator
    (:func:`warpworm.analysis.world_split.run_shares`, as ``simulate --workers`` does). Worlds never interact, so
    every per-world result equals one batch's bit for bit. Each output key is concatenated along ``world_axis[key]``
    (a key not in ``world_axis``: the first share's value, for outputs that do not depend on the worlds).
    """
    quiet_warp()
    mkw = dict(model_kw or {})

    def share(lo, hi):
        p = params if (lo, hi) == (0, num_worlds) else slice_worlds(params, num_worlds, lo, hi)
        return core(Model.from_params(p, hi - lo, device, **mkw), p, **run_kw)

    return concat(run_shares(share, num_worlds, workers, device=device), world_axis)


def section_vertices(n_units: int, section: int, corners=(0, 1, 2)) -> np.ndarray:
    """Vertex indices of the given corners of cross-section ``section`` (0 tail … 2n head); corner 0 bottom-left,
    1 bottom-right, 2 top (docs/crease.md: vertex 3s + k)."""
    if not 0 <= section <= 2 * n_units:
        raise ValueError(f"section must be in [0, {2 * n_units}], got {section}")
    return np.array([3 * section + k for k in corners], np.int32)


def lift_worm(state, dz: float) -> None:
    """Raise every vertex of every world by ``dz`` [m] (a rig that starts the worm above the floor)."""
    x = state.positions.numpy() + np.array([0.0, 0.0, dz], np.float32)
    state.positions.assign(x)


def to_jsonable(obj):
    """Arrays to lists, NumPy scalars to Python, recursively; drops non-data values (models, params)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items() if k not in ("model", "params")}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if np.isfinite(f) else None
    return obj


def save_json(result: dict, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(result)))
    return path
