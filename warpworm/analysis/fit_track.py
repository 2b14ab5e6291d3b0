"""Fit worm parameters to a band track (``warpworm track``'s ratios and displacement): every candidate one world of
one batched simulation, searched with CMA-ES (the ``cma`` package) and polished by Levenberg-Marquardt; then a global
profile of every parameter over its whole search range (the others re-fitted, all points one batch a step), which
also moves a fit out of a side valley, and per parameter the acceptable range: every evaluated world within a
chi-square rise of 3.84 at the track's noise. A parameter whose range exceeds its tolerance is reported as not
identifiable from the track.

The simulated observable is the tracked one: each candidate world is run with the existing batched Simulator
(:func:`warpworm.analysis.gait_runs.run_gait`), its frames interpolated to the track's times and, when the track
came with its camera, rendered through that camera (band pixel centroids from the segmentation, then the same
back-projection onto the same plane as the tracker), so parallax of a lifted worm part is the same in both; without a
camera the band centres seen from above (:func:`warpworm.render.labels.band_centres`) are used. Parameters are
searched in log space within a factor ``spread`` of the gait preset's values. Residuals are scaled by the tracker's
accuracy (``SIGMA_RATIO``, ``SIGMA_DISP``), so the cost is a mean squared z-score.
"""

from __future__ import annotations

import time
from dataclasses import fields, replace

import numpy as np

from warpworm.analysis.gait_runs import run_gait
from warpworm.analysis.track import back_project, ratios_and_displacement
from warpworm.physics import gaits
from warpworm.physics.params import WormParams
from warpworm.render import Renderer, make_cameras
from warpworm.render.labels import band_centres, band_pixel_centroids
from warpworm.render.scene import build_scene

PATH_KEYS = {"w": "wavelength", "a": "amplitude", "h": "closest_approach"}
SIGMA_RATIO = 0.01
"""Tracker accuracy of a deformation ratio (tests/test_track.py), the residual's scale."""
SIGMA_DISP = 5e-4
"""Tracker accuracy of the displacement [m], the residual's scale."""
PIN_REL = 0.05
"""Default relative tolerance: a parameter is pinned when its acceptable range stays within ± this."""
TOLERANCE = {"epm_moment": 0.03}
"""Per-parameter tolerances other than PIN_REL (the EPM moment within 3 %: the calibration's target for a magnet's
strength)."""
ACCEPT_DCHI2 = 3.84
"""Chi-square rise of an acceptable candidate: the 95 % quantile of chi-square with one degree of freedom."""
PROFILE_FACTOR = 2.5
"""Geometric step of the global profile's grid, from the tolerance out to the search bound."""
VERDICT_MARGIN = 0.25
"""A verdict's margin, so that verdicts do not flip on image noise: a parameter is *pinned* when its acceptable
range's half-width is below tolerance / (1 + margin), *not pinned* above tolerance x (1 + margin) or at a search
bound, and *borderline* between. Where a re-rendering moves a range by less than these 25 % (the fit staying in its
basin) a verdict can change only between a definite state and borderline; pinned <-> not pinned needs the range to
change by a factor 1.25^2 = 1.56. The profile evaluates both edges of the band (held at the tolerance / 1.25 and
x 1.25) so its crossing there is measured, not extrapolated. Measured on path-traced footage the noise can move the
fit to another basin of a rugged cost and change a range by up to 124 % (docs/calibration.md, "Many worms")."""


def fittable_fields() -> tuple[str, ...]:
    """Scalar positive WormParams fields a track may fit."""
    p = WormParams()
    return tuple(f.name for f in fields(WormParams) if isinstance(getattr(p, f.name), float) and getattr(p, f.name) > 0
                 and f.name not in ("n_units",))


def parse_path(text: str | None) -> dict:
    """``"w=0.024,a=0.045,h=0.005"`` [m] -> WormParams path fields; None -> {}."""
    out = {}
    for item in filter(None, (text or "").split(",")):
        k, _, v = item.partition("=")
        if k.strip() not in PATH_KEYS:
            raise ValueError(f"--path {item!r}: unknown key {k!r}; expected w=, a=, h= (wavelength, amplitude, "
                             "closest approach [m])")
        try:
            val = float(v)
        except ValueError:
            raise ValueError(f"--path {item!r}: got {v!r}; expected a length [m]") from None
        if not (np.isfinite(val) and val >= 0):
            raise ValueError(f"--path {item!r}: got {val}; expected a length >= 0 [m]")
        out[PATH_KEYS[k.strip()]] = val
    return out


def parse_fit(text: str) -> list[str]:
    names = [n.strip() for n in text.split(",") if n.strip()]
    ok = fittable_fields()
    bad = [n for n in names if n not in ok]
    if not names or bad or len(set(names)) != len(names):
        raise ValueError(f"--fit: got {text!r}; expected distinct WormParams fields, e.g. hinge_stiffness,"
                         f"valley_bar_stiffness,mu_static,epm_moment (one of {ok})")
    return names


