"""Faults injected into dataset jobs (fake stages, tests/test_dataset_fakes.py): disk full, read-only folder, damaged
shards and manifests, a second job on a locked folder, SIGTERM / SIGINT / SIGKILL at random moments then --resume;
plus the schema table, the shard plan for workers, `warpworm verify`, the COCO export and the CUDA-warning-free start."""

import argparse
import builtins
import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from warpworm.data import dataset as ds
from warpworm.commands import verify as vf
from warpworm.data.job import shard_plan

from test_dataset_pipeline import FAKE, _cli, _reference, assert_same, everything, run, tiny

DOCS = Path(__file__).parent.parent / "docs" / "dataset.md"


@pytest.fixture(scope="module")
def ref(tmp_path_factory):
    """The uninterrupted job of _cli's arguments (22 samples, 4 shards of 6): the truth every recovery must equal."""
    return _reference(tmp_path_factory.mktemp("ref"))


def _verify(d) -> tuple[int, list[str]]:
    problems, _ = vf.verify_dataset(d)
    return (1 if problems else 0), problems


# --- 1. quiet start --------------------------------------------------------------------------------------------------
def test_no_cuda_warning_on_cpu_and_one_device_line(tmp_path):
    for dev in ("cpu", "auto"):
        args, env = _cli(tmp_path / dev, f"sim.device={dev}")
        r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 0, r.stderr
        assert "CUDA warning" not in r.stderr and "CUDA driver" not in r.stdout, r.stderr
        lines = [ln for ln in r.stderr.splitlines() if ln.startswith("device:")]
        assert len(lines) == 1 and lines[0].startswith("device: cpu"), r.stderr


# --- 2. schema: one table, generated from the code, equal to the files ----------------------------------------------
def test_docs_table_is_the_schema_and_files_follow_it(tmp_path):
    text = DOCS.read_text()
    assert ds.schema_markdown() in text, "docs/dataset.md: regenerate the table with warpworm.data.dataset.schema_markdown()"
    assert text.count(ds.SCHEMA_TABLE_BEGIN) == 1
    run(tiny(), tmp_path / "d")
    r = ds.open(tmp_path / "d")
    with h5py.File(r.shard_paths[-1]) as f:  # the last, shorter shard (4 samples)
        names = []
        f.visititems(lambda n, o: names.append(n) if isinstance(o, h5py.Dataset) else None)
        assert sorted(n for n in names if not n.startswith("params/")) == sorted(fl.name for fl in ds.FIELDS)
        dims = {"N": 4, "H": 16, "W": 24, "P": len(json.loads(f.attrs["keypoint_names"])),
                "C": len(f.attrs["crease_hinges"]), "E": len(f.attrs["bar_edges"]), "V": f["worm/vertices"].shape[1]}
        for fl in ds.FIELDS:
            assert f[fl.name].shape == ds.resolve_shape(fl, dims), fl.name
            assert str(f[fl.name].dtype) == fl.dtype, fl.name
            assert f[fl.name].attrs["unit"] == fl.unit, fl.name
        # keypoints/body against an independent inverse of the stored 4x4 body pose
        body, kw, kb = f["poses/body"][...], f["keypoints/world"][...], f["keypoints/body"][...]
        hom = np.concatenate([kw, np.ones(kw.shape[:2] + (1,))], -1)
        assert np.allclose(np.einsum("nij,npj->npi", np.linalg.inv(body), hom)[..., :3], kb, rtol=0, atol=1e-12)
        assert f["keypoints/body"].attrs["unit"] == "m"


