"""The output folder's rule, checked before any work: new, empty, or (with ``--resume``) a warpworm dataset; writable."""

from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path

from warpworm.data.dataset.schema import FORMAT
from warpworm.errors import ConfigError


def _is_warpworm_manifest(path: Path) -> bool:
    """Whether ``path`` is a warpworm dataset's manifest (another tool's manifest.json is not)."""
    try:
        return json.loads(path.read_text()).get("format") == FORMAT
    except (OSError, ValueError, AttributeError, UnicodeDecodeError):
        return False


def check_output_dir(out: str | os.PathLike, resume: bool) -> None:
    """Refuse an unwritable output folder, or a non-empty one without ``resume``; writes nothing that stays.

    A writability probe creates and removes one temporary file (the only reliable test: permission bits lie for root
    and on read-only mounts).
    """
    out = Path(out)
    errors = []
    if out.exists() and not out.is_dir():
        raise ConfigError([f"--out: got '{out}'; expected a folder (it is a file)"])
    if out.is_dir():
        names = sorted(p.name for p in out.iterdir())
        ours = [n for n in names if re.fullmatch(r"shard-\d+\.h5", n)
                or (n == "manifest.json" and _is_warpworm_manifest(out / n))]
        visible = [n for n in names if not n.startswith(".")]  # hidden: a killed job's lock and temporaries
        if visible and not ours:  # not a warpworm dataset: never write next to someone else's files
            what = "an empty or new folder" + (" or a dataset to resume" if resume else "")
            raise ConfigError([f"--out: got '{out}'; expected {what} (it holds other files, e.g. {visible[0]}, and "
                               "no warpworm dataset: no shard-*.h5, no manifest.json of format warpworm-dataset)"])
        if not resume and names:
            raise ConfigError([f"--out: got '{out}'; expected an empty or new folder (it is not empty: it holds a "
                               "warpworm dataset; use --resume to continue its job, or another --out)"])
        probe_dir = out
    else:
        probe_dir = out.parent
        while not probe_dir.exists() and probe_dir != probe_dir.parent:
            probe_dir = probe_dir.parent
    try:
        fd, name = tempfile.mkstemp(prefix=".warpworm-probe-", dir=probe_dir)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        errors.append(f"--out: got '{out}'; expected a writable folder ({exc.strerror}: {probe_dir})")
    if errors:
        raise ConfigError(errors)
