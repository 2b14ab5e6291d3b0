"""Reference ray caster (independent of the rasterizer): one ``wp.Mesh`` BVH per world, one ray per pixel.

Used by the tests as ground truth for depth and segmentation and by the benchmark as the baseline. The floor is a
real two-triangle square here (:meth:`SceneBatch.reference_mesh`), not the rasterizer's analytic plane.
"""

from __future__ import annotations

import numpy as np
import warp as wp

from warpworm.render.camera import Cameras
from warpworm.render.scene import SceneBatch


# forward only: nothing differentiates through rendering, and skipping adjoints halves the compile time
wp.set_module_options({"enable_backward": False})

@wp.kernel
def cast_rays(
    # Model:
    meshes: wp.array(dtype=wp.uint64),
    face_label: wp.array2d(dtype=wp.int32),
    # Data in:
    image_world: wp.array(dtype=wp.int32),
    cam_rot: wp.array(dtype=wp.mat33),
    cam_trans: wp.array(dtype=wp.vec3),
    cam_intr: wp.array(dtype=wp.vec4),
    directions: wp.array3d(dtype=wp.vec3),
    # Data out:
    depth: wp.array3d(dtype=float),
    seg: wp.array3d(dtype=wp.uint8),
):
    """Nearest hit of the ray through pixel centre (x, y) of image ``img`` (or along ``directions[img, y, x]``,
    camera frame with z = 1, when given: shape (N, H, W), else (1, 1, 1)): camera z [m] (0: miss) and its label."""
    img, y, x = wp.tid()
    w = image_world[img]
    R = cam_rot[img]
    t = cam_trans[img]
    k = cam_intr[img]
    d_cam = wp.vec3((float(x) - k[2]) / k[0], (float(y) - k[3]) / k[1], 1.0)
    if directions.shape[0] > 1:
        d_cam = directions[img, y, x]
    Rt = wp.transpose(R)
    eye = -(Rt * t)
    length = wp.length(d_cam)
    d_world = Rt * (d_cam / length)
    q = wp.mesh_query_ray(meshes[w], eye, d_world, 1.0e6)
    if q.result:
        depth[img, y, x] = q.t / length  # ray parameter along a unit direction -> camera z
        seg[img, y, x] = wp.uint8(face_label[w, q.face])
    else:
        depth[img, y, x] = 0.0
        seg[img, y, x] = wp.uint8(0)


class RayCaster:
    """Ray casts a :class:`SceneBatch` with Warp's BVH meshes; same outputs as :class:`Renderer` (depth, seg)."""

    def __init__(self, width: int, height: int, *, device=None):
        wp.init()
        self.width = int(width)
        self.height = int(height)
        self.device = wp.get_device(device)
        self._meshes = []

    def build(self, scene: SceneBatch) -> None:
        """Build one BVH per world (kept alive on ``self``)."""
        self._meshes = []
        labels = []
        for w in range(scene.num_worlds):
            v, f, lab = scene.reference_mesh(w)
            self._meshes.append(wp.Mesh(points=wp.array(v.astype(np.float32), dtype=wp.vec3, device=self.device),
                                        indices=wp.array(f.reshape(-1), dtype=wp.int32, device=self.device)))
            labels.append(lab)
        self._ids = wp.array(np.array([m.id for m in self._meshes], dtype=np.uint64), dtype=wp.uint64,
                             device=self.device)
        self._labels = wp.array(np.stack(labels), dtype=wp.int32, device=self.device)

    def render(self, scene: SceneBatch | None, cameras: Cameras, directions=None) -> dict:
        """``depth`` (N, H, W) float32 [m] (0 = miss) and ``seg`` (N, H, W) uint8; ``scene`` None reuses the BVHs.
        ``directions``: each pixel's ray (N, H, W, 3) in the camera frame with z = 1 (e.g. through a lens
        distortion) instead of the pinhole ray through its centre."""
        if scene is not None:
            self.build(scene)
        d = self.device
        N = len(cameras)
        K = cameras.K
        intr = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]], axis=1)
        depth = wp.empty((N, self.height, self.width), dtype=float, device=d)
        seg = wp.empty((N, self.height, self.width), dtype=wp.uint8, device=d)
        wp.launch(cast_rays, dim=(N, self.height, self.width), device=d,
                  inputs=[self._ids, self._labels, wp.array(cameras.world.astype(np.int32), dtype=wp.int32, device=d),
                          _vec(cameras.R, wp.mat33, d), _vec(cameras.t, wp.vec3, d), _vec(intr, wp.vec4, d),
                          _vec(np.zeros((1, 1, 1, 3)) if directions is None else directions, wp.vec3, d)],
                  outputs=[depth, seg])
        return {"depth": depth.numpy(), "seg": seg.numpy()}


def _vec(a, dtype, device):
    return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=dtype, device=device)
