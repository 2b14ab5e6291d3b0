"""Host launcher of the block-per-world implicit substeps (:mod:`warpworm.kernels.implicit_tile`), the GPU path.

:class:`TileSubsteps` does what ``Simulator._world_cmd(state, control, n).launch()`` does (``n`` implicit substeps
of every world, in place on the :class:`~warpworm.sim.model.State`), with one block of ``block_dim`` threads per world
instead of one thread. It assembles the band path's Newton systems bit for bit; with ``factorization="band"`` it
also factors them with the same arithmetic (results identical on the CPU), with "dense" (``wp.tile_cholesky``) the
factor rounds differently: results agree to float rounding where the dynamics is continuous (a contact decision
near its threshold can flip on a difference of a few 1e-9 m, in the band path too). Typical use, in place of ``_world_cmd``::

    tiles = TileSubsteps(sim.model, sim)             # band; block_dim: 32 on CUDA, 1 on the CPU
    tiles.launch(state, sim.substeps, control)       # = sim._world_cmd(state, control, sim.substeps).launch()

Everything the kernel reads from the Model, the Simulator, the State and the Control goes through
:func:`kernel_arguments`, the one place to re-wire when those classes change. The solver's scratch (x at the start of
the substep, x − x̃, the Newton band and right-hand side) is its own. Nothing loops over worlds on the host.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpworm.kernels.implicit_tile import MAX_REGISTERS, make_tile_substep_kernel

FACTORIZATIONS = ("band", "dense")
"""How a block solves its world's Newton systems: "band", the block band factored in place column-parallel (bit for
bit the band path's factor; ~no shared memory: one warp per world, many worlds per SM); "dense", the 3V × 3V matrix
as a float32 tile in shared memory, ``wp.tile_cholesky`` (cuSolverDx on a GPU; 55 KB per world: 4 worlds per SM)."""

DEFAULT_CUDA_BLOCK_DIM = {"band": 32, "dense": 128}
"""Threads per world on a GPU. band: one warp (a column of the band has at most B = 6 blocks below the diagonal, the
rows 39 vertices); dense: 4 warps, so the 4 worlds an SM's shared memory holds still give 16 warps to hide latency,
and the dense Cholesky's row updates and the band scatter split over them."""


