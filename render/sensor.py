"""Seeded camera-sensor effects: colour jitter, defocus blur, noise on the device; a JPEG round trip on the host.

Each image ``i`` draws its effect parameters from its own ``seeds[i]`` (``np.random.default_rng([seed, 0x5E75])``)
unless they are given, and its noise from Warp's counter-based generator keyed by the same seed, so it comes out the
same in any batch and on any device. Effects act on RGB only; depth, segmentation and labels are unchanged (blur and
JPEG move no geometry). The renderer applies them inside its pass (``Renderer.render(..., sensor=SensorBatch)``);
:func:`apply_sensor` does the same to images already on the host.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from statistics import NormalDist

import cv2
import numpy as np
import warp as wp

from warpworm.render import sensor_kernels as snk


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


@dataclass
class SensorBatch:
    """Per-image sensor values of a batch of N images, each an (N,) array (the names of :data:`SENSOR_PARAMS`), and
    each image's noise ``seed``. Build one with :meth:`from_values` or :meth:`draw`."""

    wb_r: np.ndarray
    wb_g: np.ndarray
    wb_b: np.ndarray
    hue_deg: np.ndarray
    saturation: np.ndarray
    contrast: np.ndarray
    brightness: np.ndarray
    blur_sigma: np.ndarray
    noise_sigma: np.ndarray
    shot_noise: np.ndarray
    jpeg_quality: np.ndarray
    seed: np.ndarray
    """(N,) int32: the image's noise stream (from its sample seed, :func:`noise_seeds`)."""

    def __len__(self) -> int:
        return len(self.seed)

    @classmethod
    def from_values(cls, values: dict, seeds) -> "SensorBatch":
        """Explicit values (name of :data:`SENSOR_PARAMS` -> scalar or (N,) array) for images with ``seeds`` (N,)."""
        seeds = np.asarray(seeds).reshape(-1)
        missing = [k for k in SENSOR_PARAMS if k not in values]
        if missing:
            raise ValueError(f"values: missing {missing}; expected every name of SENSOR_PARAMS")
        v = {k: np.broadcast_to(np.asarray(values[k]), (len(seeds),)) for k in SENSOR_PARAMS}
        return cls(**v, seed=noise_seeds(seeds))

    @classmethod
    def draw(cls, seeds, config: "SensorConfig | None" = None) -> "SensorBatch":
        """Values drawn from ``config``'s ranges by each image's seed (12 uniforms of ``[seed, 0x5E75]``)."""
        cfg = SensorConfig() if config is None else config
        seeds = np.asarray(seeds).reshape(-1)
        u = np.array([np.random.default_rng([int(s), 0x5E75]).uniform(size=12) for s in seeds]).reshape(-1, 12)
        draws = [_draws(row, cfg) for row in u]
        return cls.from_values({k: np.array([d[k] for d in draws]) for k in SENSOR_PARAMS}, seeds)

    def take(self, index) -> "SensorBatch":
        """The values of images ``index`` (a slice or indices)."""
        return SensorBatch(**{f.name: np.asarray(getattr(self, f.name))[index] for f in fields(self)})

    def needs_jpeg(self) -> bool:
        """Whether any image has a JPEG round trip (quality 1..99)."""
        q = np.asarray(self.jpeg_quality)
        return bool(np.any((q > 0) & (q < 100)))


def noise_seeds(seeds) -> np.ndarray:
    """Each image's 31-bit noise seed from its (any-width) integer seed: a multiplicative hash of the seed and the
    sensor's stream tag 0x5E75. (N,) int32."""
    s = np.asarray(seeds).reshape(-1).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = (s ^ np.uint64(0x5E75)) * np.uint64(0x9E3779B97F4A7C15)
        h ^= h >> np.uint64(31)
    return (h & np.uint64(0x7FFFFFFF)).astype(np.int32)


