"""The paper's Table I as a batched search: every (w, a, h) grid point of a gait is one world of one batch.

§IV-C: "the other three parameters are identified using a grid search algorithm to maximize the distance that the
origami moves". :func:`search_gait` runs the whole grid at once (split over threads, one per core, each a batch of
its share of the worlds, :mod:`warpworm.analysis.world_split`; results do not depend on the split since worlds
never interact), measures every world with
:func:`warpworm.analysis.gait_metrics.gait_metrics` and ranks the stable, unfolded worlds by distance per cycle in the
commanded direction.
"""

from __future__ import annotations

import csv
import itertools
import warnings
from dataclasses import replace

import numpy as np

from warpworm.analysis.gait_runs import run_gait_split

GRID_KEYS = {"w": "wavelength", "a": "amplitude", "h": "closest_approach"}
"""Short names of the searchable path parameters -> WormParams fields."""



def parse_grid(spec: str) -> dict[str, np.ndarray]:
    """``"w=0.008:0.024:5,a=0.03,0.05,h=0.01:0.03:5"`` -> {"wavelength": array, ...} [m, s].

    Each key takes ``lo:hi:n`` (n values, linear, ends included) or a comma-separated list of values. Keys: w, a, h
    (the period is one for the whole batch: a share runs its worlds for cycles × the longest period of its share).
    Raises ValueError naming the item and what was expected."""
    out: dict[str, list[float]] = {}
    key = None
    for item in [s.strip() for s in spec.split(",") if s.strip()]:
        if "=" in item:
            key, item = (s.strip() for s in item.split("=", 1))
            if key not in GRID_KEYS:
                raise ValueError(f"--grid: unknown key {key!r}; expected one of {sorted(GRID_KEYS)}")
            if GRID_KEYS[key] in out:
                raise ValueError(f"--grid: key {key!r} given twice")
            out[GRID_KEYS[key]] = []
        elif key is None:
            raise ValueError(f"--grid: {item!r} has no key; expected KEY=VALUES, e.g. w=0.01:0.03:5")
        try:
            if ":" in item:
                lo, hi, n = item.split(":")
                if int(n) < 1:
                    raise ValueError
                vals = np.linspace(float(lo), float(hi), int(n)).tolist()
            else:
                vals = [float(item)]
        except ValueError:
            raise ValueError(f"--grid: {key}={item!r} is not a number or lo:hi:n (n >= 1 values)") from None
        if not all(np.isfinite(vals)) or min(vals) < 0:
            raise ValueError(f"--grid: {key}={item!r}: expected finite values >= 0")
        out[GRID_KEYS[key]].extend(vals)
    if not out:
        raise ValueError("--grid: empty; expected e.g. w=0.01:0.03:5,a=0.04,h=0.01:0.03:5")
    return {k: np.asarray(v) for k, v in out.items()}


