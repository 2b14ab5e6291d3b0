"""§IV-D, E, G: the three gait presets as three worlds of one batch (force plate, strain, deformation) and the
contraction's rise and fall times."""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.experiments.common import dt_substeps, section_vertices, split_run
from warpworm.physics import crease, gaits
from warpworm.physics.params import GAITS, WormParams
from warpworm.sim.model import Model
from warpworm.sim.simulator import Simulator


def _batched_gait_params(gait_list, base: WormParams | None = None, **overrides) -> WormParams:
    """One WormParams for W = len(gait_list) worlds: every scalar field on which the gait presets differ becomes a
    per-world array (``gait`` is set per world by the caller; ``backward`` is shared)."""
    presets = [gaits.preset_params(g, base=base, **overrides) for g in gait_list]
    merged = {}
    for f in fields(WormParams):
        vals = [getattr(p, f.name) for p in presets]
        if f.name in ("gait", "backward", "magnet_model", "n_units"):
            continue
        arrs = [np.asarray(v, np.float64) if not isinstance(v, str) else None for v in vals]
        if any(a is None for a in arrs) or all(np.array_equal(arrs[0], a, equal_nan=True) for a in arrs):
            continue
        if arrs[0].ndim == 0:
            merged[f.name] = np.array([float(a) for a in arrs])
        else:
            merged[f.name] = np.stack([np.broadcast_to(a, arrs[0].shape) for a in arrs])
    return replace(presets[0], **merged)


def gait_model(gait_list, *, anchors=None, anchor_stiffness=1.0e4, base=None, device="cpu", **overrides):
    """A Model with one world per gait in ``gait_list``, each on its own gait's sinusoidal EPM path."""
    p = replace(_batched_gait_params(gait_list, base=base, **overrides), gait=np.array(gait_list, dtype=str))
    model = Model.from_params(p, len(gait_list), device, anchors=anchors, anchor_stiffness=anchor_stiffness)
    return model, p


GAIT_RECORD = ("positions", "bar_strain", "anchor_force", "magnet_pos", "time", "unstable")
"""Snapshot keys a gait record keeps (``time`` per world, (S, W))."""


def _gait_core(model, params, *, duration, sample_every, settle, dt, substeps, rewind=False) -> dict:
    """Settle, then record the keys of :data:`GAIT_RECORD` every ``sample_every`` steps for ``duration`` [s]
    (``rewind``: each world's sinusoidal path repeats its first pass in place, :class:`warpworm.physics.gaits.EpmPath`)."""
    sim = Simulator(model, dt=dt, substeps=substeps)
    if rewind:
        sim.set_path(replace(model.default_path, rewind=np.ones(1)))
    state = sim.initial_state()
    if settle > 0:
        sim.settle(state, settle)
    n_samples = max(1, int(round(duration / (dt * sample_every))))
    rec = sim.run(state, dt * sample_every * np.arange(n_samples + 1), keys=GAIT_RECORD, stack=True)
    rec.pop("clock", None)
    return rec


def run_gaits(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2, anchors=None,
              anchor_stiffness: float = 1.0e4, dt=None, substeps=None, device="cpu", base=None, workers: int | None = 1,
              rewind: bool = False, **overrides) -> dict:
    """Run each gait preset as one world of a batch for ``duration`` [s]; record a trajectory.

    Returns ``gaits`` (list), ``time (S,)``, ``positions (S, W, V, 3)``, ``bar_strain (S, W, E)``,
    ``anchor_force (S, W, A, 3)``, ``magnet_pos (S, W, 4, 3)``, ``unstable (W,)``, ``rest_positions (W, V, 3)``
    (the settled shape at t = 0), ``rewind`` and ``model``. ``workers`` threads share the worlds
    (:func:`split_run`). ``rewind``: every cycle repeats the EPM's first pass in place (a worm tied down).
    """
    quiet_warp()
    gait_list = list(gait_list)
    dt, substeps = dt_substeps(dt, substeps)
    model, p = gait_model(gait_list, anchors=anchors, anchor_stiffness=anchor_stiffness, base=base,
                           device=device, **overrides)
    axis = {"positions": 1, "bar_strain": 1, "anchor_force": 1, "magnet_pos": 1, "time": 1, "unstable": 1}
    frames = split_run(_gait_core, p, len(gait_list), axis, workers=workers, device=device,
                       model_kw=dict(anchors=anchors, anchor_stiffness=anchor_stiffness), duration=duration,
                       sample_every=sample_every, settle=settle, dt=dt, substeps=substeps, rewind=rewind)
    rec = {k: frames[k] for k in ("positions", "bar_strain", "anchor_force", "magnet_pos")}
    rec["time"] = frames["time"].max(axis=1)  # an unstable world's clock stops: take the max
    rec["unstable"] = frames["unstable"][-1]
    rec["rest_positions"] = frames["positions"][0]
    rec["gaits"] = gait_list
    rec["rewind"] = bool(rewind)
    rec["model"] = model
    rec["params"] = p
    return rec


