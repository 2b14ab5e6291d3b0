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
import errno as errno_mod
import fcntl
import glob
import hashlib
import socket
import time
import json
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

import h5py
import numpy as np

from warpworm import ids
from warpworm.data import signal_hold

SCHEMA_VERSION = 1
FORMAT = "warpworm-dataset"
"""The ``format`` of every shard's root attributes and of the manifest."""
MANIFEST = "manifest.json"
SHARD_RE = re.compile(r"^shard-(\d{5})\.h5$")
QUATERNION_ORDER = "wxyz"

SEGMENTATION_IDS = ids.SEGMENTATION_IDS
"""Segmentation ids (:mod:`warpworm.ids`, docs/architecture.md): worm segments 0..4 run tail -> head."""

UNITS = {"length": "m", "depth": "m (camera z; 0 = background)", "angle": "rad", "time": "s", "pixel": "px",
         "mass": "kg", "moment": "A*m^2", "frames": "OpenCV camera (+z forward, +y down), x_cam = R x_world + t; "
         "poses are object -> world 4x4"}

@dataclass(frozen=True)
class Field:
    """One dataset of every shard: its name, per-file shape (symbols N, H, W, P, C, E, V or integers), dtype, unit."""

    name: str
    shape: tuple
    dtype: str
    unit: str
    description: str


SHAPE_SYMBOLS = {
    "N": "samples in the shard (attribute count)", "H": "render.height [px]", "W": "render.width [px]",
    "P": "keypoints (root attribute keypoint_names)", "C": "creases (rows of root attribute crease_hinges)",
    "E": "bars (rows of root attribute bar_edges)", "V": "sheet vertices (worm mesh)",
}
"""What each symbol of :attr:`Field.shape` stands for."""

FIELDS: tuple[Field, ...] = (
    Field("rgb", ("N", "H", "W", 3), "uint8", "", "colour image, sRGB, after sensor effects"),
    Field("depth", ("N", "H", "W"), "float32", "m", "camera-frame z of the first surface; 0 = background"),
    Field("segmentation", ("N", "H", "W"), "uint8", "",
          f"ids, see root attribute segmentation_ids: {ids.SEGMENTATION_TEXT}"),
    Field("camera/K", ("N", 3, 3), "float64", "px", "intrinsics, row-major, fx, fy > 0, pixel centres at integers"),
    Field("camera/R", ("N", 3, 3), "float64", "", "world -> camera rotation (x_cam = R x_world + t)"),
    Field("camera/t", ("N", 3), "float64", "m", "world -> camera translation"),
    Field("camera/position", ("N", 3), "float64", "m", "camera centre in world (= -R^T t)"),
    Field("camera/in_frame", ("N",), "float32", "",
          "fraction of the worm's vertices (every frame the camera shows) inside the image; below "
          "camera.min_in_frame only if no view in camera.max_tries draws reached it"),
    Field("poses/body", ("N", 4, 4), "float64", "m",
          "worm body frame -> world (origin: mean of the segment centres, x tail->head, z dorsal)"),
    Field("poses/ipm", ("N", 3, 4, 4), "float64", "m", "IPM (tail, centre, head) -> world; disk axis = local z"),
    Field("poses/epm", ("N", 4, 4), "float64", "m", "EPM -> world; moment along local z"),
    Field("poses/body_quat", ("N", 4), "float64", "", "body rotation as a unit quaternion (w, x, y, z)"),
    Field("keypoints/world", ("N", "P", 3), "float64", "m", "keypoints in world, names in root attribute keypoint_names"),
    Field("keypoints/camera", ("N", "P", 3), "float64", "m", "keypoints in the camera frame (R x_world + t)"),
    Field("keypoints/body", ("N", "P", 3), "float64", "m",
          "keypoints in the worm body frame: poses/body^-1 applied to keypoints/world"),
    Field("keypoints/pixel", ("N", "P", 2), "float64", "px",
          "projection (u, v) of keypoints/world through K, R, t (cv2.projectPoints, no distortion)"),
    Field("keypoints/visibility", ("N", "P"), "uint8", "",
          "COCO: 0 outside the image (or behind the camera), 1 occluded, 2 visible (docs/render.md)"),
    Field("creases/angle", ("N", "C"), "float32", "rad",
          "signed dihedral of every crease (valley +, mountain -), order = root attribute crease_hinges"),
    Field("bars/strain", ("N", "E"), "float32", "", "Cauchy strain dL/L0 of every bar, order = root attribute bar_edges"),
    Field("worm/vertices", ("N", "V", 3), "float32", "m",
          "deformed sheet vertices in world (triangles: root attribute mesh_triangles)"),
    Field("labels/bbox_obj", ("N", 4), "float32", "px", "worm box (x, y, w, h) of the projected mesh, occlusion ignored"),
    Field("labels/bbox_visib", ("N", 4), "float32", "px", "worm box (x, y, w, h) of its visible pixels; 0s if none"),
    Field("labels/visib_fract", ("N",), "float32", "", "visible worm pixels / pixels of the worm rendered alone"),
    Field("labels/worm_mask", ("N", "H", "W"), "uint8", "", "1 where the worm's sheet projects, occluders ignored"),
    Field("labels/deformation", ("N", 4), "float32", "",
          "distances between adjacent segment centres over their rest values"),
    Field("time", ("N",), "float32", "s", "simulated time of the frame after settling"),
    Field("trajectory", ("N",), "int64", "", "trajectory (simulated world) id; its frames are consecutive samples"),
    Field("frame", ("N",), "int32", "", "frame index within the trajectory (sim.frame_times)"),
    Field("attempt", ("N",), "int32", "", "replacement attempt that gave a stable world (0: first draw)"),
    Field("sample_id", ("N",), "int64", "", "global sample id, == row in the whole dataset"),
    Field("seed", ("N",), "int64", "", "per-sample 63-bit seed derived from (master seed, sample id) for pixel noise"),
)
"""Every dataset of every shard, in the order of the docs table (``params/<group>.<name>`` come in addition)."""

