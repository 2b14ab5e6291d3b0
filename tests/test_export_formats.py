"""Round trips between warpworm's own commands and the readers of the formats they write (issue 25).

One tiny real dataset per module (the default config, 8 samples, 64 x 48 px), then:

* generate -> export-bop: every file where the BOP format spec (bop_toolkit docs/bop_datasets_format.md) puts it,
  each field with its type and units; the models' PLY read back by trimesh, their extents = models_info.json's,
  the worm's half-turn symmetry mapping its mesh onto itself; poses recomposed from the HDF5 labels;
* generate -> export-webdataset: read through ``webdataset.WebDataset``, every image, depth, pose, mask and keypoint
  against the HDF5 labels;
* generate -> export-yolo: Ultralytics' label format re-parsed (and Ultralytics' own YOLODataset where it installs);
* the 16 exported keypoints are distinct points (no pair closer than 1 mm on the body) and the three new ones
  project like the dataset's own keypoints do;
* simulate -> export-usd (the ``times`` key of simulate's trajectory.npz);
* every JSON any of these wrote parses strictly (no NaN / Infinity).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.data.export_json import loads_strict

GEN = ["--num", "8", "--no-progress", "--no-preview", "sim.worlds=2", "shard_size=4", "sim.settle_time=0.02",
       "sim.frame_times=[0.1, 0.2]", "render.width=64", "render.height=48"]


def _warpworm(*args, timeout=300, cwd=None):
    """``warpworm ARGS`` in a subprocess (the console entry point, as a user runs it)."""
    return subprocess.run([sys.executable, "-m", "warpworm", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd)


def _cli(*args):
    """``warpworm ARGS`` in this process (fast: no interpreter and Warp start-up per call); returncode, stdout,
    stderr as a subprocess's. Not for ``generate``, which takes over the process's signal handlers."""
    from contextlib import redirect_stderr, redirect_stdout
    from io import StringIO
    from types import SimpleNamespace

    from warpworm.cli import main

    out, err = StringIO(), StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as exc:
            code = exc.code
    return SimpleNamespace(returncode=code, stdout=out.getvalue(), stderr=err.getvalue())


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("fmt") / "data"
    r = _warpworm("generate", "default", "--out", d, "--seed", "5", *GEN)
    assert r.returncode == 0, r.stderr
    return d


def _strict_json_files(root: Path) -> int:
    n = 0
    for p in root.rglob("*.json"):
        loads_strict(p.read_text())
        n += 1
    return n


def test_bop_export_follows_the_spec(data_dir, tmp_path):
    import trimesh

    out = tmp_path / "bop"
    r = _cli("export-bop", data_dir, out)
    assert r.returncode == 0, r.stderr
    rd = ds.open(data_dir)
    N = len(rd)
    # models/: one PLY per object in mm, models_info.json with the spec's fields (keys are obj_id strings)
    info = loads_strict((out / "models" / "models_info.json").read_text())
    assert sorted(info, key=int) == ["1", "2", "3", "4", "5"]
    for k, m in info.items():
        mesh = trimesh.load(out / "models" / f"obj_{int(k):06d}.ply", process=False)
        v = np.asarray(mesh.vertices)
        assert len(mesh.faces) > 0
        for ax, c in enumerate("xyz"):
            assert m[f"min_{c}"] == pytest.approx(v[:, ax].min()) and m[f"size_{c}"] == pytest.approx(np.ptp(v[:, ax]))
        assert m["diameter"] == pytest.approx(np.linalg.norm(v[:, None] - v[None], axis=-1).max())
        for S in m.get("symmetries_discrete", []):
            T = np.reshape(S, (4, 4))
            assert np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3)) and np.isclose(np.linalg.det(T[:3, :3]), 1)
            moved = v @ T[:3, :3].T + T[:3, 3]  # a symmetry maps the mesh's vertices onto its vertices
            assert np.abs(np.linalg.norm(moved[:, None] - v[None], axis=-1).min(axis=1)).max() < 1e-6
    worm = trimesh.load(out / "models" / "obj_000001.ply", process=False)
    a, l0 = float(rd.read("params/worm.a", [0])[0]), float(rd.read("params/worm.l0", [0])[0])
    assert info["1"]["size_x"] == pytest.approx(1e3 * l0, rel=1e-6)  # the rest worm, in mm, along its body x
    assert info["1"]["size_y"] == pytest.approx(1e3 * a, rel=1e-6)
    assert info["1"]["symmetries_discrete"] == [np.diag([-1.0, -1, 1, 1]).reshape(-1).tolist()]
    # the worm model is the dataset's own sheet: its triangles, each vertex used, each edge in one or two triangles
    # (an open tube is not watertight, so that is no check); its area the rest sheet's (build_worm) in mm²
    tri = np.asarray(rd.attrs["mesh_triangles"])
    assert np.array_equal(worm.faces, tri) and len(worm.vertices) == tri.max() + 1 == len(np.unique(tri))
    edges = np.sort(worm.edges, axis=1)
    assert np.unique(edges, axis=0, return_counts=True)[1].max() <= 2
    from warpworm.physics import crease

    b = float(rd.read("params/worm.b", [0])[0])
    rest = crease.build_worm(a, b, int((rd.config.get("sim") or {}).get("n_units", 6)), l0=l0)
    rest_area = 0.5 * np.linalg.norm(np.cross(*(rest.vertices[tri[:, k]] - rest.vertices[tri[:, 0]]
                                                for k in (1, 2))), axis=-1).sum()
    assert worm.area == pytest.approx(1e6 * rest_area, rel=1e-7)  # ASCII PLY digits: measured 1.5e-8
    # the worm model placed by the exported pose lands on the dataset's vertices where the worm is at rest-like
    cam = loads_strict((out / "camera.json").read_text())
    assert {"fx", "fy", "cx", "cy", "width", "height", "depth_scale"} <= set(cam)
    scene = out / "train_pbr" / "000000"
    sc, gt, gi = (loads_strict((scene / f"scene_{n}.json").read_text()) for n in ("camera", "gt", "gt_info"))
    assert sorted(map(int, sc)) == list(range(N))
    for i in range(N):
        c, s = sc[str(i)], rd[i]
        assert len(c["cam_K"]) == 9 and len(c["cam_R_w2c"]) == 9 and len(c["cam_t_w2c"]) == 3
        assert [g["obj_id"] for g in gt[str(i)]] == [1, 2, 3, 4, 5]
        T = s["poses/body"]
        g = gt[str(i)][0]
        assert np.allclose(np.reshape(g["cam_R_m2c"], (3, 3)), s["camera/R"] @ T[:3, :3])
        assert np.allclose(g["cam_t_m2c"], 1e3 * (s["camera/R"] @ T[:3, 3] + s["camera/t"]))
        for e in gi[str(i)]:
            assert set(e) >= {"bbox_obj", "bbox_visib", "px_count_all", "px_count_valid", "px_count_visib",
                              "visib_fract"}
        for sub in ("rgb", "depth"):
            assert (scene / sub / f"{i:06d}.png").is_file()
        for k in range(5):
            assert (scene / "mask_visib" / f"{i:06d}_{k:06d}.png").is_file()
    assert _strict_json_files(out) >= 6
    # OUT exists now: refused without --overwrite, accepted with it
    r = _cli("export-bop", data_dir, out, "--limit", "2")
    assert r.returncode == 2 and "--overwrite" in r.stderr and r.stderr.count("\n") == 1
    assert _cli("export-bop", data_dir, out, "--limit", "2", "--overwrite").returncode == 0


def test_webdataset_round_trip(data_dir, tmp_path):
    wds = pytest.importorskip("webdataset")
    from pycocotools import mask as mask_utils

    from warpworm.data.export_webdataset import decode_png

    out = tmp_path / "wds"
    r = _cli("export-webdataset", data_dir, out, "--shard-size", "3")
    assert r.returncode == 0, r.stderr
    shards = sorted(out.glob("shard-*.tar"))
    assert len(shards) == 3  # 8 images, 3 per shard
    key_to_shard = loads_strict((out / "key_to_shard.json").read_text())
    rd = ds.open(data_dir)
    seen = 0
    for sample in wds.WebDataset([str(p) for p in shards], shardshuffle=False):
        key = sample["__key__"]
        lab = loads_strict(sample["warpworm.json"].decode())
        i = lab["sample_id"]
        s = rd[i]
        assert key == f"{i // 1000:06d}_{i % 1000:06d}" and key_to_shard[key] == i // 3
        assert np.array_equal(decode_png(sample["rgb.png"]), s["rgb"])
        cam = loads_strict(sample["camera.json"].decode())
        depth = decode_png(sample["depth.png"]).astype(np.float64) * cam["depth_scale"] / 1e3
        assert np.abs(depth - s["depth"]).max() <= 0.5 * cam["depth_scale"] / 1e3 + 1e-9
        assert np.allclose(np.reshape(cam["cam_K"], (3, 3)), s["camera/K"])
        gt = loads_strict(sample["gt.json"].decode())
        assert np.allclose(gt[2]["cam_t_m2c"], 1e3 * (s["camera/R"] @ s["poses/ipm"][1, :3, 3] + s["camera/t"]))
        masks = loads_strict(sample["mask_visib.json"].decode())
        rle = masks["0"]
        dec = mask_utils.decode(mask_utils.frPyObjects(rle, *rle["size"])).astype(bool)
        assert np.array_equal(dec, (s["segmentation"] >= 2) & (s["segmentation"] <= 6))
        assert np.allclose(lab["crease_angle"], s["creases/angle"]) and np.allclose(lab["pose_body"], s["poses/body"])
        assert lab["time"] == pytest.approx(float(s["time"])) and lab["frame"] == int(s["frame"])
        assert len(lab["keypoint_names"]) == 16 and np.shape(lab["keypoints_pixel"]) == (16, 2)
        names = json.loads(rd.attrs["keypoint_names"])
        for k, n in enumerate(lab["keypoint_names"][:13]):
            assert np.allclose(lab["keypoints_pixel"][k], s["keypoints/pixel"][names.index(n)])
            assert lab["keypoints_visibility"][k] == s["keypoints/visibility"][names.index(n)]
        seen += 1
    assert seen == len(rd) == 8
    assert _strict_json_files(out) >= 3


def test_exported_keypoints_are_distinct_points(data_dir):
    from warpworm.data import export_keypoints as ek
    from warpworm.physics import crease
    from warpworm.render.labels import WormBody

    rd = ds.open(data_dir)
    kpx = ek.KeypointExporter(rd)
    assert kpx.names == ek.KEYPOINT_NAMES and len(set(kpx.names)) == 16
    # on the rest worm: every pair of the 16 body points at least 1 mm apart (the dataset's IPM centres are 0 mm
    # from tail / seg2 / head, which is what the export replaces)
    pat = crease.build_worm(0.02, 0.008, 6, l0=0.08)
    sheet = WormBody.from_pattern(pat).sheet_keypoints(pat.vertices)  # seg0..4, tail, head, 6 corners
    pts = np.concatenate([sheet, pat.vertices[kpx.dorsal]])
    d = np.linalg.norm(pts[:, None] - pts[None], axis=-1) + np.eye(16)
    assert d.min() > 1e-3
    assert np.all(pat.vertices[kpx.dorsal, 2] == pat.vertices[:, 2].max())  # dorsal: the top ridge at rest
    # the projection of the new points follows the dataset's own: stored world keypoints -> stored pixels
    idx = np.arange(len(rd))
    uv, z = ek.project(rd.read("keypoints/world", idx), rd.read("camera/K", idx), rd.read("camera/R", idx),
                       rd.read("camera/t", idx))
    assert np.abs(uv - rd.read("keypoints/pixel", idx)).max() < 1e-6
    # ... and the visibility rule for surface points reproduces the dataset's flags of the six corners
    names = json.loads(rd.attrs["keypoint_names"])
    c = [names.index(n) for n in ek.DATASET_NAMES[7:]]
    assert np.array_equal(ek.visibility(uv[:, c], z[:, c], rd.read("depth", idx)),
                          rd.read("keypoints/visibility", idx)[:, c])
    # symmetries are involutions and pair names that exist
    for pairs in (ek.MIRROR_PAIRS, ek.HALF_TURN_PAIRS):
        p = ek.permutation(pairs)
        assert [p[p[i]] for i in range(16)] == list(range(16))


def test_exported_surface_keypoints_project_through_the_lens_as_opencv_does():
    """The dorsal points the exports add are projected with each camera's lens distortion (``render.distortion``),
    like the images and the dataset's own keypoints: equal to ``cv2.projectPoints`` with the same coefficients."""
    import cv2

    from warpworm.data import export_keypoints as ek

    rng = np.random.default_rng(11)
    pts = rng.uniform(-0.03, 0.03, (3, 5, 3))
    R = np.stack([cv2.Rodrigues(rng.normal(size=3))[0] for _ in range(3)])
    t = np.c_[rng.uniform(-0.01, 0.01, (3, 2)), rng.uniform(0.15, 0.3, 3)]
    K = np.array([[[f, 0.0, 127.5], [0.0, f, 120.0], [0.0, 0.0, 1.0]] for f in (200.0, 260.0, 320.0)])
    dist = np.c_[rng.uniform(-0.25, 0.25, (3, 2)), rng.uniform(-0.002, 0.002, (3, 2)), np.zeros(3)]
    uv, z = ek.project(pts, K, R, t, dist)
    for i in range(3):
        want = cv2.projectPoints(pts[i], cv2.Rodrigues(R[i])[0], t[i], K[i], dist[i])[0][:, 0]
        np.testing.assert_allclose(uv[i], want, atol=1e-9)
        np.testing.assert_allclose(z[i], (pts[i] @ R[i].T + t[i])[:, 2], atol=1e-15)


