"""The shard writer: one HDF5 shard streamed in batches under a temporary name, then committed (flush, fsync,
checksum, rename). Images are chunked one sample per chunk and compressed; small labels are buffered and written
contiguous at commit."""

from __future__ import annotations

import os
from pathlib import Path

import h5py
import numpy as np

from warpworm.data import signal_hold
from warpworm.data.dataset.files import DatasetWriteError, FailSafeFile, file_sha256, fsync_dir, write_error
from warpworm.data.dataset.folder import shard_name
from warpworm.data.dataset.schema import IMAGE_KEYS, SCHEMA


def _filters(name: str, compression: str, level: int) -> dict:
    if name not in IMAGE_KEYS or compression == "none":
        return {}
    f = {"compression": compression}
    if compression == "gzip":
        f["compression_opts"] = int(level)
    if name == "depth":
        f["shuffle"] = True  # float32: shuffle groups exponent bytes, which compress well
    return f


class ShardWriter:
    """Writes one shard: rows [0, count) of sample ids [first_id, first_id + count), streamed in batches.

    Args:
        out_dir: dataset folder.
        index: shard index k.
        first_id, count: sample ids of the shard.
        root_attrs: attributes for the file root (resolved config YAML, versions, units, names, ...).
        compression, level: image filter ('lzf' | 'gzip' | 'none').
    """

    @signal_hold.holds_signals  # h5py calls back into Python here (warpworm.data.signal_hold)
    def __init__(self, out_dir, index: int, first_id: int, count: int, root_attrs: dict,
                 compression: str = "lzf", level: int = 1):
        self.dir = Path(out_dir)
        self.index, self.first_id, self.count = index, first_id, count
        self.final = self.dir / shard_name(index)
        self.tmp = self.dir / f".{shard_name(index)}.tmp-{os.getpid()}"
        self.compression, self.level = compression, level
        self.rows_written = np.zeros(count, dtype=bool)
        self._datasets: dict = {}
        self._buffers: dict[str, np.ndarray] = {}
        self._io = None
        self.sha256 = ""
        try:
            self._io = FailSafeFile(self.tmp)
            self.f = h5py.File(self._io, "w", libver="latest")
            for k, v in root_attrs.items():
                self.f.attrs[k] = v
            self.f.attrs["shard_index"] = index
            self.f.attrs["first_sample"] = first_id
            self.f.attrs["count"] = count
            self.f.attrs["complete"] = False
        except OSError as exc:
            err = (self._io.error if self._io is not None else None) or exc
            self._cleanup()
            raise write_error(err, self.tmp, "creating shard") from exc
        self._check_io("creating shard")

    def _check_io(self, doing: str) -> None:
        """Raise the first write error the file saw (the temporary is deleted first)."""
        err = self._io.error if self._io is not None else None
        if err is not None:
            self.abort()
            raise write_error(err, self.tmp, doing) from err

    def _create(self, name: str, arr: np.ndarray):
        shape = (self.count,) + arr.shape[1:]
        filt = _filters(name, self.compression, self.level)
        kw = {}
        if filt:
            kw = dict(chunks=(1,) + arr.shape[1:], **filt)
        ds = self.f.create_dataset(name, shape=shape, dtype=arr.dtype, **kw)
        meta = SCHEMA.get(name)
        if meta is not None:
            ds.attrs["unit"], ds.attrs["description"] = meta[1], meta[2]
        elif name.startswith("params/"):
            ds.attrs["description"] = f"randomized value of {name[7:]} per sample"
        return ds

    @signal_hold.holds_signals  # h5py calls back into Python here (warpworm.data.signal_hold)
    def write(self, row: int, batch: dict[str, np.ndarray], step: int = 1) -> None:
        """Write ``batch`` (name -> (n, ...) arrays) to rows row, row + step, ..., row + (n-1)*step.

        Images go to the file at once (one strided hyperslab per dataset: frames of a batch of trajectories land
        every F rows). Small labels (a few hundred bytes a sample) are buffered and written once at commit, because
        ~80 tiny h5py writes per batch cost more than the data.
        """
        n = None
        sl = None
        try:
            for name, arr in batch.items():
                arr = np.asarray(arr)
                if arr.dtype == object:
                    arr = arr.astype("S")
                n = arr.shape[0]
                sl = slice(row, row + step * (n - 1) + 1, step)
                if name in IMAGE_KEYS:
                    dset = self._datasets.get(name)
                    if dset is None:
                        dset = self._datasets[name] = self._create(name, arr)
                    dset[sl] = arr
                else:
                    buf = self._buffers.get(name)
                    if buf is None:
                        buf = self._buffers[name] = np.zeros((self.count,) + arr.shape[1:], arr.dtype)
                    elif arr.dtype.kind == "S" and arr.dtype.itemsize > buf.dtype.itemsize:
                        # other callers' text; the pipeline passes text at its schema width (shard.text_column)
                        buf = self._buffers[name] = buf.astype(arr.dtype)
                    buf[sl] = arr
        except OSError as exc:
            err = (self._io.error if self._io is not None else None) or exc
            self.abort()
            raise write_error(err, self.tmp, "writing shard") from exc
        self._check_io("writing shard")
        if sl is not None:
            self.rows_written[sl] = True

    @signal_hold.holds_signals  # h5py calls back into Python here (warpworm.data.signal_hold)
    def commit(self) -> Path:
        """Mark complete, flush, fsync, rename to the final name; returns the final path."""
        if not self.rows_written.all():
            missing = np.flatnonzero(~self.rows_written)
            self.abort()
            raise RuntimeError(f"shard {self.index}: rows {missing[:5]}... were never written")
        try:
            for name, buf in self._buffers.items():
                self._create(name, buf)[...] = buf
            self.f.attrs["complete"] = True
            self.f.flush()
            self.f.close()
            self.f = None
            self._check_io("finishing shard")
            os.fsync(self._io.raw.fileno())
            self._io.close()
            self._io = None
            self.sha256 = file_sha256(self.tmp)
            os.replace(self.tmp, self.final)
            fsync_dir(self.dir)
        except OSError as exc:
            if isinstance(exc, DatasetWriteError):
                raise
            err = (self._io.error if self._io is not None else None) or exc
            self.abort()
            raise write_error(err, self.tmp, "finishing shard") from exc
        return self.final

    @signal_hold.holds_signals  # h5py calls back into Python here (warpworm.data.signal_hold)
    def _cleanup(self):
        try:
            if getattr(self, "f", None) is not None:
                self.f.close()
        except Exception:  # noqa: BLE001 - best effort on an already failing file
            pass
        self.f = None
        try:
            if getattr(self, "_io", None) is not None:
                self._io.close()
        except Exception:  # noqa: BLE001
            pass
        self._io = None
        try:
            self.tmp.unlink()
        except OSError:
            pass

    def abort(self):
        """Close and delete the temporary file (nothing final is touched)."""
        self._cleanup()
