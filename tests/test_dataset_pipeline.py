"""Pipeline I/O machinery against the deterministic fake stages (tests/test_dataset_fakes.py): determinism across
shard sizes and worker counts, schema, readers, unstable-world replacement, crash-and-resume, refusals, write errors."""

import errno
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from warpworm.data import dataset as ds
from warpworm.data.config import ConfigError, load_config
from warpworm.data.job import generate

FAKE = "test_dataset_fakes:FakeStages"
TESTS = Path(__file__).parent


def tiny(**over):
    raw = {"num_samples": 22, "shard_size": 6, "seed": 7,
           "sim": {"worlds": 2, "frame_times": [0.1, 0.3]}, "render": {"width": 24, "height": 16},
           "output": {"preview": False},
           # the fake reports worlds with k_alpha > 0.9 unstable: about 1 in 5 is dropped and redrawn
           "randomize": {"worm": {"hinge_stiffness": {"uniform": [0.5, 1.0]}}}}
    for k, v in over.items():
        if isinstance(v, dict):
            raw[k] = {**raw.get(k, {}), **v}
        else:
            raw[k] = v
    return load_config(raw)


def run(cfg, out, **kw):
    kw.setdefault("progress", False)
    return generate(cfg, out, stages=FAKE, **kw)


def everything(root):
    r = ds.open(root)
    return {k: r.read(k) for k in r.keys()}, r


def assert_same(a, b):
    assert set(a) == set(b)
    for k in a:
        assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=a[k].dtype.kind == "f"), k


def test_same_seed_same_arrays_and_seed_matters(tmp_path):
    run(tiny(), tmp_path / "a")
    run(tiny(), tmp_path / "b")
    run(tiny(seed=8), tmp_path / "c")
    a, _ = everything(tmp_path / "a")
    b, _ = everything(tmp_path / "b")
    c, _ = everything(tmp_path / "c")
    assert_same(a, b)
    assert not np.array_equal(a["rgb"], c["rgb"])
    assert not np.array_equal(a["params/worm.hinge_stiffness"], c["params/worm.hinge_stiffness"])


def test_shards_workers_and_batch_size_do_not_change_samples(tmp_path):
    run(tiny(), tmp_path / "s6")  # 4 shards of 6 (last one 4)
    run(tiny(shard_size=22, sim={"worlds": 5}), tmp_path / "s22")  # 1 shard, other batches
    run(tiny(), tmp_path / "w2", workers=2)  # 2 spawned worker processes
    a, ra = everything(tmp_path / "s6")
    assert len(ra.shard_paths) == 4 and len(ra) == 22
    b, rb = everything(tmp_path / "s22")
    assert len(rb.shard_paths) == 1
    c, _ = everything(tmp_path / "w2")
    assert_same(a, b)
    assert_same(a, c)


