"""Batched simulator of magnetically actuated origami worms: the host loop around :mod:`warpworm.kernels`.

One :meth:`Simulator.step` = one magnetic-wrench evaluation (EPM pose from its path, IPM poses from their mounts,
net wrench on every magnet by :func:`warpworm.physics.magnets.launch_world_wrenches`, distributed onto the mount
vertices) and ``substeps`` substeps in one launch by the solver (:mod:`warpworm.sim.solver`). The wrench is held over
a step's substeps (it varies on the magnets' ms time scale; ``magnet_every_substep=True`` for dt studies). All
worlds are in every launch. Typical use::

    model = Model.from_params(gaits.preset_params("peristaltic"), num_worlds=16, device="cpu")
    sim = Simulator(model, dt=4e-3, substeps=2)
    state = sim.initial_state()
    sim.settle(state, 0.3)               # EPM absent, the worm settles under gravity; t restarts at 0
    frames = sim.run(state, [0.5, 1.0])  # snapshots (dicts of NumPy arrays) at t = 0.5 s and 1 s

The inputs of a run (EPM path, anchor targets) are a :class:`~warpworm.sim.model.Control`: ``sim.control`` by
default, or one passed to :meth:`~Simulator.step` / :meth:`~Simulator.run`.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from warpworm.ids import WORLD_CRUMPLED, WORLD_EXPLODED
from warpworm.kernels import magnet_pose, world_status
from warpworm.physics.gaits import DEFAULT_DT, DEFAULT_SUBSTEPS
from warpworm.physics.magnets import launch_world_wrenches, pair_wrench_scratch
from warpworm.sim import capture_gate
from warpworm.sim.model import Control, Model, State
from warpworm.sim.solver import BandedSolver, SolverBase, SubstepSettings, put_bounded
from warpworm.sim.tile_solver import TileSolver
from warpworm.transforms import quat_wxyz_to_matrix, quat_xyzw_to_wxyz


def model_wrenches(model: Model, state: State, moment: wp.array, *, epm_wrench: bool = True,
                   force_out: wp.array | None = None, torque_out: wp.array | None = None,
                   pair_scratch: tuple[wp.array, wp.array] | None = None, skip_stopped: bool = False) -> None:
    """:func:`warpworm.physics.magnets.launch_world_wrenches` on a model's magnets in a state (the simulator's one
    call of the magnet API): net force and torque on every magnet of every world, into ``state.magnet_force`` /
    ``magnet_torque`` unless other outputs are given. ``epm_wrench=False`` leaves the EPM's own wrench (slot 0) zero
    and spends nothing on it: the dynamics needs only the IPMs'. ``pair_scratch``: the caller's
    (:func:`warpworm.physics.magnets.pair_wrench_scratch`), else one per call. ``skip_stopped``: the worlds whose
    status (``state.unstable``) is non-zero keep the wrenches they had (the substeps no longer move them)."""
    launch_world_wrenches(
        model.magnet_model,
        model.magnet_shape,
        model.magnet_size,
        moment,
        state.magnet_pos,
        state.magnet_rot,
        state.magnet_force if force_out is None else force_out,
        state.magnet_torque if torque_out is None else torque_out,
        model.dipole_density,
        model.device,
        epm_wrench=epm_wrench,
        pair_scratch=pair_scratch,
        stopped=state.unstable if skip_stopped else None,
    )


def cpu_graphs_supported() -> bool:
    """Whether this Warp can capture graphs on the CPU (1.19 and later; before, ``capture_begin`` wants CUDA)."""
    try:
        return tuple(int(v) for v in wp.config.version.split(".")[:2]) >= (1, 19)
    except ValueError:
        return False


MAX_GRAPHS = 4
"""Step graphs a simulator keeps (one per (state, control, EPM on/off), the oldest dropped first): each pins its
state's arrays, and a caller that makes a state per trajectory would otherwise keep them all."""


SOLVERS = ("band", "tile-band", "tile-dense")
"""The ways a world's Newton system is solved (``Simulator(solver=...)``)."""


def make_solver(name: str, model: Model, settings: SubstepSettings) -> SolverBase:
    """The solver :data:`SOLVERS` calls ``name``: :class:`BandedSolver` or a :class:`TileSolver` of that
    factorization."""
    if name not in SOLVERS:
        raise ValueError(f"solver: got {name!r}; expected one of {SOLVERS}")
    if name == "band":
        return BandedSolver(model, settings)
    return TileSolver(model, settings, factorization=name[len("tile-"):])


