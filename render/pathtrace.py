"""A path-traced engine for the rasterizer's scenes: Mitsuba 3 (``pip install warpworm[pathtrace]``), ``scalar_rgb``.

Same meshes (worm sheet by segment, IPM disks, EPM bar, floor square at the plate's pose), cameras, colours and
lights (every point light, a sphere of its ``light_size``) as :mod:`warpworm.render.rasterizer`, but light transport
simulated: shadows (soft from the spherical lights and from the ambient sky; hard from the sun, whose angular size
``sun_size`` is not reproduced), interreflection between panels and floor, anti-aliased edges (``spp`` samples
spread over each pixel by a Gaussian filter). Only RGB comes from here; depth, segmentation, keypoints and every
other label stay the rasterizer's exact pixel-centre passes (docs/dataset.md, "The path-traced engine").

Light units are matched to the rasterizer's Lambert shading (radiance ``albedo * (ambient + E_sun cos + ...)``):
a diffuse BSDF reflects ``albedo / pi`` of the irradiance, so the sun's irradiance and the lamp's intensity are the
rasterizer's values times pi, and the sky's radiance is the ambient value. Display gamma 2 as the rasterizer.
Not reproduced: the procedural paper fibres and the floor grain (the checker is), the EPM's painted half.

Camera (OpenCV ``x_cam = R x + t``, pixel centres at integers) -> Mitsuba's perspective sensor: ``to_world =
[R^T diag(-1, -1, 1) | -R^T t]``, vertical fov ``2 atan(H / (2 fy))``, principal-point offset
``((W - 1) / 2 - cx) / W`` and ``((H - 1) / 2 - cy) / H`` (Mitsuba's pixel x covers [x, x + 1]); square pixels
(``fx == fy``, as the dataset sampler draws) only. :func:`pixel_centre_seg` casts Mitsuba rays through the pixel
centres of the same sensors, so a test can compare the two engines' geometry pixel by pixel.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from warpworm import ids
from warpworm.render.camera import Cameras
from warpworm.render.distortion import widened_pinholes
from warpworm.render.scene import SceneBatch
from warpworm.rng import seed_uniforms

VARIANT = "scalar_rgb"
"""Mitsuba variant: runs on any CPU from the PyPI wheel. ``llvm_ad_rgb`` is ~4x faster per sample (a 256² image:
~0.5 s at 32 spp against ~1 s at 16 spp) but needs libLLVM >= 16 (Debian 12 ships 14 and 15, which it refuses or
crashes on), so it is not the default."""
LAMP_RADIUS = 0.02
"""Radius [m] of the sphere that stands for a point lamp when the appearance gives no ``light_size`` (soft shadows);
same radiant intensity."""
ENGINES = ("raster", "pathtraced")
"""Meaning of the per-sample ``engine`` dataset's values 0 and 1."""
_ENGINE_STREAM = 0x9A7E


def mitsuba():
    """The ``mitsuba`` module with :data:`VARIANT` set; ImportError naming the extra when it is not installed."""
    try:
        import mitsuba as mi
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise ImportError("render.engine 'pathtraced' needs Mitsuba 3: pip install 'warpworm[pathtrace]' "
                          "(or pip install 'mitsuba>=3.5')") from exc
    if mi.variant() != VARIANT:
        mi.set_variant(VARIANT)
    return mi


def choose_pathtraced(seeds: np.ndarray, fraction: float) -> np.ndarray:
    """Which samples are path-traced: (N,) bool, ``uniform(seed) < fraction``, one draw per sample from its own
    per-sample seed (so the choice does not depend on batches, shards or workers)."""
    seeds = np.asarray(seeds, dtype=np.int64).reshape(-1)
    if fraction <= 0.0:
        return np.zeros(len(seeds), bool)
    if fraction >= 1.0:
        return np.ones(len(seeds), bool)
    return seed_uniforms(seeds, _ENGINE_STREAM, 1)[:, 0] < fraction


