"""Dataset job configuration: YAML -> validated dataclasses (a pydantic v2 schema), with dotted command-line overrides.

The schema is the dataclasses below (their field docstrings are the documentation) and :data:`PARAM_SPECS` (every
randomizable parameter); ``warpworm config-schema`` exports it as a JSON Schema for editors (docs/config.md).
All SI: m, s, rad, kg.

Every mistake (unknown key, wrong type, negative size, low > high, unknown gait, unwritable output folder) raises
:class:`ConfigError` *before any work*, with one line per problem naming the key path, the value given and what was
expected. Nothing is written by loading or validating a config. Building the dataclasses in code (e.g.
``dataclasses.replace``) does not validate: only YAML / mappings from outside go through :func:`config_from_dict`.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import math
import os
import re
import tempfile
import typing
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import AfterValidator, BeforeValidator, ConfigDict, Field, PlainValidator, TypeAdapter, \
    ValidationError, ValidationInfo, WithJsonSchema
from pydantic_core import PydanticCustomError
from typing_extensions import TypedDict

from warpworm.data import randomize as rnd
from warpworm.errors import ConfigError
from warpworm.physics.param_specs import WORM_SPECS, ParamSpec
from warpworm.physics.param_specs import check_worm_params, worm_param_problems  # noqa: F401  shim (issue 42): old path
from warpworm.physics.param_specs import fmt_value as _fmt


_PI = math.pi


# ---------------------------------------------------------------------------------------------------------------------
# Randomizable parameters: group -> name -> ParamSpec (default distribution, unit, allowed range, doc). The worm's
# group is the parameter contract itself (warpworm.physics.param_specs.WORM_SPECS).
PARAM_SPECS: dict[str, dict[str, ParamSpec]] = {
    "worm": WORM_SPECS,
    # The camera group is what warpworm.render.sample_cameras takes: ranges (a constant or {uniform: [lo, hi]}) that it
    # draws from per attempt, redrawing views where less than min_in_frame of the worm is inside the image.
    "camera": {
        "distance": ParamSpec({"uniform": [0.17, 0.28]}, "m", positive=True, ranges_only=True,
                              doc="camera to look-at point"),
        "elevation": ParamSpec({"uniform": [0.35, 1.2]}, "rad", low=-_PI / 2, high=_PI / 2, ranges_only=True,
                               doc="angle above the floor plane"),
        "azimuth": ParamSpec({"uniform": [-_PI, _PI]}, "rad", ranges_only=True,
                             doc="about world z, from the worm's +x axis"),
        "roll": ParamSpec({"uniform": [-0.08, 0.08]}, "rad", ranges_only=True, doc="rotation about the optical axis"),
        "fov_y": ParamSpec({"uniform": [0.6, 0.9]}, "rad", low=0.05, high=3.0, ranges_only=True,
                           doc="vertical field of view"),
        "lookat_jitter": ParamSpec(0.005, "m", low=0.0, constant_only=True,
                                   doc="half side of the cube the look-at point is jittered in (stored: the offset's "
                                       "length)"),
        "min_in_frame": ParamSpec(0.9, "1", low=0.0, high=1.0, constant_only=True,
                                  doc="views with a smaller fraction of the worm's vertices (all frames the camera "
                                      "shows) inside the image are redrawn (stored: the kept view's fraction)"),
        "max_tries": ParamSpec(16, "1", low=1, high=1000, constant_only=True, integer=True,
                               doc="draws per camera before the best one is kept below min_in_frame"),
    },
    "light": {
        "elevation": ParamSpec({"uniform": [0.5, 1.4]}, "rad", doc="directional light elevation"),
        "azimuth": ParamSpec({"uniform": [-_PI, _PI]}, "rad", doc="directional light azimuth"),
        "intensity": ParamSpec({"uniform": [0.6, 1.0]}, "1", low=0.0, doc="directional light intensity"),
        "ambient": ParamSpec({"uniform": [0.15, 0.35]}, "1", low=0.0, high=1.0, doc="ambient light"),
    },
    "color": {
        "worm_hue": ParamSpec({"uniform": [0.0, 1.0]}, "1", low=0.0, high=1.0, doc="sheet colour hue"),
        "worm_saturation": ParamSpec({"uniform": [0.0, 0.5]}, "1", low=0.0, high=1.0, doc="sheet saturation"),
        "worm_value": ParamSpec({"uniform": [0.7, 1.0]}, "1", low=0.0, high=1.0, doc="sheet brightness"),
        "floor_hue": ParamSpec({"uniform": [0.0, 1.0]}, "1", low=0.0, high=1.0, doc="floor hue"),
        "floor_saturation": ParamSpec({"uniform": [0.0, 0.6]}, "1", low=0.0, high=1.0, doc="floor saturation"),
        "floor_value": ParamSpec({"uniform": [0.2, 0.6]}, "1", low=0.0, high=1.0, doc="floor brightness"),
        "background_value": ParamSpec({"uniform": [0.0, 0.4]}, "1", low=0.0, high=1.0, doc="background grey"),
    },
    "texture": {
        "floor": ParamSpec({"choice": ["plain", "checker", "noise"]}, "", values=("plain", "checker", "noise"),
                           doc="floor pattern"),
        "floor_scale": ParamSpec({"loguniform": [0.005, 0.03]}, "m", positive=True, doc="floor pattern period"),
        "worm": ParamSpec({"choice": ["plain", "fibre"]}, "", values=("plain", "fibre", "bands"),
                          doc="sheet pattern ('bands': the paper's five marker bands, warpworm.render.scene.BAND_COLORS)"),
    },
    "sensor": {
        "noise_std": ParamSpec({"uniform": [0.0, 4.0]}, "8-bit levels", low=0.0, doc="Gaussian pixel noise std"),
        "blur_sigma": ParamSpec({"uniform": [0.0, 0.8]}, "px", low=0.0, doc="Gaussian blur sigma (0: none)"),
        "jpeg_quality": ParamSpec({"choice": [100, 95, 80, 60]}, "1", low=1, high=100,
                                  doc="JPEG re-encode quality (100: none)"),
        "brightness": ParamSpec({"uniform": [-12.0, 12.0]}, "8-bit levels", doc="additive colour jitter"),
        "contrast": ParamSpec({"uniform": [0.85, 1.15]}, "1", positive=True, doc="multiplicative colour jitter"),
    },
}
"""Every randomizable parameter. ``params/<group>.<name>`` in the files holds each sample's value."""

