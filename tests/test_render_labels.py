"""Labels against OpenCV and against the rendered depth: projectPoints, solvePnP, visibility, body frame, ratios."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from warpworm.render import (
    Renderer,
    build_scene,
    make_cameras,
    sample_appearance,
    sample_cameras,
)
from warpworm.render.camera import intrinsics, look_at
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.render.labels import KEYPOINT_NAMES, VIS_EPS, WormBody, compute_labels

from warpworm import quiet_warp
from warpworm.transforms import axis_angle_to_matrix, quat_wxyz_to_matrix

quiet_warp()

SIZE = 128


@pytest.fixture(scope="module")
def batch():
    pattern = default_pattern()
    W, C = 6, 4
    states = posed_worm_states(100 + np.arange(W), pattern)
    scene = build_scene(states["positions"], pattern.triangles, pattern.triangle_segment,
                        magnet_pos=states["magnet_pos"], magnet_rot=states["magnet_rot"],
                        worm_texcoords=pattern.vertices, appearance=sample_appearance(np.arange(W)))
    cams = sample_cameras(500 + np.arange(W * C), states["positions"], width=SIZE, height=SIZE,
                          world_index=np.arange(W * C) % W, distance=(0.1, 0.3))
    images = Renderer(SIZE, SIZE).render(scene, cams)
    labels = compute_labels(states, pattern, cams, images)
    return pattern, states, cams, images, labels


def test_keypoints_equal_cv2_project_points(batch):
    _, _, cams, _, lab = batch
    for n in range(len(cams)):
        rvec, _ = cv2.Rodrigues(lab["R"][n])
        uv, _ = cv2.projectPoints(lab["keypoints_world"][n], rvec, lab["t"][n], lab["K"][n], None)
        assert np.abs(uv[:, 0] - lab["keypoints_2d"][n]).max() <= 0.01
        # and from the body frame with the stored camera-frame body pose
        rvec_b, _ = cv2.Rodrigues(lab["body_R_cam"][n])
        uv_b, _ = cv2.projectPoints(lab["keypoints_body"][n], rvec_b, lab["body_t_cam"][n], lab["K"][n], None)
        assert np.abs(uv_b[:, 0] - lab["keypoints_2d"][n]).max() <= 0.01


def _rot_angle(Ra, Rb):
    c = (np.trace(Ra.T @ Rb) - 1) / 2
    return float(np.arccos(np.clip(c, -1, 1)))


def test_solve_pnp_recovers_body_pose(batch):
    _, _, cams, _, lab = batch
    for n in range(len(cams)):
        obj = lab["keypoints_body"][n].astype(np.float64)
        img = lab["keypoints_2d"][n].astype(np.float64)
        ok, rvec, tvec = cv2.solvePnP(obj, img, lab["K"][n], None, flags=cv2.SOLVEPNP_SQPNP)
        assert ok
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, lab["K"][n], None, rvec, tvec)
        R, _ = cv2.Rodrigues(rvec)
        assert _rot_angle(R, lab["body_R_cam"][n]) <= 1e-3
        assert np.linalg.norm(tvec[:, 0] - lab["body_t_cam"][n]) <= 1e-4


def test_pose_blocks_are_consistent(batch):
    _, states, cams, _, lab = batch
    wi = cams.world
    # quaternions (w, x, y, z) reproduce the matrices; camera pose = camera extrinsics o world pose
    assert np.allclose(quat_wxyz_to_matrix(lab["body_q_cam"]), lab["body_R_cam"], atol=1e-9)
    assert np.allclose(quat_wxyz_to_matrix(lab["magnet_q_world"]), lab["magnet_R_world"], atol=1e-9)
    assert np.allclose(lab["magnet_t_world"], states["magnet_pos"][wi])
    assert np.allclose(lab["body_R_cam"], lab["R"] @ lab["body_R_world"])
    for n in range(len(cams)):
        m = 2  # centre IPM
        t_cam = lab["R"][n] @ states["magnet_pos"][wi[n], m] + lab["t"][n]
        assert np.allclose(lab["magnet_t_cam"][n, m], t_cam)
    # IPM keypoints are the magnets' centres
    k = KEYPOINT_NAMES.index("ipm_centre")
    assert np.allclose(lab["keypoints_world"][:, k], lab["magnet_t_world"][:, 2])
    assert np.all(np.linalg.det(lab["body_R_world"]) > 0.999999)


def test_visibility_agrees_with_depth(batch):
    _, _, cams, images, lab = batch
    vis = lab["keypoint_visibility"]
    assert (vis == 2).any() and (vis == 1).any()  # the scenes show both
    for n in range(len(cams)):  # re-derive with a plain per-keypoint loop
        for p in range(len(KEYPOINT_NAMES)):
            u, v = lab["keypoints_2d"][n, p]
            z = lab["keypoints_cam"][n, p, 2]
            x, y = int(round(u)), int(round(v))
            if z <= 0 or not (0 <= x < SIZE and 0 <= y < SIZE):
                assert vis[n, p] == 0
                continue
            D = float(images["depth"][n, y, x])
            L = int(images["seg"][n, y, x])
            own = (L == 7 + p - 7) if 7 <= p < 10 else (2 <= L <= 6)
            tol = lab["keypoint_depth_tol"][n, p]
            visible = D == 0 or z - D <= VIS_EPS or (z - D <= tol and own)
            assert vis[n, p] == (2 if visible else 1), (n, KEYPOINT_NAMES[p], z, D, L)
            if vis[n, p] == 2:  # a visible keypoint is never behind another object's surface by more than VIS_EPS
                assert own or z - D <= VIS_EPS or D == 0


def test_occluder_and_outside():
    pattern = default_pattern()
    states = posed_worm_states([7], pattern, bend=0.0)
    centre = states["positions"][0].mean(axis=0)
    # move the EPM to a large slab between a top-down camera and the worm
    states["magnet_pos"][0, 0] = centre + [0, 0, 0.05]
    states["magnet_rot"][0, 0] = np.eye(3)
    scene = build_scene(states["positions"], pattern.triangles, pattern.triangle_segment,
                        magnet_pos=states["magnet_pos"], magnet_rot=states["magnet_rot"], epm_size=(0.2, 0.2, 0.005))
    K = intrinsics(100.0, 100.0, 63.5, 63.5)
    R0, t0 = look_at(centre + [0, 0, 0.3], centre)
    R1, t1 = look_at(centre + [0, 0, 0.3], centre + [0, 0, 1.0] + [0.5, 0, 0])  # looking away, up
    cams = make_cameras(K, np.stack([R0, R1]), np.stack([t0, t1]), 0, 128, 128)
    images = Renderer(128, 128).render(scene, cams)
    lab = compute_labels(states, pattern, cams, images)
    assert np.all(lab["keypoint_visibility"][0] == 1)
    assert np.all(lab["keypoint_visibility"][1] == 0)
    assert lab["visible_fraction"][0] == 0.0 and lab["worm_pixels_total"][0] > 100
    assert np.all(lab["worm_box_visible"][0] == -1)


def test_body_frame_and_ratios_follow_rigid_motion():
    pattern = default_pattern()
    body = WormBody.from_pattern(pattern)
    x = pattern.vertices
    R0, o0 = body.body_frame(x)
    assert np.allclose(R0, np.eye(3), atol=1e-12)  # at rest: world axes, x forward, z up
    assert np.allclose(o0, pattern.keypoints(x)[:5].mean(axis=0))
    Rr = axis_angle_to_matrix([0.3, -0.5, 0.8], 1.1)
    tr = np.array([0.1, -0.2, 0.05])
    R1, o1 = body.body_frame(x @ Rr.T + tr)
    assert np.allclose(R1, Rr, atol=1e-12)
    assert np.allclose(o1, Rr @ o0 + tr)
    # deformation ratios: 1 at rest; a uniform 10 % squash along x gives 0.9
    states = {"positions": np.stack([x, x * [0.9, 1, 1]]), "magnet_pos": np.zeros((2, 4, 3)),
              "magnet_rot": np.tile(np.eye(3), (2, 4, 1, 1))}
    cams = make_cameras(intrinsics(100, 100, 31.5, 31.5), np.tile(np.eye(3), (2, 1, 1)), [[0, 0, 1]] * 2, [0, 1], 64, 64)
    lab = compute_labels(states, body, cams)
    assert np.allclose(lab["deformation_ratio"][0], 1.0)
    assert np.allclose(lab["deformation_ratio"][1], 0.9)


def test_boxes_and_visible_fraction(batch):
    _, _, cams, images, lab = batch
    box, vbox = lab["worm_box"], lab["worm_box_visible"]
    has = vbox[:, 0] >= 0
    assert has.all()
    # the visible pixels lie inside the box of the projected vertices (pixel centres: within half a pixel)
    assert np.all(vbox[:, 0] >= np.floor(box[:, 0])) and np.all(vbox[:, 2] <= np.ceil(box[:, 2]))
    assert np.all(vbox[:, 1] >= np.floor(box[:, 1])) and np.all(vbox[:, 3] <= np.ceil(box[:, 3]))
    assert np.all((lab["visible_fraction"] > 0.3) & (lab["visible_fraction"] <= 1.0))
    assert np.all(lab["worm_pixels_visible"] <= lab["worm_pixels_total"])
