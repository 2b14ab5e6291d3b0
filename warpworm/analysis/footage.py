"""Band footage that warpworm's rasterizer did not draw: a simulated worm path-traced by Mitsuba 3
(:mod:`warpworm.render.pathtrace`, ``scalar_rgb``) under a randomized hard light (a small spherical lamp, optionally
a sun), a dim room light (the constant sky), seen by a camera tilted off vertical with its own K and lens
distortion, then the dataset's sensor effects (:func:`warpworm.render.sensor.apply_sensor`). With it, the band
centres the tracker must find: the centroids of each band's visible pixels through the same camera (the
rasterizer's pixel-centre segmentation of the same scene, which agrees with the path tracer's own first hits,
:func:`warpworm.render.pathtrace.pixel_centre_seg`; docs/render.md) — or, with ``truth="pathtracer"``, the path
tracer's own first hits (undistorted cameras only; slow: one scalar ray per pixel).

Used by the tracker's tests and by ``benchmarks/calibrate_many.py`` (docs/calibration.md).
"""

from __future__ import annotations

import numpy as np

from warpworm import ids
from warpworm.analysis.track import CameraModel
from warpworm.render import (Renderer, default_appearance, focal_from_fov, look_at, make_cameras,
                             scene_from_snapshot)
from warpworm.render.labels import band_pixel_centroids
from warpworm.render.pathtrace import pixel_centre_seg, render_pathtraced
from warpworm.render.scene import band_appearance
from warpworm.render.sensor import apply_sensor


def random_look(rng: np.random.Generator, *, shading: str = "hard") -> dict:
    """One randomized look: ``lamp_pos`` [m] (above the bench at 30-70 degrees elevation, any azimuth),
    ``lamp_power`` (irradiance at 1 m), ``lamp_size`` [m] (radius, 2-8 mm: hard shadows), ``ambient`` (the room
    light, 0.06-0.2 of the lamp's irradiance: a face turned from the lamp shows 25-45 % of its lit value), ``sun`` (irradiance, 0 half the time), ``sun_dir``,
    ``floor`` (the dark floor's linear albedo, 0.01-0.03) and ``tint`` (the lamp's colour, within ±8 % per channel)."""
    az, el = rng.uniform(0, 2 * np.pi), np.radians(rng.uniform(30, 70))
    d = rng.uniform(0.25, 0.4)
    pos = np.array([0.045, 0.0, 0.0]) + d * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    tint = 1 + rng.uniform(-0.08, 0.08, 3)
    amb = rng.uniform(0.06, 0.2) if shading == "hard" else 0.25
    sun_on = rng.uniform() < 0.5
    sd = np.array([rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), 1.0])
    return {"lamp_pos": pos, "lamp_power": rng.uniform(0.06, 0.1) * d ** 2 / 0.09 * tint,
            "lamp_size": rng.uniform(0.002, 0.008), "ambient": np.full(3, amb) * (1 + rng.uniform(-0.05, 0.05, 3)),
            "sun": (rng.uniform(0.2, 0.4) if sun_on else 0.0) * tint, "sun_dir": sd / np.linalg.norm(sd),
            "floor": rng.uniform(0.01, 0.03), "tint": tint}


def random_camera(rng: np.random.Generator, width: int, height: int, *, centre=(0.045, 0.0, 0.0),
                  tilt_deg=(6.0, 14.0), distortion: bool = True, span: float = 0.0) -> CameraModel:
    """A camera 0.17-0.22 m from ``centre`` looking at it, tilted ``tilt_deg`` off vertical toward a random azimuth,
    rolled so image +x is roughly world +x, 24-30 degrees vertical field of view, square pixels, a principal point
    within ±3 % of the centre, radial distortion k1 in ±0.08 (``distortion``); farther when needed for the image's
    shorter side to hold ``span`` [m] (the worm's path) with 15 % to spare."""
    c = np.asarray(centre, np.float64) + np.array([rng.uniform(-0.004, 0.004), rng.uniform(-0.004, 0.004), 0.0])
    tl, az = np.radians(rng.uniform(*tilt_deg)), rng.uniform(0, 2 * np.pi)
    d = rng.uniform(0.17, 0.22)
    fov = np.radians(rng.uniform(24, 30))
    d = max(d, 1.15 * span / (2 * np.tan(fov / 2)))
    eye = c + d * np.array([np.sin(tl) * np.cos(az), np.sin(tl) * np.sin(az), np.cos(tl)])
    R, t = look_at(eye, c, up=(0.0, 1.0, 0.0))
    f = float(focal_from_fov(fov, height))
    K = np.array([[f, 0, (width - 1) / 2 + rng.uniform(-0.03, 0.03) * width],
                  [0, f, (height - 1) / 2 + rng.uniform(-0.03, 0.03) * height], [0, 0, 1.0]])
    dist = np.array([rng.uniform(-0.08, 0.08), 0.0, 0.0, 0.0, 0.0]) if distortion else np.zeros(5)
    return CameraModel(K=K, R=R, t=t, dist=dist)


