"""The one table of ids (warpworm.ids) is what every user reads, and the copies it cannot replace agree with it."""

from __future__ import annotations

import json

from warpworm.physics import crease, magnets, params
from warpworm.data import dataset, export_bop
from warpworm import ids
from warpworm.sim import model
from warpworm.kernels import common, magnet_wrench
from warpworm.render import raster_math, scene


def test_segmentation_ids_are_one_table():
    assert scene.LABEL_NAMES == ids.SEGMENTATION_NAMES
    assert len(ids.SEGMENTATION_NAMES) == ids.NUM_SEGMENTATION_IDS
    assert raster_math.SEG_EPM == ids.SEG_EPM == ids.NUM_SEGMENTATION_IDS - 1
    assert raster_math.SEG_WORM_LAST - raster_math.SEG_WORM_FIRST + 1 == crease.NUM_SEGMENTS
    assert dataset.SEGMENTATION_IDS is ids.SEGMENTATION_IDS
    assert export_bop.OBJECTS[1][1] == tuple(range(ids.SEG_WORM_FIRST, ids.SEG_WORM_LAST + 1))
    assert [v[1][0] for k, v in sorted(export_bop.OBJECTS.items())][1:] == [*ids.SEG_IPMS, ids.SEG_EPM]


def test_dataset_files_spell_the_ids_as_schema_version_1_always_did():
    # the files' attribute and the docs' text, written out by hand (schema version 1): the table may not drift
    assert json.dumps(dataset.SEGMENTATION_IDS) == (
        '{"background": 0, "floor": 1, "worm_segment_0": 2, "worm_segment_1": 3, "worm_segment_2": 4, '
        '"worm_segment_3": 5, "worm_segment_4": 6, "ipm_tail": 7, "ipm_centre": 8, "ipm_head": 9, "epm": 10}')
    assert ids.SEGMENTATION_TEXT == ("0 background, 1 floor, 2..6 worm segments tail->head, 7/8/9 tail/centre/head "
                                     "IPM, 10 EPM")
    assert ids.HINGE_LABEL_TEXT == "0 flat, 1 mountain, 2 valley"


def test_magnet_and_crease_ids_are_one_table():
    assert model.SHAPE_CUBOID == magnets.SHAPE_CUBOID == common.SHAPE_CUBOID == ids.SHAPE_CUBOID
    assert model.SHAPE_CYLINDER == magnets.SHAPE_CYLINDER == common.SHAPE_CYLINDER == ids.SHAPE_CYLINDER
    assert params.MAGNET_MODELS == ids.MAGNET_MODELS
    assert magnets.MODELS == {"dipoles": magnet_wrench.MODEL_DIPOLES, "analytic": magnet_wrench.MODEL_ANALYTIC}
    assert (crease.FLAT, crease.MOUNTAIN, crease.VALLEY) == (common.LABEL_FLAT, common.LABEL_MOUNTAIN,
                                                            common.LABEL_VALLEY)
    assert crease.LABEL_NAMES[crease.BOUNDARY] == "boundary" and len(set(crease.LABEL_NAMES)) == 4