# Parameters that are shared by one solver batch: a batch is split into groups by these. Gait and direction are
# per-world parameters (the EPM path is per world); the magnet model is a different branch of the wrench kernel.
BATCH_SHARED = ("worm.magnet_model",)


# ---------------------------------------------------------------------------------------------------------------------
def _problem(detail: str, path: str | None = None) -> PydanticCustomError:
    """A check of ours failing: ``detail`` is "got X; expected Y"; ``path`` names the key when it is not the one
    being validated (a check relating two keys)."""
    return PydanticCustomError("config", "{detail}", {"detail": detail, "path": path})


# Strict scalars: the string "yes", "0.1" or 1.5 for an integer are mistakes, not values to convert; an integer is
# a number (stored as a float).
Int = Annotated[int, Field(strict=True)]
Num = Annotated[float, Field(strict=True)]
Bool = Annotated[bool, Field(strict=True)]
Str = Annotated[str, Field(strict=True)]
_SECTION = ConfigDict(extra="forbid", allow_inf_nan=False, use_attribute_docstrings=True, validate_default=True)


def _none_is_empty(v):
    return {} if v is None else v  # "sim:" with nothing under it = all defaults


def _check_frame_times(ft: list[float], info: ValidationInfo) -> list[float]:
    if any(t < 0 for t in ft) or any(b <= a for a, b in zip(ft, ft[1:])):
        raise _problem(f"got {ft}; expected strictly increasing times >= 0 [s]")
    dt = info.data.get("dt") if info.data.get("frame_unit", "s") == "s" else None  # cycles: rounded per world
    # frames are taken after whole steps: a time between steps would be rounded silently, and two frames within one
    # step would store the same snapshot under two times
    if dt is not None and any(abs(t / dt - round(t / dt)) > 1e-6 * max(1.0, t / dt) for t in ft):
        raise _problem(f"got {ft}; expected multiples of sim.dt = {dt} [s]")
    return ft


def _check_device(ident: str) -> str:
    """"auto" -> the first GPU if there is one, else the CPU (stored so in the config); refused unless Warp can run on
    it here (so a CUDA config fails before any work on a machine without a GPU, not in a worker's traceback)."""
    import warp as wp

    from warpworm import quiet_warp

    quiet_warp()
    if ident == "auto":
        ident = "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"
    try:
        if ident.startswith("cuda") and wp.get_cuda_device_count() == 0:
            raise ValueError(ident)  # asking Warp for it would print CUDA driver errors first
        wp.get_device(ident)
    except (ValueError, RuntimeError):
        raise _problem(f"got {_fmt(ident)}; expected 'auto' or a Warp device available here: one of "
                       f"{[str(d) for d in wp.get_devices()]} (override with sim.device=cpu)") from None
    return ident


@dataclass
class SimConfig:
    """The batched simulation (SI units)."""

    __pydantic_config__ = _SECTION
    worlds: Annotated[Int, Field(ge=1)] = 64
    """W: worlds simulated at once in one solver batch."""
    dt: Annotated[Num, Field(gt=0)] = 0.004
    """Solver time step [s] (the gait runs' warpworm.physics.gaits.DEFAULT_DT)."""
    substeps: Annotated[Int, Field(ge=1)] = 2
    """Solver substeps per time step."""
    settle_time: Annotated[Num, Field(ge=0)] = 0.3
    """Time [s] the worm settles under gravity with the EPM parked at the path start."""
    frame_unit: Literal["s", "cycle"] = "s"
    """Unit of ``frame_times``: 's' (seconds, multiples of ``dt``), or 'cycle' (issue 24: cycles of each world's EPM
    path, ``worm.cycle_period``: frame f of a world is taken at ``round(frame_times[f] · period / dt) · dt``, so
    k + 0.5 is its k-th closest approach and a whole number a far point, whatever the period; ``time`` stores the
    seconds)."""
    frame_times: Annotated[list[Num], Field(strict=True, min_length=1), AfterValidator(_check_frame_times)] = \
        field(default_factory=lambda: [0.2, 0.5, 0.8, 1.0])
    """Times [s] after settling at which frames are taken, strictly increasing, multiples of ``dt``; each trajectory
    gives len(frame_times) samples."""
    n_units: Annotated[Int, Field(ge=1)] = 6
    """Prism units of the worm; fixes the number of creases and vertices, so one value per dataset."""
    max_attempts: Annotated[Int, Field(ge=1)] = 4
    """Unstable worlds are redrawn with attempt + 1, at most this many attempts in all; then the job fails."""
    device: Annotated[Str, AfterValidator(_check_device)] = "cpu"
    """Warp device for simulation and rendering: "cpu", "cuda:N", or "auto" (the first GPU if any, else the CPU)."""


