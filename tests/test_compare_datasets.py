"""benchmarks/compare_datasets.py: a copy is IDENTICAL; a planted change is found with its exact size and extent."""

import shutil
import sys
from pathlib import Path

import h5py
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from compare_datasets import compare_folders, main  # noqa: E402


def _shard(folder: Path) -> Path:
    folder.mkdir()
    rng = np.random.default_rng(0)
    with h5py.File(folder / "shard-00000.h5", "w") as f:
        f["rgb"] = rng.integers(0, 255, (2, 4, 4, 3), dtype=np.uint8)
        f["depth"] = rng.random((2, 4, 4)).astype(np.float32)
        f["params/worm.gait"] = np.array([b"omega", b"omega"])
        f.attrs["seed_master"] = 7
        f.attrs["created_unix"] = 1.0  # names the run: not compared
    return folder / "shard-00000.h5"


def test_copy_identical_and_planted_change_found(tmp_path, capsys):
    a = _shard(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    assert compare_folders(tmp_path / "a", tmp_path / "b")["identical"]
    with h5py.File(tmp_path / "b" / a.name, "r+") as f:
        rgb = f["rgb"][...]
        rgb[1, 2, 3, 0] ^= 0x10  # one channel of one pixel, by 16
        f["rgb"][...] = rgb
        f["depth"][0, 0, 0] += 0.25
        f.attrs["seed_master"] = 8
        f.attrs["created_unix"] = 2.0
    res = compare_folders(tmp_path / "a", tmp_path / "b")
    rows = {r["dataset"]: r for r in res["rows"]}
    assert not res["identical"] and res["problems"] == []
    assert rows["rgb"]["max_abs"] == 16 and rows["rgb"]["frac_differ"] == 1 / 32  # one pixel of 2 x 4 x 4
    assert abs(rows["depth"]["max_abs"] - 0.25) < 1e-6 and rows["depth"]["frac_differ"] == 1 / 32
    assert rows["params/worm.gait"]["identical"]
    assert [r["dataset"] for r in res["rows"] if r.get("note") == "attribute"] == ["/@seed_master"]
    assert main([str(tmp_path / "a"), str(tmp_path / "a")]) == 0 and "IDENTICAL" in capsys.readouterr().out


def test_missing_dataset_is_a_problem(tmp_path):
    _shard(tmp_path / "a")
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    with h5py.File(tmp_path / "b" / "shard-00000.h5", "r+") as f:
        del f["depth"]
    assert main([str(tmp_path / "a"), str(tmp_path / "b")]) == 2
