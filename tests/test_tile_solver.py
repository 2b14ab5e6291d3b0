"""The block-per-world implicit substeps (:class:`warpworm.sim.tile_solver.TileSolver`, the GPU path) against the banded path.

The truth is the banded path with full Newton steps (``Simulator(chord=False).run_substeps``: one thread per world,
block-banded Cholesky; the tile kernels take no chord steps, the band default does). The tile path
assembles the same Newton systems bit for bit (row by row instead of element by element). With
``factorization="band"`` it also factors them with the same arithmetic, column-parallel, so the runs must be
identical to the last bit in every scenario here: falling, landing, sticking and sliding on inclines, anchors, worlds
frozen by the speed check, the peristaltic preset's magnets. With "dense" (``wp.tile_cholesky``) the factor rounds
differently, so positions must agree to float32 rounding, 1e-6 m after 200 substeps, in the scenarios whose outcome
is continuous in the input: settling on a flat floor and magnet-driven gait steps. Not on the inclines: there the band
path disagrees with itself by 1.3e-5 m at a landing and 1.3 mm for a sliding worm after 200 substeps when its
start is moved by 4e-9 m (a contact's stick/slip test near its threshold flips), so no float rounding could match.

On the CPU Warp runs a block as one thread (``block_dim=1``) unless ``wp.config.enable_cpu_blocks`` is set; two tests
run several cooperative threads per world that way (4 threads: fewer than a column's 6 band rows and ~10 vertices
each; 32: some threads own two vertices), so the block logic (barriers, thread-strided rows, the scatter rounds,
the flag reductions) is checked here, not only on a GPU. The sm_90 compile check needs NVRTC (shipped with Warp),
not a GPU.

Cold, the CPU builds take ~15-30 s per (factorization, block size), the sm_90 builds 40-60 s (PTX) and ~110 s (the
dense cubin, with the cuSolverDx LTOs);
Warp's kernel cache keeps them afterwards.
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np
import pytest
import warp as wp

from warpworm.physics import gaits
from warpworm import quiet_warp
from warpworm.analysis.gait_metrics import wing_altitude_ratio
from warpworm.sim.model import Model
from warpworm.physics.params import WormParams
from warpworm.sim.simulator import Simulator
from warpworm.sim.tile_solver import DEFAULT_CUDA_BLOCK_DIM, FACTORIZATIONS, TileSolver, vertex_incidence

quiet_warp()

TOL = 1.0e-6
"""Position agreement [m] of the dense tile factorisation with the banded path after 200 substeps."""

FIELDS = ("positions", "velocities", "floor_force", "contact", "crease_angle", "bar_strain", "unstable", "step_count")
"""The State arrays the substeps write."""


def _copy_state(src, dst) -> None:
    for f in dataclasses.fields(src):
        getattr(dst, f.name).assign(getattr(src, f.name))


def _lift(sim, states, lift, incline) -> None:
    """Move every world of each state ``lift[w]`` [m] off its floor (along the normal of its ``incline[w]``)."""
    n = np.stack([-np.sin(incline), np.zeros_like(incline), np.cos(incline)], axis=-1)
    x = states[0].positions.numpy() + (np.asarray(lift)[:, None] * n)[:, None, :].astype(np.float32)
    for s in states:
        s.positions.assign(x)


def landing(incline=(0.0, 0.15, 0.35), friction_backward_ratio=1.0, **sim_kwargs):
    """Three worlds dropped 1, 2, 3 mm onto floors of the given inclines [rad] (default 0, 0.15 and 0.35: the last
    above the friction angle atan(0.268) = 0.26 rad, so it slides), with the given ``friction_backward_ratio``
    (scalar or per world; default 1, isotropic), 1 ms substeps. Returns (sim, band state, tile state)."""
    incline = np.asarray(incline, np.float64)
    model = Model.from_params(WormParams(floor_incline=incline, friction_backward_ratio=friction_backward_ratio),
                              3, "cpu")
    sim = Simulator(model, dt=1.0e-3, substeps=1, **{"chord": False, **sim_kwargs})
    band, tile = sim.initial_state(), sim.initial_state()
    _lift(sim, (band, tile), [1.0e-3, 2.0e-3, 3.0e-3], incline)
    return sim, band, tile


def settling_flat():
    """Three worlds dropped 1, 2 and 3 mm onto a flat floor, 1 ms substeps."""
    model = Model.from_params(WormParams(), 3, "cpu")
    sim = Simulator(model, dt=1.0e-3, substeps=1, chord=False)
    band, tile = sim.initial_state(), sim.initial_state()
    _lift(sim, (band, tile), [1.0e-3, 2.0e-3, 3.0e-3], np.zeros(3))
    return sim, band, tile


def anchored():
    """Two worlds hanging from three anchored tail vertices (force plate springs) 2 mm above a flat floor."""
    model = Model.from_params(WormParams(), 2, "cpu", anchors=[0, 1, 2], anchor_stiffness=[[50.0, 50.0, 50.0],
                                                                                          [200.0, 100.0, 50.0]])
    sim = Simulator(model, dt=1.0e-3, substeps=1, chord=False)
    band, tile = sim.initial_state(), sim.initial_state()
    _lift(sim, (band, tile), [2.0e-3, 2.0e-3], np.zeros(2))
    sim.control.set_anchor_targets(sim.control.anchor_target.numpy() + np.float32([0.0, 0.0, 2.0e-3]))
    return sim, band, tile


def _run_substeps(sim, band, tile, tiles, n: int) -> None:
    sim.run_substeps(band, n)
    tiles.step(tile, n, sim.control)


def _gait_steps(sim, band, tile, tiles, steps: int) -> None:
    """``steps`` steps of each state, each step's magnetic wrench evaluated from that state's own positions."""
    for _ in range(steps):
        sim.update_magnets(band)
        sim.run_substeps(band, sim.substeps)
        sim.update_magnets(tile)
        tiles.step(tile, sim.substeps, sim.control)


def gait():
    """The peristaltic preset on two worlds: settled 0.1 s by the banded path, then steps of 2 ms (2 substeps)."""
    model = Model.from_params(gaits.preset_params("peristaltic"), 2, "cpu")
    sim = Simulator(model, dt=2.0e-3, substeps=2, chord=False)
    band = sim.initial_state()
    sim.settle(band, 0.1)
    tile = model.state()
    _copy_state(band, tile)
    return sim, band, tile


def gait_off_floor():
    """The peristaltic preset's magnets driving two worms held 3 cm above the floor without gravity: magnet-driven
    and contact-free, so the dynamics is continuous and rounding differences stay rounding-sized (on the floor, a
    stick/slip or landing decision near its threshold amplifies them: the banded path itself moves 1.3e-5 m at a
    landing when its start moves by 4e-9 m; there the band factorization is compared bit for bit instead)."""
    model = Model.from_params(gaits.preset_params("peristaltic", gravity=0.0), 2, "cpu")
    sim = Simulator(model, dt=2.0e-3, substeps=2, chord=False)
    band = sim.initial_state()
    band.positions.assign(band.positions.numpy() + np.array([0.0, 0.0, 0.03], np.float32))
    tile = model.state()
    _copy_state(band, tile)
    return sim, band, tile


def test_vertex_incidence_lists_every_element_of_each_vertex_in_order():
    model = Model.from_params(WormParams(), 1, "cpu")
    for elements in (model.edges.numpy(), model.hinges.numpy()):
        start, index = vertex_incidence(elements, model.num_vertices)
        for u in range(model.num_vertices):
            expected = np.flatnonzero((elements == u).any(axis=1))  # ascending by construction
            np.testing.assert_array_equal(index[start[u]:start[u + 1]], expected)
    with pytest.raises(ValueError, match="vertex indices"):
        vertex_incidence(np.array([[0, 5]]), 5)


def test_bad_arguments_name_the_key():
    model = Model.from_params(WormParams(), 1, "cpu")
    sim = Simulator(model, chord=False)
    with pytest.raises(ValueError, match="factorization"):
        TileSolver(model, sim.settings, factorization="lu")
    with pytest.raises(ValueError, match="block_dim"):
        TileSolver(model, sim.settings, block_dim=0)
    with pytest.raises(ValueError, match="num_substeps"):
        TileSolver(model, sim.settings).step(sim.initial_state(), 0, sim.control)


def _assert_identical(band, tile) -> None:
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(tile, f).numpy(), getattr(band, f).numpy(), err_msg=f)


def test_band_factorization_is_bit_for_bit_the_band_path_landing_and_sliding():
    sim, band, tile = landing()
    x0 = band.positions.numpy().copy()
    _run_substeps(sim, band, tile, TileSolver(sim.model, sim.settings, "band"), 200)
    # the run did what it is meant to exercise: every world landed and touches its floor, the steep one slid
    assert (band.unstable.numpy() == 0).all() and (band.step_count.numpy() == 200).all()
    assert band.contact.numpy().any(axis=1).all()
    slide = np.abs(band.positions.numpy()[2, :, 0] - x0[2, :, 0]).mean()
    assert slide > 1.0e-3, f"the worm on the 0.35 rad floor slid only {slide * 1e3:.3f} mm"
    _assert_identical(band, tile)


def test_band_factorization_is_bit_for_bit_the_band_path_with_a_one_way_skin():
    """Friction that differs by direction (``friction_backward_ratio`` per world 2, ½, 2) on floors of 0, +0.35 and
    −0.35 rad: the head-up worm slides tail-ward on half the friction, the head-down one head-ward; the tile path's
    friction, contact updates and landings scale μ as the banded path's, bit for bit."""
    sim, band, tile = landing(incline=(0.0, 0.35, -0.35), friction_backward_ratio=np.array([2.0, 0.5, 2.0]))
    x0 = band.positions.numpy().copy()
    _run_substeps(sim, band, tile, TileSolver(sim.model, sim.settings, "band"), 200)
    assert (band.unstable.numpy() == 0).all() and band.contact.numpy().any(axis=1).all()
    dx = (band.positions.numpy()[:, :, 0] - x0[:, :, 0]).mean(axis=1)
    assert dx[1] < -1.0e-3 and dx[2] > 1.0e-3, dx  # down the slopes: tail-ward on +0.35, head-ward on −0.35
    _assert_identical(band, tile)


