"""``warpworm track FRAMES --camera CAMERA.json --out track.csv``: the five marker bands of a video (or an image folder)
as four deformation ratios and the displacement per frame (:mod:`warpworm.analysis.track`; the paper's Fig. 11).

CAMERA.json: ``K`` (3x3) [px], ``R`` (3x3) and ``t`` (3) [m] (world -> camera, OpenCV), optionally ``dist`` (OpenCV
distortion) and ``floor_incline`` [rad]: a dataset sample's ``camera/K``, ``camera/R``, ``camera/t``. The CSV has one
row per frame (:data:`warpworm.analysis.track.CSV_COLUMNS`); a band not seen leaves its cells empty. Next to it,
``<out>.json`` keeps the camera, image size and plane height: ``warpworm fit-track`` looks at the simulation through
the same camera.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from warpworm.analysis import track as T
from warpworm.analysis.track import OVERRIDABLE, Thresholds, dataset_band_colors, parse_band_colors
from warpworm.commands.common import refuse
from warpworm.data import export_json as strict_json

HELP = "track the five marker bands in a video or image folder: deformation ratios and displacement per frame (CSV)"


def add_arguments(parser) -> None:
    parser.add_argument("frames", metavar="FRAMES", help="a video file or a folder of images (sorted by name)")
    parser.add_argument("--camera", required=True, metavar="CAMERA.json", help="K, R, t [, dist, floor_incline]")
    parser.add_argument("--out", default="track.csv", help="output CSV (default track.csv)")
    parser.add_argument("--fps", type=float, default=None,
                        help="frame rate [1/s] (default: the video's, or 30 for an image folder)")
    parser.add_argument("--height", type=float, default=None,
                        help="height [m] above the floor of the plane the band centres are taken on (default: the "
                             "default worm's band centres seen from above at rest)")
    parser.add_argument("--band-colors", default=None, metavar="R,G,B;R,G,B;...",
                        help="the five band colours tail -> head as displayed, each R,G,B in [0, 1] (default: the "
                             "paper's blue, pink, white, green, red)")
    parser.add_argument("--threshold", action="append", default=[], metavar="NAME=VALUE",
                        help="override a segmentation threshold: hue_tol, sat_frac, floor_sigma, min_pixels, blob_reach; "
                             "brightness_cut=1 (with val_frac) restores the first tracker's brightness rule "
                             "(docs/calibration.md)")
    parser.add_argument("--band-colors-from", default=None, metavar="DATASET",
                        help="take the band colours from a dataset folder's config (render.band_colors; the paper's "
                             "when it has none)")
    parser.add_argument("--json", action="store_true", help="print a JSON summary only")


def _thresholds(args):
    over = {}
    for item in args.threshold:
        name, _, value = item.partition("=")
        if name not in OVERRIDABLE:
            raise ValueError(f"--threshold {item!r}: unknown name {name!r}; expected one of {OVERRIDABLE}")
        try:
            over[name] = int(value) if name == "min_pixels" else float(value)
        except ValueError:
            raise ValueError(f"--threshold {item!r}: got {value!r}; expected a number") from None
    if args.band_colors is not None and args.band_colors_from is not None:
        raise ValueError(f"--band-colors / --band-colors-from: got both ({args.band_colors!r}, "
                         f"{args.band_colors_from!r}); expected one")
    if args.band_colors_from is not None:
        return Thresholds.from_colors(dataset_band_colors(args.band_colors_from), **over)
    return Thresholds.from_colors(parse_band_colors(args.band_colors), **over)


def main(args) -> int:
    try:
        if args.fps is not None and not args.fps > 0:
            raise ValueError(f"--fps: got {args.fps}; expected a frame rate > 0")
        if args.height is not None and not np.isfinite(args.height):
            raise ValueError(f"--height: got {args.height}; expected a height [m]")
        if not Path(args.camera).is_file():
            raise ValueError(f"--camera: got {args.camera!r}; expected a CAMERA.json file")
        cam = T.CameraModel.load(args.camera)
        cam.validate()
        thr = _thresholds(args)
        frames, fps = T.read_frames(args.frames, args.fps)
        height = T.default_band_height() if args.height is None else float(args.height)
        tr = T.track(frames, cam, thr, height=height, fps=fps)
    except ValueError as exc:
        return refuse(exc)
    T.write_csv(args.out, tr)
    T.write_meta(T.meta_path(args.out), cam, frames[0].shape[1], frames[0].shape[0], height, fps, tr["ref"])
    seen = tr["seen"]
    summary = {"frames": int(len(frames)), "fps": fps, "height_m": height, "frames_all_bands": int(seen.all(1).sum()),
               "unseen_per_band": (len(seen) - seen.sum(0)).astype(int).tolist(),
               "ratio_min": np.nanmin(tr["ratios"], axis=0).tolist(),
               "ratio_max": np.nanmax(tr["ratios"], axis=0).tolist(),
               "displacement_end_m": float(tr["displacement"][-1]) if np.isfinite(tr["displacement"][-1]) else None,
               "out": str(args.out), "meta": str(T.meta_path(args.out))}
    if args.json:
        print(strict_json.dumps(summary))  # a band never seen: its ratio min/max as null
        return 0
    print(f"tracked {summary['frames']} frames at {fps:g} fps; all five bands seen in {summary['frames_all_bands']} "
          f"(unseen per band, tail -> head: {summary['unseen_per_band']})")
    print("ratio min/max: " + ", ".join(f"{a:.3f}/{b:.3f}" for a, b in zip(summary["ratio_min"], summary["ratio_max"])))
    if summary["displacement_end_m"] is not None:
        print(f"displacement at the last frame: {1e3 * summary['displacement_end_m']:.2f} mm")
    print(f"wrote {args.out}")
    return 0