PARAMS_FIELD = Field("params/<group>.<name>", ("N",), "float64 / bytes / bool", "(the parameter's)",
                     "every randomized value, one dataset per name in root attribute params_names")

SCHEMA: dict[str, tuple[str, str, str]] = {
    f.name: (f.dtype, f.unit, f"({', '.join(str(d) for d in f.shape[1:])}{',' if len(f.shape) == 2 else ''}) "
             f"{f.description}") for f in FIELDS}
"""name -> (dtype, unit, description with the per-sample shape); the ``description`` attribute of each dataset."""
SCHEMA["view"] = ("int32", "", "() which of the trajectory's render.views_per_frame cameras shows this sample "
                  "(written only when views_per_frame > 1; sample = (trajectory K + view) F + frame)")
SCHEMA["engine"] = ("uint8", "", "() renderer of this sample's rgb: 0 raster, 1 path-traced (warpworm.render.pathtrace; "
                    "written only with render.engine pathtraced or render.pathtraced_fraction > 0; labels are raster)")
SCHEMA["camera/dist"] = ("float64", "", "(5,) lens distortion (k1, k2, p1, p2, k3), OpenCV's model: rgb, depth, "
                         "segmentation and keypoints/pixel (= cv2.projectPoints with it) go through it; written only "
                         "with render.distortion")

SCHEMA_TABLE_BEGIN = "<!-- schema table: generated from warpworm.data.dataset.FIELDS by schema_markdown(); do not edit -->"
SCHEMA_TABLE_END = "<!-- end of schema table -->"


def schema_markdown() -> str:
    """The docs' table of every HDF5 dataset (docs/dataset.md holds exactly this text; a test checks it)."""
    def shape(f):
        return "(" + ", ".join(str(d) for d in f.shape) + ("," if len(f.shape) == 1 else "") + ")"

    rows = ["| dataset | shape | dtype | unit | meaning |", "|---|---|---|---|---|"]
    for f in FIELDS + (PARAMS_FIELD,):
        rows.append(f"| `{f.name}` | {shape(f)} | {f.dtype} | {f.unit or '—'} | {f.description} |")
    syms = "; ".join(f"{k} = {v}" for k, v in SHAPE_SYMBOLS.items())
    return "\n".join([SCHEMA_TABLE_BEGIN, *rows, "", f"Shape symbols: {syms}.", SCHEMA_TABLE_END])


def resolve_shape(field: Field, dims: dict[str, int]) -> tuple[int, ...]:
    """A field's shape with its symbols replaced by ``dims`` (e.g. {"N": 6, "H": 16, ...})."""
    return tuple(dims[d] if isinstance(d, str) else d for d in field.shape)


IMAGE_KEYS = ("rgb", "depth", "segmentation", "labels/worm_mask")


class DatasetWriteError(OSError):
    """Writing a shard failed (disk full, read-only folder, ...). Completed shards are intact; rerun with --resume."""


class DatasetError(ValueError):
    """A dataset folder is damaged or not a dataset (missing / unreadable manifest, unreadable shard)."""


def write_error(exc: OSError, path, doing: str) -> DatasetWriteError:
    """One-line :class:`DatasetWriteError` naming the file, the cause and what to do."""
    import errno as _e

    code = exc.errno or 0
    what = os.strerror(code) if code else str(exc)
    if code in (_e.ENOSPC, _e.EDQUOT):
        fix = "free space on that file system (or point --out elsewhere and start again)"
    elif code in (_e.EACCES, _e.EPERM, _e.EROFS):
        fix = "make the folder writable (permissions, a read-write mount)"
    else:
        fix = "fix the storage problem"
    return DatasetWriteError(code, f"{doing} {path} failed: {what} [errno {code}]. Completed shards are intact and "
                                   f"nothing half-written is left; {fix}, then rerun the same command with --resume")