def test_schema_attributes_and_readers(tmp_path):
    cfg = tiny()
    summary = run(cfg, tmp_path / "d")
    data, r = everything(tmp_path / "d")
    N, H, W = 22, 16, 24
    P = len(json.loads(r.attrs["keypoint_names"]))
    expect = {"rgb": ((N, H, W, 3), np.uint8), "depth": ((N, H, W), np.float32), "segmentation": ((N, H, W), np.uint8),
              "camera/K": ((N, 3, 3), None), "camera/R": ((N, 3, 3), None), "camera/t": ((N, 3), None),
              "poses/body": ((N, 4, 4), None), "poses/ipm": ((N, 3, 4, 4), None), "poses/epm": ((N, 4, 4), None),
              "keypoints/world": ((N, P, 3), None), "keypoints/pixel": ((N, P, 2), None),
              "keypoints/visibility": ((N, P), None), "sample_id": ((N,), None), "seed": ((N,), None)}
    for k, (shape, dtype) in expect.items():
        assert data[k].shape == shape, k
        if dtype is not None:
            assert data[k].dtype == dtype, k
    assert data["creases/angle"].ndim == 2 and data["creases/angle"].shape[0] == N
    assert set(np.unique(data["keypoints/visibility"])) <= {0, 1, 2}
    assert np.array_equal(data["sample_id"], np.arange(N))
    assert len(np.unique(data["seed"])) == N
    # camera matrices: positive focal lengths, proper rotations
    assert np.all(data["camera/K"][:, 0, 0] > 0) and np.all(data["camera/K"][:, 1, 1] > 0)
    assert np.allclose(np.linalg.det(data["camera/R"]), 1)
    # every randomized value is stored
    names = json.loads(r.attrs["params_names"])
    assert names == sorted(cfg.flat_distributions())
    for n in names:
        assert data[f"params/{n}"].shape == (N,)
    # root attributes
    a = r.attrs
    for key in ("config_yaml", "schema_version", "warpworm_version", "warp_version", "units", "keypoint_names",
                "crease_order", "segmentation_ids", "quaternion_order"):
        assert key in a, key
    assert a["quaternion_order"] == "wxyz"
    assert load_config(yaml.safe_load(a["config_yaml"])).to_yaml() == cfg.to_yaml()  # (NaN != NaN in dicts)
    with h5py.File(r.shard_paths[0]) as f:
        assert f["depth"].attrs["unit"] == "m" and f["rgb"].compression == "gzip" and f["rgb"].chunks == (1, H, W, 3)
    # manifest
    m = json.loads((tmp_path / "d" / "manifest.json").read_text())
    assert m["complete"] and m["samples_written"] == N and len(m["shards"]) == 4
    from warpworm.data.export_json import jsonable  # the manifest is strict JSON: NaN (a gait preset's value) as null

    assert yaml.safe_dump(m["config"]) == yaml.safe_dump(jsonable(cfg.to_dict())) and "warp" in m["versions"]
    # random access == bulk read; the torch-style dataset
    for i in (0, 5, 6, 21, -1):
        s = r[i]
        for k in ("rgb", "sample_id", "poses/ipm", "params/worm.gait"):
            assert np.array_equal(s[k], data[k][i]), (i, k)
    assert np.array_equal(r.read("rgb", [21, 0, 7]), data["rgb"][[21, 0, 7]])
    wd = ds.WormDataset(str(tmp_path / "d"), keys=("rgb", "sample_id"), transform=lambda s: {**s, "x": 1})
    assert len(wd) == N and wd[13]["sample_id"] == 13 and wd[13]["x"] == 1
    import pickle

    wd2 = pickle.loads(pickle.dumps(ds.WormDataset(str(tmp_path / "d"))))  # DataLoader workers get a pickled copy
    assert np.array_equal(wd2[3]["rgb"], data["rgb"][3])
    assert summary.new_samples == N


def test_unstable_worlds_are_replaced_deterministically_and_counted(tmp_path):
    s = run(tiny(num_samples=60, shard_size=12), tmp_path / "u")
    data, _ = everything(tmp_path / "u")
    assert s.replaced_worlds > 0
    assert np.all(data["params/worm.hinge_stiffness"] <= 0.9)  # no unstable world kept
    assert int((data["attempt"][data["frame"] == 0] > 0).sum()) <= s.replaced_worlds
    m = json.loads((tmp_path / "u" / "manifest.json").read_text())
    assert m["summary"]["replaced_worlds"] == s.replaced_worlds


def test_non_empty_folder_refused_and_config_change_refused_on_resume(tmp_path):
    run(tiny(), tmp_path / "d")
    with pytest.raises(ConfigError, match="expected an empty or new folder"):
        run(tiny(), tmp_path / "d")
    with pytest.raises(ConfigError, match="seed"):
        run(tiny(seed=99), tmp_path / "d", resume=True)
    s = run(tiny(), tmp_path / "d", resume=True)  # nothing left to do
    assert s.shards_written == 0 and s.shards_done_before == 4


def _cli(out, *extra, env_extra=None):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    env.update(env_extra or {})
    args = [sys.executable, "-m", "warpworm", "generate", "default", "--out", str(out), "--stages", FAKE,
            "--no-progress", "--num", "22", "--seed", "7", "shard_size=6", "sim.worlds=2", "sim.frame_times=[0.1, 0.3]",
            "render.width=24", "render.height=16", "output.preview=false",
            "randomize.worm.hinge_stiffness={uniform: [0.5, 1.0]}", *extra]
    return args, env


