"""§IV-B: compression and 3-point flexure, quasi-static: anchors stepped, held, read; the linearized bar-and-hinge
prediction (NumPy, no solver) beside them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.experiments.common import NO_MAGNETS, dt_substeps, lift_worm, section_vertices, split_run
from warpworm.physics import crease
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator

DEFAULT_HINGE_SWEEP = (0.0025, 0.005, 0.01, 0.02, 0.04)
"""Default k_α sweep [N/rad] of compression / flexure: around the default material's 0.005 (warpworm.physics.materials)."""


def linear_anchor_response(model, params: WormParams, target_offsets: np.ndarray, world: int = 0,
                           anchor_stiffness: float | np.ndarray | None = None) -> np.ndarray:
    """Independent quasi-static prediction: anchor forces [N], shape (A, 3), for small anchor-target offsets.

    Linearizes the bar-and-hinge energy at the rest shape of ``world`` (NumPy, float64, no solver involved):
    K = Σ_bars (EA/L0) e eᵀ + Σ_hinges k_α L ∇ψ ∇ψᵀ + Σ_anchors k_a (on the anchored vertex), solves K u = k_a Δt on
    the anchored vertices and returns k_a (u − Δt) per anchor (the worm's pull on the anchor, as ``snapshot``'s
    ``anchor_force``). No gravity, no contact: compare with a zero-gravity run.

    Args:
        model: the :class:`~warpworm.sim.model.Model` (topology, rest geometry, anchors).
        params: its parameters (``bar_stiffness``, ``hinge_stiffness`` per world or shared).
        target_offsets: anchor target displacements [m], shape (A, 3).
        world: which world's stiffness and geometry.
        anchor_stiffness: [N/m] (default the model's).
    """
    pat = model.pattern
    V = model.num_vertices
    x = np.asarray(model.rest_positions_host[world], np.float64)
    ea = float(np.broadcast_to(np.asarray(params.bar_stiffness, np.float64), (model.num_worlds,))[world])
    ka = float(np.broadcast_to(np.asarray(params.hinge_stiffness, np.float64), (model.num_worlds,))[world])
    rest_len = model.rest_length.numpy()
    rest_len = rest_len[world % rest_len.shape[0]].astype(np.float64)
    hinge_len = model.hinge_length.numpy()
    hinge_len = hinge_len[world % hinge_len.shape[0]].astype(np.float64)
    K = np.zeros((3 * V, 3 * V))
    e = x[pat.edges[:, 1]] - x[pat.edges[:, 0]]
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    ea_e = np.full(model.num_edges, ea)
    valley = getattr(params, "valley_bar_stiffness", None)
    if valley is not None:
        ea_e[pat.edge_label == crease.VALLEY] = float(np.broadcast_to(np.asarray(valley, np.float64),
                                                                     (model.num_worlds,))[world])
    kb = ea_e / rest_len
    for s, (i, j) in enumerate(pat.edges):  # small dense assembly (V = 39): a host loop over elements is fine
        blk = kb[s] * np.outer(e[s], e[s])
        for a, b, sg in ((i, i, 1), (j, j, 1), (i, j, -1), (j, i, -1)):
            K[3 * a:3 * a + 3, 3 * b:3 * b + 3] += sg * blk
    g = crease.dihedral_gradients(x, pat.hinges)  # (H, 4, 3)
    for h, stencil in enumerate(pat.hinges):
        gv = np.zeros(3 * V)
        for c, v in enumerate(stencil):
            gv[3 * v:3 * v + 3] += g[h, c]
        K += ka * hinge_len[h] * np.outer(gv, gv)
    av = model.anchor_vertex.numpy()
    if anchor_stiffness is None:
        ak = model.anchor_stiffness.numpy()
        ak = ak[world % ak.shape[0]].astype(np.float64)
    else:
        ak = np.broadcast_to(np.asarray(anchor_stiffness, np.float64), (len(av),))
    f = np.zeros(3 * V)
    off = np.asarray(target_offsets, np.float64).reshape(len(av), 3)
    for a, v in enumerate(av):
        K[3 * v:3 * v + 3, 3 * v:3 * v + 3] += ak[a] * np.eye(3)
        f[3 * v:3 * v + 3] += ak[a] * off[a]
    u = np.linalg.solve(K, f).reshape(V, 3)
    return ak[:, None] * (u[av] - off)


