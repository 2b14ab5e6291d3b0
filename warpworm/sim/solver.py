"""The substep solvers behind :class:`~warpworm.sim.simulator.Simulator`: one interface, two launch layouts.

As Newton's ``SolverBase``: a solver is built for a :class:`~warpworm.sim.model.Model` and its
:class:`SubstepSettings`, owns its scratch, and ``step(state, num_substeps, control)`` advances every world in place
(one launch; ``command`` returns it recorded, for graph capture). :class:`BandedSolver` launches
:func:`warpworm.kernels.implicit_euler.implicit_step` (one thread per world);
:class:`warpworm.sim.tile_solver.TileSolver` the block-per-world kernel of :mod:`warpworm.kernels.implicit_tile`.
Both run the physics of :mod:`warpworm.kernels.substep`. Nothing loops over worlds on the host.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import warp as wp

from warpworm.kernels import implicit_euler, substep
from warpworm.physics import crease

MAX_COMMANDS = 8
"""Recorded launches a solver keeps (one per (state, control, substep count), the oldest dropped first): each pins
its state's arrays. A captured graph keeps the command it replays alive whatever the solver drops."""


def put_bounded(cache: dict, key, value, limit: int) -> None:
    """``cache[key] = value`` as the newest entry, dropping the oldest while more than ``limit`` would remain."""
    cache.pop(key, None)
    while len(cache) >= limit:
        cache.pop(next(iter(cache)))  # dicts keep insertion order
    cache[key] = value


@dataclass(frozen=True)
class SubstepSettings:
    """How a solver takes a substep (the :class:`~warpworm.sim.simulator.Simulator` arguments of the same names)."""

    dt: float
    """Substep [s]."""
    newton: int = 24
    """Newton steps per substep at most (>= 2: the contacts are updated between Newton steps)."""
    newton_tol: float = 1.0e-4
    """[m/s] a Newton step (the second or later) changing no vertex's velocity by more than this ends the substep."""
    chord: bool = False
    """Chord Newton steps (banded layout only)."""
    slip_speed: float = 1.0e-5
    """Static friction's regularisation speed ε [m/s]."""
    strain_limit: float = 0.5
    """|ΔL/L0| beyond which a bar flags its world unstable (waist bars: at least 0.9)."""
    speed_limit: float = 20.0
    """[m/s] a vertex faster (or non-finite) flags its world unstable."""
    fold_tolerance: float = float(np.radians(5.0))
    """[rad] a hinge this far outside its NoFoldThrough range: the world crumpled."""

    def __post_init__(self):
        if not self.dt > 0:
            raise ValueError(f"dt: the substep must be > 0 [s], got {self.dt}")
        if int(self.newton) < 2:
            raise ValueError(f"newton must be >= 2 (the contacts are updated between Newton steps), got {self.newton}")
        if not self.newton_tol >= 0:
            raise ValueError(f"newton_tol must be >= 0 [m/s], got {self.newton_tol}")
        if not self.slip_speed > 0:
            raise ValueError(f"slip_speed must be > 0 [m/s], got {self.slip_speed}")


def model_struct(model) -> substep.BarHingeModel:
    """The kernels' view of ``model``: every :class:`~warpworm.kernels.substep.BarHingeModel` field is the model's
    array of the same name."""
    out = substep.BarHingeModel()
    for name in substep.BarHingeModel.vars:
        setattr(out, name, getattr(model, name))
    return out


def state_struct(state) -> substep.BarHingeState:
    """The kernels' view of a :class:`~warpworm.sim.model.State`."""
    out = substep.BarHingeState()
    out.x, out.v = state.positions, state.velocities
    for name in ("floor_force", "bar_strain", "crease_angle", "contact", "unstable", "step_count"):
        setattr(out, name, getattr(state, name))
    return out


