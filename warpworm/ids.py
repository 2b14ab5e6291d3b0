"""The one table of integer ids and names shared by host code, kernels and files (plain Python constants).

Kernels take their ``wp.constant``s from here (``from warpworm import ids``); host modules re-export the names
they always had (``crease.MOUNTAIN``, ``render.raster_kernels.LABEL_EPM``, ``model.SHAPE_CUBOID``, ...). The dataset
files' ``segmentation_ids`` attribute (``warpworm.dataset.SEGMENTATION_IDS``) spells the same ids with its own names
(``worm_segment_0`` ...); ``tests/test_ids.py`` keeps it equal to this table.
"""

from __future__ import annotations

# --- segmentation ids of the rendered label image (docs/architecture.md) ------------------------------------------
SEG_BACKGROUND = 0
SEG_FLOOR = 1
SEG_WORM_FIRST = 2
"""Worm segments 0..4, tail -> head, are ids SEG_WORM_FIRST..SEG_WORM_LAST."""
SEG_WORM_LAST = 6
SEG_IPM_FIRST = 7
"""IPMs tail, centre, head are ids SEG_IPM_FIRST..SEG_IPM_FIRST + 2 (magnet slots 1..3)."""
SEG_EPM = 10
NUM_SEGMENTATION_IDS = 11
SEGMENTATION_NAMES = ("background", "floor", "worm_seg0", "worm_seg1", "worm_seg2", "worm_seg3", "worm_seg4",
                      "ipm_tail", "ipm_centre", "ipm_head", "epm")
"""Name of every segmentation id, indexed by id."""

# --- magnets ---------------------------------------------------------------------------------------------------------
SHAPE_CUBOID = 0
SHAPE_CYLINDER = 1

MAGNET_MODELS = ("dipoles", "analytic")
"""Magnet force models; a model's id in the kernels is its index here."""
MODEL_DIPOLES = MAGNET_MODELS.index("dipoles")
MODEL_ANALYTIC = MAGNET_MODELS.index("analytic")

# --- crease labels of the origami pattern's edges and hinges ---------------------------------------------------------
FLAT = 0
MOUNTAIN = 1
VALLEY = 2
BOUNDARY = 3
"""An open end's edge (no hinge)."""
CREASE_LABEL_NAMES = ("flat", "mountain", "valley", "boundary")
"""Name of every crease label, indexed by label."""