def test_yolo_export_in_ultralytics_format(data_dir, tmp_path):
    import yaml

    from warpworm.data import export_keypoints as ek

    out = tmp_path / "yolo"
    r = _cli("export-yolo", data_dir, out, "--val-fraction", "0.5")
    assert r.returncode == 0, r.stderr
    cfg = yaml.safe_load((out / "dataset.yaml").read_text())
    assert cfg["kpt_shape"] == [16, 3] and cfg["names"] == {0: "worm"}
    assert cfg["flip_idx"] == ek.permutation(ek.MIRROR_PAIRS) and len(cfg["kpt_oks_sigmas"]) == 16
    rd = ds.open(data_dir)
    traj = {int(s): int(t) for s, t in zip(rd.read("sample_id"), rd.read("trajectory"))}
    parts = {}
    kpx = ek.KeypointExporter(rd)
    for part in ("train", "val"):
        for img in sorted((out / "images" / part).glob("*.png")):
            sid = int(img.stem)
            parts.setdefault(part, set()).add(traj[sid])
            lbl = out / "labels" / part / f"{img.stem}.txt"  # Ultralytics: /images/ -> /labels/, .png -> .txt
            rows = [list(map(float, ln.split())) for ln in lbl.read_text().splitlines()]
            s = rd[sid]
            H, W = s["rgb"].shape[:2]
            assert np.array_equal(cv2.imread(str(img))[..., ::-1], s["rgb"])
            if not rows:
                assert s["labels/bbox_visib"][2] == 0
                continue
            (row,) = rows
            assert len(row) == 5 + 16 * 3 and row[0] == 0
            x, y, w, h = s["labels/bbox_visib"]
            assert np.allclose(row[1:5], [(x + w / 2) / W, (y + h / 2) / H, w / W, h / H], atol=1e-6)
            kp = np.reshape(row[5:], (16, 3))
            uv, vis = kpx.read([sid])
            assert np.array_equal(kp[:, 2], vis[0])
            on = vis[0] > 0
            assert np.allclose(kp[on, 0] * W, uv[0, on, 0], atol=1e-4) and np.all(kp[~on, :2] == 0)
    assert parts["train"].isdisjoint(parts["val"])  # whole trajectories on one side


