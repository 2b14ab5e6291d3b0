"""Dataset job configuration: YAML -> typed, validated dataclasses, with dotted command-line overrides.

Every mistake (unknown key, wrong type, negative size, low > high, unknown gait, unwritable output folder) raises
:class:`ConfigError` *before any work*, with one line per problem naming the key path, the value given and what was
expected. Nothing is written by loading or validating a config.

Schema (all SI: m, s, rad, kg; see ``docs/dataset.md`` and the packaged ``dataset_configs/default.yaml``)::

    name: str                       # free text, stored in the files
    seed: int >= 0                  # master seed; sample i's values depend only on (seed, i)
    num_samples: int >= 1           # N images (samples) in the dataset
    shard_size: int >= 1            # samples per HDF5 shard; a multiple of len(sim.frame_times)
    sim:
      worlds: int >= 1              # W worlds simulated at once (batch size)
      dt: float > 0                 # time step [s]
      substeps: int >= 1            # solver substeps per step
      settle_time: float >= 0       # EPM parked, worm settles under gravity [s]
      frame_times: [float >= 0]     # times after settling at which frames are taken [s], strictly increasing
      n_units: int >= 1             # prism units (fixes array shapes: creases, vertices) — shared by the dataset
      max_attempts: int >= 1        # an unstable world is redrawn (attempt + 1) at most this many times in all
      device: str                   # Warp device: "cpu", "cuda:0" or "auto"
    render:
      width, height: int >= 8       # image size [px]
      batch: int >= 1               # images per render call (memory bound)
      camera_per_frame: bool        # false: one camera per trajectory (a video); true: a new camera per frame
    output:
      compression: lzf | gzip | none
      compression_level: 0..9       # gzip only
      preview: bool                 # contact sheet PNG + MP4 of one world at the end
    randomize:                      # group -> parameter -> distribution (see warpworm.randomize)
      worm:    {<WormParams field or component>: dist}
      camera:  {distance, elevation, azimuth, roll, fov_y (constant or uniform), lookat_jitter,
                min_in_frame, max_tries (constants)}
      light:   {elevation, azimuth, intensity, ambient}
      color:   {worm_hue, worm_saturation, worm_value, floor_hue, floor_saturation, floor_value, background_value}
      texture: {floor, floor_scale, worm}
      sensor:  {noise_std, blur_sigma, jpeg_quality, brightness, contrast}
"""

from __future__ import annotations

import copy
import dataclasses
import math
import os
import tempfile
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from . import randomize as rnd
from .params import GAITS, MAGNET_MODELS, WormParams


class ConfigError(ValueError):
    """Invalid configuration; ``errors`` holds one message per problem ("path: got X; expected Y")."""

    def __init__(self, errors: list[str]):
        self.errors = list(errors)
        super().__init__("invalid dataset config:\n  " + "\n  ".join(self.errors))


# ---------------------------------------------------------------------------------------------------------------------
# Randomizable parameters: group -> name -> (default distribution, unit, allowed range, doc).
@dataclass(frozen=True)
class ParamSpec:
    default: Any
    unit: str
    low: float | None = None  # inclusive bounds a value may take (None: unbounded)
    high: float | None = None
    values: tuple | None = None  # allowed values for discrete parameters
    doc: str = ""
    positive: bool = False  # strictly > 0
    preset: bool = False  # NaN (the default) means "the gait preset's value" (warpworm.gaits.GAIT_PRESETS)
    ranges_only: bool = False  # a constant or {uniform: [lo, hi]} only (the camera sampler's ranges)
    constant_only: bool = False  # a setting, not a distribution
    integer: bool = False  # whole numbers only


_WP = WormParams()
_PI = math.pi


