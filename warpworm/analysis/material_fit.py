"""Calibrate the crease stiffness k_α against a measured force–displacement curve (paper §IV-B, Fig. 7).

The paper tuned k_α until the simulated compression and 3-point flexure curves matched the measured ones. Here the
measured curve is a CSV table (:func:`read_curve`); every candidate k_α is one world of ONE batch of the virtual
experiment (:func:`warpworm.analysis.experiments.compression` / :func:`~warpworm.analysis.experiments.flexure`), every other parameter
held at the base (material) values. :func:`fit_hinge_stiffness` runs a log-spaced coarse batch over ``k_range``, a
finer log-spaced batch between the coarse minimum's neighbours, interpolates the minimum of the squared residual
with a parabola in log k_α, and runs the fitted k_α once more (one world) to report its residual and curve.

Host code (NumPy); SI units: displacement [m], force [N], k_α [N/rad].

CSV format (``TABLE.csv``)::

    displacement_m,force_n      <- header line (optional; with it, columns are found by name, extra ones ignored)
    0.0,0.0
    0.00025,0.0061
    ...

``displacement_m``: the head's shortening (compression) or the centre's deflection (flexure) [m], ≥ 0 and strictly
ascending; ``force_n``: the load-cell force [N] relative to the unloaded reading (the experiments subtract their
preload the same way). ``#`` starts a comment line; blank lines are skipped. At least 3 data rows.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from warpworm.analysis import experiments as ex

COLUMNS = ("displacement_m", "force_n")
TESTS = ("compression", "flexure")

FIT_SETTINGS = {
    "compression": dict(hold=0.2, settle=0.2, anchor_stiffness=1.0e4),
    "flexure": dict(hold=0.2, settle=0.2, anchor_stiffness=1.0e3),
}
"""Rig settings of the fits' experiments (overridable by keyword). ``hold`` 0.2 s per load step: the force is then
within ~1 % of its 0.4 s value (0.1 s, the sweep's default, is 1–3 % short of equilibrium). Flexure uses 1e3 N/m
anchors: its force (a few mN over a 17 mN preload) is read as k_a × a float32 position difference, which at 1e4 N/m
is quantized in ~19 µN steps (~3 % of the first load step); 1e3 N/m makes the steps 10× finer."""


class CurveError(ValueError):
    """A measured-curve table that cannot be used (message names the file, the column / value and the expectation)."""


def read_curve(path) -> tuple[np.ndarray, np.ndarray]:
    """Read and check a measured curve: returns ``displacement (N,)`` [m] and ``force (N,)`` [N], float64.

    Raises :class:`CurveError` for a missing file, missing / wrong columns, a non-numeric or non-finite value, fewer
    than 3 rows, a negative displacement or displacements that are not strictly ascending.
    """
    path = Path(path)
    if not path.is_file():
        raise CurveError(f"{path}: no such file (expected a CSV table with columns {', '.join(COLUMNS)})")
    with path.open(newline="") as fh:
        rows = [(i + 1, [c.strip() for c in r]) for i, r in enumerate(csv.reader(fh))
                if r and any(c.strip() for c in r) and not r[0].strip().startswith("#")]
    if not rows:
        raise CurveError(f"{path}: empty table (expected columns {', '.join(COLUMNS)} and at least 3 rows)")

    def _num(s):
        try:
            float(s)
            return True
        except ValueError:
            return False

    line, first = rows[0]
    if not all(_num(c) for c in first):  # a header line
        names = [c.lower() for c in first]
        missing = [c for c in COLUMNS if c not in names]
        if missing:
            raise CurveError(f"{path}: header (line {line}) {first} lacks column(s) {missing}; expected columns "
                             f"{', '.join(COLUMNS)} (displacement [m], force [N])")
        cols = [names.index(c) for c in COLUMNS]
        rows = rows[1:]
    else:
        if len(first) != 2:
            raise CurveError(f"{path}: line {line} has {len(first)} columns and no header; expected 2 columns "
                             f"{', '.join(COLUMNS)} (or a header line naming them)")
        cols = [0, 1]
    data = np.empty((len(rows), 2))
    for r, (line, vals) in enumerate(rows):
        for k, (c, name) in enumerate(zip(cols, COLUMNS)):
            if c >= len(vals) or vals[c] == "":
                raise CurveError(f"{path}: line {line} has no value in column {name!r}; expected a number")
            try:
                v = float(vals[c])
            except ValueError:
                raise CurveError(f"{path}: line {line}, column {name!r}: {vals[c]!r} is not a number") from None
            if not np.isfinite(v):
                raise CurveError(f"{path}: line {line}, column {name!r}: {vals[c]!r} is not finite; expected a "
                                 "finite number")
            data[r, k] = v
    if len(data) < 3:
        raise CurveError(f"{path}: {len(data)} data row(s); expected at least 3 (columns {', '.join(COLUMNS)})")
    d, f = data[:, 0], data[:, 1]
    lines = [ln for ln, _ in rows]
    if np.any(d < 0):
        i = int(np.argmax(d < 0))
        raise CurveError(f"{path}: line {lines[i]}, column 'displacement_m': {d[i]:g} is negative; expected "
                         "displacements >= 0 [m] (shortening / deflection)")
    if np.any(np.diff(d) <= 0):
        i = int(np.argmax(np.diff(d) <= 0)) + 1
        raise CurveError(f"{path}: line {lines[i]}, column 'displacement_m': {d[i]:g} after {d[i - 1]:g}; expected "
                         "strictly ascending displacements")
    if not np.any(d > 0):
        raise CurveError(f"{path}: column 'displacement_m' has no value > 0; expected a loading curve")
    return d, f


def write_curve(path, displacement, force) -> Path:
    """Write a curve table (header + rows) in the format :func:`read_curve` reads."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w") as fh:
        fh.write(",".join(COLUMNS) + "\n")
        for d, f in zip(np.asarray(displacement, np.float64), np.asarray(force, np.float64)):
            fh.write(f"{d:.9g},{f:.9g}\n")
    return path


