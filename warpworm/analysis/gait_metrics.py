"""What a gait did, measured from a trajectory: deformation, crawl versus slide, lift, fold violations.

Host-side NumPy on stacked snapshots (``Simulator.snapshot`` keys) of W worlds over F frames; every function is
vectorized over worlds and frames. The quantities follow the paper's §IV-E (Fig. 11): the four deformation ratios are
the distances between adjacent segment centres (keypoints ``seg0..seg4``, tail → head) over their values at the first
frame, so < 1 is a contraction of that part of the worm.
"""

from __future__ import annotations

import numpy as np

from warpworm.physics import crease
from warpworm.physics.params import EPM as EPM_SLOT
from warpworm.physics.params import IPM_CENTRE as IPM_CENTRE_SLOT
from warpworm.physics.params import IPM_HEAD as IPM_HEAD_SLOT


def segment_ratios(pattern: crease.CreasePattern, positions: np.ndarray) -> np.ndarray:
    """Deformation ratios, shape (F, W, 4): adjacent segment-centre distances over their first-frame values.

    Args:
        pattern: the worm's crease pattern (keypoints ``seg0..seg4``).
        positions: vertex positions [m], shape (F, W, V, 3).
    """
    kp = pattern.keypoints(np.asarray(positions, np.float64))
    idx = [pattern.keypoint_names.index(f"seg{i}") for i in range(crease.NUM_SEGMENTS)]
    d = np.linalg.norm(np.diff(kp[..., idx, :], axis=-2), axis=-1)
    return d / d[:1]


def fold_violation(hinge_label: np.ndarray, crease_angle: np.ndarray) -> np.ndarray:
    """How far each crease is outside its NoFoldThrough range [rad] (mountain [−π, 0], valley [0, π]; 0 inside),
    same shape as ``crease_angle`` (..., H)."""
    a = np.asarray(crease_angle, np.float64)
    lab = np.asarray(hinge_label)
    lo = np.where(lab == crease.VALLEY, 0.0, -np.pi)
    hi = np.where(lab == crease.MOUNTAIN, 0.0, np.pi)
    return np.maximum(lo - a, 0.0) + np.maximum(a - hi, 0.0)


