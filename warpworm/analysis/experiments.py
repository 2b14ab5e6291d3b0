"""The paper's virtual experiments (Swaminathan et al., RA-L 2021, §IV), batched: one Simulator per experiment.

Every function returns a dict with NumPy arrays and a ``"summary"`` dict of plain floats / strings (JSON-ready with
:func:`to_jsonable`). A sweep (hinge stiffnesses, slopes, gaits) is W worlds of one :class:`~warpworm.sim.simulator.
Simulator`; nothing loops over worlds on the host. SI units throughout (the plots convert to mm / mN).

==================  ====================================================================================================
force_distance      §IV-A, Fig. 5: attraction of two 1 cm³ N52 cubes (0.9 A·m², unlike poles facing) vs gap, dipole
                    model at several densities and the exact (analytic) model, beside the closed-form table.
compression         §IV-B, Fig. 6/7: tail section anchored, head section pushed along −x in quasi-static increments;
                    force vs displacement, one world per hinge stiffness k_α; linear quasi-static prediction beside it.
flexure             §IV-B: worm lifted on two supports near its ends, centre section pushed down; force vs deflection
                    per k_α (force relative to the unloaded preload), linear prediction beside it.
slope               §IV-F: worm (no magnets) on inclines β across atan(μs); slide along the slope vs time and the
                    Coulomb prediction ½ g (sin β − μk cos β) t².
force_plate         §IV-D, Fig. 9/10: tail tied by anchors to a fixed point while each gait runs; anchor force vs time.
strain              §IV-G, Fig. 12: Cauchy strain of every bar over a gait: max / mean |strain| per bar.
deformation         §IV-E, Fig. 11: the four deformation ratios (adjacent segment-centre distances over rest) vs time
                    and the net displacement, per gait.
==================  ====================================================================================================

Gait experiments run the three gait presets (:func:`warpworm.physics.gaits.preset_params`) as three worlds of one batch: the
presets' per-gait scalars become per-world arrays and each world gets its own gait's EPM path.
"""

from __future__ import annotations

import json
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from warpworm.physics import crease, gaits
from warpworm import quiet_warp
from warpworm.physics import magnets as mg
from warpworm.physics.params import GAITS, WormParams
from warpworm.analysis.world_split import world_shares  # noqa: F401  (the split's shares; re-exported)
from warpworm.sim.simulator import Simulator

EXPERIMENTS = ("force-distance", "compression", "flexure", "slope", "force-plate", "strain", "deformation")

CUBE_TABLE = {
    1: 26.04212, 2: 18.76765, 3: 14.05910, 5: 8.401509, 7: 5.308457, 10: 2.879273, 15: 1.214808, 20: 0.592872,
    30: 0.189106,
}
"""Closed-form attraction [N] of two coaxial 10 mm cubes, 0.9 A·m² each, unlike poles facing, by face gap [mm]
(shared/DESIGN-NOTES.md; closed form and magpylib agree to 3e-7)."""

DEFAULT_HINGE_SWEEP = (0.0025, 0.005, 0.01, 0.02, 0.04)
"""Default k_α sweep [N/rad] of compression / flexure: around the default material's 0.005 (warpworm.physics.materials)."""

NO_MAGNETS = dict(ipm_moment=np.zeros(3), epm_moment=0.0)
"""Overrides that switch every magnet off (mechanical tests: compression, flexure, slope)."""


# ----------------------------------------------------------------------------------------------------------------
# helpers


def _dt_substeps(dt, substeps):
    return (getattr(gaits, "DEFAULT_DT", 4.0e-3) if dt is None else float(dt),
            gaits.DEFAULT_SUBSTEPS if substeps is None else int(substeps))


