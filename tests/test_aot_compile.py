"""Every Warp kernel module compiles for CUDA sm_90 (H100 / H200) ahead of time, on this CPU-only machine.

No GPU is needed: Warp ships NVRTC, which compiles CUDA C++ without a driver. The CPU tests never generate the CUDA
code path of a kernel, so a CUDA-only mistake (a construct the CUDA code generator or NVRTC rejects) would otherwise
land unseen until someone runs on a GPU. The truth here is NVRTC itself: it either builds the PTX or reports the
error.

The kernel modules are discovered (``pkgutil`` over ``warpworm.kernels`` and ``warpworm.render``, every submodule
that defines a kernel), not listed, so a new kernel file is covered the day it lands.

Compiled artifacts go to Warp's kernel cache (keyed by a hash of the module's source and options): an unchanged module
is not rebuilt, a changed one is. Cold, the whole set took ~30 s on the 2-core machine (magnet wrench most of it).
"""

from __future__ import annotations

import importlib
import pkgutil

import pytest

wp = pytest.importorskip("warp")

ARCH = 90
"""sm_90: the H100 / H200 (Hopper) the GPU path is written for."""

PACKAGES = ("warpworm.kernels", "warpworm.render")


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
    """Names of every submodule of :data:`PACKAGES` whose Warp module holds at least one kernel."""
    names = []
    for pkg_name in PACKAGES:
        pkg = importlib.import_module(pkg_name)
        for info in pkgutil.iter_modules(pkg.__path__):
            name = f"{pkg_name}.{info.name}"
            importlib.import_module(name)  # an import error here is a failure, not a skip
            if wp.get_module(name).kernels:
                names.append(name)
    return names


MODULES = kernel_modules()


def test_kernel_modules_are_discovered():
    # the solver, the magnet poses / wrench and the rasterizer must be among them (a discovery that finds nothing
    # would make the compile test below vacuous)
    for expected in ("warpworm.kernels.implicit_euler", "warpworm.kernels.magnet_wrench",
                     "warpworm.kernels.magnet_pose", "warpworm.render.raster_kernels"):
        assert expected in MODULES, (expected, MODULES)


@pytest.mark.parametrize("name", MODULES)
def test_module_compiles_for_sm90(name):
    reason = _nvrtc_reason()
    if reason:
        pytest.skip(reason)
    module = wp.get_module(name)
    paths = wp.compile_aot_module(module, arch=ARCH, use_ptx=True)
    assert paths, name
    for p in paths:
        assert p.exists() and p.stat().st_size > 0, p
        assert p.read_text(errors="replace").lstrip().startswith("//"), p  # PTX text (NVRTC's header comment)
        assert f".target sm_{ARCH}" in p.read_text(errors="replace"), p
