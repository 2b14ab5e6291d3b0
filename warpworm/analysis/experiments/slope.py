"""§IV-F: the worm (no magnets) on inclines across atan(μs): its slide vs time beside Coulomb's prediction."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.experiments.common import NO_MAGNETS, dt_substeps, split_run
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator


def _slope_core(model, params, *, frame_times, dt, substeps) -> dict:
    """The simulation of :func:`slope` on one batch: vertex centroids ``(S, W, 3)`` [m] (float64) and world times
    ``(S, W)`` [s] at ``frame_times`` from t = 0, magnets off; ``unstable (W,)`` at the end."""
    sim = Simulator(model, dt=dt, substeps=substeps)
    state = sim.initial_state()
    rec = sim.run(state, frame_times, epm=False, keys=("positions", "time", "unstable"), stack=True)
    return {"centroid": rec["positions"].astype(np.float64).mean(axis=2), "time": rec["time"],
            "unstable": rec["unstable"][-1]}


def slope(offsets_deg=(-4.0, -2.0, -1.0, 1.0, 2.0, 4.0), duration: float = 0.5, *, settle: float = 0.2,
          sample_every: int = 5, base: WormParams | None = None, dt=None, substeps=None, device="cpu",
          slide_threshold: float = 1.0e-4, workers: int | None = 1, **overrides) -> dict:
    """Slope sliding test (§IV-F): the worm (magnets off, damping 0) on inclines β = atan(μs) + offsets, one world each.
    The worm faces uphill (the floor rises toward its head, +x), so it would slide tail-ward: with a skin that grips
    one way (``friction_backward_ratio`` r) both coefficients are r times theirs and the angle is atan(r μs).

    The centroid's motion down the slope is recorded from t = 0 (worm built unloaded at rest on the slope) for
    ``settle + duration`` [s]: ``slide (S, W)`` [m] down-slope, ``predicted (S, W)`` = ½ g (sin β − μk cos β) t² where
    β > atan(μs), else 0. A world "slides" when it moves more than ``slide_threshold`` [m] after ``settle`` (the
    worm takes its weight first; a contact transient may slip a few vertices by ~0.1 mm); the summary gives
    the transition angle bracket. ``workers`` threads share the worlds (:func:`split_run`).
    """
    quiet_warp()
    dt, substeps = dt_substeps(dt, substeps)
    b = base or WormParams()
    skin = float(np.asarray(overrides.get("friction_backward_ratio", b.friction_backward_ratio)))
    mu_s = skin * float(np.asarray(overrides.get("mu_static", b.mu_static)))  # sliding down = tail-ward
    beta = np.arctan(mu_s) + np.deg2rad(np.asarray(offsets_deg, np.float64))
    kw = dict(NO_MAGNETS, damping=0.0)
    kw.update(overrides)
    p = replace(b, floor_incline=beta, **kw)
    W = len(beta)
    down = np.stack([-np.cos(beta), np.zeros(W), -np.sin(beta)], axis=1)  # (W, 3) down the slope
    n_frames = max(1, int(round((settle + duration) / (dt * sample_every))))
    r = split_run(_slope_core, p, W, {"centroid": 1, "time": 1, "unstable": 0}, workers=workers, device=device,
                  frame_times=dt * sample_every * np.arange(n_frames + 1), dt=dt, substeps=substeps)
    ts = r["time"].max(axis=1)  # an unstable world's clock stops: take the max
    slide = np.einsum("swc,wc->sw", r["centroid"] - r["centroid"][0], down)
    s = {"unstable": r["unstable"]}
    g = float(np.asarray(p.gravity))
    mu_k = skin * float(np.asarray(p.mu_kinetic))
    acc = np.where(beta > np.arctan(mu_s), g * (np.sin(beta) - mu_k * np.cos(beta)), 0.0)
    pred = 0.5 * acc[None] * ts[:, None] ** 2
    i0 = int(np.searchsorted(ts, settle - 1e-9))
    after = slide[-1] - slide[i0]  # motion after the settling transient
    slides = after > slide_threshold
    below = np.rad2deg(beta[~slides]).max() if (~slides).any() else float("nan")
    above = np.rad2deg(beta[slides]).min() if slides.any() else float("nan")
    return {
        "beta": beta, "offsets_deg": np.asarray(offsets_deg, np.float64), "time": ts, "slide": slide,
        "predicted": pred, "slides": slides, "unstable": s["unstable"],
        "summary": {
            "mu_static": mu_s, "mu_kinetic": mu_k, "friction_backward_ratio": skin,
            "friction_angle_deg": float(np.rad2deg(np.arctan(mu_s))),
            "beta_deg": np.rad2deg(beta).tolist(), "final_slide_mm": (1e3 * slide[-1]).tolist(),
            "predicted_slide_mm": (1e3 * pred[-1]).tolist(),
            "slide_after_settle_mm": (1e3 * after).tolist(), "settle_s": float(settle),
            "largest_holding_beta_deg": float(below), "smallest_sliding_beta_deg": float(above),
            "duration_s": float(ts[-1]),
        },
    }
