"""The tile layout of the implicit-Euler substep: one block of threads per world, one Newton row per thread.

The physics is :mod:`.substep`'s, called with a vertex as ``row`` (thread ``lane`` gathers the bars and hinges
incident on its vertices u = lane, lane + T, ... from host-built incidence lists, ascending element index) and with
(lane, T) as the per-vertex stride, so every block of the Newton system gets the banded layout's contributions in the
banded layout's order: the systems are :func:`.implicit_euler.implicit_step`'s bit for bit. Launched with
``wp.launch_tiled(kernel, dim=W, block_dim=T)``; full Newton steps (no chord steps). The solve:

- ``dense``: the banded matrix scattered into a 3V × 3V float32 tile in shared memory (``wp.tile_scatter_masked``, one entry
  per thread per call), ``wp.tile_cholesky_inplace`` / ``wp.tile_cholesky_solve_inplace`` (cuSolverDx where Warp has
  libmathdx). Zeroed once per launch: the in-place factor keeps each row's envelope, inside the banded part. The factor
  rounds differently from the banded layout's;
- band: the block band factored in place column-parallel (:func:`block_banded_cholesky_factor`, the banded layout's
  arithmetic, so bit for bit its result), solved by thread 0; ~no shared memory, one warp per world.

:func:`block_max` is the block barrier and makes a flag the whole block's, so every thread takes the same branches
and calls the same tile operations the same number of times (a barrier in divergent code hangs a GPU block; in
Warp 1.19 a shared tile's element assignment is one, hence ``tile_scatter_masked``). The tile's side 3V is a
compile-time constant: :func:`make_tile_substep_kernel` builds one module per shape.
"""

from __future__ import annotations

import functools

import warp as wp

from .banded_cholesky import banded_cholesky_solve, inverse_lower_cholesky3
from .common import freeze_world
from .substep import (CONTACTS_LANDED, WORLD_CRUMPLED, BarHingeModel, BarHingeState, NewtonScratch, SubstepOptions,
                      WorldCoefficients, add_anchors, add_bar, add_hinge, apply_step, finish_vertices, friction_row,
                      inertia_row, predict, project_rhs, project_row, update_contacts, update_hinge_angles,
                      world_coefficients)

wp.set_module_options({"enable_backward": False})

FLAG_CRUMPLED = wp.constant(1)  # block flag codes, ordered so the block maximum is the worst
FLAG_EXPLODED = wp.constant(2)


@wp.struct
class VertexIncidence:
    """Vertex -> incident bars and hinges, CSR, element indices ascending: ``bar[bar_start[u]:bar_start[u + 1]]``."""

    bar_start: wp.array(dtype=wp.int32)  # (V + 1,)
    bar: wp.array(dtype=wp.int32)  # (2E,)
    hinge_start: wp.array(dtype=wp.int32)  # (V + 1,)
    hinge: wp.array(dtype=wp.int32)  # (4H,)


@wp.func
def block_max(flag: int) -> int:
    """The largest ``flag`` of the block's threads, returned to every thread: a cooperative tile reduction, so also
    a block barrier (every write before it is seen by every thread after it). Every thread must call it."""
    t = wp.tile(flag)
    m = wp.tile_max(t)
    return m[0]


@wp.func
def assemble_row(world: int, u: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                 anchor_target: wp.array2d(dtype=wp.vec3), inc: VertexIncidence, s: BarHingeState,
                 w: NewtonScratch) -> int:
    """Vertex ``u``'s row of the gradient and of the lower block-banded part, friction excepted; writes only that row, so
    rows need no atomics. Reads every vertex's x: call it after a barrier. Returns 1 for an over-strained bar."""
    inertia_row(world, u, c, m, True, w)
    for q in range(inc.bar_start[u], inc.bar_start[u + 1]):
        if add_bar(world, inc.bar[q], u, c, m, opt, True, s, w) != 0:
            return 1
    for q in range(inc.hinge_start[u], inc.hinge_start[u + 1]):
        add_hinge(world, inc.hinge[q], u, c, m, True, s, w)
    add_anchors(world, u, c, m, anchor_target, True, s, w)
    return 0


@wp.func
def assemble_rows(world: int, lane: int, bd: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                  anchor_target: wp.array2d(dtype=wp.vec3), inc: VertexIncidence, s: BarHingeState,
                  w: NewtonScratch) -> int:
    """:func:`assemble_row` of this thread's rows; the block's flag (and barrier)."""
    flag = int(0)
    for u in range(lane, s.x.shape[1], bd):
        if assemble_row(world, u, c, m, opt, anchor_target, inc, s, w) != 0:
            flag = 1
    return block_max(flag)