def test_ultralytics_loads_the_yolo_export_and_trains(data_dir, tmp_path, monkeypatch):
    """Ultralytics' own loader reads our YOLO-pose export (every label row, keypoints in pixels as ours) and its
    trainer runs: a pose model built from its YAML (no weights downloaded) trains one epoch (2 steps of batch 2) on
    the export and reports a finite loss. Needs the ``interop-yolo`` extra (torch: see docs/testing.md)."""
    # before its first import: its settings file (and datasets folder) in the test's folder, not ~/.config
    monkeypatch.setenv("YOLO_CONFIG_DIR", str(tmp_path / "ycfg"))
    monkeypatch.setenv("YOLO_OFFLINE", "1")
    pytest.importorskip("ultralytics", reason="ultralytics not installed (its own extra, heavy: pip install -e "
                                              "'.[interop-yolo]'; docs/testing.md)")
    from ultralytics import YOLO
    from ultralytics.data.dataset import YOLODataset
    from ultralytics.data.utils import check_det_dataset

    from warpworm.data import export_keypoints as ek

    out = tmp_path / "yolo"
    assert _cli("export-yolo", data_dir, out, "--val-fraction", "0.5").returncode == 0
    data = check_det_dataset(str(out / "dataset.yaml"))
    assert data["kpt_shape"] == [16, 3] and data["nc"] == 1
    rd = ds.open(data_dir)
    kpx = ek.KeypointExporter(rd)
    n_labels = 0
    for part in ("train", "val"):
        dset = YOLODataset(img_path=data[part], data=data, task="pose", augment=False, imgsz=64)
        for lab in dset.labels:
            sid = int(Path(lab["im_file"]).stem)
            uv, vis = kpx.read([sid])
            if len(lab["cls"]) == 0:
                assert rd[sid]["labels/bbox_visib"][2] == 0
                continue
            n_labels += 1
            H, W = lab["shape"]
            kp = lab["keypoints"][0]  # normalised (16, 3), as Ultralytics keeps them
            on = vis[0] > 0
            assert np.array_equal(kp[:, 2] > 0, on)
            # the label text's 6 decimals of the normalised coordinate: 0.5e-6 x 64 px = 3.2e-5 px at most
            assert np.abs(kp[on, 0] * W - uv[0, on, 0]).max() < 1e-4
            assert np.abs(kp[on, 1] * H - uv[0, on, 1]).max() < 1e-4
    assert n_labels >= 4
    model = YOLO("yolov8n-pose.yaml")  # built from its YAML: random weights, nothing downloaded
    model.train(data=str(out / "dataset.yaml"), epochs=1, imgsz=64, batch=2, workers=0, device="cpu", plots=False,
                val=False, amp=False, project=str(tmp_path / "runs"), name="t", exist_ok=True, verbose=False,
                pretrained=False)
    loss = model.trainer.tloss  # the epoch's mean losses (a tensor, or a dict of them in newer releases)
    parts = list(loss.values()) if isinstance(loss, dict) else [loss]
    values = np.concatenate([np.ravel(np.asarray(v.detach().cpu() if hasattr(v, "detach") else v, float))
                             for v in parts])
    assert tuple(model.trainer.model.kpt_shape) == (16, 3)
    assert values.size >= 4 and np.all(np.isfinite(values)) and values.sum() > 0, loss