def _worm_specs() -> dict[str, ParamSpec]:
    s = {
        "a": ParamSpec(_WP.a, "m", positive=True, doc="side of the triangular cross-section"),
        "b": ParamSpec(_WP.b, "m", positive=True, doc="panel length along the worm, unfolded"),
        "l0": ParamSpec(_WP.l0, "m", positive=True, doc="rest length of the worm (sets the rest fold angle, eq. 7)"),
        "sheet_density": ParamSpec(_WP.sheet_density, "kg/m^2", positive=True, doc="areal density of the sheet"),
        "hinge_stiffness": ParamSpec(_WP.hinge_stiffness, "N*m/rad/m", positive=True, doc="crease stiffness k_alpha"),
        "bar_stiffness": ParamSpec(_WP.bar_stiffness, "N", positive=True, doc="bar axial rigidity EA"),
        "valley_bar_stiffness": ParamSpec(_WP.valley_bar_stiffness, "N", positive=True,
                                          doc="axial rigidity EA of the valley-ring bars (panel bending; lets the tube fold)"),
        "damping": ParamSpec(_WP.damping, "1/s", low=0.0, doc="linear velocity damping rate"),
        "mu_static": ParamSpec(_WP.mu_static, "1", low=0.0, doc="static friction coefficient"),
        "mu_kinetic": ParamSpec(_WP.mu_kinetic, "1", low=0.0,
                                doc="kinetic friction coefficient (clipped to <= mu_static per sample)"),
        "floor_incline": ParamSpec(_WP.floor_incline, "rad", low=-_PI / 2, high=_PI / 2, doc="floor slope about +y"),
        "gravity": ParamSpec(_WP.gravity, "m/s^2", low=0.0, doc="gravitational acceleration"),
        "dipole_density": ParamSpec(_WP.dipole_density, "1/m^3", positive=True, doc="dipoles per m^3 ('dipoles')"),
        "magnet_mass_density": ParamSpec(_WP.magnet_mass_density, "kg/m^3", positive=True, doc="magnet density"),
        "epm_moment": ParamSpec(_WP.epm_moment, "A*m^2", low=0.0, doc="EPM dipole moment magnitude"),
        "epm_size_x": ParamSpec(float(_WP.epm_size[0]), "m", positive=True, doc="EPM extent along its x"),
        "epm_size_y": ParamSpec(float(_WP.epm_size[1]), "m", positive=True, doc="EPM extent along its y"),
        "epm_size_z": ParamSpec(float(_WP.epm_size[2]), "m", positive=True, doc="EPM extent along its z (moment)"),
        "ipm_moment_tail": ParamSpec(float(_WP.ipm_moment[0]), "A*m^2", low=0.0, doc="tail IPM moment"),
        "ipm_moment_centre": ParamSpec(float(_WP.ipm_moment[1]), "A*m^2", low=0.0, doc="centre IPM moment"),
        "ipm_moment_head": ParamSpec(float(_WP.ipm_moment[2]), "A*m^2", low=0.0, doc="head IPM moment"),
        "ipm_diameter": ParamSpec(_WP.ipm_diameter, "m", positive=True, doc="IPM disk diameter"),
        "ipm_thickness": ParamSpec(_WP.ipm_thickness, "m", positive=True, doc="IPM disk thickness"),
        "wavelength": ParamSpec(_WP.wavelength, "m", low=0.0, doc="EPM path wavelength w"),
        "amplitude": ParamSpec(_WP.amplitude, "m", low=0.0, doc="EPM path amplitude a"),
        "closest_approach": ParamSpec(_WP.closest_approach, "m", low=0.0, doc="EPM closest approach h"),
        "orientation": ParamSpec(_WP.orientation, "rad", preset=True,
                                 doc="EPM moment angle theta (NaN: the gait preset)"),
        "cycle_period": ParamSpec(_WP.cycle_period, "s", positive=True, doc="duration of one EPM cycle"),
        # Batch-shared in the solver; randomizing them splits a batch into groups (one solver model per group).
        "gait": ParamSpec(_WP.gait, "", values=GAITS, doc="EPM path preset"),
        "backward": ParamSpec(_WP.backward, "", values=(False, True), doc="drive toward -x"),
        "magnet_model": ParamSpec(_WP.magnet_model, "", values=MAGNET_MODELS, doc="magnet force model"),
    }
    # Path (and other) fields that the gait presets tune default to NaN = "the preset's value for the sample's gait",
    # so a config that only names a gait gets the tuned path (resolved per sample in warpworm.pipeline.draw_worm).
    from .gaits import GAIT_PRESETS

    for key in sorted({k for preset in GAIT_PRESETS.values() for k in preset}):
        if key in s:
            s[key] = dataclasses.replace(s[key], default=float("nan"), preset=True,
                                         doc=s[key].doc + " (default NaN: the gait preset's value)")
    if hasattr(_WP, "hinge_damping"):
        s["hinge_damping"] = ParamSpec(_WP.hinge_damping, "N*m*s/rad/m", low=0.0, doc="crease damping c_alpha")
    # Any other scalar WormParams field is randomizable too (constant at its default unless configured), so a field
    # added to the parameter contract is never silently unreachable from configs.
    for f in fields(WormParams):
        v = getattr(_WP, f.name)
        if f.name not in s and f.name not in ("n_units", "epm_size", "ipm_moment") and isinstance(v, (int, float)) \
                and not isinstance(v, bool):
            s[f.name] = ParamSpec(float(v), "see warpworm.params", doc=f"WormParams.{f.name}")
    return s