@wp.func
def newton_system(world: int, lane: int, bd: int, it: int, c: WorldCoefficients, m: BarHingeModel,
                  opt: SubstepOptions, anchor_target: wp.array2d(dtype=wp.vec3), inc: VertexIncidence,
                  s: BarHingeState, w: NewtonScratch) -> int:
    """The system of Newton step ``it``, in the banded layout's order: the rows without friction, the contact update
    (after the first step), anew if a vertex landed, then each row's friction and projection. Returns the block's
    bad flag."""
    bad = assemble_rows(world, lane, bd, c, m, opt, anchor_target, inc, s, w)
    if bad != 0:
        return bad
    if it >= 1:
        change = block_max(update_contacts(world, lane, bd, c, m, opt.slip_speed, s, w))
        if change == CONTACTS_LANDED:
            bad = assemble_rows(world, lane, bd, c, m, opt, anchor_target, inc, s, w)
            if bad != 0:
                return bad
    for u in range(lane, s.x.shape[1], bd):
        friction_row(world, u, c, opt.slip_speed, True, s, w)
        project_row(world, u, c, m, s, w)
        project_rhs(world, u, c, s, w)
    return block_max(0)  # barrier: every row finished before the solve reads it


@wp.func
def block_banded_cholesky_factor(world: int, lane: int, bd: int, nv: int, bw: int, mat: wp.array3d(dtype=wp.mat33)):
    """:func:`~.banded_cholesky.banded_cholesky_factor` column-parallel over the block's ``bd`` threads, entry by entry
    its arithmetic (so bit for bit its factor): per column, thread 0 the diagonal block, a barrier, the ≤ B blocks
    below it one row per thread. Every thread must call it."""
    for j in range(nv):
        if lane == 0:
            s = mat[world, j, 0]
            for k in range(wp.max(0, j - bw), j):
                l = mat[world, j, j - k]
                s = s - l * wp.transpose(l)
            mat[world, j, 0] = inverse_lower_cholesky3(s)
        block_max(0)  # the diagonal's inverse before the rows below read it
        for i in range(j + 1 + lane, wp.min(nv, j + bw + 1), bd):
            inv_t = wp.transpose(mat[world, j, 0])
            t = mat[world, i, i - j]
            for k in range(wp.max(0, i - bw), j):
                t = t - mat[world, i, i - k] * wp.transpose(mat[world, j, j - k])
            mat[world, i, i - j] = t * inv_t
    block_max(0)  # the last column before anyone reads the factor


@wp.func
def banded_solve_and_apply(world: int, lane: int, bd: int, bw: int, tol: float, s: BarHingeState,
                         w: NewtonScratch) -> int:
    """Factor and solve the banded matrix in place and take the step. Returns 1 if this thread's vertices moved ``tol`` or
    more (or non-finitely)."""
    nv = s.x.shape[1]
    block_banded_cholesky_factor(world, lane, bd, nv, bw, w.hess)
    if lane == 0:
        banded_cholesky_solve(world, nv, bw, w.hess, w.grad)
    block_max(0)  # barrier: the step solved before every thread reads its rows
    moving = int(0)
    for i in range(lane, nv, bd):
        dx = -w.grad[world, i]
        apply_step(world, i, dx, s, w)
        if not (wp.length(dx) < tol):
            moving = 1
    return moving


@wp.func
def banded_entry(world: int, q: int, bw: int, slots: int, hess: wp.array3d(dtype=wp.mat33)):
    """Slot ``q`` of the lower block-banded part as a dense-matrix entry: (row, col, value, ok); block (u, u − d) entry
    (a, b); the diagonal blocks' upper entries are skipped (the factorisation reads the lower triangle only)."""
    u = q // (9 * (bw + 1))
    rem = q - u * 9 * (bw + 1)
    d = rem // 9
    a = (rem - d * 9) // 3
    b = rem - d * 9 - a * 3
    vv = u - d
    ok = q < slots and vv >= 0 and (d > 0 or b <= a)
    row = int(0)
    col = int(0)
    val = float(0.0)
    if ok:
        row = 3 * u + a
        col = 3 * vv + b
        val = hess[world, u, d][a, b]
    return row, col, val, ok


