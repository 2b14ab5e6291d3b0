"""Learnability benchmark (issue 24): does what a small network learns from our images transfer to another renderer?

Trains a small CNN (keypoints by soft-argmax heatmaps, crease angles, the four deformation ratios) for a fixed budget
of optimizer steps (deterministic for a seed; ``--budget-s`` adds a wall-clock cap) on one dataset, then reports on a held-out set of another seed with a shifted camera and light, rendered twice: by
the rasterizer (in-domain) and by the path-traced engine (``render.engine: pathtraced``: the same scenes, cameras,
colours and lights, the same labels). Reads the HDF5 shards with h5py only; torch (CPU) is the ``torch`` extra.

Metrics per test set: keypoint error [px] on visible keypoints, PCK@5, head/tail swap rate (the prediction is nearer
the ground truth turned half a turn about the body's vertical axis), the head/tail-agnostic keypoint error (the
better of the two), body rotation error by PnP (cv2.solvePnP of the predicted pixels against the training mean of
``keypoints/body``; median), crease-angle and deformation-ratio MAE against predicting the training mean (the crease
ratio also over the creases seen and not seen, both faces visible by the label depth, and by thirds of the image
scale at the worm, px/m). Goals
(issue 24): cross-engine agnostic keypoint error <= 1.5x in-domain; swap rate equal within 5 points; crease MAE
<= 0.6x the mean baseline in-domain.

Three readers of the folds beyond the defaults (docs/dataset.md, "Where production's creases are"): ``--head
triangles`` also samples the features at every mesh triangle, placed from the predicted keypoints; ``--crop S`` reads
an S x S crop around the worm's box (top-down, COCO's protocol with ground-truth boxes) instead of the whole image;
``--heatmap-stride 2`` puts the heatmaps on a learned 2x upsampling (finer keypoints).

    pip install torch  # CPU wheel is enough
    python benchmarks/pose_baseline.py --config default     # 3072 train / 192 test at 128^2, 3000 steps
    python benchmarks/pose_baseline.py --data out/pose_bench --skip-generate     # reuse generated datasets

Writes benchmarks/results/pose_baseline.json and prints a table (docs/dataset.md, "Learnability benchmark").
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import cv2
import h5py
import numpy as np

from warpworm.render.distortion import distort, undistort

TEST_SHIFT = ["randomize.camera.distance={uniform: [0.16, 0.24]}", "randomize.light.intensity={uniform: [0.4, 0.7]}",
              "randomize.light.ambient={uniform: [0.1, 0.25]}"]
"""The held-out set's shift: cameras farther (default 0.12-0.2 m), light dimmer (0.6-1.0, ambient 0.15-0.35)."""


# ---------------------------------------------------------------------------------------------------------------------
# data
def generate_sets(a) -> dict[str, Path]:
    """train (seed a.seed), test (seed a.seed + 1000, shifted) and test_pt (the same scenes path-traced)."""
    root = Path(a.data)
    size = [f"render.width={a.size}", f"render.height={a.size}", "output.preview=false"] + list(a.set or [])
    sets = {"train": (a.seed, a.train_num, []),
            "test": (a.seed + 1000, a.test_num, TEST_SHIFT),
            "test_pt": (a.seed + 1000, a.test_num, TEST_SHIFT + ["render.engine=pathtraced",
                                                                 f"render.pathtraced_spp={a.spp}"])}
    out = {}
    for name, (seed, num, extra) in sets.items():
        out[name] = root / name
        if a.skip_generate:
            continue
        cmd = [sys.executable, "-m", "warpworm", "generate", a.config, "--out", str(out[name]), "--num", str(num),
               "--seed", str(seed), "--workers", str(a.workers), *size, *extra]
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
        print(f"generated {name}: {num} samples in {time.perf_counter() - t0:.0f} s", flush=True)
    return out


SEEN_KEYS = ("worm/vertices", "depth", "camera/dist")
"""What :func:`creases_seen` reads besides the camera: the test sets load them (``load(root, SEEN_KEYS)``)."""


def load(root: Path, extra: tuple = ()) -> dict[str, np.ndarray]:
    """Every array the benchmark needs (and ``extra``), concatenated over the shards (h5py only)."""
    keys = ("rgb", "keypoints/pixel", "keypoints/visibility", "keypoints/body", "camera/K", "camera/R", "camera/t",
            "poses/body", "creases/angle", "labels/deformation", "labels/bbox_obj", "sample_id") + tuple(extra)
    parts: dict[str, list] = {k: [] for k in keys}
    names = hinges = None
    for p in sorted(root.glob("shard-*.h5")):
        with h5py.File(p, "r") as f:
            names, hinges = json.loads(f.attrs["keypoint_names"]), np.asarray(f.attrs["crease_hinges"])
            triangles = np.asarray(f.attrs["mesh_triangles"])
            for k in keys:
                if k in f or k not in extra:  # an optional extra (camera/dist: lens distortion off) may be absent
                    parts[k].append(f[k][...])
    d = {k: np.concatenate(v) for k, v in parts.items() if v}
    d["names"], d["crease_hinges"], d["mesh_triangles"] = names, hinges, triangles
    return d