# --- 3. shards sized for the workers ---------------------------------------------------------------------------------
def test_shard_plan_gives_every_worker_work_and_keeps_the_samples(tmp_path, ref):
    prod = tiny(num_samples=2048, shard_size=16384, sim={"worlds": 2, "frame_times": [0.1 * i for i in range(1, 9)]})
    c, note = shard_plan(prod, 2)
    assert (c.shard_size, c.num_shards) == (1024, 2) and "16384 -> 1024" in note
    assert shard_plan(prod, 1)[0].shard_size == 16384 and shard_plan(prod, 1)[1] is None
    few = tiny(num_samples=4, shard_size=6)  # 2 trajectories of 2 frames: at most 2 shards
    c, note = shard_plan(few, 4)
    assert c.num_shards == 2 and "2 of 4 workers will be idle" in note and "trajector" in note
    # one shard of 22 samples on 2 workers -> 2 shards (12 + 10); the same samples as 4 shards of 6
    s = run(tiny(shard_size=22), tmp_path / "w2", workers=2)
    a, r = everything(tmp_path / "w2")
    assert len(r.shard_paths) == 2 and s.shards_total == 2
    m = json.loads((tmp_path / "w2" / "manifest.json").read_text())
    assert m["shard_size"] == 12 and m["shard_size_requested"] == 22
    run(tiny(), tmp_path / "s6")
    assert_same(a, everything(tmp_path / "s6")[0])
    # resuming with another worker count keeps the first run's sharding
    s = run(tiny(shard_size=22), tmp_path / "w2", resume=True)
    assert s.shards_total == 2 and s.shards_written == 0


# --- 4. disk full, read-only -----------------------------------------------------------------------------------------
def _inject_write_error(monkeypatch, shard: int, err: int):
    real = ds.FailSafeFile._raw_write

    def raw_write(self, b):
        if f"shard-{shard:05d}" in self.path.name and self.raw.tell() > 2000:
            raise OSError(err, os.strerror(err))
        return real(self, b)

    monkeypatch.setattr(ds.FailSafeFile, "_raw_write", raw_write)


def _only_final_files(d):
    names = sorted(p.name for p in Path(d).iterdir())
    assert not [n for n in names if ".tmp" in n], names  # nothing half-written left
    return [n for n in names if not n.startswith(".")]


@pytest.mark.parametrize("err, advice", [(errno.ENOSPC, "free space"), (errno.EROFS, "writable")])
def test_write_error_mid_shard_one_line_intact_shards_and_resume(tmp_path, monkeypatch, ref, err, advice):
    out = tmp_path / "d"
    cfg = tiny()
    _inject_write_error(monkeypatch, 2, err)
    with pytest.raises(ds.DatasetWriteError) as ei:
        run(cfg, out)
    msg = str(ei.value.strerror)
    assert "\n" not in msg and "shard-00002.h5" in msg and advice in msg and "--resume" in msg, msg
    assert _only_final_files(out) == ["manifest.json", "shard-00000.h5", "shard-00001.h5"]
    m = json.loads((out / "manifest.json").read_text())
    assert not m["complete"] and [s["index"] for s in m["shards"]] == [0, 1]
    for s in m["shards"]:  # the finished shards are intact: their bytes are what was checksummed at commit
        assert ds.file_sha256(out / s["file"]) == s["sha256"]
    monkeypatch.undo()
    run(cfg, out, resume=True)
    assert _verify(out) == (0, [])


def test_read_only_folder_mid_job_permission_error(tmp_path, monkeypatch):
    out = tmp_path / "d"
    real_init = ds.FailSafeFile.__init__

    def init(self, path):
        if "shard-00001" in Path(path).name:
            raise PermissionError(errno.EACCES, "Permission denied", str(path))
        real_init(self, path)

    monkeypatch.setattr(ds.FailSafeFile, "__init__", init)
    with pytest.raises(ds.DatasetWriteError, match=r"shard-00001\.h5.*Permission denied.*writable.*--resume"):
        run(tiny(), out)
    assert _only_final_files(out) == ["manifest.json", "shard-00000.h5"]