def candidate_params(base, names, values: np.ndarray):
    """``base`` WormParams with ``names`` set per world to ``values`` (W, p); mu_kinetic follows mu_static at the
    base's kinetic/static ratio."""
    v = np.asarray(values, np.float64)
    over = {n: v[:, i].copy() for i, n in enumerate(names)}
    if "mu_static" in over and "mu_kinetic" not in over:
        over["mu_kinetic"] = over["mu_static"] * float(base.mu_kinetic) / float(base.mu_static)
    return replace(base, **over)


def _interp(times_src, values, times):
    """values (F, W, ...) at times_src (F,) linearly interpolated at times (T,) -> (T, W, ...)."""
    j = np.clip(np.searchsorted(times_src, times, side="right"), 1, len(times_src) - 1)
    t0, t1 = times_src[j - 1], times_src[j]
    a = ((times - t0) / np.where(t1 > t0, t1 - t0, 1.0)).reshape((-1,) + (1,) * (values.ndim - 1))
    return (1 - a) * values[j - 1] + a * values[j]


def simulate_frames(params, num_worlds: int, times, *, settle=0.2, device="cpu") -> dict:
    """Run the batch and return its frames at ``times`` (T,) [s after settling]: ``positions`` (T, W, V, 3),
    ``magnet_pos``, ``magnet_rot``, ``unstable`` (W,), ``model``."""
    dt = gaits.DEFAULT_DT
    period = float(np.max(np.asarray(params.cycle_period)))
    r = run_gait(params, num_worlds, (float(np.max(times)) + 4 * dt) / period, device=device, settle=settle,
                 fps=1.0 / (2 * dt), save_worlds=num_worlds)
    fr = r["frames"]
    t = np.asarray(fr["time"], np.float64)
    out = {k: _interp(t, np.asarray(fr[k], np.float64), times) for k in ("positions", "magnet_pos", "magnet_rot")}
    bad = np.asarray(r["unstable"]) | ~np.isfinite(out["positions"]).all(axis=(0, 2, 3))
    out.update(unstable=bad, model=r["model"])
    return out


def band_pixels_from_render(frames: dict, model, cam, width: int, height: int, scale=0.5, chunk=64,
                            device="cpu") -> np.ndarray:
    """Band pixel centroids (T, W, 5, 2) [px of ``cam``] of every frame and world as ``cam`` (no distortion) sees
    them, from the renderer's segmentation at ``scale`` times the resolution; NaN where a band is unseen."""
    T_, W = frames["positions"].shape[:2]
    w_s, h_s = max(8, int(round(width * scale))), max(8, int(round(height * scale)))
    sx, sy = w_s / width, h_s / height
    K = cam.K.copy()
    K[0] *= sx
    K[1] *= sy
    K[0, 2], K[1, 2] = sx * (cam.K[0, 2] + 0.5) - 0.5, sy * (cam.K[1, 2] + 0.5) - 0.5
    renderer = Renderer(w_s, h_s, device=device)
    p = model.params
    pos = frames["positions"].reshape(T_ * W, -1, 3)
    rest = np.asarray(model.rest_positions_host)
    rest = np.broadcast_to(rest, (W,) + rest.shape[-2:])
    out = np.full((T_ * W, 5, 2), np.nan)
    for lo in range(0, T_ * W, chunk):
        idx = np.arange(lo, min(lo + chunk, T_ * W))
        wi = idx % W
        one = lambda a: np.broadcast_to(np.asarray(a, np.float64), (W,))[wi]  # noqa: E731
        scene = build_scene(pos[idx], model.pattern.triangles, model.pattern.triangle_segment,
                            magnet_pos=frames["magnet_pos"].reshape(T_ * W, 4, 3)[idx],
                            magnet_rot=frames["magnet_rot"].reshape(T_ * W, 4, 3, 3)[idx], worm_texcoords=rest[wi],
                            ipm_diameter=one(p.ipm_diameter), ipm_thickness=one(p.ipm_thickness),
                            floor_incline=one(p.floor_incline), show_epm=False)
        n = len(idx)
        cams = make_cameras(K, np.broadcast_to(cam.R, (n, 3, 3)), np.broadcast_to(cam.t, (n, 3)), np.arange(n),
                            w_s, h_s)
        pix, cnt = band_pixel_centroids(renderer.render(scene, cams)["seg"])
        out[idx, :, 0] = (pix[..., 0] + 0.5) / sx - 0.5  # back to the pixels of ``cam``
        out[idx, :, 1] = (pix[..., 1] + 0.5) / sy - 0.5
        out[idx] = np.where(cnt[..., None] < 3, np.nan, out[idx])
    return out.reshape(T_, W, 5, 2)