def _quasi_static_core(model, params, *, anchors_moving, direction, displacements, lift, settle, hold, dt,
                       substeps, linear_axis=None) -> dict:
    """The simulation of :func:`_quasi_static` on one batch (one thread's share): raw per-world readings, and with
    ``linear_axis`` the share's own linear prediction after it (:func:`_linear_units`): no third thread beside the
    shares, and one share's prediction overlaps the other's replays (docs/dynamics.md, "One job on every core")."""
    sim = Simulator(model, dt=dt, substeps=substeps)
    state = sim.initial_state()
    av = model.anchor_vertex.numpy()
    moving = np.isin(av, anchors_moving)
    x0 = model.rest_positions_host.astype(np.float64).copy()
    x0[..., 2] += lift
    if lift:
        lift_worm(state, lift)
    base_t = x0[:, av]  # (W, A, 3)
    sim.set_anchor_targets(base_t)
    n_settle, n_hold = int(round(settle / dt)), max(1, int(round(hold / dt)))
    sim.step(state, n_settle, epm=False)
    d = np.concatenate([[0.0], np.asarray(displacements, np.float64)])
    u = np.asarray(direction, np.float64) / np.linalg.norm(direction)
    fm, disp, reac, snaps = [], [], [], None
    for dk in d:  # the anchor targets change between holds: not one Simulator.run
        t = base_t.copy()
        t[:, moving] += dk * u
        sim.set_anchor_targets(t)
        sim.step(state, n_hold, epm=False)
        snaps = sim.snapshot(state)
        af = snaps["anchor_force"].astype(np.float64)  # (W, A, 3), as applied by the solver
        fm.append(-(af[:, moving] @ u).sum(axis=1))  # the worm resists the push: it pulls the pusher along -u
        reac.append((af[:, ~moving] @ u).sum(axis=1))  # and loads the fixed supports along +u
        xs = snaps["positions"][:, av].astype(np.float64) - x0[:, av]
        disp.append((xs[:, moving] @ u).mean(axis=1) - (xs[:, ~moving] @ u).mean(axis=1))
    out = {"force_raw": np.array(reac), "force_pusher_raw": np.array(fm), "displacement": np.array(disp),
           "prescribed": d, "unstable": snaps["unstable"], "final_positions": snaps["positions"]}
    if linear_axis is not None:
        out["linear_units"] = _linear_units(model, params, moving, linear_axis)
    return out


def _quasi_static(params, num_worlds, anchors, anchor_stiffness, anchors_moving, direction, displacements, *,
                  lift=0.0, settle=0.2, hold=0.1, dt=None, substeps=None, device="cpu", workers=1,
                  linear_axis=None) -> dict:
    """Shared driver: moving anchors' targets stepped by ``displacements`` along ``direction``; other anchors fixed;
    the worlds split over ``workers`` threads (:func:`split_run`).

    Returns ``force (K+1, W)`` [N]: the load on the fixed anchors along ``direction`` (the load cell) minus its value
    at zero displacement, ``force_raw`` (without that subtraction), ``force_pusher`` / ``force_pusher_raw``: the same
    read on the moving anchors (equal at equilibrium; coarser, since the anchor force is k_a times a float32
    position difference and float32 positions are coarser far from the origin), ``displacement (K+1, W)`` (measured
    mean motion of the moving vertices along ``direction``), ``prescribed (K+1,)``, ``unstable (W,)``,
    ``final_positions (W, V, 3)``; with ``linear_axis``, ``linear_units (W,)`` [N/m] (:func:`_linear_units`).
    """
    dt, substeps = dt_substeps(dt, substeps)
    axis = {"force_raw": 1, "force_pusher_raw": 1, "displacement": 1, "unstable": 0, "final_positions": 0,
            "linear_units": 0}
    r = split_run(_quasi_static_core, params, num_worlds, axis, workers=workers, device=device,
                  model_kw=dict(anchors=anchors, anchor_stiffness=anchor_stiffness),
                  anchors_moving=np.asarray(anchors_moving), direction=tuple(direction), displacements=displacements,
                  lift=lift, settle=settle, hold=hold, dt=dt, substeps=substeps, linear_axis=linear_axis)
    r["force"] = r["force_raw"] - r["force_raw"][0]
    r["force_pusher"] = r["force_pusher_raw"] - r["force_pusher_raw"][0]
    return r