def test_band_factorization_is_bit_for_bit_the_band_path_anchored():
    sim, band, tile = anchored()
    _run_substeps(sim, band, tile, TileSolver(sim.model, sim.settings, "band"), 200)
    x = band.positions.numpy()
    assert x[:, 3:, 2].min() < 1.0e-4 < x[:, :3, 2].min()  # the body reached the floor, the anchored tail did not
    _assert_identical(band, tile)


def test_both_layouts_count_the_same_newton_steps():
    """The one solver interface: ``newton_stats`` of the tile layout (band factorization) and of the banded layout with
    full steps agree world by world (the same iterations: the same systems, the same stopping test), over landings
    and slides where the count varies between worlds."""
    sim, band, tile = landing()
    tiles = TileSolver(sim.model, sim.settings, "band")
    _run_substeps(sim, band, tile, tiles, 60)
    b, t = sim.newton_stats(), tiles.newton_stats()
    assert len(set(b["steps"])) > 1 and (b["steps"] >= 2 * 60).all(), b  # the worlds took different step counts
    for k in ("steps", "factors", "capped"):
        np.testing.assert_array_equal(t[k], b[k], err_msg=k)


def test_band_factorization_freezes_the_same_worlds():
    """The speed check at 0.17 m/s: the worlds dropped 2 and 3 mm (0.20, 0.24 m/s at impact) are frozen, the one
    dropped 1 mm (0.14 m/s) is not; a frozen world stays as the banded path leaves it."""
    sim, band, tile = landing(speed_limit=0.17)
    _run_substeps(sim, band, tile, TileSolver(sim.model, sim.settings, "band"), 60)
    np.testing.assert_array_equal(band.unstable.numpy(), [0, 1, 1])
    _assert_identical(band, tile)


