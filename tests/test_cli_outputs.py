"""What the commands show a person: search-gait's heat map covers every grid point with a colour bar, and its ranking
has no nan where the grid does not vary a field (issue 25: 206 x 196 px, title cut off, no colour bar, half the grid
hidden at the best point's a; `--grid w=0.016` printed nan for a and h)."""

from __future__ import annotations

import cv2
import numpy as np

from warpworm.analysis.gait_search import grid_points, parse_grid
from warpworm.commands.search_gait import AXES, full_points, write_heatmap
from warpworm.physics import gaits


def _result(grid_text, seed=0):
    pts = grid_points(parse_grid(grid_text))
    n = len(next(iter(pts.values())))
    rng = np.random.default_rng(seed)
    return {"points": pts, "per_cycle_m": rng.uniform(0.0, 0.01, n), "valid": rng.uniform(size=n) > 0.2}


def test_heatmap_shows_every_grid_point_with_a_colour_bar(tmp_path):
    res = _result("w=0.008:0.032:5,a=0.03,0.045,0.06,h=0.006:0.03:7")
    pts = full_points(res, gaits.preset_params("omega"))
    path = write_heatmap(tmp_path / "h.png", res, pts, "test")
    img = cv2.imread(str(path))
    assert img.shape[1] >= 640 and img.shape[0] >= 200
    # one panel per a: count the viridis cells of each colour; the best point is the one bright yellow cell, the
    # worst the one dark purple cell, and every invalid point a grey cell
    top, bottom = cv2.applyColorMap(np.array([[255]], np.uint8), cv2.COLORMAP_VIRIDIS)[0, 0], \
        cv2.applyColorMap(np.array([[0]], np.uint8), cv2.COLORMAP_VIRIDIS)[0, 0]
    grey = np.array([160, 160, 160])
    bar_x = img.shape[1] - 90 + 8  # the colour bar's column holds both ends too
    body = img[:, :bar_x - 10]

    def n_cells(colour):  # blobs of a cell's size (>= 14 x 10 px; anti-aliased text makes only specks)
        _, _, stats, _ = cv2.connectedComponentsWithStats(np.all(body == colour, axis=-1).astype(np.uint8))
        return int((stats[1:, cv2.CC_STAT_AREA] >= 140).sum()), stats[1:, cv2.CC_STAT_AREA]

    assert n_cells(top)[0] == 1 and n_cells(bottom)[0] == 1
    # grey cells: every invalid point (neighbours merge into one blob, so count pixels: one cell's area each)
    _, areas = n_cells(grey)
    cell = int(np.min(n_cells(top)[1][n_cells(top)[1] >= 140]))
    assert int(areas[areas >= 140].sum()) == cell * int((~res["valid"]).sum())
    assert np.all(img[:, bar_x] == top, axis=-1).any() and np.all(img[:, bar_x] == bottom, axis=-1).any()


def test_an_ungridded_field_is_the_presets_value_not_nan():
    res = _result("w=0.016")
    p = gaits.preset_params("omega")
    pts = full_points(res, p)
    assert set(pts) == {k for k, _ in AXES}
    for k in ("amplitude", "closest_approach"):
        assert np.all(pts[k] == float(np.asarray(getattr(p, k)).reshape(-1)[0]))
    assert np.isfinite(np.concatenate(list(pts.values()))).all()


def test_preview_key_names_every_keypoint_colour():
    """preview.png's key has one swatch per colour the contact sheet draws keypoints in (its own rule)."""
    from warpworm.data.previews import legend
    from warpworm.render.contact_sheet import _kp_color
    from warpworm.render.labels import KEYPOINT_NAMES

    img = legend(774)
    assert img.shape[1] == 774 and img.dtype == np.uint8
    first = img[:18]
    for colour in {tuple(_kp_color(n)) for n in KEYPOINT_NAMES}:
        assert np.all(first == np.array(colour, np.uint8), axis=-1).sum() >= 20, colour  # a filled swatch