def _steps(max_displacement, increments, displacements) -> np.ndarray:
    """Prescribed displacement steps (K,) [m]: ``displacements`` if given (ascending, > 0), else uniform."""
    if displacements is None:
        return np.linspace(0.0, max_displacement, increments + 1)[1:]
    d = np.asarray(displacements, np.float64).reshape(-1)
    if d.size == 0 or not np.all(np.isfinite(d)) or np.any(d <= 0) or np.any(np.diff(d) <= 0):
        raise ValueError(f"displacements: expected ascending finite values > 0 [m], got {d.tolist()}")
    return d


def _stiffness_sweep(hinge_stiffness, base: WormParams | None, overrides: dict):
    """Quasi-static rigs: one world per k_α (W,), magnets off, damping raised so each hold ends near equilibrium.
    Returns (k_α (W,), W, WormParams)."""
    quiet_warp()
    ks = np.asarray(hinge_stiffness, np.float64)
    kw = dict(NO_MAGNETS, damping=50.0)
    kw.update(overrides)
    return ks, len(ks), replace(base or WormParams(), hinge_stiffness=ks, **kw)


def _linear_units(model, params: WormParams, moving: np.ndarray, axis: int) -> np.ndarray:
    """The linear prediction (:func:`linear_anchor_responses`) of every world of ``model``: the summed force along
    ``axis`` of the anchors ``moving`` (A,) bool per metre of their offset along ``-axis``, the others fixed (W,)
    [N/m] (host NumPy, independent of the simulation)."""
    off = np.zeros((len(moving), 3))
    off[moving, axis] = -1.0
    return linear_anchor_responses(model, params, off * 1e-6)[:, moving, axis].sum(axis=1) / 1e-6


def _rows(a, W: int) -> np.ndarray:
    """A model array's rows for every world (W, ...) as float64, row ``w % rows`` (as the kernels read it)."""
    a = np.asarray(a)
    return a[np.arange(W) % a.shape[0]].astype(np.float64)


