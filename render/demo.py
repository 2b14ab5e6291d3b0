"""Synthetic worm states for tests, benchmarks and the CLI when no simulator output is at hand.

:func:`posed_worm_states` bends the crease pattern's rest sheet along its axis (a smooth, seeded arc in the vertical
and the horizontal plane), places it on the floor at a random yaw and offset, computes the IPM poses from the mounts
and puts the EPM above it: a snapshot-like dict with the keys :func:`warpworm.render.labels.schema_labels` reads.
"""

from __future__ import annotations

import numpy as np

from warpworm.rng import seed_uniforms
from warpworm.transforms import axis_angle_to_matrix


def default_pattern():
    """The paper's worm (a = 20 mm, b = 8 mm, 6 units, l0 = 80 mm) from :mod:`warpworm.physics.crease`."""
    from warpworm.physics.crease import build_worm

    return build_worm(0.020, 0.008, 6, l0=0.080)


def _bend(x: np.ndarray, curv_v: np.ndarray, curv_h: np.ndarray) -> np.ndarray:
    """Bend rest vertices (V, 3) along x into arcs of curvature curv_v (in x-z) and curv_h (in x-y), per world."""
    W = curv_v.shape[0]
    xc = x[:, 0].mean()
    s = x[None, :, 0] - xc  # arc length from the middle, (1, V)
    out = np.broadcast_to(x, (W,) + x.shape).copy()
    for k, (curv, ax) in enumerate(((curv_v, 2), (curv_h, 1))):
        c = np.where(np.abs(curv) < 1e-6, 1e-6, curv)[:, None]
        r = out[..., ax] - (x[None, :, ax].mean() if ax == 1 else 0.0)
        th = s * c
        # a point at arc length s, offset r toward the centre of curvature, on an arc of radius 1/c
        newx = xc + (1.0 / c - r) * np.sin(th)
        newr = 1.0 / c - (1.0 / c - r) * np.cos(th)
        out[..., 0] = newx
        out[..., ax] = newr + (x[None, :, ax].mean() if ax == 1 else 0.0)
        s = out[..., 0] - xc
    return out


def posed_worm_states(seeds, pattern=None, *, bend: float = 8.0, spread: float = 0.02, epm_height=(0.04, 0.07),
                      lift: float = 0.0) -> dict:
    """Snapshot-like states of W worlds, one per seed (independent of batching).

    Args:
        seeds: one integer per world, (W,).
        pattern: crease pattern (default :func:`default_pattern`).
        bend: largest curvature [1/m] of the vertical and horizontal arcs.
        spread: largest offset of the worm's centre from the origin in x and y [m].
        epm_height: range of the EPM centre's height above the worm [m].
        lift: lift the worm this far off the floor [m].
    Returns:
        dict with ``positions`` (W, V, 3), ``magnet_pos`` (W, 4, 3), ``magnet_rot`` (W, 4, 3, 3),
        ``crease_angle`` (W, H), ``bar_strain`` (W, E) (float64, SI).
    """
    from warpworm.physics.crease import dihedral_angles, edge_lengths, mount_poses

    p = default_pattern() if pattern is None else pattern
    seeds = np.asarray(seeds).reshape(-1)
    W = seeds.shape[0]
    u = seed_uniforms(seeds, 0xD3E0, 12)
    x = _bend(p.vertices, bend * (2 * u[:, 0] - 1), bend * (2 * u[:, 1] - 1))
    x[..., 2] -= x[..., 2].min(axis=1, keepdims=True) - lift  # rest on the floor
    yaw = 2 * np.pi * u[:, 2]
    Rz = axis_angle_to_matrix([0, 0, 1], yaw)
    centre = x.mean(axis=1, keepdims=True) * np.array([1, 1, 0])
    shift = spread * (2 * u[:, 3:5] - 1)
    x = np.einsum("wij,wvj->wvi", Rz, x - centre) + np.concatenate([shift, np.zeros((W, 1))], 1)[:, None]
    mp, mr = mount_poses(p, x)
    epm_p = x.mean(axis=1) + np.stack([0.01 * (2 * u[:, 5] - 1), 0.01 * (2 * u[:, 6] - 1),
                                       epm_height[0] + (epm_height[1] - epm_height[0]) * u[:, 7]], 1)
    epm_r = np.einsum("wij,wjk->wik", axis_angle_to_matrix([0, 0, 1], 2 * np.pi * u[:, 8]),
                      axis_angle_to_matrix([0, 1, 0], np.pi * (u[:, 9] - 0.5)))
    L = edge_lengths(x, p.edges)
    return {
        "positions": x,
        "magnet_pos": np.concatenate([epm_p[:, None], mp], axis=1),
        "magnet_rot": np.concatenate([epm_r[:, None], mr], axis=1),
        "crease_angle": dihedral_angles(x, p.hinges),
        "bar_strain": L / p.edge_rest_length - 1.0,
    }
