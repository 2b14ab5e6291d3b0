"""``warpworm verify DIR``: re-read every shard of a dataset and check it against its manifest and its own labels.

Checks, per shard: the file is listed in the manifest and exists; its SHA-256 and size equal the manifest's; it opens,
is marked complete and holds sample ids [first, first + count); every dataset of :data:`warpworm.data.dataset.FIELDS` is
there with the documented shape and dtype (and every ``params/*`` has one value per sample); and the label invariants:

* quaternions (``poses/body_quat``) are unit and equal ``poses/body``'s rotation; every rotation (camera, body, IPMs,
  EPM) is orthonormal with det +1, and every pose's last row is (0, 0, 0, 1);
* ``keypoints/camera`` = R ``keypoints/world`` + t; ``keypoints/pixel`` = their projection through K (pinhole, as
  ``cv2.projectPoints`` without distortion); ``keypoints/body`` = ``poses/body``⁻¹ ``keypoints/world``;
  ``camera/position`` = −Rᵀt;
* visibility consistent with depth (docs/render.md's rule): 0 exactly where the keypoint is behind the camera or its
  rounded pixel is outside the image; where the depth there is 0 or at most 0.5 mm in front of the keypoint it is 2;
  1 only where a surface is more than 0.5 mm in front;
* segmentation ids in [0, ids.SEG_EPM] (0..10), depth finite and >= 0.

Exit code 0 only if every check holds; 1 if any fails (one line per problem, naming the shard); 2 if DIR is not a
dataset folder at all.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import h5py
import numpy as np

from warpworm import ids
from warpworm.commands.common import dataset_folder
from warpworm.data import dataset as ds
from warpworm.data.dataset import DatasetError
from warpworm.render.distortion import distort

HELP = "Check a dataset folder: shard checksums, sample ids, shapes and label invariants (exit 0 only if all hold)."

VIS_EPS = 5e-4
"""Depth tolerance [m] of the visibility rule (= warpworm.render.labels.VIS_EPS; docs/render.md)."""
TOL_ROT = 1e-8
"""Orthonormality tolerance of rotations computed on the host in float64 (camera, body frame)."""
TOL_ROT_F32 = 8 * float(np.finfo(np.float32).eps)
"""... and of the magnets' rotations, which come from the simulator's float32 state."""
TOL_M = 1e-9  # [m] frames and keypoints are float64
TOL_PX = 1e-6  # [px]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("dir", help="dataset folder (with manifest.json)")
    parser.add_argument("--max-problems", type=int, default=50, help="stop listing after this many (default 50)")


def _rot_problems(name: str, R: np.ndarray, tol: float = TOL_ROT) -> list[str]:
    R = R.reshape(-1, 3, 3)
    err = np.abs(np.einsum("nji,njk->nik", R, R) - np.eye(3)).max(axis=(1, 2))
    det = np.linalg.det(R)
    out = []
    bad = np.flatnonzero((err > tol) | (np.abs(det - 1) > tol))
    if bad.size:
        out.append(f"{name}: {bad.size} rotation(s) not orthonormal with det +1 (max |RᵀR − I| = {err.max():.3g}, "
                   f"det in [{det.min():.6f}, {det.max():.6f}])")
    return out


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def check_labels(d: dict, H: int, W: int) -> list[str]:
    """Invariants of one shard's label arrays ``d`` (name -> (N, ...)); a list of problems (empty: all hold)."""
    out = []
    K, R, t = d["camera/K"], d["camera/R"], d["camera/t"]
    out += _rot_problems("camera/R", R)
    if not (np.all(K[:, 0, 0] > 0) and np.all(K[:, 1, 1] > 0)):
        out.append("camera/K: fx or fy <= 0")
    pos = -np.einsum("nji,nj->ni", R, t)
    if np.abs(pos - d["camera/position"]).max(initial=0) > TOL_M:
        out.append(f"camera/position != -R^T t (max error {np.abs(pos - d['camera/position']).max():.3g} m)")
    for name in ("poses/body", "poses/epm", "poses/ipm"):
        T = d[name].reshape(-1, 4, 4)
        out += _rot_problems(name, T[:, :3, :3], TOL_ROT if name == "poses/body" else TOL_ROT_F32)
        if not np.array_equal(T[:, 3], np.broadcast_to([0.0, 0.0, 0.0, 1.0], T[:, 3].shape)):
            out.append(f"{name}: last row is not (0, 0, 0, 1)")
    q = d["poses/body_quat"]
    qn = np.linalg.norm(q, axis=-1)
    if np.abs(qn - 1).max(initial=0) > 1e-9:
        out.append(f"poses/body_quat: not unit (| |q| - 1 | up to {np.abs(qn - 1).max():.3g})")
    else:
        e = np.abs(_quat_to_matrix(q) - d["poses/body"][:, :3, :3]).max(initial=0)
        if e > 1e-9:
            out.append(f"poses/body_quat: its rotation differs from poses/body's by up to {e:.3g}")
    kw = d["keypoints/world"]
    kc = np.einsum("nij,npj->npi", R, kw) + t[:, None]
    e = np.abs(kc - d["keypoints/camera"]).max(initial=0)
    if e > TOL_M:
        out.append(f"keypoints/camera != R keypoints/world + t (max error {e:.3g} m)")
    z = kc[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xn, yn = kc[..., 0] / z, kc[..., 1] / z
        if "camera/dist" in d:  # lens distortion (render.distortion): OpenCV's model, warpworm.render.distortion
            xn, yn = distort(xn, yn, d["camera/dist"][:, None, :])
        u = K[:, None, 0, 0] * xn + K[:, None, 0, 1] * yn + K[:, None, 0, 2]
        v = K[:, None, 1, 1] * yn + K[:, None, 1, 2]
    uv = np.stack([u, v], -1)
    front = z > 0
    e = np.abs(uv - d["keypoints/pixel"])[front].max(initial=0)
    if e > TOL_PX:
        out.append(f"keypoints/pixel is not the projection of keypoints/world through K, R, t (max error {e:.3g} px)")
    body = d["poses/body"]
    kb = np.einsum("nij,npj->npi", np.linalg.inv(body), np.concatenate([kw, np.ones(kw.shape[:2] + (1,))], -1))[..., :3]
    e = np.abs(kb - d["keypoints/body"]).max(initial=0)
    if e > TOL_M:
        out.append(f"keypoints/body != poses/body^-1 keypoints/world (max error {e:.3g} m)")
    vis = d["keypoints/visibility"]
    if not np.isin(vis, (0, 1, 2)).all():
        out.append("keypoints/visibility: values outside {0, 1, 2}")
    px, py = np.rint(d["keypoints/pixel"][..., 0]), np.rint(d["keypoints/pixel"][..., 1])
    with np.errstate(invalid="ignore"):
        inside = front & (px >= 0) & (px < W) & (py >= 0) & (py < H)
    n_idx = np.broadcast_to(np.arange(len(vis))[:, None], vis.shape)
    D = np.zeros(vis.shape)
    D[inside] = d["depth"][n_idx[inside], py[inside].astype(np.int64), px[inside].astype(np.int64)]
    bad0 = (vis == 0) != ~inside
    if bad0.any():
        out.append(f"keypoints/visibility: {int(bad0.sum())} keypoint(s) with v = 0 inside the image or v > 0 outside "
                   f"it (first: sample row {int(np.argwhere(bad0)[0][0])})")
    gap = z - D
    must_see = inside & ((D == 0) | (gap <= VIS_EPS))
    bad2 = must_see & (vis != 2)
    if bad2.any():
        out.append(f"keypoints/visibility: {int(bad2.sum())} keypoint(s) marked occluded with nothing more than "
                   f"{VIS_EPS * 1e3:.1f} mm in front in the depth map")
    bad1 = (vis == 1) & ~(inside & (D > 0) & (gap > VIS_EPS))
    if bad1.any():
        out.append(f"keypoints/visibility: {int(bad1.sum())} keypoint(s) marked occluded without a surface in front")
    seg = d["segmentation"]
    if seg.size and seg.max() > ids.SEG_EPM:
        out.append(f"segmentation: id {int(seg.max())} > {ids.SEG_EPM}")
    dep = d["depth"]
    if not np.isfinite(dep).all() or (dep < 0).any():
        out.append("depth: non-finite or negative values")
    return out


def verify_dataset(root, max_problems: int = 50) -> tuple[list[str], dict]:
    """All problems of dataset folder ``root`` (each line starts with the file it concerns), and counts."""

    root = Path(root)
    problems: list[str] = []
    m = ds.read_manifest(root)  # DatasetError if missing / unreadable
    listed = {int(s["index"]): s for s in m["shards"]}
    num_shards = int(m.get("num_shards", len(listed)))
    if not m.get("complete"):
        problems.append(f"{root / ds.MANIFEST}: complete = false (the job did not finish: rerun it with --resume)")
    for k in range(num_shards):
        if k not in listed:
            problems.append(f"{root / ds.MANIFEST}: shard {k} ({ds.shard_name(k)}) is not listed")
    on_disk = sorted(n for n in (p.name for p in root.iterdir()) if ds.SHARD_RE.match(n))
    for n in on_disk:
        if int(ds.SHARD_RE.match(n).group(1)) not in listed:
            problems.append(f"{root / n}: not listed in the manifest")
    samples = 0
    names = None
    for k in sorted(listed):
        s = listed[k]
        path = root / s.get("file", ds.shard_name(k))
        if not path.is_file():
            problems.append(f"{path}: missing (listed in the manifest)")
            continue
        if s.get("bytes") and path.stat().st_size != int(s["bytes"]):
            problems.append(f"{path}: {path.stat().st_size} bytes, the manifest says {s['bytes']} (truncated?)")
        if not s.get("sha256"):
            problems.append(f"{path}: the manifest has no sha256 for it (written by an older warpworm?)")
        why = ds.shard_problem(path, int(s["first_sample"]), int(s["count"]), sha256=s.get("sha256") or None)
        if why is not None:
            problems.append(f"{path}: {why}")
            continue
        try:
            with h5py.File(path, "r") as f:
                N = int(f.attrs["count"])
                P = len(json.loads(f.attrs["keypoint_names"]))
                dims = {"N": N, "P": P, "C": len(f.attrs["crease_hinges"]), "E": len(f.attrs["bar_edges"])}
                if "rgb" in f:
                    dims["H"], dims["W"] = f["rgb"].shape[1:3]
                if "worm/vertices" in f:
                    dims["V"] = f["worm/vertices"].shape[1]
                data = {}
                for fld in ds.FIELDS:
                    if fld.name not in f:
                        problems.append(f"{path}: dataset {fld.name} missing")
                        continue
                    dset = f[fld.name]
                    want = ds.resolve_shape(fld, dims) if all(not isinstance(x, str) or x in dims
                                                               for x in fld.shape) else None
                    if want is not None and dset.shape != want:
                        problems.append(f"{path}: {fld.name} has shape {dset.shape}; expected {want} {fld.shape}")
                    if str(dset.dtype) != fld.dtype:
                        problems.append(f"{path}: {fld.name} has dtype {dset.dtype}; expected {fld.dtype}")
                    data[fld.name] = dset[...]
                pnames = json.loads(f.attrs["params_names"])
                for pn in pnames:
                    if f"params/{pn}" not in f or f[f"params/{pn}"].shape != (N,):
                        problems.append(f"{path}: params/{pn} missing or not ({N},)")
                if names is None:
                    names = pnames
                if len(data) == len(ds.FIELDS):
                    if "camera/dist" in f:  # written only with render.distortion
                        data["camera/dist"] = f["camera/dist"][...]
                    problems += [f"{path}: {p}" for p in check_labels(data, dims["H"], dims["W"])]
                samples += N
        except (OSError, KeyError, ValueError) as exc:
            problems.append(f"{path}: unreadable ({type(exc).__name__}: {str(exc)[:160]})")
        if len(problems) >= max_problems:
            break
    if samples != int(m.get("num_samples", samples)) and not problems:
        problems.append(f"{root / ds.MANIFEST}: {samples} samples in the shards, num_samples = {m['num_samples']}")
    return problems[:max_problems], {"shards": len(listed), "samples": samples}


def main(args: argparse.Namespace) -> int:
    try:
        dataset_folder(args.dir)
        problems, counts = verify_dataset(args.dir, args.max_problems)
    except (DatasetError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    for p in problems:
        print(p)
    if problems:
        bad = sorted({p.split(":")[0] for p in problems})
        print(f"verify: {len(problems)} problem(s) in {', '.join(Path(b).name for b in bad)}; a damaged shard is "
              "deleted and written again by the job's command with --resume", file=sys.stderr)
        return 1
    print(f"verify: {args.dir}: {counts['samples']} samples in {counts['shards']} shard(s): checksums, sample ids, "
          "shapes and label invariants all hold")
    return 0