def split_run(core, params: WormParams, num_worlds: int, world_axis: dict, *, workers: int | None = 1,
              device="cpu", model_kw: dict | None = None, **run_kw) -> dict:
    """``core(model, params, **run_kw) -> dict of arrays`` on ``num_worlds`` worlds, the worlds split over
    ``workers`` threads of this process (None: every core), each a batch of a contiguous share with its own Model
    (its parameters sliced by :func:`warpworm.physics.params.slice_worlds`) and Simulator
    (:func:`warpworm.analysis.world_split.run_shares`, as ``simulate --workers`` does). Worlds never interact, so
    every per-world result equals one batch's bit for bit. Each output key is concatenated along ``world_axis[key]``
    (a key not in ``world_axis``: the first share's value, for outputs that do not depend on the worlds).
    """
    from warpworm.analysis.world_split import concat, run_shares
    from warpworm.physics.params import slice_worlds
    from warpworm.sim.model import Model

    quiet_warp()
    mkw = dict(model_kw or {})

    def share(lo, hi):
        p = params if (lo, hi) == (0, num_worlds) else slice_worlds(params, num_worlds, lo, hi)
        return core(Model.from_params(p, hi - lo, device, **mkw), p, **run_kw)

    return concat(run_shares(share, num_worlds, workers, device=device), world_axis)


def section_vertices(n_units: int, section: int, corners=(0, 1, 2)) -> np.ndarray:
    """Vertex indices of the given corners of cross-section ``section`` (0 tail … 2n head); corner 0 bottom-left,
    1 bottom-right, 2 top (docs/crease.md: vertex 3s + k)."""
    if not 0 <= section <= 2 * n_units:
        raise ValueError(f"section must be in [0, {2 * n_units}], got {section}")
    return np.array([3 * section + k for k in corners], np.int32)


def _lift(state, dz: float) -> None:
    x = state.positions.numpy() + np.array([0.0, 0.0, dz], np.float32)
    state.positions.assign(x)


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


def _batched_gait_params(gait_list, base: WormParams | None = None, **overrides) -> WormParams:
    """One WormParams for W = len(gait_list) worlds: every scalar field on which the gait presets differ becomes a
    per-world array (``gait`` is set per world by the caller; ``backward`` is shared)."""
    presets = [gaits.preset_params(g, base=base, **overrides) for g in gait_list]
    merged = {}
    for f in fields(WormParams):
        vals = [getattr(p, f.name) for p in presets]
        if f.name in ("gait", "backward", "magnet_model", "n_units"):
            continue
        arrs = [np.asarray(v, np.float64) if not isinstance(v, str) else None for v in vals]
        if any(a is None for a in arrs) or all(np.array_equal(arrs[0], a, equal_nan=True) for a in arrs):
            continue
        if arrs[0].ndim == 0:
            merged[f.name] = np.array([float(a) for a in arrs])
        else:
            merged[f.name] = np.stack([np.broadcast_to(a, arrs[0].shape) for a in arrs])
    return replace(presets[0], **merged)


def _gait_model(gait_list, *, anchors=None, anchor_stiffness=1.0e4, base=None, device="cpu", **overrides):
    """A Model with one world per gait in ``gait_list``, each on its own gait's sinusoidal EPM path."""
    from warpworm.sim.model import Model

    p = replace(_batched_gait_params(gait_list, base=base, **overrides), gait=np.array(gait_list, dtype=str))
    model = Model.from_params(p, len(gait_list), device, anchors=anchors, anchor_stiffness=anchor_stiffness)
    return model, p


GAIT_RECORD = ("positions", "bar_strain", "anchor_force", "magnet_pos", "time", "unstable")
"""Snapshot keys a gait record keeps (``time`` per world, (S, W))."""


def _gait_core(model, params, *, duration, sample_every, settle, dt, substeps, rewind=False) -> dict:
    """Settle, then record the keys of :data:`GAIT_RECORD` every ``sample_every`` steps for ``duration`` [s]
    (``rewind``: each world's sinusoidal path repeats its first pass in place, :class:`warpworm.physics.gaits.EpmPath`)."""
    sim = Simulator(model, dt=dt, substeps=substeps)
    if rewind:
        sim.set_path(replace(model.default_path, rewind=np.ones(1)))
    state = sim.initial_state()
    if settle > 0:
        sim.settle(state, settle)
    n_samples = max(1, int(round(duration / (dt * sample_every))))
    rec = sim.run(state, dt * sample_every * np.arange(n_samples + 1), keys=GAIT_RECORD, stack=True)
    rec.pop("clock", None)
    return rec