def grid_points(grid: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The Cartesian product of the grid: each field an array (N,), N = the product of the lengths."""
    keys = list(grid)
    pts = np.array(list(itertools.product(*[grid[k] for k in keys])), np.float64).reshape(-1, len(keys))
    return {k: pts[:, i] for i, k in enumerate(keys)}


def search_gait(params, grid: dict[str, np.ndarray], cycles: int = 3, *, workers: int | None = None,
                dt: float | None = None, substeps: int | None = None, fps: float = 25.0, settle: float = 0.2,
                max_ratio: float | None = None) -> dict:
    """Run every grid point of ``params``' gait (one world each) and rank them.

    Args:
        params: base WormParams (gait, direction, material); the grid fields override it per world.
        grid: from :func:`parse_grid`.
        cycles: EPM cycles per world.
        workers: threads (default: the machine's cores); each simulates a contiguous share of the worlds.
        max_ratio: if given, a valid world must also deform: some deformation ratio at or below it (e.g. 0.9).

    Returns a dict: ``points`` (field -> (N,)), ``metrics`` (per-world arrays, as gait_metrics, plus ``unstable``,
    ``displacement_m``), ``per_cycle_m`` (N,) mean distance per cycle in the commanded direction (cycles after the
    first when there are several: the first starts from rest), ``valid`` (N,) (below), ``order``
    indices of the valid worlds best first, ``best`` the best point's fields (None if no world is valid). Valid:
    stable (never flagged exploded or crumpled, :class:`~warpworm.sim.simulator.Simulator`), at most 1.05 w per cycle (a
    worm dragged along faster than the EPM advances slides, it does not crawl), and with ``max_ratio`` deforming.
    """
    if int(cycles) < 1:
        raise ValueError(f"cycles: {cycles}; expected at least 1 whole EPM cycle")
    pts = grid_points(grid)
    N = len(next(iter(pts.values())))

    r = run_gait_split(replace(params, **pts), N, cycles, workers=workers, dt=dt, substeps=substeps, settle=settle,
                       fps=fps, save_worlds=0)
    metrics = dict(r["metrics"], unstable=r["unstable"], crumpled=r["crumpled"], displacement_m=r["displacement_m"])
    sign = -1.0 if params.backward else 1.0
    cyc = metrics["cycle_displacement_m"] * sign
    per_cycle = cyc[:, 1:].mean(axis=1) if cyc.shape[1] > 1 else cyc[:, 0]
    w = pts.get("wavelength", np.broadcast_to(np.asarray(params.wavelength, np.float64), (N,)))
    w = w * np.broadcast_to(np.asarray(params.wavelength_scale, np.float64), (N,))
    # stable (the simulator flags a world whose creases fold through its range by more than its fold tolerance), and
    # not dragged further than the EPM advances (a crawl makes at most w per cycle)
    valid = ~metrics["unstable"].astype(bool) & (per_cycle <= 1.05 * w)
    if max_ratio is not None:
        valid &= metrics["deformation_ratio_min"].min(axis=1) <= max_ratio
    order = np.flatnonzero(valid)[np.argsort(-per_cycle[valid], kind="stable")]
    best = {k: float(v[order[0]]) for k, v in pts.items()} if len(order) else None
    return {"points": pts, "metrics": metrics, "per_cycle_m": per_cycle, "valid": valid, "order": order,
            "best": best}


def write_csv(path, result: dict) -> None:
    """One row per grid point: its fields, distance per cycle, validity and the scalar gait metrics."""
    pts, m = result["points"], result["metrics"]
    cols = list(pts) + ["per_cycle_m", "valid"]
    scal = [k for k, v in m.items() if np.asarray(v).ndim == 1]
    ratio = [f"ratio_min_{i}" for i in range(4)]
    with np.errstate(all="ignore"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: no contraction in any cycle
            hold = np.nanmax(m["end_hold_ratio"], axis=1)
    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols + scal + ratio + ["end_hold_max"])
        for i in range(len(result["per_cycle_m"])):
            w.writerow([f"{pts[k][i]:.6g}" for k in pts] + [f"{result['per_cycle_m'][i]:.6g}",
                                                             int(result["valid"][i])]
                       + [f"{float(m[k][i]):.6g}" for k in scal]
                       + [f"{r:.4f}" for r in m["deformation_ratio_min"][i]] + [f"{hold[i]:.4f}"])


def write_heatmap(path, result: dict, x_key: str = "wavelength", y_key: str = "closest_approach") -> None:
    """Distance per cycle over (x_key, y_key) at the best point's other fields (grey: unstable or crumpled)."""
    import cv2  # start-up time: OpenCV loads on first use

    pts, per, valid = result["points"], result["per_cycle_m"], result["valid"]
    if x_key not in pts or y_key not in pts:
        return
    keep = np.ones(len(per), bool)
    if result["best"] is not None:
        for k, v in result["best"].items():
            if k not in (x_key, y_key):
                keep &= np.isclose(pts[k], v)
    xs, ys = np.unique(pts[x_key][keep]), np.unique(pts[y_key][keep])
    cell_w = 48
    cell_h = int(np.clip(720 // max(len(ys), 1), 8, 48))
    grid = np.full((len(ys), len(xs)), np.nan)
    ok = np.zeros_like(grid, bool)
    for i in np.flatnonzero(keep):
        r, c = np.searchsorted(ys, pts[y_key][i]), np.searchsorted(xs, pts[x_key][i])
        grid[r, c], ok[r, c] = per[i], valid[i]
    finite = grid[ok]
    lo, hi = (float(finite.min()), float(finite.max())) if finite.size else (0.0, 1.0)
    u = np.clip((grid - lo) / max(hi - lo, 1e-12), 0, 1)
    img = cv2.applyColorMap((255 * np.nan_to_num(u)).astype(np.uint8), cv2.COLORMAP_VIRIDIS)
    img[~ok] = (128, 128, 128)
    img = cv2.resize(img[::-1], (cell_w * len(xs), cell_h * len(ys)), interpolation=cv2.INTER_NEAREST)
    pad_l, pad_b, pad_t = 90, 60, 40
    canvas = np.full((img.shape[0] + pad_b + pad_t, img.shape[1] + pad_l + 20, 3), 255, np.uint8)
    canvas[pad_t:pad_t + img.shape[0], pad_l:pad_l + img.shape[1]] = img
    font = cv2.FONT_HERSHEY_SIMPLEX
    for c, x in enumerate(xs):
        cv2.putText(canvas, f"{1e3 * x:.0f}", (pad_l + c * cell_w + 8, pad_t + img.shape[0] + 18), font, 0.4, 0, 1)
    step = max(1, int(np.ceil(14 / cell_h)))
    for r, y in enumerate(ys[::-1]):
        if r % step == 0:
            cv2.putText(canvas, f"{1e3 * y:.1f}", (pad_l - 40, pad_t + r * cell_h + cell_h // 2 + 4), font, 0.4, 0, 1)
    cv2.putText(canvas, f"{x_key} [mm]", (pad_l, canvas.shape[0] - 12), font, 0.45, 0, 1)
    cv2.putText(canvas, f"{y_key} [mm]", (4, 20), font, 0.45, 0, 1)
    cv2.putText(canvas, f"distance/cycle {1e3 * lo:.2f} .. {1e3 * hi:.2f} mm (grey: unstable/crumpled)",
                (pad_l, 32), font, 0.4, 0, 1)
    cv2.imwrite(str(path), canvas)