def _crossing(t, y, j, level) -> float:
    """Time [s] where the segment (t[j], y[j]) – (t[j + 1], y[j + 1]) crosses ``level`` (linear interpolation)."""
    dy = y[j + 1] - y[j]
    return float(t[j] + (t[j + 1] - t[j]) * ((level - y[j]) / dy if dy != 0 else 0.5))


def rise_fall_times(t, y, period: float, *, t0: float = 0.0, lo: float = 0.1, hi: float = 0.9,
                    baseline: float | str = 0.0) -> dict:
    """Per-cycle rise and fall times of a pulsed signal (the force plate's pull, paper Fig. 10).

    The record is cut into cycles [t0 + c T, t0 + (c + 1) T) (T = ``period`` [s]; only whole cycles). In each cycle
    the peak is the largest sample; the levels are baseline + ``lo`` / ``hi`` × (peak − baseline), with ``baseline``
    0 by default (10 % and 90 % of the cycle's peak: a force plate reads 0 unloaded; a cycle whose peak is not above
    the baseline gives NaN), any fixed value, or ``"trough"``: each edge from its own trough, the smallest sample
    within one period before the peak (rise) or after it (fall), which follows a drifting offset. The rise time is
    from the last
    upward crossing of the low level before the peak to the last crossing of the high level before it; the fall time
    from the first downward crossing of the high level after the peak to the first crossing of the low level after
    it. Crossings are linearly interpolated between samples and searched within one period of the peak (so a pulse
    may straddle a cycle boundary); a crossing not found gives NaN.

    Args:
        t: sample times [s], shape (S,), ascending.
        y: the signal (any unit), shape (S,).
        period: cycle length T [s].
        t0: start of the first cycle [s] (the EPM path's s = 0; ``Simulator.settle`` restarts the clock at 0).

    Returns: ``rise (C,)``, ``fall (C,)`` [s], ``peak (C,)``, ``baseline (C,)``, ``peak_time (C,)`` [s] per whole cycle,
    and ``rise_mean`` / ``fall_mean`` [s]: the NaN-ignoring means over the cycles after the first (NaN when there is
    only one cycle).
    """
    t = np.asarray(t, np.float64).reshape(-1)
    y = np.asarray(y, np.float64).reshape(-1)
    T = float(period)
    n_cyc = int(np.floor((t[-1] - t0) / T + 1e-9)) if len(t) else 0
    out = {k: np.full(n_cyc, np.nan) for k in ("rise", "fall", "peak", "baseline", "peak_time")}
    for c in range(n_cyc):  # host analysis of a recorded signal (a few cycles), not a loop over worlds
        a, b = t0 + c * T, t0 + (c + 1) * T
        idx = np.nonzero((t >= a - 1e-12) & (t < b - 1e-12))[0]
        if len(idx) < 3:
            continue
        ip = idx[np.argmax(y[idx])]
        peak = y[ip]
        win = (t >= t[ip] - T) & (t <= t[ip] + T)
        if isinstance(baseline, str):
            if baseline != "trough":
                raise ValueError(f"baseline: expected a number or 'trough', got {baseline!r}")
            base_r, base_f = y[:ip + 1][win[:ip + 1]].min(), y[ip:][win[ip:]].min()
        else:
            base_r = base_f = float(baseline)
        out["peak"][c], out["baseline"][c], out["peak_time"][c] = peak, base_r, t[ip]
        if peak > base_r:
            l_lo, l_hi = base_r + lo * (peak - base_r), base_r + hi * (peak - base_r)
            before = np.nonzero(win[:ip] & (y[:ip] < l_hi))[0]
            before_lo = np.nonzero(win[:ip] & (y[:ip] < l_lo))[0]
            if len(before) and len(before_lo):
                out["rise"][c] = _crossing(t, y, before[-1], l_hi) - _crossing(t, y, before_lo[-1], l_lo)
        if peak > base_f:
            l_lo, l_hi = base_f + lo * (peak - base_f), base_f + hi * (peak - base_f)
            after = ip + 1 + np.nonzero(win[ip + 1:] & (y[ip + 1:] < l_hi))[0]
            after_lo = ip + 1 + np.nonzero(win[ip + 1:] & (y[ip + 1:] < l_lo))[0]
            if len(after) and len(after_lo):
                out["fall"][c] = _crossing(t, y, after_lo[0] - 1, l_lo) - _crossing(t, y, after[0] - 1, l_hi)

    def _mean(v):
        v = v[1:]
        return float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")

    out["rise_mean"], out["fall_mean"] = _mean(out["rise"]), _mean(out["fall"])
    return out


