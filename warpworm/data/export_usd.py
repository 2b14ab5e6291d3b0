"""Time-sampled USD stages of worm worlds, from a dataset folder or a saved trajectory.

Stage layout (``metersPerUnit = 1``, ``upAxis = Z``, ``timeCodesPerSecond = 100``: time code = simulated time × 100)::

    /World                              Xform (defaultPrim)
    /World/Floor                        Mesh: a square on the (inclined) floor plane
    /World/w000                         Xform, one per exported world (offset along +y by ``spacing``)
    /World/w000/Worm                    Mesh: points time-sampled [m]; doubleSided;
                                          primvars:displayColor (vertex)  crease colour: blue mountain .. red valley
                                          primvars:creaseColor  (vertex)  the same, under its own name
                                          primvars:strainColor  (vertex)  |bar strain|: black 0 .. yellow >= 2 %
                                          primvars:creaseAngle  (vertex)  mean signed angle of incident creases [rad]
                                          primvars:barStrain    (vertex)  mean |strain| of incident bars
    /World/w000/IPM_tail|IPM_centre|IPM_head   Xform, transform time-sampled; child Cylinder (axis Z) = the disk
    /World/w000/EPM                     Xform, transform time-sampled; child Cube scaled to the EPM's extents
    /World/w000/Camera                  Camera (dataset sources): OpenCV pose converted to USD's −Z-forward, +Y-up;
                                          with render.views_per_frame K > 1 one camera per view, Camera_v0 ..
                                          Camera_v<K-1>; a camera that moves (render.camera_per_frame) is
                                          time-sampled at the frames its view shows

Sources:
* a dataset folder (``warpworm generate``): trajectory ``j``'s frames are the samples with ``trajectory == j``; one
  time sample per simulated frame (its K views share the physical state: the first view's sample is taken), the
  views' cameras each their own prim;
* a trajectory file (``.npz`` or ``.h5``) with ``positions (F, W, V, 3)`` [m], ``magnet_pos (F, W, 4, 3)``,
  ``magnet_rot (F, W, 4, 3, 3)``, ``crease_angle (F, W, H)``, ``bar_strain (F, W, E)``, ``time (F,)`` [s] and the
  topology ``triangles (T, 3)``, ``hinges (H, 4)``, ``edges (E, 2)`` (optional ``ipm_diameter``, ``ipm_thickness``,
  ``epm_size``, ``floor_incline``; when absent the :class:`~warpworm.physics.params.WormParams` defaults are used).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdUtils, Vt

from warpworm import transforms as tf
from warpworm.data import dataset as ds
from warpworm.physics.params import WormParams

TIME_CODES_PER_SECOND = 100.0
MAGNET_NAMES = ("EPM", "IPM_tail", "IPM_centre", "IPM_head")


@dataclass
class Track:
    """One world over F frames (NumPy, SI)."""

    name: str
    time: np.ndarray  # (F,) [s]
    points: np.ndarray  # (F, V, 3) [m]
    magnet_pose: np.ndarray  # (F, 4, 4, 4) magnet -> world, slots EPM, tail, centre, head
    crease_angle: np.ndarray  # (F, H) [rad]
    bar_strain: np.ndarray  # (F, E)
    triangles: np.ndarray  # (T, 3)
    hinges: np.ndarray  # (H, 4)
    edges: np.ndarray  # (E, 2)
    ipm_diameter: float
    ipm_thickness: float
    epm_size: np.ndarray  # (3,)
    floor_incline: float
    cameras: tuple = ()  # ViewCamera per view (dataset sources)


@dataclass
class ViewCamera:
    """One view's OpenCV pinhole camera (world -> camera) at the frames it shows."""

    name: str  # prim name under the world: Camera (one view), Camera_v<k> (K views)
    time: np.ndarray  # (n,) [s] the frames' times
    K: np.ndarray  # (n, 3, 3) [px]
    R: np.ndarray  # (n, 3, 3)
    t: np.ndarray  # (n, 3) [m]
    width: int
    height: int