def observe(params, num_worlds: int, times, ref: int, meta: dict | None, *, render_scale=0.5, device="cpu") -> dict:
    """The simulated track of every world: ``ratios`` (W, T, 4), ``displacement`` (W, T) [m], ``unstable`` (W,),
    ``centres`` (W, T, 5, 3). ``meta``: the track's camera (``camera`` CameraModel, ``width``, ``height``,
    ``height_m``) or None (band centres seen from above)."""
    fr = simulate_frames(params, num_worlds, np.asarray(times, np.float64), device=device)
    model = fr["model"]
    if meta is not None and meta.get("camera") is not None:
        cam = meta["camera"]
        uv = band_pixels_from_render(fr, model, cam, meta["width"], meta["height"], render_scale, device=device)
        cam0 = replace(cam, dist=np.zeros(5))
        centres = back_project(uv, cam0, meta["height_m"])
    else:
        centres = band_centres(fr["positions"], model.pattern.triangles, model.pattern.triangle_segment)
    centres = np.moveaxis(centres, 0, 1)  # (W, T, 5, 3)
    r, d = ratios_and_displacement(centres, ref)
    return {"ratios": r, "displacement": d, "unstable": fr["unstable"], "centres": centres}


def residuals(obs: dict, track: dict) -> np.ndarray:
    """Scaled residuals (W, n) of every world against the track's finite ratios and displacements (z-scores)."""
    mr, md = track["ratios"], track["displacement"]
    okr, okd = np.isfinite(mr), np.isfinite(md)
    rr = (obs["ratios"][:, okr] - mr[okr]) / SIGMA_RATIO
    rd = (obs["displacement"][:, okd] - md[okd]) / SIGMA_DISP
    res = np.concatenate([rr, rd], axis=1)
    return np.where(np.isfinite(res) & ~obs["unstable"][:, None], res, 1e3)


def _stencil(x, step):
    """The point x (p,) and its central-difference neighbours x ± step e_i: (2p + 1, p)."""
    p = len(x)
    return np.concatenate([x[None], x + step * np.eye(p), x - step * np.eye(p)])


def _jacobian(res, p, step):
    """d residual / d log-parameter (n, p) from a :func:`_stencil` batch's residuals (2p + 1, n)."""
    return (res[1:1 + p] - res[1 + p:]).T / (2 * step)


def _as_clips(track, base, meta, ref=None) -> list[dict]:
    """One clip or several filmed of one worm -> [{"track", "base", "meta", "ref"}, ...]: ``track``, ``base`` and
    ``meta`` each one value (one clip) or a list (one per clip; a single base or meta serves every clip)."""
    tracks = track if isinstance(track, (list, tuple)) else [track]
    n = len(tracks)
    bases = base if isinstance(base, (list, tuple)) else [base] * n
    metas = meta if isinstance(meta, (list, tuple)) else [meta] * n
    if len(bases) != n or len(metas) != n:
        raise ValueError(f"clips: got {n} tracks, {len(bases)} bases, {len(metas)} cameras; expected one each")
    return [{"track": t, "base": b, "meta": m, "ref": int(t.get("ref", 0) if ref is None or n > 1 else ref)}
            for t, b, m in zip(tracks, bases, metas)]


def _evaluate(base, names, theta0, X, track, ref, meta, seen=None, **kw):
    """One batch: the cost (W,), residuals (W, n) and simulated tracks of the log-parameter points X (W, p);
    appends (X, cost) to ``seen``. Several clips of one worm (``track``, ``base``, ``meta`` lists, as
    :func:`_as_clips`): every clip's batch is run at the same points, their residuals joined (the first clip's
    simulated track under the plain keys, the others' as ``KEY@i``)."""
    vals = theta0[None] * np.exp(np.asarray(X, np.float64))
    res, obs = [], {}
    for i, c in enumerate(_as_clips(track, base, meta, ref)):
        o = observe(candidate_params(c["base"], names, vals), len(vals), c["track"]["time"], c["ref"], c["meta"], **kw)
        res.append(residuals(o, c["track"]))
        obs.update({(k if i == 0 else f"{k}@{i}"): v for k, v in o.items()})
    res = np.concatenate(res, axis=1)
    cost = np.mean(res ** 2, axis=1)
    if seen is not None:
        seen.append((np.asarray(X, np.float64), cost))
    return cost, res, obs


class _Batches:
    """Evaluates log-parameter points (W, p), clipped to ±``lim``, as one batch per call (:func:`_evaluate`) and keeps
    every evaluated point and its cost: the candidates the acceptable ranges are read from."""

    def __init__(self, base, names, theta0, track, ref, meta, lim, kw):
        self.args, self.lim, self.kw, self.seen = (base, names, theta0), lim, kw, []
        self.track, self.ref, self.meta = track, ref, meta

    def __call__(self, X):
        X = np.clip(np.asarray(X, np.float64), -self.lim, self.lim)
        return _evaluate(*self.args, X, self.track, self.ref, self.meta, seen=self.seen, **self.kw)

    def all(self) -> tuple[np.ndarray, np.ndarray]:
        """Every evaluated point (N, p) and its cost (N,)."""
        return np.concatenate([x for x, _ in self.seen]), np.concatenate([c for _, c in self.seen])

    @property
    def worlds(self) -> int:
        return sum(len(x) for x, _ in self.seen)


