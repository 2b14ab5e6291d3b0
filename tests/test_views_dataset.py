"""``render.views_per_frame: K``: K cameras of every simulated frame, each its own sample. Against the deterministic
fake stages (tests/test_dataset_fakes.py): the samples do not depend on shards, workers or a kill and resume; the K
views of a frame share the simulated world and differ in camera, sample id and pixel noise; view 0 is the camera of a
K = 1 job; and the config refuses a shard size that splits a trajectory's views."""

import os
import subprocess
import sys

import numpy as np
import pytest

from warpworm.data.config import ConfigError, load_config

from test_dataset_pipeline import FAKE, _wait_for_temp, assert_same, everything, run, tiny

K = 2
F = 2  # tiny()'s frame_times


def views(**over):
    over.setdefault("render", {})
    over["render"] = {**over["render"], "views_per_frame": K}
    over.setdefault("num_samples", 20)
    over.setdefault("shard_size", 8)
    return tiny(**over)


def test_sample_layout_and_what_views_share(tmp_path):
    run(views(), tmp_path / "v")
    a, r = everything(tmp_path / "v")
    i = a["sample_id"]
    assert len(r) == 20 and np.array_equal(i, np.arange(20))
    # sample = (trajectory K + view) F + frame
    assert np.array_equal(a["trajectory"], i // (K * F))
    assert np.array_equal(a["view"], (i // F) % K)
    assert np.array_equal(a["frame"], i % F)
    assert a["view"].dtype == np.int32
    for j in np.unique(a["trajectory"]):
        s0 = (a["trajectory"] == j) & (a["view"] == 0)
        s1 = (a["trajectory"] == j) & (a["view"] == 1)
        if s1.sum() < F:
            continue  # the last trajectory is cut by num_samples
        # same simulated world, frame by frame: physics and its draws equal ...
        for k in ("worm/vertices", "poses/body", "creases/angle", "time", "params/worm.hinge_stiffness",
                  "params/color.worm_hue", "attempt"):
            assert np.array_equal(a[k][s0], a[k][s1]), k
        # ... seen by another camera (one per view, fixed over the frames), with its own pixel-noise seed
        assert not np.allclose(a["camera/R"][s0][0], a["camera/R"][s1][0])
        assert np.array_equal(a["camera/R"][s1][0], a["camera/R"][s1][-1])
        assert len(np.unique(a["seed"][(a["trajectory"] == j)])) == K * F


def test_view_zero_is_the_camera_of_a_one_view_job(tmp_path):
    run(tiny(num_samples=10, shard_size=10), tmp_path / "k1")
    run(views(num_samples=20, shard_size=20), tmp_path / "k2")
    a, _ = everything(tmp_path / "k1")
    b, _ = everything(tmp_path / "k2")
    assert "view" not in a
    v0 = b["view"] == 0
    for k in ("camera/K", "camera/R", "camera/t", "worm/vertices", "trajectory", "frame", "params/camera.distance"):
        assert np.array_equal(a[k], b[k][v0]), k


def test_shards_workers_and_batches_do_not_change_samples(tmp_path):
    run(views(), tmp_path / "s8")  # 3 shards of 8 (last one 4)
    run(views(shard_size=20, sim={"worlds": 5}), tmp_path / "s20")  # 1 shard, other solver batches
    run(views(render={"batch": 4}), tmp_path / "b4")  # a render call per trajectory
    run(views(), tmp_path / "w2", workers=2)  # 2 spawned worker processes
    a, ra = everything(tmp_path / "s8")
    assert len(ra.shard_paths) == 3
    for other in ("s20", "b4", "w2"):
        assert_same(a, everything(tmp_path / other)[0])


def test_killed_job_resumed_gives_the_same_samples(tmp_path):
    from test_dataset_pipeline import _cli

    extra = ["render.views_per_frame=2", "shard_size=8"]
    out = tmp_path / "job"
    args, env = _cli(out, *extra, env_extra={"WARPWORM_FAKE_SLEEP": "0.15"})
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    _wait_for_temp(out, proc)
    proc.kill()  # kill -9 mid-shard
    proc.wait(timeout=30)
    assert len(list(out.glob("shard-*.h5"))) < 3
    args, env = _cli(out, *extra, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    ref = load_config("default", ["shard_size=8", "sim.worlds=2", "sim.frame_times=[0.1, 0.3]", "render.width=24",
                                  "render.height=16", "output.preview=false", "render.views_per_frame=2",
                                  "randomize.worm.hinge_stiffness={uniform: [0.5, 1.0]}"], num_samples=22, seed=7)
    run(ref, tmp_path / "ref")
    got, rr = everything(out)
    assert len(rr) == 22 and not list(out.glob(".*.tmp-*"))
    assert_same(got, everything(tmp_path / "ref")[0])


def test_shard_size_must_hold_whole_trajectories_of_views():
    with pytest.raises(ConfigError, match=r"shard_size: got 6; expected a multiple of render.views_per_frame"):
        views(shard_size=6)
    with pytest.raises(ConfigError, match=r"render.views_per_frame: got 0; expected >= 1"):
        tiny(render={"views_per_frame": 0})
    assert "views_per_frame" not in tiny().to_dict()["render"]  # K = 1: the config text of before the option
    assert views().to_dict()["render"]["views_per_frame"] == K