def test_simulate_trajectory_to_usd(tmp_path):
    from warpworm.data.export_usd import read_points

    r = _warpworm("simulate", "--cycles", "1", "--settle", "0.02", "--magnet-model", "analytic", "--fps", "10",
                  "--out", tmp_path / "sim")
    assert r.returncode == 0, r.stderr
    traj = np.load(tmp_path / "sim" / "trajectory.npz")
    r = _warpworm("export-usd", tmp_path / "sim" / "trajectory.npz", "--out", tmp_path / "t.usda", "--check")
    assert r.returncode == 0, r.stderr + r.stdout
    assert "check: passed" in r.stdout
    times, pts = read_points(tmp_path / "t.usda")
    assert np.allclose(times, traj["times"]) and np.array_equal(pts, traj["positions"][:, 0])
    r = _cli("export-usd", tmp_path / "sim" / "trajectory.npz", "--out", tmp_path / "u.usda", "--worlds", "3")
    assert r.returncode == 2 and "--worlds" in r.stderr and not (tmp_path / "u.usda").exists()


def test_generate_report_and_every_json_is_strict(data_dir, tmp_path):
    """The dataset's manifest (which holds the config's NaN 'gait preset' values) and report are strict JSON, with
    null where a value is absent; report re-reads the dataset."""
    manifest = loads_strict((data_dir / "manifest.json").read_text())
    assert manifest["config"]["randomize"]["worm"]["orientation"] is None  # NaN = the preset's: null, not NaN
    r = _cli("report", data_dir, "--out", tmp_path / "rep")
    assert r.returncode == 0, r.stderr
    rep = loads_strict((tmp_path / "rep.json").read_text())
    assert rep["folders"][0]["samples"] == 8
    with pytest.raises(ValueError):
        loads_strict('{"a": NaN}')