PARAM_SPECS: dict[str, dict[str, ParamSpec]] = {
    "worm": _worm_specs(),
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
        "worm": ParamSpec({"choice": ["plain", "fibre"]}, "", values=("plain", "fibre"), doc="sheet pattern"),
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

# Parameters that are shared by one solver batch: a batch is split into groups by these.
BATCH_SHARED = ("worm.gait", "worm.backward", "worm.magnet_model")


# ---------------------------------------------------------------------------------------------------------------------
@dataclass
class SimConfig:
    worlds: int = 64
    """W: worlds simulated at once in one solver batch."""
    dt: float = 0.004
    """Solver time step [s] (the gait runs' warpworm.gaits.DEFAULT_DT)."""
    substeps: int = 4
    """Solver substeps per time step."""
    settle_time: float = 0.3
    """Time [s] the worm settles under gravity with the EPM parked at the path start."""
    frame_times: list = field(default_factory=lambda: [0.2, 0.5, 0.8, 1.0])
    """Times [s] after settling at which frames are taken; each trajectory gives len(frame_times) samples; multiples of ``dt``."""
    n_units: int = 6
    """Prism units of the worm; fixes the number of creases and vertices, so one value per dataset."""
    max_attempts: int = 4
    """Unstable worlds are redrawn with attempt + 1, at most this many attempts in all; then the job fails."""
    device: str = "cpu"
    """Warp device for simulation and rendering: "cpu", "cuda:N", or "auto" (the first GPU if any, else the CPU)."""


@dataclass
class RenderConfig:
    width: int = 128
    """Image width [px]."""
    height: int = 96
    """Image height [px]."""
    camera_per_frame: bool = False
    """False: one camera per trajectory (frames of a world form a video); True: a new camera for every frame."""
    batch: int = 1024
    """Images per render call (whole trajectories); bounds the memory of images held before writing."""


@dataclass
class OutputConfig:
    compression: str = "gzip"
    """HDF5 filter for images: 'gzip' (level 1 measured smaller *and* faster to write and read than 'lzf' on rendered
    images; benchmarks/bench_dataset.py), 'lzf' or 'none'."""
    compression_level: int = 1
    """gzip level 0..9 (ignored for lzf/none)."""
    preview: bool = True
    """Write ``preview.png`` (contact sheet) and ``preview.mp4`` (one world) at the end."""


@dataclass
class DatasetConfig:
    name: str = "dataset"
    seed: int = 0
    num_samples: int = 64
    shard_size: int = 32
    sim: SimConfig = field(default_factory=SimConfig)
    render: RenderConfig = field(default_factory=RenderConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    randomize: dict = field(default_factory=dict)
    """group -> name -> :class:`warpworm.randomize.Distribution`, every parameter of PARAM_SPECS resolved."""

    # ---- derived -------------------------------------------------------------------------------------------------
    @property
    def frames_per_trajectory(self) -> int:
        return len(self.sim.frame_times)

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
        d = {
            "name": self.name, "seed": self.seed, "num_samples": self.num_samples, "shard_size": self.shard_size,
            "sim": dataclasses.asdict(self.sim), "render": dataclasses.asdict(self.render),
            "output": dataclasses.asdict(self.output),
            "randomize": {g: {n: dist.to_yaml() for n, dist in p.items()} for g, p in self.randomize.items()},
        }
        return d

    def to_yaml(self) -> str:
        return yaml.safe_dump(self.to_dict(), sort_keys=False)


# ---------------------------------------------------------------------------------------------------------------------
_TYPE_NAMES = {int: "an integer", float: "a number", bool: "true/false", str: "a string", list: "a list of numbers"}

# path -> (min, strict) for numeric checks beyond the type
_CONSTRAINTS = {
    "seed": (0, False), "num_samples": (1, False), "shard_size": (1, False),
    "sim.worlds": (1, False), "sim.dt": (0, True), "sim.substeps": (1, False), "sim.settle_time": (0, False),
    "sim.n_units": (1, False), "sim.max_attempts": (1, False),
    "render.width": (8, False), "render.height": (8, False), "render.batch": (1, False), "output.compression_level": (0, False),
}


def _fmt(v) -> str:
    return repr(v) if not isinstance(v, str) else f"'{v}'"


def _coerce(value, typ, path, errors):
    """Check a YAML scalar against a field type; ints are accepted for floats (never bools for numbers)."""
    if typ is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            errors.append(f"{path}: got {_fmt(value)}; expected {_TYPE_NAMES[float]}")
            return None
        return float(value)
    if typ is int:
        if isinstance(value, bool) or not isinstance(value, int):
            errors.append(f"{path}: got {_fmt(value)}; expected {_TYPE_NAMES[int]}")
            return None
        return value
    if typ is bool:
        if not isinstance(value, bool):
            errors.append(f"{path}: got {_fmt(value)}; expected true or false")
            return None
        return value
    if typ is str:
        if not isinstance(value, str):
            errors.append(f"{path}: got {_fmt(value)}; expected a string")
            return None
        return value
    if typ is list:
        if not isinstance(value, list) or not value or any(
                isinstance(x, bool) or not isinstance(x, (int, float)) for x in value):
            errors.append(f"{path}: got {_fmt(value)}; expected a non-empty list of numbers")
            return None
        return [float(x) for x in value]
    raise TypeError(typ)


_FIELD_TYPES = {"int": int, "float": float, "bool": bool, "str": str, "list": list}


def _build_section(cls, raw, path, errors):
    obj = cls()
    if raw is None:
        return obj
    if not isinstance(raw, dict):
        errors.append(f"{path}: got {_fmt(raw)}; expected a mapping with keys {[f.name for f in fields(cls)]}")
        return obj
    names = {f.name: f for f in fields(cls)}
    for key, value in raw.items():
        p = f"{path}.{key}" if path else str(key)
        if key not in names:
            errors.append(f"{p}: unknown key; expected one of {sorted(names)}")
            continue
        typ = _FIELD_TYPES[names[key].type] if isinstance(names[key].type, str) else names[key].type
        v = _coerce(value, typ, p, errors)
        if v is None:
            continue
        lim = _CONSTRAINTS.get(p)
        if lim is not None:
            lo, strict = lim
            if (v <= lo) if strict else (v < lo):
                errors.append(f"{p}: got {_fmt(value)}; expected {'>' if strict else '>='} {lo}")
                continue
        setattr(obj, key, v)
    return obj


def _check_spec(path: str, dist: rnd.Distribution, spec: ParamSpec, errors: list[str]):
    if spec.values is not None and not (spec.low is not None and dist.is_numeric):
        vals = rnd.distribution_values(dist)
        if not vals:
            errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected a constant or choice/grid of {list(spec.values)}")
            return
        bad = [v for v in vals if v not in spec.values or type(v) is not type(spec.values[0])]
        if bad:
            errors.append(f"{path}: got {_fmt(bad[0])}; expected one of {list(spec.values)}")
        return
    if spec.constant_only and not isinstance(dist, rnd.Constant):
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected a constant [{spec.unit}] ({spec.doc})")
        return
    if spec.ranges_only and not isinstance(dist, (rnd.Constant, rnd.Uniform)):
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected a constant or {{uniform: [lo, hi]}} "
                      f"[{spec.unit}] (the camera sampler draws uniformly in the range, per attempt)")
        return
    b = rnd.distribution_bounds(dist)
    if b is None:
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected numeric values [{spec.unit}]")
        return
    lo, hi = b
    if spec.integer and not (float(lo).is_integer() and float(hi).is_integer()):
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected a whole number")
    if spec.preset and isinstance(dist, rnd.Constant) and math.isnan(lo):
        return
    if spec.positive and lo <= 0:
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected values > 0 [{spec.unit}]")
    if spec.low is not None and lo < spec.low:
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected values >= {spec.low} [{spec.unit}]")
    if spec.high is not None and hi > spec.high:
        errors.append(f"{path}: got {_fmt(dist.to_yaml())}; expected values <= {spec.high} [{spec.unit}]")


def _build_randomize(raw, errors) -> dict:
    out: dict[str, dict[str, rnd.Distribution]] = {}
    if raw is not None and not isinstance(raw, dict):
        errors.append(f"randomize: got {_fmt(raw)}; expected a mapping of groups {sorted(PARAM_SPECS)}")
        raw = None
    raw = raw or {}
    for group in raw:
        if group not in PARAM_SPECS:
            errors.append(f"randomize.{group}: unknown group; expected one of {sorted(PARAM_SPECS)}")
    for group, specs in PARAM_SPECS.items():
        given = raw.get(group) or {}
        if not isinstance(given, dict):
            errors.append(f"randomize.{group}: got {_fmt(given)}; expected a mapping of parameters")
            given = {}
        for name in given:
            if name not in specs:
                errors.append(f"randomize.{group}.{name}: unknown parameter; expected one of {sorted(specs)}")
        out[group] = {}
        for name, spec in specs.items():
            path = f"randomize.{group}.{name}"
            src = given[name] if name in given else spec.default
            try:
                dist = rnd.parse_distribution(src)
            except rnd.DistributionError as exc:
                errors.append(f"{path}: {exc}")
                continue
            _check_spec(path, dist, spec, errors)
            out[group][name] = dist
    return out


def config_from_dict(raw: dict) -> DatasetConfig:
    """Validate a raw mapping (as loaded from YAML) into a :class:`DatasetConfig`; raises :class:`ConfigError`."""
    errors: list[str] = []
    if not isinstance(raw, dict):
        raise ConfigError([f"<root>: got {_fmt(raw)}; expected a mapping"])
    top = {"name": str, "seed": int, "num_samples": int, "shard_size": int}
    sections = {"sim": SimConfig, "render": RenderConfig, "output": OutputConfig}
    cfg = DatasetConfig()
    for key, value in raw.items():
        if key in top:
            v = _coerce(value, top[key], key, errors)
            if v is None:
                continue
            lim = _CONSTRAINTS.get(key)
            if lim is not None and v < lim[0]:
                errors.append(f"{key}: got {_fmt(value)}; expected >= {lim[0]}")
                continue
            setattr(cfg, key, v)
        elif key in sections:
            setattr(cfg, key, _build_section(sections[key], value, key, errors))
        elif key != "randomize":
            errors.append(f"{key}: unknown key; expected one of {sorted([*top, *sections, 'randomize'])}")
    cfg.randomize = _build_randomize(raw.get("randomize"), errors)

    ft = cfg.sim.frame_times
    if any(t < 0 for t in ft) or any(b <= a for a, b in zip(ft, ft[1:])):
        errors.append(f"sim.frame_times: got {ft}; expected strictly increasing times >= 0 [s]")
    elif cfg.sim.dt > 0:
        # frames are taken after whole steps: a time between steps would be rounded silently, and two frames within
        # one step would store the same snapshot under two times
        steps = [t / cfg.sim.dt for t in ft]
        if any(abs(k - round(k)) > 1e-6 * max(1.0, k) for k in steps):
            errors.append(f"sim.frame_times: got {ft}; expected multiples of sim.dt = {cfg.sim.dt} [s]")
    if cfg.output.compression not in ("lzf", "gzip", "none"):
        errors.append(f"output.compression: got {_fmt(cfg.output.compression)}; expected one of ['lzf', 'gzip', 'none']")
    if cfg.output.compression_level > 9:
        errors.append(f"output.compression_level: got {cfg.output.compression_level}; expected 0..9")
    if cfg.shard_size % len(ft) != 0:
        errors.append(f"shard_size: got {cfg.shard_size}; expected a multiple of len(sim.frame_times) = {len(ft)} "
                      "(a shard holds whole trajectories)")
    if cfg.sim.device == "auto":  # the first GPU if there is one, else the CPU (resolved and stored in the config)
        cfg.sim.device = _auto_device()
    device_error = _check_device(cfg.sim.device)
    if device_error:
        errors.append(f"sim.device: got {_fmt(cfg.sim.device)}; expected {device_error}")
    if errors:
        raise ConfigError(errors)
    return cfg


def _auto_device() -> str:
    import warp as wp

    from . import quiet_warp

    quiet_warp()
    return "cuda:0" if wp.get_cuda_device_count() > 0 else "cpu"


def _check_device(ident: str) -> str | None:
    """None if Warp can run on ``ident`` here, else what would be accepted (so a CUDA config fails before any work
    on a machine without a GPU, not in a worker's traceback)."""
    import warp as wp

    from . import quiet_warp

    quiet_warp()
    try:
        wp.get_device(ident)
    except (ValueError, RuntimeError):
        names = [str(d) for d in wp.get_devices()]
        return f"'auto' or a Warp device available here: one of {names} (override with sim.device=cpu)"
    return None


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
    except yaml.YAMLError as exc:
        raise ConfigError([f"config: {source} is not valid YAML: {exc}"]) from None
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
        if not resume and any(out.iterdir()):
            raise ConfigError([f"--out: got '{out}'; expected an empty or new folder (it is not empty; "
                               "use --resume to continue a job there)"])
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
