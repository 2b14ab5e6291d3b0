"""The marker bands outside the tracker (issue #26): ``render.band_colors`` in dataset configs (validated, used by
the renderer, recorded in the dataset and read back by ``warpworm track --band-colors-from``), and the bands in
``warpworm simulate``'s previews (``--texture-worm bands``)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from warpworm.data.config import ConfigError, load_config
from warpworm.render.scene import BAND_COLORS

COLORS = [[0.1, 0.2, 0.9], [0.9, 0.3, 0.6], [0.9, 0.9, 0.9], [0.3, 0.9, 0.1], [0.8, 0.1, 0.05]]


def _yaml(c) -> str:
    return "render.band_colors=[" + ",".join("[" + ",".join(str(v) for v in rgb) + "]" for rgb in c) + "]"


def test_band_colors_config_key_is_validated_and_left_out_when_absent():
    cfg = load_config("default", ["randomize.texture.worm=bands", _yaml(COLORS)])
    assert cfg.render.band_colors == COLORS and cfg.to_dict()["render"]["band_colors"] == COLORS
    assert "band_colors" not in load_config("default").to_dict()["render"]  # absent: config_yaml as before
    for bad, shown in ((COLORS[:4], "[[0.1"), ([[0.1, 0.2, 1.5]] + COLORS[1:], "1.5"), ("red", "'red'")):
        text = _yaml(bad) if isinstance(bad, list) else f"render.band_colors={bad}"
        with pytest.raises(ConfigError, match="render.band_colors") as e:
            load_config("default", [text])
        assert shown in str(e.value) and "expected" in str(e.value)


def test_band_colors_reach_the_renderer_and_the_dataset(tmp_path):
    from warpworm.analysis import track as T
    from warpworm.data import sampling
    from warpworm.data.job import generate

    over = ["randomize.texture.worm=bands", _yaml(COLORS)]
    cfg = load_config("default", over)
    a = sampling.sample_appearance(cfg, np.arange(2))  # albedo = display colour squared (render.scene.band_appearance)
    np.testing.assert_allclose(a.albedo[:, 2:7], np.broadcast_to(np.square(COLORS), (2, 5, 3)))
    # a tiny dataset records them (config_yaml), the tracker reads them back; one without the key gives the paper's
    for name, extra, want in (("custom", over, COLORS), ("paper", ["randomize.texture.worm=bands"], BAND_COLORS)):
        small = load_config("default", ["sim.worlds=1", "render.width=24", "render.height=16", "output.preview=false",
                                        "sim.frame_times=[0.052]", "shard_size=1", *extra], num_samples=1)
        generate(small, tmp_path / name, progress=False, log=lambda m: None)
        np.testing.assert_array_equal(T.dataset_band_colors(tmp_path / name), want)
    with pytest.raises(ValueError, match="--band-colors-from"):
        T.dataset_band_colors(tmp_path / "missing")


def test_band_facet_colours_paint_segments_tail_to_head():
    from warpworm.commands.simulate import band_facet_colours
    from warpworm.physics import crease

    pat = crease.build_worm(0.02, 0.008, 6, 0.08)
    bgr = band_facet_colours(pat.triangle_segment, COLORS)
    x = pat.vertices[pat.triangles].mean(axis=1)[:, 0]
    order = [int(np.round(x[pat.triangle_segment == s].mean() * 1e4)) for s in range(5)]
    assert order == sorted(order)  # segment 0 is the tail (smallest x)
    for s in range(5):
        want = np.round(255 * np.array(COLORS[s])[::-1])
        np.testing.assert_array_equal(bgr[pat.triangle_segment == s], np.broadcast_to(want, (15 if s != 2 else 12, 3)))


def test_simulate_previews_draw_the_bands(tmp_path, capsys):
    from warpworm.cli import main

    base = ["simulate", "--gait", "inchworm", "--cycles", "1", "--fps", "4", "--save-worlds", "1", "--json"]
    assert main(base + ["--texture-worm", "bands", "--out", str(tmp_path / "b")]) == 0
    assert main(base + ["--out", str(tmp_path / "p")]) == 0
    capsys.readouterr()
    banded = cv2.imread(str(tmp_path / "b" / "preview_strip.png"))
    plain = cv2.imread(str(tmp_path / "p" / "preview_strip.png"))
    for rgb in BAND_COLORS:  # each band's colour fills facets in the banded strip, not in the plain one (whose
        bgr = np.round(255 * rgb[::-1]).astype(np.uint8)  # anti-aliased outlines may hit the near-grey white)
        n_band, n_plain = ((im == bgr).all(axis=-1).sum() for im in (banded, plain))
        assert n_band > 2000 and n_plain < 0.01 * n_band, (rgb, n_band, n_plain)
    # refused before any work: colours without bands, malformed colours
    for extra in (["--band-colors", ";".join(",".join(map(str, c)) for c in COLORS)],
                  ["--texture-worm", "bands", "--band-colors", "1,0,0"]):
        assert main(base + extra + ["--out", str(tmp_path / "no")]) == 2
        assert not (tmp_path / "no").exists() and "--band-colors" in capsys.readouterr().err


def test_simulate_previews_follow_a_randomize_config_with_bands(tmp_path):
    import argparse

    import yaml

    from warpworm.commands.simulate import _preview_bands
    from warpworm.data.config import read_yaml

    raw = read_yaml("default")
    raw.setdefault("randomize", {}).setdefault("texture", {})["worm"] = "bands"
    raw.setdefault("render", {})["band_colors"] = COLORS
    path = tmp_path / "bands.yaml"
    path.write_text(yaml.safe_dump(raw))
    ns = dict(texture_worm=None, band_colors=None, randomize=str(path))
    np.testing.assert_array_equal(_preview_bands(argparse.Namespace(**ns)), COLORS)
    assert _preview_bands(argparse.Namespace(**{**ns, "texture_worm": "plain"})) is None  # the flag wins
    assert _preview_bands(argparse.Namespace(**{**ns, "randomize": "default"})) is None  # texture.worm plain/fibre
