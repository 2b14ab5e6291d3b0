"""The keypoints the trainer exports (COCO, YOLO, webdataset) write: 16 distinct points of the worm's body.

The dataset's ``keypoints/*`` keep their 16 points (byte-identical files), three of which are the IPM centres: the
tail and head IPMs sit on the axis at the end sections (``ipm_tail`` = ``tail``, ``ipm_head`` = ``head`` in the image
to ~3e-5 px) and the centre IPM on the axis at the middle (= ``seg2``, inside the tube: never visible). They teach a
keypoint model nothing and distort OKS metrics, so the exports replace them with three distinct points of the sheet:

==============  ========================================================================================================
seg0 .. seg4    the five segment centres on the tube's axis (dataset keypoints)
tail, head      the centres of the end sections (dataset keypoints)
tail_top, ...   the six corners of the end sections: top (dorsal), left, right (dataset keypoints)
seg1_top        the dorsal (highest at rest) corner of the cross-section nearest seg1's centre
seg2_top        ... nearest seg2's centre (the worm's middle section)
seg3_top        ... nearest seg3's centre
==============  ========================================================================================================

The three new points are projected from ``worm/vertices`` through the sample's camera (pixel centres at integers, as
``keypoints/pixel``) and get the dataset's visibility rule for surface points (render/labels.py: visible unless a
surface is more than 0.5 mm in front; 0 outside the image).

Symmetries (:data:`MIRROR_PAIRS`, :data:`HALF_TURN_PAIRS`): an image mirrored left-right shows a worm whose left and
right corners swap (Ultralytics' ``flip_idx``); a half turn about the dorsal axis maps the worm nearly onto itself with
head and tail swapped (what a symmetry-aware metric must accept).
"""

from __future__ import annotations

import json

import numpy as np

from warpworm.physics import crease
from warpworm.render.camera import Cameras

DATASET_NAMES = ("seg0", "seg1", "seg2", "seg3", "seg4", "tail", "head", "tail_top", "tail_left", "tail_right",
                 "head_top", "head_left", "head_right")
"""The dataset keypoints the exports keep, in this order."""
DORSAL_NAMES = ("seg1_top", "seg2_top", "seg3_top")
KEYPOINT_NAMES = DATASET_NAMES + DORSAL_NAMES
"""The exported keypoints, in order (16)."""

MIRROR_PAIRS = (("tail_left", "tail_right"), ("head_left", "head_right"))
HALF_TURN_PAIRS = (("tail", "head"), ("seg0", "seg4"), ("seg1", "seg3"), ("tail_top", "head_top"),
                   ("tail_left", "head_right"), ("tail_right", "head_left"), ("seg1_top", "seg3_top"))

OKS_SIGMAS = {"seg0": 0.035, "seg1": 0.035, "seg2": 0.035, "seg3": 0.035, "seg4": 0.035, "tail": 0.035,
              "head": 0.035, "tail_top": 0.025, "tail_left": 0.025, "tail_right": 0.025, "head_top": 0.025,
              "head_left": 0.025, "head_right": 0.025, "seg1_top": 0.025, "seg2_top": 0.025, "seg3_top": 0.025}
"""Per-keypoint OKS sigmas (COCO's scale: the person's are 0.025 (eyes) .. 0.107 (hips)): axis points inside the tube
are placed less sharply by an annotator or a model than surface corners."""

VIS_EPS = 5e-4
"""[m] the visibility rule's depth tolerance for surface points (= warpworm.render.labels.VIS_EPS)."""


def permutation(pairs, names=KEYPOINT_NAMES) -> list[int]:
    """The index map of a symmetry over ``names``: keypoint i goes to index out[i]."""
    idx = {n: i for i, n in enumerate(names)}
    out = list(range(len(names)))
    for a, b in pairs:
        if a in idx and b in idx:
            out[idx[a]], out[idx[b]] = idx[b], idx[a]
    return out


def index_pairs(pairs, names=KEYPOINT_NAMES, base: int = 0) -> list[list[int]]:
    """``pairs`` of names as indices into ``names`` (``base`` 1: COCO's 1-based), those present only."""
    return [[names.index(a) + base, names.index(b) + base] for a, b in pairs if a in names and b in names]


