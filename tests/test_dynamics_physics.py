"""Physics of the implicit solver against independent truths: rest, friction on an incline, free fall, energy, dt.

Each test uses one or a few worlds and short horizons so the dynamics suite stays within minutes on one core.
The truths are closed forms (g, g(sin β − μk cos β), the crease pattern's rest angles), not earlier runs.
"""

from __future__ import annotations

import numpy as np
import pytest

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.sim.model import Model
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator

quiet_warp()

NO_MAGNETS = dict(ipm_moment=np.zeros(3), epm_moment=0.0)


def _com(x: np.ndarray) -> np.ndarray:
    return x.mean(axis=-2)


def _lift(state, dz: float) -> None:
    x = state.positions.numpy() + np.array([0.0, 0.0, dz], np.float32)
    state.positions.assign(x)


def test_rest_creases_hold_rest_angle_and_do_not_drift():
    """The built worm, IPMs included, settles under gravity with every crease within 0.5° of rest, and stays."""
    p = WormParams()  # default worm with its three IPMs (mass and IPM-IPM forces), EPM parked
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=2)
    state = sim.initial_state()
    sim.step(state, 150, epm=False)  # 0.3 s
    a = sim.snapshot(state)
    sim.step(state, 150, epm=False)  # 0.3 s more
    b = sim.snapshot(state)
    rest = np.broadcast_to(model.hinge_rest_angle_host, b["crease_angle"].shape)
    dev = np.rad2deg(np.abs(b["crease_angle"] - rest)).max()
    assert dev < 0.5, f"crease deviates {dev:.3f} deg from rest"
    drift = np.abs(_com(b["positions"]) - _com(a["positions"])).max()
    assert drift < 1e-5, f"centroid drifted {drift * 1e3:.4f} mm in 0.3 s at rest"
    assert not b["unstable"].any()
    # the bottom face rests on the floor
    assert b["contact"].any() and b["positions"][..., 2].min() > -1e-6


RIGID_SHEET = dict(hinge_stiffness=0.3, valley_bar_stiffness=2.0)
"""A stiff sheet (60x the default creases, 7x the waists) for the friction tests, whose truth (Coulomb's law for a
block) is a rigid body's: a soft worm also flexes under the uneven friction of its contacts."""


@pytest.mark.parametrize("substeps", [2, 4, 16], ids=["2ms", "1ms", "250us"])  # 2 ms: the gaits' default
@pytest.mark.parametrize("mu_s, mu_k", [(0.268, 0.24), (0.35, 0.33)])
def test_incline_below_friction_angle_does_not_creep(mu_s, mu_k, substeps):
    beta = np.arctan(mu_s) - np.deg2rad(2.0)
    p = WormParams(mu_static=mu_s, mu_kinetic=mu_k, floor_incline=beta, damping=0.0, **NO_MAGNETS, **RIGID_SHEET)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=4e-3, substeps=substeps)
    state = sim.initial_state()
    # The worm is built unloaded; let it take its weight first. Then it is at rest on the slope. (With mu_k far below
    # tan(beta), e.g. 0.35 / 0.2, the light contact vertices, which carry more than their share of the down-slope
    # load, slip while it settles and the slip spreads: docs/dynamics.md.)
    sim.step(state, 50, epm=False)
    x0 = sim.snapshot(state)["positions"]
    sim.step(state, 500, epm=False)  # 2 s
    x1 = sim.snapshot(state)["positions"]
    slide = np.linalg.norm(_com(x1) - _com(x0), axis=-1).max()
    # measured 1.55-1.81e-5 m over 2 s in all six cases: the regularised static friction's creep, ~ε = 1e-5 m/s
    # (Simulator slip_speed) times tan β / μs; 5e-5 m is 2.8x that (a tenfold creep speed fails)
    assert slide < 5e-5, f"worm crept {slide * 1e3:.4f} mm over 2 s at {np.rad2deg(beta):.2f} deg"