def _check_range(r: list) -> list:
    if r[0] > r[1] or r[0] < 0:
        raise _problem(f"got {r}; expected [lo, hi] with 0 <= lo <= hi")
    return r


def _check_band_colors(c):
    if c is not None:
        a = np.asarray(c, dtype=np.float64)
        if a.shape != (5, 3) or not np.all((a >= 0) & (a <= 1)):
            raise _problem(f"got {c}; expected five [r, g, b] display colours in [0, 1], tail -> head")
    return c


def _mitsuba_missing() -> bool:
    import importlib.util

    return importlib.util.find_spec("mitsuba") is None


def _check_engine(engine: str) -> str:
    if engine == "pathtraced" and _mitsuba_missing():
        raise _problem("got 'pathtraced'; expected 'raster' here: Mitsuba 3 is not installed (pip install "
                       "'warpworm[pathtrace]')")
    return engine


def _check_pathtraced_fraction(frac: float, info: ValidationInfo) -> float:
    if frac > 0 and info.data.get("engine") == "pathtraced":
        raise _problem(f"got {frac}; expected 0 with render.engine 'pathtraced' (every image is path-traced; mix the "
                       "engines with engine 'raster' and a fraction)")
    if frac > 0 and _mitsuba_missing():
        raise _problem(f"got {frac}; expected 0 here: Mitsuba 3 is not installed (pip install 'warpworm[pathtrace]')")
    return frac


def _check_signed_range(r: list) -> list:
    if r[0] > r[1]:
        raise _problem(f"got {r}; expected [lo, hi] with lo <= hi")
    return r