@wp.func
def rhs_entry(world: int, q: int, n: int, grad: wp.array2d(dtype=wp.vec3)):
    """Entry ``q`` of the right-hand side: (index, value, ok)."""
    ok = q < n
    val = float(0.0)
    idx = int(0)
    if ok:
        idx = q
        val = grad[world, q // 3][q - (q // 3) * 3]
    return idx, val, ok


@wp.func
def finish_substep(world: int, lane: int, bd: int, c: WorldCoefficients, m: BarHingeModel, opt: SubstepOptions,
                   s: BarHingeState, w: NewtonScratch) -> int:
    """Velocities, the floor once more, hinge angles; the block's worst flag (0, FLAG_CRUMPLED, FLAG_EXPLODED)."""
    bad, changed = finish_vertices(world, lane, bd, c, m, opt, s, w)
    flag = wp.where(bad != 0, FLAG_EXPLODED, 0)
    block_max(flag)  # barrier: every final x before the hinge angles read them
    if update_hinge_angles(world, lane, bd, m, opt.fold_tolerance, s) != 0:
        flag = wp.max(flag, FLAG_CRUMPLED)
    return block_max(flag)  # barrier: angles and flags before the next substep moves any vertex


MAX_REGISTERS = 128
"""Registers per thread on CUDA (``__maxnreg__``): unbounded, ptxas (CUDA 13.0, sm_90) gave 192 (band) and 241
(dense), capping an H200 SM at 10 band or 2 dense worlds; at 128, 16 and 4 (docs/dynamics.md, "The solver").
"""


@functools.cache
def make_tile_substep_kernel(num_vertices: int, half_bandwidth: int, dense: bool = True,
                             max_registers: int | None = MAX_REGISTERS):
    """The block-per-world substep kernel for worms of ``num_vertices`` vertices and Newton-matrix half-bandwidth
    ``half_bandwidth`` (vertex blocks), dense or banded solve (module docstring); one module per (shape, solve)."""
    if num_vertices < 1 or half_bandwidth < 0:
        raise ValueError(f"num_vertices must be >= 1 and half_bandwidth >= 0, got {num_vertices}, {half_bandwidth}")
    N = 3 * num_vertices
    DENSE = bool(dense)
    BW = int(half_bandwidth)
    SLOTS = num_vertices * (half_bandwidth + 1) * 9  # 3x3 entries of the lower block-banded part, with the out-of-range ones

    @wp.kernel(enable_backward=False, module="unique", cuda_max_registers=max_registers)
    def implicit_step_tile(m: BarHingeModel, opt: SubstepOptions, f_ext: wp.array2d(dtype=wp.vec3),
                           anchor_target: wp.array2d(dtype=wp.vec3), inc: VertexIncidence, s: BarHingeState,
                           w: NewtonScratch):
        """:func:`.implicit_euler.implicit_step`'s substeps, one world per block: launch_tiled dim (W,), any
        block_dim; ``w.hess`` has ``half_bandwidth + 1`` blocks per row."""
        world, lane = wp.tid()
        bd = wp.block_dim()
        if s.unstable[world] != 0:  # the same for every thread of the block: the whole block leaves
            return
        nv = s.x.shape[1]
        c = world_coefficients(m, world, opt.dt)
        if wp.static(DENSE):
            # the world's Newton matrix (lower triangle; factored in place) and right-hand side, in shared memory
            mat = wp.tile_zeros(shape=(N, N), dtype=float, storage="shared")
            rhs = wp.tile_zeros(shape=(N,), dtype=float, storage="shared")
        for sub in range(opt.num_substeps):
            predict(world, lane, bd, c, m, opt.slip_speed, f_ext, s, w)
            bad = block_max(0)  # barrier: every x predicted before any row reads it
            converged = int(0)
            for it in range(opt.newton):
                bad = newton_system(world, lane, bd, it, c, m, opt, anchor_target, inc, s, w)
                if bad != 0:
                    break
                if lane == 0:
                    w.newton_steps[world] = w.newton_steps[world] + 1
                    w.newton_factors[world] = w.newton_factors[world] + 1
                moving = int(0)
                if wp.static(DENSE):
                    for r in range((SLOTS + bd - 1) // bd):
                        row, col, val, ok = banded_entry(world, r * bd + lane, BW, SLOTS, w.hess)
                        wp.tile_scatter_masked(mat, row, col, val, ok)
                    for r in range((N + bd - 1) // bd):
                        idx, val, ok = rhs_entry(world, r * bd + lane, N, w.grad)
                        wp.tile_scatter_masked(rhs, idx, val, ok)
                    wp.tile_cholesky_inplace(mat)
                    wp.tile_cholesky_solve_inplace(mat, rhs)
                    for i in range(lane, nv, bd):
                        dx = -wp.vec3(rhs[3 * i], rhs[3 * i + 1], rhs[3 * i + 2])
                        apply_step(world, i, dx, s, w)
                        if not (wp.length(dx) < opt.newton_tol):
                            moving = 1
                else:
                    moving = banded_solve_and_apply(world, lane, bd, BW, opt.newton_tol, s, w)
                moving = block_max(moving)  # also the barrier: the step taken before the next rows read x
                if it >= 1 and moving == 0:
                    converged = 1  # the banded layout's test: no vertex moved by newton_tol or more
                    break
            if bad != 0:
                if lane == 0:
                    freeze_world(world, nv, s.x, s.v, w.x_prev, w.delta, s.unstable)
                return
            if converged == 0 and lane == 0:
                w.newton_capped[world] = w.newton_capped[world] + 1
            worst = finish_substep(world, lane, bd, c, m, opt, s, w)
            if worst != 0:
                if lane == 0:
                    freeze_world(world, nv, s.x, s.v, w.x_prev, w.delta, s.unstable)
                    if worst == FLAG_CRUMPLED:
                        s.unstable[world] = WORLD_CRUMPLED
                return
            if lane == 0:
                s.step_count[world] = s.step_count[world] + 1

    return implicit_step_tile
