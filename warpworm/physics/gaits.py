"""EPM paths: the paper's sinusoidal path (§IV-C), keyframed paths, and the gait presets (§III-A–C).

The worm walks on the top face of a support plate (the floor, z = 0, ``WormParams.support_thickness`` thick); the EPM
moves **beneath** it (§III-B: the EPM's repulsion "pushes the middle of the origami upward"; §IV-C: h is the "closest
approach from the origami base"). The EPM is kinematic: its pose is a function of time evaluated on the device each
step (:func:`warpworm.kernels.magnet_pose.epm_sine_pose` / ``epm_keyframe_pose``).

Sinusoidal path (per world; s = t / period + phase, in cycles)::

    x(t) = x0 + direction · w · s                        advances one wavelength w per cycle (``rewind``:
                                                         w · (s − ⌊s⌋), the pass repeated in place, returning
                                                         smoothly within 0.1 cycle of each far point)
    gap(t) = h + a · (1 + cos 2πs) / 2                   far (h + a) at s = 0, closest approach h at s = 1/2
    z(t) = −(gap(t) + e(θ))                              the EPM's top face ``gap`` below the origami base z = 0
    moment direction = (cos θ, 0, sin θ)                 θ from +x toward +z (up), in the x–z plane

``h`` (``WormParams.closest_approach``) is the gap from the origami base to the EPM's nearest (top) face, at least
the plate's thickness; e(θ) = ½ (L_z |sin θ| + L_x |cos θ|) is the half-height of the tilted EPM cuboid (L_z along its
moment). x0 puts the first closest approach (s = 1/2) at the gait's placement point.

Backward is the mirror image x → −x of forward. A magnetic moment is an axial vector: under that mirror its x
component stays and its z component flips, so θ → −θ (south-up ↔ north-up, "the opposite pole between the posterior
IPMs"), while the IPM configuration (tail −x, centre +x, head −x) maps onto itself. Omega's θ = 0 is its own mirror
image: backward omega keeps the EPM's pose and reverses its path (θ = π would turn every force around, pulling the
centre down instead of repelling it up).

Gait presets (IPM moments: tail −x, centre +x, head −x: the anterior IPMs face each other with their north poles,
the posterior ones with their south poles; forward = +x):

=============  ===========================================  ====================================  =====================
gait           forward: EPM orientation (θ)                 placement (first closest approach)    backward (θ)
=============  ===========================================  ====================================  =====================
peristaltic    south pole up (θ = −π/2): attracts the two   between centre and head IPMs, nearer  north pole up
               anterior north poles, the anterior half      the centre                            (θ = +π/2), between
               contracts                                                                          centre and tail
omega          flat, north pole forward (θ = 0): centre     under the centre IPM                  the same pose, the
               repelled up, ends pulled in                                                        path reversed
inchworm       north pole up (θ = +π/2): anterior half an   between centre and head, nearer the   south pole up
               inverted U                                   centre                                (θ = −π/2), between
                                                                                                  centre and tail
=============  ===========================================  ====================================  =====================

:func:`preset_params` returns :class:`~warpworm.physics.params.WormParams` with a gait's tuned path (w, a, h,
period); the tuning is ``warpworm search-gait``, a batched grid search as the paper's Table I.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from warpworm.physics.params import GAITS, WormParams, per_world

DEFAULT_DT = 4.0e-3
"""Step of the gait runs [s]: the magnetic wrench and EPM pose are refreshed every step."""
DEFAULT_SUBSTEPS = 2
"""Implicit substeps per step in the gait runs (2 ms substeps): converged for the six presets against 0.5 ms ones,
at less Newton work per simulated second than 1 ms ones."""

SINE_FIELDS = ("start_x", "start_y", "wavelength", "amplitude", "depth", "theta", "period", "direction", "phase",
               "rewind")
"""The sinusoidal path's per-world fields (:class:`warpworm.kernels.magnet_pose.SinePath`)."""

