"""Host side of the batched rasterizer: uploads a :class:`SceneBatch` and :class:`Cameras` and renders every image
of the batch on the device in one pass, from the z-buffers to the finished 8-bit pixels.

Usage::

    renderer = Renderer(128, 128, device="cpu")
    out = renderer.render(scene, cameras)          # dict of NumPy arrays
    out["rgb"]    # (N, H, W, 3) uint8
    out["depth"]  # (N, H, W) float32, camera z [m], 0 = background
    out["seg"]    # (N, H, W) uint8, ids of docs/render.md
    out["worm_mask"]  # (N, H, W) bool, worm silhouette ignoring occluders (for the visible fraction)
    dev = renderer.render(scene, cameras, out="device")   # the same as wp.arrays that stay on the device

A batch costs a fixed number of launches whatever its size: the shadow maps (with ``shadows``), the raster pass
(one z-buffer at pixel centres, and one ``supersample`` times finer for colour when supersampling or through a
lens), one resolve pass (labels and colour of every pixel: :mod:`~warpworm.render.raster_kernels` for plain
pinhole images, :mod:`~warpworm.render.sample_kernels` for supersampled or lens images) and, given ``sensor``
values, three sensor launches (:mod:`~warpworm.render.sensor_kernels`). The host copies the finished batch once
(``out="host"``); a JPEG round trip, the one effect that needs a library, runs there afterwards
(:func:`~warpworm.render.sensor.jpeg_round_trip`). Very large batches are split into chunks of at most
``max_chunk_pixels`` z-buffer pixels so device memory stays bounded.

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
from warpworm.render import sample_kernels as sk
from warpworm.render import sensor_kernels as snk
from warpworm.render import shadow_kernels as shk
from warpworm.render.raster_math import EMPTY_KEY, NOISE_SIZE, SEG_FLOOR
from warpworm.render.shading import Look
from warpworm.render.camera import Cameras
from warpworm.render.distortion import lens_margins
from warpworm.render.scene import SceneBatch
from warpworm.render.sensor import SensorBatch, jpeg_round_trip, launch_sensor


def _vec_array(a, dtype, device):
    return wp.array(np.ascontiguousarray(a, dtype=np.float32), dtype=dtype, device=device)


def lit_lights(power) -> np.ndarray:
    """Which point lights of ``power`` (..., L, 3) are lit: non-zero as the kernels read it (float32,
    :func:`~warpworm.render.shadow_kernels.is_dark`), shape (..., L)."""
    return np.any(np.asarray(power).astype(np.float32) != 0, axis=-1)


def lit_first(pos, power, size) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point lights ``pos`` (Wa, L, 3), ``power`` (Wa, L, 3), ``size`` (Wa, L) with each row's lit lights first, in
    their order, and the slots dark in every row dropped (one kept): the kernels skip a dark light (zero power as
    float32, :func:`~warpworm.render.shadow_kernels.is_dark`) and sum the others in this order, so the images are the
    same, while the light loops and the shadow maps (:func:`shadow_cameras`) pay only for lit lights."""
    pos, power, size = np.asarray(pos), np.asarray(power), np.asarray(size)
    lit = lit_lights(power)  # (Wa, L)
    order = np.argsort(~lit, axis=1, kind="stable")[:, :max(1, int(lit.sum(axis=1).max(initial=0)))]
    return (np.take_along_axis(pos, order[..., None], axis=1), np.take_along_axis(power, order[..., None], axis=1),
            np.take_along_axis(size, order, axis=1))


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


def plain_look(a) -> bool:
    """True when appearance ``a`` uses no per-pixel shading option (several lights, the paper BSDF, a glossy or clear
    plate), so that the plain resolve kernel
    (:func:`raster_kernels.make_resolve_shade`) renders it bit for bit: exactly one point light per world and it lit,
    no paper BSDF, no clear (transmitting) or glossy floor. Judged on the float32 values the kernels read."""
    f32 = lambda v: np.asarray(v, dtype=np.float32)  # noqa: E731
    power, pb = f32(a.light_power), f32(a.paper_bsdf)
    return bool(power.shape[1] == 1 and np.all(np.any(power != 0, axis=-1))
                and not np.any((pb[..., 0] > 0) | (pb[..., 1] > 0) | (pb[..., 3] > 0))
                and not np.any(f32(a.floor_transmit) > 0)
                and not np.any(f32(a.specular)[:, SEG_FLOOR, 0] > 0))