def test_bop_toolkit_reads_the_exports(data_dir, tmp_path):
    """bop_toolkit's own loaders, where bop_toolkit_lib is importable (it is not on PyPI: install it from its
    repository). Checked by hand on 2026-12-03 with its source: the same reads hold."""
    inout = pytest.importorskip("bop_toolkit_lib.inout")
    misc = pytest.importorskip("bop_toolkit_lib.misc")
    bop_webdataset = pytest.importorskip("bop_toolkit_lib.dataset.bop_webdataset")
    out, wdir = tmp_path / "bop", tmp_path / "wds"
    assert _cli("export-bop", data_dir, out).returncode == 0
    assert _cli("export-webdataset", data_dir, wdir).returncode == 0
    info = inout.load_json(str(out / "models" / "models_info.json"), keys_to_int=True)
    n_sym = {k: len(misc.get_symmetry_transformations(m, max_sym_disc_step=0.01)) for k, m in info.items()}
    assert n_sym[1] == 2 and n_sym[5] == 6  # identity + the half turn; the EPM's 6
    for k in info:
        assert len(inout.load_ply(str(out / "models" / f"obj_{k:06d}.ply"))["pts"]) > 0
    gts = inout.load_scene_gt(str(out / "train_pbr" / "000000" / "scene_gt.json"))
    rd = ds.open(data_dir)
    T = rd[0]["poses/body"]
    assert np.allclose(gts[0][0]["cam_t_m2c"].ravel(), 1e3 * (rd[0]["camera/R"] @ T[:3, 3] + rd[0]["camera/t"]))
    s = bop_webdataset.load_image_data(str(wdir / "shard-000000.tar"), "000000_000000", load_gt=True,
                                       rgb_suffix=".png")
    assert np.array_equal(s["im_rgb"], rd[0]["rgb"]) and len(s["gt"]) == 5