@pytest.mark.parametrize("substeps", [1, 2, 40], ids=["2ms", "1ms", "50us"])
@pytest.mark.parametrize("mu_s, mu_k", [(0.268, 0.24), (0.35, 0.2)])
def test_incline_above_friction_angle_slides_with_coulomb_acceleration(mu_s, mu_k, substeps):
    beta = np.arctan(mu_s) + np.deg2rad(2.0)
    g = 9.81
    p = WormParams(mu_static=mu_s, mu_kinetic=mu_k, floor_incline=beta, damping=0.0, gravity=g, **NO_MAGNETS,
                   **RIGID_SHEET)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=substeps)
    state = sim.initial_state()
    axis = np.array([np.cos(beta), 0.0, np.sin(beta)])  # up the slope
    ts, s = [], []
    for _ in range(40):  # 0.4 s, sampled every 10 ms
        sim.step(state, 5, epm=False)
        snap = sim.snapshot(state)
        ts.append(snap["time"][0])
        s.append(float(_com(snap["positions"][0]) @ axis))
    ts, s = np.array(ts), np.array(s)
    keep = ts > 0.05  # after the contact transient of the first substeps
    acc = -2.0 * np.polyfit(ts[keep], s[keep], 2)[0]  # down the slope
    expected = g * (np.sin(beta) - mu_k * np.cos(beta))
    # measured 0.8e-5 to 9.3e-5 of the expected over these six cases (docs/dynamics.md: 0.01-0.1 %); a 1 % error in
    # the normal force moves a by ~3 % here, so 5e-4 (≤ 5.4x the largest measured) leaves no room for one
    assert abs(acc - expected) < 5e-4 * expected, f"a = {acc:.5f} m/s², expected {expected:.5f}"


def _slide_acceleration(p, substeps: int = 2, seconds: float = 0.4) -> float:
    """Acceleration [m/s²] of the worm's centroid down the floor's slope, fitted after the contact transient."""
    beta = float(p.floor_incline)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=substeps)
    state = sim.initial_state()
    axis = np.array([np.cos(beta), 0.0, np.sin(beta)])  # up the slope when beta > 0
    ts, s = [], []
    for _ in range(int(round(seconds / 0.01))):
        sim.step(state, 5, epm=False)
        snap = sim.snapshot(state)
        ts.append(snap["time"][0])
        s.append(float(_com(snap["positions"][0]) @ axis))
    ts, s = np.array(ts), np.array(s)
    keep = ts > 0.05
    return -2.0 * np.sign(beta) * np.polyfit(ts[keep], s[keep], 2)[0]


def test_backward_friction_ratio_holds_a_worm_head_up_and_not_head_down():
    """A skin that grips twice as hard tail-ward (``friction_backward_ratio`` 2): on a 20° slope, steeper than
    atan μs = 15.0° but not than atan 2μs = 28.2°, the worm facing uphill (sliding down would be tail-ward) holds,
    and facing downhill (head-ward) slides with Coulomb's g (sin β − μk cos β) of the head-ward μk, to 0.05 %."""
    mu_s, mu_k, ratio = 0.268, 0.24, 2.0
    beta = np.deg2rad(20.0)
    kw = dict(mu_static=mu_s, mu_kinetic=mu_k, friction_backward_ratio=ratio, damping=0.0, **NO_MAGNETS,
              **RIGID_SHEET)
    model = Model.from_params(WormParams(floor_incline=beta, **kw), 1, "cpu")
    sim = Simulator(model, dt=4e-3, substeps=2)
    state = sim.initial_state()
    sim.step(state, 50, epm=False)
    x0 = sim.snapshot(state)["positions"]
    sim.step(state, 500, epm=False)  # 2 s
    slide = np.linalg.norm(_com(sim.snapshot(state)["positions"]) - _com(x0), axis=-1).max()
    assert slide < 1e-4, f"head-up worm crept {slide * 1e3:.4f} mm over 2 s at 20 deg with a 2x tail-ward grip"
    acc = _slide_acceleration(WormParams(floor_incline=-beta, **kw))
    expected = 9.81 * (np.sin(beta) - mu_k * np.cos(beta))
    # measured 1.2e-6 of the expected; 5e-4 as the isotropic slides' (a skin profile off by 1 % at θ = 0 fails it)
    assert abs(acc - expected) < 5e-4 * expected, f"head-down a = {acc:.5f} m/s², expected {expected:.5f}"