def vertex_incidence(pairs_or_stencils: np.ndarray, num_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """CSR lists of the elements (rows of ``pairs_or_stencils``, shape (n, k) vertex indices) incident on each
    vertex, element indices ascending: ``index[start[u]:start[u + 1]]``. Returns (start (V + 1,), index), int32."""
    el = np.asarray(pairs_or_stencils, dtype=np.int64)
    if el.ndim != 2:
        raise ValueError(f"elements: expected shape (n, k) of vertex indices, got {el.shape}")
    if el.size and (el.min() < 0 or el.max() >= num_vertices):
        raise ValueError(f"elements: vertex indices must be in [0, {num_vertices}), got [{el.min()}, {el.max()}]")
    vert = el.reshape(-1)
    elem = np.repeat(np.arange(len(el)), el.shape[1])
    order = np.lexsort((elem, vert))  # by vertex, then element ascending
    start = np.zeros(num_vertices + 1, np.int64)
    np.add.at(start, vert + 1, 1)
    return np.cumsum(start).astype(np.int32), elem[order].astype(np.int32)


def kernel_arguments(model, simulator, state, control, scratch, incidence, num_substeps: int) -> tuple[list, list]:
    """(inputs, outputs) of :func:`~warpworm.kernels.implicit_tile.make_tile_substep_kernel`'s kernel from the
    Model, the Simulator (substep settings), the State, the Control (anchor targets) and this solver's scratch
    (x_prev, delta, hess, grad, released). The only place that knows those classes' field names."""
    m, sim = model, simulator
    inputs = [m.inv_mass, m.gravity, m.damping, m.edges, m.rest_length, m.bar_stiffness, m.bar_stop_strain,
              m.bar_stop_stiffness, m.hinges, m.hinge_rest_angle, m.hinge_length, m.hinge_label, m.hinge_stiffness,
              m.hinge_damping, m.fold_limit_stiffness, m.anchor_vertex, m.anchor_stiffness, m.floor_incline,
              m.mu_static, m.mu_kinetic, m.friction_backward_ratio, *incidence, sim.dt_sub, int(num_substeps), sim.newton, sim.newton_tol * sim.dt_sub, sim.slip_speed,
              sim.bar_strain_limit, sim.speed_limit, sim.fold_tolerance, state.external_force, control.anchor_target]
    outputs = [state.positions, state.velocities, scratch["x_prev"], scratch["delta"], state.floor_force,
               scratch["hess"], scratch["grad"], scratch["released"], state.bar_strain, state.crease_angle, state.contact, state.unstable,
               state.step_count]
    return inputs, outputs


class TileSubsteps:
    """The implicit substeps of every world of ``model``, one block of threads per world.

    Args:
        model: the batch (:class:`~warpworm.sim.model.Model`); its topology sets the kernel's tile size (3V).
        simulator: the :class:`~warpworm.sim.simulator.Simulator` whose substep length, Newton count, friction and
            stability settings are used (read at each new recording, as ``_world_cmd`` does).
        factorization: one of :data:`FACTORIZATIONS` (default "band").
        block_dim: threads per world; default :data:`DEFAULT_CUDA_BLOCK_DIM` on CUDA, 1 on the CPU. On the CPU values
            above 1 run as cooperative fibers only with ``wp.config.enable_cpu_blocks`` set (slower; for testing the
            block logic), else Warp runs 1.
        max_registers: CUDA registers per thread (default
            :data:`warpworm.kernels.implicit_tile.MAX_REGISTERS`; ``None`` unbounded); ignored on the CPU.
    """

    def __init__(self, model, simulator, factorization: str = "band", block_dim: int | None = None,
                 max_registers: int | None = MAX_REGISTERS):
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization: expected one of {FACTORIZATIONS}, got {factorization!r}")
        self.factorization = factorization
        self.model = model
        self.simulator = simulator
        if block_dim is None:
            block_dim = DEFAULT_CUDA_BLOCK_DIM[factorization] if model.device.is_cuda else 1
        if not 1 <= int(block_dim) <= 1024:
            raise ValueError(f"block_dim: expected 1..1024 threads per world, got {block_dim}")
        self.block_dim = int(block_dim)
        V = model.num_vertices
        edges = model.edges.numpy()
        hinges = model.hinges.numpy()
        self.bandwidth = int(model.vertex_bandwidth)
        bs, bi = vertex_incidence(edges, V)
        hs, hi = vertex_incidence(hinges, V)
        dev = model.device
        self.incidence = [wp.array(a, dtype=wp.int32, device=dev) for a in (bs, bi, hs, hi)]
        """Vertex -> bars and vertex -> hinges, CSR: [bar start (V + 1,), bars, hinge start (V + 1,), hinges]."""
        self.kernel = make_tile_substep_kernel(V, self.bandwidth, factorization == "dense", max_registers)
        W = model.num_worlds
        self.scratch = {
            "x_prev": wp.zeros((W, V), dtype=wp.vec3, device=dev),
            "delta": wp.zeros((W, V), dtype=wp.vec3, device=dev),
            "hess": wp.zeros((W, V, self.bandwidth + 1), dtype=wp.mat33, device=dev),
            "grad": wp.zeros((W, V), dtype=wp.vec3, device=dev),
            "released": wp.zeros((W, V), dtype=wp.int32, device=dev),
        }
        """The solver's scratch, shared by every state it steps (nothing in it outlives a launch; delta is zero
        between launches): x_prev, delta (W, V) vec3 [m], hess (W, V, B + 1) mat33, grad (W, V) vec3, released (W, V) int32."""
        self._cmds = {}

    @property
    def shared_bytes_per_world(self) -> int:
        """Shared memory one block (world) needs on CUDA [bytes], as Warp records it in the module's metadata (builds
        or loads the module for this device): dense, the 3V × 3V float32 tile, the right-hand side and the
        reductions' scratch; band, the scratch only."""
        exe = self.kernel.module.load(self.model.device, self.block_dim)
        sizes = [v for k, v in exe.meta.items() if k.endswith("_cuda_kernel_forward_smem_bytes")]
        if len(sizes) != 1:
            raise RuntimeError(f"module metadata: expected one forward kernel's shared memory size, got {exe.meta}")
        return int(sizes[0])

    def command(self, state, control, num_substeps: int):
        """The recorded launch (``wp.launch_tiled(..., record_cmd=True)``) of ``num_substeps`` substeps of every world
        of ``state`` under ``control``: what ``Simulator._world_cmd`` returns, to ``.launch()`` or capture in a graph.
        Recorded once per (state, control, count)."""
        if int(num_substeps) < 1:
            raise ValueError(f"num_substeps: expected >= 1, got {num_substeps}")
        key = (id(state), id(control), int(num_substeps))
        cmd = self._cmds.get(key)
        if cmd is not None and cmd[0] is state and cmd[1] is control:
            return cmd[2]
        inputs, outputs = kernel_arguments(self.model, self.simulator, state, control, self.scratch, self.incidence,
                                           num_substeps)
        c = wp.launch_tiled(self.kernel, dim=self.model.num_worlds, inputs=inputs, outputs=outputs,
                            block_dim=self.block_dim, device=self.model.device, record_cmd=True)
        self._cmds[key] = (state, control, c)
        return c

    def launch(self, state, num_substeps: int, control=None) -> None:
        """Advance every world of ``state`` by ``num_substeps`` implicit substeps (in place) under ``control``
        (default the simulator's), as ``Simulator._world_cmd(state, control, num_substeps).launch()`` does."""
        self.command(state, control if control is not None else self.simulator.control, num_substeps).launch()