class _FailSafeFile:
    """The shard's file as HDF5 sees it (h5py's ``fileobj`` driver): unbuffered writes to a real file; the first
    OSError (ENOSPC, EIO, EROFS, ...) is recorded in :attr:`error` and every later write is dropped (reported as done).

    Why: when the disk fills up mid-shard, HDF5 keeps retrying the failed writes while closing the file and at
    interpreter exit (one traceback per cached metadata block, then a segfault, exit 139). Dropping the writes after
    the first failure lets HDF5 close cleanly; the writer then deletes the temporary and raises one clear error.
    """

    def __init__(self, path: Path):
        self.path = path
        self.raw = builtins.open(path, "w+b", buffering=0)
        self.error: OSError | None = None
        self._pos = 0

    def _raw_write(self, b) -> int:
        return self.raw.write(b)

    def write(self, b) -> int:
        n = len(memoryview(b).cast("B"))
        if self.error is None:
            try:
                mv = memoryview(b).cast("B")
                done = 0
                while done < n:
                    w = self._raw_write(mv[done:])
                    if not w:
                        raise OSError(errno_mod.EIO, "short write")
                    done += w
            except OSError as exc:
                self.error = exc
        self._pos += n
        if self.error is None:
            return n
        try:
            self.raw.seek(self._pos)
        except OSError:
            pass
        return n

    def read(self, n=-1):
        return self.raw.read(n)

    def readinto(self, b):
        return self.raw.readinto(b)

    def seek(self, pos, whence=0):
        self._pos = self.raw.seek(pos, whence)
        return self._pos

    def tell(self):
        return self._pos

    def truncate(self, size=None):
        if self.error is None:
            try:
                return self.raw.truncate(size)
            except OSError as exc:
                self.error = exc
        return size

    def flush(self):
        pass

    def close(self):
        self.raw.close()


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
    from warpworm.data.export_json import jsonable  # strict JSON: NaN / inf as null (JSON.parse rejects NaN)

    data = json.dumps(jsonable(obj), indent=1, sort_keys=False, default=_json_default, allow_nan=False)
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
        raise write_error(exc, path, "writing") from exc


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
            self._io = _FailSafeFile(self.tmp)
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
            _fsync_dir(self.dir)
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


def file_sha256(path, block: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex), as stored per shard in the manifest."""
    h = hashlib.sha256()
    with builtins.open(path, "rb") as f:
        while True:
            b = f.read(block)
            if not b:
                return h.hexdigest()
            h.update(b)


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


# ---------------------------------------------------------------------------------------------------------------------
# Advisory lock on a dataset folder
LOCK_NAME = ".warpworm.lock"


class DatasetLockedError(RuntimeError):
    """Another running job holds the folder's lock."""


class FolderLock:
    """An exclusive advisory lock (``flock``) on ``DIR/.warpworm.lock`` held for a whole job.

    The file names the holder (JSON: pid, host, start time, command). The kernel releases the lock when the holder
    dies, however it dies, so a lock file with a holder in it that can be locked again is *stale* (a killed job):
    :attr:`stale` then holds the dead job's record. A clean exit empties the file. ``flock`` is per host on most
    network file systems: two hosts writing one NFS folder are not stopped by it (use one folder per job there).
    """

    def __init__(self, root):
        self.path = Path(root) / LOCK_NAME
        self.fd = None
        self.stale: dict | None = None

    @staticmethod
    def describe(info: dict) -> str:
        return (f"pid {info.get('pid')} on host {info.get('host')} started {info.get('started')}"
                + (f" ({info.get('command')})" if info.get("command") else ""))

    def acquire(self, command: str = "") -> "FolderLock":
        import sys

        try:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise write_error(exc, self.path, "creating the lock file") from exc
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            info = _read_lock(fd)
            os.close(fd)
            raise DatasetLockedError(f"{self.path.parent} is in use by another job: {self.describe(info)}; wait for "
                                     "it to finish or stop it (kill -TERM <pid>), then rerun with --resume") from None
        old = _read_lock(fd)
        if old:
            self.stale = old
        info = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "command": command or " ".join(sys.argv)}
        try:
            os.ftruncate(fd, 0)
            os.pwrite(fd, json.dumps(info).encode(), 0)
        except OSError as exc:
            os.close(fd)
            raise write_error(exc, self.path, "writing the lock file") from exc
        self.fd = fd
        return self

    def release(self) -> None:
        if self.fd is None:
            return
        try:
            os.ftruncate(self.fd, 0)  # empty = released cleanly (not stale)
        except OSError:
            pass
        try:
            fcntl.flock(self.fd, fcntl.LOCK_UN)
        finally:
            os.close(self.fd)
            self.fd = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.release()


def _read_lock(fd) -> dict:
    try:
        raw = os.pread(fd, 4096, 0)
        return json.loads(raw) if raw.strip() else {}
    except (OSError, ValueError):
        return {"pid": "?", "host": "?", "started": "?"}


def lock_holder(root) -> dict | None:
    """The record of the job holding ``root``'s lock now, or None (no lock file, or a stale one)."""
    path = Path(root) / LOCK_NAME
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except BlockingIOError:
            return _read_lock(fd)
        fcntl.flock(fd, fcntl.LOCK_UN)
        return None
    finally:
        os.close(fd)


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
        import yaml

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