def test_band_factorization_is_bit_for_bit_the_band_path_under_the_gait_magnets():
    sim, band, tile = gait()
    x0 = band.positions.numpy().copy()
    _gait_steps(sim, band, tile, TileSolver(sim.model, sim.settings, "band"), 100)
    assert np.linalg.norm(band.positions.numpy() - x0, axis=-1).max() > 1.0e-3  # the magnets moved the worm
    _assert_identical(band, tile)


def test_band_factorization_is_bit_for_bit_the_band_path_at_the_panel_contact():
    """The inchworm's EPM 7 mm under the plate (w 20, a 50 mm) presses wings against the panels' contact barrier
    (common.wing_contact, altitude below 2 % of the hinge length) at its second closest approach: the barrier's
    terms, assembled row by row in the tile kernel, are the banded path's bit for bit."""
    model = Model.from_params(gaits.preset_params("inchworm", wavelength=0.020, amplitude=0.05, closest_approach=0.007),
                              2, "cpu")
    sim = Simulator(model, dt=2.0e-3, substeps=2, chord=False)
    band = sim.initial_state()
    sim.settle(band, 0.05)
    sim.step(band, 700)  # the banded path alone to t = 1.4 s, before the second closest approach (t = 1.5 s)
    tile = model.state()
    _copy_state(band, tile)
    tiles = TileSolver(sim.model, sim.settings, "band")
    hinges = model.hinges.numpy()
    lowest = 1.0
    for _ in range(10):  # to t = 1.6 s
        _gait_steps(sim, band, tile, tiles, 10)
        lowest = min(lowest, float(wing_altitude_ratio(hinges, band.positions.numpy()).min()))
    assert lowest < 0.02, lowest  # the barrier was pressed
    _assert_identical(band, tile)


