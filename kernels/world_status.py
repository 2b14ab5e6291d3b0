"""World status changes the host asks for between steps (``State.unstable``: 0 running, else frozen; ids: the
statuses)."""

from __future__ import annotations

import warp as wp

from warpworm import ids

wp.set_module_options({"enable_backward": False})

WORLD_OK = wp.constant(ids.WORLD_OK)
WORLD_RETIRED = wp.constant(ids.WORLD_RETIRED)


@wp.kernel
def retire_worlds(retire: wp.array(dtype=wp.int32), unstable: wp.array(dtype=wp.int32)):
    """Mark world ``w`` retired where ``retire[w]`` is non-zero and it is still running (an unstable world keeps its
    flag); launched over the W worlds."""
    w = wp.tid()
    if retire[w] != 0 and unstable[w] == WORLD_OK:
        unstable[w] = WORLD_RETIRED