def test_backward_friction_ratio_scales_the_tailward_kinetic_friction():
    """Past atan(2 μs) (30° here) the head-up worm slides tail-ward against twice the kinetic friction:
    g (sin β − 2 μk cos β), to 0.05 % (with the isotropic μk it would be 2.2× that)."""
    mu_s, mu_k, ratio = 0.268, 0.24, 2.0
    beta = np.deg2rad(30.0)
    p = WormParams(mu_static=mu_s, mu_kinetic=mu_k, friction_backward_ratio=ratio, floor_incline=beta, damping=0.0,
                   **NO_MAGNETS, **RIGID_SHEET)
    acc = _slide_acceleration(p)
    expected = 9.81 * (np.sin(beta) - ratio * mu_k * np.cos(beta))
    # measured 1.4e-4 of the expected (3.6x under the bound)
    assert abs(acc - expected) < 5e-4 * expected, f"a = {acc:.5f} m/s², expected {expected:.5f}"


@pytest.mark.parametrize("incline_deg, substeps", [(0.0, 2), (0.0, 8), (8.0, 2)], ids=["flat-1ms", "flat-250us",
                                                                                       "8deg-1ms"])
def test_kicked_worm_stops_after_coulombs_distance(incline_deg, substeps):
    """A worm resting on the floor, kicked up the slope at v0 = 0.1 m/s, slides to a stop after v0² / (2 a) with
    a = g (sin i + μk cos i) (on the flat: v0² / (2 μk g)); implicit Euler's sum of end-of-step velocities takes
    v0 h / 2 less (h the substep: the discrete sum of a linear decay)."""
    mu_s, mu_k, g, v0 = 0.268, 0.24, 9.81, 0.1
    beta = np.deg2rad(incline_deg)
    p = WormParams(mu_static=mu_s, mu_kinetic=mu_k, floor_incline=beta, damping=0.0, gravity=g, **NO_MAGNETS,
                   **RIGID_SHEET)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=substeps)
    state = sim.initial_state()
    sim.step(state, 50, epm=False)  # takes its weight
    axis = np.array([np.cos(beta), 0.0, np.sin(beta)])  # up the slope
    x0 = _com(sim.snapshot(state)["positions"][0])
    v = state.velocities.numpy()
    v[:] = (v0 * axis).astype(np.float32)
    state.velocities.assign(v)
    sim.step(state, 50, epm=False)  # 0.1 s: stops after 42 ms (flat) / 28 ms (8°)
    snap = sim.snapshot(state)
    assert np.abs(snap["velocities"]).max() < 1e-4  # stopped (held by static friction)
    d = float((_com(snap["positions"][0]) - x0) @ axis)
    expected = v0**2 / (2.0 * g * (np.sin(beta) + mu_k * np.cos(beta))) - 0.5 * v0 * sim.dt_sub
    # measured 0.6 µm short in all three (2.9e-4 / 3.2e-4 / 4.5e-4 of the distance); a 1 % error in μk or in the
    # normal force moves it by ~20 µm
    assert abs(d - expected) < 2e-6, f"slid {d * 1e3:.5f} mm, expected {expected * 1e3:.5f} mm"


