"""Export a warpworm dataset folder as BOP-webdataset tar shards (the layout bop_toolkit converts BOP datasets to and
MegaPose-scale training sets ship in: bop_toolkit_lib/dataset/bop_webdataset.py, bop_imagewise.py).

Written::

    OUT/shard-000000.tar ...        # up to --shard-size images each, in sample order (shuffle when reading)
    OUT/key_to_shard.json           # image key -> shard index
    OUT/camera.json, OUT/models/    # as export-bop: intrinsics, the object models (PLY, mm) and models_info.json
    OUT/models_info.json

Per image, under the key ``{scene:06d}_{image:06d}`` (scene = sample // 1000, image = sample % 1000, as export-bop)::

    KEY.rgb.png          KEY.depth.png (uint16, depth [mm] = value * depth_scale)
    KEY.camera.json      cam_K, cam_R_w2c, cam_t_w2c [mm], depth_scale
    KEY.gt.json          [{obj_id, cam_R_m2c, cam_t_m2c [mm]}] over the 5 objects (export_bop.OBJECTS)
    KEY.gt_info.json     [{bbox_obj, bbox_visib, px_count_*, visib_fract}]
    KEY.mask.json        {instance: uncompressed RLE} (column-major counts, as bop_toolkit's pycoco_utils)
    KEY.mask_visib.json  the same for the visible masks
    KEY.warpworm.json    what BOP has no field for: sample_id, trajectory, frame, time [s], the 16 distinct keypoints
                         (names, pixel [px], visibility; warpworm.data.export_keypoints), crease angles [rad], the four
                         deformation ratios, the body pose (4x4, world [m])

Every JSON is strict (no NaN). Reading back: ``webdataset.WebDataset(urls)`` yields one dict per key
(tests/test_export_formats.py reads it and compares with the HDF5 labels).
"""

from __future__ import annotations

import io

import cv2
import numpy as np

from warpworm.data import export_bop as bop
from warpworm.data import export_json as strict_json
from warpworm.data.export_keypoints import KeypointExporter

SHARD_SIZE = 1000
"""Images per tar shard (BOP-webdataset's maximum)."""


def _png(img: np.ndarray) -> bytes:
    ok, buf = cv2.imencode(".png", img)
    if not ok:
        raise OSError("PNG encoding failed")
    return buf.tobytes()


def rle_uncompressed(mask: np.ndarray) -> dict:
    """COCO / bop_toolkit uncompressed RLE of a (H, W) boolean mask: run lengths in column-major order, starting with
    zeros ({"size": [H, W], "counts": [...]}; pycocotools' ``frPyObjects`` reads it)."""
    flat = np.asarray(mask, bool).flatten(order="F")
    change = np.flatnonzero(np.diff(flat.astype(np.int8))) + 1
    bounds = np.concatenate([[0], change, [flat.size]])
    counts = np.diff(bounds).tolist()
    if flat.size and flat[0]:
        counts = [0] + counts
    return {"size": [int(mask.shape[0]), int(mask.shape[1])], "counts": [int(c) for c in counts]}


def export_webdataset(src, out, *, limit: int | None = None, shard_size: int = SHARD_SIZE) -> dict:
    """Write the shards of dataset ``src`` to ``out``; returns {"images": n, "shards": k}."""
    import webdataset as wds  # optional dependency: webdataset (the export extra)

    reader, out, n = bop.begin_export(src, out, limit)
    kpx = KeypointExporter(reader)
    key_to_shard, shards = {}, 0
    for s0 in range(0, n, shard_size):
        idx = np.arange(s0, min(n, s0 + shard_size))
        extra = {k: reader.read(k, idx) for k in ("sample_id", "trajectory", "frame", "time", "creases/angle",
                                                  "labels/deformation", "poses/body")}
        uv, vis = kpx.read(idx)
        path = out / f"shard-{shards:06d}.tar"
        tmp = path.with_name(f".{path.name}.tmp")
        with wds.TarWriter(str(tmp)) as sink:
            for j, i, rec in bop.image_records(reader, idx):
                key = f"{i // bop.SCENE_SIZE:06d}_{i % bop.SCENE_SIZE:06d}"
                labels = {"sample_id": int(extra["sample_id"][j]), "trajectory": int(extra["trajectory"][j]),
                          "frame": int(extra["frame"][j]), "time": float(extra["time"][j]),
                          "keypoint_names": list(kpx.names), "keypoints_pixel": uv[j].tolist(),
                          "keypoints_visibility": vis[j].tolist(), "crease_angle": extra["creases/angle"][j],
                          "deformation": extra["labels/deformation"][j], "pose_body": extra["poses/body"][j]}
                sink.write({
                    "__key__": key, "rgb.png": _png(rec["rgb"][..., ::-1]), "depth.png": _png(rec["depth"]),
                    "camera.json": strict_json.dumps(rec["camera"]).encode(),
                    "gt.json": strict_json.dumps(rec["gt"]).encode(),
                    "gt_info.json": strict_json.dumps(rec["gt_info"]).encode(),
                    "mask.json": strict_json.dumps({str(k): rle_uncompressed(m)
                                                    for k, m in enumerate(rec["mask"])}).encode(),
                    "mask_visib.json": strict_json.dumps({str(k): rle_uncompressed(m)
                                                          for k, m in enumerate(rec["mask_visib"])}).encode(),
                    "warpworm.json": strict_json.dumps(labels).encode()})
                key_to_shard[key] = shards
        tmp.replace(path)
        shards += 1
    strict_json.write(out / "key_to_shard.json", key_to_shard)
    reader.close()
    return {"images": int(n), "shards": shards}


def decode_png(data: bytes) -> np.ndarray:
    """A PNG from a shard as an array (uint8 RGB for rgb.png, as stored for depth.png)."""
    img = cv2.imdecode(np.frombuffer(io.BytesIO(data).getvalue(), np.uint8), cv2.IMREAD_UNCHANGED)
    return img[..., ::-1] if img.ndim == 3 else img
