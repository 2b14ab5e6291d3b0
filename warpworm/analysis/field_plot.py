"""The field around a bar magnet, as the paper's Fig. 2, drawn with OpenCV (no matplotlib needed).

Panels side by side, all in the x–z plane through the magnet's centre (the magnet is magnetized along its long
axis z): the 'dipoles' model at 1 dipole/cm³ and at 64/cm³, the exact 'analytic' field, and the relative
difference |B_64 − B_exact| / |B_exact|. Colour = log10 |B| [T] on one shared scale; white needles show the
field direction (the paper's free compass needles); dots mark the dipoles of the aggregation.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from warpworm.physics import magnets as mg

PANEL_PX = (300, 420)  # (width, height) of each panel's plot area
HEADER_PX = 46
FOOTER_PX = 40


def _panel(logb, valid, lo, hi, cmap=cv2.COLORMAP_VIRIDIS):
    norm = np.clip((logb - lo) / (hi - lo), 0, 1)
    img = cv2.applyColorMap((255 * norm).astype(np.uint8), cmap)
    img[~valid] = (90, 90, 90)
    return img


def _to_px(x, z, extent, shape):
    (x0, x1), (z0, z1) = extent
    h, w = shape
    return int(round((x - x0) / (x1 - x0) * (w - 1))), int(round((z1 - z) / (z1 - z0) * (h - 1)))


def field_maps(magnet: mg.Magnet, extent, resolution, densities=(1e6, 64e6)):
    """B on an x–z grid (y = 0): dict name -> (H, W, 3) [T]; also the grid's x, z [m] and the inside mask."""
    (x0, x1), (z0, z1) = extent
    w, h = resolution
    xs = np.linspace(x0, x1, w)
    zs = np.linspace(z1, z0, h)  # image rows go down
    X, Z = np.meshgrid(xs, zs)
    pts = np.stack([X, np.zeros_like(X), Z], axis=-1)
    pose = (np.zeros(3), np.eye(3))
    maps = {f"dipoles {d * 1e-6:g}/cm³": mg.field(magnet, pose, pts, model="dipoles", density=d) for d in densities}
    maps["analytic"] = mg.field(magnet, pose, pts, model="analytic")
    half = 0.5 * magnet.size
    inside = (np.abs(X) <= half[0]) & (np.abs(Z) <= half[2])
    return maps, X, Z, inside


def render_field_picture(path, *, size=(0.01, 0.01, 0.04), moment=3.6, densities=(1e6, 64e6),
                         extent=((-0.03, 0.03), (-0.042, 0.042)), needle_step_px=21) -> Path:
    """Draw the field around a bar magnet (default 10×10×40 mm, 3.6 A·m² along its long axis) and write a PNG.

    Returns the path written. Panels: dipoles at each density, analytic, relative difference of the densest
    dipole model to the analytic field.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    magnet = mg.Cuboid(size, moment=moment)
    maps, X, Z, inside = field_maps(magnet, extent, PANEL_PX, densities)
    mags = {k: np.linalg.norm(v, axis=-1) for k, v in maps.items()}
    exact = mags["analytic"]
    lo = float(np.floor(np.log10(np.percentile(exact[~inside], 1)) * 4) / 4)
    hi = float(np.ceil(np.log10(np.percentile(exact[~inside], 99.5)) * 4) / 4)
    panels = []
    h, w = PANEL_PX[1], PANEL_PX[0]
    pose = (np.zeros(3), np.eye(3))
    for name, B in maps.items():
        valid = ~inside & np.isfinite(mags[name])
        img = _panel(np.log10(np.maximum(mags[name], 1e-12)), valid, lo, hi)
        # needles: unit field direction in the x–z plane
        for r in range(needle_step_px // 2, h, needle_step_px):
            for c in range(needle_step_px // 2, w, needle_step_px):
                if inside[r, c]:
                    continue
                bx, bz = B[r, c, 0], B[r, c, 2]
                n = np.hypot(bx, bz)
                if not np.isfinite(n) or n == 0:
                    continue
                dx, dy = 0.42 * needle_step_px * bx / n, -0.42 * needle_step_px * bz / n
                p0 = (int(c - dx), int(r - dy))
                p1 = (int(c + dx), int(r + dy))
                cv2.arrowedLine(img, p0, p1, (255, 255, 255), 1, cv2.LINE_AA, tipLength=0.35)
        # magnet outline, north end marked
        half = 0.5 * magnet.size
        tl = _to_px(-half[0], half[2], extent, (h, w))
        br = _to_px(half[0], -half[2], extent, (h, w))
        cv2.rectangle(img, tl, br, (255, 255, 255), 1)
        cv2.putText(img, "N", (tl[0] + 3, tl[1] + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 255), 1, cv2.LINE_AA)
        if name.startswith("dipoles"):
            d = float(name.split()[1].split("/")[0]) * 1e6
            for p in mg.dipole_grid(magnet, d):
                if abs(p[1]) <= 0.5 * magnet.size[1] / max(1, round(magnet.size[1] * d ** (1 / 3))) + 1e-12:
                    cv2.circle(img, _to_px(p[0], p[2], extent, (h, w)), 2, (0, 0, 255), -1, cv2.LINE_AA)
        panels.append((name, img))
    # relative difference of the densest dipole model
    dense = f"dipoles {max(densities) * 1e-6:g}/cm³"
    rel = np.linalg.norm(maps[dense] - maps["analytic"], axis=-1) / np.maximum(exact, 1e-30)
    img = _panel(np.log10(np.maximum(rel, 1e-6)), ~inside, -5.0, 0.0, cv2.COLORMAP_INFERNO)
    half = 0.5 * magnet.size
    cv2.rectangle(img, _to_px(-half[0], half[2], extent, (h, w)), _to_px(half[0], -half[2], extent, (h, w)),
                  (255, 255, 255), 1)
    for lvl, col in ((-2, (255, 255, 255)), (-3, (200, 200, 200))):
        mask = ((rel > 10.0**lvl) & ~inside).astype(np.uint8)
        contours, _ = cv2.findContours(mask, cv2.RETR_LIST, cv2.CHAIN_APPROX_SIMPLE)
        cv2.drawContours(img, contours, -1, col, 1, cv2.LINE_AA)
    panels.append((f"|B{max(densities) * 1e-6:g} - B|/|B|", img))

    canvas = np.full((HEADER_PX + h + FOOTER_PX, len(panels) * (w + 8) + 8, 3), 255, np.uint8)
    for k, (name, img) in enumerate(panels):
        x = 8 + k * (w + 8)
        canvas[HEADER_PX:HEADER_PX + h, x:x + w] = img
        title = name.replace("³", "3")
        cv2.putText(canvas, title, (x + 4, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    foot = HEADER_PX + h + 26
    cv2.putText(canvas, f"10x10x40 mm bar, {moment:g} A.m2 along +z; x-z plane; colour log10|B| [T] from {lo:g} "
                f"to {hi:g}; last panel log10 rel. diff -5..0, contours 1% and 0.1%",
                (8, foot), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
    if not cv2.imwrite(str(path), canvas):
        raise OSError(f"could not write {path}")
    del pose
    return path
