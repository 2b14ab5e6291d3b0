"""The banded layout of the implicit-Euler substep: one thread per world, elements added whole, chord Newton steps.

:func:`implicit_step` is launched over worlds (``world = wp.tid()``); each thread runs its world's substeps with the
physics of :mod:`.substep` (adders called with ``ALL_ROWS``, per-vertex phases with stride 1; the hinges
:data:`~.hinge_lanes.LANES` at a time, :mod:`.hinge_lanes`, the same numbers) and solves each Newton system with the
block-banded Cholesky of :mod:`.banded_cholesky`. With ``refactor`` 0 (the default) only the first step
of every other substep, and a step after a contact changed, assembles and factors; the others are chord steps on the
last factor, taken only if they at least halve the last step, and ending a substep only with the error estimate
θ/(1 − θ)·step below :data:`STOP_ERROR` times the tolerance (docs/dynamics.md, "Newton convergence").
"""

from __future__ import annotations

import warp as wp

from .banded_cholesky import ALL_ROWS, banded_cholesky_factor, banded_cholesky_solve
from .common import freeze_world
from .hinge_lanes import add_hinges, update_hinge_angles_lanes
from .substep import (CONTACTS_LANDED, WORLD_CRUMPLED, BarHingeModel, BarHingeState, NewtonScratch, SubstepOptions,
                      WorldCoefficients, add_anchors, add_bar, apply_step, finish_vertices, friction_row, inertia_row,
                      predict, project_row, project_rhs, update_contacts, world_coefficients)

wp.set_module_options({"enable_backward": False})

CHORD_CONTRACTION = wp.constant(0.5)  # a chord step is taken only if it is shorter than this times the last step
STOP_ERROR = wp.constant(0.1)  # a chord step ends a substep only if θ/(1 − θ)·step is below this times the tolerance


@wp.func
def elastic_terms(world: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                  anchor_target: wp.array2d(dtype=wp.vec3), with_hessian: bool, s: BarHingeState,
                  w: NewtonScratch) -> int:
    """Inertia, bars, hinges and anchors into ``grad`` (and the unprojected banded matrix): all but the friction, which is
    tangential and so not in the floor's normal balance that the contact update reads. Returns 1 if a bar is
    strained beyond its limit (or non-finite)."""
    for i in range(s.x.shape[1]):
        inertia_row(world, i, c, m, with_hessian, w)
    for e in range(m.edges.shape[0]):
        if add_bar(world, e, ALL_ROWS, c, m, opt, with_hessian, s, w) != 0:
            return 1
    add_hinges(world, c, m, with_hessian, s, w)  # 8 at a time in SIMD lanes on the CPU, the same numbers
    add_anchors(world, ALL_ROWS, c, m, anchor_target, with_hessian, s, w)
    return 0


@wp.func
def friction_terms(world: int, c: WorldCoefficients, slip_speed: float, with_hessian: bool, s: BarHingeState,
                   w: NewtonScratch):
    """Every vertex's :func:`~.substep.friction_row`."""
    for i in range(s.x.shape[1]):
        friction_row(world, i, c, slip_speed, with_hessian, s, w)


@wp.func
def project_on_contacts(world: int, c: WorldCoefficients, m: BarHingeModel, s: BarHingeState, w: NewtonScratch):
    """Every row's :func:`~.substep.project_row`."""
    for u in range(s.x.shape[1]):
        project_row(world, u, c, m, s, w)


@wp.func
def assemble(world: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
             anchor_target: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch) -> int:
    """The whole Newton system: gradient and Gauss–Newton banded matrix, friction included, projected on the contacts.
    Returns 1 if a bar is strained beyond its limit."""
    if elastic_terms(world, c, m, opt, anchor_target, True, s, w) != 0:
        return 1
    friction_terms(world, c, opt.slip_speed, True, s, w)
    project_on_contacts(world, c, m, s, w)
    return 0


@wp.func
def newton_solve(world: int, c: WorldCoefficients, factor: bool, s: BarHingeState, w: NewtonScratch) -> float:
    """Solve H dx = −grad on the allowed directions, leaving −dx in ``w.grad``; ``factor`` the fresh H first, else
    reuse the factor in ``w.hess`` (a chord step). Returns max |dx| [m] (1e30 for a non-finite step)."""
    nv = s.x.shape[1]
    bw = w.hess.shape[2] - 1
    for i in range(nv):
        project_rhs(world, i, c, s, w)
    if factor:
        banded_cholesky_factor(world, nv, bw, w.hess)
    banded_cholesky_solve(world, nv, bw, w.hess, w.grad)
    step = float(0.0)
    for i in range(nv):
        length = wp.length(w.grad[world, i])
        if not (length < 1.0e30):
            length = 1.0e30  # a non-finite step is no convergence (wp.max would drop a NaN)
        step = wp.max(step, length)
    return step


