"""Every randomizable parameter: ``randomize.<group>.<name>`` -> its :class:`ParamSpec` (default distribution, unit,
allowed values). The worm's group is the parameter contract itself (:data:`warpworm.physics.param_specs.WORM_SPECS`);
the others are the renderer's (cameras, lights, colours, textures, sensor)."""

from __future__ import annotations

import math

from warpworm.physics.param_specs import WORM_SPECS, ParamSpec

_PI = math.pi

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