class SolverBase:
    """A substep solver for every world of ``model``: ``step(state, num_substeps, control)``."""

    def __init__(self, model, settings: SubstepSettings):
        self.model = model
        self.settings = settings
        W, V, dev = model.num_worlds, model.num_vertices, model.device
        waist = model.pattern.edge_label == crease.VALLEY
        self.strain_limit = wp.array(np.where(waist, max(settings.strain_limit, 0.9), settings.strain_limit)
                                     .astype(np.float32), dtype=float, device=dev)
        """|strain| beyond which a bar flags its world unstable, shape (E,), float."""
        self.model_arrays = model_struct(model)
        self.scratch = substep.NewtonScratch()
        """Scratch shared by every state this solver steps (nothing in it outlives a launch; ``delta`` is zero
        between launches): x_prev, delta, grad (W, V) vec3, hess (W, V, B + 1) mat33, released (W, V) int32, and
        the Newton counters (W,) int32."""
        s = self.scratch
        s.x_prev, s.delta, s.grad = (wp.zeros((W, V), dtype=wp.vec3, device=dev) for _ in range(3))
        s.hess = wp.zeros((W, V, model.half_bandwidth + 1), dtype=wp.mat33, device=dev)
        s.released = wp.zeros((W, V), dtype=wp.int32, device=dev)
        s.newton_steps, s.newton_capped, s.newton_factors = (wp.zeros(W, dtype=wp.int32, device=dev)
                                                             for _ in range(3))
        self._cmds = {}

    def options(self, num_substeps: int) -> substep.SubstepOptions:
        """The kernels' settings for a launch of ``num_substeps`` substeps."""
        st, o = self.settings, substep.SubstepOptions()
        o.dt, o.num_substeps, o.newton = st.dt, int(num_substeps), int(st.newton)
        o.refactor = 0 if st.chord else 1
        o.newton_tol = st.newton_tol * st.dt
        o.slip_speed, o.strain_limit = st.slip_speed, self.strain_limit
        o.speed_limit, o.fold_tolerance = st.speed_limit, st.fold_tolerance
        return o

    def _record(self, state, control, num_substeps: int):
        """The launch of ``num_substeps`` substeps, recorded (``record_cmd=True``)."""
        raise NotImplementedError

    def command(self, state, num_substeps: int, control):
        """The recorded launch of ``num_substeps`` substeps of every world of ``state`` under ``control``, to
        ``.launch()`` or capture in a graph; recorded once per (state, count, control)."""
        if int(num_substeps) < 1:
            raise ValueError(f"num_substeps: expected >= 1, got {num_substeps}")
        key = (id(state), id(control), int(num_substeps))
        cmd = self._cmds.get(key)
        if cmd is not None and cmd[0] is state and cmd[1] is control:
            return cmd[2]
        c = self._record(state, control, int(num_substeps))
        put_bounded(self._cmds, key, (state, control, c), MAX_COMMANDS)
        return c

    def step(self, state, num_substeps: int, control):
        """Advance every world of ``state`` by ``num_substeps`` substeps under ``control`` (in place; returns it),
        the magnetic force in ``state.external_force`` held. The argument order of
        :meth:`warpworm.sim.simulator.Simulator.step` (state, count, control)."""
        self.command(state, num_substeps, control).launch()
        return state

    def newton_stats(self, reset: bool = False) -> dict:
        """Per world since built (or the last reset), shape (W,) int64 each: ``steps`` (Newton steps summed over
        substeps), ``factors`` (those that assembled and factored the Hessian; the rest were chord steps) and
        ``capped`` (substeps that took all ``newton`` steps without meeting the tolerance)."""
        s = self.scratch
        out = {"steps": s.newton_steps.numpy().astype(np.int64),
               "factors": s.newton_factors.numpy().astype(np.int64),
               "capped": s.newton_capped.numpy().astype(np.int64)}
        if reset:
            for a in (s.newton_steps, s.newton_factors, s.newton_capped):
                a.zero_()
        return out


class BandedSolver(SolverBase):
    """One thread per world, block-banded Cholesky, chord steps if ``settings.chord``
    (:func:`warpworm.kernels.implicit_euler.implicit_step`)."""

    def _record(self, state, control, num_substeps: int):
        return wp.launch(implicit_euler.implicit_step, dim=self.model.num_worlds,
                         inputs=[self.model_arrays, self.options(num_substeps), state.external_force,
                                 control.anchor_target, state_struct(state), self.scratch],
                         device=self.model.device, record_cmd=True)