@wp.func
def newton_system(world: int, it: int, fresh: bool, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                  anchor_target: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch):
    """The system of Newton step ``it`` (``fresh``: with a new Hessian); after the first step one assembly serves
    both the contact update and the step, friction added after it. A landing (x moved) or, for a chord step, a
    changed contact assembles anew. Returns (bad, fresh)."""
    if it == 0:
        if fresh:
            return assemble(world, c, m, opt, anchor_target, s, w), fresh
        bad = elastic_terms(world, c, m, opt, anchor_target, False, s, w)
        if bad == 0:
            friction_terms(world, c, opt.slip_speed, False, s, w)
        return bad, fresh
    if elastic_terms(world, c, m, opt, anchor_target, fresh, s, w) != 0:
        return 1, fresh
    change = update_contacts(world, 0, 1, c, m, opt.slip_speed, s, w)
    if change == CONTACTS_LANDED or (change != 0 and not fresh):
        return assemble(world, c, m, opt, anchor_target, s, w), True
    friction_terms(world, c, opt.slip_speed, fresh, s, w)
    if fresh:
        project_on_contacts(world, c, m, s, w)
    return 0, fresh


@wp.func
def newton_iterations(world: int, have_factor: bool, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                      anchor_target: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch):
    """One substep's Newton steps, the first on the factor the last substep left if ``have_factor``. A chord step
    that would not halve the last step is not taken (the next refactors at this x). Returns (bad, converged,
    carried: this substep made a factor the next may start on)."""
    carried = bool(False)
    bad = int(0)
    last_step = float(1.0e30)
    stalled = bool(False)
    converged = bool(False)
    for it in range(opt.newton):
        fresh = (it == 0 and not have_factor) or opt.refactor != 0 or stalled
        bad, fresh = newton_system(world, it, fresh, c, m, opt, anchor_target, s, w)
        if bad != 0:
            break
        w.newton_steps[world] = w.newton_steps[world] + 1
        if fresh:
            w.newton_factors[world] = w.newton_factors[world] + 1
        step = newton_solve(world, c, fresh, s, w)
        if fresh:
            carried = opt.refactor == 0 and not have_factor
        if not fresh and not (step < CHORD_CONTRACTION * last_step):
            stalled = True
            continue
        for i in range(s.x.shape[1]):
            apply_step(world, i, -w.grad[world, i], s, w)
        # converged: after one contact update at least; after a chord step only with its error estimate small
        theta = step / last_step
        if it >= 1 and step < opt.newton_tol and (
                fresh or step * theta < STOP_ERROR * opt.newton_tol * (1.0 - theta)):
            converged = True
            break
        stalled = False
        last_step = step
    return bad, converged, carried


@wp.kernel
def implicit_step(m: BarHingeModel, opt: SubstepOptions, f_ext: wp.array2d(dtype=wp.vec3),
                  anchor_target: wp.array2d(dtype=wp.vec3), s: BarHingeState, w: NewtonScratch):
    """``opt.num_substeps`` substeps of length ``opt.dt`` [s] of one world. Launch dim (W,). ``f_ext (W, V)`` the
    step's magnetic force [N]; ``anchor_target (W, A)`` [m]. A world flagged unstable is frozen from then on. The
    factor the last substep made serves the next substep's first step if no contact changed status since (within a
    launch only: a launch's result never depends on what ran before it)."""
    world = wp.tid()
    if s.unstable[world] != 0:
        return
    c = world_coefficients(m, world, opt.dt)
    carried = bool(False)
    for sub in range(opt.num_substeps):
        statuses_changed = predict(world, 0, 1, c, m, opt.slip_speed, f_ext, s, w)
        bad, converged, carried = newton_iterations(world, carried and statuses_changed == 0, c, m, opt,
                                                    anchor_target, s, w)
        if bad == 0 and not converged:
            w.newton_capped[world] = w.newton_capped[world] + 1  # the cap, not the tolerance, ended it
        if bad == 0:
            bad, statuses_changed = finish_vertices(world, 0, 1, c, m, opt, s, w)
            if statuses_changed != 0:
                carried = False  # the factor's projection is another contact set's
            crumpled = update_hinge_angles_lanes(world, m, opt.fold_tolerance, s)
            if bad == 0 and crumpled != 0:
                freeze_world(world, s.x.shape[1], s.x, s.v, w.x_prev, w.delta, s.unstable)
                s.unstable[world] = WORLD_CRUMPLED
                return
        if bad != 0:
            freeze_world(world, s.x.shape[1], s.x, s.v, w.x_prev, w.delta, s.unstable)
            return
        s.step_count[world] = s.step_count[world] + 1
