"""Moment calibration: a planted moment is recovered from synthetic force–distance tables."""

import numpy as np
import pytest

from warpworm.analysis import calibration as cal
from warpworm.physics import magnets as mg

GAPS = np.array([1, 2, 3, 5, 7, 10, 15, 20, 30]) * 1e-3


def test_recovers_planted_moment_noise_free(tmp_path):
    cube = mg.Cuboid(0.01, moment=0.9)
    forces = cal.pair_forces(cube, cube, GAPS)
    path = cal.write_table(tmp_path / "table.csv", GAPS, forces)
    fit = cal.fit_moment(path, shape="cube", size=0.01)
    assert fit.moment == pytest.approx(0.9, rel=1e-4)
    assert fit.polarization == pytest.approx(1.1310, rel=1e-3)
    assert fit.residual_rel < 1e-5
    assert np.allclose(fit.predicted, forces, rtol=1e-4)


def test_recovers_planted_moment_with_noise():
    rng = np.random.default_rng(0)
    disk = mg.Cylinder(0.01, 0.003, moment=0.2)
    forces = cal.pair_forces(disk, disk, GAPS)
    noisy = forces * (1 + 0.01 * rng.normal(size=forces.shape))  # 1 % measurement noise
    fit = cal.fit_moment((GAPS, noisy), shape="cylinder", diameter=0.01, height=0.003, relative=True)
    assert fit.moment == pytest.approx(0.2, rel=0.01)
    assert 0.002 < fit.residual_rel < 0.05


def test_known_target_fits_the_source_linearly():
    bar = mg.Cuboid((0.01, 0.01, 0.02), moment=1.5)
    cube = mg.Cuboid(0.01, moment=0.8)
    forces = cal.pair_forces(bar, cube, GAPS[:6])
    fit = cal.fit_moment((GAPS[:6], forces), shape="cube", size=(0.01, 0.01, 0.02), target=cube)
    assert fit.moment == pytest.approx(1.5, rel=1e-4)


def test_paper_fit_with_dipoles_model():
    # a table from the exact model, fitted with the paper's 64/cm³ dipoles over the operating range (>= 5 mm)
    cube = mg.Cuboid(0.01, moment=0.9)
    g = GAPS[GAPS >= 5e-3]
    fit = cal.fit_moment((g, cal.pair_forces(cube, cube, g)), model="dipoles")
    assert fit.moment == pytest.approx(0.9, rel=1e-3)


def test_cli_prints_fit(tmp_path, capsys):
    from warpworm.cli import main

    cube = mg.Cuboid(0.01, moment=0.9)
    path = cal.write_table(tmp_path / "t.csv", GAPS, cal.pair_forces(cube, cube, GAPS))
    assert main(["calibrate", str(path), "--shape", "cube", "--size", "0.01"]) == 0
    out = capsys.readouterr().out
    assert "fitted moment: 0.9" in out and "residual" in out


def test_bad_table(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("gap_m,force_N\n0.001,abc\n")
    with pytest.raises(ValueError, match="bad.csv:2"):
        cal.fit_moment(p)
