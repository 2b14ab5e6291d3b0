"""Nothing world-fixed relative to the worm (issue 24, item 1): with ``render.plate_pose`` and ``render.lights:
random`` no rendered cue around the worm tells its head from its tail, while the fixed lamp of before does; the posed
plate's floor and the drawn lights are where the draws say (independent re-derivations)."""

from __future__ import annotations

import numpy as np
import pytest

from warpworm import quiet_warp
from warpworm.data.config import ConfigError, load_config
from warpworm.rng import seed_uniforms
from warpworm.data.sampling import appearance_draws, dataset_cameras, sample_appearance
from warpworm.render import Renderer, build_scene, default_appearance, make_cameras
from warpworm.render.camera import intrinsics, look_at
from warpworm.render.demo import _bend, default_pattern
from warpworm.render.placement import distractor_mesh, place
from warpworm.render.raycast import RayCaster

quiet_warp()
PATTERN = default_pattern()
ON = ["render.plate_pose=true", "render.lights=random"]
OFF = ["render.plate_pose=false", "render.lights=fixed"]  # the look of before (the default config's until issue 24)


def dataset_like_worms(n: int):
    """n gently bent worms as a dataset's trajectories start: tail at the origin, heading +x, on the floor, the EPM
    under the floor. Returns (positions (n, V, 3), magnet_pos (n, 4, 3), magnet_rot (n, 4, 3, 3), tail (n, 3),
    head (n, 3)) [m]."""
    from warpworm.physics.crease import mount_poses

    u = seed_uniforms(np.arange(n), 0xBEEF, 2)
    x = _bend(PATTERN.vertices, 6 * (2 * u[:, 0] - 1), 6 * (2 * u[:, 1] - 1))
    x[..., 2] -= x[..., 2].min(axis=1, keepdims=True)
    x[..., 0] -= x[..., 0].min(axis=1, keepdims=True)
    mp, mr = mount_poses(PATTERN, x)
    epm = np.broadcast_to([0.04, 0.0, -0.03], (n, 1, 3))
    xs = x[..., 0:1]
    tail = (x * (xs <= xs.min(axis=1, keepdims=True) + 1e-6)).sum(1) / (xs <= xs.min(1, keepdims=True) + 1e-6).sum(1)
    head = (x * (xs >= xs.max(axis=1, keepdims=True) - 1e-6)).sum(1) / (xs >= xs.max(1, keepdims=True) - 1e-6).sum(1)
    return (x, np.concatenate([epm, mp], 1), np.concatenate([np.broadcast_to(np.eye(3), (n, 1, 3, 3)), mr], 1),
            tail, head)


def head_tail_differences(overrides, n: int = 256, shadows: bool = False) -> np.ndarray:
    """Per image of n dataset-like scenes (the config's looks, lights and cameras, its 128 x 96 images): the floor
    around the worm split at the perpendicular bisector of its tail -> head axis in the image (floor pixels within one
    worm length of its middle), as (log of the head half's mean luminance over the tail half's, head half's
    luminance std - tail half's [8-bit levels]), shape (n', 2) for the n' images with >= 20 pixels on each side."""
    cfg = load_config("default", list(overrides))
    x, mp, mr, tail, head = dataset_like_worms(n)
    ids = np.arange(n)
    scene = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=mp, magnet_rot=mr,
                        worm_texcoords=PATTERN.vertices, appearance=sample_appearance(cfg, ids),
                        extra_mesh=distractor_mesh(appearance_draws(cfg, ids), n))
    cams, _ = dataset_cameras(cfg, ids, x)
    cams.world = ids.astype(np.int32)
    out = Renderer(cfg.render.width, cfg.render.height, shadows=shadows).render(scene, cams)
    uv, _ = cams.project(np.stack([tail, head], axis=1))
    H, W = out["seg"].shape[1:]
    yy, xx = np.mgrid[0:H, 0:W]
    lum = out["rgb"].astype(np.float64).mean(axis=-1)
    rows = []
    for i in range(n):
        mid, axis = uv[i].mean(axis=0), uv[i, 1] - uv[i, 0]
        rel = np.stack([xx - mid[0], yy - mid[1]], axis=-1)
        near = (np.linalg.norm(rel, axis=-1) < np.linalg.norm(axis)) & (out["seg"][i] == 1)
        side = rel @ axis
        h, t = near & (side > 0), near & (side < 0)
        if h.sum() >= 20 and t.sum() >= 20:
            rows.append((np.log(lum[i][h].mean() / lum[i][t].mean()), lum[i][h].std() - lum[i][t].std()))
    return np.array(rows)


