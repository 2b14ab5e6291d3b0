"""warpworm: batched multiphysics simulation of magnetically actuated origami worm robots on NVIDIA Warp.

SI units everywhere (m, kg, s, N, A·m², T, rad). Rotations are 3x3 matrices on the host; inside kernels
they are ``wp.quat`` in Warp's (x, y, z, w) order.
"""

__version__ = "0.1.0"


def quiet_warp() -> None:
    """Silence Warp's informational output (banner, module loads), which goes to stdout; warnings still show."""
    import warp as wp

    if hasattr(wp, "LOG_WARNING"):  # Warp >= 1.12: leveled logging
        wp.config.log_level = wp.LOG_WARNING
    else:
        wp.config.quiet = True
