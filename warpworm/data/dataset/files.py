"""Crash-safe files: the errors a dataset folder raises, a file object that survives a full disk under HDF5, JSON
written atomically (temporary, fsync, rename), and the shards' SHA-256."""

from __future__ import annotations

import builtins
import errno
import hashlib
import json
import os
from pathlib import Path
from typing import Any

import numpy as np

from warpworm.data.export_json import jsonable  # strict JSON: NaN / inf as null (JSON.parse rejects NaN)


class DatasetWriteError(OSError):
    """Writing a shard failed (disk full, read-only folder, ...). Completed shards are intact; rerun with --resume."""


class DatasetError(ValueError):
    """A dataset folder is damaged or not a dataset (missing / unreadable manifest, unreadable shard)."""


def write_error(exc: OSError, path, doing: str) -> DatasetWriteError:
    """One-line :class:`DatasetWriteError` naming the file, the cause and what to do."""
    code = exc.errno or 0
    what = os.strerror(code) if code else str(exc)
    if code in (errno.ENOSPC, errno.EDQUOT):
        fix = "free space on that file system (or point --out elsewhere and start again)"
    elif code in (errno.EACCES, errno.EPERM, errno.EROFS):
        fix = "make the folder writable (permissions, a read-write mount)"
    else:
        fix = "fix the storage problem"
    return DatasetWriteError(code, f"{doing} {path} failed: {what} [errno {code}]. Completed shards are intact and "
                                   f"nothing half-written is left; {fix}, then rerun the same command with --resume")


class FailSafeFile:
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
                        raise OSError(errno.EIO, "short write")
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


def fsync_dir(path: Path) -> None:
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
    data = json.dumps(jsonable(obj), indent=1, sort_keys=False, default=_json_default, allow_nan=False)
    try:
        with builtins.open(tmp, "w") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
        fsync_dir(path.parent)
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


def file_sha256(path, block: int = 1 << 20) -> str:
    """SHA-256 of a file's bytes (hex), as stored per shard in the manifest."""
    h = hashlib.sha256()
    with builtins.open(path, "rb") as f:
        while True:
            b = f.read(block)
            if not b:
                return h.hexdigest()
            h.update(b)
