"""The one table of integer ids and names shared by host code, kernels and files (plain Python constants).

Kernels take their ``wp.constant``s from here (``from warpworm import ids``); host modules re-export the names
they always had (``crease.MOUNTAIN``, ``render.raster_kernels.LABEL_EPM``, ``model.SHAPE_CUBOID``, ...). The dataset
files' ``segmentation_ids`` attribute is :data:`SEGMENTATION_IDS` (``warpworm.data.dataset.SEGMENTATION_IDS`` is this
table), the renderer's ``LABEL_NAMES`` is :data:`SEGMENTATION_NAMES`, the BOP / COCO exports and ``warpworm verify``
read their ids from here.
"""

from __future__ import annotations

# --- segmentation ids of the rendered label image ------------------------------------------
SEG_BACKGROUND = 0
SEG_FLOOR = 1
SEG_WORM_FIRST = 2
"""Worm segments 0..4, tail -> head, are ids SEG_WORM_FIRST..SEG_WORM_LAST."""
SEG_WORM_LAST = 6
SEG_IPM_FIRST = 7
"""IPMs tail, centre, head are ids SEG_IPM_FIRST..SEG_IPM_FIRST + 2 (magnet slots 1..3)."""
SEG_EPM = 10
NUM_SEGMENTATION_IDS = 11
SEG_WORM = tuple(range(SEG_WORM_FIRST, SEG_WORM_LAST + 1))
"""The worm's ids, segment 0..4 (tail -> head)."""
SEG_IPMS = (SEG_IPM_FIRST, SEG_IPM_FIRST + 1, SEG_IPM_FIRST + 2)
"""The tail, centre and head IPM's ids."""
SEGMENTATION_NAMES = ("background", "floor", "worm_segment_0", "worm_segment_1", "worm_segment_2", "worm_segment_3",
                      "worm_segment_4", "ipm_tail", "ipm_centre", "ipm_head", "epm")
"""Name of every segmentation id, indexed by id (also the dataset files' names)."""
SEGMENTATION_IDS = {name: i for i, name in enumerate(SEGMENTATION_NAMES)}
"""name -> id: the dataset files' root attribute ``segmentation_ids`` (JSON)."""
SEGMENTATION_TEXT = (f"{SEG_BACKGROUND} background, {SEG_FLOOR} floor, {SEG_WORM_FIRST}..{SEG_WORM_LAST} worm segments "
                     f"tail->head, {'/'.join(map(str, SEG_IPMS))} tail/centre/head IPM, {SEG_EPM} EPM")
"""One line naming every id (dataset docs and attributes)."""

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
HINGE_LABEL_TEXT = f"{FLAT} flat, {MOUNTAIN} mountain, {VALLEY} valley"
"""The labels a hinge (crease) can have, in one line (the dataset's ``crease_order`` attribute)."""

# --- world status (``State.unstable``) -------------------------------------------------------------------------------
WORLD_OK = 0
WORLD_EXPLODED = 1
"""A bar strained past its limit, a vertex too fast, or a non-finite value: the world is frozen."""
WORLD_CRUMPLED = 2
"""A crease folded through its NoFoldThrough range by more than the tolerance: the sheet crumpled; frozen."""
WORLD_RETIRED = 3
"""Taken out of the run by the host (``Simulator.retire``: every frame it is wanted for is taken): frozen, stable."""