def linear_anchor_responses(model, params: WormParams, target_offsets: np.ndarray) -> np.ndarray:
    """:func:`linear_anchor_response` of every world at once, bit for bit (W, A, 3) [N] (model's anchor stiffness):
    every world's stiffness matrix takes the same additions in the same order (one per bar, hinge and anchor, each a
    block of every world at once; the zero entries of a hinge's 3V x 3V outer product added nothing), at about a tenth
    of the per-world loop's CPU (docs/dynamics.md, "Notes moved from the code"). tests/test_threads_split.py checks it
    against the per-world function."""
    pat, W, V = model.pattern, model.num_worlds, model.num_vertices
    x = np.asarray(model.rest_positions_host, np.float64)  # (W, V, 3)
    per_world = lambda v: np.broadcast_to(np.asarray(v, np.float64), (W,))  # noqa: E731  (a parameter: scalar or (W,))
    ea_e = np.repeat(per_world(params.bar_stiffness)[:, None], model.num_edges, axis=1)
    valley = getattr(params, "valley_bar_stiffness", None)
    if valley is not None:
        ea_e[:, pat.edge_label == crease.VALLEY] = per_world(valley)[:, None]
    kb = ea_e / _rows(model.rest_length.numpy(), W)  # (W, E)
    hl = _rows(model.hinge_length.numpy(), W)  # (W, H)
    ka = per_world(params.hinge_stiffness)
    e = x[:, pat.edges[:, 1]] - x[:, pat.edges[:, 0]]
    e /= np.linalg.norm(e, axis=-1, keepdims=True)
    K = np.zeros((W, 3 * V, 3 * V))
    for s, (i, j) in enumerate(pat.edges):
        blk = kb[:, s, None, None] * (e[:, s, :, None] * e[:, s, None, :])  # np.outer's products, world by world
        bi, bj = slice(3 * i, 3 * i + 3), slice(3 * j, 3 * j + 3)
        K[:, bi, bi] += blk  # the four distinct 3x3 blocks (x - b is x + (-b) to the bit)
        K[:, bj, bj] += blk
        K[:, bi, bj] -= blk
        K[:, bj, bi] -= blk
    g = crease.dihedral_gradients(x, pat.hinges)  # (W, H, 4, 3)
    for h, stencil in enumerate(pat.hinges):
        r = (3 * np.asarray(stencil)[:, None] + np.arange(3)).reshape(-1)  # the 12 nonzero entries of gv
        gv = g[:, h].reshape(W, 12)
        K[:, r[:, None], r[None, :]] += (ka * hl[:, h])[:, None, None] * (gv[:, :, None] * gv[:, None, :])
    av = model.anchor_vertex.numpy()
    ak = _rows(model.anchor_stiffness.numpy(), W)  # (W, A)
    off = np.asarray(target_offsets, np.float64).reshape(len(av), 3)
    f = np.zeros((W, 3 * V))
    for a, v in enumerate(av):
        d = np.arange(3 * v, 3 * v + 3)
        K[:, d, d] += ak[:, a, None]  # ak * eye(3): the off-diagonal zeros add nothing
        f[:, d] += ak[:, a, None] * off[a]
    u = np.linalg.solve(K, f[..., None]).reshape(W, V, 3)  # one LAPACK gesv per world, as the per-world solve
    return ak[:, :, None] * (u[:, av] - off)


def compression(hinge_stiffness=DEFAULT_HINGE_SWEEP, max_displacement: float = 2.0e-3, increments: int = 8,
                *, displacements=None, base: WormParams | None = None, hold: float = 0.1, settle: float = 0.2,
                anchor_stiffness: float = 1.0e4, dt=None, substeps=None, device="cpu", workers: int | None = 1,
                **overrides) -> dict:
    """Compression test (§IV-B): tail section (3 vertices) anchored, head section pushed along −x; one world per k_α.

    The worm lies on the floor (gravity and friction on, magnets off unless ``overrides`` turn them on). The head
    anchors' targets move by ``max_displacement / increments`` per increment and are held ``hold`` [s] (damping
    raised to 50/s so each hold ends near equilibrium). ``force`` is the head anchors' resisting force along +x
    minus its value before loading [N]; ``displacement`` the head section's measured shortening [m]; ``linear`` the
    independent linear quasi-static prediction (no gravity, no friction) at the prescribed displacement.
    ``displacements`` (K,) [m], ascending and > 0, replaces the uniform ``max_displacement`` / ``increments`` steps
    (:mod:`warpworm.analysis.material_fit` prescribes a measured table's displacements). ``workers`` threads share the
    worlds (:func:`split_run`; results equal one batch's).
    """
    ks, W, p = _stiffness_sweep(hinge_stiffness, base, overrides)
    n = int(p.n_units)
    tail, head = section_vertices(n, 0), section_vertices(n, 2 * n)
    anchors = np.concatenate([tail, head])
    steps = _steps(max_displacement, increments, displacements)
    r = _quasi_static(p, W, anchors, anchor_stiffness, head, (-1.0, 0.0, 0.0), steps, settle=settle, hold=hold,
                      dt=dt, substeps=substeps, device=device, workers=workers, linear_axis=0)
    lin = r["prescribed"][:, None] * r.pop("linear_units")  # (K+1, W) [N]
    fmax = r["force"][-1]
    dmax = r["displacement"][-1]
    r.update(hinge_stiffness=ks, linear=lin, summary={
        "hinge_stiffness_N_per_rad": ks.tolist(),
        "force_at_max_mN": (1e3 * fmax).tolist(),
        "measured_displacement_at_max_mm": (1e3 * dmax).tolist(),
        "secant_stiffness_N_per_m": (fmax / np.maximum(dmax, 1e-12)).tolist(),
        "linear_stiffness_N_per_m": (lin[-1] / max(r["prescribed"][-1], 1e-12)).tolist(),
        "bar_stiffness_EA_N": float(np.asarray(p.bar_stiffness).max()),
        "valley_bar_stiffness": str(getattr(p, "valley_bar_stiffness", "not in WormParams")),
        "unstable_worlds": int(r["unstable"].sum()),
    })
    return r


