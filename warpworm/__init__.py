"""warpworm: batched multiphysics simulation of magnetically actuated origami worm robots on NVIDIA Warp.

SI units everywhere (m, kg, s, N, A·m², T, rad). Rotations are 3x3 matrices on the host; inside kernels
they are ``wp.quat`` in Warp's (x, y, z, w) order.
"""

__version__ = "0.1.0"

CUDA_DRIVER_WARNING = "Warp CUDA warning: Could not find or load the NVIDIA CUDA driver"
"""The line Warp's native library prints (C ``fprintf``) on init when there is no CUDA driver."""

cuda_driver_missing: bool | None = None
"""After :func:`quiet_warp`: True if Warp found no CUDA driver (so every device is the CPU), None if not yet known."""


def quiet_warp() -> None:
    """Silence Warp's informational output (banner, module loads), which goes to stdout; warnings still show.

    Also initialises Warp now, without the native library's ``Warp CUDA warning: Could not find or load the NVIDIA
    CUDA driver`` line: Warp 1.19 has no option to skip the CUDA probe (``wp_init`` always ``dlopen``s libcuda and
    ``fprintf``s the warning to fd 2), so file descriptor 2 is redirected to a temporary file for the duration of
    ``wp.init()`` only, and everything else it printed is written back to stderr. On a machine without a driver the
    only device is the CPU; a config asking for ``cuda:N`` is then refused with the available devices
    (``warpworm.data.config.sections._check_device``), and the dataset pipeline prints one line naming the device it runs on, so nothing
    is lost by dropping the warning. Recorded in :data:`cuda_driver_missing`.
    """
    import warp as wp

    if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.12: leveled logging
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True
    _init_warp_without_cuda_warning(wp)


def _init_warp_without_cuda_warning(wp) -> None:
    global cuda_driver_missing
    import os
    import sys
    import tempfile

    try:
        from warp._src import context as _ctx
        initialised = _ctx.runtime is not None
    except Exception:  # noqa: BLE001 - another Warp layout: plain init
        initialised = False
        _ctx = None
    if initialised or _ctx is None:
        if _ctx is None:
            wp.init()
        if cuda_driver_missing is None:
            cuda_driver_missing = not wp.is_cuda_available()
        return
    try:
        sys.stderr.flush()
    except Exception:  # noqa: BLE001
        pass
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as cap:
        try:
            os.dup2(cap.fileno(), 2)
            try:
                wp.init()
            finally:
                os.dup2(saved, 2)
                os.close(saved)
        finally:
            cap.seek(0)
            text = cap.read().decode("utf-8", "replace")
    kept = [ln for ln in text.splitlines(keepends=True) if not ln.startswith(CUDA_DRIVER_WARNING)]
    cuda_driver_missing = len(kept) != len(text.splitlines()) or not wp.is_cuda_available()
    if kept:
        sys.stderr.write("".join(kept))
        sys.stderr.flush()
