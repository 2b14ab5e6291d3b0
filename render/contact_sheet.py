"""A contact sheet: one row per image (RGB | depth colour map | segmentation overlay with labels drawn).

The third column draws the labels over the image so a person sees at a glance that they sit on the worm: keypoints
(filled = visible, hollow = occluded, none = outside; colour by keypoint), the worm's projected box (thin) and visible
box (thick), the body frame's axes (x red, y green, z blue; 1 cm), and the visible fraction.
"""

from __future__ import annotations

import cv2
import numpy as np

from warpworm import ids
from warpworm.render.labels import KEYPOINT_NAMES

# segmentation colours (RGB) by id: background, floor, five worm segments, three IPMs, EPM
SEG_COLORS = np.array([
    [0, 0, 0], [90, 90, 90],
    [230, 25, 75], [245, 130, 48], [255, 225, 25], [60, 180, 75], [70, 240, 240],
    [0, 130, 200], [145, 30, 180], [240, 50, 230], [170, 110, 40],
], dtype=np.uint8)

_KP_COLORS = {  # RGB
    "seg": (255, 255, 255), "tail": (0, 255, 255), "head": (255, 0, 255), "ipm": (255, 255, 0),
    "corner": (255, 128, 0),
}


def _kp_color(name: str):
    for k, c in _KP_COLORS.items():
        if name.startswith(k) or (k == "corner" and ("_top" in name or "_left" in name or "_right" in name)):
            return c
    return (255, 255, 255)


def depth_colormap(depth: np.ndarray) -> np.ndarray:
    """(H, W) depth [m] -> (H, W, 3) RGB uint8 (TURBO on inverse depth, near = red; background black)."""
    valid = depth > 0
    out = np.zeros(depth.shape + (3,), np.uint8)
    if not valid.any():
        return out
    inv = np.zeros_like(depth, dtype=np.float64)
    inv[valid] = 1.0 / depth[valid]
    lo, hi = np.percentile(inv[valid], [1, 99])
    norm = np.clip((inv - lo) / max(hi - lo, 1e-12), 0, 1)
    col = cv2.applyColorMap((norm * 255).astype(np.uint8), cv2.COLORMAP_TURBO)[..., ::-1]
    out[valid] = col[valid]
    return out


def seg_overlay(rgb: np.ndarray, seg: np.ndarray, alpha: float = 0.55) -> np.ndarray:
    """Blend the segmentation colours over the image (background and floor are left mostly untouched)."""
    col = SEG_COLORS[seg]
    a = np.where(seg[..., None] >= ids.SEG_WORM_FIRST, alpha, 0.15 * (seg[..., None] == ids.SEG_FLOOR))
    return (rgb * (1 - a) + col * a).astype(np.uint8)


