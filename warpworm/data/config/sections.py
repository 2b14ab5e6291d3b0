"""The config's sections ``sim``, ``render`` and ``output`` as pydantic dataclasses (their field docstrings are the
documentation), the strict scalar types and the checks that relate a field to others."""

from __future__ import annotations

import importlib.util
from dataclasses import dataclass, field
from typing import Annotated, Literal

import numpy as np
from pydantic import AfterValidator, ConfigDict, Field, ValidationInfo
from pydantic_core import PydanticCustomError

from warpworm import quiet_warp
from warpworm.physics.gaits import DEFAULT_DT, DEFAULT_SUBSTEPS
from warpworm.physics.param_specs import fmt_value as _fmt


def problem(detail: str, path: str | None = None) -> PydanticCustomError:
    """A check of ours failing: ``detail`` is "got X; expected Y"; ``path`` names the key when it is not the one
    being validated (a check relating two keys)."""
    return PydanticCustomError("config", "{detail}", {"detail": detail, "path": path})


# Strict scalars: the string "yes", "0.1" or 1.5 for an integer are mistakes, not values to convert; an integer is
# a number (stored as a float).
Int = Annotated[int, Field(strict=True)]
Num = Annotated[float, Field(strict=True)]
Bool = Annotated[bool, Field(strict=True)]
Str = Annotated[str, Field(strict=True)]
SECTION = ConfigDict(extra="forbid", allow_inf_nan=False, use_attribute_docstrings=True, validate_default=True)


def none_is_empty(v):
    return {} if v is None else v  # "sim:" with nothing under it = all defaults


def _check_frame_times(ft: list[float], info: ValidationInfo) -> list[float]:
    if any(t < 0 for t in ft) or any(b <= a for a, b in zip(ft, ft[1:])):
        raise problem(f"got {ft}; expected strictly increasing times >= 0 [s]")
    dt = info.data.get("dt") if info.data.get("frame_unit", "s") == "s" else None  # cycles: rounded per world
    # frames are taken after whole steps: a time between steps would be rounded silently, and two frames within one
    # step would store the same snapshot under two times
    if dt is not None and any(abs(t / dt - round(t / dt)) > 1e-6 * max(1.0, t / dt) for t in ft):
        raise problem(f"got {ft}; expected multiples of sim.dt = {dt} [s]")
    return ft


def _check_device(ident: str) -> str:
    """"auto" -> the first GPU if there is one, else the CPU (stored so in the config); refused unless Warp can run on
    it here (so a CUDA config fails before any work on a machine without a GPU, not in a worker's traceback)."""
    import warp as wp  # start-up time: Warp loads only when a config names a device

    quiet_warp()
    if ident == "auto":
        ident = "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"
    try:
        if ident.startswith("cuda") and wp.get_cuda_device_count() == 0:
            raise ValueError(ident)  # asking Warp for it would print CUDA driver errors first
        wp.get_device(ident)
    except (ValueError, RuntimeError):
        raise problem(f"got {_fmt(ident)}; expected 'auto' or a Warp device available here: one of "
                       f"{[str(d) for d in wp.get_devices()]} (override with sim.device=cpu)") from None
    return ident


