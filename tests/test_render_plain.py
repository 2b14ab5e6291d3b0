"""The plain resolve kernel (the default look's fast path, ``raster_kernels.make_resolve_shade(plain=True)``) against
the general kernel: the renderer picks it only for looks without issue-24 shading options, and where it is picked it
gives exactly the general kernel's bytes."""

from __future__ import annotations

import dataclasses

import numpy as np

from warpworm import ids, quiet_warp
from warpworm.data.config import load_config
from warpworm.data.sampling import sample_appearance
from warpworm.render import Renderer, build_scene, sample_cameras
from warpworm.render import raster_kernels as rk
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.rasterizer import plain_look

quiet_warp()


def _scene(appearance=None, worlds=3):
    pattern = default_pattern()
    st = posed_worm_states(np.arange(worlds), pattern)
    plain = load_config("default", ["render.plate_pose=false", "render.lights=fixed"])  # one lamp, as before issue 24
    app = sample_appearance(plain, np.arange(worlds)) if appearance is None else appearance
    scene = build_scene(st["positions"], pattern.triangles, pattern.triangle_segment, magnet_pos=st["magnet_pos"],
                        magnet_rot=st["magnet_rot"], worm_texcoords=pattern.vertices, appearance=app)
    cams = sample_cameras(np.arange(2 * worlds), st["positions"][np.arange(2 * worlds) % worlds], width=64,
                          height=48, world_index=np.arange(2 * worlds) % worlds)
    return app, scene, cams


def test_plain_path_only_without_shading_options():
    app, _, _ = _scene()
    assert plain_look(app)
    pad = dataclasses.replace(app, light_pos=np.concatenate([app.light_pos, app.light_pos], axis=1),
                              light_power=np.concatenate([app.light_power, 0 * app.light_power], axis=1),
                              light_size=np.concatenate([app.light_size, app.light_size], axis=1))
    dark = dataclasses.replace(app, light_power=np.where(np.arange(3)[:, None, None] == 1, 0.0, app.light_power))
    paper = app.paper_bsdf.copy()
    paper[2, 3] = 0.3  # one world's ground ambient
    spec = app.specular.copy()
    spec[0, ids.SEG_FLOOR, 0] = 0.2  # one glossy plate
    for other in (pad, dark, dataclasses.replace(app, paper_bsdf=paper), dataclasses.replace(app, specular=spec),
                  dataclasses.replace(app, floor_transmit=np.where(np.arange(3) == 1, 0.4, 0.0))):
        assert not plain_look(other)
    assert Renderer(64, 48)._upload_scene(_scene()[1])["shade"] is rk.resolve_shade_plain
    assert Renderer(64, 48, shadows=True)._upload_scene(_scene()[1])["shade"] is rk.resolve_shade


def test_plain_kernel_equals_general_kernel():
    # a second point light of zero power sends the same look through the general kernel, which skips it (a dark
    # pad adds nothing): every output must be the same bytes
    app, scene, cams = _scene()
    out = Renderer(64, 48).render(scene, cams, normals=True)
    pad = dataclasses.replace(app, light_pos=np.concatenate([app.light_pos, app.light_pos + 0.1], axis=1),
                              light_power=np.concatenate([app.light_power, 0 * app.light_power], axis=1),
                              light_size=np.concatenate([app.light_size, app.light_size], axis=1))
    _, scene2, _ = _scene(pad)
    r = Renderer(64, 48)
    assert r._upload_scene(scene2)["shade"] is rk.resolve_shade
    ref = r.render(scene2, cams, normals=True)
    assert (out["seg"] == 1).mean() > 0.3 and np.isin(out["seg"], np.arange(2, 7)).any()  # floor and sheet seen
    for k in ("rgb", "depth", "seg", "worm_mask", "normals"):
        assert np.array_equal(out[k], ref[k]), k
