"""BOP and USD exports, read back and compared with the dataset (fake stages: tests/test_dataset_fakes.py)."""

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.data.config import load_config
from warpworm.data.job import generate


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("exp") / "data"
    cfg = load_config({"num_samples": 12, "seed": 3, "sim": {"worlds": 3, "frame_times": [0.1, 0.2, 0.4]},
                       "shard_size": 6, "render": {"width": 32, "height": 24}, "output": {"preview": False},
                       "randomize": {"worm": {"floor_incline": 0.05}}})
    generate(cfg, d, stages="test_dataset_fakes:FakeStages", progress=False)
    return d


def test_bop_round_trip(data_dir, tmp_path):
    out = tmp_path / "bop"
    r = subprocess.run([sys.executable, "-m", "warpworm", "export-bop", str(data_dir), str(out)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    rd = ds.open(data_dir)
    N = len(rd)
    cam = json.loads((out / "camera.json").read_text())
    K0 = rd.read("camera/K", [0])[0]
    assert (cam["fx"], cam["fy"], cam["cx"], cam["cy"]) == (K0[0, 0], K0[1, 1], K0[0, 2], K0[1, 2])
    scene = out / "train_pbr" / "000000"
    sc = json.loads((scene / "scene_camera.json").read_text())
    gt = json.loads((scene / "scene_gt.json").read_text())
    info = json.loads((scene / "scene_gt_info.json").read_text())
    assert len(sc) == len(gt) == len(info) == N
    for i in range(N):
        s = rd[i]
        c = sc[str(i)]
        assert np.allclose(np.reshape(c["cam_K"], (3, 3)), s["camera/K"])
        assert np.allclose(np.array(c["cam_t_w2c"]) / 1000.0, s["camera/t"])
        scale = c["depth_scale"]
        # object -> camera in mm, recomposed here from the dataset's world poses and the camera
        body = s["poses/body"]
        g = gt[str(i)][0]
        assert g["obj_id"] == 1
        Rm2c = np.reshape(g["cam_R_m2c"], (3, 3))
        assert np.allclose(Rm2c, s["camera/R"] @ body[:3, :3], atol=1e-12)
        assert np.allclose(np.array(g["cam_t_m2c"]), 1000.0 * (s["camera/R"] @ body[:3, 3] + s["camera/t"]))
        ipm = gt[str(i)][2]
        assert ipm["obj_id"] == 3 and np.allclose(np.array(ipm["cam_t_m2c"]) / 1000.0,
                                                   s["camera/R"] @ s["poses/ipm"][1, :3, 3] + s["camera/t"])
        # images
        rgb = cv2.imread(str(scene / "rgb" / f"{i:06d}.png"))[..., ::-1]
        assert np.array_equal(rgb, s["rgb"])
        dep = cv2.imread(str(scene / "depth" / f"{i:06d}.png"), cv2.IMREAD_UNCHANGED)
        assert dep.dtype == np.uint16
        assert np.abs(dep * scale / 1000.0 - s["depth"]).max() <= 0.5 * scale / 1000.0 + 1e-9
        mv = cv2.imread(str(scene / "mask_visib" / f"{i:06d}_000000.png"), cv2.IMREAD_UNCHANGED) > 0
        worm = (s["segmentation"] >= 2) & (s["segmentation"] <= 6)
        assert np.array_equal(mv, worm)
        inf = info[str(i)][0]
        if worm.any():
            ys, xs = np.nonzero(worm)
            assert inf["bbox_visib"] == [xs.min(), ys.min(), xs.max() - xs.min() + 1, ys.max() - ys.min() + 1]
        assert inf["px_count_visib"] == int(worm.sum())
        assert 0.0 <= inf["visib_fract"] <= 1.0


def test_usd_stage_is_compliant_and_points_round_trip(data_dir, tmp_path):
    from pxr import Usd, UsdGeom

    from warpworm.data.export_usd import compliance_errors, read_points

    out = tmp_path / "worm.usda"
    r = subprocess.run([sys.executable, "-m", "warpworm", "export-usd", str(data_dir), "--out", str(out), "--worlds",
                        "0,3", "--check"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr + r.stdout
    assert compliance_errors(out, include_warnings=True) == []
    rd = ds.open(data_dir)
    traj = rd.read("trajectory")
    for j in (0, 3):
        idx = np.flatnonzero(traj == j)
        times, pts = read_points(out, f"/World/w{j:03d}/Worm")
        assert np.allclose(times, rd.read("time", idx))
        assert np.array_equal(pts, rd.read("worm/vertices", idx))  # exact: float32 both ways
    stage = Usd.Stage.Open(str(out))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == "Z"
    # the centre IPM's time-sampled transform is the dataset's pose (USD row-vector matrices: transposed)
    idx = np.flatnonzero(traj == 3)
    xf = UsdGeom.Xformable(stage.GetPrimAtPath("/World/w003/IPM_centre"))
    for k, code in enumerate(xf.GetXformOpOrderAttr().Get() and xf.GetOrderedXformOps()[0].GetAttr().GetTimeSamples()):
        M = np.array(xf.GetOrderedXformOps()[0].Get(Usd.TimeCode(code)))
        assert np.allclose(M.T, rd.read("poses/ipm", idx)[k, 1])
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/w000/Worm"))
    for pv in ("displayColor", "creaseColor", "strainColor", "creaseAngle", "barStrain"):
        assert UsdGeom.PrimvarsAPI(mesh).GetPrimvar(pv).IsDefined(), pv
    assert stage.GetPrimAtPath("/World/w000/Camera").IsA(UsdGeom.Camera)
    assert stage.GetPrimAtPath("/World/Floor").IsA(UsdGeom.Mesh)


def test_usd_from_trajectory_file_and_checker_catches_errors(tmp_path):
    from pxr import Usd, UsdGeom

    from warpworm.data.export_usd import compliance_errors, export_usd, read_points

    rng = np.random.default_rng(0)
    F, W, V = 5, 2, 6
    traj = {"positions": rng.normal(size=(F, W, V, 3)).astype(np.float32) * 0.01,
            "magnet_pos": rng.normal(size=(F, W, 4, 3)) * 0.01,
            "magnet_rot": np.broadcast_to(np.eye(3), (F, W, 4, 3, 3)), "time": np.linspace(0, 1, F),
            "triangles": np.array([[0, 1, 2], [2, 3, 4], [3, 4, 5]]), "hinges": np.array([[0, 1, 2, 3]]),
            "edges": np.array([[0, 1], [1, 2]]), "crease_angle": rng.normal(size=(F, W, 1)),
            "bar_strain": rng.normal(size=(F, W, 2)) * 0.01}
    np.savez(tmp_path / "t.npz", **traj)
    p = export_usd(tmp_path / "t.npz", tmp_path / "t.usda", worlds=[1])
    assert compliance_errors(p) == []
    _, pts = read_points(p, "/World/w001/Worm")
    assert np.array_equal(pts, traj["positions"][:, 1])
    # a stage without the required metadata is reported: the check is not vacuous
    bad = Usd.Stage.CreateNew(str(tmp_path / "bad.usda"))
    UsdGeom.Xform.Define(bad, "/X")
    bad.GetRootLayer().Save()
    assert compliance_errors(tmp_path / "bad.usda")
