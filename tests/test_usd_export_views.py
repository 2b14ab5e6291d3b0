"""``warpworm export-usd`` of datasets whose frames are several samples: ``render.views_per_frame: K`` (K cameras of
one physical state) and ``render.camera_per_frame`` (a camera that moves). Against the deterministic fake stages
(tests/test_dataset_fakes.py), read back with pxr: one time sample per simulated frame, strictly increasing, the
points at each the dataset's state; every view its own camera, which projects the dataset's keypoints/world onto its
keypoints/pixel (Gf.Camera's frustum: an independent pinhole model)."""

import numpy as np

from warpworm.data import dataset as ds

from test_dataset_pipeline import run, tiny

K, F = 2, 3


def _export(data, out, worlds="0,1"):
    from warpworm.cli import main

    assert main(["export-usd", str(data), "--out", str(out), "--worlds", worlds, "--check"]) == 0
    from pxr import Usd

    return Usd.Stage.Open(str(out))


def _pixels(stage, prim_path, code, width, height, world_points):
    """Project (P, 3) world points [m] through the USD camera at time ``code`` -> (P, 2) px (centres at integers)."""
    from pxr import Gf, Usd, UsdGeom

    cam = stage.GetPrimAtPath(prim_path)
    frustum = UsdGeom.Camera(cam).GetCamera(Usd.TimeCode(float(code))).frustum
    # the camera's world (/World/wNNN, offset by --spacing) carries the dataset's world frame: row vectors
    offset = UsdGeom.Xformable(cam.GetParent()).ComputeLocalToWorldTransform(Usd.TimeCode(float(code)))
    m = offset * frustum.ComputeViewMatrix() * frustum.ComputeProjectionMatrix()
    ndc = np.array([list(m.Transform(Gf.Vec3d(*map(float, p)))) for p in world_points])
    return np.stack([(ndc[:, 0] + 1) / 2 * width - 0.5, (1 - ndc[:, 1]) / 2 * height - 0.5], 1)


def _frame_state(stage, j):
    from pxr import Usd, UsdGeom

    attr = UsdGeom.Mesh(stage.GetPrimAtPath(f"/World/w{j:03d}/Worm")).GetPointsAttr()
    codes = np.asarray(attr.GetTimeSamples())
    return codes, [np.asarray(attr.Get(Usd.TimeCode(c)), np.float32) for c in codes]


def test_views_give_one_time_sample_per_frame_and_a_camera_per_view(tmp_path):
    from pxr import UsdGeom

    cfg = tiny(num_samples=2 * K * F, shard_size=K * F, sim={"frame_times": [0.1, 0.2, 0.36]},
               render={"views_per_frame": K})
    run(cfg, tmp_path / "v")  # 2 shards, a trajectory each: samples (trajectory, view, frame)
    stage = _export(tmp_path / "v", tmp_path / "v.usda")
    r = ds.open(tmp_path / "v")
    a = {k: r.read(k) for k in ("trajectory", "view", "frame", "time", "worm/vertices", "keypoints/world",
                                "keypoints/pixel")}
    h, w = r.read("depth", [0]).shape[1:]
    assert cfg.render.views_per_frame == K
    for j in (0, 1):
        codes, points = _frame_state(stage, j)
        assert len(codes) == F and np.all(np.diff(codes) > 0)
        mine = a["trajectory"] == j
        for f, (code, pts) in enumerate(zip(codes, points)):
            rows = np.flatnonzero(mine & (a["frame"] == f))
            assert len(rows) == K  # K samples of this frame ...
            assert np.isclose(code / stage.GetTimeCodesPerSecond(), a["time"][rows[0]])
            for i in rows:  # ... and the stage's state at its time is every one's state
                assert np.array_equal(pts, a["worm/vertices"][i])
        cams = [p for p in stage.GetPrimAtPath(f"/World/w{j:03d}").GetChildren() if p.IsA(UsdGeom.Camera)]
        assert sorted(p.GetName() for p in cams) == [f"Camera_v{v}" for v in range(K)]
        for v in range(K):
            path = f"/World/w{j:03d}/Camera_v{v}"
            for i in np.flatnonzero(mine & (a["view"] == v)):
                code = float(a["time"][i]) * stage.GetTimeCodesPerSecond()  # as the exporter: float64 of the float32
                uv = _pixels(stage, path, code, w, h, a["keypoints/world"][i])
                assert np.allclose(uv, a["keypoints/pixel"][i], atol=1e-3), (j, v, i)
        # the two views are different cameras (view 1's projection is not view 0's)
        i1 = np.flatnonzero(mine & (a["view"] == 1))[0]
        assert not np.allclose(_pixels(stage, f"/World/w{j:03d}/Camera_v0", 10.0, w, h, a["keypoints/world"][i1]),
                               a["keypoints/pixel"][i1], atol=1.0)


def test_camera_per_frame_is_time_sampled(tmp_path):
    from pxr import UsdGeom

    run(tiny(num_samples=2 * F, shard_size=F, sim={"frame_times": [0.1, 0.2, 0.36]},
             render={"camera_per_frame": True}), tmp_path / "c")
    stage = _export(tmp_path / "c", tmp_path / "c.usda", worlds="1")
    r = ds.open(tmp_path / "c")
    idx = np.flatnonzero(r.read("trajectory") == 1)
    h, w = r.read("depth", [0]).shape[1:]
    codes, points = _frame_state(stage, 1)
    assert len(codes) == F and np.all(np.diff(codes) > 0)
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/w001/Camera"))
    assert len(UsdGeom.Xformable(cam).GetOrderedXformOps()[0].GetAttr().GetTimeSamples()) == F
    kw, kp = r.read("keypoints/world", idx), r.read("keypoints/pixel", idx)
    for f, code in enumerate(codes):
        assert np.array_equal(points[f], r.read("worm/vertices", idx[f:f + 1])[0])
        assert np.allclose(_pixels(stage, "/World/w001/Camera", code, w, h, kw[f]), kp[f], atol=1e-3), f