# ---------------------------------------------------------------------------------------------------------------------
# scene and sensor dictionaries
def sensor_dict(K: np.ndarray, R: np.ndarray, t: np.ndarray, width: int, height: int, *, spp: int = 16,
                seed: int = 0) -> dict:
    """Mitsuba perspective sensor of one OpenCV camera: ``K (3,3)`` [px], ``R (3,3)``, ``t (3,)`` [m]."""
    mi = mitsuba()
    fx, fy, cx, cy = float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2])
    if abs(fx - fy) > 1e-9 * max(fx, fy) or abs(float(K[0, 1])) > 0:
        raise ValueError(f"camera/K: got fx={fx}, fy={fy}, skew={K[0, 1]}; expected square pixels and no skew "
                         "(Mitsuba's perspective sensor has one focal length and refuses a scaled to_world)")
    Rt = np.asarray(R, np.float64).T
    m = np.eye(4)
    m[:3, :3] = Rt @ np.diag([-1.0, -1.0, 1.0])
    m[:3, 3] = -Rt @ np.asarray(t, np.float64)
    return {
        "type": "perspective", "fov_axis": "y", "fov": math.degrees(2.0 * math.atan(height / (2.0 * fy))),
        "principal_point_offset_x": ((width - 1) / 2.0 - cx) / width,
        "principal_point_offset_y": ((height - 1) / 2.0 - cy) / height,
        "near_clip": 1e-3, "far_clip": 100.0, "to_world": mi.ScalarTransform4f(m.tolist()),
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "pixel_format": "rgba",
                 "rfilter": {"type": "gaussian"}},
        "sampler": {"type": "independent", "sample_count": int(spp), "seed": int(seed) % (2**31 - 1)},
    }


def _rgb(v) -> dict:
    return {"type": "rgb", "value": [float(x) for x in np.clip(v, 0.0, 1.0)]}


_PLASTIC: dict[tuple, object] = {}


def _bsdf(mi, label: int, albedo: np.ndarray, spec: np.ndarray):
    """Twosided diffuse paper for the sheet, rough plastic for magnets with a specular term (Beckmann alpha from the
    Blinn-Phong exponent, sqrt(2 / (n + 2))). Rough plastic precomputes Fresnel tables (~80 ms each): cached by its
    parameters (the magnets' look is the same in every world of a dataset)."""
    if label >= ids.SEG_IPM_FIRST and spec[0] > 0:
        key = (round(float(spec[1]), 6), *np.round(np.asarray(albedo, np.float64), 6).tolist())
        if key not in _PLASTIC:
            if len(_PLASTIC) > 256:
                _PLASTIC.clear()
            _PLASTIC[key] = mi.load_dict({"type": "roughplastic", "distribution": "beckmann",
                                          "alpha": float(math.sqrt(2.0 / (spec[1] + 2.0))),
                                          "diffuse_reflectance": _rgb(albedo)})
        return _PLASTIC[key]
    return mi.load_dict({"type": "twosided", "material": {"type": "diffuse", "reflectance": _rgb(albedo)}})


def _floor(mi, scene: SceneBatch, w: int, albedo: np.ndarray) -> dict:
    """The floor square as a rectangle (local [-1, 1]^2, normal +z) with the rasterizer's checker: cell (i, j) of
    side ``tile`` in floor coordinates gets the base colour when i + j is even, else the base mixed with
    ``floor_color2`` by the contrast. Mitsuba's checkerboard gives ``color0`` where floor(2u) + floor(2v) is even."""
    a = scene.appearance
    n, ax = scene.floor_normal[w], scene.floor_axis[w]
    b = np.cross(n, ax)
    h = float(scene.floor_half[w])
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = ax * h, b * h, n
    m[:3, 3] = scene.floor_origin[w] if hasattr(scene, "floor_origin") else 0.0  # the plate's centre
    ft = a.floor_tex[w % a.floor_tex.shape[0]]
    fc2 = a.floor_color2[w % a.floor_color2.shape[0]]
    refl = _rgb(albedo)
    if ft[1] > 0:
        s = h / float(ft[0])  # rectangle uv = (x / h + 1) / 2  ->  u' = x / (2 tile)
        refl = {"type": "checkerboard", "color0": _rgb(albedo), "color1": _rgb(albedo + ft[1] * (fc2 - albedo)),
                "to_uv": mi.ScalarTransform3f().translate([-0.5 * s, -0.5 * s]) @ mi.ScalarTransform3f().scale([s, s])}
    return {"type": "rectangle", "to_world": mi.ScalarTransform4f(m.tolist()),
            "bsdf": {"type": "diffuse", "reflectance": refl}}