@pytest.mark.skipif(not os.access("/dev/full", os.W_OK), reason="no writable /dev/full on this machine")
def test_real_enospc_from_dev_full_mid_shard(tmp_path, monkeypatch):
    """A real ENOSPC, raised by the kernel: once shard 2's file holds 2 kB, its bytes go to /dev/full (every write
    there fails with ENOSPC) through the writer's own file object, so the OSError takes the writer's path (no error
    made up by the test): one line naming the shard, the OS's reason and the advice, the finished shards intact, the
    temporary gone, and --resume completes the job. Runs where ``mount`` is not
    allowed (the tmpfs test below needs root)."""
    out = tmp_path / "d"
    real_init = ds.FailSafeFile.__init__
    full = []

    def init(self, path):
        real_init(self, path)
        if "shard-00002" in Path(path).name:
            raw = self.raw
            dev_full = builtins.open("/dev/full", "wb", buffering=0)
            full.append(dev_full)

            def raw_write(b):
                return (dev_full if raw.tell() > 2000 else raw).write(b)

            self._raw_write = raw_write

    monkeypatch.setattr(ds.FailSafeFile, "__init__", init)
    with pytest.raises(ds.DatasetWriteError) as ei:
        run(tiny(), out)
    assert full, "shard 2 was never opened"
    assert ei.value.errno == errno.ENOSPC
    msg = str(ei.value.strerror)
    assert "\n" not in msg and "shard-00002.h5" in msg and os.strerror(errno.ENOSPC) in msg and "free space" in msg
    assert "--resume" in msg, msg
    assert _only_final_files(out) == ["manifest.json", "shard-00000.h5", "shard-00001.h5"]
    monkeypatch.undo()
    for f in full:
        f.close()
    run(tiny(), out, resume=True)
    assert _verify(out) == (0, []) and len(ds.open(out)) == 22


