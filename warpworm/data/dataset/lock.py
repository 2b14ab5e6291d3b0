"""The advisory lock on a dataset folder (``flock`` on ``DIR/.warpworm.lock``) that one job holds while it writes."""

from __future__ import annotations

import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path

from warpworm.data.dataset.files import write_error

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