def tolerance(name: str) -> float:
    """The relative accuracy a fitted parameter must be known to for the track to pin it (k_α, μ_s and the rest
    5 %, the EPM moment 3 %)."""
    return TOLERANCE.get(name, PIN_REL)


def delta_chi2(cost, best_cost: float, n_res: int, p: int):
    """Chi-square rise of candidates of mean squared z-score ``cost`` over the best, at the track's noise: the
    tracker's accuracy (``SIGMA_RATIO``, ``SIGMA_DISP``, the z-scores' unit), or the best fit's residual variance
    RSS / (n - p) where that is larger. Not the residual alone: its frames are correlated (the simulated renders and
    the tracked images differ systematically), and at the residual's variance a planted value 0.8 % off was
    excluded (docs/calibration.md)."""
    return (np.asarray(cost) - best_cost) * n_res / max(1.0, best_cost * n_res / max(1, n_res - p))


def _search(ev, p, lim, budget, pop, seed, log, show, starts=None):
    """CMA-ES over the log-parameters within ±lim, one batch of ``pop`` worlds a generation, until ``budget``
    worlds. ``starts`` (k, p): points evaluated first as one batch (e.g. the plan's design worms); the search then
    starts at the best of them with half the spread. Returns the best point (p,) and the history [(worlds, best
    cost)]."""
    import cma

    x0, sigma, best = np.zeros(p), lim / 3, (np.inf, np.zeros(p))
    if starts is not None and len(starts):
        S = np.clip(np.asarray(starts, np.float64).reshape(-1, p), -lim, lim)
        c0 = ev(S)[0]
        k = int(np.argmin(c0))
        x0, sigma, best = S[k].copy(), lim / 6, (float(c0[k]), S[k].copy())
        if log:
            log(f"  {ev.worlds:4d} worlds (starts): best cost {best[0]:.4g}  {show(best[1])}")
    es = cma.CMAEvolutionStrategy(x0, sigma, {"bounds": [-lim, lim], "popsize": pop, "seed": seed + 1,
                                              "verbose": -9})
    history, worlds = [], 0
    while worlds + pop <= max(budget, pop):
        X = np.array(es.ask())
        cost = ev(X)[0]
        es.tell(list(X), cost.tolist())
        worlds += pop
        if cost.min() < best[0]:
            best = (float(cost.min()), X[int(np.argmin(cost))].copy())
        history.append((ev.worlds, best[0]))
        if log:
            log(f"  {ev.worlds:4d} worlds: best cost {best[0]:.4g}  {show(best[1])}")
    return best[1], history


def _refine(ev, x, steps, step, lim, history, log, show, tag="refine") -> dict:
    """``steps`` Levenberg-Marquardt steps from each start x (k, p) (or one point (p,)), all starts' steps and their
    central differences one batch of k(2p + 1) worlds a step. Returns the best point reached: ``x``, ``cost``,
    residuals ``r`` (n,), Jacobian ``J`` (n, p), ``obs`` (its world's simulated track)."""
    xs = np.atleast_2d(np.asarray(x, np.float64))
    k, p = xs.shape
    w = 2 * p + 1

    def run(points):
        cost, res, obs = ev(np.concatenate([_stencil(q, step) for q in points]))
        return [{"x": q, "cost": float(cost[i * w]), "r": res[i * w], "J": _jacobian(res[i * w:(i + 1) * w], p, step),
                 "obs": {kk: a[i * w] for kk, a in obs.items()}} for i, q in enumerate(np.clip(points, -lim, lim))]

    sts, lam = run(xs), np.full(k, 1e-2)
    for _ in range(steps):
        trial = []
        for st, lm in zip(sts, lam):
            A = st["J"].T @ st["J"]
            trial.append(st["x"] - np.linalg.solve(A + lm * np.diag(np.diag(A) + 1e-9), st["J"].T @ st["r"]))
        new = run(np.clip(np.array(trial), -lim, lim))
        for i in range(k):
            if new[i]["cost"] < sts[i]["cost"]:
                sts[i], lam[i] = new[i], lam[i] / 3
            else:
                lam[i] *= 4
        best = min(sts, key=lambda d: d["cost"])
        history.append((ev.worlds, best["cost"]))
        if log:
            log(f"  {ev.worlds:4d} worlds ({tag}): cost {best['cost']:.4g}  {show(best['x'])}")
    return min(sts, key=lambda d: d["cost"])


def _profile_dips(xb, cb, held, target, cost, x, limit=None):
    """Points (k, p) where a profile has a local minimum away from the fit (a dip between higher neighbours, or at
    its far end below its neighbour): another valley the fit may have missed, to be refined with every parameter
    free; the ``limit`` lowest (default p)."""
    limit = len(xb) if limit is None else limit
    out = []
    for i in np.unique(held):
        for sgn in (-1.0, 1.0):
            sel = np.nonzero((held == i) & (sgn * (target - xb[i]) > 0))[0]
            sel = sel[np.argsort(np.abs(target[sel] - xb[i]))]
            c = np.concatenate([[cb], cost[sel], [np.inf]])
            for j in range(1, len(c) - 1):
                if c[j] < c[j - 1] and c[j] <= c[j + 1]:
                    out.append((c[j], x[sel[j - 1]]))
    out.sort(key=lambda d: d[0])  # the lowest ``limit`` dips
    return np.array([d[1] for d in out[:limit]]).reshape(-1, len(xb))