def tracks_from_dataset(root, trajectories=(0,)) -> list[Track]:
    """Tracks of the given trajectory ids of a dataset folder: one frame per simulated frame (with
    ``render.views_per_frame`` K > 1 a frame is K samples of one physical state: the first one's state is taken) and
    one :class:`ViewCamera` per view."""
    r = ds.open(root)
    try:
        a = r.attrs
        traj = r.read("trajectory")
        has_view = "view" in r.keys()
        height, width = r.read("depth", [0]).shape[1:3]
        out = []
        for j in trajectories:
            idx = np.flatnonzero(traj == j)  # sample order: view-major, then frame
            if idx.size == 0:
                raise ValueError(f"trajectory {j} is not in {root} (it has {traj.min()}..{traj.max()})")
            frame = r.read("frame", idx)
            view = r.read("view", idx) if has_view else np.zeros(idx.size, np.int32)
            _, first = np.unique(frame, return_index=True)  # each frame's first sample (view 0), by frame
            state = idx[first]
            time = r.read("time", state).astype(np.float64)
            if np.any(np.diff(time) <= 0):
                raise ValueError(f"trajectory {j} of {root}: frame times {time.tolist()} are not strictly increasing")
            pose = np.concatenate([r.read("poses/epm", state)[:, None], r.read("poses/ipm", state)], axis=1)
            p0 = lambda n: float(r.read(f"params/worm.{n}", state[:1])[0])  # noqa: E731
            views = np.unique(view)
            cams = []
            for v in views:
                sel = idx[view == v]  # frames in increasing order within a view
                cams.append(ViewCamera(
                    name="Camera" if len(views) == 1 else f"Camera_v{int(v)}",
                    time=r.read("time", sel).astype(np.float64), K=r.read("camera/K", sel),
                    R=r.read("camera/R", sel), t=r.read("camera/t", sel), width=int(width), height=int(height)))
            out.append(Track(
                name=f"w{j:03d}", time=time, points=r.read("worm/vertices", state).astype(np.float32),
                magnet_pose=pose, crease_angle=r.read("creases/angle", state),
                bar_strain=r.read("bars/strain", state), triangles=np.asarray(a["mesh_triangles"]),
                hinges=np.asarray(a["crease_hinges"]), edges=np.asarray(a["bar_edges"]),
                ipm_diameter=p0("ipm_diameter"), ipm_thickness=p0("ipm_thickness"),
                epm_size=np.array([p0("epm_size_x"), p0("epm_size_y"), p0("epm_size_z")]),
                floor_incline=p0("floor_incline"), cameras=tuple(cams)))
    finally:
        r.close()
    return out


def _read_arrays(path: Path) -> dict:
    """Every array of an .npz or HDF5 file (name -> array); ValueError naming the file if it is neither."""
    try:
        if path.suffix == ".npz":
            with np.load(path, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}

        with h5py.File(path, "r") as f:
            d = {}
            f.visititems(lambda n, o: d.__setitem__(n, o[...]) if isinstance(o, h5py.Dataset) else None)
            return d
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{path}: not a trajectory file (expected .npz or HDF5: {exc})") from None


def tracks_from_trajectory(path, worlds=(0,)) -> list[Track]:
    """Tracks of worlds ``worlds`` of a trajectory file (.npz or .h5; keys in the module docstring)."""
    path = Path(path)
    d = _read_arrays(path)
    if "time" not in d and "times" in d:  # `warpworm simulate`'s trajectory.npz names it `times`
        d["time"] = d["times"]
    missing = [k for k in ("positions", "magnet_pos", "magnet_rot", "time", "triangles") if k not in d]
    if missing:
        raise ValueError(f"{path}: not a trajectory file (missing {missing}; expected `warpworm simulate`'s "
                         "trajectory.npz or a dataset folder)")
    w = WormParams()
    F, S = d["positions"].shape[:2]
    bad = [j for j in worlds if not 0 <= j < S]
    if bad:
        raise ValueError(f"--worlds: got {bad}; expected world indices in [0, {S}) (the file holds {S} world(s))")
    out = []
    for j in worlds:
        pose = tf.pose_matrix(d["magnet_rot"][:, j], d["magnet_pos"][:, j])

        def get(key, default, j=j):
            v = d.get(key)
            if v is None:
                return default
            v = np.asarray(v)
            return v if v.ndim == 0 or v.shape[0] != d["positions"].shape[1] else v[j]

        out.append(Track(
            name=f"w{j:03d}", time=np.asarray(d["time"], np.float64).reshape(F, -1)[:, 0],
            points=d["positions"][:, j].astype(np.float32), magnet_pose=pose,
            crease_angle=d["crease_angle"][:, j] if "crease_angle" in d else np.zeros((F, 0)),
            bar_strain=d["bar_strain"][:, j] if "bar_strain" in d else np.zeros((F, 0)),
            triangles=d["triangles"], hinges=d.get("hinges", np.zeros((0, 4), np.int32)),
            edges=d.get("edges", np.zeros((0, 2), np.int32)),
            ipm_diameter=float(get("ipm_diameter", w.ipm_diameter)),
            ipm_thickness=float(get("ipm_thickness", w.ipm_thickness)),
            epm_size=np.asarray(get("epm_size", w.epm_size), np.float64).reshape(3),
            floor_incline=float(get("floor_incline", w.floor_incline))))
    return out


