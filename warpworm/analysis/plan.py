"""Plan the clips to film before anyone films: which EPM paths (gait, w, a, h, cycles, direction) make
the parameters a user wants to calibrate identifiable from ``warpworm track``'s ratios and displacement, for any
worm inside the expected ranges.

Every candidate path x design worm x parameter perturbation is one world of one batched simulation
(:func:`warpworm.analysis.fit_track.simulate_frames`, gait and path per world): for each candidate and design worm the
Jacobian J of the track's z-scored observables (the four ratios over their first frame's and the displacement, at
12.5 frames/s; scaled by the tracker's accuracy ``SIGMA_RATIO``, ``SIGMA_DISP`` as ``fit-track``'s cost) with
respect to the log-parameters (central differences, ``step`` in log). A set of clips filmed of one worm adds its
Fisher information J^T J; its predicted acceptable half-width per parameter is sqrt(3.84 (F^-1)_ii) (the local
form of ``fit-track``'s chi-square-3.84 range). A clip whose track is not smooth at some design worm (the forward
and backward differences disagree by more than half their sum: a stick-slip event that comes or goes within ±5 %)
is never chosen: its central difference promises information that is a jump, and its cost has side valleys as low
as the true one (measured: a 2-cycle omega clip, w 12 mm, where the worm slides 50 mm, fitted 18 % off with
every parameter "pinned"). The plan is chosen greedily: the clip that lowers the worst
(over design worms and parameters) half-width / tolerance most, then the next, until every design worm's predicted
half-widths are within ``margin`` times the tolerances or ``max_clips`` clips are chosen.

The design worms span the ranges: the centre and the 2^p corners of the box in log-parameters, shrunk to
``corner_frac`` of the way out (the corners themselves are the least typical draws). Observables are the band centres
seen from above (:func:`warpworm.render.labels.band_centres`): the planning ignores the camera's parallax, which
``fit-track`` models.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import fields, replace

import numpy as np

from warpworm.analysis.fit_track import SIGMA_DISP, SIGMA_RATIO, candidate_params, simulate_frames, tolerance
from warpworm.analysis.track import ratios_and_displacement
from warpworm.physics import gaits
from warpworm.physics.gaits import GAIT_PRESETS
from warpworm.physics.params import VECTOR_FIELDS
from warpworm.render.labels import band_centres

PRODUCTION_RANGES = {"hinge_stiffness": (0.003, 0.01), "mu_static": (0.2, 0.4), "epm_moment": (3.0, 4.0)}
"""Production's ranges (dataset_configs/production.yaml) of the parameters a video calibrates."""
FPS = 12.5
"""Frames per second of the planned clips (and of the benchmark's footage)."""


def candidate_paths(gaits=("peristaltic", "omega", "inchworm"), w_scales=(0.75, 1.0, 1.25), a_scales=(0.75, 1.0, 1.3),
                    h_scales=(0.95, 1.3), cycles=(1.0, 2.0), directions=(False,)) -> list[dict]:
    """Candidate clips: every gait preset's path with its wavelength, amplitude and closest approach scaled (within
    production's ``wavelength_scale`` 0.75-1.25 and ``closest_approach_scale`` 0.95-1.3), ``cycles`` and direction
    (``backward``). Each a dict: gait, backward, wavelength, amplitude, closest_approach [m], cycles."""
    out = []
    for g, bw, ws, as_, hs, cy in itertools.product(gaits, directions, w_scales, a_scales, h_scales, cycles):
        pre = GAIT_PRESETS[g]
        out.append({"gait": g, "backward": bool(bw), "wavelength": pre["wavelength"] * ws,
                    "amplitude": pre["amplitude"] * as_, "closest_approach": pre["closest_approach"] * hs,
                    "cycles": float(cy)})
    return out


def design_worms(ranges: dict, corner_frac: float = 0.8) -> np.ndarray:
    """The design worms (D, p) inside ``ranges`` {name: (lo, hi)}: the log-centre and the 2^p corners pulled
    ``corner_frac`` of the way from the centre."""
    lo = np.log([r[0] for r in ranges.values()])
    hi = np.log([r[1] for r in ranges.values()])
    c, h = (lo + hi) / 2, (hi - lo) / 2
    pts = [c] + [c + corner_frac * h * np.array(s) for s in itertools.product((-1.0, 1.0), repeat=len(lo))]
    return np.exp(np.array(pts))