def _profile_targets(xb, lim, names, factor=PROFILE_FACTOR):
    """The global profile's grid: each parameter i held at xb_i ± log(1 + tol_i) * factor^k (k = 0, 1, ...) up to
    and including the search bounds ±lim. Returns held (m,) parameter indices and target (m,) log values."""
    held, target = [], []
    for i, n in enumerate(names):
        t = np.log1p(tolerance(n))
        offs = t * factor ** np.arange(int(np.ceil(np.log(2 * lim / t) / np.log(factor))) + 1)
        offs = np.concatenate([offs, t * np.array([1 / (1 + VERDICT_MARGIN), 1 + VERDICT_MARGIN])])  # the verdict band
        v = np.unique(np.round(np.clip(xb[i] + np.concatenate([offs, -offs]), -lim, lim), 12))
        v = v[np.abs(v - xb[i]) > 1e-9]
        held += [i] * len(v)
        target += list(v)
    return np.array(held, np.int64), np.array(target, np.float64)


def _profile(ev, st, names, lim, steps):
    """The global profile: every parameter held at each :func:`_profile_targets` value over its whole range, the
    others re-fitted. All points of all parameters are one batch per step: the first batch evaluates two starts per
    point (the fit's linearised conditional minimum, and the lowest-cost candidate evaluated so far with that
    parameter near the held value), the better is kept; then ``steps`` Levenberg-Marquardt steps with a Broyden
    (secant) Jacobian per point, started from the fit's. Returns held (m,), target (m,), cost (m,), x (m, p)."""
    xb, J, r0 = st["x"], st["J"], st["r"]
    held, target = _profile_targets(xb, lim, names)
    m, p = len(held), len(xb)
    free = [np.array([j for j in range(p) if j != i]) for i in held]
    X0 = np.repeat(xb[None], m, 0)
    X0[np.arange(m), held] = target
    for k in range(m):
        f = free[k]
        if len(f):
            X0[k, f] += np.linalg.lstsq(J[:, f], -(r0 + J[:, held[k]] * (target[k] - xb[held[k]])), rcond=None)[0]
    Xs, cs = ev.all()
    extra, owner = [], []
    for k in range(m):
        near = np.abs(Xs[:, held[k]] - target[k]) <= 0.4 * abs(target[k] - xb[held[k]])
        if near.any():
            x = Xs[near][int(np.argmin(cs[near]))].copy()
            x[held[k]] = target[k]
            if np.abs(x - np.clip(X0[k], -lim, lim)).max() > 1e-6:
                extra.append(x)
                owner.append(k)
    cost, res, _ = ev(np.concatenate([X0] + ([np.array(extra)] if extra else [])))
    cur_x, cur_c, cur_r = np.clip(X0, -lim, lim), cost[:m].copy(), res[:m].copy()
    for e, k in enumerate(owner):
        if cost[m + e] < cur_c[k]:
            cur_x[k], cur_c[k], cur_r[k] = np.clip(extra[e], -lim, lim), cost[m + e], res[m + e]
    B, lam = np.repeat(J[None], m, 0), np.full(m, 1e-2)
    for _ in range(steps):
        trial = cur_x.copy()
        for k in range(m):
            f = free[k]
            if len(f):
                Bf = B[k][:, f]
                A = Bf.T @ Bf
                trial[k, f] -= np.linalg.solve(A + lam[k] * np.diag(np.diag(A) + 1e-9), Bf.T @ cur_r[k])
        trial = np.clip(trial, -lim, lim)
        cost, res, _ = ev(trial)
        for k in range(m):
            s = trial[k] - cur_x[k]
            if s @ s > 0:  # secant update from the step taken, accepted or not
                B[k] += np.outer(res[k] - cur_r[k] - B[k] @ s, s) / (s @ s)
            if cost[k] < cur_c[k]:
                cur_x[k], cur_c[k], cur_r[k], lam[k] = trial[k], cost[k], res[k], lam[k] / 3
            else:
                lam[k] *= 4
    return held, target, cur_c, cur_x