def dorsal_vertices(n_units: int, rest_vertices: np.ndarray) -> np.ndarray:
    """Vertex ids (3,) of seg1_top, seg2_top, seg3_top: the highest rest vertex of the section (a vertex triple
    3 s .. 3 s + 2) nearest each segment centre (section coordinate (i + 0.5) (S - 1) / 5, S = 2 n + 1 sections)."""
    S = 2 * int(n_units) + 1
    out = []
    for i in (1, 2, 3):
        s = int(np.rint((i + 0.5) * (S - 1) / 5))
        tri = 3 * s + np.arange(3)
        out.append(int(tri[np.argmax(rest_vertices[tri, 2])]))
    return np.asarray(out)


def project(points: np.ndarray, K: np.ndarray, R: np.ndarray, t: np.ndarray,
            dist: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World points (N, P, 3) [m] through cameras K, R, t (N, ...) and their lens distortion ``dist`` (N, 5), OpenCV's
    (k1, k2, p1, p2, k3; None: pinhole), as the renderer draws them -> pixels (N, P, 2) and camera depth (N, P) [m]."""
    cams = Cameras(K=K, R=R, t=t, world=np.arange(len(K)), width=0, height=0, dist=dist)
    uv, pc = cams.project(np.asarray(points, np.float64))
    return uv, pc[..., 2]


def visibility(uv: np.ndarray, z: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """COCO flags (N, P) of surface points: 0 outside the image or behind the camera, 1 occluded (a surface more than
    :data:`VIS_EPS` in front at the rounded pixel), 2 visible."""
    H, W = depth.shape[1:]
    with np.errstate(invalid="ignore"):
        px, py = np.rint(uv[..., 0]), np.rint(uv[..., 1])
        inside = (z > 0) & (px >= 0) & (px < W) & (py >= 0) & (py < H)
    pxi, pyi = np.where(inside, px, 0).astype(np.int64), np.where(inside, py, 0).astype(np.int64)
    D = depth[np.arange(depth.shape[0])[:, None], pyi, pxi].astype(np.float64)
    visible = (D == 0) | (z - D <= VIS_EPS)
    return np.where(inside, np.where(visible, 2, 1), 0).astype(np.uint8)


class KeypointExporter:
    """Reads the exported keypoints of samples of one dataset (``reader``: :func:`warpworm.data.dataset.open`)."""

    def __init__(self, reader):
        names = json.loads(reader.attrs["keypoint_names"])
        self.reader = reader
        kept = [n for n in DATASET_NAMES if n in names]
        self.take = [names.index(n) for n in kept]
        n_units = int((reader.config.get("sim") or {}).get("n_units", 6))
        rest = crease.build_worm(0.02, 0.008, n_units, l0=0.08).vertices
        # the worm's own mesh (a test's stand-in mesh has other vertices: no dorsal points there)
        same_mesh = np.asarray(reader.attrs["mesh_triangles"]).max() + 1 == len(rest)
        self.dorsal = dorsal_vertices(n_units, rest) if same_mesh else np.zeros(0, np.int64)
        self.names = tuple(kept) + (DORSAL_NAMES if same_mesh else ())
        """The exported keypoint names (:data:`KEYPOINT_NAMES` for warpworm's own datasets)."""

    def read(self, idx) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (n, 16, 2) [px] and COCO visibility flags (n, 16) of samples ``idx``."""
        r = self.reader
        idx = np.asarray(idx)
        uv = r.read("keypoints/pixel", idx)[:, self.take].astype(np.float64)
        vis = r.read("keypoints/visibility", idx)[:, self.take].astype(np.uint8)
        if not len(self.dorsal):
            return uv, vis
        verts = r.read("worm/vertices", idx)[:, self.dorsal].astype(np.float64)
        dist = r.read("camera/dist", idx) if "camera/dist" in r.keys() else None  # lens distortion on
        duv, z = project(verts, r.read("camera/K", idx), r.read("camera/R", idx), r.read("camera/t", idx), dist)
        dvis = visibility(duv, z, r.read("depth", idx))
        return np.concatenate([uv, duv], axis=1), np.concatenate([vis, dvis], axis=1)
