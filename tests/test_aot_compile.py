"""Every Warp kernel module compiles for CUDA sm_90 (H100 / H200) ahead of time, on this CPU-only machine.

No GPU is needed: Warp ships NVRTC, which compiles CUDA C++ without a driver. The CPU tests never generate the CUDA
code path of a kernel, so a CUDA-only mistake (a construct the CUDA code generator or NVRTC rejects) would otherwise
land unseen until someone runs on a GPU. The truth here is NVRTC itself: it either builds the PTX or reports the
error.

The kernel modules are discovered (``pkgutil`` over ``warpworm.kernels`` and ``warpworm.render``, every submodule
that defines a kernel), not listed, so a new kernel file is covered the day it lands.

Compiled artifacts go to Warp's kernel cache (keyed by a hash of the module's source and options): an unchanged module
is not rebuilt, a changed one is. The modules compile in parallel threads (Warp generates code under a lock and runs
NVRTC outside it), the largest first (cold timings per module: docs/testing.md).
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from concurrent.futures import ThreadPoolExecutor

import pytest

wp = pytest.importorskip("warp")

ARCH = 90
"""sm_90: the H100 / H200 (Hopper) the GPU path is written for."""

PACKAGES = ("warpworm.kernels", "warpworm.render", "warpworm")
"""Where kernels live (``warpworm.kernels``: the physics; ``warpworm.render``: the rasterizer); host modules of
``warpworm`` itself are scanned too, in case a kernel is defined there."""


def _nvrtc_reason() -> str | None:
    """None when NVRTC can build sm_90 code in this process; else why not (the skip reason)."""
    from warpworm import quiet_warp

    quiet_warp()
    wp.init()
    from warp._src.context import runtime

    if not getattr(runtime, "is_cuda_enabled", False):
        return "this Warp build has no CUDA support (NVRTC unavailable)"
    archs = getattr(runtime, "nvrtc_supported_archs", set())
    if ARCH not in archs:
        return f"NVRTC cannot target sm_{ARCH} (supported: {sorted(archs)})"
    return None


def kernel_modules() -> list[str]:
    """Names of every module of :data:`PACKAGES` that defines a Warp kernel (its source mentions ``wp.kernel``, and
    once imported its Warp module holds at least one)."""
    names = []
    for pkg_name in PACKAGES:
        pkg = importlib.import_module(pkg_name)
        for info in pkgutil.iter_modules(pkg.__path__):
            if info.ispkg:
                continue
            name = f"{pkg_name}.{info.name}"
            src = os.path.join(info.module_finder.path, f"{info.name}.py")
            if not os.path.exists(src) or "wp.kernel" not in open(src, encoding="utf-8").read():
                continue  # no kernel: not imported (host modules may need optional packages)
            importlib.import_module(name)  # an import error here is a failure, not a skip
            if wp.get_module(name).kernels:
                names.append(name)
    return names


def factory_modules(skip=()) -> list[str]:
    """Names of the kernel modules that building a :class:`~warpworm.sim.simulator.Simulator` for every solver in
    ``simulator.SOLVERS`` creates beyond ``skip`` (kernels made by a factory for the worm's shape, each its own
    ``module="unique"`` module, e.g. the block-per-world tile substeps), on a one-world CPU model, and the renderer's
    2 x 2 lens sample resolve (a factory kernel specialized on the sample count and the lens)."""
    from warp._src.context import user_modules

    from warpworm.physics import gaits
    from warpworm.render.sample_kernels import resolve_samples_kernel
    from warpworm.sim.model import Model
    from warpworm.sim.simulator import SOLVERS, Simulator

    before = set(user_modules)
    model = Model.from_params(gaits.preset_params("peristaltic"), 1, "cpu")
    for solver in SOLVERS:
        Simulator(model, solver=solver)
    resolve_samples_kernel(2, True)  # the renderer's sample resolve, as production's images take it
    return [n for n in list(user_modules) if n not in before and n not in skip and user_modules[n].kernels]


FILE_MODULES = kernel_modules()
MODULES = FILE_MODULES + factory_modules(FILE_MODULES)


def test_kernel_modules_are_discovered():
    # the solver, the magnet poses / wrench and the rasterizer must be among them (a discovery that finds nothing
    # would make the compile test below vacuous)
    for expected in ("warpworm.kernels.implicit_euler", "warpworm.kernels.magnet_wrench",
                     "warpworm.kernels.magnet_pose", "warpworm.render.raster_kernels"):
        assert expected in MODULES, (expected, MODULES)
    # and the tile solver's factory kernels (one module per factorization), unless the tile solver is gone
    from warpworm.sim.simulator import SOLVERS

    tiles = [s for s in SOLVERS if s.startswith("tile-")]
    assert len(MODULES) - len(FILE_MODULES) >= len(tiles) + 1, (MODULES, SOLVERS)
    assert any(n.startswith("resolve_samples_2x2_lens") for n in MODULES), MODULES


def _compile(name: str):
    from warp._src.context import user_modules

    # the module's own options (block_dim 256 unless it sets one; the tile solver launches 32 / 128 threads per
    # world on a GPU: the same code paths, other tile sizes)
    return wp.compile_aot_module(user_modules[name], arch=ARCH, use_ptx=True)


@pytest.fixture(scope="module")
def compiled() -> dict:
    """Module name -> its PTX paths, or the exception its compilation raised."""
    reason = _nvrtc_reason()
    if reason:
        pytest.skip(reason)
    # largest source first: the magnet wrench dominates, start it before the small ones
    order = sorted(MODULES, key=lambda n: -os.path.getsize(importlib.import_module(n).__file__)
                   if n in FILE_MODULES else 0)
    with ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1))) as pool:
        futures = {n: pool.submit(_compile, n) for n in order}
    return {n: (f.exception() or f.result()) for n, f in futures.items()}


@pytest.mark.parametrize("name", MODULES)
def test_module_compiles_for_sm90(name, compiled):
    paths = compiled[name]
    if isinstance(paths, BaseException):
        raise paths
    assert paths, name
    for p in paths:
        text = p.read_text(errors="replace")
        assert p.stat().st_size > 0 and text.lstrip().startswith("//"), p  # PTX text (NVRTC's header comment)
        assert f".target sm_{ARCH}" in text, p