def acceptable_ranges(X, cost, xb, best_cost, n_res, lim, threshold=ACCEPT_DCHI2, profile=None):
    """The acceptable range of each log-parameter relative to xb (p,): the extent of every evaluated point X (N, p)
    whose chi-square rise over the best (:func:`delta_chi2`) is within ``threshold``, widened on each side to where
    the ``profile`` (held (m,), target (m,), cost (m,)) crosses the threshold between its last accepted point (or the
    fit) and the first rejected one beyond it (linear in the square root of the rise: exact for a quadratic profile).
    Returns lo (p,) <= 0, hi (p,) >= 0 (log offsets) and at_bound (p,) (an acceptable point on a search bound)."""
    p = X.shape[1]
    ok = delta_chi2(cost, best_cost, n_res, p) <= threshold
    A = np.concatenate([xb[None], X[ok]])
    lo, hi = np.minimum((A - xb).min(axis=0), 0.0), np.maximum((A - xb).max(axis=0), 0.0)
    at_bound = (np.abs(A) >= 0.999 * lim).any(axis=0) & ((hi > 0) | (lo < 0))
    if profile is not None:
        q = np.sqrt(np.maximum(delta_chi2(profile["cost"], best_cost, n_res, p), 0.0))
        for i in range(p):
            for sgn in (-1.0, 1.0):
                sel = (profile["held"] == i) & (sgn * (profile["target"] - xb[i]) > 0)
                g, qq = np.abs(profile["target"][sel] - xb[i]), q[sel]
                order = np.argsort(g)
                g, qq = np.concatenate([[0.0], g[order]]), np.concatenate([[0.0], qq[order]])
                out = np.nonzero(qq > np.sqrt(threshold))[0]
                if len(out) == 0:
                    continue
                k = out[0]  # the first rejected point; k - 1 is accepted
                edge = g[k - 1] + (g[k] - g[k - 1]) * (np.sqrt(threshold) - qq[k - 1]) / (qq[k] - qq[k - 1])
                if sgn > 0:
                    hi[i] = max(hi[i], edge)
                else:
                    lo[i] = min(lo[i], -edge)
    return lo, hi, at_bound


def fit_batches(ev, names, *, lim: float, budget: int, pop: int, seed: int = 0, step: float = 0.05, refine: int = 4,
                profile: int = 6, log=None, show=str, start=None, starts=None) -> dict:
    """The search and the global uncertainty over an evaluator ``ev`` (:class:`_Batches`: log-parameter points
    (W, p) -> cost (W,), residuals (W, n), obs; one batch a call; ``ev.all()`` every evaluated point): CMA-ES
    (:func:`_search`), ``refine`` Levenberg-Marquardt steps (:func:`_refine`), the global profile (:func:`_profile`),
    whose local minima away from the fit (:func:`_profile_dips`) are refined with every parameter free; a lower cost
    met anywhere, a chi-square drop above 1, moves the fit there, which is refined and profiled again (once). ``start`` (p,): refine from there instead of searching. Returns st (the fit's x, cost, r, J, obs),
    history, moved, profile (held, target, cost) or None, lo, hi (p,) (the acceptable range's log offsets), at_bound
    (p,), pinned (p,), n_res."""
    p = len(names)
    if start is None:
        xb, history = _search(ev, p, lim, budget, pop, seed, log, show, starts)
    else:
        xb, history = np.asarray(start, np.float64), []
    st = _refine(ev, xb, refine, step, lim, history, log, show)
    n_res, moved, prof = len(st["r"]), False, None
    for _ in range(2 if profile > 0 else 0):
        prof = _profile(ev, st, names, lim, profile)
        dips = _profile_dips(st["x"], st["cost"], *prof)
        if len(dips):  # other valleys the profile passed through: refined with every parameter free, one batch a step
            _refine(ev, dips, refine, step, lim, history, log, show, tag="profile dips")
        X, c = ev.all()
        j = int(np.argmin(c))
        if not c[j] < st["cost"]:
            break
        moved, significant = True, delta_chi2(c[j], st["cost"], n_res, p) < -1.0
        st = _refine(ev, X[j], refine if significant else 0, step, lim, history, log, show, tag="profile moved it")
        if not significant:
            break
    X, c = ev.all()
    prof = None if prof is None else {"held": prof[0], "target": prof[1], "cost": prof[2]}
    lo, hi, at_bound = acceptable_ranges(X, c, st["x"], st["cost"], n_res, lim, profile=prof)
    tol = np.array([tolerance(n) for n in names])
    verdict = verdicts(lo, hi, at_bound, tol)
    return {"st": st, "history": history, "moved": moved, "n_res": n_res, "lo": lo, "hi": hi, "at_bound": at_bound,
            "pinned": verdict == "pinned", "verdict": verdict, "tolerance": tol, "profile": prof}


def verdicts(lo, hi, at_bound, tol, margin: float = VERDICT_MARGIN) -> np.ndarray:
    """Per parameter "pinned", "borderline" or "not pinned" from the acceptable range's log offsets lo (p,) <= 0,
    hi (p,) >= 0, at_bound (p,) and the relative tolerances tol (p,) (:data:`VERDICT_MARGIN`)."""
    w = np.maximum(-np.asarray(lo), np.asarray(hi)) / np.log1p(np.asarray(tol, np.float64))
    out = np.where(w < 1 / (1 + margin) - 1e-9, "pinned", np.where(w > 1 + margin, "not pinned", "borderline"))
    return np.where(np.asarray(at_bound, bool), "not pinned", out).astype(object)