# theta (forward, backward) and where the first closest approach is, as a fraction of the way from the centre IPM
# toward the head IPM (forward) or toward the tail IPM (backward); 0 = over the centre IPM.
GAIT_ORIENTATION = {
    "peristaltic": (-0.5 * np.pi, 0.5 * np.pi),
    "omega": (0.0, 0.0),
    "inchworm": (0.5 * np.pi, -0.5 * np.pi),
}
GAIT_PLACEMENT = {"peristaltic": 0.4, "omega": 0.0, "inchworm": 0.2}

# Tuned paths per gait: the best distance per cycle of batched grid searches (warpworm search-gait) among the worlds
# that stay stable and unfolded, keep up with the EPM and deform, kept where they are robust (both magnet models,
# wrench refresh intervals and directions).
GAIT_PRESETS = {
    "peristaltic": dict(wavelength=0.024, amplitude=0.045, closest_approach=0.005, cycle_period=1.0),
    "omega": dict(wavelength=0.016, amplitude=0.03, closest_approach=0.025, cycle_period=1.0),
    "inchworm": dict(wavelength=0.020, amplitude=0.06, closest_approach=0.0055, cycle_period=1.0),
}


@dataclass
class EpmPath:
    """A kinematic EPM path for W worlds.

    ``kind == "sine"``: the fields of :data:`SINE_FIELDS`, each shape (1,) or (W,) [m, rad, s; direction ±1;
    phase in cycles; rewind 0 / 1: 1 repeats the pass of the first cycle in every cycle, x = x0 + direction · w ·
    (s − ⌊s⌋) for s − ⌊s⌋ in [0.1, 0.9], returning smoothly (position and velocity continuous) within 0.1 cycle of
    each far point (``kernels.magnet_pose.rewound_advance``), for a worm tied in place]; ``depth`` is how far below
    the origami base
    (z = 0) the EPM's *centre* is at closest approach (h + the half-height e(θ) of the tilted cuboid).
    ``kind == "keyframes"``: ``key_time (K,)`` [s] ascending, ``key_pos (K, 3)`` or (W, K, 3) [m],
    ``key_rot (K, 3, 3)`` or (W, K, 3, 3) (magnet -> world); linear / slerp between keys, held outside.
    """

    kind: str = "sine"
    start_x: np.ndarray = field(default_factory=lambda: np.zeros(1))
    start_y: np.ndarray = field(default_factory=lambda: np.zeros(1))
    wavelength: np.ndarray = field(default_factory=lambda: np.full(1, 0.02))
    amplitude: np.ndarray = field(default_factory=lambda: np.full(1, 0.03))
    depth: np.ndarray = field(default_factory=lambda: np.full(1, 0.04))
    theta: np.ndarray = field(default_factory=lambda: np.zeros(1))
    period: np.ndarray = field(default_factory=lambda: np.ones(1))
    direction: np.ndarray = field(default_factory=lambda: np.ones(1))
    phase: np.ndarray = field(default_factory=lambda: np.zeros(1))
    rewind: np.ndarray = field(default_factory=lambda: np.zeros(1))
    key_time: np.ndarray | None = None
    key_pos: np.ndarray | None = None
    key_rot: np.ndarray | None = None


def keyframe_path(times, positions, rotations) -> EpmPath:
    """A keyframed EPM path: times (K,) [s], positions (K, 3) or (W, K, 3) [m], rotations (K, 3, 3) or (W, K, 3, 3)."""
    t = np.asarray(times, np.float64).reshape(-1)
    if len(t) < 1 or np.any(np.diff(t) < 0):
        raise ValueError("keyframe_path: need at least one key and ascending times")
    return EpmPath(kind="keyframes", key_time=t, key_pos=np.asarray(positions, np.float64),
                   key_rot=np.asarray(rotations, np.float64))


