"""Plate materials (issue 24, item 6): a clear acrylic plate mixes the EPM under it into its colour by its
transmittance while every label stays the plate's; a glossy plate's highlight of a point light sits at the light's
mirror point."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.data.sampling import appearance_draws, sample_appearance
from warpworm.render import Renderer, build_scene, default_appearance, make_cameras
from warpworm.render.camera import intrinsics, look_at

from test_render_transfer import PATTERN, dataset_like_worms

quiet_warp()


def _render(app, floor_half=1.0, size=(96, 72)):
    x, mp, mr, _, _ = dataset_like_worms(1)
    mp = mp.copy()
    mp[:, 0] = (0.04, 0.0, -0.012)  # the EPM 7 mm under the plate, below the worm
    scene = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=mp, magnet_rot=mr,
                        worm_texcoords=PATTERN.vertices, appearance=app, floor_half=floor_half,
                        epm_size=(0.01, 0.01, 0.01))
    R, t = look_at([[0.04, -0.12, 0.2]], [[0.04, 0.0, 0.0]])
    cams = make_cameras(intrinsics(150, 150, (size[0] - 1) / 2, (size[1] - 1) / 2), R, t, 0, *size)
    return Renderer(*size).render(scene, cams), cams


def test_acrylic_shows_the_epm_by_its_transmittance():
    opaque, _ = _render(default_appearance(1))
    a = default_appearance(1)
    a.floor_transmit = np.array([0.4])
    clear, _ = _render(a)
    under, _ = _render(default_appearance(1), floor_half=0.0)  # the EPM with no plate in front
    for k in ("depth", "seg", "worm_mask"):
        assert np.array_equal(opaque[k], clear[k]), k  # labels: the first surface, the plate
    epm = (under["seg"] == 10) & (opaque["seg"] == 1)
    assert epm.sum() > 20
    lin = lambda r: (r["rgb"][epm].astype(np.float64) / 255) ** 2  # noqa: E731
    pred = np.sqrt(0.6 * lin(opaque) + 0.4 * lin(under)) * 255
    assert np.abs(pred - clear["rgb"][epm]).max() <= 1.5  # three 8-bit roundings through the square and the root
    elsewhere = ~epm & (opaque["seg"] == 1) & (under["seg"] == 0)
    assert np.array_equal(opaque["rgb"][elsewhere], clear["rgb"][elsewhere])


def test_glossy_highlight_at_the_mirror_point():
    a = default_appearance(1)
    a.sun_color = np.zeros((1, 3))
    a.floor_tex = np.array([[0.01, 0.0, 0.0, 300.0]])  # plain plate
    lamp = np.array([0.04, 0.06, 0.15])
    a.light_pos = lamp[None, None]
    a.light_power = np.full((1, 1, 3), 0.004)  # no pixel saturates
    a.ambient = np.full((1, 3), 0.05)
    a.specular = a.specular.copy()
    a.specular[0, 1] = (0.8, 400.0)
    out, cams = _render(a, size=(160, 120))
    matte, _ = _render(_matte(a), size=(160, 120))
    assert out["rgb"].max() < 255
    eye = cams.position[0]
    mirror = lamp * [1, 1, -1]  # the lamp's image in the plate z = 0
    hit = eye + (mirror - eye) * (eye[2] / (eye[2] - mirror[2]))
    uv, _ = cams.project(hit[None, None])
    lin = lambda r: (r["rgb"][0].astype(float) / 255) ** 2  # noqa: E731
    highlight = np.where(out["seg"][0] == 1, (lin(out) - lin(matte)).sum(-1), -1)
    v, u = np.unravel_index(np.argmax(highlight), highlight.shape)
    assert np.hypot(u - uv[0, 0, 0], v - uv[0, 0, 1]) <= 2.0  # the specular lobe peaks at the mirror point
    assert highlight.max() > 0.05


def _matte(a):
    m = a.take([0])
    m.specular = m.specular.copy()
    m.specular[0, 1] = (0.0, 16.0)
    return m


def test_materials_drawn_per_trajectory():
    cfg = load_config("default", ["render.plate_materials=[matte, glossy, acrylic]"])
    app = appearance_draws(cfg, np.arange(300))
    kinds, n = np.unique(app["plate.material"].astype(str), return_counts=True)
    assert list(kinds) == ["acrylic", "glossy", "matte"] and n.min() > 70
    a = sample_appearance(cfg, np.arange(300))
    acrylic = app["plate.material"].astype(str) == "acrylic"
    assert np.all((a.floor_transmit[acrylic] >= 0.3) & (a.floor_transmit[acrylic] <= 0.6))
    assert np.all(a.floor_transmit[~acrylic] == 0)
    assert np.all((a.specular[:, 1, 0] > 0) == (app["plate.material"].astype(str) != "matte"))
