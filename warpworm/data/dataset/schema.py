"""The dataset schema: every HDF5 dataset of a shard (name, shape, dtype, unit, meaning), the root attributes' units,
and the docs table generated from it."""

from __future__ import annotations

import functools
import sys
from dataclasses import dataclass

import h5py
import numpy as np

import warpworm
from warpworm import ids

SCHEMA_VERSION = 1
FORMAT = "warpworm-dataset"
"""The ``format`` of every shard's root attributes and of the manifest."""
QUATERNION_ORDER = "wxyz"


@functools.lru_cache(maxsize=None)
def versions() -> dict[str, str]:
    """The versions of the code that writes a dataset (the manifest's ``versions``)."""
    return {"warpworm": warpworm.__version__, "warp": warp_version(), "numpy": np.__version__,
            "h5py": h5py.__version__, "python": sys.version.split()[0]}


@functools.lru_cache(maxsize=None)
def warp_version() -> str:
    """The Warp version that writes the files (root attribute ``warp_version``, the manifest's ``versions``)."""
    try:
        import warp  # start-up time: Warp loads on first use

        return str(warp.__version__)
    except Exception:  # noqa: BLE001 - the fake stages in tests do not need Warp
        return "unavailable"

SEGMENTATION_IDS = ids.SEGMENTATION_IDS
"""Segmentation ids (:mod:`warpworm.ids`): worm segments 0..4 run tail -> head."""

UNITS = {"length": "m", "depth": "m (camera z; 0 = background)", "angle": "rad", "time": "s", "pixel": "px",
         "mass": "kg", "moment": "A*m^2", "frames": "OpenCV camera (+z forward, +y down), x_cam = R x_world + t; "
         "poses are object -> world 4x4"}

@dataclass(frozen=True)
class Field:
    """One dataset of every shard: its name, per-file shape (symbols N, H, W, P, C, E, V or integers), dtype, unit."""

    name: str
    shape: tuple
    dtype: str
    unit: str
    description: str


SHAPE_SYMBOLS = {
    "N": "samples in the shard (attribute count)", "H": "render.height [px]", "W": "render.width [px]",
    "P": "keypoints (root attribute keypoint_names)", "C": "creases (rows of root attribute crease_hinges)",
    "E": "bars (rows of root attribute bar_edges)", "V": "sheet vertices (worm mesh)",
}
"""What each symbol of :attr:`Field.shape` stands for."""

FIELDS: tuple[Field, ...] = (
    Field("rgb", ("N", "H", "W", 3), "uint8", "", "colour image, sRGB, after sensor effects"),
    Field("depth", ("N", "H", "W"), "float32", "m", "camera-frame z of the first surface; 0 = background"),
    Field("segmentation", ("N", "H", "W"), "uint8", "",
          f"ids, see root attribute segmentation_ids: {ids.SEGMENTATION_TEXT}"),
    Field("camera/K", ("N", 3, 3), "float64", "px", "intrinsics, row-major, fx, fy > 0, pixel centres at integers"),
    Field("camera/R", ("N", 3, 3), "float64", "", "world -> camera rotation (x_cam = R x_world + t)"),
    Field("camera/t", ("N", 3), "float64", "m", "world -> camera translation"),
    Field("camera/position", ("N", 3), "float64", "m", "camera centre in world (= -R^T t)"),
    Field("camera/in_frame", ("N",), "float32", "",
          "fraction of the worm's vertices (every frame the camera shows) inside the image; below "
          "camera.min_in_frame only if no view in camera.max_tries draws reached it"),
    Field("poses/body", ("N", 4, 4), "float64", "m",
          "worm body frame -> world (origin: mean of the segment centres, x tail->head, z dorsal)"),
    Field("poses/ipm", ("N", 3, 4, 4), "float64", "m", "IPM (tail, centre, head) -> world; disk axis = local z"),
    Field("poses/epm", ("N", 4, 4), "float64", "m", "EPM -> world; moment along local z"),
    Field("poses/body_quat", ("N", 4), "float64", "", "body rotation as a unit quaternion (w, x, y, z)"),
    Field("keypoints/world", ("N", "P", 3), "float64", "m", "keypoints in world, names in root attribute keypoint_names"),
    Field("keypoints/camera", ("N", "P", 3), "float64", "m", "keypoints in the camera frame (R x_world + t)"),
    Field("keypoints/body", ("N", "P", 3), "float64", "m",
          "keypoints in the worm body frame: poses/body^-1 applied to keypoints/world"),
    Field("keypoints/pixel", ("N", "P", 2), "float64", "px",
          "projection (u, v) of keypoints/world through K, R, t (cv2.projectPoints, no distortion)"),
    Field("keypoints/visibility", ("N", "P"), "uint8", "",
          "COCO: 0 outside the image (or behind the camera), 1 occluded, 2 visible (docs/render.md)"),
    Field("creases/angle", ("N", "C"), "float32", "rad",
          "signed dihedral of every crease (valley +, mountain -), order = root attribute crease_hinges"),
    Field("bars/strain", ("N", "E"), "float32", "", "Cauchy strain dL/L0 of every bar, order = root attribute bar_edges"),
    Field("worm/vertices", ("N", "V", 3), "float32", "m",
          "deformed sheet vertices in world (triangles: root attribute mesh_triangles)"),
    Field("labels/bbox_obj", ("N", 4), "float32", "px", "worm box (x, y, w, h) of the projected mesh, occlusion ignored"),
    Field("labels/bbox_visib", ("N", 4), "float32", "px", "worm box (x, y, w, h) of its visible pixels; 0s if none"),
    Field("labels/visib_fract", ("N",), "float32", "", "visible worm pixels / pixels of the worm rendered alone"),
    Field("labels/worm_mask", ("N", "H", "W"), "uint8", "", "1 where the worm's sheet projects, occluders ignored"),
    Field("labels/deformation", ("N", 4), "float32", "",
          "distances between adjacent segment centres over their rest values"),
    Field("time", ("N",), "float32", "s", "simulated time of the frame after settling"),
    Field("trajectory", ("N",), "int64", "", "trajectory (simulated world) id; its frames are consecutive samples"),
    Field("frame", ("N",), "int32", "", "frame index within the trajectory (sim.frame_times)"),
    Field("attempt", ("N",), "int32", "", "replacement attempt that gave a stable world (0: first draw)"),
    Field("sample_id", ("N",), "int64", "", "global sample id, == row in the whole dataset"),
    Field("seed", ("N",), "int64", "", "per-sample 63-bit seed derived from (master seed, sample id) for pixel noise"),
)
"""Every dataset of every shard, in the order of the docs table (``params/<group>.<name>`` come in addition)."""