def scene_dict(scene: SceneBatch, world: int) -> dict:
    """World ``world`` of a :class:`SceneBatch` as a Mitsuba scene dictionary (no sensor): one mesh per
    segmentation id, the floor, a constant sky (the ambient term), the sun and the lamp."""
    mi = mitsuba()
    w = int(world)
    a = scene.appearance
    albedo = a.albedo[w % a.albedo.shape[0]]
    spec = a.specular[w % a.specular.shape[0]]
    verts = np.asarray(scene.vertices[w], np.float32)
    out = {"type": "scene", "integrator": {"type": "path", "max_depth": 5, "hide_emitters": True}}
    for label in np.unique(scene.tri_label):
        tris = scene.triangles[scene.tri_label == label]
        used, inv = np.unique(tris, return_inverse=True)
        props = mi.Properties()
        props["bsdf"] = _bsdf(mi, int(label), albedo[label], spec[label])
        mesh = mi.Mesh(f"seg{int(label)}", len(used), len(tris), props=props, has_vertex_normals=False)
        p = mi.traverse(mesh)
        p["vertex_positions"] = verts[used].ravel()
        p["faces"] = inv.reshape(-1).astype(np.uint32)
        p.update()
        out[f"seg{int(label)}"] = mesh
    if float(scene.floor_half[w]) > 0:
        out["floor"] = _floor(mi, scene, w, albedo[ids.SEG_FLOOR])
    amb = a.ambient[w % a.ambient.shape[0]]
    out["sky"] = {"type": "constant", "radiance": {"type": "rgb", "value": [float(x) for x in amb]}}
    sun = a.sun_color[w % a.sun_color.shape[0]]
    if np.any(sun > 0):
        out["sun"] = {"type": "directional", "direction": [float(-x) for x in a.sun_dir[w % a.sun_dir.shape[0]]],
                      "irradiance": {"type": "rgb", "value": [float(math.pi * x) for x in sun]}}
    for k, (pos, power, radius) in enumerate(_point_lights(a, w)):
        if not np.any(power > 0):
            continue  # padding of a world with fewer lights
        if radius <= 0:
            out[f"lamp{k}"] = {"type": "point", "position": [float(x) for x in pos],
                               "intensity": {"type": "rgb", "value": [float(math.pi * x) for x in power]}}
            continue
        # a sphere of radiance L has intensity pi r^2 L toward any direction: L = power / r^2 gives pi * power
        out[f"lamp{k}"] = {"type": "sphere", "center": [float(x) for x in pos], "radius": float(radius),
                           "emitter": {"type": "area", "radiance": {
                               "type": "rgb", "value": [float(x / radius**2) for x in power]}}}
    return out


def _point_lights(a, w: int):
    """(position [m], irradiance at 1 m (3,), radius [m]) of every point light of world ``w``: the appearance's
    ``light_pos / light_power / light_size`` (W, L, ...), or its single ``lamp_pos / lamp_power`` with
    :data:`LAMP_RADIUS`."""
    if hasattr(a, "light_pos"):
        pos, power = a.light_pos[w % a.light_pos.shape[0]], a.light_power[w % a.light_power.shape[0]]
        size = a.light_size[w % a.light_size.shape[0]]
        return list(zip(pos, power, size))
    return [(a.lamp_pos[w % a.lamp_pos.shape[0]], a.lamp_power[w % a.lamp_power.shape[0]], LAMP_RADIUS)]


# ---------------------------------------------------------------------------------------------------------------------
# rendering
def _background(scene: SceneBatch, w: int, height: int, width: int) -> np.ndarray:
    """The rasterizer's vertical background gradient (linear RGB), (H, W, 3)."""
    a = scene.appearance
    top, bot = a.bg_top[w % a.bg_top.shape[0]], a.bg_bottom[w % a.bg_bottom.shape[0]]
    f = (np.arange(height) / float(height))[:, None, None]
    return np.broadcast_to(top + (bot - top) * f, (height, width, 3))