def draw_labels(img: np.ndarray, labels: dict, n: int, scale: float = 1.0) -> np.ndarray:
    """Draw image ``n``'s labels (dataset names: ``camera/K|R|t``, ``poses/body``, ``keypoints/pixel`` and, when
    present, ``keypoints/visibility``, ``labels/bbox_obj``, ``labels/bbox_visib``, ``labels/visib_fract``) on ``img``
    (RGB, already ``scale`` times the render size)."""
    img = np.ascontiguousarray(img)
    s = scale
    sh = 4  # fixed-point bits for sub-pixel drawing
    f = float(1 << sh)

    def pt(uv):
        # pixel centres are integer coordinates: (u + 0.5) * s - 0.5 maps them to the scaled image's centres
        return (int(round(((uv[0] + 0.5) * s - 0.5) * f)), int(round(((uv[1] + 0.5) * s - 0.5) * f)))

    _draw_boxes(img, labels, n, pt, sh)
    _draw_body_axes(img, labels, n, pt, sh)
    vis = labels.get("keypoints/visibility")
    r = max(2, int(round(2.5 * s)))
    for p, name in enumerate(KEYPOINT_NAMES):
        v = 2 if vis is None else int(vis[n, p])
        if v == 0:
            continue
        uv = labels["keypoints/pixel"][n, p]
        c = _kp_color(name)
        if v == 2:
            cv2.circle(img, pt(uv), r * int(f), c, -1, cv2.LINE_AA, sh)
            cv2.circle(img, pt(uv), r * int(f), (0, 0, 0), 1, cv2.LINE_AA, sh)
        else:
            cv2.circle(img, pt(uv), r * int(f), c, 1, cv2.LINE_AA, sh)
    if "labels/visib_fract" in labels:
        cv2.putText(img, f"vis {labels['labels/visib_fract'][n]:.2f}", (4, img.shape[0] - 6),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def _draw_boxes(img, labels, n, pt, sh) -> None:
    """The projected worm's box (thin) and its visible pixels' box (thick), both (x, y, w, h) [px]."""
    if "labels/bbox_obj" in labels:
        b = labels["labels/bbox_obj"][n]
        if np.all(np.isfinite(b)):
            cv2.rectangle(img, pt(b[:2]), pt(b[:2] + b[2:]), (200, 200, 200), 1, cv2.LINE_AA, sh)
    if "labels/bbox_visib" in labels and labels["labels/bbox_visib"][n][2] > 0:
        b = labels["labels/bbox_visib"][n].astype(float)  # whole pixels: around the first and last pixel centres
        cv2.rectangle(img, pt(b[:2] - 0.5), pt(b[:2] + b[2:] - 0.5), (255, 255, 255), 2, cv2.LINE_AA, sh)


def _draw_body_axes(img, labels, n, pt, sh) -> None:
    """The body frame's x, y, z axes (red, green, blue), 1 cm long, when all in front of the camera."""
    K, R, t = labels["camera/K"][n], labels["camera/R"][n], labels["camera/t"][n]
    body = labels["poses/body"][n]
    o, Rb = body[:3, 3], body[:3, :3]
    ends = np.concatenate([o[None], o + 0.01 * Rb.T], axis=0)
    pc = ends @ R.T + t
    if np.all(pc[:, 2] > 1e-4):
        xy = pc[:, :2] / pc[:, 2:]
        if "camera/dist" in labels:  # through the lens, as the image and keypoints/pixel (render.distortion)
            from warpworm.render.distortion import distort

            xy = np.stack(distort(xy[:, 0], xy[:, 1], np.asarray(labels["camera/dist"][n])), axis=1)
        uv = xy * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
        for a, c in zip(range(1, 4), [(255, 0, 0), (0, 255, 0), (0, 80, 255)]):
            cv2.line(img, pt(uv[0]), pt(uv[a]), c, 2, cv2.LINE_AA, sh)


def contact_sheet(samples: dict, labels: dict | None = None, *, rgb=None, max_rows: int = 8, scale: float = 1.0,
                  titles=None) -> np.ndarray:
    """Contact sheet (RGB uint8) of the first ``max_rows`` images.

    Args:
        samples: images and labels under the dataset's names (``rgb``, ``depth``, ``segmentation``, ``camera/*``,
            ``poses/body``, ``keypoints/*``, ``labels/*``): dataset samples stacked, or the renderer's output with
            :func:`warpworm.render.labels.schema_labels`'s labels (``labels``, merged in; the renderer's ``seg``
            stands for ``segmentation``).
        rgb: images to show in the first column instead of ``rgb`` (e.g. with sensor effects).
        scale: tile scale factor (nearest-neighbour up-scaling for small renders).
        titles: optional text per row.
    """
    d = {**samples, **(labels or {})}
    segm = d["segmentation"] if "segmentation" in d else d["seg"]
    rgb = d["rgb"] if rgb is None else rgb
    N = min(len(rgb), max_rows)
    rows = []
    for n in range(N):  # drawing is per image by nature (OpenCV)
        def up(a, interp=cv2.INTER_NEAREST):
            return cv2.resize(a, None, fx=scale, fy=scale, interpolation=interp) if scale != 1 else a.copy()

        tiles = [up(rgb[n], cv2.INTER_LINEAR), up(depth_colormap(d["depth"][n])),
                 draw_labels(up(seg_overlay(d["rgb"][n], segm[n])), d, n, scale)]
        if titles is not None:
            cv2.putText(tiles[0], str(titles[n]), (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1,
                        cv2.LINE_AA)
        row = np.concatenate([np.pad(t, ((1, 1), (1, 1), (0, 0))) for t in tiles], axis=1)
        rows.append(row)
    sheet = np.concatenate(rows, axis=0)
    header = np.zeros((22, sheet.shape[1], 3), np.uint8)
    tw = sheet.shape[1] // 3
    for i, txt in enumerate(("RGB", "depth (near = red)", "seg + keypoints (hollow: occluded)")):
        cv2.putText(header, txt, (i * tw + 4, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (255, 255, 255), 1, cv2.LINE_AA)
    return np.concatenate([header, sheet], axis=0)


def save_png(path, rgb: np.ndarray) -> None:
    """Write an RGB uint8 image as PNG."""
    if not cv2.imwrite(str(path), np.ascontiguousarray(rgb[..., ::-1])):
        raise OSError(f"could not write {path}")