def fit(track, base, names, *, budget: int = 96, popsize: int | None = None, spread: float = 3.0, seed: int = 0,
        meta: dict | None = None, step: float = 0.05, refine: int = 4, profile: int = 6, log=None, starts=None,
        **kw) -> dict:
    """Fit ``names`` to ``track`` (or to several clips of one worm jointly: ``track``, ``base`` and ``meta`` lists,
    one per clip, their residuals joined; :func:`_as_clips`): every candidate one world of a batch (:func:`observe`)
    searched over log(names /
    base) within ±log(spread), CMA-ES with ``popsize`` worlds a generation until ``budget`` worlds, ``refine``
    Levenberg-Marquardt steps (2p + 1 worlds each), then the global profile with ``profile`` re-fit steps (0: none,
    the ranges then come from the search's candidates only) (:func:`fit_batches`). ``starts`` (k, p): parameter
    values evaluated first (e.g. the plan's design worms); the search starts at the best of them. A parameter is pinned when its
    acceptable range (:func:`acceptable_ranges` over every evaluated world) stays inside ±its :func:`tolerance`.

    Returns a dict: names, base, value (p,), x, cost, rms_ratio, rms_disp_m, chi2_red (at the tracker's accuracy),
    range_rel (p, 2) (the acceptable range relative to the fitted value), at_bound (p,), tolerance (p,), pinned (p,),
    sigma_rel (p,) (the local curvature's 1-sigma at the track's noise, for information), weakest (p,) (the least
    pinned combination of log-parameters at the fit), weakest_sigma, obs (the best world's simulated track),
    history [(worlds, best cost)], worlds, wall_s, moved (the profile moved the fit), profile (held, target, cost),
    n_res, threshold, evaluated (every evaluated point (N, p) and its cost)."""
    t0 = time.perf_counter()
    p = len(names)
    clips = _as_clips(track, base, meta)
    base0, track0 = clips[0]["base"], clips[0]["track"]
    theta0 = np.array([float(np.ravel(getattr(base0, n))[0]) for n in names])
    ref, lim = int(track0.get("ref", 0)), float(np.log(spread))
    pop = int(popsize or max(4 + int(3 * np.log(p)), 8))
    ev = _Batches(base, names, theta0, track, ref, meta, lim, kw)
    show = lambda x: "  ".join(f"{n}={v:.4g}" for n, v in zip(names, theta0 * np.exp(x)))  # noqa: E731
    out = fit_batches(ev, names, lim=lim, budget=budget, pop=pop, seed=seed, step=step, refine=refine,
                      profile=profile, log=log, show=show,
                      starts=None if starts is None else np.log(np.asarray(starts, np.float64) / theta0))
    st, n_res = out["st"], out["n_res"]
    r0, J = st["r"], st["J"]
    chi2 = float(np.sum(r0 ** 2) / max(1, n_res - p))
    jtj = J.T @ J
    evals, evecs = np.linalg.eigh(jtj)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.where(np.diag(jtj) > 0, np.sqrt(np.clip(np.diag(np.linalg.pinv(jtj)) * chi2, 0, None)), np.inf)
        weakest_sigma = float(np.sqrt(chi2 / evals[0])) if evals[0] > 0 else np.inf
    ok_r = [np.isfinite(c["track"]["ratios"]).sum() for c in clips]
    ok_d = [np.isfinite(c["track"]["displacement"]).sum() for c in clips]
    r_idx = np.concatenate([np.arange(o, o + a) for o, a in zip(np.cumsum([0] + [a + d for a, d in zip(ok_r, ok_d)]),
                                                                  ok_r)]).astype(int)
    d_idx = np.setdiff1d(np.arange(len(r0)), r_idx)
    return {
        "names": list(names), "base": theta0, "value": theta0 * np.exp(st["x"]), "x": st["x"], "cost": st["cost"],
        "rms_ratio": float(np.sqrt(np.mean(r0[r_idx] ** 2)) * SIGMA_RATIO),
        "rms_disp_m": float(np.sqrt(np.mean(r0[d_idx] ** 2)) * SIGMA_DISP), "chi2_red": chi2, "clips": len(clips),
        "range_rel": np.expm1(np.stack([out["lo"], out["hi"]], axis=1)), "at_bound": out["at_bound"],
        "tolerance": out["tolerance"], "pinned": out["pinned"], "verdict": out["verdict"], "sigma_rel": sigma, "weakest": evecs[:, 0],
        "weakest_sigma": weakest_sigma, "obs": st["obs"], "history": out["history"], "worlds": ev.worlds,
        "wall_s": time.perf_counter() - t0, "moved": out["moved"], "profile": out["profile"], "n_res": n_res,
        "threshold": ACCEPT_DCHI2, "evaluated": ev.all(),
    }


