"""Text parameters (``params/worm.gait``, ``params/texture.*``, ``params/plate.material``, ...) are fixed-width bytes
whose width is the longest value the schema allows, so one seed gives the same dtypes, not only the same values, in
every shard whatever the shard size. Against the deterministic fake stages (tests/test_dataset_fakes.py)."""

import glob

import h5py
import numpy as np

from test_dataset_pipeline import everything, run, tiny

# the schema's text values, written out here (docs/dataset.md), not read from the code under test
LONGEST = {"worm.gait": "peristaltic", "worm.magnet_model": "analytic", "texture.floor": "checker",
           "texture.worm": "fibre", "plate.material": "acrylic"}


def _text_config(shard_size):
    return tiny(shard_size=shard_size, render={"plate_materials": ["matte", "glossy", "acrylic"]},
                randomize={"worm": {"hinge_stiffness": {"uniform": [0.5, 1.0]},
                                    "gait": {"choice": ["omega", "inchworm", "peristaltic"]}},
                           "texture": {"floor": {"choice": ["plain", "checker", "noise"]},
                                       "worm": {"choice": ["plain", "fibre", "bands"]}}})


def _per_shard(root):
    """name -> [(dtype, values)] of every shard, in shard order."""
    out = {}
    for path in sorted(glob.glob(f"{root}/shard-*.h5")):
        with h5py.File(path) as f:
            f.visititems(lambda n, o: out.setdefault(n, []).append((o.dtype, o[()]))
                         if isinstance(o, h5py.Dataset) else None)
    return out


def test_text_dtypes_do_not_depend_on_the_shard_size(tmp_path):
    run(_text_config(2), tmp_path / "s2")  # a shard per trajectory (F = 2): few distinct values per shard
    run(_text_config(22), tmp_path / "s22")
    a, b = _per_shard(tmp_path / "s2"), _per_shard(tmp_path / "s22")
    assert set(a) == set(b) and len(a["rgb"]) == 11 and len(b["rgb"]) == 1
    for name in a:
        assert {dt for dt, _ in a[name]} == {b[name][0][0]}, name  # every dataset: one dtype, the same in both
        assert np.array_equal(np.concatenate([v for _, v in a[name]]), b[name][0][1],
                              equal_nan=b[name][0][0].kind == "f"), name
    for key, longest in LONGEST.items():
        assert b[f"params/{key}"][0][0] == np.dtype(f"S{len(longest)}"), key
    # the small shards did hold only shorter values somewhere (what used to narrow their dtype)
    floor = [v for _, v in a["params/texture.floor"]]
    assert min(max(len(x) for x in v) for v in floor) < len("checker")
    assert {x.decode() for v in floor for x in v} == {"plain", "checker", "noise"}


def test_reader_widens_text_of_older_datasets(tmp_path, monkeypatch):
    """Datasets written before the fix hold shard-dependent widths: reading across shards must not truncate."""
    from warpworm.data import shard

    run(_text_config(22), tmp_path / "new")
    monkeypatch.setattr(shard, "text_column", lambda name, v: np.asarray(v, dtype=object))  # the old writer
    run(_text_config(2), tmp_path / "old")
    widths = {dt.itemsize for dt, _ in _per_shard(tmp_path / "old")["params/texture.floor"]}
    assert len(widths) > 1  # really shard-dependent
    new, _ = everything(tmp_path / "new")
    old, _ = everything(tmp_path / "old")
    for key in LONGEST:
        assert np.array_equal(old[f"params/{key}"], new[f"params/{key}"]), key