def test_every_other_json_we_write_is_strict(data_dir, tmp_path, capfd, monkeypatch):
    """search.json, experiment JSON, COCO, the JSON schema and the commands' --json lines: strict JSON (run in this
    process through the CLI to stay fast)."""
    from warpworm.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["search-gait", "--gait", "omega", "--grid", "w=0.02", "--cycles", "1", "--magnet-model", "analytic",
                 "--out", "sg"]) == 0
    s = loads_strict((tmp_path / "sg" / "search.json").read_text())
    assert set(s["best"] or {}) <= {"wavelength", "amplitude", "closest_approach"}
    assert main(["experiment", "force-distance", "--quick", "--no-plot", "--out", "ex"]) == 0
    assert main(["export-coco", str(data_dir), "coco"]) == 0
    assert main(["config-schema", "--out", "schema.json"]) == 0
    assert _strict_json_files(tmp_path) >= 4
    capfd.readouterr()
    assert main(["simulate", "--cycles", "1", "--settle", "0.02", "--magnet-model", "analytic", "--json",
                 "--no-output"]) == 0
    assert main(["render", "--worlds", "1", "--cameras", "1", "--size", "32", "--source", "posed", "--json",
                 "--out", "r"]) == 0
    for line in capfd.readouterr().out.strip().splitlines():
        loads_strict(line)
