"""benchmarks/compare_datasets.py: a copy is IDENTICAL; a planted change is found with its exact size and extent."""

import json
import shutil
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from compare_datasets import compare_folders, main  # noqa: E402


def _dataset(folder: Path, splits=(2,)) -> Path:
    """A dataset folder of 2 samples (rgb, depth, a text parameter) in shards of ``splits`` samples, with its
    manifest; returns the first shard."""
    from warpworm.data.dataset import FORMAT, MANIFEST

    folder.mkdir()
    rng = np.random.default_rng(0)
    data = {"rgb": rng.integers(0, 255, (2, 4, 4, 3), dtype=np.uint8),
            "depth": rng.random((2, 4, 4)).astype(np.float32),
            "params/worm.gait": np.array([b"omega", b"omega"])}
    first, names = 0, []
    for k, n in enumerate(splits):
        names.append(f"shard-{k:05d}.h5")
        with h5py.File(folder / names[-1], "w") as f:
            for key, arr in data.items():
                f[key] = arr[first:first + n]
            f["depth"].attrs["unit"] = "m"
            f.attrs.update({"seed_master": 7, "count": n, "shard_index": k, "first_sample": first,
                            "warpworm_version": "1.0"})  # the code's version: not compared
        first += n
    (folder / MANIFEST).write_text(json.dumps({"format": FORMAT, "shards": names}))
    return folder / names[0]


def test_copy_identical_and_planted_change_found(tmp_path, capsys):
    a = _dataset(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    assert compare_folders(tmp_path / "a", tmp_path / "b")["identical"]
    with h5py.File(tmp_path / "b" / a.name, "r+") as f:
        rgb = f["rgb"][...]
        rgb[1, 2, 3, 0] ^= 0x10  # one channel of one pixel, by 16
        f["rgb"][...] = rgb
        f["depth"][0, 0, 0] += 0.25
        f.attrs["seed_master"] = 8
        f.attrs["warpworm_version"] = "2.0"
    res = compare_folders(tmp_path / "a", tmp_path / "b")
    rows = {r["dataset"]: r for r in res["rows"]}
    assert not res["identical"] and res["problems"] == []
    assert rows["rgb"]["max_abs"] == 16 and rows["rgb"]["frac_differ"] == 1 / 32  # one pixel of 2 x 4 x 4
    assert abs(rows["depth"]["max_abs"] - 0.25) < 1e-6 and rows["depth"]["frac_differ"] == 1 / 32
    assert rows["params/worm.gait"]["identical"]
    assert [r["dataset"] for r in res["rows"] if r.get("note") == "attribute"] == ["/@seed_master"]
    assert main([str(tmp_path / "a"), str(tmp_path / "a")]) == 0 and "IDENTICAL" in capsys.readouterr().out


def test_the_same_samples_in_other_shards_compare_identical(tmp_path):
    _dataset(tmp_path / "one", splits=(2,))
    _dataset(tmp_path / "two", splits=(1, 1))
    assert compare_folders(tmp_path / "one", tmp_path / "two")["identical"]


def test_missing_dataset_is_a_problem(tmp_path):
    _dataset(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    with h5py.File(tmp_path / "b" / "shard-00000.h5", "r+") as f:
        del f["depth"]
    assert main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2
