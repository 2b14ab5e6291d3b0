"""Export a warpworm dataset folder to the BOP layout (https://github.com/thodan/bop_toolkit, docs/bop_datasets_format.md).

Layout written::

    OUT/camera.json                                 # the first image's intrinsics + depth_scale (per image: scene_camera)
    OUT/models_info.json                            # object ids and names (the worm is deformable: no model files)
    OUT/train_pbr/{scene:06d}/rgb/{im:06d}.png
    OUT/train_pbr/{scene:06d}/depth/{im:06d}.png    # uint16; depth [mm] = value * depth_scale
    OUT/train_pbr/{scene:06d}/mask/{im:06d}_{gt:06d}.png        # object silhouette (occlusion ignored; see below)
    OUT/train_pbr/{scene:06d}/mask_visib/{im:06d}_{gt:06d}.png  # visible pixels of the object (from segmentation)
    OUT/train_pbr/{scene:06d}/scene_camera.json     # cam_K, cam_R_w2c, cam_t_w2c [mm], depth_scale
    OUT/train_pbr/{scene:06d}/scene_gt.json         # obj_id, cam_R_m2c, cam_t_m2c [mm]
    OUT/train_pbr/{scene:06d}/scene_gt_info.json    # bbox_obj, bbox_visib, px_count_all, px_count_visib, visib_fract

Scenes hold 1000 images: sample i is image ``i % 1000`` of scene ``i // 1000``. Objects (obj_id): 1 worm body frame,
2 tail IPM, 3 centre IPM, 4 head IPM, 5 EPM. BOP units are mm for translations and depth.

The worm's ``mask`` is its full silhouette as rendered (``labels/worm_mask``); for the magnets the dataset has no
unoccluded render, so their ``mask`` is their visible mask and their ``visib_fract`` is 1 when visible (an
approximation, stated in ``models_info.json``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from warpworm.data import dataset as ds
from warpworm.data import export_json as strict_json
from warpworm import ids

OBJECTS = {1: ("worm", ids.SEG_WORM), 2: ("ipm_tail", (ids.SEG_IPMS[0],)), 3: ("ipm_centre", (ids.SEG_IPMS[1],)),
           4: ("ipm_head", (ids.SEG_IPMS[2],)), 5: ("epm", (ids.SEG_EPM,))}
"""obj_id -> (name, segmentation ids)."""
SCENE_SIZE = 1000
DEPTH_SCALE = 0.1
"""BOP depth_scale [mm per PNG unit]: 0.1 mm resolution, up to 6.5 m."""


def _bbox(mask: np.ndarray) -> list[int]:
    """(x, y, w, h) of a boolean mask's pixels, or [-1, -1, -1, -1] when empty (BOP's convention)."""
    ys, xs = np.nonzero(mask)
    if ys.size == 0:
        return [-1, -1, -1, -1]
    return [int(xs.min()), int(ys.min()), int(xs.max() - xs.min() + 1), int(ys.max() - ys.min() + 1)]


def _write_json(path: Path, obj) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(strict_json.dumps(obj, indent=1))
    os.replace(tmp, path)


def export_bop(src, out, *, split: str = "train_pbr", limit: int | None = None) -> dict:
    """Write the BOP layout of dataset ``src`` to ``out``; returns {"images": n, "scenes": k}."""
    import cv2

    reader = ds.open(src)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n = len(reader) if limit is None else min(limit, len(reader))
    if n == 0:
        raise ValueError(f"{src} holds no samples")
    K0 = reader.read("camera/K", [0])[0]
    H, W = reader.read("depth", [0]).shape[1:]
    _write_json(out / "camera.json", {"cx": float(K0[0, 2]), "cy": float(K0[1, 2]), "fx": float(K0[0, 0]),
                                      "fy": float(K0[1, 1]), "width": int(W), "height": int(H),
                                      "depth_scale": DEPTH_SCALE})
    _write_json(out / "models_info.json", {
        str(k): {"name": v[0], "segmentation_ids": list(v[1]),
                 "note": ("body frame of the deformable worm (docs/dataset.md)" if k == 1 else
                          "mask = visible mask and visib_fract = 1 if visible: no unoccluded render is stored")}
        for k, v in OBJECTS.items()})
    scenes = 0
    for s0 in range(0, n, SCENE_SIZE):
        idx = np.arange(s0, min(n, s0 + SCENE_SIZE))
        sdir = out / split / f"{s0 // SCENE_SIZE:06d}"
        for sub in ("rgb", "depth", "mask", "mask_visib"):
            (sdir / sub).mkdir(parents=True, exist_ok=True)
        cams, gts, infos = {}, {}, {}
        # read in blocks: random access is per shard anyway, and this keeps memory flat
        for b0 in range(0, len(idx), 256):
            blk = idx[b0:b0 + 256]
            data = {k: reader.read(k, blk) for k in ("rgb", "depth", "segmentation", "labels/worm_mask", "camera/K",
                                                     "camera/R", "camera/t", "poses/body", "poses/ipm", "poses/epm")}
            for j, i in enumerate(blk):
                im = int(i - s0)
                R, t, K = data["camera/R"][j], data["camera/t"][j], data["camera/K"][j]
                cv2.imwrite(str(sdir / "rgb" / f"{im:06d}.png"), data["rgb"][j][..., ::-1])
                dmm = data["depth"][j].astype(np.float64) * 1000.0 / DEPTH_SCALE
                cv2.imwrite(str(sdir / "depth" / f"{im:06d}.png"), np.clip(np.rint(dmm), 0, 65535).astype(np.uint16))
                cams[str(im)] = {"cam_K": K.reshape(-1).tolist(), "cam_R_w2c": R.reshape(-1).tolist(),
                                 "cam_t_w2c": (t * 1000.0).tolist(), "depth_scale": DEPTH_SCALE}
                poses = [data["poses/body"][j], *data["poses/ipm"][j], data["poses/epm"][j]]
                seg = data["segmentation"][j]
                gl, il = [], []
                for gt, (obj_id, (_, ids)) in enumerate(OBJECTS.items()):
                    T = poses[obj_id - 1]
                    gl.append({"obj_id": obj_id, "cam_R_m2c": (R @ T[:3, :3]).reshape(-1).tolist(),
                               "cam_t_m2c": ((R @ T[:3, 3] + t) * 1000.0).tolist()})
                    visib = np.isin(seg, ids)
                    full = data["labels/worm_mask"][j] > 0 if obj_id == 1 else visib
                    full = full | visib
                    cv2.imwrite(str(sdir / "mask" / f"{im:06d}_{gt:06d}.png"), full.astype(np.uint8) * 255)
                    cv2.imwrite(str(sdir / "mask_visib" / f"{im:06d}_{gt:06d}.png"), visib.astype(np.uint8) * 255)
                    na, nv = int(full.sum()), int(visib.sum())
                    il.append({"bbox_obj": _bbox(full), "bbox_visib": _bbox(visib), "px_count_all": na,
                               "px_count_valid": na, "px_count_visib": nv,
                               "visib_fract": float(nv / na) if na else 0.0})
                gts[str(im)] = gl
                infos[str(im)] = il
        _write_json(sdir / "scene_camera.json", cams)
        _write_json(sdir / "scene_gt.json", gts)
        _write_json(sdir / "scene_gt_info.json", infos)
        scenes += 1
    reader.close()
    return {"images": int(n), "scenes": scenes}