def _interp_rows(xp, fp, x):
    """Row-wise linear interpolation (linear extrapolation at both ends): ``xp, fp (W, K)`` ascending, ``x (N,)``
    → ``(W, N)``. Vectorized over rows."""
    W, K = xp.shape
    j = np.clip((xp[:, :, None] <= x[None, None, :]).sum(axis=1) - 1, 0, K - 2)  # (W, N) segment index
    r = np.arange(W)[:, None]
    x0, x1, f0, f1 = xp[r, j], xp[r, j + 1], fp[r, j], fp[r, j + 1]
    dx = np.where(np.abs(x1 - x0) > 0, x1 - x0, 1.0)
    return f0 + (f1 - f0) * (x[None, :] - x0) / dx


def simulated_table(test: str, hinge_stiffness: float, *, base=None, increments: int = 8, noise: float = 0.0,
                    rng: np.random.Generator | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The table a bench test of a simulated worm gives: ``test``'s curve (the fits' rig settings,
    :data:`FIT_SETTINGS`) at ``hinge_stiffness`` [N/rad] with every other parameter at ``base``, ``increments`` load
    steps; every force times (1 + ``noise`` N(0, 1)) drawn from ``rng``. Returns ``displacement (increments + 1,)``
    [m] (the first row the unloaded state, 0) and ``force`` [N], as :func:`read_curve` returns a measured table."""
    if noise and rng is None:
        raise ValueError(f"simulated_table: noise {noise} needs rng, the generator its draws come from; got None")
    fn = ex.compression if test == "compression" else ex.flexure
    r = fn((hinge_stiffness,), increments=increments, base=base, **FIT_SETTINGS[test])
    d, f = r["displacement"][:, 0].copy(), r["force"][:, 0].astype(np.float64)
    d[0] = 0.0  # the unloaded row (measured ~1e-7 m, float32)
    if noise:
        f = f * (1.0 + noise * rng.standard_normal(f.shape))
    return d.astype(np.float64), f


def simulate_curves(test: str, hinge_stiffness, displacement, *, base=None, max_increments: int = 24,
                    **kwargs) -> dict:
    """One batch, one world per k_α: the simulated force at the measured displacements.

    The experiment prescribes the table's positive displacements as its load steps (or, for a table of more than
    ``max_increments`` rows, ``max_increments`` uniform steps up to its largest displacement), then the force of each
    world is interpolated at the table's displacements against the world's *measured* displacement (the anchors give
    a little, so it falls slightly short of the prescribed one; the last point is extrapolated linearly).

    Args:
        test: ``"compression"`` or ``"flexure"``.
        hinge_stiffness: candidate k_α [N/rad], shape (W,).
        displacement: the table's displacements [m], shape (N,), ascending, ≥ 0.
        base: the :class:`~warpworm.physics.params.WormParams` holding every other parameter (the material).
        kwargs: passed to the experiment (``hold``, ``settle``, ``anchor_stiffness``, ``dt``, …), over
            :data:`FIT_SETTINGS`.

    Returns: ``force (W, N)`` [N] at ``displacement``, and ``result``: the experiment's own result dict.
    """
    if test not in TESTS:
        raise ValueError(f"test: expected one of {TESTS}, got {test!r}")
    d = np.asarray(displacement, np.float64).reshape(-1)
    steps = d[d > 0]
    if len(steps) > max_increments:
        steps = np.linspace(0.0, d.max(), max_increments + 1)[1:]
    fn = ex.compression if test == "compression" else ex.flexure
    kw = dict(FIT_SETTINGS[test])
    kw.update(kwargs)
    r = fn(np.asarray(hinge_stiffness, np.float64).reshape(-1), displacements=steps, base=base, **kw)
    xp, fp = r["displacement"].T, r["force"].T  # (W, K + 1), first column the unloaded state
    return {"force": _interp_rows(xp, fp, d), "result": r}


def _rms(a, axis=-1):
    return np.sqrt(np.mean(np.square(a), axis=axis))


T_975 = (12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160, 2.145, 2.131,
         2.120, 2.110, 2.101, 2.093, 2.086)
"""Student's t 97.5 % quantiles for 1..20 degrees of freedom (beyond: 1.96 + 2.5 / dof, within 0.3 %)."""