@pytest.mark.parametrize("scenario", ["settling_flat", "gait_off_floor"])
def test_dense_tile_factorization_matches_the_band_path_to_rounding(scenario):
    sim, band, tile = globals()[scenario]()
    x0 = band.positions.numpy().copy()
    tiles = TileSolver(sim.model, sim.settings, "dense")
    if scenario == "gait_off_floor":
        _gait_steps(sim, band, tile, tiles, 100)
    else:
        _run_substeps(sim, band, tile, tiles, 200)
    xb, xt = band.positions.numpy(), tile.positions.numpy()
    assert np.linalg.norm(xb - x0, axis=-1).max() > 1.0e-3  # the worms moved (fell / were driven)
    assert (band.unstable.numpy() == 0).all()
    if scenario == "gait_off_floor":
        assert not band.contact.numpy().any()  # still contact-free: a continuous trajectory
    err = np.abs(xt - xb).max()
    assert err < TOL, f"dense tile and band positions differ by {err:.3e} m after 200 substeps ({scenario})"
    for f in ("contact", "unstable", "step_count"):
        np.testing.assert_array_equal(getattr(tile, f).numpy(), getattr(band, f).numpy(), err_msg=f)


@pytest.mark.parametrize("factorization, block_dim", [("band", 4), ("dense", 32)])
def test_cooperative_threads_per_world_match_the_band_path(factorization, block_dim):
    """Several threads per world on CPU fibers (module docstring), 30 substeps: band, the landing worlds (exactly);
    dense, the worlds settling on the flat floor (to rounding)."""
    sim, band, tile = landing() if factorization == "band" else settling_flat()
    old = wp.config.enable_cpu_blocks
    wp.config.enable_cpu_blocks = True
    try:
        tiles = TileSolver(sim.model, sim.settings, factorization, block_dim=block_dim)
        tiles.step(tile, 30, sim.control)
    finally:
        wp.config.enable_cpu_blocks = old
    sim.run_substeps(band, 30)
    if factorization == "band":
        _assert_identical(band, tile)
    else:
        err = np.abs(tile.positions.numpy() - band.positions.numpy()).max()
        assert err < TOL, f"dense tile ({block_dim} threads) and band positions differ by {err:.3e} m"
        np.testing.assert_array_equal(tile.contact.numpy(), band.contact.numpy())
        np.testing.assert_array_equal(tile.step_count.numpy(), np.full(3, 30))


def test_shared_memory_per_world():
    """The budget the occupancy rests on. dense: the 3V × 3V float32 tile, the 3V right-hand side and < 1 KB of
    reduction scratch, and four such blocks (with the 1 KB the hardware reserves per block) fit the 228 KB of an
    H200 (sm_90) SM; band: the reduction scratch only."""
    model = Model.from_params(WormParams(), 1, "cpu")
    sim = Simulator(model, chord=False)
    n = 3 * model.num_vertices
    dense = TileSolver(model, sim.settings, "dense").shared_bytes_per_world
    assert 4 * (n * n + n) <= dense < 4 * (n * n + n) + 1024, dense
    assert 4 * (dense + 1024) <= 228 * 1024
    assert TileSolver(model, sim.settings, "band").shared_bytes_per_world < 1024