def run_gaits(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2, anchors=None,
              anchor_stiffness: float = 1.0e4, dt=None, substeps=None, device="cpu", base=None, workers: int | None = 1,
              rewind: bool = False, **overrides) -> dict:
    """Run each gait preset as one world of a batch for ``duration`` [s]; record a trajectory.

    Returns ``gaits`` (list), ``time (S,)``, ``positions (S, W, V, 3)``, ``bar_strain (S, W, E)``,
    ``anchor_force (S, W, A, 3)``, ``magnet_pos (S, W, 4, 3)``, ``unstable (W,)``, ``rest_positions (W, V, 3)``
    (the settled shape at t = 0), ``rewind`` and ``model``. ``workers`` threads share the worlds
    (:func:`split_run`). ``rewind``: every cycle repeats the EPM's first pass in place (a worm tied down).
    """
    quiet_warp()
    gait_list = list(gait_list)
    dt, substeps = _dt_substeps(dt, substeps)
    model, p = _gait_model(gait_list, anchors=anchors, anchor_stiffness=anchor_stiffness, base=base,
                           device=device, **overrides)
    axis = {"positions": 1, "bar_strain": 1, "anchor_force": 1, "magnet_pos": 1, "time": 1, "unstable": 1}
    frames = split_run(_gait_core, p, len(gait_list), axis, workers=workers, device=device,
                       model_kw=dict(anchors=anchors, anchor_stiffness=anchor_stiffness), duration=duration,
                       sample_every=sample_every, settle=settle, dt=dt, substeps=substeps, rewind=rewind)
    rec = {k: frames[k] for k in ("positions", "bar_strain", "anchor_force", "magnet_pos")}
    rec["time"] = frames["time"].max(axis=1)  # an unstable world's clock stops: take the max
    rec["unstable"] = frames["unstable"][-1]
    rec["rest_positions"] = frames["positions"][0]
    rec["gaits"] = gait_list
    rec["rewind"] = bool(rewind)
    rec["model"] = model
    rec["params"] = p
    return rec


# ----------------------------------------------------------------------------------------------------------------
# 1. force-distance (§IV-A, Fig. 5)


def force_distance(gaps=None, densities=(1e6, 8e6, 64e6), moment: float = 0.9, side: float = 0.010) -> dict:
    """Attraction [N] between two coaxial cubes (side ``side``, ``moment`` each, unlike poles facing) vs face gap.

    Returns ``gap (K,)`` [m], ``analytic (K,)`` [N], ``dipoles (D, K)`` [N] (one row per density [1/m³]),
    ``densities (D,)``, ``table_gap (T,)`` [m] and ``table_force (T,)`` [N] (DESIGN-NOTES closed form),
    ``analytic_at_table (T,)`` and ``dipoles_at_table (D, T)``, and a summary of relative errors vs the table.
    """
    from warpworm.analysis.calibration import pair_forces

    gaps = np.geomspace(0.5e-3, 40e-3, 60) if gaps is None else np.asarray(gaps, np.float64)
    cube = mg.Cuboid((side, side, side), moment=(0.0, 0.0, moment))
    tg = np.array(sorted(CUBE_TABLE), np.float64) * 1e-3
    tf = np.array([CUBE_TABLE[k] for k in sorted(CUBE_TABLE)])
    allg = np.concatenate([gaps, tg])
    ana = pair_forces(cube, cube, allg, model="analytic")
    dip = np.stack([pair_forces(cube, cube, allg, model="dipoles", density=d) for d in densities])
    K = len(gaps)
    rel_a = ana[K:] / tf - 1.0
    rel_d = dip[:, K:] / tf - 1.0
    summary = {"analytic_max_rel_err_vs_table": float(np.abs(rel_a).max())}
    for d, r in zip(densities, rel_d):
        summary[f"dipoles_{d / 1e6:g}_per_cm3_rel_err_at_1mm"] = float(r[0])
        summary[f"dipoles_{d / 1e6:g}_per_cm3_max_rel_err_from_5mm"] = float(np.abs(r[tg >= 5e-3 - 1e-12]).max())
    return {
        "gap": gaps, "analytic": ana[:K], "dipoles": dip[:, :K], "densities": np.asarray(densities, np.float64),
        "table_gap": tg, "table_force": tf, "analytic_at_table": ana[K:], "dipoles_at_table": dip[:, K:],
        "summary": summary,
    }


