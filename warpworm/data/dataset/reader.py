"""Reading a dataset folder: random access to every sample over the shards (:class:`DatasetReader`, :func:`open`) and a
PyTorch-style map dataset over it (:class:`WormDataset`; torch is not required)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import h5py
import numpy as np
import yaml

from warpworm.data.dataset.files import DatasetError
from warpworm.data.dataset.folder import SHARD_RE, read_manifest


class DatasetReader:
    """Random access to every sample of a sharded dataset folder.

    ``len(ds)`` samples; ``ds[i]`` -> dict name -> per-sample array; ``ds.read(name, indices)`` -> stacked arrays.
    Files are opened lazily per process, so a reader can be passed to DataLoader workers (fork or spawn).
    Only shards present on disk are listed (a job still running or killed shows what is complete): then ``i`` counts
    the samples on disk in shard order and may differ from ``ds[i]["sample_id"]``; in a finished dataset (the
    manifest's ``complete``) the two are equal.
    """

    def __init__(self, root):
        self.root = Path(root)
        self.manifest = read_manifest(self.root)
        shards = []
        for name in sorted(os.listdir(self.root)):
            m = SHARD_RE.match(name)
            if m:
                shards.append((int(m.group(1)), self.root / name))
        self.shard_paths = [p for _, p in shards]
        counts = []
        for p in self.shard_paths:
            try:
                with h5py.File(p, "r") as f:
                    counts.append(int(f.attrs["count"]))
            except (OSError, KeyError) as exc:
                raise DatasetError(f"{p}: unreadable shard ({type(exc).__name__}: {str(exc)[:160]}); run "
                                   f"`warpworm verify {self.root}`, then the job's command with --resume to redo "
                                   "it") from exc
        self.counts = np.asarray(counts, dtype=np.int64)
        self.offsets = np.concatenate([[0], np.cumsum(self.counts)])
        self._files: dict[int, h5py.File] = {}
        self._pid = os.getpid()

    def __len__(self) -> int:
        return int(self.offsets[-1])

    def __getstate__(self):
        d = dict(self.__dict__)
        d["_files"] = {}
        return d

    def _file(self, k: int) -> h5py.File:
        if self._pid != os.getpid():  # forked: h5py handles must not be shared across processes
            self._files, self._pid = {}, os.getpid()
        f = self._files.get(k)
        if f is None:
            f = self._files[k] = h5py.File(self.shard_paths[k], "r")
        return f

    def _locate(self, i: int) -> tuple[int, int]:
        n = len(self)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError(f"sample {i} out of range [0, {n})")
        k = int(np.searchsorted(self.offsets, i, side="right") - 1)
        return k, i - int(self.offsets[k])

    @property
    def attrs(self) -> dict:
        """Root attributes of the first shard (the same in every shard except shard_index/first_sample/count)."""
        f = self._file(0)
        return {k: (v.decode() if isinstance(v, bytes) else v) for k, v in f.attrs.items()}

    @property
    def config(self) -> dict:
        """The config the dataset was written with (root attribute ``config_yaml``) as a dict ({} where empty)."""
        return yaml.safe_load(self.attrs["config_yaml"]) or {}

    def keys(self) -> list[str]:
        out = []
        self._file(0).visititems(lambda name, obj: out.append(name) if isinstance(obj, h5py.Dataset) else None)
        return out

    def __getitem__(self, i: int) -> dict[str, np.ndarray]:
        k, r = self._locate(int(i))
        f = self._file(k)
        return {name: f[name][r] for name in self.keys()}

    def read(self, name: str, indices: Iterable[int] | slice | None = None) -> np.ndarray:
        """Stack ``name`` over sample indices (default: all), reading each shard once."""
        if indices is None:
            indices = np.arange(len(self))
        elif isinstance(indices, slice):
            indices = np.arange(len(self))[indices]
        idx = np.asarray(indices, dtype=np.int64)
        idx = np.where(idx < 0, idx + len(self), idx)
        if idx.size and (idx.min() < 0 or idx.max() >= len(self)):
            raise IndexError(f"indices out of range [0, {len(self)})")
        shard = np.searchsorted(self.offsets, idx, side="right") - 1
        first = None
        out = None
        for k in np.unique(shard):
            sel = np.flatnonzero(shard == k)
            rows = idx[sel] - self.offsets[k]
            order = np.argsort(rows)
            data = self._file(int(k))[name][np.sort(rows)]  # h5py needs increasing unique rows
            if first is None:
                out = np.empty((idx.size,) + data.shape[1:], dtype=data.dtype)
                first = True
            elif data.dtype != out.dtype:  # text written before its width was fixed: widen, never truncate
                out = out.astype(np.result_type(out.dtype, data.dtype))
            out[sel[order]] = data
        if out is None:
            ds = self._file(0)[name]
            out = np.empty((0,) + ds.shape[1:], dtype=ds.dtype)
        return out

    def close(self):
        for f in self._files.values():
            try:
                f.close()
            except Exception:  # noqa: BLE001
                pass
        self._files = {}

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def open(root) -> DatasetReader:  # noqa: A001 - mirrors h5py.File / zarr.open
    """Open a dataset folder for random access: ``ds = warpworm.data.dataset.open(DIR); ds[i]["rgb"]``."""
    return DatasetReader(root)


@dataclass
class WormDataset:
    """A PyTorch-style map dataset over a folder (``__len__``, ``__getitem__``); torch is not required.

    Args:
        root: dataset folder.
        keys: datasets to return (default: every one).
        transform: optional callable applied to each sample dict.
    Pass it to ``torch.utils.data.DataLoader`` as is; NumPy arrays are converted by the default collate.
    """

    root: str
    keys: tuple[str, ...] | None = None
    transform: Any = None

    def __post_init__(self):
        self._reader = DatasetReader(self.root)
        self._keys = list(self.keys) if self.keys is not None else self._reader.keys()

    def __len__(self) -> int:
        return len(self._reader)

    def __getitem__(self, i: int) -> dict[str, np.ndarray]:
        k, r = self._reader._locate(int(i))
        f = self._reader._file(k)
        sample = {name: f[name][r] for name in self._keys}
        return self.transform(sample) if self.transform is not None else sample
