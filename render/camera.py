"""Pinhole cameras in the OpenCV convention, look-at extrinsics and a seeded shell sampler.

Convention (docs/architecture.md): camera +z forward, +y down, +x right; ``x_cam = R @ x_world + t``; ``K`` is
row-major ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` with positive fx, fy [px]; pixel centres are at integer (u, v),
so the image centre is ``((width - 1) / 2, (height - 1) / 2)``. Exactly what ``cv2.projectPoints(X, rvec, t, K, None)``
computes with ``rvec = cv2.Rodrigues(R)``.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from warpworm.rng import seed_uniforms


@dataclass
class Cameras:
    """A batch of N images: one camera each and the world it looks at."""

    K: np.ndarray
    """Intrinsics, shape (N, 3, 3), float64."""
    R: np.ndarray
    """World-to-camera rotation, shape (N, 3, 3), float64."""
    t: np.ndarray
    """World-to-camera translation [m], shape (N, 3), float64."""
    world: np.ndarray
    """Index of the world each image shows, shape (N,), int32."""
    width: int
    height: int
    accepted: np.ndarray | None = None
    """Sampler only: whether the view met the in-frame requirement, shape (N,), bool."""
    in_frame: np.ndarray | None = None
    """Sampler only: fraction of the worm's points inside the image, shape (N,)."""
    draws: dict | None = None
    """Sampler only: the kept draw of each image, (N,) arrays: ``distance`` [m], ``elevation_deg``,
    ``azimuth_deg``, ``roll_deg``, ``fov_deg`` (along ``fov_axis``), and ``lookat`` (N, 3) [m]."""
    dist: np.ndarray | None = None
    """Lens distortion (k1, k2, p1, p2, k3) of each image, OpenCV's model (:mod:`warpworm.render.distortion`),
    shape (N, 5); None: pinhole. :meth:`project` and the renderer apply it."""
    gain: np.ndarray | None = None
    """Linear RGB gain of each image, (N, 3): exposure (2^EV) times white balance, applied by the renderer before the
    display encoding, as a camera's processing does; None: 1."""

    def __len__(self) -> int:
        return self.K.shape[0]

    @property
    def position(self) -> np.ndarray:
        """Camera centres in the world [m], shape (N, 3): ``-R^T t``."""
        return -np.einsum("nji,nj->ni", self.R, self.t)

    def take(self, index) -> "Cameras":
        """The cameras ``index`` (an int array or slice)."""
        out = {}
        for f in fields(self):
            a = getattr(self, f.name)
            if isinstance(a, dict):
                out[f.name] = {k: v[index] for k, v in a.items()}
            else:
                out[f.name] = a[index] if isinstance(a, np.ndarray) else a
        return Cameras(**out)

    def project(self, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points of each image's world.

        Args:
            points_world: (N, P, 3) points [m] (already gathered per image).
        Returns:
            uv (N, P, 2) pixels, float64 (through ``dist`` when set: ``cv2.projectPoints`` with it); and points in
            the camera frame (N, P, 3) [m].
        """
        pc = np.einsum("nij,npj->npi", self.R, points_world) + self.t[:, None]
        z = pc[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = pc[..., 0] / z
            y = pc[..., 1] / z
        if self.dist is not None:
            from warpworm.render.distortion import distort

            x, y = distort(x, y, np.asarray(self.dist, dtype=np.float64)[:, None, :])
        u = self.K[:, None, 0, 0] * x + self.K[:, None, 0, 1] * y + self.K[:, None, 0, 2]
        v = self.K[:, None, 1, 1] * y + self.K[:, None, 1, 2]
        return np.stack([u, v], axis=-1), pc


def intrinsics(fx, fy, cx, cy) -> np.ndarray:
    """K matrices from broadcastable (fx, fy, cx, cy) [px], shape (..., 3, 3)."""
    fx, fy, cx, cy = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (fx, fy, cx, cy)))
    K = np.zeros(fx.shape + (3, 3))
    K[..., 0, 0] = fx
    K[..., 1, 1] = fy
    K[..., 0, 2] = cx
    K[..., 1, 2] = cy
    K[..., 2, 2] = 1.0
    return K


def focal_from_fov(fov_rad, size) -> np.ndarray:
    """Focal length [px] that spans the horizontal field of view ``fov_rad`` over ``size`` pixels."""
    return 0.5 * size / np.tan(0.5 * np.asarray(fov_rad, dtype=np.float64))


def look_at(eye, target, up=(0.0, 0.0, 1.0), roll=0.0) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV extrinsics of cameras at ``eye`` looking at ``target`` with ``up`` (world) on top of the image.

    Args:
        eye, target: (..., 3) [m]. up: (3,) or (..., 3). roll: rotation about the optical axis [rad], (...,).
    Returns:
        R (..., 3, 3) world-to-camera and t (..., 3) with ``x_cam = R x_world + t``.
    """
    eye = np.asarray(eye, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    f = target - eye
    f = f / np.linalg.norm(f, axis=-1, keepdims=True)
    upv = np.broadcast_to(np.asarray(up, dtype=np.float64), f.shape)
    x = np.cross(f, upv)
    nx = np.linalg.norm(x, axis=-1, keepdims=True)
    # looking straight along up: any right vector works; take world x projected off f
    alt = np.cross(f, np.broadcast_to([0.0, 1.0, 0.0], f.shape))
    x = np.where(nx > 1e-9, x / np.maximum(nx, 1e-300), alt / np.linalg.norm(alt, axis=-1, keepdims=True))
    y = np.cross(f, x)  # +y down in the image
    roll = np.asarray(roll, dtype=np.float64)[..., None]
    c, s = np.cos(roll), np.sin(roll)
    xr = c * x + s * y
    yr = -s * x + c * y
    R = np.stack([xr, yr, f], axis=-2)
    t = -np.einsum("...ij,...j->...i", R, eye)
    return R, t


def make_cameras(K, R, t, world, width: int, height: int) -> Cameras:
    """Cameras from arrays (broadcast K over N when one is given)."""
    R = np.asarray(R, dtype=np.float64).reshape(-1, 3, 3)
    N = R.shape[0]
    K = np.broadcast_to(np.asarray(K, dtype=np.float64), (N, 3, 3)).copy()
    t = np.asarray(t, dtype=np.float64).reshape(N, 3)
    world = np.broadcast_to(np.asarray(world, dtype=np.int32), (N,)).copy()
    return Cameras(K=K, R=R.copy(), t=t.copy(), world=world, width=int(width), height=int(height))


def _between(u: np.ndarray, lo_hi) -> np.ndarray:
    """Uniforms in [0, 1) mapped to [lo, hi)."""
    lo, hi = lo_hi
    return lo + (hi - lo) * u


def _view_from_uniforms(u: np.ndarray, look_centre: np.ndarray, *, distance, elevation_deg, azimuth_deg, roll_deg,
                        lookat_jitter, fov_deg, fov_axis, aspect_jitter, principal_jitter, width, height, up):
    """One view per row of uniforms ``u`` (n, 12) around look-at centres (n, 3) [m] (the ranges of
    :func:`sample_cameras`): (K (n, 3, 3), R (n, 3, 3), t (n, 3), the drawn values by name, (n,) or (n, 3))."""
    dist = _between(u[:, 0], distance)
    el_deg = _between(u[:, 1], elevation_deg)
    az_deg = _between(u[:, 2], azimuth_deg)
    roll_d = _between(u[:, 3], roll_deg)
    el, az, roll = np.deg2rad(el_deg), np.deg2rad(az_deg), np.deg2rad(roll_d)
    look = look_centre + lookat_jitter * (2 * u[:, 4:7] - 1)
    eye = look + dist[:, None] * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], 1)
    R, t = look_at(eye, look, up=up, roll=roll)
    fov = _between(u[:, 7], fov_deg)
    if fov_axis == "x":
        fx = focal_from_fov(np.deg2rad(fov), width)
        fy = fx * (1 + aspect_jitter * (2 * u[:, 8] - 1))
    else:
        fy = focal_from_fov(np.deg2rad(fov), height)
        fx = fy * (1 + aspect_jitter * (2 * u[:, 8] - 1))
    cx = (width - 1) / 2 + principal_jitter * width * (2 * u[:, 9] - 1)
    cy = (height - 1) / 2 + principal_jitter * height * (2 * u[:, 10] - 1)
    drawn = {"distance": dist, "elevation_deg": el_deg, "azimuth_deg": az_deg, "roll_deg": roll_d, "fov_deg": fov,
             "lookat": look}
    return intrinsics(fx, fy, cx, cy), R, t, drawn