@dataclass
class RenderConfig:
    """The images."""

    __pydantic_config__ = _SECTION
    width: Annotated[Int, Field(ge=8)] = 128
    """Image width [px]."""
    height: Annotated[Int, Field(ge=8)] = 96
    """Image height [px]."""
    camera_per_frame: Bool = False
    """False: one camera per trajectory (frames of a world form a video); True: a new camera for every frame."""
    batch: Annotated[Int, Field(ge=1)] = 1024
    """Images per render call (whole trajectories); bounds the memory of images held before writing."""
    views_per_frame: Annotated[Int, Field(ge=1)] = 1
    """K: cameras rendered of every simulated frame, each its own sample (own camera draw, labels and sample id);
    a trajectory gives K * len(sim.frame_times) samples. 1 (the default) writes the datasets of before this option."""
    # -- issue 24: nothing world-fixed relative to the worm; shadows (docs/render.md "Transfer"); OFF values keep the
    # datasets of before (RENDER_OFF_GROUPS leaves them out of config_yaml)
    plate_pose: Bool = False
    """Draw the plate's pose relative to the worm per trajectory: yaw uniform in [0, 2π) about the floor normal and
    an offset uniform in a disk of radius ``plate_offset``; the floor square, its textures (another uniform angle and
    offset) and every light move with it, so nothing drawn is fixed relative to the worm's head and tail. Simulation,
    cameras and labels are untouched. False: floor, textures and lamp fixed in the world the worm starts in (+x)."""
    plate_offset: Annotated[Num, Field(ge=0)] = 0.05
    """Radius [m] of the disk the plate's offset is drawn in (``plate_pose``)."""
    lights: Literal["fixed", "random"] = "fixed"
    """'fixed': the directional light (``randomize.light``) and one lamp at (-0.15, 0.2, 0.3) m (in the plate's frame
    with ``plate_pose``); 'random': the directional light and ``light_count`` point lights drawn per trajectory."""
    light_count: Annotated[list[Int], Field(strict=True, min_length=2, max_length=2), AfterValidator(_check_range)] = \
        field(default_factory=lambda: [1, 4])
    """[lo, hi]: point lights per trajectory, uniform integers (``lights: random``; 0 allowed: directional only)."""
    light_distance: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                              AfterValidator(_check_range)] = field(default_factory=lambda: [0.15, 0.6])
    """[lo, hi] [m]: each point light's distance from the plate's centre, uniform."""
    light_elevation: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                               AfterValidator(_check_range)] = field(default_factory=lambda: [0.35, 1.45])
    """[lo, hi] [rad]: each point light's elevation above the plate seen from its centre (azimuth uniform)."""
    light_size: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                          AfterValidator(_check_range)] = field(default_factory=lambda: [0.002, 0.03])
    """[lo, hi] [m]: radius of each point light (spherical); sets its shadows' softness."""
    light_irradiance: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                                AfterValidator(_check_range)] = field(default_factory=lambda: [0.1, 0.6])
    """[lo, hi]: each point light's irradiance at the plate's centre (facing it), uniform; the sun's is
    ``light.intensity``."""
    light_warmth: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                            AfterValidator(_check_range)] = field(default_factory=lambda: [0.0, 1.0])
    """[lo, hi] in [0, 1]: each light's colour from cool daylight (0, ~6500 K) to warm tungsten (1, ~3000 K)."""
    shadows: Bool = False
    """Shadows from every light (the directional light and each point light): a depth map of the scene's meshes
    rendered from the light by the same rasterizer, soft by percentage-closer filtering (docs/render.md)."""
    shadow_map: Annotated[Int, Field(ge=0, le=4096)] = 0
    """Side [px] of each light's shadow map; 0: the image's larger side (a texel about a pixel at the worm)."""
    supersample: Annotated[Int, Field(ge=1, le=8)] = 1
    """Anti-aliased RGB: s x s samples per pixel averaged in linear RGB (s = 1: one sample at the centre). Depth,
    segmentation, masks and keypoint visibility stay exact at pixel centres (docs/render.md)."""
    distortion: Bool = False
    """Lens distortion drawn per camera (OpenCV's k1, k2, p1, p2, k3, each uniform in its range below), stored as
    camera/dist: images are warped through it; keypoints/pixel (= cv2.projectPoints with it), labels/bbox_obj and
    visibility follow it (docs/render.md)."""
    distortion_k1: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                             AfterValidator(_check_signed_range)] = field(default_factory=lambda: [-0.25, 0.05])
    """[lo, hi]: radial k1 (negative: barrel)."""
    distortion_k2: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                             AfterValidator(_check_signed_range)] = field(default_factory=lambda: [-0.02, 0.08])
    """[lo, hi]: radial k2."""
    distortion_p: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                            AfterValidator(_check_signed_range)] = field(default_factory=lambda: [-0.002, 0.002])
    """[lo, hi]: tangential p1 and p2 (each drawn)."""
    distortion_k3: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                             AfterValidator(_check_signed_range)] = field(default_factory=lambda: [0.0, 0.0])
    """[lo, hi]: radial k3."""
    motion_blur: Annotated[Num, Field(ge=0, le=0.2)] = 0.0
    """Shutter time [s]: RGB averaged over ``motion_blur_samples`` sub-frames of the open shutter, the sheet moved
    along its simulated velocities (labels at the frame's time; docs/render.md). 0: no blur."""
    motion_blur_samples: Annotated[Int, Field(ge=2, le=64)] = 4
    """Sub-frames of the shutter (``motion_blur``)."""
    paper_bsdf: Bool = False
    """The sheet as paper: wrapped diffuse (light through the thin sheet), a soft sheen and a hemispherical ambient
    (sky above, the floor's bounce below) instead of Lambert with a constant ambient; parameters per trajectory
    (params/paper.*; docs/render.md)."""
    plate_materials: Annotated[list[Literal["matte", "glossy", "acrylic"]], Field(min_length=1)] = \
        field(default_factory=lambda: ["matte"])
    """Plate materials drawn per trajectory, equally likely: 'matte' (as before), 'glossy' (highlights of every
    light), 'acrylic' (glossy and clear: the EPM under the plate shows through). ['matte']: as before."""
    distractors: Annotated[list[Int], Field(strict=True, min_length=2, max_length=2),
                           AfterValidator(_check_range)] = field(default_factory=lambda: [0, 0])
    """[lo, hi]: distractor objects on the plate per trajectory (paper scraps, cubes, cylinders, rulers), around the
    worm's region and sometimes in front of it: occlusion shows in keypoints/visibility and labels/visib_fract; they
    are segmented as the floor (id 1). [0, 0]: none."""
    exposure: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                        AfterValidator(_check_signed_range)] = field(default_factory=lambda: [0.0, 0.0])
    """[lo, hi] [stops]: per-sample exposure, uniform: the image's linear light times 2^EV before the display
    encoding (highlights clip), stored as params/sensor.exposure. [0, 0]: off."""
    white_balance: Annotated[list[Num], Field(strict=True, min_length=2, max_length=2),
                             AfterValidator(_check_range)] = field(default_factory=lambda: [1.0, 1.0])
    """[lo, hi]: per-sample red and blue gains over green in linear light (a white-balance error), each uniform,
    stored as params/sensor.wb_red, params/sensor.wb_blue. [1, 1]: off."""
    # -- issue 24: the path-traced engine (warpworm.render.pathtrace, the `pathtrace` extra); labels stay the raster's
    engine: Annotated[Literal["raster", "pathtraced"], AfterValidator(_check_engine)] = "raster"
    """'raster': every image from the rasterizer; 'pathtraced': every image path-traced by Mitsuba 3 (same meshes,
    cameras, colours, lights; depth, segmentation and every label from the rasterizer's exact passes)."""
    pathtraced_fraction: Annotated[Num, Field(ge=0, le=1), AfterValidator(_check_pathtraced_fraction)] = 0.0
    """With ``engine: raster``: the share of samples path-traced instead, drawn per sample from its seed (each
    sample's engine is stored in the ``engine`` dataset). 0: none."""
    pathtraced_spp: Annotated[Int, Field(ge=1)] = 16
    """Samples per pixel of the path-traced images."""
    # -- issue 26: the marker bands' colours (randomize.texture.worm: bands)
    band_colors: Annotated[list[list[Num]] | None, AfterValidator(_check_band_colors)] = None
    """Five display colours [[r, g, b], ...] in [0, 1], tail -> head, of the worm painted in bands
    (``randomize.texture.worm: bands``; ``warpworm track --band-colors-from DATASET`` reads them back). None: the
    paper's (``warpworm.render.scene.BAND_COLORS``)."""