@dataclass
class SimConfig:
    """The batched simulation (SI units)."""

    __pydantic_config__ = SECTION
    worlds: Annotated[Int, Field(ge=1)] = 64
    """W: worlds simulated at once in one solver batch."""
    dt: Annotated[Num, Field(gt=0)] = DEFAULT_DT
    """Solver time step [s] (the gait runs' warpworm.physics.gaits.DEFAULT_DT)."""
    substeps: Annotated[Int, Field(ge=1)] = DEFAULT_SUBSTEPS
    """Solver substeps per time step."""
    settle_time: Annotated[Num, Field(ge=0)] = 0.3
    """Time [s] the worm settles under gravity with the EPM parked at the path start."""
    frame_unit: Literal["s", "cycle"] = "s"
    """Unit of ``frame_times``: 's' (seconds, multiples of ``dt``), or 'cycle' (cycles of each world's EPM
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
        raise problem(f"got {r}; expected [lo, hi] with 0 <= lo <= hi")
    return r


def _check_band_colors(c):
    if c is not None:
        a = np.asarray(c, dtype=np.float64)
        if a.shape != (5, 3) or not np.all((a >= 0) & (a <= 1)):
            raise problem(f"got {c}; expected five [r, g, b] display colours in [0, 1], tail -> head")
    return c


def _mitsuba_missing() -> bool:
    return importlib.util.find_spec("mitsuba") is None


def _check_engine(engine: str) -> str:
    if engine == "pathtraced" and _mitsuba_missing():
        raise problem("got 'pathtraced'; expected 'raster' here: Mitsuba 3 is not installed (pip install "
                       "'warpworm[pathtrace]')")
    return engine


def _check_pathtraced_fraction(frac: float, info: ValidationInfo) -> float:
    if frac > 0 and info.data.get("engine") == "pathtraced":
        raise problem(f"got {frac}; expected 0 with render.engine 'pathtraced' (every image is path-traced; mix the "
                       "engines with engine 'raster' and a fraction)")
    if frac > 0 and _mitsuba_missing():
        raise problem(f"got {frac}; expected 0 here: Mitsuba 3 is not installed (pip install 'warpworm[pathtrace]')")
    return frac


def _check_signed_range(r: list) -> list:
    if r[0] > r[1]:
        raise problem(f"got {r}; expected [lo, hi] with lo <= hi")
    return r


@dataclass
class RenderConfig:
    """The images."""

    __pydantic_config__ = SECTION
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
    # -- nothing world-fixed relative to the worm, and shadows; OFF values keep the
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
    rendered from the light by the same rasterizer, soft by percentage-closer filtering."""
    shadow_map: Annotated[Int, Field(ge=0, le=4096)] = 0
    """Side [px] of each light's shadow map; 0: the image's larger side (a texel about a pixel at the worm)."""
    supersample: Annotated[Int, Field(ge=1, le=8)] = 1
    """Anti-aliased RGB: s x s samples per pixel averaged in linear RGB (s = 1: one sample at the centre). Depth,
    segmentation, masks and keypoint visibility stay exact at pixel centres."""
    texture_filter: Bool = True
    """With supersample > 1: a pixel wholly on the floor takes the floor texture's mean over its footprint (the
    checker's exact box average) instead of s x s texture samples (closer to the pixel's true mean, a third of the
    work); false: every pixel sampled s x s."""
    distortion: Bool = False
    """Lens distortion drawn per camera (OpenCV's k1, k2, p1, p2, k3, each uniform in its range below), stored as
    camera/dist: images are warped through it; keypoints/pixel (= cv2.projectPoints with it), labels/bbox_obj and
    visibility follow it."""
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
    along its simulated velocities (labels at the frame's time). 0: no blur."""
    motion_blur_samples: Annotated[Int, Field(ge=2, le=64)] = 4
    """Sub-frames of the shutter (``motion_blur``)."""
    paper_bsdf: Bool = False
    """The sheet as paper: wrapped diffuse (light through the thin sheet), a soft sheen and a hemispherical ambient
    (sky above, the floor's bounce below) instead of Lambert with a constant ambient; parameters per trajectory
    (params/paper.*)."""
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
    # -- the path-traced engine (warpworm.render.pathtrace, the `pathtrace` extra); labels stay the raster's
    engine: Annotated[Literal["raster", "pathtraced"], AfterValidator(_check_engine)] = "raster"
    """'raster': every image from the rasterizer; 'pathtraced': every image path-traced by Mitsuba 3 (same meshes,
    cameras, colours, lights; depth, segmentation and every label from the rasterizer's exact passes)."""
    pathtraced_fraction: Annotated[Num, Field(ge=0, le=1), AfterValidator(_check_pathtraced_fraction)] = 0.0
    """With ``engine: raster``: the share of samples path-traced instead, drawn per sample from its seed (each
    sample's engine is stored in the ``engine`` dataset). 0: none."""
    pathtraced_spp: Annotated[Int, Field(ge=1)] = 16
    """Samples per pixel of the path-traced images."""
    # -- the marker bands' colours (randomize.texture.worm: bands)
    band_colors: Annotated[list[list[Num]] | None, AfterValidator(_check_band_colors)] = None
    """Five display colours [[r, g, b], ...] in [0, 1], tail -> head, of the worm painted in bands
    (``randomize.texture.worm: bands``; ``warpworm track --band-colors-from DATASET`` reads them back). None: the
    paper's (``warpworm.render.scene.BAND_COLORS``)."""


RENDER_OFF_GROUPS = {"plate_pose": ("plate_offset",),
                     "lights": ("light_count", "light_distance", "light_elevation", "light_size", "light_irradiance",
                                "light_warmth"),
                     "shadows": ("shadow_map",), "supersample": (), "texture_filter": (),
                     "distortion": ("distortion_k1", "distortion_k2", "distortion_p", "distortion_k3"),
                     "exposure": (), "white_balance": (), "distractors": (), "plate_materials": (), "paper_bsdf": (),
                     "motion_blur": ("motion_blur_samples",),
                     "engine": ("pathtraced_fraction", "pathtraced_spp"), "band_colors": ()}
"""render switch -> the keys it enables: a group whose switch and keys are all at their defaults (OFF) is left out
of ``to_dict`` (so the files' config_yaml stays that of before the option)."""


def render_keys_left_out(render: "RenderConfig") -> set:
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

    __pydantic_config__ = SECTION
    compression: Literal["lzf", "gzip", "none"] = "gzip"
    """HDF5 filter for images: 'gzip' (level 1: smaller than 'lzf' on rendered images and readable by every HDF5
    tool), 'lzf' or 'none'."""
    compression_level: Annotated[Int, Field(ge=0, le=9)] = 1
    """gzip level 0..9 (ignored for lzf/none)."""
    preview: Bool = True
    """Write ``preview.png`` (contact sheet) and ``preview.mp4`` (one world) at the end."""
