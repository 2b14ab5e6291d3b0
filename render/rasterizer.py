"""Host side of the batched rasterizer: uploads a :class:`SceneBatch` and :class:`Cameras`, launches the two passes.

Usage::

    renderer = Renderer(128, 128, device="cpu")
    out = renderer.render(scene, cameras)          # dict of NumPy arrays
    out["rgb"]    # (N, H, W, 3) uint8
    out["depth"]  # (N, H, W) float32, camera z [m], 0 = background
    out["seg"]    # (N, H, W) uint8, ids of docs/render.md
    out["worm_mask"]  # (N, H, W) bool, worm silhouette ignoring occluders (for the visible fraction)

A batch of N images costs one buffer clear and two kernel launches; very large batches are split into chunks of at
most ``max_chunk_pixels`` pixels so device memory stays bounded (17 bytes per pixel with normals off).

Warp runs a CPU kernel on one thread. ``threads > 1`` splits a CPU batch into that many interleaved chunk streams,
each with its own buffers, launched from Python threads: Warp calls CPU kernels through ctypes, which releases the
GIL, and the generated CPU kernels keep no global state, so the streams run in parallel on separate cores. The images
are identical whatever ``threads`` is (tested).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from warpworm.render import raster_kernels as rk
from warpworm.render.camera import Cameras
from warpworm.render.scene import SceneBatch


def _vec_array(a, dtype, device):
    return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=dtype, device=device)


def bake_noise(size: int = 128, seed: int = 20240611) -> np.ndarray:
    """Tileable fractal value noise in [0, 1], shape (size, size) float32.

    Three octaves of smoothstep-interpolated lattice noise (8, 32 and ``size`` cells per tile, weights 0.5, 0.3,
    0.2), normalized to [0, 1]. The seed is fixed, so every renderer bakes the same texture; worlds differ by their
    texture offsets (``Appearance.tex_seed``)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((size, size))
    amp_sum = 0.0
    for cells, amp in ((8, 0.5), (32, 0.3), (size, 0.2)):
        lat = rng.uniform(size=(cells, cells))
        t = (np.arange(size) * cells / size)
        i0 = np.floor(t).astype(int)
        f = t - i0
        f = f * f * (3 - 2 * f)
        i1 = (i0 + 1) % cells
        row = lat[i0][:, i0] * (1 - f)[None, :] + lat[i0][:, i1] * f[None, :]
        row1 = lat[i1][:, i0] * (1 - f)[None, :] + lat[i1][:, i1] * f[None, :]
        out += amp * (row * (1 - f)[:, None] + row1 * f[:, None])
        amp_sum += amp
    out /= amp_sum
    out = (out - out.min()) / (out.max() - out.min())
    return out.astype(np.float32)