RENDER_OFF_GROUPS = {"plate_pose": ("plate_offset",),
                     "lights": ("light_count", "light_distance", "light_elevation", "light_size", "light_irradiance",
                                "light_warmth"),
                     "shadows": ("shadow_map",), "supersample": (),
                     "distortion": ("distortion_k1", "distortion_k2", "distortion_p", "distortion_k3"),
                     "exposure": (), "white_balance": (), "distractors": (), "plate_materials": (), "paper_bsdf": (),
                     "motion_blur": ("motion_blur_samples",),
                     "engine": ("pathtraced_fraction", "pathtraced_spp"), "band_colors": ()}
"""render switch -> the keys it enables: a group whose switch and keys are all at their defaults (OFF) is left out
of ``to_dict`` (so the files' config_yaml stays that of before the option)."""


def _render_keys_left_out(render: "RenderConfig") -> set:
    default = RenderConfig()
    out = set()
    for switch, keys in RENDER_OFF_GROUPS.items():
        group = (switch, *keys)
        if all(getattr(render, k) == getattr(default, k) for k in group):
            out.update(group)
    return out


@dataclass
class OutputConfig:
    """The HDF5 files and the previews."""

    __pydantic_config__ = _SECTION
    compression: Literal["lzf", "gzip", "none"] = "gzip"
    """HDF5 filter for images: 'gzip' (level 1 measured smaller *and* faster to write and read than 'lzf' on rendered
    images; benchmarks/bench_dataset.py), 'lzf' or 'none'."""
    compression_level: Annotated[Int, Field(ge=0, le=9)] = 1
    """gzip level 0..9 (ignored for lzf/none)."""
    preview: Bool = True
    """Write ``preview.png`` (contact sheet) and ``preview.mp4`` (one world) at the end."""


# ---------------------------------------------------------------------------------------------------------------------
# randomize: group -> parameter -> distribution, one TypedDict per group generated from PARAM_SPECS. A parameter is
# parsed by warpworm.data.randomize.parse_distribution, then checked against its ParamSpec (_check_spec).
def _check_spec(dist: rnd.Distribution, spec: ParamSpec) -> list[str]:
    """What is wrong with ``dist`` for a parameter of ``spec`` ("got X; expected Y" each); [] if nothing."""
    got = f"got {_fmt(dist.to_yaml())}"
    if spec.values is not None and not (spec.low is not None and dist.is_numeric):
        vals = rnd.distribution_values(dist)
        if not vals:
            return [f"{got}; expected a constant or choice/grid of {list(spec.values)}"]
        bad = [v for v in vals if v not in spec.values or type(v) is not type(spec.values[0])]
        return [f"got {_fmt(bad[0])}; expected one of {list(spec.values)}"] if bad else []
    if spec.constant_only and not isinstance(dist, rnd.Constant):
        return [f"{got}; expected a constant [{spec.unit}] ({spec.doc})"]
    if spec.ranges_only and not isinstance(dist, (rnd.Constant, rnd.Uniform)):
        return [f"{got}; expected a constant or {{uniform: [lo, hi]}} [{spec.unit}] (the camera sampler draws "
                "uniformly in the range, per attempt)"]
    b = rnd.distribution_bounds(dist)
    if b is None:
        return [f"{got}; expected numeric values [{spec.unit}]"]
    lo, hi = b
    if math.isnan(lo) or math.isnan(hi):  # NaN = "the gait preset's value", only where a preset gives one
        return [] if spec.preset and isinstance(dist, rnd.Constant) else [f"{got}; expected a number [{spec.unit}]"]
    problems = []
    if spec.integer and not (float(lo).is_integer() and float(hi).is_integer()):
        problems.append(f"{got}; expected a whole number")
    if spec.positive and lo <= 0:
        problems.append(f"{got}; expected values > 0 [{spec.unit}]")
    if spec.low is not None and lo < spec.low:
        problems.append(f"{got}; expected values >= {spec.low} [{spec.unit}]")
    if spec.high is not None and hi > spec.high:
        problems.append(f"{got}; expected values <= {spec.high} [{spec.unit}]")
    return problems


def _dist_validator(spec: ParamSpec):
    def parse(raw) -> rnd.Distribution:
        try:
            dist = rnd.parse_distribution(raw)
        except rnd.DistributionError as exc:
            raise _problem(str(exc)) from None
        problems = _check_spec(dist, spec)
        if problems:
            raise _problem("; ".join(problems))
        return dist
    return parse


