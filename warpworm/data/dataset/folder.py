"""A dataset folder's layout: shard names, the manifest, what a complete shard is, the temporaries a killed job
leaves."""

from __future__ import annotations

import glob
import json
import os
import re
from pathlib import Path

import h5py
import numpy as np

from warpworm.data.dataset.files import DatasetError, file_sha256
from warpworm.data.dataset.schema import (FORMAT, QUATERNION_ORDER, SCHEMA_VERSION, SEGMENTATION_IDS, UNITS,
                                          versions)

MANIFEST = "manifest.json"
SHARD_RE = re.compile(r"^shard-(\d{5})\.h5$")


def shard_name(k: int) -> str:
    return f"shard-{k:05d}.h5"


def clean_temporaries(out_dir, pattern: str = ".*.tmp-*") -> list[str]:
    """Delete temporary files a killed job left (default every ``.shard-*.tmp-*`` and ``.manifest.json.tmp-*``; or
    those matching ``pattern``, a glob in ``out_dir``); returns their names."""
    removed = []
    for p in glob.glob(os.path.join(str(out_dir), pattern)):
        try:
            os.unlink(p)
            removed.append(os.path.basename(p))
        except OSError:
            pass
    return removed


def shard_problem(path, expected_first: int, expected_count: int, sha256: str | None = None) -> str | None:
    """Why shard ``path`` is not a complete shard of ids [first, first + count) (with the manifest's ``sha256``:
    also byte-identical to what was written), or None."""
    if sha256:
        try:
            got = file_sha256(path)
        except OSError as exc:
            return f"unreadable ({exc.strerror})"
        if got != sha256:
            return f"checksum mismatch (manifest sha256 {sha256[:12]}..., file {got[:12]}...): changed after it was written"
    try:
        with h5py.File(path, "r") as f:
            if not bool(f.attrs.get("complete", False)):
                return "not marked complete"
            if int(f.attrs["first_sample"]) != expected_first or int(f.attrs["count"]) != expected_count:
                return (f"holds samples [{int(f.attrs['first_sample'])}, +{int(f.attrs['count'])}); expected "
                        f"[{expected_first}, +{expected_count})")
            ids = f["sample_id"][...]
            if ids.shape != (expected_count,) or not np.array_equal(
                    ids, np.arange(expected_first, expected_first + expected_count)):
                return "sample_id is not the expected range"
    except (OSError, KeyError, ValueError) as exc:
        return f"unreadable as HDF5 (truncated or damaged: {type(exc).__name__}: {str(exc)[:120]})"
    return None


def manifest(cfg, done: dict[int, dict], complete: bool, summary: dict | None = None,
             shard_size_requested: int | None = None) -> dict:
    """The manifest of a dataset job: its config ``cfg`` (a :class:`~warpworm.data.config.DatasetConfig`), the shards
    on disk ``done`` {k: {bytes, sha256, replaced}}, whether every shard is there, the job's summary (None while it
    runs) and the shard size asked for (when the job split it for its workers)."""
    shards = []
    for k in sorted(done):
        s = done[k]
        a, b = cfg.shard_range(k)
        shards.append({"index": k, "file": shard_name(k), "first_sample": a, "count": b - a,
                       "bytes": s.get("bytes", 0), "sha256": s.get("sha256", ""), "replaced": s.get("replaced", 0)})
    return {
        "format": FORMAT, "schema_version": SCHEMA_VERSION, "complete": complete,
        "num_samples": cfg.num_samples, "shard_size": cfg.shard_size, "num_shards": cfg.num_shards,
        "shard_size_requested": cfg.shard_size if shard_size_requested is None else shard_size_requested,
        "samples_written": int(sum(s["count"] for s in shards)), "shards": shards,
        "config": cfg.to_dict(), "versions": versions(), "quaternion_order": QUATERNION_ORDER,
        "units": UNITS, "segmentation_ids": SEGMENTATION_IDS, "summary": summary,
    }


def read_manifest(root) -> dict:
    """The manifest of dataset folder ``root``; :class:`DatasetError` naming the file and the fix if it is missing
    or damaged."""
    mpath = Path(root) / MANIFEST
    if not mpath.is_file():
        raise DatasetError(f"{mpath}: missing, so {root} is not a (finished) warpworm dataset folder; if a job wrote "
                           "shards there, rerun it with --resume to rebuild the manifest from the shards")
    try:
        m = json.loads(mpath.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise DatasetError(f"{mpath}: unreadable ({type(exc).__name__}: {exc}); rerun the job that wrote it with "
                           "--resume to rebuild it from the shards") from exc
    if not isinstance(m, dict) or m.get("format") != FORMAT or not isinstance(m.get("shards"), list):
        raise DatasetError(f"{mpath}: not a warpworm manifest (expected a JSON object with format "
                           f"{FORMAT!r} and a shards list); rerun the job with --resume to rebuild it")
    return m