def _vertex_mean(values: np.ndarray, index: np.ndarray, num_vertices: int) -> np.ndarray:
    """Mean over incident elements: values (F, M), index (M, k) vertex ids -> (F, V)."""
    F = values.shape[0]
    acc = np.zeros((F, num_vertices))
    cnt = np.zeros(num_vertices)
    for c in range(index.shape[1]):  # k = 2 columns: loop over stencil columns, vectorized over frames/elements
        np.add.at(acc, (slice(None), index[:, c]), values)
        np.add.at(cnt, index[:, c], 1.0)
    return acc / np.maximum(cnt, 1.0)


def _crease_colour(angle: np.ndarray) -> np.ndarray:
    """Signed angle [rad] -> RGB: blue (mountain, -pi) .. white (flat) .. red (valley, +pi)."""
    s = np.clip(angle / np.pi, -1, 1)[..., None]
    white = np.ones(3)
    return np.where(s >= 0, white + s * (np.array([0.85, 0.1, 0.1]) - white),
                    white - s * (np.array([0.1, 0.25, 0.85]) - white))


def _strain_colour(strain: np.ndarray) -> np.ndarray:
    s = np.clip(np.abs(strain) / 0.02, 0, 1)[..., None]
    return s * np.array([1.0, 0.9, 0.1])


def _gf_matrix(T: np.ndarray):
    """4x4 column-vector transform (object -> world) -> Gf.Matrix4d (USD uses row vectors: transpose)."""
    return Gf.Matrix4d(*np.asarray(T, np.float64).T.reshape(-1).tolist())


def _define_floor(stage, incline: float, floor_half: float) -> None:
    """A square in the inclined plane (normal (-sin i, 0, cos i)), as in the simulator and renderer."""
    u = np.array([np.cos(incline), 0.0, np.sin(incline)])
    v = np.array([0.0, 1.0, 0.0])
    corners = np.array([floor_half * (su * u + sv * v) for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1))])
    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")
    floor.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(corners.astype(np.float32)))
    floor.CreateFaceVertexCountsAttr([4])
    floor.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    floor.CreateExtentAttr([Gf.Vec3f(*corners.min(0).tolist()), Gf.Vec3f(*corners.max(0).tolist())])
    floor.CreateDisplayColorAttr([Gf.Vec3f(0.45, 0.42, 0.38)])


def _define_worm(stage, root: str, tr: Track, codes) -> None:
    """The worm's mesh, time-sampled points and extent, and per-vertex crease / strain primvars."""
    V = tr.points.shape[1]
    mesh = UsdGeom.Mesh.Define(stage, f"{root}/Worm")
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(tr.triangles), 3, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(tr.triangles, np.int32).reshape(-1)))
    mesh.CreateDoubleSidedAttr(True)
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    pts, ext = mesh.CreatePointsAttr(), mesh.CreateExtentAttr()
    api = UsdGeom.PrimvarsAPI(mesh)
    crease_v = (_vertex_mean(tr.crease_angle, tr.hinges[:, 1:3], V) if tr.hinges.size
                else np.zeros((len(codes), V)))
    strain_v = (_vertex_mean(np.abs(tr.bar_strain), tr.edges, V) if tr.edges.size
                else np.zeros((len(codes), V)))
    pv_disp = mesh.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex)
    pv_crease = api.CreatePrimvar("creaseColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    pv_strain = api.CreatePrimvar("strainColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
    pv_angle = api.CreatePrimvar("creaseAngle", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex)
    pv_bar = api.CreatePrimvar("barStrain", Sdf.ValueTypeNames.FloatArray, UsdGeom.Tokens.vertex)
    cc = _crease_colour(crease_v).astype(np.float32)
    sc = _strain_colour(strain_v).astype(np.float32)
    for f, tc in enumerate(codes):
        p = np.ascontiguousarray(tr.points[f], np.float32)
        pts.Set(Vt.Vec3fArray.FromNumpy(p), tc)
        ext.Set([Gf.Vec3f(*p.min(0).tolist()), Gf.Vec3f(*p.max(0).tolist())], tc)
        col = Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(cc[f]))
        pv_disp.Set(col, tc)
        pv_crease.Set(col, tc)
        pv_strain.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(sc[f])), tc)
        pv_angle.Set(Vt.FloatArray.FromNumpy(crease_v[f].astype(np.float32)), tc)
        pv_bar.Set(Vt.FloatArray.FromNumpy(strain_v[f].astype(np.float32)), tc)


