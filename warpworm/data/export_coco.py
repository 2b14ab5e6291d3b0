"""The COCO exporter (``warpworm export-coco DIR OUT``): images and a COCO keypoint annotation file
(https://cocodataset.org/#format-data).

Written::

    OUT/images/{sample_id:06d}.png        # the dataset's rgb, losslessly
    OUT/annotations/keypoints.json        # COCO: info, images, annotations, categories

One category, ``worm`` (id 1), with the 16 distinct keypoints of :mod:`warpworm.data.export_keypoints` (the dataset's
IPM centres, which coincide with other keypoints in the image, are replaced by three dorsal points) and a ``skeleton``
(1-based pairs: the body axis tail - seg0 ... seg4 - head, each dorsal point to its segment, the end-section corners
to their end), ``flip_pairs`` (1-based: the keypoints a left-right mirrored image swaps) and ``half_turn_pairs`` (the
keypoints the worm's near-symmetry, a half turn about its dorsal axis, swaps: head <-> tail). One annotation per
image: ``keypoints`` = [u, v, v_flag] * P with the dataset's visibility (0 outside the image, 1 occluded, 2 visible;
u = v = 0 where the flag is 0, as COCO requires), ``num_keypoints`` = keypoints with a flag > 0, ``bbox`` = the visible
worm box (x, y, w, h) [px] (``labels/bbox_visib``; the projected box ``labels/bbox_obj`` clipped to the image where
no worm pixel is visible), ``area`` = visible worm pixels (segmentation ids 2..6), ``segmentation`` = that mask as an
uncompressed RLE (column-major, as pycocotools' ``frPyObjects``), ``iscrowd`` 0. Keypoint pixel centres are at integer
coordinates (the dataset's OpenCV convention, which is also COCO's keypoint convention).

For ``COCOeval(..., "keypoints")`` set ``params.kpt_oks_sigmas`` to P values (pycocotools' default has COCO's 17
person keypoints); the file's ``info.kpt_oks_sigmas`` holds ours (export_keypoints.OKS_SIGMAS).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from warpworm import ids
from warpworm.data import dataset as ds
from warpworm.data import export_json as strict_json
from warpworm.data import export_keypoints as ek
from warpworm.data.export_webdataset import rle_uncompressed


def skeleton(names: list[str]) -> list[list[int]]:
    """1-based keypoint pairs between the names that exist: body axis, IPMs to their segments, corners to their end."""
    idx = {n: i + 1 for i, n in enumerate(names)}
    chain = ["tail"] + [f"seg{i}" for i in range(5)] + ["head"]
    pairs = list(zip(chain[:-1], chain[1:]))
    pairs += [("seg1_top", "seg1"), ("seg2_top", "seg2"), ("seg3_top", "seg3")]
    for end in ("tail", "head"):
        pairs += [(f"{end}_{c}", end) for c in ("top", "left", "right")]
    return [[idx[a], idx[b]] for a, b in pairs if a in idx and b in idx]


def export_coco(src, out, limit: int | None = None, overwrite: bool = False) -> dict:
    """Write ``out``; returns {"images": n, "annotations": n, "file": path}."""
    reader = ds.open(src)
    out = Path(out)
    if out.exists() and any(out.iterdir()) and not overwrite:
        raise ValueError(f"OUT: got '{out}'; expected an empty or new folder (or --overwrite)")
    (out / "images").mkdir(parents=True, exist_ok=True)
    (out / "annotations").mkdir(parents=True, exist_ok=True)
    kpx = ek.KeypointExporter(reader)
    names = list(kpx.names)
    P = len(names)
    n = len(reader) if limit is None else min(limit, len(reader))
    images, anns = [], []
    for i in range(n):
        s = reader[i]
        sid = int(s["sample_id"])
        rgb = s["rgb"]
        H, W = rgb.shape[:2]
        fname = f"{sid:06d}.png"
        if not cv2.imwrite(str(out / "images" / fname), np.ascontiguousarray(rgb[..., ::-1])):
            raise OSError(f"could not write {out / 'images' / fname}")
        images.append({"id": sid, "file_name": f"images/{fname}", "width": int(W), "height": int(H)})
        uv, vis = kpx.read([i])
        uv, vis = uv[0], vis[0].astype(np.int64)
        kp = np.zeros((P, 3))
        kp[:, :2] = np.where(vis[:, None] > 0, uv, 0.0)
        kp[:, 2] = vis
        seg = s["segmentation"]
        worm = (seg >= ids.SEG_WORM_FIRST) & (seg <= ids.SEG_WORM_LAST)
        area = int(worm.sum())
        bv = s["labels/bbox_visib"].astype(np.float64)
        if bv[2] > 0 and bv[3] > 0:
            bbox = bv
        else:
            b = s["labels/bbox_obj"].astype(np.float64)
            x0, y0 = np.clip(b[0], 0, W), np.clip(b[1], 0, H)
            x1, y1 = np.clip(b[0] + b[2], 0, W), np.clip(b[1] + b[3], 0, H)
            bbox = np.array([x0, y0, x1 - x0, y1 - y0])
        anns.append({"id": sid + 1, "image_id": sid, "category_id": 1, "iscrowd": 0,
                     "keypoints": [float(x) if j % 3 < 2 else int(x) for j, x in enumerate(kp.reshape(-1))],
                     "num_keypoints": int((vis > 0).sum()), "bbox": [float(x) for x in bbox], "area": float(area),
                     "segmentation": rle_uncompressed(worm)})
    coco = {
        "info": {"description": f"warpworm dataset {Path(src).resolve().name} (COCO keypoints export)",
                 "version": str(reader.attrs.get("warpworm_version", "")), "year": 2024,
                 "kpt_oks_sigmas": [ek.OKS_SIGMAS[n] for n in names]},
        "licenses": [],
        "images": images,
        "annotations": anns,
        "categories": [{"id": 1, "name": "worm", "supercategory": "robot", "keypoints": names,
                        "skeleton": skeleton(names),
                        "flip_pairs": ek.index_pairs(ek.MIRROR_PAIRS, names, base=1),
                        "half_turn_pairs": ek.index_pairs(ek.HALF_TURN_PAIRS, names, base=1)}],
    }
    path = out / "annotations" / "keypoints.json"
    strict_json.write(path, coco)
    reader.close()
    return {"images": len(images), "annotations": len(anns), "file": str(path)}