def force_plate(gait_list=GAITS, duration: float = 2.0, *, anchor_stiffness: float = 1.0e4, sample_every: int = 2,
                settle: float = 0.2, rewind: bool = True, record: dict | None = None, **kw) -> dict:
    """Force plate (§IV-D): the tail section's 3 vertices tied by anchors (strength ``anchor_stiffness`` [N/m]) to
    their settled rest points while each gait runs. ``force (S, W, 3)`` [N] is the summed anchor force (the worm's
    pull on the plate; +x = forward pull), ``pull (S, W)`` its x component, ``force_magnitude (S, W)`` its length
    (the paper's reading: the Anchor's strength times the displacement vector of the tied point).

    ``rewind`` (default): the EPM repeats its first pass in place every cycle (:class:`warpworm.physics.gaits.EpmPath`), so
    the tied worm is driven the same way in every cycle and the pulses settle to a periodic train. Without it the
    EPM advances w per cycle as in locomotion and leaves the tied worm behind: after two or three cycles it passes
    ahead of the head and the pulses fade, so the per-cycle shapes would describe where the magnet has gone, not the
    gait. With ``record`` (a :func:`run_gaits` record) the run is not repeated and its own ``rewind`` is what the
    summary reports (``rewind`` here is then unused).

    Pulse shape (Fig. 10: the paper's inchworm rises steeply and falls smoothly, omega the reverse): per gait the
    10 %→90 % rise time and 90 %→10 % fall time of the pull in each EPM cycle (:func:`rise_fall_times`),
    ``rise_time (C, W)`` / ``fall_time (C, W)`` [s] with levels at 10 % / 90 % of the cycle's peak (zero baseline;
    NaN in a cycle whose peak pull is not > 0), ``rise_time_trough`` / ``fall_time_trough`` with each edge measured
    from its own trough (robust to a drifting offset), ``rise_time_magnitude`` / ``fall_time_magnitude`` of
    ``force_magnitude`` (zero baseline), and in the summary their means over the cycles after the first (NaN / null
    with fewer than two whole cycles: ``duration`` ≥ 2 periods)."""
    if record is None:
        n = int((kw.get("base") or WormParams()).n_units)
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle,
                           anchors=section_vertices(n, 0), anchor_stiffness=anchor_stiffness, rewind=rewind, **kw)
    F = record["anchor_force"].sum(axis=2).astype(np.float64)  # (S, W, 3)
    t = record["time"]
    pull, magnitude = F[..., 0], np.linalg.norm(F, axis=-1)
    summary = {"gaits": list(record["gaits"]), "duration_s": float(t[-1]), "rewind": bool(record.get("rewind", False)),
               "anchor_stiffness_N_per_m": float(anchor_stiffness),
               "max_pull_mN": (1e3 * pull.max(axis=0)).tolist(), "mean_pull_mN": (1e3 * pull.mean(axis=0)).tolist(),
               "min_pull_mN": (1e3 * pull.min(axis=0)).tolist(),
               "max_abs_force_mN": (1e3 * magnitude.max(axis=0)).tolist(),
               "unstable": record["unstable"].tolist()}
    W = pull.shape[1]
    params = record.get("params")
    periods = (np.broadcast_to(np.asarray(params.cycle_period, np.float64), (W,)) if params is not None
               else np.ones(W))
    res = {}
    for tag, signal, bl in (("", pull, 0.0), ("_trough", pull, "trough"), ("_magnitude", magnitude, 0.0)):
        shapes = [rise_fall_times(t, signal[:, w], periods[w], baseline=bl) for w in range(W)]  # host analysis
        C = min(len(s["rise"]) for s in shapes)
        res["rise_time" + tag] = np.stack([s["rise"][:C] for s in shapes], axis=1) if C else np.zeros((0, W))
        res["fall_time" + tag] = np.stack([s["fall"][:C] for s in shapes], axis=1) if C else np.zeros((0, W))
        rm, fm = np.array([s["rise_mean"] for s in shapes]), np.array([s["fall_mean"] for s in shapes])
        summary.update({
            f"rise_time_10_90{tag}_ms": (1e3 * rm).tolist(),
            f"fall_time_90_10{tag}_ms": (1e3 * fm).tolist(),
            f"rise_over_fall{tag}": np.where(fm > 0, rm / np.where(fm > 0, fm, 1.0), np.nan).tolist(),
        })
    summary.update(cycle_period_s=periods.tolist(), whole_cycles=int(res["rise_time"].shape[0]))
    return {"time": t, "force": F, "pull": pull, "force_magnitude": magnitude, "gaits": list(record["gaits"]),
            "unstable": record["unstable"], **res, "summary": summary}


