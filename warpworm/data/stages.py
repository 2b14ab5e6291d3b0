"""The pipeline's two heavy stages (simulation, rendering) behind one small interface.

The job (:mod:`warpworm.data.job`) runs neither the simulator nor the renderer itself: it calls a *stages* object (see
:class:`Stages`) given as ``"module:attribute"`` so that worker processes can import it. The default,
:class:`warpworm.data.warp_stages.WarpStages`, is warpworm's simulator and renderer (loaded by :func:`load_stages`
when the shards run: the job's own modules never import the simulator); tests plug in a closed-form double.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from warpworm.data.config import DatasetConfig
from warpworm.data.sampling import RenderDraws
from warpworm.physics.params import WormParams

DEFAULT_STAGES = "warpworm.data.warp_stages:WarpStages"


@dataclass
class SimResult:
    """What :meth:`Stages.simulate_batch` returns for B worlds.

    frames: one snapshot dict per ``sim.frame_times`` entry, each with at least ``positions (B,V,3)``,
        ``magnet_pos (B,4,3)``, ``magnet_rot (B,4,3,3)``, ``crease_angle (B,H)``, ``bar_strain (B,E)`` [SI].
    unstable: (B,) bool: the world went unstable at some point (it is dropped and redrawn).
    """

    frames: list[dict[str, np.ndarray]]
    unstable: np.ndarray


class Stages(Protocol):
    """The two heavy stages of the pipeline (simulation, rendering), pluggable for tests and other engines."""

    def metadata(self, cfg: DatasetConfig) -> dict:
        """Static per-dataset facts: ``keypoint_names`` (P,), ``triangles (T,3)``, ``triangle_segment (T,)``,
        ``hinges (H,4)``, ``hinge_label (H,)``, ``edges (E,2)``, ``num_vertices``."""

    def simulate_batch(self, params: WormParams, num_worlds: int, cfg: DatasetConfig) -> SimResult:
        """Settle for ``sim.settle_time`` then drive the EPM paths; snapshots at ``sim.frame_times``."""

    def render_batch(self, frame: dict[str, np.ndarray], draws: RenderDraws,
                     cfg: DatasetConfig) -> dict[str, np.ndarray]:
        """Render B images of one snapshot per world and compute their labels.

        ``draws`` (:class:`warpworm.data.sampling.RenderDraws`) holds everything drawn for the B images: the worlds'
        ``params``, ``cameras`` (a :class:`warpworm.render.Cameras`: image b shows world b of ``frame``), the drawn
        ``appearance`` values (B,) each and the renderer's ``look`` built from them, the ``sensor`` values, and
        ``seeds`` (B,) int64 that all pixel noise must derive from.

        Returns name -> (B, ...) arrays for the image and label datasets of :data:`warpworm.data.dataset.SCHEMA`
        (rgb, depth, segmentation, poses/*, keypoints/*, creases/angle, bars/strain, worm/vertices, labels/*).
        """


def load_stages(spec: str | Any) -> Any:
    """``"package.module:attr"`` -> a stages instance (attr is instantiated if it is a class or factory)."""
    if not isinstance(spec, str):
        return spec
    mod, _, attr = spec.partition(":")
    obj = getattr(importlib.import_module(mod), attr or "Stages")
    return obj() if callable(obj) else obj
