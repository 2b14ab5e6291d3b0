"""A small deterministic *test double* for the pipeline's two heavy stages (simulation, rendering).

It is not a simulator: it moves a strip-shaped "worm" along +x as a closed-form function of the drawn parameters and
"renders" its projected bounding box, so the I/O machinery (config, randomization, sharding, resume, readers, exports)
can be tested in milliseconds and independently of the physics. It returns exactly the keys the real stages return.

Knobs for tests, read from the environment (so they reach spawned workers and subprocesses):
* ``WARPWORM_FAKE_SLEEP``: seconds to sleep per simulated batch (to catch a job mid-shard);
* worlds whose ``hinge_stiffness`` exceeds ``WARPWORM_FAKE_UNSTABLE_ABOVE`` (default 0.9) report unstable.
"""

from __future__ import annotations

import os
import time

import numpy as np

from warpworm import transforms as tf
from warpworm.data.stages import SimResult

KEYPOINT_NAMES = ["seg0", "seg1", "seg2", "seg3", "seg4", "tail", "head"]


def _topology(n: int):
    V = 2 * (n + 1)
    tris, edges = [], set()
    for i in range(n):
        a, b, c, d = 2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3
        tris += [(a, c, b), (b, c, d)]
        for e in ((a, b), (a, c), (b, c), (b, d), (c, d)):
            edges.add(tuple(sorted(e)))
    hinges = np.array([(2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 5 if 2 * i + 5 < V else 2 * i + 1) for i in range(n)],
                      np.int32)
    tri = np.array(tris, np.int32)
    seg = np.minimum((np.arange(len(tri)) // 2) * 5 // n, 4).astype(np.int32)
    return V, tri, np.array(sorted(edges), np.int32), hinges, seg


class FakeStages:
    """Deterministic closed-form stand-in for :class:`warpworm.data.warp_stages.WarpStages` (tests only)."""

    def metadata(self, cfg):
        V, tri, edges, hinges, seg = _topology(cfg.sim.n_units)
        return {"keypoint_names": KEYPOINT_NAMES, "triangles": tri, "triangle_segment": seg, "hinges": hinges,
                "hinge_label": np.full(len(hinges), 2, np.int8), "edges": edges, "num_vertices": V}

    def simulate_batch(self, params, num_worlds, cfg):
        time.sleep(float(os.environ.get("WARPWORM_FAKE_SLEEP", "0")))
        n = cfg.sim.n_units
        V, tri, edges, hinges, _ = _topology(n)
        B = num_worlds
        a = np.broadcast_to(np.asarray(params.a, float), (B,))
        l0 = np.broadcast_to(np.asarray(params.l0, float), (B,))
        k = np.broadcast_to(np.asarray(params.hinge_stiffness, float), (B,))
        w = np.broadcast_to(np.asarray(params.wavelength, float), (B,))
        T = np.broadcast_to(np.asarray(params.cycle_period, float), (B,))
        i = np.arange(V) // 2
        side = np.where(np.arange(V) % 2 == 0, -0.5, 0.5)
        rest = np.stack([l0[:, None] * (i[None] / n - 0.5), a[:, None] * side[None], np.full((B, V), 0.002)], -1)
        frames = []
        for t in cfg.sim.frame_times:
            pos = rest.copy()
            pos[..., 0] += (w * t / T)[:, None] * (1 + 0.1 * np.sin(2 * np.pi * t))
            pos[..., 2] += 0.001 * np.sin(2 * np.pi * t + i[None] * k[:, None])
            mpos = np.zeros((B, 4, 3))
            mpos[:, 0] = pos[:, V // 2] + np.array([0, 0, 0.03])
            mpos[:, 1], mpos[:, 2], mpos[:, 3] = pos[:, 0], pos[:, V // 2], pos[:, -1]
            mrot = np.broadcast_to(tf.axis_angle_to_matrix([0, 0, 1], 0.1 * t), (B, 4, 3, 3)).copy()
            frames.append({
                "positions": pos, "magnet_pos": mpos, "magnet_rot": mrot,
                "crease_angle": np.sin(t + np.arange(len(hinges))[None] * k[:, None]),
                "bar_strain": 1e-3 * np.cos(t + np.arange(len(edges))[None] * k[:, None]),
            })
        unstable = k > float(os.environ.get("WARPWORM_FAKE_UNSTABLE_ABOVE", "0.9"))
        return SimResult(frames=frames, unstable=unstable)

    def render_batch(self, frame, draws, cfg):
        cameras, appearance, seeds = draws.cameras, draws.appearance, draws.seeds
        B = len(seeds)
        H, W = cameras.height, cameras.width
        pos = frame["positions"]
        pc = np.einsum("bij,bvj->bvi", cameras.R, pos) + cameras.t[:, None]
        uvw = np.einsum("bij,bvj->bvi", cameras.K, pc)
        uv = uvw[..., :2] / uvw[..., 2:3]
        lo, hi = uv.min(1), uv.max(1)
        u = np.arange(W, dtype=float)  # pixel centres at integers, as in OpenCV
        v = np.arange(H, dtype=float)
        mask = ((u[None, None, :] >= lo[:, 0, None, None]) & (u[None, None, :] <= hi[:, 0, None, None])
                & (v[None, :, None] >= lo[:, 1, None, None]) & (v[None, :, None] <= hi[:, 1, None, None]))
        frac = np.clip((u[None, None, :] - lo[:, 0, None, None]) / np.maximum(hi - lo, 1e-9)[:, 0, None, None], 0, 1)
        seg = np.where(mask, 2 + np.minimum((frac * 5).astype(np.int64), 4), 0).astype(np.uint8)
        depth = np.where(mask, pc[..., 2].mean(1)[:, None, None], 0).astype(np.float32)
        bg = (255 * appearance["color.background_value"]).astype(np.uint8)
        fg = (255 * appearance["color.worm_value"]).astype(np.uint8)
        rgb = np.where(mask[..., None], fg[:, None, None, None], bg[:, None, None, None]).repeat(3, -1)
        noise = np.stack([np.random.default_rng(int(s)).integers(0, 3, (H, W, 3), dtype=np.uint8) for s in seeds])
        rgb = (rgb + noise).astype(np.uint8)
        # keypoints: five segment centres (vertex groups along x), tail, head
        V = pos.shape[1]
        groups = np.array_split(np.arange(V), 5)
        kw = np.stack([pos[:, g].mean(1) for g in groups] + [pos[:, :2].mean(1), pos[:, -2:].mean(1)], 1)
        kc = np.einsum("bij,bpj->bpi", cameras.R, kw) + cameras.t[:, None]
        kuv = np.einsum("bij,bpj->bpi", cameras.K, kc)
        kpix = kuv[..., :2] / kuv[..., 2:3]
        # COCO visibility by the renderer's rule (docs/render.md) against this fake's own depth map: 0 behind the
        # camera or the rounded pixel outside, 2 where nothing lies more than 0.5 mm in front (or a worm pixel within
        # 1 cm: the keypoint's own surface), else 1
        px, py = np.rint(kpix[..., 0]), np.rint(kpix[..., 1])
        inside = (px >= 0) & (px < W) & (py >= 0) & (py < H) & (kc[..., 2] > 0)
        pxi, pyi = np.where(inside, px, 0).astype(int), np.where(inside, py, 0).astype(int)
        D = depth[np.arange(B)[:, None], pyi, pxi].astype(np.float64)
        L = seg[np.arange(B)[:, None], pyi, pxi]
        gap = kc[..., 2] - D
        visible = (D == 0) | (gap <= 5e-4) | ((gap <= 0.01) & (L >= 2) & (L <= 6))
        vis = np.where(inside, np.where(visible, 2, 1), 0).astype(np.uint8)
        body = tf.pose_matrix(np.broadcast_to(np.eye(3), (B, 3, 3)), pos.mean(1))
        mags = tf.pose_matrix(frame["magnet_rot"], frame["magnet_pos"])
        ys, xs = np.nonzero(mask.any(2)), None
        visib = np.zeros((B, 4), np.float32)
        any_px = mask.any((1, 2))
        rows = mask.any(2)
        cols = mask.any(1)
        y0 = np.argmax(rows, 1)
        y1 = H - np.argmax(rows[:, ::-1], 1)
        x0 = np.argmax(cols, 1)
        x1 = W - np.argmax(cols[:, ::-1], 1)
        visib[any_px] = np.stack([x0, y0, x1 - x0, y1 - y0], 1)[any_px]
        del ys, xs
        return {
            "rgb": rgb, "depth": depth, "segmentation": seg,
            "poses/body": body, "poses/ipm": mags[:, 1:4], "poses/epm": mags[:, 0],
            "poses/body_quat": tf.matrix_to_quat_wxyz(body[:, :3, :3]),
            "keypoints/world": kw, "keypoints/camera": kc, "keypoints/pixel": kpix,
            "keypoints/body": np.einsum("nji,npj->npi", body[:, :3, :3], kw - body[:, None, :3, 3]),
            "keypoints/visibility": vis,
            "creases/angle": frame["crease_angle"].astype(np.float32),
            "bars/strain": frame["bar_strain"].astype(np.float32),
            "worm/vertices": pos.astype(np.float32),
            "labels/bbox_obj": np.concatenate([lo, hi - lo], 1).astype(np.float32),
            "labels/bbox_visib": visib,
            "labels/visib_fract": any_px.astype(np.float32),
            "labels/deformation": np.ones((B, 4), np.float32),
            "labels/worm_mask": mask.astype(np.uint8),
        }