class Simulator:
    """Integrator for a :class:`~warpworm.sim.model.Model` (all worlds at once, CPU or CUDA).

    Args:
        model: the batch.
        dt: step [s]: the magnetic wrench and the EPM pose are refreshed once per step (default the gait runs',
            :data:`warpworm.physics.gaits.DEFAULT_DT`).
        substeps: substeps per step (``dt / substeps`` the substep; default
            :data:`~warpworm.physics.gaits.DEFAULT_SUBSTEPS`: 2 ms substeps, accurate for the gaits).
        magnet_every_substep: re-evaluate the magnetic wrench every substep (slower; for dt studies).
        strain_limit: a bar strained beyond |ΔL/L0| this flags its world unstable (the soft waist bars at
            ``max(strain_limit, 0.9)``).
        speed_limit: a vertex faster than this [m/s] (or non-finite) flags its world unstable.
        fold_tolerance: a hinge this far [rad] outside its NoFoldThrough range means the sheet crumpled: the world
            is frozen and flagged (``State.unstable`` 2; 1 is an explosion). Default 5°.
        use_graph: capture a step as a graph and replay it (default: on CUDA, and on the CPU from Warp 1.19, where
            a failing capture falls back to plain launches); the same trajectory bit for bit, less launch cost. A
            graph is captured per (state, control, EPM on/off) and again after ``control.set_path``.
        newton: Newton steps per substep at most (>= 2; the contacts are updated before every step after the
            first). 24: a stick–slip transition can take 15–25 at 2 ms substeps.
        newton_tol: a Newton step (the second or later) changing no vertex's velocity by more than this [m/s] ends
            the substep (default 1e-4; 0 takes every step). A fixed step count is not converged through a
            snap-through.
        chord: chord Newton steps (reuse the last factor; :mod:`warpworm.kernels.implicit_euler`); default on for
            the banded solver, which alone has them.
        slip_speed: static friction's regularisation speed ε [m/s]: a worm held by friction creeps at most ~ε.
        solver: one of :data:`SOLVERS`: ``"band"`` one thread per world (:class:`~warpworm.sim.solver.BandedSolver`);
            ``"tile-band"`` / ``"tile-dense"`` a block of threads per world, the banded matrix factored column-parallel
            (bit-identical to "band") or a dense tile Cholesky in shared memory
            (:class:`~warpworm.sim.tile_solver.TileSolver`; the GPU layouts).
    """

    def __init__(
        self,
        model: Model,
        dt: float = DEFAULT_DT,
        substeps: int = DEFAULT_SUBSTEPS,
        *,
        magnet_every_substep: bool = False,
        strain_limit: float = SubstepSettings.strain_limit,
        fold_tolerance: float = SubstepSettings.fold_tolerance,
        speed_limit: float = SubstepSettings.speed_limit,
        use_graph: bool | None = None,
        newton: int = SubstepSettings.newton,
        chord: bool | None = None,
        newton_tol: float = SubstepSettings.newton_tol,
        slip_speed: float = SubstepSettings.slip_speed,
        solver: str = "band",
    ):
        if solver not in SOLVERS:
            raise ValueError(f"solver: got {solver!r}; expected one of {SOLVERS}")
        self.model = model
        bad_dt = not (0.0 < float(dt) < math.inf)  # also NaN
        bad_sub = not (float(substeps) >= 1 and float(substeps).is_integer())  # also NaN, inf, 1.5
        if bad_dt or bad_sub:
            raise ValueError("; ".join(m for m in (
                f"Simulator dt: got {dt}; expected a finite step > 0 [s]" if bad_dt else "",
                f"Simulator substeps: got {substeps}; expected a whole number >= 1" if bad_sub else "") if m))
        self.dt = float(dt)
        self.substeps = int(substeps)
        self.dt_sub = self.dt / self.substeps
        self.magnet_every_substep = bool(magnet_every_substep)
        self.settings = SubstepSettings(
            dt=self.dt_sub, newton=int(newton), newton_tol=float(newton_tol),
            chord=solver == "band" if chord is None else bool(chord), slip_speed=float(slip_speed),
            strain_limit=float(strain_limit), speed_limit=float(speed_limit), fold_tolerance=float(fold_tolerance))
        """The substep's settings, as the solver takes them."""
        self.use_graph = (model.device.is_cuda or cpu_graphs_supported()) if use_graph is None else bool(use_graph)
        self.control = model.control()
        """The default inputs (the params' EPM path, anchors at rest): ``step`` uses it unless given another."""
        self.solver = make_solver(solver, model, self.settings)
        """The substep solver (:class:`~warpworm.sim.solver.SolverBase`), owner of its scratch."""
        W, dev = model.num_worlds, model.device
        # the magnet pairs' wrenches between the wrench's two launches: allocated here, before any graph capture
        M = model.magnet_shape.shape[1]  # EPM and the three IPMs
        self._pair_scratch = pair_wrench_scratch(W, M, dev)
        self._snapshot_wrench = (wp.zeros((W, M), dtype=wp.vec3, device=dev),
                                 wp.zeros((W, M), dtype=wp.vec3, device=dev))
        self._last_moment = model.magnet_moment
        self._graphs = {}

    @property
    def newton(self) -> int:
        """Newton steps per substep at most."""
        return self.settings.newton

    def newton_stats(self, reset: bool = False) -> dict:
        """The solver's Newton counters per world (:meth:`~warpworm.sim.solver.SolverBase.newton_stats`)."""
        return self.solver.newton_stats(reset)

    # ------------------------------------------------------------------------------------------------------------
    def initial_state(self) -> State:
        """Every world at its rest shape on its floor, at rest, t = 0, magnet poses evaluated."""
        state = self.model.state()
        self._magnet_poses(state, self.control)
        return state

    @property
    def launches_per_substep(self) -> float:
        """Kernel launches per substep: per step 5 for the magnets (EPM pose, IPM poses, wrench, zero f_ext,
        distribution), plus 1 per step for the substeps."""
        per_step = 5  # epm pose, ipm poses, wrench, zero f_ext, distribute
        if self.magnet_every_substep:
            return 1.0 + per_step
        return (1.0 + per_step) / self.substeps

    # ------------------------------------------------------------------------------------------------------------
    def _magnet_poses(self, state: State, control: Control) -> None:
        m, k = self.model, magnet_pose  # k: the pose kernels
        W = m.num_worlds
        if control.path.kind == "sine":
            wp.launch(k.epm_sine_pose, dim=W, inputs=[control.sine, self.dt_sub, state.step_count],
                      outputs=[state.magnet_pos, state.magnet_rot], device=m.device)
        else:
            wp.launch(k.epm_keyframe_pose, dim=W, inputs=[control.keyframes, self.dt_sub, state.step_count],
                      outputs=[state.magnet_pos, state.magnet_rot], device=m.device)
        wp.launch(k.ipm_poses, dim=(W, 3), inputs=[m.mount_vertices, m.mount_local_pos, m.mount_local_rot,
                                                    state.positions],
                  outputs=[state.magnet_pos, state.magnet_rot], device=m.device)

    def update_magnets(self, state: State, control: Control | None = None, *, epm: bool = True) -> State:
        """Evaluate the magnet poses at the current time and positions, the net magnetic wrench on every magnet and
        its distribution onto the mount vertices (``state.external_force``), as the first substep of a step does."""
        self._wrench(state, control or self.control, self.model.magnet_moment if epm else
                     self.model.magnet_moment_parked)
        return state

    def _wrench(self, state: State, control: Control, moment: wp.array) -> None:
        m = self.model
        self._magnet_poses(state, control)
        model_wrenches(m, state, moment, epm_wrench=False, pair_scratch=self._pair_scratch, skip_stopped=True)
        state.external_force.zero_()
        wp.launch(magnet_pose.distribute_wrench, dim=(m.num_worlds, 3),
                  inputs=[m.mount_vertices, state.positions, state.magnet_pos, state.magnet_force,
                          state.magnet_torque],
                  outputs=[state.external_force], device=m.device)

    def run_substeps(self, state: State, num_substeps: int, control: Control | None = None) -> State:
        """Advance every world by ``num_substeps`` solver substeps under the magnetic force already in
        ``state.external_force`` (no wrench or pose update: for checks of the solver alone)."""
        self.solver.step(state, int(num_substeps), control or self.control)
        return state

    def _one_step(self, state: State, control: Control, moment: wp.array) -> None:
        if self.magnet_every_substep:
            cmd = self.solver.command(state, 1, control)
            for _ in range(self.substeps):
                self._wrench(state, control, moment)
                cmd.launch()
        else:
            self._wrench(state, control, moment)
            self.solver.command(state, self.substeps, control).launch()

    # ------------------------------------------------------------------------------------------------------------
    def step(self, state: State, num_steps: int = 1, control: Control | None = None, *, epm: bool = True) -> State:
        """Advance every world by ``num_steps`` steps of ``dt`` (in place; returns ``state``) under ``control``
        (default :attr:`control`).

        ``epm=False`` runs with the EPM absent (its moment zeroed), as :meth:`settle` does.
        """
        control = control or self.control
        moment = self.model.magnet_moment if epm else self.model.magnet_moment_parked
        self._last_moment = moment
        if self.use_graph:
            key = (id(state), id(control), epm)
            g = self._graphs.get(key)
            n = int(num_steps)
            if n > 0 and (g is None or g[0] is not state or g[1] is not control or g[3] != control.revision):
                # the first step of a new graph runs as plain launches, so that whatever a first launch creates
                # lazily (a Warp module, the wrench's quadrature arrays, a tile solver's scratch) exists before the
                # capture: inside a capture, an array made from host data has its copy recorded, not done
                self._one_step(state, control, moment)
                n -= 1
                try:
                    with capture_gate.capturing(), wp.ScopedCapture(device=self.model.device) as capture:
                        self._one_step(state, control, moment)
                except Exception:  # a Warp that cannot capture on this device: plain launches from now on
                    if self.model.device.is_cuda:
                        raise
                    self.use_graph = False
                    return self.step(state, n, control, epm=epm)
                # the graph keeps the recorded substep command it replays alive, whatever the solver drops
                g = (state, control, capture.graph, control.revision,
                     self.solver.command(state, 1 if self.magnet_every_substep else self.substeps, control))
                put_bounded(self._graphs, key, g, MAX_GRAPHS)
            with capture_gate.released():  # a replay touches no capture state: others may launch or capture meanwhile
                for _ in range(n):
                    wp.capture_launch(g[2])
            return state
        for _ in range(int(num_steps)):
            self._one_step(state, control, moment)
        return state

    def retire(self, state: State, worlds) -> None:
        """Stop stepping the worlds where ``worlds`` ((W,) bool) is true: the substeps skip them from now on, as they
        skip an unstable world, and their state stays as it is (status ``WORLD_RETIRED``; an unstable world keeps
        its flag). Worlds are independent, so the others' trajectories are unchanged, bit for bit; a batch whose
        worlds want frames at different times stops paying for each world after its last one."""
        mask = np.asarray(worlds, dtype=bool)
        if mask.shape != state.unstable.shape:
            raise ValueError(f"retire: worlds has shape {mask.shape}; expected one bool per world, "
                             f"{state.unstable.shape}")
        if not mask.any():  # (called once per frame step: nothing to launch when no world finishes there)
            return
        wp.launch(world_status.retire_worlds, dim=mask.shape[0], device=self.model.device,
                  inputs=[wp.array(mask.astype(np.int32), dtype=wp.int32, device=self.model.device)],
                  outputs=[state.unstable])

    def settle(self, state: State, duration: float = 0.3, *, reset_time: bool = True) -> State:
        """Let every world settle under gravity with the EPM absent (parked far away) for ``duration`` [s].

        With ``reset_time`` the clock (and so the EPM path) restarts at t = 0 afterwards and velocities are zeroed,
        so a gait starts from a settled worm.
        """
        self.step(state, int(round(duration / self.dt)), epm=False)
        if reset_time:
            state.step_count.zero_()
            state.velocities.zero_()
        self._magnet_poses(state, self.control)
        return state

    def run(self, state: State, frame_times, control: Control | None = None, *, epm: bool = True, keys=None,
            stack: bool = False):
        """The run loop: step from the current time to each of ``frame_times`` and take a :meth:`snapshot` there.

        Args:
            state: advanced in place.
            frame_times: times [s] measured from the current time (after :meth:`settle`, the gait clock), non-
                decreasing and >= 0; each is rounded to a whole number of steps of ``dt``. A time of 0 snapshots the
                current state.
            control: the inputs (default :attr:`control`).
            epm: the EPM present (False: parked, as while settling).
            keys: snapshot keys to keep (default: all; fewer saves host memory on long recordings).
            stack: return one dict of arrays stacked over frames, shape (S, ...), instead of a list of S dicts.

        Every frame also carries ``clock`` [s]: the host's time of the frame (an unstable world's own ``time``
        stops when it freezes; the clock does not).
        """
        steps = np.rint(np.asarray(frame_times, np.float64).reshape(-1) / self.dt).astype(np.int64)
        if steps.size and (steps[0] < 0 or np.any(np.diff(steps) < 0)):
            raise ValueError(f"frame_times must be non-decreasing and >= 0 [s], got {list(frame_times)}")
        frames, done = [], 0
        for n in steps:
            if n > done:
                self.step(state, int(n - done), control, epm=epm)
                done = int(n)
            snap = self.snapshot(state, control)
            if keys is not None:
                snap = {k: snap[k] for k in keys}
            snap["clock"] = done * self.dt
            frames.append(snap)
        if stack:
            return {k: np.stack([f[k] for f in frames]) for k in frames[0]} if frames else {}
        return frames

    # ------------------------------------------------------------------------------------------------------------
    def snapshot(self, state: State, control: Control | None = None) -> dict:
        """Host copies (NumPy) of the state.

        Returns ``positions (W, V, 3)``, ``velocities (W, V, 3)`` [m, m/s]; ``magnet_pos (W, 4, 3)`` [m],
        ``magnet_rot (W, 4, 3, 3)`` (magnet -> world; slots EPM, tail, centre, head); ``magnet_force``,
        ``magnet_torque (W, 4, 3)`` [N, N·m] (net magnetic wrench on each magnet at these poses, the EPM's too); ``crease_angle (W, H)`` [rad]; ``bar_strain (W, E)``;
        ``anchor_force (W, A, 3)`` [N]: the force each anchor applies, the pull of the worm on it (force plate);
        ``contact (W, V)`` bool; ``unstable (W,)`` bool (exploded or crumpled; a world :meth:`retire` stopped is
        not); ``crumpled (W,)`` bool (a crease folded through its range by more than ``fold_tolerance``); ``time
        (W,)`` [s].
        """
        m = self.model
        control = control or self.control
        self._magnet_poses(state, control)  # poses at the current time (the wrench kept the step's starting ones)
        # the whole wrench at these poses, the EPM's included (the dynamics skips it), with the magnets of the last
        # step (the EPM parked after settle)
        f_snap, t_snap = self._snapshot_wrench
        model_wrenches(m, state, self._last_moment, force_out=f_snap, torque_out=t_snap,
                              pair_scratch=self._pair_scratch)
        # .numpy() aliases device memory on the CPU: copy, so a snapshot never changes after it is taken
        x = state.positions.numpy().copy()
        q = state.magnet_rot.numpy()
        A = m.num_anchors
        if A:
            av = m.anchor_vertex.numpy()
            ak = np.broadcast_to(m.anchor_stiffness.numpy(), (m.num_worlds, A))
            anchor_force = ak[..., None] * (x[:, av] - control.anchor_target.numpy())
        else:
            anchor_force = np.zeros((m.num_worlds, 0, 3), np.float32)
        status = state.unstable.numpy()
        return {
            "positions": x,
            "velocities": state.velocities.numpy().copy(),
            "magnet_pos": state.magnet_pos.numpy().copy(),
            "magnet_rot": quat_wxyz_to_matrix(quat_xyzw_to_wxyz(q)).astype(np.float32),
            "magnet_force": f_snap.numpy().copy(),
            "magnet_torque": t_snap.numpy().copy(),
            "crease_angle": state.crease_angle.numpy().copy(),
            "bar_strain": state.bar_strain.numpy().copy(),
            "anchor_force": anchor_force.astype(np.float32),
            "contact": state.contact.numpy().astype(bool),
            "unstable": (status == WORLD_EXPLODED) | (status == WORLD_CRUMPLED),
            "crumpled": status == WORLD_CRUMPLED,
            "time": (state.step_count.numpy().astype(np.float64) * self.dt_sub),
        }

    def set_anchor_targets(self, targets) -> None:
        """Set the default control's anchor targets [m], shape (A, 3) (all worlds) or (W, A, 3)."""
        self.control.set_anchor_targets(targets)

    def set_path(self, path) -> None:
        """Set the default control's EPM path (:class:`warpworm.physics.gaits.EpmPath`); takes effect at the next step."""
        self.control.set_path(path)
