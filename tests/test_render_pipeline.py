"""The renderer's one-pass pipeline: device-resident results equal the host's, and a batch costs a fixed number of
kernel launches whatever its size (shadows, supersampling, a lens and the sensor all on)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import warp as wp

from warpworm.data.config import load_config
from warpworm.data.sampling import sample_appearance
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.sensor import SENSOR_PARAMS, SensorBatch

LENS = (-0.2, 0.05, 0.001, -0.001, 0.0)


def _batch(n_images: int, size: int = 32, lens: bool = True):
    pattern = default_pattern()
    worlds = 2
    st = posed_worm_states(np.arange(worlds), pattern)
    cfg = load_config("default", ["render.lights=random", "render.paper_bsdf=true"])
    scene = build_scene(st["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=pattern.vertices,
                        appearance=sample_appearance(cfg, np.arange(worlds)))
    cams = sample_cameras(np.arange(n_images), st["positions"][np.arange(n_images) % worlds], width=size,
                          height=size, world_index=np.arange(n_images) % worlds)
    if lens:
        cams = dataclasses.replace(cams, dist=np.tile([LENS], (n_images, 1)),
                                   gain=np.tile([[1.2, 1.0, 0.9]], (n_images, 1)))
    values = {k: np.full(n_images, v) for k, v in zip(SENSOR_PARAMS, (1.05, 1.0, 0.95, 3.0, 1.1, 1.1, 0.02, 0.6,
                                                                       0.01, 0.005, 0))}
    return scene, cams, SensorBatch.from_values(values, np.arange(n_images) + 7)


def test_device_result_equals_host_result():
    scene, cams, sensor = _batch(3)
    r = Renderer(32, 32, device="cpu", shadows=True, supersample=2)
    host = {k: v.copy() for k, v in r.render(scene, cams, normals=True, sensor=sensor).items()}
    dev = r.render(scene, cams, normals=True, sensor=sensor, out="device")
    other = dataclasses.replace(cams, R=cams.R[::-1].copy(), t=cams.t[::-1].copy())
    r.render(scene, other, normals=True, sensor=sensor)  # a later batch must not touch the device result
    assert all(isinstance(v, wp.array) for v in dev.values())
    assert set(dev) == set(host)
    assert np.array_equal(dev["rgb"].numpy(), host["rgb"])  # vec3ub (N, H, W) -> (N, H, W, 3)
    assert np.array_equal(dev["depth"].numpy(), host["depth"])
    assert np.array_equal(dev["seg"].numpy(), host["seg"])
    assert np.array_equal(dev["worm_mask"].numpy().astype(bool), host["worm_mask"])
    assert np.array_equal(dev["normals"].numpy(), host["normals"])
    assert host["rgb"].std() > 5  # an image, not a blank


def test_device_output_refuses_a_host_jpeg():
    scene, cams, sensor = _batch(2)
    sensor.jpeg_quality = np.array([80, 0])
    with pytest.raises(ValueError, match="JPEG round trip .* runs on the host"):
        Renderer(32, 32, device="cpu").render(scene, cams, sensor=sensor, out="device")


@pytest.mark.parametrize("lens", [False, True])
def test_launches_do_not_grow_with_the_batch(monkeypatch, lens):
    counts = []
    launch = wp.launch

    def counting(*args, **kwargs):
        counts[-1] += 1
        return launch(*args, **kwargs)

    monkeypatch.setattr(wp, "launch", counting)
    r = Renderer(32, 32, device="cpu", shadows=True, supersample=2)
    for n in (1, 64):
        scene, cams, sensor = _batch(n, lens=lens)
        counts.append(0)
        r.render(scene, cams, sensor=sensor)
    # shadow maps (depths and block minima, minima within reach and pairs), two raster passes, one resolve, three
    # sensor launches; through a lens one more, the image border's rays (the pinhole grid's margins)
    assert counts[0] == counts[1] == 8 + lens, counts


def test_results_do_not_depend_on_the_batch_split():
    scene, cams, sensor = _batch(6)
    whole = Renderer(32, 32, shadows=True, supersample=2).render(scene, cams, sensor=sensor)
    small = Renderer(32, 32, shadows=True, supersample=2, max_chunk_pixels=1)  # one image per chunk
    parts = small.render(scene, cams, sensor=sensor)
    for k in whole:
        assert np.array_equal(whole[k], parts[k]), k