def _mass_from_definitions(p: WormParams, model: Model) -> float:
    """The worm's mass [kg] from its definition, computed apart from the model's lumping: sheet_density × the rest
    mesh's area (trimesh) + each IPM's magnet_mass_density × π r² h."""
    import trimesh

    area = trimesh.Trimesh(model.rest_positions_host[0].astype(np.float64), model.pattern.triangles,
                           process=False).area
    ipm = p.magnet_mass_density * np.pi * (p.ipm_diameter / 2) ** 2 * p.ipm_thickness
    return float(p.sheet_density * area + len(model.pattern.mount_vertices) * ipm)


def test_masses_are_density_times_area_and_volume():
    """The lumped masses against their definitions, computed apart: the sheet is sheet_density × its area (trimesh's
    area of the rest mesh), each IPM magnet_mass_density × π r² h, the total their sum (the worm's 22.6 mN weight of
    docs/design notes), and the centre of mass that of the facets' area-weighted centroids (trimesh) and the IPMs at
    their mount centres (the lumping keeps it: docs/dynamics.md)."""
    import trimesh

    from warpworm.physics import crease

    for kw in ({}, dict(a=0.025, b=0.009, sheet_density=0.2, ipm_diameter=0.008, ipm_thickness=0.002)):
        p = WormParams(**kw)
        model = Model.from_params(p, 1, "cpu")
        x = model.rest_positions_host[0].astype(np.float64)
        mesh = trimesh.Trimesh(x, model.pattern.triangles, process=False)
        m = model.vertex_mass_host[0]
        sheet = p.sheet_density * mesh.area
        ipm = p.magnet_mass_density * np.pi * (p.ipm_diameter / 2) ** 2 * p.ipm_thickness
        assert model.sheet_mass_host[0] == pytest.approx(sheet, rel=1e-12)
        assert model.ipm_mass_host[0] == pytest.approx(ipm, rel=1e-12)
        n_ipm = len(model.pattern.mount_vertices)
        assert m.sum() == pytest.approx(sheet + n_ipm * ipm, rel=1e-12)
        if not kw:
            assert m.sum() * p.gravity == pytest.approx(0.0226, abs=5e-5)  # the 22.6 mN the docs quote
        mounts, _ = crease.mount_poses(model.pattern, x)
        com = (p.sheet_density * (mesh.area_faces[:, None] * mesh.triangles_center).sum(0)
               + ipm * mounts.sum(0)) / (sheet + n_ipm * ipm)
        assert np.abs(m @ x / m.sum() - com).max() < 1e-12


def test_free_fall_matches_g():
    g = 9.81
    p = WormParams(damping=0.0, gravity=g, **NO_MAGNETS)
    model = Model.from_params(p, 1, "cpu")
    sim = Simulator(model, dt=2e-3, substeps=8)
    state = sim.initial_state()
    _lift(state, 0.2)
    ts, z = [], []
    for _ in range(20):  # 0.2 s: falls ~0.2 m, does not reach the floor
        sim.step(state, 5, epm=False)
        snap = sim.snapshot(state)
        ts.append(snap["time"][0])
        z.append(_com(snap["positions"][0])[2])
    assert not snap["contact"].any()
    acc = 2.0 * np.polyfit(np.array(ts), np.array(z), 2)[0]
    assert abs(acc + g) < 1e-3 * g, f"free-fall acceleration {acc:.5f}, expected {-g}"
    # the shape is unchanged while falling (uniform field: no internal forces)
    rest = np.broadcast_to(model.hinge_rest_angle_host, snap["crease_angle"].shape)
    assert np.rad2deg(np.abs(snap["crease_angle"] - rest)).max() < 0.05


