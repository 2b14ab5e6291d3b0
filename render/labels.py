"""Per-image labels: cameras, 6-DOF poses, keypoints with COCO visibility, boxes, deformation ratios.

Everything is vectorised NumPy over worlds and images (no Python loop per image). Inputs are a snapshot-like dict of
W worlds (``Simulator.snapshot()``), the :class:`Cameras` of N images (``cameras.world`` says which world each shows)
and, for visibility and boxes, the renderer's output for those images.

Body frame of the worm (right-handed, origin and axes recomputed from the deformed sheet in every state)::

                  z (dorsal, up at rest)
                  ^
                  |      y (left)
         tail     |     /                      head
          |\\------|----/--------------------/|
          | \\     |   /                    / |      x: unit vector tail keypoint -> head keypoint
          |  >----o--------------------->  x  |      o: mean of the five segment centres seg0..seg4
          | /                             \\  |      z: dorsal direction (below), made orthogonal to x
          |/-------------------------------\\|      y = z × x
        floor (ventral face rests on it at rest)

The dorsal direction is ``u = Σ_v w_v p_v`` with ``w_v ∝ (z⁰_v − mean z⁰)``, the rest heights of the vertices
(weights sum to 0, so u is translation-invariant; for a rigidly moved rest worm u is exactly the rotated rest +z).
At rest on a flat floor the body frame is the world frame shifted to the worm's middle.

Keypoints (names in :data:`KEYPOINT_NAMES`): the pattern's ``seg0..seg4`` (segment centres, on the tube's axis),
``tail``, ``head`` (centres of the end sections), the three IPM centres, and six surface corners of the end sections
(``tail_top``, ``tail_left``, ``tail_right``, ``head_top``, ...) which make the set non-collinear so that PnP is
well posed (every other keypoint lies on the worm's axis at rest).

COCO visibility per keypoint: 0 = outside the image (behind the camera, or the pixel ``round(u), round(v)`` outside),
1 = occluded, 2 = visible. With ``z`` the keypoint's camera depth and ``D``, ``L`` the depth and segmentation id at
its pixel: visible iff ``D == 0`` (nothing there), or ``z − D <= VIS_EPS`` (no surface more than 0.5 mm in front),
or ``z − D <= tol_k`` and ``L`` is the keypoint's own object (the worm's ids 2..6 for worm keypoints, the magnet's id
for an IPM centre). ``tol_k`` lets interior points show through their own surface: the tube's circumradius + 1 mm for
axis points, the disk radius + 0.5 mm for IPM centres, ``VIS_EPS`` for surface corners.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from warpworm.render.camera import Cameras
from warpworm.ids import SEG_IPM_FIRST, SEG_WORM_FIRST, SEG_WORM_LAST
from warpworm.transforms import matrix_to_quat_wxyz, pose_matrix

VIS_EPS = 5e-4
"""Depth tolerance [m] of the visibility test for any surface in front of a keypoint."""

CORNER_NAMES = ("tail_top", "tail_left", "tail_right", "head_top", "head_left", "head_right")
IPM_NAMES = ("ipm_tail", "ipm_centre", "ipm_head")
KEYPOINT_NAMES = ("seg0", "seg1", "seg2", "seg3", "seg4", "tail", "head") + IPM_NAMES + CORNER_NAMES
"""Order of the keypoint axis of every keypoint array."""
MAGNET_NAMES = ("epm", "ipm_tail", "ipm_centre", "ipm_head")


@dataclass
class WormBody:
    """What the labels need from a crease pattern: keypoint stencils, dorsal weights, rest geometry."""

    kp_vertices: np.ndarray
    """Vertices of the 13 sheet keypoints (seg0..4, tail, head, 6 corners), shape (13, K), int."""
    kp_weights: np.ndarray
    """Their weights, shape (13, K); each row sums to 1."""
    up_weights: np.ndarray
    """Dorsal-direction weights per vertex (sum 0), shape (V,)."""
    rest_vertices: np.ndarray
    """Rest vertices [m], shape (V, 3)."""
    axis_radius: float
    """Largest rest distance of a vertex from the tube axis [m] (visibility tolerance of axis keypoints)."""

    @classmethod
    def from_pattern(cls, pattern) -> "WormBody":
        """Build from a :class:`warpworm.physics.crease.CreasePattern` with keypoints seg0..seg4, tail, head."""
        names = list(pattern.keypoint_names)
        order = [names.index(n) for n in ("seg0", "seg1", "seg2", "seg3", "seg4", "tail", "head")]
        kv = pattern.keypoint_vertices[order]
        kw = pattern.keypoint_weights[order]
        x = pattern.vertices
        corners = []
        for end in (5, 6):  # tail, head: the surface corners of the end section
            verts = np.unique(kv[end][kw[end] > 1e-9])
            top = verts[np.argmax(x[verts, 2])]
            rest = verts[verts != top]
            corners += [top, rest[np.argmax(x[rest, 1])], rest[np.argmin(x[rest, 1])]]
        K = kv.shape[1]
        cv = np.repeat(np.array(corners)[:, None], K, axis=1)
        cw = np.zeros((6, K))
        cw[:, 0] = 1.0
        zc = x[:, 2] - x[:, 2].mean()
        up = zc / np.sum(zc * zc)
        kp = np.einsum("pk,pkc->pc", kw, x[kv])
        axis_pts = kp[:5]
        # distance of every vertex from the polyline through the rest segment centres (the tube's axis)
        a, b = axis_pts[0], axis_pts[-1]
        d = (b - a) / np.linalg.norm(b - a)
        rel = x - a
        radial = rel - np.outer(rel @ d, d)
        return cls(kp_vertices=np.concatenate([kv, cv]).astype(np.int32), kp_weights=np.concatenate([kw, cw]),
                   up_weights=up, rest_vertices=x.copy(), axis_radius=float(np.linalg.norm(radial, axis=1).max()))

    def sheet_keypoints(self, positions: np.ndarray) -> np.ndarray:
        """The 13 sheet keypoints [m] for positions (..., V, 3) -> (..., 13, 3)."""
        return np.einsum("pk,...pkc->...pc", self.kp_weights, positions[..., self.kp_vertices, :])

    def body_frame(self, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Body frame for positions (..., V, 3): rotation (..., 3, 3) (body -> world, columns x, y, z), origin (..., 3)."""
        kp = self.sheet_keypoints(positions)
        origin = kp[..., 0:5, :].mean(axis=-2)
        ex = kp[..., 6, :] - kp[..., 5, :]
        ex = ex / np.linalg.norm(ex, axis=-1, keepdims=True)
        up = np.einsum("v,...vc->...c", self.up_weights, positions)
        ez = up - np.einsum("...c,...c->...", up, ex)[..., None] * ex
        ez = ez / np.linalg.norm(ez, axis=-1, keepdims=True)
        ey = np.cross(ez, ex)
        return np.stack([ex, ey, ez], axis=-1), origin