def _param_schema(spec: ParamSpec) -> dict:
    """A parameter's JSON Schema as pydantic exports it: what it is and its default. The YAML forms it may take are
    added from the same ParamSpec by warpworm.commands.config_schema."""
    out = {"description": f"{spec.doc} [{spec.unit}]" if spec.unit else spec.doc}
    default = rnd.parse_distribution(spec.default).to_yaml()
    if not (isinstance(default, float) and math.isnan(default)):  # NaN (the gait preset's value) has no JSON spelling
        out["default"] = default
    return out


def _group(name: str, specs: dict[str, ParamSpec]):
    params = {n: Annotated[Any, PlainValidator(_dist_validator(s)), WithJsonSchema(_param_schema(s))]
              for n, s in specs.items()}
    td = TypedDict(f"Randomize{name.capitalize()}", params, total=False)
    td.__doc__ = f"randomize.{name}: parameter -> distribution; parameters not named keep their defaults."
    td.__pydantic_config__ = ConfigDict(extra="forbid")
    return Annotated[td, BeforeValidator(_none_is_empty)]


_DEFAULTS = {g: {n: rnd.parse_distribution(s.default) for n, s in specs.items()} for g, specs in PARAM_SPECS.items()}
_Randomize = TypedDict("Randomize", {g: _group(g, specs) for g, specs in PARAM_SPECS.items()}, total=False)
_Randomize.__pydantic_config__ = ConfigDict(extra="forbid")
_Randomize.__doc__ = "group -> parameter -> distribution (warpworm.data.randomize; docs/dataset.md)."


def _with_defaults(given: dict) -> dict:
    """Every parameter of PARAM_SPECS, in its order: the given distribution, else the default."""
    return {g: {n: given.get(g, {}).get(n, d) for n, d in dists.items()} for g, dists in _DEFAULTS.items()}


def _whole_trajectories(sim: SimConfig, info: ValidationInfo) -> SimConfig:
    shard_size, n = info.data.get("shard_size"), len(sim.frame_times)
    if shard_size is not None and shard_size % n:
        raise _problem(f"got {shard_size}; expected a multiple of len(sim.frame_times) = {n} (a shard holds whole "
                       "trajectories)", path="shard_size")
    return sim


def _whole_trajectory_views(render: RenderConfig, info: ValidationInfo) -> RenderConfig:
    shard_size, sim = info.data.get("shard_size"), info.data.get("sim")
    k = render.views_per_frame
    if k > 1 and shard_size is not None and sim is not None and shard_size % (k * len(sim.frame_times)):
        raise _problem(f"got {shard_size}; expected a multiple of render.views_per_frame * len(sim.frame_times) = "
                       f"{k} * {len(sim.frame_times)} (a shard holds whole trajectories)", path="shard_size")
    return render