def _appearance(look: dict, colors, F: int):
    app = default_appearance(1)
    app.albedo = app.albedo.copy()
    app.albedo[:, ids.SEG_FLOOR] = look["floor"]
    app.floor_tex = np.array([[0.02, 0.0, 0.0, 300.0]])
    app.ambient = np.asarray(look["ambient"], np.float64)[None]
    app.sun_color = np.asarray(look["sun"] * np.ones(3), np.float64)[None]
    app.sun_dir = np.asarray(look["sun_dir"], np.float64)[None]
    app.light_pos = np.asarray(look["lamp_pos"], np.float64)[None, None]
    app.light_power = np.asarray(look["lamp_power"], np.float64)[None, None]
    app.light_size = np.array([[float(look["lamp_size"])]])
    app.bg_top = app.bg_bottom = np.full((1, 3), look["floor"])
    return band_appearance(app, colors).take(np.zeros(F, np.int64))


def pathtraced_band_video(frames: dict, model, cam: CameraModel, width: int, height: int, look: dict, *,
                          world: int = 0, colors=None, spp: int = 8, sensor_values: dict | None = None,
                          seed: int = 0, truth: str = "raster", return_seg: bool = False):
    """Path-traced RGB uint8 frames (F, H, W, 3) of world ``world`` of stacked snapshots ``frames`` (as
    :func:`warpworm.analysis.gait_runs.run_gait` returns them) painted with the bands under ``look``
    (:func:`random_look`), through ``cam`` (its distortion included), plus ``sensor_values`` (per-image
    :func:`warpworm.render.sensor.apply_sensor` values, each (F,)); and the true band centres (F, 5, 2) [px]: the
    centroids of each band's visible pixels (``truth`` "raster": the rasterizer's pixel-centre segmentation through
    the same camera; "pathtracer": Mitsuba's own first hit per pixel centre, undistorted cameras only); with
    ``return_seg`` also that segmentation (F, H, W)."""
    pos = np.asarray(frames["positions"])[:, world]
    F = pos.shape[0]
    snap = {"positions": pos, "magnet_pos": np.asarray(frames["magnet_pos"])[:, world],
            "magnet_rot": np.asarray(frames["magnet_rot"])[:, world]}
    p = model.params
    one = lambda v: float(np.ravel(v)[world % np.size(v)])  # noqa: E731
    scene = scene_from_snapshot(snap, model.pattern, None, appearance=_appearance(look, colors, F),
                                rest_vertices=model.rest_positions_host[world],
                                ipm_diameter=one(p.ipm_diameter), ipm_thickness=one(p.ipm_thickness),
                                epm_size=np.asarray(p.epm_size, np.float64).reshape(-1, 3)[0],
                                floor_incline=one(p.floor_incline))
    cams = make_cameras(cam.K, np.broadcast_to(cam.R, (F, 3, 3)), np.broadcast_to(cam.t, (F, 3)), np.arange(F),
                        width, height)
    if np.any(cam.dist != 0):
        cams.dist = np.broadcast_to(np.asarray(cam.dist, np.float64), (F, 5)).copy()
    rgb = render_pathtraced(scene, cams, spp=spp, seeds=seed + np.arange(F))
    if truth == "pathtracer":
        if np.any(cam.dist != 0):
            raise ValueError("truth='pathtracer': expected an undistorted camera (pixel_centre_seg is a pinhole)")
        seg = pixel_centre_seg(scene, cams)
    else:
        seg = Renderer(width, height, device="cpu").render(scene, cams)["seg"]
    centres, _ = band_pixel_centroids(seg)
    if sensor_values is not None:
        rgb = apply_sensor(rgb, seed + np.arange(F), values=sensor_values)
    return (rgb, centres, seg) if return_seg else (rgb, centres)
