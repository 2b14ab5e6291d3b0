"""Compare two dataset folders written by ``warpworm generate``, dataset by dataset: identical, or how far apart.

Usage::

    python3 benchmarks/compare_datasets.py A B [--json OUT.json]

For every HDF5 dataset, over every sample in order (the project's ``DatasetReader``: the shards' layout does not
matter), it reports whether the two are byte-identical and, where not, the largest absolute difference and the
fraction of elements that differ (for images: of pixels). The attributes are compared too, except the versions of
the code that wrote them and each shard's place. Prints ``IDENTICAL`` when everything matches, else a list of what
differs; exits 0 either way (a report, not a test) and 2 when the folders do not hold the same samples or
datasets. Used to check that the default dataset is byte-identical after a change, and how far a CUDA run lies from
the CPU's on the same seed (``benchmarks/gpu_check.sh``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

from warpworm.data.dataset import DatasetReader

RUN_ATTRS = ("warp_version", "warpworm_version")
"""Root attributes that name the code that wrote a dataset, not its data: skipped (a comparison across a change)."""
SHARD_ATTRS = ("shard_index", "first_sample", "count", "shard_size")
"""Root attributes that describe one shard's place: the comparison is of samples, whatever the sharding."""


def _attrs(reader) -> dict[str, object]:
    """The root attributes (``/@name``) and each dataset's (``dataset@name``) of the reader's first shard, less
    RUN_ATTRS and SHARD_ATTRS."""
    out = {f"/@{k}": v for k, v in reader.attrs.items() if k not in RUN_ATTRS + SHARD_ATTRS}
    with h5py.File(reader.shard_paths[0], "r") as f:
        for key in reader.keys():
            out.update({f"{key}@{k}": v for k, v in f[key].attrs.items()})
    return out


def compare_arrays(a: np.ndarray, b: np.ndarray) -> dict:
    """identical / max_abs / frac_differ of two arrays of one dataset (shape and dtype must match)."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return {"identical": False, "note": f"shape/dtype {a.shape} {a.dtype} vs {b.shape} {b.dtype}"}
    if a.tobytes() == b.tobytes():
        return {"identical": True}
    if a.dtype.kind not in "fiub":
        return {"identical": False, "frac_differ": float(np.mean(a != b))}
    x, y = a.astype(np.float64), b.astype(np.float64)
    diff = (x != y) & ~(np.isnan(x) & np.isnan(y))
    per = diff.any(axis=-1) if (a.ndim == 4 and a.shape[-1] in (3, 4)) else diff  # images: a pixel, any channel
    finite = np.isfinite(x) & np.isfinite(y)
    return {"identical": False, "max_abs": float(np.abs(x - y)[finite].max(initial=0.0)),
            "frac_differ": float(per.mean())}


def compare_folders(a: Path, b: Path) -> dict:
    """{"identical": bool, "rows": [...], "problems": [...]}: every dataset over every sample, read through
    :class:`warpworm.data.dataset.DatasetReader` (so two folders of the same samples in other shards compare equal),
    and the attributes."""
    ra, rb = DatasetReader(a), DatasetReader(b)
    problems, rows = [], []
    if len(ra) != len(rb):
        problems.append(f"samples differ: {len(ra)} vs {len(rb)}")
    ka, kb = set(ra.keys()), set(rb.keys())
    if ka != kb:
        problems.append(f"datasets only in one: {sorted(ka ^ kb)}")
    if not problems:
        rows = [{"dataset": key, **compare_arrays(ra.read(key), rb.read(key))} for key in sorted(ka)]
    aa, ab = _attrs(ra), _attrs(rb)
    rows += [{"dataset": key, "identical": False, "note": "attribute"} for key in sorted(set(aa) | set(ab))
             if not np.array_equal(np.asarray(aa.get(key)), np.asarray(ab.get(key)))]
    identical = not problems and all(r["identical"] for r in rows)
    return {"identical": identical, "rows": rows, "problems": problems}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("a", type=Path)
    ap.add_argument("b", type=Path)
    ap.add_argument("--json", type=Path, help="write the whole comparison here")
    args = ap.parse_args(argv)
    res = compare_folders(args.a, args.b)
    if args.json:
        args.json.write_text(json.dumps(res, indent=1, default=str))
    for p in res["problems"]:
        print("PROBLEM:", p)
    if res["identical"]:
        print("IDENTICAL")
    else:
        differ = [r for r in res["rows"] if not r["identical"]]
        same = len(res["rows"]) - len(differ)
        print(f"{same} of {len(res['rows'])} datasets identical; differing:")
        for r in differ:
            extra = " ".join(f"{k}={v:.4g}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()
                             if k not in ("dataset", "identical"))
            print(f"  {r['dataset']}: {extra}")
    return 2 if res["problems"] else 0


if __name__ == "__main__":
    sys.exit(main())
