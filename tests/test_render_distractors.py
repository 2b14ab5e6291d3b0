"""Distractor objects on the plate (issue 24, item 6): paper scraps, cubes, cylinders and rulers around the worm,
never on it, in front of it at times; the occlusion they cause is in the labels (visible fraction, keypoint
visibility), checked against the BVH ray caster with and without them."""

from __future__ import annotations

import numpy as np

from warpworm import quiet_warp
from warpworm.data.config import load_config
from warpworm.data.sampling import appearance_draws, dataset_cameras, sample_appearance
from warpworm.render import Renderer, build_scene
from warpworm.render.labels import schema_labels
from warpworm.render.placement import KINDS, distractor_mesh
from warpworm.render.raycast import RayCaster

from test_render_transfer import PATTERN, dataset_like_worms

quiet_warp()
CFG = ["render.distractors=[3, 6]"]


def _segment_distance(p: np.ndarray) -> np.ndarray:
    """Distance [m] of floor points p (..., 2) from the worm's travel segment x in [-0.03, 0.11], y = 0."""
    x = np.clip(p[..., 0], -0.03, 0.11)
    return np.hypot(p[..., 0] - x, p[..., 1])


def test_distractors_stay_off_the_worm():
    cfg = load_config("default", CFG)
    n = 400
    app = appearance_draws(cfg, np.arange(n))
    v, t, lab, _ = distractor_mesh(app, n)
    kinds = set()
    for i in range(6):
        sel = lab == lab.min() + i
        pts = v[:, np.unique(t[sel])]  # (n, k, 3) vertices of slot i (a point when absent)
        shown = np.ptp(pts[..., 0], axis=1) > 0
        kinds |= set(app[f"distractors.{i}.kind"][shown].astype(int).tolist())
        # the capsule of radius 15 mm around the segment (where a trajectory's worm lies) holds no object vertex;
        # edges between vertices outside a convex capsule may still cut it: check points along every edge too
        tri = t[sel]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            e = v[:, tri[:, a], :2][:, :, None] + np.linspace(0, 1, 9)[None, None, :, None] * \
                (v[:, tri[:, b], :2] - v[:, tri[:, a], :2])[:, :, None]
            assert np.all(_segment_distance(e[shown]) > 0.015)
        assert np.all(pts[..., 2] >= 0)  # on the floor, not in it
    assert kinds == set(range(len(KINDS)))
    counts = app["distractors.count"]
    assert counts.min() == 3 and counts.max() == 6


def test_occlusion_in_labels_matches_ray_casting():
    cfg = load_config("default", CFG)
    n = 96
    x, mp, mr, _, _ = dataset_like_worms(n)
    ids = np.arange(n)
    app = appearance_draws(cfg, ids)
    kw = dict(magnet_pos=mp, magnet_rot=mr, worm_texcoords=PATTERN.vertices, appearance=sample_appearance(cfg, ids))
    scene = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, extra_mesh=distractor_mesh(app, n), **kw)
    bare = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, **kw)
    alone = build_scene(x, PATTERN.triangles, PATTERN.triangle_segment, worm_texcoords=PATTERN.vertices)
    cams, _ = dataset_cameras(cfg, ids, x)
    cams.world = ids.astype(np.int32)
    W, H = cams.width, cams.height
    img = Renderer(W, H).render(scene, cams)
    states = {"positions": x, "magnet_pos": mp, "magnet_rot": mr}
    lab = schema_labels(states, PATTERN, cams, img, ipm_diameter=0.01)
    ref = RayCaster(W, H).render(scene, cams)
    ref_bare = RayCaster(W, H).render(bare, cams)
    ref_alone = RayCaster(W, H).render(alone, cams)
    assert np.mean(np.where(ref["seg"] > 10, 1, ref["seg"]) == img["seg"]) > 0.995  # distractors: the floor's id
    worm = lambda s: (s >= 2) & (s <= 6)  # noqa: E731
    seen = worm(ref["seg"]).sum(axis=(1, 2))
    # the label: visible worm pixels over those of the worm rendered alone (magnets hide some of it too)
    truth = seen / np.maximum(worm(ref_alone["seg"]).sum(axis=(1, 2)), 1)
    np.testing.assert_allclose(lab["labels/visib_fract"], truth, atol=0.01)
    occluded = seen / np.maximum(worm(ref_bare["seg"]).sum(axis=(1, 2)), 1) < 0.97  # hidden by distractors
    assert 0.02 < occluded.mean() < 0.6, occluded.mean()  # in front of the worm at times, not always
    # a keypoint whose pixel shows a distractor nearer than it is occluded (visibility 1)
    uv = np.rint(lab["keypoints/pixel"]).astype(int)
    inside = (uv[..., 0] >= 0) & (uv[..., 0] < W) & (uv[..., 1] >= 0) & (uv[..., 1] < H)
    k = np.nonzero(inside)
    at = ref["seg"][k[0], uv[..., 1][k], uv[..., 0][k]]
    nearer = ref["depth"][k[0], uv[..., 1][k], uv[..., 0][k]] < lab["keypoints/camera"][..., 2][k] - 1e-3
    hidden = (at > 10) & nearer
    assert hidden.sum() > 0
    assert np.all(lab["keypoints/visibility"][k][hidden] == 1)
