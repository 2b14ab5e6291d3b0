"""The one table of ids (warpworm.ids) is what every user reads, and the copies it cannot replace agree with it."""

from __future__ import annotations

from warpworm import crease, dataset, ids, magnets, model, params
from warpworm.kernels import common, magnet_fields, magnet_wrench
from warpworm.render import raster_kernels, scene


def test_segmentation_ids_are_one_table():
    assert scene.LABEL_NAMES == ids.SEGMENTATION_NAMES
    assert len(ids.SEGMENTATION_NAMES) == ids.NUM_SEGMENTATION_IDS == raster_kernels.NUM_LABELS
    assert raster_kernels.LABEL_EPM == ids.SEG_EPM == ids.NUM_SEGMENTATION_IDS - 1
    assert raster_kernels.LABEL_WORM_LAST - raster_kernels.LABEL_WORM_FIRST + 1 == crease.NUM_SEGMENTS
    # warpworm/dataset.py keeps its own names (the files' ``segmentation_ids`` attribute): same ids, same order
    assert sorted(dataset.SEGMENTATION_IDS.values()) == list(range(ids.NUM_SEGMENTATION_IDS))
    by_id = sorted(dataset.SEGMENTATION_IDS, key=dataset.SEGMENTATION_IDS.get)
    assert [n.replace("worm_segment_", "worm_seg") for n in by_id] == list(ids.SEGMENTATION_NAMES)


def test_magnet_and_crease_ids_are_one_table():
    assert model.SHAPE_CUBOID == magnets.SHAPE_CUBOID == magnet_fields.SHAPE_CUBOID == ids.SHAPE_CUBOID
    assert model.SHAPE_CYLINDER == magnets.SHAPE_CYLINDER == magnet_fields.SHAPE_CYLINDER == ids.SHAPE_CYLINDER
    assert params.MAGNET_MODELS == ids.MAGNET_MODELS
    assert magnets.MODELS == {"dipoles": magnet_wrench.MODEL_DIPOLES, "analytic": magnet_wrench.MODEL_ANALYTIC}
    assert (crease.FLAT, crease.MOUNTAIN, crease.VALLEY) == (common.LABEL_FLAT, common.LABEL_MOUNTAIN,
                                                            common.LABEL_VALLEY)
    assert crease.LABEL_NAMES[crease.BOUNDARY] == "boundary" and len(set(crease.LABEL_NAMES)) == 4