def z_scores(d: np.ndarray) -> np.ndarray:
    """Mean over its standard error, per column: a paired test of 'no difference between the halves'."""
    return d.mean(axis=0) / (d.std(axis=0, ddof=1) / np.sqrt(len(d)))


def test_fixed_lamp_tells_head_from_tail():
    # the old setting: lamp at (-0.15, 0.2, 0.3) m, worms heading +x -> the tail's floor is brighter (measured
    # z = -30 for the luminance, -6.7 for the texture contrast)
    d = head_tail_differences(OFF)
    assert len(d) > 200
    z = z_scores(d)
    assert z[0] < -10 and abs(z[1]) > 4, z


@pytest.mark.parametrize("shadows,more", [(False, []), (True, []), (False, ["render.distractors=[2, 5]"])])
def test_posed_plate_and_random_lights_hide_head_and_tail(shadows, more):
    d = head_tail_differences(ON + more, shadows=shadows)
    assert len(d) > 200
    z = z_scores(d)
    assert np.all(np.abs(z) < 3), z  # measured: |z| < 2 for both statistics, with and without shadows, distractors


def test_draws_keyed_by_trajectory_and_recorded():
    cfg = load_config("default", ON + ["render.light_count=[2, 3]"])
    a = appearance_draws(cfg, np.arange(10))
    b = appearance_draws(cfg, np.arange(4, 8))
    for k in ("plate.yaw", "plate.offset_u", "lights.count", "lights.2.azimuth", "lights.0.irradiance"):
        assert np.array_equal(a[k][4:8], b[k]), k  # the same trajectory draws the same, in any batch
    assert set(np.unique(a["lights.count"])) <= {2.0, 3.0}
    assert np.all((a["plate.yaw"] >= 0) & (a["plate.yaw"] < 2 * np.pi))
    assert np.all(np.hypot(a["plate.offset_u"], a["plate.offset_v"]) <= cfg.render.plate_offset)
    # old configs draw nothing new (datasets of before keep their params)
    old = load_config("default", OFF)
    assert not any(k.startswith(("plate.", "lights.")) for k in appearance_draws(old, np.arange(3)))


def test_lights_are_where_the_draws_say():
    cfg = load_config("default", ON + ["render.light_count=[3, 3]"])
    app = appearance_draws(cfg, np.arange(5))
    a = sample_appearance(cfg, np.arange(5))
    for i in range(3):
        el, az, d = (app[f"lights.{i}.{k}"] for k in ("elevation", "azimuth", "distance"))
        c, s = np.cos(app["plate.yaw"]), np.sin(app["plate.yaw"])
        p = np.stack([d * np.cos(el) * np.cos(az), d * np.cos(el) * np.sin(az), d * np.sin(el)], 1)
        world = np.stack([c * p[:, 0] - s * p[:, 1] + app["plate.offset_u"],
                          s * p[:, 0] + c * p[:, 1] + app["plate.offset_v"], p[:, 2]], 1)
        np.testing.assert_allclose(a.light_pos[:, i], world, atol=1e-12)
        # irradiance at the plate's centre (facing the light), mean over the channels = the drawn value
        np.testing.assert_allclose(a.light_power[:, i].mean(1) / d**2, app[f"lights.{i}.irradiance"], rtol=1e-12)
    sun_az = np.arctan2(a.sun_dir[:, 1], a.sun_dir[:, 0])
    np.testing.assert_allclose(np.cos(sun_az - app["light.azimuth"] - app["plate.yaw"]), 1.0, atol=1e-9)