def _nvrtc_reason() -> str | None:
    """None when NVRTC can build sm_90 code in this process; else why not (the skip reason)."""
    wp.init()
    from warp._src.context import runtime

    if not getattr(runtime, "is_cuda_enabled", False):
        return "this Warp build has no CUDA support (NVRTC unavailable)"
    if 90 not in getattr(runtime, "nvrtc_supported_archs", set()):
        return "NVRTC cannot target sm_90"
    return None


# band as PTX at its GPU block size and register bound; dense as the cubin that links cuSolverDx (30 s cold), which
# runs when WARPWORM_CUBIN_TEST=1 (before a GPU run; the package-wide tests/test_aot_compile.py builds every module's
# PTX, the dense kernel's included, on every CI run)
@pytest.mark.parametrize("factorization, use_ptx", [
    ("band", True),
    pytest.param("dense", False, marks=pytest.mark.skipif(
        os.environ.get("WARPWORM_CUBIN_TEST") != "1",
        reason="the cuSolverDx cubin link (30 s cold) runs with WARPWORM_CUBIN_TEST=1")),
], ids=["band-ptx", "dense-cubin"])
def test_tile_kernel_compiles_for_sm90(factorization, use_ptx):
    """The kernel's own module (one per shape and factorisation, so the package-wide compile test cannot discover
    it) builds for sm_90 at its GPU block size and register bound. PTX builds the cooperative tile Cholesky (Warp
    links cuSolverDx only into a cubin); the dense cubin links cuSolverDx's potrf / potrs for the 117 × 117 tile and
    128 threads where Warp has libmathdx, as a GPU run would."""
    reason = _nvrtc_reason()
    if reason:
        pytest.skip(reason)
    from warp._src.context import runtime

    from warpworm.kernels.implicit_tile import MAX_REGISTERS, make_tile_substep_kernel

    model = Model.from_params(WormParams(), 1, "cpu")
    kernel = make_tile_substep_kernel(model.num_vertices, model.half_bandwidth, factorization == "dense")
    module = kernel.module  # a module of this kernel alone: its options are ours to set
    module.options["block_dim"] = DEFAULT_CUDA_BLOCK_DIM[factorization]
    paths = wp.compile_aot_module(module, arch=90, use_ptx=use_ptx)  # into the kernel cache: rebuilt only on change
    assert paths
    for p in paths:
        assert p.exists() and p.stat().st_size > 0, p
        if use_ptx:
            ptx = p.read_text(errors="replace")
            assert ptx.lstrip().startswith("//"), p  # PTX text (NVRTC's header comment)
            assert f".maxnreg {MAX_REGISTERS}" in ptx  # the register bound the occupancy figures assume
        elif runtime.core.wp_is_mathdx_enabled():
            assert b"cusolverdx" in p.read_bytes(), p


def test_simulator_solver_option_runs_the_tile_path_bit_for_bit():
    """``Simulator(solver="tile-band")``: the whole gait step (poses, wrench, substeps) through the tile kernel gives
    the banded solver's trajectory with full Newton steps (``chord=False``; the tile kernels take no chord steps) bit
    for bit; an unknown solver is refused by name."""
    p = gaits.preset_params("inchworm", magnet_model="analytic")
    out = {}
    for solver in ("band", "tile-band"):
        sim = Simulator(Model.from_params(p, 2, "cpu"), dt=4e-3, substeps=4, solver=solver, chord=False)
        state = sim.initial_state()
        sim.settle(state, 0.02)
        out[solver] = sim.run(state, [0.04], keys=("positions", "crease_angle"))[0]
    for k in ("positions", "crease_angle"):
        np.testing.assert_array_equal(out["band"][k], out["tile-band"][k])
    with pytest.raises(ValueError, match="solver: got 'cg'"):
        Simulator(Model.from_params(p, 1, "cpu"), solver="cg")