# ---------------------------------------------------------------------------------------------------------------------
@dataclass
class DatasetConfig:
    """A dataset job: what to simulate and render, how much, and how it is stored (SI units; docs/dataset.md)."""

    __pydantic_config__ = _SECTION
    name: Str = "dataset"
    """Free text, stored in the files."""
    seed: Annotated[Int, Field(ge=0)] = 0
    """Master seed: sample i's values depend only on (seed, i)."""
    num_samples: Annotated[Int, Field(ge=1)] = 64
    """N: images (samples) in the dataset."""
    shard_size: Annotated[Int, Field(ge=1)] = 32
    """Samples per HDF5 shard; a multiple of len(sim.frame_times) (a shard holds whole trajectories)."""
    sim: Annotated[SimConfig, BeforeValidator(_none_is_empty), AfterValidator(_whole_trajectories)] = \
        field(default_factory=SimConfig)
    """The batched simulation."""
    render: Annotated[RenderConfig, BeforeValidator(_none_is_empty), AfterValidator(_whole_trajectory_views)] = \
        field(default_factory=RenderConfig)
    """Images."""
    output: Annotated[OutputConfig, BeforeValidator(_none_is_empty)] = field(default_factory=OutputConfig)
    """The HDF5 files and previews."""
    randomize: Annotated[_Randomize, BeforeValidator(_none_is_empty), AfterValidator(_with_defaults)] = \
        field(default_factory=dict)
    """group -> parameter -> distribution (a number is a constant; the forms: warpworm.data.randomize); parameters not
    named keep their defaults. Loaded, it holds every parameter of PARAM_SPECS as a warpworm.data.randomize.Distribution."""

    # ---- derived -------------------------------------------------------------------------------------------------
    @property
    def frames_per_trajectory(self) -> int:
        return len(self.sim.frame_times)

    @property
    def samples_per_trajectory(self) -> int:
        """K * F: every view (``render.views_per_frame``) of every frame of one simulated world."""
        return self.render.views_per_frame * len(self.sim.frame_times)

    @property
    def num_shards(self) -> int:
        return -(-self.num_samples // self.shard_size)

    def shard_range(self, k: int) -> tuple[int, int]:
        """Sample ids [start, stop) of shard k: always [k*S, min((k+1)*S, N)), whatever the workers."""
        return k * self.shard_size, min((k + 1) * self.shard_size, self.num_samples)

    def flat_distributions(self) -> dict[str, rnd.Distribution]:
        """'group.name' -> distribution."""
        return {f"{g}.{n}": d for g, params in self.randomize.items() for n, d in params.items()}

    def to_dict(self) -> dict:
        return {
            "name": self.name, "seed": self.seed, "num_samples": self.num_samples, "shard_size": self.shard_size,
            "sim": {k: v for k, v in dataclasses.asdict(self.sim).items() if not (k == "frame_unit" and v == "s")},
            # views_per_frame = 1 is left out, so the files' config_yaml stays that of before the option
            "render": {k: v for k, v in dataclasses.asdict(self.render).items()
                       if not (k == "views_per_frame" and v == 1) and k not in _render_keys_left_out(self.render)},
            "output": dataclasses.asdict(self.output),
            "randomize": {g: {n: dist.to_yaml() for n, dist in p.items()} for g, p in self.randomize.items()},
        }

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


@functools.cache
def schema_adapter() -> TypeAdapter:
    """pydantic's validator (and JSON Schema) of DatasetConfig, built on first use (0.3 s, not paid by processes that
    only import this module)."""
    return TypeAdapter(DatasetConfig)


# ---------------------------------------------------------------------------------------------------------------------
# pydantic's errors -> "path: got X; expected Y"
_KEYS = {"": [f.name for f in fields(DatasetConfig)], "sim": [f.name for f in fields(SimConfig)],
         "render": [f.name for f in fields(RenderConfig)], "output": [f.name for f in fields(OutputConfig)],
         "randomize": list(PARAM_SPECS), **{f"randomize.{g}": list(s) for g, s in PARAM_SPECS.items()}}
_EXPECTED = {"int_type": "an integer", "float_type": "a number", "finite_number": "a finite number",
             "bool_type": "true or false", "string_type": "a string", "list_type": "a list of numbers",
             "too_short": "a non-empty list", "greater_than_equal": ">= {ge}", "greater_than": "> {gt}",
             "less_than_equal": "<= {le}", "literal_error": "{expected}"}
_MAPPING = ("dataclass_type", "dataclass_exact_type", "dict_type", "model_type")


def _path(loc) -> str:
    return "".join(f"[{k}]" if isinstance(k, int) else f".{k}" for k in loc).lstrip(".")


def _message(e: dict) -> str:
    loc, kind, ctx = e["loc"], e["type"], e.get("ctx") or {}
    path = _path(loc)
    if kind == "config":
        return f"{ctx['path'] or path}: {ctx['detail']}"
    if kind in ("extra_forbidden", "unexpected_keyword_argument", "invalid_key"):  # invalid: not a string (YAML 1:)
        parent = _path(loc[:-1])
        what = {2: "group", 3: "parameter"}.get(len(loc), "key") if loc[0] == "randomize" else "key"
        key = f"{parent}.{loc[-1]}" if parent else str(loc[-1])
        return f"{key}: unknown {what}; expected one of {sorted(_KEYS.get(parent, []))}"
    if kind in _MAPPING:
        expected = "a mapping of parameters" if path.startswith("randomize.") else f"a mapping with keys {_KEYS[path]}"
    else:  # bounds of float fields come as floats: say 0, not 0.0
        ctx = {k: int(v) if isinstance(v, float) and v.is_integer() else v for k, v in ctx.items()}
        expected = _EXPECTED[kind].format(**ctx) if kind in _EXPECTED else e["msg"]
    return f"{path}: got {_fmt(e['input'])}; expected {expected}"


@functools.cache
def _field_adapter(section: str, name: str) -> TypeAdapter:
    cls = {"sim": SimConfig, "render": RenderConfig, "output": OutputConfig}[section]
    return TypeAdapter(typing.get_type_hints(cls, include_extras=True)[name])


def check_option(option: str, value, key: str):
    """A command-line ``option``'s ``value`` validated as the config key ``key`` (e.g. ``--dt`` as ``sim.dt``,
    ``--device`` as ``sim.device``): the validated value, or :class:`ConfigError` "--dt (sim.dt): got X; expected Y"."""
    section, name = key.split(".")
    try:
        out = _field_adapter(section, name).validate_python(value)
    except ValidationError as exc:
        msgs = [_message({**e, "loc": ()}) for e in exc.errors(include_url=False)]
        msgs = [m.replace(f"(override with {key}=cpu)", f"(use {option} cpu)") for m in msgs]
        raise ConfigError([f"{option} ({key}){m}" for m in msgs]) from None
    if isinstance(out, float) and not math.isfinite(out):  # as the config's sections (allow_inf_nan=False)
        raise ConfigError([f"{option} ({key}): got {_fmt(out)}; expected a finite number"])
    return out


def check_options(options: dict) -> dict:
    """:func:`check_option` of every ``{option: (value, key)}`` whose value is not None, all problems at once;
    returns {option: validated value}."""
    out, problems = {}, []
    for option, (value, key) in options.items():
        if value is None:
            out[option] = None
            continue
        try:
            out[option] = check_option(option, value, key)
        except ConfigError as exc:
            problems += exc.errors
    if problems:
        raise ConfigError(problems)
    return out


def config_from_dict(raw: dict) -> DatasetConfig:
    """Validate a raw mapping (as loaded from YAML) into a :class:`DatasetConfig`; raises :class:`ConfigError`."""
    if not isinstance(raw, dict):
        raise ConfigError([f"<root>: got {_fmt(raw)}; expected a mapping"])
    try:
        return schema_adapter().validate_python(raw)
    except ValidationError as exc:
        raise ConfigError([_message(e) for e in exc.errors(include_url=False)]) from None


# ---------------------------------------------------------------------------------------------------------------------
def config_packaged_names() -> list[str]:
    """Names of the YAML configs shipped in ``warpworm.dataset_configs``."""
    root = resources.files("warpworm.dataset_configs")
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".yaml"))


