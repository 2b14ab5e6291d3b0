"""``warpworm report``: the JSON numbers re-derived from the HDF5 shards with h5py + NumPy, the side-by-side PNG of two
folders (a sweep of one parameter), the JSON-only fallback without matplotlib, and bad input (exit 2, one line)."""

import json
import shutil
import subprocess
import sys

import cv2
import h5py
import numpy as np
import pytest

GEN = ["--num", "8", "--no-progress", "--no-preview", "sim.worlds=4", "shard_size=4", "sim.settle_time=0.02",
       "sim.frame_times=[0.02, 0.04]", "render.width=32", "render.height=24"]


def _warpworm(*args, timeout=180):
    return subprocess.run([sys.executable, "-m", "warpworm", *args], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def folders(tmp_path_factory):
    """Two tiny real-physics datasets of the default config: seed 1, and seed 2 with mu_static swept to [0.1, 0.2]."""
    root = tmp_path_factory.mktemp("report")
    a, b = root / "a", root / "b"
    r = _warpworm("generate", "default", "--out", str(a), "--seed", "1", *GEN)
    assert r.returncode == 0, r.stderr
    r = _warpworm("generate", "default", "--out", str(b), "--seed", "2", *GEN,
                  "randomize.worm.mu_static={uniform: [0.1, 0.2]}")
    assert r.returncode == 0, r.stderr
    return a, b


def _read(folder):
    """Every shard's arrays concatenated, straight from h5py (independent of warpworm's readers)."""
    shards = sorted(folder.glob("shard-*.h5"))
    out = {}
    for p in shards:
        with h5py.File(p, "r") as f:
            names = ["trajectory", "creases/angle", "labels/deformation", "labels/visib_fract", "labels/bbox_obj",
                     "camera/position", "poses/body"] + [f"params/{n}" for n in json.loads(f.attrs["params_names"])]
            for n in names:
                out.setdefault(n, []).append(f[n][...])
    return {k: np.concatenate(v) for k, v in out.items()}, len(shards)


def _expected(d):
    """The report's numbers, computed here with a plain loop over trajectories."""
    traj = d["trajectory"]
    rng, mins = [], []
    for t in np.unique(traj):
        sel = traj == t
        ang = np.degrees(d["creases/angle"][sel].astype(np.float64))  # (frames, C)
        rng.append((ang.max(axis=0) - ang.min(axis=0)).max())
        mins.append(d["labels/deformation"][sel].min())
    return np.array(rng), np.array(mins, dtype=np.float64)


def test_report_numbers_equal_the_shards(folders, tmp_path):
    a, _ = folders
    out = tmp_path / "rep"
    r = _warpworm("report", str(a), "--out", str(out))
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "rep.json").read_text())
    assert rep["png"] == str(tmp_path / "rep.png")
    img = cv2.imread(str(tmp_path / "rep.png"))
    assert img is not None and img.shape[0] > 500 and img.shape[1] > 500
    (f,) = rep["folders"]
    d, n_shards = _read(a)
    assert n_shards == 2  # the trajectories are spread over two shards
    assert f["samples"] == 8 == len(d["trajectory"])
    assert f["trajectories"] == 4 == len(np.unique(d["trajectory"]))
    rng, mins = _expected(d)
    c = f["crease_range_within_trajectory_deg"]
    assert c["count"] == 4
    assert c["median"] == pytest.approx(np.median(rng), rel=1e-12)
    assert c["min"] == pytest.approx(rng.min(), rel=1e-12) and c["max"] == pytest.approx(rng.max(), rel=1e-12)
    assert rng.max() > 0  # the worm moved: a range of 0 everywhere would not test much
    assert f["min_deformation_per_trajectory"]["min"] == pytest.approx(mins.min(), rel=1e-12)
    assert f["fraction_trajectories_min_deformation_le_0.9"] == np.mean(mins <= 0.9)
    vf = d["labels/visib_fract"].astype(np.float64)
    assert f["visib_fract"]["mean"] == pytest.approx(vf.mean(), rel=1e-12)
    box = d["labels/bbox_obj"].astype(np.float64)
    assert f["bbox_size_px"]["max"] == pytest.approx(np.sqrt(box[:, 2] * box[:, 3]).max(), rel=1e-12)
    dist = np.linalg.norm(d["camera/position"] - d["poses/body"][:, :3, 3], axis=1)
    assert f["camera_distance_m"]["min"] == pytest.approx(dist.min(), rel=1e-12)
    # every parameter: min / mean / max (numbers), counts (text, booleans)
    names = [k[len("params/"):] for k in d if k.startswith("params/")]
    assert sorted(f["params"]) == sorted(names)
    for n in names:
        v, got = d[f"params/{n}"], f["params"][n]
        if v.dtype.kind == "f":
            assert (got["min"], got["max"]) == (v.min(), v.max()), n
            assert got["mean"] == pytest.approx(v.mean(), rel=1e-12), n
        else:
            t = [x.decode() if isinstance(x, bytes) else str(x) for x in v]
            assert got["counts"] == {k: t.count(k) for k in set(t)}, n
    # the varying / constant split is the data's
    for n in names:
        v = d[f"params/{n}"]
        assert (n in rep["params_varying"]) == (len(np.unique(v)) > 1), n


