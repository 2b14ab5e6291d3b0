"""Fit worm parameters to a band track (``warpworm track``'s ratios and displacement): every candidate one world of
one batched simulation, searched with CMA-ES (the ``cma`` package), then the fit's local curvature for per-parameter
uncertainty and the combinations the track cannot pin down.

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

PATH_KEYS = {"w": "wavelength", "a": "amplitude", "h": "closest_approach"}
SIGMA_RATIO = 0.01
"""Tracker accuracy of a deformation ratio (tests/test_track.py), the residual's scale."""
SIGMA_DISP = 5e-4
"""Tracker accuracy of the displacement [m], the residual's scale."""
SCAN_STEPS = (-0.4, -0.2, -0.1, -0.05, 0.05, 0.1, 0.2, 0.4)
"""Steps in log-parameter space of the scan along the least pinned combination."""
PIN_REL = 0.05
"""A parameter is pinned down when its 1-sigma relative uncertainty is below this."""


def fittable_fields() -> tuple[str, ...]:
    """Scalar positive WormParams fields a track may fit."""
    from warpworm.physics.params import WormParams

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
    from warpworm.analysis.gait_runs import run_gait
    from warpworm.physics import gaits

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
    from warpworm.render import Renderer, make_cameras
    from warpworm.render.scene import build_scene
    from warpworm.render.labels import band_pixel_centroids

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
    from warpworm.analysis.track import back_project, ratios_and_displacement
    from warpworm.render.labels import band_centres

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


def _evaluate(base, names, theta0, X, track, ref, meta, seen=None, **kw):
    """One batch: the cost (W,), residuals (W, n) and simulated tracks of the log-parameter points X (W, p);
    appends (X, cost) to ``seen``."""
    vals = theta0[None] * np.exp(np.asarray(X, np.float64))
    obs = observe(candidate_params(base, names, vals), len(vals), track["time"], ref, meta, **kw)
    res = residuals(obs, track)
    cost = np.mean(res ** 2, axis=1)
    if seen is not None:
        seen.append((np.asarray(X, np.float64), cost))
    return cost, res, obs


def _uncertainty(J, xb, cb, chi2, n_res, lim, base, names, theta0, track, ref, meta, kw):
    """Per-parameter 1-sigma in log space (p,): the curvature's (J^T J scaled by the reduced chi-square when above
    1), at least the share of the least pinned combination's scanned extent (one batch along it, a chi-square rise
    of 1), at least the farthest evaluated point within that rise (a curved valley the curvature misses); inf when
    that reaches the search bound. Also returns the least pinned combination (p,), its 1-sigma, the scan and its
    chi-square rise."""
    jtj = J.T @ J
    evals, evecs = np.linalg.eigh(jtj)
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.sqrt(np.clip(np.diag(np.linalg.pinv(jtj) * max(1.0, chi2)), 0, None))
        weakest_sigma = float(np.sqrt(max(1.0, chi2) / evals[0])) if evals[0] > 0 else np.inf
    sigma = np.where(np.diag(jtj) > 0, sigma, np.inf)
    v = evecs[:, 0]
    scan = np.array(SCAN_STEPS)
    cs = _evaluate(base, names, theta0, np.clip(xb[None] + scan[:, None] * v[None], -lim, lim), track, ref, meta,
                   **kw)[0]
    dchi2 = (cs - cb) * n_res / max(1.0, chi2)
    inside = np.abs(scan[dchi2 <= 1.0])
    extent = float(inside.max()) if inside.size else 0.0
    if extent >= max(abs(scan)):
        extent = np.inf  # flat over the whole scan
    part = np.abs(v) > 0.05  # parameters taking part in the combination
    lift = np.zeros_like(sigma)
    lift[part] = np.abs(v[part]) * extent
    sigma = np.maximum(sigma, lift)
    X_all = np.concatenate([x for x, _ in kw["seen"]])
    c_all = np.concatenate([c for _, c in kw["seen"]])
    far = np.abs(X_all[(c_all - cb) * n_res / max(1.0, chi2) <= 1.0] - xb[None]).max(axis=0)
    sigma = np.where(far >= 0.999 * lim, np.inf, np.maximum(sigma, far))
    return sigma, v, max(weakest_sigma, extent), scan, dchi2


