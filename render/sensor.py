"""Seeded camera-sensor effects with OpenCV: colour jitter, defocus blur, noise, JPEG round trip.

Each image ``i`` draws its effect parameters and noise from its own ``seeds[i]`` (``np.random.default_rng([seed,
0x5E75])``), so it comes out the same in any batch. Effects act on RGB only; depth, segmentation and labels are
unchanged (blur and JPEG move no geometry). The loop over images is OpenCV's per-image API.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


@dataclass
class SensorConfig:
    """Ranges of the per-image effects (uniform draws); a range (0, 0) or probability 0 disables an effect."""

    brightness: tuple = (-0.08, 0.08)
    """Additive brightness offset (fraction of full scale)."""
    contrast: tuple = (0.85, 1.15)
    """Contrast gain about mid-grey."""
    saturation: tuple = (0.8, 1.2)
    """Saturation gain (HSV)."""
    hue_deg: tuple = (-6.0, 6.0)
    """Hue shift [deg]."""
    white_balance: tuple = (0.93, 1.07)
    """Independent gain per channel."""
    blur_sigma: tuple = (0.0, 0.8)
    """Gaussian defocus sigma [px]."""
    noise_sigma: tuple = (0.0, 0.02)
    """Gaussian read noise (fraction of full scale)."""
    shot_noise: tuple = (0.0, 0.01)
    """Signal-dependent noise: sigma = shot * sqrt(value) (fraction of full scale)."""
    jpeg_probability: float = 0.5
    """Chance of a JPEG round trip."""
    jpeg_quality: tuple = (60, 95)
    """JPEG quality range."""


SENSOR_PARAMS = ("wb_r", "wb_g", "wb_b", "hue_deg", "saturation", "contrast", "brightness", "blur_sigma",
                 "noise_sigma", "shot_noise", "jpeg_quality")
"""Per-image effect values (:func:`apply_sensor` ``values``, or drawn from a :class:`SensorConfig`): white-balance
gains, hue shift [deg], saturation gain, contrast, brightness (fraction of full scale), blur sigma [px], read noise and
shot noise (fraction of full scale), JPEG quality (0 = no JPEG round trip)."""


def _draws(u: np.ndarray, cfg: SensorConfig) -> dict:
    def draw(r, k):
        return r[0] + (r[1] - r[0]) * u[k]

    return {"wb_r": draw(cfg.white_balance, 0), "wb_g": draw(cfg.white_balance, 1), "wb_b": draw(cfg.white_balance, 2),
            "hue_deg": draw(cfg.hue_deg, 3), "saturation": draw(cfg.saturation, 4), "contrast": draw(cfg.contrast, 5),
            "brightness": draw(cfg.brightness, 6), "blur_sigma": draw(cfg.blur_sigma, 7),
            "noise_sigma": draw(cfg.noise_sigma, 8), "shot_noise": draw(cfg.shot_noise, 9),
            "jpeg_quality": int(round(draw(cfg.jpeg_quality, 11))) if u[10] < cfg.jpeg_probability else 0}


def apply_sensor(rgb: np.ndarray, seeds, config: SensorConfig | None = None, *, values: dict | None = None
                 ) -> np.ndarray:
    """Sensor effects on a batch ``rgb`` (N, H, W, 3) uint8 with one seed per image; returns a new array.

    ``values``: explicit per-image effect values (name of :data:`SENSOR_PARAMS` -> (N,) array) instead of drawing
    them from ``config`` (e.g. values drawn by a dataset's own distributions); pixel noise still comes from each
    image's seed. Neutral colour values (gains 1, hue 0) skip the colour conversions.
    """
    cfg = SensorConfig() if config is None else config
    seeds = np.asarray(seeds).reshape(-1)
    if len(seeds) != len(rgb):
        raise ValueError(f"need one seed per image: {len(seeds)} seeds for {len(rgb)} images")
    if values is not None:
        missing = [k for k in SENSOR_PARAMS if k not in values]
        if missing:
            raise ValueError(f"values: missing {missing}; expected every name of SENSOR_PARAMS")
        values = {k: np.broadcast_to(np.asarray(values[k]), (len(rgb),)) for k in SENSOR_PARAMS}
    out = np.empty_like(rgb)
    for i in range(len(rgb)):
        rng = np.random.default_rng([int(seeds[i]), 0x5E75])
        u = rng.uniform(size=12)  # drawn even with explicit values, so the noise stream is the same either way
        v = _draws(u, cfg) if values is None else {k: values[k][i] for k in SENSOR_PARAMS}
        img = rgb[i].astype(np.float32) / 255.0
        # colour: white balance, saturation and hue (HSV), contrast, brightness
        wb = np.array([v["wb_r"], v["wb_g"], v["wb_b"]], np.float32)
        if np.any(wb != 1):
            img *= wb
            np.clip(img, 0, 1, out=img)
        if v["hue_deg"] != 0 or v["saturation"] != 1:
            hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)  # float: H in [0, 360)
            hsv[..., 0] = (hsv[..., 0] + v["hue_deg"]) % 360.0
            hsv[..., 1] = np.clip(hsv[..., 1] * v["saturation"], 0, 1)
            img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
        img = (img - 0.5) * v["contrast"] + 0.5 + v["brightness"]
        sigma = float(v["blur_sigma"])
        if sigma > 0.05:
            img = cv2.GaussianBlur(img, (0, 0), sigmaX=sigma)
        ns, ss = float(v["noise_sigma"]), float(v["shot_noise"])
        if ns > 0 or ss > 0:
            # (a scalar std when there is no shot noise: same values, no per-pixel sqrt)
            std = ns + ss * np.sqrt(np.clip(img, 0, 1)) if ss > 0 else img.dtype.type(ns)
            img = img + rng.standard_normal(img.shape).astype(np.float32) * std
        img8 = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
        q = int(v["jpeg_quality"])
        if 0 < q < 100:
            ok, buf = cv2.imencode(".jpg", img8[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
            img8 = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
        out[i] = img8
    return out


def exposure_gains(render_cfg, seeds) -> tuple[np.ndarray, dict] | None:
    """Per-sample exposure and white balance (``render.exposure``, ``render.white_balance``) from each sample's seed
    (stream 0xE7905): linear RGB gains (n, 3) = 2^EV x (red gain, 1, blue gain) for :attr:`Cameras.gain`, and the
    drawn values by name (``sensor.exposure`` [stops], ``sensor.wb_red``, ``sensor.wb_blue``), each (n,). None
    when both are off ([0, 0] stops, gains [1, 1])."""
    ev_lo, ev_hi = render_cfg.exposure
    wb_lo, wb_hi = render_cfg.white_balance
    if ev_lo == ev_hi == 0.0 and wb_lo == wb_hi == 1.0:
        return None
    from warpworm.rng import seed_uniforms

    u = seed_uniforms(np.asarray(seeds).reshape(-1), 0xE7905, 3)
    ev = ev_lo + (ev_hi - ev_lo) * u[:, 0]
    red, blue = wb_lo + (wb_hi - wb_lo) * u[:, 1], wb_lo + (wb_hi - wb_lo) * u[:, 2]
    gain = np.exp2(ev)[:, None] * np.stack([red, np.ones_like(red), blue], axis=1)
    return gain, {"sensor.exposure": ev, "sensor.wb_red": red, "sensor.wb_blue": blue}