class Renderer:
    """Off-screen z-buffer rasterizer for batches of (world, camera) images, on any Warp device."""

    def __init__(self, width: int, height: int, *, device=None, near: float = 1e-3,
                 max_chunk_pixels: int = 1 << 23, threads: int = 1):
        """
        Args:
            width, height: image size [px].
            device: Warp device ("cpu", "cuda:0", ...); default Warp's default device.
            near: triangles with a vertex closer than this to the camera plane [m] are skipped.
            max_chunk_pixels: largest number of pixels rendered per launch pair (per thread).
            threads: CPU only: render this many chunks concurrently (one core each); ignored on CUDA.
        """
        wp.init()
        self.width = int(width)
        self.height = int(height)
        self.device = wp.get_device(device)
        self.near = float(near)
        self.max_chunk_images = max(1, int(max_chunk_pixels) // (self.width * self.height))
        self.threads = max(1, int(threads)) if self.device.is_cpu else 1
        self._buffers: dict = {}
        # load the kernels once here: concurrent first launches from several threads would race to load them
        wp.load_module(rk, device=self.device)
        self._noise = wp.array(bake_noise(rk.NOISE_SIZE), dtype=float, device=self.device)

    # -- uploads -------------------------------------------------------------------------------------------------------

    def _upload_scene(self, scene: SceneBatch) -> dict:
        d = self.device
        a = scene.appearance
        s = {
            "triangles": wp.array(np.ascontiguousarray(scene.triangles, dtype=np.int32), dtype=wp.vec3i, device=d),
            "tri_label": wp.array(np.ascontiguousarray(scene.tri_label, dtype=np.int32), dtype=wp.int32, device=d),
            "vertices": _vec_array(scene.vertices, wp.vec3, d),
            "texcoords": _vec_array(scene.texcoords, wp.vec3, d),
            "albedo": _vec_array(a.albedo, wp.vec3, d),
            "specular": _vec_array(a.specular, wp.vec2, d),
            "floor_normal": _vec_array(scene.floor_normal, wp.vec3, d),
            "floor_axis": _vec_array(scene.floor_axis, wp.vec3, d),
            "floor_half": wp.array(np.asarray(scene.floor_half, dtype=np.float32), dtype=float, device=d),
            "floor_tex": _vec_array(a.floor_tex, wp.vec4, d),
            "floor_color2": _vec_array(a.floor_color2, wp.vec3, d),
            "paper_tex": _vec_array(a.paper_tex, wp.vec2, d),
            "tex_seed": wp.array(np.asarray(a.tex_seed, dtype=np.int32), dtype=wp.int32, device=d),
            "ambient": _vec_array(a.ambient, wp.vec3, d),
            "sun_dir": _vec_array(a.sun_dir, wp.vec3, d),
            "sun_color": _vec_array(a.sun_color, wp.vec3, d),
            "lamp_pos": _vec_array(a.lamp_pos, wp.vec3, d),
            "lamp_power": _vec_array(a.lamp_power, wp.vec3, d),
            "bg_top": _vec_array(a.bg_top, wp.vec3, d),
            "bg_bottom": _vec_array(a.bg_bottom, wp.vec3, d),
        }
        return s

    def _get_buffers(self, n: int, normals: bool, slot: int = 0) -> dict:
        key = (n, normals, slot)
        if key not in self._buffers:
            d, H, W = self.device, self.height, self.width
            # keep only the buffers of the current batch shape (one set per thread slot)
            self._buffers = {k: v for k, v in self._buffers.items() if k[:2] == (n, normals)}
            self._buffers[key] = {
                "zkey": wp.empty((n, H * W), dtype=wp.int64, device=d),
                "mask": wp.empty((n, H * W), dtype=wp.uint8, device=d),
                "rgb": wp.empty((n, H * W), dtype=wp.vec3ub, device=d),
                "depth": wp.empty((n, H * W), dtype=float, device=d),
                "seg": wp.empty((n, H * W), dtype=wp.uint8, device=d),
                "normals": wp.empty((n, H * W) if normals else (1, 1), dtype=wp.vec3, device=d),
                "image_world": wp.empty(n, dtype=wp.int32, device=d),
                "cam_rot": wp.empty(n, dtype=wp.mat33, device=d),
                "cam_trans": wp.empty(n, dtype=wp.vec3, device=d),
                "cam_intr": wp.empty(n, dtype=wp.vec4, device=d),
            }
        return self._buffers[key]

    # -- rendering -----------------------------------------------------------------------------------------------------

    def render(self, scene: SceneBatch, cameras: Cameras, *, normals: bool = False) -> dict:
        """Render every camera of ``cameras`` (image i shows world ``cameras.world[i]``).

        Returns:
            dict of NumPy arrays: ``rgb`` (N, H, W, 3) uint8; ``depth`` (N, H, W) float32 camera z [m], 0 for
            background; ``seg`` (N, H, W) uint8; ``worm_mask`` (N, H, W) bool (worm silhouette, occluders ignored);
            ``normals`` (N, H, W, 3) float32 camera-frame unit normals (0 for background) when ``normals=True``.
        """
        if cameras.width != self.width or cameras.height != self.height:
            raise ValueError(f"cameras are {cameras.width}x{cameras.height}, renderer is {self.width}x{self.height}")
        if len(cameras) and (cameras.world.min() < 0 or cameras.world.max() >= scene.num_worlds):
            raise ValueError(f"cameras.world must index the scene's {scene.num_worlds} worlds")
        if np.any(np.abs(cameras.K[:, 0, 1]) > 0):
            raise ValueError("skewed intrinsics (K[0, 1] != 0) are not supported")
        N = len(cameras)
        H, W = self.height, self.width
        out = {
            "rgb": np.empty((N, H, W, 3), np.uint8),
            "depth": np.empty((N, H, W), np.float32),
            "seg": np.empty((N, H, W), np.uint8),
            "worm_mask": np.empty((N, H, W), bool),
        }
        if normals:
            out["normals"] = np.empty((N, H, W, 3), np.float32)
        if N == 0:
            return out
        s = self._upload_scene(scene)
        T = min(self.threads, N)
        chunk = min(-(-N // T), self.max_chunk_images)
        pieces = [(start, min(N, start + chunk)) for start in range(0, N, chunk)]
        for slot in range(T):  # allocate every stream's buffers before any thread starts
            self._get_buffers(chunk, normals, slot)

        def stream(slot: int) -> None:
            for start, stop in pieces[slot::T]:
                res = self._render_chunk(s, cameras, start, stop, chunk, normals, slot)
                for k, v in res.items():
                    out[k][start:stop] = v

        if T == 1:
            stream(0)
        else:
            with ThreadPoolExecutor(T) as pool:
                for f in [pool.submit(stream, slot) for slot in range(T)]:
                    f.result()
        return out

    def _render_chunk(self, s: dict, cameras: Cameras, start: int, stop: int, chunk: int, normals: bool,
                      slot: int = 0) -> dict:
        n = stop - start
        b = self._get_buffers(chunk, normals, slot)
        intr = np.zeros((chunk, 4), np.float32)
        K = cameras.K[start:stop]
        intr[:n] = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2], K[:, 1, 2]], axis=1)
        rot = np.zeros((chunk, 3, 3), np.float32)
        rot[:n] = cameras.R[start:stop]
        trans = np.zeros((chunk, 3), np.float32)
        trans[:n] = cameras.t[start:stop]
        world = np.zeros(chunk, np.int32)
        world[:n] = cameras.world[start:stop]
        b["cam_intr"].assign(intr)
        b["cam_rot"].assign(rot)
        b["cam_trans"].assign(trans)
        b["image_world"].assign(world)
        b["zkey"].fill_(rk.EMPTY_KEY)
        b["mask"].zero_()
        d = self.device
        common = [b["image_world"], b["cam_rot"], b["cam_trans"], b["cam_intr"]]
        wp.launch(rk.raster_triangles, dim=(n, s["triangles"].shape[0]), device=d,
                  inputs=[s["triangles"], s["tri_label"], s["vertices"], *common, self.width, self.height, self.near],
                  outputs=[b["zkey"], b["mask"]])
        # CPU: a thread per image row (per-thread overhead and per-row setup paid once); GPU: a thread per pixel
        span = self.width if d.is_cpu else 1
        wp.launch(rk.resolve_shade, dim=(n, self.height, (self.width + span - 1) // span), device=d,
                  inputs=[s["triangles"], s["tri_label"], s["vertices"], s["texcoords"], *common, b["zkey"],
                          self.width, self.height, span,
                          s["albedo"], s["specular"], s["floor_normal"], s["floor_axis"], s["floor_half"],
                          s["floor_tex"], s["floor_color2"], s["paper_tex"], s["tex_seed"], s["ambient"],
                          s["sun_dir"], s["sun_color"], s["lamp_pos"], s["lamp_power"], s["bg_top"], s["bg_bottom"],
                          self._noise, int(normals)],
                  outputs=[b["rgb"], b["depth"], b["seg"], b["normals"]])
        H, W = self.height, self.width
        res = {
            "rgb": b["rgb"].numpy()[:n].reshape(n, H, W, 3),
            "depth": b["depth"].numpy()[:n].reshape(n, H, W),
            "seg": b["seg"].numpy()[:n].reshape(n, H, W),
            "worm_mask": b["mask"].numpy()[:n].reshape(n, H, W).astype(bool),
        }
        if normals:
            res["normals"] = b["normals"].numpy()[:n].reshape(n, H, W, 3)
        return res
