"""Export a warpworm dataset folder to the BOP layout (https://github.com/thodan/bop_toolkit, docs/bop_datasets_format.md).

Layout written::

    OUT/camera.json                                 # the first image's intrinsics + depth_scale (per image: scene_camera)
    OUT/models/obj_{obj_id:06d}.ply                 # each object's mesh in its own frame [mm] (ASCII PLY)
    OUT/models/models_info.json                     # diameter, min_x/y/z, size_x/y/z [mm], symmetries (below)
    OUT/models_info.json                            # = models/models_info.json plus names and segmentation ids
    OUT/train_pbr/{scene:06d}/rgb/{im:06d}.png
    OUT/train_pbr/{scene:06d}/depth/{im:06d}.png    # uint16; depth [mm] = value * depth_scale
    OUT/train_pbr/{scene:06d}/mask/{im:06d}_{gt:06d}.png        # object silhouette (occlusion ignored; see below)
    OUT/train_pbr/{scene:06d}/mask_visib/{im:06d}_{gt:06d}.png  # visible pixels of the object (from segmentation)
    OUT/train_pbr/{scene:06d}/scene_camera.json     # cam_K, cam_R_w2c, cam_t_w2c [mm], depth_scale
    OUT/train_pbr/{scene:06d}/scene_gt.json         # obj_id, cam_R_m2c, cam_t_m2c [mm]
    OUT/train_pbr/{scene:06d}/scene_gt_info.json    # bbox_obj, bbox_visib, px_count_all, px_count_visib, visib_fract

Scenes hold 1000 images: sample i is image ``i % 1000`` of scene ``i // 1000``. Objects (obj_id): 1 worm body frame,
2 tail IPM, 3 centre IPM, 4 head IPM, 5 EPM. BOP units are mm for translations and depth.

Models: the worm is its rest-shape mesh in its body frame (``poses/body``: x tail -> head, z dorsal, origin the mean
of the segment centres) for the first sample's a, b, l0 (a dataset that randomizes them has one mesh
per sample: the model is then that of sample 0, as ``models_info.json``'s note says); a deformed worm differs from it
by its folds. The IPMs are disks (axis +z, the moment), the EPM a cuboid of its extents (long axis +z). Symmetries
(BOP's ``symmetries_discrete``: 4x4 row-major, translation in mm; ``symmetries_continuous``: axis and offset): the worm
is nearly symmetric under a half turn about its dorsal axis z (head <-> tail; it looks the same, so a pose metric must
accept both; the magnets' moments are not visible); an IPM disk is continuous about z and has a half turn about x; the
EPM has quarter turns about z and half turns about x.

The worm's ``mask`` is its full silhouette as rendered (``labels/worm_mask``); for the magnets the dataset has no
unoccluded render, so their ``mask`` is their visible mask and their ``visib_fract`` is 1 when visible (an
approximation, stated in ``models_info.json``).
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import trimesh

from warpworm import ids
from warpworm.data import dataset as ds
from warpworm.data import export_json as strict_json
from warpworm.physics import crease
from warpworm.render.labels import WormBody

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
    strict_json.write(path, obj, indent=1)


def _half_turn(axis: int) -> list[float]:
    T = np.eye(4)
    for k in range(3):
        if k != axis:
            T[k, k] = -1.0
    return T.reshape(-1).tolist()


def _turn_z(quarters: int) -> list[float]:
    c, s_ = np.rint(np.cos(quarters * np.pi / 2)), np.rint(np.sin(quarters * np.pi / 2))
    T = np.eye(4)
    T[:2, :2] = [[c, -s_], [s_, c]]
    return T.reshape(-1).tolist()


def object_meshes(reader) -> dict:
    """obj_id -> trimesh.Trimesh in the object's own frame [m] (module docstring), from sample 0's parameters."""
    p = {k: float(reader.read(f"params/worm.{k}", [0])[0]) for k in
         ("a", "b", "l0", "ipm_diameter", "ipm_thickness", "epm_size_x", "epm_size_y", "epm_size_z")}
    n_units = _n_units(reader)
    pattern = crease.build_worm(p["a"], p["b"], n_units, l0=p["l0"])
    R, o = WormBody.from_pattern(pattern).body_frame(pattern.vertices)
    worm = trimesh.Trimesh((pattern.vertices - o) @ R, pattern.triangles, process=False)
    disk = trimesh.creation.cylinder(radius=0.5 * p["ipm_diameter"], height=p["ipm_thickness"], sections=32)
    epm = trimesh.creation.box(extents=(p["epm_size_x"], p["epm_size_y"], p["epm_size_z"]))
    return {1: worm, 2: disk, 3: disk.copy(), 4: disk.copy(), 5: epm}


def _n_units(reader) -> int:
    return int((reader.config.get("sim") or {}).get("n_units", 6))


SYMMETRIES = {
    1: {"symmetries_discrete": [_half_turn(2)]},
    2: {"symmetries_continuous": [{"axis": [0, 0, 1], "offset": [0, 0, 0]}], "symmetries_discrete": [_half_turn(0)]},
    5: {"symmetries_discrete": [_turn_z(1), _turn_z(2), _turn_z(3), _half_turn(0), _half_turn(1)]},
}
SYMMETRIES[3] = SYMMETRIES[4] = SYMMETRIES[2]
"""obj_id -> BOP symmetry fields (module docstring)."""


def write_models(reader, out: Path) -> dict:
    """``models/obj_*.ply`` [mm] and ``models/models_info.json``; returns models_info (obj_id -> fields)."""
    (out / "models").mkdir(parents=True, exist_ok=True)
    info = {}
    for obj_id, mesh in object_meshes(reader).items():
        v = np.asarray(mesh.vertices) * 1000.0
        mm = mesh.copy()
        mm.vertices = v
        (out / "models" / f"obj_{obj_id:06d}.ply").write_bytes(mm.export(file_type="ply", encoding="ascii"))
        lo, hi = v.min(axis=0), v.max(axis=0)
        diff = v[:, None, :] - v[None, :, :]
        info[str(obj_id)] = {"diameter": float(np.sqrt((diff ** 2).sum(-1)).max()),
                             "min_x": float(lo[0]), "min_y": float(lo[1]), "min_z": float(lo[2]),
                             "size_x": float(hi[0] - lo[0]), "size_y": float(hi[1] - lo[1]),
                             "size_z": float(hi[2] - lo[2]), **SYMMETRIES.get(obj_id, {})}
    _write_json(out / "models" / "models_info.json", info)
    return info


IMAGE_KEYS = ("rgb", "depth", "segmentation", "labels/worm_mask", "camera/K", "camera/R", "camera/t", "poses/body",
              "poses/ipm", "poses/epm")


def image_records(reader, idx, block: int = 256):
    """Yield (j, sample index, record) for samples ``idx``: the BOP annotations of one image, ``camera``
    (scene_camera entry), ``gt`` and ``gt_info`` (lists over :data:`OBJECTS`), ``mask`` / ``mask_visib`` (5, H, W)
    bool, ``rgb`` (H, W, 3) uint8 RGB, ``depth`` (H, W) uint16 [depth_scale mm]. Read in blocks (random access is
    per shard anyway; memory stays flat)."""
    for b0 in range(0, len(idx), block):
        blk = np.asarray(idx[b0:b0 + block])
        data = {k: reader.read(k, blk) for k in IMAGE_KEYS}
        for j, i in enumerate(blk):
            R, t, K = data["camera/R"][j], data["camera/t"][j], data["camera/K"][j]
            dmm = data["depth"][j].astype(np.float64) * 1000.0 / DEPTH_SCALE
            poses = [data["poses/body"][j], *data["poses/ipm"][j], data["poses/epm"][j]]
            seg = data["segmentation"][j]
            gl, il, full_m, vis_m = [], [], [], []
            for obj_id, (_, seg_ids) in OBJECTS.items():
                T = poses[obj_id - 1]
                gl.append({"obj_id": obj_id, "cam_R_m2c": (R @ T[:3, :3]).reshape(-1).tolist(),
                           "cam_t_m2c": ((R @ T[:3, 3] + t) * 1000.0).tolist()})
                visib = np.isin(seg, seg_ids)
                full = (data["labels/worm_mask"][j] > 0 if obj_id == 1 else visib) | visib
                na, nv = int(full.sum()), int(visib.sum())
                il.append({"bbox_obj": _bbox(full), "bbox_visib": _bbox(visib), "px_count_all": na,
                           "px_count_valid": na, "px_count_visib": nv,
                           "visib_fract": float(nv / na) if na else 0.0})
                full_m.append(full)
                vis_m.append(visib)
            yield j, int(i), {
                "camera": {"cam_K": K.reshape(-1).tolist(), "cam_R_w2c": R.reshape(-1).tolist(),
                           "cam_t_w2c": (t * 1000.0).tolist(), "depth_scale": DEPTH_SCALE},
                "gt": gl, "gt_info": il, "mask": np.stack(full_m), "mask_visib": np.stack(vis_m),
                "rgb": np.ascontiguousarray(data["rgb"][j]),
                "depth": np.clip(np.rint(dmm), 0, 65535).astype(np.uint16)}


def write_model_files(reader, out: Path) -> None:
    """``models/`` and the root ``models_info.json`` (names, segmentation ids, notes) of an export to ``out``."""
    models = write_models(reader, out)
    _write_json(out / "models_info.json", {
        str(k): {**models[str(k)], "name": v[0], "segmentation_ids": list(v[1]),
                 "note": ("rest shape of the deformable worm in its body frame, sample 0's a, b, l0; nearly "
                          "symmetric under a half turn about z (head <-> tail)" if k == 1 else
                          "mask = visible mask and visib_fract = 1 if visible: no unoccluded render is stored")}
        for k, v in OBJECTS.items()})


def begin_export(src, out, limit: int | None):
    """Open dataset ``src``, create ``out`` and write its ``camera.json``, ``models/`` and ``models_info.json``;
    returns (reader, out as a Path, number of samples to export). ValueError when there are none."""
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
    write_model_files(reader, out)
    return reader, out, n


def export_bop(src, out, *, split: str = "train_pbr", limit: int | None = None) -> dict:
    """Write the BOP layout of dataset ``src`` to ``out``; returns {"images": n, "scenes": k}."""
    reader, out, n = begin_export(src, out, limit)
    scenes = 0
    for s0 in range(0, n, SCENE_SIZE):
        idx = np.arange(s0, min(n, s0 + SCENE_SIZE))
        sdir = out / split / f"{s0 // SCENE_SIZE:06d}"
        for sub in ("rgb", "depth", "mask", "mask_visib"):
            (sdir / sub).mkdir(parents=True, exist_ok=True)
        cams, gts, infos = {}, {}, {}
        for j, i, rec in image_records(reader, idx):
            im = int(i - s0)
            cv2.imwrite(str(sdir / "rgb" / f"{im:06d}.png"), rec["rgb"][..., ::-1])
            cv2.imwrite(str(sdir / "depth" / f"{im:06d}.png"), rec["depth"])
            for gt in range(len(OBJECTS)):
                cv2.imwrite(str(sdir / "mask" / f"{im:06d}_{gt:06d}.png"), rec["mask"][gt].astype(np.uint8) * 255)
                cv2.imwrite(str(sdir / "mask_visib" / f"{im:06d}_{gt:06d}.png"),
                            rec["mask_visib"][gt].astype(np.uint8) * 255)
            cams[str(im)], gts[str(im)], infos[str(im)] = rec["camera"], rec["gt"], rec["gt_info"]
        _write_json(sdir / "scene_camera.json", cams)
        _write_json(sdir / "scene_gt.json", gts)
        _write_json(sdir / "scene_gt_info.json", infos)
        scenes += 1
    reader.close()
    return {"images": int(n), "scenes": scenes}