def _wait_for_temp(out, proc, timeout=60):
    t0 = time.time()
    while time.time() - t0 < timeout:
        tmps = list(Path(out).glob(".shard-*.tmp-*")) if Path(out).exists() else []
        if tmps:
            return tmps
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError("no shard was started")


def _reference(tmp_path):
    # The same job as _cli's, uninterrupted, in this process (the default.yaml randomization + the overrides).
    cfg = load_config("default", ["shard_size=6", "sim.worlds=2", "sim.frame_times=[0.1, 0.3]", "render.width=24",
                                  "render.height=16", "output.preview=false",
                                  "randomize.worm.hinge_stiffness={uniform: [0.5, 1.0]}"], num_samples=22, seed=7)
    run(cfg, tmp_path / "ref")
    return everything(tmp_path / "ref")[0]


def _check_complete_and_equal(out, ref):
    assert not list(Path(out).glob(".*.tmp-*"))
    data, r = everything(out)
    assert len(r) == 22 and np.array_equal(np.sort(data["sample_id"]), np.arange(22))
    assert json.loads((Path(out) / "manifest.json").read_text())["complete"]
    for p in r.shard_paths:
        with h5py.File(p) as f:
            assert f.attrs["complete"]
    assert_same(data, ref)


def test_worker_killed_mid_shard_then_resume(tmp_path):
    out = tmp_path / "job"
    args, env = _cli(out, "--workers", "2", env_extra={"WARPWORM_FAKE_SLEEP": "0.15"})
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tmp = _wait_for_temp(out, proc)[0]
    victim = int(tmp.name.rsplit("-", 1)[1])  # the worker writing that shard
    os.kill(victim, signal.SIGKILL)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 1 and "--resume" in err, err
    done = sorted(p.name for p in out.glob("shard-*.h5"))
    assert len(done) < 4  # the killed worker's shard is missing
    args, env = _cli(out, "--resume", "--workers", "2")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    _check_complete_and_equal(out, _reference(tmp_path))


def test_whole_job_killed_then_resume(tmp_path):
    out = tmp_path / "job"
    args, env = _cli(out, "--workers", "2", env_extra={"WARPWORM_FAKE_SLEEP": "0.15"})
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    tmps = _wait_for_temp(out, proc)
    proc.kill()  # kill -9 of the job's main process
    proc.wait(timeout=30)
    for t in tmps:  # orphaned workers notice and exit (watchdog, 0.5 s), so nothing keeps writing
        pid = int(t.name.rsplit("-", 1)[1])
        t_end = time.monotonic() + 30.0  # a ceiling against a hang: the wait ends when the worker is gone
        while time.monotonic() < t_end:
            try:
                os.kill(pid, 0)
            except ProcessLookupError:
                break
            time.sleep(0.02)
        else:
            raise AssertionError(f"worker {pid} outlived its parent by 30 s")
    args, env = _cli(out, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    _check_complete_and_equal(out, _reference(tmp_path))


@pytest.mark.skipif(not os.access("/dev/full", os.W_OK), reason="no writable /dev/full on this machine")
def test_disk_full_gives_clear_error_and_keeps_completed_shards(tmp_path, monkeypatch):
    """The disk fills up while shard 2 is written: a plain OSError, the kernel's own ENOSPC from /dev/full, raised
    inside the writer's HDF5 dataset creation, so the writer's translation into its one clear error is what is
    tested (the test used to raise the project's DatasetWriteError itself)."""
    real_create = ds.ShardWriter._create

    def create(self, name, arr):
        if self.index == 2:
            with open("/dev/full", "wb", buffering=0) as full:
                full.write(b"\0" * 4096)  # OSError(ENOSPC) from the kernel
        return real_create(self, name, arr)

    monkeypatch.setattr(ds.ShardWriter, "_create", create)
    with pytest.raises(ds.DatasetWriteError, match="shard-00002.*No space left on device.*--resume") as ei:
        run(tiny(), tmp_path / "d")
    assert ei.value.errno == errno.ENOSPC
    names = sorted(p.name for p in (tmp_path / "d").iterdir())
    assert names == [ds.LOCK_NAME, "manifest.json", "shard-00000.h5", "shard-00001.h5"]  # no temporary left
    m = json.loads((tmp_path / "d" / "manifest.json").read_text())
    assert not m["complete"] and [s["index"] for s in m["shards"]] == [0, 1]
    monkeypatch.setattr(ds.ShardWriter, "_create", real_create)
    run(tiny(), tmp_path / "d", resume=True)
    assert len(ds.open(tmp_path / "d")) == 22


def test_read_only_folder_refused_before_work(tmp_path):
    with pytest.raises(ConfigError, match="writable"):
        run(tiny(), "/proc/warpworm-dataset")


def test_ray_engine_gives_the_same_samples(tmp_path, monkeypatch):
    ray = pytest.importorskip("ray", reason="Ray not installed (optional extra: pip install 'warpworm[ray]')")
    # local Ray workers inherit the environment: let them import the fake stages
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(TESTS), os.environ.get("PYTHONPATH", "")]))
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        run(tiny(), tmp_path / "ray", engine="ray")
    finally:
        ray.shutdown()
    run(tiny(), tmp_path / "local")
    assert_same(everything(tmp_path / "ray")[0], everything(tmp_path / "local")[0])


