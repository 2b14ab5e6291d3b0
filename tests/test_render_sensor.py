"""The device sensor effects against OpenCV with explicit values: colour through ``cv2.cvtColor``'s float HSV, blur
against ``cv2.GaussianBlur``, JPEG against an ``imencode`` round trip, noise std measured on a flat image."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from warpworm.render.sensor import SENSOR_PARAMS, SensorBatch, apply_sensor, gaussian_taps

NEUTRAL = dict(zip(SENSOR_PARAMS, (1.0, 1.0, 1.0, 0.0, 1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0)))


def _values(n: int, **changes) -> dict:
    v = {k: np.full(n, float(x)) for k, x in NEUTRAL.items()}
    v.update({k: np.broadcast_to(np.asarray(x, float), (n,)) for k, x in changes.items()})
    return v


def _opencv(img: np.ndarray, v: dict, i: int) -> np.ndarray:
    """The camera chain of one image with OpenCV and NumPy, noise off (the earlier host implementation)."""
    x = img.astype(np.float32) / 255.0
    wb = np.array([v["wb_r"][i], v["wb_g"][i], v["wb_b"][i]], np.float32)
    if np.any(wb != 1):
        x = np.clip(x * wb, 0, 1)
    if v["hue_deg"][i] != 0 or v["saturation"][i] != 1:
        hsv = cv2.cvtColor(x, cv2.COLOR_RGB2HSV)
        hsv[..., 0] = (hsv[..., 0] + np.float32(v["hue_deg"][i])) % 360.0
        hsv[..., 1] = np.clip(hsv[..., 1] * np.float32(v["saturation"][i]), 0, 1)
        x = cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)
    x = (x - np.float32(0.5)) * np.float32(v["contrast"][i]) + np.float32(0.5 + v["brightness"][i])
    if v["blur_sigma"][i] > 0.05:
        x = cv2.GaussianBlur(x, (0, 0), sigmaX=float(v["blur_sigma"][i]))
    return (np.clip(x, 0, 1) * 255 + 0.5).astype(np.uint8)


def _images(n: int, size: int = 48) -> np.ndarray:
    rng = np.random.default_rng(3)
    base = cv2.resize(rng.integers(0, 256, (n * 8, 8, 3)).astype(np.uint8), (size, n * size),
                      interpolation=cv2.INTER_CUBIC)
    return np.ascontiguousarray(base.reshape(n, size, size, 3))


@pytest.mark.parametrize("sigma", [0.3, 0.5, 0.8, 1.7])
def test_blur_is_opencvs_gaussian(sigma):
    img = _images(2)
    v = _values(2, blur_sigma=sigma, contrast=1.1, brightness=-0.02)
    out = apply_sensor(img, [1, 2], values=v)
    ref = np.stack([_opencv(img[i], v, i) for i in range(2)])
    diff = np.abs(out.astype(int) - ref)
    # float32 sums in another order: a rounding flip of one level on a pixel now and then (measured <= 0.05 %)
    assert diff.max() <= 1 and (diff > 0).mean() < 0.005
    # and the blur is the one asked for: sigma 10 % off moves far more pixels
    w = _values(2, blur_sigma=sigma * 1.1, contrast=1.1, brightness=-0.02)
    assert (np.abs(apply_sensor(img, [1, 2], values=w).astype(int) - ref) > 0).mean() > 0.02


def test_each_image_its_own_blur():
    # a batch of different sigmas (kernels of different sides, one without blur): each image as OpenCV blurs it alone
    img = _images(4)
    v = _values(4, blur_sigma=[0.24, 0.0, 0.8, 1.7], contrast=1.05)
    out = apply_sensor(img, [1, 2, 3, 4], values=v)
    ref = np.stack([_opencv(img[i], v, i) for i in range(4)])
    diff = np.abs(out.astype(int) - ref)
    assert diff.max() <= 1 and (diff > 0).mean() < 0.005


def test_taps_are_opencvs_kernel():
    for sigma in (0.3, 0.6, 0.8, 1.3, 2.5):
        w, r = gaussian_taps(np.array([sigma]), 50)
        k = cv2.getGaussianKernel(int(2 * r[0] + 1), sigma, cv2.CV_32F).ravel()
        assert np.array_equal(w[0, : 2 * r[0] + 1], k), sigma


def test_colour_is_opencvs_hsv_path():
    img = _images(3)
    v = _values(3, wb_r=[1.1, 0.9, 1.0], wb_b=[0.95, 1.05, 1.0], hue_deg=[-6.0, 4.0, 0.0],
                saturation=[0.8, 1.2, 1.0], contrast=[0.9, 1.15, 1.0], brightness=[0.05, -0.03, 0.0])
    out = apply_sensor(img, [4, 5, 6], values=v)
    ref = np.stack([_opencv(img[i], v, i) for i in range(3)])
    diff = np.abs(out.astype(int) - ref)
    assert diff.max() <= 1 and (diff > 0).mean() < 0.002
    assert np.array_equal(out[2], img[2])  # neutral values: the image unchanged
    # the hue shift's sign matters: the opposite shift is far from OpenCV's
    w = dict(v, hue_deg=-v["hue_deg"])
    assert np.abs(apply_sensor(img, [4, 5, 6], values=w).astype(int)[:2] - ref[:2]).mean() > 1.0


def test_jpeg_is_an_imencode_round_trip():
    img = _images(3)
    out = apply_sensor(img, [1, 2, 3], values=_values(3, jpeg_quality=[75, 0, 95]))
    for i, q in ((0, 75), (2, 95)):
        _, buf = cv2.imencode(".jpg", img[i][..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, q])
        assert np.array_equal(out[i], cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])
    assert np.array_equal(out[1], img[1])


@pytest.mark.parametrize("read, shot", [(0.02, 0.0), (0.0, 0.03), (0.01, 0.02)])
def test_noise_std_on_a_flat_image(read, shot):
    level = 0.5
    img = np.full((2, 128, 128, 3), int(level * 255 + 0.5), np.uint8)
    out = apply_sensor(img, [11, 12], values=_values(2, noise_sigma=read, shot_noise=shot)).astype(float) / 255
    expected = read + shot * np.sqrt(img[0, 0, 0, 0] / 255.0)
    measured = out.std(axis=(1, 2, 3))
    # quantization adds 1/12 level² of variance; 49,152 draws per image: the std's sampling error 0.32 %, within 1 %
    np.testing.assert_allclose(np.sqrt(measured ** 2 - (1 / 255) ** 2 / 12), expected, rtol=0.01)
    assert abs(out.mean() - img[0, 0, 0, 0] / 255) < 1e-3  # zero mean
    assert not np.array_equal(out[0], out[1])  # each image its own stream


def test_noise_is_gaussian_and_independent():
    # at 0.1 of full scale (25 levels) quantization hardly matters: the draws' shape against the normal law, and no
    # correlation between the channels of a pixel or neighbouring pixels (the draws come in polar pairs)
    img = np.full((1, 256, 256, 3), 128, np.uint8)
    z = (apply_sensor(img, [5], values=_values(1, noise_sigma=0.1)).astype(float)[0] - 128) / 25.5
    flat = z.reshape(-1)
    n = flat.size  # 196,608 draws
    assert abs(flat.mean()) < 5 / np.sqrt(n)  # centred (quantization by rounding adds no bias)
    assert abs(flat.std() - 1.0) < 0.01
    assert abs(np.mean(np.abs(flat) < 1.0) - 0.6827) < 0.005  # ~4.7 sigma of its sampling error
    assert abs(np.mean(np.abs(flat) < 2.0) - 0.9545) < 0.003
    kurtosis = np.mean(flat ** 4) / np.mean(flat ** 2) ** 2
    assert abs(kurtosis - 3.0) < 5 * np.sqrt(24 / n), kurtosis  # quantization moves it by ~1e-4
    bound = 5 / np.sqrt(z.shape[0] * z.shape[1])
    for a, b in [(z[..., 0], z[..., 1]), (z[..., 1], z[..., 2]), (z[:, :-1, 0], z[:, 1:, 0]),
                 (z[:, :-1, 2], z[:, 1:, 0]), (z[:-1, :, 1], z[1:, :, 1])]:
        assert abs(np.corrcoef(a.ravel(), b.ravel())[0, 1]) < bound


def test_noise_follows_each_images_seed_in_any_batch():
    img = _images(3)
    v = _values(3, noise_sigma=0.02, blur_sigma=0.5)
    a = apply_sensor(img, [1, 2, 3], values=v)
    assert np.array_equal(apply_sensor(img[1:2], [2], values=_values(1, noise_sigma=0.02, blur_sigma=0.5))[0], a[1])
    assert not np.array_equal(apply_sensor(img[:1], [9], values=_values(1, noise_sigma=0.02, blur_sigma=0.5))[0],
                              a[0])


def test_drawn_values_are_deterministic_and_checked():
    img = _images(2)
    assert np.array_equal(apply_sensor(img, [1, 2]), apply_sensor(img, [1, 2]))
    with pytest.raises(ValueError, match="missing"):
        SensorBatch.from_values({"wb_r": 1.0}, [1])
    with pytest.raises(ValueError, match="one seed per image"):
        apply_sensor(img, [1])
