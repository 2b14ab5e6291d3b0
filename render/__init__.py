"""Off-screen batched rendering and labels for warpworm (installs as ``warpworm.render``).

Public API::

    from warpworm.render import Renderer, sample_cameras, build_scene
    from warpworm.render.labels import schema_labels
"""

from warpworm.render.camera import Cameras, focal_from_fov, intrinsics, look_at, make_cameras, sample_cameras
from warpworm.render.rasterizer import Renderer
from warpworm.render.scene import (
    LABEL_NAMES,
    Appearance,
    SceneBatch,
    build_scene,
    default_appearance,
    hsv_to_rgb,
    scene_from_snapshot,
)

__all__ = [
    "LABEL_NAMES",
    "Appearance",
    "Cameras",
    "Renderer",
    "SceneBatch",
    "build_scene",
    "default_appearance",
    "focal_from_fov",
    "hsv_to_rgb",
    "intrinsics",
    "look_at",
    "make_cameras",
    "sample_cameras",
    "scene_from_snapshot",
]
