"""``warpworm simulate``: run a gait on W worlds, print each world's net displacement, write a trajectory and a preview.

Outputs in ``--out`` (default ``./simulate_out``):
- ``trajectory.npz``: ``times (F,)`` [s]; ``positions (F, S, V, 3)``, ``magnet_pos (F, S, 4, 3)`` [m];
  ``magnet_rot (F, S, 4, 3, 3)``; ``crease_angle (F, S, H)`` [rad]; ``bar_strain (F, S, E)``; ``unstable (S,)``;
  topology ``triangles``, ``edges``, ``hinges``, ``hinge_label``, ``triangle_segment``; ``displacement_m (W,)``;
  S = the first ``--save-worlds`` worlds (float32).
- ``preview.mp4`` (OpenCV mp4v; side view of world 0 with the magnets) and ``preview_strip.png`` (frames side by side);
  with ``--texture-worm bands`` (or a ``--randomize`` config whose ``texture.worm`` is ``bands``) the facets are
  painted in the paper's five marker bands (``--band-colors``, or the config's ``render.band_colors``), as the
  renderer paints them.
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from warpworm import quiet_warp
from warpworm.analysis.gait_metrics import end_centres, segment_ratios
from warpworm.analysis.gait_runs import randomized_params, run_gait_split
from warpworm.analysis.track import parse_band_colors
from warpworm.commands.common import check_minimum, check_positive, device_option, first_run_notice, refuse
from warpworm.data import export_json as strict_json
from warpworm.data import randomize as rnd
from warpworm.data.config import check_options, load_config
from warpworm.physics import gaits
from warpworm.physics.param_specs import check_worm_params
from warpworm.physics.params import parse_overrides
from warpworm.render.scene import BAND_COLORS
from warpworm.sim.model import Model

HELP = "run a gait (peristaltic, omega, inchworm; forward or backward) on W worlds and report net displacement"

def add_arguments(parser) -> None:
    parser.add_argument("--gait", choices=["peristaltic", "omega", "inchworm"], default="peristaltic")
    parser.add_argument("--backward", action="store_true", help="drive the worm toward -x")
    parser.add_argument("--cycles", type=int, default=5, help="EPM cycles to run (default 5)")
    parser.add_argument("--worlds", type=int, default=1, help="number of worlds W (default 1)")
    parser.add_argument("--device", default="cpu", help="Warp device: cpu | cuda | cuda:N (default cpu)")
    parser.add_argument("--magnet-model", choices=["dipoles", "analytic"], default="dipoles")
    parser.add_argument("--dt", type=float, default=None, help="step [s] (magnet wrench refresh; default preset)")
    parser.add_argument("--substeps", type=int, default=None, help="solver substeps per step (default preset: 2, i.e. 2 ms)")
    parser.add_argument("--settle", type=float, default=0.2, help="settling time before the gait [s] (default 0.2)")
    parser.add_argument("--json", action="store_true", help="print only a JSON summary on stdout")
    parser.add_argument("--out", default="simulate_out", help="output folder (default ./simulate_out)")
    parser.add_argument("--no-output", action="store_true", help="write no trajectory / preview files")
    parser.add_argument("--save-worlds", type=int, default=4, help="worlds stored in the trajectory (default 4)")
    parser.add_argument("--fps", type=float, default=30.0, help="trajectory / preview frame rate [1/s]")
    parser.add_argument("--seed", type=int, default=0, help="seed of --randomize")
    parser.add_argument("--workers", type=int, default=None,
                        help="threads to split the worlds over (default: every core; results equal one thread's)")
    parser.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                        help="override a WormParams field of every world (after --randomize), e.g. --set "
                             "friction_backward_ratio=2 --set wavelength=0.006")
    parser.add_argument("--randomize", nargs="?", const="default", default=None, metavar="CONFIG",
                        help="draw every world's parameters as a dataset job of CONFIG (default: default) with --seed "
                             "draws its trajectories (the config's distributions around the gait preset), gait, "
                             "direction and magnet model fixed to this command's")
    parser.add_argument("--texture-worm", choices=["plain", "bands"], default=None,
                        help="the previews' sheet: 'bands' paints the five marker bands (as a dataset config's "
                             "texture.worm: bands; default: the --randomize config's, else plain)")
    parser.add_argument("--band-colors", default=None, metavar="R,G,B;R,G,B;...",
                        help="the five band colours tail -> head as displayed, each R,G,B in [0, 1] (default: the "
                             "--randomize config's render.band_colors, else the paper's)")


def _draw_frame(x, tri, mpos, mrot, msize, width=640, height=360, xlim=(-0.03, 0.14), zlim=(-0.01, 0.10), *,
                edges=None, edge_colour=None, facet_colour=None):
    """Side view (x right, z up) of one world: facets, floor line (z = 0; the EPM moves beneath it), magnets (EPM red,
    IPMs orange); with ``edges`` (E, 2) and ``edge_colour`` (E, 3) BGR the bars are drawn in those colours; with
    ``facet_colour`` (T, 3) BGR the facets are filled in those (the marker bands)."""

    img = np.full((height, width, 3), 255, np.uint8)
    sx = width / (xlim[1] - xlim[0])
    sz = height / (zlim[1] - zlim[0])
    s = min(sx, sz)

    def px(p):
        return np.stack([(p[..., 0] - xlim[0]) * s, height - (p[..., 2] - zlim[0]) * s], -1).astype(np.int32)

    y0 = px(np.array([0.0, 0.0, 0.0]))[1]
    cv2.line(img, (0, int(y0)), (width - 1, int(y0)), (80, 80, 80), 1)
    pts = px(x[tri])
    for k, poly in enumerate(pts):  # back-to-front order is irrelevant for a flat-shaded outline view
        cv2.fillConvexPoly(img, poly, (225, 235, 240) if facet_colour is None else tuple(int(c) for c in facet_colour[k]))
        cv2.polylines(img, [poly], True, (120, 120, 120), 1, cv2.LINE_AA)
    if edges is not None:
        ends = px(x[np.asarray(edges)])
        for (a, b), c in zip(ends, edge_colour):
            cv2.line(img, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), tuple(int(v) for v in c), 2, cv2.LINE_AA)
    for m in range(4):
        half = 0.5 * msize[m]
        corners = np.array([[sx_, sy_, sz_] for sx_ in (-1, 1) for sy_ in (-1, 1) for sz_ in (-1, 1)]) * half
        world = mpos[m] + corners @ mrot[m].T
        hull = cv2.convexHull(px(world))
        cv2.fillConvexPoly(img, hull, (60, 60, 220) if m == 0 else (200, 90, 40))
        tip = px(mpos[m] + mrot[m][:, 2] * (0.6 * float(np.max(msize[m]))))
        cv2.arrowedLine(img, tuple(int(v) for v in px(mpos[m])), tuple(int(v) for v in tip), (0, 0, 0), 1,
                        cv2.LINE_AA, tipLength=0.3)
    return img


def strain_colour(strain: np.ndarray, scale: float) -> np.ndarray:
    """BGR colours (E, 3) uint8 from blue (no strain) to red (|strain| >= ``scale``), as the paper's Fig. 12."""
    u = np.clip(np.abs(strain) / max(scale, 1e-12), 0.0, 1.0)[:, None]
    return ((1.0 - u) * np.array([220.0, 80.0, 30.0]) + u * np.array([30.0, 30.0, 230.0])).astype(np.uint8)


