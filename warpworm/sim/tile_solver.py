"""The block-per-world solver (:mod:`warpworm.kernels.implicit_tile`), the GPU layout of the substep.

:class:`TileSolver` is a :class:`~warpworm.sim.solver.SolverBase`: ``step(state, n, control)`` runs the banded
layout's substeps with one block of ``block_dim`` threads per world instead of one thread. It assembles the banded
layout's Newton systems bit for bit; ``factorization="band"`` also factors them with the same arithmetic (identical
results on the CPU), "dense" (``wp.tile_cholesky``) rounds differently.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpworm.kernels.implicit_tile import MAX_REGISTERS, VertexIncidence, make_tile_substep_kernel
from warpworm.sim.solver import SolverBase, SubstepSettings, state_struct

FACTORIZATIONS = ("band", "dense")
"""How a block solves its world's Newton systems: "band", the block band in place, column-parallel (~no shared
memory: one warp per world); "dense", a 3V × 3V float32 tile in shared memory (55 KB per world: 4 per H200 SM)."""

DEFAULT_CUDA_BLOCK_DIM = {"band": 32, "dense": 128}
"""Threads per world on a GPU: band one warp (a band column has at most 6 blocks below the diagonal); dense 4 warps,
so the 4 worlds an SM holds still give 16 warps to hide latency."""


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


class TileSolver(SolverBase):
    """The substeps of every world of ``model``, one block of threads per world.

    Args:
        model: the batch; its topology sets the kernel's tile size (3V).
        settings: the substep's settings (``chord`` must be off: this layout takes full Newton steps).
        factorization: one of :data:`FACTORIZATIONS` (default "band").
        block_dim: threads per world; default :data:`DEFAULT_CUDA_BLOCK_DIM` on CUDA, 1 on the CPU (where more run as
            cooperative fibers only with ``wp.config.enable_cpu_blocks``: for testing the block logic).
        max_registers: CUDA registers per thread (default :data:`~warpworm.kernels.implicit_tile.MAX_REGISTERS`;
            ``None`` unbounded).
    """

    def __init__(self, model, settings: SubstepSettings, factorization: str = "band", block_dim: int | None = None,
                 max_registers: int | None = MAX_REGISTERS):
        if factorization not in FACTORIZATIONS:
            raise ValueError(f"factorization: expected one of {FACTORIZATIONS}, got {factorization!r}")
        if settings.chord:
            raise ValueError("chord: chord Newton steps are implemented by the 'band' solver only, got solver="
                             f"'tile-{factorization}'")
        if block_dim is None:
            block_dim = DEFAULT_CUDA_BLOCK_DIM[factorization] if model.device.is_cuda else 1
        if not 1 <= int(block_dim) <= 1024:
            raise ValueError(f"block_dim: expected 1..1024 threads per world, got {block_dim}")
        super().__init__(model, settings)
        self.factorization = factorization
        self.block_dim = int(block_dim)
        V = model.num_vertices
        self.incidence = VertexIncidence()
        """Vertex -> bars and vertex -> hinges (CSR, element indices ascending)."""
        inc = self.incidence
        for kind, elements in (("bar", model.edges), ("hinge", model.hinges)):
            start, index = vertex_incidence(elements.numpy(), V)
            setattr(inc, f"{kind}_start", wp.array(start, dtype=wp.int32, device=model.device))
            setattr(inc, kind, wp.array(index, dtype=wp.int32, device=model.device))
        self.kernel = make_tile_substep_kernel(V, int(model.half_bandwidth), factorization == "dense",
                                               max_registers)

    @property
    def shared_bytes_per_world(self) -> int:
        """Shared memory one block (world) needs on CUDA [bytes], from the module's metadata (builds or loads it):
        dense, the 3V × 3V float32 tile, the right-hand side and the reductions' scratch; band, the scratch only."""
        exe = self.kernel.module.load(self.model.device, self.block_dim)
        sizes = [v for k, v in exe.meta.items() if k.endswith("_cuda_kernel_forward_smem_bytes")]
        if len(sizes) != 1:
            raise RuntimeError(f"module metadata: expected one forward kernel's shared memory size, got {exe.meta}")
        return int(sizes[0])

    def _record(self, state, control, num_substeps: int):
        return wp.launch_tiled(self.kernel, dim=self.model.num_worlds,
                               inputs=[self.model_arrays, self.options(num_substeps), state.external_force,
                                       control.anchor_target, self.incidence, state_struct(state), self.scratch],
                               block_dim=self.block_dim, device=self.model.device, record_cmd=True)