def epm_half_height(epm_size: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Half the vertical extent e(θ) [m] of the EPM cuboid (extents ``epm_size (W, 3)`` [m] in its own frame, moment
    along its own +z) when its moment is tilted to θ in the x–z plane, shape (W,): its own z axis is
    (cos θ, 0, sin θ) and its own x axis (sin θ, 0, −cos θ), so e = ½ (L_z |sin θ| + L_x |cos θ|)."""
    size = np.asarray(epm_size, np.float64)
    return 0.5 * (size[..., 2] * np.abs(np.sin(theta)) + size[..., 0] * np.abs(np.cos(theta)))


def gait_theta(gait: str, backward: bool) -> float:
    """EPM moment angle θ [rad] of a gait preset (from +x toward +z)."""
    if gait not in GAITS:
        raise ValueError(f"gait must be one of {GAITS}, got {gait!r}")
    return float(GAIT_ORIENTATION[gait][1 if backward else 0])


def per_world_gait(params: WormParams, num_worlds: int) -> tuple[np.ndarray, np.ndarray]:
    """``params.gait`` and ``params.backward`` per world: gait names (W,) str and directions (W,) bool (each field is
    shared, a scalar, or per world, shape (W,))."""
    W = num_worlds
    gait = np.broadcast_to(np.asarray(params.gait, dtype=str), (W,))
    back = np.broadcast_to(np.asarray(params.backward, dtype=bool), (W,))
    bad = sorted(set(gait.tolist()) - set(GAITS))
    if bad:
        raise ValueError(f"worm.gait: got {bad[0]!r}; expected one of {GAITS}")
    return gait, back


def sine_path(params: WormParams, ipm_x: np.ndarray, num_worlds: int) -> EpmPath:
    """The sinusoidal EPM path of ``params`` (gait, backward, w, a, h, θ, period) placed on each world's worm.

    Args:
        params: the batch parameters; ``gait`` and ``backward`` may differ per world (arrays (W,)); ``orientation``
            NaN takes the gait preset's θ; the gap is ``closest_approach × closest_approach_scale`` and the
            wavelength ``wavelength × wavelength_scale``.
        ipm_x: x of the (tail, centre, head) IPM centres at rest [m], shape (W, 3).
        num_worlds: W.
    """
    W = num_worlds
    ipm_x = np.broadcast_to(np.asarray(ipm_x, np.float64), (W, 3))
    gait, back = per_world_gait(params, W)
    g_idx = np.argmax(gait[:, None] == np.asarray(GAITS)[None, :], axis=1)  # (W,) index into GAITS, no world loop
    preset_theta = np.array([GAIT_ORIENTATION[g] for g in GAITS], np.float64)[g_idx, back.astype(np.int64)]
    theta = per_world(params.orientation, W)
    theta = np.where(np.isnan(theta), preset_theta, theta)
    h = per_world(params.closest_approach, W) * per_world(params.closest_approach_scale, W)
    plate = per_world(params.support_thickness, W)
    if np.any(~(h >= plate)):
        bad = float(np.asarray(h)[~(h >= plate)][0])
        raise ValueError(f"worm.closest_approach: {bad} m puts the EPM inside the support plate; expected >= "
                         f"worm.support_thickness ({float(np.max(plate))} m): h is the gap from the origami base "
                         "(z = 0) to the EPM's top face, and the EPM moves beneath the plate")
    frac = np.array([GAIT_PLACEMENT[g] for g in GAITS], np.float64)[g_idx]
    end = np.where(back, ipm_x[:, 0], ipm_x[:, 2])
    place = ipm_x[:, 1] + frac * (end - ipm_x[:, 1])
    direction = np.where(back, -1.0, 1.0)
    w = per_world(params.wavelength, W) * per_world(params.wavelength_scale, W)
    return EpmPath(
        kind="sine",
        start_x=place - direction * 0.5 * w,
        start_y=np.zeros(W),
        wavelength=w,
        amplitude=per_world(params.amplitude, W),
        depth=h + epm_half_height(per_world(params.epm_size, W, (3,)), theta),
        theta=theta,
        period=per_world(params.cycle_period, W),
        direction=direction,
        phase=np.zeros(W),
    )


def preset_params(gait: str, backward: bool = False, base: WormParams | None = None, **overrides) -> WormParams:
    """``base`` (default ``WormParams()``) with the gait, direction and the gait's tuned path parameters set."""
    if gait not in GAITS:
        raise ValueError(f"gait must be one of {GAITS}, got {gait!r}")
    p = replace(base or WormParams(), gait=gait, backward=bool(backward), **GAIT_PRESETS[gait])
    return replace(p, **overrides) if overrides else p