def flexure(hinge_stiffness=DEFAULT_HINGE_SWEEP, max_deflection: float = 2.0e-3, increments: int = 8, *,
            displacements=None, lift: float = 0.02, base: WormParams | None = None, hold: float = 0.1, settle: float = 0.2,
            anchor_stiffness: float = 1.0e4, dt=None, substeps=None, device="cpu", workers: int | None = 1,
            **overrides) -> dict:
    """3-point flexure (§IV-B): worm lifted ``lift`` [m] off the floor, held at the bottom corners of the sections
    next to both ends (two line supports free to rotate about y), centre section pushed down; one world per k_α.

    Gravity is on: ``force`` is the load anchors' resisting force (+z) minus the unloaded preload [N] against the
    measured deflection [m]. The supports are anchors (pins, not rollers), so at large deflection the span's stretch
    adds a membrane stiffening that a roller test would not have; ``linear`` is the linear prediction.
    ``displacements`` (K,) [m], ascending and > 0, replaces the uniform ``max_deflection`` / ``increments`` steps.
    ``workers`` threads share the worlds (:func:`split_run`; results equal one batch's).
    """
    ks, W, p = _stiffness_sweep(hinge_stiffness, base, overrides)
    n = int(p.n_units)
    sup = np.concatenate([section_vertices(n, 1, (0, 1)), section_vertices(n, 2 * n - 1, (0, 1))])
    load = section_vertices(n, n)
    anchors = np.concatenate([sup, load])
    steps = _steps(max_deflection, increments, displacements)
    r = _quasi_static(p, W, anchors, anchor_stiffness, load, (0.0, 0.0, -1.0), steps, lift=lift, settle=settle,
                      hold=hold, dt=dt, substeps=substeps, device=device, workers=workers, linear_axis=2)
    lin = r["prescribed"][:, None] * r.pop("linear_units")  # (K+1, W) [N]
    fmax, dmax = r["force"][-1], r["displacement"][-1]
    r.update(hinge_stiffness=ks, linear=lin, summary={
        "hinge_stiffness_N_per_rad": ks.tolist(),
        "force_at_max_mN": (1e3 * fmax).tolist(),
        "measured_deflection_at_max_mm": (1e3 * dmax).tolist(),
        "secant_stiffness_N_per_m": (fmax / np.maximum(dmax, 1e-12)).tolist(),
        "linear_stiffness_N_per_m": (lin[-1] / max(r["prescribed"][-1], 1e-12)).tolist(),
        "preload_mN": (1e3 * r["force_raw"][0]).tolist(),
        "unstable_worlds": int(r["unstable"].sum()),
    })
    return r