def read_yaml(source: str | os.PathLike) -> dict:
    """Load a config mapping from a path or a packaged name (``default``); ConfigError if neither exists/parses."""
    p = Path(source)
    if p.is_file():
        text = p.read_text()
    else:
        name = str(source)[:-5] if str(source).endswith(".yaml") else str(source)
        res = resources.files("warpworm.dataset_configs") / f"{name}.yaml"
        if "/" in str(source) or not res.is_file():
            raise ConfigError([f"config: got {_fmt(str(source))}; expected a YAML file path or a packaged name "
                               f"{config_packaged_names()}"])
        text = res.read_text()
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:  # one line: where, and what the parser expected
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1}, column {mark.column + 1})" if mark is not None else ""
        what = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ConfigError([f"config: {source} is not valid YAML{where}: {what}"]) from None
    return raw if raw is not None else {}


def apply_overrides(raw: dict, overrides: list[str]) -> dict:
    """Apply ``a.b.c=value`` overrides (value parsed as YAML) to a raw mapping; returns a new mapping."""
    raw = copy.deepcopy(raw)
    errors = []
    for item in overrides:
        if "=" not in item:
            errors.append(f"override {_fmt(item)}: expected key.path=value")
            continue
        path, text = item.split("=", 1)
        keys = path.strip().split(".")
        if not all(keys):
            errors.append(f"override {_fmt(item)}: empty key in path {_fmt(path)}")
            continue
        try:
            value = yaml.safe_load(text)
        except yaml.YAMLError:
            value = text
        node = raw
        for i, k in enumerate(keys[:-1]):
            nxt = node.get(k)
            if nxt is None:
                nxt = node[k] = {}
            if not isinstance(nxt, dict):
                errors.append(f"{'.'.join(keys[:i + 1])}: got {_fmt(nxt)}; cannot set {path} under a non-mapping")
                break
            node = nxt
        else:
            node[keys[-1]] = value
    if errors:
        raise ConfigError(errors)
    return raw


def load_config(source, overrides: list[str] = (), **top_level) -> DatasetConfig:
    """Load, override and validate. ``top_level`` (e.g. ``num_samples=100, seed=3``) are applied when not None."""
    raw = read_yaml(source) if not isinstance(source, dict) else copy.deepcopy(source)
    if not isinstance(raw, dict):
        raise ConfigError([f"<root>: got {_fmt(raw)}; expected a mapping"])
    raw = apply_overrides(raw, list(overrides))
    for k, v in top_level.items():
        if v is not None:
            raw[k] = v
    return config_from_dict(raw)


def _is_warpworm_manifest(path: Path) -> bool:
    """Whether ``path`` is a warpworm dataset's manifest (another tool's manifest.json is not)."""
    import json

    from warpworm.data.dataset import FORMAT

    try:
        return json.loads(path.read_text()).get("format") == FORMAT
    except (OSError, ValueError, AttributeError, UnicodeDecodeError):
        return False


def check_output_dir(out: str | os.PathLike, resume: bool) -> None:
    """Refuse an unwritable output folder, or a non-empty one without ``resume``; writes nothing that stays.

    A writability probe creates and removes one temporary file (the only reliable test: permission bits lie for root
    and on read-only mounts).
    """
    out = Path(out)
    errors = []
    if out.exists() and not out.is_dir():
        raise ConfigError([f"--out: got '{out}'; expected a folder (it is a file)"])
    if out.is_dir():
        names = sorted(p.name for p in out.iterdir())
        ours = [n for n in names if re.fullmatch(r"shard-\d+\.h5", n)
                or (n == "manifest.json" and _is_warpworm_manifest(out / n))]
        visible = [n for n in names if not n.startswith(".")]  # hidden: a killed job's lock and temporaries
        if visible and not ours:  # not a warpworm dataset: never write next to someone else's files
            what = "an empty or new folder" + (" or a dataset to resume" if resume else "")
            raise ConfigError([f"--out: got '{out}'; expected {what} (it holds other files, e.g. {visible[0]}, and "
                               "no warpworm dataset: no shard-*.h5, no manifest.json of format warpworm-dataset)"])
        if not resume and names:
            raise ConfigError([f"--out: got '{out}'; expected an empty or new folder (it is not empty: it holds a "
                               "warpworm dataset; use --resume to continue its job, or another --out)"])
        probe_dir = out
    else:
        probe_dir = out.parent
        while not probe_dir.exists() and probe_dir != probe_dir.parent:
            probe_dir = probe_dir.parent
    try:
        fd, name = tempfile.mkstemp(prefix=".warpworm-probe-", dir=probe_dir)
        os.close(fd)
        os.unlink(name)
    except OSError as exc:
        errors.append(f"--out: got '{out}'; expected a writable folder ({exc.strerror}: {probe_dir})")
    if errors:
        raise ConfigError(errors)
