"""Previews of a finished dataset: ``preview.png`` (a contact sheet of the first samples, read back from the shards)
and ``preview.mp4`` (trajectory 0 resimulated densely with the same draws). Written by the ``generate`` command
after the job (:func:`warpworm.data.job.generate` does not write them), never part of the data.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import cv2
import numpy as np

from warpworm.data import dataset as ds
from warpworm.data.config import DatasetConfig
from warpworm.data.sampling import appearance_draws, render_draws
from warpworm.data.shard import ShardStats, simulate_with_replacement
from warpworm.data.stages import DEFAULT_STAGES, load_stages
from warpworm.render import make_cameras
from warpworm.render.contact_sheet import _kp_color, contact_sheet, save_png
from warpworm.render.labels import KEYPOINT_NAMES


PREVIEW_TEMPORARIES = (".preview.tmp.png", ".preview.tmp.mp4")
"""Where the previews are written before they are renamed into place."""


def remove_preview_temporaries(out) -> None:
    """Remove what an interrupted :func:`write_previews` left (its temporaries; the finished previews stay)."""
    for name in PREVIEW_TEMPORARIES:
        (Path(out) / name).unlink(missing_ok=True)


def legend(width: int) -> np.ndarray:
    """A key under the contact sheet (RGB uint8, ``width`` px wide): what the third column's colours and marks mean."""
    groups: dict = {}  # the sheet's own colours, grouped: each colour once, with the keypoints drawn in it
    for name in KEYPOINT_NAMES:
        groups.setdefault(tuple(_kp_color(name)), []).append(name)

    def label(names):
        if all(n.startswith("seg") for n in names):
            return f"{names[0]}-{names[-1][3:]}" if len(names) > 1 else names[0]
        if all(n.startswith("ipm") for n in names):
            return "IPM centres"
        base = [n for n in names if "_" not in n]
        return (base[0] if base else names[0]) + (" + end corners" if len(names) > 1 else "")

    font, items = cv2.FONT_HERSHEY_SIMPLEX, [(label(v), k) for k, v in groups.items()]
    lines = [items, ["keypoints: filled = visible, hollow = occluded (none: outside the image)",
                     "boxes: thin = projected worm, thick = visible worm pixels; axes: body x red, y green, z blue "
                     "(1 cm)", "'vis 0.90': the fraction of the worm's pixels that are visible"]]
    rows = [np.zeros((18, width, 3), np.uint8) for _ in range(1 + len(lines[1]))]
    x = 6
    for name, colour in lines[0]:
        cv2.circle(rows[0], (x + 5, 9), 4, tuple(int(c) for c in colour), -1, cv2.LINE_AA)
        cv2.putText(rows[0], name, (x + 14, 13), font, 0.38, (255, 255, 255), 1, cv2.LINE_AA)
        x += 30 + cv2.getTextSize(name, font, 0.38, 1)[0][0]
    for r, text in zip(rows[1:], lines[1]):
        cv2.putText(r, text, (6, 13), font, 0.36, (255, 255, 255), 1, cv2.LINE_AA)
    return np.concatenate(rows, axis=0)


def write_previews(cfg: DatasetConfig, out, stages=DEFAULT_STAGES, max_rows: int = 8) -> list[Path]:
    """``preview.png``: the renderer's contact sheet (:func:`warpworm.render.contact_sheet.contact_sheet`) of the
    first samples; ``preview.mp4``: trajectory 0 resimulated at 20 fps over ``sim.frame_times`` with the same draws,
    seen from sample 0's stored camera (one world, small)."""
    out = Path(out)
    reader = ds.open(out)
    try:
        n = min(len(reader), max_rows)
        paths = []
        if n == 0:
            return paths
        samples = [reader[i] for i in range(n)]
        stacked = {k: np.stack([smp[k] for smp in samples]) for k in samples[0] if not k.startswith("params/")}
        # written under a temporary name and renamed: an interrupted preview leaves no half-written file
        sheet = contact_sheet(stacked, max_rows=n, scale=2)
        save_png(out / ".preview.tmp.png", np.concatenate([sheet, legend(sheet.shape[1])], axis=0))
        os.replace(out / ".preview.tmp.png", out / "preview.png")
        paths.append(out / "preview.png")
        cam = {k: reader.read(f"camera/{k}", [0]) for k in ("K", "R", "t")}
    finally:
        reader.close()
    # video: trajectory 0 with a dense frame list (same parameters and camera as in the dataset)
    T = cfg.sim.frame_times[-1]
    nf = max(2, int(T * 20) + 1)
    dense = dataclasses.replace(cfg, sim=dataclasses.replace(cfg.sim, frame_times=list(np.linspace(0, T, nf)),
                                                             worlds=1), shard_size=nf, num_samples=nf)
    stg = load_stages(stages)
    traj = np.array([0])
    frames, world_values, _ = simulate_with_replacement(stg, dense, traj, ShardStats(0, 0))
    cams = make_cameras(cam["K"], cam["R"], cam["t"], 0, cfg.render.width, cfg.render.height)
    draws = render_draws(cfg, world_values, appearance_draws(cfg, traj), np.array([0]), cams, np.zeros(1, np.int64))
    vw = cv2.VideoWriter(str(out / ".preview.tmp.mp4"), cv2.VideoWriter_fourcc(*"mp4v"), 20,
                         (cfg.render.width, cfg.render.height))
    try:
        for f in frames:
            img = stg.render_batch(f, draws, cfg)["rgb"][0]
            vw.write(np.ascontiguousarray(img[..., ::-1]))
    finally:
        vw.release()
    os.replace(out / ".preview.tmp.mp4", out / "preview.mp4")
    paths.append(out / "preview.mp4")
    return paths
