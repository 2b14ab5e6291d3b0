"""How far a fold moves a panel edge in the image: pixels per degree of crease, by camera distance and elevation.

For every crease (hinge i, j, k, l; shared edge j-k) of the rest worm (the dataset's ``WormParams`` geometry), a fold
of ``--fold`` degrees turns each wing about the crease: its free vertex (i or l) moves by ``r · δ`` along the wing's
normal (r: its distance from the crease line). That 3-D motion is projected through a look-at camera at the given
distance and elevation (azimuth averaged over 12 directions, the worm centred, fov_y = ``--fov`` rad) with the
projection's Jacobian, and the median over creases and wings is reported, with the share of the worm's vertices that
fall inside the image (the dataset sampler redraws views below ``camera.min_in_frame``).

    python benchmarks/fold_pixels.py                       # 128x96 and 256x256, fold 3 deg (docs/dataset.md)
    python benchmarks/fold_pixels.py --size 256x256 --fov 0.7 --fold 3
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from warpworm.physics import crease
from warpworm.physics.params import WormParams
from warpworm.render.camera import look_at


def rest_worm():
    w = WormParams()
    return crease.build_worm(w.a, w.b, w.n_units, l0=w.l0)


def wing_motion(pattern, fold_rad: float) -> tuple[np.ndarray, np.ndarray]:
    """Points (2H, 3) [m] (each crease's two wing vertices) and their motion (2H, 3) [m] for a fold of ``fold_rad``."""
    x = pattern.vertices
    pts, mot = [], []
    for i, j, k, l in pattern.hinges:
        e = x[k] - x[j]
        e = e / np.linalg.norm(e)
        for v in (i, l):
            rel = x[v] - x[j]
            radial = rel - (rel @ e) * e  # from the crease line to the vertex
            mot.append(np.cross(e, radial) * fold_rad)  # rotation about the crease: |motion| = r δ
            pts.append(x[v])
    return np.asarray(pts), np.asarray(mot)


def camera(distance, elevation, azimuth, centre, fov_y, width, height):
    d = np.array([np.cos(elevation) * np.cos(azimuth), np.cos(elevation) * np.sin(azimuth), np.sin(elevation)])
    R, t = look_at(centre + distance * d, centre)
    f = (height / 2.0) / np.tan(fov_y / 2.0)
    return np.asarray(R), np.asarray(t), f


def pixel_motion(pts, mot, R, t, f) -> np.ndarray:
    """|d(u, v)| [px] of points ``pts`` moving by ``mot`` (first order: the projection's Jacobian)."""
    pc = pts @ R.T + t
    dc = mot @ R.T
    z = pc[:, 2]
    du = f / z * (dc[:, 0] - pc[:, 0] / z * dc[:, 2])
    dv = f / z * (dc[:, 1] - pc[:, 1] / z * dc[:, 2])
    return np.hypot(du, dv)


def in_frame(verts, R, t, f, width, height) -> float:
    pc = verts @ R.T + t
    u = f * pc[:, 0] / pc[:, 2] + (width - 1) / 2
    v = f * pc[:, 1] / pc[:, 2] + (height - 1) / 2
    return float(np.mean((u >= 2) & (u <= width - 3) & (v >= 2) & (v <= height - 3) & (pc[:, 2] > 0)))


def table(size, fov, fold_deg, distances, elevations):
    width, height = size
    pat = rest_worm()
    pts, mot = wing_motion(pat, np.radians(fold_deg))
    centre = pat.vertices.mean(axis=0)
    rows = []
    for dist in distances:
        for el in elevations:
            px, fr = [], []
            for az in np.linspace(0, 2 * np.pi, 12, endpoint=False):
                R, t, f = camera(dist, np.radians(el), az, centre, fov, width, height)
                px.append(pixel_motion(pts, mot, R, t, f))
                fr.append(in_frame(pat.vertices, R, t, f, width, height))
            px = np.concatenate(px)
            rows.append({"size": f"{width}x{height}", "distance": dist, "elevation_deg": el,
                         "median_px": float(np.median(px)), "p90_px": float(np.percentile(px, 90)),
                         "in_frame_min": float(np.min(fr))})
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", action="append", help="WxH (repeatable; default 128x96 and 256x256)")
    ap.add_argument("--fov", type=float, default=0.7, help="vertical field of view [rad]")
    ap.add_argument("--fold", type=float, default=3.0, help="fold [deg]")
    ap.add_argument("--out", default=str(Path(__file__).parent / "results" / "fold_pixels.json"))
    a = ap.parse_args(argv)
    sizes = [tuple(int(v) for v in s.split("x")) for s in (a.size or ["128x96", "256x256"])]
    rows = []
    for size in sizes:
        rows += table(size, a.fov, a.fold, [0.08, 0.10, 0.12, 0.14, 0.16, 0.20, 0.28], [15, 30, 45, 60, 75])
    print(f"panel-edge motion of a {a.fold:g} deg fold, median over creases and 12 azimuths [px] "
          f"(p90); fov_y {a.fov} rad; worm in frame (worst azimuth)")
    for r in rows:
        print(f"{r['size']:>8} d={r['distance']:.2f} m el={r['elevation_deg']:>2} deg: {r['median_px']:.2f} "
              f"({r['p90_px']:.2f}) px  in-frame {r['in_frame_min']:.2f}")
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps({"fov_y": a.fov, "fold_deg": a.fold, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