def test_two_lights_add_up():
    # irradiance is linear: image(A and B) = image(A) + image(B) - image(neither), in linear RGB (display gamma 2)
    x, mp, mr, _, _ = dataset_like_worms(2)
    base = default_appearance(2)
    base.sun_color = np.zeros((1, 3))
    pos = np.array([[[0.1, 0.05, 0.2], [-0.1, -0.1, 0.15]]])
    pw = np.array([[[0.01, 0.012, 0.008], [0.006, 0.005, 0.007]]])
    R, t = look_at([[0.04, -0.15, 0.15], [0.0, 0.12, 0.12]], [[0.04, 0, 0], [0.04, 0, 0]])
    cams = make_cameras(intrinsics(60, 60, 31.5, 23.5), R, t, [0, 1], 64, 48)
    lin = []
    for on in ([1, 1], [1, 0], [0, 1], [0, 0]):
        a = base.take([0, 0])
        a.light_pos, a.light_power, a.light_size = pos, pw * np.array(on)[None, :, None], np.full((1, 2), 0.01)
        scene = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=mp, magnet_rot=mr,
                            worm_texcoords=PATTERN.vertices, appearance=a)
        lin.append((Renderer(64, 48).render(scene, cams)["rgb"].astype(np.float64) / 255) ** 2)
    pred = np.sqrt(np.clip(lin[1] + lin[2] - lin[3], 0, None)) * 255
    got = np.sqrt(lin[0]) * 255
    ok = got < 250
    # each 8-bit level is at most 0.5 off; through the square and the root three such errors stay within 2 levels
    assert np.abs(pred - got)[ok].max() <= 2.0


def test_posed_plate_floor_matches_ray_caster_and_checker():
    # a small floor square, yawed and shifted: its edges (segmentation and depth, against the BVH ray caster with
    # the floor as two real triangles) and its checker (against the analytic parity at the pixel's floor point)
    x, mp, mr, _, _ = dataset_like_worms(2)
    a = default_appearance(2)
    a.plate = np.array([[0.7, 0.01, -0.02], [2.5, -0.015, 0.0]])
    a.floor_tex = np.array([[0.01, 1.0, 0.0, 300.0]])
    a.floor_color2 = np.zeros((1, 3))
    scene = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, magnet_pos=mp, magnet_rot=mr,
                        worm_texcoords=PATTERN.vertices, appearance=a, floor_half=0.05, show_epm=False)
    eye, tgt = np.array([[0.04, 0.0, 0.25], [0.04, 0.0, 0.25]]), np.array([[0.04, 0.0, 0.0], [0.04, 0.0, 0.0]])
    R, t = look_at(eye, tgt, up=(0.0, 1.0, 0.0))
    cams = make_cameras(intrinsics(150, 150, 47.5, 47.5), R, t, [0, 1], 96, 96)
    out = Renderer(96, 96).render(scene, cams)
    ref = RayCaster(96, 96).render(scene, cams)
    from test_render_raster import _assert_agree_off_edges

    _assert_agree_off_edges(out, ref, scene, cams)  # was: 0.5 % of the pixels may differ, depth to 0.1 mm
    # checker parity at each floor pixel's point, in the posed plate's axes
    for i, (yaw, ou, ov) in enumerate(a.plate):
        floor = out["seg"][i] == 1
        v, u = np.nonzero(floor)
        ray = np.einsum("ji,nj->ni", cams.R[i], np.stack([(u - 47.5) / 150, (v - 47.5) / 150, np.ones_like(u)], 1))
        p = eye[i] + ray * (-eye[i, 2] / ray[:, 2])[:, None]
        q = p[:, :2] - [ou, ov]
        pu = np.cos(yaw) * q[:, 0] + np.sin(yaw) * q[:, 1]
        pv = -np.sin(yaw) * q[:, 0] + np.cos(yaw) * q[:, 1]
        odd = (np.floor(pu / 0.01) + np.floor(pv / 0.01)) % 2 == 1
        dark = out["rgb"][i][floor].mean(axis=1) < 20
        assert np.mean(dark == odd) > 0.97  # (pixels on a tile edge may go either way)


def test_config_errors_name_the_key():
    with pytest.raises(ConfigError, match="render.light_size: got \\[0.05, 0.01\\]"):
        load_config("default", ["render.light_size=[0.05, 0.01]"])
    with pytest.raises(ConfigError, match="render.lights"):
        load_config("default", ["render.lights=sometimes"])
    with pytest.raises(ConfigError, match="render.plate_offset"):
        load_config("default", ["render.plate_offset=-1"])


def test_off_values_leave_config_and_appearance_as_before():
    cfg = load_config("default", OFF)
    assert not any(k.startswith(("plate", "light", "shadow")) for k in cfg.to_dict()["render"])
    on = load_config("default", OFF + ["render.plate_pose=true"]).to_dict()["render"]
    assert on["plate_pose"] is True and on["plate_offset"] == 0.05
    a = sample_appearance(cfg, np.arange(3))
    assert np.all(a.plate == 0) and a.light_pos.shape == (3, 1, 3)
    assert np.all(place(a, {}).light_pos == a.light_pos)