def clip_params(base, clip: dict, names, values: np.ndarray):
    """``base`` WormParams for W worlds of one clip: its gait, direction and path, and ``names`` set to ``values``
    (W, p) (mu_kinetic follows mu_static)."""
    p = replace(base, gait=clip["gait"], backward=bool(clip["backward"]), wavelength=float(clip["wavelength"]),
                amplitude=float(clip["amplitude"]), closest_approach=float(clip["closest_approach"]))
    return candidate_params(p, names, values)


def _merge(parts):
    """One WormParams for the concatenated worlds of several WormParams (each field per world)."""
    first, sizes = parts[0][0], [n for _, n in parts]
    out = {}
    for f in fields(first):
        vals = [getattr(p, f.name) for p, _ in parts]
        arrs = []
        for v, n in zip(vals, sizes):
            a = np.asarray(v)
            vec = f.name in VECTOR_FIELDS
            per = (a.ndim == 2) if vec else (a.ndim == 1)
            if not per:
                a = np.broadcast_to(a, (n,) + a.shape)
            arrs.append(a)
        if all(np.array_equal(np.asarray(vals[0]), np.asarray(v)) and np.asarray(v).ndim == (1 if f.name in
               VECTOR_FIELDS else 0) for v in vals):
            out[f.name] = vals[0]
        else:
            out[f.name] = np.concatenate(arrs)
    return replace(first, **out)


def observables(params, num_worlds: int, times, *, device="cpu") -> tuple[np.ndarray, np.ndarray]:
    """Simulated track (W, n) of z-scored ratios and displacement seen from above at ``times``, and ``unstable``
    (W,)."""
    fr = simulate_frames(params, num_worlds, np.asarray(times, np.float64), device=device)
    m = fr["model"]
    c = np.moveaxis(band_centres(fr["positions"], m.pattern.triangles, m.pattern.triangle_segment), 0, 1)
    r, d = ratios_and_displacement(c, 0)
    z = np.concatenate([r.reshape(num_worlds, -1) / SIGMA_RATIO, d / SIGMA_DISP], axis=1)
    bad = fr["unstable"] | ~np.isfinite(z).all(axis=1)
    return z, bad