def t_975(dof: int) -> float:
    """Student's t 97.5 % quantile for ``dof`` degrees of freedom: the half-width factor of a 95 % interval."""
    return T_975[dof - 1] if dof <= len(T_975) else 1.96 + 2.5 / dof


def log_half_width(residual, slope) -> float:
    """Half-width of the linearized 95 % interval of a one-parameter least-squares fit: t sqrt(RSS / (N - 1) /
    sum(slope²)) (t: :func:`t_975` of N - 1), from the ``residual`` (N,) at the fit and ``slope`` (N,), the model's
    derivative by the parameter (here ln k_α, so the result is a half-width in ln k_α; 0.05 is about ±5 %).
    Infinite with fewer than 2 points or a flat model."""
    r = np.asarray(residual, np.float64).reshape(-1)
    j = np.asarray(slope, np.float64).reshape(-1)
    if len(r) < 2 or not np.any(j):
        return float("inf")
    return float(t_975(len(r) - 1) * np.sqrt(np.sum(r ** 2) / (len(r) - 1) / np.sum(j ** 2)))


def fit_hinge_stiffness(test: str, displacement, force, *, base=None, k_range=(5.0e-4, 0.1), coarse: int = 24,
                        fine: int = 16, verify: bool = True, **kwargs) -> dict:
    """Fit k_α [N/rad] so that the simulated ``test`` curve matches a measured one (least squares in force).

    Every other parameter is held at ``base`` (e.g. :func:`warpworm.physics.materials.material_params`). Stage 1: ``coarse``
    candidates log-spaced over ``k_range``, one batch; stage 2: ``fine`` candidates log-spaced between the stage-1
    minimum's neighbours, one batch; the minimum of the sum of squared residuals is interpolated by a parabola in
    log k_α through the stage-2 minimum and its neighbours. With ``verify`` the fitted k_α runs once more, with k_α
    2 % above and below it (one batch of three worlds): its residual and curve are reported, and how well the curve
    pins k_α (:func:`log_half_width` from the residual and the curve's slope); otherwise the curve is interpolated
    (in log k_α) from stage 2 and the half-width is not computed.

    Args:
        test: ``"compression"`` or ``"flexure"``.
        displacement: measured displacements [m], shape (N,), ascending, ≥ 0 (:func:`read_curve`).
        force: measured forces [N], shape (N,), relative to the unloaded reading.
        k_range: (low, high) search bounds [N/rad].
        kwargs: passed to the experiment (``hold``, ``settle``, ``max_increments``, …).

    Returns a dict: ``hinge_stiffness`` (fitted k_α [N/rad]), ``rms_residual_n`` [N], ``relative_residual`` (RMS
    residual over the RMS measured force), ``at_bound`` (True when the coarse minimum sits at an end of ``k_range``:
    widen it), ``sensitivity`` (d ln RMS(F_sim) / d ln k_α at the fit: how strongly the curve depends on k_α),
    ``half_width_log`` (the 95 % half-width in ln k_α, NaN without ``verify``) and ``interval_rel`` (that interval
    relative to the fit, (low, high)), ``coarse`` / ``fine`` (``k (W,)``, ``rms (W,)`` [N]), ``displacement (N,)``,
    ``force (N,)``, ``fitted_force (N,)`` [N], and ``summary`` (JSON-ready).
    """
    d = np.asarray(displacement, np.float64).reshape(-1)
    f = np.asarray(force, np.float64).reshape(-1)
    if d.shape != f.shape:
        raise ValueError(f"displacement {d.shape} and force {f.shape}: expected equal shapes (N,)")
    lo, hi = float(k_range[0]), float(k_range[1])
    if not 0 < lo < hi:
        raise ValueError(f"k_range: expected 0 < low < high [N/rad], got {k_range}")

    def sse(ks):
        sim = simulate_curves(test, ks, d, base=base, **kwargs)
        res = sim["force"] - f[None]
        return np.sum(res ** 2, axis=1), sim

    k1 = np.geomspace(lo, hi, coarse)
    s1, sim1 = sse(k1)
    i1 = int(np.argmin(s1))
    at_bound = i1 in (0, coarse - 1)
    k2 = np.geomspace(k1[max(i1 - 1, 0)], k1[min(i1 + 1, coarse - 1)], fine)
    s2, sim2 = sse(k2)
    i2 = int(np.argmin(s2))
    lk = np.log(k2)
    k_fit = float(k2[i2])
    if 0 < i2 < fine - 1:
        x, y = lk[i2 - 1:i2 + 2], s2[i2 - 1:i2 + 2]
        a, b, _ = np.polyfit(x - x[1], y, 2)
        if a > 0:
            k_fit = float(np.exp(x[1] + np.clip(-b / (2 * a), x[0] - x[1], x[2] - x[1])))
    half = float("nan")
    if verify:
        step = 0.02
        sim3 = simulate_curves(test, [k_fit, k_fit * np.exp(-step), k_fit * np.exp(step)], d, base=base, **kwargs)
        fitted = sim3["force"][0]
        half = log_half_width(fitted - f, (sim3["force"][2] - sim3["force"][1]) / (2 * step))
    else:
        j = int(np.clip(np.searchsorted(lk, np.log(k_fit)) - 1, 0, fine - 2))
        w = (np.log(k_fit) - lk[j]) / (lk[j + 1] - lk[j])
        fitted = (1 - w) * sim2["force"][j] + w * sim2["force"][j + 1]
    rms = float(_rms(fitted - f))
    rel = rms / max(float(_rms(f)), 1e-300)
    # sensitivity from the coarse grid around the minimum (central difference of ln RMS force in ln k)
    rf = _rms(sim1["force"], axis=1)
    ja, jb = max(i1 - 1, 0), min(i1 + 1, coarse - 1)
    sens = float(np.log(rf[jb] / rf[ja]) / np.log(k1[jb] / k1[ja])) if jb > ja and rf[ja] > 0 else float("nan")
    unstable = int(sim1["result"]["unstable"].sum() + sim2["result"]["unstable"].sum())
    half_rel = [float(np.expm1(-half)), float(np.expm1(half))]  # the 95 % interval of k_α, relative
    summary = {
        "test": test, "hinge_stiffness_N_per_rad": k_fit, "rms_residual_N": rms, "rms_residual_mN": 1e3 * rms,
        "relative_residual": rel, "at_search_bound": bool(at_bound), "sensitivity_dlnF_dlnk": sens,
        "search_range_N_per_rad": [lo, hi], "coarse_worlds": int(coarse), "fine_worlds": int(fine),
        "fine_range_N_per_rad": [float(k2[0]), float(k2[-1])], "rows": int(len(d)),
        "max_displacement_mm": 1e3 * float(d.max()), "max_force_mN": 1e3 * float(np.abs(f).max()),
        "unstable_worlds": unstable, "hinge_stiffness_95_rel": half_rel,
    }
    return {
        "test": test, "hinge_stiffness": k_fit, "rms_residual_n": rms, "relative_residual": rel,
        "at_bound": bool(at_bound), "sensitivity": sens, "half_width_log": half, "interval_rel": half_rel,
        "coarse": {"k": k1, "rms": np.sqrt(s1 / len(d))}, "fine": {"k": k2, "rms": np.sqrt(s2 / len(d))},
        "displacement": d, "force": f, "fitted_force": fitted, "summary": summary,
    }