def _define_magnets(stage, root: str, tr: Track, codes) -> None:
    """The EPM (a cube scaled to its extents) and the IPMs (cylinders), each a time-sampled transform."""
    for slot, name in enumerate(MAGNET_NAMES):
        mx = UsdGeom.Xform.Define(stage, f"{root}/{name}")
        op = mx.AddTransformOp()
        for f, tc in enumerate(codes):
            op.Set(_gf_matrix(tr.magnet_pose[f, slot]), tc)
        if slot == 0:
            cube = UsdGeom.Cube.Define(stage, f"{root}/{name}/Geom")
            cube.CreateSizeAttr(1.0)
            cube.AddScaleOp().Set(Gf.Vec3f(*np.asarray(tr.epm_size, float).tolist()))
            cube.CreateDisplayColorAttr([Gf.Vec3f(0.6, 0.6, 0.62)])
        else:
            cyl = UsdGeom.Cylinder.Define(stage, f"{root}/{name}/Geom")
            cyl.CreateAxisAttr(UsdGeom.Tokens.z)
            cyl.CreateRadiusAttr(tr.ipm_diameter / 2)
            cyl.CreateHeightAttr(tr.ipm_thickness)
            r, h = tr.ipm_diameter / 2, tr.ipm_thickness / 2
            cyl.CreateExtentAttr([Gf.Vec3f(-r, -r, -h), Gf.Vec3f(r, r, h)])
            cyl.CreateDisplayColorAttr([Gf.Vec3f(0.55, 0.55, 0.58)])


def _define_camera(stage, root: str, cam: ViewCamera) -> None:
    """A dataset view's OpenCV pinhole camera as a USD camera: fixed values if it does not move over the frames,
    else time-sampled at the frames' times."""
    w, h = cam.width, cam.height
    c2w = np.broadcast_to(np.eye(4), (len(cam.time), 4, 4)).copy()
    # OpenCV camera (+z forward, +y down) -> USD camera (-z forward, +y up): flip the y and z axes
    c2w[:, :3, :3] = np.swapaxes(cam.R, 1, 2) @ np.diag([1.0, -1.0, -1.0])
    c2w[:, :3, 3] = (-np.swapaxes(cam.R, 1, 2) @ cam.t[:, :, None])[:, :, 0]  # centre -R^T t
    pitch = 36.0 / w  # aperture units per pixel column (mm for a 36 mm-wide sensor); only ratios matter
    row = pitch * cam.K[:, 0, 0] / cam.K[:, 1, 1]  # aperture units per pixel row (fx / fy: non-square pixels)
    values = {"xform": c2w, "horizontalAperture": np.full(len(cam.time), w * pitch), "verticalAperture": h * row,
              "focalLength": cam.K[:, 0, 0] * pitch,
              "horizontalApertureOffset": (cam.K[:, 0, 2] - (w - 1) / 2) * pitch,
              "verticalApertureOffset": -(cam.K[:, 1, 2] - (h - 1) / 2) * row}
    moving = any(not np.all(a == a[:1]) for a in (cam.K, cam.R, cam.t))  # any frame differs from the first
    codes = ([Usd.TimeCode(float(t * TIME_CODES_PER_SECOND)) for t in cam.time] if moving
             else [Usd.TimeCode.Default()])
    prim = UsdGeom.Camera.Define(stage, f"{root}/{cam.name}")
    op = prim.AddTransformOp()
    attrs = {"horizontalAperture": prim.CreateHorizontalApertureAttr(),
             "verticalAperture": prim.CreateVerticalApertureAttr(), "focalLength": prim.CreateFocalLengthAttr(),
             "horizontalApertureOffset": prim.CreateHorizontalApertureOffsetAttr(),
             "verticalApertureOffset": prim.CreateVerticalApertureOffsetAttr()}
    for f, tc in enumerate(codes):
        op.Set(_gf_matrix(values["xform"][f]), tc)
        for key, attr in attrs.items():
            attr.Set(float(values[key][f]), tc)
    prim.CreateClippingRangeAttr(Gf.Vec2f(0.001, 100.0))


