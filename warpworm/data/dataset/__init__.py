"""Sharded HDF5 datasets: the schema, a crash-safe writer, an atomic manifest, the folder lock, and readers.

Layout of a dataset folder::

    DIR/manifest.json          # written atomically; shards, counts, config, versions, summary
    DIR/shard-00000.h5         # sample ids [0, S)
    DIR/shard-00001.h5         # sample ids [S, 2S) ... shard k always holds [k*S, min((k+1)*S, N))
    DIR/preview.png, preview.mp4

Crash safety: a shard is written under a temporary name (``.shard-00001.h5.tmp-<pid>``), flushed, fsynced, then
renamed to its final name, and the folder fsynced. A final-named shard is therefore always complete; a killed job leaves
at most temporary files, which ``--resume`` deletes before redoing the missing shards. Because shard k's content depends
only on (config, k), a resumed job gives the same bytes of data as an uninterrupted one.

Storage: images (rgb, depth, segmentation, worm mask)
are chunked one sample per chunk and compressed with the config's filter (default gzip level 1, with byte shuffle for
depth); small per-sample labels are buffered per shard and stored contiguous and uncompressed (a few hundred bytes a
sample; chunking them costs more than it saves). Rows are always written as contiguous ranges.

Modules: ``schema`` (FIELDS, SCHEMA, docs table), ``files`` (errors, fail-safe file, atomic JSON, SHA-256), ``folder``
(shard names, manifest, shard checks, temporaries), ``writer`` (ShardWriter), ``lock`` (FolderLock), ``output_dir``
(check_output_dir: the folder's rule before any work), ``reader`` (DatasetReader, open, WormDataset). Every public name is importable from here.
"""

from __future__ import annotations

from warpworm.data.dataset.files import (DatasetError, DatasetWriteError, FailSafeFile, atomic_write_json,
                                         file_sha256, write_error)
from warpworm.data.dataset.folder import (MANIFEST, SHARD_RE, clean_temporaries, manifest, read_manifest, shard_name,
                                          shard_problem)
from warpworm.data.dataset.output_dir import check_output_dir
from warpworm.data.dataset.lock import LOCK_NAME, DatasetLockedError, FolderLock, lock_holder
from warpworm.data.dataset.reader import DatasetReader, WormDataset, open  # noqa: A004 - mirrors h5py.File / zarr.open
from warpworm.data.dataset.schema import (FIELDS, FORMAT, IMAGE_KEYS, PARAMS_FIELD, QUATERNION_ORDER, SCHEMA,
                                          SCHEMA_TABLE_BEGIN, SCHEMA_TABLE_END, SCHEMA_VERSION, SEGMENTATION_IDS,
                                          SHAPE_SYMBOLS, UNITS, Field, resolve_shape, schema_markdown, versions,
                                          warp_version)
from warpworm.data.dataset.writer import ShardWriter