def _pixel_lookup(arr: np.ndarray, px: np.ndarray, py: np.ndarray) -> np.ndarray:
    """arr (N, H, W) sampled at integer pixels (N, P) (already clipped)."""
    n = np.arange(arr.shape[0])[:, None]
    return arr[n, py, px]


def _box_from_mask(mask: np.ndarray) -> np.ndarray:
    """Inclusive integer pixel box (xmin, ymin, xmax, ymax) of every mask (N, H, W); -1s for empty masks."""
    N, H, W = mask.shape
    cols = mask.any(axis=1)
    rows = mask.any(axis=2)
    has = cols.any(axis=1)
    xmin = np.argmax(cols, axis=1)
    xmax = W - 1 - np.argmax(cols[:, ::-1], axis=1)
    ymin = np.argmax(rows, axis=1)
    ymax = H - 1 - np.argmax(rows[:, ::-1], axis=1)
    box = np.stack([xmin, ymin, xmax, ymax], axis=1)
    box[~has] = -1
    return box


def keypoints_in_body(body: np.ndarray, kp_world: np.ndarray) -> np.ndarray:
    """``keypoints/body`` (n, P, 3) [m]: world keypoints (n, P, 3) in the body frame, R_b^T (x - t_b) for body ->
    world poses ``body`` (n, 4, 4)."""
    body = np.asarray(body, np.float64)
    return np.einsum("nji,npj->npi", body[:, :3, :3], np.asarray(kp_world, np.float64) - body[:, None, :3, 3])