def _energies(model: Model, snap: dict) -> tuple[float, float]:
    """Kinetic and potential (bars + creases) energy [J] of world 0, closed forms on the snapshot (independent of the
    solver)."""
    m = model.vertex_mass_host[0]
    v = snap["velocities"][0].astype(np.float64)
    ke = 0.5 * float(np.sum(m * np.sum(v**2, axis=-1)))
    from warpworm.physics import crease

    L0 = model.rest_length.numpy()[0].astype(np.float64)
    L = crease.edge_lengths(snap["positions"][0].astype(np.float64), model.pattern.edges)
    pe = 0.5 * float(np.sum(model.bar_stiffness.numpy()[0] / L0 * (L - L0) ** 2))
    dpsi = snap["crease_angle"][0].astype(np.float64) - model.hinge_rest_angle_host[0]
    kh = float(model.params.hinge_stiffness) * model.hinge_length.numpy()[0]
    return ke, pe + 0.5 * float(np.sum(kh * dpsi**2))


def _lowest_elastic_mode(model: Model):
    """(ω [rad/s], mode shape (V, 3)) of the worm's softest elastic mode: K φ = ω² M φ with K the Hessian of E at
    rest from the NumPy reference (tests/numpy_reference.py; at rest, with no force in any element, the Gauss–Newton
    Hessian is the exact one), M the lumped masses. Its six rigid modes (and the mechanism modes under 2 rad/s)
    are skipped."""
    import scipy.linalg
    from numpy_reference import NumpyImplicit

    V = model.num_vertices
    x = model.rest_positions_host[:1].astype(np.float64)
    g, K = NumpyImplicit(model, 1.0)._elastic(x, x, model.hinge_rest_angle_host[:1].astype(np.float64),
                                              np.zeros((1, V)))
    # the rest shape is an equilibrium, to the float32 rounding of the rest lengths (EA × 6e-8 ~ 1e-6 N; measured 1.1e-6)
    assert np.abs(g).max() < 5e-6, np.abs(g).max()
    w2, phi = scipy.linalg.eigh(K[0], np.diag(np.repeat(model.vertex_mass_host[0], 3)))
    k = int(np.argmax(w2 > 4.0))
    return float(np.sqrt(w2[k])), phi[:, k].reshape(V, 3)


def test_undamped_oscillation_trades_energy_and_loses_it_at_implicit_eulers_rate():
    """Every damping off (velocity and crease damping 0), no gravity, no floor: kick the worm along its softest
    elastic mode (ω ≈ 36 rad/s). Kinetic and potential energy trade (the potential reaches 98 % of the total, the
    kinetic falls under 1 %), and the total decays only as implicit Euler's own dissipation of a linear mode, E0 (1 +
    ω²h²)^(−N) after N substeps h, which shrinks with h at first order (halving h halves the loss over 0.1 s)."""
    p = WormParams(damping=0.0, hinge_damping=0.0, gravity=0.0, **NO_MAGNETS)
    model = Model.from_params(p, 1, "cpu")
    omega, shape = _lowest_elastic_mode(model)
    assert 20.0 < omega < 60.0, omega
    losses = {}
    for sub in (4, 8):
        sim = Simulator(model, dt=1e-3, substeps=sub, newton_tol=0.0, chord=False)
        state = sim.initial_state()
        _lift(state, 0.01)  # off the floor; low, so float32 positions resolve the bars' strain energy
        state.velocities.assign((0.01 * shape / np.abs(shape).max())[None].astype(np.float32))  # 1 cm/s at most
        e0 = sum(_energies(model, sim.snapshot(state)))
        trace = []
        for _ in range(100):  # 0.1 s: 0.57 periods
            sim.step(state, 1, epm=False)
            trace.append(_energies(model, sim.snapshot(state)))
        ke, pe = np.array(trace).T / e0
        h = sim.dt_sub
        expected = (1.0 + (omega * h) ** 2) ** (-sub * np.arange(1, 101))
        # measured: within 2.1e-4 / 1.1e-4 of E0 of the closed form (4 / 8 substeps; float32 states, a mildly
        # nonlinear mode); potential 0.986 / 0.993 of E0 at most, kinetic 3e-4 at least
        assert np.abs(ke + pe - expected).max() < 1e-3, np.abs(ke + pe - expected).max()
        assert np.all(np.diff(ke + pe) < 1e-4)  # never gains
        assert pe.max() > 0.98 and ke.min() < 0.01, (pe.max(), ke.min())
        losses[sub] = 1.0 - (ke[-1] + pe[-1])
    # first order in h: measured loss ratio 1.98 (0.0319 / 0.0161)
    assert abs(losses[4] / losses[8] - 2.0) < 0.2, losses