CROP_MARGIN = 1.15
"""A crop's side over the longer side of the worm's box (``labels/bbox_obj``)."""
CROP_JITTER = 0.05
"""The training crops' box jitter (scale, log-normal; centre, in units of the side): a detector's box is not exact."""


def crop_to_worm(d: dict, side: int, rng: np.random.Generator | None = None, jitter: float = 0.0,
                 rotate: float = 0.0, turn: float | None = None) -> dict:
    """The top-down view of ``d``: each image resampled (bilinear) to a ``side`` x ``side`` crop of the square around
    the worm's box ``labels/bbox_obj`` (CROP_MARGIN x its longer side; with ``rng``, its scale and centre jittered by
    ``jitter``, log-normal / in units of the side, as a detector's box would be), keypoints and intrinsics mapped into
    the crop (pixel centres at integers: u = x0 + (j + 0.5) s / side - 0.5), keypoints outside it marked unseen.
    Evaluating with the label's box is COCO's top-down keypoint protocol with ground-truth boxes. The depth is
    dropped (the seen / unseen crease split needs the full image). With ``rng`` and ``rotate`` [rad], each crop is
    also turned in the image plane by a uniform angle in [-rotate, rotate] about its centre (a training
    augmentation), or by ``turn`` [rad] each (test-time augmentation); a turned crop has no pinhole K, so
    ``camera/K`` is dropped too."""
    import torch  # optional dependency: torch

    box = d["labels/bbox_obj"].astype(np.float64)
    c = box[:, :2] + box[:, 2:] / 2
    s = np.maximum(CROP_MARGIN * box[:, 2:].max(1), 16.0)
    if rng is not None and jitter:
        s = s * np.exp(rng.normal(0.0, jitter, len(s)))
        c = c + rng.normal(0.0, jitter, c.shape) * s[:, None]
    x0 = c - s[:, None] / 2  # native coordinates of the crop's outer corner
    phi = rng.uniform(-rotate, rotate, len(c)) if (rng is not None and rotate) else None
    if turn is not None:
        phi = np.full(len(c), float(turn))
    H, W = d["rgb"].shape[1:3]
    j = (np.arange(side) + 0.5) / side
    out = np.empty((len(c), side, side, 3), np.uint8)
    for a in range(0, len(c), 128):
        b = slice(a, a + 128)
        if phi is None:
            u = x0[b, 0, None] + j * s[b, None] - 0.5  # sample points' native pixel coordinates
            v = x0[b, 1, None] + j * s[b, None] - 0.5
            gx, gy = np.broadcast_arrays(((2 * u + 1) / W - 1)[:, None, :], ((2 * v + 1) / H - 1)[:, :, None])
        else:  # the offset from the centre, (j - 1/2) s, turned by phi
            cs, sn = np.cos(phi[b])[:, None, None], np.sin(phi[b])[:, None, None]
            ox, oy = (j[None, None, :] - 0.5) * s[b, None, None], (j[None, :, None] - 0.5) * s[b, None, None]
            u = c[b, 0, None, None] + cs * ox - sn * oy - 0.5
            v = c[b, 1, None, None] + sn * ox + cs * oy - 0.5
            gx, gy = (2 * u + 1) / W - 1, (2 * v + 1) / H - 1
        img = torch.from_numpy(d["rgb"][b]).permute(0, 3, 1, 2).float()
        crop = torch.nn.functional.grid_sample(img, torch.from_numpy(np.stack([gx, gy], -1)).float(),
                                               align_corners=False)
        out[b] = crop.round().clamp(0, 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
    f = side / s
    e = {k: v for k, v in d.items() if k != "depth"}
    e["rgb"] = out
    if phi is None:
        e["keypoints/pixel"] = (d["keypoints/pixel"] + 0.5 - x0[:, None]) * f[:, None, None] - 0.5
        K = d["camera/K"].copy()
        K[:, :2, :2] *= f[:, None, None]
        K[:, :2, 2] = (d["camera/K"][:, :2, 2] + 0.5 - x0) * f[:, None] - 0.5
        e["camera/K"] = K
    else:  # the offset turned back by -phi, in crop pixels
        o = d["keypoints/pixel"] + 0.5 - c[:, None]
        cs, sn = np.cos(phi)[:, None], np.sin(phi)[:, None]
        e["keypoints/pixel"] = (np.stack([cs * o[..., 0] + sn * o[..., 1], -sn * o[..., 0] + cs * o[..., 1]], -1)
                                * f[:, None, None] + side / 2 - 0.5)
        e.pop("camera/K", None)
    kp = e["keypoints/pixel"]
    outside = ((kp < -0.5) | (kp > side - 0.5)).any(-1)
    e["keypoints/visibility"] = np.where(outside, 0, d["keypoints/visibility"]).astype(d["keypoints/visibility"].dtype)
    return e


def faces_seen(d: dict, tris: np.ndarray, depth_tol: float = 2.5e-4) -> np.ndarray:
    """(N, T) bool: triangle t (vertex indices ``tris[t]`` into ``worm/vertices``) is in view at the pixel of its
    centroid: the label depth there is the depth of the triangle's own plane along that pixel's ray (within
    ``depth_tol`` [m]), not nearer (hidden under the worm, behind a fold or a distractor), and the triangle is not
    edge-on (|cos| > 0.05 between its normal and the ray). In view, the label depth is the plane's to 0.02 mm (the
    exact pixel centres of the rasterizer's depth pass); hidden, millimetres off: the tolerance sits between."""
    N = len(d["depth"])
    h, w = d["depth"].shape[1:]
    V = d["worm/vertices"].astype(np.float64)
    R, K = d["camera/R"], d["camera/K"]
    dist = (d["camera/dist"] if "camera/dist" in d else np.zeros((N, 5)))[:, None]  # (N, 1, 5)
    fx, fy, cx, cy = (K[:, 0, 0, None], K[:, 1, 1, None], K[:, 0, 2, None], K[:, 1, 2, None])
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    nrm = np.einsum("nij,ncj->nci", R, np.cross(V[:, b] - V[:, a], V[:, c] - V[:, a]))  # camera frame
    cen = np.einsum("nij,ncj->nci", R, (V[:, a] + V[:, b] + V[:, c]) / 3.0) + d["camera/t"][:, None]
    xd, yd = distort(cen[..., 0] / cen[..., 2], cen[..., 1] / cen[..., 2], dist)
    iu, iv = np.round(fx * xd + cx).astype(int), np.round(fy * yd + cy).astype(int)  # the centroid's pixel
    rx, ry, _ = undistort((iu - cx) / fx, (iv - cy) / fy, dist)  # that pixel centre's ray (z = 1)
    ray = np.stack([rx, ry, np.ones_like(rx)], -1)
    along = (nrm * ray).sum(-1)
    cos = np.abs(along) / (np.linalg.norm(nrm, axis=-1) * np.linalg.norm(ray, axis=-1))
    z_plane = (nrm * cen).sum(-1) / np.where(cos > 0.05, along, 1.0)
    inside = (iu >= 0) & (iu < w) & (iv >= 0) & (iv < h)
    z = d["depth"][np.arange(N)[:, None], np.clip(iv, 0, h - 1), np.clip(iu, 0, w - 1)]
    return (cos > 0.05) & inside & (np.abs(z - z_plane) < depth_tol)


def creases_seen(d: dict, depth_tol: float = 2.5e-4) -> np.ndarray:
    """(N, C) bool: both triangles of crease c (stencil (i, j, k, l), shared edge j-k: triangles (i, j, k) and
    (j, l, k)) are in view (:func:`faces_seen`). A crease with a face out of view shows its angle to no camera."""
    H = d["crease_hinges"]
    return faces_seen(d, H[:, [0, 1, 2]], depth_tol) & faces_seen(d, H[:, [1, 3, 2]], depth_tol)


def triangle_weights(d: dict, k: int = 8, ridge: float = 1e-2) -> np.ndarray:
    """(T, P) affine weights (rows sum to 1) that place each mesh triangle's centroid from the P keypoints: a ridge
    fit (``ridge``, in units of the body's RMS size) over its k nearest keypoints on the training set's mean
    body-frame shape. ``W @ uv`` then puts a point on every panel from keypoints alone: from the exact ones, within
    0.8 px (median; 90 %: 2.9 px) of the centroid's projection at production's 128², 1.6 px (3.8 px) on the default
    config's nearer views (the affine approximation of the perspective, and the folds' own motion). The ridge keeps
    the weights small where the nearest keypoints are near-collinear (least norm: up to 13, which multiplies the
    keypoints' errors). Reads ``worm/vertices``, ``poses/body``, ``keypoints/body`` and ``mesh_triangles``."""
    Rb, tb = d["poses/body"][:, :3, :3], d["poses/body"][:, :3, 3]
    body = np.einsum("nji,ncj->nci", Rb, d["worm/vertices"].astype(np.float64) - tb[:, None])
    centroids = body[:, d["mesh_triangles"]].mean(2).mean(0)  # (T, 3)
    kp = d["keypoints/body"].mean(0)  # (P, 3)
    scale = np.sqrt(((kp - kp.mean(0)) ** 2).sum(1).mean())  # [m]: the fit in units of the body's size
    W = np.zeros((len(centroids), len(kp)))
    for t, c in enumerate(centroids):
        near = np.argsort(np.linalg.norm(kp - c, axis=1))[:k]
        A = np.r_[(kp[near] - c).T / scale, 10.0 * np.ones((1, len(near)))]  # x, y, z about c; the sum, stiffly
        W[t, near] = np.linalg.solve(A.T @ A + ridge * np.eye(len(near)), A.T @ np.r_[0.0, 0.0, 0.0, 10.0])
    return W


def flip_permutation(names: list[str]) -> np.ndarray:
    """Keypoint index under the half turn about the body's vertical axis: head <-> tail, left <-> right."""
    def turned(n: str) -> str:
        if n.startswith("seg"):
            return f"seg{4 - int(n[3:])}"
        n = n.replace("tail", "#").replace("head", "tail").replace("#", "head")
        return n.replace("left", "#").replace("right", "left").replace("#", "right")
    return np.array([names.index(turned(n)) for n in names])


# ---------------------------------------------------------------------------------------------------------------------
# model
def build_model(num_kp: int, num_reg: int, size: int, net_size: int | None = None, head: str = "keypoints",
                tri_w: np.ndarray | None = None, heat_stride: int = 4):
    import torch  # optional dependency: torch
    from torch import nn  # optional dependency: torch

    def block(cin, cout, stride):
        return nn.Sequential(nn.Conv2d(cin, cout, 3, stride, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
                             nn.Conv2d(cout, cout, 3, 1, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True))

    class Net(nn.Module):
        """Stride-4 feature map -> keypoint heatmaps (soft-argmax to pixels); creases + ratios from the globally
        pooled deep features (``head="global"``) or, by default (``head="keypoints"``), also from the stride-4
        features pooled under each keypoint's heatmap and the predicted keypoints' normalized 2-D layout: a fold
        shows as the shading and outline of the panels next to the keypoints, which a global average washes out.
        ``head="triangles"`` adds 16 features sampled (bilinearly) at every mesh triangle's image point, placed from
        the predicted keypoints by ``tri_w`` (:func:`triangle_weights`): the panels' shading, read where each is.
        ``heat_stride=2``: the heatmaps on a learned 2x upsampling of the stride-4 map (a transposed convolution and
        a 3x3 block), cells of 2 network pixels, for keypoints finer than a 4-pixel cell's soft-argmax gives."""

        def __init__(self):
            super().__init__()
            # a 4x4 patch stem (stride 4: a quarter of the MACs of two stride-2 blocks; CPU-sized), then 3x3 blocks
            stem = nn.Sequential(nn.Conv2d(3, 32, 4, 4, bias=False), nn.BatchNorm2d(32), nn.ReLU(inplace=True))
            self.body = nn.Sequential(stem, block(32, 48, 1))
            self.deep = nn.Sequential(block(48, 64, 2), block(64, 96, 2), nn.AdaptiveAvgPool2d(1), nn.Flatten())
            if heat_stride == 2:
                self.up = nn.Sequential(nn.ConvTranspose2d(48, 32, 4, 2, 1, bias=False), nn.BatchNorm2d(32),
                                        nn.ReLU(inplace=True), nn.Conv2d(32, 32, 3, 1, 1, bias=False),
                                        nn.BatchNorm2d(32), nn.ReLU(inplace=True))
            else:
                self.up = nn.Identity()
            self.heat = nn.Conv2d(32 if heat_stride == 2 else 48, num_kp, 1)
            self.head = head
            n_in = 96 + (num_kp * (48 + 2) if head in ("keypoints", "triangles") else 0)
            if head == "triangles":
                self.register_buffer("tri_w", torch.tensor(tri_w, dtype=torch.float32))
                self.tri_feat = nn.Conv2d(48, 16, 1)
                n_in += len(tri_w) * 16
            self.reg = nn.Sequential(nn.Linear(n_in, 256), nn.ReLU(inplace=True), nn.Linear(256, num_reg))
            self.pool = max(1, size // (net_size or size))  # the network sees size / pool pixels (area average)
            self.stride = self.pool * float(heat_stride)  # native pixels per heatmap cell
            self.heat_stride = heat_stride

        def forward(self, x):
            if self.pool > 1:
                x = nn.functional.avg_pool2d(x, self.pool)
            f = self.body(x)
            h = self.heat(self.up(f))
            n, k, hh, ww = h.shape
            logp = torch.log_softmax(h.reshape(n, k, -1), dim=-1)
            p = logp.exp().reshape(n, k, hh, ww)
            xs = (torch.arange(ww, dtype=x.dtype) + 0.5) * self.stride - 0.5  # feature cell centre in pixels
            ys = (torch.arange(hh, dtype=x.dtype) + 0.5) * self.stride - 0.5
            uv = torch.stack([(p.sum(2) * xs).sum(-1), (p.sum(3) * ys).sum(-1)], dim=-1)
            self.cells = (xs, ys)
            z = self.deep(f)
            if self.head in ("keypoints", "triangles"):
                p4 = p if self.heat_stride == 4 else nn.functional.avg_pool2d(p, 2) * 4.0  # the mass per stride-4 cell
                at_kp = torch.einsum("nkhw,nchw->nkc", p4, f).reshape(n, -1)  # features under each heatmap
                rel = uv - uv.mean(1, keepdim=True)  # the 2-D layout, translation and scale removed
                rel = rel / rel.pow(2).sum(-1).mean(1).sqrt().clamp(min=1e-3)[:, None, None]
                z = torch.cat([z, at_kp, rel.reshape(n, -1)], dim=1)
            if self.head == "triangles":  # grid_sample's [-1, 1] spans the feature map's outer cell edges
                pts = torch.einsum("tp,npc->ntc", self.tri_w, uv.detach())  # (n, T, 2) native px
                grid = torch.stack([(pts[..., 0] + 0.5) / (ww * self.stride), (pts[..., 1] + 0.5) / (hh * self.stride)],
                                   -1) * 2.0 - 1.0
                at_tri = nn.functional.grid_sample(self.tri_feat(f), grid[:, :, None], align_corners=False)
                z = torch.cat([z, at_tri.reshape(n, -1)], dim=1)
            return uv, self.reg(z), logp

    return Net()


def _targets(d: dict, stats: dict):
    creases = (d["creases/angle"] - stats["crease_mean"]) / stats["crease_std"]
    ratios = (d["labels/deformation"] - stats["ratio_mean"]) / stats["ratio_std"]
    return np.concatenate([creases, ratios], axis=1).astype(np.float32)


def heatmap_ce(logp, kp, xs, ys, sigma: float):
    """Cross-entropy of the predicted cell distribution ``logp`` (n, k, cells) against a Gaussian of ``sigma`` [px]
    around each true keypoint ``kp`` (n, k, 2) [px] on the cell centres ``xs``, ``ys``: (n, k). Supervises every cell
    directly (faster to learn from scratch than the soft-argmax's coordinate alone)."""
    import torch  # optional dependency: torch

    d2 = (xs[None, None, None, :] - kp[..., 0, None, None]) ** 2 + (ys[None, None, :, None] - kp[..., 1, None, None]) ** 2
    t = torch.softmax(-d2.reshape(*kp.shape[:2], -1) / (2 * sigma**2), dim=-1)
    return -(t * logp).sum(-1)


CROP_KEYS = ("rgb", "keypoints/pixel", "keypoints/visibility", "camera/K", "labels/bbox_obj")
"""What :func:`crop_to_worm` reads for a training batch."""
AUG_EXPOSURE, AUG_WHITE = 0.2, 0.05
"""``--augment``: log-normal gains of an image (exposure) and of each of its channels (white balance)."""

KP_SCALE = 8.0
"""[px] per unit of the keypoint L1 loss (brings pixels to the heatmap loss's scale)."""


def train(d: dict, a) -> tuple[object, dict, dict]:
    """AdamW for ``--steps`` steps (or until ``--budget-s``), cosine-decayed: heatmap cross-entropy + 0.5 x the L1 of
    the soft-argmax pixels / KP_SCALE on in-image keypoints, + ``--reg-weight`` x L1 on the normalized creases and
    ratios. With ``--augment --crop S``, ``d`` holds the native images and every batch is cropped afresh."""
    import torch  # optional dependency: torch

    torch.manual_seed(a.seed)
    torch.set_num_threads(a.threads)
    stats = {"crease_mean": d["creases/angle"].mean(0), "crease_std": d["creases/angle"].std(0) + 1e-6,
             "ratio_mean": d["labels/deformation"].mean(0), "ratio_std": d["labels/deformation"].std(0) + 1e-6}
    n = len(d["rgb"])
    # uint8, normalized per batch; --augment --crop crops the native images afresh and needs no channel-first copy
    x = None if a.augment and a.crop else torch.from_numpy(d["rgb"]).permute(0, 3, 1, 2).contiguous()
    kp = torch.from_numpy(d["keypoints/pixel"].astype(np.float32))
    w = torch.from_numpy((d["keypoints/visibility"] > 0).astype(np.float32))
    arng, tgen = np.random.default_rng(a.seed + 1), torch.Generator().manual_seed(a.seed + 1)

    def batch(idx):
        """The images [-1, 1], keypoints [px] and their weights of one batch; with ``--augment``, each image
        cropped afresh (``--crop``: box jitter and an in-plane turn) and its exposure and white balance drawn."""
        if not a.augment:
            return x[idx].float() / 127.5 - 1.0, kp[idx], w[idx]
        if a.crop:
            e = crop_to_worm({k: d[k][idx] for k in CROP_KEYS}, a.crop, arng, CROP_JITTER,
                             np.radians(a.augment_turn))
            xb = torch.from_numpy(e["rgb"]).permute(0, 3, 1, 2).float()
            kb = torch.from_numpy(e["keypoints/pixel"].astype(np.float32))
            wb = torch.from_numpy((e["keypoints/visibility"] > 0).astype(np.float32))
        else:
            xb, kb, wb = x[idx].float(), kp[idx], w[idx]
        gain = torch.exp(AUG_EXPOSURE * torch.randn(len(idx), 1, 1, 1, generator=tgen)
                         + AUG_WHITE * torch.randn(len(idx), 3, 1, 1, generator=tgen))
        return (xb * gain / 127.5 - 1.0).clamp(-1.0, 1.0), kb, wb
    reg = torch.from_numpy(_targets(d, stats))
    model = build_model(kp.shape[1], reg.shape[1], a.size, a.net_size, a.head,
                        triangle_weights(d) if a.head == "triangles" else None, a.heatmap_stride)
    opt = torch.optim.AdamW(model.parameters(), lr=2e-3, weight_decay=1e-4)
    # cosine decay over the step budget: the last epochs average out the batch noise instead of jumping on it
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda i: 0.5 * (1.0 + np.cos(np.pi * min(i / a.steps, 1.0))))
    rng = np.random.default_rng(a.seed)
    t0, steps, epochs, log = time.perf_counter(), 0, 0, []
    def done():  # the fixed budget: optimizer steps (reproducible on any machine), capped by wall time if given
        return steps >= a.steps or (a.budget_s is not None and time.perf_counter() - t0 >= a.budget_s)

    while not done():
        model.train()
        for idx in np.array_split(rng.permutation(n), max(1, n // a.batch)):
            xb, kb, wb = batch(idx)
            uv, r, logp = model(xb)
            l_kp = ((uv - kb).abs().sum(-1) * wb).sum() / wb.sum().clamp(min=1) / KP_SCALE
            l_heat = (heatmap_ce(logp, kb, *model.cells, model.stride) * wb).sum() / wb.sum().clamp(min=1)
            l_reg = (r - reg[idx]).abs().mean()
            loss = l_heat + 0.5 * l_kp + a.reg_weight * l_reg
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            steps += 1
            if done():
                break
        epochs += 1
        log.append({"epoch": epochs, "s": round(time.perf_counter() - t0, 1), "kp_loss_px": float(l_kp.detach()) * KP_SCALE,
                    "reg_loss": float(l_reg.detach())})
        print(f"epoch {epochs}: {log[-1]['s']} s, keypoint L1 {log[-1]['kp_loss_px']:.2f} px, "
              f"creases+ratios L1 {log[-1]['reg_loss']:.3f} (normalized)", flush=True)
    return model, stats, {"steps": steps, "epochs": epochs, "train_s": round(time.perf_counter() - t0, 1),
                          "log": log}


def predict(model, d: dict, stats: dict):
    import torch  # optional dependency: torch

    model.eval()
    uvs, regs = [], []
    with torch.no_grad():
        for i in range(0, len(d["rgb"]), 64):
            x = torch.from_numpy(d["rgb"][i:i + 64]).permute(0, 3, 1, 2).float() / 127.5 - 1.0
            uv, r, _ = model(x)
            uvs.append(uv.numpy())
            regs.append(r.numpy())
    uv, r = np.concatenate(uvs).astype(np.float64), np.concatenate(regs).astype(np.float64)
    C = len(stats["crease_mean"])
    creases = r[:, :C] * stats["crease_std"] + stats["crease_mean"]
    ratios = r[:, C:] * stats["ratio_std"] + stats["ratio_mean"]
    return uv, creases, ratios


def predict_turned(model, d: dict, stats: dict, side: int, turns: int):
    """:func:`predict` on ``turns`` crops of each image turned by 2 pi k / turns (test-time augmentation of a
    network trained with ``--augment``): creases and ratios averaged, keypoints turned back into the unturned crop
    (a turn about the crop's centre) and the per-coordinate median taken (robust to one view's head/tail swap)."""
    uvs, crs, rts = [], [], []
    for k in range(turns):
        phi = 2.0 * np.pi * k / turns
        uv, cr, rt = predict(model, crop_to_worm(d, side, turn=phi), stats)
        o = uv + 0.5 - side / 2
        cs, sn = np.cos(phi), np.sin(phi)
        uvs.append(np.stack([cs * o[..., 0] - sn * o[..., 1], sn * o[..., 0] + cs * o[..., 1]], -1) + side / 2 - 0.5)
        crs.append(cr)
        rts.append(rt)
    return np.median(uvs, axis=0), np.mean(crs, axis=0), np.mean(rts, axis=0)


# ---------------------------------------------------------------------------------------------------------------------
# metrics
def pnp_rotation_errors(uv: np.ndarray, d: dict, body_model: np.ndarray) -> np.ndarray:
    """Angle [deg] between the body rotation in the camera frame from cv2.solvePnP (predicted pixels of in-image
    keypoints, 3-D points = the training mean of keypoints/body) and the true one; NaN where PnP fails."""
    out = np.full(len(uv), np.nan)
    for i in range(len(uv)):
        m = d["keypoints/visibility"][i] > 0
        if m.sum() < 6:
            continue
        ok = False
        for flags in (cv2.SOLVEPNP_SQPNP, cv2.SOLVEPNP_EPNP):  # SQPnP refuses clustered points: EPnP then
            try:  # object points in mm (the rotation does not depend on the scale)
                ok, rvec, _ = cv2.solvePnP(1e3 * body_model[m], uv[i][m], d["camera/K"][i], None, flags=flags)
            except cv2.error:
                ok = False
            if ok:
                break
        if not ok:
            continue
        R_pred = cv2.Rodrigues(rvec)[0]
        R_true = d["camera/R"][i] @ d["poses/body"][i][:3, :3]
        c = (np.trace(R_pred.T @ R_true) - 1.0) / 2.0
        out[i] = np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))
    return out


def evaluate(uv, creases, ratios, d: dict, flip: np.ndarray, train_stats: dict, body_model: np.ndarray) -> dict:
    vis = d["keypoints/visibility"] == 2
    gt = d["keypoints/pixel"]
    err = np.linalg.norm(uv - gt, axis=-1)
    err_flip = np.linalg.norm(uv - gt[:, flip], axis=-1)
    nv = vis.sum(1)
    ok = nv >= 4
    per = (err * vis).sum(1) / np.maximum(nv, 1)
    per_flip = (err_flip * vis).sum(1) / np.maximum(nv, 1)
    swapped = per_flip < per
    agnostic = np.where(swapped[:, None], err_flip, err)
    rot = pnp_rotation_errors(uv, d, body_model)
    c_abs = np.degrees(np.abs(creases - d["creases/angle"]))
    c_abs_base = np.degrees(np.abs(train_stats["crease_mean"] - d["creases/angle"]))
    c_err, c_base = c_abs.mean(), c_abs_base.mean()
    seen = creases_seen(d) if "depth" in d else None
    r_err = np.abs(ratios - d["labels/deformation"]).mean()
    r_base = np.abs(train_stats["ratio_mean"] - d["labels/deformation"]).mean()
    mean_pos = np.linalg.norm(train_stats["kp_mean"][None] - gt, axis=-1)
    return {
        "images": int(len(uv)), "kp_err_px": float(err[vis].mean()), "kp_err_agnostic_px": float(agnostic[vis].mean()),
        "kp_err_mean_position_px": float(mean_pos[vis].mean()), "pck5": float((err[vis] <= 5.0).mean()),
        "swap_rate": float(swapped[ok].mean()), "pnp_rot_median_deg": float(np.nanmedian(rot)),
        "pnp_failed": int(np.isnan(rot).sum()), "crease_mae_deg": float(c_err), "crease_mae_mean_baseline_deg":
        float(c_base), "ratio_mae": float(r_err), "ratio_mae_mean_baseline": float(r_base),
        **({} if seen is None else {
            "creases_seen_fraction": float(seen.mean()),
            "crease_ratio_seen": float(c_abs[seen].mean() / c_abs_base[seen].mean()),
            "crease_ratio_unseen": float(c_abs[~seen].mean() / c_abs_base[~seen].mean())}),
        "crease_ratio_by_view_scale": _by_view_scale(c_abs.mean(1), c_abs_base.mean(1), d)}


def _by_view_scale(err: np.ndarray, base: np.ndarray, d: dict) -> list[float]:
    """Crease MAE over the mean baseline in the thirds of the test set by the image scale at the worm, fx over the
    depth of the body's origin [px/m] (far or wide views to near or narrow ones): whether the views that show the
    worm larger show its folds better. Not the worm's length in pixels: a contracted worm is shorter, so that would
    sort by the fold itself."""
    origin = d["poses/body"][:, :3, 3]
    depth = np.einsum("nij,nj->ni", d["camera/R"], origin)[:, 2] + d["camera/t"][:, 2]
    thirds = np.array_split(np.argsort(d["camera/K"][:, 0, 0] / depth, kind="stable"), 3)
    return [float(err[i].mean() / base[i].mean()) for i in thirds]


# ---------------------------------------------------------------------------------------------------------------------
def table(res: dict) -> str:
    rows = [("keypoint error, visible [px]", "kp_err_px", "{:.2f}"),
            ("  head/tail-agnostic [px]", "kp_err_agnostic_px", "{:.2f}"),
            ("  mean-position baseline [px]", "kp_err_mean_position_px", "{:.2f}"),
            ("PCK@5", "pck5", "{:.3f}"), ("head/tail swapped", "swap_rate", "{:.1%}"),
            ("body rotation by PnP, median [deg]", "pnp_rot_median_deg", "{:.1f}"),
            ("crease MAE [deg]", "crease_mae_deg", "{:.2f}"),
            ("  training-mean baseline [deg]", "crease_mae_mean_baseline_deg", "{:.2f}"),
            ("  creases seen (both faces visible)", "creases_seen_fraction", "{:.1%}"),
            ("  crease MAE / baseline, seen creases", "crease_ratio_seen", "{:.3f}"),
            ("  crease MAE / baseline, unseen creases", "crease_ratio_unseen", "{:.3f}"),
            ("  crease MAE / baseline by thirds of the image scale at the worm", "crease_ratio_by_view_scale", "{}"),
            ("deformation-ratio MAE", "ratio_mae", "{:.4f}"),
            ("  training-mean baseline", "ratio_mae_mean_baseline", "{:.4f}")]
    sets = [k for k in ("test", "test_pt") if k in res]
    head = "| metric | " + " | ".join({"test": "rasterized (in-domain)", "test_pt": "path-traced"}[s] for s in sets)
    lines = [head + " |", "|---" * (len(sets) + 1) + "|"]
    for label, key, fmt in rows:
        if all(key in res[s] for s in sets):
            cell = (lambda v: " / ".join(f"{x:.3f}" for x in v)) if fmt == "{}" else fmt.format
            lines.append(f"| {label} | " + " | ".join(cell(res[s][key]) for s in sets) + " |")
    return "\n".join(lines)


def goals(res: dict) -> dict:
    t, p = res["test"], res.get("test_pt")
    g = {"crease_mae_ratio_to_baseline": t["crease_mae_deg"] / t["crease_mae_mean_baseline_deg"]}
    g["crease_goal_met (<= 0.6)"] = bool(g["crease_mae_ratio_to_baseline"] <= 0.6)
    if p is not None:
        g["cross_engine_kp_ratio"] = p["kp_err_agnostic_px"] / t["kp_err_agnostic_px"]
        g["cross_engine_goal_met (<= 1.5)"] = bool(g["cross_engine_kp_ratio"] <= 1.5)
        g["swap_rate_difference_points"] = 100 * abs(p["swap_rate"] - t["swap_rate"])
        g["swap_goal_met (<= 5 points)"] = bool(g["swap_rate_difference_points"] <= 5)
    return g


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default="default")
    ap.add_argument("--set", action="append", help="extra KEY=VALUE for every generated set (repeatable)")
    ap.add_argument("--data", default="out/pose_bench", help="folder of the train / test / test_pt datasets")
    ap.add_argument("--skip-generate", action="store_true", help="use the datasets already in --data")
    ap.add_argument("--train-num", type=int, default=3072)
    ap.add_argument("--test-num", type=int, default=192)
    ap.add_argument("--size", type=int, default=128, help="square image side [px]")
    ap.add_argument("--net-size", type=int, default=32,
                    help="side the network sees [px] (images area-averaged down to it; keypoints stay native px)")
    ap.add_argument("--head", choices=("keypoints", "global", "triangles"), default="keypoints",
                    help="crease/ratio head: features under the keypoints + their 2-D layout, global pooling only, or "
                         "keypoints + features sampled on every mesh triangle placed from the keypoints")
    ap.add_argument("--heatmap-stride", type=int, choices=(4, 2), default=4,
                    help="network pixels per heatmap cell: 4, or 2 through a learned upsampling (finer keypoints)")
    ap.add_argument("--crop", type=int, default=0,
                    help="top-down: the network reads a CROP x CROP crop around the worm's box (labels/bbox_obj) "
                         "instead of the whole image (--size: the rendered side); 0: the whole image")
    ap.add_argument("--augment", action="store_true",
                    help="draw every training batch afresh: exposure and white balance, and with --crop the box "
                         "jitter and an in-plane turn (--augment-turn)")
    ap.add_argument("--augment-turn", type=float, default=0.0,
                    help="--augment --crop: the crops' in-plane turn, uniform within +- this [deg] (180 measured "
                         "worse on production's creases: docs/dataset.md)")
    ap.add_argument("--reg-weight", type=float, default=1.0,
                    help="weight of the crease + ratio L1 in the training loss (against the keypoints')")
    ap.add_argument("--tta", type=int, default=1,
                    help="--crop: test on this many turned crops of each image (2 pi k / TTA; for --augment networks)")
    ap.add_argument("--save-model", help="write the trained network, its target statistics and log here (torch)")
    ap.add_argument("--load-model", help="evaluate a network written by --save-model instead of training one")
    ap.add_argument("--spp", type=int, default=16, help="path-traced samples per pixel")
    ap.add_argument("--no-pathtraced", action="store_true", help="skip the path-traced test set")
    ap.add_argument("--steps", type=int, default=3000, help="training budget: optimizer steps of --batch images")
    ap.add_argument("--budget-s", type=float, default=None, help="also stop training after this many seconds")
    ap.add_argument("--batch", type=int, default=16)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "pose_baseline.json"))
    a = ap.parse_args(argv)
    try:
        import torch  # optional dependency: torch
    except ImportError:
        print("error: the benchmark needs torch: pip install torch (the CPU wheel is enough)", file=sys.stderr)
        return 2
    # the code this run uses: read at its start (a training takes long; the tree may move on meanwhile)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True,
                            cwd=Path(__file__).parent).stdout.strip()
    dirty = bool(subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                                text=True, cwd=Path(__file__).parent).stdout.strip())
    paths = generate_sets(a)
    if a.no_pathtraced:
        paths.pop("test_pt")
    tr = load(paths["train"], ("worm/vertices",) if a.head == "triangles" else ())
    native = tr
    if a.crop:  # the network sees the crop at its own resolution
        tr = crop_to_worm(tr, a.crop, np.random.default_rng(a.seed), CROP_JITTER)
    ta = argparse.Namespace(**{**vars(a), **({"size": a.crop, "net_size": a.crop} if a.crop else {})})
    if a.load_model:  # a network trained before, with the same data and model options
        saved = torch.load(a.load_model, weights_only=False)
        model = build_model(len(tr["names"]), len(saved["stats"]["crease_mean"]) + tr["labels/deformation"].shape[1],
                            ta.size, ta.net_size, a.head, triangle_weights(tr) if a.head == "triangles" else None,
                            a.heatmap_stride)
        model.load_state_dict(saved["state"])
        stats, info = saved["stats"], saved["train"]
    else:
        model, stats, info = train(native if (a.crop and a.augment) else tr, ta)
        if a.save_model:
            torch.save({"state": model.state_dict(), "stats": dict(stats), "train": info, "args": vars(a)},
                       a.save_model)
    stats["kp_mean"] = tr["keypoints/pixel"].mean(0)
    body_model = tr["keypoints/body"].mean(0)
    flip = flip_permutation(tr["names"])
    res = {}
    for name in [k for k in ("test", "test_pt") if k in paths]:
        d = load(paths[name], SEEN_KEYS)
        native_test = d
        if a.crop:
            d = crop_to_worm(d, a.crop)
        pred = (predict_turned(model, native_test, stats, a.crop, a.tta) if (a.crop and a.tta > 1)
                else predict(model, d, stats))
        res[name] = evaluate(*pred, d, flip, stats, body_model)
    report = {"args": vars(a), "commit": commit, "worktree_modified": dirty,
              "pythonpath": os.environ.get("PYTHONPATH", ""), "train": info, **res,
              "goals": goals(res)}
    print(table(res))
    print(json.dumps(report["goals"], indent=1))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