def test_real_full_tmpfs_exit_code_3(tmp_path, ref):
    mnt = tmp_path / "tiny_fs"
    mnt.mkdir()
    if os.geteuid() != 0 or subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mnt)],
                                           capture_output=True).returncode != 0:
        pytest.skip("cannot mount a tmpfs here (needs root)")
    try:
        args, env = _cli(mnt / "d")
        r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 3, (r.returncode, r.stderr[-2000:])  # was 139 (segfault)
        err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and "No space left on device" in err[0] and "--resume" in err[0], r.stderr
        assert "Traceback" not in r.stderr
        _only_final_files(mnt / "d")
        for p in (mnt / "d").glob("shard-*.h5"):  # every final shard there is complete
            k = int(p.name[6:11])
            assert ds.shard_problem(p, 6 * k, min(6, 22 - 6 * k)) is None
        # move the job to a roomy disk, resume there: equal to the uninterrupted one
        shutil.copytree(mnt / "d", tmp_path / "moved")
    finally:
        subprocess.run(["umount", str(mnt)], capture_output=True)
    args, env = _cli(tmp_path / "moved", "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert_same(everything(tmp_path / "moved")[0], ref)


# --- 4/5. damaged shards and manifests, verify -----------------------------------------------------------------------
def _job(tmp_path, name="d"):
    args, env = _cli(tmp_path / name)
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return tmp_path / name


def test_bit_flip_and_truncation_found_by_verify_and_redone_by_resume(tmp_path, ref):
    d = _job(tmp_path)
    assert _verify(d) == (0, [])
    p1, p2 = d / "shard-00001.h5", d / "shard-00002.h5"
    raw = bytearray(p1.read_bytes())
    raw[len(raw) // 2] ^= 0x10  # one bit
    p1.write_bytes(bytes(raw))
    p2.write_bytes(p2.read_bytes()[: p2.stat().st_size // 2])
    r = subprocess.run([sys.executable, "-m", "warpworm", "verify", str(d)], capture_output=True, text=True,
                       timeout=60)
    assert r.returncode == 1
    assert "shard-00001.h5: checksum mismatch" in r.stdout and "shard-00002.h5" in r.stdout, r.stdout
    assert "shard-00000.h5" not in r.stdout and "shard-00003.h5" not in r.stdout
    args, env = _cli(d, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "shard-00001.h5: checksum mismatch" in r.stderr and "shard-00002.h5" in r.stderr
    assert _verify(d) == (0, [])
    assert_same(everything(d)[0], ref)


def test_corrupt_or_missing_manifest(tmp_path, ref):
    d = _job(tmp_path)
    (d / "manifest.json").write_text('{"format": "warpworm-dataset", "shards": [')  # cut mid-write by hand
    with pytest.raises(ds.DatasetError, match=r"manifest\.json: unreadable.*--resume"):
        ds.open(d)
    assert vf.main(argparse.Namespace(dir=str(d), max_problems=50)) == 2
    args, env = _cli(d, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "rebuilding it from the shards" in r.stderr, r.stderr
    assert _verify(d) == (0, []) and r.stdout.count("wrote 0 shard(s)") == 1
    (d / "manifest.json").unlink()
    with pytest.raises(ds.DatasetError, match="missing"):
        ds.open(d)
    args, env = _cli(d, "--resume", "--seed", "8")  # another config: refused, naming the shard and the key
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and "shard-00000.h5" in r.stderr and "seed" in r.stderr, r.stderr
    args, env = _cli(d, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "missing; rebuilding" in r.stderr, r.stderr
    assert _verify(d) == (0, [])
    assert_same(everything(d)[0], ref)


def test_verify_label_invariants_catch_tampering(tmp_path):
    run(tiny(), tmp_path / "d")
    with h5py.File(ds.open(tmp_path / "d").shard_paths[0]) as f:
        data = {fl.name: f[fl.name][...] for fl in ds.FIELDS}
    assert vf.check_labels(data, 16, 24) == []
    for key, change, expect in [
        ("keypoints/pixel", lambda a: a + np.array([0.01, 0.0]), "projection"),
        ("poses/body_quat", lambda a: a * 1.001, "not unit"),
        ("camera/R", lambda a: a * 1.0001, "orthonormal"),
        ("keypoints/body", lambda a: a + 1e-6, "keypoints/body"),
        ("keypoints/visibility", lambda a: np.where(a == 2, 0, a), "v = 0 inside"),
        ("keypoints/visibility", lambda a: np.where(a == 2, 1, a), "occluded"),
    ]:
        bad = dict(data, **{key: change(data[key].copy())})
        problems = vf.check_labels(bad, 16, 24)
        assert any(expect in p for p in problems), (key, problems)


# --- 4. advisory lock ------------------------------------------------------------------------------------------------
def test_second_job_on_a_locked_folder_is_refused_by_name_and_a_stale_lock_is_recognised(tmp_path):
    d = tmp_path / "d"
    d.mkdir()
    with ds.FolderLock(d).acquire(command="holder-job"):
        args, env = _cli(d, "--resume")
        r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
        assert r.returncode == 4, r.stderr
        assert f"pid {os.getpid()}" in r.stderr and "host" in r.stderr and "started" in r.stderr, r.stderr
        assert "holder-job" in r.stderr
        with pytest.raises(ds.DatasetLockedError, match=f"pid {os.getpid()}"):
            run(tiny(), d, resume=True)
    assert not list(d.glob("shard-*"))
    # a lock file left by a job that is gone (written, not held): recognised as stale and taken over
    (d / ds.LOCK_NAME).write_text(json.dumps({"pid": 999999, "host": "gone-host", "started": "2020-01-01T00:00:00"}))
    notes = []
    run(tiny(), d, resume=True, log=notes.append)
    assert any("stale lock" in n and "999999" in n and "gone-host" in n for n in notes), notes
    assert ds.lock_holder(d) is None and (d / ds.LOCK_NAME).read_text() == ""  # released cleanly: empty


# --- 4. signals at random moments, then --resume ---------------------------------------------------------------------
def _wait_started(out, proc, old, timeout=60):
    t0 = time.time()
    while time.time() - t0 < timeout:
        if Path(out).exists() and set(Path(out).glob(".shard-*.tmp-*")) - old:  # this run is writing a shard
            return
        if proc.poll() is not None:
            return
        time.sleep(0.01)
    raise AssertionError("the job never started a shard")


def _interrupt_once(out, sig, workers, resume, rng):
    """Start the job (resuming if asked), send ``sig`` at a random moment once it writes a shard, and check the stop.
    Returns True if the signal was delivered, False if the job finished first."""
    extra = ["--workers", workers] + (["--resume"] if resume else [])
    args, env = _cli(out, *extra, env_extra={"WARPWORM_FAKE_SLEEP": "0.08"})
    old = set(out.glob(".shard-*.tmp-*")) if out.exists() else set()  # a SIGKILLed run's leftovers
    proc = subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    _wait_started(out, proc, old)
    time.sleep(float(rng.uniform(0.0, 0.5)))
    delivered = proc.poll() is None
    if delivered:
        os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=60)
    if proc.returncode == 0:
        return False  # finished before the signal
    if sig == signal.SIGKILL:
        assert proc.returncode == -signal.SIGKILL  # orphaned workers exit by their watchdog (0.5 s): waited below
    else:
        assert proc.returncode == 128 + sig, (sig, proc.returncode, err)
        assert "stopped: interrupted by" in err and "--resume" in err, err
        assert not list(out.glob(".*.tmp-*")), list(out.iterdir())
        m = json.loads((out / "manifest.json").read_text())
        assert sorted(s["file"] for s in m["shards"]) == sorted(p.name for p in out.glob("shard-*.h5"))
    t_end = time.monotonic() + 30.0  # a ceiling against a hang, not a timing: the loop ends when the session empties
    while True:  # no live process of the job is left in its session (exited ones may be zombies
        ps = subprocess.run(["ps", "-o", "stat=,pid=,args=", "-s", str(proc.pid)], capture_output=True, text=True)
        live = [ln for ln in ps.stdout.splitlines() if ln.strip() and not ln.strip().startswith("Z")]
        if not live or time.monotonic() > t_end:  # (un-reaped where pid 1 does not reap orphans, as here)
            break
        time.sleep(0.05)
    if live:
        raise AssertionError(f"interrupted job ({sig.name}) left live processes: {live}")
    return delivered


def _finish_and_check(out, ref):
    args, env = _cli(out, "--resume")
    r = subprocess.run(args, env=env, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert not list(out.glob(".*.tmp-*"))
    assert _verify(out) == (0, [])
    assert_same(everything(out)[0], ref)


def test_killed_at_random_moments_then_resumed_equals_uninterrupted(tmp_path, ref):
    """20 interruptions at random moments (seeded), cycling SIGTERM, SIGKILL, SIGTERM and SIGINT over 1 and 2 workers,
    each followed by --resume; a job that completes is checked and a new one started. SIGTERM and SIGINT must stop
    cleanly (exit 128 + signal, no temporary, workers gone, manifest listing exactly the shards on disk); SIGKILL
    leaves at most temporaries and a stale lock. Every finished dataset equals the uninterrupted one byte for byte."""
    rng = np.random.default_rng(20240611)
    plan = [(signal.SIGTERM, "1"), (signal.SIGKILL, "1"), (signal.SIGTERM, "2"), (signal.SIGINT, "2")]
    interrupted, jobs, step, resume = 0, 0, 0, False
    out = tmp_path / f"job{jobs}"
    while interrupted < 20:
        sig, workers = plan[step % len(plan)]
        step += 1
        if _interrupt_once(out, sig, workers, resume, rng):
            interrupted += 1
            resume = True
        else:  # the job finished: check it and start the next one
            _finish_and_check(out, ref)
            jobs += 1
            out, resume = tmp_path / f"job{jobs}", False
        assert step < 80, "the jobs keep finishing before the signal"
    if out.exists():
        _finish_and_check(out, ref)


# --- 6. COCO keypoints -----------------------------------------------------------------------------------------------
def test_coco_export_structure_and_cocoeval(tmp_path):
    import cv2

    run(tiny(num_samples=8), tmp_path / "d")
    r = subprocess.run([sys.executable, "-m", "warpworm", "export-coco", str(tmp_path / "d"), str(tmp_path / "c")],
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    coco = json.loads((tmp_path / "c" / "annotations" / "keypoints.json").read_text())
    rd = ds.open(tmp_path / "d")
    from warpworm.data import export_keypoints as ek  # the 16 distinct exported keypoints (tests/test_export_formats.py)

    names = list(ek.KeypointExporter(rd).names)
    take = [json.loads(rd.attrs["keypoint_names"]).index(n) for n in ek.DATASET_NAMES if n in names]
    P, Q = len(names), len(take)
    (cat,) = coco["categories"]
    assert cat["id"] == 1 and cat["keypoints"] == names
    assert all(1 <= a <= P and 1 <= b <= P and a != b for a, b in cat["skeleton"]) and len(cat["skeleton"]) >= P - 1
    assert len(coco["images"]) == len(coco["annotations"]) == 8
    ids = {im["id"] for im in coco["images"]}
    for ann in coco["annotations"]:
        s = rd[ann["image_id"]]
        im = next(i for i in coco["images"] if i["id"] == ann["image_id"])
        assert ann["image_id"] in ids and ann["category_id"] == 1 and ann["iscrowd"] == 0
        kp = np.array(ann["keypoints"], float).reshape(P, 3)
        assert np.array_equal(kp[:Q, 2], s["keypoints/visibility"][take])  # COCO 0/1/2 = the dataset's flags
        v = kp[:, 2] > 0
        assert np.array_equal(kp[:Q][v[:Q], :2], s["keypoints/pixel"][take][v[:Q]]) and np.all(kp[~v, :2] == 0)
        assert ann["num_keypoints"] == int(v.sum())
        worm = (s["segmentation"] >= 2) & (s["segmentation"] <= 6)
        assert ann["area"] == worm.sum()
        x, y, w, h = ann["bbox"]
        assert 0 <= x and 0 <= y and x + w <= im["width"] and y + h <= im["height"]
        png = cv2.imread(str(tmp_path / "c" / im["file_name"]))[..., ::-1]
        assert np.array_equal(png, s["rgb"])
    pc = pytest.importorskip("pycocotools", reason="pycocotools not installed (test extra)")
    del pc
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval

    gt = COCO(str(tmp_path / "c" / "annotations" / "keypoints.json"))
    for ann in gt.dataset["annotations"]:  # the RLE decodes to the dataset's visible worm pixels
        seg = rd[ann["image_id"]]["segmentation"]
        assert np.array_equal(gt.annToMask(ann).astype(bool), (seg >= 2) & (seg <= 6))
    # pycocotools scores a detection off by a known shift d: its OKS is the closed form over the visible keypoints,
    # mean exp(−d² / (2 s² (2σ)²)) with s² the worm's visible pixel count from the segmentation (not the export's
    # area) and σ each keypoint's own sigma by name (export_keypoints.OKS_SIGMAS, not the file's list); so a wrong
    # area, a sigma list out of the keypoints' order or a wrong visibility flag fails here (the ground truth against
    # itself scored AP 1 whatever the file said)
    sig = np.array([ek.OKS_SIGMAS[n] for n in coco["categories"][0]["keypoints"]])
    shift = {}
    dets = []
    for a in gt.dataset["annotations"]:
        kp = np.array(a["keypoints"], float).reshape(-1, 3)
        shift[a["id"]] = 0.05 * np.sqrt(a["area"])  # px along x: OKS ~0.6-0.9 for these sigmas
        kp[kp[:, 2] > 0, 0] += shift[a["id"]]
        dets.append(dict(a, keypoints=kp.reshape(-1).tolist(), score=1.0))
    dt = gt.loadRes(dets)
    ev = COCOeval(gt, dt, "keypoints")
    ev.params.kpt_oks_sigmas = np.array(coco["info"]["kpt_oks_sigmas"])  # as a user sets them: from the file
    ev.evaluate()
    checked = 0
    for a in gt.dataset["annotations"]:
        vis = np.array(a["keypoints"]).reshape(-1, 3)[:, 2] > 0
        if not vis.any():
            continue
        seg = rd[a["image_id"]]["segmentation"]
        s2 = float(((seg >= 2) & (seg <= 6)).sum())
        expected = np.mean(np.exp(-shift[a["id"]] ** 2 / (2.0 * s2 * (2.0 * sig[vis]) ** 2)))
        got = np.asarray(ev.ious[(a["image_id"], a["category_id"])])
        # both float64 (pycocotools adds eps to the area): 1e-12 is rounding, far under any export error
        assert got.shape == (1, 1) and got[0, 0] == pytest.approx(expected, rel=1e-12), (got, expected)
        checked += 1
    assert checked >= 2