def _profile(xb, cb, n_res, chi2, lim, delta, iters, step, ev) -> tuple[np.ndarray, np.ndarray, float]:
    """Profile of every parameter at xb ± ``delta`` (log): that parameter held there, the others re-fitted by
    ``iters`` damped Gauss-Newton steps, all 2p profile points and their stencils one batch per step (``ev(X)`` ->
    cost (W,), residuals (W, n)). Returns the profile 1-sigma (p,) (delta over the square root of the smaller
    chi-square rise of the two sides; inf if a side does not rise), the best point the profiles met (p,) and its
    cost: below ``cb`` means the fit had not found the minimum."""
    p = len(xb)
    pts = np.array([np.clip(xb + sgn * delta * np.eye(p)[i], -lim, lim) for i in range(p) for sgn in (-1, 1)])
    held = np.repeat(np.arange(p), 2)
    best_c = np.full(len(pts), np.inf)
    best_x = pts.copy()
    for _ in range(max(1, iters)):
        batch, where = [], []
        for k, (x, i) in enumerate(zip(pts, held)):
            free = [j for j in range(p) if j != i]
            st = [x] + [x + step * np.eye(p)[j] for j in free] + [x - step * np.eye(p)[j] for j in free]
            where.append((len(batch), free))
            batch += st
        cost, res = ev(np.clip(np.array(batch), -lim, lim))
        for k, (at, free) in enumerate(where):
            q = len(free)
            if cost[at] >= best_c[k]:  # no better: back halfway toward the best so far
                pts[k] = 0.5 * (pts[k] + best_x[k])
                continue
            best_c[k], best_x[k] = cost[at], pts[k].copy()
            J = (res[at + 1:at + 1 + q] - res[at + 1 + q:at + 1 + 2 * q]).T / (2 * step)
            A = J.T @ J
            dx = -np.linalg.solve(A + 0.1 * np.diag(np.diag(A) + 1e-9), J.T @ res[at])
            pts[k, free] = np.clip(pts[k, free] + dx, -lim, lim)
    rise = (best_c - cb) * n_res / max(1.0, chi2)
    side = np.minimum(rise[0::2], rise[1::2])
    with np.errstate(divide="ignore", invalid="ignore"):
        sigma = np.where(side > 0, delta / np.sqrt(np.maximum(side, 1e-300)), np.inf)
    k = int(np.argmin(best_c))
    return sigma, best_x[k], float(best_c[k])


