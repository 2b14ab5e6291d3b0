"""The parameter contract: every randomizable :class:`~warpworm.physics.params.WormParams` field's unit, bounds and
config default, declared once and read by the config schema (``warpworm.data.config``), the model
(``warpworm.sim.model.ModelBuilder``) and the JSON Schema (``warpworm config-schema``).

The default of each spec is the field's ``WormParams`` default, except the EPM path fields a gait preset tunes: there
it is NaN, "the preset's value for the sample's gait" (resolved per sample by ``warpworm.data.sampling.draw_worm``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from warpworm.errors import ConfigError
from warpworm.physics.gaits import GAIT_PRESETS
from warpworm.physics.params import GAITS, MAGNET_MODELS, WormParams


@dataclass(frozen=True)
class ParamSpec:
    """One randomizable parameter: its default distribution (a number is a constant), unit and allowed values."""

    default: Any
    unit: str
    low: float | None = None  # inclusive bounds a value may take (None: unbounded)
    high: float | None = None
    values: tuple | None = None  # allowed values for discrete parameters
    doc: str = ""
    positive: bool = False  # strictly > 0
    preset: bool = False  # NaN (the default) means "the gait preset's value" (warpworm.physics.gaits.GAIT_PRESETS)
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
        "friction_backward_ratio": ParamSpec(_WP.friction_backward_ratio, "1", positive=True,
                                             doc="friction tail-ward over head-ward (1: isotropic, the paper's)"),
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
    # so a config that only names a gait gets the tuned path.
    for key in sorted({k for preset in GAIT_PRESETS.values() for k in preset}):
        if key in s:
            s[key] = dataclasses.replace(s[key], default=float("nan"), preset=True,
                                         doc=s[key].doc + " (default NaN: the gait preset's value)")
    s["hinge_damping"] = ParamSpec(_WP.hinge_damping, "N*m*s/rad/m", low=0.0, doc="crease damping c_alpha")
    # Any other scalar WormParams field is randomizable too (constant at its default unless configured), so a field
    # added to the parameter contract is never silently unreachable from configs.
    for f in fields(WormParams):
        v = getattr(_WP, f.name)
        if f.name not in s and f.name not in ("n_units", "epm_size", "ipm_moment") and isinstance(v, (int, float)) \
                and not isinstance(v, bool):
            s[f.name] = ParamSpec(float(v), "see warpworm.physics.params", doc=f"WormParams.{f.name}")
    # bounds for some of those, set in place (the order of WORM_SPECS is the order of every shard's config_yaml: a
    # resumed dataset compares it as text)
    s["support_thickness"] = ParamSpec(_WP.support_thickness, "m", low=0.0,
                                       doc="support plate the worm walks on; the EPM moves beneath it")
    s["closest_approach_scale"] = ParamSpec(_WP.closest_approach_scale, "1", positive=True,
                                            doc="closest approach h x this (after the gait preset)")
    s["wavelength_scale"] = ParamSpec(_WP.wavelength_scale, "1", positive=True,
                                      doc="wavelength w x this (after the gait preset)")
    s["waist_close_strain"] = ParamSpec(_WP.waist_close_strain, "1", low=0.0, high=1.0,
                                        doc="how far a waist bar may shorten before it turns rigid (strain)")
    s["waist_stop_strain"] = ParamSpec(_WP.waist_stop_strain, "1", low=0.0,
                                       doc="stretch beyond which a waist bar turns rigid (strain)")
    s["fold_limit_stiffness"] = ParamSpec(_WP.fold_limit_stiffness, "N*m/rad/m", low=0.0,
                                          doc="barrier stiffness of a crease past its fold range")
    return s


WORM_SPECS: dict[str, ParamSpec] = _worm_specs()
"""``randomize.worm.<name>`` -> its spec, in the order of every shard's ``config_yaml``. The vector fields appear by
component (``epm_size_x``, ``ipm_moment_tail``, ...: :data:`VECTOR_PARTS`)."""

VECTOR_PARTS = {"epm_size_x": ("epm_size", 0), "epm_size_y": ("epm_size", 1), "epm_size_z": ("epm_size", 2),
                "ipm_moment_tail": ("ipm_moment", 0), "ipm_moment_centre": ("ipm_moment", 1),
                "ipm_moment_head": ("ipm_moment", 2)}
"""Spec name -> (WormParams vector field, component)."""


def fmt_value(v) -> str:
    """A value as the error messages quote it: strings in single quotes, everything else as ``repr``."""
    return repr(v) if not isinstance(v, str) else f"'{v}'"


def value_problem(values, spec: ParamSpec) -> str | None:
    """What is wrong with the values (one per world) of a parameter of ``spec`` ("got X; expected Y"), or None."""
    if spec.values is not None:
        bad = [v for v in np.atleast_1d(np.asarray(values, dtype=object)).tolist() if v not in spec.values]
        return f"got {fmt_value(bad[0])}; expected one of {list(spec.values)}" if bad else None
    try:
        a = np.asarray(values, np.float64).reshape(-1)
    except (TypeError, ValueError):
        return f"got {fmt_value(values)}; expected a number [{spec.unit}]"
    nan = np.isnan(a)
    if nan.any() and not spec.preset:  # NaN = "the gait preset's value", only where a preset gives one
        return f"got nan; expected a number [{spec.unit}]"
    a = a[~nan]
    checks = [(~np.isfinite(a), "a finite number"), (a <= 0 if spec.positive else a != a, "values > 0"),
              (a < spec.low if spec.low is not None else a != a, f"values >= {spec.low}"),
              (a > spec.high if spec.high is not None else a != a, f"values <= {spec.high}")]
    for bad, what in checks:
        if bad.any():
            return f"got {fmt_value(float(a[bad][0]))}; expected {what} [{spec.unit}]"
    return None


def worm_param_problems(params: WormParams) -> list[str]:
    """Every value of ``params`` (shared or one per world) checked against :data:`WORM_SPECS`; one
    "worm.<field>: got X; expected Y" per problem (empty: all hold)."""
    out = []
    for name, spec in WORM_SPECS.items():
        if name in VECTOR_PARTS:
            field_name, k = VECTOR_PARTS[name]
            v = np.asarray(getattr(params, field_name), np.float64)
            v = v[..., k] if v.ndim and v.shape[-1] == 3 else v
        elif hasattr(params, name):
            v = getattr(params, name)
        else:
            continue
        problem = value_problem(v, spec)
        if problem:
            out.append(f"worm.{name}: {problem}")
    if not (isinstance(params.n_units, (int, np.integer)) and params.n_units >= 1):
        out.append(f"worm.n_units: got {fmt_value(params.n_units)}; expected a whole number >= 1")
    return out


def check_worm_params(params: WormParams) -> WormParams:
    """``params`` if every value holds the contract (:func:`worm_param_problems`), else :class:`ConfigError` with one
    line per problem. Every entry point calls it: the commands, the dataset sampler, ``ModelBuilder``."""
    problems = worm_param_problems(params)
    if problems:
        raise ConfigError(problems)
    return params