def test_fraction_of_contracted_trajectories(folders, tmp_path):
    """One frame of one trajectory set to a 0.85 deformation ratio, one of another to float32(0.9) (just below 0.9):
    2 of 4 trajectories have a minimum <= 0.9; the smallest per-trajectory minimum is the edited 0.85."""
    a, _ = folders
    c = tmp_path / "c"
    shutil.copytree(a, c)
    shards = sorted(c.glob("shard-*.h5"))
    with h5py.File(shards[0], "r+") as f:
        traj = f["trajectory"][...]
        deform = f["labels/deformation"][...]
        t0 = traj[0]
        deform[np.flatnonzero(traj == t0)[1], 2] = 0.85
        f["labels/deformation"][...] = deform
    with h5py.File(shards[1], "r+") as f:
        traj = f["trajectory"][...]
        deform = f["labels/deformation"][...]
        deform[np.flatnonzero(traj == traj[-1])[0], 0] = np.float32(0.9)
        f["labels/deformation"][...] = deform
    r = _warpworm("report", str(c), "--out", str(tmp_path / "c_report"))
    assert r.returncode == 0, r.stderr
    (f,) = json.loads((tmp_path / "c_report.json").read_text())["folders"]
    assert f["fraction_trajectories_min_deformation_le_0.9"] == 0.5
    assert f["min_deformation_per_trajectory"]["min"] == pytest.approx(0.85, abs=1e-7)


def test_two_folders_side_by_side(folders, tmp_path):
    a, b = folders
    r = _warpworm("report", str(a), str(b), "--out", str(tmp_path / "ab.png"))
    assert r.returncode == 0, r.stderr
    rep = json.loads((tmp_path / "ab.json").read_text())
    assert [f["dir"] for f in rep["folders"]] == [str(a), str(b)]
    assert rep["params_config_differs"] == ["worm.mu_static"]  # what the sweep changed
    assert rep["params_varying"][0] == "worm.mu_static"
    mb = rep["folders"][1]["params"]["worm.mu_static"]
    assert mb["config"] == {"uniform": [0.1, 0.2]} and 0.1 <= mb["min"] <= mb["max"] <= 0.2
    # shared bins span both folders' values
    for key, edges in rep["bins"].items():
        lo = min(f[key]["min"] for f in rep["folders"])
        hi = max(f[key]["max"] for f in rep["folders"])
        assert edges[0] <= lo and edges[-1] >= hi, key
    img = cv2.imread(str(tmp_path / "ab.png"))
    one = cv2.imread(str(a / "report.png")) if (a / "report.png").exists() else None
    # the folders share each panel (one colour each): the picture keeps one folder's layout, 4 panels across, and a
    # readable aspect (a column per folder and a row per quantity made it 720 x 9542 px)
    assert img is not None and img.shape[1] >= 4 * 250 and img.shape[0] <= 2.5 * img.shape[1]
    if one is not None:
        assert img.shape[1] == one.shape[1]


def test_without_matplotlib_writes_json_and_says_so(folders, tmp_path, monkeypatch, capsys):
    a, _ = folders
    monkeypatch.setitem(sys.modules, "matplotlib", None)  # `import matplotlib` raises ImportError
    from warpworm.cli import main

    assert main(["report", str(a), "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plots extra" in err[0], err
    rep = json.loads((tmp_path / "r.json").read_text())
    assert rep["png"] is None and not (tmp_path / "r.png").exists() and rep["folders"][0]["samples"] == 8


@pytest.mark.parametrize("bad", ["missing", "empty", "file"])
def test_bad_input_is_one_line_and_exit_2(tmp_path, bad):
    p = tmp_path / bad
    if bad == "empty":
        p.mkdir()
    elif bad == "file":
        p.write_text("x")
    r = _warpworm("report", str(p), "--out", str(tmp_path / "r"), timeout=60)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and str(p) in lines[0], r.stderr
    assert not (tmp_path / "r.json").exists()
