"""The paper BSDF (issue 24, item 7): wrapped diffuse + Charlie sheen + hemispherical ambient on the sheet, checked
pixel by pixel against the formula evaluated in NumPy on flat facets of known orientation; Lambert unchanged when
off; the draws per trajectory."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.data.sampling import appearance_draws, sample_appearance
from warpworm.render import Renderer, SceneBatch, default_appearance, make_cameras
from warpworm.render.camera import intrinsics, look_at

quiet_warp()
ALBEDO = np.array([0.7, 0.6, 0.5])
PB = np.array([0.3, 0.35, 0.5, 0.4])  # wrap, sheen, roughness, ground
SUN = np.array([0.3, -0.5, 0.81])
SUN /= np.linalg.norm(SUN)


def _facet(normal):
    """A 4 cm square of worm paper (id 4) through the origin with unit ``normal``, lit by the sun only."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    e1 = np.cross(n, [0.3, 0.2, 0.9])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    v = 0.02 * np.array([-e1 - e2, e1 - e2, e1 + e2, -e1 + e2])
    a = default_appearance(1)
    a.albedo = a.albedo.copy()
    a.albedo[0, 4] = ALBEDO
    a.paper_tex = np.zeros((1, 2))
    a.sun_dir, a.sun_color, a.ambient = SUN[None], np.full((1, 3), 0.6), np.full((1, 3), 0.2)
    a.light_power = np.zeros_like(a.light_power)
    a.paper_bsdf = PB[None]
    return SceneBatch.from_mesh(v, np.array([[0, 1, 2], [0, 2, 3]]), [4, 4], floor_half=0.0, appearance=a), n


def _expected(n, p, eye):
    """The BSDF's colour (linear) at points p (k, 3) of a facet with normal n seen from eye: the formula in NumPy."""
    w, s, r, g = PB
    v = eye - p
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    flip = np.where((v @ n) < 0, -1.0, 1.0)[:, None]  # double-sided: the side the camera sees
    nn = n[None] * flip
    ndv = np.maximum((nn * v).sum(1), 1e-4)
    amb = 0.2 * ALBEDO[None] * (g + (1 - g) * 0.5 * (1 + nn[:, 2]))[:, None]
    ndl = nn @ SUN
    diff = 0.6 * ALBEDO[None] * (np.maximum(ndl + w, 0) / (1 + w))[:, None]
    h = SUN[None] + v
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    nh = (nn * h).sum(1)
    d = (2 + 1 / r) * np.maximum(1 - nh**2, 0) ** (0.5 / r) / (2 * np.pi)
    sheen = np.where(ndl > 0, 0.6 * s * d / (4 * (ndl + ndv - ndl * ndv)) * ndl, 0.0)
    return amb + diff + sheen[:, None]


def test_paper_bsdf_matches_its_formula():
    for normal, eye in (([0, 0, 1], [0.05, -0.2, 0.25]), ([0.2, -0.9, 0.3], [0.1, -0.25, 0.05]),
                        ([-0.6, 0.3, -0.74], [-0.15, 0.08, -0.2]), ([0.9, 0.1, -0.2], [0.3, 0.02, 0.1]),
                        ([0, 0, 1], [0.05, -0.2, -0.25])):  # the last sees the back face (normal flipped, ground)
        scene, n = _facet(normal)
        R, t = look_at([eye], [[0.0, 0.0, 0.0]])
        cams = make_cameras(intrinsics(200.0, 200.0, 31.5, 31.5), R, t, 0, 64, 64)
        out = Renderer(64, 64).render(scene, cams)
        mask = out["seg"][0] == 4
        assert mask.sum() > 200
        vv, uu = np.nonzero(mask)
        ray = np.stack([(uu - 31.5) / 200, (vv - 31.5) / 200, np.ones(len(uu))], 1) @ cams.R[0]
        p = cams.position[0] + ray * out["depth"][0][mask][:, None]
        want = np.floor(np.sqrt(np.clip(_expected(n, p, np.asarray(eye, float)), 0, 1)) * 255 + 0.5)
        assert np.abs(out["rgb"][0][mask].astype(float) - want).max() <= 1.0, normal


def test_off_is_lambert():
    scene, n = _facet([0.2, -0.9, 0.3])
    scene.appearance.paper_bsdf = np.zeros((1, 4))
    R, t = look_at([[0.1, -0.25, 0.05]], [[0.0, 0.0, 0.0]])
    cams = make_cameras(intrinsics(200.0, 200.0, 31.5, 31.5), R, t, 0, 64, 64)
    out = Renderer(64, 64).render(scene, cams)
    mask = out["seg"][0] == 4
    lin = ALBEDO * (0.2 + 0.6 * max(n @ SUN, 0.0))
    want = np.floor(np.sqrt(lin) * 255 + 0.5)
    assert np.abs(out["rgb"][0][mask].astype(float) - want).max() <= 1.0


def test_paper_draws():
    cfg = load_config("default", ["render.paper_bsdf=true"])
    app = appearance_draws(cfg, np.arange(50))
    a = sample_appearance(cfg, np.arange(50))
    np.testing.assert_array_equal(a.paper_bsdf[:, 1], app["paper.sheen"])
    assert np.all((a.paper_bsdf[:, 0] >= 0.15) & (a.paper_bsdf[:, 0] <= 0.45))
    assert np.all(sample_appearance(load_config("default"), np.arange(3)).paper_bsdf == 0)
