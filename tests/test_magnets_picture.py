"""The field picture and the `warpworm field` command produce a real image."""

import cv2

from warpworm.analysis.field_plot import render_field_picture


def test_render_field_picture(tmp_path):
    path = render_field_picture(tmp_path / "f.png")
    img = cv2.imread(str(path))
    assert img is not None and img.shape[0] > 300 and img.shape[1] > 1000
    assert img.std() > 20  # not blank


def test_field_command(tmp_path, capsys):
    from warpworm.cli import main

    assert main(["field", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert (tmp_path / "field.png").exists() and "wrote" in out