def clip_jacobians(clips, names, worms, base=None, *, step=0.05, chunk=512, device="cpu", log=None,
                   max_nonlinearity: float = 0.5) -> dict:
    """J (C, D, n_c, p) per clip and design worm (a list per clip: n_c differs with the clip's cycles), ``ok`` (C, D)
    (every world of the stencil stable and the track smooth in every parameter: the forward and backward
    differences' mismatch |f - b| / |f + b| at most ``max_nonlinearity``; ``nonlin`` (C, D) the largest mismatch).
    All clips of one length of time run as one batch per ``chunk`` worlds."""
    base = base or gaits.preset_params("peristaltic", magnet_model="analytic")
    D, p = worms.shape
    stencil = np.concatenate([np.zeros((1, p)), step * np.eye(p), -step * np.eye(p)])  # (2p+1, p) log offsets
    vals = (worms[:, None, :] * np.exp(stencil[None])).reshape(-1, p)  # (D (2p+1), p)
    J = [None] * len(clips)
    ok = np.zeros((len(clips), D), bool)
    nonlin = np.full((len(clips), D), np.inf)
    by_len: dict[float, list[int]] = {}
    for i, c in enumerate(clips):
        by_len.setdefault(float(c["cycles"]), []).append(i)
    per = len(vals)
    for cyc, idx in by_len.items():
        times = np.arange(int(round(cyc * FPS)) + 1) / FPS
        for lo in range(0, len(idx), max(1, chunk // per)):
            part = idx[lo:lo + max(1, chunk // per)]
            t0 = time.perf_counter()
            params = _merge([(clip_params(base, clips[i], names, vals), per) for i in part])
            z, bad = observables(params, per * len(part), times, device=device)
            z, bad = z.reshape(len(part), D, 2 * p + 1, -1), bad.reshape(len(part), D, 2 * p + 1)
            for k, i in enumerate(part):
                J[i] = (z[k, :, 1:1 + p] - z[k, :, 1 + p:]).transpose(0, 2, 1) / (2 * step)  # (D, n, p)
                # smooth: the forward and backward differences agree; a track that jumps (a stick-slip event
                # that comes or goes between the perturbations) has a huge, meaningless central difference and
                # a rugged cost with side valleys as low as the true one
                nonlin[i] = roughness(z[k, :, 0], z[k, :, 1:1 + p], z[k, :, 1 + p:]).max(axis=1)
                ok[i] = ~bad[k].any(axis=1) & (nonlin[i] <= max_nonlinearity)
            if log:
                log(f"  {len(part)} clips x {D} worms x {2 * p + 1} = {per * len(part)} worlds, {cyc:g} cycle(s): "
                    f"{time.perf_counter() - t0:.1f} s")
    return {"J": J, "ok": ok, "nonlin": nonlin}


def roughness(z0: np.ndarray, zp: np.ndarray, zm: np.ndarray) -> np.ndarray:
    """How far a track is from smooth in each parameter: |f - b| / |f + b| of the forward difference f = z(+step) -
    z0 and the backward b = z0 - z(-step), from tracks z0 (..., n), zp and zm (..., p, n); (..., p). 0 for a linear
    response, ~step x curvature / slope for a smooth one, ~1 or more where the track jumps between the points."""
    f = zp - z0[..., None, :]
    b = z0[..., None, :] - zm
    return np.linalg.norm(f - b, axis=-1) / np.maximum(np.linalg.norm(f + b, axis=-1), 1e-12)


def half_widths(F: np.ndarray) -> np.ndarray:
    """Predicted acceptable half-widths (..., p) in log of Fisher matrices (..., p, p): sqrt(3.84 (F^-1)_ii); inf
    where F is singular."""
    out = np.full(F.shape[:-1], np.inf)
    for idx in np.ndindex(F.shape[:-2]):
        try:
            c = np.linalg.inv(F[idx])
            d = np.diag(c)
            out[idx] = np.where(d > 0, np.sqrt(3.84 * np.clip(d, 0, None)), np.inf)
        except np.linalg.LinAlgError:
            pass
    return out


def least_pinned(F: np.ndarray) -> tuple[np.ndarray, float]:
    """The least pinned direction of a Fisher matrix (p, p) in log-parameters (unit vector, sign: largest component
    positive) and its predicted acceptable half-width along it (sqrt(3.84 / smallest eigenvalue), in log)."""
    lam, vec = np.linalg.eigh(F)
    v = vec[:, 0] * np.sign(vec[np.argmax(np.abs(vec[:, 0])), 0])
    return v, float(np.sqrt(3.84 / lam[0])) if lam[0] > 0 else float("inf")


def greedy_plan(fisher: np.ndarray, ok: np.ndarray, tol: np.ndarray, *, max_clips: int = 3, margin: float = 0.5
                ) -> tuple[list[int], np.ndarray]:
    """Clips (indices into fisher's first axis (C, D, p, p)) chosen one at a time to lower the worst ratio
    half-width / tolerance over design worms and parameters; stops when it is <= ``margin`` or at ``max_clips``.
    A clip unstable at any design worm is never chosen. Returns the indices and the worst ratio after each pick."""
    chosen, worst, acc = [], [], np.zeros(fisher.shape[1:])
    usable = ok.all(axis=1)
    for _ in range(max_clips):
        score = np.full(len(fisher), np.inf)
        for c in np.nonzero(usable)[0]:
            if c in chosen:
                continue
            score[c] = np.max(half_widths(acc + fisher[c]) / np.log1p(tol))
        best = int(np.argmin(score))
        if not np.isfinite(score[best]) and chosen:
            break
        chosen.append(best)
        acc = acc + fisher[best]
        worst.append(float(score[best]))
        if score[best] <= margin:
            break
    return chosen, np.array(worst)


def plan(names, ranges: dict, *, clips=None, max_clips: int = 3, margin: float = 0.5, corner_frac: float = 0.8,
         step: float = 0.05, device="cpu", log=None, max_nonlinearity: float = 0.5) -> dict:
    """Plan clips that pin ``names`` for every design worm in ``ranges``. Returns: names, worms (D, p), clips (the
    candidates), ok (C, D), half (C, D, p) (each candidate alone), chosen (indices), worst (after each pick),
    plan_half (D, p) (the plan's predicted half-widths), tolerance (p,), worlds, wall_s."""
    t0 = time.perf_counter()
    names = list(names)
    clips = candidate_paths() if clips is None else clips
    worms = design_worms({n: ranges[n] for n in names}, corner_frac)
    jac = clip_jacobians(clips, names, worms, step=step, device=device, log=log, max_nonlinearity=max_nonlinearity)
    F = np.stack([np.einsum("dni,dnj->dij", J, J) for J in jac["J"]])  # (C, D, p, p)
    tol = np.array([tolerance(n) for n in names])
    chosen, worst = greedy_plan(F, jac["ok"], tol, max_clips=max_clips, margin=margin)
    half = half_widths(F)
    plan_half = half_widths(F[chosen].sum(axis=0))
    return {"names": names, "worms": worms, "clips": clips, "ok": jac["ok"], "nonlin": jac["nonlin"], "half": half,
            "chosen": chosen,
            "worst": worst, "plan_half": plan_half, "tolerance": tol, "fisher": F,
            "worlds": len(clips) * len(worms) * (2 * len(names) + 1), "wall_s": time.perf_counter() - t0}


def clip_text(c: dict) -> str:
    return (f"{c['gait']}{' backward' if c['backward'] else ''} w={c['wavelength']:.4g} a={c['amplitude']:.4g} "
            f"h={c['closest_approach']:.4g} cycles={c['cycles']:g}")


def report_lines(res: dict) -> list[str]:
    names, tol = res["names"], res["tolerance"]
    rough = int((~res["ok"].all(axis=1) & np.isfinite(res["nonlin"]).all(axis=1)).sum())
    out = [f"design worms ({len(res['worms'])}): the ranges' log-centre and corners; {len(res['clips'])} candidate "
           f"clips ({int((~res['ok'].all(axis=1)).sum())} refused: unstable or not smooth at some design worm, "
           f"{rough} of them only not smooth); {res['worlds']} worlds in {res['wall_s']:.0f} s",
           "best single clip of each gait (worst predicted acceptable half-width over the design worms, % ; "
           "tolerance " + ", ".join(f"{n} {100 * t:.0f} %" for n, t in zip(names, tol)) + "):"]
    hw = np.expm1(res["half"])  # (C, D, p)
    usable = res["ok"].all(axis=1)
    for g in sorted({c["gait"] for c in res["clips"]}):
        idx = [i for i, c in enumerate(res["clips"]) if c["gait"] == g and usable[i]]
        for cyc in sorted({res["clips"][i]["cycles"] for i in idx}):
            sub = [i for i in idx if res["clips"][i]["cycles"] == cyc]
            if not sub:
                continue
            best = min(sub, key=lambda i: np.max(hw[i].max(axis=0) / tol))
            w = hw[best].max(axis=0)
            out.append(f"  {clip_text(res['clips'][best]):58s} " + "  ".join(
                f"{n} ±{100 * v:.1f}%{'' if v <= t else ' (not pinned)'}" for n, v, t in zip(names, w, tol)))
    out.append("plan:")
    for k, i in enumerate(res["chosen"]):
        out.append(f"  clip {k + 1}: {clip_text(res['clips'][i])}  (worst half-width / tolerance after it: "
                   f"{res['worst'][k]:.2f})")
    w = np.expm1(res["plan_half"]).max(axis=0)
    out.append("predicted acceptable half-widths of the plan (worst design worm): " + ", ".join(
        f"{n} ±{100 * v:.2f} %" for n, v in zip(names, w)))
    if res["chosen"]:
        Fp = res["fisher"][res["chosen"]].sum(axis=0)  # (D, p, p)
        d = int(np.argmax((res["plan_half"] / np.log1p(tol)).max(axis=1)))
        v, hw = least_pinned(Fp[d])
        out.append(f"least pinned direction of the plan at its worst design worm ({d}): " + " ".join(
            f"{c:+.2f} log {n}" for c, n in zip(v, names)) + f"  (±{100 * np.expm1(hw):.1f} % along it)")
    return out