PARAMS_FIELD = Field("params/<group>.<name>", ("N",), "float64 / bytes / bool", "(the parameter's)",
                     "every randomized value, one dataset per name in root attribute params_names")

SCHEMA: dict[str, tuple[str, str, str]] = {
    f.name: (f.dtype, f.unit, f"({', '.join(str(d) for d in f.shape[1:])}{',' if len(f.shape) == 2 else ''}) "
             f"{f.description}") for f in FIELDS}
"""name -> (dtype, unit, description with the per-sample shape); the ``description`` attribute of each dataset."""
SCHEMA["view"] = ("int32", "", "() which of the trajectory's render.views_per_frame cameras shows this sample "
                  "(written only when views_per_frame > 1; sample = (trajectory K + view) F + frame)")
SCHEMA["engine"] = ("uint8", "", "() renderer of this sample's rgb: 0 raster, 1 path-traced (warpworm.render.pathtrace; "
                    "written only with render.engine pathtraced or render.pathtraced_fraction > 0; labels are raster)")
SCHEMA["camera/dist"] = ("float64", "", "(5,) lens distortion (k1, k2, p1, p2, k3), OpenCV's model: rgb, depth, "
                         "segmentation and keypoints/pixel (= cv2.projectPoints with it) go through it; written only "
                         "with render.distortion")

SCHEMA_TABLE_BEGIN = "<!-- schema table: generated from warpworm.data.dataset.FIELDS by schema_markdown(); do not edit -->"
SCHEMA_TABLE_END = "<!-- end of schema table -->"


def schema_markdown() -> str:
    """The docs' table of every HDF5 dataset."""
    def shape(f):
        return "(" + ", ".join(str(d) for d in f.shape) + ("," if len(f.shape) == 1 else "") + ")"

    rows = ["| dataset | shape | dtype | unit | meaning |", "|---|---|---|---|---|"]
    for f in FIELDS + (PARAMS_FIELD,):
        rows.append(f"| `{f.name}` | {shape(f)} | {f.dtype} | {f.unit or '—'} | {f.description} |")
    syms = "; ".join(f"{k} = {v}" for k, v in SHAPE_SYMBOLS.items())
    return "\n".join([SCHEMA_TABLE_BEGIN, *rows, "", f"Shape symbols: {syms}.", SCHEMA_TABLE_END])


def resolve_shape(field: Field, dims: dict[str, int]) -> tuple[int, ...]:
    """A field's shape with its symbols replaced by ``dims`` (e.g. {"N": 6, "H": 16, ...})."""
    return tuple(dims[d] if isinstance(d, str) else d for d in field.shape)


IMAGE_KEYS = ("rgb", "depth", "segmentation", "labels/worm_mask")
