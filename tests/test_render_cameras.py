"""Cameras (OpenCV convention, sampler), sensor effects and the ``warpworm render`` command."""

from __future__ import annotations

import cv2
import numpy as np
from warpworm.render import look_at, sample_cameras
from warpworm.render.camera import intrinsics, make_cameras
from warpworm.render.demo import default_pattern, posed_worm_states
from warpworm.rng import seed_uniforms as uniforms
from warpworm.render.sensor import apply_sensor

from warpworm import quiet_warp

quiet_warp()


def test_look_at_is_opencv():
    # a camera on +x looking at the origin (facing -x) with z up: world z is image up (-y_cam), world +y image right
    R, t = look_at([1.0, 0, 0], [0, 0, 0])
    assert np.allclose(R @ [0, 0, 1], [0, -1, 0])
    assert np.allclose(R @ [0, 1, 0], [1, 0, 0])
    assert np.allclose(R @ [1.0, 0, 0] + t, 0)
    assert np.allclose(R @ [0, 0, 0] + t, [0, 0, 1])
    assert np.isclose(np.linalg.det(R), 1.0)
    cams = make_cameras(intrinsics(100, 100, 31.5, 31.5), R, t, 0, 64, 64)
    pts = np.array([[[0, 0.1, 0.05], [0, -0.1, 0], [0, 0, 0]]])
    uv, _ = cams.project(pts)
    ref, _ = cv2.projectPoints(pts[0], cv2.Rodrigues(R)[0], t, cams.K[0], None)
    assert np.allclose(uv[0], ref[:, 0], atol=1e-9)
    assert np.allclose(cams.position, [[1, 0, 0]])


def test_sampler_in_frame_and_batch_independent():
    states = posed_worm_states(np.arange(3), default_pattern())
    pts = states["positions"]
    seeds = np.arange(40) + 77
    cams = sample_cameras(seeds, pts, width=96, height=96, world_index=np.arange(40) % 3, min_in_frame=1.0)
    assert cams.accepted.all()
    assert np.all(cams.K[:, 0, 0] > 0) and np.all(cams.K[:, 1, 1] > 0)
    uv, pc = cams.project(pts[cams.world])
    assert np.all(pc[..., 2] > 0)
    assert np.all((uv >= 0) & (uv <= 95))
    # camera i depends on its seed only, not on the batch it was drawn in
    one = sample_cameras(seeds[[7]], pts, width=96, height=96, world_index=[7 % 3], min_in_frame=1.0)
    assert np.array_equal(one.R[0], cams.R[7]) and np.array_equal(one.K[0], cams.K[7])
    # a view that cannot contain the worm is flagged, not silently accepted
    far = sample_cameras([1], pts[:1] * 50.0, width=32, height=32, distance=(0.05, 0.06), max_tries=2)
    assert not far.accepted[0] and far.in_frame[0] < 1.0


def test_uniforms_are_seeded_and_independent():
    a = uniforms([1, 2, 3], 5, 4)
    assert np.array_equal(a, uniforms([1, 2, 3], 5, 4))
    assert np.array_equal(a[1], uniforms([2], 5, 4)[0])
    assert not np.array_equal(a, uniforms([1, 2, 3], 6, 4))
    assert np.all((a >= 0) & (a < 1))


def test_sensor_effects_seeded():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, size=(3, 32, 32, 3), dtype=np.uint8)
    a = apply_sensor(img, [1, 2, 3])
    b = apply_sensor(img, [1, 2, 3])
    assert np.array_equal(a, b)
    assert not np.array_equal(a[0], img[0])
    assert np.array_equal(apply_sensor(img[1:2], [2])[0], a[1])  # per-image seeds: batch-independent
    assert not np.array_equal(apply_sensor(img[:1], [9])[0], a[0])


def test_render_command_writes_contact_sheet(tmp_path):
    from warpworm.cli import main

    rc = main(["render", "--worlds", "2", "--cameras", "2", "--size", "64", "--out", str(tmp_path), "--source",
               "posed", "--sensor", "--json"])
    assert rc == 0
    sheet = cv2.imread(str(tmp_path / "contact_sheet.png"))
    assert sheet is not None and sheet.shape[0] > 4 * 64 and sheet.shape[1] >= 3 * 64
    data = np.load(tmp_path / "labels.npz")
    assert data["rgb"].shape == (4, 64, 64, 3) and data["keypoints/pixel"].shape == (4, 16, 2)
    assert data["seg"].max() <= 10


def test_render_command_simulates_worlds_drawn_from_the_config(tmp_path):
    """--source sim: the worlds are the default config's draws (those of a dataset job's first trajectories with
    that seed), with the command's gait; the labels are the dataset schema's."""
    from warpworm.cli import main
    from warpworm.commands.render import simulate_states
    from warpworm.data.config import load_config
    from warpworm.data.sampling import randomized_params

    cfg = load_config("default", ["randomize.worm.gait=omega"], seed=3)
    snap, model = simulate_states(cfg, 2, 3, "omega", 0.02, "cpu")
    p = randomized_params(cfg, 2, 3)
    np.testing.assert_array_equal(np.asarray(model.params.hinge_stiffness), np.asarray(p.hinge_stiffness))
    assert np.all(np.asarray(model.params.gait) == "omega") and snap["positions"].shape[0] == 2
    rc = main(["render", "--worlds", "2", "--cameras", "1", "--size", "48", "--out", str(tmp_path), "--gait", "omega",
               "--sim-time", "0.02", "--json"])
    assert rc == 0
    data = np.load(tmp_path / "labels.npz")
    assert data["poses/body"].shape == (2, 4, 4) and data["keypoints/visibility"].shape == (2, 16)
