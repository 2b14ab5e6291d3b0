"""Motion blur from the simulated velocities: the shutter's open interval sampled by sub-frames.

A frame's snapshot holds each sheet vertex's position and velocity; over a shutter open for ``T`` seconds centred on
the frame's time, vertex ``v`` sweeps ``p_v + u_v τ`` for τ in [-T/2, T/2] (the velocities are constant over a
shutter of a few hundredths of a second to first order). :func:`motion_blurred_rgb` renders K sub-frames at
``τ_k = T ((k + ½) / K − ½)`` and averages them in linear RGB (display gamma 2), as a sensor integrates light over
its exposure; every label stays the frame's own (τ = 0). The IPMs ride with the sheet (each moves with the sheet
vertex nearest to it); the EPM, under the plate, is drawn at its frame position.
"""

from __future__ import annotations

import numpy as np


def shutter_offsets(shutter: float, samples: int) -> np.ndarray:
    """Sub-frame times τ_k [s] of a shutter open ``shutter`` seconds, centred on the frame: (K,)."""
    return shutter * ((np.arange(samples) + 0.5) / samples - 0.5)


def displaced_vertices(scene, frame: dict, tau: float, disk_segments: int = 16) -> np.ndarray:
    """The vertices (W, Vs, 3) of a :func:`warpworm.render.scene.build_scene` scene moved by τ [s]: the sheet's V
    vertices (first in the scene) along ``frame["velocities"]`` (W, V, 3), each IPM disk (next, in slot order, 2 +
    2 ``disk_segments`` vertices each) with the sheet vertex nearest to its centre; the rest as they are."""
    x = np.asarray(frame["positions"], dtype=np.float64)
    u = np.asarray(frame["velocities"], dtype=np.float64)
    V = x.shape[1]
    out = scene.vertices.astype(np.float64)
    out[:, :V] += tau * u
    if "magnet_pos" in frame:
        mp = np.asarray(frame["magnet_pos"], dtype=np.float64)
        near = np.argmin(np.linalg.norm(x[:, None] - mp[:, 1:4, None], axis=-1), axis=-1)  # (W, 3)
        step = tau * np.take_along_axis(u, near[..., None], axis=1)  # (W, 3 disks, 3)
        k = 2 + 2 * disk_segments
        for d in range(3):
            out[:, V + d * k:V + (d + 1) * k] += step[:, d, None]
    return out.astype(np.float32)


def motion_blurred_rgb(renderer, scene, cameras, frame: dict, shutter: float, samples: int) -> np.ndarray:
    """RGB (N, H, W, 3) uint8 of ``scene`` seen by ``cameras`` through ``renderer``: the mean, in linear RGB, of the
    K = ``samples`` sub-frames of :func:`shutter_offsets`, each the scene with :func:`displaced_vertices`."""
    import dataclasses

    acc = None
    for tau in shutter_offsets(shutter, samples):
        moved = dataclasses.replace(scene, vertices=displaced_vertices(scene, frame, float(tau)))
        rgb = renderer.render(moved, cameras)["rgb"].astype(np.float32) / 255.0
        acc = rgb * rgb if acc is None else acc + rgb * rgb
    return np.minimum(np.sqrt(acc / samples) * 255.0 + 0.5, 255.0).astype(np.uint8)


__all__ = ["displaced_vertices", "motion_blurred_rgb", "shutter_offsets"]
