"""A reference tracker for the paper's five marker bands (§IV-E, Fig. 11): HSV segmentation, per-band centroid,
back-projection onto a plane parallel to the floor, then the four deformation ratios and the displacement per frame.

Host-side OpenCV and NumPy only. The camera follows OpenCV (``x_cam = R x_world + t``; K, distortion ``(k1, k2, p1,
p2[, k3])``) and the floor is the plane through the world origin with normal ``(-sin i, 0, cos i)`` for incline i
(warpworm's floor; ``floor_incline`` in the camera file). A band's centre is taken on the plane at ``height`` [m]
above the floor along its normal: the height of the band centres seen from above in the worm's rest pose
(:func:`default_band_height`). A worm part that lifts off the floor is seen displaced (parallax): the same camera
model must then be used for the simulation it is compared with (``warpworm fit-track`` does so).

Classification (OpenCV HSV: H in [0, 180), S and V in [0, 255]; :func:`band_masks`) follows from the band colours
(:meth:`Thresholds.from_colors`, the colours' own hue H_b and saturation S_b) and never from the paint's brightness:
a face turned from the light keeps its hue and saturation (shading scales linear RGB; the display's power law keeps
the channel ratios), only its value drops. A pixel goes to the coloured band of nearest hue if that hue is within
``hue_tol`` (30) and its saturation >= ``sat_frac`` (0.5) S_b, and it stands 0.5 ``floor_sigma`` (5) noise levels
above the background next to it (the floor's level and noise estimated per image from its unsaturated pixels; the
darkest smoothed background within 3 px: a lit floor or the band's own shadow); where it is as dark as that, the
hue and saturation of its 3x3 mean decide (a face in deep shadow). A pixel goes to the white (low-saturation) band
if its saturation is below ``sat_frac`` times that of the colour of nearest hue and it stands ``floor_sigma`` noise
levels above the floor, or 3 levels (3x3 mean, against a coarse local floor map) and connected to such a pixel (a
white face in shadow). A pixel next to the background counts only if it is at least half-way from the background's
brightness to the band's own nearby (the face's light), and splitting at the nearest hue and at half the saturation
divides a pixel that mixes a band with its neighbour, the floor or a magnet evenly, so no centroid is pulled.
``brightness_cut=1`` restores the first tracker's rule (value >= ``val_frac`` V_b; it loses shaded faces:
docs/calibration.md). Of each mask only the largest 8-connected blob and the blobs near it (centroid within
``blob_reach`` times its size) are kept: a band is one patch of paint, a grey magnet or noise elsewhere is not. A
band with fewer than ``min_pixels`` pixels is *unseen* in that frame: its centre is NaN, and so are the ratios and
the displacement that need it. A dark, unsaturated floor keeps the white band clean.
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict, dataclass, field
from pathlib import Path

import cv2
import numpy as np

from warpworm.data import dataset as ds
from warpworm.data import randomize as rnd
from warpworm.data.config import PARAM_SPECS
from warpworm.data.sampling import sensor_values
from warpworm.physics import crease
from warpworm.physics.params import WormParams
from warpworm.render import (Renderer, default_appearance, focal_from_fov, look_at, make_cameras,
                             scene_from_snapshot)
from warpworm.render.labels import band_centres
from warpworm.render.scene import BAND_COLORS, band_appearance
from warpworm.render.sensor import apply_sensor

NUM_BANDS = 5
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


@dataclass
class CameraModel:
    """A calibrated camera and the floor: K (3, 3) [px], dist (5,) OpenCV distortion, R (3, 3) and t (3,) [m] world
    -> camera, floor_incline [rad] (the floor's slope about +y, warpworm's ``floor_incline``)."""

    K: np.ndarray
    R: np.ndarray
    t: np.ndarray
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    floor_incline: float = 0.0

    @classmethod
    def load(cls, path) -> "CameraModel":
        """Read CAMERA.json: ``K`` (3x3), ``R`` (3x3), ``t`` (3), optional ``dist`` and ``floor_incline`` (the
        dataset's ``camera/K``, ``camera/R``, ``camera/t`` and ``params/worm.floor_incline`` of one sample)."""
        d = json.loads(Path(path).read_text())
        missing = [k for k in ("K", "R", "t") if k not in d]
        if missing:
            raise ValueError(f"{path}: missing key(s) {missing}; expected K (3x3), R (3x3), t (3) and optionally "
                             "dist (4, 5, 8 or 12 values) and floor_incline [rad]")
        return cls(K=np.asarray(d["K"], np.float64), R=np.asarray(d["R"], np.float64),
                   t=np.asarray(d["t"], np.float64).reshape(3), dist=np.asarray(d.get("dist", np.zeros(5)), np.float64),
                   floor_incline=float(d.get("floor_incline", 0.0)))

    def save(self, path) -> None:
        d = {k: np.asarray(v).tolist() for k, v in asdict(self).items()}
        Path(path).write_text(json.dumps(d, indent=1))

    def validate(self) -> None:
        for name, shape in (("K", (3, 3)), ("R", (3, 3)), ("t", (3,))):
            if np.shape(getattr(self, name)) != shape:
                raise ValueError(f"camera {name}: got shape {np.shape(getattr(self, name))}; expected {shape}")
        if not (self.K[0, 0] > 0 and self.K[1, 1] > 0):
            raise ValueError(f"camera K: got fx={self.K[0, 0]}, fy={self.K[1, 1]}; expected positive focal lengths")
        if abs(np.linalg.det(self.R) - 1.0) > 1e-6:
            raise ValueError(f"camera R: got det {np.linalg.det(self.R):.6g}; expected a rotation (det 1)")


OVERRIDABLE = ("hue_tol", "sat_frac", "val_frac", "min_pixels", "blob_reach", "brightness_cut", "floor_sigma", "soft")


@dataclass
class Thresholds:
    """HSV thresholds of the five bands (OpenCV units): the colours' ``hue`` (5,) in [0, 180), ``sat`` and ``val``
    (5,) in [0, 255], ``white`` (5,) bool (a low-saturation band), and the rules' knobs (module docstring)."""

    hue: np.ndarray
    sat: np.ndarray
    val: np.ndarray
    white: np.ndarray
    hue_tol: float = 30.0
    sat_frac: float = 0.6
    val_frac: float = 0.5
    min_pixels: int = 12
    blob_reach: float = 1.5
    brightness_cut: float = 0.0
    """1: the brightness rule of the first tracker (value >= ``val_frac`` times the band colour's; loses faces turned
    from the light, docs/calibration.md). 0 (default): brightness-independent, a pixel is a band's if its hue and
    saturation (unchanged when a face is shaded: shading scales linear RGB, and the display's power law keeps the
    ratios) say so and it stands ``floor_sigma`` noise levels above the floor's brightness (estimated per image)."""
    floor_sigma: float = 5.0
    """Noise levels of the floor a white pixel must stand above it (half as many for a coloured one, which its
    chroma also gates)."""
    soft: float = 1.0
    """1 (default): a band's centre is the centroid of its soft weights (:func:`band_weights`: every pixel on a
    boundary unmixed into the two classes whose nearby colours explain it best), so the part of a band that blur
    and antialiasing smear into its neighbours' pixels, or theirs into its, counts by the fraction it covers. 0: the
    centroid of the hard masks (:func:`band_masks`). Ignored with ``brightness_cut``."""

    @classmethod
    def from_colors(cls, colors=None, **overrides) -> "Thresholds":
        """Thresholds for display colours (5, 3) in [0, 1] (default the paper's, ``render.scene.BAND_COLORS``);
        a colour with saturation < 0.3 is a white band. ``overrides``: any of :data:`OVERRIDABLE`."""
        c = np.asarray(BAND_COLORS if colors is None else colors, np.float64)
        if c.shape != (NUM_BANDS, 3) or not np.all((c >= 0) & (c <= 1)):
            raise ValueError(f"band colors: got shape {c.shape}; expected (5, 3) RGB in [0, 1], tail -> head")
        bad = [k for k in overrides if k not in OVERRIDABLE]
        if bad:
            raise ValueError(f"threshold override(s) {bad}: unknown; expected one of {OVERRIDABLE}")
        hsv = cv2.cvtColor(np.round(c * 255).astype(np.uint8)[None], cv2.COLOR_RGB2HSV)[0].astype(np.float64)
        return cls(hue=hsv[:, 0], sat=hsv[:, 1], val=hsv[:, 2], white=hsv[:, 1] < 0.3 * 255, **overrides)


def parse_band_colors(text: str | None, key: str = "--band-colors"):
    """``"r,g,b;r,g,b;..."`` (five display colours tail -> head, each in [0, 1]) -> (5, 3) array; None -> None.
    ``key`` names the option in the error."""
    if text is None:
        return None
    try:
        c = np.array([[float(x) for x in part.split(",")] for part in str(text).split(";")])
    except ValueError:
        c = None
    if c is None or c.shape != (NUM_BANDS, 3) or not np.all((c >= 0) & (c <= 1)):
        raise ValueError(f"{key}: got {text!r}; expected five R,G,B triples in [0, 1] separated by ';' (tail -> head)")
    return c


def dataset_band_colors(path) -> np.ndarray:
    """The band colours (5, 3) a dataset folder was rendered with: its ``config_yaml`` attribute's
    ``render.band_colors`` (the paper's :data:`warpworm.render.scene.BAND_COLORS` when the config left it out)."""
    try:
        reader = ds.open(path)
    except Exception as exc:  # noqa: BLE001 (any unreadable folder: one clear message)
        raise ValueError(f"--band-colors-from: got {str(path)!r}; expected a dataset folder ({exc})") from None
    try:
        cfg = reader.config
    finally:
        reader.close()
    colors = (cfg.get("render") or {}).get("band_colors")
    return BAND_COLORS.copy() if colors is None else np.asarray(colors, np.float64)


def floor_level(v: np.ndarray, s: np.ndarray) -> tuple[float, float]:
    """The floor's brightness and its noise (OpenCV V units) in one image, from its unsaturated pixels (S below 96):
    the median and 1.4826 times the median absolute deviation of their V, the bright tail beyond 4 of those
    deviations dropped (three passes): the floor fills most of a frame filmed as docs/calibration.md asks; the white
    band and the magnets are the bright tail."""
    vv = v[s < 96].astype(np.float64)
    if vv.size < 16:
        vv = v.astype(np.float64).ravel()
    for _ in range(3):
        med = float(np.median(vv))
        sig = max(1.0, 1.4826 * float(np.median(np.abs(vv - med))))
        vv = vv[vv <= med + 4 * sig]
    return med, sig


def floor_map(v: np.ndarray, s: np.ndarray, cell: int | None = None) -> tuple[np.ndarray, float]:
    """The floor's brightness per pixel (H, W) float32 (a lamp lights a floor unevenly) and its noise: the
    :func:`floor_level` of every ``cell``-pixel cell (default a quarter of the image's shorter side) of a coarse grid
    from the window of twice its size around it, interpolated bilinearly, and never above the whole image's floor
    level plus 3 noise levels (a window the worm fills); the noise is the whole image's."""
    H, W = v.shape
    fl0, sig = floor_level(v, s)
    cell = int(cell or max(16, min(H, W) // 4))
    ny, nx = max(1, int(np.ceil(H / cell))), max(1, int(np.ceil(W / cell)))
    grid = np.zeros((ny, nx), np.float32)
    for i in range(ny):
        for j in range(nx):
            y0, x0 = max(0, i * cell - cell // 2), max(0, j * cell - cell // 2)
            grid[i, j] = floor_level(v[y0:y0 + 2 * cell, x0:x0 + 2 * cell], s[y0:y0 + 2 * cell, x0:x0 + 2 * cell])[0]
    # cell centres at (i + 0.5) cell: resize maps them there
    full = cv2.resize(np.minimum(grid, fl0 + 3 * sig), (nx * cell, ny * cell), interpolation=cv2.INTER_LINEAR)
    return full[:H, :W], sig


def band_masks(rgb: np.ndarray, thr: Thresholds) -> np.ndarray:
    """The five band masks (5, H, W) bool of one RGB uint8 image (H, W, 3) (rules in the module docstring)."""
    hsv = cv2.cvtColor(np.ascontiguousarray(rgb, np.uint8), cv2.COLOR_RGB2HSV).astype(np.int16)
    h, s, v = hsv[..., 0], hsv[..., 1], hsv[..., 2]
    dh = np.abs(h[None] - thr.hue[:, None, None])
    dh = np.minimum(dh, 180 - dh)
    dh[thr.white] = 999
    nearest = np.argmin(dh, axis=0)
    hue_ok = np.min(dh, axis=0) <= thr.hue_tol
    # white/colour split at half the saturation of the colour the pixel's hue is nearest to
    white_sat = thr.sat_frac * np.where(thr.white, 255.0, thr.sat)[nearest]
    out = np.zeros((NUM_BANDS,) + rgb.shape[:2], bool)
    cand = np.zeros_like(out)
    for b in range(NUM_BANDS):
        if thr.white[b]:
            cand[b] = s < white_sat
        else:
            cand[b] = hue_ok & (nearest == b) & (s >= thr.sat_frac * thr.sat[b])
        if thr.brightness_cut:
            cand[b] &= v >= thr.val_frac * thr.val[b]
    if not thr.brightness_cut:
        # Brightness only against the background next to a pixel, never against the paint's colour: the floor's
        # noise (global), the darkest smoothed background within 3 px (a lit floor, or the band's own shadow)
        fl, sig = floor_level(v, s)
        flm, _ = floor_map(v, s)
        vs = cv2.blur(v.astype(np.float32), (3, 3))
        colour = cand[~thr.white].any(axis=0)
        bg = cv2.erode(np.where(colour, 255.0, vs).astype(np.float32), np.ones((7, 7), np.uint8))
        bg = np.minimum(bg, fl)
        lit = v >= bg + 0.5 * thr.floor_sigma * sig  # the colours are gated by their chroma too
        # a face in deep shadow can be as dark as the floor: there the chroma of the 3x3 mean decides (the floor's
        # noise averaged down, the paint's hue and saturation kept)
        hsv_s = cv2.cvtColor(cv2.blur(np.ascontiguousarray(rgb, np.uint8), (3, 3)), cv2.COLOR_RGB2HSV).astype(np.int16)
        dh_s = np.abs(hsv_s[..., 0][None] - thr.hue[:, None, None])
        dh_s = np.minimum(dh_s, 180 - dh_s)
        dh_s[thr.white] = 999
        near_s = np.argmin(dh_s, axis=0)
        ok_s = np.min(dh_s, axis=0) <= thr.hue_tol
        for b in range(NUM_BANDS):
            if not thr.white[b]:
                dark = ok_s & (near_s == b) & (hsv_s[..., 1] >= thr.sat_frac * thr.sat[b]) & (nearest == b)
                cand[b] = (cand[b] & lit) | (dark & ~lit)
                continue
            # hysteresis against the local floor: white where floor_sigma noise levels above it, and every
            # unsaturated pixel connected to such a one whose 3x3 mean stands 3 levels above it (a white face in
            # shadow, nearly as dark as the lit floor)
            strong = cand[b] & (v >= np.maximum(fl, flm) + thr.floor_sigma * sig)
            weak = cand[b] & (vs >= flm + 3.0 * sig)
            n, lab = cv2.connectedComponents((weak | strong).astype(np.uint8), connectivity=8)
            keep = np.zeros(n, bool)
            keep[np.unique(lab[strong])] = True
            keep[0] = False
            cand[b] = keep[lab]
        band = cand.any(axis=0)
        # an edge pixel (next to a pixel of no band) counts if it is at least half-way from that background to the
        # band's own brightness nearby (the brightest of its inner pixels within 2 px: the face's light, not the
        # paint's), so a pixel that mixes band and floor is split evenly whatever the shading
        edge_of = cv2.dilate((~band).astype(np.uint8), np.ones((3, 3), np.uint8)) > 0
        for b in range(NUM_BANDS):
            edge = cand[b] & edge_of
            ref = cv2.dilate(np.where(cand[b] & ~edge, v, 0).astype(np.uint8), np.ones((5, 5), np.uint8))
            half = 2.0 * v >= bg + ref.astype(np.float32)
            if thr.white[b]:  # and a white edge pixel needs white inside it (not a colour's desaturated rim)
                half &= ref > 0
            cand[b] &= ~edge | half
    for b in range(NUM_BANDS):
        out[b] = _near_largest(cand[b], thr.blob_reach)
    return out


def _near_largest(mask: np.ndarray, reach: float) -> np.ndarray:
    """The largest 8-connected blob of ``mask`` and every other blob of 2+ pixels whose centroid lies within
    ``reach`` times the largest's size (sqrt of its area) of its centroid: a band is one patch of paint, seen in
    pieces where folds hide parts of it, while a grey magnet or noise elsewhere is not the band."""
    n, lab, stats, cents = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=8)
    if n <= 2:
        return lab > 0
    area = stats[1:, cv2.CC_STAT_AREA]
    big = int(np.argmax(area))
    near = (np.linalg.norm(cents[1:] - cents[1 + big], axis=1) <= reach * np.sqrt(area[big])) & (area >= 2)
    return np.isin(lab, 1 + np.nonzero(near)[0])


SOFT_CORE_PX = 1
"""A class's core (:func:`band_weights`): its mask eroded by this many pixels."""
SOFT_WINDOWS = (5, 9, 17)
"""Windows [px] in which a class's nearby colour is looked for, the smallest with a core pixel first."""
SOFT_MIN_CONTRAST = 12.0
"""Two classes whose nearby colours differ by less than this (RGB units) are not unmixed against each other."""


def band_weights(rgb: np.ndarray, masks: np.ndarray) -> np.ndarray:
    """Soft band weights (5, H, W) in [0, 1] of one RGB uint8 image and its hard :func:`band_masks`.

    Six classes: the five bands and the background (every pixel of no band). A class's *core* is its mask eroded
    by :data:`SOFT_CORE_PX`: those pixels are its own (weight 1). Every other pixel lies on a boundary, where the
    camera's blur and the renderer's antialiasing mix the colours of what meets there (linearly, in the display
    values the blur acts on). Its colour c is explained by each pair of classes (i, j), not both background, whose
    nearby colours r_i, r_j (the mean of the class's core pixels in the smallest of :data:`SOFT_WINDOWS` that holds
    one: the local light, not the paint's) differ by at least :data:`SOFT_MIN_CONTRAST`: c = a r_i + (1 - a) r_j,
    a in [0, 1] by least squares; the pair with the smallest residual gets a and 1 - a. A boundary pixel with no
    such pair keeps its hard mask. Mass is conserved under blur (a symmetric blur moves no centroid of a linear
    mixture): the centroid of the weights is that of the area each band covers, a sliver smeared over three pixels
    included, where the hard masks gain or lose whole pixels at every edge."""
    B = masks.shape[0]
    img = np.asarray(rgb, np.float32)
    cls = np.concatenate([masks, ~masks.any(axis=0)[None]])
    k = np.ones((2 * SOFT_CORE_PX + 1,) * 2, np.uint8)
    core = np.stack([cv2.erode(c.astype(np.uint8), k, borderType=cv2.BORDER_REPLICATE) > 0 for c in cls])
    C = len(cls)
    H, W = masks.shape[1:]
    ref = np.zeros((C, H, W, 3), np.float32)
    have = np.zeros((C, H, W), bool)
    for c in range(C):
        cf = core[c].astype(np.float32)
        for win in SOFT_WINDOWS:
            n = cv2.boxFilter(cf, -1, (win, win), normalize=False)
            sm = cv2.boxFilter(img * cf[..., None], -1, (win, win), normalize=False)
            new = (n > 0.5) & ~have[c]
            ref[c][new] = sm[new] / n[new][:, None]
            have[c] |= new
    zone = ~core.any(axis=0)
    w = core[:B].astype(np.float32)
    best = np.full((H, W), np.inf, np.float32)
    alpha = np.zeros((H, W), np.float32)
    first = np.full((H, W), -1)
    second = np.full((H, W), -1)
    for i in range(C):
        for j in range(i + 1, C):
            ok = zone & have[i] & have[j]
            d = ref[i] - ref[j]
            dd = (d * d).sum(-1)
            ok &= dd > SOFT_MIN_CONTRAST ** 2
            if not ok.any():
                continue
            a = np.clip(((img - ref[j]) * d).sum(-1) / np.maximum(dd, 1e-6), 0.0, 1.0)
            res = ((img - ref[j] - a[..., None] * d) ** 2).sum(-1)
            better = ok & (res < best)
            best[better], alpha[better], first[better], second[better] = res[better], a[better], i, j
    for b in range(B):
        w[b] += np.where(first == b, alpha, 0.0) + np.where(second == b, 1.0 - alpha, 0.0)
    nopair = zone & (first < 0)
    w[:, nopair] = masks[:, nopair]
    return w


def band_centroids(rgb: np.ndarray, thr: Thresholds) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centroids (5, 2) (u = column, v = row; NaN when unseen) and pixel counts (5,) of the bands (the hard
    masks' counts; the centroid is that of :func:`band_weights` unless ``thr.soft`` is 0)."""
    m = band_masks(rgb, thr)
    n = m.sum(axis=(1, 2))
    wt = band_weights(rgb, m) if (thr.soft and not thr.brightness_cut) else m.astype(np.float64)
    mass = wt.sum(axis=(1, 2))
    rows, cols = np.arange(rgb.shape[0]), np.arange(rgb.shape[1])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = (wt.sum(axis=1) * cols).sum(axis=1) / mass
        v = (wt.sum(axis=2) * rows).sum(axis=1) / mass
    uv = np.stack([u, v], -1)
    uv[n < thr.min_pixels] = np.nan
    return uv, n


def back_project(uv: np.ndarray, cam: CameraModel, height: float) -> np.ndarray:
    """World points [m] (..., 3) where the pixel rays through ``uv`` (..., 2) (distorted pixels) meet the plane
    ``height`` [m] above the floor (along its normal); NaN in, NaN out."""
    uv = np.asarray(uv, np.float64)
    flat = uv.reshape(-1, 2)
    ok = np.isfinite(flat).all(axis=1)
    xn = np.full_like(flat, np.nan)
    if ok.any():
        xn[ok] = cv2.undistortPoints(flat[ok][:, None], cam.K, cam.dist).reshape(-1, 2)
    ray_c = np.concatenate([xn, np.ones((len(flat), 1))], axis=1)
    ray_w = ray_c @ cam.R  # R^T d for each row
    centre = -cam.R.T @ cam.t
    i = cam.floor_incline
    n = np.array([-np.sin(i), 0.0, np.cos(i)])
    with np.errstate(invalid="ignore", divide="ignore"):
        s = (height - centre @ n) / (ray_w @ n)
    return (centre + s[:, None] * ray_w).reshape(uv.shape[:-1] + (3,))


def ratios_and_displacement(centres: np.ndarray, ref: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Four deformation ratios (..., F, 4) (adjacent band-centre distances over frame ``ref``'s) and the
    displacement (..., F) [m] of the five centres' mean along frame ``ref``'s tail -> head direction, from centres
    (..., F, 5, 3) [m] (leading axes: e.g. worlds); NaN where a band is missing."""
    c = np.asarray(centres, np.float64)
    d = np.linalg.norm(np.diff(c, axis=-2), axis=-1)
    axis = c[..., ref, -1, :] - c[..., ref, 0, :]
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    mean = c.mean(axis=-2)
    return d / d[..., ref:ref + 1, :], ((mean - mean[..., ref:ref + 1, :]) @ axis[..., None])[..., 0]


def read_frames(source, fps: float | None = None):
    """Frames of a video file or an image folder (sorted names): (list of RGB uint8 (H, W, 3), fps)."""
    p = Path(source)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"FRAMES {source}: a folder without images; expected {IMAGE_SUFFIXES} files")
        frames = [cv2.imread(str(f), cv2.IMREAD_COLOR) for f in files]
        bad = [str(f) for f, im in zip(files, frames) if im is None]
        if bad:
            raise ValueError(f"FRAMES: unreadable image(s) {bad[:3]}")
        return [cv2.cvtColor(f, cv2.COLOR_BGR2RGB) for f in frames], float(fps or 30.0)
    if not p.is_file():
        raise ValueError(f"FRAMES {source}: no such file or folder; expected a video file or an image folder")
    cap = cv2.VideoCapture(str(p))
    frames = []
    while True:
        ok, im = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(im, cv2.COLOR_BGR2RGB))
    rate = fps or cap.get(cv2.CAP_PROP_FPS) or 30.0
    cap.release()
    if not frames:
        raise ValueError(f"FRAMES {source}: OpenCV read no frame; expected a video file or an image folder")
    return frames, float(rate)


def track(frames, cam: CameraModel, thr: Thresholds | None = None, *, height: float, fps: float = 30.0) -> dict:
    """Track the bands in ``frames`` (sequence of RGB uint8 (H, W, 3)).

    Returns a dict: ``time`` (F,) [s] (frame / fps), ``pixel`` (F, 5, 2) band centroids [px] (NaN unseen),
    ``pixels`` (F, 5) counts, ``seen`` (F, 5) bool, ``world`` (F, 5, 3) [m] on the plane ``height`` above the floor,
    ``ratios`` (F, 4), ``displacement`` (F,) [m] (reference: the first frame with all five bands seen, ``ref``).
    """
    cam.validate()
    thr = Thresholds.from_colors() if thr is None else thr
    got = [band_centroids(f, thr) for f in frames]
    uv = np.stack([g[0] for g in got])
    counts = np.stack([g[1] for g in got])
    seen = np.isfinite(uv).all(axis=-1)
    full = np.nonzero(seen.all(axis=1))[0]
    if len(full) == 0:
        raise ValueError("no frame shows all five bands; check the thresholds (docs/calibration.md)")
    world = back_project(uv, cam, height)
    ratios, disp = ratios_and_displacement(world, ref=int(full[0]))
    return {"time": np.arange(len(frames)) / fps, "pixel": uv, "pixels": counts, "seen": seen, "world": world,
            "ratios": ratios, "displacement": disp, "ref": int(full[0])}


CSV_COLUMNS = (["frame", "time_s", "seen"] + [f"{a}{b}" for b in range(NUM_BANDS) for a in ("u", "v")]
               + [f"{a}{b}_m" for b in range(NUM_BANDS) for a in ("x", "y", "z")]
               + [f"ratio{b}" for b in range(4)] + ["displacement_m"])
"""track.csv: one row per frame; ``seen`` five 0/1 digits (tail -> head); empty cells where a band is unseen."""


def write_csv(path, tr: dict) -> None:
    def cell(x):
        return "" if not np.isfinite(x) else repr(float(x))

    with open(path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(CSV_COLUMNS)
        for i in range(len(tr["time"])):
            w.writerow([i, repr(float(tr["time"][i])), "".join("1" if s else "0" for s in tr["seen"][i])]
                       + [cell(x) for x in tr["pixel"][i].ravel()] + [cell(x) for x in tr["world"][i].ravel()]
                       + [cell(x) for x in tr["ratios"][i]] + [cell(tr["displacement"][i])])


def read_csv(path) -> dict:
    """A track.csv back: ``time`` (F,), ``seen`` (F, 5), ``pixel`` (F, 5, 2), ``world`` (F, 5, 3), ``ratios`` (F, 4),
    ``displacement`` (F,) (NaN for empty cells)."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows or rows[0] != CSV_COLUMNS:
        raise ValueError(f"{path}: header {rows[0][:4] if rows else []}...; expected the track.csv columns "
                         f"{CSV_COLUMNS[:4]}... (written by warpworm track)")
    body = rows[1:]
    num = np.array([[float(x) if x != "" else np.nan for x in r[3:]] for r in body]).reshape(len(body), -1)
    return {"time": np.array([float(r[1]) for r in body]),
            "seen": np.array([[c == "1" for c in r[2]] for r in body]).reshape(len(body), NUM_BANDS),
            "pixel": num[:, :10].reshape(-1, 5, 2), "world": num[:, 10:25].reshape(-1, 5, 3),
            "ratios": num[:, 25:29], "displacement": num[:, 29]}


def default_band_height(params=None) -> float:
    """Height [m] above the floor of the band centres seen from above (:func:`warpworm.render.labels.band_centres`)
    in the rest pose of ``params`` (default WormParams) lying on its base: the plane :func:`track` back-projects
    onto."""
    p = WormParams() if params is None else params
    pat = crease.build_worm(float(np.ravel(p.a)[0]), float(np.ravel(p.b)[0]), int(p.n_units), float(np.ravel(p.l0)[0]))
    c = band_centres(pat.vertices, pat.triangles, pat.triangle_segment)
    return float(np.mean(c[:, 2]) - pat.vertices[:, 2].min())


def harshest_sensor(num: int, sensor: dict | None = None) -> dict:
    """:func:`warpworm.render.sensor.apply_sensor` values (each (num,)) of a dataset's harshest camera: the upper end
    of every ``sensor.*`` range (noise, blur, brightness, contrast) with JPEG off (quality 100). ``sensor``: a
    config's ``randomize['sensor']`` distributions; default the randomization's own (``PARAM_SPECS``: noise 4
    levels, blur 0.8 px, brightness +12, contrast 1.15). Through :func:`warpworm.data.sampling.sensor_values`, the
    conversion a dataset uses."""
    if sensor is None:
        sensor = {n: rnd.parse_distribution(spec.default) for n, spec in PARAM_SPECS["sensor"].items()}

    def top(d):
        return float(d.high) if isinstance(d, rnd.Uniform) else float(np.max(getattr(d, "values", [d.value])))

    app = {f"sensor.{n}": np.full(num, top(d)) for n, d in sensor.items() if n != "jpeg_quality"}
    app["sensor.jpeg_quality"] = np.full(num, 100, np.int64)
    return sensor_values(app)


def render_band_video(frames: dict, model, cam: CameraModel, width: int, height: int, *, world: int = 0,
                      colors=None, sensor_values: dict | None = None, seed: int = 0, device="cpu",
                      return_images: bool = False):
    """RGB uint8 frames (F, H, W, 3) of one simulated world painted with the bands, seen by ``cam`` (no distortion):
    ``frames`` holds stacked snapshots (``positions`` (F, W', V, 3), ``magnet_pos``, ``magnet_rot``) as
    :func:`warpworm.analysis.gait_runs.run_gait` returns them. A dark plain floor; ``sensor_values`` (per-image
    :func:`warpworm.render.sensor.apply_sensor` values, each (F,)) add the camera's noise, blur and JPEG. With
    ``return_images``: (rgb, the renderer's clean output dict with ``seg`` and ``depth``)."""
    pos = np.asarray(frames["positions"])[:, world]
    F = pos.shape[0]
    snap = {"positions": pos, "magnet_pos": np.asarray(frames["magnet_pos"])[:, world],
            "magnet_rot": np.asarray(frames["magnet_rot"])[:, world]}
    app = default_appearance(1)
    app.albedo = app.albedo.copy()
    app.albedo[:, 1] = 0.03  # dark plain floor
    app.floor_tex = np.array([[0.02, 0.0, 0.0, 300.0]])
    app = band_appearance(app, colors).take(np.zeros(F, np.int64))
    p = model.params
    one = lambda v: float(np.ravel(v)[world % np.size(v)])  # noqa: E731
    scene = scene_from_snapshot(snap, model.pattern, None, appearance=app,
                                rest_vertices=model.rest_positions_host[world],
                                ipm_diameter=one(p.ipm_diameter), ipm_thickness=one(p.ipm_thickness),
                                epm_size=np.asarray(p.epm_size, np.float64).reshape(-1, 3)[0],
                                floor_incline=one(p.floor_incline))
    cams = make_cameras(cam.K, np.broadcast_to(cam.R, (F, 3, 3)), np.broadcast_to(cam.t, (F, 3)), np.arange(F),
                        width, height)
    images = Renderer(width, height, device=device).render(scene, cams)
    rgb = images["rgb"]
    if sensor_values is not None:
        rgb = apply_sensor(rgb, seed + np.arange(F), values=sensor_values)
    return (rgb, images) if return_images else rgb


def overhead_camera(centre=(0.045, 0.0, 0.0), distance=0.25, width=320, height=240, fov_deg=40.0,
                    tilt_deg=0.0) -> CameraModel:
    """A camera ``distance`` [m] above ``centre`` looking down (tilted ``tilt_deg`` toward -y), image +x = world +x:
    the paper's view of the bench."""
    c = np.asarray(centre, np.float64)
    tl = np.radians(tilt_deg)
    eye = c + distance * np.array([0.0, -np.sin(tl), np.cos(tl)])
    R, t = look_at(eye, c, up=(0.0, 1.0, 0.0))
    f = float(focal_from_fov(np.radians(fov_deg), height))
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
    return CameraModel(K=K, R=R, t=t)


def write_meta(path, cam: CameraModel, width: int, height: int, height_m: float, fps: float, ref: int) -> None:
    """The track's camera and plane next to its CSV (``track.json`` for ``track.csv``): what ``warpworm fit-track``
    needs to look at the simulation through the same camera."""
    d = {k: np.asarray(v).tolist() for k, v in asdict(cam).items()}
    d.update(width=int(width), height=int(height), height_m=float(height_m), fps=float(fps), ref=int(ref))
    Path(path).write_text(json.dumps(d, indent=1))


def read_meta(path) -> dict:
    """:func:`write_meta`'s file back: ``camera`` (CameraModel), ``width``, ``height``, ``height_m``, ``fps``,
    ``ref``."""
    d = json.loads(Path(path).read_text())
    cam = CameraModel(K=np.asarray(d["K"], np.float64), R=np.asarray(d["R"], np.float64),
                      t=np.asarray(d["t"], np.float64), dist=np.asarray(d.get("dist", np.zeros(5)), np.float64),
                      floor_incline=float(d.get("floor_incline", 0.0)))
    return {"camera": cam, "width": int(d["width"]), "height": int(d["height"]), "height_m": float(d["height_m"]),
            "fps": float(d["fps"]), "ref": int(d["ref"])}


def meta_path(csv_path) -> Path:
    """Where :func:`write_meta` puts the camera of ``csv_path`` (same name, ``.json``)."""
    return Path(csv_path).with_suffix(".json")