def strain(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2,
           record: dict | None = None, **kw) -> dict:
    """Bar strain (§IV-G): Cauchy strain (L − L0)/L0 of every bar over each gait (free worm, no anchors).

    ``strain (S, W, E)``, ``max_abs (W, E)`` and ``mean_abs (W, E)`` per bar, ``max_over_bars (S, W)``, the bar
    endpoints' positions at the most strained instant ``peak_positions (W, V, 3)``, ``edges (E, 2)``, ``edge_label``.
    """
    if record is None:
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle, **kw)
    eps = record["bar_strain"].astype(np.float64)  # (S, W, E)
    a = np.abs(eps)
    max_abs, mean_abs = a.max(axis=0), a.mean(axis=0)
    over = a.max(axis=2)  # (S, W)
    ipeak = over.argmax(axis=0)
    W = eps.shape[1]
    peak_pos = record["positions"][ipeak, np.arange(W)]
    pat = record["model"].pattern
    labels = {crease.FLAT: "flat", crease.MOUNTAIN: "mountain", crease.VALLEY: "valley", crease.BOUNDARY: "boundary"}
    per_label = {}
    for lab, name in labels.items():
        m = pat.edge_label == lab
        if m.any():
            per_label[name] = (max_abs[:, m].max(axis=1)).tolist()
    summary = {"gaits": list(record["gaits"]), "duration_s": float(record["time"][-1]),
               "max_abs_strain": max_abs.max(axis=1).tolist(), "mean_abs_strain": mean_abs.mean(axis=1).tolist(),
               "most_strained_bar": max_abs.argmax(axis=1).tolist(), "max_abs_strain_by_label": per_label,
               "unstable": record["unstable"].tolist()}
    return {"time": record["time"], "strain": eps, "max_abs": max_abs, "mean_abs": mean_abs, "max_over_bars": over,
            "peak_positions": peak_pos, "edges": pat.edges, "edge_label": pat.edge_label,
            "gaits": list(record["gaits"]), "unstable": record["unstable"], "summary": summary}


def deformation(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2,
                record: dict | None = None, **kw) -> dict:
    """Deformation ratios and displacement (§IV-E, Fig. 11), free worm, one world per gait.

    The five segment centres ``seg0..seg4`` (``pattern.keypoints``) give four distances between neighbours;
    ``ratio (S, W, 4)`` divides them by their values at t = 0 (the settled worm). ``displacement (S, W)`` [m] is the
    mean x of the five centres relative to t = 0 (net forward motion, +x).
    """
    if record is None:
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle, **kw)
    pat = record["model"].pattern
    idx = [pat.keypoint_names.index(f"seg{i}") for i in range(5)]
    kp = pat.keypoints(record["positions"].astype(np.float64))[..., idx, :]  # (S, W, 5, 3)
    dist = np.linalg.norm(np.diff(kp, axis=2), axis=-1)  # (S, W, 4)
    ratio = dist / dist[0]
    disp = kp[..., 0].mean(axis=2) - kp[0, :, :, 0].mean(axis=1)  # (S, W)
    summary = {"gaits": list(record["gaits"]), "duration_s": float(record["time"][-1]),
               "net_displacement_mm": (1e3 * disp[-1]).tolist(),
               "ratio_min": ratio.min(axis=0).tolist(), "ratio_max": ratio.max(axis=0).tolist(),
               "unstable": record["unstable"].tolist()}
    return {"time": record["time"], "ratio": ratio, "distance": dist, "displacement": disp,
            "keypoints": kp, "gaits": list(record["gaits"]), "unstable": record["unstable"], "summary": summary}
