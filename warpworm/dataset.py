"""Sharded HDF5 datasets: a crash-safe writer, an atomic manifest, and readers (random access, PyTorch-style).

Layout of a dataset folder::

    DIR/manifest.json          # written atomically; shards, counts, config, versions, summary
    DIR/shard-00000.h5         # sample ids [0, S)
    DIR/shard-00001.h5         # sample ids [S, 2S) ... shard k always holds [k*S, min((k+1)*S, N))
    DIR/preview.png, preview.mp4

Crash safety: a shard is written under a temporary name (``.shard-00001.h5.tmp-<pid>``), flushed, fsynced, then
renamed to its final name, and the folder fsynced. A final-named shard is therefore always complete; a killed job leaves
at most temporary files, which ``--resume`` deletes before redoing the missing shards. Because shard k's content depends
only on (config, k), a resumed job gives the same bytes of data as an uninterrupted one.

Storage (chosen by ``benchmarks/bench_dataset.py``; see docs/dataset.md): images (rgb, depth, segmentation, worm mask)
are chunked one sample per chunk and compressed with the config's filter (default gzip level 1, with byte shuffle for
depth); small per-sample labels are buffered per shard and stored contiguous and uncompressed (a few hundred bytes a
sample; chunking them costs more than it saves). Rows are always written as contiguous ranges.
"""

from __future__ import annotations

import builtins
import glob
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import h5py
import numpy as np

SCHEMA_VERSION = 1
MANIFEST = "manifest.json"
SHARD_RE = re.compile(r"^shard-(\d{5})\.h5$")
QUATERNION_ORDER = "wxyz"

SEGMENTATION_IDS = {
    "background": 0, "floor": 1, "worm_segment_0": 2, "worm_segment_1": 3, "worm_segment_2": 4, "worm_segment_3": 5,
    "worm_segment_4": 6, "ipm_tail": 7, "ipm_centre": 8, "ipm_head": 9, "epm": 10,
}
"""Segmentation ids (docs/architecture.md): worm segments 0..4 run tail -> head."""

UNITS = {"length": "m", "depth": "m (camera z; 0 = background)", "angle": "rad", "time": "s", "pixel": "px",
         "mass": "kg", "moment": "A*m^2", "frames": "OpenCV camera (+z forward, +y down), x_cam = R x_world + t; "
         "poses are object -> world 4x4"}

# name -> (dtype, unit, description). Shapes are per sample; the file's arrays have a leading N (samples in the shard).
SCHEMA: dict[str, tuple[str, str, str]] = {
    "rgb": ("uint8", "", "(H, W, 3) colour image, sRGB, after sensor effects"),
    "depth": ("float32", "m", "(H, W) camera-frame z of the first surface; 0 = background"),
    "segmentation": ("uint8", "", "(H, W) ids, see root attribute segmentation_ids"),
    "camera/K": ("float64", "px", "(3, 3) intrinsics, row-major, fx, fy > 0"),
    "camera/R": ("float64", "", "(3, 3) world -> camera rotation (x_cam = R x_world + t)"),
    "camera/t": ("float64", "m", "(3,) world -> camera translation"),
    "camera/position": ("float64", "m", "(3,) camera centre in world"),
    "camera/in_frame": ("float32", "", "() fraction of the worm's vertices (every frame the camera shows) inside the "
                        "image; below camera.min_in_frame only if no view in camera.max_tries draws reached it"),
    "poses/body": ("float64", "m", "(4, 4) worm body frame -> world"),
    "poses/ipm": ("float64", "m", "(3, 4, 4) IPM (tail, centre, head) -> world"),
    "poses/epm": ("float64", "m", "(4, 4) EPM -> world"),
    "poses/body_quat": ("float64", "", "(4,) body rotation as a quaternion (w, x, y, z)"),
    "keypoints/world": ("float64", "m", "(P, 3) keypoints in world, names in root attribute keypoint_names"),
    "keypoints/camera": ("float64", "m", "(P, 3) keypoints in the camera frame"),
    "keypoints/pixel": ("float64", "px", "(P, 2) projection (u, v); pixel centres at integer (u, v) as in OpenCV"),
    "keypoints/visibility": ("uint8", "", "(P,) COCO: 0 outside the image, 1 occluded, 2 visible"),
    "creases/angle": ("float32", "rad", "(C,) signed dihedral of every crease, crease-pattern hinge order"),
    "bars/strain": ("float32", "", "(E,) Cauchy strain dL/L0 of every bar, crease-pattern edge order"),
    "worm/vertices": ("float32", "m", "(V, 3) worm mesh vertex positions in world"),
    "labels/bbox_obj": ("float32", "px", "(4,) worm box (x, y, w, h) of the projected mesh, occlusion ignored"),
    "labels/bbox_visib": ("float32", "px", "(4,) worm box (x, y, w, h) of its visible pixels; 0 if none"),
    "labels/visib_fract": ("float32", "", "() visible worm pixels / pixels of the worm rendered alone (estimate)"),
    "labels/worm_mask": ("uint8", "", "(H, W) 1 where the worm's sheet projects, occluders ignored (BOP 'mask')"),
    "labels/deformation": ("float32", "", "(4,) distances between adjacent segment centres over their rest values"),
    "time": ("float32", "s", "() simulated time of the frame after settling"),
    "trajectory": ("int64", "", "() trajectory (simulated world) id; its frames are consecutive samples"),
    "frame": ("int32", "", "() frame index within the trajectory (sim.frame_times)"),
    "attempt": ("int32", "", "() replacement attempt that gave a stable world (0: first draw)"),
    "sample_id": ("int64", "", "() global sample id, == row in the whole dataset"),
    "seed": ("int64", "", "() per-sample 63-bit seed derived from (master seed, sample id) for pixel noise"),
}
"""Datasets every shard holds (``params/<group>.<name>`` come in addition, one per randomized parameter)."""