def gaussian_taps(sigma: np.ndarray, max_radius: int) -> tuple[np.ndarray, np.ndarray]:
    """Each image's blur kernel as ``cv2.GaussianBlur(img, (0, 0), sigma)`` builds it for float images: side
    ``round(8 sigma + 1) | 1``, weights ``exp(-x² / (2 sigma²))`` normalized in float64, stored as float32. Returns
    (weights (N, 2 R + 1) centred at column R, radius (N,) int32); radius 0 (no blur) where sigma <= 0.05.
    ``max_radius``: a bound (one less than the image's shorter side, for the mirrored border)."""
    sigma = np.asarray(sigma, np.float64).reshape(-1)
    on = sigma > 0.05
    ksize = np.where(on, np.rint(sigma * 8.0 + 1.0).astype(np.int64) | 1, 1)
    radius = np.minimum((ksize - 1) // 2, max_radius)
    R = int(radius.max(initial=0))
    x = np.arange(-R, R + 1, dtype=np.float64)[None]
    s = np.where(on, sigma, 1.0)[:, None]
    w = np.where(np.abs(x) <= radius[:, None], np.exp(-0.5 / (s * s) * x * x), 0.0)
    w /= w.sum(axis=1, keepdims=True)
    return w.astype(np.float32), radius.astype(np.int32)


_NORMAL_TABLES: dict = {}


def normal_table(device) -> wp.array:
    """The standard normal's quantiles at (i + 1/2) / 2^16, i = 0 .. 2^16 - 1 (float32, on ``device``; made once
    per device): the sensor noise's inverse-transform table (:func:`~warpworm.render.sensor_kernels.normal_pair`)."""
    key = str(device)
    if key not in _NORMAL_TABLES:
        n = 1 << snk.NORMAL_TABLE_BITS
        quantile = NormalDist().inv_cdf
        q = np.array([quantile((i + 0.5) / n) for i in range(n)], np.float32)
        _NORMAL_TABLES[key] = wp.array(q, dtype=float, device=device)
    return _NORMAL_TABLES[key]


def launch_sensor(rgb, batch: SensorBatch, width: int, height: int, device, scratch: tuple | None = None) -> None:
    """The device effects of ``batch`` on ``rgb`` (a ``wp.array`` (N, H*W) of vec3ub, in place): colour, blur along
    rows, blur along columns + noise + quantization: three launches whatever N. ``scratch``: two vec3 arrays of at
    least (N, H*W) to work in (the renderer keeps them between chunks); None: allocated here."""
    n = len(batch)
    if n == 0:
        return
    d = device
    f32 = np.float32
    wb = wp.array(np.stack([batch.wb_r, batch.wb_g, batch.wb_b], axis=1).astype(f32), dtype=wp.vec3, device=d)
    hscb = wp.array(np.stack([batch.hue_deg, batch.saturation, batch.contrast, batch.brightness], axis=1).astype(f32),
                    dtype=wp.vec4, device=d)
    w, r = gaussian_taps(batch.blur_sigma, min(width, height) - 1)
    weights = wp.array(w, dtype=float, device=d)
    radius = wp.array(r, dtype=wp.int32, device=d)
    noise = wp.array(np.stack([batch.noise_sigma, batch.shot_noise], axis=1).astype(f32), dtype=wp.vec2, device=d)
    seed = wp.array(np.asarray(batch.seed, np.int32), dtype=wp.int32, device=d)
    if scratch is None:
        scratch = tuple(wp.empty((n, width * height), dtype=wp.vec3, device=d) for _ in range(2))
    a, b = scratch[0][:n], scratch[1][:n]
    wp.launch(snk.sensor_colour, dim=(n, height), inputs=[rgb, wb, hscb, width], outputs=[a], device=d)
    wp.launch(snk.sensor_blur_rows, dim=(n, height), inputs=[a, weights, radius, width], outputs=[b], device=d)
    wp.launch(snk.sensor_blur_cols_noise, dim=(n, height),
              inputs=[b, weights, radius, noise, seed, normal_table(d), width, height], outputs=[rgb], device=d)


def jpeg_round_trip(rgb: np.ndarray, quality) -> np.ndarray:
    """A JPEG encode + decode (OpenCV, 4:2:0) of each image (N, H, W, 3) uint8 whose ``quality`` (N,) is in 1..99;
    the others pass unchanged. The one sensor effect that needs a library: it runs on the host after the batch's
    copy, about 1 ms per 256² image here (docs/render.md)."""
    q = np.asarray(quality).astype(np.int64).reshape(-1)
    sel = np.flatnonzero((q > 0) & (q < 100))
    if len(sel) == 0:
        return rgb
    out = rgb.copy()
    for i in sel:
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb[i], cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, int(q[i])])
        cv2.cvtColor(cv2.imdecode(buf, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB, dst=out[i])
    return out


def apply_sensor(rgb: np.ndarray, seeds, config: SensorConfig | None = None, *, values: dict | None = None,
                 device=None) -> np.ndarray:
    """Sensor effects on a batch ``rgb`` (N, H, W, 3) uint8 already on the host, one seed per image; returns a new
    array. The renderer's own kernels (:func:`launch_sensor`) on ``device`` (default: the CPU), then the JPEG round
    trips.

    ``values``: explicit per-image effect values (name of :data:`SENSOR_PARAMS` -> (N,) array) instead of drawing
    them from ``config`` (e.g. values drawn by a dataset's own distributions); pixel noise still comes from each
    image's seed.
    """
    seeds = np.asarray(seeds).reshape(-1)
    if len(seeds) != len(rgb):
        raise ValueError(f"need one seed per image: {len(seeds)} seeds for {len(rgb)} images")
    batch = SensorBatch.draw(seeds, config) if values is None else SensorBatch.from_values(values, seeds)
    return apply_sensor_batch(rgb, batch, device)


def apply_sensor_batch(rgb: np.ndarray, batch: SensorBatch, device=None) -> np.ndarray:
    """:func:`apply_sensor` with the values already in a :class:`SensorBatch` (one per image of ``rgb``)."""
    N, H, W = rgb.shape[:3]
    if len(batch) != N:
        raise ValueError(f"need one sensor value set per image: {len(batch)} for {N} images")
    if N == 0:
        return rgb.copy()
    d = wp.get_device("cpu" if device is None else device)
    img = wp.array(np.ascontiguousarray(rgb, dtype=np.uint8).reshape(N, H * W, 3), dtype=wp.vec3ub, device=d)
    launch_sensor(img, batch, W, H, d)
    return jpeg_round_trip(img.numpy().reshape(N, H, W, 3), batch.jpeg_quality)


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
