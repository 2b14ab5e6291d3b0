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


def apply_sensor(rgb: np.ndarray, seeds, config: SensorConfig | None = None) -> np.ndarray:
    """Sensor effects on a batch ``rgb`` (N, H, W, 3) uint8 with one seed per image; returns a new array."""
    cfg = SensorConfig() if config is None else config
    seeds = np.asarray(seeds).reshape(-1)
    if len(seeds) != len(rgb):
        raise ValueError(f"need one seed per image: {len(seeds)} seeds for {len(rgb)} images")
    out = np.empty_like(rgb)
    for i in range(len(rgb)):
        rng = np.random.default_rng([int(seeds[i]), 0x5E75])
        u = rng.uniform(size=12)

        def draw(r, k):
            return r[0] + (r[1] - r[0]) * u[k]

        img = rgb[i].astype(np.float32) / 255.0
        # colour: white balance, saturation and hue (HSV), contrast, brightness
        img *= np.array([draw(cfg.white_balance, 0), draw(cfg.white_balance, 1), draw(cfg.white_balance, 2)],
                        np.float32)
        np.clip(img, 0, 1, out=img)
        hsv = cv2.cvtColor(img, cv2.COLOR_RGB2HSV)  # float: H in [0, 360)
        hsv[..., 0] = (hsv[..., 0] + draw(cfg.hue_deg, 3)) % 360.0
        hsv[..., 1] = np.clip(hsv[..., 1] * draw(cfg.saturation, 4), 0, 1)
        img = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
        img = (img - 0.5) * draw(cfg.contrast, 5) + 0.5 + draw(cfg.brightness, 6)
        sigma = draw(cfg.blur_sigma, 7)
        if sigma > 0.05:
            img = cv2.GaussianBlur(img, (0, 0), sigmaX=sigma)
        ns, ss = draw(cfg.noise_sigma, 8), draw(cfg.shot_noise, 9)
        if ns > 0 or ss > 0:
            std = ns + ss * np.sqrt(np.clip(img, 0, 1))
            img = img + rng.standard_normal(img.shape).astype(np.float32) * std
        img8 = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
        if u[10] < cfg.jpeg_probability:
            q = int(round(draw(cfg.jpeg_quality, 11)))
            ok, buf = cv2.imencode(".jpg", img8[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
            img8 = cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1]
        out[i] = img8
    return out