def _in_frame_fraction(cams: "Cameras", pts: np.ndarray, margin: float) -> np.ndarray:
    """Fraction of each image's points (n, P, 3) [m] in front of its camera and at least ``margin`` px inside."""
    uv, pc = cams.project(pts)
    inside = ((pc[..., 2] > 1e-3) & (uv[..., 0] >= margin) & (uv[..., 0] <= cams.width - 1 - margin)
              & (uv[..., 1] >= margin) & (uv[..., 1] <= cams.height - 1 - margin))
    return inside.mean(axis=1)


def sample_cameras(
    seeds,
    worm_points,
    *,
    width: int,
    height: int,
    world_index=None,
    target=None,
    distance=(0.15, 0.35),
    elevation_deg=(20.0, 80.0),
    azimuth_deg=(-180.0, 180.0),
    roll_deg=(-10.0, 10.0),
    lookat_jitter: float = 0.01,
    fov_deg=(35.0, 60.0),
    fov_axis: str = "x",
    aspect_jitter: float = 0.02,
    principal_jitter: float = 0.02,
    min_in_frame: float = 0.98,
    margin: float = 2.0,
    max_tries: int = 16,
    up=(0.0, 0.0, 1.0),
) -> Cameras:
    """Cameras on a shell around each world's worm, resampled until the worm is in frame.

    Every image ``i`` draws from its own ``seeds[i]`` with the counter-based generator
    (:func:`warpworm.rng.seed_uniforms`), so its camera does not depend on the batch it is drawn in. Attempts are vectorised over images; an image whose worm is less
    than ``min_in_frame`` inside the image (fraction of ``worm_points`` projecting at least ``margin`` px inside,
    in front of the camera) draws again, up to ``max_tries``; then the best attempt is kept and ``accepted`` is False.

    Args:
        seeds: one integer per image, shape (N,).
        worm_points: points whose in-frame fraction is tested (e.g. the worm's vertices) [m], shape (W, P, 3).
        width, height: image size [px].
        world_index: world of each image, (N,); default ``arange(N) % W``.
        target: look-at centre per world [m], (W, 3); default the mean of ``worm_points``.
        distance: camera-to-target range [m]. elevation_deg: above the horizontal plane (world z up) [deg].
        azimuth_deg: about world z, 0 = looking from +x [deg]. roll_deg: about the optical axis [deg].
        lookat_jitter: uniform jitter of the look-at point in a cube of this half side [m].
        fov_deg: field of view range [deg] along ``fov_axis`` ("x": horizontal over ``width``, "y": vertical over
            ``height``). aspect_jitter: relative fy/fx jitter (pixel aspect).
        principal_jitter: principal point offset range as a fraction of the image size.
        min_in_frame, margin, max_tries: rejection rule above. up: world up vector.
    """
    if fov_axis not in ("x", "y"):
        raise ValueError(f"fov_axis: got {fov_axis!r}; expected 'x' or 'y'")
    seeds = np.asarray(seeds).reshape(-1)
    N = seeds.shape[0]
    pts = np.asarray(worm_points, dtype=np.float64)
    W = pts.shape[0]
    wi = np.arange(N) % W if world_index is None else np.asarray(world_index).reshape(N)
    tgt = pts.mean(axis=1) if target is None else np.asarray(target, dtype=np.float64)
    K = np.zeros((N, 3, 3))
    R = np.zeros((N, 3, 3))
    t = np.zeros((N, 3))
    frac = np.full(N, -1.0)
    accepted = np.zeros(N, dtype=bool)
    draws = {k: np.zeros(N) for k in ("distance", "elevation_deg", "azimuth_deg", "roll_deg", "fov_deg")}
    draws["lookat"] = np.zeros((N, 3))
    pending = np.arange(N)
    for attempt in range(max_tries):
        if pending.size == 0:
            break
        u = seed_uniforms(seeds[pending], 0xCA3E0 + attempt, 12)
        Ki, Ri, ti, drawn = _view_from_uniforms(
            u, tgt[wi[pending]], distance=distance, elevation_deg=elevation_deg, azimuth_deg=azimuth_deg,
            roll_deg=roll_deg, lookat_jitter=lookat_jitter, fov_deg=fov_deg, fov_axis=fov_axis,
            aspect_jitter=aspect_jitter, principal_jitter=principal_jitter, width=width, height=height, up=up)
        cams = Cameras(K=Ki, R=Ri, t=ti, world=wi[pending], width=width, height=height)
        fr = _in_frame_fraction(cams, pts[wi[pending]], margin)
        better = fr > frac[pending]  # keep the best attempt for images that never pass
        idx = pending[better]
        K[idx], R[idx], t[idx], frac[idx] = Ki[better], Ri[better], ti[better], fr[better]
        for k, v in drawn.items():
            draws[k][idx] = v[better]
        ok = fr >= min_in_frame
        accepted[pending[ok]] = True
        pending = pending[~ok]
    return Cameras(K=K, R=R, t=t, world=wi.astype(np.int32), width=int(width), height=int(height),
                   accepted=accepted, in_frame=frac, draws=draws)
