"""Export a warpworm dataset folder for Ultralytics YOLO pose training (https://docs.ultralytics.com/datasets/pose/).

Written::

    OUT/images/train/{sample_id:06d}.png    OUT/labels/train/{sample_id:06d}.txt
    OUT/images/val/...                      OUT/labels/val/...      (whole trajectories: no frame of a validation
                                                                     trajectory is in train)
    OUT/dataset.yaml                        path, train, val, names {0: worm}, kpt_shape [16, 3], flip_idx,
                                            kpt_names; and, for the user's own metric code (Ultralytics does not
                                            read them), kpt_oks_sigmas and half_turn_idx

A label file holds one line per visible worm (none when no worm pixel is visible: a background image)::

    0 cx cy w h  x1 y1 v1 ... x16 y16 v16

box and keypoints normalized by the image size (x / W, y / H), the box = the visible worm pixels
(``labels/bbox_visib``); v = the dataset's COCO flag (0 outside the image, with x = y = 0; 1 occluded; 2 visible).
Keypoints: the 16 distinct points of :mod:`warpworm.data.export_keypoints`. ``flip_idx`` is the keypoint map of a
left-right mirrored image (Ultralytics' fliplr augmentation): the end sections' left and right corners swap.
``half_turn_idx`` is the worm's near-symmetry (a half turn about its dorsal axis: head <-> tail).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import yaml

from warpworm.data import dataset as ds
from warpworm.data import export_keypoints as ek


def split_trajectories(traj: np.ndarray, val_fraction: float) -> np.ndarray:
    """Boolean (N,): True for samples in validation: every trajectory whose rank among the dataset's trajectories
    falls in the last ``val_fraction`` (at least one trajectory when the fraction is > 0 and there are two or more)."""
    uniq = np.unique(traj)
    n_val = int(np.ceil(val_fraction * len(uniq))) if val_fraction > 0 and len(uniq) > 1 else 0
    n_val = min(n_val, len(uniq) - 1) if len(uniq) > 1 else 0
    return np.isin(traj, uniq[len(uniq) - n_val:]) if n_val else np.zeros(len(traj), bool)


def label_line(bbox, uv, vis, W: int, H: int) -> str | None:
    """One YOLO pose line (class 0) or None when the box is empty; bbox (x, y, w, h) [px], uv (P, 2), vis (P,)."""
    x, y, w, h = (float(v) for v in bbox)
    if w <= 0 or h <= 0:
        return None
    vals = [(x + 0.5 * w) / W, (y + 0.5 * h) / H, w / W, h / H]
    for (u, v), f in zip(uv, vis):
        vals += [u / W, v / H, int(f)] if f > 0 else [0.0, 0.0, 0]
    return "0 " + " ".join(f"{v:.6f}" if isinstance(v, float) else str(v) for v in vals)


def export_yolo(src, out, *, limit: int | None = None, val_fraction: float = 0.1) -> dict:
    """Write ``out``; returns {"train": n, "val": n, "labels": lines written, "yaml": path}."""
    reader = ds.open(src)
    out = Path(out)
    n = len(reader) if limit is None else min(limit, len(reader))
    if n == 0:
        raise ValueError(f"{src} holds no samples")
    kpx = ek.KeypointExporter(reader)
    names = list(kpx.names)
    idx = np.arange(n)
    val = split_trajectories(reader.read("trajectory", idx), val_fraction)
    counts = {"train": 0, "val": 0, "labels": 0}
    for part in ("train", "val"):
        (out / "images" / part).mkdir(parents=True, exist_ok=True)
        (out / "labels" / part).mkdir(parents=True, exist_ok=True)
    for b0 in range(0, n, 256):
        blk = idx[b0:b0 + 256]
        rgb, sid, box = reader.read("rgb", blk), reader.read("sample_id", blk), reader.read("labels/bbox_visib", blk)
        uv, vis = kpx.read(blk)
        H, W = rgb.shape[1:3]
        for j, i in enumerate(blk):
            part = "val" if val[i] else "train"
            stem = f"{int(sid[j]):06d}"
            if not cv2.imwrite(str(out / "images" / part / f"{stem}.png"), np.ascontiguousarray(rgb[j][..., ::-1])):
                raise OSError(f"could not write {out / 'images' / part / stem}.png")
            line = label_line(box[j], uv[j], vis[j], W, H)
            (out / "labels" / part / f"{stem}.txt").write_text("" if line is None else line + "\n")
            counts[part] += 1
            counts["labels"] += line is not None
    cfg = {"path": str(out.resolve()), "train": "images/train", "val": "images/val" if counts["val"] else
           "images/train", "names": {0: "worm"}, "kpt_shape": [len(names), 3],
           "flip_idx": ek.permutation(ek.MIRROR_PAIRS, names), "kpt_names": {0: names},
           "kpt_oks_sigmas": [ek.OKS_SIGMAS[k] for k in names],
           "half_turn_idx": ek.permutation(ek.HALF_TURN_PAIRS, names)}
    path = out / "dataset.yaml"
    path.write_text("# warpworm export-yolo (warpworm.data.export_yolo): Ultralytics pose dataset\n"
                    + yaml.safe_dump(cfg, sort_keys=False, default_flow_style=None))
    reader.close()
    return {**counts, "yaml": str(path)}