IMAGE_KEYS = ("rgb", "depth", "segmentation", "labels/worm_mask")


class DatasetWriteError(OSError):
    """Writing a shard failed (disk full, read-only folder, ...). Completed shards are intact; rerun with --resume."""


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_json(path: str | os.PathLike, obj: Any) -> None:
    """Write JSON via temp file + fsync + rename, so readers see the old or the new file, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    data = json.dumps(obj, indent=1, sort_keys=False, default=_json_default)
    try:
        with builtins.open(tmp, "w") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        _fsync_dir(path.parent)
    except OSError as exc:
        try:
            tmp.unlink()
        except OSError:
            pass
        raise DatasetWriteError(exc.errno, f"could not write {path}: {exc.strerror}") from exc


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(type(o))


def shard_name(k: int) -> str:
    return f"shard-{k:05d}.h5"


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
        try:
            self.f = h5py.File(self.tmp, "w", libver="latest")
            for k, v in root_attrs.items():
                self.f.attrs[k] = v
            self.f.attrs["shard_index"] = index
            self.f.attrs["first_sample"] = first_id
            self.f.attrs["count"] = count
            self.f.attrs["complete"] = False
        except OSError as exc:
            self._cleanup()
            raise DatasetWriteError(exc.errno or 0, f"cannot create shard {self.tmp}: {exc}") from exc

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
                        buf = self._buffers[name] = buf.astype(arr.dtype)
                    buf[sl] = arr
        except OSError as exc:
            self.abort()
            raise DatasetWriteError(exc.errno or 0, f"write to {self.tmp} failed ({exc}); completed shards are "
                                    "intact: free space / fix permissions and rerun with --resume") from exc
        if sl is not None:
            self.rows_written[sl] = True

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
            fd = os.open(self.tmp, os.O_RDONLY)
            try:
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(self.tmp, self.final)
            _fsync_dir(self.dir)
        except OSError as exc:
            self.abort()
            raise DatasetWriteError(exc.errno or 0, f"finishing shard {self.final} failed ({exc}); completed shards "
                                    "are intact: rerun with --resume") from exc
        return self.final

    def _cleanup(self):
        try:
            if getattr(self, "f", None) is not None:
                self.f.close()
        except Exception:  # noqa: BLE001 - best effort on an already failing file
            pass
        self.f = None
        try:
            self.tmp.unlink()
        except OSError:
            pass

    def abort(self):
        """Close and delete the temporary file (nothing final is touched)."""
        self._cleanup()


def clean_temporaries(out_dir) -> list[str]:
    """Delete temporary files a killed job left (``.shard-*.tmp-*``, ``.manifest.json.tmp-*``); returns their names."""
    removed = []
    for p in glob.glob(os.path.join(out_dir, ".*.tmp-*")):
        try:
            os.unlink(p)
            removed.append(os.path.basename(p))
        except OSError:
            pass
    return removed


def shard_is_valid(path, expected_first: int, expected_count: int) -> bool:
    """A final-named shard that opens, is marked complete and holds the expected sample ids."""
    try:
        with h5py.File(path, "r") as f:
            if not bool(f.attrs.get("complete", False)):
                return False
            if int(f.attrs["first_sample"]) != expected_first or int(f.attrs["count"]) != expected_count:
                return False
            ids = f["sample_id"][...]
            return ids.shape == (expected_count,) and np.array_equal(
                ids, np.arange(expected_first, expected_first + expected_count))
    except (OSError, KeyError):
        return False


# ---------------------------------------------------------------------------------------------------------------------
# Readers
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
        mpath = self.root / MANIFEST
        if not mpath.is_file():
            raise FileNotFoundError(f"{self.root} has no {MANIFEST}: not a warpworm dataset folder")
        self.manifest = json.loads(mpath.read_text())
        shards = []
        for name in sorted(os.listdir(self.root)):
            m = SHARD_RE.match(name)
            if m:
                shards.append((int(m.group(1)), self.root / name))
        self.shard_paths = [p for _, p in shards]
        counts = []
        for p in self.shard_paths:
            with h5py.File(p, "r") as f:
                counts.append(int(f.attrs["count"]))
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
    """Open a dataset folder for random access: ``ds = warpworm.dataset.open(DIR); ds[i]["rgb"]``."""
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