# ----------------------------------------------------------------------------------------------------------------
# 2./3. compression and 3-point flexure (§IV-B)


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
        _lift(state, lift)
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
    dt, substeps = _dt_substeps(dt, substeps)
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
    of the per-world loop's CPU (which was half of ``experiment compression``'s at 192 worlds, holding the GIL;
    docs/dynamics.md). tests/test_threads_split.py checks it against the per-world function."""
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


# ----------------------------------------------------------------------------------------------------------------
# 4. slope (§IV-F)


def _slope_core(model, params, *, frame_times, dt, substeps) -> dict:
    """The simulation of :func:`slope` on one batch: vertex centroids ``(S, W, 3)`` [m] (float64) and world times
    ``(S, W)`` [s] at ``frame_times`` from t = 0, magnets off; ``unstable (W,)`` at the end."""
    sim = Simulator(model, dt=dt, substeps=substeps)
    state = sim.initial_state()
    rec = sim.run(state, frame_times, epm=False, keys=("positions", "time", "unstable"), stack=True)
    return {"centroid": rec["positions"].astype(np.float64).mean(axis=2), "time": rec["time"],
            "unstable": rec["unstable"][-1]}


def slope(offsets_deg=(-4.0, -2.0, -1.0, 1.0, 2.0, 4.0), duration: float = 0.5, *, settle: float = 0.2,
          sample_every: int = 5, base: WormParams | None = None, dt=None, substeps=None, device="cpu",
          slide_threshold: float = 1.0e-4, workers: int | None = 1, **overrides) -> dict:
    """Slope sliding test (§IV-F): the worm (magnets off, damping 0) on inclines β = atan(μs) + offsets, one world each.
    The worm faces uphill (the floor rises toward its head, +x), so it would slide tail-ward: with a skin that grips
    one way (``friction_backward_ratio`` r) both coefficients are r times theirs and the angle is atan(r μs).

    The centroid's motion down the slope is recorded from t = 0 (worm built unloaded at rest on the slope) for
    ``settle + duration`` [s]: ``slide (S, W)`` [m] down-slope, ``predicted (S, W)`` = ½ g (sin β − μk cos β) t² where
    β > atan(μs), else 0. A world "slides" when it moves more than ``slide_threshold`` [m] after ``settle`` (the
    worm takes its weight first; a contact transient may slip a few vertices by ~0.1 mm); the summary gives
    the transition angle bracket. ``workers`` threads share the worlds (:func:`split_run`).
    """
    quiet_warp()
    dt, substeps = _dt_substeps(dt, substeps)
    b = base or WormParams()
    skin = float(np.asarray(overrides.get("friction_backward_ratio", b.friction_backward_ratio)))
    mu_s = skin * float(np.asarray(overrides.get("mu_static", b.mu_static)))  # sliding down = tail-ward
    beta = np.arctan(mu_s) + np.deg2rad(np.asarray(offsets_deg, np.float64))
    kw = dict(NO_MAGNETS, damping=0.0)
    kw.update(overrides)
    p = replace(b, floor_incline=beta, **kw)
    W = len(beta)
    down = np.stack([-np.cos(beta), np.zeros(W), -np.sin(beta)], axis=1)  # (W, 3) down the slope
    n_frames = max(1, int(round((settle + duration) / (dt * sample_every))))
    r = split_run(_slope_core, p, W, {"centroid": 1, "time": 1, "unstable": 0}, workers=workers, device=device,
                  frame_times=dt * sample_every * np.arange(n_frames + 1), dt=dt, substeps=substeps)
    ts = r["time"].max(axis=1)  # an unstable world's clock stops: take the max
    slide = np.einsum("swc,wc->sw", r["centroid"] - r["centroid"][0], down)
    s = {"unstable": r["unstable"]}
    g = float(np.asarray(p.gravity))
    mu_k = skin * float(np.asarray(p.mu_kinetic))
    acc = np.where(beta > np.arctan(mu_s), g * (np.sin(beta) - mu_k * np.cos(beta)), 0.0)
    pred = 0.5 * acc[None] * ts[:, None] ** 2
    i0 = int(np.searchsorted(ts, settle - 1e-9))
    after = slide[-1] - slide[i0]  # motion after the settling transient
    slides = after > slide_threshold
    below = np.rad2deg(beta[~slides]).max() if (~slides).any() else float("nan")
    above = np.rad2deg(beta[slides]).min() if slides.any() else float("nan")
    return {
        "beta": beta, "offsets_deg": np.asarray(offsets_deg, np.float64), "time": ts, "slide": slide,
        "predicted": pred, "slides": slides, "unstable": s["unstable"],
        "summary": {
            "mu_static": mu_s, "mu_kinetic": mu_k, "friction_backward_ratio": skin,
            "friction_angle_deg": float(np.rad2deg(np.arctan(mu_s))),
            "beta_deg": np.rad2deg(beta).tolist(), "final_slide_mm": (1e3 * slide[-1]).tolist(),
            "predicted_slide_mm": (1e3 * pred[-1]).tolist(),
            "slide_after_settle_mm": (1e3 * after).tolist(), "settle_s": float(settle),
            "largest_holding_beta_deg": float(below), "smallest_sliding_beta_deg": float(above),
            "duration_s": float(ts[-1]),
        },
    }


# ----------------------------------------------------------------------------------------------------------------
# 5.-7. gait experiments (§IV-D, E, G)


def _crossing(t, y, j, level) -> float:
    """Time [s] where the segment (t[j], y[j]) – (t[j + 1], y[j + 1]) crosses ``level`` (linear interpolation)."""
    dy = y[j + 1] - y[j]
    return float(t[j] + (t[j + 1] - t[j]) * ((level - y[j]) / dy if dy != 0 else 0.5))


def rise_fall_times(t, y, period: float, *, t0: float = 0.0, lo: float = 0.1, hi: float = 0.9,
                    baseline: float | str = 0.0) -> dict:
    """Per-cycle rise and fall times of a pulsed signal (the force plate's pull, paper Fig. 10).

    The record is cut into cycles [t0 + c T, t0 + (c + 1) T) (T = ``period`` [s]; only whole cycles). In each cycle
    the peak is the largest sample; the levels are baseline + ``lo`` / ``hi`` × (peak − baseline), with ``baseline``
    0 by default (10 % and 90 % of the cycle's peak: a force plate reads 0 unloaded; a cycle whose peak is not above
    the baseline gives NaN), any fixed value, or ``"trough"``: each edge from its own trough, the smallest sample
    within one period before the peak (rise) or after it (fall), which follows a drifting offset. The rise time is
    from the last
    upward crossing of the low level before the peak to the last crossing of the high level before it; the fall time
    from the first downward crossing of the high level after the peak to the first crossing of the low level after
    it. Crossings are linearly interpolated between samples and searched within one period of the peak (so a pulse
    may straddle a cycle boundary); a crossing not found gives NaN.

    Args:
        t: sample times [s], shape (S,), ascending.
        y: the signal (any unit), shape (S,).
        period: cycle length T [s].
        t0: start of the first cycle [s] (the EPM path's s = 0; ``Simulator.settle`` restarts the clock at 0).

    Returns: ``rise (C,)``, ``fall (C,)`` [s], ``peak (C,)``, ``baseline (C,)``, ``peak_time (C,)`` [s] per whole cycle,
    and ``rise_mean`` / ``fall_mean`` [s]: the NaN-ignoring means over the cycles after the first (NaN when there is
    only one cycle).
    """
    t = np.asarray(t, np.float64).reshape(-1)
    y = np.asarray(y, np.float64).reshape(-1)
    T = float(period)
    n_cyc = int(np.floor((t[-1] - t0) / T + 1e-9)) if len(t) else 0
    out = {k: np.full(n_cyc, np.nan) for k in ("rise", "fall", "peak", "baseline", "peak_time")}
    for c in range(n_cyc):  # host analysis of a recorded signal (a few cycles), not a loop over worlds
        a, b = t0 + c * T, t0 + (c + 1) * T
        idx = np.nonzero((t >= a - 1e-12) & (t < b - 1e-12))[0]
        if len(idx) < 3:
            continue
        ip = idx[np.argmax(y[idx])]
        peak = y[ip]
        win = (t >= t[ip] - T) & (t <= t[ip] + T)
        if isinstance(baseline, str):
            if baseline != "trough":
                raise ValueError(f"baseline: expected a number or 'trough', got {baseline!r}")
            base_r, base_f = y[:ip + 1][win[:ip + 1]].min(), y[ip:][win[ip:]].min()
        else:
            base_r = base_f = float(baseline)
        out["peak"][c], out["baseline"][c], out["peak_time"][c] = peak, base_r, t[ip]
        if peak > base_r:
            l_lo, l_hi = base_r + lo * (peak - base_r), base_r + hi * (peak - base_r)
            before = np.nonzero(win[:ip] & (y[:ip] < l_hi))[0]
            before_lo = np.nonzero(win[:ip] & (y[:ip] < l_lo))[0]
            if len(before) and len(before_lo):
                out["rise"][c] = _crossing(t, y, before[-1], l_hi) - _crossing(t, y, before_lo[-1], l_lo)
        if peak > base_f:
            l_lo, l_hi = base_f + lo * (peak - base_f), base_f + hi * (peak - base_f)
            after = ip + 1 + np.nonzero(win[ip + 1:] & (y[ip + 1:] < l_hi))[0]
            after_lo = ip + 1 + np.nonzero(win[ip + 1:] & (y[ip + 1:] < l_lo))[0]
            if len(after) and len(after_lo):
                out["fall"][c] = _crossing(t, y, after_lo[0] - 1, l_lo) - _crossing(t, y, after[0] - 1, l_hi)

    def _mean(v):
        v = v[1:]
        return float(np.nanmean(v)) if np.isfinite(v).any() else float("nan")

    out["rise_mean"], out["fall_mean"] = _mean(out["rise"]), _mean(out["fall"])
    return out


def force_plate(gait_list=GAITS, duration: float = 2.0, *, anchor_stiffness: float = 1.0e4, sample_every: int = 2,
                settle: float = 0.2, rewind: bool = True, record: dict | None = None, **kw) -> dict:
    """Force plate (§IV-D): the tail section's 3 vertices tied by anchors (strength ``anchor_stiffness`` [N/m]) to
    their settled rest points while each gait runs. ``force (S, W, 3)`` [N] is the summed anchor force (the worm's
    pull on the plate; +x = forward pull), ``pull (S, W)`` its x component, ``force_magnitude (S, W)`` its length
    (the paper's reading: the Anchor's strength times the displacement vector of the tied point).

    ``rewind`` (default): the EPM repeats its first pass in place every cycle (:class:`warpworm.physics.gaits.EpmPath`), so
    the tied worm is driven the same way in every cycle and the pulses settle to a periodic train. Without it the
    EPM advances w per cycle as in locomotion and leaves the tied worm behind: after two or three cycles it passes
    ahead of the head and the pulses fade, so the per-cycle shapes would describe where the magnet has gone, not the
    gait. With ``record`` (a :func:`run_gaits` record) the run is not repeated and its own ``rewind`` is what the
    summary reports (``rewind`` here is then unused).

    Pulse shape (Fig. 10: the paper's inchworm rises steeply and falls smoothly, omega the reverse): per gait the
    10 %→90 % rise time and 90 %→10 % fall time of the pull in each EPM cycle (:func:`rise_fall_times`),
    ``rise_time (C, W)`` / ``fall_time (C, W)`` [s] with levels at 10 % / 90 % of the cycle's peak (zero baseline;
    NaN in a cycle whose peak pull is not > 0), ``rise_time_trough`` / ``fall_time_trough`` with each edge measured
    from its own trough (robust to a drifting offset), ``rise_time_magnitude`` / ``fall_time_magnitude`` of
    ``force_magnitude`` (zero baseline), and in the summary their means over the cycles after the first (NaN / null
    with fewer than two whole cycles: ``duration`` ≥ 2 periods)."""
    if record is None:
        n = int((kw.get("base") or WormParams()).n_units)
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle,
                           anchors=section_vertices(n, 0), anchor_stiffness=anchor_stiffness, rewind=rewind, **kw)
    F = record["anchor_force"].sum(axis=2).astype(np.float64)  # (S, W, 3)
    t = record["time"]
    pull, magnitude = F[..., 0], np.linalg.norm(F, axis=-1)
    summary = {"gaits": list(record["gaits"]), "duration_s": float(t[-1]), "rewind": bool(record.get("rewind", False)),
               "anchor_stiffness_N_per_m": float(anchor_stiffness),
               "max_pull_mN": (1e3 * pull.max(axis=0)).tolist(), "mean_pull_mN": (1e3 * pull.mean(axis=0)).tolist(),
               "min_pull_mN": (1e3 * pull.min(axis=0)).tolist(),
               "max_abs_force_mN": (1e3 * magnitude.max(axis=0)).tolist(),
               "unstable": record["unstable"].tolist()}
    W = pull.shape[1]
    params = record.get("params")
    periods = (np.broadcast_to(np.asarray(params.cycle_period, np.float64), (W,)) if params is not None
               else np.ones(W))
    res = {}
    for tag, signal, bl in (("", pull, 0.0), ("_trough", pull, "trough"), ("_magnitude", magnitude, 0.0)):
        shapes = [rise_fall_times(t, signal[:, w], periods[w], baseline=bl) for w in range(W)]  # host analysis
        C = min(len(s["rise"]) for s in shapes)
        res["rise_time" + tag] = np.stack([s["rise"][:C] for s in shapes], axis=1) if C else np.zeros((0, W))
        res["fall_time" + tag] = np.stack([s["fall"][:C] for s in shapes], axis=1) if C else np.zeros((0, W))
        rm, fm = np.array([s["rise_mean"] for s in shapes]), np.array([s["fall_mean"] for s in shapes])
        summary.update({
            f"rise_time_10_90{tag}_ms": (1e3 * rm).tolist(),
            f"fall_time_90_10{tag}_ms": (1e3 * fm).tolist(),
            f"rise_over_fall{tag}": np.where(fm > 0, rm / np.where(fm > 0, fm, 1.0), np.nan).tolist(),
        })
    summary.update(cycle_period_s=periods.tolist(), whole_cycles=int(res["rise_time"].shape[0]))
    return {"time": t, "force": F, "pull": pull, "force_magnitude": magnitude, "gaits": list(record["gaits"]),
            "unstable": record["unstable"], **res, "summary": summary}


def strain(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2,
           record: dict | None = None, **kw) -> dict:
    """Bar strain (§IV-G): Cauchy strain (L − L0)/L0 of every bar over each gait (free worm, no anchors).

    ``strain (S, W, E)``, ``max_abs (W, E)`` and ``mean_abs (W, E)`` per bar, ``max_over_bars (S, W)``, the bar
    endpoints' positions at the most strained instant ``peak_positions (W, V, 3)``, ``edges (E, 2)``, ``edge_label``.
    """
    if record is None:
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle, **kw)
    eps = record["bar_strain"].astype(np.float64)  # (S, W, E)
    a = np.abs(eps)
    max_abs, mean_abs = a.max(axis=0), a.mean(axis=0)
    over = a.max(axis=2)  # (S, W)
    ipeak = over.argmax(axis=0)
    W = eps.shape[1]
    peak_pos = record["positions"][ipeak, np.arange(W)]
    pat = record["model"].pattern
    labels = {crease.FLAT: "flat", crease.MOUNTAIN: "mountain", crease.VALLEY: "valley", crease.BOUNDARY: "boundary"}
    per_label = {}
    for lab, name in labels.items():
        m = pat.edge_label == lab
        if m.any():
            per_label[name] = (max_abs[:, m].max(axis=1)).tolist()
    summary = {"gaits": list(record["gaits"]), "duration_s": float(record["time"][-1]),
               "max_abs_strain": max_abs.max(axis=1).tolist(), "mean_abs_strain": mean_abs.mean(axis=1).tolist(),
               "most_strained_bar": max_abs.argmax(axis=1).tolist(), "max_abs_strain_by_label": per_label,
               "unstable": record["unstable"].tolist()}
    return {"time": record["time"], "strain": eps, "max_abs": max_abs, "mean_abs": mean_abs, "max_over_bars": over,
            "peak_positions": peak_pos, "edges": pat.edges, "edge_label": pat.edge_label,
            "gaits": list(record["gaits"]), "unstable": record["unstable"], "summary": summary}


def deformation(gait_list=GAITS, duration: float = 2.0, *, sample_every: int = 2, settle: float = 0.2,
                record: dict | None = None, **kw) -> dict:
    """Deformation ratios and displacement (§IV-E, Fig. 11), free worm, one world per gait.

    The five segment centres ``seg0..seg4`` (``pattern.keypoints``) give four distances between neighbours;
    ``ratio (S, W, 4)`` divides them by their values at t = 0 (the settled worm). ``displacement (S, W)`` [m] is the
    mean x of the five centres relative to t = 0 (net forward motion, +x).
    """
    if record is None:
        record = run_gaits(gait_list, duration, sample_every=sample_every, settle=settle, **kw)
    pat = record["model"].pattern
    idx = [pat.keypoint_names.index(f"seg{i}") for i in range(5)]
    kp = pat.keypoints(record["positions"].astype(np.float64))[..., idx, :]  # (S, W, 5, 3)
    dist = np.linalg.norm(np.diff(kp, axis=2), axis=-1)  # (S, W, 4)
    ratio = dist / dist[0]
    disp = kp[..., 0].mean(axis=2) - kp[0, :, :, 0].mean(axis=1)  # (S, W)
    summary = {"gaits": list(record["gaits"]), "duration_s": float(record["time"][-1]),
               "net_displacement_mm": (1e3 * disp[-1]).tolist(),
               "ratio_min": ratio.min(axis=0).tolist(), "ratio_max": ratio.max(axis=0).tolist(),
               "unstable": record["unstable"].tolist()}
    return {"time": record["time"], "ratio": ratio, "distance": dist, "displacement": disp,
            "keypoints": kp, "gaits": list(record["gaits"]), "unstable": record["unstable"], "summary": summary}


# ----------------------------------------------------------------------------------------------------------------
# output


def to_jsonable(obj):
    """Arrays to lists, NumPy scalars to Python, recursively; drops non-data values (models, params)."""
    if isinstance(obj, dict):
        return {str(k): to_jsonable(v) for k, v in obj.items() if k not in ("model", "params")}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, (np.bool_,)):
        return bool(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        f = float(obj)
        return f if np.isfinite(f) else None
    return obj


def save_json(result: dict, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_jsonable(result)))
    return path