def keypoint_depth_tolerance(body: WormBody, ipm_diameter) -> np.ndarray:
    """Per-keypoint depth tolerance [m] of the visibility rule (module docstring), (W, P) for ``ipm_diameter`` ()
    or (W,) [m]: interior points may show through their own surface by this much."""
    d_ipm = np.atleast_1d(np.asarray(ipm_diameter, dtype=np.float64))
    tol = np.full((d_ipm.shape[0], len(KEYPOINT_NAMES)), VIS_EPS)
    tol[:, 0:7] = body.axis_radius + 1e-3
    tol[:, 7:10] = (0.5 * d_ipm + VIS_EPS)[:, None]
    return tol


def keypoint_visibility(uv: np.ndarray, z: np.ndarray, depth: np.ndarray, segm: np.ndarray,
                        tol: np.ndarray) -> np.ndarray:
    """COCO visibility (N, P) uint8 of keypoints at pixels ``uv`` (N, P, 2) with camera depth ``z`` (N, P) [m]
    against the rendered ``depth`` / ``segm`` (N, H, W) and the depth tolerances ``tol`` (N, P) [m]."""
    H, Wd = depth.shape[1:]
    P = uv.shape[1]
    with np.errstate(invalid="ignore"):
        px = np.rint(uv[..., 0])
        py = np.rint(uv[..., 1])
        inside = (z > 0) & (px >= 0) & (px < Wd) & (py >= 0) & (py < H)
    pxi = np.where(inside, px, 0).astype(np.int64)
    pyi = np.where(inside, py, 0).astype(np.int64)
    D = _pixel_lookup(depth, pxi, pyi).astype(np.float64)
    L = _pixel_lookup(segm, pxi, pyi).astype(np.int64)
    # each keypoint's own object: the worm's ids for worm keypoints, its magnet's id for an IPM centre
    worm_kp = np.ones(P, bool)
    worm_kp[7:10] = False
    own = np.where(worm_kp[None], (L >= SEG_WORM_FIRST) & (L <= SEG_WORM_LAST),
                   L == (SEG_IPM_FIRST + np.arange(P) - 7)[None])
    gap = z - D
    visible = (D == 0) | (gap <= VIS_EPS) | ((gap <= tol) & own)
    return np.where(inside, np.where(visible, 2, 1), 0).astype(np.uint8)