def write_stage(tracks: list[Track], path, *, spacing: float = 0.0, floor_half: float = 0.3) -> Path:
    """Write a time-sampled USD stage (``.usda`` or ``.usdc``) of ``tracks``; returns the path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.SetTimeCodesPerSecond(TIME_CODES_PER_SECOND)
    stage.SetFramesPerSecond(TIME_CODES_PER_SECOND)
    t_all = np.concatenate([tr.time for tr in tracks])
    stage.SetStartTimeCode(float(t_all.min() * TIME_CODES_PER_SECOND))
    stage.SetEndTimeCode(float(t_all.max() * TIME_CODES_PER_SECOND))
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    _define_floor(stage, tracks[0].floor_incline, floor_half)
    for k, tr in enumerate(tracks):
        root = f"/World/{tr.name}"
        xf = UsdGeom.Xform.Define(stage, root)
        if spacing:
            xf.AddTranslateOp().Set(Gf.Vec3d(0.0, k * spacing, 0.0))
        codes = [Usd.TimeCode(float(t * TIME_CODES_PER_SECOND)) for t in tr.time]
        _define_worm(stage, root, tr, codes)
        _define_magnets(stage, root, tr, codes)
        for cam in tr.cameras:
            _define_camera(stage, root, cam)
    stage.GetRootLayer().customLayerData = {"warpworm": json.dumps({"source_tracks": [t.name for t in tracks]})}
    stage.GetRootLayer().Save()
    return path


def compliance_errors(path, *, include_warnings: bool = False) -> list[str]:
    """Problems found by USD's compliance checks on the stage (empty list: compliant).

    ``pxr.UsdUtils.ComplianceChecker`` where the installed USD has it (usd-core <= 25.x); USD 26 removed it in favour of
    the ``UsdValidation`` framework (what ``usdchecker`` runs now), so there every registered validator is run.
    """
    if hasattr(UsdUtils, "ComplianceChecker"):
        checker = UsdUtils.ComplianceChecker(arkit=False, skipARKitRootLayerCheck=False, rootPackageOnly=False,
                                             skipVariants=False, verbose=False)
        checker.CheckCompliance(str(path))
        out = list(checker.GetErrors()) + list(checker.GetFailedChecks())
        return out + (list(checker.GetWarnings()) if include_warnings else [])
    from pxr import UsdValidation  # version: USD 26+ only (the framework that replaced ComplianceChecker)

    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(path)))
    bad = {UsdValidation.ValidationErrorType.Error}
    if include_warnings:
        bad.add(UsdValidation.ValidationErrorType.Warn)
    return [f"{e.GetValidator().GetMetadata().name if e.GetValidator() else ''}: {e.GetMessage()}"
            for e in errors if e.GetType() in bad]


def read_points(path, prim: str = "/World/w000/Worm") -> tuple[np.ndarray, np.ndarray]:
    """(times [s] (F,), points (F, V, 3)) of a worm mesh read back from a stage."""
    stage = Usd.Stage.Open(str(path))
    attr = UsdGeom.Mesh(stage.GetPrimAtPath(prim)).GetPointsAttr()
    codes = attr.GetTimeSamples()
    pts = np.stack([np.asarray(attr.Get(Usd.TimeCode(c)), np.float32) for c in codes])
    return np.asarray(codes) / stage.GetTimeCodesPerSecond(), pts


def export_usd(source, out, *, worlds=(0,), spacing: float | None = None) -> Path:
    """Stage from a dataset folder (trajectory ids ``worlds``) or a trajectory file (world indices ``worlds``)."""
    src = Path(source)
    if src.is_dir():
        tracks = tracks_from_dataset(src, worlds)
    elif src.is_file():
        tracks = tracks_from_trajectory(src, worlds)
    else:
        raise FileNotFoundError(f"{source}: neither a dataset folder nor a trajectory file")
    if spacing is None:
        spacing = 0.0 if len(tracks) == 1 else 0.12
    return write_stage(tracks, out, spacing=spacing)
