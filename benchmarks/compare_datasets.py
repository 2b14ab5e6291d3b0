"""Compare two dataset folders written by ``warpworm generate``, dataset by dataset: identical, or how far apart.

Usage::

    python3 benchmarks/compare_datasets.py A B [--json OUT.json]

For every HDF5 dataset of every shard (paired by file name) it reports whether the two are byte-identical and, where
not, the largest absolute difference and the fraction of elements that differ (for images: of pixels). The shards'
attributes are compared too, except the ones that name the run (timings, host, device). Prints ``IDENTICAL`` when
everything matches, else a table of what differs; exits 0 either way (a report, not a test) and 2 when the folders
do not hold the same shards or the same datasets. Used to check that the default dataset is byte-identical after a
change, and how far a CUDA run lies from the CPU's on the same seed (``benchmarks/gpu_check.sh``).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

RUN_ATTRS = ("created", "wall", "time", "host", "device", "seconds", "version")
"""Attribute name fragments that describe the run rather than the data: skipped."""


def _datasets(f: h5py.File) -> dict[str, h5py.Dataset]:
    out = {}
    f.visititems(lambda name, obj: out.__setitem__(name, obj) if isinstance(obj, h5py.Dataset) else None)
    return out


def _attrs(f: h5py.File) -> dict[str, object]:
    out = {}

    def visit(name, obj):
        for k, v in obj.attrs.items():
            if not any(s in k.lower() for s in RUN_ATTRS):
                out[f"{name}@{k}"] = v

    visit("/", f)
    f.visititems(visit)
    return out


def compare_arrays(a: np.ndarray, b: np.ndarray) -> dict:
    """identical / max_abs / frac_differ of two arrays of one dataset (shape and dtype must match)."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return {"identical": False, "note": f"shape/dtype {a.shape} {a.dtype} vs {b.shape} {b.dtype}"}
    if a.tobytes() == b.tobytes():
        return {"identical": True}
    if a.dtype.kind in "fiub":
        x, y = a.astype(np.float64), b.astype(np.float64)
        diff = x != y
        if a.dtype.kind == "f":
            diff &= ~(np.isnan(x) & np.isnan(y))
        # images (N, H, W[, C]): a pixel differs if any of its channels does
        per = diff.any(axis=-1) if (a.ndim == 4 and a.shape[-1] in (3, 4)) else diff
        finite = np.isfinite(x) & np.isfinite(y)
        return {"identical": False, "max_abs": float(np.abs(x - y)[finite].max(initial=0.0)),
                "frac_differ": float(per.mean())}
    return {"identical": False, "frac_differ": float(np.mean(a != b))}


def compare_folders(a: Path, b: Path) -> dict:
    """{"identical": bool, "rows": [...], "problems": [...]} over the shards both folders hold."""
    shards_a = sorted(p.name for p in a.glob("*.h5"))
    shards_b = sorted(p.name for p in b.glob("*.h5"))
    problems, rows = [], []
    if shards_a != shards_b:
        problems.append(f"shards differ: {shards_a} vs {shards_b}")
    for name in sorted(set(shards_a) & set(shards_b)):
        with h5py.File(a / name, "r") as fa, h5py.File(b / name, "r") as fb:
            da, db = _datasets(fa), _datasets(fb)
            if set(da) != set(db):
                problems.append(f"{name}: datasets only in one: {sorted(set(da) ^ set(db))}")
            for key in sorted(set(da) & set(db)):
                rows.append({"shard": name, "dataset": key, **compare_arrays(da[key][()], db[key][()])})
            aa, ab = _attrs(fa), _attrs(fb)
            for key in sorted(set(aa) | set(ab)):
                va, vb = aa.get(key), ab.get(key)
                if not np.array_equal(np.asarray(va), np.asarray(vb)):
                    rows.append({"shard": name, "dataset": key, "identical": False, "note": "attribute"})
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
                             if k not in ("shard", "dataset", "identical"))
            print(f"  {r['shard']} {r['dataset']}: {extra}")
    return 2 if res["problems"] else 0


if __name__ == "__main__":
    sys.exit(main())