def _xywh(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    return np.concatenate([lo, hi - lo], axis=1)


def schema_labels(states: dict, body, cameras: Cameras, images: dict | None = None, *,
                  rest_positions=None, ipm_diameter=0.010, ipm_thickness=0.001) -> dict:
    """Labels of N images of W worlds, named and typed as the dataset schema (:data:`warpworm.data.dataset.SCHEMA`).

    Args:
        states: snapshot dict with ``positions`` (W, V, 3), ``magnet_pos`` (W, 4, 3), ``magnet_rot`` (W, 4, 3, 3) and,
            passed through when present, ``crease_angle`` (W, H), ``bar_strain`` (W, E).
        body: a :class:`WormBody` or a crease pattern (converted with :meth:`WormBody.from_pattern`).
        cameras: the images' cameras; ``cameras.world`` (N,) indexes the worlds.
        images: :meth:`Renderer.render` output (``depth``, ``seg``, ``worm_mask``) for visibility, the visible box,
            the visible fraction and the worm mask; None skips those labels.
        rest_positions: rest vertices (V, 3) or (W, V, 3) for the deformation ratios' rest distances
            (default: the body's rest vertices; pass per-world rest geometry when a, b, l0 vary per world).
        ipm_diameter, ipm_thickness: [m], () or (W,): visibility tolerance of the IPM centres.

    Returns:
        name -> (N, ...) array: ``poses/body`` (N, 4, 4) body -> world, ``poses/ipm`` (N, 3, 4, 4), ``poses/epm``
        (N, 4, 4), ``poses/body_quat`` (N, 4) (w, x, y, z); ``keypoints/world``, ``keypoints/camera``,
        ``keypoints/body`` (N, P, 3) [m], ``keypoints/pixel`` (N, P, 2) [px]; ``labels/bbox_obj`` (N, 4) (x, y, w, h)
        of all projected worm vertices, unclipped [px]; ``labels/deformation`` (N, 4); ``creases/angle``,
        ``bars/strain``, ``worm/vertices`` when ``states`` has them. With ``images``: ``keypoints/visibility``
        (N, P) uint8, ``labels/bbox_visib`` (N, 4) (x, y, w, h) of the visible worm pixels (0s when hidden),
        ``labels/visib_fract`` (N,), ``labels/worm_mask`` (N, H, W) uint8.
    """
    if not isinstance(body, WormBody):
        body = WormBody.from_pattern(body)
    wi = np.asarray(cameras.world, dtype=np.int64)
    pos = np.asarray(states["positions"], dtype=np.float64)
    mpos = np.asarray(states["magnet_pos"], dtype=np.float64)
    mrot = np.asarray(states["magnet_rot"], dtype=np.float64)

    # --- per world ---
    Rb, ob = body.body_frame(pos)  # (W, 3, 3), (W, 3)
    sheet = body.sheet_keypoints(pos)  # (W, 13, 3)
    kp_world = np.concatenate([sheet[:, :7], mpos[:, 1:4], sheet[:, 7:]], axis=1)  # (W, 16, 3)
    rest = body.rest_vertices if rest_positions is None else np.asarray(rest_positions, dtype=np.float64)
    rest_dist = np.linalg.norm(np.diff(body.sheet_keypoints(rest)[..., 0:5, :], axis=-2), axis=-1)
    ratio = np.linalg.norm(np.diff(sheet[:, 0:5], axis=1), axis=-1) / rest_dist  # (W, 4), rest broadcast

    # --- per image ---
    pose_body = pose_matrix(Rb[wi], ob[wi])
    mags = pose_matrix(mrot[wi], mpos[wi])
    kw = kp_world[wi]
    uv, kc = cameras.project(kw)
    wuv, _ = cameras.project(pos[wi])
    out = {
        "poses/body": pose_body, "poses/ipm": mags[:, 1:4], "poses/epm": mags[:, 0],
        "poses/body_quat": matrix_to_quat_wxyz(Rb[wi]),
        "keypoints/world": kw, "keypoints/camera": kc, "keypoints/pixel": uv,
    }
    img = {} if images is None else _image_labels(images, uv, kc[..., 2], keypoint_depth_tolerance(
        body, np.broadcast_to(np.asarray(ipm_diameter, dtype=np.float64), (pos.shape[0],)))[wi])
    # (the order of the keys is the order a shard creates its HDF5 datasets in: kept as it always was, so that the
    # files stay byte-identical)
    if images is not None:
        out["keypoints/visibility"] = img.pop("keypoints/visibility")
    for key, name in (("crease_angle", "creases/angle"), ("bar_strain", "bars/strain"), ("positions", "worm/vertices")):
        if key in states:
            out[name] = np.asarray(states[key])[wi].astype(np.float32)
    out["labels/bbox_obj"] = _xywh(wuv.min(axis=1), wuv.max(axis=1)).astype(np.float32)
    out.update(img)
    out["labels/deformation"] = ratio[wi].astype(np.float32)
    out["keypoints/body"] = keypoints_in_body(pose_body, kw)
    return out


def _image_labels(images: dict, uv: np.ndarray, z: np.ndarray, tol: np.ndarray) -> dict:
    """The labels that need the rendered images: visibility, the visible box and fraction, the worm mask."""
    segm = images["seg"]
    worm_vis = (segm >= SEG_WORM_FIRST) & (segm <= SEG_WORM_LAST)
    vb = _box_from_mask(worm_vis).astype(np.float32)  # inclusive pixels, -1 when hidden
    nv = worm_vis.sum(axis=(1, 2))
    nt = images["worm_mask"].sum(axis=(1, 2))
    return {
        "keypoints/visibility": keypoint_visibility(uv, z, images["depth"], segm, tol),
        "labels/bbox_visib": np.where(vb[:, :1] >= 0, _xywh(vb[:, :2], vb[:, 2:] + 1), 0).astype(np.float32),
        "labels/visib_fract": np.where(nt > 0, nv / np.maximum(nt, 1), 0.0).astype(np.float32),
        "labels/worm_mask": images["worm_mask"].astype(np.uint8),
    }


def band_centres(positions, triangles, triangle_segment, view=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Centres [m] of the five marker bands (segments 0..4, tail -> head; ``render.scene.BAND_COLORS``) as a camera
    looking along ``-view`` sees them: the centroid of each band's facets weighted by their area projected on
    ``view`` (facets facing away weigh 0), i.e. the centre of the band's pixels in an orthographic view.
    ``positions`` (..., V, 3), ``triangles`` (T, 3), ``triangle_segment`` (T,), ``view`` (3,) or (..., 3) unit
    (default: straight up, a camera above a flat floor). Returns (..., 5, 3); NaN for a band facing away entirely."""
    x = np.asarray(positions, dtype=np.float64)
    tri = np.asarray(triangles)
    a, b, c = (x[..., tri[:, k], :] for k in range(3))
    n2 = np.cross(b - a, c - a)  # 2 * area * unit normal
    v = np.asarray(view, dtype=np.float64)[..., None, :]
    w = np.maximum(np.einsum("...tc,...tc->...t", n2, np.broadcast_to(v, n2.shape)), 0.0)
    onehot = (np.asarray(triangle_segment)[:, None] == np.arange(5)[None]).astype(np.float64)  # (T, 5)
    num = np.einsum("...t,tb,...tc->...bc", w, onehot, (a + b + c) / 3.0)
    den = np.einsum("...t,tb->...b", w, onehot)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / den[..., None]


def band_pixel_centroids(seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (N, 5, 2) [px] of band b's visible pixels (segmentation id 2 + b) in each of N segmentation images
    (N, H, W), NaN when unseen, and the pixel counts (N, 5)."""
    seg = np.asarray(seg)
    N, H, W = seg.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    pix, cnt = np.full((N, 5, 2), np.nan), np.zeros((N, 5), np.int64)
    for b in range(5):
        m = seg == SEG_WORM_FIRST + b
        n = m.sum(axis=(1, 2))
        cnt[:, b] = n
        with np.errstate(invalid="ignore", divide="ignore"):
            pix[:, b] = np.stack([(m * u).sum(axis=(1, 2)), (m * v).sum(axis=(1, 2))], -1) / n[:, None]
    return pix, cnt


def band_labels(images: dict, cameras: Cameras) -> dict:
    """The marker bands as N rendered images show them (scenes painted with
    :func:`warpworm.render.scene.band_appearance`; what ``warpworm track`` measures): ``bands/pixel`` (N, 5, 2) [px]
    the centroid of band b's visible pixels (segmentation id 2 + b), ``bands/pixels`` (N, 5) their count,
    ``bands/world`` (N, 5, 3) [m] the mean surface point under them (pixels lifted with the depth); NaN when unseen."""
    seg = np.asarray(images["seg"])
    depth = np.asarray(images["depth"], dtype=np.float64)
    N, H, W = seg.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    Kinv = np.linalg.inv(cameras.K)
    ray = np.einsum("nij,jhw->nhwi", Kinv, np.stack([u, v, np.ones_like(u)]))  # z = 1 rays (N, H, W, 3)
    pc = ray * depth[..., None]
    pw = np.einsum("nji,nhwj->nhwi", cameras.R, pc - cameras.t[:, None, None])  # R^T (x_cam - t)
    pix, cnt = band_pixel_centroids(seg)
    world = np.full((N, 5, 3), np.nan)
    for b in range(5):
        with np.errstate(invalid="ignore", divide="ignore"):
            world[:, b] = np.einsum("nhw,nhwc->nc", seg == SEG_WORM_FIRST + b, pw) / cnt[:, b, None]
    return {"bands/pixel": pix, "bands/pixels": cnt, "bands/world": world}