def fit(track: dict, base, names, *, budget: int = 96, popsize: int | None = None, spread: float = 3.0, seed: int = 0,
        meta: dict | None = None, step: float = 0.05, refine: int = 4, profile: int = 3, log=None, **kw) -> dict:
    """CMA-ES over log(names / base) within ±log(spread), each generation one batch of ``popsize`` worlds, until
    ``budget`` worlds; then ``refine`` Levenberg-Marquardt steps from the best point, each one batch of 2p + 1 worlds
    (the step and its central differences of ``step`` in log); then ``profile`` steps of every parameter's profile
    (:func:`_profile`, 2p(2p - 1) worlds a step; 0: none), which also moves the fit when they meet a lower valley; the
    1-sigma is the larger of the profile's and :func:`_uncertainty`'s (one more batch). Returns a dict: names, base, value (p,), cost, rms_ratio, rms_disp_m, chi2_red, sigma_rel (p,), pinned
    (p,) bool, weakest (p,) (the least pinned combination of log-parameters) and weakest_sigma, obs (the best world's
    simulated track), history (list of (worlds, best cost)), worlds, wall_s, scan."""
    import cma

    t0 = time.perf_counter()
    p = len(names)
    theta0 = np.array([float(np.ravel(getattr(base, n))[0]) for n in names])
    ref = int(track.get("ref", 0))
    pop = int(popsize or max(4 + int(3 * np.log(p)), 8))
    lim = float(np.log(spread))
    es = cma.CMAEvolutionStrategy(np.zeros(p), lim / 3, {"bounds": [-lim, lim], "popsize": pop, "seed": seed + 1,
                                                         "verbose": -9})
    best = (np.inf, np.zeros(p))
    history, worlds = [], 0
    kw = dict(kw, seen=[])
    while worlds + pop <= max(budget, pop):
        X = np.array(es.ask())
        cost = _evaluate(base, names, theta0, X, track, ref, meta, **kw)[0]
        es.tell(list(X), cost.tolist())
        worlds += pop
        if cost.min() < best[0]:
            best = (float(cost.min()), X[int(np.argmin(cost))].copy())
        history.append((worlds, best[0]))
        if log:
            log(f"  {worlds:4d} worlds: best cost {best[0]:.4g}  " + "  ".join(
                f"{n}={v:.4g}" for n, v in zip(names, theta0 * np.exp(best[1]))))
    xb, cb = best[1], best[0]
    cost, res, obs = _evaluate(base, names, theta0, _stencil(xb, step), track, ref, meta, **kw)
    worlds += 2 * p + 1
    cb, r0, J, ob = float(cost[0]), res[0], _jacobian(res, p, step), obs
    lam = 1e-2
    for _ in range(refine):  # Levenberg-Marquardt from the best point, the step and its stencil one batch each
        A = J.T @ J
        dx = -np.linalg.solve(A + lam * np.diag(np.diag(A) + 1e-9), J.T @ r0)
        xn = np.clip(xb + dx, -lim, lim)
        cost, res, obs = _evaluate(base, names, theta0, _stencil(xn, step), track, ref, meta, **kw)
        worlds += 2 * p + 1
        if cost[0] < cb:
            xb, cb, r0, J, ob, lam = xn, float(cost[0]), res[0], _jacobian(res, p, step), obs, lam / 3
        else:
            lam *= 4
        history.append((worlds, cb))
        if log:
            log(f"  {worlds:4d} worlds (refine): cost {cb:.4g}  " + "  ".join(
                f"{n}={v:.4g}" for n, v in zip(names, theta0 * np.exp(xb))))
    n_res = len(r0)
    chi2 = float(np.sum(r0 ** 2) / max(1, n_res - p))
    prof_sigma, moved = np.zeros(p), False
    if profile > 0:
        def ev(X):
            c, r, _ = _evaluate(base, names, theta0, X, track, ref, meta, **kw)
            return c, r

        prof_sigma, xp, cp = _profile(xb, cb, n_res, chi2, lim, 0.15, profile, step, ev)
        worlds += 2 * p * (2 * p - 1) * profile
        if cp < cb:  # the profiles found a lower valley: polish there instead
            moved = True
            cost, res, obs = _evaluate(base, names, theta0, _stencil(xp, step), track, ref, meta, **kw)
            worlds += 2 * p + 1
            if cost[0] < cb:
                xb, cb, r0, J, ob = xp, float(cost[0]), res[0], _jacobian(res, p, step), obs
            if log:
                log(f"  {worlds:4d} worlds (profile found a lower valley): cost {cb:.4g}  " + "  ".join(
                    f"{n}={v:.4g}" for n, v in zip(names, theta0 * np.exp(xb))))
        chi2 = float(np.sum(r0 ** 2) / max(1, n_res - p))
    obs = ob
    sigma, v, weakest_sigma, scan, dchi2 = _uncertainty(J, xb, cb, chi2, n_res, lim, base, names, theta0, track, ref,
                                                        meta, kw)
    worlds += len(SCAN_STEPS)
    sigma = np.maximum(sigma, prof_sigma)
    nr = int(np.isfinite(track["ratios"]).sum())
    return {
        "names": list(names), "base": theta0, "value": theta0 * np.exp(xb), "x": xb, "cost": cb,
        "rms_ratio": float(np.sqrt(np.mean(r0[:nr] ** 2)) * SIGMA_RATIO),
        "rms_disp_m": float(np.sqrt(np.mean(r0[nr:] ** 2)) * SIGMA_DISP), "chi2_red": chi2,
        "sigma_rel": sigma, "pinned": sigma < PIN_REL, "weakest": v, "weakest_sigma": weakest_sigma,
        "obs": {k: a[0] for k, a in obs.items()}, "history": history, "worlds": worlds,
        "wall_s": time.perf_counter() - t0, "scan": (scan, dchi2), "profile_sigma": prof_sigma,
        "profile_moved": moved,
    }


def report_lines(result: dict) -> list[str]:
    """The fit as text: value, 1-sigma, pinned or not, the weakest combination."""
    out = [f"{'parameter':24s} {'preset':>11s} {'fitted':>11s} {'1-sigma':>9s}  pinned by this track?"]
    for n, b, v, s, ok in zip(result["names"], result["base"], result["value"], result["sigma_rel"],
                              result["pinned"]):
        sig = f"{100 * s:8.2f}%" if np.isfinite(s) else "unbounded"
        out.append(f"{n:24s} {b:11.5g} {v:11.5g} {sig:>9s}  {'yes' if ok else 'NO (not identifiable)'}")
    out.append(f"residual: ratios {result['rms_ratio']:.4f} rms, displacement {1e3 * result['rms_disp_m']:.3f} mm "
               f"rms (reduced chi2 {result['chi2_red']:.3g} at the tracker's accuracy)")
    w = result["weakest"]
    combo = " ".join(f"{c:+.2f}*log({n})" for c, n in zip(w, result["names"]) if abs(c) > 0.05)
    ws = result["weakest_sigma"]
    tail = f"{100 * ws:.2f}%" if np.isfinite(ws) else f"beyond the scan's ±{100 * max(SCAN_STEPS):.0f}%"
    out.append(f"least pinned combination: {combo}  (1-sigma {tail})")
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