class Renderer:
    """Off-screen z-buffer rasterizer for batches of (world, camera) images, on any Warp device."""

    def __init__(self, width: int, height: int, *, device=None, near: float = 1e-3,
                 max_chunk_pixels: int = 1 << 23, threads: int = 1, shadows: bool = False, shadow_map: int = 0,
                 supersample: int = 1, texture_filter: bool = True):
        """
        Args:
            width, height: image size [px].
            device: Warp device ("cpu", "cuda:0", ...); default Warp's default device.
            near: triangles with a vertex closer than this to the camera plane [m] are skipped.
            max_chunk_pixels: largest number of pixels rendered per launch pair (per thread).
            threads: CPU only: render this many chunks concurrently (one core each); ignored on CUDA.
            shadows: shadows from the sun and every point light (a ``shadow_map`` x ``shadow_map`` depth map per
                light and world, rasterized by the same pass; soft by percentage-closer filtering).
            supersample: s > 1 anti-aliases RGB: each pixel is the mean (in linear RGB) of s x s samples on a regular
                grid over its square, from a z-buffer s times finer (samples on one surface share its lighting, with
                their mean albedo); depth, segmentation, the worm mask and normals still come from the pixel centre
                (the s = 1 pass, bit for bit).
            texture_filter: with s > 1, a pixel whose samples all see the floor takes the floor texture's mean over
                its footprint (the checker's exact box average, the grain at the centre) instead of s x s texture
                samples, lit at its first sample as before: the same picture for less than a third of the work
                (most of an image is floor). False: every pixel sampled s x s.
            shadow_map: side [px] of each shadow map; 0: ``max(width, height)`` (the map fits the shadow casters,
                so a texel is then about a pixel of an image framing the worm).
        """
        wp.init()
        self.width = int(width)
        self.height = int(height)
        self.device = wp.get_device(device)
        self.near = float(near)
        self.max_chunk_images = max(1, int(max_chunk_pixels) // (self.width * self.height))
        self.threads = max(1, int(threads)) if self.device.is_cpu else 1
        self.max_chunk_pixels = int(max_chunk_pixels)
        self.shadows = bool(shadows)
        if int(shadow_map) < 0:
            raise ValueError(f"shadow_map: got {shadow_map}; expected a side [px] >= 1, or 0 for the image's")
        self.shadow_map = int(shadow_map) or max(self.width, self.height)
        if int(supersample) < 1:
            raise ValueError(f"supersample: got {supersample}; expected samples per pixel side >= 1")
        self.supersample = int(supersample)
        self.texture_filter = bool(texture_filter)
        self._buffers: dict = {}
        self._maps: dict = {}
        self._no_mask = wp.empty((1, 1), dtype=wp.uint8, device=self.device)  # raster_depth's unused silhouette
        self._no_tiles = wp.empty((1, 1), dtype=float, device=self.device)  # raster_triangles' unused block minima
        # load the kernels once here: concurrent first launches from several threads would race to load them
        for module in (rk, shk, snk):
            wp.load_module(module, device=self.device)
        self._noise = wp.array(bake_noise(NOISE_SIZE), dtype=float, device=self.device)

    # -- uploads -------------------------------------------------------------------------------------------------------

    def _upload_scene(self, scene: SceneBatch) -> dict:
        d = self.device
        a = scene.appearance
        look = Look()
        look.albedo = _vec_array(a.albedo, wp.vec3, d)
        look.specular = _vec_array(a.specular, wp.vec2, d)
        look.floor_normal = _vec_array(scene.floor_normal, wp.vec3, d)
        look.floor_axis = _vec_array(scene.floor_axis, wp.vec3, d)
        look.floor_origin = _vec_array(scene.floor_origin, wp.vec3, d)
        look.floor_half = wp.array(np.asarray(scene.floor_half, dtype=np.float32), dtype=float, device=d)
        look.floor_tex = _vec_array(a.floor_tex, wp.vec4, d)
        look.floor_color2 = _vec_array(a.floor_color2, wp.vec3, d)
        look.paper_tex = _vec_array(a.paper_tex, wp.vec2, d)
        look.tex_seed = wp.array(np.asarray(a.tex_seed, dtype=np.int32), dtype=wp.int32, device=d)
        look.bg_top = _vec_array(a.bg_top, wp.vec3, d)
        look.bg_bottom = _vec_array(a.bg_bottom, wp.vec3, d)
        look.noise = self._noise
        look.floor_transmit = wp.array(np.asarray(a.floor_transmit, dtype=np.float32), dtype=float, device=d)
        look.paper_bsdf = _vec_array(a.paper_bsdf, wp.vec4, d)
        pos, power, size = lit_first(a.light_pos, a.light_power, a.light_size)
        light_arrays = {
            "ambient": _vec_array(a.ambient, wp.vec3, d), "sun_dir": _vec_array(a.sun_dir, wp.vec3, d),
            "sun_color": _vec_array(a.sun_color, wp.vec3, d), "pos": _vec_array(pos, wp.vec3, d),
            "power": _vec_array(power, wp.vec3, d), "size": wp.array(size.astype(np.float32), dtype=float, device=d),
        }
        return {
            "triangles": wp.array(np.ascontiguousarray(scene.triangles, dtype=np.int32), dtype=wp.vec3i, device=d),
            "tri_label": wp.array(np.ascontiguousarray(scene.tri_label, dtype=np.int32), dtype=wp.int32, device=d),
            "vertices": _vec_array(scene.vertices, wp.vec3, d),
            "texcoords": _vec_array(scene.texcoords, wp.vec3, d),
            "look": look, "light_arrays": light_arrays, "lights": self._lights(light_arrays, None), "scene": scene,
            "shade": rk.resolve_shade_plain if not self.shadows and plain_look(a) else rk.resolve_shade,
        }

    def _get_buffers(self, n: int, grid: tuple, sub: int, slot: int = 0) -> dict:
        """Scratch buffers of one chunk stream: ``n`` images on a label grid ``grid`` = (width, height) and, for
        ``sub`` > 0, a sample grid ``sub`` times finer. Only the current batch shape's buffers are kept."""
        key = (n, grid, sub, slot)
        if key not in self._buffers:
            d = self.device
            gw, gh = grid
            self._buffers = {k: v for k, v in self._buffers.items() if k[:3] == (n, grid, sub)}
            fine = gw * gh * sub * sub if sub else 1
            self._buffers[key] = {
                "zkey": wp.empty((n, gw * gh), dtype=wp.int64, device=d),
                "mask": wp.empty((n, gw * gh), dtype=wp.uint8, device=d),
                "fine_key": wp.empty((n, fine), dtype=wp.int64, device=d),
                "fine_mask": wp.empty((n, fine), dtype=wp.uint8, device=d),  # written by the raster pass, unread
                "image_world": wp.empty(n, dtype=wp.int32, device=d),
                "cam_rot": wp.empty(n, dtype=wp.mat33, device=d),
                "cam_trans": wp.empty(n, dtype=wp.vec3, device=d),
                "cam_intr": wp.empty(n, dtype=wp.vec4, device=d),
                "cam_margin": wp.empty(n, dtype=wp.vec3i, device=d),
                "fine_intr": wp.empty(n, dtype=wp.vec4, device=d),
                "cam_dist": wp.zeros(n, dtype=wp.vec4, device=d),
                "cam_k3": wp.zeros(n, dtype=float, device=d),
                "cam_gain": wp.empty(n, dtype=wp.vec3, device=d),
            }
        return self._buffers[key]

    def _lights(self, arrays: dict, maps: dict | None) -> shk.Lights:
        """The kernel's :class:`Lights` from uploaded light arrays and, when shadows are on, a chunk's maps."""
        d = self.device
        lights = shk.Lights()
        for name, arr in arrays.items():
            setattr(lights, name, arr)
        lights.shadows = 0 if maps is None else 1
        lights.map_side = self.shadow_map
        lights.map_tiles = -(-self.shadow_map // shk.SHADOW_TILE)
        if maps is None:  # never read: placeholders
            maps = {"first": wp.zeros(1, dtype=wp.int32, device=d), "depth": wp.zeros((1, 1), dtype=float, device=d),
                    "rot": wp.zeros(1, dtype=wp.mat33, device=d), "trans": wp.zeros(1, dtype=wp.vec3, device=d),
                    "intr": wp.zeros(1, dtype=wp.vec4, device=d), "size": wp.zeros(1, dtype=float, device=d),
                    "pair_min": wp.zeros((1, 1), dtype=float, device=d),
                    "reach": wp.zeros((1, 1), dtype=float, device=d), "floor": wp.zeros(1, dtype=wp.mat44, device=d)}
        lights.map_first, lights.map_depth, lights.map_rot = maps["first"], maps["depth"], maps["rot"]
        lights.map_trans, lights.map_intr, lights.map_light_size = maps["trans"], maps["intr"], maps["size"]
        lights.map_pair_min, lights.map_reach, lights.map_floor = maps["pair_min"], maps["reach"], maps["floor"]
        return lights

    def _map_buffers(self, M: int, slot: int) -> dict:
        """Scratch arrays for ``M`` shadow maps of chunk stream ``slot`` (views of buffers kept between chunks and
        batches, grown when a chunk needs more maps: fresh host memory would be paged in for every chunk)."""
        S = self.shadow_map
        tiles = -(-S // shk.SHADOW_TILE)
        buf = self._maps.get(slot)
        if buf is None or buf["depth"].shape[0] < M:
            d = self.device
            buf = {"depth": wp.empty((M, S * S), dtype=float, device=d),
                   "tile_min": wp.empty((M, tiles * tiles), dtype=float, device=d),
                   "pair_min": wp.empty((M, tiles * tiles), dtype=float, device=d),
                   "reach": wp.empty((M, tiles * tiles), dtype=float, device=d)}
            self._maps[slot] = buf
        return {k: v[:M] for k, v in buf.items()}

    def _shadow_maps(self, s: dict, worlds: np.ndarray, slot: int = 0) -> shk.Lights:
        """The scene's :class:`Lights` with the shadow maps of ``worlds`` (unique scene world ids) rasterized: one
        map for the sun and one per point light of each world (:func:`shadow_cameras`)."""
        d, S = self.device, self.shadow_map
        scene = s["scene"]
        cams = shadow_cameras(scene, worlds, S)
        M = len(cams["world"])
        first = np.full(scene.num_worlds, -1, np.int32)
        first[worlds] = cams["first"]
        buf = self._map_buffers(M, slot)
        buf["depth"].fill_(shk.NO_CASTER)
        buf["tile_min"].fill_(shk.NO_CASTER)
        maps = {"first": wp.array(first, dtype=wp.int32, device=d), "depth": buf["depth"],
                "rot": _vec_array(cams["R"], wp.mat33, d), "trans": _vec_array(cams["t"], wp.vec3, d),
                "intr": _vec_array(cams["intr"], wp.vec4, d),
                "size": wp.array(cams["size"].astype(np.float32), dtype=float, device=d),
                "floor": wp.array(floor_projection(cams["R"], cams["t"], cams["intr"],
                                                   scene.floor_normal[cams["world"]]), dtype=wp.mat44, device=d)}
        wp.launch(rk.raster_depth, dim=(M, s["triangles"].shape[0]), device=d,
                  inputs=[s["triangles"], s["tri_label"], s["vertices"],
                          wp.array(cams["world"].astype(np.int32), dtype=wp.int32, device=d), maps["rot"],
                          maps["trans"], maps["intr"], S, S, self.near],
                  outputs=[maps["depth"], self._no_mask, buf["tile_min"]])
        tiles = -(-S // shk.SHADOW_TILE)
        maps["tile_min"] = buf["tile_min"]
        maps["reach"] = buf["reach"]
        maps["pair_min"] = buf["pair_min"]
        wp.launch(shk.shadow_reach_min, dim=(M, tiles * tiles), device=d, inputs=[maps["tile_min"], tiles],
                  outputs=[maps["reach"], maps["pair_min"]])
        return self._lights(s["light_arrays"], maps)

    # -- rendering -----------------------------------------------------------------------------------------------------

    def render(self, scene: SceneBatch, cameras: Cameras, *, normals: bool = False, sensor: SensorBatch | None = None,
               out: str = "host") -> dict:
        """Render every camera of ``cameras`` (image i shows world ``cameras.world[i]``).

        Args:
            normals: also write camera-frame normals.
            sensor: per-image sensor effects (:class:`~warpworm.render.sensor.SensorBatch`) applied on the device
                before the copy; its JPEG round trips (quality in 1..99) run on the host afterwards, so they need
                ``out="host"``.
            out: ``"host"`` (NumPy arrays) or ``"device"`` (``wp.array``s on the renderer's device, nothing copied:
                ``wp.to_torch`` hands them to PyTorch without a copy).

        Returns:
            dict: ``rgb`` (N, H, W, 3) uint8; ``depth`` (N, H, W) float32 camera z [m], 0 for background; ``seg``
            (N, H, W) uint8; ``worm_mask`` (N, H, W) bool (worm silhouette, occluders ignored); ``normals``
            (N, H, W, 3) float32 camera-frame unit normals (0 for background) when ``normals=True``. With
            ``out="device"``: ``rgb`` vec3ub (N, H, W), ``depth`` float32, ``seg`` and ``worm_mask`` uint8 (N, H, W),
            ``normals`` vec3 (N, H, W).
        """
        if out not in ("host", "device"):
            raise ValueError(f"out: got {out!r}; expected 'host' or 'device'")
        if cameras.width != self.width or cameras.height != self.height:
            raise ValueError(f"cameras are {cameras.width}x{cameras.height}, renderer is {self.width}x{self.height}")
        if len(cameras) and (cameras.world.min() < 0 or cameras.world.max() >= scene.num_worlds):
            raise ValueError(f"cameras.world must index the scene's {scene.num_worlds} worlds")
        if np.any(np.abs(cameras.K[:, 0, 1]) > 0):
            raise ValueError("skewed intrinsics (K[0, 1] != 0) are not supported")
        N, H, W = len(cameras), self.height, self.width
        if sensor is not None and len(sensor) != N:
            raise ValueError(f"sensor: {len(sensor)} images' values for {N} cameras; expected one per camera")
        if sensor is not None and out == "device" and sensor.needs_jpeg():
            raise ValueError("sensor: a JPEG round trip (jpeg_quality 1..99) runs on the host; expected out='host' "
                             "or jpeg_quality 0")
        lens = cameras.dist is not None and bool(np.any(np.asarray(cameras.dist) != 0))
        # each camera's own widening (its image must not depend on the batch it is in), the grids sized for the widest
        if lens and N:
            left, top, gws, ghs = lens_margins(cameras, self.device)
        else:
            left, top, gws, ghs = np.zeros(N, int), np.zeros(N, int), np.full(N, W), np.full(N, H)
        margins = np.stack([left, top, ghs], axis=1).astype(np.int32)  # (left, top, grid height) per camera [px]
        gw, gh = int(gws.max(initial=W)), int(ghs.max(initial=H))
        sub = self.supersample if (self.supersample > 1 or lens) else 0  # 0: the plain pixel-centre path
        d = self.device
        res = {"rgb": wp.empty((N, H * W), dtype=wp.vec3ub, device=d),
               "depth": wp.empty((N, H * W), dtype=float, device=d),
               "seg": wp.empty((N, H * W), dtype=wp.uint8, device=d),
               "worm_mask": wp.empty((N, H * W), dtype=wp.uint8, device=d),
               "normals": wp.empty((N, H * W) if normals else (1, 1), dtype=wp.vec3, device=d)}
        if N:
            s = self._upload_scene(scene)
            T = min(self.threads, N)
            per_image = gw * gh * (1 + sub * sub)
            if self.shadows:  # the chunk's shadow maps (a world per image at most) count against max_chunk_pixels
                per_image += (1 + scene.appearance.light_pos.shape[1]) * self.shadow_map ** 2
            chunk = max(1, min(-(-N // T), self.max_chunk_pixels // per_image))
            pieces = [(start, min(N, start + chunk)) for start in range(0, N, chunk)]
            for slot in range(T):  # allocate every stream's buffers before any thread starts
                self._get_buffers(chunk, (gw, gh), sub, slot)
            # the sample resolve this batch takes (None: the plain pixel-centre path), loaded before any stream
            resolve = sk.resolve_samples_kernel(sub, lens, normals, self.texture_filter) if sub else None
            if resolve is not None:
                wp.load_module(resolve.module, device=d)
            view = (margins, gw, gh, sub, lens, resolve)

            def stream(slot: int) -> None:
                for start, stop in pieces[slot::T]:
                    self._render_chunk(s, cameras, view, start, stop, chunk, normals, slot, res, sensor)

            if T == 1:
                stream(0)
            else:
                with ThreadPoolExecutor(T) as pool:
                    for f in [pool.submit(stream, slot) for slot in range(T)]:
                        f.result()
        if not normals:
            del res["normals"]
        if out == "device":
            return {k: v.reshape((N, H, W)) for k, v in res.items()}
        host = {"rgb": res["rgb"].numpy().reshape(N, H, W, 3), "depth": res["depth"].numpy().reshape(N, H, W),
                "seg": res["seg"].numpy().reshape(N, H, W),
                "worm_mask": res["worm_mask"].numpy().reshape(N, H, W).astype(bool)}
        if normals:
            host["normals"] = res["normals"].numpy().reshape(N, H, W, 3)
        if sensor is not None and sensor.needs_jpeg():
            host["rgb"] = jpeg_round_trip(host["rgb"], sensor.jpeg_quality)
        return host

    def _render_chunk(self, s: dict, cameras: Cameras, view: tuple, start: int, stop: int, chunk: int, normals: bool,
                      slot: int, res: dict, sensor: SensorBatch | None) -> None:
        """Images ``start:stop`` into the outputs ``res`` (device arrays (N, H*W)): camera uploads, shadow maps,
        raster pass(es), resolve, sensor."""
        margins, gw, gh, sub, lens, resolve = view
        n = stop - start
        b = self._get_buffers(chunk, (gw, gh), sub, slot)
        K = cameras.K[start:stop]
        margin = np.zeros((chunk, 3), np.int32)
        margin[:n] = margins[start:stop]
        intr = np.zeros((chunk, 4), np.float32)
        intr[:n] = np.stack([K[:, 0, 0], K[:, 1, 1], K[:, 0, 2] + margin[:n, 0], K[:, 1, 2] + margin[:n, 1]], axis=1)
        rot = np.zeros((chunk, 3, 3), np.float32)
        rot[:n] = cameras.R[start:stop]
        trans = np.zeros((chunk, 3), np.float32)
        trans[:n] = cameras.t[start:stop]
        world = np.zeros(chunk, np.int32)
        world[:n] = cameras.world[start:stop]
        gain = np.ones((chunk, 3), np.float32)
        if cameras.gain is not None:
            gain[:n] = cameras.gain[start:stop]
        b["cam_intr"].assign(intr)
        b["cam_margin"].assign(margin)
        b["cam_gain"].assign(gain)
        b["cam_rot"].assign(rot)
        b["cam_trans"].assign(trans)
        b["image_world"].assign(world)
        d = self.device
        out = {k: v[start:stop] for k, v in res.items() if k != "normals" or normals}
        out_normals = out["normals"] if normals else res["normals"]  # else a 1-element dummy, never written
        lights = s["lights"]
        if self.shadows:
            lights = self._shadow_maps(s, np.unique(world[:n]), slot)
        common = [b["image_world"], b["cam_rot"], b["cam_trans"]]
        tris = s["triangles"].shape[0]
        if sub == 0:  # plain pinhole images: raster at pixel centres straight into the outputs, resolve and shade
            b["zkey"].fill_(EMPTY_KEY)
            out["worm_mask"].zero_()
            wp.launch(rk.raster_triangles, dim=(n, tris), device=d,
                      inputs=[s["triangles"], s["tri_label"], s["vertices"], *common, b["cam_intr"], gw, gh,
                              self.near],
                      outputs=[b["zkey"], out["worm_mask"], self._no_tiles])
            # CPU: a thread per image row (per-thread overhead and per-row setup paid once); GPU: a thread per pixel
            span = self.width if d.is_cpu else 1
            wp.launch(s["shade"], dim=(n, self.height, (self.width + span - 1) // span), device=d,
                      inputs=[s["triangles"], s["tri_label"], s["look"], lights, s["vertices"], s["texcoords"],
                              *common, b["cam_intr"], b["zkey"], self.width, self.height, span, int(normals),
                              b["cam_gain"]],
                      outputs=[out["rgb"], out["depth"], out["seg"], out_normals])
        else:  # supersampled and/or through a lens: a label grid, a sample grid, one resolve of both
            fine = np.zeros((chunk, 4), np.float32)
            fine[:n] = intr[:n] * sub
            fine[:n, 2:] += 0.5 * (sub - 1)
            b["fine_intr"].assign(fine)
            if lens:
                dist = np.zeros((chunk, 5), np.float32)
                dist[:n] = cameras.dist[start:stop]
                b["cam_dist"].assign(np.ascontiguousarray(dist[:, :4]))
                b["cam_k3"].assign(np.ascontiguousarray(dist[:, 4]))
            b["zkey"].fill_(EMPTY_KEY)
            b["mask"].zero_()
            b["fine_key"].fill_(EMPTY_KEY)
            wp.launch(rk.raster_triangles, dim=(n, tris), device=d,
                      inputs=[s["triangles"], s["tri_label"], s["vertices"], *common, b["cam_intr"], gw, gh,
                              self.near],
                      outputs=[b["zkey"], b["mask"], self._no_tiles])
            wp.launch(rk.raster_triangles, dim=(n, tris), device=d,
                      inputs=[s["triangles"], s["tri_label"], s["vertices"], *common, b["fine_intr"], gw * sub,
                              gh * sub, self.near],
                      outputs=[b["fine_key"], b["fine_mask"], self._no_tiles])
            span = self.width if d.is_cpu else 1
            wp.launch(resolve, dim=(n, self.height, (self.width + span - 1) // span), device=d,
                      inputs=[s["triangles"], s["tri_label"], s["look"], lights, s["vertices"], s["texcoords"],
                              *common, b["cam_intr"], b["cam_dist"], b["cam_k3"], b["cam_gain"], b["fine_intr"],
                              b["zkey"], b["mask"], b["fine_key"], self.width, self.height, span, gw, gh,
                              b["cam_margin"]],
                      outputs=[out["rgb"], out["depth"], out["seg"], out["worm_mask"], out_normals])
        if sensor is not None:
            if "sensor" not in b:
                b["sensor"] = tuple(wp.empty((chunk, self.width * self.height), dtype=wp.vec3, device=d)
                                    for _ in range(2))
            launch_sensor(out["rgb"], sensor.take(slice(start, stop)), self.width, self.height, d, b["sensor"])


def shadow_cameras(scene: SceneBatch, worlds: np.ndarray, side: int) -> dict:
    """Pinhole cameras of the shadow maps of ``worlds``: world-major, each world's sun, then its lit point lights in
    :func:`lit_first` order (the dark ones, which no kernel looks up, get none), each looking from its light at the
    centre of the world's meshes above the floor plane and just covering their bounding sphere (radius r). The
    directional sun is a point light ``max(100 r, 1 m)`` away along ``sun_dir`` (its rays then within r / 100 rad of
    parallel), of radius ``sun_size`` (angular, rad) times that distance.

    Returns dict over the M maps: ``world`` (M,), ``R`` (M, 3, 3), ``t`` (M, 3), ``intr`` (M, 4) = (fx, fy, cx, cy)
    [px], ``size`` (M,) light radius [m]; and ``first`` (len(worlds),): each world's sun map (its point light i is
    map ``first + 1 + i``). A light inside the sphere gets a 160 degree field of view (its map sees what it can).
    """
    from warpworm.render.camera import look_at

    a = scene.appearance
    worlds = np.asarray(worlds, dtype=np.int64)
    v = scene.vertices[worlds].astype(np.float64)  # (n, V, 3)
    # casters: what is above the floor plane (the opaque floor hides the rest and what it could shade), else all
    above = np.einsum("nvk,nk->nv", v, scene.floor_normal[worlds]) > -1e-4
    above |= ~above.any(axis=1, keepdims=True)
    big = np.where(above[..., None], 0.0, np.inf)
    lo, hi = (v + big).min(axis=1), (v - big).max(axis=1)
    centre = 0.5 * (lo + hi)
    radius = np.maximum(np.where(above, np.linalg.norm(v - centre[:, None], axis=2), 0.0).max(axis=1), 1e-4)
    light_pos, light_power, light_size = lit_first(a.light_pos, a.light_power, a.light_size)
    L = light_pos.shape[1]
    sun_d = np.maximum(100.0 * radius, 1.0)
    sun = a.sun_dir[worlds % a.sun_dir.shape[0]]
    eye = np.concatenate([(centre + sun * sun_d[:, None])[:, None], light_pos[worlds % light_pos.shape[0]]],
                         axis=1)  # (n, 1 + L, 3)
    size = np.concatenate([(np.tan(a.sun_size[worlds % a.sun_size.shape[0]]) * sun_d)[:, None],
                           light_size[worlds % light_size.shape[0]]], axis=1)
    tgt = np.broadcast_to(centre[:, None], eye.shape)
    dist = np.linalg.norm(eye - tgt, axis=2)
    half = np.where(dist > radius[:, None] * 1.01, np.arcsin(np.minimum(radius[:, None] / np.maximum(dist, 1e-9),
                                                                        0.999)), np.deg2rad(80.0))
    R, t = look_at(eye.reshape(-1, 3), tgt.reshape(-1, 3))
    f = 0.5 * side / np.tan(half.reshape(-1))
    c = np.full_like(f, (side - 1) / 2)
    # a map for the sun and each lit light (lit first: a world's dark slots are its last)
    lit = np.concatenate([np.ones((len(worlds), 1), bool), lit_lights(light_power[worlds % light_power.shape[0]])],
                         axis=1)
    keep = lit.reshape(-1)
    count = lit.sum(axis=1)
    return {"world": np.repeat(worlds, 1 + L)[keep], "R": R[keep], "t": t[keep],
            "intr": np.stack([f, f, c, c], axis=1)[keep], "size": size.reshape(-1)[keep],
            "first": (np.cumsum(count) - count).astype(np.int32)}


def floor_projection(R, t, intr, floor_normal) -> np.ndarray:
    """Each shadow map's projection of its world's floor plane (M, 4, 4) float32: rows (u·c, v·c, c, z) of (p, 1)
    for a floor point p [m], c its depth in the map camera, (u, v) the texel position and z the depth [m] that
    :func:`~warpworm.render.shadow_kernels.light_visibility` finds for p with normal ``floor_normal``: on a plane its
    offset along the normal (1.5 texels) and its bias (one texel) are linear in c.

    ``R`` (M, 3, 3), ``t`` (M, 3), ``intr`` (M, 4) = (fx, fy, cx, cy): the maps' cameras (fx = 0: a dark light's
    map, never read: zeros); ``floor_normal`` (M, 3): the floor normal of each map's world."""
    R = np.asarray(R, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)
    k = np.asarray(intr, dtype=np.float64)
    live = k[:, 0] != 0.0
    f = np.where(live, k[:, 0], 1.0)
    rn = np.einsum("mij,mj->mi", R, np.asarray(floor_normal, dtype=np.float64))
    # offset point: pc + rn * 1.5 * c / f, so its depth is c * s_w and its x, y are pc_xy + a_xy * c
    a = 1.5 * rn / f[:, None]
    s_w = 1.0 + a[:, 2]
    rows = np.concatenate([R, t[:, :, None]], axis=2)  # (M, 3, 4): pc = rows @ (p, 1)
    out = np.zeros((len(R), 4, 4))
    for i, (fi, ci) in enumerate(((k[:, 0], k[:, 2]), (k[:, 1], k[:, 3]))):
        # u = f (pc_x + a_x c) / (s_w c) + cx = [(f / s_w) pc_x + (f a_x / s_w + cx) c] / c
        out[:, i] = (fi / s_w)[:, None] * rows[:, i] + (fi * a[:, i] / s_w + ci)[:, None] * rows[:, 2]
    out[:, 2] = rows[:, 2]
    out[:, 3] = (s_w - 1.0 / f)[:, None] * rows[:, 2]  # z = c s_w - c / f
    out[~live] = 0.0
    return out.astype(np.float32)