def _in_frame(data, margin=2.0):
    """Fraction of each sample's worm vertices that project at least ``margin`` px inside the image (re-derived)."""
    pc = np.einsum("nij,nvj->nvi", data["camera/R"], data["worm/vertices"].astype(np.float64)) + data["camera/t"][:, None]
    uv = np.einsum("nij,nvj->nvi", data["camera/K"], pc)
    u, v = uv[..., 0] / uv[..., 2], uv[..., 1] / uv[..., 2]
    H, W = data["depth"].shape[1:]
    inside = (pc[..., 2] > 1e-3) & (u >= margin) & (u <= W - 1 - margin) & (v >= margin) & (v <= H - 1 - margin)
    return inside.mean(axis=1)


def test_cameras_keep_the_worm_in_frame_and_do_not_depend_on_batching(tmp_path):
    cam = {"render": {"width": 24, "height": 16, "camera_per_frame": True},
           "randomize": {"worm": {"hinge_stiffness": {"uniform": [0.5, 1.0]}},
                         "camera": {"distance": {"uniform": [0.05, 0.3]}, "min_in_frame": 0.95}}}
    s = run(tiny(**cam), tmp_path / "a")
    a, _ = everything(tmp_path / "a")
    assert s.cameras_below_min == 0
    assert np.all(a["camera/in_frame"] >= 0.95)
    assert np.allclose(a["camera/in_frame"], _in_frame(a), atol=1e-6)  # the stored fraction is the real one
    assert np.allclose(a["params/camera.min_in_frame"], a["camera/in_frame"])
    # a view's distance / fov are drawn within the configured ranges, and stored
    assert np.all((a["params/camera.distance"] >= 0.05) & (a["params/camera.distance"] <= 0.3))
    # same cameras with another shard size and batch size (per-sample seeds)
    run(tiny(**cam, shard_size=22, sim={"worlds": 5, "frame_times": [0.1, 0.3]}), tmp_path / "b")
    b, _ = everything(tmp_path / "b")
    for k in ("camera/K", "camera/R", "camera/t", "camera/in_frame", "params/camera.azimuth"):
        assert np.array_equal(a[k], b[k]), k


def test_unattainable_in_frame_requirement_keeps_best_view_and_counts_it(tmp_path):
    # 1 cm away with a narrow field of view: the worm can never be 99 % inside a 24 x 16 image
    cam = {"randomize": {"worm": {"hinge_stiffness": {"uniform": [0.5, 1.0]}},
                         "camera": {"distance": 0.01, "fov_y": 0.1, "min_in_frame": 0.99, "max_tries": 3}}}
    s = run(tiny(**cam), tmp_path / "a")
    a, _ = everything(tmp_path / "a")
    assert s.cameras_below_min == len(np.unique(a["trajectory"]))  # one camera per trajectory, none met it
    assert np.all(a["camera/in_frame"] < 0.99)
    m = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert m["summary"]["cameras_below_min"] == s.cameras_below_min
