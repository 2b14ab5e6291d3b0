"""A contact sheet: one row per image (RGB | depth colour map | segmentation overlay with labels drawn).

The third column draws the labels over the image so a person sees at a glance that they sit on the worm: keypoints
(filled = visible, hollow = occluded, none = outside; colour by keypoint), the worm's projected box (thin) and visible
box (thick), the body frame's axes (x red, y green, z blue; 1 cm), and the visible fraction.
"""

from __future__ import annotations

import cv2
import numpy as np

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
    a = np.where(seg[..., None] >= 2, alpha, 0.15 * (seg[..., None] == 1))
    return (rgb * (1 - a) + col * a).astype(np.uint8)


def draw_labels(img: np.ndarray, labels: dict, n: int, scale: float = 1.0) -> np.ndarray:
    """Draw image ``n``'s labels on ``img`` (RGB, already ``scale`` times the render size)."""
    img = np.ascontiguousarray(img)
    s = scale
    sh = 4  # fixed-point bits for sub-pixel drawing
    f = float(1 << sh)

    def pt(uv):
        # pixel centres are integer coordinates: (u + 0.5) * s - 0.5 maps them to the scaled image's centres
        return (int(round(((uv[0] + 0.5) * s - 0.5) * f)), int(round(((uv[1] + 0.5) * s - 0.5) * f)))

    if "worm_box" in labels:
        b = labels["worm_box"][n]
        if np.all(np.isfinite(b)):
            cv2.rectangle(img, pt(b[:2]), pt(b[2:]), (200, 200, 200), 1, cv2.LINE_AA, sh)
    if "worm_box_visible" in labels and labels["worm_box_visible"][n][0] >= 0:
        b = labels["worm_box_visible"][n].astype(float)
        cv2.rectangle(img, pt(b[:2] - 0.5), pt(b[2:] + 0.5), (255, 255, 255), 2, cv2.LINE_AA, sh)
    # body axes, 1 cm
    K, R, t = labels["K"][n], labels["R"][n], labels["t"][n]
    o = labels["body_t_world"][n]
    Rb = labels["body_R_world"][n]
    ends = np.concatenate([o[None], o + 0.01 * Rb.T], axis=0)
    pc = ends @ R.T + t
    if np.all(pc[:, 2] > 1e-4):
        uv = pc[:, :2] / pc[:, 2:] * [K[0, 0], K[1, 1]] + [K[0, 2], K[1, 2]]
        for a, c in zip(range(1, 4), [(255, 0, 0), (0, 255, 0), (0, 80, 255)]):
            cv2.line(img, pt(uv[0]), pt(uv[a]), c, 2, cv2.LINE_AA, sh)
    vis = labels.get("keypoint_visibility")
    r = max(2, int(round(2.5 * s)))
    for p, name in enumerate(KEYPOINT_NAMES):
        v = 2 if vis is None else int(vis[n, p])
        if v == 0:
            continue
        uv = labels["keypoints_2d"][n, p]
        c = _kp_color(name)
        if v == 2:
            cv2.circle(img, pt(uv), r * int(f), c, -1, cv2.LINE_AA, sh)
            cv2.circle(img, pt(uv), r * int(f), (0, 0, 0), 1, cv2.LINE_AA, sh)
        else:
            cv2.circle(img, pt(uv), r * int(f), c, 1, cv2.LINE_AA, sh)
    if "visible_fraction" in labels:
        cv2.putText(img, f"vis {labels['visible_fraction'][n]:.2f}", (4, img.shape[0] - 6),
                    cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def contact_sheet(images: dict, labels: dict, *, rgb=None, max_rows: int = 8, scale: float = 1.0,
                  titles=None) -> np.ndarray:
    """Contact sheet (RGB uint8) of the first ``max_rows`` images.

    Args:
        images: renderer output (``rgb``, ``depth``, ``seg``). labels: :func:`compute_labels` output.
        rgb: images to show in the first column instead of ``images['rgb']`` (e.g. with sensor effects).
        scale: tile scale factor (nearest-neighbour up-scaling for small renders).
        titles: optional text per row.
    """
    rgb = images["rgb"] if rgb is None else rgb
    N = min(len(rgb), max_rows)
    rows = []
    for n in range(N):  # drawing is per image by nature (OpenCV)
        def up(a, interp=cv2.INTER_NEAREST):
            return cv2.resize(a, None, fx=scale, fy=scale, interpolation=interp) if scale != 1 else a.copy()

        tiles = [up(rgb[n], cv2.INTER_LINEAR), up(depth_colormap(images["depth"][n])),
                 draw_labels(up(seg_overlay(images["rgb"][n], images["seg"][n])), labels, n, scale)]
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