def wing_altitude_ratio(hinges: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """The smaller wing altitude over the hinge length of every hinge stencil (i, j, k, l) (shared edge j–k), shape
    ``positions.shape[:-2] + (H,)``: what the kernels' panel contact (``kernels.common.wing_contact``, below 0.02)
    and collapse check (``SLIVER_ALTITUDE``, below 0.005) read; the worm's wings rest at 0.17 or more."""
    x = np.asarray(positions, np.float64)
    xi, xj, xk, xl = (x[..., np.asarray(hinges)[:, c], :] for c in range(4))
    length2 = np.sum((xk - xj) ** 2, axis=-1)
    n1 = np.linalg.norm(np.cross(xj - xi, xk - xi), axis=-1)
    n2 = np.linalg.norm(np.cross(xk - xl, xj - xl), axis=-1)
    return np.minimum(n1, n2) / length2


def end_centres(pattern: crease.CreasePattern, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centres of the tail and head mount rings [m] (the end sections the tail and head IPMs ride on:
    ``pattern.mount_vertices`` rows 0 and 2), each shape ``positions.shape[:-2] + (3,)``."""
    x = np.asarray(positions, np.float64)
    mv = pattern.mount_vertices
    return x[..., mv[0], :].mean(axis=-2), x[..., mv[-1], :].mean(axis=-2)


def _at_time(t, values, when):
    """``values (F, W, ...)`` sampled at times ``t (F,)``, linearly interpolated per world at ``when (W,)`` [s];
    NaN where ``when`` lies outside [t[0], t[-1]]. Vectorized over worlds (one searchsorted)."""
    F, W = values.shape[:2]
    j = np.clip(np.searchsorted(t, when, side="right"), 1, F - 1)  # (W,) t[j-1] <= when < t[j]
    t0, t1 = t[j - 1], t[j]
    a = np.where(t1 > t0, (when - t0) / np.where(t1 > t0, t1 - t0, 1.0), 0.0)
    wi = np.arange(W)
    a = a.reshape((W,) + (1,) * (values.ndim - 2))
    out = (1.0 - a) * values[j - 1, wi] + a * values[j, wi]
    inside = (when >= t[0] - 1e-12) & (when <= t[-1] + 1e-12)
    return np.where(inside.reshape((W,) + (1,) * (values.ndim - 2)), out, np.nan)


def _cycle_measures(s, C: int, centroid, ratios, length, tail, head, mag_x):
    """Per cycle c < C (W, C): centroid displacement [m], smallest segment ratios (W, C, 4), end hold ratio and
    approach placement (see :func:`gait_metrics`), from ``s`` (F, W) cycles, ``centroid``, ``length``, ``tail``,
    ``head`` (F, W) [m], ``ratios`` (F, W, 4) and ``mag_x`` (F, W, 4) [m] along the axis."""
    F, W = s.shape
    cyc_disp = np.zeros((W, C))
    cyc_rmin = np.ones((W, C, 4))
    hold = np.full((W, C), np.nan)
    placement = np.full((W, C), np.nan)
    wi = np.arange(W)
    for c in range(C):  # a few cycles: the loop is over cycles, every operation is over all worlds
        inside = (s >= c - 1e-9) & (s <= c + 1 + 1e-9)  # (F, W)
        first = np.argmax(inside, axis=0)
        last = F - 1 - np.argmax(inside[::-1], axis=0)
        cyc_disp[:, c] = centroid[last, wi] - centroid[first, wi]
        cyc_rmin[:, c] = np.where(inside[..., None], ratios, np.inf).min(axis=0)
        longest = np.argmax(np.where(inside, length, -np.inf), axis=0)
        after = inside & (np.arange(F)[:, None] >= longest[None, :])
        shortest = np.argmin(np.where(after, length, np.inf), axis=0)
        start = np.where(shortest > longest, longest, first)
        shortest = np.where(shortest > longest, shortest, np.argmin(np.where(inside, length, np.inf), axis=0))
        dt_ = np.abs(tail[shortest, wi] - tail[start, wi])
        dh = np.abs(head[shortest, wi] - head[start, wi])
        big = np.maximum(dt_, dh)
        contracted = (shortest != start) & (big > 0)  # a cycle in which the worm never got shorter has no value
        hold[:, c] = np.where(contracted, np.minimum(dt_, dh) / np.where(big > 0, big, 1.0), np.nan)
        near = np.argmin(np.abs(s - (c + 0.5)), axis=0)  # (W,) the frame nearest the closest approach
        mx = mag_x[near, wi]  # (W, 4)
        spacing = mx[:, IPM_HEAD_SLOT] - mx[:, IPM_CENTRE_SLOT]
        placement[:, c] = (mx[:, EPM_SLOT] - mx[:, IPM_CENTRE_SLOT]) / np.where(spacing != 0, spacing, np.nan)
    return cyc_disp, cyc_rmin, hold, placement


def _far_point_measures(s, t, T, centroid, ratios, C: int):
    """The largest centroid motion [m] and |ratio - 1| (W,) in the windows ±0.1 cycle around the far points
    s = 1..C: ``s`` (F, W) cycles, ``t`` (F,) [s], ``T`` (W,) periods [s], ``centroid`` (F, W) [m] along the
    axis, ``ratios`` (F, W, 4)."""
    W = centroid.shape[1]
    far = np.zeros(W)
    far_dev = np.zeros(W)
    for k in range(1, C + 1):
        # the window [k − 0.1, k + 0.1] cycles: its frames plus the values interpolated at its two ends, so that the
        # measure does not depend on whether a frame happens to fall on an end (fps 50 puts one there, fps 25 not)
        win = np.abs(s - k) <= 0.1 + 1e-9
        ends = [_at_time(t, v, (k + e) * T) for e in (-0.1, 0.1) for v in (centroid, ratios)]
        c_lo, r_lo, c_hi, r_hi = ends
        hi = np.maximum(np.where(win, centroid, -np.inf).max(axis=0), np.fmax(c_lo, c_hi))
        lo = np.minimum(np.where(win, centroid, np.inf).min(axis=0), np.fmin(c_lo, c_hi))
        far = np.maximum(far, np.where(np.isfinite(hi - lo), hi - lo, 0.0))
        dev = np.where(win[..., None], np.abs(ratios - 1.0), 0.0).max(axis=(0, 2))
        dev_ends = np.fmax(np.abs(r_lo - 1.0), np.abs(r_hi - 1.0)).max(axis=-1)
        far_dev = np.maximum(far_dev, np.where(np.isfinite(dev_ends), dev_ends, 0.0))
        far_dev = np.maximum(far_dev, dev)
    return far, far_dev


def gait_metrics(pattern, hinge_label, frames: dict, period, incline=0.0) -> dict:
    """Per-world measures of one gait run.

    Args:
        pattern: the crease pattern.
        hinge_label: crease labels (H,).
        frames: stacked snapshots: ``positions (F, W, V, 3)`` [m], ``magnet_pos (F, W, 4, 3)`` [m],
            ``crease_angle (F, W, H)`` [rad], ``time (F,)`` [s] from the start of the gait (t = 0 at the first
            frame's EPM path origin), ``unstable (W,)`` optional.
        period: EPM cycle period [s], scalar or (W,).
        incline: floor slope about +y [rad], scalar or (W,) (the worm axis is (cos β, 0, sin β)).

    Returns a dict of NumPy arrays (W = worlds, C = whole cycles in the run):
        ``deformation_ratio_min``, ``deformation_ratio_max`` (W, 4); ``crease_angle_range_deg`` (W,) the largest
        swing (max − min over time) of any crease; ``tail_displacement_m``, ``head_displacement_m`` (W,) along the
        axis; ``centre_ipm_max_lift_m`` (W,) highest rise of the centre IPM above its first-frame height;
        ``max_fold_violation_deg`` (W,); ``cycle_displacement_m`` (W, C) net motion of the vertex centroid per
        cycle; ``cycle_ratio_min`` (W, C, 4) the smallest ratio of each segment pair in each cycle;
        ``end_hold_ratio`` (W, C): in each cycle's contraction (from its longest head–tail length to the shortest
        after it; from the cycle start when the shortest comes first), the motion of the end that moved less over that of the end that moved more (0: one end held,
        1: both ends moved together, i.e. slid); ``far_point_motion_m`` (W,) the largest centroid motion in the
        windows ±0.1 cycle around the EPM's far points (s = 0, 1, 2, …) after the first (the frames within and
        the centroid interpolated at the window's ends, so the frame rate does not move the window);
        ``far_point_ratio_deviation`` (W,) the largest |ratio − 1| in those windows (has the worm relaxed?);
        ``approach_placement`` (W, C) where the EPM passes at each closest approach (s = c + ½, the frame nearest
        it): its position along the axis from the centre IPM over the centre-to-head IPM spacing (0 under the
        centre IPM, 1 under the head IPM, < 0 toward the tail; the presets start at ``gaits.GAIT_PLACEMENT``, which
        the worm's own motion then shifts);
        ``length_ratio_min`` (W,) the smallest head–tail distance over its first value;
        ``lateral_displacement_m`` (W,) net motion of the vertex centroid across the axis, along +y in the floor plane
        (the EPM path runs along the axis: a worm that crawls straight keeps it ~0); ``lateral_drift_max_m`` (W,) the
        largest |lateral offset| of the centroid from its first frame.
    """
    x = np.asarray(frames["positions"], np.float64)
    F, W = x.shape[:2]
    t = np.asarray(frames["time"], np.float64).reshape(F)
    beta = np.broadcast_to(np.asarray(incline, np.float64), (W,))
    axis = np.stack([np.cos(beta), np.zeros(W), np.sin(beta)], -1)
    T = np.broadcast_to(np.asarray(period, np.float64), (W,))

    ratios = segment_ratios(pattern, x)
    ang = np.asarray(frames["crease_angle"], np.float64)
    viol = fold_violation(hinge_label, ang)
    tail_c, head_c = end_centres(pattern, x)  # (F, W, 3)
    tail = np.einsum("fwc,wc->fw", tail_c, axis)
    head = np.einsum("fwc,wc->fw", head_c, axis)
    centre = x.mean(axis=2)  # (F, W, 3) vertex centroid
    centroid = np.einsum("fwc,wc->fw", centre, axis)
    lateral = centre[..., 1] - centre[:1, :, 1]  # +y lies in the floor plane whatever the incline (about +y)
    normal = np.stack([-np.sin(beta), np.zeros(W), np.cos(beta)], -1)  # the floor's normal: lift is height above it
    mag = np.asarray(frames["magnet_pos"], np.float64)
    lift = np.einsum("fwc,wc->fw", mag[:, :, IPM_CENTRE_SLOT], normal)
    mag_x = np.einsum("fwmc,wc->fwm", mag, axis)  # (F, W, 4) along the worm's axis

    s = t[:, None] / T[None, :]  # (F, W) cycles since the gait started
    C = int(np.floor(s[-1].min() + 1e-9))
    length = np.linalg.norm(head_c - tail_c, axis=-1)  # head–tail distance (a worm that turns is not shorter)
    cyc_disp, cyc_rmin, hold, placement = _cycle_measures(s, C, centroid, ratios, length, tail, head, mag_x)
    far, far_dev = _far_point_measures(s, t, T, centroid, ratios, C)

    return {
        "deformation_ratio_min": ratios.min(axis=0),
        "deformation_ratio_max": ratios.max(axis=0),
        "crease_angle_range_deg": np.degrees((ang.max(axis=0) - ang.min(axis=0)).max(axis=-1)),
        "tail_displacement_m": tail[-1] - tail[0],
        "head_displacement_m": head[-1] - head[0],
        "centre_ipm_max_lift_m": (lift - lift[:1]).max(axis=0),
        "max_fold_violation_deg": np.degrees(viol.max(axis=(0, 2))),
        "cycle_displacement_m": cyc_disp,
        "cycle_ratio_min": cyc_rmin,
        "end_hold_ratio": hold,
        "approach_placement": placement,
        "far_point_motion_m": far,
        "far_point_ratio_deviation": far_dev,
        "length_ratio_min": (length / length[:1]).min(axis=0),
        "lateral_displacement_m": lateral[-1],
        "lateral_drift_max_m": np.abs(lateral).max(axis=0),
    }
