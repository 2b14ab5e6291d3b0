"""k_α calibration from a force–displacement table (warpworm.analysis.material_fit) against planted truths.

Truth: a k_α planted in a simulated curve (the default material, mineral paper, every other parameter held), with
2 % multiplicative Gaussian noise (fixed seed), written to CSV and fitted back through the file reader.
"""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.analysis import material_fit as mf
from warpworm.physics.materials import material_params

K_PLANTED = 0.008  # N/rad, between mineral paper (0.005) and tracing paper (0.010)
FAST = dict(coarse=16, fine=8)  # 16 + 8 + 1 worlds: three batches


def _planted_table(tmp_path, test, seed=0):
    base = material_params("mineral_paper")
    d, noisy = mf.simulated_table(test, K_PLANTED, base=base, noise=0.02, rng=np.random.default_rng(seed))
    return mf.write_curve(tmp_path / f"{test}.csv", d, noisy), base


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("fit")
    out = {}
    for test in mf.TESTS:
        path, base = _planted_table(tmp, test)
        d, f = mf.read_curve(path)
        out[test] = mf.fit_hinge_stiffness(test, d, f, base=base, **FAST)
    return out


def test_compression_fit_recovers_planted_hinge_stiffness(fits):
    fit = fits["compression"]
    assert not fit["at_bound"] and fit["summary"]["unstable_worlds"] == 0
    assert abs(fit["hinge_stiffness"] / K_PLANTED - 1.0) < 0.05, fit["summary"]
    # the residual is the planted noise (2 % per point), not a misfit
    assert fit["relative_residual"] < 0.03, fit["summary"]
    assert fit["sensitivity"] > 0.3, fit["summary"]  # the curve does depend on k_α at this material
    # the reported 95 % interval holds the planted value and is about what 2 % noise on 8 points allows:
    # 2.36 x 2 % / (0.48 sqrt 8) = 3.5 % for a curve with d ln F / d ln k = 0.48
    lo, hi = fit["interval_rel"]
    assert fit["hinge_stiffness"] * (1 + lo) <= K_PLANTED <= fit["hinge_stiffness"] * (1 + hi), fit["summary"]
    assert 0.015 < fit["half_width_log"] < 0.055, fit["summary"]  # 3.5 % x the 95 % range of s / sigma at 7 dof


def test_compression_and_flexure_fits_agree(fits):
    kc, kf = fits["compression"]["hinge_stiffness"], fits["flexure"]["hinge_stiffness"]
    assert abs(kf / K_PLANTED - 1.0) < 0.05, fits["flexure"]["summary"]
    assert abs(kc / kf - 1.0) < 0.10, (kc, kf)


def _write(path, text):
    path.write_text(text)
    return path


@pytest.mark.parametrize("text, match", [
    ("displacement_m,force\n0,0\n1e-3,1e-2\n2e-3,2e-2\n", r"lacks column\(s\) \['force_n'\]"),
    ("0,0,0\n1e-3,1e-2,0\n2e-3,2e-2,0\n", "3 columns and no header"),
    ("displacement_m,force_n\n0,0\n1e-3,1e-2\n", "2 data row.*at least 3"),
    ("displacement_m,force_n\n0,0\n1e-3,nan\n2e-3,2e-2\n", r"line 3, column 'force_n': 'nan' is not finite"),
    ("displacement_m,force_n\n0,0\n1e-3,abc\n2e-3,2e-2\n", r"line 3, column 'force_n': 'abc' is not a number"),
    ("displacement_m,force_n\n0,0\n2e-3,1e-2\n1e-3,2e-2\n", r"line 4, column 'displacement_m'.*strictly ascending"),
    ("displacement_m,force_n\n-1e-3,0\n1e-3,1e-2\n2e-3,2e-2\n", "negative"),
])
def test_bad_tables_raise_clear_errors(tmp_path, text, match):
    path = _write(tmp_path / "bad.csv", text)
    with pytest.raises(mf.CurveError, match=match) as exc:
        mf.read_curve(path)
    assert str(path) in str(exc.value)


def test_missing_file_and_headerless_table(tmp_path):
    with pytest.raises(mf.CurveError, match="no such file"):
        mf.read_curve(tmp_path / "nope.csv")
    d, f = mf.read_curve(_write(tmp_path / "ok.csv", "# comment\n0,0\n\n1e-3,1e-2\n2e-3,2.5e-2\n"))
    np.testing.assert_array_equal(d, [0.0, 1e-3, 2e-3])
    np.testing.assert_array_equal(f, [0.0, 1e-2, 2.5e-2])


def test_cli_fit_rejects_bad_table_before_simulating(tmp_path, capsys):
    from warpworm.cli import main

    bad = _write(tmp_path / "bad.csv", "displacement_m,force_n\n0,0\n1e-3,1e-2\n")
    assert main(["experiment", "compression", "--fit", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "at least 3" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_log_half_width_covers_95_percent_of_linear_fits():
    # mf.log_half_width is the linearized 95 % half-width of a one-parameter least-squares fit: on a model that is
    # exactly linear in its parameter (y = theta * slope + Gaussian noise), refitting 20000 noisy draws must put the
    # truth inside fit +- half-width in 95 % of them (binomial sd 0.15 %), with 8 points as in the docs' tables
    # (Student's t of 7 degrees of freedom matters there: 1.96 would cover ~91 %); its t quantiles against scipy's.
    from scipy import stats

    rng = np.random.default_rng(5)
    slope = np.linspace(0.5, 3.0, 8)
    draws = 20000
    y = 0.7 * slope + 0.1 * rng.standard_normal((draws, 8))
    theta = y @ slope / (slope @ slope)
    half = np.array([mf.log_half_width(yi - ti * slope, slope) for yi, ti in zip(y, theta)])
    assert abs(np.mean(np.abs(theta - 0.7) <= half) - 0.95) < 0.006  # 4 binomial sd
    assert mf.log_half_width(np.zeros(8), np.zeros(8)) == float("inf")  # a flat curve pins nothing
    dof = np.arange(1, 200)
    np.testing.assert_allclose([mf.t_975(int(d)) for d in dof], stats.t.ppf(0.975, dof), rtol=3e-3)


def test_a_noisy_table_without_a_generator_is_refused():
    with pytest.raises(ValueError, match="simulated_table: noise 0.02 needs rng"):
        mf.simulated_table("compression", K_PLANTED, noise=0.02)