def write_filmstrip(path: Path, frames: dict, model, params, world: int = 0, count: int = 8) -> Path:
    """A side-view filmstrip of ``world``: ``count`` frames over the last whole EPM cycle, bars coloured by their
    Cauchy strain (blue none → red the largest in the strip), the EPM (red) and IPMs (orange) drawn, the floor line at
    z = 0; time, the four deformation ratios and the head–tail length under each frame."""

    pat = model.pattern
    t = frames["time"]
    period = float(np.max(np.asarray(params.cycle_period)))
    start = max(0.0, (np.floor(t[-1] / period + 1e-9) - 1.0) * period)
    pick = [int(np.argmin(np.abs(t - (start + period * k / count)))) for k in range(count)]
    x = frames["positions"][:, world].astype(np.float64)
    mpos = frames["magnet_pos"][:, world]
    ratios = segment_ratios(pat, frames["positions"][:, world:world + 1])[:, 0]
    strain = frames["bar_strain"][:, world]
    scale = float(np.abs(strain[pick]).max())
    lo = min(x[pick][..., 0].min(), mpos[pick, 0, 0].min()) - 0.01
    hi = max(x[pick][..., 0].max(), mpos[pick, 0, 0].max()) + 0.01
    zlo = min(-0.02, float(mpos[pick, 0, 2].min()) - 0.025)
    ztop = max(0.05, float(x[pick][..., 2].max()) + 0.01)
    size = model.magnet_size_host[world]
    tiles = []
    for f in pick:
        img = _draw_frame(x[f], pat.triangles, mpos[f], frames["magnet_rot"][f, world], size, width=420, height=300,
                          xlim=(lo, hi), zlim=(zlo, ztop), edges=pat.edges, edge_colour=strain_colour(strain[f], scale))
        tail_c, head_c = end_centres(pat, x[f])
        length = np.linalg.norm(head_c - tail_c)
        cv2.putText(img, f"t = {t[f]:.2f} s   L = {1e3 * length:.1f} mm", (8, 18), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                    (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(img, "ratios " + " ".join(f"{r:.2f}" for r in ratios[f]), (8, 36), cv2.FONT_HERSHEY_SIMPLEX,
                    0.45, (0, 0, 0), 1, cv2.LINE_AA)
        tiles.append(img)
    rows = [np.concatenate(tiles[i:i + 4], axis=1) for i in range(0, len(tiles), 4)]
    sheet = np.concatenate(rows, axis=0)
    title = np.full((30, sheet.shape[1], 3), 255, np.uint8)
    cv2.putText(title, f"{params.gait}{' backward' if params.backward else ''}: one EPM cycle, bars coloured by strain "
                f"(blue 0 -> red {100 * scale:.1f} %)", (8, 21), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1,
                cv2.LINE_AA)
    path = Path(path)
    cv2.imwrite(str(path), np.concatenate([title, sheet], axis=0))
    return path


def band_facet_colours(triangle_segment, colors) -> np.ndarray:
    """BGR uint8 (T, 3) of each facet painted in the marker bands: segment i (tail -> head) gets display colour
    ``colors[i]`` ((5, 3) RGB in [0, 1]), as :func:`warpworm.render.scene.band_appearance` paints the render."""
    c = np.asarray(colors, np.float64)[np.asarray(triangle_segment)]
    return np.round(255 * c[:, ::-1]).astype(np.uint8)


def write_outputs(out: Path, result: dict, params, num_worlds: int, band_colors=None) -> list[Path]:
    """trajectory.npz, preview.mp4 and preview_strip.png (world 0); ``band_colors`` (5, 3) paints the previews'
    facets in the marker bands."""

    out.mkdir(parents=True, exist_ok=True)
    model, fr = result["model"], result["frames"]
    pat = model.pattern
    paths = []
    traj = out / "trajectory.npz"
    np.savez_compressed(
        traj, times=fr["time"], positions=fr["positions"], magnet_pos=fr["magnet_pos"], magnet_rot=fr["magnet_rot"],
        crease_angle=fr["crease_angle"], bar_strain=fr["bar_strain"], unstable=result["unstable"],
        displacement_m=result["displacement_m"], triangles=pat.triangles, edges=pat.edges, hinges=pat.hinges,
        hinge_label=pat.hinge_label, triangle_segment=pat.triangle_segment, gait=params.gait,
        backward=params.backward,
    )
    paths.append(traj)
    x = fr["positions"][:, 0]
    lo = min(x[..., 0].min(), fr["magnet_pos"][:, 0, :, 0].min()) - 0.02
    hi = max(x[..., 0].max(), fr["magnet_pos"][:, 0, :, 0].max()) + 0.02
    ztop = max(0.06, float(fr["magnet_pos"][:, 0, 0, 2].max()) + 0.03)
    size = model.magnet_size_host[0]
    facets = None if band_colors is None else band_facet_colours(pat.triangle_segment, band_colors)
    imgs = [_draw_frame(x[f], pat.triangles, fr["magnet_pos"][f, 0], fr["magnet_rot"][f, 0], size,
                        xlim=(lo, hi), zlim=(-0.01, ztop), facet_colour=facets) for f in range(len(x))]
    for f, img in enumerate(imgs):
        cv2.putText(img, f"{params.gait}{' backward' if params.backward else ''}  t = {fr['time'][f]:.2f} s",
                    (10, 22), cv2.FONT_HERSHEY_SIMPLEX, 0.55, (0, 0, 0), 1, cv2.LINE_AA)
    video = out / "preview.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), 30.0, (imgs[0].shape[1], imgs[0].shape[0]))
    for img in imgs:
        writer.write(img)
    writer.release()
    paths.append(video)
    pick = np.linspace(0, len(imgs) - 1, min(6, len(imgs))).astype(int)
    strip = out / "preview_strip.png"
    cv2.imwrite(str(strip), np.concatenate([imgs[i][:, :, :] for i in pick], axis=1))
    paths.append(strip)
    paths.append(write_filmstrip(out / "filmstrip.png", fr, model, params))
    return paths


def _preview_bands(args):
    """The previews' band colours (5, 3), or None for the plain sheet: ``--texture-worm`` / ``--band-colors``, else
    the ``--randomize`` config's ``texture.worm`` (a constant ``bands``) and ``render.band_colors``."""

    colors = parse_band_colors(args.band_colors)
    texture = args.texture_worm
    if args.randomize and (texture is None or colors is None):
        cfg = load_config(args.randomize)
        worm = cfg.randomize["texture"]["worm"]
        if texture is None and isinstance(worm, rnd.Constant) and worm.value == "bands":
            texture = "bands"
        if colors is None and cfg.render.band_colors is not None:
            colors = np.asarray(cfg.render.band_colors, np.float64)
    if texture != "bands":
        if args.band_colors is not None:
            raise ValueError(f"--band-colors: got {args.band_colors!r} without bands; expected --texture-worm bands "
                             "(or a --randomize config with texture.worm: bands)")
        return None
    return BAND_COLORS if colors is None else colors


def main(args) -> int:
    quiet_warp()

    try:  # the rules generate applies to the same values (warpworm.data.config), before any work
        check_options({"--worlds": (args.worlds, "sim.worlds"), "--dt": (args.dt, "sim.dt"),
                       "--substeps": (args.substeps, "sim.substeps"), "--settle": (args.settle, "sim.settle_time")})
        check_minimum(cycles=(args.cycles, 1), save_worlds=(args.save_worlds, 1), workers=(args.workers, 1))
        check_positive(fps=args.fps)
        device = device_option(args.device)
        overrides = parse_overrides(args.set)
        params = gaits.preset_params(args.gait, args.backward, magnet_model=args.magnet_model)
        if args.randomize:
            params = randomized_params(args.randomize, args.gait, args.backward, args.magnet_model, args.worlds,
                                       args.seed)
        params = check_worm_params(replace(params, **overrides))
        Model.from_params(params, args.worlds, "cpu")  # refuse bad values of any world before any work (~50 ms at 4096)
        band_colors = _preview_bands(args)
        if not args.no_output and Path(args.out).exists() and not Path(args.out).is_dir():
            raise ValueError(f"--out: got '{args.out}'; expected a folder (it is a file)")
    except ValueError as e:
        return refuse(e)
    want_files = not args.no_output
    if args.worlds > 1 and not args.randomize:
        print(f"note: the {args.worlds} worlds are identical (one parameter set); add --randomize to draw each "
              "world's material, magnets and EPM path from the default dataset config", file=sys.stderr)

    first_run_notice()
    # one process per core on the CPU; a GPU runs every world in one batch
    workers = args.workers if device == "cpu" else 1
    result = run_gait_split(params, args.worlds, args.cycles, workers=workers, device=device, dt=args.dt,
                            substeps=args.substeps, settle=args.settle,
                            fps=args.fps if (want_files or args.json) else None, save_worlds=args.save_worlds)
    disp = result["displacement_m"]
    unstable = result["unstable"]
    paths = write_outputs(Path(args.out), result, params, args.worlds, band_colors) if want_files else []
    if args.json:
        summary = {
            "gait": args.gait,
            "worlds": args.worlds,
            "displacement_m": [float(d) for d in disp],
            "unstable": [bool(u) for u in unstable],
            "crumpled": [bool(c) for c in result["crumpled"]],
            "sim_time_s": float(result["sim_time_s"]),
            "wall_time_s": float(result["wall_time_s"]),
        }
        if result["metrics"] is not None:
            summary.update({k: np.asarray(v).tolist() for k, v in result["metrics"].items()})
        sys.stdout.write(strict_json.dumps(summary) + "\n")
        return 0
    direction = "backward" if args.backward else "forward"
    print(f"{args.gait} {direction}: {args.cycles} cycles, {result['sim_time_s']:.2f} s simulated on {args.worlds} "
          f"world(s) in {result['wall_time_s']:.1f} s wall")
    for w, (d, u) in enumerate(zip(disp, unstable)):
        print(f"  world {w:4d}: net displacement along the worm axis {1e3 * d:+8.2f} mm"
              f"  ({1e3 * d / max(result['sim_time_s'], 1e-12):+.2f} mm/s){'  UNSTABLE (frozen)' if u else ''}")
    m = result["metrics"]
    if m is not None:
        for w in range(min(args.worlds, 8)):
            print(f"  world {w:4d}: ratios min {np.round(m['deformation_ratio_min'][w], 3).tolist()}, crease swing "
                  f"{m['crease_angle_range_deg'][w]:.1f} deg, fold violation {m['max_fold_violation_deg'][w]:.1f} deg\n"
                  f"  world {w:4d}: tail {1e3 * m['tail_displacement_m'][w]:+.1f} mm, head "
                  f"{1e3 * m['head_displacement_m'][w]:+.1f} mm, centre lift {1e3 * m['centre_ipm_max_lift_m'][w]:.1f} "
                  f"mm, lateral drift {1e3 * m['lateral_displacement_m'][w]:+.1f} mm (max "
                  f"{1e3 * m['lateral_drift_max_m'][w]:.1f})")
            if m["approach_placement"].shape[1]:
                print(f"  world {w:4d}: per cycle: smallest ratio "
                      f"{np.round(m['cycle_ratio_min'][w].min(axis=-1), 3).tolist()}, end hold "
                      f"{np.round(m['end_hold_ratio'][w], 2).tolist()}\n  world {w:4d}: per cycle: EPM placement at "
                      f"closest approach (0 centre IPM, 1 head IPM) {np.round(m['approach_placement'][w], 2).tolist()}")
    for p in paths:
        print(f"  wrote {p}")
    return 0