def _run_dt(dt_sub: float, t_end: float) -> np.ndarray:
    """Zero gravity, tail section pinned by anchors, EPM held still above the anterior half: the worm bends toward
    it smoothly (no contact, no stick-slip), so the trajectory is a smooth function of dt."""
    p = gaits.preset_params("peristaltic", gravity=0.0, damping=5.0, magnet_model="dipoles")
    model = Model.from_params(p, 1, "cpu", anchors=[0, 1, 2], anchor_stiffness=1e3)
    ipm = model.ipm_rest_pos_host[0, :, 0]
    substeps = 4
    sim = Simulator(model, dt=dt_sub * substeps, substeps=substeps)
    sim.set_path(gaits.keyframe_path([0.0], [[ipm[1] + 0.4 * (ipm[2] - ipm[1]), 0.0, 0.09]], [np.eye(3)]))
    state = sim.initial_state()
    sim.step(state, int(round(t_end / sim.dt)))
    snap = sim.snapshot(state)
    assert not snap["unstable"].any()
    return snap["positions"][0].astype(np.float64)


def test_dt_halving_converges():
    t_end = 0.06
    ref = _run_dt(1.25e-5, t_end)
    start = Model.from_params(WormParams(), 1, "cpu").rest_positions_host[0]
    errs = [np.abs(_run_dt(h, t_end) - ref).max() for h in (1e-4, 5e-5, 2.5e-5)]
    moved = np.abs(ref - start).max()
    assert moved > 1e-3, f"the magnets should deform the worm noticeably (moved {moved})"
    # errors shrink as dt halves: at least by 0.7 per halving (measured ~0.45: first order)
    assert errs[1] < 0.7 * errs[0] and errs[2] < 0.7 * errs[1], errs


@pytest.mark.parametrize("substeps", [2, 4, 16], ids=["2ms", "1ms", "250us"])
def test_axial_squeeze_folds_the_creases(substeps):
    """The worm folds: squeezing it axially (tail ring anchored, head ring pushed toward it, no gravity) shortens
    it through crease rotation and the soft valley-ring bars, while every other bar stays rigid (EA = 1e4 N: the
    squeeze takes ~N, where the default 20 N bars would strain by a few %), at 2 ms, 1 ms and 250 µs substeps."""
    p = WormParams(gravity=0.0, damping=20.0, bar_stiffness=1.0e4, **NO_MAGNETS)
    model = Model.from_params(p, 1, "cpu")
    pat = model.pattern
    n = pat.vertices.shape[0] // 3 - 1  # last section index
    tail, head = [0, 1, 2], [3 * n, 3 * n + 1, 3 * n + 2]
    model = Model.from_params(p, 1, "cpu", anchors=tail + head, anchor_stiffness=1e3)
    sim = Simulator(model, dt=4e-3, substeps=substeps)
    state = sim.initial_state()
    x0 = state.positions.numpy()[0].astype(np.float64)
    targets = x0[tail + head].copy()
    # 7.5 % of the 80 mm worm: at 8 mm (10 %) the converged solve crumples the bellows at 250 µs substeps (a crease
    # folds through past 7 mm, the snap-through; a fixed 3 Newton steps, the first default, did not see it)
    squeeze = 6e-3
    for r in np.linspace(0.0, 1.0, 31)[1:]:  # ramp the squeeze over 0.3 s, then hold 0.3 s
        t = targets.copy()
        t[3:, 0] -= r * squeeze
        sim.set_anchor_targets(t)
        sim.step(state, 3)
    sim.step(state, 75)
    snap = sim.snapshot(state)
    assert not snap["unstable"].any()
    x = snap["positions"][0].astype(np.float64)
    shortening = x0[head, 0].mean() - x[head, 0].mean() - (x0[tail, 0].mean() - x[tail, 0].mean())
    assert shortening > 0.7 * squeeze, f"shortened only {shortening * 1e3:.2f} mm"
    from warpworm.physics import crease

    valley = pat.edge_label == crease.VALLEY
    strain = crease.edge_lengths(x, pat.edges) / crease.edge_lengths(x0, pat.edges) - 1.0
    assert np.abs(strain[~valley]).max() < 2e-3, np.abs(strain[~valley]).max()
    # the length is taken up by folding: the transverse creases (valley and mountain rings) turn by degrees
    turn = np.rad2deg(np.abs(snap["crease_angle"][0] - model.hinge_rest_angle_host[0]))
    rings = (pat.hinge_label == crease.VALLEY) | ((pat.hinge_label == crease.MOUNTAIN)
                                                 & (np.abs(model.hinge_rest_angle_host[0]) < 1.2))
    assert np.median(turn[rings]) > 2.0, np.median(turn[rings])