def report_lines(result: dict) -> list[str]:
    """The fit as text: value, acceptable range, tolerance, pinned or not, the weakest local combination."""
    out = [f"{'parameter':24s} {'preset':>11s} {'fitted':>11s} {'acceptable range':>20s} {'tol':>5s}  "
           "pinned by this track?"]
    verdict = result.get("verdict", np.where(result["pinned"], "pinned", "not pinned"))
    for n, b, v, (lo, hi), ab, tol, vd in zip(result["names"], result["base"], result["value"], result["range_rel"],
                                              result["at_bound"], result["tolerance"], verdict):
        rng = f"{100 * lo:+.1f}% .. {100 * hi:+.1f}%" + (" (bound)" if ab else "")
        say = {"pinned": "yes", "not pinned": "NO: not identifiable from this track",
               "borderline": f"borderline: within ±{100 * VERDICT_MARGIN:.0f} % of the tolerance (add a clip)"}[vd]
        out.append(f"{n:24s} {b:11.5g} {v:11.5g} {rng:>20s} {100 * tol:4.0f}%  {say}")
    X, c = result["evaluated"]
    n_ok = int((delta_chi2(c, result["cost"], result["n_res"], len(result["names"])) <= result["threshold"]).sum())
    out.append(f"acceptable: chi-square rise <= {result['threshold']:.2f} (95 %, one parameter) at the track's noise "
               f"(the tracker's accuracy, or the residual if larger); {n_ok} of {len(c)} evaluated worlds"
               + ("; the profile found a lower valley and moved the fit" if result["moved"] else "")
               + ("" if result["profile"] is not None else "; no profile (ranges from the search's candidates only)"))
    out.append(f"residual: ratios {result['rms_ratio']:.4f} rms, displacement {1e3 * result['rms_disp_m']:.3f} mm "
               f"rms (reduced chi2 {result['chi2_red']:.3g} at the tracker's accuracy)")
    loose = [n for n, ok in zip(result["names"], result["pinned"]) if not ok]
    out.append(f"verdicts: pinned below the tolerance / {1 + VERDICT_MARGIN:g}, not pinned above the tolerance x "
               f"{1 + VERDICT_MARGIN:g} or at a bound, borderline between (stable under re-rendering noise)")
    if loose:
        out.append(f"not identifiable from this track: {', '.join(loose)} (docs/calibration.md: which gait and how "
                   "many cycles pin which parameter; or measure it (steps 1-2) and pass it with --set)")
    w = result["weakest"]
    combo = " ".join(f"{c:+.2f}*log({n})" for c, n in zip(w, result["names"]) if abs(c) > 0.05)
    ws = result["weakest_sigma"]
    out.append(f"least pinned local combination: {combo}  (1-sigma {100 * ws:.2f}%)" if np.isfinite(ws) else
               f"least pinned local combination: {combo}  (flat)")
    return out


def write_fragment(path, gait: str, backward: bool, path_fields: dict, result: dict, base) -> str:
    """The fitted parameters as a YAML config fragment (``randomize.worm.*``: merge into a dataset config, or pass
    each as ``generate ... randomize.worm.NAME=VALUE`` / ``simulate --set NAME=VALUE``); returns the text. ``base``:
    the WormParams the fit started from (mu_kinetic follows mu_static as in :func:`candidate_params`)."""
    names = list(result["names"])
    fitted = candidate_params(base, names, np.asarray(result["value"], np.float64)[None])
    extra = ["mu_kinetic"] if "mu_static" in names and "mu_kinetic" not in names else []
    vals = {n: float(np.asarray(getattr(fitted, n)).reshape(-1)[0]) for n in names + extra}
    worm = {"gait": gait, "backward": bool(backward), **path_fields, **vals}
    lines = ["# warpworm fit-track: fitted worm parameters (a config fragment)",
             "# simulate: " + " ".join(f"--set {k}={v:.6g}" for k, v in {**path_fields, **vals}.items()),
             "randomize:", "  worm:"]
    for k, v in worm.items():
        lines.append(f"    {k}: {str(v).lower() if isinstance(v, bool) else (v if isinstance(v, str) else f'{v:.6g}')}")
    text = "\n".join(lines) + "\n"
    with open(path, "w") as f:
        f.write(text)
    return text


def plot_fit(path, track: dict, result: dict, title: str = "") -> None:
    """A Fig. 11-like picture: the four ratios and the displacement over time, measured (red) vs fitted (blue)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = track["time"]
    fig, ax = plt.subplots(1, 5, figsize=(17, 3.2))
    names = ("blue-pink", "pink-white", "white-green", "green-red")
    for i in range(4):
        ax[i].plot(t, track["ratios"][:, i], "r.-", label="measured")
        ax[i].plot(t, result["obs"]["ratios"][:, i], "b-", label="fitted")
        ax[i].set_title(names[i])
        ax[i].set_xlabel("time [s]")
    ax[0].set_ylabel("deformation ratio")
    ax[4].plot(t, 1e3 * track["displacement"], "r.-", label="measured")
    ax[4].plot(t, 1e3 * result["obs"]["displacement"], "b-", label="fitted")
    ax[4].set_title("displacement [mm]")
    ax[4].set_xlabel("time [s]")
    ax[4].legend()
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