def render_pathtraced(scene: SceneBatch, cameras: Cameras, *, spp: int = 16, seeds: np.ndarray | None = None,
                      linear: bool = False) -> np.ndarray:
    """Path-trace every camera's image of its world: (N, H, W, 3) uint8 (display gamma 2, as the rasterizer), or
    linear float32 with ``linear``. Image i uses ``seeds[i]`` (default i) for Mitsuba's sampler; objects are
    composited over the rasterizer's background gradient by their coverage (alpha). As the rasterizer: the camera's
    ``gain`` (exposure x white balance) scales the linear light, and a camera with lens distortion (``dist``) is
    rendered as a widened pinhole image warped through it (:func:`_distorted`)."""
    N, H, W = len(cameras), int(cameras.height), int(cameras.width)
    seeds = np.arange(N) if seeds is None else np.asarray(seeds).reshape(-1)
    dist = getattr(cameras, "dist", None)
    if dist is not None and np.any(np.asarray(dist) != 0):
        out = _distorted(scene, cameras, spp, seeds)
    else:
        out = _trace(scene, cameras, spp, seeds)
    gain = getattr(cameras, "gain", None)
    if gain is not None:
        out = out * np.asarray(gain, np.float32)[:, None, None, :]
    if linear:
        return out
    return (np.sqrt(np.clip(out, 0.0, 1.0)) * 255.0 + 0.5).astype(np.uint8)


def _trace(scene: SceneBatch, cameras: Cameras, spp: int, seeds: np.ndarray) -> np.ndarray:
    """Pinhole images, linear RGB over the background, (N, H, W, 3) float32 (``cameras.dist`` and ``gain`` ignored)."""
    mi = mitsuba()
    N, H, W = len(cameras), int(cameras.height), int(cameras.width)
    out = np.zeros((N, H, W, 3), np.float32)
    loaded: dict[int, object] = {}
    for i in range(N):
        w = int(cameras.world[i])
        if w not in loaded:
            loaded = {w: mi.load_dict(scene_dict(scene, w))}  # images of one world are consecutive in datasets
        sensor = mi.load_dict(sensor_dict(cameras.K[i], cameras.R[i], cameras.t[i], W, H, spp=spp,
                                          seed=int(seeds[i])))
        img = np.asarray(mi.render(loaded[w], sensor=sensor, spp=int(spp), seed=int(seeds[i]) % (2**31 - 1)))
        alpha = np.clip(img[..., 3:4], 0.0, 1.0)
        out[i] = img[..., :3] + (1.0 - alpha) * _background(scene, w, H, W)
    return out


def _distorted(scene: SceneBatch, cameras: Cameras, spp: int, seeds: np.ndarray) -> np.ndarray:
    """Images through ``cameras.dist`` as the rasterizer made them before it followed each pixel through the lens: each
    camera's pinhole image, its K widened by margins that hold the ray of every distorted pixel centre of its own
    image (:func:`warpworm.render.distortion.widened_pinholes`: no image depends on the other cameras of the call),
    warped bilinearly (``cv2.remap``). Linear (N, H, W, 3) float32."""
    N, H, W = len(cameras), int(cameras.height), int(cameras.width)
    out = []
    for i, (view, mx, my) in enumerate(widened_pinholes(cameras)):  # each camera widened by its own lens
        pin = _trace(scene, view, spp, seeds[i:i + 1])
        out.append(cv2.remap(pin[0], mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE))
    return np.stack(out).reshape(N, H, W, 3)


def pixel_centre_seg(scene: SceneBatch, cameras: Cameras) -> np.ndarray:
    """Segmentation ids (N, H, W) uint8 of Mitsuba's first hit through every pixel centre of the same sensors the
    images use (0 = nothing hit): the path tracer's geometry, to compare with the rasterizer's pixel-centre pass."""
    mi = mitsuba()
    N, H, W = len(cameras), int(cameras.height), int(cameras.width)
    seg = np.zeros((N, H, W), np.uint8)
    for i in range(N):
        w = int(cameras.world[i])
        sc = mi.load_dict(scene_dict(scene, w))
        sensor = mi.load_dict(sensor_dict(cameras.K[i], cameras.R[i], cameras.t[i], W, H, spp=1))
        names = {}
        for y in range(H):
            for x in range(W):
                ray, _ = sensor.sample_ray(0.0, 0.5, mi.ScalarPoint2f((x + 0.5) / W, (y + 0.5) / H),
                                           mi.ScalarPoint2f(0.5, 0.5))
                si = sc.ray_intersect(ray)
                if not si.is_valid():
                    continue
                sid = si.shape.id()
                if sid not in names:
                    names[sid] = ids.SEG_FLOOR if sid == "floor" else (int(sid[3:]) if sid.startswith("seg") else 0)
                seg[i, y, x] = names[sid]
    return seg


__all__ = ["ENGINES", "LAMP_RADIUS", "VARIANT", "choose_pathtraced", "mitsuba", "pixel_centre_seg",
           "render_pathtraced", "scene_dict", "sensor_dict"]