def test_anchor_forces_carry_the_weight_of_a_hanging_worm():
    """Force plate: a worm hung 6 cm above the floor by its end sections comes to rest with the anchors' reported
    forces summing to its weight (m g, m from the sheet's density × trimesh's area and the IPMs' ρ π r² h)."""
    p = WormParams(damping=50.0, **NO_MAGNETS)
    n2 = 2 * p.n_units
    ends = [0, 1, 2, 3 * n2, 3 * n2 + 1, 3 * n2 + 2]  # the tail and head sections' vertices
    model = Model.from_params(p, 1, "cpu", anchors=ends, anchor_stiffness=1e3)
    sim = Simulator(model, dt=4e-3, substeps=4)
    state = sim.initial_state()
    rest = state.positions.numpy()[0, ends].astype(np.float64)
    for lift in np.linspace(0.0, 0.06, 31)[1:]:  # raise the anchors over 0.24 s (a jump would tear the sheet)
        sim.set_anchor_targets(rest + [0.0, 0.0, lift])
        sim.step(state, 2)
    sim.step(state, 150)  # hold 0.6 s, well damped
    snap = sim.snapshot(state)
    assert not snap["unstable"].any() and not snap["contact"].any()
    weight = _mass_from_definitions(p, model) * p.gravity  # not the model's own masses: a wrong area fails here
    pull = snap["anchor_force"][0].sum(axis=0)  # the worm pulls the anchors down
    assert abs(pull[2] / -weight - 1.0) < 0.01, (pull, weight)
    assert np.abs(pull[:2]).max() < 0.01 * weight


def test_model_declares_every_attribute_and_the_kernels_read_them_by_name():
    """The Model's attributes are exactly its declared ones (a builder that adds an undeclared array is refused), and
    every field of the kernels' ``BarHingeModel`` is a Model array of the same name and shape."""
    from warpworm.kernels.substep import BarHingeModel
    from warpworm.sim.model import ModelBuilder
    from warpworm.sim.solver import model_struct

    model = Model.from_params(WormParams(), 2, "cpu")
    assert set(vars(model)) == set(Model.__annotations__)
    view = model_struct(model)
    for name in BarHingeModel.vars:
        assert getattr(view, name).shape == getattr(model, name).shape, name
    builder = ModelBuilder(WormParams(), 1)
    builder.host["hinge_rest"] = (np.zeros((1, model.num_hinges), np.float32), float)
    with pytest.raises(RuntimeError, match="not declared by Model: \\['hinge_rest'\\]"):
        builder.finalize("cpu")
